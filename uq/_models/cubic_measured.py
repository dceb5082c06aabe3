"""The per-pressure cubics with the measured pressure as a covariate of the pressure-holding error.

The per-pressure cubics with the pressure-holding error modelled, not lumped into the noise.

The stand holds each reading at p_u + dp_i (paper section 3.2). The error moves the force by
dp_i dP/dp_u and, by Boyle's law (eq. 4: the gas volume V keeps its value), leaves the piston
short by V dp_i / (p_abs S). The plain model (``uq._models.cubic``) folds both into independent
noise: the force floor sigma0 and the piston's sigma_L. Two better models, both linear-Gaussian
in the eight coefficients given their sampled parameters (so they run through the same driver,
``fit_collapsed``, with exact coefficient draws):

**Measured pressure** (``MEASURED``; recordings with ``set_pressure_bar`` and each reading's
``pressure_bar``). The covariate dp_hat_i = measured - set is the holding error plus the sensor's
error: a gain error g (the paper's sensor: 0.1 %) read once per test, so dp_hat_i = dp_i + delta
with delta = p_u g common to the test (the sensor's 1 Pa resolution is negligible). Readings are
corrected,

    force_i + lever_i delta = P(x_i) + e_F,i,        lever_i = Phat_i / p_u   (plug-in dP/dp_u)
    piston_i - V delta / (p_abs S) = L(x_i) - (V - V_s) dp_i / (p_abs S) + e_L,i
    with dp_i = dp_hat_i - delta,

where Phat is the test's least-squares force (eq. 1's F_eff as the lever, the one the models
already use; a casing's dP/dp_u is larger, by 13 % at x0 for Table 1, which leaves a residual of
13 % of a pressure error that is itself under 0.1 % of p_u). The unknowns delta and the gas volume
V (its departure from the stand's V_s, prior sd 50 %) are two extra coefficients: the model stays
linear. delta's prior is its posterior from the measured series alone: the gain's N(0, (p_u
0.1 %)^2) combined with the series' mean (dp_hat = dp + delta, dp a stationary AR(1) series with
the sample variance and lag-one correlation of dp_hat, which delta does not change), so the
unknown common part is as small as the sensor and the series allow. e_F ~ N(0, sigma0^2 +
(r Phat)^2), e_L ~ N(0, sigma_L^2) as in the plain model, but now without the pressure term.

The sensor (its gain error and resolution) is the stand's: ``StandDescription.pressure_sensor_*``
(``--stand``; the paper's by default).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from uq._data.stand_description import StandDescription
from uq._inference.collapsed import CollapsedModel, hold_out_by_weight
from uq._inference.float64 import jax, jnp
from uq._inference.latent import common_offset
from uq._inference.linear import draw_exact, gaussian_loglik, linear_posterior
from uq._models.cubic import (
    SAMPLER_NAMES,
    basis,
    coefficient_prior_sd,
    least_squares,
    log_prior_noise,
    noise_prior_mean,
    noise_sds,
    observed,
    report,
    stack_design,
    start,
)
from uq._models.cubic_results import noise_reference
from uq._models.pair import block_loo
from uq._physics.cubic import cubic
from uq._physics.quantities import BAR_PA

VOLUME_PRIOR_REL_SD = 0.5  # the measured model's V - V_s ~ N(0, (0.5 V_s)^2)

# ----------------------------------------------------------------------------- measured pressure


class MeasuredData(NamedTuple):
    X: jnp.ndarray  # (n, 4)
    force: jnp.ndarray  # (n,) as read, N
    piston: jnp.ndarray  # (n,) as read, m
    ref_force: jnp.ndarray  # (n,)
    prior_mean: jnp.ndarray  # (3,)
    weight: jnp.ndarray  # (n,)
    lever: jnp.ndarray  # (n,) dP/dp_u plug-in, m^2
    dp: jnp.ndarray  # (n,) measured deviation less the common offset's prior mean, Pa
    boyle: jnp.ndarray  # () 1 / (p_abs S), 1/(Pa m^2)
    volume: jnp.ndarray  # () the stand's gas volume V_s, m^3
    offset_sd: jnp.ndarray  # () prior sd of the common offset left, Pa
    offset_mean: jnp.ndarray  # () its prior mean (already taken out of dp), Pa


def measured_data(test, x0_m: float, noise: str, stand: StandDescription, area_m2: float):
    """The measured model's arrays for one test (and the least-squares cubics of the corrected
    readings, ``(data, lsq_force, lsq_piston, ref_force)`` as ``cubic._prepare``)."""
    u = test.height_m - x0_m
    p_pa = test.pressure_bar * BAR_PA
    dp_hat = (np.asarray(test.measured_pressure_bar, float) - test.pressure_bar) * BAR_PA
    mean, sd = common_offset(dp_hat, p_pa, ordered=test.step is not None, stand=stand)
    dp = dp_hat - mean
    lsq_raw = least_squares(u, test.force_N)
    lever = cubic(lsq_raw, u) / p_pa
    boyle = 1.0 / ((test.pressure_bar + stand.p_atm_bar) * BAR_PA * area_m2)
    V = stand.gas_volume_at_xmax_m3
    force_c = test.force_N - lever * dp
    piston_c = test.piston_m + V * boyle * dp
    lsq_f = least_squares(u, force_c)
    lsq_l = least_squares(u, piston_c)
    ref = noise_reference(lsq_f, u, noise)
    data = MeasuredData(
        basis(u),
        jnp.asarray(test.force_N),
        jnp.asarray(test.piston_m),
        jnp.asarray(ref),
        jnp.asarray(noise_prior_mean(stand)),
        jnp.ones(u.size),
        jnp.asarray(lever),
        jnp.asarray(dp),
        jnp.asarray(boyle),
        jnp.asarray(V),
        jnp.asarray(sd),
        jnp.asarray(mean),
    )
    return data, lsq_f, lsq_l, ref


def _measured_design(d: MeasuredData):
    """Stacked design (2n, 10): [alpha (4), gamma (4), V - V_s, delta'] and corrected readings."""
    n = d.force.shape[0]
    Z8 = stack_design(d.X)
    col_v = jnp.concatenate([jnp.zeros(n), -d.dp * d.boyle])
    col_off = jnp.concatenate([-d.lever, jnp.full(n, d.volume * d.boyle)])
    Z = jnp.concatenate([Z8, col_v[:, None], col_off[:, None]], axis=1)
    y = jnp.concatenate([d.force - d.lever * d.dp, d.piston + d.volume * d.boyle * d.dp])
    prior_sd = jnp.concatenate(
        [coefficient_prior_sd(), jnp.stack([VOLUME_PRIOR_REL_SD * d.volume, d.offset_sd])]
    )
    return Z, y, prior_sd


def _measured_post(theta, d: MeasuredData):
    sigma_f, sigma_L, nat = noise_sds(theta, d)
    Z, y, prior_sd = _measured_design(d)
    sd = jnp.concatenate([sigma_f, jnp.full(d.force.shape, sigma_L)])
    w = jnp.concatenate([d.weight, d.weight])
    return linear_posterior(Z, y, sd, prior_sd, w), nat


def measured_log_prob(theta, d: MeasuredData):
    post, nat = _measured_post(theta, d)
    return log_prior_noise(nat, d.prior_mean) + post.log_marginal


def measured_draw_linear(theta, key, d: MeasuredData):
    return draw_exact(_measured_post(theta, d)[0], key)


def measured_pointwise(theta, beta, d: MeasuredData):
    sigma_f, sigma_L, _ = noise_sds(theta, d)
    Z, y, _ = _measured_design(d)
    mu = Z @ beta
    n = d.force.shape[0]
    return {
        "force_N": gaussian_loglik(y[:n], mu[:n], sigma_f),
        "piston_m": gaussian_loglik(y[n:], mu[n:], sigma_L),
    }


def measured_predict(theta, beta, key, d: MeasuredData):
    """A replicate of the readings as read, at the measured pressures."""
    sigma_f, sigma_L, _ = noise_sds(theta, d)
    Z, y, _ = _measured_design(d)
    n = d.force.shape[0]
    mu = Z @ beta
    kf, kl = jax.random.split(key)
    return {
        "force_N": mu[:n] + d.lever * d.dp + sigma_f * jax.random.normal(kf, (n,)),
        "piston_m": mu[n:] - d.volume * d.boyle * d.dp + sigma_L * jax.random.normal(kl, (n,)),
    }


def measured_pointwise_loo(theta, d: MeasuredData):
    """log p(force_i, piston_i | noise, the other readings), coefficients integrated out."""
    sigma_f, sigma_L, _ = noise_sds(theta, d)
    Z, y, prior_sd = _measured_design(d)
    sd = jnp.concatenate([sigma_f, jnp.full(d.force.shape, sigma_L)])
    Zw, yw = Z / sd[:, None], y / sd
    post = linear_posterior(Zw, yw, jnp.ones_like(yw), prior_sd)
    n = d.force.shape[0]
    return block_loo(Zw, yw, n, post.chol, post.mean) - jnp.log(sigma_f) - jnp.log(sigma_L)


def measured_start(d: MeasuredData) -> np.ndarray:
    _, y, _ = _measured_design(d)
    n = d.force.shape[0]
    return start(d._replace(force=y[:n], piston=y[n:]))


def measured_report(theta, beta, d: MeasuredData) -> dict:
    out = report(theta, beta[:, :8], d)
    return out | {
        "V_gas_m3": float(d.volume) + beta[:, 8],
        "pressure_offset_Pa": float(d.offset_mean) + beta[:, 9],
    }


def measured_corrected(d: MeasuredData, beta_mean) -> dict:
    """The readings corrected at the posterior-mean gas volume and offset (for the order check)."""
    V = float(d.volume) + float(beta_mean[8])
    dp = np.asarray(d.dp) - float(beta_mean[9])
    return {
        "force": np.asarray(d.force) - np.asarray(d.lever) * dp,
        "piston": np.asarray(d.piston) + V * float(d.boyle) * dp,
    }


MEASURED = CollapsedModel.of(
    globals(),
    "per-pressure cubics (eqs. 8, 9), measured pressure as a covariate",
    SAMPLER_NAMES,
    prefix="measured_",
    observed=observed,
    hold_out=hold_out_by_weight,
)
