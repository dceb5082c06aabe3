"""The virtual stand's spring with one potential (n50-thermo), the elastic_casing mechanism, and the
sealed test: Maxwell relation, absolute volume, Table 1 fit, the mechanism's magnitude, the sealed
truth against the physics core and the gas law."""

from __future__ import annotations

import numpy as np
import pytest

from uq._cli.main import main
from uq._data.recordings import read_recordings
from uq._data.reference import cubic, cubic_slope, table1
from uq._data.stand_description import PAPER_STAND
from uq._io.errors import InputError
from uq._physics.mechanisms import (
    ELASTIC_CASING_PROFILE,
    MECHANISMS,
    elastic_casing_slope,
    parse_effects,
)
from uq._physics.sealed import Charge, Element, sealed_path
from uq._stand.sealed_test import sealed_truth, simulate_sealed, true_volume_m3
from uq._stand.simulator import (
    Layout,
    ThermoSpring,
    TraditionalSpring,
    casing_reference_area_m2,
    simulate,
    true_curves,
)

XS = np.linspace(0.065, 0.155, 19)
S_PISTON = 54.82e-4


def _d(f, x, h):
    return (f(x + h) - f(x - h)) / (2 * h)


def test_force_and_volume_derive_from_one_potential():
    """P = -dG/dx, V = -dG/dp_u (central differences of G) and dP/dp_u = dV/dx (Maxwell)."""
    s = ThermoSpring()
    for p in (0.5, 3.0, 8.0, 14.0):
        pa = p * 1e5
        dGdx = _d(lambda x, p=p: s.potential_J(x, p), XS, 1e-6)
        assert np.allclose(-dGdx, s.force_N(XS, p), rtol=1e-7, atol=1e-3)
        dGdp = _d(lambda q: s.potential_J(XS, q / 1e5), pa, 10.0)
        assert np.allclose(-dGdp, s.volume_m3(XS, p), rtol=1e-8)
        dPdp = _d(lambda q: s.force_N(XS, q / 1e5), pa, 10.0)
        dVdx = _d(lambda x, p=p: s.volume_m3(x, p), XS, 1e-6)
        assert np.allclose(dPdp, dVdx, rtol=1e-7) and np.allclose(
            dVdx, s.volume_area_m2(XS, p), rtol=1e-7
        )
        # the piston describes the same volume (eq. 5): -S dL/dx = dV/dx
        assert np.allclose(-S_PISTON * s.piston_slope(XS, p), s.volume_area_m2(XS, p))
        assert np.allclose(
            -S_PISTON * _d(lambda x, p=p: s.piston_m(x, p), XS, 1e-6),
            s.volume_area_m2(XS, p),
            rtol=1e-7,
        )


def test_absolute_volume_and_the_fit_to_table1():
    s = ThermoSpring()
    assert s.volume_m3(np.array(0.155), 0.0) == pytest.approx(PAPER_STAND.element_volume_at_xmax_m3)
    # C(x0) = 0 by default: the volume at x0 does not change with pressure (the contract's assumption)
    assert np.ptp([s.volume_m3(np.array(0.112), p) for p in (0.1, 5.0, 10.0)]) < 1e-15
    other = ThermoSpring(compliance_at_x0_m3_per_pa=40e-6 / 1e5)
    assert other.volume_m3(np.array(0.112), 5.0) - other.volume_m3(
        np.array(0.112), 0.0
    ) == pytest.approx(200e-6)
    t = table1()
    u = XS - 0.112
    for i, p in enumerate(t.pressures_bar[1:], start=1):
        P = cubic(t.force[i], u)
        rel = np.sqrt(np.mean((s.force_N(XS, p) - P) ** 2)) / np.mean(np.abs(P))
        assert rel < 0.035, (p, rel)
        A = -S_PISTON * cubic_slope(t.piston[i], u)
        assert np.sqrt(np.mean((s.volume_area_m2(XS, p) - A) ** 2)) / np.mean(A) < 0.07, p
    # the area grows with pressure as Table 1's does at x0 (about 0.02-0.03 per bar)
    m = s.compliance_slope(np.array(0.112)) * 1e5 / s.traditional_area_m2(np.array(0.112))
    assert 0.015 < m < 0.04


