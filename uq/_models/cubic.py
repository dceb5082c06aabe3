"""Per-pressure Bayesian cubics: force (eq. 8) and piston coordinate (eq. 9) of one test.

Model of one test at overpressure p_u, u = x - x0 (m), t = u / h with h = 0.05 m:

    force_k  ~ N(sum_j alpha_j t_k^j,  sigma0^2 + (r * |Phat_k|)^2)     (eq. 8)
    piston_k ~ N(sum_j gamma_j t_k^j,  sigma_L^2)                        (eq. 9)

Phat_k is the least-squares force at point k (a direct linear least-squares solve), so the load
cell's relative error r and the floor sigma0 (pressure holding, displacement, relaxation)
make the force noise grow with the force, as the stand's error budget does.

Priors (weakly informative, fixed physical scales, so they can be sampled for calibration):
    alpha_j ~ N(0, (100 kN)^2)    (the load cell's range; t is within about +-1 on the stand)
    gamma_j ~ N(0, (1 m)^2)       (longer than the 630 mm cylinder stroke)
    log sigma0[N] ~ N(log 10, 2^2),  log r ~ N(log r_stand, 1),  log sigma_L[m] ~ N(log 1e-3, 2^2)
with r_stand the stand's load-cell error (0.5 % on the paper's stand).

Given the three noise parameters the coefficients are Gaussian: the model is a
:class:`uq._inference.collapsed.CollapsedModel` (``MODEL``), fitted by the one driver
``fit_collapsed`` (emcee on the noise, exact draws of the eight coefficients), reported in the
paper's basis (a + b u + c u^2 + d u^3, SI units).

The variants have a module each: the force alone (``uq._models.cubic_force``), the measured
pressure as a covariate (``uq._models.cubic_measured``), AR(1) pressure-holding errors
(``uq._models.cubic_ar1``); the fits of a campaign are ``uq._models.cubic_fit`` and their results
(numpy only) ``uq._models.cubic_results``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from uq._data.recordings import PressureTest
from uq._data.reference import FORCE_NAMES, PAPER_PISTON_AREA_M2, PISTON_NAMES
from uq._data.stand_description import PAPER_STAND, StandDescription
from uq._inference.collapsed import CollapsedModel, hold_out_by_weight
from uq._inference.exported import persistent_jit
from uq._inference.float64 import jax, jnp
from uq._inference.linear import draw_exact, gaussian_loglik, linear_posterior, loo_given_noise
from uq._models.cubic_results import NOISE_NAMES, noise_reference
from uq._physics.quantities import BASIS_SCALE_M, force_noise_var, to_paper_basis

MAX_DRAWS = 8000  # retained posterior samples per test after thinning
FORCE_PRIOR_SD_N = 1.0e5
PISTON_PRIOR_SD_M = 1.0
SAMPLER_NAMES = ("log_noise_at_mean_force", "logit_floor_share", "log_sigma_L")
NOISE_PRIOR_SD = np.array([2.0, 1.0, 2.0])


def noise_prior_mean(stand: StandDescription = PAPER_STAND) -> np.ndarray:
    """Prior centres of (log sigma0 [N], log r, log sigma_L [m]); r's from the stand's load cell
    (a stand declaring a perfect load cell still gets a 0.01 % centre: log 0 has no prior)."""
    return np.log(np.array([10.0, max(stand.load_cell_rel_sd, 1e-4), 1.0e-3]))


NOISE_PRIOR_MEAN = noise_prior_mean(PAPER_STAND)


def basis(u_m, scale: float = BASIS_SCALE_M, degree: int = 3):
    """Design matrix [1, t, t^2, t^3], t = u/scale; (n, degree+1).

    Concrete heights (numpy) are computed in numpy with XLA's own operations (it divides by a
    constant as a product with the constant's reciprocal, and raises to an integer power by the
    products of ``_power``), so the matrix is the one JAX computes, to the bit (tested), without
    the half-dozen one-operation programs JAX would look up in its compilation cache for it in
    every process; traced heights (inside a jitted function) in JAX."""
    if isinstance(u_m, jax.core.Tracer):
        t = jnp.asarray(u_m) / scale
        return jnp.stack([t**j for j in range(degree + 1)], axis=-1)
    t = np.asarray(u_m, float) * (1.0 / scale)
    # device_put, not jnp.asarray: the latter compiles a copy program for every new shape
    return jax.device_put(np.stack([_power(t, j) for j in range(degree + 1)], axis=-1))


def _power(x: np.ndarray, n: int) -> np.ndarray:
    """x**n for an integer n >= 0 by the products JAX's ``integer_pow`` makes (square and
    multiply, in its order): numpy's ``x**3`` calls ``pow``, which can differ in the last bit."""
    if n == 0:
        return np.ones_like(x)
    acc = None
    while n > 0:
        if n & 1:
            acc = x if acc is None else acc * x
        n >>= 1
        if n > 0:
            x = x * x
    return acc


