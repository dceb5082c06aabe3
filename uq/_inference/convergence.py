"""Convergence of an emcee run: the project's rules, each failure an enum member with its message.

The rules (per sampled problem; ``uq._inference.sampler`` extends a run until they pass):

* tau:        the chain after burn-in is at least ``tau_multiple`` (50) integrated
              autocorrelation times long (emcee's estimator, the largest over ensembles and
              parameters);
* R-hat:      rank-normalised split R-hat <= 1.01 (ArviZ);
* ESS:        bulk and tail effective sample size >= 400;
* acceptance: mean acceptance fraction in 0.15..0.6 (running longer does not change it, so a
              failure is reported but does not extend the run). With independence proposals in
              the move mixture only the lower bound applies: there a high acceptance means the
              proposal fits the posterior, not that the steps are tiny.
* finite:     every draw of every reported variable is finite (a NaN or infinity is a failure of
              the model's numerics, never of the run's length: reported, never silently averaged).

A run's verdict is a frozen :class:`Convergence` (optimistix's ``Solution.result`` style): a tuple
of :class:`Problem`, each a :class:`Failure` member with the numbers that failed. Its messages do
not name command-line options (a notebook user has none); the ``uq`` command asks for the advice
in its own words (``messages(advice=CLI_ADVICE)``).

How the walkers are shown to ArviZ, and why. The walkers of one emcee ensemble are coupled
(every proposal is built from other walkers), so they are not independent chains; emcee's and
ArviZ's authors both warn against giving walkers to R-hat/ESS as chains (emcee docs and
dfm/emcee#279; arviz-devs/arviz#977 and #2156). What they recommend instead is several
independently started ensembles (Buchner's autoemcee: four) compared with each other:

* Storage: each ensemble is one ArviZ chain and its draws are in time order, the walkers of
  one step next to each other (emcee's ``get_chain(flat=True)`` order): samples are
  (n_ensembles, n_steps * n_walkers, dim). ArviZ's split R-hat therefore compares the first
  half of the run with the second half (a drift is seen) and the ensembles with each other.
* ESS: the draw-to-draw autocorrelation of such a chain is not what limits the information
  (neighbouring draws are different walkers), so ArviZ's ESS of it would count every draw as
  independent. ESS is computed by ArviZ on the ensemble-mean chains m_c(t) (mean over the
  walkers of ensemble c at step t), which carry every cross-walker correlation, and converted
  to draws by the definition ESS = Var(x) / MCSE^2 = ESS_ArviZ(m) * Var(x) / Var(m). With
  independent walkers this equals emcee's n_steps * n_walkers / tau; with coupled walkers it is
  smaller, never inflated by the number of walkers. Bulk ESS does this on the rank-normalised
  draws, tail ESS on the indicators of the 5 % and 95 % quantiles (as ArviZ defines them), and
  the MCSE of the mean is ArviZ's MCSE of the ensemble-mean chains.

The statistics are ArviZ's definitions (rank-normalised split R-hat, ESS by Geyer's initial
monotone sequence, MCSE of the mean; Vehtari et al. 2021), computed here in numpy for many
scalars at once (:func:`diagnostics`): the same numbers as ArviZ to rounding
(tests/inference/test_convergence.py), at a fraction of the cost of ArviZ's one-scalar-a-call
xarray path, so the rules can be checked after every chunk of a run.
"""

from __future__ import annotations

import enum
import functools
import math
from dataclasses import dataclass, field

import numpy as np

RHAT_MAX = 1.01
ESS_MIN = 400.0
ACCEPT_RANGE = (0.15, 0.6)

#: What to do when a run is too short, in the library's words and in the command line's.
LIBRARY_ADVICE = "run longer (Settings.max_steps) or use more walkers (Settings.n_walkers)"
CLI_ADVICE = "raise --max-steps or use more walkers"


