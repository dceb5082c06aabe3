"""Pressure-coupled surface model: one model of force and volume over all tests of a campaign.

Model (u = x - x0, t = u / h with h = 0.05 m, q = (p_u - p_mid) / p_half in -1..1 over the
tested pressures, p_u in Pa where it multiplies):

    force_ij  = p_i F_p(u_ij, p_i) + E(u_ij)
    piston_ij = r_i - (1/S) int_0^u [F_p(u', p_i) + D(u', p_i)] du'

    F_p(u, p) = sum_{k<=K, l<=Lp} c_kl t^k q^l   (pressure area, grows smoothly with p)
    E(u)      = sum_{m<=Ke} e_m t^m               (casing force, the same at every pressure)
    D(u, p)   = sum_{k<=Dk, l<=Dl} d_kl t^k q^l   (volume excess -dV/dx - F_p; 0 = traditional)

Names. F_p = (P - E) / p_u is the area on which the pressure acts once the casing's own force
is removed ("pressure area", ``pressure_area_m2`` in JSON). It is *not* the paper's effective
area F_eff = P / p_u (eq. 1), which includes the casing force: F_eff = F_p + E / p_u. Both are
reported, each under its own name (``feff_m2`` is always the paper's P / p_u).

r_i is one piston reference per test (nuisance). Everything is linear in (c, e, d, r) given
the noise, so the coefficients are integrated out with the collapsed kernel (``uq._inference.linear``)
and drawn exactly; emcee samples the five noise parameters only.

Noise (stand's error budget, paper section 3.2): the pressure-holding error dp of one
reading moves the force by +dp F_p and the piston by -V_gas dp / (p_abs S) at once (a
higher pressure compresses the gas, so the piston stands short of its isobaric position),
so each reading (force, piston) is bivariate normal with covariance

    [[s0^2 + (r Phat)^2 + b^2,  -b c], [-b c, c^2 + sL^2]],
    b = k_p dp_i F_p_hat,  c = k_p dp_i (V0 - dV_hat) / (p_abs S)

with dp_i the stand's holding sd (0.01 bar, 0.001 bar at 0.1 bar), k_p its multiplier, V0
the gas volume at the highest height and dV_hat the volume increment. The stand's constants
come from a ``StandDescription`` (``--stand FILE.toml``; default the paper's stand): dp_i from
its pressure holding, p_atm, and the centres of the priors
log s0[N] ~ N(log 10, 1.5), log r ~ N(log stand.load_cell_rel_sd, 0.5), log k_p ~ N(0, 0.5),
log sL[m] ~ N(log 1e-4, 1.5), log V0[m^3] ~ N(log stand.gas_volume_at_xmax_m3, 0.5) (paper:
0.5 %, 6.2 L); standardised coefficients ~ N(0, 1) with physical scales (c, d: 0.1 m^2;
e: 10 kN; r: 1 m).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import asdict, dataclass

import arviz as az
import numpy as np
import optimistix as optx

from uq._data.recordings import Recordings
from uq._data.stand_description import PAPER_STAND, StandDescription
from uq._inference.float64 import jax, jnp
from uq._inference.linear import (
    LOG_2PI,
    draw_exact,
    gram_plan,
    linear_posterior,
    map_rows,
    posterior_from_moments,
    row_keys,
    weighted_gram,
)
from uq._inference.sampler import Chains, Settings, convergence, run_ensembles, thin
from uq._inference.summary import band, estimate, loglik_idata, psis_loo
from uq._io.errors import InputError
from uq._physics.quantities import BAR_PA, BASIS_SCALE_M, force_noise_var

MAX_DRAWS = 4000
SCALE_C = 0.1  # m^2
SCALE_E = 1.0e4  # N
SCALE_D = 0.1  # m^2
SCALE_R = 1.0  # m
NOISE_NAMES = ("log_s0_N", "log_rel_load", "log_k_p", "log_sL_m", "log_V0_m3")


def noise_prior_mean(stand: StandDescription = PAPER_STAND) -> np.ndarray:
    """Prior centres of the five noise logs from the stand's description (a stand declaring a
    perfect load cell still gets a 0.01 % floor: log 0 has no prior)."""
    rel = max(stand.load_cell_rel_sd, 1e-4)
    return np.array(
        [np.log(10.0), np.log(rel), 0.0, np.log(1e-4), np.log(stand.gas_volume_at_xmax_m3)]
    )


NOISE_PRIOR_MEAN = noise_prior_mean(PAPER_STAND)
NOISE_PRIOR_SD = np.array([1.5, 0.5, 0.5, 1.5, 0.5])
LEVEL = 0.90


@dataclass(frozen=True)
class Orders:
    """Polynomial orders: pressure area F_p degree K in t and Lp in q, casing degree Ke, D degrees (Dk, Dl).

    Dk = -1 means D = 0 (the traditional theory for the volume); Ke = -1 means no casing term.
    """

    K: int = 3
    Lp: int = 2
    Ke: int = 2
    Dk: int = 1
    Dl: int = 1

    @property
    def label(self) -> str:
        d = "none" if self.Dk < 0 else f"{self.Dk}x{self.Dl}"
        return f"F_p {self.K}x{self.Lp}, casing {self.Ke}, D {d}"


#: chosen by PSIS-LOO on data/n50 (docs/surface.md): elpd_loo -262.3 against -299.0 (dse 13.8)
#: for the next best (F_p 3x4, casing 3, D 2x2) and -431.2 for F_p 3x2, casing 2, D 1x1
DEFAULT_ORDERS = Orders(3, 5, 3, 2, 3)
#: the small candidate set ranked by PSIS-LOO (``select_orders``, ``uq surface --select``)
CANDIDATES = (
    Orders(3, 2, 2, 1, 1),
    Orders(3, 4, 2, 1, 1),
    Orders(3, 7, 2, 1, 1),
    Orders(3, 4, 3, 2, 2),
    Orders(3, 5, 3, 2, 3),
)


# ----------------------------------------------------------------------------- design


def _tq(t, q, kmax, lmax, integrate=False):
    t = np.asarray(t, float)[..., None, None]
    q = np.asarray(q, float)[..., None, None]
    k = np.arange(kmax + 1)[:, None]
    lq = np.arange(lmax + 1)[None, :]
    if integrate:
        cols = t ** (k + 1) / (k + 1) * q**lq
    else:
        cols = t**k * q**lq
    cols = np.broadcast_to(cols, cols.shape)
    return cols.reshape(*cols.shape[:-2], -1)


def _poly(t, m):
    t = np.asarray(t, float)[..., None]
    return t ** np.arange(m + 1)


@dataclass(frozen=True)
class Geometry:
    x0_m: float
    area_m2: float
    p_mid: float
    p_half: float

    def t(self, x_m):
        return (np.asarray(x_m, float) - self.x0_m) / BASIS_SCALE_M

    def q(self, p_bar):
        return (np.asarray(p_bar, float) - self.p_mid) / self.p_half


def _sizes(o: Orders, n_tests: int):
    nc = (o.K + 1) * (o.Lp + 1)
    ne = o.Ke + 1
    nd = 0 if o.Dk < 0 else (o.Dk + 1) * (o.Dl + 1)
    return nc, ne, nd, n_tests


def designs(o: Orders, g: Geometry, x_m, p_bar, test_index, n_tests):
    """Force and piston design matrices in standardised coefficients, (n, k) each."""
    t, q = g.t(x_m), g.q(p_bar)
    p_pa = np.asarray(p_bar, float) * BAR_PA
    n = t.size
    nc, ne, nd, nr = _sizes(o, n_tests)
    Xf = np.zeros((n, nc + ne + nd + nr))
    Xl = np.zeros_like(Xf)
    Xf[:, :nc] = p_pa[:, None] * _tq(t, q, o.K, o.Lp) * SCALE_C
    if ne:
        Xf[:, nc : nc + ne] = _poly(t, o.Ke) * SCALE_E
    lever = -BASIS_SCALE_M / g.area_m2
    Xl[:, :nc] = lever * _tq(t, q, o.K, o.Lp, integrate=True) * SCALE_C
    if nd:
        Xl[:, nc + ne : nc + ne + nd] = lever * _tq(t, q, o.Dk, o.Dl, integrate=True) * SCALE_D
    Xl[np.arange(n), nc + ne + nd + np.asarray(test_index)] = SCALE_R
    return Xf, Xl


# ----------------------------------------------------------------------------- likelihood


def _cov_factors(theta, c):
    """Per-point whitening of the (force, piston) pair: (L11, L21, L22), each (n,)."""
    s0, rel, kp, sL, V0 = (jnp.exp(theta[i]) for i in range(5))
    a2 = force_noise_var(s0, rel, c["phat"])
    b = kp * c["dp_pa"] * c["feff_hat"]
    cc = kp * c["dp_pa"] * jnp.maximum(V0 - c["dv_hat"], 1e-4) / (c["p_abs_pa"] * c["area"])
    L11 = jnp.sqrt(a2 + b**2)
    L21 = -b * cc / L11  # pressure error: force up, piston down (anti-correlated)
    L22 = jnp.sqrt(cc**2 + sL**2 - L21**2)
    return L11, L21, L22


def _whiten(theta, Xf, Xl, F, L, c):
    L11, L21, L22 = _cov_factors(theta, c)
    yf = F / L11
    xf = Xf / L11[:, None]
    yl = (L - L21 * yf) / L22
    xl = (Xl - L21[:, None] * xf) / L22[:, None]
    return jnp.concatenate([xf, xl]), jnp.concatenate([yf, yl])


def gram_groups(Xf, Xl):
    """The design pairs of the whitened Gram matrix, grouped by their weight (``_posterior``)."""
    return [[(Xf, Xf)], [(Xl, Xl)], [(Xl, Xf), (Xf, Xl)]]


def _posterior(theta, Xf, Xl, F, L, c):
    """The coefficients' Gaussian posterior given the noise theta (log_marginal includes the
    readings' covariance determinant).

    Whitening reading i, a = xf / L11 and b = xl / L22 - s xf with s = L21 / (L11 L22), makes the
    Gram matrix  Xf^T diag(1/L11^2 + s^2) Xf + Xl^T diag(1/L22^2) Xl - (Xl^T diag(s/L22) Xf + its
    transpose): three weight vectors on designs that do not change while sampling, formed from
    the plan ``c["gram"]`` (``uq._inference.linear.GramPlan``) without the whitened design.
    """
    L11, L21, L22 = _cov_factors(theta, c)
    s = L21 / (L11 * L22)
    yf = F / L11
    yl = (L - L21 * yf) / L22
    gram = weighted_gram(c["gram"], (1.0 / L11**2 + s**2, 1.0 / L22**2, -s / L22))
    rhs = Xf.T @ (yf / L11 - s * yl) + Xl.T @ (yl / L22)
    log_det = 2.0 * jnp.sum(jnp.log(L11) + jnp.log(L22))
    return posterior_from_moments(
        gram, rhs, jnp.sum(yf**2 + yl**2), 2 * F.size, log_det, jnp.ones(Xf.shape[1])
    )


def _log_prior(theta, mean):
    z = (theta - mean) / NOISE_PRIOR_SD
    return -0.5 * jnp.sum(z**2)


def _one_log_prob(theta, Xf, Xl, F, L, c):
    lp = _log_prior(theta, c["prior_mean"]) + _posterior(theta, Xf, Xl, F, L, c).log_marginal
    return jnp.where(jnp.isfinite(lp), lp, -jnp.inf)


@jax.jit
def log_prob(thetas, Xf, Xl, F, L, c):
    """Log posterior of the noise parameters (coefficients integrated out); (W, 5) -> (W,)."""
    return jax.vmap(lambda th: _one_log_prob(th, Xf, Xl, F, L, c))(thetas)


def _neg(theta, args):
    return -_one_log_prob(theta, *args)


@jax.jit
def _bfgs(theta0, Xf, Xl, F, L, c):
    sol = optx.minimise(
        _neg,
        optx.BFGS(rtol=1e-8, atol=1e-8),
        theta0,
        args=(Xf, Xl, F, L, c),
        max_steps=400,
        throw=False,
    )
    return sol.value, sol.result


def _draw(theta, key, Xf, Xl, F, L, c):
    """One exact coefficient draw given the noise theta (mapped over samples by ``map_rows``)."""
    return draw_exact(_posterior(theta, Xf, Xl, F, L, c), key)


def _pointwise(theta, beta, Xf, Xl, F, L, c):
    """Pointwise log-likelihood of each (force, piston) reading at one draw, (n,)."""
    L11, L21, L22 = _cov_factors(theta, c)
    r1 = (F - Xf @ beta) / L11
    r2 = (L - Xl @ beta - L21 * r1) / L22
    return -0.5 * (r1**2 + r2**2) - jnp.log(L11) - jnp.log(L22) - LOG_2PI


def _block_loo(X, y, n, chol, mean):
    """log N of each whitened 2-row block (rows i, n+i) under the predictive from the other blocks.

    With unit whitened noise and posterior precision A = L L^T, leaving block i out gives the
    predictive N(X_i m_-i, (I - H_i)^-1) with H_i = X_i A^-1 X_i^T, and y_i - X_i m_-i =
    (I - H_i)^-1 (y_i - X_i m) (Woodbury): no refit needed.
    """
    Z = jax.scipy.linalg.solve_triangular(chol, X.T, lower=True)
    Zf, Zl = Z[:, :n], Z[:, n:]
    a, d, b = 1.0 - jnp.sum(Zf**2, 0), 1.0 - jnp.sum(Zl**2, 0), -jnp.sum(Zf * Zl, 0)
    r = y - X @ mean
    r1, r2 = r[:n], r[n:]
    det = a * d - b * b
    quad = (d * r1**2 - 2.0 * b * r1 * r2 + a * r2**2) / det
    return -0.5 * quad + 0.5 * jnp.log(det) - LOG_2PI


def _pointwise_loo(theta, Xf, Xl, F, L, c):
    """log p(force_i, piston_i | noise, all other readings), coefficients integrated out, (n,).

    PSIS-LOO over the noise draws with these (instead of the pointwise likelihood at drawn
    coefficients) importance-samples only the 5 noise parameters, which one reading hardly
    moves; the coefficients' leave-one-out is exact. Same ELPD, far smaller Pareto k.
    """

    X, y = _whiten(theta, Xf, Xl, F, L, c)
    post = _posterior(theta, Xf, Xl, F, L, c)
    L11, _, L22 = _cov_factors(theta, c)
    return _block_loo(X, y, F.size, post.chol, post.mean) - jnp.log(L11) - jnp.log(L22)


# ----------------------------------------------------------------------------- fit


def refuse_extrapolation(
    height_m, p_bar, height_range_m, pressure_range_bar, what: str, model: str
) -> None:
    """InputError naming the first height or overpressure outside the tested ranges: models of the
    stand's recordings answer only where it measured."""
    for values, (lo, hi), scale, unit, name, tested in (
        (height_m, height_range_m, 1e3, "mm", "height", "heights"),
        (p_bar, pressure_range_bar, 1.0, "bar", "overpressure", "pressures"),
    ):
        v = np.atleast_1d(np.asarray(values, float))
        out = (v < lo - 1e-9) | (v > hi + 1e-9)
        if np.any(out):
            raise InputError(
                f"{what}{name} {v[out][0] * scale:g} {unit} is outside the tested {tested} "
                f"{lo * scale:g}..{hi * scale:g} {unit}; {model} does not extrapolate"
            )


