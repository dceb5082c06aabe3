"""Importance sampling of the sampled parameters theta, checked by Pareto smoothing (PSIS).

For a collapsed model (``uq._inference.collapsed``) whose theta is a few parameters with a near
Gaussian posterior, independent draws from a proposal q close to the posterior p, weighted by
p / q, replace the Markov chain: no burn-in, no autocorrelation, one vectorised call of the log
posterior per stage. Whether that worked is judged by the draws themselves (Yao, Vehtari,
Simpson & Gelman 2018, "Yes, but did it work?"; Vehtari et al. 2024, "Pareto smoothed importance
sampling"): the Pareto shape k-hat of the largest weights (``K_MAX``, 0.7: above it the
estimates are unreliable at any affordable number of draws) and the effective sample size of the
smoothed weights, which must reach the convergence rules' ``ESS_MIN`` for every sampled parameter
in the bulk and in both 5 % tails. A run that fails either is refused (``Importance.passed``
false, with the reason), and the caller samples with emcee instead.

The proposal (``sample``): a Student t (``DF``) at the MAP with the Laplace covariance alone is
not enough (measured on data/n50 and five simulated campaigns: k-hat 0.46-0.95, and at 0.68 the
force floor's 5 % quantile 0.43 posterior sd off the sampler's), because the posterior of theta
is skewed (the force floor, the length scale). So it is adapted, the form of the sampler's held
proposal (``uq._inference.sampler._HeldIndependence``): each coordinate standardised by the
weighted draws' mean and sd and transformed by Yeo-Johnson with the exponent that makes its
(resampled) draws most nearly normal, a t with the transformed draws' weighted mean and
covariance; a share ``DEFENSIVE`` of every stage's draws comes from the Laplace t
``DEFENSIVE_SCALE`` times as wide, and the weights use the mixture's density, so no weight can
exceed 1 / ``DEFENSIVE`` times the Laplace t's ratio (Hesterberg 1995's defensive mixture).

The stages recycle their draws (adaptive multiple importance sampling, AMIS: Cornuet, Marin, Mira
& Robert 2012): the first stage's ``STAGE_DRAWS`` come from the Laplace t; each of the ``REFITS``
stages after it draws ``STAGE_DRAWS`` from the proposal fitted to all the adapted stages' draws so
far, and those draws are weighted by the deterministic mixture of the adapted stages' proposals
(the balance heuristic: p / mean_j q_j), so no draw is thrown away and the posterior's far tails
(the force floor's and the length scale's, where the likelihood goes flat and the prior takes
over), which a stage of a few thousand draws barely reaches, shape the proposals of the next. The
adapted stages' pooled draws make the posterior: they are resampled systematically to ``n_keep``
equally weighted draws, so every downstream computation (exact coefficient draws, bands,
quantiles) is that of a sampler's draws. Measured against the earlier form (three adaptations, a
last stage of 64000 draws from one proposal, 76000 evaluations) on the between-pressure study's
ten campaigns of the paper's eleven-pressure layout: every campaign kept (k-hat at most 0.60,
every ESS at least 958) with 24000 evaluations, where the earlier form refused four (docs/speed.md).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from uq._inference.convergence import ESS_MIN
from uq._inference.loo import PARETO_K_MAX, psislw
from uq._inference.sampler import yeo_johnson, yeo_johnson_exponents, yeo_johnson_log_slope

#: Pareto k-hat above which importance sampling is refused (Vehtari et al. 2024): the PSIS-LOO rule's
K_MAX = PARETO_K_MAX
#: draws of every stage
STAGE_DRAWS = 3000
#: stages after the first (the Laplace t's), each from the proposal fitted to the draws before it;
#: their pooled draws make the posterior
REFITS = 7
#: degrees of freedom of the t proposals
DF = 4.0
#: share of every stage's draws from the widened Laplace t, and its width in Laplace sds
DEFENSIVE = 0.1
DEFENSIVE_SCALE = 2.0
#: resampled draws the Yeo-Johnson exponents are fitted to
LAMBDA_DRAWS = 2000


@dataclass(frozen=True)
class _T:
    """A Student t after a per-coordinate standardisation and Yeo-Johnson transformation: x =
    center + scale * YJ^-1(y), y ~ t(df, mean, chol chol^T)."""

    center: np.ndarray
    scale: np.ndarray
    lam: np.ndarray
    mean: np.ndarray
    chol: np.ndarray
    df: float = DF

    def draw(self, rng: np.random.Generator, n: int) -> np.ndarray:
        d = self.center.size
        z = rng.standard_normal((n, d))
        w = np.sqrt(self.df / rng.chisquare(self.df, size=(n, 1)))
        y = self.mean + w * z @ self.chol.T
        return self.center + self.scale * yeo_johnson(y, self.lam, inverse=True)

    def log_density(self, x: np.ndarray) -> np.ndarray:
        d = self.center.size
        u = (x - self.center) / self.scale
        with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
            v = np.linalg.solve(self.chol, (yeo_johnson(u, self.lam) - self.mean).T).T
            r = np.sum(v * v, axis=1)
            norm = (
                math.lgamma((self.df + d) / 2)
                - math.lgamma(self.df / 2)
                - 0.5 * d * math.log(self.df * math.pi)
                - np.sum(np.log(np.diag(self.chol)))
                - np.sum(np.log(self.scale))
            )
            return (
                norm
                - 0.5 * (self.df + d) * np.log1p(r / self.df)
                + yeo_johnson_log_slope(u, self.lam)
            )


def _laplace(center: np.ndarray, cov: np.ndarray, widen: float = 1.0) -> _T:
    d = center.size
    one = np.ones(d)
    return _T(center, one, one, np.zeros(d), widen * np.linalg.cholesky(cov))


def _fitted(x: np.ndarray, w: np.ndarray, rng: np.random.Generator) -> _T:
    """The transformed t fitted to draws ``x`` (n, d) with normalised weights ``w`` (n,)."""
    center = w @ x
    scale = np.sqrt(w @ (x - center) ** 2)
    z = (x - center) / scale
    lam = yeo_johnson_exponents(z[rng.choice(len(x), size=LAMBDA_DRAWS, p=w)])
    y = yeo_johnson(z, lam)
    mean = w @ y
    cov = ((y - mean) * w[:, None]).T @ (y - mean)
    return _T(center, scale, lam, mean, np.linalg.cholesky(cov))


def _mixture_log_density(parts: list[tuple[float, _T]], x: np.ndarray, known=None) -> np.ndarray:
    """log of sum_j p_j q_j(x); ``known``: per part, its log density at ``x`` when already made
    (None: computed here)."""
    logs = [
        q.log_density(x) if k is None else k
        for (_, q), k in zip(parts, known or [None] * len(parts), strict=True)
    ]
    terms = np.stack([math.log(p) + lq for (p, _), lq in zip(parts, logs, strict=True)])
    top = np.max(terms, axis=0)
    top = np.where(np.isfinite(top), top, 0.0)
    return top + np.log(np.sum(np.exp(terms - top), axis=0))


def _mixture_draw(parts: list[tuple[float, _T]], rng, n: int) -> np.ndarray:
    counts = rng.multinomial(n, [p for p, _ in parts])
    x = np.concatenate([q.draw(rng, k) for (_, q), k in zip(parts, counts, strict=True)])
    return x[rng.permutation(n)]


def psis_weights(log_ratio: np.ndarray) -> tuple[np.ndarray, float]:
    """Pareto-smoothed normalised importance weights of log ratios log p - log q (n,) (ArviZ's
    ``psislw`` with ``reff=1``, by the project's own kernel ``uq._inference.loo``) and the
    Pareto k-hat; non-finite ratios weigh 0."""
    lr = np.where(np.isfinite(log_ratio), log_ratio, -np.inf)
    lw, k = psislw(lr - np.max(lr))
    w = np.exp(lw - np.max(lw))
    return w / w.sum(), float(k)


def weighted_ess(x: np.ndarray, w: np.ndarray) -> dict:
    """Effective sample sizes of self-normalised importance estimates (Vehtari et al. 2024, eq.
    6 with h): of the mean of each column of ``x`` (n, d) (``bulk``) and of its 5 % and 95 %
    quantiles (``tail``, the smaller: the indicators of the two cuts, as the rules' tail ESS)."""

    def ess_of(h):  # h (n, d)
        m = w @ h
        var = w @ (h - m) ** 2
        with np.errstate(invalid="ignore", divide="ignore"):
            return var / (w**2 @ (h - m) ** 2)

    order = np.argsort(x, axis=0)
    cum = np.cumsum(np.take_along_axis(np.broadcast_to(w[:, None], x.shape), order, 0), 0)
    tails = []
    for q in (0.05, 0.95):
        cut = np.take_along_axis(x, order, 0)[np.argmax(cum >= q, axis=0), np.arange(x.shape[1])]
        tails.append(ess_of((x <= cut).astype(float)))
    return {"bulk": ess_of(x), "tail": np.minimum(*tails)}


@dataclass(frozen=True)
class Importance:
    """What :func:`sample` did: the resampled draws (n_keep, d) and the checks that judge them."""

    samples: np.ndarray
    pareto_k: float
    ess: float  # of the smoothed weights, 1 / sum w^2
    ess_bulk: dict  # per sampled parameter
    ess_tail: dict
    n_draws: int
    stages_k: tuple[float, ...]
    problem: str | None  # why the draws are refused; None when they pass

    @property
    def passed(self) -> bool:
        return self.problem is None

    def to_json(self) -> dict:
        return {
            "passed": self.passed,
            "reason": self.problem,
            "pareto_k": self.pareto_k,
            "pareto_k_max": K_MAX,
            "ess": self.ess,
            "ess_min": ESS_MIN,
            "n_draws": self.n_draws,
            "n_kept": int(self.samples.shape[0]),
            "adaptation_pareto_k": list(self.stages_k),
            "ess_bulk": dict(self.ess_bulk),
            "ess_tail": dict(self.ess_tail),
        }


def sample(log_prob, center, cov, names, *, seed: int, n_keep: int) -> Importance:
    """Importance sampling of ``log_prob`` ((m, d) -> (m,), vectorised) from the MAP ``center``
    (d,) and Laplace covariance ``cov`` (d, d): the Laplace stage, ``REFITS`` adapted stages whose
    draws are pooled under their proposals' mixture, PSIS, the checks (module docstring), and
    ``n_keep`` draws resampled systematically from the smoothed weights. Deterministic for
    ``seed``."""
    rng = np.random.default_rng(seed)
    center, cov = np.asarray(center, float), np.asarray(cov, float)
    defensive = (DEFENSIVE, _laplace(center, cov, DEFENSIVE_SCALE))
    parts = [(1.0 - DEFENSIVE, _laplace(center, cov)), defensive]
    x = _mixture_draw(parts, rng, STAGE_DRAWS)
    with np.errstate(over="ignore", invalid="ignore"):
        lp = np.asarray(log_prob(x), float)
        w, k = psis_weights(lp - _mixture_log_density(parts, x))
    ks = []
    # the adapted stages: proposals, draws, log posteriors, the defensive part's log density at
    # each stage's draws (every proposal shares it), and the log density of every stage's draws
    # under every proposal (logq[j][i]: proposal j at stage i's draws)
    props, xs, lps, logd, logq = [], [], [], [], []
    for i in range(REFITS):
        ks.append(k)
        try:
            parts = [(1.0 - DEFENSIVE, _fitted(x, w, rng)), defensive]
        except np.linalg.LinAlgError:
            return _refused(x, ks, f"the weighted draws of stage {i + 1} have no covariance")
        new = _mixture_draw(parts, rng, STAGE_DRAWS)
        with np.errstate(over="ignore", invalid="ignore"):
            lps.append(np.asarray(log_prob(new), float))
            logd.append(defensive[1].log_density(new))
            for j, q in enumerate(props):
                logq[j].append(_mixture_log_density(q, new, (None, logd[-1])))
            props.append(parts)
            xs.append(new)
            logq.append(
                [_mixture_log_density(parts, a, (None, b)) for a, b in zip(xs, logd, strict=True)]
            )
            x = np.concatenate(xs)
            pooled = np.logaddexp.reduce([np.concatenate(row) for row in logq], axis=0)
            w, k = psis_weights(np.concatenate(lps) - (pooled - math.log(len(props))))
    ess = float(1.0 / np.sum(w * w))
    per = weighted_ess(x, w)
    bulk = {n: float(v) for n, v in zip(names, per["bulk"], strict=True)}
    tail = {n: float(v) for n, v in zip(names, per["tail"], strict=True)}
    low = min(min(bulk.values()), min(tail.values()))
    problem = None
    if not k <= K_MAX:
        problem = f"Pareto k-hat {k:.2f} > {K_MAX}"
    elif not low >= ESS_MIN:
        problem = f"effective sample size {low:.0f} < {ESS_MIN:.0f}"
    u = (rng.random() + np.arange(n_keep)) / n_keep
    idx = np.minimum(np.searchsorted(np.cumsum(w), u), len(w) - 1)
    # in random order: systematic resampling keeps the pooled draws' order, stage by stage, and
    # the runs the kept draws are split into (R-hat and ESS, ``uq._inference.convergence``) must
    # not be the stages
    idx = idx[rng.permutation(n_keep)]
    return Importance(x[idx], k, ess, bulk, tail, len(x), tuple(ks), problem)


def _refused(x, ks, reason) -> Importance:
    return Importance(x[:0], math.inf, 0.0, {}, {}, 0, tuple(ks), reason)
