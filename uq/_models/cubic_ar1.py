"""The per-pressure cubics with AR(1) pressure-holding errors in recording order.

**AR(1) pressure-holding errors** (``AR1``; pressure not recorded, recording order known). The
holding errors are latent: dp = k_p s_p z with z a stationary AR(1) series in recording order
(unit variance, lag-one correlation rho, a slowly corrected screw drive), s_p the stand's holding
sd. One dp_i moves both readings of row i, so per test the 2n readings have covariance

    Sigma = diag(sigma_F^2, sigma_L^2) + u u^T o R(rho),    u = [lever k_p s_p ; -V/(p_abs S) k_p s_p]

(R_ij = rho^|i-j|), i.e. Sigma = D + U R U^T with U = [diag(b); diag(c)]. ``uq._inference.latent``
integrates the latent out exactly by whitening (the Kalman filter of the series, one O(n) scan:
W with W^T W = Sigma^-1 applied to readings and design), so the coefficients stay conjugate.
Sampled: (psi, eta, log sigma_L) as in the plain model, log k_p ~ N(0, 0.5^2), log V ~
N(log V_s, 0.5^2), and atanh(rho) with rho uniform on (-1, 1). sigma0 and sigma_L are then what
is left besides the pressure holding (displacement, calipers), and sigma_L's prior is centred on
that remainder of the stand's budget (``ar1_noise_prior_mean``), not on the plain model's 1 mm.

: The pressure sensor the measured model assumes (the paper's, section 3.2: 0.1 % accuracy, read
: as a gain error common to a test; its 1 Pa resolution is negligible). The virtual stand's
: ``--record-pressure`` sensor is the same (uq._stand.shapes).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from uq._data.stand_description import StandDescription
from uq._inference.collapsed import CollapsedModel, hold_out_by_weight
from uq._inference.float64 import jax, jnp
from uq._inference.latent import (
    ar1_precision,
    ar1_series,
    block_conditional_logpdf,
    paired_ar1_posterior,
    paired_ar1_precision,
)
from uq._inference.linear import LOG_2PI, draw_exact
from uq._models.cubic import (
    NOISE_PRIOR_SD,
    SAMPLER_NAMES,
    CubicData,
    coefficient_prior_sd,
    log_prior_noise,
    natural_noise,
    noise_prior_mean,
    observed,
    prepare,
    report,
    stack_design,
    start,
)
from uq._physics.cubic import cubic, cubic_slope
from uq._physics.quantities import BAR_PA, force_noise_var

LOG_KP_PRIOR_SD = 0.5
LOG_V_PRIOR_SD = 0.5
AR_SAMPLER_NAMES = SAMPLER_NAMES + ("log_k_p", "log_V_gas", "atanh_rho")

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


def ar1_noise_prior_mean(stand: StandDescription, lsq_piston, u) -> np.ndarray:
    """Prior centres of (log sigma0, log r, log sigma_L) for the AR(1) model: the plain model's,
    except sigma_L's. The plain model centres sigma_L on 1 mm, the scale of the holding error's
    piston term it lumps into the noise (Boyle's law: 1 to 6 mm on the paper's stand); here that
    term is the latent series, and what is left is the stand's calipers and displacement sensor
    (the latter through the piston's slope dL/dx, from the least-squares cubic at the readings):
    sqrt(caliper_sd^2 + (displacement_sd rms dL/dx)^2), never under 1 um (log 0 has no prior).
    With the 1 mm centre the weakly identified white part took variance from the series at low
    pressure (0.34 mm fitted where the stand's is 0.08 mm)."""
    slope = cubic_slope(np.asarray(lsq_piston, float), np.asarray(u, float))
    left = math.hypot(stand.caliper_sd_m, stand.displacement_sd_m * math.sqrt(np.mean(slope**2)))
    out = noise_prior_mean(stand)
    out[2] = math.log(max(left, 1e-6))
    return out


def ar1_data(test, x0_m: float, noise: str, stand: StandDescription, area_m2: float):
    """The AR(1) model's arrays for one test in recording order (``cubic._prepare``'s tuple)."""
    data, lsq_f, lsq_l, ref = prepare(test, x0_m, noise, stand)
    u = test.height_m - x0_m
    p_pa = test.pressure_bar * BAR_PA
    n = u.size
    ar = AR1Data(
        data.X,
        data.force,
        data.piston,
        data.ref_force,
        jnp.asarray(
            np.concatenate(
                [ar1_noise_prior_mean(stand, lsq_l, u), [0.0, np.log(stand.gas_volume_at_xmax_m3)]]
            )
        ),
        data.weight,
        jnp.asarray(cubic(lsq_f, u) / p_pa),
        jnp.asarray(float(stand.pressure_sd_bar(test.pressure_bar)) * BAR_PA),
        jnp.asarray(1.0 / ((test.pressure_bar + stand.p_atm_bar) * BAR_PA * area_m2)),
        jnp.asarray(np.stack([np.arange(n), n + np.arange(n)], axis=1)),
    )
    return ar, lsq_f, lsq_l, ref


def _parts(theta, d: AR1Data):
    """(v (2n,), uf (n,), ul (n,), nat (3,), (k_p, V, rho)) at theta (6,): the independent
    variances and each reading's loading on the holding-error series z (force, piston)."""
    nat = natural_noise(theta[:3], jnp.mean(d.ref_force))
    a2 = force_noise_var(jnp.exp(nat[0]), jnp.exp(nat[1]), d.ref_force)
    n = d.force.shape[0]
    kp, V, rho = jnp.exp(theta[3]), jnp.exp(theta[4]), jnp.tanh(theta[5])
    v = jnp.concatenate([a2, jnp.full(n, jnp.exp(2.0 * nat[2]))])
    uf, ul = d.lever * d.hold_sd * kp, jnp.full(n, -V * d.boyle * d.hold_sd * kp)
    return v, uf, ul, nat, (kp, V, rho)


def ar1_parts(theta, d: AR1Data):
    """(v (2n,), U (2n, n), Q (n, n), log det Q, nat (3,), (k_p, V, rho)) at theta (6,)."""
    v, uf, ul, nat, params = _parts(theta, d)
    Q, ldQ = ar1_precision(params[2], uf.size)
    return v, jnp.concatenate([jnp.diag(uf), jnp.diag(ul)], axis=0), Q, ldQ, nat, params


def _ar1_post(theta, d: AR1Data):
    """The coefficients' posterior given theta: the whitened O(n) form (``paired_ar1_posterior``),
    checked against the dense ``latent_posterior`` and a dense Cholesky factor in the tests."""
    v, uf, ul, nat, (kp, V, rho) = _parts(theta, d)
    Z = stack_design(d.X)
    y = jnp.concatenate([d.force, d.piston])
    w = jnp.concatenate([d.weight, d.weight])
    post = paired_ar1_posterior(Z, y, v, uf, ul, rho, coefficient_prior_sd(), w)
    return post, nat, (kp, V, rho)


def ar1_log_prior(theta, d: AR1Data):
    nat = natural_noise(theta[:3], jnp.mean(d.ref_force))
    rho = jnp.tanh(theta[5])
    return (
        log_prior_noise(nat, d.prior_mean[:3])
        - 0.5 * ((theta[3] - d.prior_mean[3]) / LOG_KP_PRIOR_SD) ** 2
        - 0.5 * ((theta[4] - d.prior_mean[4]) / LOG_V_PRIOR_SD) ** 2
        + jnp.log1p(-(rho**2))  # rho uniform on (-1, 1): the Jacobian of tanh
    )


#: Sampled parameters farther than this many prior sds from their prior centre are refused: the
#: prior gives them no weight (and 1 - rho^2 would lose its digits beyond |atanh rho| = 4).
PRIOR_BOX_SD = 8.0


def ar1_log_prob(theta, d: AR1Data):
    post, nat, _ = _ar1_post(theta, d)
    z = jnp.concatenate(
        [
            (nat - d.prior_mean[:3]) / NOISE_PRIOR_SD,
            (theta[3:5] - d.prior_mean[3:5]) / jnp.array([LOG_KP_PRIOR_SD, LOG_V_PRIOR_SD]),
            theta[5:6]
            / 0.5,  # |rho| < tanh(4) = 0.9993: stationary, and 1 - rho^2 keeps its digits
        ]
    )
    inside = jnp.all(jnp.abs(z) < PRIOR_BOX_SD)
    return jnp.where(inside, ar1_log_prior(theta, d) + post.log_marginal, -jnp.inf)


def ar1_draw_linear(theta, key, d: AR1Data):
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
    v, uf, ul, _, (_, _, rho) = _parts(theta, d)
    r = jnp.concatenate([d.force, d.piston]) - stack_design(d.X) @ beta
    f, p = _split_pair(paired_ar1_precision(v, uf, ul, rho), r, d.blocks)
    return {"force_N": f, "piston_m": p}


def ar1_pointwise_loo(theta, d: AR1Data):
    """log p(force_i, piston_i | noise, the test's other readings), coefficients integrated out."""
    v, uf, ul, _, (_, _, rho) = _parts(theta, d)
    Z = stack_design(d.X)
    y = jnp.concatenate([d.force, d.piston])
    P0 = paired_ar1_precision(v, uf, ul, rho)
    post = _ar1_post(theta, d._replace(weight=jnp.ones_like(d.weight)))[0]
    G = jax.scipy.linalg.solve_triangular(post.chol, Z.T @ P0, lower=True)  # (k, 2n)
    return block_conditional_logpdf(P0 - G.T @ G, y, d.blocks)


def ar1_predict(theta, beta, key, d: AR1Data):
    """A replicate: mean curves, a fresh AR(1) holding-error series, independent reading noise."""
    v, uf, ul, _, (_, _, rho) = _parts(theta, d)
    n = d.force.shape[0]
    k1, k2 = jax.random.split(key)
    z = ar1_series(rho, jax.random.normal(k1, (n,)))
    y = (
        stack_design(d.X) @ beta
        + jnp.concatenate([uf * z, ul * z])
        + jnp.sqrt(v) * jax.random.normal(k2, (2 * n,))
    )
    return {"force_N": y[:n], "piston_m": y[n:]}


def ar1_start(d: AR1Data) -> np.ndarray:
    base = start(CubicData(d.X, d.force, d.piston, d.ref_force, d.prior_mean[:3], d.weight))
    out = []
    for rho in (0.0, 0.6):
        s = base.copy()
        s[2] = np.log(np.exp(base[2]) / 30.0)  # the holding error takes the piston's scatter
        out.append(np.concatenate([s, [0.0, float(d.prior_mean[4]), np.arctanh(rho)]]))
    return np.array(out)


def ar1_report(theta, beta, d: AR1Data) -> dict:
    out = report(theta[:, :3], beta, d)
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


AR1 = CollapsedModel.of(
    globals(),
    "per-pressure cubics (eqs. 8, 9), AR(1) pressure-holding errors in recording order",
    AR_SAMPLER_NAMES,
    prefix="ar1_",
    observed=observed,
    hold_out=hold_out_by_weight,
)


def prewhiten(residuals, rho: float):
    """Prais-Winsten transform of a series with AR(1) errors of lag-one correlation ``rho``:
    e_0 sqrt(1 - rho^2), e_i - rho e_(i-1) (independent errors of the same innovation sd)."""
    r = np.asarray(residuals, float)
    out = np.empty_like(r)
    out[0] = r[0] * np.sqrt(1.0 - rho**2)
    out[1:] = r[1:] - rho * r[:-1]
    return out
