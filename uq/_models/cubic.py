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
from uq._inference.linear import draw_exact, gaussian_loglik, linear_posterior, loo_given_noise
from uq._inference.sampler import Settings
from uq._inference.summary import estimate
from uq._models.residual_order import ALPHA as ORDER_ALPHA
from uq._models.residual_order import lag_one_check, order_warnings
from uq._physics.cubic import cubic
from uq._physics.quantities import BASIS_SCALE_M, force_noise_var, to_paper_basis

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
    """Sampler coordinates -> (log sigma0, log r, log sigma_L).

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
    return jnp.stack(
        [psi + 0.5 * log_phi, psi + 0.5 * log_1mphi - jnp.log(ref_mean), theta[..., 2]], axis=-1
    )


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


# ----------------------------------------------------------------------------- results


def noise_reference(lsq_force, u, noise: str) -> np.ndarray:
    """Force level of the relative noise term at u: the least-squares curve's |P| ("budget"), or
    its mean over these points ("constant")."""
    ref = np.abs(cubic(lsq_force, u))
    return np.full_like(ref, ref.mean()) if noise == "constant" else ref


@dataclass(eq=False, frozen=True, repr=False)
class PressureFit:
    """Posterior of one test: the driver's :class:`~uq._inference.collapsed.Posterior` and what the
    test's quantities need. Draw arrays are (chains, draws, ...) in the paper's basis, SI."""

    test: PressureTest
    x0_m: float
    lsq_force: np.ndarray  # (4,)
    lsq_piston: np.ndarray  # (4,)
    posterior: Posterior
    ref_force_N: np.ndarray  # (n,) force level of the relative noise term at each point
    noise_model: str  # "budget" or "constant" (fit_test's noise)
    force: np.ndarray  # (C, D, 4) a_P..d_P
    piston: np.ndarray  # (C, D, 4) a_L..d_L
    noise: np.ndarray  # (C, D, 3) sigma0_N, rel_force, sigma_L_m
    #: the recording-order check of the residuals (uq._models.residual_order): force, piston, alpha
    order_check: dict
    #: the pressure-holding error: "plain" (in the noise), "measured" (measured pressure as a
    #: covariate) or "ar1" (AR(1) in recording order); uq._models.cubic_pressure
    variant: str = "plain"

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
        post = posterior.idata.posterior

        def stack(names):
            return np.stack([np.asarray(post[n]) for n in names], axis=-1)

        force, piston, noise = stack(FORCE_NAMES), stack(PISTON_NAMES), stack(NOISE_NAMES)
        u = test.height_m - x0_m
        mean_noise = noise.reshape(-1, 3).mean(axis=0)
        design = np.asarray(basis(u))
        readings = {"force": test.force_N, "piston": test.piston_m}
        if variant == "measured":  # the readings the model fits: corrected by the measured pressure
            from uq._models.cubic_pressure import measured_corrected

            readings = measured_corrected(posterior.data, posterior.beta.reshape(-1, 10).mean(0))
        residuals = {
            "force": readings["force"] - cubic(force.reshape(-1, 4).mean(0), u),
            "piston": readings["piston"] - cubic(piston.reshape(-1, 4).mean(0), u),
        }
        sd = {
            "force": np.sqrt(force_noise_var(mean_noise[0], mean_noise[1], ref_force_N)),
            "piston": np.full(u.shape, mean_noise[2]),
        }
        designs = {"force": design, "piston": design}
        if variant == "ar1":  # check what the AR(1) model leaves: Prais-Winsten innovations
            from uq._models.cubic_pressure import ar1_order_whitening, prewhiten

            theta_mean = posterior.theta.reshape(-1, posterior.theta.shape[-1]).mean(0)
            rho, sd = ar1_order_whitening(posterior.data, theta_mean)
            for b in ("force", "piston"):
                residuals[b] = prewhiten(residuals[b] / sd[b], rho[b])
                designs[b] = np.stack(
                    [prewhiten(c, rho[b]) for c in (design / sd[b][:, None]).T], axis=1
                )
                sd[b] = np.ones(u.shape)
        check = {b: lag_one_check(residuals[b], sd[b], designs[b]) for b in ("force", "piston")}
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
        )

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
        y = self.test.force_N if block == "force" else self.test.piston_m
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
        """One entry of ``tests`` in ``uq fit --json`` (docs/formats.md)."""
        conv = self.convergence.to_json(advice, variables=False)
        var = self.convergence.variables
        s_P, eps_P = self.deviation_measures()

        def block(draws, names):
            return {
                n: estimate(draws[..., i])
                | {k: var[n][k] for k in ("r_hat", "ess_bulk", "ess_tail", "mcse_mean")}
                for i, n in enumerate(names)
            }

        return {
            "pressure_bar": self.pressure_bar,
            "n_points": self.test.n_points,
            "force": block(self.force, FORCE_NAMES),
            "piston": block(self.piston, PISTON_NAMES),
            "s_P_N": s_P,
            "eps_P_pct": eps_P,
            "noise": {
                n: estimate(self.noise[..., i])
                | {"r_hat": var[n]["r_hat"], "ess_bulk": var[n]["ess_bulk"]}
                for i, n in enumerate(NOISE_NAMES)
            },
            "least_squares": {
                "force": dict(zip(FORCE_NAMES, self.lsq_force.tolist(), strict=True)),
                "piston": dict(zip(PISTON_NAMES, self.lsq_piston.tolist(), strict=True)),
            },
            "covariance": {
                "force": np.cov(self.flat("force"), rowvar=False),
                "piston": np.cov(self.flat("piston"), rowvar=False),
            },
            "convergence": conv,
            "residual_order": self.order_check,
        } | self._pressure_holding_json(var)

    def _pressure_holding_json(self, var) -> dict:
        """How the model treated the pressure-holding error, and its extra parameters."""
        from uq._models.cubic_pressure import AR_EXTRA_NAMES, MEASURED_EXTRA_NAMES

        if self.variant == "plain":
            return {}
        names = AR_EXTRA_NAMES if self.variant == "ar1" else MEASURED_EXTRA_NAMES
        post = self.idata.posterior
        block = {"model": self.variant}
        for n in names:
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


def _prepare(test: PressureTest, x0_m: float, noise: str, stand: StandDescription):
    if noise not in ("budget", "constant"):
        raise ValueError(f"noise must be 'budget' or 'constant', got {noise!r}")
    u = test.height_m - x0_m
    lsq_f = least_squares(u, test.force_N)
    lsq_l = least_squares(u, test.piston_m)
    ref_force = noise_reference(lsq_f, u, noise)
    data = CubicData(
        basis(u),
        jnp.asarray(test.force_N),
        jnp.asarray(test.piston_m),
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

    The pressure-holding error (uq._models.cubic_pressure): ``pressure="measured"`` uses each
    reading's measured pressure (``PressureTest.measured_pressure_bar``) as a covariate; otherwise
    ``ar1`` says whether the holding errors are an AR(1) series in recording order: "off" (in the
    independent noise, the default), "on" (every test with a recording order), "auto" (the tests
    whose residuals the recording-order check flags under the independent model are refitted
    with it). Tests without piston readings, or without a recording order for AR(1), keep the
    plain model. ``piston_area_m2``: the stand's S (Boyle's law moves the piston by dV / S).
    """
    from uq._models import cubic_pressure as CP

    if pressure not in PRESSURE_MODELS:
        raise ValueError(f"pressure must be one of {PRESSURE_MODELS}, got {pressure!r}")
    if ar1 not in AR1_CHOICES:
        raise ValueError(f"ar1 must be one of {AR1_CHOICES}, got {ar1!r}")
    tests = list(tests)
    seeds = test_seeds(seed, len(tests))

    def variant_of(t) -> str:
        if t.piston_m is None:
            return "plain"
        if pressure == "measured":
            return "measured"
        if ar1 == "on" and t.step is not None:
            return "ar1"
        return "plain"

    def prepare(t, variant):
        if variant == "measured":
            return CP.measured_data(t, x0_m, noise, stand, piston_area_m2)
        if variant == "ar1":
            return CP.ar1_data(t, x0_m, noise, stand, piston_area_m2)
        return _prepare(t, x0_m, noise, stand)

    models = {"plain": MODEL, "measured": CP.MEASURED, "ar1": CP.AR1}
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
            i: PressureFit.of(tests[i], x0_m, lsq_f, lsq_l, post, ref, noise, variant)
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
