"""Posterior summaries in the contract's shape: {"mean", "sd", "q05", "q95"}, and PSIS-LOO."""

from __future__ import annotations

import warnings

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


def loglik_idata(loglik):
    """ArviZ InferenceData holding pointwise log-likelihoods ``loglik`` (chains, draws, n) only."""
    import arviz as az

    ll = np.asarray(loglik)
    return az.from_dict(posterior={"_": np.zeros(ll.shape[:2])}, log_likelihood={"reading": ll})


def psis_loo(loglik, *, reff: float | None = None):
    """ArviZ's PSIS-LOO (pointwise) of log-likelihoods (chains, draws, n); ``reff`` the relative
    efficiency of the draws (None: ArviZ estimates it from the chains; 1.0 for independent draws).
    ArviZ's warning about high Pareto k is not raised: every caller reports the k values itself."""
    import arviz as az

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        return az.loo(loglik_idata(loglik), pointwise=True, reff=reff)
