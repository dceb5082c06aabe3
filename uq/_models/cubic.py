"""Per-pressure Bayesian cubics: force (eq. 8) and piston coordinate (eq. 9) of one test.

Model of one test at overpressure p_u, u = x - x0 (m), t = u / h with h = 0.05 m:

    force_k  ~ N(sum_j alpha_j t_k^j,  sigma0^2 + (r * |Phat_k|)^2)     (eq. 8)
    piston_k ~ N(sum_j gamma_j t_k^j,  sigma_L^2)                        (eq. 9)

Phat_k is the least-squares force at point k (optimistix Levenberg-Marquardt), so the load
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
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import optimistix as optx

from uq._data.recordings import PressureTest, Recordings
from uq._data.reference import FORCE_NAMES, PAPER_PISTON_AREA_M2, PISTON_NAMES
from uq._data.stand_description import PAPER_STAND, StandDescription
from uq._inference.collapsed import CollapsedModel, Posterior, fit_collapsed
from uq._inference.convergence import CLI_ADVICE, LIBRARY_ADVICE
from uq._inference.float64 import jax, jnp
from uq._inference.latent import (
    ar1_precision,
    ar1_series,
    block_conditional_logpdf,
    common_offset,
    paired_ar1_posterior,
    paired_ar1_precision,
)
from uq._inference.linear import (
    LOG_2PI,
    draw_exact,
    gaussian_loglik,
    linear_posterior,
    loo_given_noise,
)
from uq._inference.sampler import Settings
from uq._inference.summary import estimate
from uq._models.residual_order import ALPHA as ORDER_ALPHA
from uq._models.residual_order import ORDER_UNKNOWN, lag_one_check, order_warnings
from uq._physics.cubic import cubic, cubic_slope
from uq._physics.quantities import BAR_PA, BASIS_SCALE_M, force_noise_var, to_paper_basis

MAX_DRAWS = 8000  # retained posterior samples per test after thinning
FORCE_PRIOR_SD_N = 1.0e5
PISTON_PRIOR_SD_M = 1.0
NOISE_NAMES = ("sigma0_N", "rel_force", "sigma_L_m")
SAMPLER_NAMES = ("log_noise_at_mean_force", "logit_floor_share", "log_sigma_L")
NOISE_PRIOR_SD = np.array([2.0, 1.0, 2.0])


def noise_prior_mean(stand: StandDescription = PAPER_STAND) -> np.ndarray:
    """Prior centres of (log sigma0 [N], log r, log sigma_L [m]); r's from the stand's load cell
    (a stand declaring a perfect load cell still gets a 0.01 % centre: log 0 has no prior)."""
    return np.log(np.array([10.0, max(stand.load_cell_rel_sd, 1e-4), 1.0e-3]))


NOISE_PRIOR_MEAN = noise_prior_mean(PAPER_STAND)


def basis(u_m, scale: float = BASIS_SCALE_M, degree: int = 3):
    """Design matrix [1, t, t^2, t^3], t = u/scale; (n, degree+1)."""
    t = jnp.asarray(u_m) / scale
    return jnp.stack([t**j for j in range(degree + 1)], axis=-1)


def _scaled_residuals(alpha, args):
    X, y, y_scale = args
    return (X @ alpha - y) / y_scale  # of order one, so the solver's tolerances mean something


@jax.jit
def _lm(X, y):
    y_scale = jnp.maximum(jnp.max(jnp.abs(y)), 1e-300)
    solver = optx.LevenbergMarquardt(rtol=1e-13, atol=1e-13)
    sol = optx.least_squares(
        _scaled_residuals,
        solver,
        jnp.zeros(X.shape[1]),
        args=(X, y, y_scale),
        max_steps=200,
        throw=False,
    )
    return sol.value, sol.result


def least_squares(u_m, y) -> np.ndarray:
    """Ordinary least-squares cubic (the paper's regression), via optimistix Levenberg-Marquardt.

    Returns the paper-basis coefficients (4,).
    """
    value, result = _lm(basis(u_m), jnp.asarray(y, dtype=float))
    if result != optx.RESULTS.successful:
        raise RuntimeError(f"least-squares cubic did not converge: {optx.RESULTS[result]}")
    return to_paper_basis(np.asarray(value))


# ----------------------------------------------------------------------------- the model


class CubicData(NamedTuple):
    """One test's arrays for the model functions (n readings)."""

    X: jnp.ndarray  # (n, 4) scaled basis [1, t, t^2, t^3]
    force: jnp.ndarray  # (n,) N
    piston: jnp.ndarray  # (n,) m
    ref_force: jnp.ndarray  # (n,) force level of the relative noise term, N
    prior_mean: jnp.ndarray  # (3,) prior centres of the natural noise logs
    weight: jnp.ndarray  # (n,) 1 = the reading informs the fit, 0 = held out (exact LOO refits)


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


def _noise(theta, d: CubicData):
    nat = natural_noise(theta, jnp.mean(d.ref_force))
    sigma0, rel, sigma_L = jnp.exp(nat[0]), jnp.exp(nat[1]), jnp.exp(nat[2])
    sigma_f = jnp.sqrt(force_noise_var(sigma0, rel, d.ref_force))
    return sigma_f, sigma_L, nat


def conditional_posteriors(theta, d: CubicData):
    """The Gaussian posteriors of the force and the piston coefficients (scaled basis) given theta."""
    sigma_f, sigma_L, _ = _noise(theta, d)
    k = d.X.shape[1]
    pf = linear_posterior(d.X, d.force, sigma_f, jnp.full(k, FORCE_PRIOR_SD_N), d.weight)
    pl = linear_posterior(
        d.X, d.piston, jnp.full(d.piston.shape, sigma_L), jnp.full(k, PISTON_PRIOR_SD_M), d.weight
    )
    return pf, pl


def log_prob(theta, d: CubicData):
    """Log posterior of the noise parameters, coefficients integrated out; theta (3,)."""
    pf, pl = conditional_posteriors(theta, d)
    z = (_noise(theta, d)[2] - d.prior_mean) / NOISE_PRIOR_SD
    return -0.5 * jnp.sum(z**2) + pf.log_marginal + pl.log_marginal


def draw_linear(theta, key, d: CubicData):
    """An exact draw of the eight coefficients (force, piston; scaled basis) given theta."""
    pf, pl = conditional_posteriors(theta, d)
    kf, kl = jax.random.split(key)
    return jnp.concatenate([draw_exact(pf, kf), draw_exact(pl, kl)])


def pointwise(theta, beta, d: CubicData):
    sigma_f, sigma_L, _ = _noise(theta, d)
    return {
        "force_N": gaussian_loglik(d.force, d.X @ beta[:4], sigma_f),
        "piston_m": gaussian_loglik(d.piston, d.X @ beta[4:], sigma_L),
    }


def predict(theta, beta, key, d: CubicData):
    """A replicate of the test's readings: the mean curves plus the model's reading noise."""
    sigma_f, sigma_L, _ = _noise(theta, d)
    kf, kl = jax.random.split(key)
    n = d.force.shape[0]
    return {
        "force_N": d.X @ beta[:4] + sigma_f * jax.random.normal(kf, (n,)),
        "piston_m": d.X @ beta[4:] + sigma_L * jax.random.normal(kl, (n,)),
    }


def pointwise_loo(theta, d: CubicData):
    """log p(force_i, piston_i | noise, the test's other readings), coefficients integrated out, (n,)."""
    sigma_f, sigma_L, _ = _noise(theta, d)
    k = d.X.shape[1]
    return loo_given_noise(d.X, d.force, sigma_f, jnp.full(k, FORCE_PRIOR_SD_N)) + loo_given_noise(
        d.X, d.piston, jnp.full(d.piston.shape, sigma_L), jnp.full(k, PISTON_PRIOR_SD_M)
    )


def hold_out(d: CubicData, held) -> CubicData:
    return d._replace(weight=jnp.asarray(np.where(np.asarray(held, bool), 0.0, 1.0)))


def start(d: CubicData) -> np.ndarray:
    """The residual scales of the least-squares cubics: psi = log force sd, eta = 0, log sigma_L."""
    X, n = np.asarray(d.X), d.force.shape[0]

    def sd(y):
        res = y - X @ np.linalg.lstsq(X, y, rcond=None)[0]
        return np.sqrt(np.sum(res**2) / max(n - 4, 1))

    return np.array(
        [np.log(sd(np.asarray(d.force)) + 1e-9), 0.0, np.log(sd(np.asarray(d.piston)) + 1e-12)]
    )


def report(theta, beta, d: CubicData) -> dict:
    noise = np.exp(np.asarray(natural_noise(jnp.asarray(theta), jnp.mean(d.ref_force))))
    force, piston = to_paper_basis(beta[:, :4]), to_paper_basis(beta[:, 4:])
    out = {n: force[:, i] for i, n in enumerate(FORCE_NAMES)}
    out |= {n: piston[:, i] for i, n in enumerate(PISTON_NAMES)}
    return out | {n: noise[:, i] for i, n in enumerate(NOISE_NAMES)}


def observed(d: CubicData) -> dict:
    return {"force_N": np.asarray(d.force), "piston_m": np.asarray(d.piston)}


MODEL = CollapsedModel(
    name="per-pressure cubics (eqs. 8, 9)",
    theta_names=SAMPLER_NAMES,
    log_prob=log_prob,
    draw_linear=draw_linear,
    pointwise=pointwise,
    start=start,
    report=report,
    predict=predict,
    observed=observed,
    pointwise_loo=pointwise_loo,
    hold_out=hold_out,
)


# ----------------------------------------------------------------------------- force only
# A test without piston readings or volume (a force-only stand): the force block of ``MODEL``
# alone. Given the noise, MODEL's force and piston blocks are independent and the piston's noise
# sigma_L has its own prior, so the force coefficients' and (sigma0, r)'s posterior here is the
# same distribution as MODEL's on the same forces (tests/models/test_cubic_force.py checks it).
# With measured pressures the readings are corrected as in ``MEASURED``'s force rows,
# force_i + lever_i delta = P(x_i) + lever_i dp_hat_i + e_F,i, the sensor's common offset delta one
# extra coefficient (prior: ``common_offset``); the stand's gas volume moves only the piston, so it
# is not a parameter here.

FORCE_NOISE_NAMES = NOISE_NAMES[:2]
#: Why a force-only test has no piston block (``uq fit --json``'s "omitted", the report's line).
NO_VOLUME = (
    "force-only test: no piston_* or volume_* column, so no piston coordinate, volume increment "
    "or volume-derived effective area"
)
#: How a test with a volume column gets its piston block (``uq fit --json``'s "piston_from").
VOLUME_AS_PISTON = (
    "from the volume_* column: L = -V / S (eq. 10, S the stand's piston area), the test's piston "
    "reference arbitrary (a_L has no meaning of its own)"
)
FORCE_SAMPLER_NAMES = SAMPLER_NAMES[:2]


class ForceData(NamedTuple):
    """One test's arrays for the force-only model (n readings, k = 4 or 5 coefficients)."""

    X: jnp.ndarray  # (n, k) scaled basis [1, t, t^2, t^3] (and -lever: the common offset)
    force: jnp.ndarray  # (n,) as read, N
    y: jnp.ndarray  # (n,) what the linear model fits: force less lever * dp (measured pressure)
    ref_force: jnp.ndarray  # (n,) force level of the relative noise term, N
    prior_mean: jnp.ndarray  # (2,) prior centres of log sigma0 and log r
    weight: jnp.ndarray  # (n,) 1 = fitted, 0 = held out
    prior_sd: jnp.ndarray  # (k,) coefficients' prior sds
    offset_mean: jnp.ndarray  # () prior mean of the common offset already taken out (Pa), or 0


def _force_noise(theta, d: ForceData):
    nat = natural_noise(theta, jnp.mean(d.ref_force))
    return jnp.sqrt(force_noise_var(jnp.exp(nat[0]), jnp.exp(nat[1]), d.ref_force)), nat


def _force_post(theta, d: ForceData):
    sigma_f, nat = _force_noise(theta, d)
    return linear_posterior(d.X, d.y, sigma_f, d.prior_sd, d.weight), nat


def force_log_prob(theta, d: ForceData):
    """Log posterior of (psi, eta), coefficients integrated out; theta (2,)."""
    post, nat = _force_post(theta, d)
    z = (nat - d.prior_mean) / NOISE_PRIOR_SD[:2]
    return -0.5 * jnp.sum(z**2) + post.log_marginal


def force_draw(theta, key, d: ForceData):
    return draw_exact(_force_post(theta, d)[0], key)


def force_pointwise(theta, beta, d: ForceData):
    return {"force_N": gaussian_loglik(d.y, d.X @ beta, _force_noise(theta, d)[0])}


def force_predict(theta, beta, key, d: ForceData):
    """A replicate of the forces as read (at the measured pressures)."""
    sigma_f = _force_noise(theta, d)[0]
    n = d.force.shape[0]
    return {"force_N": d.X @ beta + (d.force - d.y) + sigma_f * jax.random.normal(key, (n,))}


def force_pointwise_loo(theta, d: ForceData):
    return loo_given_noise(d.X, d.y, _force_noise(theta, d)[0], d.prior_sd)


def force_start(d: ForceData) -> np.ndarray:
    X, y = np.asarray(d.X), np.asarray(d.y)
    res = y - X @ np.linalg.lstsq(X, y, rcond=None)[0]
    sd = np.sqrt(np.sum(res**2) / max(y.size - X.shape[1], 1))
    return np.array([np.log(sd + 1e-9), 0.0])


def force_report(theta, beta, d: ForceData) -> dict:
    noise = np.exp(np.asarray(natural_noise(jnp.asarray(theta), jnp.mean(d.ref_force))))
    force = to_paper_basis(beta[:, :4])
    out = {n: force[:, i] for i, n in enumerate(FORCE_NAMES)}
    out |= {n: noise[:, i] for i, n in enumerate(FORCE_NOISE_NAMES)}
    if beta.shape[1] > 4:
        out["pressure_offset_Pa"] = float(d.offset_mean) + beta[:, 4]
    return out


def force_observed(d: ForceData) -> dict:
    return {"force_N": np.asarray(d.force)}


FORCE_ONLY = CollapsedModel(
    name="per-pressure cubic of the force (eq. 8), force-only test",
    theta_names=FORCE_SAMPLER_NAMES,
    log_prob=force_log_prob,
    draw_linear=force_draw,
    pointwise=force_pointwise,
    start=force_start,
    report=force_report,
    predict=force_predict,
    observed=force_observed,
    pointwise_loo=force_pointwise_loo,
    hold_out=hold_out,
)


def force_data(
    test: PressureTest, x0_m: float, noise: str, stand: StandDescription, measured: bool = False
):
    """The force-only model's arrays for one test, ``(data, lsq_force, None, ref_force)`` as
    ``_prepare``; ``measured``: the readings' measured pressures are a covariate (``MEASURED``'s
    force rows, with the sensor's common offset as a fifth coefficient)."""
    if noise not in ("budget", "constant"):
        raise ValueError(f"noise must be 'budget' or 'constant', got {noise!r}")
    u = test.height_m - x0_m
    X = basis(u)
    y = np.asarray(test.force_N, float)
    prior_sd = np.full(4, FORCE_PRIOR_SD_N)
    offset_mean = 0.0
    if measured:
        p_pa = test.pressure_bar * BAR_PA
        dp_hat = (np.asarray(test.measured_pressure_bar, float) - test.pressure_bar) * BAR_PA
        offset_mean, offset_sd = common_offset(dp_hat, p_pa, ordered=test.step is not None)
        lever = cubic(least_squares(u, test.force_N), u) / p_pa
        y = y - lever * (dp_hat - offset_mean)
        X = jnp.concatenate([X, -jnp.asarray(lever)[:, None]], axis=1)
        prior_sd = np.append(prior_sd, offset_sd)
    lsq_f = least_squares(u, y)
    ref = noise_reference(lsq_f, u, noise)
    data = ForceData(
        X,
        jnp.asarray(test.force_N),
        jnp.asarray(y),
        jnp.asarray(ref),
        jnp.asarray(noise_prior_mean(stand)[:2]),
        jnp.ones(u.size),
        jnp.asarray(prior_sd),
        jnp.asarray(offset_mean),
    )
    return data, lsq_f, None, ref


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


# ----------------------------------------------------------------------------- results


def noise_reference(lsq_force, u, noise: str) -> np.ndarray:
    """Force level of the relative noise term at u: the least-squares curve's |P| ("budget"), or
    its mean over these points ("constant")."""
    ref = np.abs(cubic(lsq_force, u))
    return np.full_like(ref, ref.mean()) if noise == "constant" else ref


@dataclass(eq=False, frozen=True, repr=False)
class PressureFit:
    """Posterior of one test: the driver's :class:`~uq._inference.collapsed.Posterior` and what the
    test's quantities need. Draw arrays are (chains, draws, ...) in the paper's basis, SI.

    A force-only test (no piston_* and no volume_* column) has no volume block: ``piston``,
    ``lsq_piston`` and ``piston_m`` are None, ``noise`` holds sigma0_N and rel_force only, and
    ``has_piston`` is False. A test with a volume column fits L = -V / S (``piston_source``
    "volume", :func:`piston_coordinate`), so every volume quantity works on it unchanged."""

    test: PressureTest
    x0_m: float
    lsq_force: np.ndarray  # (4,)
    lsq_piston: np.ndarray | None  # (4,), None for a force-only test
    posterior: Posterior
    ref_force_N: np.ndarray  # (n,) force level of the relative noise term at each point
    noise_model: str  # "budget" or "constant" (fit_test's noise)
    force: np.ndarray  # (C, D, 4) a_P..d_P
    piston: np.ndarray | None  # (C, D, 4) a_L..d_L, None for a force-only test
    noise: np.ndarray  # (C, D, 3) sigma0_N, rel_force, sigma_L_m (C, D, 2 without the piston)
    #: the recording-order check of the residuals (uq._models.residual_order): force, piston,
    #: alpha; for a test in unknown order {"alpha", "skipped": why}
    order_check: dict
    #: the pressure-holding error: "plain" (in the noise), "measured" (measured pressure as a
    #: covariate) or "ar1" (AR(1) in recording order); the pressure-holding section below
    variant: str = "plain"
    #: where the volume block's L readings come from: "piston" (piston_* column), "volume"
    #: (L = -V / S from a volume_* column) or None (force-only test)
    piston_source: str | None = "piston"
    #: the L readings (m) the volume block fits, as read (None for a force-only test)
    piston_m: np.ndarray | None = None

    @classmethod
    def of(
        cls,
        test,
        x0_m,
        lsq_force,
        lsq_piston,
        posterior: Posterior,
        ref_force_N,
        noise_model,
        variant: str = "plain",
    ):
        post = posterior.reported
        has_piston = lsq_piston is not None

        def stack(names):
            return np.stack([np.asarray(post[n]) for n in names], axis=-1)

        force = stack(FORCE_NAMES)
        piston = stack(PISTON_NAMES) if has_piston else None
        noise = stack(NOISE_NAMES if has_piston else FORCE_NOISE_NAMES)
        piston_m = np.asarray(posterior.data.piston, float) if has_piston else None
        source = None
        if has_piston:
            source = "piston" if test.piston_m is not None else "volume"
        blocks = ("force", "piston") if has_piston else ("force",)
        if test.step is None:
            check = {"skipped": ORDER_UNKNOWN}
        else:
            check = cls._order_check(
                test, x0_m, posterior, ref_force_N, variant, force, piston, noise, piston_m, blocks
            )
        return cls(
            test,
            x0_m,
            lsq_force,
            lsq_piston,
            posterior,
            ref_force_N,
            noise_model,
            force,
            piston,
            noise,
            check | {"alpha": ORDER_ALPHA},
            variant,
            source,
            piston_m,
        )

    @staticmethod
    def _order_check(
        test, x0_m, posterior, ref_force_N, variant, force, piston, noise, piston_m, blocks
    ) -> dict:
        """The recording-order check of each block's residuals under the fitted model."""
        u = test.height_m - x0_m
        mean_noise = noise.reshape(-1, noise.shape[-1]).mean(axis=0)
        design = np.asarray(basis(u))
        readings = {"force": test.force_N, "piston": piston_m}
        beta_mean = posterior.beta.reshape(-1, posterior.beta.shape[-1]).mean(0)
        if variant == "measured" and "piston" in blocks:  # corrected by the measured pressure
            readings = measured_corrected(posterior.data, beta_mean)
        elif variant == "measured":  # force only: the offset is the fifth coefficient
            d = posterior.data
            readings = {"force": np.asarray(d.y) - np.asarray(d.X)[:, 4] * beta_mean[4]}
        residuals = {"force": readings["force"] - cubic(force.reshape(-1, 4).mean(0), u)}
        sd = {"force": np.sqrt(force_noise_var(mean_noise[0], mean_noise[1], ref_force_N))}
        if "piston" in blocks:
            residuals["piston"] = readings["piston"] - cubic(piston.reshape(-1, 4).mean(0), u)
            sd["piston"] = np.full(u.shape, mean_noise[2])
        designs = {b: design for b in blocks}
        if variant == "ar1":  # check what the AR(1) model leaves: Prais-Winsten innovations
            theta_mean = posterior.theta.reshape(-1, posterior.theta.shape[-1]).mean(0)
            rho, sd = ar1_order_whitening(posterior.data, theta_mean)
            for b in blocks:
                residuals[b] = prewhiten(residuals[b] / sd[b], rho[b])
                designs[b] = np.stack(
                    [prewhiten(c, rho[b]) for c in (design / sd[b][:, None]).T], axis=1
                )
                sd[b] = np.ones(u.shape)
        return {b: lag_one_check(residuals[b], sd[b], designs[b]) for b in blocks}

    @property
    def has_piston(self) -> bool:
        """The test has a volume block (piston_* or volume_* column); False: force only."""
        return self.piston is not None

    @property
    def pressure_bar(self) -> float:
        return self.test.pressure_bar

    @property
    def idata(self):
        return self.posterior.idata

    @property
    def convergence(self):
        return self.posterior.convergence

    @property
    def chains(self):
        return self.posterior.chains

    def flat(self, name: str) -> np.ndarray:
        arr = getattr(self, name)
        return arr.reshape(-1, *arr.shape[2:])

    def ref_force(self) -> np.ndarray:
        return self.ref_force_N

    def ref_force_at(self, height_m) -> np.ndarray:
        """The force level of the relative noise term at any heights, by the rule the fit used at
        the data: the report's predictive bands use it on their grid."""
        u = np.asarray(height_m, float) - self.x0_m
        if self.noise_model == "constant":
            return np.full(u.shape, float(np.mean(self.ref_force_N)))
        return noise_reference(self.lsq_force, u, self.noise_model)

    def mean_residuals(self, block: str) -> np.ndarray:
        """Readings minus the posterior-mean curve of ``block`` ("force" N or "piston" m), (n,)."""
        if block == "piston" and not self.has_piston:
            raise ValueError(f"the {self.test.label} test is force-only: it has no piston block")
        y = self.test.force_N if block == "force" else self.piston_m
        return y - cubic(self.flat(block).mean(0), self.test.height_m - self.x0_m)

    def deviation_measures(self) -> tuple[float, float]:
        """The paper's s_P (N) and eps_P (%) of the posterior-mean curve (section 5)."""
        res = self.mean_residuals("force")
        return float(np.sqrt(np.mean(res**2))), float(
            100.0 * np.mean(np.abs(res / self.test.force_N))
        )

    def model_warnings(self) -> list[str]:
        """The recording-order check's warnings (none when the residuals look independent)."""
        return order_warnings(self.order_check)

    def summary(self):
        """ArviZ's summary table (pandas DataFrame) of the coefficients and noise parameters."""
        return self.posterior.summary()

    def to_json(self, advice: str = CLI_ADVICE) -> dict:
        """One entry of ``tests`` in ``uq fit --json`` (docs/formats.md). A force-only test has no
        "piston" blocks (estimates, least squares, covariance) and says why under "omitted"; a
        test whose L comes from a volume column says so under "piston_from"."""
        conv = self.convergence.to_json(advice, variables=False)
        var = self.convergence.variables
        s_P, eps_P = self.deviation_measures()
        noise_names = NOISE_NAMES if self.has_piston else FORCE_NOISE_NAMES

        def block(draws, names):
            return {
                n: estimate(draws[..., i])
                | {k: var[n][k] for k in ("r_hat", "ess_bulk", "ess_tail", "mcse_mean")}
                for i, n in enumerate(names)
            }

        out = {
            "pressure_bar": self.pressure_bar,
            "n_points": self.test.n_points,
            "force": block(self.force, FORCE_NAMES),
        }
        if self.has_piston:
            out["piston"] = block(self.piston, PISTON_NAMES)
        out |= {
            "s_P_N": s_P,
            "eps_P_pct": eps_P,
            "noise": {
                n: estimate(self.noise[..., i])
                | {"r_hat": var[n]["r_hat"], "ess_bulk": var[n]["ess_bulk"]}
                for i, n in enumerate(noise_names)
            },
            "least_squares": {
                "force": dict(zip(FORCE_NAMES, self.lsq_force.tolist(), strict=True))
            },
            "covariance": {"force": np.cov(self.flat("force"), rowvar=False)},
            "convergence": conv,
            "residual_order": self.order_check,
        }
        if self.has_piston:
            out["least_squares"]["piston"] = dict(
                zip(PISTON_NAMES, self.lsq_piston.tolist(), strict=True)
            )
            out["covariance"]["piston"] = np.cov(self.flat("piston"), rowvar=False)
        else:
            out["omitted"] = {"piston": NO_VOLUME}
        if self.piston_source == "volume":
            out["piston_from"] = VOLUME_AS_PISTON
        return out | self._pressure_holding_json(var)

    def _pressure_holding_json(self, var) -> dict:
        """How the model treated the pressure-holding error, and its extra parameters."""

        if self.variant == "plain":
            return {}
        names = AR_EXTRA_NAMES if self.variant == "ar1" else MEASURED_EXTRA_NAMES
        post = self.posterior.reported
        block = {"model": self.variant}
        for n in (n for n in names if n in post):  # a force-only test has no gas volume
            block[n] = estimate(np.asarray(post[n])) | {
                k: var[n][k] for k in ("r_hat", "ess_bulk") if k in var.get(n, {})
            }
        return {"pressure_holding": block}

    def __repr__(self) -> str:
        state = "converged" if self.convergence.converged else "NOT converged"
        return (
            f"PressureFit({self.pressure_bar:g} bar, {self.test.n_points} readings, "
            f"{self.flat('force').shape[0]} draws, {state})"
        )


def _prepare(
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
    piston, _ = piston_coordinate(test, piston_area_m2)
    if piston is None:
        raise ValueError(
            f"the {test.label} test is force-only: fit it with FORCE_ONLY (force_data)"
        )
    u = test.height_m - x0_m
    lsq_f = least_squares(u, test.force_N)
    lsq_l = least_squares(u, piston)
    ref_force = noise_reference(lsq_f, u, noise)
    data = CubicData(
        basis(u),
        jnp.asarray(test.force_N),
        jnp.asarray(piston),
        jnp.asarray(ref_force),
        jnp.asarray(noise_prior_mean(stand)),
        jnp.ones(np.size(test.force_N)),
    )
    return data, lsq_f, lsq_l, ref_force


def test_seeds(seed: int, n: int) -> list[int]:
    """Independent per-test seeds derived from one campaign seed."""
    return [int(s.generate_state(1)[0]) for s in np.random.SeedSequence(seed).spawn(n)]


PRESSURE_MODELS = ("set", "measured")
AR1_CHOICES = ("off", "on", "auto")


def fit_tests(
    tests,
    x0_m: float,
    *,
    seed: int,
    settings: Settings = Settings(),
    noise: str = "budget",
    stand: StandDescription = PAPER_STAND,
    desc: str | None = None,
    pressure: str = "set",
    ar1: str = "off",
    piston_area_m2: float = PAPER_PISTON_AREA_M2,
) -> list[PressureFit]:
    """Fit several tests at once: one emcee run samples every test's ensembles in lockstep
    (``fit_collapsed`` with a list of data), each test with its own independent ensembles,
    burn-in and convergence verdict. The exact coefficient draws of test i use the i-th seed
    derived from ``seed`` (:func:`test_seeds`).

    ``noise="budget"`` (default): force sd grows with the force (load cell) over a floor.
    ``noise="constant"``: one force sd for the whole test, the common but wrong choice kept
    for the calibration suite's misspecification study (the total is still sampled; its split
    into floor and relative parts is then unidentified and follows the prior).

    The pressure-holding error (the pressure-holding section below): ``pressure="measured"`` uses each
    reading's measured pressure (``PressureTest.measured_pressure_bar``) as a covariate; otherwise
    ``ar1`` says whether the holding errors are an AR(1) series in recording order: "off" (in the
    independent noise, the default), "on" (every test with a recording order), "auto" (the tests
    whose residuals the recording-order check flags under the independent model are refitted
    with it). Tests without a recording order keep the plain model for AR(1). Force-only tests (no
    piston_* and no volume_* column) are fitted by ``FORCE_ONLY`` (the force block; with measured
    pressures as its covariate under ``pressure="measured"``); a test with a volume column fits
    L = -V / S (:func:`piston_coordinate`) with the plain model (its volume was not read off the
    stand's piston, so the pressure-holding terms do not apply to it). ``piston_area_m2``: the
    stand's S (Boyle's law moves the piston by dV / S; a volume column's L = -V / S).
    """

    if pressure not in PRESSURE_MODELS:
        raise ValueError(f"pressure must be one of {PRESSURE_MODELS}, got {pressure!r}")
    if ar1 not in AR1_CHOICES:
        raise ValueError(f"ar1 must be one of {AR1_CHOICES}, got {ar1!r}")
    tests = list(tests)
    seeds = test_seeds(seed, len(tests))

    def variant_of(t) -> str:
        if t.piston_m is None and t.volume_m3 is None:  # force only
            return "force-measured" if pressure == "measured" else "force"
        if t.piston_m is None:  # L from a volume column: not read off the stand's piston
            return "plain"
        if pressure == "measured":
            return "measured"
        if ar1 == "on" and t.step is not None:
            return "ar1"
        return "plain"

    def prepare(t, variant):
        if variant == "measured":
            return measured_data(t, x0_m, noise, stand, piston_area_m2)
        if variant == "ar1":
            return ar1_data(t, x0_m, noise, stand, piston_area_m2)
        if variant in ("force", "force-measured"):
            return force_data(t, x0_m, noise, stand, measured=variant == "force-measured")
        return _prepare(t, x0_m, noise, stand, piston_area_m2)

    models = {
        "plain": MODEL,
        "measured": MEASURED,
        "ar1": AR1,
        "force": FORCE_ONLY,
        "force-measured": FORCE_ONLY,
    }
    #: the pressure-holding treatment PressureFit.variant records for each model key
    holding = {"force": "plain", "force-measured": "measured"}
    variants = [variant_of(t) for t in tests]

    def run(indices, variant, label):
        prepared = [prepare(tests[i], variant) for i in indices]
        posts = fit_collapsed(
            models[variant],
            [p[0] for p in prepared],
            seed=seed,
            settings=settings,
            max_draws=MAX_DRAWS,
            seeds=[seeds[i] for i in indices],
            desc=label,
        )
        return {
            i: PressureFit.of(
                tests[i], x0_m, lsq_f, lsq_l, post, ref, noise, holding.get(variant, variant)
            )
            for i, (_, lsq_f, lsq_l, ref), post in zip(indices, prepared, posts, strict=True)
        }

    fits: dict[int, PressureFit] = {}
    for variant in models:
        idx = [i for i, v in enumerate(variants) if v == variant]
        if idx:
            fits |= run(
                idx, variant, desc if variant == "plain" else f"{desc or 'sampling'} ({variant})"
            )
    if ar1 == "auto" and pressure != "measured":
        flagged = [
            i
            for i, f in fits.items()
            if f.variant == "plain"
            and tests[i].step is not None
            and tests[i].piston_m is not None
            and f.model_warnings()
        ]
        if flagged:
            fits |= run(flagged, "ar1", f"{desc or 'sampling'} (AR(1) where flagged)")
    return [fits[i] for i in range(len(tests))]


def fit_test(
    test: PressureTest,
    x0_m: float,
    *,
    seed: int,
    settings: Settings = Settings(),
    noise: str = "budget",
    stand: StandDescription = PAPER_STAND,
    pressure: str = "set",
    ar1: str = "off",
) -> PressureFit:
    """One test's posterior (:func:`fit_tests` of one test)."""
    return fit_tests(
        [test],
        x0_m,
        seed=seed,
        settings=settings,
        noise=noise,
        stand=stand,
        pressure=pressure,
        ar1=ar1,
    )[0]


@dataclass(eq=False, frozen=True, repr=False)
class CampaignFit:
    """The per-pressure cubics of every test of a campaign (:func:`fit_campaign`)."""

    recordings: Recordings
    tests: list[PressureFit]
    seed: int
    stand: StandDescription = PAPER_STAND

    @property
    def converged(self) -> bool:
        return all(t.convergence.converged for t in self.tests)

    def at(self, pressure_bar: float) -> PressureFit:
        for t in self.tests:
            if abs(t.pressure_bar - pressure_bar) < 1e-9:
                return t
        raise KeyError(pressure_bar)

    def summary(self):
        """One row per test and coefficient: ArviZ's summary statistics (pandas DataFrame)."""
        import pandas as pd

        return pd.concat(
            {f"{t.pressure_bar:g} bar": t.summary() for t in self.tests}, names=["test", "quantity"]
        )

    def warnings(self, advice: str = LIBRARY_ADVICE) -> list[str]:
        """The sampler's failed rules of every test, each prefixed with its pressure."""
        return [
            f"{t.pressure_bar:g} bar: {w}"
            for t in self.tests
            for w in t.convergence.messages(advice)
        ]

    def model_warnings(self) -> list[str]:
        """The recording-order warnings of every test, each prefixed with its pressure."""
        return [f"{t.pressure_bar:g} bar: {w}" for t in self.tests for w in t.model_warnings()]

    def to_json(self, advice: str = CLI_ADVICE) -> dict:
        """What ``uq fit --json`` writes (docs/formats.md): per test the coefficients' and noise's
        posterior summaries, the coefficient blocks' covariance, least squares and diagnostics."""
        rec = self.recordings
        return {
            "x0_m": rec.x0_m,
            "piston_area_m2": rec.piston_area_m2,
            "source": os.path.basename(rec.path),
            "seed": self.seed,
            "converged": self.converged,
            "warnings": self.warnings(advice),
            "model_warnings": self.model_warnings(),
            "tests": [t.to_json(advice) for t in self.tests],
        }

    def save(self, out_dir) -> list:
        """One NetCDF file per test (ArviZ InferenceData with posterior, log_likelihood,
        posterior_predictive and observed_data groups), made in memory and written atomically (a
        full disk is a one-line error, not a crash inside HDF5: ``uq._io.files.netcdf_bytes``);
        returns the paths."""
        from pathlib import Path

        from uq._io.files import write_netcdf_atomic

        out = Path(out_dir)
        return [
            write_netcdf_atomic(out / f"posterior_{t.pressure_bar:g}bar.nc", t.idata)
            for t in self.tests
        ]

    def __repr__(self) -> str:
        state = "converged" if self.converged else "NOT converged"
        return (
            f"CampaignFit({len(self.tests)} tests at "
            f"{', '.join(f'{t.pressure_bar:g}' for t in self.tests)} bar, "
            f"{self.recordings.n_points} readings, seed {self.seed}, {state})"
        )


def fit_campaign(
    recordings: Recordings,
    *,
    seed: int = 0,
    settings: Settings = Settings(),
    stand: StandDescription = PAPER_STAND,
    pressure_ar1: str = "off",
) -> CampaignFit:
    """Fit every test of a campaign: one emcee run samples all tests in lockstep, each with its
    own ensembles and convergence checks (:func:`fit_tests`). ``stand``: the stand the recordings
    were taken on (its load cell centres the prior of the relative force noise). ``uq fit`` is
    this plus :meth:`CampaignFit.to_json`. Recordings with measured pressures
    (``Recordings.pressure_measured``) use them as a covariate of the pressure-holding error;
    otherwise ``pressure_ar1`` ("off", "on", "auto") models the holding errors as an AR(1) series
    in recording order (:func:`fit_tests`).

    >>> import uq
    >>> rec = uq.simulate("n50", seed=1, layout=uq.Layout(pressures_bar=(1.0, 5.0), step_m=0.01))
    >>> fit = uq.fit_campaign(rec, seed=1, settings=uq.Settings(max_steps=200))
    >>> [t.pressure_bar for t in fit.tests], fit.at(5.0).flat("force").shape[1]
    ([1.0, 5.0], 4)
    >>> a_P = fit.at(5.0).flat("force")[:, 0]   # posterior draws of a_P, the force at x0 (N)
    >>> bool(12e3 < a_P.mean() < 14e3)
    True
    """
    fits = fit_tests(
        recordings.tests,
        recordings.x0_m,
        seed=seed,
        settings=settings,
        stand=stand,
        desc="sampling all tests",
        pressure="measured" if getattr(recordings, "pressure_measured", False) else "set",
        ar1=pressure_ar1,
        piston_area_m2=getattr(recordings, "piston_area_m2", PAPER_PISTON_AREA_M2),
    )
    return CampaignFit(recordings, fits, seed, stand)


# ----------------------------------------------------------------------------- the pressure-holding error
# The per-pressure cubics with the pressure-holding error modelled, not lumped into the noise.
#
# The stand holds each reading at p_u + dp_i (paper section 3.2). The error moves the force by
# dp_i dP/dp_u and, by Boyle's law (eq. 4: the gas volume V keeps its value), leaves the piston
# short by V dp_i / (p_abs S). The plain model (``uq._models.cubic``) folds both into independent
# noise: the force floor sigma0 and the piston's sigma_L. Two better models, both linear-Gaussian
# in the eight coefficients given their sampled parameters (so they run through the same driver,
# ``fit_collapsed``, with exact coefficient draws):
#
# **Measured pressure** (``MEASURED``; recordings with ``set_pressure_bar`` and each reading's
# ``pressure_bar``). The covariate dp_hat_i = measured - set is the holding error plus the sensor's
# error: a gain error g (the paper's sensor: 0.1 %) read once per test, so dp_hat_i = dp_i + delta
# with delta = p_u g common to the test (the sensor's 1 Pa resolution is negligible). Readings are
# corrected,
#
#     force_i + lever_i delta = P(x_i) + e_F,i,        lever_i = Phat_i / p_u   (plug-in dP/dp_u)
#     piston_i - V delta / (p_abs S) = L(x_i) - (V - V_s) dp_i / (p_abs S) + e_L,i
#     with dp_i = dp_hat_i - delta,
#
# where Phat is the test's least-squares force (eq. 1's F_eff as the lever, the one the models
# already use; a casing's dP/dp_u is larger, by 13 % at x0 for Table 1, which leaves a residual of
# 13 % of a pressure error that is itself under 0.1 % of p_u). The unknowns delta and the gas volume
# V (its departure from the stand's V_s, prior sd 50 %) are two extra coefficients: the model stays
# linear. delta's prior is its posterior from the measured series alone: the gain's N(0, (p_u
# 0.1 %)^2) combined with the series' mean (dp_hat = dp + delta, dp a stationary AR(1) series with
# the sample variance and lag-one correlation of dp_hat, which delta does not change), so the
# unknown common part is as small as the sensor and the series allow. e_F ~ N(0, sigma0^2 +
# (r Phat)^2), e_L ~ N(0, sigma_L^2) as in the plain model, but now without the pressure term.
#
# **AR(1) pressure-holding errors** (``AR1``; pressure not recorded, recording order known). The
# holding errors are latent: dp = k_p s_p z with z a stationary AR(1) series in recording order
# (unit variance, lag-one correlation rho, a slowly corrected screw drive), s_p the stand's holding
# sd. One dp_i moves both readings of row i, so per test the 2n readings have covariance
#
#     Sigma = diag(sigma_F^2, sigma_L^2) + u u^T o R(rho),    u = [lever k_p s_p ; -V/(p_abs S) k_p s_p]
#
# (R_ij = rho^|i-j|), i.e. Sigma = D + U R U^T with U = [diag(b); diag(c)]. ``uq._inference.latent``
# integrates the latent out exactly by whitening (the Kalman filter of the series, one O(n) scan:
# W with W^T W = Sigma^-1 applied to readings and design), so the coefficients stay conjugate.
# Sampled: (psi, eta, log sigma_L) as in the plain model, log k_p ~ N(0, 0.5^2), log V ~
# N(log V_s, 0.5^2), and atanh(rho) with rho uniform on (-1, 1). sigma0 and sigma_L are then what
# is left besides the pressure holding (displacement, calipers), and sigma_L's prior is centred on
# that remainder of the stand's budget (``ar1_noise_prior_mean``), not on the plain model's 1 mm.

#: The pressure sensor the measured model assumes (the paper's, section 3.2: 0.1 % accuracy, read
#: as a gain error common to a test; its 1 Pa resolution is negligible). The virtual stand's
#: ``--record-pressure`` sensor is the same (uq._stand.shapes).

VOLUME_PRIOR_REL_SD = 0.5  # the measured model's V - V_s ~ N(0, (0.5 V_s)^2)
LOG_KP_PRIOR_SD = 0.5
LOG_V_PRIOR_SD = 0.5
AR_SAMPLER_NAMES = SAMPLER_NAMES + ("log_k_p", "log_V_gas", "atanh_rho")
AR_EXTRA_NAMES = ("k_p", "V_gas_m3", "rho")
MEASURED_EXTRA_NAMES = ("V_gas_m3", "pressure_offset_Pa")


def _stack_design(X):
    z = jnp.zeros_like(X)
    return jnp.concatenate(
        [jnp.concatenate([X, z], axis=1), jnp.concatenate([z, X], axis=1)], axis=0
    )


def _coefficient_prior_sd(k: int = 4):
    return jnp.concatenate([jnp.full(k, FORCE_PRIOR_SD_N), jnp.full(k, PISTON_PRIOR_SD_M)])


def _log_prior_cubic_noise(nat, prior_mean):
    z = (nat - prior_mean) / NOISE_PRIOR_SD
    return -0.5 * jnp.sum(z**2)


# ----------------------------------------------------------------------------- measured pressure


class MeasuredData(NamedTuple):
    X: jnp.ndarray  # (n, 4)
    force: jnp.ndarray  # (n,) as read, N
    piston: jnp.ndarray  # (n,) as read, m
    ref_force: jnp.ndarray  # (n,)
    prior_mean: jnp.ndarray  # (3,)
    weight: jnp.ndarray  # (n,)
    lever: jnp.ndarray  # (n,) dP/dp_u plug-in, m^2
    dp: jnp.ndarray  # (n,) measured deviation less the common offset's prior mean, Pa
    boyle: jnp.ndarray  # () 1 / (p_abs S), 1/(Pa m^2)
    volume: jnp.ndarray  # () the stand's gas volume V_s, m^3
    offset_sd: jnp.ndarray  # () prior sd of the common offset left, Pa
    offset_mean: jnp.ndarray  # () its prior mean (already taken out of dp), Pa


def measured_data(test, x0_m: float, noise: str, stand: StandDescription, area_m2: float):
    """The measured model's arrays for one test (and the least-squares cubics of the corrected
    readings, ``(data, lsq_force, lsq_piston, ref_force)`` as ``cubic._prepare``)."""
    u = test.height_m - x0_m
    p_pa = test.pressure_bar * BAR_PA
    dp_hat = (np.asarray(test.measured_pressure_bar, float) - test.pressure_bar) * BAR_PA
    mean, sd = common_offset(dp_hat, p_pa, ordered=test.step is not None)
    dp = dp_hat - mean
    lsq_raw = least_squares(u, test.force_N)
    lever = cubic(lsq_raw, u) / p_pa
    boyle = 1.0 / ((test.pressure_bar + stand.p_atm_bar) * BAR_PA * area_m2)
    V = stand.gas_volume_at_xmax_m3
    force_c = test.force_N - lever * dp
    piston_c = test.piston_m + V * boyle * dp
    lsq_f = least_squares(u, force_c)
    lsq_l = least_squares(u, piston_c)
    ref = noise_reference(lsq_f, u, noise)
    data = MeasuredData(
        basis(u),
        jnp.asarray(test.force_N),
        jnp.asarray(test.piston_m),
        jnp.asarray(ref),
        jnp.asarray(noise_prior_mean(stand)),
        jnp.ones(u.size),
        jnp.asarray(lever),
        jnp.asarray(dp),
        jnp.asarray(boyle),
        jnp.asarray(V),
        jnp.asarray(sd),
        jnp.asarray(mean),
    )
    return data, lsq_f, lsq_l, ref


def _measured_design(d: MeasuredData):
    """Stacked design (2n, 10): [alpha (4), gamma (4), V - V_s, delta'] and corrected readings."""
    n = d.force.shape[0]
    Z8 = _stack_design(d.X)
    col_v = jnp.concatenate([jnp.zeros(n), -d.dp * d.boyle])
    col_off = jnp.concatenate([-d.lever, jnp.full(n, d.volume * d.boyle)])
    Z = jnp.concatenate([Z8, col_v[:, None], col_off[:, None]], axis=1)
    y = jnp.concatenate([d.force - d.lever * d.dp, d.piston + d.volume * d.boyle * d.dp])
    prior_sd = jnp.concatenate(
        [_coefficient_prior_sd(), jnp.stack([VOLUME_PRIOR_REL_SD * d.volume, d.offset_sd])]
    )
    return Z, y, prior_sd


def _measured_noise(theta, d: MeasuredData):
    nat = natural_noise(theta, jnp.mean(d.ref_force))
    sigma_f = jnp.sqrt(force_noise_var(jnp.exp(nat[0]), jnp.exp(nat[1]), d.ref_force))
    return sigma_f, jnp.exp(nat[2]), nat


def _measured_post(theta, d: MeasuredData):
    sigma_f, sigma_L, nat = _measured_noise(theta, d)
    Z, y, prior_sd = _measured_design(d)
    sd = jnp.concatenate([sigma_f, jnp.full(d.force.shape, sigma_L)])
    w = jnp.concatenate([d.weight, d.weight])
    return linear_posterior(Z, y, sd, prior_sd, w), nat


def measured_log_prob(theta, d: MeasuredData):
    post, nat = _measured_post(theta, d)
    return _log_prior_cubic_noise(nat, d.prior_mean) + post.log_marginal


def measured_draw(theta, key, d: MeasuredData):
    return draw_exact(_measured_post(theta, d)[0], key)


def measured_pointwise(theta, beta, d: MeasuredData):
    sigma_f, sigma_L, _ = _measured_noise(theta, d)
    Z, y, _ = _measured_design(d)
    mu = Z @ beta
    n = d.force.shape[0]
    return {
        "force_N": gaussian_loglik(y[:n], mu[:n], sigma_f),
        "piston_m": gaussian_loglik(y[n:], mu[n:], sigma_L),
    }


def measured_predict(theta, beta, key, d: MeasuredData):
    """A replicate of the readings as read, at the measured pressures."""
    sigma_f, sigma_L, _ = _measured_noise(theta, d)
    Z, y, _ = _measured_design(d)
    n = d.force.shape[0]
    mu = Z @ beta
    kf, kl = jax.random.split(key)
    return {
        "force_N": mu[:n] + d.lever * d.dp + sigma_f * jax.random.normal(kf, (n,)),
        "piston_m": mu[n:] - d.volume * d.boyle * d.dp + sigma_L * jax.random.normal(kl, (n,)),
    }


def measured_pointwise_loo(theta, d: MeasuredData):
    """log p(force_i, piston_i | noise, the other readings), coefficients integrated out."""
    from uq._models.pair import block_loo

    sigma_f, sigma_L, _ = _measured_noise(theta, d)
    Z, y, prior_sd = _measured_design(d)
    sd = jnp.concatenate([sigma_f, jnp.full(d.force.shape, sigma_L)])
    Zw, yw = Z / sd[:, None], y / sd
    post = linear_posterior(Zw, yw, jnp.ones_like(yw), prior_sd)
    n = d.force.shape[0]
    return block_loo(Zw, yw, n, post.chol, post.mean) - jnp.log(sigma_f) - jnp.log(sigma_L)


def measured_start(d: MeasuredData) -> np.ndarray:
    _, y, _ = _measured_design(d)
    n = d.force.shape[0]
    return start(d._replace(force=y[:n], piston=y[n:]))


def measured_report(theta, beta, d: MeasuredData) -> dict:
    out = report(theta, beta[:, :8], d)
    return out | {
        "V_gas_m3": float(d.volume) + beta[:, 8],
        "pressure_offset_Pa": float(d.offset_mean) + beta[:, 9],
    }


def measured_corrected(d: MeasuredData, beta_mean) -> dict:
    """The readings corrected at the posterior-mean gas volume and offset (for the order check)."""
    V = float(d.volume) + float(beta_mean[8])
    dp = np.asarray(d.dp) - float(beta_mean[9])
    return {
        "force": np.asarray(d.force) - np.asarray(d.lever) * dp,
        "piston": np.asarray(d.piston) + V * float(d.boyle) * dp,
    }


MEASURED = CollapsedModel(
    name="per-pressure cubics (eqs. 8, 9), measured pressure as a covariate",
    theta_names=SAMPLER_NAMES,
    log_prob=measured_log_prob,
    draw_linear=measured_draw,
    pointwise=measured_pointwise,
    start=measured_start,
    report=measured_report,
    predict=measured_predict,
    observed=observed,
    pointwise_loo=measured_pointwise_loo,
    hold_out=hold_out,
)


# ----------------------------------------------------------------------------- AR(1) holding errors


class AR1Data(NamedTuple):
    X: jnp.ndarray  # (n, 4), readings in recording order
    force: jnp.ndarray
    piston: jnp.ndarray
    ref_force: jnp.ndarray
    prior_mean: jnp.ndarray  # (5,) cubic noise centres (3), log k_p centre, log V centre
    weight: jnp.ndarray
    lever: jnp.ndarray  # (n,) dP/dp_u plug-in, m^2
    hold_sd: jnp.ndarray  # () the stand's holding sd at this pressure, Pa
    boyle: jnp.ndarray  # () 1 / (p_abs S)
    blocks: jnp.ndarray  # (n, 2) int: rows (i, n + i) of reading i in the stacked vectors


def ar1_noise_prior_mean(stand: StandDescription, lsq_piston, u) -> np.ndarray:
    """Prior centres of (log sigma0, log r, log sigma_L) for the AR(1) model: the plain model's,
    except sigma_L's. The plain model centres sigma_L on 1 mm, the scale of the holding error's
    piston term it lumps into the noise (Boyle's law: 1 to 6 mm on the paper's stand); here that
    term is the latent series, and what is left is the stand's calipers and displacement sensor
    (the latter through the piston's slope dL/dx, from the least-squares cubic at the readings):
    sqrt(caliper_sd^2 + (displacement_sd rms dL/dx)^2), never under 1 um (log 0 has no prior).
    With the 1 mm centre the weakly identified white part took variance from the series at low
    pressure (0.34 mm fitted where the stand's is 0.08 mm)."""
    slope = cubic_slope(np.asarray(lsq_piston, float), np.asarray(u, float))
    left = math.hypot(stand.caliper_sd_m, stand.displacement_sd_m * math.sqrt(np.mean(slope**2)))
    out = noise_prior_mean(stand)
    out[2] = math.log(max(left, 1e-6))
    return out


def ar1_data(test, x0_m: float, noise: str, stand: StandDescription, area_m2: float):
    """The AR(1) model's arrays for one test in recording order (``cubic._prepare``'s tuple)."""
    data, lsq_f, lsq_l, ref = _prepare(test, x0_m, noise, stand)
    u = test.height_m - x0_m
    p_pa = test.pressure_bar * BAR_PA
    n = u.size
    ar = AR1Data(
        data.X,
        data.force,
        data.piston,
        data.ref_force,
        jnp.asarray(
            np.concatenate(
                [ar1_noise_prior_mean(stand, lsq_l, u), [0.0, np.log(stand.gas_volume_at_xmax_m3)]]
            )
        ),
        data.weight,
        jnp.asarray(cubic(lsq_f, u) / p_pa),
        jnp.asarray(float(stand.pressure_sd_bar(test.pressure_bar)) * BAR_PA),
        jnp.asarray(1.0 / ((test.pressure_bar + stand.p_atm_bar) * BAR_PA * area_m2)),
        jnp.asarray(np.stack([np.arange(n), n + np.arange(n)], axis=1)),
    )
    return ar, lsq_f, lsq_l, ref


def ar1_parts(theta, d: AR1Data):
    """(v (2n,), U (2n, n), Q (n, n), log det Q, nat (3,), (k_p, V, rho)) at theta (6,)."""
    nat = natural_noise(theta[:3], jnp.mean(d.ref_force))
    a2 = force_noise_var(jnp.exp(nat[0]), jnp.exp(nat[1]), d.ref_force)
    n = d.force.shape[0]
    kp, V, rho = jnp.exp(theta[3]), jnp.exp(theta[4]), jnp.tanh(theta[5])
    b = d.lever * d.hold_sd * kp
    c = -V * d.boyle * d.hold_sd * kp
    v = jnp.concatenate([a2, jnp.full(n, jnp.exp(2.0 * nat[2]))])
    U = jnp.concatenate([jnp.diag(b), c * jnp.eye(n)], axis=0)
    Q, ldQ = ar1_precision(rho, n)
    return v, U, Q, ldQ, nat, (kp, V, rho)


def _paired(theta, d: AR1Data):
    """(v (2n,), uf (n,), ul (n,), rho): the independent variances and each reading's loading on
    the holding-error series z (force, piston)."""
    nat = natural_noise(theta[:3], jnp.mean(d.ref_force))
    a2 = force_noise_var(jnp.exp(nat[0]), jnp.exp(nat[1]), d.ref_force)
    n = d.force.shape[0]
    kp, V, rho = jnp.exp(theta[3]), jnp.exp(theta[4]), jnp.tanh(theta[5])
    v = jnp.concatenate([a2, jnp.full(n, jnp.exp(2.0 * nat[2]))])
    return v, d.lever * d.hold_sd * kp, jnp.full(n, -V * d.boyle * d.hold_sd * kp), rho


def _ar1_post(theta, d: AR1Data):
    """The coefficients' posterior given theta: the whitened O(n) form (``paired_ar1_posterior``),
    checked against the dense ``latent_posterior`` and a dense Cholesky factor in the tests."""
    nat = natural_noise(theta[:3], jnp.mean(d.ref_force))
    a2 = force_noise_var(jnp.exp(nat[0]), jnp.exp(nat[1]), d.ref_force)
    n = d.force.shape[0]
    kp, V, rho = jnp.exp(theta[3]), jnp.exp(theta[4]), jnp.tanh(theta[5])
    v = jnp.concatenate([a2, jnp.full(n, jnp.exp(2.0 * nat[2]))])
    uf = d.lever * d.hold_sd * kp
    ul = jnp.full(n, -V * d.boyle * d.hold_sd * kp)
    Z = _stack_design(d.X)
    y = jnp.concatenate([d.force, d.piston])
    w = jnp.concatenate([d.weight, d.weight])
    post = paired_ar1_posterior(Z, y, v, uf, ul, rho, _coefficient_prior_sd(), w)
    return post, nat, (kp, V, rho)


def ar1_log_prior(theta, d: AR1Data):
    nat = natural_noise(theta[:3], jnp.mean(d.ref_force))
    rho = jnp.tanh(theta[5])
    return (
        _log_prior_cubic_noise(nat, d.prior_mean[:3])
        - 0.5 * ((theta[3] - d.prior_mean[3]) / LOG_KP_PRIOR_SD) ** 2
        - 0.5 * ((theta[4] - d.prior_mean[4]) / LOG_V_PRIOR_SD) ** 2
        + jnp.log1p(-(rho**2))  # rho uniform on (-1, 1): the Jacobian of tanh
    )


#: Sampled parameters farther than this many prior sds from their prior centre are refused: the
#: prior gives them no weight (and 1 - rho^2 would lose its digits beyond |atanh rho| = 4).
PRIOR_BOX_SD = 8.0


def ar1_log_prob(theta, d: AR1Data):
    post, nat, _ = _ar1_post(theta, d)
    z = jnp.concatenate(
        [
            (nat - d.prior_mean[:3]) / NOISE_PRIOR_SD,
            (theta[3:5] - d.prior_mean[3:5]) / jnp.array([LOG_KP_PRIOR_SD, LOG_V_PRIOR_SD]),
            theta[5:6]
            / 0.5,  # |rho| < tanh(4) = 0.9993: stationary, and 1 - rho^2 keeps its digits
        ]
    )
    inside = jnp.all(jnp.abs(z) < PRIOR_BOX_SD)
    return jnp.where(inside, ar1_log_prior(theta, d) + post.log_marginal, -jnp.inf)


def ar1_draw(theta, key, d: AR1Data):
    return draw_exact(_ar1_post(theta, d)[0], key)


def _split_pair(P, r, blocks):
    """Block conditionals of each reading pair split by the chain rule: force_i given the other
    readings, piston_i given force_i and the others. Returns (force (n,), piston (n,))."""
    total = block_conditional_logpdf(P, r, blocks)
    Pll = P[blocks[:, 1], blocks[:, 1]]
    gl = (P @ r)[blocks[:, 1]]
    # piston_i given everything else: precision P_ll, residual (P r)_l / P_ll
    piston = -0.5 * gl**2 / Pll + 0.5 * jnp.log(Pll) - 0.5 * LOG_2PI
    return total - piston, piston


def ar1_pointwise(theta, beta, d: AR1Data):
    """log p(reading_i | coefficients, noise, the test's other readings), split into force and
    piston by the chain rule (the errors are correlated: the readings do not factorise)."""
    v, uf, ul, rho = _paired(theta, d)
    r = jnp.concatenate([d.force, d.piston]) - _stack_design(d.X) @ beta
    f, p = _split_pair(paired_ar1_precision(v, uf, ul, rho), r, d.blocks)
    return {"force_N": f, "piston_m": p}


def ar1_pointwise_loo(theta, d: AR1Data):
    """log p(force_i, piston_i | noise, the test's other readings), coefficients integrated out."""
    v, uf, ul, rho = _paired(theta, d)
    Z = _stack_design(d.X)
    y = jnp.concatenate([d.force, d.piston])
    P0 = paired_ar1_precision(v, uf, ul, rho)
    post = _ar1_post(theta, d._replace(weight=jnp.ones_like(d.weight)))[0]
    G = jax.scipy.linalg.solve_triangular(post.chol, Z.T @ P0, lower=True)  # (k, 2n)
    return block_conditional_logpdf(P0 - G.T @ G, y, d.blocks)


def ar1_predict(theta, beta, key, d: AR1Data):
    """A replicate: mean curves, a fresh AR(1) holding-error series, independent reading noise."""
    v, uf, ul, rho = _paired(theta, d)
    n = d.force.shape[0]
    k1, k2 = jax.random.split(key)
    z = ar1_series(rho, jax.random.normal(k1, (n,)))
    y = (
        _stack_design(d.X) @ beta
        + jnp.concatenate([uf * z, ul * z])
        + jnp.sqrt(v) * jax.random.normal(k2, (2 * n,))
    )
    return {"force_N": y[:n], "piston_m": y[n:]}


def ar1_start(d: AR1Data) -> np.ndarray:
    base = start(CubicData(d.X, d.force, d.piston, d.ref_force, d.prior_mean[:3], d.weight))
    out = []
    for rho in (0.0, 0.6):
        s = base.copy()
        s[2] = np.log(np.exp(base[2]) / 30.0)  # the holding error takes the piston's scatter
        out.append(np.concatenate([s, [0.0, float(d.prior_mean[4]), np.arctanh(rho)]]))
    return np.array(out)


def ar1_report(theta, beta, d: AR1Data) -> dict:
    out = report(theta[:, :3], beta, d)
    return out | {
        "k_p": np.exp(theta[:, 3]),
        "V_gas_m3": np.exp(theta[:, 4]),
        "rho": np.tanh(theta[:, 5]),
    }


def ar1_order_whitening(d: AR1Data, theta_mean) -> tuple[dict, dict]:
    """Lag-one correlation each block's errors have under the fitted model (posterior-mean noise),
    for pre-whitening the residuals before the recording-order check: rho times the share of the
    holding error in the block's variance."""
    v, U, _, _, _, (_, _, rho) = ar1_parts(jnp.asarray(theta_mean), d)
    n = d.force.shape[0]
    v, U = np.asarray(v), np.asarray(U)
    dpvar_f = np.diag(U[:n]) ** 2
    dpvar_l = U[n:][np.arange(n), np.arange(n)] ** 2
    share_f = float(np.mean(dpvar_f / (dpvar_f + v[:n])))
    share_l = float(np.mean(dpvar_l / (dpvar_l + v[n:])))
    sd_f = np.sqrt(dpvar_f + v[:n])
    sd_l = np.sqrt(dpvar_l + v[n:])
    return (
        {"force": float(rho) * share_f, "piston": float(rho) * share_l},
        {"force": sd_f, "piston": sd_l},
    )


AR1 = CollapsedModel(
    name="per-pressure cubics (eqs. 8, 9), AR(1) pressure-holding errors in recording order",
    theta_names=AR_SAMPLER_NAMES,
    log_prob=ar1_log_prob,
    draw_linear=ar1_draw,
    pointwise=ar1_pointwise,
    start=ar1_start,
    report=ar1_report,
    predict=ar1_predict,
    observed=observed,
    pointwise_loo=ar1_pointwise_loo,
    hold_out=hold_out,
)


def collapsed_model(data) -> CollapsedModel:
    """The model bundle whose data ``data`` is (a fit's ``posterior.data``), for refits."""
    kinds = ((ForceData, FORCE_ONLY), (MeasuredData, MEASURED), (AR1Data, AR1), (CubicData, MODEL))
    for kind, model in kinds:
        if isinstance(data, kind):
            return model
    raise TypeError(f"not the data of a per-pressure cubic: {type(data).__name__}")


def prewhiten(residuals, rho: float):
    """Prais-Winsten transform of a series with AR(1) errors of lag-one correlation ``rho``:
    e_0 sqrt(1 - rho^2), e_i - rho e_(i-1) (independent errors of the same innovation sd)."""
    r = np.asarray(residuals, float)
    out = np.empty_like(r)
    out[0] = r[0] * np.sqrt(1.0 - rho**2)
    out[1:] = r[1:] - rho * r[:-1]
    return out
