"""The sealed spring's physics (uq/_physics/sealed.py) against closed forms and independent solutions.

Elements with known answers, each a potential G(x, p_u) = -p_u V0(x) - p_u^2 C(x)/2 + E(x)
(P = -dG/dx, V = -dG/dp_u): an inextensible cylinder (constant area), a cone (area linear in x),
and a casing with compliance (V depends on p_u). Every element carries a draw axis.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

from uq._io.errors import InputError
from uq._physics.sealed import (
    P_ATM_PA,
    Charge,
    Element,
    GridElement,
    check_polytropic,
    inextensible_rate,
    isolation_pct,
    natural_frequency_Hz,
    sealed_path,
    transmissibility,
)

X_C = 0.112
HEIGHTS = np.linspace(0.085, 0.140, 12)
P_C = 5.0e5


def potential_element(a0, a1=0.0, c0=0.0, c1=0.0, f_e=0.0):
    """V0' = a0 + a1 u, C = c0 + c1 u, casing force F_E = -E' = f_e (u = x - x_c); parameters may be
    per draw, shape (S, 1). P = p (a0 + a1 u) + p^2 c1 / 2 + f_e, V = a0 u + a1 u^2/2 + p (c0 + c1 u)."""

    def u(x):
        return np.asarray(x, float) - X_C

    return Element(
        force_N=lambda x, p: p * (a0 + a1 * u(x)) + p**2 * c1 / 2 + f_e,
        dforce_dx=lambda x, p: p * a1 + 0.0 * p,
        dforce_dp=lambda x, p: a0 + a1 * u(x) + p * c1,
        volume_m3=lambda x, p: a0 * u(x) + a1 * u(x) ** 2 / 2 + p * (c0 + c1 * u(x)),
        dvolume_dx=lambda x, p: a0 + a1 * u(x) + p * c1,
        dvolume_dp=lambda x, p: c0 + c1 * u(x) + 0.0 * p,
    )


def test_inextensible_cylinder_is_exact():
    """Constant area A: p_abs (V + V_r)^n = const in closed form and k = n p_abs A^2 / (V + V_r),
    per draw (three charge volumes), isothermal and adiabatic, with and without a reservoir."""
    A = 0.028
    v_c = np.array([2.5e-3, 3.3e-3, 4.0e-3])
    for n in (1.0, 1.4):
        for v_r in (0.0, 2.0e-3):
            path = sealed_path(potential_element(A), HEIGHTS, Charge(X_C, P_C, v_c, n, v_r))
            V = v_c[:, None] + A * (HEIGHTS - X_C)
            p_abs = (P_C + P_ATM_PA) * ((v_c[:, None] + v_r) / (V + v_r)) ** n
            assert np.allclose(path.overpressure_pa + P_ATM_PA, p_abs, rtol=1e-12)
            assert np.allclose(path.rate_N_per_m, n * p_abs * A**2 / (V + v_r), rtol=1e-10)
            assert np.allclose(path.force_N, (p_abs - P_ATM_PA) * A, rtol=1e-12)
            assert np.allclose(path.volume_m3, V, rtol=1e-12) and path.in_range.all()


def test_cone_adds_minus_p_dA_dx():
    """Area A(x) = a0 + a1 u: k = n p_abs A^2 / V - p_u a1 (the inextensible closed form)."""
    a0, a1 = 0.027, -0.22
    path = sealed_path(potential_element(a0, a1), HEIGHTS, Charge(X_C, P_C, 3.3e-3, 1.2))
    u = HEIGHTS - X_C
    V = 3.3e-3 + a0 * u + a1 * u**2 / 2
    p_abs = (P_C + P_ATM_PA) * (3.3e-3 / V) ** 1.2
    want = inextensible_rate(p_abs - P_ATM_PA, a0 + a1 * u, a1, V, 1.2)
    assert np.allclose(path.rate_N_per_m[0], want, rtol=1e-10)
    # the cone term is not small: dropping it would be caught
    assert np.all(np.abs(-(p_abs - P_ATM_PA) * a1) > 0.2 * want)


def _casing():
    # per-draw compliance C(x_c) of 0, 20 and 60 cm^3/bar; C' = 0.024/bar x V0'(x_c) (Table 1's
    # growth of the volume-derived area at x0)
    c0 = np.array([[0.0], [20e-6 / 1e5], [60e-6 / 1e5]])
    return potential_element(0.027, -0.22, c0, C1, f_e=-150.0), c0


C1 = 0.024 * 0.027 / 1e5


def test_casing_term_at_the_charge_height():
    """With dV/dp_u != 0 the gas law gives dp/dx = -n p_abs V_x / (V + V_r + n p_abs V_p): at x_c,
    k = -P_x + n p_abs P_p V_x / (V_c + V_r + n p_abs C(x_c)), per draw; the draws differ by the
    casing term alone, and by more than the solver's tolerance."""
    el, c0 = _casing()
    n, v_c, v_r = 1.4, 3.3e-3, 1.0e-3
    path = sealed_path(el, np.array([X_C]), Charge(X_C, P_C, v_c, n, v_r))
    p_abs = P_C + P_ATM_PA
    vx = 0.027 + P_C * C1  # = P_p by the Maxwell relation
    want = -P_C * (-0.22) + n * p_abs * vx * vx / (v_c + v_r + n * p_abs * c0[:, 0])
    assert np.allclose(path.rate_N_per_m[:, 0], want, rtol=1e-12)
    assert path.rate_N_per_m[0, 0] / path.rate_N_per_m[2, 0] > 1.03


