"""The thermodynamic model's likelihood and fit (JAX): the potential G(x, p_u) of
:mod:`uq._models.thermo` as a :class:`uq._inference.collapsed.CollapsedModel` over the (force,
piston) reading pairs (``uq._models.pair``), with the piston's travel factor 1 + m = S / S_true
sampled beside the noise, fitted by the one driver. The model and its priors are described in
:mod:`uq._models.thermo`.
"""

from __future__ import annotations

import numpy as np

from uq._data.recordings import Recordings
from uq._data.stand_description import PAPER_STAND, StandDescription
from uq._inference.collapsed import CollapsedModel, hold_out_by_weight
from uq._inference.float64 import jnp
from uq._inference.sampler import Settings
from uq._io.errors import InputError
from uq._models import pair
from uq._models.pair import NATURAL_NAMES, NOISE_NAMES, PairData
from uq._models.thermo import (
    CANDIDATES,
    MAX_DRAWS,
    TRAVEL_PRIOR_SD,
    ThermoFit,
    ThermoOrders,
    default_orders,
    designs,
    force_pressure_slope,
    geometry_of,
)

THETA_NAMES = (*NOISE_NAMES, "log_travel_factor")

# ----------------------------------------------------------------------------- the model


def _scale(theta):
    return jnp.exp(theta[5])


def log_prob(theta, d: PairData):
    """Log posterior of the noise parameters and the travel factor, coefficients integrated out."""
    prior_m = -0.5 * (theta[5] / TRAVEL_PRIOR_SD) ** 2
    return (
        pair.log_prior(theta[:5], d)
        + prior_m
        + pair.posterior(theta[:5], d, _scale(theta)).log_marginal
    )


def draw_linear(theta, key, d: PairData):
    return pair.draw(theta[:5], key, d, _scale(theta))


def pointwise(theta, beta, d: PairData):
    return {"reading": pair.pointwise(theta[:5], beta, d, _scale(theta))}


def predict(theta, beta, key, d: PairData):
    return pair.predict(theta[:5], beta, key, d, _scale(theta))


def pointwise_loo(theta, d: PairData):
    return pair.pointwise_loo(theta[:5], d, _scale(theta))


def start(d: PairData) -> np.ndarray:
    return np.concatenate([np.asarray(d.prior_mean), [0.0]])


def report(theta, beta, d: PairData) -> dict:
    theta = np.asarray(theta)
    noise = np.exp(theta[:, :5])
    out = {n: noise[:, i] for i, n in enumerate(NATURAL_NAMES)}
    out["travel_factor"] = np.exp(theta[:, 5])
    out["piston_area_m2"] = float(d.area) / np.exp(theta[:, 5])
    return out


MODEL = CollapsedModel.of(
    globals(),
    "thermodynamic potential G(x, p_u)",
    THETA_NAMES,
    observed=pair.observed,
    hold_out=hold_out_by_weight,
)


# ----------------------------------------------------------------------------- fit


def collapsed_model(data) -> CollapsedModel:
    """The likelihood whose data ``data`` is (a fit's ``posterior.data``), for refits."""
    return MODEL


def thermo_data(rec: Recordings, orders: ThermoOrders, stand: StandDescription) -> PairData:
    """The model's arrays: designs, readings, and the noise references from a weighted
    least-squares fit of the same potential (force, and the force's pressure derivative as the
    lever of a pressure-holding error)."""
    g = geometry_of(rec)
    return pair.campaign_data(
        rec,
        stand,
        g.area_m2,
        lambda x, p, idx, n_tests: designs(orders, g, x, p, idx, n_tests),
        lambda x, p, beta: force_pressure_slope(orders, g, x, p, beta[: orders.n_potential]),
    )


def fit_thermo(
    rec: Recordings,
    orders: ThermoOrders | None = None,
    *,
    seed: int = 0,
    settings: Settings = Settings(),
    max_draws: int = MAX_DRAWS,
    stand: StandDescription = PAPER_STAND,
) -> ThermoFit:
    """The thermodynamic model's posterior by the one driver: optimistix MAP of the noise and the
    travel factor, emcee over them, exact draws of the potential's coefficients and the piston
    references, ArviZ data and the convergence verdict. ``stand``: the stand the recordings were
    taken on (its pressure holding and gas volume enter the reading covariance and priors).
    ``orders``: the potential's degrees (default: :func:`default_orders` of the campaign)."""
    if len(rec.tests) < 2:
        raise InputError(
            f"{rec.path}: the thermodynamic model relates force and volume through their pressure "
            "derivatives and needs tests at two or more pressures"
        )
    if not rec.has_piston:
        raise InputError(
            f"{rec.path}: force-only campaign: the thermodynamic model fits force and volume "
            "together and needs piston_* or volume_*"
        )
    orders = default_orders(len(rec.tests)) if orders is None else orders
    return pair.fit_over_tests(
        ThermoFit,
        MODEL,
        thermo_data(rec, orders, stand),
        rec,
        orders,
        geometry_of(rec),
        seed=seed,
        settings=settings,
        max_draws=max_draws,
        stand=stand,
        desc="thermodynamic sampling",
    )


def select_orders(
    rec: Recordings,
    candidates=CANDIDATES,
    *,
    seed: int = 0,
    settings: Settings | None = None,
    stand: StandDescription = PAPER_STAND,
):
    """Fit each candidate and rank by PSIS-LOO; returns (best fit, comparison rows)."""
    return pair.select_orders(
        fit_thermo, rec, candidates, seed=seed, settings=settings or Settings(), stand=stand
    )
