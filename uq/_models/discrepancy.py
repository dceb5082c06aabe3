"""The surface with a discrepancy in pressure (Kennedy and O'Hagan): the smooth surface plus, per
tested pressure, a deviation of the test's cubic drawn from a Gaussian process in p_u.

Model (uq/_models/surface.py's notation: t = (x - x0) / h, h = 0.05 m, p_i in Pa where it
multiplies, lever -h/S):

    force_ij  = [surface force]_ij  + p_i sum_k delta_ik t^k + p_ref sum_k phi_ik t^k
    piston_ij = [surface piston]_ij - (h/S) sum_k (delta_ik + eps_ik) t^(k+1) / (k+1)

delta_i (m^2, k = 0..K) is a deviation of the pressure area F_p at test i, so it enters the volume
as F_p does; eps_i (m^2) a deviation of the volume-derived area alone, as the surface's D; phi_i
(m^2) a deviation of the force that is not proportional to p_u (a casing force that changes with
the pressure), as an area at p_ref, the highest tested overpressure (``p_ref_pa``). Over the tests
each coefficient is a Gaussian process in p_u (uq._models.discrepancy_gp): Cov(delta_ik, delta_jk)
= a_F^2 s_k^2 R(p_i, p_j; l), eps's with a_V, phi's with a_P, Matern 3/2 R, s_k = 1 (t^k is of
order one over the stroke).

Why two force blocks. A deviation whose force grows with p_u (a cord layer that engages) has an
area deviation of about one size at every pressure: delta's, with one amplitude. A deviation whose
force is about one size at every pressure (a wave in the casing's force) has an area deviation
growing as 1/p_u towards the low end: one amplitude for delta, learnt mostly from the high
pressures where the area deviation is small, is too small there, and the band between low tested
pressures misses (reports/between-coverage, n50-ripple at 1.75 bar, before phi). phi carries that
kind with its own amplitude; each amplitude's prior shrinks to zero, so a spring with one kind
gets the other's block near zero. Their sum is one Gaussian process with the non-stationary
force covariance R_ij (p_i p_j a_F^2 + p_ref^2 a_P^2).

Written with standardised normals z (delta_.k = a_F s_k chol(R) z_Fk, and so on), every
coefficient -- the surface's beta and z -- is N(0, 1) a priori and enters the readings linearly:
given theta = (the five noise logs of the pair likelihood, log a_F, log a_V, log a_P, log l) the
model is linear-Gaussian, one :class:`CollapsedModel` fitted by the one driver (emcee over theta,
exact coefficient draws). A campaign without piston readings has the force surface
(uq/_models/surface_force.py) with delta and phi: theta = (three noise logs, log a_F, log a_P,
log l).

Cost. At a fixed pressure the surface's force is a polynomial in t of degree m_t = max(K, Ke, Dk)
and its piston one of degree m_t + 1 with a constant, and so are the deviations: every mean of the
model lies, test by test, in the span of Z_i = [force: p_i t^k, k <= m_t | piston: t^k, k <= m_t + 1].
The readings enter through per-test moments H_i = Z_i^T Sigma_i^-1 Z_i, b_i = Z_i^T Sigma_i^-1 y_i
(per-test sums of the monomials of t times the pair likelihood's three weights, over each
test's readings padded to one length: ``padded_rows``), and the model's
coefficients map to each test's Z-coefficients by gamma_i = A_i beta + D_i v_i(theta) z, A_i
fixed (least squares from the surface's design rows at the test's heights, the residual checked
to be zero when the data are built), D_i the deviations' columns. The Gram matrix is then
sum_i C_i^T H_i C_i + I over the surface's and the deviations' coefficients (183 for data/n50):
the same matrix as the dense design's X^T W X, at a cost independent of the number of readings;
and by Woodbury's identity it is never factored: the one Cholesky factor per theta is of the
(T m x T m) matrix I + R P R^T (P = C C^T, H_i = R_i^T R_i), for the density, the exact draws
(Matheron's rule) and the leave-one-out densities alike (``span_posterior``; tested against the
dense design and against brute-force Gaussian integration in tests/models/test_discrepancy.py).
The fixed parts of that matrix are made once with the data (``span_products``: A A^T and, per
deviation block, D D^T), so a theta costs the readings' moments, two products of the block-diagonal
R with a (T m x T m) matrix and two Cholesky factorisations (``span_posterior``).
"""

from __future__ import annotations

import dataclasses
import math
from typing import NamedTuple

import numpy as np

from uq._data.recordings import Recordings
from uq._data.stand_description import PAPER_STAND, StandDescription
from uq._inference.collapsed import CollapsedModel, hold_out_by_weight
from uq._inference.float64 import jax, jnp
from uq._inference.linear import LOG_2PI, gaussian_loglik, posterior_from_moments
from uq._inference.sampler import INDEPENDENCE_MIX, Settings, min_walkers_for_independence
from uq._io.errors import InputError
from uq._models import discrepancy_gp as gp
from uq._models import pair, surface, surface_force, surface_likelihood
from uq._models.discrepancy_fit import BLOCK_INFO, BLOCKS, FORCE_BLOCKS, DiscrepancyFit, p_ref_pa
from uq._models.pair import NATURAL_NAMES, NOISE_NAMES, NOISE_PRIOR_SD
from uq._physics.quantities import BAR_PA, BASIS_SCALE_M

#: sampled: the force blocks' joint amplitude r = sqrt(a_F^2 + a_P^2) and phi's share
#: u = logit(2 atan2(a_P, a_F) / pi) (``force_amplitudes``), eps's amplitude, the length scale
GP_NAMES = ("log_a_force_m2", "logit_phi_share", "log_a_V_m2", "log_length_bar")
THETA_NAMES = NOISE_NAMES + GP_NAMES
FORCE_THETA_NAMES = surface_force.THETA_NAMES + tuple(GP_NAMES[i] for i in (0, 1, 3))
#: relative residual up to which the per-test span Z_i must reproduce the surface's design rows
SPAN_RTOL = 1e-9