@dataclass(eq=False, frozen=True)
class SurfaceFit:
    """Posterior of the surface model. ``beta`` (C, D, k) standardised coefficients."""

    recordings: Recordings
    orders: Orders
    geometry: Geometry
    theta: np.ndarray  # (C, D, 5) sampler coordinates (logs)
    beta: np.ndarray  # (C, D, k)
    chains: Chains
    idata: az.InferenceData
    diagnostics: dict
    loglik: np.ndarray  # (C, D', n) pointwise, per (force, piston) reading
    map_theta: np.ndarray
    seconds: float = 0.0
    selection: tuple = ()
    stand: StandDescription = PAPER_STAND
    loglik_loo: np.ndarray | None = None  # (C, D', n) log p(reading_i | noise, other readings)

    # ---- ranges
    @property
    def pressure_range_bar(self):
        p = self.recordings.pressures_bar
        return float(p.min()), float(p.max())

    @property
    def height_range_m(self):
        return self.recordings.height_range_m

    def check_range(self, height_m, p_bar, what="") -> None:
        """Refuse heights/pressures outside the tested ranges (no extrapolation)."""
        refuse_extrapolation(
            height_m, p_bar, self.height_range_m, self.pressure_range_bar, what, "the surface model"
        )

    # ---- coefficient blocks (physical units, flattened draws)
    def flat_beta(self, max_draws: int | None = None) -> np.ndarray:
        b = self.beta.reshape(-1, self.beta.shape[-1])
        if max_draws and b.shape[0] > max_draws:
            b = b[:: int(np.ceil(b.shape[0] / max_draws))]
        return b

    def blocks(self, beta=None):
        beta = self.flat_beta() if beta is None else beta
        nc, ne, nd, nr = _sizes(self.orders, len(self.recordings.tests))
        c = beta[:, :nc] * SCALE_C
        e = beta[:, nc : nc + ne] * SCALE_E
        d = beta[:, nc + ne : nc + ne + nd] * SCALE_D
        r = beta[:, nc + ne + nd :] * SCALE_R
        return c, e, d, r

    # ---- surfaces at arbitrary points: draws (S, n)
    def _grid(self, height_m, p_bar, check):
        h, p = np.broadcast_arrays(np.asarray(height_m, float), np.asarray(p_bar, float))
        if check:
            self.check_range(h, p)
        g = self.geometry
        return h.shape, g.t(h.ravel()), g.q(p.ravel()), p.ravel()

    def pressure_area_draws(self, height_m, p_bar, *, check=True, beta=None):
        """Pressure area F_p(x, p_u) = (P - E) / p_u draws, m^2, shape (S, *broadcast shape)."""
        shape, t, q, _ = self._grid(height_m, p_bar, check)
        c = self.blocks(beta)[0]
        o = self.orders
        return (c @ _tq(t, q, o.K, o.Lp).T).reshape(-1, *shape)

    def feff_draws(self, height_m, p_bar, *, check=True, beta=None):
        """The paper's effective area F_eff = P / p_u (eq. 1) of the mean force, m^2."""
        p = np.broadcast_to(
            np.asarray(p_bar, float), np.broadcast(np.asarray(height_m), np.asarray(p_bar)).shape
        )
        return self.force_draws(height_m, p_bar, check=check, beta=beta) / (p * BAR_PA)

    def _casing(self, shape, t, beta):
        """E(x) draws on an evaluated grid (shape, t from ``_grid``), N."""
        return (self.blocks(beta)[1] @ _poly(t, self.orders.Ke).T).reshape(-1, *shape)

    def casing_draws(self, height_m, *, check=True, beta=None):
        shape, t, _, _ = self._grid(height_m, self.pressure_range_bar[0], check)
        return self._casing(shape, t, beta)

    def force_draws(self, height_m, p_bar, *, check=True, beta=None):
        """Force P(x, p_u) = p_u F_p + E draws (mean curve, no reading noise), N."""
        p = np.broadcast_to(
            np.asarray(p_bar, float), np.broadcast(np.asarray(height_m), np.asarray(p_bar)).shape
        )
        fe = self.pressure_area_draws(height_m, p_bar, check=check, beta=beta)
        shape, t, _, _ = self._grid(height_m, p_bar, False)
        E = self._casing(shape, t, beta)
        return p * BAR_PA * fe + E

    def volume_excess_draws(self, height_m, p_bar, *, check=True, beta=None):
        """D(x, p_u) = -dV/dx - F_p draws, m^2 (0 in the traditional theory)."""
        shape, t, q, _ = self._grid(height_m, p_bar, check)
        d = self.blocks(beta)[2]
        o = self.orders
        if o.Dk < 0:
            return np.zeros((self.blocks(beta)[0].shape[0], *shape))
        return (d @ _tq(t, q, o.Dk, o.Dl).T).reshape(-1, *shape)

    def spread_draws(self, height_m, p_bar, *, check=True, beta=None):
        """Traditional characteristic p_u (-dV/dx) minus the experimental force: p_u D - E, N."""
        p = np.broadcast_to(
            np.asarray(p_bar, float), np.broadcast(np.asarray(height_m), np.asarray(p_bar)).shape
        )
        D = self.volume_excess_draws(height_m, p_bar, check=check, beta=beta)
        shape, t, _, _ = self._grid(height_m, p_bar, False)
        E = self._casing(shape, t, beta)
        return p * BAR_PA * D - E

    def bands(self, height_m, p_bar, level: float = LEVEL) -> dict:
        """Pointwise 90 % bands of F_p, the paper's F_eff, force and spread (refuses extrapolation)."""
        out = {}
        for name, fn in (
            ("pressure_area_m2", self.pressure_area_draws),
            ("feff_m2", self.feff_draws),
            ("force_N", self.force_draws),
            ("spread_N", self.spread_draws),
        ):
            m, lo, hi = band(fn(height_m, p_bar), axis=0, level=level)
            out[name] = {"mean": m, "lower": lo, "upper": hi}
        return out

    # ---- LOO
    def loo(self):
        return psis_loo(self.loglik_loo)


