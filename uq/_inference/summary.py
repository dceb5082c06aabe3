"""Posterior summaries in the contract's shape: {"mean", "sd", "q05", "q95"}, bands, and the one
rule by which draws are thinned."""

from __future__ import annotations

import numpy as np


def estimate(draws, axis=None) -> dict:
    """Summary of posterior draws (flattened unless ``axis`` is given)."""
    d = np.asarray(draws, float)
    if axis is None:
        d = d.reshape(-1)
        axis = 0
    return {
        "mean": np.mean(d, axis=axis),
        "sd": np.std(d, axis=axis, ddof=1),
        "q05": np.quantile(d, 0.05, axis=axis),
        "q95": np.quantile(d, 0.95, axis=axis),
    }


def band(draws, axis=0, level=0.90) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(mean, lower, upper) of an equal-tailed ``level`` band over ``axis`` (:func:`quantiles`)."""
    d = np.asarray(draws, float)
    a = (1.0 - level) / 2.0
    lo, hi = quantiles(d, (a, 1.0 - a), axis)
    return d.mean(axis=axis), lo, hi


def quantiles(draws, qs, axis=0) -> np.ndarray:
    """``np.quantile(draws, qs, axis=axis)`` (its default, linear method): the same numbers (a
    tie of -0.0 and 0.0 may come out as either) at about a third of the cost. numpy partitions
    the draws once around every rank it needs, on a path several times slower than its
    (vectorised) partition around one rank; here each quantile's two neighbouring order
    statistics come from one partition around one rank, and numpy interpolates between them
    (``np.quantile`` of the pair at the fractional rank: the same arithmetic). A NaN among the
    draws gives NaN, as numpy does."""
    x = np.moveaxis(np.asarray(draws, float), axis, -1).copy()  # partitioned in place
    n = x.shape[-1]
    out = []
    for q in qs:
        rank = (n - 1) * q  # numpy's, as it computes it
        k = int(np.floor(rank))
        if not 0 <= k < n - 1:  # the largest draw, a single one, or q out of [0, 1]: numpy's way
            out.append(np.quantile(x, q, axis=-1))
            continue
        x.partition(k, axis=-1)
        pair = np.stack([x[..., k], x[..., k + 1 :].min(axis=-1)])
        out.append(np.quantile(pair, rank - k, axis=0))
    return np.where(np.isnan(x).any(axis=-1), np.nan, np.stack(out))[()]


def thin_step(n: int, max_draws: int | None) -> int:
    """Every how many-th of ``n`` draws is kept so that at most ``max_draws`` remain: ceil(n /
    max_draws), 1 when they fit (or for None). The one rule behind every fit's fixed draws and
    ``on_draws``, the sampler's retained steps, the replicates and the leave-one-out draws."""
    return int(np.ceil(n / max_draws)) if max_draws and n > max_draws else 1


def thin_rows(draws: np.ndarray, max_draws: int | None) -> np.ndarray:
    """Rows (draws) kept evenly, every :func:`thin_step`-th, so that at most ``max_draws`` remain."""
    return draws[:: thin_step(draws.shape[0], max_draws)]