def test_path_agrees_with_independent_solutions():
    """Newton's path against (1) scipy's brentq on the gas law at each height and (2) solve_ivp on
    dp_u/dx (S2) from the charge; the rate against a central difference of the path force.
    Tolerances: 1e-9 relative on pressure (both solvers at 1e-12), 1e-6 on the rate (difference
    step 1e-5 m: truncation about (h/0.05 m)^2)."""
    el, _ = _casing()
    n, v_c, v_r = 1.3, 3.3e-3, 0.5e-3
    xs = np.linspace(0.090, 0.135, 10)
    path = sealed_path(el, xs, Charge(X_C, P_C, v_c, n, v_r))
    log_k = np.log(P_C + P_ATM_PA) + n * np.log(v_c + v_r)

    def p_at(x, s):
        def gap(p):
            V = (
                v_c
                + el.volume_m3(np.array([x]), np.full((3, 1), p))[s, 0]
                - el.volume_m3(np.array([X_C]), np.full((3, 1), P_C))[s, 0]
            )
            return np.log(p + P_ATM_PA) + n * np.log(V + v_r) - log_k

        return brentq(gap, 0.5e5, 40e5, xtol=1e-12, rtol=1e-14)

    for s in range(3):
        ref = np.array([p_at(x, s) for x in xs])
        assert np.allclose(path.overpressure_pa[s], ref, rtol=1e-9)

        def rhs(x, p, s=s):
            P = np.full((3, 1), p[0])
            xa = np.array([x])
            V = (
                v_c
                + el.volume_m3(xa, P)[s, 0]
                - el.volume_m3(np.array([X_C]), np.full((3, 1), P_C))[s, 0]
            )
            Vx, Vp = el.dvolume_dx(xa, P)[s, 0], el.dvolume_dp(xa, P)[s, 0]
            return [-n * (p[0] + P_ATM_PA) * Vx / (V + v_r + n * (p[0] + P_ATM_PA) * Vp)]

        for lo_hi in ((X_C, xs[-1]), (X_C, xs[0])):
            sol = solve_ivp(rhs, lo_hi, [P_C], rtol=1e-11, atol=1e-6, dense_output=True)
            inside = (xs - lo_hi[0]) * (lo_hi[1] - lo_hi[0]) >= 0
            assert np.allclose(sol.sol(xs[inside])[0], path.overpressure_pa[s, inside], rtol=1e-8)
        h = 1e-5
        for j, x in enumerate(xs):
            P = [
                el.force_N(np.array([xx]), np.full((3, 1), p_at(xx, s)))[s, 0]
                for xx in (x - h, x + h)
            ]
            assert path.rate_N_per_m[s, j] == pytest.approx(-(P[1] - P[0]) / (2 * h), rel=1e-6)


def test_isothermal_and_adiabatic_limits():
    """At the charge height of a cylinder the rate scales with n exactly (1.4 / 1.0); away from it the
    pressure follows Boyle (n = 1) or the adiabat (n = 1.4)."""
    el = potential_element(0.028)
    iso = sealed_path(el, HEIGHTS, Charge(X_C, P_C, 3.3e-3, 1.0))
    adi = sealed_path(el, HEIGHTS, Charge(X_C, P_C, 3.3e-3, 1.4))
    j = np.argmin(np.abs(HEIGHTS - X_C))
    x1 = np.array([X_C])
    k_iso = sealed_path(el, x1, Charge(X_C, P_C, 3.3e-3, 1.0)).rate_N_per_m
    k_adi = sealed_path(el, x1, Charge(X_C, P_C, 3.3e-3, 1.4)).rate_N_per_m
    assert k_adi / k_iso == pytest.approx(1.4, rel=1e-12)
    V = 3.3e-3 + 0.028 * (HEIGHTS - X_C)
    assert np.allclose((iso.overpressure_pa + P_ATM_PA) * V, (P_C + P_ATM_PA) * 3.3e-3, rtol=1e-12)
    assert np.allclose(
        (adi.overpressure_pa + P_ATM_PA) * V**1.4, (P_C + P_ATM_PA) * 3.3e-3**1.4, rtol=1e-12
    )
    assert j >= 0 and np.all(adi.rate_N_per_m[0] > iso.rate_N_per_m[0])