def _arrays(rec: Recordings):
    tests = rec.tests
    x = np.concatenate([t.height_m for t in tests])
    p = np.concatenate([np.full(t.n_points, t.pressure_bar) for t in tests])
    F = np.concatenate([t.force_N for t in tests])
    L = np.concatenate([t.piston_m for t in tests])
    idx = np.concatenate([np.full(t.n_points, i) for i, t in enumerate(tests)])
    return x, p, F, L, idx


def geometry_of(rec: Recordings) -> Geometry:
    p = rec.pressures_bar
    mid, half = (p.max() + p.min()) / 2, max((p.max() - p.min()) / 2, 1e-3)
    return Geometry(rec.x0_m, rec.piston_area_m2, float(mid), float(half))


def _reference(o, g, x, p, F, L, idx, n_tests):
    """Weighted least squares start: reference force, F_p, volume increment per reading."""
    Xf, Xl = designs(o, g, x, p, idx, n_tests)
    wf = 1.0 / (0.005 * np.abs(F) + 20.0)
    wl = np.full_like(L, 1.0 / 1e-3)
    A = np.concatenate([Xf * wf[:, None], Xl * wl[:, None]])
    y = np.concatenate([F * wf, L * wl])
    beta, *_ = np.linalg.lstsq(A, y, rcond=None)
    phat = np.abs(Xf @ beta)
    nc = (o.K + 1) * (o.Lp + 1)
    feff = _tq(g.t(x), g.q(p), o.K, o.Lp) @ (beta[:nc] * SCALE_C)
    lhat = Xl @ beta
    dv = np.zeros_like(L)
    for i in range(n_tests):
        s = idx == i
        top = np.argmax(x[s])
        dv[s] = g.area_m2 * (lhat[s] - lhat[s][top])
    return beta, phat, np.abs(feff), np.maximum(dv, 0.0), Xf, Xl


