"""emcee driver: the stateful edge around pure log-probabilities.

``run_many`` samples K problems at once (the tests of a campaign, or one model): every problem gets
``n_ensembles`` (default 4) independent emcee ensembles from overdispersed starts, extended in
chunks until every convergence rule (``uq._inference.convergence``) passes on the sampled
parameters, or ``max_steps`` is reached (then the verdict names each rule that failed). All
ensembles of all problems are walker groups of one emcee sampler whose moves never mix groups
(``_Grouped``), so each move costs one vectorised log-probability call for everything, not one per
ensemble. The moves (``INDEPENDENCE_MIX``): mostly independence Metropolis-Hastings from a Student
t fitted to the other half of the walker's ensemble (``_GroupedIndependence``, the parametric form
of emcee's KDEMove), with emcee's DE and DE-snooker moves; ensembles too small to fit that
proposal use DE moves only (``effective_mix``). The snooker move is ter Braak & Vrugt's
(2008, Stat. Comput. 18, 435) as upstream emcee has it since dfm/emcee#531 (January 2025), not
as emcee 3.1.6 (the version installed) ships it: 3.1.6's direction is not of unit length and its
Metropolis factor has half the exponent, so it does not keep the target (``_GroupedSnooker``).
Every move is checked to keep a correlated Gaussian's variance within 1.2 %
(tests/inference/test_sampler.py).

Starts: each ensemble is drawn afresh from ``N(center, init_spread^2 cov)``, ``cov`` the caller's
estimate of the posterior covariance (the Laplace approximation at the optimum), so the walkers
start overdispersed by ``init_spread`` (3) posterior widths in every direction, the weakly
identified ones included.

Storage (``Chains``): each ensemble is one chain and its draws are in time order, the walkers of
one step next to each other (emcee's ``get_chain(flat=True)`` order); why, and how R-hat and ESS
are computed on such chains: ``uq._inference.convergence``.
"""

from __future__ import annotations

import dataclasses
import functools
import importlib
import math
import sys
import warnings
from dataclasses import dataclass

import numpy as np

from uq._inference.convergence import ACCEPT_RANGE, failed_rules
from uq._inference.summary import thin_step


def _gaussian_kde(*args, **kwargs):
    """scipy.stats.gaussian_kde, imported when first called (emcee's KDEMove, unused by uq)."""
    return importlib.import_module("scipy.stats").gaussian_kde(*args, **kwargs)


def _import_emcee():
    """emcee, without the import of scipy.stats it makes for its KDEMove alone (``from scipy.stats
    import gaussian_kde``, under ``except ImportError``): about 0.6 CPU s of every ``uq fit``,
    which uses neither. scipy.stats is held out of the import for that moment only (a None in
    ``sys.modules`` makes the import raise ImportError), then emcee's ``gaussian_kde`` is set to
    a function that imports it when called, so a KDEMove still works. Nothing is done when
    scipy.stats or emcee is already imported."""
    if "emcee" in sys.modules or "scipy.stats" in sys.modules:
        return importlib.import_module("emcee")
    sys.modules["scipy.stats"] = None
    try:
        module = importlib.import_module("emcee")
    finally:
        del sys.modules["scipy.stats"]
    kde = sys.modules.get("emcee.moves.kde")
    if kde is not None and getattr(kde, "gaussian_kde", True) is None:
        kde.gaussian_kde = _gaussian_kde
    return module


emcee = _import_emcee()


