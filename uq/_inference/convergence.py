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
"""

from __future__ import annotations

import enum
import math
import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

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

    @property
    def extends_run(self) -> bool:
        """Whether running longer can cure it (the acceptance fraction does not change with length)."""
        return self not in (Failure.ACCEPTANCE, Failure.NONFINITE)


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
    (floats, or lists for vector variables). ``tau``: per sampled parameter.
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

    @property
    def converged(self) -> bool:
        return not self.problems

    def messages(self, advice: str = LIBRARY_ADVICE) -> list[str]:
        return [p.message(advice) for p in self.problems]

    @property
    def warnings(self) -> list[str]:
        return self.messages()

    def worst(self) -> tuple[float, float]:
        """(largest R-hat, smallest bulk ESS) over every reported variable."""
        rh = max(float(np.max(v["r_hat"])) for v in self.variables.values())
        ess = min(float(np.min(v["ess_bulk"])) for v in self.variables.values())
        return rh, ess

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
        if variables:
            out["variables"] = self.variables
        return out

    def __repr__(self) -> str:
        state = "converged" if self.converged else f"{len(self.problems)} rule(s) failed"
        return f"Convergence({state}, {self.n_steps} steps, burn-in {self.burn_in})"


# ----------------------------------------------------------------------------- statistics


def _worst(values, pick):
    """``pick`` (max or min) of the values, NaN if any is NaN (an undefined statistic fails its rule)."""
    v = np.asarray(values, float)
    return float("nan") if np.any(np.isnan(v)) else float(pick(v))


def _ess_of_summary(x: np.ndarray, per_step: np.ndarray) -> float:
    """Draw-scale ESS of the ensemble-mean chains ``per_step`` (C, T) summarising ``x``."""
    import arviz as az

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
    import arviz as az

    x = np.asarray(x, float)
    C = x.shape[0]
    xw = x.reshape(C, -1, n_walkers)
    with warnings.catch_warnings():
        warnings.simplefilter(
            "ignore"
        )  # "more chains than draws" on very short runs: judged by the rules
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
    diag = {
        nm: chain_diagnostics(chains.samples[..., i], chains.n_walkers)
        for i, nm in enumerate(chains.names)
    }
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


def convergence(posterior: dict, chains) -> Convergence:
    """The verdict for the reported variables ``posterior`` (name -> (chains, draws, ...) arrays,
    in the sampler's storage order) of a run ``chains``: the sampler's own failed rules first, then
    those of the reported variables (e.g. exactly drawn coefficients)."""
    per_var, diag = {}, {}
    for n, arr in posterior.items():
        arr = np.asarray(arr)
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