def _consts(x, p, phat, feff, dv, area, stand: StandDescription):
    return {
        "phat": jnp.asarray(phat),
        "feff_hat": jnp.asarray(feff),
        "dv_hat": jnp.asarray(dv),
        "dp_pa": jnp.asarray(stand.pressure_sd_bar(p) * BAR_PA),
        "p_abs_pa": jnp.asarray((p + stand.p_atm_bar) * BAR_PA),
        "area": jnp.asarray(area),
        "prior_mean": jnp.asarray(noise_prior_mean(stand)),
    }


def fit_surface(
    rec: Recordings,
    orders: Orders = DEFAULT_ORDERS,
    *,
    seed: int = 0,
    settings: Settings = Settings(),
    max_draws: int = MAX_DRAWS,
    stand: StandDescription = PAPER_STAND,
) -> SurfaceFit:
    """optimistix MAP of the noise, emcee over it, exact coefficient draws, ArviZ diagnostics.

    ``stand`` is the stand the recordings were taken on: its pressure holding and p_atm enter
    the reading covariance, its load cell and gas volume centre the noise priors."""
    t0 = time.perf_counter()
    n_tests = len(rec.tests)
    if n_tests < orders.Lp + 1:
        raise InputError(
            f"{rec.path}: {n_tests} tests at different pressures cannot fix an effective area of "
            f"degree {orders.Lp} in pressure; the surface model needs at least {orders.Lp + 1}"
        )
    g = geometry_of(rec)
    x, p, F, L, idx = _arrays(rec)
    _, phat, feff, dv, Xf, Xl = _reference(orders, g, x, p, F, L, idx, n_tests)
    c = {**_consts(x, p, phat, feff, dv, g.area_m2, stand), "gram": gram_plan(gram_groups(Xf, Xl))}
    args = (jnp.asarray(Xf), jnp.asarray(Xl), jnp.asarray(F), jnp.asarray(L), c)
    theta0 = jnp.asarray(noise_prior_mean(stand))
    theta, result = _bfgs(theta0, *args)
    theta = np.asarray(theta)
    if not np.all(np.isfinite(theta)) or not np.isfinite(
        float(log_prob(jnp.asarray(theta)[None], *args)[0])
    ):
        theta = np.asarray(theta0)
    scale = np.full(5, 1.0 / np.sqrt(2.0 * x.size)) / settings.init_scale * 0.5

    def lp(th):
        return np.asarray(log_prob(np.asarray(th, float), *args))

    chains = thin(
        run_ensembles(
            lp, theta, scale, NOISE_NAMES, seed=seed, settings=settings, desc="surface sampling"
        ),
        max_draws,
    )
    C, D, _ = chains.samples.shape
    flat = jnp.asarray(chains.samples.reshape(C * D, 5))
    keys = row_keys(jax.random.PRNGKey(seed), C * D)
    beta = np.asarray(map_rows(_draw, (flat, keys), args)).reshape(C, D, -1)
    # pointwise log-likelihood for PSIS-LOO on at most ~2000 draws
    step = max(1, int(np.ceil(C * D / 2000)))
    th_s, b_s = chains.samples[:, ::step], beta[:, ::step]
    Cs, Ds = th_s.shape[:2]
    th_rows = jnp.asarray(th_s.reshape(Cs * Ds, 5))
    ll = np.asarray(
        map_rows(_pointwise, (th_rows, jnp.asarray(b_s.reshape(Cs * Ds, -1))), args)
    ).reshape(Cs, Ds, -1)
    ll_loo = np.asarray(map_rows(_pointwise_loo, (th_rows,), args)).reshape(Cs, Ds, -1)
    noise = _natural(chains.samples)
    posterior = {
        n: noise[..., i] for i, n in enumerate(("s0_N", "rel_load", "k_p", "sL_m", "V0_m3"))
    }
    idata = az.from_dict(
        posterior=posterior,
        sample_stats={"lp": chains.log_prob},
        attrs={"sampler": "emcee on the noise, coefficients drawn exactly", "orders": orders.label},
    )
    t_diag = time.perf_counter()
    diagnostics = convergence(idata, chains, list(posterior))
    diagnostics["seconds"] = time.perf_counter() - t_diag
    return SurfaceFit(
        rec,
        orders,
        g,
        chains.samples,
        beta,
        chains,
        idata,
        diagnostics,
        ll,
        theta,
        seconds=time.perf_counter() - t0,
        stand=stand,
        loglik_loo=ll_loo,
    )


