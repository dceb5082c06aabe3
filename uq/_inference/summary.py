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
    """(mean, lower, upper) of an equal-tailed ``level`` band over ``axis`` (both quantiles from
    one partition of the draws: the same numbers as one call each)."""
    d = np.asarray(draws, float)
    a = (1.0 - level) / 2.0
    lo, hi = np.quantile(d, [a, 1.0 - a], axis=axis)
    return d.mean(axis=axis), lo, hi


def thin_step(n: int, max_draws: int | None) -> int:
    """Every how many-th of ``n`` draws is kept so that at most ``max_draws`` remain: ceil(n /
    max_draws), 1 when they fit (or for None). The one rule behind every fit's fixed draws and
    ``on_draws``, the sampler's retained steps, the replicates and the leave-one-out draws."""
    return int(np.ceil(n / max_draws)) if max_draws and n > max_draws else 1


def thin_rows(draws: np.ndarray, max_draws: int | None) -> np.ndarray:
    """Rows (draws) kept evenly, every :func:`thin_step`-th, so that at most ``max_draws`` remain."""
    return draws[:: thin_step(draws.shape[0], max_draws)]