def test_elastic_casing_profile_is_table1s():
    """ELASTIC_CASING_PROFILE recomputed: the pressure slope (1..10 bar) of -S dL/dx at 19 heights,
    a quadratic in t = u / 0.05 m by least squares, normalised at x0 (to 0.02)."""
    t1 = table1()
    u = XS - 0.112
    area = -S_PISTON * cubic_slope(t1.piston[:, None, :], u)
    slope = np.array([np.polyfit(t1.pressures_bar[1:], area[1:, j], 1)[0] for j in range(XS.size)])
    q = np.polyfit(u / 0.05, slope, 2)[::-1]
    assert np.allclose(q / q[0], ELASTIC_CASING_PROFILE, atol=0.02)


def test_elastic_casing_mechanism_follows_the_contract():
    """On the traditional spring: force gains p^2 C'/2, the volume-derived area gains p C', so
    (dV/dx - F_eff) / F_eff / p_bar = m at x0 and the Maxwell relation still holds."""
    assert "elastic_casing" in MECHANISMS and MECHANISMS["elastic_casing"].unit == "1/bar"
    assert parse_effects(["elastic_casing=0.024"]) == {"elastic_casing": 0.024}
    with pytest.raises(InputError, match="elastic_casing"):
        parse_effects(["elastic_casing=2.4"])
    s, m = TraditionalSpring(), 0.024
    comp, step = np.ones(XS.size, bool), np.zeros(XS.size)

    def curves(x, p, eff):
        return true_curves(s, eff, x, p, np.ones(np.size(x), bool), np.zeros(np.size(x)))

    f0, l0 = true_curves(s, {}, XS, 6.0, comp, step)
    f1, l1 = true_curves(s, {"elastic_casing": m}, XS, 6.0, comp, step)
    area = casing_reference_area_m2(s)
    assert area == pytest.approx(s.effective_area_m2(np.array(0.112), 5.0))
    assert np.allclose(f1 - f0, (6e5) ** 2 * elastic_casing_slope(XS, 0.112, m, area) / 2)
    for p in (2.0, 6.0, 9.0):
        vx = -S_PISTON * _d(lambda x, p=p: curves(x, p, {"elastic_casing": m})[1], XS, 1e-6)
        fp = _d(lambda q: curves(XS, q, {"elastic_casing": m})[0], p, 1e-4) / 1e5
        assert np.allclose(vx, fp, rtol=1e-6)  # Maxwell
        x0 = np.array([0.112])
        vx0 = -S_PISTON * _d(lambda x, p=p: curves(x, p, {"elastic_casing": m})[1], x0, 1e-6)[0]
        f0 = float(s.effective_area_m2(x0, p)[0])
        assert (vx0 - f0) / f0 / p == pytest.approx(m, rel=1e-6)


def test_simulate_thermo_writes_ordinary_recordings(tmp_path):
    out = tmp_path / "thermo.csv"
    args = [
        "simulate",
        "--out",
        str(out),
        "--spring",
        "n50-thermo",
        "--pressures",
        "1,5,9",
        "--step-mm",
        "10",
    ]
    assert main(args + ["--effect", "elastic_casing=0.01"]) == 0
    rec = read_recordings(out)
    assert [t.pressure_bar for t in rec.tests] == [1.0, 5.0, 9.0]
    # the readings scatter about the spring's truth by the stand's budget (0.5 % load cell and more)
    s = ThermoSpring()
    t = rec.tests[1]
    f, _ = true_curves(s, {"elastic_casing": 0.01}, t.height_m, 5.0, t.compression, t.step)
    assert 0.002 < np.std((t.force_N - f) / f) < 0.012
    assert (
        main(
            [
                "simulate",
                "--out",
                str(tmp_path / "x.csv"),
                "--spring",
                "n50-thermo",
                "--pressures",
                "25",
            ]
        )
        == 2
    )