class DevData(NamedTuple):
    """A campaign's arrays for the discrepancy surface with piston readings (n readings, T tests,
    m = 2 m_t + 3 Z-columns per test, k_s surface coefficients, n_k deviation coefficients).

    The reading fields are named as ``uq._models.pair.PairData``'s, so the pair likelihood's noise
    functions (``cov_factors``, ``readings``, ``log_prior``) take it as they are."""

    t: jnp.ndarray  # (n,) (x - x0) / h
    test: jnp.ndarray  # (n,) int, the reading's test
    F: jnp.ndarray  # (n,) force, N
    L: jnp.ndarray  # (n,) piston, m
    phat: jnp.ndarray
    feff_hat: jnp.ndarray
    dp_pa: jnp.ndarray
    p_abs_pa: jnp.ndarray
    area: jnp.ndarray
    prior_mean: jnp.ndarray  # (5,) the noise logs' prior centres
    weight: jnp.ndarray  # (n,) 1 fitted, 0 held out
    dp_meas: jnp.ndarray
    p_pa: jnp.ndarray  # (T,) tested overpressures, Pa
    p_bar: jnp.ndarray  # (T,) the same in bar (the process's coordinate)
    A: jnp.ndarray  # (T, m, k_s) surface coefficients -> Z-coefficients
    D: jnp.ndarray  # (T, m, 3 n_k) deviations (delta, eps, phi) -> Z-coefficients
    s: jnp.ndarray  # (n_k,) coefficient scales s_k
    rates: jnp.ndarray  # (3,) exponential prior rates of a_F, a_V, a_P (1/m^2)
    AAt: jnp.ndarray  # (T m, T m) A A^T: the surface's share of the span's prior covariance
    E: jnp.ndarray  # (3, T m, T m) per deviation block, D_i diag(s)^2 D_j^T (``span_products``)
    rows: jnp.ndarray  # (T, n_max) int, each test's readings, padded (``padded_rows``)
    powers: jnp.ndarray  # (T, n_max, 2 m_t + 3) t^k at those readings, 0 on the padding


class ForceDevData(NamedTuple):
    """The same for a campaign without piston readings (m = m_t + 1 force columns, delta and phi);
    the reading fields are named as ``uq._models.surface_force.ForceData``'s."""

    t: jnp.ndarray
    test: jnp.ndarray
    F: jnp.ndarray
    phat: jnp.ndarray
    feff_hat: jnp.ndarray
    dp_pa: jnp.ndarray
    dp_meas: jnp.ndarray
    prior_mean: jnp.ndarray  # (3,)
    weight: jnp.ndarray
    p_pa: jnp.ndarray
    p_bar: jnp.ndarray
    A: jnp.ndarray  # (T, m, k_s)
    D: jnp.ndarray  # (T, m, 2 n_k) (delta, phi)
    s: jnp.ndarray
    rates: jnp.ndarray  # (2,)
    AAt: jnp.ndarray  # (T m, T m)
    E: jnp.ndarray  # (2, T m, T m)
    rows: jnp.ndarray  # (T, n_max)
    powers: jnp.ndarray  # (T, n_max, 2 m_t + 1)


# ----------------------------------------------------------------------------- the span Z_i


def span_degree(orders: surface.Orders) -> int:
    """m_t: the degree in t of every force mean at a fixed pressure (the piston's is m_t + 1)."""
    return max(orders.K, orders.Ke, orders.Dk, deviation_degree(orders))


def deviation_degree(orders: surface.Orders) -> int:
    """The deviations' degree in t: the pressure area's K (capped, as K is, by the test with the
    fewest heights: ``uq._models.surface.orders_for``)."""
    return orders.K


def z_rows(t, p_pa, m_t: int, piston: bool):
    """Force rows (n, m) and piston rows (n, m) of Z at heights ``t`` of one test at ``p_pa``."""
    t = np.asarray(t, float)[:, None]
    nf = m_t + 1
    m = nf + (m_t + 2 if piston else 0)
    Zf = np.zeros((t.shape[0], m))
    Zf[:, :nf] = p_pa * t ** np.arange(nf)
    Zl = np.zeros_like(Zf)
    if piston:
        Zl[:, nf:] = t ** np.arange(m_t + 2)
    return Zf, Zl


def deviation_rows(t, p_pa, n_k: int, area_m2: float | None, p_ref_pa: float):
    """The deviation channels' force and piston rows at heights ``t`` of a test at ``p_pa``, block
    after block (``BLOCKS``: delta, eps, phi; without piston, ``area_m2`` None: ``FORCE_BLOCKS``),
    n_k channels each: delta's force p t^k and piston -(h/S) t^(k+1)/(k+1), eps's piston alone
    (the same rows), phi's force p_ref t^k alone. Returns (force (n, n_c), piston (n, n_c) or
    None)."""
    t = np.asarray(t, float)[:, None]
    k = np.arange(n_k)
    tk = t**k
    delta, phi = p_pa * tk, p_ref_pa * tk
    if area_m2 is None:
        return np.concatenate([delta, phi], axis=1), None
    integ = (-BASIS_SCALE_M / area_m2) * t ** (k + 1) / (k + 1)
    zero = np.zeros_like(delta)
    return np.concatenate([delta, zero, phi], axis=1), np.concatenate([integ, integ, zero], axis=1)


