"""emcee driver and ArviZ diagnostics: the stateful edge around pure log-probabilities.

``run_ensembles`` runs at least two independent emcee ensembles from a start near the
optimum, extends them in chunks until the chain after burn-in is at least ``tau_multiple``
integrated autocorrelation times long (emcee's estimator), and returns the post-burn-in
chains. ``convergence`` computes R-hat, bulk/tail ESS and MCSE with ArviZ and applies the
project's rules (R-hat <= 1.01, ESS >= 400, acceptance fraction in 0.15..0.6, chain >= 50
tau), returning warnings a user can act on.
"""

from __future__ import annotations

import dataclasses
import math
import warnings
from dataclasses import dataclass, field

import arviz as az
import emcee
import numpy as np

RHAT_MAX = 1.01
ESS_MIN = 400.0
ACCEPT_RANGE = (0.15, 0.6)


@dataclass
class Settings:
    """Sampler settings (all seeded; defaults suit 1-10 sampled parameters)."""

    n_walkers: int = 16
    n_ensembles: int = 2
    tau_multiple: float = 50.0
    burn_tau: float = 5.0
    chunk: int = 200
    min_steps: int = 400
    max_steps: int = 20000
    init_scale: float = 0.05

    def validate(self) -> None:
        from ._errors import InputError

        if self.n_ensembles < 2:
            raise InputError("option --ensembles: at least 2 independent ensembles are needed for R-hat")
        if self.n_walkers < 4 or self.n_walkers % 2:
            raise InputError("option --walkers: an even number of at least 4 walkers is needed")
        if self.max_steps < 10:
            raise InputError("option --max-steps: at least 10 steps")


@dataclass
class Chains:
    """Post-burn-in samples. ``samples`` (n_ensembles * n_walkers, n_draws, n_dim)."""

    names: tuple[str, ...]
    samples: np.ndarray
    log_prob: np.ndarray  # (chains, draws)
    acceptance: np.ndarray  # (chains,)
    tau: np.ndarray  # (n_dim,) max over ensembles
    n_steps: int
    burn: int
    n_ensembles: int
    warnings: list[str] = field(default_factory=list)


def thin(chains: Chains, max_total: int) -> Chains:
    """Keep every k-th draw so that at most about ``max_total`` samples remain.

    Draws closer than an autocorrelation time carry little extra information; thinning keeps
    the exact coefficient draws and derived bands cheap without changing the diagnostics.
    """
    C, D = chains.samples.shape[:2]
    k = max(1, int(np.ceil(C * D / max_total)))
    if k == 1:
        return chains
    return dataclasses.replace(chains, samples=chains.samples[:, ::k], log_prob=chains.log_prob[:, ::k])


def _moves():
    # Differential-evolution moves mix better than the stretch move in few dimensions.
    return [(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)]


def _tau(chain: np.ndarray) -> np.ndarray:
    """Integrated autocorrelation time per dimension; chain (steps, walkers, dim)."""
    return emcee.autocorr.integrated_time(chain, tol=0, quiet=True)