def _natural(theta):
    return np.exp(np.asarray(theta))


def select_orders(
    rec: Recordings,
    candidates=CANDIDATES,
    *,
    seed: int = 0,
    settings: Settings | None = None,
    stand: StandDescription = PAPER_STAND,
):
    """Fit each candidate and rank by PSIS-LOO; returns (best fit, comparison rows)."""
    settings = settings or Settings()
    fits = {
        o.label: fit_surface(rec, o, seed=seed, settings=settings, stand=stand) for o in candidates
    }
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        cmp = az.compare({k: loglik_idata(f.loglik_loo) for k, f in fits.items()}, ic="loo")
    rows = [
        {
            "orders": k,
            "elpd_loo": float(r["elpd_loo"]),
            "p_loo": float(r["p_loo"]),
            "elpd_diff": float(r["elpd_diff"]),
            "dse": float(r["dse"]),
            "rank": int(r["rank"]),
            "warning": bool(r["warning"]),
        }
        for k, r in cmp.iterrows()
    ]
    return dataclasses.replace(fits[cmp.index[0]], selection=tuple(rows)), rows


#: a PSIS-LOO difference is called only beyond this many SEs of the difference (and ELPD_MIN)
SE_MULTIPLE = 2.0
#: differences below 4 ELPD are unreliable whatever their SE (Sivula, Magnusson, Vehtari 2020)
ELPD_MIN = 4.0
#: PSIS-LOO is unreliable for a reading whose Pareto k exceeds this (Vehtari et al. 2017/2024)
PARETO_K_MAX = 0.7


def _loo_part(loo, n_coefficients, loglik) -> dict:
    """Summary of one model's LOO; p_loo = lppd (at the drawn coefficients) - elpd_loo."""
    from scipy.special import logsumexp

    ll = np.asarray(loglik).reshape(-1, np.shape(loglik)[-1])
    lppd = float(np.sum(logsumexp(ll, axis=0) - np.log(ll.shape[0])))
    k = np.asarray(loo.pareto_k)
    return {
        "elpd_loo": float(loo.elpd_loo),
        "se": float(loo.se),
        "p_loo": lppd - float(loo.elpd_loo),
        "max_pareto_k": float(np.max(k)),
        "n_pareto_k_above_0.7": int(np.sum(k > PARETO_K_MAX)),
        "n_coefficients": int(n_coefficients),
    }


def loo_verdict(loo_a, loo_b, names=("surface", "per-pressure cubics")) -> dict:
    """Pointwise ELPD difference a - b with its SE, and which model the data prefer.

    "refused" when either LOO has a reading with Pareto k > 0.7 (the importance-sampling
    estimate of that reading's ELPD, hence the difference, is not reliable); "indistinguishable"
    unless |diff| > SE_MULTIPLE x SE and > ELPD_MIN; else the name of the better model.
    """
    diff = np.asarray(loo_a.loo_i) - np.asarray(loo_b.loo_i)
    n = diff.size
    d, se = float(diff.sum()), float(np.sqrt(n * np.var(diff, ddof=1)))
    k_bad = {
        nm: int(np.sum(np.asarray(lo.pareto_k) > PARETO_K_MAX))
        for nm, lo in zip(names, (loo_a, loo_b), strict=True)
    }
    if any(k_bad.values()):
        which = ", ".join(f"{nm}: {c}" for nm, c in k_bad.items() if c)
        verdict, why = (
            "refused",
            (
                f"PSIS-LOO not reliable: readings with Pareto k > {PARETO_K_MAX:g} ({which}); "
                "no verdict (K-fold cross-validation would be needed)"
            ),
        )
    elif abs(d) > SE_MULTIPLE * se and abs(d) > ELPD_MIN:
        verdict = names[0] if d > 0 else names[1]
        why = f"ELPD difference {d:.1f} +- {se:.1f} exceeds {SE_MULTIPLE:g} SE"
    else:
        verdict = "indistinguishable"
        why = f"ELPD difference {d:.1f} +- {se:.1f} is within {SE_MULTIPLE:g} SE (or below {ELPD_MIN:g})"
    return {
        "elpd_diff": d,
        "elpd_diff_se": se,
        "better": verdict,
        "reason": why,
        "rule": f"better only if |diff| > {SE_MULTIPLE:g} SE and > {ELPD_MIN:g}, and every Pareto k <= {PARETO_K_MAX:g}",
    }


