"""Leave-one-out model comparison in one place: PSIS-LOO, exact refits, K-fold, and the rules.

* :func:`psis` — ArviZ's PSIS-LOO of pointwise log-likelihoods, as a :class:`Loo`.
* :func:`reloo` — PSIS terms whose Pareto k exceeds ``PARETO_K_MAX`` replaced by exact
  leave-one-out values from a refit callable (ArviZ's ``reloo`` remedy; arviz-stats
  ``loo/reloo.py``): ``refit(i)`` returns log p(y_i | y_-i) from the model refitted without term i.
* :func:`kfold` — exact K-fold cross-validation from a callable that scores held-out terms,
  the sibling remedy when too many terms are unreliable for refits one by one.
* :func:`held_out_density` — the exact leave-out value from a refitted posterior whose data kept
  the held-out terms with zero weight (every model here can: ``CollapsedModel.hold_out``).
* :func:`remedy` — the one policy for a comparison PSIS-LOO cannot be trusted with, used by the
  model comparison (``uq._derived.comparison``) and the discrepancy engine: the unreliable terms
  refitted exactly while there are at most ``MAX_REFITS`` of them in a model, K-fold of both
  models beyond.
* :func:`verdict` — which of two models the data prefer: a difference counts only beyond
  ``SE_MULTIPLE`` (2) standard errors and ``ELPD_MIN`` (4) nats, and no verdict is given while a
  Pareto k > 0.7 remains ("refused").
* :func:`z_required` — the diagnose engine's rule for one mechanism's worth (its gain must exceed
  4 nats and a Bonferroni-adjusted number of standard errors).

Standard errors of a difference are sqrt(n Var(diff)) over the pointwise differences, as ArviZ's
``compare`` computes them.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np
from scipy.special import ndtr, ndtri

from uq._inference.threads import THREADS, side_by_side

#: a PSIS-LOO term is unreliable when its Pareto k exceeds this (Vehtari et al. 2017/2024)
PARETO_K_MAX = 0.7
#: a difference is called only beyond this many standard errors ...
SE_MULTIPLE = 2.0
#: ... and beyond this many nats (Sivula, Magnusson, Vehtari 2020: smaller ones are unreliable)
ELPD_MIN = 4.0
#: exact refits for at most this many unreliable terms of a model; more: K-fold instead (:func:`remedy`)
MAX_REFITS = 20
#: the folds of the K-fold cross-validation that replaces the refits
N_FOLDS = 10


@dataclass(frozen=True)
class Loo:
    """Pointwise leave-one-out log predictive densities of one model.

    ``loo_i`` (n,), ``pareto_k`` (n,) (0 where a term is exact: refits, K-fold), ``method`` how
    they were obtained, ``n_refits`` how many terms were replaced by exact refits."""

    loo_i: np.ndarray
    pareto_k: np.ndarray
    method: str = "psis-loo"
    n_refits: int = 0
    p_loo: float = float("nan")

    @property
    def elpd(self) -> float:
        return float(np.sum(self.loo_i))

    @property
    def se(self) -> float:
        return float(math.sqrt(self.loo_i.size * np.var(self.loo_i)))

    @property
    def n_bad(self) -> int:
        return int(np.sum(self.pareto_k > PARETO_K_MAX))

    @property
    def reliable(self) -> bool:
        return self.n_bad == 0

    def pareto(self) -> dict:
        """PSIS reliability: the largest Pareto k and how many terms exceed 0.7.

        A k ArviZ could not estimate (``inf``: a tail too short or degenerate to fit) counts as
        over 0.7; ``max`` is then None (JSON has no infinity) and ``n_undefined`` says how many."""
        finite = np.isfinite(self.pareto_k)
        return {
            "max": float(np.max(self.pareto_k)) if finite.all() else None,
            "n_over_0.7": self.n_bad,
            "n_undefined": int(np.sum(~finite)),
            "n_terms": int(self.pareto_k.size),
        }

    def __repr__(self) -> str:
        return f"Loo(elpd {self.elpd:.1f} +- {self.se:.1f}, {self.method}, max k {np.max(self.pareto_k):.2f})"


def loglik_idata(loglik):
    """ArviZ InferenceData holding pointwise log-likelihoods ``loglik`` (chains, draws, n) only."""
    # reason: ArviZ (and xarray under it) costs about a second to import; a fit never needs it
    import arviz as az

    ll = np.asarray(loglik)
    return az.from_dict(posterior={"_": np.zeros(ll.shape[:2])}, log_likelihood={"reading": ll})


def psis(loglik, *, reff: float | None = None) -> Loo:
    """ArviZ's PSIS-LOO of log-likelihoods (chains, draws, n) (``az.loo(pointwise=True)``, Vehtari
    et al. 2017/2024), computed by :func:`psis_loo` for every reading at once. ``reff`` the relative
    efficiency of the draws: 1.0 for independent draws; None as ArviZ takes it for a log-likelihood
    alone (its ESS of a constant posterior: 1, or (D - 1) / D for an odd number D of draws per
    chain). Every caller reports the Pareto k values itself (ArviZ's warning is not raised)."""
    ll = np.asarray(loglik, float)
    C, D, n = ll.shape
    if reff is None:
        reff = 1.0 if C == 1 else 2 * (D // 2) / D
    loo_i, k, p_loo = psis_loo(ll.reshape(C * D, n).T, reff)
    return Loo(loo_i, k, "psis-loo", 0, p_loo)


def _logsumexp(a: np.ndarray, axis: int = -1) -> np.ndarray:
    top = np.max(a, axis=axis, keepdims=True)
    top = np.where(np.isfinite(top), top, 0.0)
    with np.errstate(divide="ignore"):
        return np.log(np.sum(np.exp(a - top), axis=axis)) + np.squeeze(top, axis)


def _gpd_fit(tails: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """ArviZ's ``_gpdfit`` (Zhang & Stephens' empirical Bayes estimate of the generalised Pareto
    shape k and scale sigma, with its weak prior on k) of many sorted tails (N, M) at once."""
    prior_bs, prior_k = 3, 10
    N, M = tails.shape
    m_est = 30 + int(M**0.5)
    b = 1 - np.sqrt(m_est / (np.arange(1, m_est + 1, dtype=float) - 0.5))
    b = (
        b[None, :] / (prior_bs * tails[:, int(M / 4 + 0.5) - 1 : int(M / 4 + 0.5)])
        + 1 / tails[:, -1:]
    )
    with np.errstate(invalid="ignore", divide="ignore"):
        k = np.mean(np.log1p(-b[:, :, None] * tails[:, None, :]), axis=2)  # (N, m_est)
        len_scale = M * (np.log(-(b / k)) - k - 1)
        weights = 1 / np.exp(len_scale[:, None, :] - len_scale[:, :, None]).sum(axis=2)
    weights = np.where(weights >= 10 * np.finfo(float).eps, weights, 0.0)  # negligible ones out
    weights = weights / weights.sum(axis=1, keepdims=True)
    b_post = np.sum(b * weights, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        k_post = np.mean(np.log1p(-b_post[:, None] * tails), axis=1)
        sigma = -k_post / b_post
    return (M * k_post + prior_k * 0.5) / (M + prior_k), sigma


def _gpd_quantiles(probs: np.ndarray, k: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """ArviZ's ``_gpinv`` for probabilities in (0, 1), many (k, sigma) at once, (N, M)."""
    k, sigma = k[:, None], sigma[:, None]
    small = np.abs(k) < np.finfo(float).eps
    with np.errstate(invalid="ignore", divide="ignore"):
        x = np.where(
            small, -np.log1p(-probs), np.expm1(-k * np.log1p(-probs)) / np.where(small, 1.0, k)
        )
    return np.where(sigma > 0, x * sigma, np.nan)


def _psislw_one(log_weights: np.ndarray, cutoff_ind: int, cutoffmin: float):
    """ArviZ's ``_psislw`` (``normalize=False``) of one reading, step by step the same numpy
    operations (the same numbers, tested against it), without importing ArviZ and xarray (about
    1.7 CPU s): for a reading whose tail is cut by ties (an MCMC chain repeats a rejected draw),
    by the smallest float, or is too short to fit. Returns (log weights, Pareto k)."""
    x = np.array(log_weights, float)
    max_x = np.max(x)
    x -= max_x
    xcutoff = max(x[np.argsort(x)[cutoff_ind]], cutoffmin)
    expxcutoff = np.exp(xcutoff)
    (tailinds,) = np.where(x > xcutoff)
    x_tail = x[tailinds]
    tail_len = len(x_tail)
    if tail_len <= 4:  # not enough tail samples for the fit
        return x + max_x, np.inf
    x_tail_si = np.argsort(x_tail)
    x_tail = np.exp(x_tail) - expxcutoff
    k, sigma = _gpd_fit_one(x_tail[x_tail_si])
    if np.isfinite(k):
        sti = np.arange(0.5, tail_len) / tail_len
        x[tailinds[x_tail_si]] = np.log(_gpd_inverse_one(sti, k, sigma) + expxcutoff)
        x[x > 0] = 0
    return x + max_x, float(k)


def psislw(log_weights: np.ndarray) -> tuple[np.ndarray, float]:
    """Pareto-smoothed log weights of independent draws (ArviZ's ``psislw`` with ``reff=1``: a
    tail of min(S / 5, 3 sqrt(S)) draws, unnormalised) and the Pareto k-hat, for importance
    sampling (``uq._inference.importance``); log_weights (S,)."""
    S = np.size(log_weights)
    n_tail = int(np.ceil(min(S / 5.0, 3.0 * np.sqrt(S))))
    return _psislw_one(log_weights, -n_tail - 1, np.log(np.finfo(float).tiny))


def _gpd_fit_one(ary: np.ndarray) -> tuple[float, float]:
    """ArviZ's ``_gpdfit`` of one sorted tail, its operations in its order (:func:`_gpd_fit` does
    many tails at once, equal to rounding)."""
    prior_bs, prior_k = 3, 10
    n = len(ary)
    m_est = 30 + int(n**0.5)
    b_ary = 1 - np.sqrt(m_est / (np.arange(1, m_est + 1, dtype=float) - 0.5))
    b_ary /= prior_bs * ary[int(n / 4 + 0.5) - 1]
    b_ary += 1 / ary[-1]
    with np.errstate(invalid="ignore", divide="ignore"):
        k_ary = np.log1p(-b_ary[:, None] * ary).mean(axis=1)
        len_scale = n * (np.log(-(b_ary / k_ary)) - k_ary - 1)
        weights = 1 / np.exp(len_scale - len_scale[:, None]).sum(axis=1)
    real = weights >= 10 * np.finfo(float).eps
    if not np.all(real):
        weights, b_ary = weights[real], b_ary[real]
    weights /= weights.sum()
    b_post = np.sum(b_ary * weights)
    with np.errstate(invalid="ignore", divide="ignore"):
        k_post = np.log1p(-b_post * ary).mean()
        sigma = -k_post / b_post
    return (n * k_post + prior_k * 0.5) / (n + prior_k), sigma


def _gpd_inverse_one(probs: np.ndarray, kappa: float, sigma: float) -> np.ndarray:
    """ArviZ's ``_gpinv`` for probabilities in (0, 1) and one (k, sigma)."""
    if sigma <= 0:
        return np.full_like(probs, np.nan)
    if np.abs(kappa) < np.finfo(float).eps:
        x = -np.log1p(-probs)
    else:
        x = np.expm1(-kappa * np.log1p(-probs)) / kappa
    return x * sigma


#: observations smoothed together (the GPD fit holds (chunk, 30 + sqrt(M), M) numbers). Small,
#: because each thread of ``side_by_side`` allocates from its own glibc arena, which keeps what it
#: once held (``uq._inference.allocator`` raises the trim threshold): with 256 readings a chunk
#: two threads kept about 115 MB more than one thread did, at 64 about 30 MB (814 readings, 4000
#: draws); the numbers are the same for any chunk (tested)
PSIS_CHUNK = 64


def _psis_chunk(ll: np.ndarray, n_tail: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`psis_loo` of the readings ``ll`` (m, S): (loo_i (m,), pareto_k (m,), each reading's
    log of the summed likelihood over the draws (m,))."""
    n, S = ll.shape
    cutoffmin = np.log(np.finfo(float).tiny)
    lw = -ll - np.max(-ll, axis=1, keepdims=True)
    # only the cut and the tail need their order: the n_tail + 1 largest weights of each reading,
    # found by a partition and then sorted (the same order statistics as a full sort)
    # (fewer than 5 tail draws: no reading is fitted here, and S may be too small to cut)
    top = np.argpartition(lw, max(S - n_tail - 1, 0), axis=1)[:, max(S - n_tail - 1, 0) :]
    vals = np.take_along_axis(lw, top, axis=1)
    ascending = np.argsort(vals, axis=1)
    top = np.take_along_axis(top, ascending, axis=1)
    vals = np.take_along_axis(vals, ascending, axis=1)
    cut = vals[:, 0]
    regular = (n_tail > 4) & (vals[:, min(1, S - 1)] > cut) & (cut > cutoffmin)
    k = np.full(n, np.inf)
    probs = np.arange(0.5, n_tail) / n_tail
    rows = np.flatnonzero(regular)
    if rows.size:
        ecut = np.exp(cut[rows])[:, None]
        tails = np.exp(vals[rows, 1:]) - ecut
        kk, sigma = _gpd_fit(tails)
        k[rows] = kk
        ok = np.isfinite(kk)
        smooth = np.log(_gpd_quantiles(probs, kk[ok], sigma[ok]) + ecut[ok])
        # the tail's weights replaced by the smoothed ones, in the tail's order; none above 0
        fit = rows[ok]
        lw[fit[:, None], top[fit, 1:]] = np.minimum(smooth, 0.0)
    for i in np.flatnonzero(~regular):  # ArviZ's one-reading algorithm for the irregular ones
        lw[i], k[i] = _psislw_one(-ll[i] - np.max(-ll[i]), -n_tail - 1, cutoffmin)
    lw = lw - _logsumexp(lw)[:, None]
    return _logsumexp(lw + ll), k, _logsumexp(ll)


def psis_loo(
    loglik: np.ndarray, reff: float = 1.0, *, chunk: int = PSIS_CHUNK, threads: int = THREADS
) -> tuple[np.ndarray, np.ndarray, float]:
    """PSIS-LOO of ``loglik`` (n, S): S draws of n readings' log-likelihoods -> (loo_i (n,),
    pareto_k (n,), p_loo). ArviZ's algorithm (``psislw`` then ``loo``), vectorised over readings:
    ArviZ smooths one reading at a time through xarray, which cost diagnose about 6 CPU s. A
    reading whose tail is cut by ties or the smallest float, or too short to fit (4 draws or
    fewer), goes through ArviZ's one-reading algorithm (:func:`_psislw_one`);
    tests/inference/test_loo.py compares both with ArviZ. The readings are smoothed ``chunk`` at
    a time, the chunks by ``threads`` threads side by side (the same numbers for any ``chunk``
    and ``threads``: every reading is smoothed on its own; tested)."""
    ll = np.asarray(loglik, float)
    n, S = ll.shape
    n_tail = int(np.ceil(min(S / 5.0, 3 * (S / reff) ** 0.5)))
    parts = [ll[lo : lo + chunk] for lo in range(0, n, chunk)] or [ll]
    done = side_by_side(lambda p: _psis_chunk(p, n_tail), parts, threads=threads)
    loo_i, k, lse = (np.concatenate(a) for a in zip(*done, strict=True))
    lppd = float(np.sum(lse - np.log(S)))
    return loo_i, k, lppd - float(np.sum(loo_i))


def logmeanexp(a, axis=0):
    """log of the mean of exp(a) along ``axis``, stably."""
    a = np.asarray(a, float)
    top = np.max(a, axis=axis, keepdims=True)
    return np.squeeze(top, axis) + np.log(np.mean(np.exp(a - top), axis=axis))


def held_out_density(loglik, terms) -> np.ndarray:
    """log p(y_i | y_-i) of the held-out ``terms`` from the pointwise log-likelihood (draws..., n)
    of a posterior fitted without them: the log of the mean likelihood over the draws."""
    ll = np.asarray(loglik, float)
    return logmeanexp(ll.reshape(-1, ll.shape[-1])[:, terms], axis=0)


def reloo(loo: Loo, refit: Callable[[int], float]) -> Loo:
    """``loo`` with every term of Pareto k > 0.7 replaced by ``refit(i)`` (exact; its k set to 0);
    how many terms to refit before K-fold is better is :func:`remedy`'s rule."""
    bad = np.flatnonzero(loo.pareto_k > PARETO_K_MAX)
    if bad.size == 0:
        return loo
    loo_i, k = loo.loo_i.copy(), loo.pareto_k.copy()
    for i in bad:
        loo_i[i], k[i] = refit(int(i)), 0.0
    return replace(
        loo,
        loo_i=loo_i,
        pareto_k=k,
        method=f"{loo.method}, k > {PARETO_K_MAX:g} terms refitted exactly",
        n_refits=int(bad.size),
    )


def kfold(
    n_units: int,
    score: Callable[[np.ndarray], np.ndarray],
    *,
    n_folds: int = N_FOLDS,
    seed: int = 0,
) -> Loo:
    """Exact K-fold cross-validation: units split at random (seeded) into ``n_folds`` folds;
    ``score(held)`` refits without the units ``held`` (bool, (n_units,)) and returns the log
    predictive density of every term (the caller's terms; NaN where not held out); the result
    holds each term's value from the fold that held it out."""
    fold = np.random.default_rng(seed).permutation(n_units) % n_folds
    out = None
    for k in range(n_folds):
        values = np.asarray(score(fold == k), float)
        out = np.full_like(values, np.nan) if out is None else out
        held = ~np.isnan(values)
        out[held] = values[held]
    return Loo(out, np.zeros_like(out), f"{n_folds}-fold cross-validation")


def remedy(
    a: Loo,
    b: Loo,
    *,
    refit: tuple[Callable[[int], float] | None, Callable[[int], float] | None] = (None, None),
    kfold_both: Callable[[], tuple[Loo, Loo]] | None = None,
) -> tuple[Loo, Loo, str]:
    """The one remedy for comparing two models whose PSIS-LOO terms are not all reliable:
    (a, b, how they were scored).

    Both reliable: as they are ("psis-loo"). At most ``MAX_REFITS`` terms of Pareto k > 0.7 in
    each model: those terms replaced by exact refits (``refit``: one callable per model, ``None``
    for a model that offers none, whose unreliable terms stay so and refuse a verdict). More:
    both models scored by exact K-fold cross-validation on the same folds (``kfold_both()``;
    without it the terms stay as they are)."""
    if a.reliable and b.reliable:
        return a, b, "psis-loo"
    if max(a.n_bad, b.n_bad) <= MAX_REFITS:
        a, b = (
            loo if fn is None else reloo(loo, fn) for loo, fn in zip((a, b), refit, strict=True)
        )
        return a, b, f"psis-loo, k > {PARETO_K_MAX:g} terms refitted exactly"
    if kfold_both is None:
        return (
            a,
            b,
            f"psis-loo (more than {MAX_REFITS} terms of k > {PARETO_K_MAX:g}: not refitted)",
        )
    ka, kb = kfold_both()
    return ka, kb, ka.method


def difference(a: Loo, b: Loo) -> tuple[float, float]:
    """ELPD difference a - b and its standard error."""
    diff = a.loo_i - b.loo_i
    return float(diff.sum()), float(math.sqrt(diff.size * np.var(diff)))


def verdict(a: Loo, b: Loo, names: tuple[str, str] = ("first", "second")) -> dict:
    """Which model the data prefer (module docstring): one of ``names``, "indistinguishable" or
    "refused"."""
    d, se = difference(a, b)
    bad = {nm: lo.n_bad for nm, lo in zip(names, (a, b), strict=True)}
    if any(bad.values()):
        which = ", ".join(f"{nm}: {c}" for nm, c in bad.items() if c)
        better = "refused"
        why = (
            f"PSIS-LOO not reliable: readings with Pareto k > {PARETO_K_MAX:g} ({which}); "
            "no verdict (K-fold cross-validation would be needed)"
        )
    elif abs(d) > SE_MULTIPLE * se and abs(d) > ELPD_MIN:
        better = names[0] if d > 0 else names[1]
        why = f"ELPD difference {d:.1f} +- {se:.1f} exceeds {SE_MULTIPLE:g} SE"
    else:
        better = "indistinguishable"
        why = f"ELPD difference {d:.1f} +- {se:.1f} is within {SE_MULTIPLE:g} SE (or below {ELPD_MIN:g})"
    return {
        "elpd_diff": d,
        "elpd_diff_se": se,
        "better": better,
        "reason": why,
        "rule": f"better only if |diff| > {SE_MULTIPLE:g} SE and > {ELPD_MIN:g}, and every Pareto k <= {PARETO_K_MAX:g}",
    }


def z_required(n_candidates: int, gain_se: float) -> float:
    """Bonferroni: the z a gain must exceed when ``n_candidates`` are tested at one step.

    ``gain_se`` is the one-sided threshold for a single candidate; its tail probability is
    shared out over the candidates, so the family of tests at a step keeps that error rate.
    """
    # norm.isf(norm.sf(g) / k) through scipy.special (scipy.stats' own formulas for the normal):
    # scipy.stats takes about 0.6 CPU s to import, which `uq fit` otherwise does not need
    return float(-ndtri(ndtr(-gain_se) / max(n_candidates, 1)))