def run_ensembles(log_prob, center, scale, names, *, seed: int, settings: Settings = Settings()) -> Chains:
    """Sample ``log_prob`` (vectorised: (W, D) -> (W,)) with emcee.

    Walkers start at ``center + settings.init_scale * scale * N(0, 1)``: ``center`` is the
    optimiser's solution and ``scale`` a per-dimension step (e.g. posterior sd estimate).
    """
    settings.validate()
    center = np.asarray(center, float)
    scale = np.asarray(scale, float)
    ndim = center.size
    rng = np.random.default_rng(seed)
    samplers, states = [], []
    for _ in range(settings.n_ensembles):
        s = emcee.EnsembleSampler(settings.n_walkers, ndim, log_prob, vectorize=True, moves=_moves())
        s.random_state = np.random.RandomState(rng.integers(2**31)).get_state()
        p0 = center + settings.init_scale * scale * rng.standard_normal((settings.n_walkers, ndim))
        samplers.append(s)
        states.append(p0)
    n_steps = 0
    next_step = settings.min_steps
    warns: list[str] = []
    while True:
        step = min(next_step, settings.max_steps - n_steps)
        for i, s in enumerate(samplers):
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)  # -inf log-prob proposals
                states[i] = s.run_mcmc(states[i], step, progress=False)
        n_steps += step
        chains = [s.get_chain() for s in samplers]
        tau = np.max([_tau(c[n_steps // 5 :]) for c in chains], axis=0)
        tau_max = float(np.nanmax(tau)) if np.all(np.isfinite(tau)) else math.inf
        burn = int(math.ceil(settings.burn_tau * tau_max)) if math.isfinite(tau_max) else n_steps // 2
        burn = min(max(burn, 20), n_steps // 2)
        if math.isfinite(tau_max) and n_steps - burn >= settings.tau_multiple * tau_max:
            break
        # Extend straight to the length the current tau asks for (+10 %), at least one chunk/4.
        needed = (settings.burn_tau + settings.tau_multiple) * (tau_max if math.isfinite(tau_max) else n_steps)
        next_step = max(int(math.ceil(1.1 * needed)) - n_steps, settings.chunk // 4)
        if n_steps >= settings.max_steps:
            warns.append(
                f"chain of {n_steps} steps is shorter than burn-in + {settings.tau_multiple:g} autocorrelation "
                f"times (tau = {tau_max:.1f}): raise --max-steps or use more walkers"
            )
            break
    samples = np.concatenate([np.swapaxes(c[burn:], 0, 1) for c in chains], axis=0)
    logp = np.concatenate([s.get_log_prob()[burn:].T for s in samplers], axis=0)
    accept = np.concatenate([s.acceptance_fraction for s in samplers])
    return Chains(tuple(names), samples, logp, accept, tau, n_steps, burn, settings.n_ensembles, warns)


def convergence(idata: az.InferenceData, chains: Chains, var_names: list[str] | None = None) -> dict:
    """ArviZ diagnostics and the project's convergence rules.

    Returns a dict with per-variable r_hat, ess_bulk, ess_tail, mcse_mean; the sampler's
    tau, acceptance fractions, steps and burn-in; ``converged`` and ``warnings``.
    """
    post = idata.posterior
    names = var_names or list(post.data_vars)
    # R-hat between the independent ensembles: each ensemble is one chain (its walkers laid
    # end to end), which ArviZ splits in halves. Walkers of one ensemble are not independent,
    # so treating them as chains makes R-hat noisy rather than informative.
    n_ens = chains.n_ensembles
    rhat = {}
    for n in names:
        arr = np.asarray(post[n])  # (chains, draws, ...)
        C, D = arr.shape[:2]
        rhat[n] = az.rhat(np.ascontiguousarray(arr.reshape(n_ens, (C // n_ens) * D, *arr.shape[2:])))
    # ESS and MCSE over walkers as chains: their autocorrelation is what limits information.
    ess_b = az.ess(post, var_names=names, method="bulk")
    ess_t = az.ess(post, var_names=names, method="tail")
    mcse = az.mcse(post, var_names=names, method="mean")
    per_var = {}
    warns = list(chains.warnings)
    for n in names:
        r = np.atleast_1d(np.asarray(rhat[n]))
        eb = np.atleast_1d(np.asarray(ess_b[n]))
        et = np.atleast_1d(np.asarray(ess_t[n]))
        per_var[n] = {
            "r_hat": r.tolist() if r.size > 1 else float(r[0]),
            "ess_bulk": eb.tolist() if eb.size > 1 else float(eb[0]),
            "ess_tail": et.tolist() if et.size > 1 else float(et[0]),
            "mcse_mean": np.atleast_1d(np.asarray(mcse[n])).tolist() if np.asarray(mcse[n]).size > 1 else float(mcse[n]),
        }
        if np.any(~np.isfinite(r)) or np.any(r > RHAT_MAX):
            warns.append(f"{n}: R-hat {np.max(r):.3f} > {RHAT_MAX}: chains disagree; run longer (--max-steps) or use more walkers")
        if np.any(~np.isfinite(eb)) or np.any(np.minimum(eb, et) < ESS_MIN):
            warns.append(
                f"{n}: effective sample size {np.min(np.minimum(eb, et)):.0f} < {ESS_MIN:.0f}: run longer (--max-steps) or use more walkers"
            )
    acc = chains.acceptance
    lo, hi = ACCEPT_RANGE
    if acc.mean() < lo or acc.mean() > hi:
        warns.append(
            f"acceptance fraction {acc.mean():.2f} outside {lo}-{hi}: the sampler is stuck or the posterior is badly scaled; check the model and start"
        )
    return {
        "converged": not warns,
        "warnings": warns,
        "n_steps": chains.n_steps,
        "burn_in": chains.burn,
        "n_chains": int(chains.samples.shape[0]),
        "n_draws": int(chains.samples.shape[1]),
        "tau": {n: float(t) for n, t in zip(chains.names, chains.tau, strict=True)},
        "acceptance_fraction": {"mean": float(acc.mean()), "min": float(acc.min()), "max": float(acc.max())},
        "variables": per_var,
    }