def least_squares(u_m, y) -> np.ndarray:
    """Ordinary least-squares cubic (the paper's regression): a linear problem, solved directly
    (numpy's SVD-based ``lstsq`` on the scaled basis [1, t, t^2, t^3], t = u / 0.05 m, whose columns
    are of order one, so the solve is well conditioned).

    Returns the paper-basis coefficients (4,).
    """
    t = np.asarray(u_m, float) / BASIS_SCALE_M
    X = t[:, None] ** np.arange(4)
    value = np.linalg.lstsq(X, np.asarray(y, float), rcond=None)[0]
    if not np.all(np.isfinite(value)):
        raise RuntimeError("least-squares cubic: the readings give no finite solution")
    return to_paper_basis(value)


# ----------------------------------------------------------------------------- the model


class CubicData(NamedTuple):
    """One test's arrays for the model functions (n readings)."""

    X: jnp.ndarray  # (n, 4) scaled basis [1, t, t^2, t^3]
    force: jnp.ndarray  # (n,) N
    piston: jnp.ndarray  # (n,) m
    ref_force: jnp.ndarray  # (n,) force level of the relative noise term, N
    prior_mean: jnp.ndarray  # (3,) prior centres of the natural noise logs
    weight: jnp.ndarray  # (n,) 1 = the reading informs the fit, 0 = held out (exact LOO refits)


class VolumeData(NamedTuple):
    """``CubicData`` of a test whose L readings come from a printed volume column (L = -V / S),
    with the sd of their rounding: ``MODEL``'s functions add it to sigma_L in quadrature. A type of
    its own, so that a piston test's program (``CubicData``) is exactly what it was."""

    X: jnp.ndarray
    force: jnp.ndarray
    piston: jnp.ndarray
    ref_force: jnp.ndarray
    prior_mean: jnp.ndarray
    weight: jnp.ndarray
    #: () sd (m) of the L readings' rounding: the volume's last printed digit, step/sqrt(12)/S
    #: (:func:`piston_rounding_sd`)
    piston_floor: jnp.ndarray


def natural_noise(theta, ref_mean):
    """Sampler coordinates -> (log sigma0, log r, log sigma_L); theta (..., 2) of a force-only
    test gives (log sigma0, log r).

    emcee moves in (psi, eta, log sigma_L): psi = log of the force noise at the mean force
    level s, eta = logit of the share phi = sigma0^2 / s^2 of the floor in it. The floor and
    the relative term trade off along a curved ridge in (log sigma0, log r); in (psi, eta)
    the well-measured total and the weakly identified split are separate directions, which
    cuts the autocorrelation time. The Jacobian of the map is constant (1/2), so the prior on
    (log sigma0, log r) carries over unchanged.
    """
    psi, eta = theta[..., 0], theta[..., 1]
    log_phi = -jnp.logaddexp(0.0, -eta)
    log_1mphi = -jnp.logaddexp(0.0, eta)
    force = jnp.stack([psi + 0.5 * log_phi, psi + 0.5 * log_1mphi - jnp.log(ref_mean)], axis=-1)
    return jnp.concatenate([force, theta[..., 2:]], axis=-1)


def piston_sd(log_sigma_L, floor=None):
    """The sd of an L reading: the sampled scatter sigma_L, and for a printed volume its rounding
    (``floor``; None for a piston read on the stand) in quadrature."""
    sigma_L = jnp.exp(log_sigma_L)
    return sigma_L if floor is None else jnp.hypot(floor, sigma_L)


def _floor(d):
    """The L rounding sd of a test's data: a ``VolumeData``'s, else None (a piston)."""
    return getattr(d, "piston_floor", None)


def noise_sds(theta, d: CubicData):
    """(force sd (n,), L sd, natural noise logs (3,)) of a test's readings at theta."""
    nat = natural_noise(theta, jnp.mean(d.ref_force))
    sigma0, rel, sigma_L = jnp.exp(nat[0]), jnp.exp(nat[1]), piston_sd(nat[2], _floor(d))
    sigma_f = jnp.sqrt(force_noise_var(sigma0, rel, d.ref_force))
    return sigma_f, sigma_L, nat