def test_reservoir_limits():
    """V_r -> infinity: the pressure stays at the charge and k -> -p_u dA/dx (the cone's own term);
    V_r = 0 is the element alone. The approach is 1 / V_r: at 1e4 m^3 within 1e-5."""
    a0, a1 = 0.027, -0.22
    big = sealed_path(potential_element(a0, a1), HEIGHTS, Charge(X_C, P_C, 3.3e-3, 1.0, 1.0e4))
    assert np.allclose(big.overpressure_pa, P_C, rtol=1e-5)
    assert np.allclose(big.rate_N_per_m, -P_C * a1, rtol=1e-5)
    none = sealed_path(potential_element(a0, a1), HEIGHTS, Charge(X_C, P_C, 3.3e-3, 1.0, 0.0))
    mid = sealed_path(potential_element(a0, a1), HEIGHTS, Charge(X_C, P_C, 3.3e-3, 1.0, 3.0e-3))
    j = np.argmin(np.abs(HEIGHTS - X_C))
    assert none.rate_N_per_m[0, j] > mid.rate_N_per_m[0, j] > big.rate_N_per_m[0, j]


def test_grid_element_reproduces_the_closed_form():
    """The same casing element given as draws on a height x pressure grid (what a posterior gives):
    P is quadratic and V linear in p_u, so the not-a-knot spline in pressure is exact; the path and
    rate agree to rounding (1e-9)."""
    el, _ = _casing()
    xs = np.sort(np.append(np.linspace(0.065, 0.155, 19), X_C))  # the charge height on the grid
    ps = np.linspace(0.1e5, 10e5, 12)
    X, P = np.meshgrid(xs, ps, indexing="ij")
    arrays = [
        np.broadcast_to(f(X.reshape(1, -1), P.reshape(1, -1)), (3, X.size)).reshape(3, *X.shape)
        for f in (el.force_N, el.dforce_dx, el.volume_m3, el.dvolume_dx)
    ]
    grid = GridElement(xs, ps, *arrays)
    charge = Charge(X_C, P_C, 3.3e-3, 1.2, 1e-3)
    on_grid = xs[(xs > 0.09) & (xs < 0.13)]
    a = sealed_path(grid, on_grid, charge, pressure_bounds_pa=grid.pressure_bounds_pa)
    b = sealed_path(el, on_grid, charge)
    for name in ("overpressure_pa", "force_N", "rate_N_per_m", "volume_m3"):
        assert np.allclose(getattr(a, name), getattr(b, name), rtol=1e-9), name
    with pytest.raises(ValueError, match="height grid"):
        grid.force_N(np.array([0.1121]), np.full((3, 1), P_C))


def test_leaving_the_known_pressures_is_marked_not_extrapolated():
    """A path whose pressure leaves the bounds is in_range False and NaN there (never a guess)."""
    el = potential_element(0.028)
    xs = np.linspace(0.065, 0.155, 19)
    path = sealed_path(el, xs, Charge(X_C, P_C, 3.3e-3, 1.0), pressure_bounds_pa=(3e5, 8e5))
    p_true = (P_C + P_ATM_PA) * 3.3e-3 / (3.3e-3 + 0.028 * (xs - X_C)) - P_ATM_PA
    inside = (p_true >= 3e5) & (p_true <= 8e5)
    assert not inside.all() and inside.any()
    assert np.array_equal(path.in_range[0], inside)
    assert np.all(np.isnan(path.force_N[0, ~inside])) and np.all(
        np.isfinite(path.force_N[0, inside])
    )