def _concat_tests(parts):
    D = min(p.shape[1] for p in parts)
    C = min(p.shape[0] for p in parts)
    return np.concatenate([p[:C, :D] for p in parts], axis=-1)


def cubic_loglik(cubic_fit) -> np.ndarray:
    """Pointwise log-likelihood (C, D, n) of the per-pressure cubics, per (force, piston) reading."""
    parts = []
    for tf in cubic_fit.tests:
        ll = tf.pointwise_loglik(max_draws=2000)
        parts.append(ll["force"] + ll["piston"])
    return _concat_tests(parts)


@jax.jit
def _diag_loo(X, y, sigma, prior_sd):
    """log p(y_i | sigma, y_-i) of a linear-Gaussian model with diagonal noise, (S, n) for sigma (S, n)."""

    def one(sg):
        Xw, yw = X / sg[:, None], y / sg
        post = linear_posterior(Xw, yw, jnp.ones_like(yw), prior_sd)
        Z = jax.scipy.linalg.solve_triangular(post.chol, Xw.T, lower=True)
        m = 1.0 - jnp.sum(Z**2, 0)
        r = yw - Xw @ post.mean
        return -0.5 * r**2 / m + 0.5 * jnp.log(m) - 0.5 * LOG_2PI - jnp.log(sg)

    return jax.vmap(one)(sigma)


def cubic_loglik_loo(cubic_fit, max_draws: int = 2000) -> np.ndarray:
    """log p(force_i, piston_i | noise, the test's other readings) of the per-pressure cubics,
    coefficients integrated out exactly (as ``_pointwise_loo`` does for the surface), (C, D', n).
    The model is uq/_models/cubic.py's: basis, coefficient priors and noise formula imported from it."""
    from uq._models.cubic import FORCE_PRIOR_SD_N, PISTON_PRIOR_SD_M, basis

    parts = []
    for tf in cubic_fit.tests:
        C, D = tf.noise.shape[:2]
        step = max(1, int(np.ceil(C * D / max_draws)))
        nz = tf.noise[:, ::step].reshape(-1, 3)
        X = basis(tf.test.height_m - tf.x0_m)
        k = X.shape[1]
        sf = np.sqrt(nz[:, :1] ** 2 + (nz[:, 1:2] * tf.ref_force()[None, :]) ** 2)
        sl = np.broadcast_to(nz[:, 2:3], sf.shape)
        ll = np.asarray(
            _diag_loo(
                X, jnp.asarray(tf.test.force_N), jnp.asarray(sf), jnp.full(k, FORCE_PRIOR_SD_N)
            )
        ) + np.asarray(
            _diag_loo(
                X, jnp.asarray(tf.test.piston_m), jnp.asarray(sl), jnp.full(k, PISTON_PRIOR_SD_M)
            )
        )
        parts.append(ll.reshape(C, -1, ll.shape[-1]))
    return _concat_tests(parts)


@jax.jit
def _diag_predictive(X, y, sigma, prior_sd, x_new, y_new, s_new):
    """log p(y_new | sigma, y) for each noise draw: sigma (S, n), s_new (S,) -> (S,)."""

    def one(sg, sn):
        post = linear_posterior(X, y, sg, prior_sd)
        z = jax.scipy.linalg.solve_triangular(post.chol, x_new, lower=True)
        var = sn**2 + jnp.sum(z**2)
        return -0.5 * ((y_new - x_new @ post.mean) ** 2 / var + jnp.log(var) + LOG_2PI)

    return jax.vmap(one)(sigma, s_new)


#: at most this many exact refits for readings whose Pareto k stays > 0.7; more are refused
RELOO_MAX = 12


