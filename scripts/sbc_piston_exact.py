"""Exact SBC of the per-pressure piston model (no MCMC): is the b_L rank test's p = 0.007 a bias?

The truths and data are drawn exactly as ``uq calibrate --truth prior`` draws them
(uq/_drivers/calibrate.py::_test_from_model); the posterior of log sigma_L is computed on a fine grid
(marginal likelihood y ~ N(0, sigma_L^2 I + X X^T), the model's prior) and the four piston
coefficients are drawn exactly given sigma_L. Uniform ranks here mean the data generator and the
model agree; then a non-uniform histogram from ``uq calibrate`` can only come from the sampler or
from chance.

    .venv/bin/python scripts/sbc_piston_exact.py [REPS] [SEED]     (default 2000 7, about 1 minute)
"""

from __future__ import annotations

import sys

import numpy as np
from scipy import stats

from uq._drivers.calibrate import N_RANKS, _test_from_model
from uq._models.cubic import (
    NOISE_PRIOR_MEAN,
    NOISE_PRIOR_SD,
    PISTON_PRIOR_SD_M,
    basis,
    to_paper_basis,
)

GRID = np.linspace(
    NOISE_PRIOR_MEAN[2] - 12, NOISE_PRIOR_MEAN[2] + 12, 2401
)  # log sigma_L, +-6 prior sd


def ranks_of_one(rng, pressure_bar: float) -> np.ndarray:
    test, truth, _ = _test_from_model(rng, pressure_bar, 0.112)
    X, y = np.asarray(basis(test.height_m - 0.112)), test.piston_m
    evals, evecs = np.linalg.eigh(X @ X.T * PISTON_PRIOR_SD_M**2)
    evals, proj = np.clip(evals, 0.0, None), evecs.T @ y
    v = np.exp(2 * GRID)[:, None] + evals[None, :]
    log_post = -0.5 * np.sum(proj**2 / v + np.log(v), axis=1)
    log_post -= 0.5 * ((GRID - NOISE_PRIOR_MEAN[2]) / NOISE_PRIOR_SD[2]) ** 2
    w = np.exp(log_post - log_post.max())
    half = 0.5 * (GRID[1] - GRID[0])
    log_s = rng.choice(GRID, size=N_RANKS, p=w / w.sum()) + rng.uniform(-half, half, N_RANKS)
    draws = []
    for s in np.exp(log_s):
        A = X.T @ X / s**2 + np.eye(4) / PISTON_PRIOR_SD_M**2
        draws.append(
            to_paper_basis(
                rng.multivariate_normal(np.linalg.solve(A, X.T @ y / s**2), np.linalg.inv(A))
            )
        )
    return np.sum(np.array(draws) < truth[4:8], axis=0)


def main(reps: int = 2000, seed: int = 7) -> None:
    rng = np.random.default_rng(seed)
    ranks = np.array([ranks_of_one(rng, (1.0, 5.0, 10.0)[r % 3]) for r in range(reps)])
    for j, name in enumerate(("a_L", "b_L", "c_L", "d_L")):
        hist = np.histogram(ranks[:, j], bins=10, range=(0, N_RANKS + 1))[0]
        print(f"{name}: ranks {hist.tolist()}  chi-square p = {stats.chisquare(hist).pvalue:.3f}")


if __name__ == "__main__":
    main(*(int(a) for a in sys.argv[1:3]))
