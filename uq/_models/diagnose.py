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

Every model shares the same jitted functions (MAP solver, Hessian, log posterior, coefficient
draws): inactive mechanisms have zero columns (which cancel exactly in the collapsed marginal
likelihood) and inactive magnitudes are held at zero, the switches being array arguments, so a
campaign compiles each once, whatever the candidate.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
import optimistix as optx

from uq._data.recordings import Recordings
from uq._data.stand_description import PAPER_STAND, StandDescription
from uq._inference.float64 import jax, jnp
from uq._inference.linear import draw_exact, gaussian_loglik, linear_posterior, map_rows, row_keys
from uq._physics.quantities import BAR_PA, BASIS_SCALE_M

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


LOG_POST_CHUNK = 32  # rows per compiled call: the sampler asks for 2 x walkers per move


def log_post(thetas: np.ndarray, mask, d: Data) -> np.ndarray:
    """Log posterior of full thetas (m, N_THETA). A sequential map (``batch_size=1``), not vmap:
    XLA CPU can deadlock on batched (vmapped) Cholesky factorisations, as seen here with batches
    of 1000 under load; a sequential map over small factorisations is only slightly slower."""
    return map_rows(_log_post, (np.atleast_2d(np.asarray(thetas, float)),), (mask, d), batch_size=1,
                    chunk=LOG_POST_CHUNK)


def draw_row(theta, key, mask, d: Data):
    """One exact coefficient draw given theta, with what the engine keeps of it (mapped by map_rows)."""
    X, y, sigma_fit, prior, s, XF, XL, sigma = _stacked(theta, mask, d)
    post = linear_posterior(X, y, sigma_fit, prior)
    beta_s = draw_exact(post, key)
    ll = gaussian_loglik(y, X @ beta_s, sigma)  # every row, held out or not, at its own noise
    beta = beta_s / s
    return ll, XF @ beta, XL @ beta, beta, sigma


def draw_rows(theta: np.ndarray, key, mask, d: Data) -> tuple[np.ndarray, ...]:
    """``draw_row`` for every row of ``theta`` (m, N_THETA), row i with key ``jax.random.split(key, m)[i]``,
    as numpy arrays (ll, muF, muL, beta, sigma). Laplace draws, K-fold draws and the sampler's draws
    share one compiled program whatever their number (``map_rows``)."""
    return map_rows(draw_row, (np.asarray(theta, float), row_keys(key, theta.shape[0])), (mask, d), chunk=256)


def active_dims(names) -> list[int]:
    return [0, 1, *sorted(NONLINEAR[m] for m in names if m in NONLINEAR)]


#: BFGS on the collapsed negative log posterior: |step| < atol + rtol |theta| and the same for
#: the objective (optimistix's Cauchy criterion), at most MAP_MAX_STEPS steps (backtracking
#: rejections count). Starts: zero, and the nonlinear magnitudes at +-MAP_START. A run that does
#: not report success is restarted once from where it stopped; if that fails too, the point is
#: kept only if a Newton step from it would gain less than MAP_DECREMENT nats.
MAP_RTOL = 1e-10
MAP_ATOL = 1e-10
MAP_MAX_STEPS = 1000
MAP_START = 0.01
MAP_DECREMENT = 1e-3


def _neg_log_post(x, args):
    """Collapsed negative log posterior over the full theta (N_THETA,), differentiable.

    ``active`` (N_THETA,) flags the sampled coordinates: inactive ones are held at zero in the
    model and carry a unit quadratic, so every candidate minimises the same function of the
    same shape (one compilation per campaign) and the Hessian's active block is exact."""
    active, mask, d = args
    return -_log_post(active * x, mask, d) + 0.5 * jnp.sum((1.0 - active) * x**2)


@jax.jit
def _minimise(x0, active, mask, d: Data):
    """One BFGS run from ``x0``: theta, objective there, whether optimistix reports success."""
    solver = optx.BFGS(rtol=MAP_RTOL, atol=MAP_ATOL)
    sol = optx.minimise(_neg_log_post, solver, x0, args=(active, mask, d), max_steps=MAP_MAX_STEPS,
                        throw=False)
    return sol.value, _neg_log_post(sol.value, (active, mask, d)), sol.result == optx.RESULTS.successful


@jax.jit
def _gradient_hessian(x, active, mask, d: Data):
    args = (active, mask, d)
    return jax.grad(_neg_log_post)(x, args), jax.hessian(_neg_log_post)(x, args)


def _best_start(starts, active, mask, d: Data):
    """The lowest finite optimum over the starts, as (theta, objective, converged), or None."""
    best = None
    for x0 in starts:
        x, f, ok = _minimise(jnp.asarray(x0), active, mask, d)
        f = float(f)
        if np.isfinite(f) and (best is None or f < best[1]):
            best = (np.asarray(x), f, bool(ok))
    return best


def fit_map(names, order: int, d: Data) -> tuple[np.ndarray, float, np.ndarray]:
    """MAP of the sampled parameters (collapsed), log posterior there, Laplace covariance (active dims).

    BFGS (optimistix) with JAX gradients on the collapsed negative log posterior, from zero and,
    with nonlinear magnitudes, from +-MAP_START in them; the Laplace covariance is the inverse of
    its JAX Hessian at the best optimum (the inverse diagonal if that is not positive definite).
    One jitted solver and one jitted Hessian serve every candidate model of a campaign: the
    model's mechanisms and active coordinates are array arguments.
    """
    mask = mask_of(names, order)
    dims = active_dims(names)
    flags = np.zeros(N_THETA)
    flags[dims] = 1.0
    active = jnp.asarray(flags)
    nonlin = flags * (np.arange(N_THETA) >= 2)
    starts = [np.zeros(N_THETA)] + ([MAP_START * nonlin, -MAP_START * nonlin] if nonlin.any() else [])
    best = _best_start(starts, active, mask, d)
    if best is not None and not best[2]:  # restart once, with a fresh BFGS, from where it stopped
        again = _best_start([best[0]], active, mask, d)
        if again is not None and again[1] <= best[1]:
            best = again
    if best is None:
        raise FloatingPointError(f"diagnose: the log posterior of model {names!r} is not finite at any start")
    x, f, converged = best
    g, Hm = (np.asarray(a) for a in _gradient_hessian(jnp.asarray(x), active, mask, d))
    g, Hm = g[dims], Hm[np.ix_(dims, dims)]
    try:
        cov = np.linalg.inv(Hm)
        np.linalg.cholesky(cov)
    except np.linalg.LinAlgError:
        cov = None
    if not converged and (cov is None or 0.5 * g @ cov @ g > MAP_DECREMENT):
        raise FloatingPointError(f"diagnose: the MAP of model {names!r} did not converge (BFGS, "
                                 f"{MAP_MAX_STEPS} steps, restarted once)")
    if cov is None:
        cov = np.diag(1.0 / np.maximum(np.abs(np.diag(Hm)), 1e-12))
    return expand(x[dims], names), -f, cov


def expand(sub: np.ndarray, names) -> np.ndarray:
    """Sampled active coordinates (..., len(dims)) -> full theta (..., N_THETA)."""
    dims = active_dims(names)
    full = np.zeros(sub.shape[:-1] + (N_THETA,))
    full[..., dims] = sub
    return full