def test_sealed_truth_obeys_the_gas_law_and_the_physics_core():
    """The stand's truth (brentq + finite-difference rate) against uq._physics.sealed with the
    spring's exact partial derivatives: pressure to 1e-10, rate to 1e-6 (difference step)."""
    s = ThermoSpring(compliance_at_x0_m3_per_pa=30e-6 / 1e5)
    xs = np.linspace(0.090, 0.140, 11)
    n, v_r = 1.3, 1.0e-3
    tr = sealed_truth("n50-thermo", xs, charge_bar=4.0, polytropic=n, reservoir_m3=v_r, spring=s)
    p_abs = tr.pressure_bar * 1e5 + 101325.0
    v = s.volume_m3(xs, tr.pressure_bar)
    assert np.allclose(
        p_abs * (v + v_r) ** n, (4e5 + 101325.0) * (tr.volume_c_m3 + v_r) ** n, rtol=1e-12
    )
    assert tr.dvdp_c_m3_per_pa == pytest.approx(30e-6 / 1e5, rel=1e-6)
    bar = 1e5
    el = Element(
        force_N=lambda x, p: s.force_N(x, p / bar),
        dforce_dx=lambda x, p: _d(lambda y: s.force_N(y, p / bar), x, 1e-6),
        dforce_dp=lambda x, p: s.volume_area_m2(x, p / bar),
        volume_m3=lambda x, p: s.volume_m3(x, p / bar),
        dvolume_dx=lambda x, p: s.volume_area_m2(x, p / bar),
        dvolume_dp=lambda x, p: s.compliance_m3_per_pa(x) + 0 * p,
    )
    path = sealed_path(el, xs, Charge(0.112, 4e5, tr.volume_c_m3, n, v_r, 101325.0))
    assert np.allclose(path.overpressure_pa[0] / bar, tr.pressure_bar, rtol=1e-10)
    assert np.allclose(path.force_N[0], tr.force_N, rtol=1e-10)
    assert np.allclose(path.rate_N_per_m[0], tr.rate_N_per_m, rtol=1e-6)
    # the casing's compliance matters: the rate without it differs by more than that
    el0 = el._replace(dvolume_dp=lambda x, p: 0 * p)
    k0 = sealed_path(
        el0, np.array([0.112]), Charge(0.112, 4e5, tr.volume_c_m3, n, v_r, 101325.0)
    ).rate_N_per_m
    assert abs(k0[0, 0] / tr.rate_N_per_m[5] - 1) > 1e-3


def test_sealed_test_readings_and_refusals():
    a = simulate_sealed("n50-thermo", charge_bar=3.0, seed=4)
    b = simulate_sealed("n50-thermo", charge_bar=3.0, seed=4)
    assert np.array_equal(a.force_N, b.force_N) and a.height_m.size == 37
    rel = a.force_N / a.truth.force_N - 1
    # load cell 0.5 % and 0.02 mm of height on a rate of order 1e5 N/m
    assert 0.003 < np.std(rel) < 0.008 and abs(np.mean(rel)) < 0.004
    assert np.all(np.abs(a.pressure_bar - a.truth.pressure_bar) < 0.06)
    at_c = sealed_truth("n50-thermo", np.array([0.112]), charge_bar=3.0)
    assert at_c.pressure_bar[0] == pytest.approx(3.0, abs=1e-9)
    j = int(
        np.argmin(np.abs(a.height_m - 0.110))
    )  # compressed 2 mm further: a little more pressure
    assert 3.0 < a.truth.pressure_bar[j] < 3.1
    assert np.all(np.isfinite(a.truth.natural_frequency_Hz[a.truth.rate_N_per_m > 0]))
    with pytest.raises(InputError, match="no sealed truth"):
        simulate_sealed("n50-thermo", effects={"hysteresis": 0.01})
    # the traditional spring with an elastic casing has a sealed truth too (volume from its piston)
    tr = sealed_truth("n50-traditional", np.array([0.1, 0.112]), effects={"elastic_casing": 0.02})
    v = true_volume_m3(TraditionalSpring(), {"elastic_casing": 0.02}, np.array(0.155), 0.0)
    assert float(v) == pytest.approx(PAPER_STAND.element_volume_at_xmax_m3)
    assert tr.rate_N_per_m[1] > 0


def test_layout_campaign_of_thermo_spring_is_in_range():
    tests = simulate("n50-thermo", seed=1, layout=Layout(pressures_bar=(0.5, 12.0), step_m=0.01))
    assert [t["pressure_bar"] for t in tests] == [0.5, 12.0]