class Failure(enum.Enum):
    """One way a run fails the rules; the value is its message template (``Problem.message``)."""

    TAU = (
        "chain of {n_steps} steps is shorter than burn-in + {multiple:g} autocorrelation times "
        "(tau = {tau:.1f}): {advice}"
    )
    R_HAT = "{name}: R-hat {value:.3f} > {limit}: chains disagree; {advice}"
    ESS = "{name}: effective sample size {value:.0f} < {limit:.0f}: {advice}"
    ACCEPTANCE = (
        "acceptance fraction {value:.2f} outside {lo:g}-{hi:g}: the sampler is stuck or the "
        "posterior is badly scaled; check the model and start"
    )
    NONFINITE = (
        "{name}: {count} of {total} draws are not finite: the model's numerics failed there and "
        "the posterior is unusable; report it as a bug"
    )


@dataclass(frozen=True)
class Problem:
    """A failed rule with the numbers that failed it (``values``: the template's fields)."""

    failure: Failure
    values: tuple[tuple[str, float | str], ...]

    def message(self, advice: str = LIBRARY_ADVICE) -> str:
        return self.failure.value.format(advice=advice, **dict(self.values))

    def __repr__(self) -> str:
        return f"Problem({self.failure.name}: {self.message()})"


def _problem(failure: Failure, **values) -> Problem:
    return Problem(failure, tuple(values.items()))


@dataclass(frozen=True)
class Convergence:
    """The verdict of one sampled problem: its failed rules and the numbers behind them.

    ``variables``: per reported variable, ``r_hat``, ``ess_bulk``, ``ess_tail``, ``mcse_mean``
    (floats, or lists for vector variables). ``tau``: per sampled parameter. ``method``: how theta
    was sampled, "emcee" or "importance" (``uq._inference.importance``: then ``variables`` holds
    the statistics of the kept draws split into ``IMPORTANCE_CHAINS`` runs, and there is no tau or
    acceptance); ``importance``: that method's checks when it was tried
    (``Importance.to_json``), also when it was refused and emcee sampled instead.
    """

    problems: tuple[Problem, ...]
    n_steps: int
    burn_in: int
    n_chains: int
    n_walkers: int
    n_draws: int
    tau: dict = field(default_factory=dict)
    acceptance: dict = field(default_factory=dict)
    variables: dict = field(default_factory=dict)
    method: str = "emcee"
    importance: dict = field(default_factory=dict)

    @property
    def converged(self) -> bool:
        return not self.problems

    def messages(self, advice: str = LIBRARY_ADVICE) -> list[str]:
        return [p.message(advice) for p in self.problems]

    @property
    def warnings(self) -> list[str]:
        return self.messages()

    def worst(self) -> tuple[float, float]:
        """(largest R-hat, smallest bulk ESS) over every reported variable (importance draws'
        too: their kept draws split into runs, ``importance_convergence``)."""
        rh = max(float(np.max(v["r_hat"])) for v in self.variables.values())
        ess = min(float(np.min(v["ess_bulk"])) for v in self.variables.values())
        return rh, ess

    def sampler_words(self) -> str | None:
        """One line on how theta was sampled when importance sampling was tried (None otherwise):
        what the user of ``uq`` is told, whichever way it went."""
        imp = self.importance
        if not imp:
            return None
        if self.method == "importance":
            ess = min(min(v["ess_bulk"], v["ess_tail"]) for v in self.variables.values())
            return (
                f"sampler: importance sampling, Pareto k-hat {imp['pareto_k']:.2f} <= "
                f"{imp['pareto_k_max']:g}, effective sample size at least {ess:.0f} (of "
                f"{imp['n_draws']} draws)"
            )
        return (
            f"sampler: emcee; importance sampling was refused ({imp['reason']}), the "
            f"Markov chain sampled instead ({self.n_steps} steps)"
        )

    def to_json(self, advice: str = CLI_ADVICE, *, variables: bool = True) -> dict:
        """The ``convergence`` document of the JSON results (docs/formats.md)."""
        out = {
            "converged": self.converged,
            "warnings": self.messages(advice),
            "n_steps": self.n_steps,
            "burn_in": self.burn_in,
            "n_chains": self.n_chains,
            "n_walkers": self.n_walkers,
            "n_draws": self.n_draws,
            "tau": dict(self.tau),
            "acceptance_fraction": dict(self.acceptance),
        }
        if self.importance:  # only where it was tried: every other document stays as it was
            out["method"] = self.method
            out["importance"] = dict(self.importance)
        if variables:
            out["variables"] = self.variables
        return out

    def __repr__(self) -> str:
        state = "converged" if self.converged else f"{len(self.problems)} rule(s) failed"
        if self.method == "importance":
            return f"Convergence({state}, importance sampling, Pareto k-hat {self.importance['pareto_k']:.2f})"
        return f"Convergence({state}, {self.n_steps} steps, burn-in {self.burn_in})"


