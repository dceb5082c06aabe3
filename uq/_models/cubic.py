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
    log sigma0[N] ~ N(log 10, 2^2),  log r ~ N(log 0.005, 1),  log sigma_L[m] ~ N(log 1e-3, 2^2)

Given the three noise parameters the coefficients are Gaussian (``uq._inference.linear``): emcee samples
(log sigma0, log r, log sigma_L) (mostly independence proposals fitted to the other walkers, with
DE moves: ``uq._inference.sampler.INDEPENDENCE_MIX``) and every retained sample gets an exact draw of the eight
coefficients, reported in the paper's basis (a + b u + c u^2 + d u^3, SI units).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import arviz as az
import numpy as np
import optimistix as optx

from uq._data.recordings import PressureTest, Recordings
from uq._data.reference import FORCE_NAMES, PISTON_NAMES
from uq._inference.float64 import jax, jnp
from uq._inference.linear import (
    draw_exact,
    gaussian_loglik,
    linear_posterior,
    map_rows,
    row_keys,
)
from uq._inference.sampler import Chains, Settings, convergence, run_many, thin
from uq._physics.quantities import BASIS_SCALE_M, force_noise_var, to_paper_basis

MAX_DRAWS = 8000  # retained posterior samples per test after thinning
FORCE_PRIOR_SD_N = 1.0e5
PISTON_PRIOR_SD_M = 1.0
NOISE_NAMES = ("sigma0_N", "rel_force", "sigma_L_m")
SAMPLER_NAMES = ("log_noise_at_mean_force", "logit_floor_share", "log_sigma_L")
NOISE_PRIOR_MEAN = np.log(np.array([10.0, 0.005, 1.0e-3]))
NOISE_PRIOR_SD = np.array([2.0, 1.0, 2.0])


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


def _noise(theta, ref_force):
    nat = natural_noise(theta, jnp.mean(ref_force))
    sigma0, rel, sigma_L = jnp.exp(nat[0]), jnp.exp(nat[1]), jnp.exp(nat[2])
    sigma_f = jnp.sqrt(force_noise_var(sigma0, rel, ref_force))
    return sigma_f, sigma_L, nat


def _log_prior(nat):
    z = (nat - NOISE_PRIOR_MEAN) / NOISE_PRIOR_SD
    return -0.5 * jnp.sum(z**2)


def _posteriors(theta, X, force, piston, ref_force):
    sigma_f, sigma_L, _ = _noise(theta, ref_force)
    k = X.shape[1]
    pf = linear_posterior(X, force, sigma_f, jnp.full(k, FORCE_PRIOR_SD_N))
    pl = linear_posterior(
        X, piston, jnp.full(piston.shape, sigma_L), jnp.full(k, PISTON_PRIOR_SD_M)
    )
    return pf, pl


@jax.jit
def log_prob(thetas, X, force, piston, ref_force):
    """Log posterior of the noise parameters, coefficients integrated out. thetas (W, 3) -> (W,)."""

    def one(theta):
        pf, pl = _posteriors(theta, X, force, piston, ref_force)
        lp = _log_prior(_noise(theta, ref_force)[2]) + pf.log_marginal + pl.log_marginal
        return jnp.where(jnp.isfinite(lp), lp, -jnp.inf)

    return jax.vmap(one)(thetas)


