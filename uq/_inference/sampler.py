"""emcee driver and ArviZ diagnostics: the stateful edge around pure log-probabilities.

``run_ensembles`` runs ``n_ensembles`` (default 4) independent emcee ensembles from
overdispersed starts and extends them in chunks until every convergence rule passes on the
sampled parameters, or ``max_steps`` is reached (then the warnings name each rule that failed).
``run_many`` does the same for K problems at once (the tests of a campaign). All ensembles of
all problems are walker groups of one emcee sampler whose moves never mix groups (``_Grouped``),
so each move costs one vectorised log-probability call for everything, not one per ensemble.
The moves (``INDEPENDENCE_MIX``): mostly independence Metropolis-Hastings from a Student t
fitted to the other half of the walker's ensemble (``_GroupedIndependence``, the parametric
form of emcee's KDEMove), with emcee's DE and DE-snooker moves; ensembles too small to fit that
proposal use DE moves only (``effective_mix``). The rules, per problem:

* tau:        the chain after burn-in (``burn_tau`` tau) is at least ``tau_multiple`` (50)
              integrated autocorrelation times long (emcee's estimator, the largest over
              ensembles and parameters);
* R-hat:      rank-normalised split R-hat <= 1.01 (ArviZ);
* ESS:        bulk and tail effective sample size >= 400;
* acceptance: mean acceptance fraction in 0.15..0.6 (running longer does not change it, so a
              failure here is reported but does not extend the run). With independence
              proposals in the move mixture only the lower bound applies: there a high
              acceptance means the proposal fits the posterior, not that the steps are tiny.

How the walkers are shown to ArviZ, and why. The walkers of one emcee ensemble are coupled
(every proposal is built from other walkers), so they are not independent chains; emcee's and
ArviZ's authors both warn against giving walkers to R-hat/ESS as chains (emcee docs and
dfm/emcee#279; arviz-devs/arviz#977 and #2156). What they recommend instead is several
independently started ensembles (Buchner's autoemcee: four) compared with each other:

* Storage: each ensemble is one ArviZ chain and its draws are in time order, the walkers of
  one step next to each other (emcee's ``get_chain(flat=True)`` order): ``samples`` is
  (n_ensembles, n_steps * n_walkers, dim). ArviZ's split R-hat therefore compares the first
  half of the run with the second half (a drift is seen) and the ensembles with each other (a
  stuck ensemble is seen).
* ESS: the draw-to-draw autocorrelation of such a chain is not what limits the information
  (neighbouring draws are different walkers), so ArviZ's ESS of it would count every draw as
  independent. ESS is computed by ArviZ on the ensemble-mean chains m_c(t) (mean over the
  walkers of ensemble c at step t), which carry every cross-walker correlation, and converted
  to draws by the definition ESS = Var(x) / MCSE^2 = ESS_ArviZ(m) * Var(x) / Var(m). With
  independent walkers this equals emcee's n_steps * n_walkers / tau; with coupled walkers it is
  smaller, never inflated by the number of walkers. Bulk ESS does this on the rank-normalised
  draws, tail ESS on the indicators of the 5 % and 95 % quantiles (as ArviZ defines them), and
  the MCSE of the mean is ArviZ's MCSE of the ensemble-mean chains.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import warnings
from dataclasses import dataclass

import arviz as az
import emcee
import numpy as np
from scipy import stats

RHAT_MAX = 1.01
ESS_MIN = 400.0
ACCEPT_RANGE = (0.15, 0.6)


@dataclass(frozen=True)
class Settings:
    """Sampler settings (all seeded; defaults suit 1-10 sampled parameters).

    Walkers start at ``center + init_spread * init_scale * scale * N(0, 1)``: callers pass
    ``scale`` such that ``init_scale * scale`` is about the posterior width, so the starts are
    ``init_spread`` (3) posterior widths wide, overdispersed, and drawn afresh per ensemble.
    """

    n_walkers: int = 32
    n_ensembles: int = 4
    tau_multiple: float = 50.0
    burn_tau: float = 5.0
    chunk: int = 200
    min_steps: int = 200
    max_steps: int = 20000
    init_scale: float = 0.05
    init_spread: float = 3.0

    def validate(self) -> None:
        from uq._io.errors import InputError

        if self.n_ensembles < 2:
            raise InputError(
                "option --ensembles: at least 2 independent ensembles are needed for R-hat (4 recommended)"
            )
        if self.n_walkers < 4 or self.n_walkers % 4:
            raise InputError(
                "option --walkers: a multiple of 4 walkers, at least 4, is needed (emcee's snooker "
                "move splits each ensemble in four)"
            )
        if self.max_steps < 10:
            raise InputError("option --max-steps: at least 10 steps")

    def require_walkers(self, ndim: int) -> None:
        """emcee's red-blue moves need at least two walkers per sampled dimension."""
        from uq._io.errors import InputError

        if self.n_walkers < 2 * ndim:
            need = 4 * math.ceil(2 * ndim / 4)
            raise InputError(
                f"option --walkers: {self.n_walkers} walkers are fewer than twice the {ndim} sampled "
                f"parameters of this model; use at least {need}"
            )