def span_map(Zf, Zl, Xf, Xl, what: str) -> np.ndarray:
    """The Z-coefficients (m, k) with Z gamma = X on the test's rows, by least squares; InputError-
    free ValueError when the span does not reproduce them (a programming error, not bad input)."""
    Z = np.concatenate([Zf, Zl]) if Zl is not None else Zf
    X = np.concatenate([Xf, Xl]) if Xl is not None else Xf
    sol, *_ = np.linalg.lstsq(Z, X, rcond=None)
    err = np.linalg.norm(Z @ sol - X) / max(np.linalg.norm(X), 1e-300)
    if err > SPAN_RTOL:
        raise ValueError(
            f"the per-test span does not reproduce the {what} (relative residual {err:.2e})"
        )
    return sol


def _tests(rec: Recordings):
    idx = np.concatenate([np.full(t.n_points, i) for i, t in enumerate(rec.tests)])
    p = np.array([t.pressure_bar for t in rec.tests], float)
    return idx, p


def _spans(rec: Recordings, orders: surface.Orders, Xf, Xl):
    """(t, test index, tested pressures, n_k, A, D): every test's span maps of the surface's force
    (and piston, ``Xl``; None: force only) design and of the deviations' rows, (T, m, k) lists."""
    g = surface.geometry_of(rec)
    x, _, _ = pair.force_arrays(rec)
    idx, p_bar = _tests(rec)
    t = g.t(x)
    m_t, n_k = span_degree(orders), deviation_degree(orders) + 1
    piston = Xl is not None
    A, D = [], []
    for i, pb in enumerate(p_bar):
        rows = idx == i
        Zf, Zl = z_rows(t[rows], pb * BAR_PA, m_t, piston)
        Zl, Xl_i = (Zl, Xl[rows]) if piston else (None, None)
        what = "surface's design" if piston else "force surface's design"
        A.append(span_map(Zf, Zl, Xf[rows], Xl_i, what))
        f, pl = deviation_rows(
            t[rows], pb * BAR_PA, n_k, g.area_m2 if piston else None, p_ref_pa(p_bar)
        )
        D.append(span_map(Zf, Zl, f, pl, "deviations' rows"))
    return t, idx, p_bar, n_k, A, D


def dev_data(
    rec: Recordings, orders: surface.Orders, stand: StandDescription = PAPER_STAND
) -> DevData:
    """The model's arrays for a campaign with piston readings."""
    base = surface_likelihood.surface_data(rec, orders, stand)
    return _dev_data(DevData, BLOCKS, rec, orders, base, base.Xf, base.Xl)


def force_dev_data(
    rec: Recordings, orders: surface.Orders, stand: StandDescription = PAPER_STAND
) -> ForceDevData:
    """The model's arrays for a campaign without piston readings (force-only, catalogue tables)."""
    base = surface_likelihood.surface_force_data(rec, orders, stand)
    return _dev_data(ForceDevData, FORCE_BLOCKS, rec, orders, base, base.X, None)


def _dev_data(cls, blocks, rec: Recordings, orders: surface.Orders, base, Xf, Xl):
    """``cls``'s arrays (one field per deviation block of ``blocks``): the readings' fields as the
    surface's data ``base`` has them, then the spans' maps, their products and the padded rows
    (the piston's rows, ``Xl``, take two more powers of t than the force's)."""
    t, idx, p_bar, n_k, A, D = _spans(
        rec, orders, np.asarray(Xf), None if Xl is None else np.asarray(Xl)
    )
    A, D = np.stack(A), np.stack(D)
    AAt, E = span_products(A, D, len(blocks))
    n_powers = 2 * span_degree(orders) + (1 if Xl is None else 3)
    rows, powers = padded_rows(t, idx, len(p_bar), n_powers)
    return cls(
        t=jnp.asarray(t),
        test=jnp.asarray(idx),
        **{f: getattr(base, f) for f in cls._fields if f in base._fields},
        p_pa=jnp.asarray(p_bar * BAR_PA),
        p_bar=jnp.asarray(p_bar),
        A=jnp.asarray(A),
        D=jnp.asarray(D),
        s=jnp.full(n_k, gp.COEFFICIENT_SCALE),
        rates=jnp.full(len(blocks), gp.amplitude_rate(reference_area(base.feff_hat))),
        AAt=AAt,
        E=E,
        rows=rows,
        powers=powers,
    )


