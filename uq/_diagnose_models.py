"""The models of ``uq diagnose``: the traditional baseline and its augmentations (section 4).

All tests of a campaign are fitted jointly. With t = (x - x0) / H, H = 0.05 m, and the
effective area F_eff(u) = sum_j a_j t^j (one curve for every pressure, order K by data):

    force   P_ij = p_i F_eff(u_ij)                                   (eq. 1)
    piston  L_ij = r_i - (1/S) int_{x0}^{x_ij} F_eff dx                (eq. 2, 5)

one piston reference r_i per test. Each mechanism adds columns or rescales columns, so the
model stays linear in (a, r, mechanism coefficients) given at most three nonlinear
magnitudes (pressure_dependent_area m_A, hysteresis m_H, volume_excess m_V):

    pressure_dependent_area  force and integral scaled by (1 + m_A p_bar)
    casing_force             force + E(u), E a cubic in t (magnitude E(x0) = e_0)
    hysteresis               force x (1 + m_H) on compression, (1 - m_H) on rebound
    force_offset             force + m
    thermal_drift            piston + step * m * 1e-6 / S   (m in cm^3 per step)
    volume_excess            integral scaled by (1 + m_V): dV/dx = F_eff (1 + m_V), force unchanged

Noise (the stand's error budget, section 3.2 of the paper): the same pressure-holding
error dp raises the force by dp F_eff and leaves the piston *short* by V_gas dp / (p_abs S)
(Boyle: at p + dp the gas needs less room), so force and piston residuals are strongly
anti-correlated. We fit the decorrelated pair z = P + c L (c = F_eff p_abs S / V_gas, a
plug-in constant per point, so c dL = -dp F_eff cancels the force's dp F_eff; a
unit-triangular linear map of the data, so likelihoods are unchanged in meaning) and L, each
with the budget's sd times a learned scale factor k_z, k_L (log k ~ N(0, 2^2)). The budget
(load cell, pressure holding, displacement, calipers, gas volumes) is a StandDescription,
the paper's stand by default.

Every model shares one jitted function: inactive mechanisms have zero columns (which cancel
exactly in the collapsed marginal likelihood) and inactive magnitudes are held at zero, so a
campaign compiles once, whatever the candidate.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ._jax import jax, jnp
from ._linear import draw_exact, gaussian_loglik, linear_posterior
from ._physics import BAR_PA, BASIS_SCALE_M
from ._recordings import Recordings
from ._stand_description import PAPER_STAND, StandDescription

MECHS = ("pressure_dependent_area", "casing_force", "hysteresis", "force_offset", "thermal_drift", "volume_excess")
N_MECH = len(MECHS)
K_MAX = 5  # highest power of t in F_eff
CASING_DEG = 3
#: Number of parameters each mechanism adds (parsimony order: fewer is simpler).
N_PARAMS = {"force_offset": 1, "thermal_drift": 1, "hysteresis": 1, "pressure_dependent_area": 1,
            "volume_excess": 1, "casing_force": CASING_DEG + 1}
SIMPLICITY = ("force_offset", "thermal_drift", "hysteresis", "volume_excess", "pressure_dependent_area", "casing_force")
THETA_NAMES = ("log_k_force", "log_k_piston", "m_area_per_bar", "m_hysteresis", "m_volume_excess")
#: Prior sds of the sampled parameters; volume_excess is a fraction of F_eff (0.12 on Table 1).
THETA_PRIOR_SD = np.array([2.0, 2.0, 0.1, 0.1, 0.3])
N_THETA = len(THETA_NAMES)
#: theta index of each nonlinear magnitude.
NONLINEAR = {"pressure_dependent_area": 2, "hysteresis": 3, "volume_excess": 4}
FEFF_PRIOR_SD = 1.0  # m^2
REF_PRIOR_SD = 1.0  # m
CASING_PRIOR_SD = 1.0e4  # N
OFFSET_PRIOR_SD = 1.0e4  # N
DRIFT_PRIOR_SD = 100.0  # cm^3 per step
FLOOR_N = 1.0
DP_RESIDUAL_SHARE = 0.2  # share of the pressure term left in z if V_gas is off


class Data(NamedTuple):
    """Campaign arrays, one entry per recorded point (n,), plus the one-hot test matrix."""

    p_bar: jnp.ndarray
    t: jnp.ndarray
    sgn: jnp.ndarray  # +1 compression, -1 rebound
    step: jnp.ndarray
    R: jnp.ndarray  # (n, n_tests)
    c: jnp.ndarray  # decorrelation constant, N/m
    force: jnp.ndarray
    piston: jnp.ndarray
    sd_z: jnp.ndarray  # budget sd of z, N
    sd_L: jnp.ndarray  # budget sd of L, m
    area: jnp.ndarray  # piston area S, m^2 (scalar)
    #: (2n,) 1 = row informs the fit, 0 = held out (K-fold); stacked as (z rows, L rows).
    fit_w: jnp.ndarray


def hold_out(d: Data, held: np.ndarray) -> Data:
    """``d`` with rows held out of the fit: ``held`` bool, (n,) recorded points (their z and L
    rows both) or (2n,) single rows of the stacked (z, L) likelihood."""
    held = np.asarray(held, bool)
    if held.size == np.asarray(d.force).size:
        held = np.concatenate([held, held])
    return d._replace(fit_w=jnp.asarray(np.where(held, 0.0, 1.0)))


def prepare(rec: Recordings, stand: StandDescription = PAPER_STAND) -> tuple[Data, dict]:
    """Arrays for the models and per-point metadata (numpy) for the residual analysis.

    Noise formulas from ``stand`` (its error budget and gas volumes)."""
    S = rec.piston_area_m2
    area_check = []
    cols = {k: [] for k in ("p", "t", "sgn", "step", "ti", "c", "F", "L", "sdz", "sdL", "x", "comp")}
    for i, test in enumerate(rec.tests):
        u = test.height_m - rec.x0_m
        t = u / BASIS_SCALE_M
        deg = min(4, test.n_points - 2)
        V = np.vander(t, deg + 1, increasing=True)
        cf = np.linalg.lstsq(V, test.force_N, rcond=None)[0]
        cl = np.linalg.lstsq(V, test.piston_m, rcond=None)[0]
        dV = np.vander(t, deg, increasing=True) * np.arange(1, deg + 1) / BASIS_SCALE_M
        P_hat = V @ cf
        dPdx = dV @ cf[1:]
        slope = dV @ cl[1:]
        p_pa = test.pressure_bar * BAR_PA
        feff = np.abs(P_hat) / p_pa
        L_hat = V @ cl
        # The piston is lowest at x_max, where the element holds element_volume_at_xmax_m3.
        v_gas = stand.receiver_air_m3 + np.maximum(stand.element_volume_at_xmax_m3 - S * (L_hat - L_hat.min()), 1e-4)
        p_abs_bar = test.pressure_bar + stand.p_atm_bar
        sdp_bar = float(stand.pressure_sd_bar(test.pressure_bar))
        c = feff * p_abs_bar * BAR_PA * S / v_gas
        sdz = np.sqrt((stand.load_cell_rel_sd * P_hat) ** 2 + (DP_RESIDUAL_SHARE * sdp_bar * BAR_PA * feff) ** 2
                      + (dPdx * stand.displacement_sd_m) ** 2 + FLOOR_N**2)
        sdL = np.sqrt((v_gas * sdp_bar / p_abs_bar / S) ** 2 + (slope * stand.displacement_sd_m) ** 2
                      + stand.caliper_sd_m**2)
        i0 = np.argmin(np.abs(u))
        area_check.append({"pressure_bar": test.pressure_bar, "from_force_m2": float(P_hat[i0] / p_pa),
                           "from_volume_m2": float(-S * slope[i0]),
                           "volume_over_force": float(-S * slope[i0] / (P_hat[i0] / p_pa))})
        n = test.n_points
        cols["p"].append(np.full(n, test.pressure_bar))
        cols["t"].append(t)
        cols["sgn"].append(np.where(test.compression, 1.0, -1.0))
        cols["step"].append(test.step.astype(float))
        cols["ti"].append(np.full(n, i))
        cols["c"].append(c)
        cols["F"].append(test.force_N)
        cols["L"].append(test.piston_m)
        cols["sdz"].append(sdz)
        cols["sdL"].append(sdL)
        cols["x"].append(test.height_m)
        cols["comp"].append(test.compression)
    cat = {k: np.concatenate(v) for k, v in cols.items()}
    R = np.eye(len(rec.tests))[cat["ti"].astype(int)]
    data = Data(*(jnp.asarray(a, dtype=float) for a in (cat["p"], cat["t"], cat["sgn"], cat["step"], R, cat["c"],
                                                           cat["F"], cat["L"], cat["sdz"], cat["sdL"])),
                jnp.asarray(S, dtype=float), jnp.ones(2 * cat["F"].size))
    meta = {"pressure_bar": cat["p"], "height_m": cat["x"], "compression": cat["comp"].astype(bool),
            "step": cat["step"].astype(int), "test": cat["ti"].astype(int), "force_N": cat["F"],
            "piston_m": cat["L"], "area": S, "area_check": area_check}
    return data, meta


def mask_of(names, order: int) -> jnp.ndarray:
    """Dynamic model switch: N_MECH mechanism flags (order of MECHS), then flags for powers 0..K_MAX of F_eff."""
    mech = [1.0 if m in names else 0.0 for m in MECHS]
    powers = [1.0 if j <= order else 0.0 for j in range(K_MAX + 1)]
    return jnp.asarray(mech + powers)


def _design(theta, mask, d: Data):
    """Design matrices of force (n, k) and piston (n, k) and the prior sds (k,)."""
    m_area = mask[0] * theta[2]
    m_hyst = mask[2] * theta[3]
    m_vol = mask[5] * theta[4]
    g = 1.0 + m_area * d.p_bar
    hy = 1.0 + m_hyst * d.sgn
    pw = jnp.arange(K_MAX + 1)
    on = mask[N_MECH:]
    T = d.t[:, None] ** pw * on
    Tint = d.t[:, None] ** (pw + 1) / (pw + 1) * on
    n = d.t.size
    zeros = jnp.zeros((n, 1))
    XF_a = (d.p_bar * BAR_PA * g * hy)[:, None] * T
    XL_a = -(BASIS_SCALE_M / d.area) * (g * (1.0 + m_vol))[:, None] * Tint
    XF_r = jnp.zeros_like(d.R)
    XL_r = d.R
    Tc = d.t[:, None] ** jnp.arange(CASING_DEG + 1)
    XF_e = mask[1] * hy[:, None] * Tc
    XL_e = jnp.zeros_like(Tc)
    XF_o = mask[3] * jnp.ones((n, 1))
    XL_d = mask[4] * (d.step * 1e-6 / d.area)[:, None]
    XF = jnp.concatenate([XF_a, XF_r, XF_e, XF_o, zeros], axis=1)
    XL = jnp.concatenate([XL_a, XL_r, XL_e, zeros, XL_d], axis=1)
    prior = jnp.concatenate([
        jnp.full(K_MAX + 1, FEFF_PRIOR_SD), jnp.full(d.R.shape[1], REF_PRIOR_SD),
        jnp.full(CASING_DEG + 1, CASING_PRIOR_SD), jnp.array([OFFSET_PRIOR_SD, DRIFT_PRIOR_SD])])
    return XF, XL, prior


def _stacked(theta, mask, d: Data):
    XF, XL, prior = _design(theta, mask, d)
    # z = P + c L: the pressure-holding error moves P by +dp F_eff and c L by -dp F_eff.
    Xz = XF + d.c[:, None] * XL
    X = jnp.concatenate([Xz, XL], axis=0)
    y = jnp.concatenate([d.force + d.c * d.piston, d.piston])
    sigma = jnp.concatenate([jnp.exp(theta[0]) * d.sd_z, jnp.exp(theta[1]) * d.sd_L])
    # Held-out rows (fit_w = 0) get an enormous sd: they drop out of the coefficient posterior
    # (their log sigma terms are removed in _log_post), so the MAP is that of the training rows.
    sigma_fit = sigma * jnp.where(d.fit_w > 0, 1.0, 1e100)
    # Column scaling: exact reparametrisation (the marginal likelihood is invariant), for numerics.
    s = jnp.sqrt(jnp.mean((X / sigma_fit[:, None]) ** 2, axis=0))
    s = jax.lax.stop_gradient(jnp.where(s > 0, s, 1.0))
    return X / s, y, sigma_fit, prior * s, s, XF, XL, sigma


def _log_post(theta, mask, d: Data):
    X, y, sigma, prior, *_ = _stacked(theta, mask, d)
    lp = linear_posterior(X, y, sigma, prior).log_marginal
    # Held-out rows' -log sigma terms depend on the noise scales: take them back out.
    lp = lp + jnp.sum((1.0 - d.fit_w) * jnp.log(sigma))
    active = jnp.concatenate([jnp.ones(2), jnp.array([mask[0], mask[2], mask[5]])])
    lp = lp - 0.5 * jnp.sum(active * (theta / THETA_PRIOR_SD) ** 2)
    return jnp.where(jnp.isfinite(lp), lp, -jnp.inf)


# lax.map, not vmap: XLA CPU can deadlock on batched (vmapped) Cholesky factorisations, as
# seen here with batches of 1000 under load; a sequential map over small factorisations is
# only slightly slower and never hangs.
@jax.jit
def log_post_batch(thetas, mask, d: Data):
    return jax.lax.map(lambda th: _log_post(th, mask, d), thetas)


PAD = 16  # every batched call is padded to a multiple of this: one compilation per campaign


def log_post(thetas: np.ndarray, mask, d: Data) -> np.ndarray:
    """Log posterior of full thetas (m, N_THETA), padded to a fixed batch size."""
    thetas = np.atleast_2d(np.asarray(thetas, float))
    m = thetas.shape[0]
    size = -(-m // PAD) * PAD
    padded = np.concatenate([thetas, np.repeat(thetas[-1:], size - m, axis=0)])
    return np.asarray(log_post_batch(jnp.asarray(padded), mask, d))[:m]


def _hessian_fd(f_batch, x, h):
    """Central-difference Hessian of f at x, all stencil points in one batched call."""
    k = x.size
    pts = [x.copy()]
    for i in range(k):
        for s in (1, -1):
            p = x.copy()
            p[i] += s * h[i]
            pts.append(p)
    pairs = []
    for i in range(k):
        for j in range(i + 1, k):
            for si, sj in ((1, 1), (1, -1), (-1, 1), (-1, -1)):
                p = x.copy()
                p[i] += si * h[i]
                p[j] += sj * h[j]
                pts.append(p)
            pairs.append((i, j))
    v = f_batch(np.array(pts))
    f0 = v[0]
    Hm = np.zeros((k, k))
    for i in range(k):
        Hm[i, i] = (v[1 + 2 * i] - 2 * f0 + v[2 + 2 * i]) / h[i] ** 2
    base = 1 + 2 * k
    for n, (i, j) in enumerate(pairs):
        a, b, c, e = v[base + 4 * n: base + 4 * n + 4]
        Hm[i, j] = Hm[j, i] = (a - b - c + e) / (4 * h[i] * h[j])
    return Hm


def draw_row(theta, key, mask, d: Data):
    """One exact coefficient draw given theta, with what the engine keeps of it (mapped by map_rows)."""
    X, y, sigma_fit, prior, s, XF, XL, sigma = _stacked(theta, mask, d)
    post = linear_posterior(X, y, sigma_fit, prior)
    beta_s = draw_exact(post, key)
    ll = gaussian_loglik(y, X @ beta_s, sigma)  # every row, held out or not, at its own noise
    beta = beta_s / s
    return ll, XF @ beta, XL @ beta, beta, sigma



def active_dims(names) -> list[int]:
    return [0, 1, *sorted(NONLINEAR[m] for m in names if m in NONLINEAR)]


def fit_map(names, order: int, d: Data) -> tuple[np.ndarray, float, np.ndarray]:
    """MAP of the sampled parameters (collapsed), log posterior there, Laplace covariance (active dims).

    Quasi-Newton (L-BFGS) on the collapsed log posterior with batched central differences:
    one jitted function serves every candidate model and the sampler, so a campaign compiles
    once however many candidates are screened.
    """
    from scipy.optimize import minimize

    mask = mask_of(names, order)
    dims = active_dims(names)

    def f_batch(sub):
        return -log_post(expand(np.asarray(sub), names), mask, d)

    def fg(sub):
        k = sub.size
        pts = np.repeat(sub[None], 1 + 2 * k, axis=0)
        for i in range(k):
            pts[1 + 2 * i, i] += 1e-6
            pts[2 + 2 * i, i] -= 1e-6
        v = f_batch(pts)
        if not np.isfinite(v[0]):
            return 1e300, np.zeros(k)
        return v[0], (v[1::2] - v[2::2]) / 2e-6

    best = None
    starts = [np.zeros(len(dims))]
    if len(dims) > 2:
        starts += [np.r_[0.0, 0.0, np.full(len(dims) - 2, 0.01)], np.r_[0.0, 0.0, np.full(len(dims) - 2, -0.01)]]
    for x0 in starts:
        res = minimize(fg, x0, jac=True, method="L-BFGS-B", options={"maxiter": 300, "gtol": 1e-7})
        if np.isfinite(res.fun) and (best is None or res.fun < best.fun):
            best = res
    sub = best.x
    h = np.where(np.arange(sub.size) < 2, 1e-3, 1e-5)
    Hm = _hessian_fd(f_batch, sub, h)
    try:
        cov = np.linalg.inv(Hm)
        np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        cov = np.diag(1.0 / np.maximum(np.abs(np.diag(Hm)), 1e-12))
    return expand(sub, names), -float(best.fun), cov


def expand(sub: np.ndarray, names) -> np.ndarray:
    """Sampled active coordinates (..., len(dims)) -> full theta (..., N_THETA)."""
    dims = active_dims(names)
    full = np.zeros(sub.shape[:-1] + (N_THETA,))
    full[..., dims] = sub
    return full
