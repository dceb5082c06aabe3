"""The surface model's likelihood and fit (JAX): the pressure-coupled surface of
:mod:`uq._models.surface` as a :class:`uq._inference.collapsed.CollapsedModel` over the (force,
piston) reading pairs of every test (``uq._models.pair``), or over the force alone for a campaign
without piston readings (``uq._models.surface_force``), fitted by the one driver. The model, its
priors and noise are described in :mod:`uq._models.surface`.
"""

from __future__ import annotations

import numpy as np

from uq._data.recordings import Recordings
from uq._data.stand_description import PAPER_STAND, StandDescription
from uq._inference.collapsed import CollapsedModel, hold_out_by_weight
from uq._inference.sampler import INDEPENDENCE_MIX, Settings
from uq._io.errors import InputError
from uq._models import pair, surface_force
from uq._models.pair import NOISE_NAMES, PairData
from uq._models.surface import (
    CANDIDATES,
    MAX_DRAWS,
    SCALE_C,
    Orders,
    SurfaceFit,
    designs,
    force_design,
    force_label,
    geometry_of,
    orders_for,
    tq_columns,
)

#: the sampler's moves for the (force, piston) surface's five noise logs (DE, DE-snooker,
#: independence t; ``uq._inference.sampler.effective_mix``): mostly independence proposals, a
#: tenth DE moves so that a posterior far from Gaussian is still explored. On data/n50 (default
#: settings) the convergence rules pass after 699, 724 and 877 steps (seeds 2, 3, 4) where the
#: sampler's default mixture (0.2, 0.1, 0.7) needed 1016, 1676 and 1166 (855-1676 over seeds
#: 0-5): about a third fewer calls of the log posterior for the same rules (docs/speed.md).
MIX = (0.1, 0.0, 0.9)


# ----------------------------------------------------------------------------- likelihood


def log_prob(theta, d: PairData):
    """Log posterior of the noise parameters (coefficients integrated out); theta (5,)."""
    return pair.log_prior(theta, d) + pair.posterior(theta, d).log_marginal


def pointwise(theta, beta, d: PairData):
    return {"reading": pair.pointwise(theta, beta, d)}


#: the pair likelihood's own draws, replicates and leave-one-out densities (no travel factor)
MODEL = CollapsedModel.of(
    globals(),
    "pressure-coupled surface",
    NOISE_NAMES,
    draw_linear=pair.draw,
    start=surface_force.start,
    report=surface_force.report,
    predict=pair.predict,
    observed=pair.observed,
    pointwise_loo=pair.pointwise_loo,
    hold_out=hold_out_by_weight,
)


def collapsed_model(data) -> CollapsedModel:
    """The likelihood whose data ``data`` is (a fit's ``posterior.data``), for refits: the force
    surface's for a campaign without piston readings, the pair's otherwise."""
    return surface_force.MODEL if isinstance(data, surface_force.ForceData) else MODEL


# ----------------------------------------------------------------------------- fit


def surface_force_data(rec: Recordings, orders: Orders, stand: StandDescription):
    """The force surface's arrays (uq._models.surface_force.ForceData): the design, the readings and
    the noise references of a weighted least-squares fit of the force."""
    g = geometry_of(rec)
    x, p, F = pair.force_arrays(rec)
    X = force_design(orders, g, x, p)
    beta = pair.reference_fit(X, F)
    nc = (orders.K + 1) * (orders.Lp + 1)
    feff = np.abs(tq_columns(g.t(x), g.q(p), orders.K, orders.Lp) @ (beta[:nc] * SCALE_C))
    return surface_force.force_data(
        X, F, np.abs(X @ beta), feff, p, stand, pair.measured_deviation(rec, stand)
    )


def surface_data(rec: Recordings, orders: Orders, stand: StandDescription) -> PairData:
    """The model's arrays for a campaign: designs, readings, the noise references, the Gram plan."""
    g = geometry_of(rec)
    nc = (orders.K + 1) * (orders.Lp + 1)
    return pair.campaign_data(
        rec,
        stand,
        g.area_m2,
        lambda x, p, idx, n_tests: designs(orders, g, x, p, idx, n_tests),
        lambda x, p, beta: tq_columns(g.t(x), g.q(p), orders.K, orders.Lp) @ (beta[:nc] * SCALE_C),
    )


def fit_surface(
    rec: Recordings,
    orders: Orders | None = None,
    *,
    seed: int = 0,
    settings: Settings = Settings(),
    max_draws: int = MAX_DRAWS,
    stand: StandDescription = PAPER_STAND,
) -> SurfaceFit:
    """The surface model's posterior: the one driver (optimistix MAP of the noise, emcee over it,
    exact coefficient draws, ArviZ data and convergence verdict).

    ``stand`` is the stand the recordings were taken on: its pressure holding and p_atm enter
    the reading covariance, its load cell and gas volume centre the noise priors. ``orders``:
    the polynomial orders, by default :func:`orders_for` the campaign.

    A campaign without piston readings (force-only, or a catalogue table) is fitted by the force
    surface alone (uq._models.surface_force; ``orders`` without a volume block, Dk = Dl = -1); its
    volume results are omitted with :func:`volume_omitted_reason`."""
    n_tests = len(rec.tests)
    orders = orders_for(rec) if orders is None else orders
    if n_tests < orders.Lp + 1:
        raise InputError(
            f"{rec.path}: {n_tests} tests at different pressures cannot fix an effective area of "
            f"degree {orders.Lp} in pressure; the surface model needs at least {orders.Lp + 1}"
        )
    force_only = not rec.has_piston
    if force_only and (orders.Dk >= 0 or orders.Dl >= 0):
        raise InputError(
            f"orders: {rec.path} has no piston readings; the force surface takes no volume block "
            f"(Dk = Dl = -1), got {orders.label}",
            param="orders",
        )
    if force_only:
        data, model = surface_force_data(rec, orders, stand), surface_force.MODEL
        k = data.X.shape[1]
        if rec.n_points - k < len(surface_force.THETA_NAMES) + 2:
            short = k + len(surface_force.THETA_NAMES) + 2
            raise InputError(
                f"{rec.path}: {rec.n_points} readings cannot fix the force surface's {k} coefficients "
                f"({force_label(orders)}) and leave residuals for its noise: it needs at least {short} "
                f"(more heights per test, or more tests)"
            )
    else:
        data, model = surface_data(rec, orders, stand), MODEL
    return pair.fit_over_tests(
        SurfaceFit,
        model,
        data,
        rec,
        orders,
        geometry_of(rec),
        seed=seed,
        settings=settings,
        max_draws=max_draws,
        stand=stand,
        desc="surface sampling",
        mix=INDEPENDENCE_MIX if force_only else MIX,
    )


def select_orders(
    rec: Recordings,
    candidates=CANDIDATES,
    *,
    seed: int = 0,
    settings: Settings | None = None,
    stand: StandDescription = PAPER_STAND,
):
    """Fit each candidate and rank by PSIS-LOO; returns (best fit, comparison rows). For a campaign
    without piston readings the candidates lose their volume block and their degrees are capped
    as :func:`orders_for` caps them (duplicates fitted once)."""
    if not rec.has_piston:
        cap = orders_for(rec)
        candidates = tuple(
            dict.fromkeys(
                Orders(
                    min(o.K, cap.K),
                    max(0, min(o.Lp, len(rec.tests) - 2)),
                    min(o.Ke, cap.Ke),
                    -1,
                    -1,
                )
                for o in candidates
            )
        )
    return pair.select_orders(
        fit_surface, rec, candidates, seed=seed, settings=settings or Settings(), stand=stand
    )