def _exact_cubic_loo(tf, i: int, seed: int, settings: Settings) -> float:
    """log p(force_i, piston_i | the test's other readings): the test refitted without reading i."""
    from dataclasses import replace

    from uq._models.cubic import FORCE_PRIOR_SD_N, PISTON_PRIOR_SD_M, _cubic_eval, basis, fit_test

    t = tf.test
    keep = np.arange(t.n_points) != i
    sub = replace(
        t,
        **{
            k: getattr(t, k)[keep]
            for k in ("height_m", "force_N", "piston_m", "compression", "step", "rows")
        },
    )
    refit = fit_test(sub, tf.x0_m, seed=seed, settings=settings)
    nz = refit.noise.reshape(-1, 3)[:: max(1, refit.noise[..., 0].size // 2000)]
    X, xi = basis(sub.height_m - tf.x0_m), basis(np.array([t.height_m[i] - tf.x0_m]))[0]
    ref_i = abs(float(_cubic_eval(refit.lsq_force, t.height_m[i] - tf.x0_m)))
    sf = np.sqrt(nz[:, :1] ** 2 + (nz[:, 1:2] * refit.ref_force()[None, :]) ** 2)
    sf_i = np.sqrt(nz[:, 0] ** 2 + (nz[:, 1] * ref_i) ** 2)
    k = X.shape[1]
    ll = np.asarray(
        _diag_predictive(
            X,
            jnp.asarray(sub.force_N),
            jnp.asarray(sf),
            jnp.full(k, FORCE_PRIOR_SD_N),
            xi,
            t.force_N[i],
            jnp.asarray(sf_i),
        )
    ) + np.asarray(
        _diag_predictive(
            X,
            jnp.asarray(sub.piston_m),
            jnp.asarray(np.broadcast_to(nz[:, 2:3], sf.shape)),
            jnp.full(k, PISTON_PRIOR_SD_M),
            xi,
            t.piston_m[i],
            jnp.asarray(nz[:, 2]),
        )
    )
    from scipy.special import logsumexp

    return float(logsumexp(ll) - np.log(ll.size))


class _ExactLoo:
    """PSIS-LOO with the readings of high Pareto k replaced by exact refits (k set to 0 there)."""

    def __init__(self, loo, replaced: dict):
        self.loo_i = np.asarray(loo.loo_i, float).copy()
        self.pareto_k = np.asarray(loo.pareto_k, float).copy()
        for j, v in replaced.items():
            self.loo_i[j], self.pareto_k[j] = v, 0.0
        n = self.loo_i.size
        self.elpd_loo, self.se = (
            float(self.loo_i.sum()),
            float(np.sqrt(n * np.var(self.loo_i, ddof=1))),
        )
        self.p_loo = float("nan")
        self.n_refits = len(replaced)


def _reloo_cubics(cubic_fit, loo, seed: int, settings: Settings):
    """Exact LOO for the cubic readings whose Pareto k > 0.7 (at most RELOO_MAX refits)."""
    bad = np.flatnonzero(np.asarray(loo.pareto_k) > PARETO_K_MAX)
    if bad.size == 0 or bad.size > RELOO_MAX:
        return loo
    offsets = np.cumsum([0] + [t.test.n_points for t in cubic_fit.tests])
    replaced = {}
    for j in bad:
        ti = int(np.searchsorted(offsets, j, side="right") - 1)
        replaced[int(j)] = _exact_cubic_loo(
            cubic_fit.tests[ti], int(j - offsets[ti]), seed + int(j), settings
        )
    return _ExactLoo(loo, replaced)


def compare_with_cubics(
    fit: SurfaceFit, cubic_fit, *, seed: int = 0, settings: Settings = Settings()
) -> dict:
    """PSIS-LOO of the surface model against the per-pressure cubics, per (force, piston) reading.

    Both models are linear in their coefficients given the noise, so each reading's leave-one-out
    predictive given the noise is exact (``_pointwise_loo``, ``cubic_loglik_loo``) and PSIS only
    reweights the noise draws: the Pareto k that made the plain PSIS-LOO refuse (k > 0.7 at drawn
    coefficients) stays low. Both are reported; the verdict uses the integrated one."""
    cub_ll, n_s, n_c = cubic_loglik(cubic_fit), fit.beta.shape[-1], 8 * len(cubic_fit.tests)
    loo_s, loo_c = psis_loo(fit.loglik_loo), psis_loo(cubic_loglik_loo(cubic_fit))
    plain_s, plain_c = psis_loo(fit.loglik), psis_loo(cub_ll)
    k_c = _loo_part(loo_c, n_c, cub_ll)  # Pareto k before the refits
    loo_c = _reloo_cubics(cubic_fit, loo_c, seed, settings)
    cubics = _loo_part(loo_c, n_c, cub_ll) | {
        "max_pareto_k_psis": k_c["max_pareto_k"],
        "n_exact_refits": getattr(loo_c, "n_refits", 0),
    }
    return {
        "surface": _loo_part(loo_s, n_s, fit.loglik),
        "cubics": cubics,
        **loo_verdict(loo_s, loo_c),
        "method": (
            "PSIS-LOO over the noise draws with the coefficients integrated out exactly per left-out reading; "
            f"cubic readings still at Pareto k > {PARETO_K_MAX:g} (up to {RELOO_MAX}) replaced by exact refits "
            "of their test without the reading"
        ),
        "plain_psis_loo": {
            "surface": _loo_part(plain_s, n_s, fit.loglik),
            "cubics": _loo_part(plain_c, n_c, cub_ll),
            **loo_verdict(plain_s, plain_c),
        },
        "unit": "log density per (force, piston) reading, summed over readings",
    }


# ----------------------------------------------------------------------------- summaries

DEFINITIONS = {
    "pressure_area_m2": "F_p = (P - E) / p_u: the area on which the pressure acts, the casing force E removed "
    "(the surface model's own quantity, not the paper's F_eff)",
    "feff_m2": "F_eff = P / p_u: the paper's effective area (eq. 1) of the model's mean force, casing force included",
    "casing_N": "E(x): the casing's own force, the same at every pressure",
    "volume_excess_m2": "D = -dV/dx - F_p: volume-derived area beyond the pressure area (0 in the traditional theory)",
    "spread_N": "p_u (-dV/dx) - P = p_u D - E: traditional minus measured force",
}


def coefficient_summary(fit: SurfaceFit) -> dict:
    c, e, d, r = fit.blocks()
    o = fit.orders
    out = {"pressure_area_m2": {}, "casing_N": {}, "volume_excess_m2": {}, "piston_reference_m": {}}
    for i, (k, lq) in enumerate((k, lq) for k in range(o.K + 1) for lq in range(o.Lp + 1)):
        out["pressure_area_m2"][f"c_{k}{lq}"] = estimate(c[:, i])
    for m in range(o.Ke + 1):
        out["casing_N"][f"e_{m}"] = estimate(e[:, m])
    if o.Dk >= 0:
        for i, (k, lq) in enumerate((k, lq) for k in range(o.Dk + 1) for lq in range(o.Dl + 1)):
            out["volume_excess_m2"][f"d_{k}{lq}"] = estimate(d[:, i])
    for i, t in enumerate(fit.recordings.tests):
        out["piston_reference_m"][f"{t.pressure_bar:g} bar"] = estimate(r[:, i])
    return out


def noise_summary(fit: SurfaceFit) -> dict:
    diag = fit.diagnostics["variables"]
    out = {}
    for n in ("s0_N", "rel_load", "k_p", "sL_m", "V0_m3"):
        est = estimate(np.asarray(fit.idata.posterior[n]))
        est["r_hat"] = diag[n]["r_hat"]
        est["ess_bulk"] = diag[n]["ess_bulk"]
        out[n] = est
    return out


def spread_region(fit: SurfaceFit, n_x: int = 46, n_p: int = 41, level: float = LEVEL) -> dict:
    """Grid of the spread's band over (x, p_u) and where it excludes zero."""
    lo, hi = fit.height_range_m
    plo, phi = fit.pressure_range_bar
    xs = np.linspace(lo, hi, n_x)
    ps = np.linspace(plo, phi, n_p)
    X, P = np.meshgrid(xs, ps, indexing="ij")
    beta = fit.flat_beta(2000)
    m, lo_b, hi_b = band(fit.spread_draws(X, P, beta=beta), axis=0, level=level)
    nonzero = (lo_b > 0) | (hi_b < 0)
    return {
        "height_m": xs,
        "pressure_bar": ps,
        "mean": m,
        "lower": lo_b,
        "upper": hi_b,
        "credibly_nonzero": nonzero,
    }


def summary(fit: SurfaceFit, comparison: dict | None = None) -> dict:
    g = fit.geometry
    reg = spread_region(fit, 19, 21)
    plo, phi = fit.pressure_range_bar
    ref = {}
    beta = fit.flat_beta(2000)
    for pb in sorted({plo, (plo + phi) / 2, phi}):
        ref[f"{pb:g}"] = {
            "pressure_area_m2": estimate(fit.pressure_area_draws(np.array(g.x0_m), pb, beta=beta)),
            "feff_m2": estimate(fit.feff_draws(np.array(g.x0_m), pb, beta=beta)),
            "force_N": estimate(fit.force_draws(np.array(g.x0_m), pb, beta=beta)),
            "spread_N": estimate(fit.spread_draws(np.array(g.x0_m), pb, beta=beta)),
        }
    return {
        "x0_m": g.x0_m,
        "piston_area_m2": g.area_m2,
        "orders": asdict(fit.orders),
        "orders_label": fit.orders.label,
        "pressure_scaling": {
            "q": "(p_bar - p_mid) / p_half",
            "p_mid_bar": g.p_mid,
            "p_half_bar": g.p_half,
        },
        "basis": "t = (x - x0) / 0.05 m; F_p = sum c_kl t^k q^l; E = sum e_m t^m; D = sum d_kl t^k q^l",
        "definitions": DEFINITIONS,
        "stand": asdict(fit.stand),
        "valid_range": {"height_m": list(fit.height_range_m), "pressure_bar": [plo, phi]},
        "coefficients": coefficient_summary(fit),
        "noise": noise_summary(fit),
        "at_x0": ref,
        "spread_credibly_nonzero_fraction": float(reg["credibly_nonzero"].mean()),
        "order_selection": list(fit.selection),
        "comparison": comparison,
        "converged": fit.diagnostics["converged"],
        "convergence": {
            k: v for k, v in fit.diagnostics.items() if k not in ("variables", "seconds")
        }
        | {
            "r_hat_max": max(np.max(v["r_hat"]) for v in fit.diagnostics["variables"].values()),
            "ess_bulk_min": min(
                np.min(v["ess_bulk"]) for v in fit.diagnostics["variables"].values()
            ),
        },
        "warnings": fit.diagnostics["warnings"],
    }


# ----------------------------------------------------------------------------- figures


def _plt():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def figure_pressure_area(fit: SurfaceFit, n_x: int = 46, n_p: int = 41):
    """Heat map of the posterior-mean pressure area F_p(x, p_u) with the 90 % band's relative width."""
    plt = _plt()
    lo, hi = fit.height_range_m
    plo, phi = fit.pressure_range_bar
    xs, ps = np.linspace(lo, hi, n_x), np.linspace(plo, phi, n_p)
    X, P = np.meshgrid(xs, ps, indexing="ij")
    m, lo_b, hi_b = band(fit.pressure_area_draws(X, P, beta=fit.flat_beta(2000)), axis=0)
    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    im = ax.pcolormesh(xs * 1e3, ps, (m * 1e4).T, shading="auto", cmap="viridis")
    cs = ax.contour(xs * 1e3, ps, (100 * (hi_b - lo_b) / np.abs(m)).T, colors="w", linewidths=0.8)
    ax.clabel(cs, fmt="%.2g %%", fontsize=7)
    fig.colorbar(im, ax=ax, label="F_p posterior mean, cm^2")
    ax.set_xlabel("height x, mm")
    ax.set_ylabel("overpressure p_u, bar")
    ax.set_title(
        "Pressure area F_p = (P - E)/p_u (casing force removed; not the paper's F_eff = P/p_u)\n"
        "(white contours: pointwise 90 % band width, % of F_p)",
        fontsize=8,
    )
    for t in fit.recordings.tests:
        ax.axhline(t.pressure_bar, color="k", lw=0.3, alpha=0.4)
    fig.tight_layout()
    return fig


def figure_spread(fit: SurfaceFit, n_x: int = 46, n_p: int = 41):
    """Heat map of the spread traditional - experimental, the credibly non-zero region outlined."""
    plt = _plt()
    reg = spread_region(fit, n_x, n_p)
    xs, ps = reg["height_m"] * 1e3, reg["pressure_bar"]
    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    vmax = float(np.max(np.abs(reg["mean"])))
    im = ax.pcolormesh(xs, ps, reg["mean"].T, shading="auto", cmap="RdBu_r", vmin=-vmax, vmax=vmax)
    if reg["credibly_nonzero"].any() and not reg["credibly_nonzero"].all():
        ax.contour(
            xs,
            ps,
            reg["credibly_nonzero"].T.astype(float),
            levels=[0.5],
            colors="k",
            linewidths=1.5,
        )
    fig.colorbar(im, ax=ax, label="p_u (-dV/dx) - P, N (posterior mean)")
    ax.set_xlabel("height x, mm")
    ax.set_ylabel("overpressure p_u, bar")
    share = 100 * reg["credibly_nonzero"].mean()
    ax.set_title(
        f"Traditional minus measured force\noutlined: 90 % band excludes 0 ({share:.0f} % of the range)",
        fontsize=9,
    )
    fig.tight_layout()
    return fig


def figure_overlay(fit: SurfaceFit, pressure_bar: float, ax=None):
    """One test's force readings with the surface model's 90 % band at that pressure."""
    plt = _plt()
    t = fit.recordings.test_at(pressure_bar)
    lo, hi = fit.height_range_m
    xs = np.linspace(lo, hi, 120)
    m, lo_b, hi_b = band(fit.force_draws(xs, pressure_bar, beta=fit.flat_beta(2000)), axis=0)
    fig = None
    if ax is None:
        fig, ax = plt.subplots(figsize=(6.0, 4.0))
    ax.fill_between(xs * 1e3, lo_b, hi_b, alpha=0.35, label="surface model 90 % band")
    ax.plot(xs * 1e3, m, lw=1)
    ax.plot(t.height_m * 1e3, t.force_N, "k.", ms=3, label="readings")
    ax.set_xlabel("height x, mm")
    ax.set_ylabel("force P, N")
    ax.set_title(f"{pressure_bar:g} bar")
    ax.legend(fontsize=7)
    return fig if fig is not None else ax.figure


# ----------------------------------------------------------------------------- CLI


def comparison_words(c: dict) -> str:
    """One line for a ``compare_with_cubics`` result."""
    if c["better"] in ("refused", "indistinguishable"):
        return f"{c['better']}: {c['reason']}"
    return (
        f"difference {c['elpd_diff']:.1f} +- {c['elpd_diff_se']:.1f} in favour of the {c['better']}"
    )