def span_products(A, D, n_blocks: int):
    """(A A^T (T m, T m), E (blocks, T m, T m)): the fixed products the span's prior covariance is
    made of, rows and columns in (test, Z-column) order. E_b = D^b diag(s)^2 D^b^T over the n_k
    channels of block b (s_k = ``gp.COEFFICIENT_SCALE``), so that the deviations' share is
    R(l) (x) 1 times sum_b a_b^2 E_b: no product with D while sampling (``prior_span_cov``)."""
    T, m, n_c = D.shape
    flat = A.reshape(T * m, -1)
    Db = D.reshape(T * m, n_blocks, n_c // n_blocks) * gp.COEFFICIENT_SCALE
    return jnp.asarray(flat @ flat.T), jnp.asarray(np.einsum("xbk,ybk->bxy", Db, Db))


def padded_rows(t, idx, n_tests: int, n_powers: int):
    """(rows (T, n_max), powers (T, n_max, n_powers)): each test's reading indices padded to the
    longest test's count (padding points at reading 0) and t^k at them, 0 on the padding: the
    per-test moments are then one product over a reading axis per test (``pair_moments``) instead
    of a scatter-add over the readings."""
    t, idx = np.asarray(t, float), np.asarray(idx)
    n_max = int(np.bincount(idx, minlength=n_tests).max())
    rows = np.zeros((n_tests, n_max), int)
    live = np.zeros((n_tests, n_max))
    for i in range(n_tests):
        r = np.flatnonzero(idx == i)
        rows[i, : r.size], live[i, : r.size] = r, 1.0
    powers = t[rows][..., None] ** np.arange(n_powers) * live[..., None]
    return jnp.asarray(rows), jnp.asarray(powers)


def reference_area(feff_hat) -> float:
    """The campaign's reference area (m^2) that scales the amplitudes' prior: the median pressure
    area of the surface's least-squares fit over the readings."""
    return float(np.median(np.abs(np.asarray(feff_hat))))


# ----------------------------------------------------------------------------- the coefficient map


def has_piston(d) -> bool:
    return isinstance(d, DevData)


def force_amplitudes(log_r, u, xp=np):
    """(a_F, a_P) from the force blocks' joint amplitude log r and phi's share u: the polar
    coordinates r = |(a_F, a_P)|, angle pi/2 sigmoid(u). Sampled so because only a combination
    of the two is well known where the tests are (the force's deviation sd is
    sqrt(p^2 a_F^2 + p_ref^2 a_P^2)): in (log a_F, log a_P) the posterior is a curved ridge with
    an arm towards zero on either side, which the ensemble sampler crosses slowly; in (log r, u)
    r is well known and u is bounded by its prior where the data do not tell."""
    ang = 0.5 * np.pi / (1.0 + xp.exp(-u))
    r = xp.exp(log_r)
    return r * xp.cos(ang), r * xp.sin(ang)


def _n_noise(theta, d) -> int:
    return theta.shape[-1] - d.rates.shape[0] - 1


def _hyper(theta, d, xp):
    """(noise logs, amplitudes per deviation block in ``BLOCKS`` (or ``FORCE_BLOCKS``) order on the
    last axis, length) from theta = (noise logs, log r, u, [log a_V], log l) on its last axis."""
    k = _n_noise(theta, d)
    a_F, a_P = force_amplitudes(theta[..., k], theta[..., k + 1], xp)
    amps = [a_F, xp.exp(theta[..., k + 2]), a_P] if has_piston(d) else [a_F, a_P]
    return theta[..., :k], xp.stack(amps, axis=-1), xp.exp(theta[..., -1])


def _split(theta, d):
    """(noise, amplitudes, length) of one theta (JAX)."""
    return _hyper(theta, d, jnp)


def hyper_draws(theta, d) -> tuple[np.ndarray, np.ndarray]:
    """The amplitudes (S, blocks; ``BLOCKS`` order) and length scales (S,) of theta draws (S, k),
    numpy."""
    return _hyper(np.asarray(theta, float), d, np)[1:]


def theta_of(noise, amplitudes, length_bar) -> np.ndarray:
    """theta from the noise logs, the amplitudes in ``BLOCKS`` (or ``FORCE_BLOCKS``) order and the
    length scale: the inverse of ``hyper_draws`` for one draw."""
    amplitudes = [float(a) for a in amplitudes]
    a_F, a_P = amplitudes[0], amplitudes[-1]
    u = np.log(2.0 / np.pi * np.arctan2(a_P, a_F)) - np.log1p(-2.0 / np.pi * np.arctan2(a_P, a_F))
    gp_part = [0.5 * np.log(a_F**2 + a_P**2), u, *np.log(amplitudes[1:-1]), np.log(length_bar)]
    return np.concatenate([np.asarray(noise, float), gp_part])


def channel_scales(amplitudes, d):
    """a s_k for every deviation channel (block after block, n_k each), (n_c,)."""
    return jnp.concatenate([a * d.s for a in amplitudes])


def coefficient_map(theta, d):
    """C (T, m, K): every test's Z-coefficients from the model's standardised coefficients
    (beta: the surface's k_s, then z: channel-major, n_c x T)."""
    Lr, g = deviation_map(theta, d)
    T, m, _ = d.D.shape
    Cz = jnp.einsum("imc,c,ij->imcj", d.D, g, Lr).reshape(T, m, -1)
    return jnp.concatenate([d.A, Cz], axis=-1)


def deviation_map(theta, d):
    """chol(R(l)) (T, T) and the channels' scales a s_k (n_c,): the deviations' part of C, the
    first argument of ``map_coefficients`` and ``map_transpose`` (made once a draw)."""
    _, amps, length = _split(theta, d)
    return jnp.linalg.cholesky(gp.correlation(d.p_bar, length, jnp)), channel_scales(amps, d)


def map_coefficients(dev_map, beta, d):
    """C beta (T, m) without forming C (``coefficient_map``: T m K numbers a draw, more memory
    traffic than the rest of a draw): A beta_s plus, per test i, D_i (g * (chol(R) Z^T)_i), Z the
    deviations' standard normals (n_c, T); ``dev_map``: ``deviation_map`` of the draw's theta."""
    Lr, g = dev_map
    T, _, n_c = d.D.shape
    ks = d.A.shape[2]
    Y = Lr @ beta[ks:].reshape(n_c, T).T  # (T, n_c)
    return jnp.einsum("iak,k->ia", d.A, beta[:ks]) + jnp.einsum("iac,ic->ia", d.D, Y * g)


def map_transpose(dev_map, v, d):
    """C^T v (K,) for v (T, m), without forming C (``map_coefficients``' transpose)."""
    Lr, g = dev_map
    W = jnp.einsum("iac,ia->ic", d.D, v)  # (T, n_c)
    z = g[:, None] * (W.T @ Lr)  # (n_c, T), channel-major as beta's z
    return jnp.concatenate([jnp.einsum("iak,ia->k", d.A, v), z.reshape(-1)])


def n_coefficients(d) -> int:
    return d.A.shape[2] + d.D.shape[2] * d.D.shape[0]


# ----------------------------------------------------------------------------- moments


def _per_test(weights, d):
    """sum over each test's readings of ``weights`` (n, k) times t^j: (k, T, 2 m_t + 3) (or + 1),
    one product per test over its padded readings (``padded_rows``)."""
    return jnp.einsum("tnk,tnp->ktp", weights[d.rows], d.powers)


def pair_moments(noise, d: DevData):
    """(H (T, m, m), b (T, m), y'Wy, 2 n, log det Sigma) of the pair likelihood in Z-space."""
    L11, L21, L22 = pair.cov_factors(noise, d)
    F, L = pair.readings(noise, d)
    w = d.weight
    s = L21 / (L11 * L22)
    yf = F / L11
    yl = (L - L21 * yf) / L22
    m = d.A.shape[1]
    nf = (m - 1) // 2  # m_t + 1 force columns, m_t + 2 piston columns
    weights = jnp.stack(
        [
            w * (1.0 / L11**2 + s**2),
            w / L22**2,
            -w * s / L22,
            w * (yf / L11 - s * yl),  # vf
            w * yl / L22,  # vl
        ],
        axis=1,
    )
    M1, M2, M3, Bf, Bl = _per_test(weights, d)
    a, b = np.arange(nf), np.arange(nf + 1)
    pp = d.p_pa[:, None, None]
    Hff = M1[:, a[:, None] + a[None, :]] * pp**2
    Hll = M2[:, b[:, None] + b[None, :]]
    Hfl = M3[:, a[:, None] + b[None, :]] * pp
    H = jnp.concatenate(
        [
            jnp.concatenate([Hff, Hfl], axis=2),
            jnp.concatenate([jnp.swapaxes(Hfl, 1, 2), Hll], axis=2),
        ],
        axis=1,
    )
    bvec = jnp.concatenate([Bf[:, :nf] * d.p_pa[:, None], Bl[:, : nf + 1]], axis=1)
    yy = jnp.sum(w * (yf**2 + yl**2))
    log_det = 2.0 * jnp.sum(w * (jnp.log(L11) + jnp.log(L22)))
    return H, bvec, yy, 2 * jnp.sum(w), log_det


def force_moments(noise, d: ForceDevData):
    """The same for the force alone (independent readings, the force surface's noise)."""
    sigma, y = surface_force.sigma_y(noise, d)
    w = d.weight / sigma**2
    nf = d.A.shape[1]
    M, B = _per_test(jnp.stack([w, w * y], axis=1), d)
    a = np.arange(nf)
    H = M[:, a[:, None] + a[None, :]] * d.p_pa[:, None, None] ** 2
    bvec = B[:, :nf] * d.p_pa[:, None]
    return H, bvec, jnp.sum(w * y**2), jnp.sum(d.weight), jnp.sum(d.weight * jnp.log(sigma**2))


def moments(noise, d):
    return pair_moments(noise, d) if has_piston(d) else force_moments(noise, d)


def prior_span_cov(theta, d):
    """P (T m, T m), rows and columns in (test, Z-column) order: the prior covariance of the tests'
    Z-coefficients, C C^T: the surface's part A A^T (fixed, ``AAt``) plus the deviations'
    R_ij D_i diag(a s)^2 D_j^T = R_ij sum_b a_b^2 E_b,ij (``E`` fixed, ``span_products``)."""
    _, amps, length = _split(theta, d)
    T, m = d.A.shape[:2]
    R = gp.correlation(d.p_bar, length, jnp)
    dev = jnp.einsum("b,bxy->xy", amps**2, d.E).reshape(T, m, T, m)
    return d.AAt + (R[:, None, :, None] * dev).reshape(T * m, T * m)


def _apply_blocks(Rt, X):
    """R X for R = blockdiag(Rt_i^T) and X (T m, k): each test's m rows times Rt_i^T."""
    T, m = Rt.shape[:2]
    return jnp.einsum("iba,ibk->iak", Rt, X.reshape(T, m, -1)).reshape(T * m, -1)


class SpanPosterior(NamedTuple):
    """The posterior given theta, in the tests' Z-space (``span_posterior``)."""

    Rt: jnp.ndarray  # (T, m, m) lower Cholesky factors of H_i (R_i = Rt_i^T)
    u: jnp.ndarray  # (T, m) R^-T b
    P: jnp.ndarray  # (T m, T m) prior covariance of the Z-coefficients (``prior_span_cov``)
    Lm: jnp.ndarray  # (T m, T m) lower Cholesky factor of M = I + R P R^T
    log_marginal: jnp.ndarray  # () log p(readings | theta)


def _bordered_cholesky(S, v, c):
    """The Cholesky factor of [[S, v], [v^T, c]] (batched over leading axes): its leading block is
    chol(S), its last row's leading part (chol(S)^-1 v)^T, so one factorisation gives both (no
    triangular solve); ``c`` only has to keep the matrix positive definite."""
    top = jnp.concatenate([S, v[..., :, None]], axis=-1)
    bottom = jnp.concatenate([v, c[..., None]], axis=-1)[..., None, :]
    L = jnp.linalg.cholesky(jnp.concatenate([top, bottom], axis=-2))
    return L[..., :-1, :-1], L[..., -1, :-1]


def span_posterior(theta, d) -> SpanPosterior:
    """The coefficients' posterior given theta, in the tests' Z-space.

    With H_i = R_i^T R_i (Cholesky) and B = R C: det(I + C^T H C) = det(I + B B^T) and
    b^T C (I + C^T H C)^-1 C^T b = |u|^2 - u^T (I + B B^T)^-1 u, u = R^-T b, so the one Cholesky
    factor is of the (T m x T m) matrix M = I + R P R^T (99 for data/n50), P = C C^T, not of the
    (K x K) Gram (183). Needs every H_i positive definite, which the fit's check of the heights per
    test ensures.

    The cost per theta: P from fixed products (``span_products``: no product with the deviations'
    maps), R P R^T as two products of the block-diagonal R with a (T m x T m) matrix (R P, then
    R (R P)^T, P being symmetric), and two Cholesky factorisations of bordered matrices: of each
    [[H_i, b_i], [b_i^T, c]] (R_i and u_i at once) and of [[M, u], [u^T, c']] (chol(M) and
    chol(M)^-1 u at once), with c = 2 y'Wy + 1 >= 2 |u_i|^2 + 1 and c' = 2 |u|^2 + 1 > u^T M^-1 u
    (M >= I), so both are positive definite whenever H_i is."""
    noise, _, _ = _split(theta, d)
    H, bvec, yy, n, log_det = moments(noise, d)
    T, m = bvec.shape
    Rt, u = _bordered_cholesky(H, bvec, jnp.full(T, 2.0 * yy + 1.0))
    P = prior_span_cov(theta, d)
    RP = _apply_blocks(Rt, P)
    RPR = _apply_blocks(Rt, RP.T)
    uu = jnp.sum(u**2)
    Lm, v = _bordered_cholesky(jnp.eye(T * m) + RPR, u.reshape(-1), 2.0 * uu + 1.0)
    quad = yy - (uu - jnp.sum(v**2))
    logdet = 2.0 * jnp.sum(jnp.log(jnp.diag(Lm)))
    return SpanPosterior(Rt, u, P, Lm, -0.5 * (quad + log_det + logdet + n * LOG_2PI))


def log_marginal(theta, d):
    """log p(readings | theta), every coefficient integrated out (``span_posterior``)."""
    return span_posterior(theta, d).log_marginal


def posterior(theta, d):
    """The (K x K) Gaussian posterior of the coefficients given theta from the Gram matrix
    sum_i C_i^T H_i C_i + I (uq._inference.linear.LinearPosterior): the direct route, which the
    tests hold ``span_posterior`` to; the fit never forms it."""
    noise, _, _ = _split(theta, d)
    H, bvec, yy, n, log_det = moments(noise, d)
    C = coefficient_map(theta, d)
    gram = jnp.einsum("iak,ial->kl", C, jnp.einsum("iab,ibl->ial", H, C))
    rhs = jnp.einsum("iak,ia->k", C, bvec)
    return posterior_from_moments(gram, rhs, yy, n, log_det, jnp.ones(C.shape[2]))


def _apply_Rt(Rt, x):
    """R^T x per test, (T, m): Rt_i x_i."""
    return jnp.einsum("iab,ib->ia", Rt, x)


def draw_from_normals(theta, e, d):
    """An exact posterior draw of the coefficients from standard normals ``e`` (K + T m,) by
    conditioning a prior draw (Matheron's rule): beta = beta0 + B^T M^-1 (u - B beta0 - xi) with
    beta0 = e[:K], xi = e[K:], B = R C; its mean is B^T M^-1 u = (I + C^T H C)^-1 C^T b and its
    covariance I - B^T M^-1 B = (I + C^T H C)^-1. e = 0 gives the posterior mean."""
    post = span_posterior(theta, d)
    T, m = post.u.shape
    K = n_coefficients(d)
    beta0, xi = e[:K], e[K:].reshape(T, m)
    dev_map = deviation_map(theta, d)
    Bb = jnp.einsum("iba,ib->ia", post.Rt, map_coefficients(dev_map, beta0, d))  # R C beta0
    w = jax.scipy.linalg.cho_solve((post.Lm, True), (post.u - Bb - xi).reshape(-1))
    return beta0 + map_transpose(dev_map, _apply_Rt(post.Rt, w.reshape(T, m)), d)


def draw_linear(theta, key, d):
    T, m = d.A.shape[:2]
    return draw_from_normals(theta, jax.random.normal(key, (n_coefficients(d) + T * m,)), d)


def span_moments(theta, d):
    """The posterior mean of every test's Z-coefficients (T, m) and the diagonal blocks G_i (T, m, m)
    of their posterior covariance: C m = P R^T M^-1 u and P - P R^T M^-1 R P (Woodbury)."""
    post = span_posterior(theta, d)
    T, m = post.u.shape
    w = jax.scipy.linalg.cho_solve((post.Lm, True), post.u.reshape(-1)).reshape(T, m)
    mean = (post.P @ _apply_Rt(post.Rt, w).reshape(-1)).reshape(T, m)
    RP = _apply_blocks(post.Rt, post.P)
    Q = jax.scipy.linalg.solve_triangular(post.Lm, RP, lower=True).reshape(T * m, T, m)
    Pd = post.P.reshape(T, m, T, m)
    G = jnp.einsum("iaib->iab", Pd) - jnp.einsum("kia,kib->iab", Q, Q)
    return mean, G


# ----------------------------------------------------------------------------- the model's functions


def log_prior(theta, d):
    """The noise logs' normal priors, a_F, a_P and a_V independent exponentials (the first two
    written in (log r, u): log of their densities plus the Jacobian
    |d(a_F, a_P) / d(log r, u)| = r^2 (pi / 2) sigmoid(u) (1 - sigmoid(u))), the length scale's
    PC prior."""
    k = _n_noise(theta, d)
    noise = theta[:k]
    lp = -0.5 * jnp.sum(((noise - d.prior_mean) / NOISE_PRIOR_SD[:k]) ** 2)
    log_r, u = theta[k], theta[k + 1]
    a_F, a_P = force_amplitudes(log_r, u, jnp)
    rate = d.rates[0]
    lp = lp + 2.0 * jnp.log(rate) - rate * (a_F + a_P)
    lp = lp + 2.0 * log_r + np.log(np.pi / 2) - jax.nn.softplus(-u) - jax.nn.softplus(u)
    if has_piston(d):
        lp = lp + gp.log_prior_amplitude(theta[k + 2], d.rates[1], jnp)
    return lp + gp.log_prior_length(theta[-1], jnp)


def log_prob(theta, d):
    """log p(theta | readings), every coefficient integrated out; theta (9,) or (6,)."""
    return log_prior(theta, d) + log_marginal(theta, d)


def z_means(theta, beta, d):
    """Every test's Z-coefficients at one draw, (T, m)."""
    return map_coefficients(deviation_map(theta, d), beta, d)


def _rows(d):
    """Each reading's force and piston rows of Z, (n, m) each (traced: built from t)."""
    m = d.A.shape[1]
    pp = d.p_pa[d.test][:, None]
    if not has_piston(d):
        return d.t[:, None] ** jnp.arange(m) * pp, None
    nf = (m - 1) // 2
    P = d.t[:, None] ** jnp.arange(nf + 1)
    zf = jnp.concatenate([P[:, :nf] * pp, jnp.zeros((d.t.shape[0], nf + 1))], axis=1)
    zl = jnp.concatenate([jnp.zeros((d.t.shape[0], nf)), P], axis=1)
    return zf, zl


def mean_readings(theta, beta, d):
    """The model's mean force (and piston) at every reading, (n,) each."""
    gam = z_means(theta, beta, d)[d.test]
    zf, zl = _rows(d)
    return jnp.sum(zf * gam, 1), (None if zl is None else jnp.sum(zl * gam, 1))


def pointwise(theta, beta, d):
    noise, _, _ = _split(theta, d)
    f, lp = mean_readings(theta, beta, d)
    if not has_piston(d):
        sigma, y = surface_force.sigma_y(noise, d)
        return {"force": gaussian_loglik(y, f, sigma)}
    L11, L21, L22 = pair.cov_factors(noise, d)
    F, L = pair.readings(noise, d)
    r1 = (F - f) / L11
    r2 = (L - lp - L21 * r1) / L22
    return {"reading": -0.5 * (r1**2 + r2**2) - jnp.log(L11) - jnp.log(L22) - LOG_2PI}


def pointwise_loo(theta, d):
    """log p(reading_i | theta, the other readings), every coefficient integrated out exactly (n,):
    the leverages come from the posterior covariance's per-test blocks G_i (``span_moments``), not
    from the (2n x K) design. The quadratic forms are taken test by test over each test's padded
    readings (``padded_rows``) and summed back to the readings, instead of through a copy of G_i
    for every reading (n m^2 numbers a draw: memory traffic that cost more than the forms)."""
    noise, _, _ = _split(theta, d)
    gam, G = span_moments(theta, d)
    zf, zl = _rows(d)
    live = d.powers[..., 0]  # (T, n_max): 1 at a reading, 0 on the padding

    def forms(u, v):  # u_i^T G v_i per reading (u, v (n, m)); v None: u_i^T gam
        U = u[d.rows]  # (T, n_max, m)
        W = gam[:, None, :] if v is None else jnp.einsum("tab,tnb->tna", G, v[d.rows])
        return jnp.zeros(u.shape[0]).at[d.rows].add(jnp.sum(U * W, -1) * live)

    if not has_piston(d):
        sigma, y = surface_force.sigma_y(noise, d)
        uf = zf / sigma[:, None]
        lev = 1.0 - forms(uf, uf)
        r = y / sigma - forms(uf, None)
        return -0.5 * r**2 / lev + 0.5 * jnp.log(lev) - 0.5 * LOG_2PI - jnp.log(sigma)
    L11, L21, L22 = pair.cov_factors(noise, d)
    F, L = pair.readings(noise, d)
    yf = F / L11
    yl = (L - L21 * yf) / L22
    uf = zf / L11[:, None]
    ul = (zl - L21[:, None] * uf) / L22[:, None]
    a = 1.0 - forms(uf, uf)
    e = 1.0 - forms(ul, ul)
    b = -forms(uf, ul)
    r1 = yf - forms(uf, None)
    r2 = yl - forms(ul, None)
    return pair.block_logpdf(a, e, b, r1, r2) - jnp.log(L11) - jnp.log(L22)


def predict(theta, beta, key, d):
    """A replicate of every reading: the mean plus the reading noise (as the surface's)."""
    noise, _, _ = _split(theta, d)
    f, lp = mean_readings(theta, beta, d)
    if not has_piston(d):
        sigma, y = surface_force.sigma_y(noise, d)
        return {"force_N": f + (d.F - y) + sigma * jax.random.normal(key, d.F.shape)}
    L11, L21, L22 = pair.cov_factors(noise, d)
    z = jax.random.normal(key, (2, d.F.shape[0]))
    F, L = pair.readings(noise, d)
    return {
        "force_N": f + (d.F - F) + L11 * z[0],
        "piston_m": lp + (d.L - L) + L21 * z[0] + L22 * z[1],
    }


def observed(d) -> dict:
    out = {"force_N": np.asarray(d.F)}
    if has_piston(d):
        out["piston_m"] = np.asarray(d.L)
    return out


def start(d) -> np.ndarray:
    """Two starts: the prior centres (every amplitude at its prior mean, the length scale at its
    median), and the amplitudes 20 times smaller (near the smooth surface)."""
    rates = np.asarray(d.rates, float)
    _, l0 = gp.prior_start(float(rates[0]))
    noise = np.asarray(d.prior_mean)
    return np.stack([theta_of(noise, 1.0 / rates / f, np.exp(l0)) for f in (1.0, 20.0)])


def report(theta, beta, d) -> dict:
    theta = np.asarray(theta)
    k = _n_noise(theta, d)
    noise = NATURAL_NAMES if has_piston(d) else surface_force.NATURAL
    out = {n: np.exp(theta[:, i]) for i, n in enumerate(noise[:k])}
    amps, length = hyper_draws(theta, d)
    names = [BLOCK_INFO[b][1] for b in (BLOCKS if has_piston(d) else FORCE_BLOCKS)]
    out.update({n: amps[:, j] for j, n in enumerate(names)})
    out["length_bar"] = length
    return out


MODEL = CollapsedModel.of(
    globals(), "surface with a discrepancy in pressure", THETA_NAMES, hold_out=hold_out_by_weight
)

FORCE_MODEL = MODEL._replace(
    name="force surface with a discrepancy in pressure", theta_names=FORCE_THETA_NAMES
)


def collapsed_model(data) -> CollapsedModel:
    """The likelihood whose data ``data`` is (a fit's ``posterior.data``), for refits and
    replicates (``LinearFit.collapsed``): the force-only one without piston readings."""
    return MODEL if has_piston(data) else FORCE_MODEL


# ----------------------------------------------------------------------------- fit


def min_heights_needed(orders: surface.Orders, piston: bool) -> int:
    """Distinct heights a test needs for its per-test moments H_i to be positive definite: the
    force's m_t + 1 coefficients at a pressure, the piston's m_t + 2."""
    return span_degree(orders) + (2 if piston else 1)


#: how the sampler's independence move fits its proposal (``uq._inference.sampler.PROPOSALS``):
#: to each ensemble's own draws during the burn-in, then held fixed (``_HeldIndependence``)
PROPOSAL = "held"
#: the sampler's moves (weights of DE, DE-snooker, independence)
MIX = INDEPENDENCE_MIX
#: theta is first importance-sampled from the MAP (``uq._inference.importance``: PSIS-checked,
#: emcee when the checks refuse it). Measured on data/n50 (2026-11-28, 12 seeds, idle machine):
#: Pareto k-hat 0.33-0.57, every sampled parameter's ESS at least 883, about 3 CPU s against
#: 29-33 for emcee; the trial behind it: docs/speed.md
IMPORTANCE = True
#: walkers per ensemble and sampled parameter (``walkers_for``)
WALKERS_PER_PARAMETER = 5


def walkers_for(settings, ndim: int):
    """``settings`` with at least ``WALKERS_PER_PARAMETER`` walkers per sampled parameter in each
    ensemble (48 for the nine of the full model, 32 for the force-only six), and at least what the
    sampler's independence move needs (uq._inference.sampler.min_walkers_for_independence).

    The sampler's held proposal (``PROPOSAL``) is fitted during the burn-in to each ensemble's own
    draws, a few thousand, so it does not need many walkers; only its first 100 steps use the
    Student t fitted to the other half of the ensemble. Measured on data/n50 (seed 20201, an
    earlier form of the proposal: 10 degrees of freedom, no burn-in floor): 92 walkers, 463
    steps and 44 CPU s; 48 walkers, 513 steps and 26 CPU s. With the half-ensemble proposal of
    every step (the sampler's default), which the nine parameters' skewed posterior (the force
    floor, the length scale) makes rough with few walkers, 92 walkers were needed: 1524 steps and
    about 120 CPU s (36 walkers of eight parameters, acceptance 0.137, below the sampler's rule,
    0.15). (With the default 32 the independence move is switched off altogether.)"""
    need = max(min_walkers_for_independence(ndim), WALKERS_PER_PARAMETER * ndim)
    need = 4 * math.ceil(need / 4)
    return settings if settings.n_walkers >= need else dataclasses.replace(settings, n_walkers=need)


def fit_discrepancy(
    rec: Recordings,
    orders: surface.Orders | None = None,
    *,
    seed: int = 0,
    settings=None,
    max_draws: int = 4000,
    stand: StandDescription = PAPER_STAND,
):
    """The surface with a discrepancy in pressure fitted to a campaign: the one driver (MAP of theta,
    emcee over it, exact coefficient draws, ArviZ data and the convergence verdict); returns a
    :class:`uq._models.discrepancy_fit.DiscrepancyFit`.

    ``orders``: the surface's (default :func:`uq._models.surface.orders_for` the campaign); a
    campaign without piston readings gets the force surface and the force's deviations (delta, phi).
    Needs two tests or more (one test has nothing between tested pressures) and, per test, the
    distinct heights that fix the test's cubic (``min_heights_needed``). Ensembles get at least the
    walkers the sampler's independence move needs (``walkers_for``)."""
    orders = surface.orders_for(rec) if orders is None else orders
    n_tests = len(rec.tests)
    if n_tests < max(2, orders.Lp + 1):
        raise InputError(
            f"{rec.path}: {n_tests} test(s) at different pressures; the surface with a discrepancy in "
            f"pressure needs at least {max(2, orders.Lp + 1)} ({orders.label})"
        )
    piston = rec.has_piston
    if not piston and (orders.Dk >= 0 or orders.Dl >= 0):
        raise InputError(
            f"orders: {rec.path} has no piston readings; the force surface takes no volume block "
            f"(Dk = Dl = -1), got {orders.label}",
            param="orders",
        )
    need = min_heights_needed(orders, piston)
    for t in rec.tests:
        have = np.unique(np.round(t.height_m, 9)).size
        if have < need:
            raise InputError(
                f"{rec.path}: the {t.pressure_bar:g}-bar test has {have} distinct heights; the "
                f"surface with a discrepancy in pressure ({orders.label}) needs {need} per test"
            )
    data = dev_data(rec, orders, stand) if piston else force_dev_data(rec, orders, stand)
    model = MODEL if piston else FORCE_MODEL
    return pair.fit_over_tests(
        DiscrepancyFit,
        model,
        data,
        rec,
        orders,
        surface.geometry_of(rec),
        seed=seed,
        settings=settings,
        max_draws=max_draws,
        stand=stand,
        desc="discrepancy sampling",
        sampler_settings=walkers_for(settings or Settings(), len(model.theta_names)),
        mix=MIX,
        proposal=PROPOSAL,
        importance=IMPORTANCE,
    )
