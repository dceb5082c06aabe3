"""Helpers of the tests of ``uq plan`` (tests/ is on sys.path): planning frames built from the
models' parts, without a sampler run (all the planner takes from a fit)."""

from __future__ import annotations

import numpy as np

from uq._data.stand_description import PAPER_STAND
from uq._derived.plan_frames import CubicFrames, DiscrepancyFrames, PairFrames
from uq._models import (
    cubic,
    pair,
    surface,
    surface_force,
    surface_likelihood,
    thermo,
    thermo_likelihood,
)
from uq._models import discrepancy as dev
from uq._models.surface import SurfaceFit
from uq._models.thermo import ThermoFit
from uq._physics.quantities import BAR_PA


def surface_builder(rec, n_draws=8, seed=0):
    """PairFrames of the surface model from its parts: the model's data, draws of the noise
    parameters scattered about the budget's centre, least-squares references."""
    o, g = surface.orders_for(rec), surface.geometry_of(rec)
    d = surface_likelihood.surface_data(rec, o, PAPER_STAND)
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
    datas = [cubic.prepare(t, rec.x0_m, "budget", PAPER_STAND)[0] for t in rec.tests]
    rng = np.random.default_rng(seed)
    thetas = [
        np.array([np.log(60.0), 0.0, np.log(1e-4)]) + 0.2 * rng.standard_normal((n_draws, 3))
        for _ in datas
    ]
    coef = np.stack([cubic.least_squares(t.height_m - rec.x0_m, t.force_N) for t in rec.tests])
    return CubicFrames(rec, datas, thetas, coef)


def pair_builder(rec, model=SurfaceFit, n_draws=8, seed=0):
    """PairFrames of the surface (force-only when ``rec`` has no piston) or the thermodynamic model
    from their parts, as :func:`surface_builder`; the references are the file's mean force level
    (any positive references serve: the tests compare the frame with the model on the same ones)."""
    stand = PAPER_STAND
    if model is ThermoFit:
        o, g = thermo.default_orders(len(rec.tests)), thermo.geometry_of(rec)
        d = thermo_likelihood.thermo_data(rec, o, stand)
        centre = np.append(np.asarray(d.prior_mean), 0.05)
    elif rec.has_piston:
        o, g = surface.orders_for(rec), surface.geometry_of(rec)
        d = surface_likelihood.surface_data(rec, o, stand)
        centre = np.asarray(d.prior_mean)
    else:
        o, g = surface.orders_for(rec), surface.geometry_of(rec)
        d = surface_likelihood.surface_force_data(rec, o, stand)
        centre = np.asarray(d.prior_mean)
    rng = np.random.default_rng(seed)
    theta = centre[None] + 0.2 * rng.standard_normal((n_draws, centre.size))
    level = float(np.mean(np.abs(np.concatenate([t.force_N for t in rec.tests]))))

    def reference(xq, pq):
        force = np.full(np.shape(xq), level) * np.asarray(pq) / 5.0
        return force, force / (np.asarray(pq) * BAR_PA)

    return PairFrames(rec, d, theta, stand, o, g, reference, model)


def discrepancy_builder(rec, n_draws=4, seed=0, length_bar=2.0):
    """DiscrepancyFrames from the model's parts: the noise logs about the budget's centre, the
    amplitudes at their prior's scale (1 / rate) and the length scale about ``length_bar``."""
    stand = PAPER_STAND
    o, g = surface.orders_for(rec), surface.geometry_of(rec)
    d = dev.dev_data(rec, o, stand) if rec.has_piston else dev.force_dev_data(rec, o, stand)
    centre = dev.theta_of(np.asarray(d.prior_mean), 1.0 / np.asarray(d.rates), length_bar)
    rng = np.random.default_rng(seed)
    theta = centre[None] + 0.2 * rng.standard_normal((n_draws, centre.size))
    level = float(np.mean(np.abs(np.concatenate([t.force_N for t in rec.tests]))))

    def reference(xq, pq):
        force = np.full(np.shape(xq), level) * np.asarray(pq) / 5.0
        return force, force / (np.asarray(pq) * BAR_PA)

    return DiscrepancyFrames(rec, d, theta, stand, o, g, reference)


def model_precision(builder, new_bar, readings, theta):
    """The precision of the coefficients given ``theta`` that the model's own likelihood gives the
    file and the planned ``readings`` (uq._models.pair.posterior; the force surface's posterior),
    in the frame's basis: the readings' values do not enter."""
    import jax.numpy as jnp

    rec, d = builder.rec, builder.data
    new_bar = np.asarray(new_bar, float)
    o, g = builder.model(np.concatenate([builder.tested, new_bar]))
    T0, J = builder.tested.size, new_bar.size
    xs = np.array([r.height_m for r in readings])
    ps = np.array([new_bar[r.test] for r in readings])
    x = np.concatenate([builder.x, xs])
    p = np.concatenate([builder.p, ps])
    idx = np.concatenate([builder.test_index, [T0 + r.test for r in readings]])
    Xf, Xl = builder._designs(o, g, x, p, idx, T0 + J)
    force, lever = builder.reference(xs, ps)
    phat = np.concatenate([np.asarray(d.phat), force])
    feff = np.concatenate([np.asarray(d.feff_hat), lever])
    zeros = np.zeros(x.size)
    if builder.force_only:
        dd = surface_force.force_data(Xf, zeros, phat, feff, p, PAPER_STAND)
        post = surface_force._posterior(jnp.asarray(theta), dd)
    else:
        dd = pair.pair_data(Xf, Xl, zeros, zeros, phat, feff, p, rec.piston_area_m2, PAPER_STAND)
        scale = np.exp(theta[5]) if builder.thermo else 1.0
        post = pair.posterior(jnp.asarray(theta[:5]), dd, scale)
    L = np.asarray(post.chol)
    return L @ L.T