@dataclass(frozen=True)
class Settings:
    """Sampler settings (all seeded; defaults suit 1-10 sampled parameters).

    Walkers start at ``center + init_spread * chol(cov) @ N(0, I)`` with ``cov`` the caller's
    estimate of the posterior covariance: ``init_spread`` (3) posterior widths wide in every
    direction, overdispersed, and drawn afresh per ensemble.
    """

    n_walkers: int = 32
    n_ensembles: int = 4
    tau_multiple: float = 50.0
    burn_tau: float = 5.0
    chunk: int = 200
    min_steps: int = 200
    max_steps: int = 20000
    init_spread: float = 3.0

    def validate(self) -> None:
        from uq._io.errors import InputError

        if self.n_ensembles < 2:
            raise InputError(
                "n_ensembles: at least 2 independent ensembles are needed for R-hat (4 recommended)",
                param="n_ensembles",
            )
        if self.n_walkers < 4 or self.n_walkers % 4:
            raise InputError(
                "n_walkers: a multiple of 4 walkers, at least 4, is needed (emcee's snooker "
                "move splits each ensemble in four)",
                param="n_walkers",
            )
        if self.max_steps < 10:
            raise InputError("max_steps: at least 10 steps", param="max_steps")

    def require_walkers(self, ndim: int) -> None:
        """emcee's red-blue moves need at least two walkers per sampled dimension."""
        from uq._io.errors import InputError

        if self.n_walkers < 2 * ndim:
            need = 4 * math.ceil(2 * ndim / 4)
            raise InputError(
                f"n_walkers: {self.n_walkers} walkers are fewer than twice the {ndim} sampled "
                f"parameters of this model; use at least {need}",
                param="n_walkers",
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
    problems: tuple = ()  # uq._inference.convergence.Problem, the rules that failed
    n_walkers: int = 1
    start: np.ndarray | None = None
    accept_range: tuple[float, float] = ACCEPT_RANGE

    def by_walker(self, arr: np.ndarray) -> np.ndarray:
        """(n_ensembles, draws, ...) in storage order -> (n_ensembles, steps, n_walkers, ...)."""
        C, D = arr.shape[:2]
        return arr.reshape(C, D // self.n_walkers, self.n_walkers, *arr.shape[2:])


#: steps per walker that thinning keeps at least: the convergence diagnostics treat every walker's
#: steps as a chain, and split-chain ESS needs at least 4 per half (with 4 ensembles of 92 walkers
#: and 1000 draws kept, every 552nd of 1500 steps left 3 a walker and every ESS undefined: NaN,
#: "not converged"). At the default 4000 draws every fit keeps more than this already.
MIN_KEPT_STEPS = 10


def thin(chains: Chains, max_total: int) -> Chains:
    """Keep every k-th step (all walkers) so that at most about ``max_total`` samples remain, but
    at least ``MIN_KEPT_STEPS`` steps per walker (more than ``max_total`` samples then remain; a
    fit's fixed draws are thinned to its own maximum again).

    Steps closer than an autocorrelation time carry little extra information; thinning keeps
    the exact coefficient draws and derived bands cheap. Whole steps are kept so the storage
    order (steps x walkers) that the diagnostics rely on survives.
    """
    C, D = chains.samples.shape[:2]
    steps = D // chains.n_walkers
    k = min(thin_step(C * D, max_total), max(1, steps // MIN_KEPT_STEPS))
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

    def propose(self, model, state):
        """emcee's ``RedBlueMove.propose`` with its per-walker accept loop as one vectorised
        comparison: the same uniforms from ``model.random`` in the same order (``rand(n)`` draws
        the stream that n calls of ``rand()`` draw), the same ``f + lp' - lp > log u`` test, so
        the same chains to the bit (tested); emcee's loop cost about 2 us a walker and step."""
        nwalkers, ndim = state.coords.shape
        if nwalkers < 2 * ndim and not self.live_dangerously:
            raise RuntimeError(
                "It is unadvisable to use a red-blue move with fewer walkers than twice the "
                "number of dimensions."
            )
        self.setup(state.coords)
        accepted = np.zeros(nwalkers, dtype=bool)
        all_inds = np.arange(nwalkers)
        inds = all_inds % self.nsplits
        if self.randomize_split:
            model.random.shuffle(inds)
        for split in range(self.nsplits):
            S1 = inds == split
            sets = [state.coords[inds == j] for j in range(self.nsplits)]
            q, factors = self.get_proposal(
                sets[split], sets[:split] + sets[split + 1 :], model.random
            )
            new_log_probs, new_blobs = model.compute_log_prob_fn(q)
            mine = all_inds[S1]
            n = min(len(mine), len(factors), len(new_log_probs))  # emcee's zip
            lnpdiff = factors[:n] + new_log_probs[:n] - state.log_prob[mine[:n]]
            accepted[mine[:n]] = lnpdiff > np.log(model.random.rand(n))
            state = self.update(
                state, emcee.State(q, log_prob=new_log_probs, blobs=new_blobs), accepted, S1
            )
        return state, accepted

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
    """The DE-snooker update (ter Braak & Vrugt 2008, Stat. Comput. 18, 435) with z, z1, z2 from
    the walker's group: x' = x + gamma (z1_P - z2_P), where z1_P, z2_P are the projections of z1,
    z2 on the line through x and z, and the Metropolis factor is (||x' - z|| / ||x - z||)^(D-1).

    The kernel of upstream emcee (dfm/emcee#531, after 3.1.6), not that of emcee 3.1.6, whose
    direction is (x - z) / sqrt(||x - z||) (not of unit length, so the step grows with the
    distance to z) and whose factor has half the exponent: that kernel does not keep the target
    (a Gaussian's variance falls by about 15 %; tests/inference/test_sampler.py). emcee's
    gamma = 1.7 is kept; the three walkers come one from each complement set, in random order.
    """

    def get_proposal(self, s, c, random):
        sg, cg = self._groups(s, c)
        G, ns, ndim = sg.shape
        rows = np.arange(G)[:, None]
        # one walker from each of the three complement sets, in random order
        # (G, ns, 3, D)
        w = np.stack([cj[rows, random.randint(cj.shape[1], size=(G, ns))] for cj in cg], axis=2)
        order = np.argsort(random.rand(G, ns, 3), axis=2)
        w = np.take_along_axis(w, order[..., None], axis=2)
        z, z1, z2 = w[:, :, 0], w[:, :, 1], w[:, :, 2]
        delta = sg - z
        norm = np.linalg.norm(delta, axis=-1, keepdims=True)
        u = delta / norm  # unit direction: the update moves x along the line through z
        q = sg + u * self.gammas * (
            np.sum(u * z1, -1, keepdims=True) - np.sum(u * z2, -1, keepdims=True)
        )
        metropolis = np.log(np.linalg.norm(q - z, axis=-1)) - np.log(norm[..., 0])
        return q.reshape(G * ns, ndim), ((ndim - 1.0) * metropolis).reshape(-1)


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
        mean = cg.mean(axis=1, keepdims=True)
        dev = cg - mean
        cov = np.einsum("gni,gnj->gij", dev, dev) / (cg.shape[1] - 1)
        try:
            chol = np.linalg.cholesky(cov)
        except np.linalg.LinAlgError:
            return s.copy(), np.zeros(s.shape[0])
        return _t_proposal(sg, mean, chol, self.df, random)


def _t_proposal(sg, mean, chol, df: float, random, warp=None):
    """Independence proposals for walkers ``sg`` (G, ns, D) from a Student t per group (``mean``
    (G, 1, D), lower factor ``chol`` (G, D, D) of its scale, ``df``): the proposals (G ns, D) and
    the Metropolis factors log q(x) - log q(x'). ``warp``: (forward, inverse, log slope) of a map
    of the sampled coordinates, the t being in its image (None: in the sampled coordinates)."""
    G, ns, D = sg.shape
    z = random.randn(G, ns, D)
    w = np.sqrt(df / random.chisquare(df, size=(G, ns, 1)))
    y = mean + w * np.einsum("gij,gnj->gni", chol, z)
    q = y if warp is None else warp[1](y)

    def log_q(x):  # up to a constant, which cancels in the factor
        u = x if warp is None else warp[0](x)
        v = np.linalg.solve(chol[:, None], (u - mean)[..., None])[..., 0]
        out = -0.5 * (df + D) * np.log1p(np.sum(v * v, axis=-1) / df)
        return out if warp is None else out + warp[2](x)

    return q.reshape(G * ns, D), (log_q(sg) - log_q(q)).reshape(-1)


#: the held proposal's degrees of freedom (``_HeldIndependence``): tails heavier than the
#: target's. An independence proposal with lighter tails than its target rarely proposes there and
#: sticks there once accepted, and a finite run's Monte Carlo error misses it: on the banana of
#: tests/inference/test_sampler.py (seeds 4-9) E x2 came out -5.5..+1.6 of its own Monte Carlo
#: standard errors from the truth with 10 degrees of freedom, -2.3..+0.3 with 3, -1.7..0 with 2
#: (the half-ensemble t of every step: -0.8..+0.6)
HELD_DF = 2.0
#: steps between two refits of the held proposal
HELD_REFIT = 50
#: about how many of a group's draws its Yeo-Johnson exponents are fitted to (every k-th)
HELD_LAMBDA_DRAWS = 1000
#: Yeo-Johnson exponents of the held proposal are kept in this range, where the transformation
#: maps the real line onto itself (``yeo_johnson``)
YJ_RANGE = (0.1, 1.9)
#: the coarse step of ``yeo_johnson_exponents``' search, in grid steps
YJ_COARSE = 5


def yeo_johnson(z: np.ndarray, lam: np.ndarray, inverse: bool = False) -> np.ndarray:
    """The Yeo-Johnson transformation (Yeo & Johnson 2000, Biometrika 87, 954; scipy.stats'
    ``yeojohnson`` with a given exponent) of each column of ``z`` with its exponent in ``lam``
    (D,), or its inverse; for 0 < lam < 2 both map the real line onto itself. (scipy has the
    transformation but not its inverse.)"""
    z, lam = np.broadcast_arrays(z, lam)
    pos = z >= 0
    a = np.where(pos, lam, 2.0 - lam)  # the branch's exponent, in (0, 2)
    u = np.abs(z)
    with np.errstate(over="ignore", invalid="ignore"):
        v = np.log1p(a * u) / a if inverse else np.log1p(u)
        v = np.expm1(v) if inverse else np.expm1(a * v) / a
    return np.where(pos, v, -v)


def yeo_johnson_exponents(z: np.ndarray, step: float = 0.02) -> np.ndarray:
    """Each column's Yeo-Johnson exponent of largest normal log-likelihood (scipy.stats'
    ``yeojohnson_llf``: (lam - 1) sum sign(z) log(1 + |z|) - n/2 log var(y)) on a grid of
    ``step`` over ``YJ_RANGE``: scipy.stats' ``yeojohnson_normmax`` (Brent's method) within the
    grid's step where its optimum lies in the range (tested), without its 5 ms of overhead a
    likelihood evaluation (about 0.4 CPU s a refit of four ensembles and nine parameters).
    Searched coarse to fine: every ``YJ_COARSE``-th exponent of the grid, then the grid's
    exponents within that coarse step of the best, a third of the grid's evaluations; the same
    exponent as the whole grid's wherever the log-likelihood has one maximum on it (tested)."""
    grid = np.arange(YJ_RANGE[0], YJ_RANGE[1] + step / 2, step)
    slope = np.sum(np.sign(z) * np.log1p(np.abs(z)), axis=0)  # (D,)

    def llf(i):  # i (G, D) grid indices, one column of z each -> (G, D)
        y = yeo_johnson(z[None], grid[i][:, None, :])  # (G, n, D)
        return (grid[i] - 1.0) * slope - 0.5 * len(z) * np.log(np.var(y, axis=1))

    coarse = np.broadcast_to(
        np.arange(0, grid.size, YJ_COARSE)[:, None], (-(-grid.size // YJ_COARSE), z.shape[1])
    )
    best = np.take_along_axis(coarse, np.argmax(llf(coarse), axis=0)[None], 0)[0]
    near = np.clip(best + np.arange(1 - YJ_COARSE, YJ_COARSE)[:, None], 0, grid.size - 1)
    return grid[np.take_along_axis(near, np.argmax(llf(near), axis=0)[None], 0)[0]]


def yeo_johnson_log_slope(z: np.ndarray, lam: np.ndarray) -> np.ndarray:
    """log d/dz of the transformation, summed over the columns: (1 + |z|)^(+-(lam - 1))."""
    return np.sum(np.where(z >= 0, lam - 1.0, 1.0 - lam) * np.log1p(np.abs(z)), axis=-1)


class _HeldIndependence(_GroupedIndependence):
    """The independence move with its proposal fitted to the group's own past draws and held
    fixed between refits (``run_many(..., proposal="held")``), instead of a Student t refitted at
    every step to the other half of the group.

    The proposal: each coordinate standardised by the draws' mean and sd and transformed by
    Yeo-Johnson with the exponent that makes its draws most nearly normal
    (``yeo_johnson_exponents``, in ``YJ_RANGE``), and a Student t (``HELD_DF``, 2) with the
    transformed draws' mean and covariance; its density in the sampled coordinates carries the
    transformation's slope. Why: the half-ensemble fit has few walkers (46 for the discrepancy
    surface's nine parameters), its mean and covariance are rough and change from step to step,
    and a t cannot follow skewed marginals (the force floor, the length scale). Measured
    offline on a finished data/n50 run (seed 20201): the acceptance of an independence sampler
    is about 0.17 with a t fitted to 46 draws, 0.26 with one fitted to all of them, 0.47 with
    this proposal.

    Why it keeps the target: the proposal is adapted during the burn-in only, as Stan adapts
    its step size and metric during warm-up. The sampler refits it (``refit``) every
    ``HELD_REFIT`` steps of the first ``settings.min_steps`` (from each ensemble's draws of the
    last ``2 HELD_REFIT`` steps or of the second half of the run, the fewer), and after the
    refit at ``min_steps`` holds it fixed for the rest of the run; a held run discards at least
    its first ``min_steps`` steps as burn-in. Every kept draw therefore comes from one
    time-homogeneous Markov chain whose every move keeps the posterior invariant: DE and snooker
    moves (red-blue updates given the complement), and independence Metropolis-Hastings from a
    fixed density q with the factor log q(x) - log q(x') (Tierney 1994, Ann. Stat. 22, 1701).
    Where the proposal came from (the burn-in's draws) does not matter to that chain's
    stationary distribution; how far its start is from it, the rules judge as in any other
    run. (Refitting on through the kept draws, as this move first did, makes the kernel depend
    on the states it moves: with 10 degrees of freedom the banana target's mean came out off by
    up to 5.5 Monte Carlo standard errors over six seeds, with 2 by up to 1.7.) Each group
    (ensemble) is fitted to its own draws only, so the ensembles stay independent of each other
    and R-hat still compares independent chains. Before the first refit (the first
    ``2 HELD_REFIT`` steps, from the overdispersed starts) the move is the half-ensemble fit of
    :class:`_GroupedIndependence`; a group whose draws give no positive-definite covariance keeps
    its previous proposal (the half-ensemble fit if none had one). A proposal that overflows is
    rejected (factor -inf).

    Burn-in: on data/n50 the first 200 steps from the starts hold too few draws in the left tail
    of the force floor (in windows of those steps its 5 % quantile is 0.3-0.9 posterior sd too
    high, with either proposal): the tail fills slowly, and the bulk's autocorrelation time (the
    burn-in rule's 5 tau, about 40 steps with this proposal) says nothing about it. A run three
    times shorter than the half-ensemble sampler's keeps that deficit in a third of its draws,
    where the longer run dilutes it (measured: the quantile 0.10 too high, 2.8 Monte Carlo
    standard errors), so a held run discards at least its first ``settings.min_steps`` steps
    and is extended to that plus the rules' 50 tau (docs/speed.md)."""

    def __init__(self, group_size: int, df: float = HELD_DF):
        super().__init__(group_size, df)
        self.fitted = None  # (G,) bool: whether the group has its held proposal
        self.center = self.scale = self.lam = None  # (G, 1, D): standardisation, exponents
        self.mean = self.chol = None  # (G, 1, D), (G, D, D): the t in the transformed space

    def refit(self, draws: np.ndarray) -> None:
        """Fit each group's proposal to its draws (G, n, D)."""
        G, _, D = draws.shape
        if self.fitted is None:
            self.fitted = np.zeros(G, bool)
            self.center, self.scale, self.lam, self.mean = (np.zeros((G, 1, D)) for _ in range(4))
            self.chol = np.zeros((G, D, D))
        for g in range(G):
            x = draws[g]
            center, scale = x.mean(axis=0), x.std(axis=0)
            if not np.all(scale > 0):
                continue
            z = (x - center) / scale
            lam = yeo_johnson_exponents(z[:: max(1, len(z) // HELD_LAMBDA_DRAWS)])
            y = yeo_johnson(z, lam)
            try:
                chol = np.linalg.cholesky(np.cov(y.T))
            except np.linalg.LinAlgError:
                continue
            self.center[g], self.scale[g], self.lam[g] = center, scale, lam
            self.mean[g], self.chol[g] = y.mean(axis=0), chol
            self.fitted[g] = True

    def get_proposal(self, s, c, random):
        if self.fitted is None or not self.fitted.all():
            return super().get_proposal(s, c, random)
        sg, _ = self._groups(s, c)
        warp = (
            lambda x: yeo_johnson((x - self.center) / self.scale, self.lam),
            lambda y: self.center + self.scale * yeo_johnson(y, self.lam, inverse=True),
            lambda x: yeo_johnson_log_slope((x - self.center) / self.scale, self.lam),
        )
        with np.errstate(over="ignore", invalid="ignore"):
            q, factor = _t_proposal(sg, self.mean, self.chol, self.df, random, warp)
        bad = ~np.all(np.isfinite(q), axis=-1) | ~np.isfinite(factor)
        return np.where(bad[:, None], sg.reshape(q.shape), q), np.where(bad, -np.inf, factor)


class _Sampler(emcee.EnsembleSampler):
    """emcee's sampler for a vectorised log-probability without blobs, whose values are taken as
    one array: emcee makes each walker's value a scalar in a Python loop (``_scalar``, about 1 us
    a walker and call), which gives the same numbers."""

    def compute_log_prob(self, coords):
        if np.any(np.isinf(coords)):
            raise ValueError("At least one parameter value was infinite")
        if np.any(np.isnan(coords)):
            raise ValueError("At least one parameter value was NaN")
        log_prob = np.array(self.log_prob_fn(coords), dtype=np.float64)
        if log_prob.shape != (len(coords),):
            raise ValueError("log_prob_fn should return one scalar a walker")
        return log_prob, None


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
#: data/n50 (32 walkers per ensemble, default seed) the per-pressure cubics meet their rules after
#: 250 steps (the 200-step floor and one extension; 684 with DE moves alone) and the surface's five
#: noise parameters after 1663 steps instead of 3142 (measured with the corrected snooker move).
#: The DE moves stay in the mixture so that a posterior far from Gaussian is still explored.
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


#: how the independence move fits its Student t: "half", to the other half of the walker's
#: ensemble at every step (``_GroupedIndependence``, the default); "held", to the ensemble's own
#: past draws between segments of the run, held fixed within one (``_HeldIndependence``)
PROPOSALS = ("half", "held")


def _moves(group_size: int, mix: tuple[float, float, float], proposal: str = "half"):
    if proposal not in PROPOSALS:
        raise ValueError(f"proposal must be one of {PROPOSALS}, got {proposal!r}")
    ind = (_HeldIndependence if proposal == "held" else _GroupedIndependence)(group_size)
    moves = zip((_GroupedDE(group_size), _GroupedSnooker(group_size), ind), mix, strict=True)
    return [(m, w) for m, w in moves if w > 0]


def _tau(chain: np.ndarray) -> np.ndarray:
    """Integrated autocorrelation time per dimension; chain (steps, walkers, dim), or
    (steps, walkers, dim) stacked for several ensembles as (E, steps, walkers, dim) -> (E, dim).

    emcee's estimator (``emcee.autocorr.integrated_time`` with ``c=5``: the walkers' normalised
    autocorrelation functions averaged, Sokal's automatic window), vectorised over ensembles,
    walkers and dimensions in one FFT instead of one call per walker and dimension (the same
    numbers to rounding; tests/inference/test_sampler.py). A walker that never moved in the window
    has no autocorrelation function (0/0): NaN, which the tau rule counts as failed.
    """
    x = np.asarray(chain, float)
    single = x.ndim == 3
    if single:
        x = x[None]
    n = x.shape[1]
    m = 2 * (1 << max(n - 1, 0).bit_length())  # emcee: twice the next power of two
    with np.errstate(invalid="ignore", divide="ignore"):
        f = np.fft.rfft(x - x.mean(axis=1, keepdims=True), n=m, axis=1)
        acf = np.fft.irfft(f * np.conjugate(f), n=m, axis=1)[:, :n]
        acf = acf / acf[:, :1]
    mean_acf = acf.mean(axis=2)  # (E, steps, dim): averaged over the walkers
    taus = 2.0 * np.cumsum(mean_acf, axis=1) - 1.0
    lags = np.arange(n)[None, :, None]
    inside = lags < 5.0 * taus
    window = np.where(inside.any(axis=1), np.argmin(inside, axis=1), n - 1)  # emcee's auto_window
    tau = np.take_along_axis(taus, window[:, None, :], axis=1)[:, 0]
    return tau[0] if single else tau


def _starts(log_prob, centers, chols, n_walkers: int, rng, tries: int = 20) -> np.ndarray:
    """Overdispersed starting walkers with finite log-probability (bad draws redrawn).

    ``log_prob`` maps (K, m, D) -> (K, m); centers (K, D); chols (K, D, D) lower factors of the
    start covariance; returns (K, n_walkers, D). After ``tries`` rounds the remaining bad walkers
    are drawn ever closer to their problem's center (halving the spread), which is finite by
    construction of the callers (an optimum).
    """
    K, D = centers.shape

    def draw(shrink, shape):
        z = rng.standard_normal(shape)
        return centers[:, None, :] + shrink * np.einsum("kij,kwj->kwi", chols, z)

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


def run_many(
    log_prob,
    centers,
    covs,
    names,
    *,
    seed: int,
    settings: Settings = Settings(),
    desc: str | None = None,
    mix: tuple[float, float, float] = INDEPENDENCE_MIX,
    proposal: str = "half",
) -> list[Chains]:
    """Sample K problems of the same dimension D at once: one emcee sampler, one call per move.

    ``log_prob`` maps (K, m, D) -> (K, m): row k of the walkers is evaluated under problem k
    (e.g. one jitted, vmapped log-probability over all tests of a campaign). centers (K, D),
    covs (K, D, D) the posterior covariance estimates the starts are drawn from. Every problem gets ``settings.n_ensembles`` independent ensembles of
    ``settings.n_walkers`` walkers (see ``_Grouped``), and the run is extended until every
    problem passes every rule, or ``max_steps``. Returns one :class:`Chains` per problem, with
    its own burn-in, tau and failed rules. ``proposal`` (``PROPOSALS``): "held" refits each
    ensemble's held independence proposal (``_HeldIndependence``) every ``HELD_REFIT`` steps of
    the first ``settings.min_steps`` from its own latest draws and then holds it fixed, checks the rules every ``settings.chunk`` steps at most (so that the
    better proposal's shorter autocorrelation times are seen before the run is extended far on
    those of the first steps), and discards at least the first ``settings.min_steps`` steps as
    burn-in (why: ``_HeldIndependence``).
    """
    from uq._io.progress import Silent, progress

    # No total: the run stops when the rules pass, usually far below max_steps, so a bar to
    # max_steps would show an ETA many times too long. It counts steps and their rate instead.
    with progress(desc=desc, unit="step") if desc else Silent(None) as bar:
        return _run_many(log_prob, centers, covs, names, seed, settings, bar, mix, proposal)


def _run_many(
    log_prob, centers, covs, names, seed: int, settings: Settings, bar, mix, proposal="half"
) -> list[Chains]:
    settings.validate()
    centers = np.atleast_2d(np.asarray(centers, float))
    K, ndim = centers.shape
    settings.require_walkers(ndim)
    chols = settings.init_spread * np.linalg.cholesky(
        np.asarray(covs, float).reshape(K, ndim, ndim)
    )
    E, W = settings.n_ensembles, settings.n_walkers
    rng = np.random.default_rng(seed)
    # Walker order: problem, ensemble, walker; each ensemble's start is drawn afresh.
    # (K, E, W, D)
    start = np.stack([_starts(log_prob, centers, chols, W, rng) for _ in range(E)], axis=1)

    def flat_log_prob(q):  # emcee's (rows, D), rows in walker order -> (rows,)
        return np.asarray(log_prob(q.reshape(K, -1, ndim)), float).reshape(-1)

    mix = effective_mix(mix, W, ndim)
    moves = _moves(W, mix, proposal)
    held = next((m for m, _ in moves if isinstance(m, _HeldIndependence)), None)
    sampler = _Sampler(K * E * W, ndim, flat_log_prob, vectorize=True, moves=moves)
    accept_range = (ACCEPT_RANGE[0], 1.0) if mix[2] > 0 else ACCEPT_RANGE
    sampler.random_state = np.random.RandomState(rng.integers(2**31)).get_state()
    state = start.reshape(-1, ndim)
    n_steps, target = 0, settings.min_steps
    while True:
        step = max(1, min(target, settings.max_steps) - n_steps)
        if held is None:
            pieces = [step]
        else:  # the rules checked every chunk; in the burn-in, refitted every HELD_REFIT steps
            step = min(step, settings.chunk)
            q, r = divmod(step, HELD_REFIT)
            pieces = [step] if n_steps >= settings.min_steps else [HELD_REFIT] * q + [r] * bool(r)
        for piece in pieces:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)  # -inf log-prob proposals
                state = sampler.run_mcmc(state, piece, progress=False)
            n_steps += piece
            if held is not None and 2 * HELD_REFIT <= n_steps <= settings.min_steps:
                # adapted in the burn-in only (_HeldIndependence): each ensemble's draws of the
                # last 2 HELD_REFIT steps or the second half, the fewer
                recent = sampler.get_chain()[max(n_steps // 2, n_steps - 2 * HELD_REFIT) :]
                held.refit(
                    recent.reshape(len(recent), K * E, W, ndim)
                    .swapaxes(0, 1)
                    .reshape(K * E, -1, ndim)
                )
        bar.update(step)
        chain, logp = sampler.get_chain(), sampler.get_log_prob()  # one copy for all problems
        accept = sampler.acceptance_fraction
        floor = settings.min_steps if held is not None else 0
        chains = [
            _collect(
                chain, logp, accept, k, names, settings, n_steps, start[k], accept_range, floor
            )
            for k in range(K)
        ]
        verdicts = [failed_rules(c, settings, full=False) for c in chains]
        n_failed = sum(bool(f) for f, _ in verdicts)
        bar.set_postfix_str(f"{n_failed} problem(s) not yet converged" if n_failed else "converged")
        if not n_failed:
            return chains
        want = max(w for f, w in verdicts if f)
        tau_max = max(float(np.max(c.tau)) for c in chains)
        if floor and math.isfinite(tau_max):  # the rules' length assumes a burn-in of 5 tau
            want = max(want, floor + math.ceil(1.1 * settings.tau_multiple * tau_max))
        if n_steps >= settings.max_steps or want <= n_steps:
            verdicts = [failed_rules(c, settings) for c in chains]
            return [
                dataclasses.replace(c, problems=tuple(f))
                for c, (f, _) in zip(chains, verdicts, strict=True)
            ]
        target = max(want, n_steps + settings.chunk // 4)


def _collect(
    chain,
    logp,
    acceptance,
    k: int,
    names,
    settings: Settings,
    n_steps: int,
    start,
    accept_range,
    burn_floor: int = 0,
) -> Chains:
    """Problem k's burn-in from its current tau, its post-burn chains in storage order, its tau;
    ``chain`` (steps, walkers, dim), ``logp`` (steps, walkers) and ``acceptance`` (walkers,) of
    the whole sampler."""
    E, W = settings.n_ensembles, settings.n_walkers
    cols = slice(k * E * W, (k + 1) * E * W)
    mine = chain[:, cols]  # (steps, E * W, dim)
    raw = mine.reshape(n_steps, E, W, -1).swapaxes(0, 1)  # (E, steps, W, dim)
    # tau from the second half: the overdispersed start's transient would inflate it
    tau = np.max(_tau(raw[:, n_steps // 2 :]), axis=0)
    tau_max = float(np.max(tau)) if np.all(np.isfinite(tau)) else math.inf
    burn = int(math.ceil(settings.burn_tau * tau_max)) if math.isfinite(tau_max) else n_steps // 2
    burn = min(max(burn, 20, burn_floor), n_steps // 2)
    samples = raw[:, burn:].reshape(E, -1, raw.shape[-1])
    lp = logp[burn:, cols].reshape(n_steps - burn, E, W).swapaxes(0, 1).reshape(E, -1)
    accept = acceptance[cols]
    return Chains(
        tuple(names), samples, lp, accept, tau, n_steps, burn, E, (), W, start, accept_range
    )