@dataclass(eq=False, frozen=True)
class PressureFit:
    """Posterior of one test. Draw arrays are (chains, draws, ...) in the paper's basis, SI."""

    test: PressureTest
    x0_m: float
    lsq_force: np.ndarray  # (4,)
    lsq_piston: np.ndarray  # (4,)
    force: np.ndarray  # (C, D, 4)
    piston: np.ndarray  # (C, D, 4)
    noise: np.ndarray  # (C, D, 3): sigma0_N, rel_force, sigma_L_m
    chains: Chains
    idata: az.InferenceData
    diagnostics: dict
    ref_force_N: np.ndarray  # (n,) force level of the relative noise term at each point
    noise_model: str = "budget"  # "budget" or "constant" (fit_test's noise)

    @property
    def pressure_bar(self) -> float:
        return self.test.pressure_bar

    def flat(self, name: str) -> np.ndarray:
        arr = getattr(self, name)
        return arr.reshape(-1, *arr.shape[2:])

    def ref_force(self) -> np.ndarray:
        return self.ref_force_N

    def ref_force_at(self, height_m) -> np.ndarray:
        """The force level of the relative noise term at any heights, by the rule the fit used at
        the data (``_noise_reference``): the report's predictive bands use it on their grid."""
        u = np.asarray(height_m, float) - self.x0_m
        if self.noise_model == "constant":
            return np.full(u.shape, float(np.mean(self.ref_force_N)))
        return _noise_reference(self.lsq_force, u, self.noise_model)

    def mean_residuals(self, block: str) -> np.ndarray:
        """Readings minus the posterior-mean curve of ``block`` ("force" N or "piston" m), (n,)."""
        y = self.test.force_N if block == "force" else self.test.piston_m
        return y - _cubic_eval(self.flat(block).mean(0), self.test.height_m - self.x0_m)

    def deviation_measures(self) -> tuple[float, float]:
        """The paper's s_P (N) and eps_P (%) of the posterior-mean curve (section 5)."""
        res = self.mean_residuals("force")
        return float(np.sqrt(np.mean(res**2))), float(
            100.0 * np.mean(np.abs(res / self.test.force_N))
        )

    def pointwise_loglik(self, max_draws: int = 2000, seed: int = 0) -> dict[str, np.ndarray]:
        """Pointwise log-likelihood (chains, draws', n) of force and piston, for PSIS-LOO."""
        C, D = self.force.shape[:2]
        step = max(1, int(np.ceil(C * D / max_draws)))
        f, l, nz = self.force[:, ::step], self.piston[:, ::step], self.noise[:, ::step]
        u = self.test.height_m - self.x0_m
        mu_f = np.einsum("cdk,nk->cdn", f, np.vander(u, 4, increasing=True))
        mu_l = np.einsum("cdk,nk->cdn", l, np.vander(u, 4, increasing=True))
        sf = np.sqrt(force_noise_var(nz[..., 0:1], nz[..., 1:2], self.ref_force()))
        ll_f = gaussian_loglik(self.test.force_N, mu_f, sf)
        ll_l = gaussian_loglik(self.test.piston_m, mu_l, nz[..., 2:3])
        return {"force": np.asarray(ll_f), "piston": np.asarray(ll_l)}


def _cubic_eval(coef, u):
    return coef[0] + coef[1] * u + coef[2] * u**2 + coef[3] * u**3


def _start(X, force, piston, ref_force, lsq_f, lsq_l, u):
    """Optimistix BFGS on the negative log posterior of the noise, from the residual scale."""
    res_f = force - _cubic_eval(lsq_f, u)
    res_l = piston - _cubic_eval(lsq_l, u)
    n = force.size
    s_f = np.sqrt(np.sum(res_f**2) / max(n - 4, 1)) + 1e-9
    s_l = np.sqrt(np.sum(res_l**2) / max(n - 4, 1)) + 1e-12
    theta0 = jnp.array([np.log(s_f), 0.0, np.log(s_l)])
    theta, result = _bfgs(
        theta0, X, jnp.asarray(force), jnp.asarray(piston), jnp.asarray(ref_force)
    )
    theta = np.asarray(theta)
    if not np.all(np.isfinite(theta)) or result != optx.RESULTS.successful:
        theta = np.asarray(theta0)
    return theta


def _neg_log_prob(theta, args):
    return -log_prob(theta[None, :], *args)[0]


@jax.jit
def _bfgs(theta0, X, force, piston, ref_force):
    sol = optx.minimise(
        _neg_log_prob,
        optx.BFGS(rtol=1e-8, atol=1e-8),
        theta0,
        args=(X, force, piston, ref_force),
        max_steps=500,
        throw=False,
    )
    return sol.value, sol.result


def fit_test(
    test: PressureTest,
    x0_m: float,
    *,
    seed: int,
    settings: Settings = Settings(),
    noise: str = "budget",
) -> PressureFit:
    """Least squares, then the emcee posterior with exact coefficient draws, then diagnostics.

    ``noise="budget"`` (default): force sd grows with the force (load cell) over a floor.
    ``noise="constant"``: one force sd for the whole test, the common but wrong choice kept
    for the calibration suite's misspecification study (the total is still sampled; its split
    into floor and relative parts is then unidentified and follows the prior).
    """
    return fit_tests([test], x0_m, seed=seed, settings=settings, noise=noise)[0]