def conditional_posteriors(theta, d: CubicData):
    """The Gaussian posteriors of the force and the piston coefficients (scaled basis) given theta."""
    sigma_f, sigma_L, _ = noise_sds(theta, d)
    k = d.X.shape[1]
    pf = linear_posterior(d.X, d.force, sigma_f, jnp.full(k, FORCE_PRIOR_SD_N), d.weight)
    pl = linear_posterior(
        d.X, d.piston, jnp.full(d.piston.shape, sigma_L), jnp.full(k, PISTON_PRIOR_SD_M), d.weight
    )
    return pf, pl


def log_prob(theta, d: CubicData):
    """Log posterior of the noise parameters, coefficients integrated out; theta (3,)."""
    pf, pl = conditional_posteriors(theta, d)
    z = (noise_sds(theta, d)[2] - d.prior_mean) / NOISE_PRIOR_SD
    return -0.5 * jnp.sum(z**2) + pf.log_marginal + pl.log_marginal


def draw_linear(theta, key, d: CubicData):
    """An exact draw of the eight coefficients (force, piston; scaled basis) given theta."""
    pf, pl = conditional_posteriors(theta, d)
    kf, kl = jax.random.split(key)
    return jnp.concatenate([draw_exact(pf, kf), draw_exact(pl, kl)])


def pointwise(theta, beta, d: CubicData):
    sigma_f, sigma_L, _ = noise_sds(theta, d)
    return {
        "force_N": gaussian_loglik(d.force, d.X @ beta[:4], sigma_f),
        "piston_m": gaussian_loglik(d.piston, d.X @ beta[4:], sigma_L),
    }


def predict(theta, beta, key, d: CubicData):
    """A replicate of the test's readings: the mean curves plus the model's reading noise."""
    sigma_f, sigma_L, _ = noise_sds(theta, d)
    kf, kl = jax.random.split(key)
    n = d.force.shape[0]
    return {
        "force_N": d.X @ beta[:4] + sigma_f * jax.random.normal(kf, (n,)),
        "piston_m": d.X @ beta[4:] + sigma_L * jax.random.normal(kl, (n,)),
    }


def pointwise_loo(theta, d: CubicData):
    """log p(force_i, piston_i | noise, the test's other readings), coefficients integrated out, (n,)."""
    sigma_f, sigma_L, _ = noise_sds(theta, d)
    k = d.X.shape[1]
    return loo_given_noise(d.X, d.force, sigma_f, jnp.full(k, FORCE_PRIOR_SD_N)) + loo_given_noise(
        d.X, d.piston, jnp.full(d.piston.shape, sigma_L), jnp.full(k, PISTON_PRIOR_SD_M)
    )


def start(d: CubicData) -> np.ndarray:
    """The residual scales of the least-squares cubics: psi = log force sd, eta = 0, log sigma_L."""
    X, n = np.asarray(d.X), d.force.shape[0]

    def sd(y):
        res = y - X @ np.linalg.lstsq(X, y, rcond=None)[0]
        return np.sqrt(np.sum(res**2) / max(n - 4, 1))

    floor = float(_floor(d) if _floor(d) is not None else 0.0)
    return np.array(
        [
            np.log(sd(np.asarray(d.force)) + 1e-9),
            0.0,
            np.log(max(sd(np.asarray(d.piston)), floor) + 1e-12),
        ]
    )


@persistent_jit()
def _natural_noise_at_mean(theta, ref_force):
    """:func:`natural_noise` at a test's mean force level: one kept program for ``report``
    (``uq._inference.exported``), not the dozen one-operation ones of calling it eagerly."""
    return natural_noise(theta, jnp.mean(ref_force))


def report(theta, beta, d: CubicData) -> dict:
    noise = np.exp(np.asarray(_natural_noise_at_mean(np.asarray(theta, float), d.ref_force)))
    if _floor(d) is not None:  # a printed volume: the sd of an L reading holds its rounding
        noise[:, 2] = np.hypot(float(d.piston_floor), noise[:, 2])
    force = to_paper_basis(beta[:, :4])
    out = {n: force[:, i] for i, n in enumerate(FORCE_NAMES)}
    if noise.shape[1] == 3:  # a piston block (theta (N, 2): the force-only cubic's)
        piston = to_paper_basis(beta[:, 4:8])
        out |= {n: piston[:, i] for i, n in enumerate(PISTON_NAMES)}
    return out | {n: noise[:, i] for i, n in enumerate(NOISE_NAMES[: noise.shape[1]])}


