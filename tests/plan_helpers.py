"""Helpers of the tests of ``uq plan`` (tests/ is on sys.path): planning frames built from the
models' parts, without a sampler run (all the planner takes from a fit)."""

from __future__ import annotations

import numpy as np

from uq._data.stand_description import PAPER_STAND
from uq._derived.plan_frames import CubicFrames, PairFrames
from uq._models import cubic, pair, surface
from uq._physics.quantities import BAR_PA


def surface_builder(rec, n_draws=8, seed=0):
    """PairFrames of the surface model from its parts: the model's data, draws of the noise
    parameters scattered about the budget's centre, least-squares references."""
    o, g = surface.orders_for(rec), surface.geometry_of(rec)
    d = surface.surface_data(rec, o, PAPER_STAND)
    rng = np.random.default_rng(seed)
    theta = np.asarray(d.prior_mean)[None] + 0.2 * rng.standard_normal((n_draws, 5))
    x, p, F, L, idx = pair.arrays(rec)
    Xf, Xl = surface.designs(o, g, x, p, idx, len(rec.tests))
    beta, *_ = np.linalg.lstsq(
        np.vstack([Xf / 100.0, Xl / 1e-4]), np.concatenate([F / 100.0, L / 1e-4]), rcond=None
    )

    def reference(xq, pq):
        Xq = surface.force_design(o, g, xq, pq, Xf.shape[1])
        force = np.abs(Xq @ beta)
        return force, force / (np.asarray(pq) * BAR_PA)

    return PairFrames(rec, d, theta, PAPER_STAND, o, g, reference), beta


def cubic_builder(rec, n_draws=8, seed=0):
    datas = [cubic._prepare(t, rec.x0_m, "budget", PAPER_STAND)[0] for t in rec.tests]
    rng = np.random.default_rng(seed)
    thetas = [
        np.array([np.log(60.0), 0.0, np.log(1e-4)]) + 0.2 * rng.standard_normal((n_draws, 3))
        for _ in datas
    ]
    coef = np.stack([cubic.least_squares(t.height_m - rec.x0_m, t.force_N) for t in rec.tests])
    return CubicFrames(rec, datas, thetas, coef)