@dataclass(frozen=True)
class _Prepared:
    """What the sampler needs of one test: data, least squares, noise reference, start."""

    test: PressureTest
    X: np.ndarray  # (n, 4) scaled basis
    lsq_f: np.ndarray
    lsq_l: np.ndarray
    ref_force: np.ndarray  # (n,)
    center: np.ndarray  # (3,) optimistix start
    scale: np.ndarray  # (3,) posterior width estimate / settings.init_scale
    noise: str  # "budget" or "constant"


def _noise_reference(lsq_force, u, noise: str) -> np.ndarray:
    """Force level of the relative noise term at u: the least-squares curve's |P| ("budget"), or
    its mean over these points ("constant")."""
    ref = np.abs(_cubic_eval(lsq_force, u))
    return np.full_like(ref, ref.mean()) if noise == "constant" else ref


def _prepare(test: PressureTest, x0_m: float, settings: Settings, noise: str) -> _Prepared:
    if noise not in ("budget", "constant"):
        raise ValueError(f"noise must be 'budget' or 'constant', got {noise!r}")
    u = test.height_m - x0_m
    lsq_f = least_squares(u, test.force_N)
    lsq_l = least_squares(u, test.piston_m)
    ref_force = _noise_reference(lsq_f, u, noise)
    X = np.asarray(basis(u))
    center = _start(jnp.asarray(X), test.force_N, test.piston_m, ref_force, lsq_f, lsq_l, u)
    # Start spread: about the posterior width of a log-scale from n points.
    scale = np.full(3, 1.0 / np.sqrt(2.0 * test.n_points)) / settings.init_scale * 0.5
    return _Prepared(test, X, lsq_f, lsq_l, ref_force, center, scale, noise)


_log_prob_tests = jax.jit(
    jax.vmap(log_prob)
)  # (K, W, 3) thetas of K tests of equal length -> (K, W)


def _campaign_log_prob(preps: list[_Prepared]):
    """One log-probability over all tests, (K, W, 3) -> (K, W): one jitted, vmapped call per
    test length (all tests of a campaign usually have one), so it compiles once per length."""
    by_len: dict[int, list[int]] = {}
    for i, pr in enumerate(preps):
        by_len.setdefault(pr.test.n_points, []).append(i)
    groups = []
    for idx in by_len.values():
        args = tuple(
            jnp.asarray(np.stack(a))
            for a in zip(
                *[
                    (preps[i].X, preps[i].test.force_N, preps[i].test.piston_m, preps[i].ref_force)
                    for i in idx
                ],
                strict=True,
            )
        )
        groups.append((np.array(idx), args))

    def lp(thetas):
        thetas = np.asarray(thetas, float)
        out = np.empty(thetas.shape[:2])
        for idx, args in groups:
            out[idx] = np.asarray(
                _log_prob_tests(thetas[idx], *args)
            )  # numpy in: jit's fast dispatch path
        return out

    return lp


def fit_tests(
    tests,
    x0_m: float,
    *,
    seed: int,
    settings: Settings = Settings(),
    noise: str = "budget",
    desc: str | None = None,
) -> list[PressureFit]:
    """Fit several tests at once: one emcee sampler runs every test's ensembles in lockstep
    (``uq._inference.sampler.run_many``), each test with its own independent ensembles, burn-in and
    convergence verdict; the run lasts until every test passes every rule. The exact
    coefficient draws of test i use the i-th seed derived from ``seed`` (:func:`test_seeds`).
    """
    preps = [_prepare(t, x0_m, settings, noise) for t in tests]
    runs = run_many(
        _campaign_log_prob(preps),
        np.stack([p.center for p in preps]),
        np.stack([p.scale for p in preps]),
        SAMPLER_NAMES,
        seed=seed,
        settings=settings,
        desc=desc,
    )
    return [
        _posterior(pr, thin(ch, MAX_DRAWS), x0_m, s)
        for pr, ch, s in zip(preps, runs, test_seeds(seed, len(preps)), strict=True)
    ]


def _draw(sigma, key, X, y, prior_sd):
    """One exact draw of a cubic's coefficients given the noise sd at each point (mapped by map_rows)."""
    return draw_exact(linear_posterior(X, y, sigma, prior_sd), key)


