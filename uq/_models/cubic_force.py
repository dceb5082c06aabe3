"""The per-pressure cubic of the force alone (eq. 8): a test without piston readings or volume.

A test without piston readings or volume (a force-only stand): the force block of ``MODEL``
alone. Given the noise, MODEL's force and piston blocks are independent and the piston's noise
sigma_L has its own prior, so the force coefficients' and (sigma0, r)'s posterior here is the
same distribution as MODEL's on the same forces (tests/models/test_cubic_force.py checks it).
With measured pressures the readings are corrected as in ``MEASURED``'s force rows,
force_i + lever_i delta = P(x_i) + lever_i dp_hat_i + e_F,i, the sensor's common offset delta one
extra coefficient (prior: ``common_offset``); the stand's gas volume moves only the piston, so it
is not a parameter here.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from uq._data.recordings import PressureTest
from uq._data.stand_description import StandDescription
from uq._inference.collapsed import CollapsedModel, hold_out_by_weight
from uq._inference.float64 import jax, jnp
from uq._inference.latent import common_offset
from uq._inference.linear import draw_exact, gaussian_loglik, linear_posterior, loo_given_noise
from uq._models.cubic import (
    FORCE_PRIOR_SD_N,
    NOISE_PRIOR_SD,
    SAMPLER_NAMES,
    basis,
    least_squares,
    natural_noise,
    noise_prior_mean,
    report,
)
from uq._models.cubic_results import noise_reference
from uq._physics.cubic import cubic
from uq._physics.quantities import BAR_PA, force_noise_var

FORCE_SAMPLER_NAMES = SAMPLER_NAMES[:2]


class ForceData(NamedTuple):
    """One test's arrays for the force-only model (n readings, k = 4 or 5 coefficients)."""

    X: jnp.ndarray  # (n, k) scaled basis [1, t, t^2, t^3] (and -lever: the common offset)
    force: jnp.ndarray  # (n,) as read, N
    y: jnp.ndarray  # (n,) what the linear model fits: force less lever * dp (measured pressure)
    ref_force: jnp.ndarray  # (n,) force level of the relative noise term, N
    prior_mean: jnp.ndarray  # (2,) prior centres of log sigma0 and log r
    weight: jnp.ndarray  # (n,) 1 = fitted, 0 = held out
    prior_sd: jnp.ndarray  # (k,) coefficients' prior sds
    offset_mean: jnp.ndarray  # () prior mean of the common offset already taken out (Pa), or 0


def _force_noise(theta, d: ForceData):
    nat = natural_noise(theta, jnp.mean(d.ref_force))
    return jnp.sqrt(force_noise_var(jnp.exp(nat[0]), jnp.exp(nat[1]), d.ref_force)), nat


def _force_post(theta, d: ForceData):
    sigma_f, nat = _force_noise(theta, d)
    return linear_posterior(d.X, d.y, sigma_f, d.prior_sd, d.weight), nat


def force_log_prob(theta, d: ForceData):
    """Log posterior of (psi, eta), coefficients integrated out; theta (2,)."""
    post, nat = _force_post(theta, d)
    z = (nat - d.prior_mean) / NOISE_PRIOR_SD[:2]
    return -0.5 * jnp.sum(z**2) + post.log_marginal


def force_draw_linear(theta, key, d: ForceData):
    return draw_exact(_force_post(theta, d)[0], key)


def force_pointwise(theta, beta, d: ForceData):
    return {"force_N": gaussian_loglik(d.y, d.X @ beta, _force_noise(theta, d)[0])}


def force_predict(theta, beta, key, d: ForceData):
    """A replicate of the forces as read (at the measured pressures)."""
    sigma_f = _force_noise(theta, d)[0]
    n = d.force.shape[0]
    return {"force_N": d.X @ beta + (d.force - d.y) + sigma_f * jax.random.normal(key, (n,))}


def force_pointwise_loo(theta, d: ForceData):
    return loo_given_noise(d.X, d.y, _force_noise(theta, d)[0], d.prior_sd)


def force_start(d: ForceData) -> np.ndarray:
    X, y = np.asarray(d.X), np.asarray(d.y)
    res = y - X @ np.linalg.lstsq(X, y, rcond=None)[0]
    sd = np.sqrt(np.sum(res**2) / max(y.size - X.shape[1], 1))
    return np.array([np.log(sd + 1e-9), 0.0])


def force_report(theta, beta, d: ForceData) -> dict:
    out = report(theta, beta, d)
    if beta.shape[1] > 4:
        out["pressure_offset_Pa"] = float(d.offset_mean) + beta[:, 4]
    return out


def force_observed(d: ForceData) -> dict:
    return {"force_N": np.asarray(d.force)}


FORCE_ONLY = CollapsedModel.of(
    globals(),
    "per-pressure cubic of the force (eq. 8), force-only test",
    FORCE_SAMPLER_NAMES,
    prefix="force_",
    hold_out=hold_out_by_weight,
)


def force_data(
    test: PressureTest, x0_m: float, noise: str, stand: StandDescription, measured: bool = False
):
    """The force-only model's arrays for one test, ``(data, lsq_force, None, ref_force)`` as
    ``_prepare``; ``measured``: the readings' measured pressures are a covariate (``MEASURED``'s
    force rows, with the sensor's common offset as a fifth coefficient)."""
    if noise not in ("budget", "constant"):
        raise ValueError(f"noise must be 'budget' or 'constant', got {noise!r}")
    u = test.height_m - x0_m
    X = basis(u)
    y = np.asarray(test.force_N, float)
    prior_sd = np.full(4, FORCE_PRIOR_SD_N)
    offset_mean = 0.0
    if measured:
        p_pa = test.pressure_bar * BAR_PA
        dp_hat = (np.asarray(test.measured_pressure_bar, float) - test.pressure_bar) * BAR_PA
        offset_mean, offset_sd = common_offset(
            dp_hat, p_pa, ordered=test.step is not None, stand=stand
        )
        lever = cubic(least_squares(u, test.force_N), u) / p_pa
        y = y - lever * (dp_hat - offset_mean)
        X = jnp.concatenate([X, -jnp.asarray(lever)[:, None]], axis=1)
        prior_sd = np.append(prior_sd, offset_sd)
    lsq_f = least_squares(u, y)
    ref = noise_reference(lsq_f, u, noise)
    data = ForceData(
        X,
        jnp.asarray(test.force_N),
        jnp.asarray(y),
        jnp.asarray(ref),
        jnp.asarray(noise_prior_mean(stand)[:2]),
        jnp.ones(u.size),
        jnp.asarray(prior_sd),
        jnp.asarray(offset_mean),
    )
    return data, lsq_f, None, ref