def observed(d: CubicData) -> dict:
    return {"force_N": np.asarray(d.force), "piston_m": np.asarray(d.piston)}


MODEL = CollapsedModel.of(
    globals(), "per-pressure cubics (eqs. 8, 9)", SAMPLER_NAMES, hold_out=hold_out_by_weight
)


def piston_coordinate(test: PressureTest, piston_area_m2: float):
    """The piston coordinate L (m) a test's volume block fits, and where it comes from:
    ``(test.piston_m, "piston")``; for a test with a ``volume_*`` column instead (a catalogue's
    volume at its stated pressure) ``(-V / S, "volume")``, since dV = V(x_max) - V(x) =
    S [L(x) - L(x_max)] (eq. 10) makes L = const - V / S, the constant being the test's arbitrary
    piston reference (as in ``uq._models.diagnose``); ``(None, None)`` for a force-only test."""
    if test.piston_m is not None:
        return test.piston_m, "piston"
    if test.volume_m3 is not None:
        return -np.asarray(test.volume_m3, float) / piston_area_m2, "volume"
    return None, None


def piston_rounding_sd(test: PressureTest, piston_area_m2: float) -> float:
    """The sd (m) of the rounding of a test's L readings: a volume column printed to a step q (its
    last digit, ``PressureTest.volume_step_m3``) is known to within +-q/2, a uniform error of sd
    q / sqrt(12), which L = -V / S carries divided by S. 0 for a piston read on the stand (its
    readings are in ``sigma_L``'s prior) and for a volume of unknown step (a test made in code).

    The rounding is a known part of the L readings' noise, like the stand's error budget: without
    it, a printed volume that a cubic passes through exactly (six catalogue heights whose
    rounded values happen to lie on a cubic) has a likelihood that grows without bound as
    sigma_L -> 0, and the fit of that test is lost to float64 (issue 29)."""
    step = getattr(test, "volume_step_m3", None)
    if test.piston_m is not None or test.volume_m3 is None or not step:
        return 0.0
    return float(step) / math.sqrt(12.0) / piston_area_m2


def prepare(
    test: PressureTest,
    x0_m: float,
    noise: str,
    stand: StandDescription,
    piston_area_m2: float = PAPER_PISTON_AREA_M2,
):
    """``MODEL``'s arrays for one test (L from its piston or volume column, :func:`piston_coordinate`)
    and ``(lsq_force, lsq_piston, ref_force)``."""
    if noise not in ("budget", "constant"):
        raise ValueError(f"noise must be 'budget' or 'constant', got {noise!r}")
    piston, source = piston_coordinate(test, piston_area_m2)
    if piston is None:
        raise ValueError(
            f"the {test.label} test is force-only: fit it with FORCE_ONLY (force_data)"
        )
    u = test.height_m - x0_m
    lsq_f = least_squares(u, test.force_N)
    lsq_l = least_squares(u, piston)
    ref_force = noise_reference(lsq_f, u, noise)
    arrays = (test.force_N, piston, ref_force, noise_prior_mean(stand), np.ones(np.size(u)))
    # device_put, not jnp.asarray: the latter compiles a copy program for every new shape
    fields = (basis(u), *(jax.device_put(np.asarray(a, float)) for a in arrays))
    if source == "volume":
        data = VolumeData(*fields, jnp.asarray(piston_rounding_sd(test, piston_area_m2)))
    else:
        data = CubicData(*fields)
    return data, lsq_f, lsq_l, ref_force


# ----------------------------------------------------------------------------- shared by the pressure-holding variants


def stack_design(X):
    """The force and piston designs of one test stacked block-diagonally, (2n, 8)."""
    z = jnp.zeros_like(X)
    return jnp.concatenate(
        [jnp.concatenate([X, z], axis=1), jnp.concatenate([z, X], axis=1)], axis=0
    )


def coefficient_prior_sd(k: int = 4):
    """Prior sds of the force and piston coefficients side by side."""
    return jnp.concatenate([jnp.full(k, FORCE_PRIOR_SD_N), jnp.full(k, PISTON_PRIOR_SD_M)])


def log_prior_noise(nat, prior_mean):
    """The log prior of the natural noise logs (log sigma0, log r, log sigma_L)."""
    z = (nat - prior_mean) / NOISE_PRIOR_SD
    return -0.5 * jnp.sum(z**2)