def _posterior(pr: _Prepared, chains: Chains, x0_m: float, seed: int) -> PressureFit:
    """Exact coefficient draws for every retained noise sample, ArviZ data and diagnostics."""
    test, ref_force = pr.test, pr.ref_force
    C, D, _ = chains.samples.shape
    rows = chains.samples.reshape(C * D, 3)
    nat = map_rows(natural_noise, (rows,), (float(np.mean(ref_force)),))
    noise_flat = np.exp(nat)
    sigma_f = np.sqrt(force_noise_var(noise_flat[:, :1], noise_flat[:, 1:2], ref_force))
    sigma_l = np.ascontiguousarray(np.broadcast_to(noise_flat[:, 2:3], sigma_f.shape))
    key_f, key_l = jax.random.split(jax.random.PRNGKey(seed))
    alpha_f = map_rows(
        _draw,
        (jnp.asarray(sigma_f), row_keys(key_f, C * D)),
        (jnp.asarray(pr.X), jnp.asarray(test.force_N), jnp.full(4, FORCE_PRIOR_SD_N)),
    )
    alpha_l = map_rows(
        _draw,
        (jnp.asarray(sigma_l), row_keys(key_l, C * D)),
        (jnp.asarray(pr.X), jnp.asarray(test.piston_m), jnp.full(4, PISTON_PRIOR_SD_M)),
    )
    force = to_paper_basis(np.asarray(alpha_f)).reshape(C, D, 4)
    piston = to_paper_basis(np.asarray(alpha_l)).reshape(C, D, 4)
    noise_draws = noise_flat.reshape(C, D, 3)
    posterior = {n: force[..., i] for i, n in enumerate(FORCE_NAMES)}
    posterior |= {n: piston[..., i] for i, n in enumerate(PISTON_NAMES)}
    posterior |= {n: noise_draws[..., i] for i, n in enumerate(NOISE_NAMES)}
    with warnings.catch_warnings():
        # "More chains than draws" on deliberately short runs: reported by our own rules below.
        warnings.filterwarnings("ignore", message="More chains", category=UserWarning)
        idata = _idata(posterior, test, x0_m, chains)
        diagnostics = convergence(idata, chains, list(posterior))
    return PressureFit(
        test,
        x0_m,
        pr.lsq_f,
        pr.lsq_l,
        force,
        piston,
        noise_draws,
        chains,
        idata,
        diagnostics,
        ref_force,
        pr.noise,
    )


def _idata(posterior, test, x0_m, chains):
    return az.from_dict(
        posterior=posterior,
        observed_data={"force_N": test.force_N, "piston_m": test.piston_m},
        constant_data={
            "height_m": test.height_m,
            "pressure_bar": np.array(test.pressure_bar),
            "x0_m": np.array(x0_m),
        },
        sample_stats={"lp": chains.log_prob},
        attrs={
            "n_ensembles": chains.n_ensembles,
            "n_walkers": chains.n_walkers,
            "draw_order": "each chain is one emcee ensemble; draw = step * n_walkers + walker",
            "sampler": "emcee (DE, DE-snooker and independence-t moves), coefficients drawn exactly",
        },
    )


@dataclass(eq=False, frozen=True)
class CampaignFit:
    recordings: Recordings
    tests: list[PressureFit]
    seed: int

    @property
    def converged(self) -> bool:
        return all(t.diagnostics["converged"] for t in self.tests)

    def at(self, pressure_bar: float) -> PressureFit:
        for t in self.tests:
            if abs(t.pressure_bar - pressure_bar) < 1e-9:
                return t
        raise KeyError(pressure_bar)


def test_seeds(seed: int, n: int) -> list[int]:
    """Independent per-test seeds derived from one campaign seed."""
    return [int(s.generate_state(1)[0]) for s in np.random.SeedSequence(seed).spawn(n)]


def fit_campaign(
    recordings: Recordings, *, seed: int = 0, settings: Settings = Settings()
) -> CampaignFit:
    """Fit every test of a campaign: one emcee run samples all tests in lockstep, each with its
    own ensembles and convergence checks (:func:`fit_tests`). ``uq fit`` is this plus
    :func:`uq.fit_json`.

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
        recordings.tests, recordings.x0_m, seed=seed, settings=settings, desc="sampling all tests"
    )
    return CampaignFit(recordings, fits, seed)