@dataclass(frozen=True)
class Chains:
    """Post-burn-in samples, one chain per ensemble in time order.

    ``samples`` (n_ensembles, n_steps_kept * n_walkers, dim): draw ``t * n_walkers + w`` is
    walker w at kept step t. ``log_prob`` (n_ensembles, same draws). ``start`` (n_ensembles,
    n_walkers, dim) the initial positions.
    """

    names: tuple[str, ...]
    samples: np.ndarray
    log_prob: np.ndarray
    acceptance: np.ndarray  # (n_ensembles * n_walkers,)
    tau: np.ndarray  # (n_dim,) max over ensembles
    n_steps: int
    burn: int
    n_ensembles: int
    warnings: tuple[str, ...] = ()
    n_walkers: int = 1
    start: np.ndarray | None = None
    accept_range: tuple[float, float] = ACCEPT_RANGE

    def by_walker(self, arr: np.ndarray) -> np.ndarray:
        """(n_ensembles, draws, ...) in storage order -> (n_ensembles, steps, n_walkers, ...)."""
        C, D = arr.shape[:2]
        return arr.reshape(C, D // self.n_walkers, self.n_walkers, *arr.shape[2:])


def thin(chains: Chains, max_total: int) -> Chains:
    """Keep every k-th step (all walkers) so that at most about ``max_total`` samples remain.

    Steps closer than an autocorrelation time carry little extra information; thinning keeps
    the exact coefficient draws and derived bands cheap. Whole steps are kept so the storage
    order (steps x walkers) that the diagnostics rely on survives.
    """
    C, D = chains.samples.shape[:2]
    k = max(1, int(np.ceil(C * D / max_total)))
    if k == 1:
        return chains

    def keep(a):
        w = chains.by_walker(a)[:, ::k]
        return w.reshape(C, -1, *a.shape[2:])

    return dataclasses.replace(chains, samples=keep(chains.samples), log_prob=keep(chains.log_prob))


class _Grouped:
    """Mixin for emcee's red-blue moves: propose within each group of walkers only.

    One emcee sampler holds every ensemble of every problem: walker ``j`` belongs to group
    ``j // group_size``. With the split fixed (walker j in sub-ensemble j % nsplits, the
    original Goodman-Weare scheme), each sub-ensemble holds ``group_size / nsplits`` walkers of
    every group, in group order, so the rows of emcee's sample and complement sets are cut
    into groups (``_groups``) and each walker's proposal uses its own group's complement only.
    The groups are therefore independent ensembles; emcee's ``propose`` (the split, the
    per-walker accept step, the update) is unchanged, and the log-probability of all groups
    is one vectorised call per sub-ensemble. The proposals are emcee's, vectorised over the
    groups (with one group, ``_GroupedDE`` draws exactly emcee's DEMove proposal; tested).
    """

    def __init__(self, group_size: int, **kwargs):
        self.group_size = int(group_size)
        super().__init__(randomize_split=False, **kwargs)

    def _groups(self, s, c):
        """(G, per, D) views of the walkers to move and of each complement set."""
        per = self.group_size // self.nsplits
        G = s.shape[0] // per
        return s.reshape(G, per, -1), [cj.reshape(G, per, -1) for cj in c]


class _GroupedDE(_Grouped, emcee.moves.DEMove):
    """emcee's DEMove (Nelson et al. 2013) with the difference vector from the walker's group."""

    def get_proposal(self, s, c, random):
        sg, cg = self._groups(s, c)
        cg = np.concatenate(cg, axis=1)  # (G, nc, D)
        G, ns, _ = sg.shape
        pairs = _nondiagonal_pairs(cg.shape[1])
        pick = pairs[random.choice(pairs.shape[0], size=G * ns, replace=True)].reshape(G, ns, 2)
        rows = np.arange(G)[:, None]
        diffs = cg[rows, pick[..., 1]] - cg[rows, pick[..., 0]]  # (G, ns, D)
        gamma = self.g0 * (1 + self.sigma * random.randn(G * ns, 1))
        return s + gamma * diffs.reshape(G * ns, -1), np.zeros(G * ns, dtype=np.float64)


class _GroupedSnooker(_Grouped, emcee.moves.DESnookerMove):
    """emcee's DESnookerMove (ter Braak & Vrugt 2008) with z, z1, z2 from the walker's group."""

    def get_proposal(self, s, c, random):
        sg, cg = self._groups(s, c)
        G, ns, ndim = sg.shape
        rows = np.arange(G)[:, None]
        # one walker from each of the three complement sets, in random order
        w = np.stack(
            [cj[rows, random.randint(cj.shape[1], size=(G, ns))] for cj in cg], axis=2
        )  # (G, ns, 3, D)
        order = np.argsort(random.rand(G, ns, 3), axis=2)
        w = np.take_along_axis(w, order[..., None], axis=2)
        z, z1, z2 = w[:, :, 0], w[:, :, 1], w[:, :, 2]
        delta = sg - z
        norm = np.linalg.norm(delta, axis=-1, keepdims=True)
        u = delta / np.sqrt(norm)
        q = sg + u * self.gammas * (
            np.sum(u * z1, -1, keepdims=True) - np.sum(u * z2, -1, keepdims=True)
        )
        metropolis = np.log(np.linalg.norm(q - z, axis=-1)) - np.log(norm[..., 0])
        return q.reshape(G * ns, ndim), (0.5 * (ndim - 1.0) * metropolis).reshape(-1)


class _GroupedIndependence(_Grouped, emcee.moves.RedBlueMove):
    """Independence Metropolis-Hastings from a multivariate Student t (``df``) with the mean and
    covariance of the walker's group's complement: the parametric cousin of emcee's KDEMove.

    The proposal depends on the complement only, which is held fixed while the walker moves, so
    the red-blue update keeps the target invariant (as KDEMove's); the Metropolis factor is
    log q(x) - log q(x'). Where the posterior of the sampled parameters is near Gaussian (the
    noise scales of a collapsed model), most proposals are accepted and each is a fresh draw,
    so the autocorrelation time falls well below that of the DE moves; the DE moves stay in
    the mixture for posteriors that are not. A group whose complement has collapsed (no
    positive-definite covariance) stays where it is for this move."""

    def __init__(self, group_size: int, df: float = 5.0):
        self.df = float(df)
        super().__init__(group_size)

    def get_proposal(self, s, c, random):
        sg, cg = self._groups(s, c)
        cg = np.concatenate(cg, axis=1)  # (G, nc, D)
        G, ns, D = sg.shape
        mean = cg.mean(axis=1, keepdims=True)
        dev = cg - mean
        cov = np.einsum("gni,gnj->gij", dev, dev) / (cg.shape[1] - 1)
        try:
            chol = np.linalg.cholesky(cov)
        except np.linalg.LinAlgError:
            return s.copy(), np.zeros(G * ns)
        z = random.randn(G, ns, D)
        w = np.sqrt(self.df / random.chisquare(self.df, size=(G, ns, 1)))
        q = mean + w * np.einsum("gij,gnj->gni", chol, z)

        def log_q(x):  # up to a constant, which cancels in the factor
            y = np.linalg.solve(chol[:, None], (x - mean)[..., None])[..., 0]
            return -0.5 * (self.df + D) * np.log1p(np.sum(y * y, axis=-1) / self.df)

        return q.reshape(G * ns, D), (log_q(sg) - log_q(q)).reshape(-1)


@functools.lru_cache(maxsize=16)
def _nondiagonal_pairs(n: int) -> np.ndarray:
    """Ordered pairs (i, j), i != j, of n walkers, in emcee's DEMove order (read-only, cached: every
    move of a run asks for the same n)."""
    rows, cols = np.tril_indices(n, -1)
    pairs = np.column_stack([np.concatenate([rows, cols]), np.concatenate([cols, rows])])
    pairs.flags.writeable = False
    return pairs


#: Move mixtures (weights of DE, DE-snooker, independence t). The default mixes mostly
#: independence proposals fitted to the rest of the walker's ensemble with DE moves: the sampled
#: parameters of every model here are a few noise scales and magnitudes whose posterior is near
#: Gaussian, where a fitted proposal is accepted often and each acceptance is a fresh draw. On
#: data/n50 (32 walkers per ensemble) the per-pressure cubics meet their rules within the 200-step
#: floor (about 850 steps with DE moves alone) and the surface's five noise parameters after about
#: 1500 steps instead of 4500. The DE
#: moves stay in the mixture so that a posterior far from Gaussian is still explored.
#: ``DE_MIX`` is the mixture without independence proposals.
DE_MIX = (0.8, 0.2, 0.0)
INDEPENDENCE_MIX = (0.2, 0.1, 0.7)


def min_walkers_for_independence(ndim: int) -> int:
    """Smallest ensemble for which the independence move is used: its proposal's mean and
    covariance come from the other half of the ensemble, which must hold at least 2 (ndim + 1)
    walkers (with fewer, e.g. 8 walkers for the surface's 5 parameters, the fitted covariance is
    too rough and the acceptance falls to about 0.15); below that the move's weight goes to DE."""
    return 4 * (ndim + 1)


def effective_mix(
    mix: tuple[float, float, float], group_size: int, ndim: int
) -> tuple[float, float, float]:
    """``mix`` as it is used for ensembles of ``group_size`` walkers in ``ndim`` dimensions."""
    de, snooker, ind = mix
    if ind > 0 and group_size < min_walkers_for_independence(ndim):
        return (de + ind, snooker, 0.0)
    return mix


def _moves(group_size: int, mix: tuple[float, float, float]):
    moves = (_GroupedDE(group_size), _GroupedSnooker(group_size), _GroupedIndependence(group_size))
    return [(m, w) for m, w in zip(moves, mix, strict=True) if w > 0]


def _tau(chain: np.ndarray) -> np.ndarray:
    """Integrated autocorrelation time per dimension; chain (steps, walkers, dim).

    A walker that never moved in the window has no autocorrelation function (0/0): NaN, which
    the tau rule counts as failed.
    """
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return emcee.autocorr.integrated_time(chain, tol=0, quiet=True)


def _starts(log_prob, centers, widths, n_walkers: int, rng, tries: int = 20) -> np.ndarray:
    """Overdispersed starting walkers with finite log-probability (bad draws redrawn).

    ``log_prob`` maps (K, m, D) -> (K, m); centers, widths (K, D); returns (K, n_walkers, D).
    After ``tries`` rounds the remaining bad walkers are drawn ever closer to their problem's
    center (halving the spread), which is finite by construction of the callers (an optimum).
    """
    K, D = centers.shape

    def draw(shrink, shape):
        return centers[:, None, :] + shrink * widths[:, None, :] * rng.standard_normal(shape)

    p0 = draw(1.0, (K, n_walkers, D))
    shrink = 1.0
    for i in range(2 * tries):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            bad = ~np.isfinite(np.asarray(log_prob(p0), float))
        if not bad.any():
            return p0
        if i >= tries:
            shrink *= 0.5
        p0 = np.where(bad[..., None], draw(shrink, p0.shape), p0)
    return np.where(bad[..., None], draw(1e-6, p0.shape), p0)


def run_ensembles(
    log_prob,
    center,
    scale,
    names,
    *,
    seed: int,
    settings: Settings = Settings(),
    desc: str | None = None,
    mix: tuple[float, float, float] = INDEPENDENCE_MIX,
) -> Chains:
    """Sample ``log_prob`` (vectorised: (W, D) -> (W,)) with emcee until the rules pass.

    ``center`` is the optimiser's solution and ``settings.init_scale * scale`` an estimate of
    the posterior width per dimension; see the module docstring for the rules and storage.
    ``desc``: show a progress bar of the steps (uq._io.progress; on a terminal only) under this name.
    ``mix``: the weights of the moves (``INDEPENDENCE_MIX``, ``DE_MIX``; see :func:`effective_mix`).
    """

    def many(thetas):  # (1, m, D) -> (1, m)
        return np.asarray(log_prob(thetas[0]))[None]

    return run_many(
        many,
        np.asarray(center, float)[None],
        np.asarray(scale, float)[None],
        names,
        seed=seed,
        settings=settings,
        desc=desc,
        mix=mix,
    )[0]


def run_many(
    log_prob,
    centers,
    scales,
    names,
    *,
    seed: int,
    settings: Settings = Settings(),
    desc: str | None = None,
    mix: tuple[float, float, float] = INDEPENDENCE_MIX,
) -> list[Chains]:
    """Sample K problems of the same dimension D at once: one emcee sampler, one call per move.

    ``log_prob`` maps (K, m, D) -> (K, m): row k of the walkers is evaluated under problem k
    (e.g. one jitted, vmapped log-probability over all tests of a campaign). centers, scales
    (K, D). Every problem gets ``settings.n_ensembles`` independent ensembles of
    ``settings.n_walkers`` walkers (see ``_Grouped``), and the run is extended until every
    problem passes every rule, or ``max_steps``. Returns one :class:`Chains` per problem, with
    its own burn-in, tau and warnings.
    """
    from uq._io.progress import _Silent, progress

    # No total: the run stops when the rules pass, usually far below max_steps, so a bar to
    # max_steps would show an ETA many times too long. It counts steps and their rate instead.
    with progress(desc=desc, unit="step") if desc else _Silent(None) as bar:
        return _run_many(log_prob, centers, scales, names, seed, settings, bar, mix)


def _run_many(
    log_prob, centers, scales, names, seed: int, settings: Settings, bar, mix
) -> list[Chains]:
    settings.validate()
    centers = np.atleast_2d(np.asarray(centers, float))
    K, ndim = centers.shape
    settings.require_walkers(ndim)
    widths = (
        settings.init_spread
        * settings.init_scale
        * np.broadcast_to(np.asarray(scales, float), centers.shape)
    )
    E, W = settings.n_ensembles, settings.n_walkers
    rng = np.random.default_rng(seed)
    # Walker order: problem, ensemble, walker; each ensemble's start is drawn afresh.
    start = np.stack(
        [_starts(log_prob, centers, widths, W, rng) for _ in range(E)], axis=1
    )  # (K, E, W, D)

    def flat_log_prob(q):  # emcee's (rows, D), rows in walker order -> (rows,)
        return np.asarray(log_prob(q.reshape(K, -1, ndim)), float).reshape(-1)

    mix = effective_mix(mix, W, ndim)
    sampler = emcee.EnsembleSampler(
        K * E * W, ndim, flat_log_prob, vectorize=True, moves=_moves(W, mix)
    )
    accept_range = (ACCEPT_RANGE[0], 1.0) if mix[2] > 0 else ACCEPT_RANGE
    sampler.random_state = np.random.RandomState(rng.integers(2**31)).get_state()
    state = start.reshape(-1, ndim)
    n_steps, target = 0, settings.min_steps
    while True:
        step = max(1, min(target, settings.max_steps) - n_steps)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # -inf log-prob proposals
            state = sampler.run_mcmc(state, step, progress=False)
        n_steps += step
        bar.update(step)
        chains = [
            _collect(sampler, k, names, settings, n_steps, start[k], accept_range) for k in range(K)
        ]
        verdicts = [_failed_rules(c, settings, full=False) for c in chains]
        n_failed = sum(bool(f) for f, _ in verdicts)
        bar.set_postfix_str(f"{n_failed} problem(s) not yet converged" if n_failed else "converged")
        if not n_failed:
            return chains
        want = max(w for f, w in verdicts if f)
        if n_steps >= settings.max_steps or want <= n_steps:
            verdicts = [_failed_rules(c, settings) for c in chains]
            return [
                dataclasses.replace(c, warnings=tuple(f))
                for c, (f, _) in zip(chains, verdicts, strict=True)
            ]
        target = max(want, n_steps + settings.chunk // 4)


def _collect(
    sampler, k: int, names, settings: Settings, n_steps: int, start, accept_range
) -> Chains:
    """Problem k's burn-in from its current tau, its post-burn chains in storage order, its tau."""
    E, W = settings.n_ensembles, settings.n_walkers
    cols = slice(k * E * W, (k + 1) * E * W)
    chain = sampler.get_chain()[:, cols]  # (steps, E * W, dim)
    logp = sampler.get_log_prob()[:, cols]
    raw = [chain[:, e * W : (e + 1) * W] for e in range(E)]
    # tau from the second half: the overdispersed start's transient would inflate it
    tau = np.max([_tau(c[n_steps // 2 :]) for c in raw], axis=0)
    tau_max = float(np.max(tau)) if np.all(np.isfinite(tau)) else math.inf
    burn = int(math.ceil(settings.burn_tau * tau_max)) if math.isfinite(tau_max) else n_steps // 2
    burn = min(max(burn, 20), n_steps // 2)
    samples = np.stack([c[burn:].reshape(-1, c.shape[-1]) for c in raw])
    lp = np.stack([logp[burn:, e * W : (e + 1) * W].reshape(-1) for e in range(E)])
    accept = sampler.acceptance_fraction[cols]
    return Chains(
        tuple(names), samples, lp, accept, tau, n_steps, burn, E, (), W, start, accept_range
    )


def _failed_rules(chains: Chains, settings: Settings, full: bool = True) -> tuple[list[str], int]:
    """Messages for the rules that fail on the sampled parameters, and the length they ask for.

    ``full=False``: when the (cheap) tau rule already fails, stop there; R-hat and ESS on a chain
    that short would fail too and only cost time. Final verdicts are always full.
    """
    n, tau = chains.n_steps, float(np.max(chains.tau))
    need = settings.burn_tau + settings.tau_multiple
    msgs, want = [], n
    if not math.isfinite(tau) or n - chains.burn < settings.tau_multiple * tau:
        msgs.append(
            f"chain of {n} steps is shorter than burn-in + {settings.tau_multiple:g} autocorrelation times "
            f"(tau = {tau:.1f}): raise --max-steps or use more walkers"
        )
        want = int(math.ceil(1.1 * need * (tau if math.isfinite(tau) else n)))
        if not full:
            return msgs, want
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # "more chains than draws" on very short runs: judged below
        diag = {
            nm: chain_diagnostics(chains.samples[..., i], chains.n_walkers)
            for i, nm in enumerate(chains.names)
        }
    msgs += _rule_warnings(diag)
    rh = _worst([d["r_hat"] for d in diag.values()], max)
    ess = _worst([min(d["ess_bulk"], d["ess_tail"]) for d in diag.values()], min)
    if not (rh <= RHAT_MAX):
        want = max(want, int(1.5 * n))
    if not (ess >= ESS_MIN):
        # ESS grows in proportion to the post-burn length
        factor = 1.2 * ESS_MIN / ess if ess > 0 else 2.0
        want = max(want, chains.burn + int(math.ceil(min(factor, 4.0) * (n - chains.burn))))
    msgs += _acceptance_warnings(chains.acceptance, chains.accept_range)
    return msgs, want


def _worst(values, pick):
    """``pick`` (max or min) of the values, NaN if any is NaN (an undefined statistic fails its rule)."""
    v = np.asarray(values, float)
    return float("nan") if np.any(np.isnan(v)) else float(pick(v))


def _ess_of_summary(x: np.ndarray, per_step: np.ndarray) -> float:
    """Draw-scale ESS of the ensemble-mean chains ``per_step`` (C, T) summarising ``x``."""
    var_m = float(np.var(per_step))
    if not var_m > 0:
        return float("nan")
    ess_m = float(az.ess(np.ascontiguousarray(per_step), method="mean"))
    return min(ess_m * float(np.var(x)) / var_m, float(x.size))


def bulk_ess(x: np.ndarray, n_walkers: int) -> float:
    """Bulk ESS of one scalar, x (n_ensembles, steps * walkers) in storage order (one ensemble
    is enough): ArviZ's rank normalisation, then the ensemble-mean chains (module docstring)."""
    x = np.asarray(x, float)
    ranks = stats.rankdata(x, axis=None).reshape(x.shape)
    z = stats.norm.ppf((ranks - 0.375) / (x.size + 0.25))  # ArviZ's rank normalisation
    return _ess_of_summary(z, z.reshape(x.shape[0], -1, n_walkers).mean(axis=2))


def chain_diagnostics(x: np.ndarray, n_walkers: int) -> dict:
    """R-hat, bulk/tail ESS and MCSE of the mean of one scalar; x (n_ensembles, steps * walkers).

    ArviZ computes each statistic; see the module docstring for what it is given and why.
    """
    x = np.asarray(x, float)
    C = x.shape[0]
    xw = x.reshape(C, -1, n_walkers)
    r_hat = float(az.rhat(np.ascontiguousarray(x)))
    ess_bulk = bulk_ess(x, n_walkers)
    tail = []
    for q in (0.05, 0.95):
        ind = (x <= np.quantile(x, q)).astype(float)
        tail.append(_ess_of_summary(ind, ind.reshape(xw.shape).mean(axis=2)))
    mcse = float(az.mcse(np.ascontiguousarray(xw.mean(axis=2)), method="mean"))
    return {
        "r_hat": r_hat,
        "ess_bulk": ess_bulk,
        "ess_tail": float(np.min(tail)),
        "mcse_mean": mcse,
    }


def _rule_warnings(diag: dict) -> list[str]:
    warns = []
    for n, d in diag.items():
        r = d["r_hat"]
        if not (r <= RHAT_MAX):
            warns.append(
                f"{n}: R-hat {r:.3f} > {RHAT_MAX}: chains disagree; run longer (--max-steps) or use more walkers"
            )
        e = min(d["ess_bulk"], d["ess_tail"])
        if not (e >= ESS_MIN):
            warns.append(
                f"{n}: effective sample size {e:.0f} < {ESS_MIN:.0f}: run longer (--max-steps) or use more walkers"
            )
    return warns


def _acceptance_warnings(acc: np.ndarray, accept_range: tuple[float, float]) -> list[str]:
    lo, hi = accept_range
    if lo <= acc.mean() <= hi:
        return []
    return [
        f"acceptance fraction {acc.mean():.2f} outside {lo:g}-{hi:g}: the sampler is stuck or the posterior is "
        "badly scaled; check the model and start"
    ]


def convergence(
    idata: az.InferenceData, chains: Chains, var_names: list[str] | None = None
) -> dict:
    """ArviZ diagnostics and the project's convergence rules for the stored variables.

    Returns a dict with per-variable r_hat, ess_bulk, ess_tail, mcse_mean; the sampler's
    tau, acceptance fractions, steps and burn-in; ``converged`` and ``warnings`` (the
    sampler's own failed rules first, then those of the derived variables).
    """
    post = idata.posterior
    names = var_names or list(post.data_vars)
    per_var, diag = {}, {}
    for n in names:
        arr = np.asarray(post[n])  # (chains, draws, ...)
        flat = arr.reshape(arr.shape[0], arr.shape[1], -1)
        ds = [chain_diagnostics(flat[..., j], chains.n_walkers) for j in range(flat.shape[-1])]
        per_var[n] = {
            k: (float(ds[0][k]) if len(ds) == 1 else [float(d[k]) for d in ds]) for k in ds[0]
        }
        diag[n] = {
            "r_hat": _worst([d["r_hat"] for d in ds], max),
            "ess_bulk": _worst([d["ess_bulk"] for d in ds], min),
            "ess_tail": _worst([d["ess_tail"] for d in ds], min),
        }
    warns = list(chains.warnings)
    warns += [
        w
        for w in _rule_warnings(diag) + _acceptance_warnings(chains.acceptance, chains.accept_range)
        if w not in warns
    ]
    acc = chains.acceptance
    return {
        "converged": not warns,
        "warnings": warns,
        "n_steps": chains.n_steps,
        "burn_in": chains.burn,
        "n_chains": int(chains.samples.shape[0]),
        "n_walkers": int(chains.n_walkers),
        "n_draws": int(chains.samples.shape[1]),
        "tau": {n: float(t) for n, t in zip(chains.names, chains.tau, strict=True)},
        "acceptance_fraction": {
            "mean": float(acc.mean()),
            "min": float(acc.min()),
            "max": float(acc.max()),
        },
        "variables": per_var,
    }
