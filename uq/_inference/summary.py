"""Posterior summaries in the contract's shape: {"mean", "sd", "q05", "q95"}, and bands."""

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
    """(mean, lower, upper) of an equal-tailed ``level`` band over ``axis``."""
    d = np.asarray(draws, float)
    a = (1.0 - level) / 2.0
    return d.mean(axis=axis), np.quantile(d, a, axis=axis), np.quantile(d, 1.0 - a, axis=axis)