def test_the_charge_point_is_on_the_path_where_the_bounds_do_not_bracket_it():
    """A compliant casing (dV/dp_u < 0) and a small volume turn the gas law back below the upper
    known pressure: the bounds then do not bracket its root at the charge height, which is still
    the charge point itself, stable there (V_c + n p_abs dV/dp_u > 0): load and rate as at any
    charge height, not NaN. Away from it the path is marked as before."""
    c0, v_c, n, p_c, bounds = -5.7e-10, 0.8e-3, 1.35, 9.0e5, (1.0e4, 1.0e6)
    el = potential_element(0.028, c0=c0)
    gap = lambda p: np.log(p + P_ATM_PA) + n * np.log(v_c + c0 * (p - p_c))  # noqa: E731
    assert gap(bounds[1]) < gap(p_c) and gap(bounds[0]) < gap(p_c)  # not bracketed at x_c
    path = sealed_path(
        el, np.array([0.100, X_C]), Charge(X_C, p_c, v_c, n), pressure_bounds_pa=bounds
    )
    assert path.in_range[0, 1] and path.overpressure_pa[0, 1] == p_c
    assert path.force_N[0, 1] == pytest.approx(0.028 * p_c, rel=1e-12)
    p_abs = p_c + P_ATM_PA
    want = n * p_abs * 0.028**2 / (v_c + n * p_abs * c0)  # test_casing_term_at_the_charge_height
    assert path.rate_N_per_m[0, 1] == pytest.approx(want, rel=1e-10)
    assert np.isfinite(natural_frequency_Hz(path.rate_N_per_m[:, 1], path.force_N[:, 1])).all()


def test_frequency_transmissibility_and_refusals():
    k, P = np.array([2.6e5, 1.0e5]), np.array([13e3, 10e3])
    f = natural_frequency_Hz(k, P)
    assert np.allclose(f, np.sqrt(k * 9.80665 / P) / (2 * np.pi))
    with pytest.raises(InputError, match=r"the rate is not positive in 1 of 3 draws"):
        natural_frequency_Hz(np.array([1e5, -2.0, 3e5]), np.array([1e4, 1e4, 1e4]), "at 112 mm")
    with pytest.raises(InputError, match=r"the load is not positive in 2 of 2 draws"):
        natural_frequency_Hz(np.array([1e5, 1e5]), np.array([0.0, -5.0]))
    T = transmissibility(np.array([0.0, 2.0, 2.0 * np.sqrt(2)]), 1.0)
    assert np.allclose(T, [1.0, 1.0 / 3.0, 1.0 / 7.0])
    assert np.allclose(isolation_pct(T), [0.0, 200.0 / 3.0, 600.0 / 7.0])
    assert transmissibility(0.5, 1.0) == pytest.approx(4.0 / 3.0) and isolation_pct(4.0 / 3.0) < 0
    with pytest.raises(InputError, match="^polytropic:"):
        check_polytropic(1.6)
    with pytest.raises(InputError, match="^polytropic:"):
        sealed_path(potential_element(0.028), HEIGHTS, Charge(X_C, P_C, 3.3e-3, 0.9))
    with pytest.raises(InputError, match="^volume_l:"):
        sealed_path(potential_element(0.028), HEIGHTS, Charge(X_C, P_C, -1e-3))


def test_grid_element_drops_finished_draws_to_the_same_numbers(monkeypatch):
    """Draws whose every height has converged leave Newton's arrays (``GridElement.on_rows``); the
    path is the one the element gives without that (the same methods as a plain ``Element``),
    to the bit, in range and out of it."""
    S = 40  # draws of their own: compliance, volume, exponent and charge, each its own steps
    el = potential_element(0.027, -0.22, np.linspace(0.0, 60e-6 / 1e5, S)[:, None], C1, -150.0)
    xs = np.sort(np.append(np.linspace(0.065, 0.155, 19), X_C))
    ps = np.linspace(0.1e5, 10e5, 12)
    X, P = np.meshgrid(xs, ps, indexing="ij")
    arrays = [
        np.broadcast_to(f(X.reshape(1, -1), P.reshape(1, -1)), (S, X.size)).reshape(S, *X.shape)
        for f in (el.force_N, el.dforce_dx, el.volume_m3, el.dvolume_dx)
    ]
    grid = GridElement(xs, ps, *arrays)
    rng = np.random.default_rng(3)
    charge = Charge(
        X_C,
        rng.uniform(1e5, 8e5, S),
        rng.uniform(1e-3, 6e-3, S),
        rng.uniform(1.0, 1.4, S),
        5e-4,
    )
    narrowed = []
    on_rows = GridElement.on_rows
    monkeypatch.setattr(
        GridElement, "on_rows", lambda self, rows: narrowed.append(len(rows)) or on_rows(self, rows)
    )
    a = sealed_path(grid, xs, charge, pressure_bounds_pa=grid.pressure_bounds_pa)
    plain = Element(
        grid.force_N,
        grid.dforce_dx,
        grid.dforce_dp,
        grid.volume_m3,
        grid.dvolume_dx,
        grid.dvolume_dp,
    )
    b = sealed_path(plain, xs, charge, pressure_bounds_pa=grid.pressure_bounds_pa)
    assert narrowed and min(narrowed) < S  # the finished draws did leave
    assert a.in_range.any() and not a.in_range.all()
    for name in a._fields:
        assert np.array_equal(getattr(a, name), getattr(b, name), equal_nan=True), name
