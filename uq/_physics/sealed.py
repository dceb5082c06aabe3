"""The sealed spring: an element charged at one height, closed, and stroked with its gas mass fixed.

Derivation in docs/design.md. An element whose isobaric characteristics are known, force
P(x, p_u) and internal volume V(x, p_u) (the paper's eqs. 1, 2 generalised: at constant p_u,
dV/dx is the volume-derived area and P the force), is charged at height x_c to overpressure p_c
with internal volume V_c, closed (optionally joined to a reservoir of volume V_r) and moved. The
gas then follows the polytrope

    p_abs (V(x, p_u) + V_r)^n = p_abs,c (V_c + V_r)^n,   p_abs = p_u + p_atm,          (S1)

n = 1 isothermal (slow strokes) .. 1.4 adiabatic (fast strokes of air). Differentiating (S1)
along the stroke, with V depending on both x and p_u (an elastic casing: dV/dp_u != 0):

    dp_u/dx = -n p_abs V_x / (V + V_r + n p_abs V_p),                                   (S2)
    k = -dP/dx = -(P_x + P_p dp_u/dx)            (the vertical rate along the path),     (S3)
    f = sqrt(k g / P) / (2 pi)                   (natural frequency of the load P / g).  (S4)

For an inextensible casing (P = p_u A(x), V_x = A, V_p = 0), (S3) is the textbook
k = n p_abs A^2 / (V + V_r) - p_u dA/dx (``inextensible_rate``).

Arrays. Everything is vectorised for posterior draws: heights have shape (H,), per-draw values
(charge volume, polytropic exponent) shape (S,) or scalars, and results (S, H). An *element* is
any object with six methods of (x_m (H,), p_pa (S, H) or broadcastable) -> (S, H), draw s of the
result paired with row s of p_pa: ``force_N``, ``dforce_dx``, ``dforce_dp``, ``volume_m3``,
``dvolume_dx``, ``dvolume_dp`` (SI: m, Pa, N, m^3). Its volume may carry any constant: the
charge's V_c fixes the absolute volume (the stand measures only volume changes, eq. 5). A closed
form is an ``Element`` of six callables; posterior draws on a height x pressure grid are a
``GridElement``.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from functools import partialmethod
from typing import NamedTuple

import numpy as np

from uq._io.errors import InputError
from uq._physics import knots

G_STANDARD = 9.80665  # m/s^2, standard gravity (the load's mass is P / g)
P_ATM_PA = 101325.0
POLYTROPIC_RANGE = (1.0, 1.4)  # isothermal .. adiabatic for air


class Element(NamedTuple):
    """Isobaric characteristics as six callables f(x_m, p_pa) -> array (module docstring)."""

    force_N: Callable
    dforce_dx: Callable
    dforce_dp: Callable
    volume_m3: Callable
    dvolume_dx: Callable
    dvolume_dp: Callable


class Charge(NamedTuple):
    """How the spring is sealed: at height ``height_m`` with overpressure ``overpressure_pa``
    and internal volume ``volume_m3`` (m^3, scalar or per draw (S,)), polytropic exponent
    ``polytropic`` (scalar or (S,)), an extra reservoir ``reservoir_m3`` joined to the element."""

    height_m: float
    overpressure_pa: float
    volume_m3: float | np.ndarray
    polytropic: float | np.ndarray = 1.0
    reservoir_m3: float = 0.0
    p_atm_pa: float = P_ATM_PA


class SealedPath(NamedTuple):
    """The sealed characteristics along the stroke, each (S, H); NaN where ``in_range`` is False
    (the path's overpressure leaves the bounds the element is known in)."""

    height_m: np.ndarray  # (H,)
    overpressure_pa: np.ndarray  # p_u(x), (S1)
    force_N: np.ndarray  # P(x, p_u(x))
    rate_N_per_m: np.ndarray  # k = -dP/dx along the path, (S3)
    volume_m3: np.ndarray  # the element's absolute internal volume V(x, p_u(x))
    in_range: np.ndarray  # bool


def check_polytropic(n) -> np.ndarray:
    """The polytropic exponent(s) as an array, refused outside 1 (isothermal) .. 1.4 (adiabatic)."""
    a = np.asarray(n, float)
    lo, hi = POLYTROPIC_RANGE
    if not np.all(np.isfinite(a)) or np.any(a < lo - 1e-12) or np.any(a > hi + 1e-12):
        raise InputError(
            f"polytropic: expected {lo:g} (isothermal) .. {hi:g} (adiabatic), got "
            f"{np.ravel(a)[(np.ravel(a) < lo) | (np.ravel(a) > hi) | ~np.isfinite(np.ravel(a))][0]:g}",
            param="polytropic",
        )
    return a


def _col(v) -> np.ndarray:
    """A scalar -> (1, 1); per-draw values (S,) -> (S, 1): broadcasts against (S, H)."""
    a = np.asarray(v, float)
    if a.ndim > 1:
        raise ValueError(f"expected a scalar or one value per draw, got shape {a.shape}")
    return a.reshape(-1, 1)


def pressure_slope(p_u, volume, dvolume_dx, dvolume_dp, polytropic, reservoir_m3, p_atm_pa):
    """dp_u/dx along the sealed path, Pa/m (S2): -n p_abs V_x / (V + V_r + n p_abs V_p)."""
    p_abs = p_u + p_atm_pa
    return (
        -polytropic * p_abs * dvolume_dx / (volume + reservoir_m3 + polytropic * p_abs * dvolume_dp)
    )


def sealed_rate(dforce_dx, dforce_dp, dp_dx):
    """k = -dP/dx along the path, N/m (S3): -(P_x + P_p dp_u/dx)."""
    return -(dforce_dx + dforce_dp * dp_dx)


def inextensible_rate(
    p_u, area_m2, darea_dx, volume_m3, polytropic=1.0, reservoir_m3=0.0, p_atm_pa=P_ATM_PA
):
    """The closed form for an inextensible casing (P = p_u A(x), V_x = A, V_p = 0), N/m:
    k = n p_abs A^2 / (V + V_r) - p_u dA/dx."""
    p_abs = p_u + p_atm_pa
    return polytropic * p_abs * area_m2**2 / (volume_m3 + reservoir_m3) - p_u * darea_dx


def _log_gap(element, x, p, v_shift, log_k, n, v_r, p_atm):
    """phi(p) = ln p_abs + n ln(V + V_r) - ln K and its derivative in p_u; phi is 0 on the path."""
    both = getattr(element, "volume_and_slope", None)  # a grid element's: one look-up for both
    V, Vp = both(x, p) if both else (element.volume_m3(x, p), element.dvolume_dp(x, p))
    V = V + v_shift
    room = V + v_r
    with np.errstate(divide="ignore", invalid="ignore"):
        phi = (
            np.log(p + p_atm)
            + n * np.where(room > 0, np.log(np.where(room > 0, room, 1.0)), -np.inf)
            - log_k
        )
        dphi = 1.0 / (p + p_atm) + n * Vp / room
    return phi, dphi


def _unbracketed_charge_points(x, charge_height_m, p_c, lo, hi, in_range) -> np.ndarray:
    """(S, H): the points at the charge height whose root the bounds do not bracket. The path's
    pressure there is the charge pressure itself (V_c fixes the volume's constant there), also
    where the gas law is not monotone over all the known pressures (a compliant casing and a
    small volume can turn it back below the upper bound): the charge point, stable or not."""
    at = np.isclose(x, float(charge_height_m), rtol=0.0, atol=1e-12)[None, :]
    return at & (p_c >= lo) & (p_c <= hi) & ~in_range


def sealed_path(
    element,
    height_m,
    charge: Charge,
    *,
    pressure_bounds_pa: tuple[float, float] | None = None,
    rtol: float = 1e-12,
    max_iter: int = 200,
) -> SealedPath:
    """Solve (S1) for p_u at every height and draw, then force, dp_u/dx and the rate (S2, S3).

    Newton's method on ln p_abs + n ln(V + V_r) = ln K (monotone in p_u while the sealed gas is
    stable, V + V_r + n p_abs V_p > 0), kept inside a bracket that every step narrows, on the
    whole (S, H) array at once. ``pressure_bounds_pa``: where the element is known (a model's
    tested pressures); a height whose path pressure lies outside is marked ``in_range`` False
    and its values NaN. Default (closed forms): any positive absolute pressure up to four times
    the inextensible guess; a point without a root there is an error, not a mark.
    """
    x = np.asarray(height_m, float).reshape(-1)
    p_atm = float(charge.p_atm_pa)
    n = _col(check_polytropic(charge.polytropic))
    v_r = float(charge.reservoir_m3)
    if not (np.isfinite(v_r) and v_r >= 0):
        raise InputError(
            f"reservoir_l: expected a volume >= 0, got {v_r * 1e3:g} L", param="reservoir_l"
        )
    v_c = _col(charge.volume_m3)
    if np.any(~np.isfinite(v_c)) or np.any(v_c <= 0):
        raise InputError(
            f"volume_l: the internal volume must be positive, got {float(np.min(v_c)) * 1e3:g} L",
            param="volume_l",
        )
    p_c = _col(charge.overpressure_pa)
    if np.any(p_c + p_atm <= 0):
        raise InputError(
            "charge_bar: the absolute charge pressure must be positive", param="charge_bar"
        )
    # the element's volume is known up to a constant: V_c fixes it at the charge point
    v_shift = v_c - element.volume_m3(np.array([float(charge.height_m)]), p_c)
    log_k = np.log(p_c + p_atm) + n * np.log(v_c + v_r)
    S = np.broadcast_shapes(v_shift.shape, n.shape, p_c.shape)[0]
    shape = (S, x.size)
    # start: the inextensible guess (the element's volume at the charge pressure)
    v0 = element.volume_m3(x, np.broadcast_to(p_c, shape)) + v_shift
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        guess = (p_c + p_atm) * ((v_c + v_r) / np.maximum(v0 + v_r, 1e-300)) ** n - p_atm
    if pressure_bounds_pa is None:
        # any positive absolute pressure up to 4x the guess (shrunk where the volume runs out)
        lo = np.full(shape, -p_atm * (1 - 1e-9))
        hi = 4.0 * (np.where(np.isfinite(guess), guess, 0.0) + p_atm) - p_atm
        for _ in range(60):
            f_hi, _ = _log_gap(element, x, hi, v_shift, log_k, n, v_r, p_atm)
            short = ~np.isfinite(f_hi)
            if not short.any():
                break
            hi = np.where(short, 0.5 * (hi + np.maximum(guess, lo)), hi)
    else:
        lo = np.full(shape, float(pressure_bounds_pa[0]))
        hi = np.full(shape, float(pressure_bounds_pa[1]))
    f_lo, _ = _log_gap(element, x, lo, v_shift, log_k, n, v_r, p_atm)
    f_hi, _ = _log_gap(element, x, hi, v_shift, log_k, n, v_r, p_atm)
    in_range = (f_lo <= 0) & (f_hi >= 0)
    at_charge = _unbracketed_charge_points(x, charge.height_m, p_c, lo, hi, in_range)
    in_range |= at_charge
    if pressure_bounds_pa is None and not in_range.all():
        raise RuntimeError(
            f"sealed path: no pressure satisfies the gas law (S1) at {int((~in_range).sum())} of {in_range.size} (draw, height) points"
        )
    p = np.where(np.isfinite(guess) & (guess > lo) & (guess < hi), guess, 0.5 * (lo + hi))
    p = np.where(at_charge, np.broadcast_to(p_c, shape), p)
    done = ~in_range | at_charge
    # Newton's steps point by point; the draws (rows) whose every height is done drop out of the
    # arrays (an element that can give a subset of its draws, ``on_rows``): the same numbers
    rows, el, per_draw = np.arange(S), element, (v_shift, log_k, n)
    p_r, lo_r, hi_r, done_r = p, lo, hi, done
    for _ in range(max_iter):
        phi, dphi = _log_gap(el, x, p_r, *per_draw, v_r, p_atm)
        lo_r = np.where(phi < 0, p_r, lo_r)
        hi_r = np.where(phi > 0, p_r, hi_r)
        with np.errstate(divide="ignore", invalid="ignore"):
            p_new = p_r - phi / dphi
        bad = ~np.isfinite(p_new) | (p_new <= lo_r) | (p_new >= hi_r)
        p_new = np.where(bad, 0.5 * (lo_r + hi_r), p_new)
        step = np.abs(p_new - p_r)
        p_r = np.where(done_r, p_r, p_new)
        done_r |= (step <= rtol * (np.abs(p_r) + p_atm)) | (phi == 0)
        if done_r.all():
            break
        going = ~done_r.all(axis=1)
        if hasattr(element, "on_rows") and going.sum() <= 0.75 * going.size:
            p[rows], done[rows] = p_r, done_r
            rows = rows[going]
            el = element.on_rows(rows)
            per_draw = tuple(a[rows] if a.shape[0] == S else a for a in (v_shift, log_k, n))
            p_r, lo_r, hi_r, done_r = p_r[going], lo_r[going], hi_r[going], done_r[going]
    else:
        p[rows], done[rows] = p_r, done_r
        raise RuntimeError(
            f"sealed path: the gas law (S1) did not converge at {int((~done).sum())} of {done.size} (draw, height) points"
        )
    p[rows] = p_r
    # heights whose path leaves the bounds are evaluated at the charge pressure (always defined), then NaN
    p = np.where(in_range, p, np.broadcast_to(p_c, shape))
    V = element.volume_m3(x, p) + v_shift
    Vp = element.dvolume_dp(x, p)
    gas_stiffness = V + v_r + n * (p + p_atm) * Vp
    unstable = in_range & ~(gas_stiffness > 0)
    if unstable.any():
        raise InputError(
            f"sealed spring: at {int(unstable.sum())} (draw, height) points the volume falls with pressure "
            "faster than the sealed gas can follow (V + V_r + n p_abs dV/dp_u <= 0): no stable sealed state"
        )
    dpdx = pressure_slope(p, V, element.dvolume_dx(x, p), Vp, n, v_r, p_atm)
    k = sealed_rate(element.dforce_dx(x, p), element.dforce_dp(x, p), dpdx)
    P = element.force_N(x, p)
    nan = np.where(in_range, 1.0, np.nan)
    return SealedPath(x, p * nan, P * nan, k * nan, V * nan, in_range)


def natural_frequency_Hz(rate_N_per_m, load_N, where: str = "", g: float = G_STANDARD):
    """f = sqrt(k g / P) / (2 pi) (S4), Hz, of the load P (N) on a spring of rate k (N/m).

    Undefined unless both are positive: refused with the number of draws at fault, never a NaN.
    """
    k = np.asarray(rate_N_per_m, float)
    P = np.asarray(load_N, float)
    k, P = np.broadcast_arrays(k, P)
    bad_k, bad_P = ~(k > 0), ~(P > 0)
    if bad_k.any() or bad_P.any():
        parts = []
        if bad_P.any():
            parts.append(f"the load is not positive in {int(bad_P.sum())} of {P.size} draws")
        if bad_k.any():
            parts.append(f"the rate is not positive in {int(bad_k.sum())} of {k.size} draws")
        raise InputError(
            f"natural frequency{' ' + where if where else ''}: {' and '.join(parts)}; "
            "f = sqrt(k g / P) / (2 pi) needs a positive load on a positive rate"
        )
    return np.sqrt(k * g / P) / (2.0 * np.pi)


def transmissibility(forcing_Hz, natural_Hz):
    """Force (and motion) transmissibility of an undamped single-degree-of-freedom mount:
    T = 1 / |1 - r^2|, r = f_forcing / f_n (infinite at resonance, r = 1)."""
    r = np.asarray(forcing_Hz, float) / np.asarray(natural_Hz, float)
    with np.errstate(divide="ignore"):
        return 1.0 / np.abs(1.0 - r**2)


def isolation_pct(transmissibility_):
    """Per cent isolation 100 (1 - T): positive above r = sqrt 2, negative (amplification) below."""
    return 100.0 * (1.0 - np.asarray(transmissibility_, float))


# ----------------------------------------------------------------------------- grid element


class GridElement:
    """An element from posterior draws on a height x pressure grid.

    ``force``, ``dforce_dx``, ``volume`` and ``dvolume_dx``: arrays (S, H, Pn) on ``height_m``
    (H,) x ``pressure_pa`` (Pn,) (the volume up to a constant per draw). Each is interpolated in
    pressure by a cubic spline (not-a-knot: exact for cubics in p_u), per draw and height;
    dP/dp_u and dV/dp_u are the splines' derivatives. The methods accept only heights on the
    grid (the sealed path is solved height by height) and evaluate draw s at its own pressure.
    """

    def __init__(self, height_m, pressure_pa, force, dforce_dx, volume, dvolume_dx):
        self.height_grid = np.asarray(height_m, float)
        self.pressure_grid = np.asarray(pressure_pa, float)
        if self.pressure_grid.size < 4 or np.any(np.diff(self.pressure_grid) <= 0):
            raise ValueError("GridElement: need at least 4 increasing pressures")
        shape = (self.height_grid.size, self.pressure_grid.size)
        self._c = {}
        for name, arr in (("P", force), ("Px", dforce_dx), ("V", volume), ("Vx", dvolume_dx)):
            a = np.asarray(arr, float)
            if a.shape[1:] != shape:
                raise ValueError(
                    f"GridElement: {name} has shape {a.shape}, expected (S, {shape[0]}, {shape[1]})"
                )
            self._c[name] = knots.coefficients(self.pressure_grid, a, axis=2)  # (4, Pn-1, S, H)
        self.n_draws = int(np.asarray(force).shape[0])
        self._rows = np.arange(self.n_draws)  # the draw each row of p_pa is evaluated for
        self._at_heights = {}  # the grid indices of the heights asked (the same ones every step)

    def on_rows(self, rows) -> GridElement:
        """The element whose row i of p_pa is draw ``rows[i]`` of this one, its coefficients shared
        (not copied): the draws still iterating in :func:`sealed_path`."""
        out = copy.copy(self)
        out._rows = self._rows[np.asarray(rows, int)]
        out.n_draws = out._rows.size
        return out

    @property
    def pressure_bounds_pa(self) -> tuple[float, float]:
        return float(self.pressure_grid[0]), float(self.pressure_grid[-1])

    def _index(self, x):
        x = np.asarray(x, float).reshape(-1)
        key = x.tobytes()
        if key not in self._at_heights:
            self._at_heights[key] = self._find(x)
        return self._at_heights[key]

    def _find(self, x):
        i = np.clip(np.searchsorted(self.height_grid, x), 0, self.height_grid.size - 1)
        j = np.clip(i - 1, 0, self.height_grid.size - 1)
        i = np.where(np.abs(self.height_grid[j] - x) < np.abs(self.height_grid[i] - x), j, i)
        if not np.allclose(self.height_grid[i], x, rtol=0, atol=1e-12):
            raise ValueError("GridElement: heights must lie on the element's height grid")
        return i

    def _eval(self, name, x, p, deriv=False):
        return self._evals(name, x, p, (deriv,))[0]

    def _evals(self, name, x, p, derivs):
        ix = self._index(x)
        p = np.broadcast_to(np.asarray(p, float), (self.n_draws, ix.size))
        c = self._c[name]
        k = np.clip(
            np.searchsorted(self.pressure_grid, p, side="right") - 1, 0, self.pressure_grid.size - 2
        )
        # the four coefficients of draw s, height ix, interval k: one look-up by flat index
        at = (k * c.shape[2] + self._rows[:, None]) * c.shape[3] + ix
        c0, c1, c2, c3 = np.take(c.reshape(4, -1), at, axis=1)
        d = p - self.pressure_grid[k]
        return [
            (3.0 * c0 * d + 2.0 * c1) * d + c2 if deriv else ((c0 * d + c1) * d + c2) * d + c3
            for deriv in derivs
        ]

    force_N = partialmethod(_eval, "P")
    dforce_dx = partialmethod(_eval, "Px")
    dforce_dp = partialmethod(_eval, "P", deriv=True)
    volume_m3 = partialmethod(_eval, "V")
    dvolume_dx = partialmethod(_eval, "Vx")
    dvolume_dp = partialmethod(_eval, "V", deriv=True)
    #: ``volume_m3`` and ``dvolume_dp`` at the same points from one look-up (the gas law's steps)
    volume_and_slope = partialmethod(_evals, "V", derivs=(False, True))
