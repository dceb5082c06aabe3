"""One problem sampled by the library's sampler, for the tests of its rules and progress bar."""

from __future__ import annotations

import numpy as np

from uq._inference.sampler import run_many


def run_one(log_prob, center, cov, names, **options):
    """``run_many`` of one problem: ``log_prob`` (W, D) -> (W,), its start ``center`` (D,) and
    posterior covariance estimate ``cov`` (D, D); ``options`` as run_many's. Its Chains."""

    def many(thetas):  # (1, m, D) -> (1, m)
        return np.asarray(log_prob(thetas[0]))[None]

    center, cov = np.asarray(center, float)[None], np.asarray(cov, float)[None]
    return run_many(many, center, cov, names, **options)[0]