# ----------------------------------------------------------------------------- statistics
# ArviZ's rank-normalised split R-hat, ESS (Geyer's initial monotone sequence) and MCSE of the
# mean (Vehtari et al. 2021, arviz.stats.diagnostics 0.23), written again in numpy and vectorised
# over many scalars at once: ArviZ computes one scalar a call through xarray, which cost a fit
# about 2.5 CPU s (in-run rule checks and the final verdict of every reported variable). The
# numbers are ArviZ's to rounding (tests/inference/test_convergence.py compares them on random,
# sticky, short and constant chains); every array below is (S, chains, draws), S scalars.


def _worst(values, pick):
    """``pick`` (max or min) of the values, NaN if any is NaN (an undefined statistic fails its rule)."""
    v = np.asarray(values, float)
    return float("nan") if np.any(np.isnan(v)) else float(pick(v))


def _average_ranks(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Ranks 1..M along the last axis of (S, M), ties given their average rank (scipy's
    ``rankdata(method="average")``; a walker that rejects a move repeats its value), and the
    values sorted along that axis (NaNs last)."""
    S, M = x.shape
    order = np.argsort(x, axis=-1)  # tied values get one average rank: the sort need not be stable
    xs = np.take_along_axis(x, order, axis=-1)
    new = np.ones((S, M), bool)
    new[:, 1:] = xs[:, 1:] != xs[:, :-1]
    flat = new.ravel()
    starts = np.flatnonzero(flat)
    ends = np.append(starts[1:], flat.size) - 1
    row = starts // M
    average = (starts + ends) / 2.0 - row * M + 1.0
    ranks_sorted = average[np.cumsum(flat) - 1].reshape(S, M)
    ranks = np.empty((S, M))
    np.put_along_axis(ranks, order, ranks_sorted, axis=-1)
    return ranks, xs


@functools.lru_cache(maxsize=8)
def _normal_scores(M: int) -> np.ndarray:
    """ArviZ's normal score of every average rank r = 1, 1.5, ..., M of M draws, at index
    2 r - 2: ``ndtri((r - 3/8) / (M + 1/4))``, computed once per M (the ranks are half-integers,
    so a lookup gives the same numbers as ndtri of each draw's rank, at a fraction of the cost)."""
    from scipy.special import ndtri

    return ndtri((np.arange(1.0, M + 0.5, 0.5) - 0.375) / (M + 0.25))


def _z_scale(x: np.ndarray, sorted_values: bool = False):
    """ArviZ's rank normalisation of each scalar's draws, pooled over its chains (same shape);
    with ``sorted_values`` also each scalar's draws sorted, (S, draws) (for its quantiles)."""
    S = x.shape[0]
    flat = x.reshape(S, -1)
    ranks, xs = _average_ranks(flat)
    z = _normal_scores(flat.shape[1])[(2.0 * ranks).astype(np.intp) - 2]
    z[np.isnan(flat).any(axis=-1)] = np.nan  # scipy's rankdata propagates a NaN to every rank
    return (z.reshape(x.shape), xs) if sorted_values else z.reshape(x.shape)


def _split(x: np.ndarray) -> np.ndarray:
    """Each chain cut into its first and last halves (the middle draw of an odd length dropped)."""
    half = x.shape[-1] // 2
    return np.concatenate([x[..., :half], x[..., x.shape[-1] - half :]], axis=1)


def _rhat(x: np.ndarray) -> np.ndarray:
    n = x.shape[-1]
    between = n * np.var(np.mean(x, axis=-1), axis=-1, ddof=1)
    within = np.mean(np.var(x, axis=-1, ddof=1), axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.sqrt((between / within + n - 1) / n)


def rhat_rank(
    x: np.ndarray, z: np.ndarray | None = None, xs: np.ndarray | None = None
) -> np.ndarray:
    """ArviZ's rank-normalised split R-hat (``az.rhat``, method "rank"), (S, C, N) -> (S,):
    the larger of the bulk and the folded (tail) R-hat; NaN with any NaN draw, fewer than 2
    chains or 4 draws. ``z``, ``xs``: ``_z_scale(x, sorted_values=True)`` if already at hand
    (with an even N the split chains hold the same draws, so their ranks and median are the
    same; the median of sorted draws is found faster, and is the same number)."""
    x = np.asarray(x, float)
    S, C, N = x.shape
    if C < 2 or N < 4:
        return np.full(S, np.nan)
    s = _split(x)
    same = N % 2 == 0
    bulk = _rhat(_split(z) if z is not None and same else _z_scale(s))
    pooled = xs if xs is not None and same else s.reshape(S, -1)
    folded = np.abs(s - np.median(pooled, axis=-1)[:, None, None])
    tail = _rhat(_z_scale(folded))
    out = np.where(tail > bulk, tail, bulk)  # Python's max(bulk, tail), as ArviZ takes it
    return np.where(np.isnan(x).any(axis=(1, 2)), np.nan, out)


def _autocov(x: np.ndarray) -> np.ndarray:
    """Autocovariance of every chain at every lag (FFT, biased: divided by the length)."""
    n = x.shape[-1]
    m = 1 << (2 * n - 1).bit_length()
    f = np.fft.rfft(x - x.mean(axis=-1, keepdims=True), n=m, axis=-1)
    return np.fft.irfft(f * np.conjugate(f), n=m, axis=-1)[..., :n] / n


def _ess(x: np.ndarray) -> np.ndarray:
    """ArviZ's ``_ess`` (Geyer's initial monotone sequence) of (S, C, N) chains, vectorised over S."""
    x = np.asarray(x, float)
    S, C, N = x.shape
    out = np.full(S, np.nan)
    bad = np.isnan(x).any(axis=(1, 2))
    const = ~bad & (np.ptp(x.reshape(S, -1), axis=-1) < np.finfo(float).resolution)
    out[const] = x[0].size
    run = ~bad & ~const
    if not run.any() or N < 2:
        return out
    x = x[run]
    acov = _autocov(x)
    mean_var = np.mean(acov[:, :, 0], axis=1) * N / (N - 1.0)
    var_plus = mean_var * (N - 1.0) / N
    if C > 1:
        var_plus = var_plus + np.var(x.mean(axis=-1), axis=-1, ddof=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        rho = 1.0 - (mean_var[:, None] - np.mean(acov, axis=1)) / var_plus[:, None]  # (s, N)
    k_max = max((N - 3) // 2, 0)  # Geyer's pairs k = 1..k_max (ArviZ: t = 2k - 1 < N - 3)
    even = np.concatenate([np.ones((rho.shape[0], 1)), rho[:, 2 : 2 * k_max + 1 : 2]], axis=1)
    odd = rho[:, 1 : 2 * k_max + 2 : 2]
    if odd.shape[1] < even.shape[1]:  # N < 2: no lag one
        odd = np.concatenate([odd, np.zeros((odd.shape[0], 1))], axis=1)
    pairs = even + odd  # (s, k_max + 1): pair 0 is rho_0 = 1 and rho_1
    # K: the first pair that is not positive (the initial positive sequence stops there), or k_max
    nonpos = ~(pairs > 0)
    K = np.where(nonpos.any(axis=1), np.argmax(nonpos, axis=1), k_max)
    # Geyer's initial monotone sequence: the pair sums made non-increasing, pairs 0..K-1 summed
    mono = np.minimum.accumulate(pairs, axis=1)
    keep = np.arange(pairs.shape[1])[None, :] < K[:, None]
    total = np.sum(np.where(keep, mono, 0.0), axis=1)
    rows = np.arange(K.size)
    last_even, last_pair = even[rows, K], pairs[rows, K]
    extra = np.where((last_even > 0) | (last_pair >= 0) | (K == 0), last_even, 0.0)
    tau = -1.0 + 2.0 * total + extra
    n_total = C * N
    tau = np.maximum(tau, 1.0 / np.log10(n_total))
    ess = n_total / tau
    ess[np.isnan(rho[:, 1]) | np.isnan(tau)] = np.nan
    out[run] = ess
    return out


def ess_mean(x: np.ndarray) -> np.ndarray:
    """ArviZ's ESS of the mean (``az.ess(method="mean")``: split chains), (S, C, N) -> (S,)."""
    x = np.asarray(x, float)
    if x.shape[-1] < 4:
        return np.full(x.shape[0], np.nan)
    return _ess(_split(x))


def mcse_mean(x: np.ndarray) -> np.ndarray:
    """ArviZ's MCSE of the mean (``az.mcse(method="mean")``), (S, C, N) -> (S,)."""
    x = np.asarray(x, float)
    sd = np.std(x.reshape(x.shape[0], -1), axis=-1, ddof=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        return sd / np.sqrt(ess_mean(x))


def _ess_of_summary(x: np.ndarray, per_step: np.ndarray) -> np.ndarray:
    """Draw-scale ESS of the ensemble-mean chains ``per_step`` (S, C, T) summarising ``x``
    (S, C, draws): ArviZ's ESS of the mean of ``per_step``, times Var(x) / Var(per_step)."""
    S = x.shape[0]
    var_m = np.var(per_step.reshape(S, -1), axis=-1)
    var_x = np.var(x.reshape(S, -1), axis=-1)
    ess_m = ess_mean(per_step)
    with np.errstate(invalid="ignore", divide="ignore"):
        ess = np.minimum(ess_m * var_x / var_m, float(x[0].size))
    return np.where(var_m > 0, ess, np.nan)


def _per_step(x: np.ndarray, n_walkers: int) -> np.ndarray:
    """(S, C, steps * walkers) in storage order -> the ensemble means (S, C, steps)."""
    S, C, D = x.shape
    return x.reshape(S, C, D // n_walkers, n_walkers).mean(axis=-1)


def diagnostics(x: np.ndarray, n_walkers: int) -> dict:
    """R-hat, bulk and tail ESS and MCSE of the mean of S scalars at once; x (S, n_ensembles,
    steps * walkers) in storage order. Each a (S,) array; see the module docstring for what
    each statistic is given and why."""
    x = np.asarray(x, float)
    if x.ndim == 2:
        x = x[None]
    z, xs = _z_scale(x, sorted_values=True)
    tail = []
    with np.errstate(invalid="ignore"):
        # quantiles of the sorted draws: the same numbers, found faster
        for cut in np.quantile(xs, (0.05, 0.95), axis=-1):
            ind = (x <= cut[:, None, None]).astype(float)
            tail.append(_ess_of_summary(ind, _per_step(ind, n_walkers)))
    return {
        "r_hat": rhat_rank(x, z, xs),
        "ess_bulk": _ess_of_summary(z, _per_step(z, n_walkers)),
        "ess_tail": np.minimum(*tail),  # NaN if either is NaN, as min() of ArviZ's values
        "mcse_mean": mcse_mean(_per_step(x, n_walkers)),
    }


def bulk_ess(x: np.ndarray, n_walkers: int) -> float:
    """Bulk ESS of one scalar, x (n_ensembles, steps * walkers) in storage order (one ensemble
    is enough): ArviZ's rank normalisation, then the ensemble-mean chains (module docstring)."""
    z = _z_scale(np.asarray(x, float)[None])
    return float(_ess_of_summary(z, _per_step(z, n_walkers))[0])


def chain_diagnostics(x: np.ndarray, n_walkers: int) -> dict:
    """R-hat, bulk/tail ESS and MCSE of the mean of one scalar; x (n_ensembles, steps * walkers)
    (:func:`diagnostics` of one scalar, as floats)."""
    return {k: float(v[0]) for k, v in diagnostics(np.asarray(x, float)[None], n_walkers).items()}


def rule_problems(diag: dict) -> list[Problem]:
    """R-hat and ESS problems of variables with ``diag[name] = {"r_hat", "ess_bulk", "ess_tail"}``."""
    out = []
    for n, d in diag.items():
        r = d["r_hat"]
        if not (r <= RHAT_MAX):
            out.append(_problem(Failure.R_HAT, name=n, value=r, limit=RHAT_MAX))
        e = min(d["ess_bulk"], d["ess_tail"])
        if not (e >= ESS_MIN):
            out.append(_problem(Failure.ESS, name=n, value=e, limit=ESS_MIN))
    return out


def acceptance_problems(acc: np.ndarray, accept_range: tuple[float, float]) -> list[Problem]:
    lo, hi = accept_range
    if lo <= acc.mean() <= hi:
        return []
    return [_problem(Failure.ACCEPTANCE, value=float(acc.mean()), lo=lo, hi=hi)]


def nonfinite_problems(posterior: dict) -> list[Problem]:
    """One NONFINITE problem per reported variable with any NaN or infinite draw."""
    out = []
    for n, arr in posterior.items():
        bad = ~np.isfinite(np.asarray(arr, float))
        if bad.any():
            out.append(_problem(Failure.NONFINITE, name=n, count=int(bad.sum()), total=bad.size))
    return out


def failed_rules(chains, settings, full: bool = True) -> tuple[list[Problem], int]:
    """The rules that fail on the sampled parameters of ``chains`` (``uq._inference.sampler.Chains``),
    and the run length they ask for.

    ``full=False``: when the (cheap) tau rule already fails, stop there; R-hat and ESS on a chain
    that short would fail too and only cost time. Final verdicts are always full.
    """
    n, tau = chains.n_steps, float(np.max(chains.tau))
    need = settings.burn_tau + settings.tau_multiple
    problems, want = [], n
    if not math.isfinite(tau) or n - chains.burn < settings.tau_multiple * tau:
        problems.append(_problem(Failure.TAU, n_steps=n, multiple=settings.tau_multiple, tau=tau))
        want = int(math.ceil(1.1 * need * (tau if math.isfinite(tau) else n)))
        if not full:
            return problems, want
    d = diagnostics(np.moveaxis(chains.samples, -1, 0), chains.n_walkers)
    diag = {nm: {k: float(v[i]) for k, v in d.items()} for i, nm in enumerate(chains.names)}
    problems += rule_problems(diag)
    rh = _worst([d["r_hat"] for d in diag.values()], max)
    ess = _worst([min(d["ess_bulk"], d["ess_tail"]) for d in diag.values()], min)
    if not (rh <= RHAT_MAX):
        want = max(want, int(1.5 * n))
    if not (ess >= ESS_MIN):
        # ESS grows in proportion to the post-burn length
        factor = 1.2 * ESS_MIN / ess if ess > 0 else 2.0
        want = max(want, chains.burn + int(math.ceil(min(factor, 4.0) * (n - chains.burn))))
    problems += acceptance_problems(chains.acceptance, chains.accept_range)
    return problems, want


#: the runs the kept importance draws are split into for their R-hat and ESS
IMPORTANCE_CHAINS = 4


def importance_convergence(posterior: dict, result) -> Convergence:
    """The verdict of importance draws that passed their checks (``uq._inference.importance``).
    The kept draws (resampled from every adapted stage's draws, in random order) are split into
    ``IMPORTANCE_CHAINS`` consecutive runs and given the chains' statistics and rules, so that every
    reported variable carries its R-hat and ESS as a sampled one does (docs/formats.md), each ESS at
    most the smallest importance ESS of the sampled parameters (bulk and tail), which are in
    ``result.to_json()``."""
    runs = {}
    for n, a in posterior.items():
        a = np.asarray(a, float).reshape(-1, *np.shape(a)[2:])
        m = a.shape[0] // IMPORTANCE_CHAINS
        runs[n] = a[: m * IMPORTANCE_CHAINS].reshape(IMPORTANCE_CHAINS, m, *a.shape[1:])
    per_var, diag = _reported_diagnostics(runs, n_walkers=1)
    # resampling adds no information: no ESS above the smallest importance ESS of the sampled
    # parameters (a kept draw's repeats are not all seen as such by the runs' autocorrelation)
    caps = {k: min(getattr(result, k).values()) for k in ("ess_bulk", "ess_tail")}
    for d in (*per_var.values(), *diag.values()):
        for k, cap in caps.items():
            d[k] = np.minimum(d[k], cap).tolist() if isinstance(d[k], list) else min(d[k], cap)
    problems = nonfinite_problems(posterior)
    problems += [p for p in rule_problems(diag) if p not in problems]
    return Convergence(
        problems=tuple(problems),
        n_steps=0,
        burn_in=0,
        n_chains=IMPORTANCE_CHAINS,
        n_walkers=0,
        n_draws=int(result.samples.shape[0]),
        variables=per_var,
        method="importance",
        importance=result.to_json(),
    )


def _reported_diagnostics(posterior: dict, n_walkers: int) -> tuple[dict, dict]:
    """Per reported variable (name -> (chains, draws, ...) arrays in storage order): its scalars'
    R-hat, ESS and MCSE (floats, or lists for vector variables), and the worst of each."""
    per_var, diag = {}, {}
    arrays = {n: np.asarray(a, float) for n, a in posterior.items()}
    flat = {n: a.reshape(a.shape[0], a.shape[1], -1) for n, a in arrays.items()}
    sizes = {n: f.shape[-1] for n, f in flat.items()}
    if flat:  # every scalar of every variable in one vectorised call
        stacked = np.moveaxis(np.concatenate(list(flat.values()), axis=-1), -1, 0)
        d = diagnostics(stacked, n_walkers)
    offset = 0
    for n, size in sizes.items():
        ds = {k: v[offset : offset + size] for k, v in d.items()}
        offset += size
        per_var[n] = {
            k: (float(v[0]) if size == 1 else [float(e) for e in v]) for k, v in ds.items()
        }
        diag[n] = {
            "r_hat": _worst(ds["r_hat"], max),
            "ess_bulk": _worst(ds["ess_bulk"], min),
            "ess_tail": _worst(ds["ess_tail"], min),
        }
    return per_var, diag


def convergence(posterior: dict, chains) -> Convergence:
    """The verdict for the reported variables ``posterior`` (name -> (chains, draws, ...) arrays,
    in the sampler's storage order) of a run ``chains``: the sampler's own failed rules first, then
    those of the reported variables (e.g. exactly drawn coefficients)."""
    per_var, diag = _reported_diagnostics(posterior, chains.n_walkers)
    problems = list(chains.problems) + nonfinite_problems(posterior)
    for p in rule_problems(diag) + acceptance_problems(chains.acceptance, chains.accept_range):
        if p not in problems:
            problems.append(p)
    acc = chains.acceptance
    return Convergence(
        problems=tuple(problems),
        n_steps=chains.n_steps,
        burn_in=chains.burn,
        n_chains=int(chains.samples.shape[0]),
        n_walkers=int(chains.n_walkers),
        n_draws=int(chains.samples.shape[1]),
        tau={n: float(t) for n, t in zip(chains.names, chains.tau, strict=True)},
        acceptance={"mean": float(acc.mean()), "min": float(acc.min()), "max": float(acc.max())},
        variables=per_var,
    )
