"""The per-pressure cubics with the pressure-holding error modelled, not lumped into the noise.

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

**AR(1) pressure-holding errors** (``AR1``; pressure not recorded, recording order known). The
holding errors are latent: dp = k_p s_p z with z a stationary AR(1) series in recording order
(unit variance, lag-one correlation rho, a slowly corrected screw drive), s_p the stand's holding
sd. One dp_i moves both readings of row i, so per test the 2n readings have covariance

    Sigma = diag(sigma_F^2, sigma_L^2) + u u^T o R(rho),    u = [lever k_p s_p ; -V/(p_abs S) k_p s_p]

(R_ij = rho^|i-j|), i.e. Sigma = D + U R U^T with U = [diag(b); diag(c)], and the latent's
precision R^-1 is tridiagonal. ``uq._inference.latent`` integrates it out exactly (Woodbury,
an n x n Cholesky factor), so the coefficients stay conjugate. Sampled: (psi, eta, log sigma_L)
as in the plain model, log k_p ~ N(0, 0.5^2), log V ~ N(log V_s, 0.5^2), and atanh(rho) with rho
uniform on (-1, 1). sigma0 and sigma_L are then what is left besides the pressure holding
(displacement, calipers).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from uq._data.stand_description import StandDescription
from uq._inference.collapsed import CollapsedModel
from uq._inference.float64 import jax, jnp
from uq._inference.latent import (
    ar1_precision,
    ar1_series,
    block_conditional_logpdf,
    paired_ar1_posterior,
    paired_ar1_precision,
)
from uq._inference.linear import (
    LOG_2PI,
    draw_exact,
    gaussian_loglik,
    linear_posterior,
)
from uq._models import cubic as C
from uq._physics.quantities import BAR_PA, force_noise_var

#: The pressure sensor the measured model assumes (the paper's, section 3.2: 0.1 % accuracy, read
#: as a gain error common to a test; its 1 Pa resolution is negligible). The virtual stand's
#: ``--record-pressure`` sensor is the same (uq._stand.shapes).
from uq._stand.shapes import SENSOR_GAIN_SD, SENSOR_RESOLUTION_PA

VOLUME_PRIOR_REL_SD = 0.5  # the measured model's V - V_s ~ N(0, (0.5 V_s)^2)
LOG_KP_PRIOR_SD = 0.5
LOG_V_PRIOR_SD = 0.5
AR_SAMPLER_NAMES = C.SAMPLER_NAMES + ("log_k_p", "log_V_gas", "atanh_rho")
AR_EXTRA_NAMES = ("k_p", "V_gas_m3", "rho")
MEASURED_EXTRA_NAMES = ("V_gas_m3", "pressure_offset_Pa")


def _stack_design(X):
    z = jnp.zeros_like(X)
    return jnp.concatenate(
        [jnp.concatenate([X, z], axis=1), jnp.concatenate([z, X], axis=1)], axis=0
    )


def _coefficient_prior_sd(k: int = 4):
    return jnp.concatenate([jnp.full(k, C.FORCE_PRIOR_SD_N), jnp.full(k, C.PISTON_PRIOR_SD_M)])


def _log_prior_cubic_noise(nat, prior_mean):
    z = (nat - prior_mean) / C.NOISE_PRIOR_SD
    return -0.5 * jnp.sum(z**2)


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


def common_offset(dp_hat_pa, p_pa: float, *, ordered: bool = True):
    """Prior mean and sd (Pa) of the common offset delta in dp_hat = dp + delta.

    delta ~ N(0, (p_u SENSOR_GAIN_SD)^2) (the sensor's gain error); dp a stationary AR(1) series
    with the sample variance and lag-one correlation of dp_hat (iid when the order is unknown).
    Returns the Gaussian posterior of delta given dp_hat, (mean, sd)."""
    dp_hat = np.asarray(dp_hat_pa, float)
    n = dp_hat.size
    var = max(float(np.var(dp_hat, ddof=1)) if n > 1 else 0.0, SENSOR_RESOLUTION_PA**2)
    rho = 0.0
    if ordered and n > 2:
        c = dp_hat - dp_hat.mean()
        den = float(np.sum(c * c))
        rho = float(np.clip(np.sum(c[1:] * c[:-1]) / den, -0.9, 0.95)) if den > 0 else 0.0
    Q = np.asarray(ar1_precision(rho, n)[0]) / var
    one = np.ones(n)
    gain_var = max((p_pa * SENSOR_GAIN_SD) ** 2, SENSOR_RESOLUTION_PA**2)
    post_var = 1.0 / (1.0 / gain_var + one @ Q @ one)
    return post_var * float(one @ Q @ dp_hat), float(np.sqrt(post_var))


def measured_data(test, x0_m: float, noise: str, stand: StandDescription, area_m2: float):
    """The measured model's arrays for one test (and the least-squares cubics of the corrected
    readings, ``(data, lsq_force, lsq_piston, ref_force)`` as ``cubic._prepare``)."""
    u = test.height_m - x0_m
    p_pa = test.pressure_bar * BAR_PA
    dp_hat = (np.asarray(test.measured_pressure_bar, float) - test.pressure_bar) * BAR_PA
    mean, sd = common_offset(dp_hat, p_pa, ordered=test.step is not None)
    dp = dp_hat - mean
    lsq_raw = C.least_squares(u, test.force_N)
    lever = C.cubic(lsq_raw, u) / p_pa
    boyle = 1.0 / ((test.pressure_bar + stand.p_atm_bar) * BAR_PA * area_m2)
    V = stand.gas_volume_at_xmax_m3
    force_c = test.force_N - lever * dp
    piston_c = test.piston_m + V * boyle * dp
    lsq_f = C.least_squares(u, force_c)
    lsq_l = C.least_squares(u, piston_c)
    ref = C.noise_reference(lsq_f, u, noise)
    data = MeasuredData(
        C.basis(u),
        jnp.asarray(test.force_N),
        jnp.asarray(test.piston_m),
        jnp.asarray(ref),
        jnp.asarray(C.noise_prior_mean(stand)),
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
    Z8 = _stack_design(d.X)
    col_v = jnp.concatenate([jnp.zeros(n), -d.dp * d.boyle])
    col_off = jnp.concatenate([-d.lever, jnp.full(n, d.volume * d.boyle)])
    Z = jnp.concatenate([Z8, col_v[:, None], col_off[:, None]], axis=1)
    y = jnp.concatenate([d.force - d.lever * d.dp, d.piston + d.volume * d.boyle * d.dp])
    prior_sd = jnp.concatenate(
        [_coefficient_prior_sd(), jnp.stack([VOLUME_PRIOR_REL_SD * d.volume, d.offset_sd])]
    )
    return Z, y, prior_sd


def _measured_noise(theta, d: MeasuredData):
    nat = C.natural_noise(theta, jnp.mean(d.ref_force))
    sigma_f = jnp.sqrt(force_noise_var(jnp.exp(nat[0]), jnp.exp(nat[1]), d.ref_force))
    return sigma_f, jnp.exp(nat[2]), nat


def _measured_post(theta, d: MeasuredData):
    sigma_f, sigma_L, nat = _measured_noise(theta, d)
    Z, y, prior_sd = _measured_design(d)
    sd = jnp.concatenate([sigma_f, jnp.full(d.force.shape, sigma_L)])
    w = jnp.concatenate([d.weight, d.weight])
    return linear_posterior(Z, y, sd, prior_sd, w), nat


def measured_log_prob(theta, d: MeasuredData):
    post, nat = _measured_post(theta, d)
    return _log_prior_cubic_noise(nat, d.prior_mean) + post.log_marginal


def measured_draw(theta, key, d: MeasuredData):
    return draw_exact(_measured_post(theta, d)[0], key)


def measured_pointwise(theta, beta, d: MeasuredData):
    sigma_f, sigma_L, _ = _measured_noise(theta, d)
    Z, y, _ = _measured_design(d)
    mu = Z @ beta
    n = d.force.shape[0]
    return {
        "force_N": gaussian_loglik(y[:n], mu[:n], sigma_f),
        "piston_m": gaussian_loglik(y[n:], mu[n:], sigma_L),
    }


def measured_predict(theta, beta, key, d: MeasuredData):
    """A replicate of the readings as read, at the measured pressures."""
    sigma_f, sigma_L, _ = _measured_noise(theta, d)
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
    from uq._models.pair import block_loo

    sigma_f, sigma_L, _ = _measured_noise(theta, d)
    Z, y, prior_sd = _measured_design(d)
    sd = jnp.concatenate([sigma_f, jnp.full(d.force.shape, sigma_L)])
    Zw, yw = Z / sd[:, None], y / sd
    post = linear_posterior(Zw, yw, jnp.ones_like(yw), prior_sd)
    n = d.force.shape[0]
    return block_loo(Zw, yw, n, post.chol, post.mean) - jnp.log(sigma_f) - jnp.log(sigma_L)


def measured_start(d: MeasuredData) -> np.ndarray:
    _, y, _ = _measured_design(d)
    n = d.force.shape[0]
    return C.start(d._replace(force=y[:n], piston=y[n:]))


def measured_report(theta, beta, d: MeasuredData) -> dict:
    out = C.report(theta, beta[:, :8], d)
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


MEASURED = CollapsedModel(
    name="per-pressure cubics (eqs. 8, 9), measured pressure as a covariate",
    theta_names=C.SAMPLER_NAMES,
    log_prob=measured_log_prob,
    draw_linear=measured_draw,
    pointwise=measured_pointwise,
    start=measured_start,
    report=measured_report,
    predict=measured_predict,
    observed=C.observed,
    pointwise_loo=measured_pointwise_loo,
    hold_out=C.hold_out,
)


# ----------------------------------------------------------------------------- AR(1) holding errors


class AR1Data(NamedTuple):
    X: jnp.ndarray  # (n, 4), readings in recording order
    force: jnp.ndarray
    piston: jnp.ndarray
    ref_force: jnp.ndarray
    prior_mean: jnp.ndarray  # (5,) cubic noise centres (3), log k_p centre, log V centre
    weight: jnp.ndarray
    lever: jnp.ndarray  # (n,) dP/dp_u plug-in, m^2
    hold_sd: jnp.ndarray  # () the stand's holding sd at this pressure, Pa
    boyle: jnp.ndarray  # () 1 / (p_abs S)
    blocks: jnp.ndarray  # (n, 2) int: rows (i, n + i) of reading i in the stacked vectors


def ar1_data(test, x0_m: float, noise: str, stand: StandDescription, area_m2: float):
    """The AR(1) model's arrays for one test in recording order (``cubic._prepare``'s tuple)."""
    data, lsq_f, lsq_l, ref = C._prepare(test, x0_m, noise, stand)
    u = test.height_m - x0_m
    p_pa = test.pressure_bar * BAR_PA
    n = u.size
    ar = AR1Data(
        data.X,
        data.force,
        data.piston,
        data.ref_force,
        jnp.asarray(
            np.concatenate([C.noise_prior_mean(stand), [0.0, np.log(stand.gas_volume_at_xmax_m3)]])
        ),
        data.weight,
        jnp.asarray(C.cubic(lsq_f, u) / p_pa),
        jnp.asarray(float(stand.pressure_sd_bar(test.pressure_bar)) * BAR_PA),
        jnp.asarray(1.0 / ((test.pressure_bar + stand.p_atm_bar) * BAR_PA * area_m2)),
        jnp.asarray(np.stack([np.arange(n), n + np.arange(n)], axis=1)),
    )
    return ar, lsq_f, lsq_l, ref


def ar1_parts(theta, d: AR1Data):
    """(v (2n,), U (2n, n), Q (n, n), log det Q, nat (3,), (k_p, V, rho)) at theta (6,)."""
    nat = C.natural_noise(theta[:3], jnp.mean(d.ref_force))
    a2 = force_noise_var(jnp.exp(nat[0]), jnp.exp(nat[1]), d.ref_force)
    n = d.force.shape[0]
    kp, V, rho = jnp.exp(theta[3]), jnp.exp(theta[4]), jnp.tanh(theta[5])
    b = d.lever * d.hold_sd * kp
    c = -V * d.boyle * d.hold_sd * kp
    v = jnp.concatenate([a2, jnp.full(n, jnp.exp(2.0 * nat[2]))])
    U = jnp.concatenate([jnp.diag(b), c * jnp.eye(n)], axis=0)
    Q, ldQ = ar1_precision(rho, n)
    return v, U, Q, ldQ, nat, (kp, V, rho)


def _paired(theta, d: AR1Data):
    """(v (2n,), uf (n,), ul (n,), rho): the independent variances and each reading's loading on
    the holding-error series z (force, piston)."""
    nat = C.natural_noise(theta[:3], jnp.mean(d.ref_force))
    a2 = force_noise_var(jnp.exp(nat[0]), jnp.exp(nat[1]), d.ref_force)
    n = d.force.shape[0]
    kp, V, rho = jnp.exp(theta[3]), jnp.exp(theta[4]), jnp.tanh(theta[5])
    v = jnp.concatenate([a2, jnp.full(n, jnp.exp(2.0 * nat[2]))])
    return v, d.lever * d.hold_sd * kp, jnp.full(n, -V * d.boyle * d.hold_sd * kp), rho


def _ar1_post(theta, d: AR1Data):
    """The coefficients' posterior given theta: the tridiagonal O(n) form of the Woodbury terms
    (``paired_ar1_posterior``), checked against the dense ``latent_posterior`` in the tests."""
    nat = C.natural_noise(theta[:3], jnp.mean(d.ref_force))
    a2 = force_noise_var(jnp.exp(nat[0]), jnp.exp(nat[1]), d.ref_force)
    n = d.force.shape[0]
    kp, V, rho = jnp.exp(theta[3]), jnp.exp(theta[4]), jnp.tanh(theta[5])
    v = jnp.concatenate([a2, jnp.full(n, jnp.exp(2.0 * nat[2]))])
    uf = d.lever * d.hold_sd * kp
    ul = jnp.full(n, -V * d.boyle * d.hold_sd * kp)
    Z = _stack_design(d.X)
    y = jnp.concatenate([d.force, d.piston])
    w = jnp.concatenate([d.weight, d.weight])
    post = paired_ar1_posterior(Z, y, v, uf, ul, rho, _coefficient_prior_sd(), w)
    return post, nat, (kp, V, rho)


def ar1_log_prior(theta, d: AR1Data):
    nat = C.natural_noise(theta[:3], jnp.mean(d.ref_force))
    rho = jnp.tanh(theta[5])
    return (
        _log_prior_cubic_noise(nat, d.prior_mean[:3])
        - 0.5 * ((theta[3] - d.prior_mean[3]) / LOG_KP_PRIOR_SD) ** 2
        - 0.5 * ((theta[4] - d.prior_mean[4]) / LOG_V_PRIOR_SD) ** 2
        + jnp.log1p(-(rho**2))  # rho uniform on (-1, 1): the Jacobian of tanh
    )


#: Sampled parameters farther than this many prior sds from their prior centre are refused: the
#: prior gives them no weight, and the Woodbury terms lose their precision there.
PRIOR_BOX_SD = 8.0


def ar1_log_prob(theta, d: AR1Data):
    post, nat, _ = _ar1_post(theta, d)
    z = jnp.concatenate(
        [
            (nat - d.prior_mean[:3]) / C.NOISE_PRIOR_SD,
            (theta[3:5] - d.prior_mean[3:5]) / jnp.array([LOG_KP_PRIOR_SD, LOG_V_PRIOR_SD]),
            theta[5:6]
            / 0.5,  # |rho| < tanh(4) = 0.9993: stationary, and 1 - rho^2 keeps its digits
        ]
    )
    inside = jnp.all(jnp.abs(z) < PRIOR_BOX_SD)
    return jnp.where(inside, ar1_log_prior(theta, d) + post.log_marginal, -jnp.inf)


def ar1_draw(theta, key, d: AR1Data):
    return draw_exact(_ar1_post(theta, d)[0], key)


def _split_pair(P, r, blocks):
    """Block conditionals of each reading pair split by the chain rule: force_i given the other
    readings, piston_i given force_i and the others. Returns (force (n,), piston (n,))."""
    total = block_conditional_logpdf(P, r, blocks)
    Pll = P[blocks[:, 1], blocks[:, 1]]
    gl = (P @ r)[blocks[:, 1]]
    # piston_i given everything else: precision P_ll, residual (P r)_l / P_ll
    piston = -0.5 * gl**2 / Pll + 0.5 * jnp.log(Pll) - 0.5 * LOG_2PI
    return total - piston, piston


def ar1_pointwise(theta, beta, d: AR1Data):
    """log p(reading_i | coefficients, noise, the test's other readings), split into force and
    piston by the chain rule (the errors are correlated: the readings do not factorise)."""
    v, uf, ul, rho = _paired(theta, d)
    r = jnp.concatenate([d.force, d.piston]) - _stack_design(d.X) @ beta
    f, p = _split_pair(paired_ar1_precision(v, uf, ul, rho), r, d.blocks)
    return {"force_N": f, "piston_m": p}


def ar1_pointwise_loo(theta, d: AR1Data):
    """log p(force_i, piston_i | noise, the test's other readings), coefficients integrated out."""
    v, uf, ul, rho = _paired(theta, d)
    Z = _stack_design(d.X)
    y = jnp.concatenate([d.force, d.piston])
    P0 = paired_ar1_precision(v, uf, ul, rho)
    post = _ar1_post(theta, d._replace(weight=jnp.ones_like(d.weight)))[0]
    G = jax.scipy.linalg.solve_triangular(post.chol, Z.T @ P0, lower=True)  # (k, 2n)
    return block_conditional_logpdf(P0 - G.T @ G, y, d.blocks)


def ar1_predict(theta, beta, key, d: AR1Data):
    """A replicate: mean curves, a fresh AR(1) holding-error series, independent reading noise."""
    v, uf, ul, rho = _paired(theta, d)
    n = d.force.shape[0]
    k1, k2 = jax.random.split(key)
    z = ar1_series(rho, jax.random.normal(k1, (n,)))
    y = (
        _stack_design(d.X) @ beta
        + jnp.concatenate([uf * z, ul * z])
        + jnp.sqrt(v) * jax.random.normal(k2, (2 * n,))
    )
    return {"force_N": y[:n], "piston_m": y[n:]}


def ar1_start(d: AR1Data) -> np.ndarray:
    base = C.start(C.CubicData(d.X, d.force, d.piston, d.ref_force, d.prior_mean[:3], d.weight))
    out = []
    for rho in (0.0, 0.6):
        s = base.copy()
        s[2] = np.log(np.exp(base[2]) / 30.0)  # the holding error takes the piston's scatter
        out.append(np.concatenate([s, [0.0, float(d.prior_mean[4]), np.arctanh(rho)]]))
    return np.array(out)


def ar1_report(theta, beta, d: AR1Data) -> dict:
    out = C.report(theta[:, :3], beta, d)
    return out | {
        "k_p": np.exp(theta[:, 3]),
        "V_gas_m3": np.exp(theta[:, 4]),
        "rho": np.tanh(theta[:, 5]),
    }


def ar1_order_whitening(d: AR1Data, theta_mean) -> tuple[dict, dict]:
    """Lag-one correlation each block's errors have under the fitted model (posterior-mean noise),
    for pre-whitening the residuals before the recording-order check: rho times the share of the
    holding error in the block's variance."""
    v, U, _, _, _, (_, _, rho) = ar1_parts(jnp.asarray(theta_mean), d)
    n = d.force.shape[0]
    v, U = np.asarray(v), np.asarray(U)
    dpvar_f = np.diag(U[:n]) ** 2
    dpvar_l = U[n:][np.arange(n), np.arange(n)] ** 2
    share_f = float(np.mean(dpvar_f / (dpvar_f + v[:n])))
    share_l = float(np.mean(dpvar_l / (dpvar_l + v[n:])))
    sd_f = np.sqrt(dpvar_f + v[:n])
    sd_l = np.sqrt(dpvar_l + v[n:])
    return (
        {"force": float(rho) * share_f, "piston": float(rho) * share_l},
        {"force": sd_f, "piston": sd_l},
    )


AR1 = CollapsedModel(
    name="per-pressure cubics (eqs. 8, 9), AR(1) pressure-holding errors in recording order",
    theta_names=AR_SAMPLER_NAMES,
    log_prob=ar1_log_prob,
    draw_linear=ar1_draw,
    pointwise=ar1_pointwise,
    start=ar1_start,
    report=ar1_report,
    predict=ar1_predict,
    observed=C.observed,
    pointwise_loo=ar1_pointwise_loo,
    hold_out=C.hold_out,
)


def prewhiten(residuals, rho: float):
    """Prais-Winsten transform of a series with AR(1) errors of lag-one correlation ``rho``:
    e_0 sqrt(1 - rho^2), e_i - rho e_(i-1) (independent errors of the same innovation sd)."""
    r = np.asarray(residuals, float)
    out = np.empty_like(r)
    out[0] = r[0] * np.sqrt(1.0 - rho**2)
    out[1:] = r[1:] - rho * r[:-1]
    return out
