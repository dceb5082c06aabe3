"""Derived quantities with bands (uq._bands): exact checks on Table 1, coverage on the n50 fit."""

from __future__ import annotations

import numpy as np
import pytest

from uq._bands import bands_from_coefficients, campaign_bands, choose_reference, feff_scatter
from uq._reference import PAPER_PISTON_AREA_M2, PAPER_X0_M, cubic, table1

X_GRID = np.linspace(0.065, 0.155, 181)


@pytest.fixture(scope="module")
def paper_bands():
    """Table 1 itself as a one-draw 'posterior'."""
    t = table1()
    return bands_from_coefficients(t.pressures_bar, t.force[:, None, :], t.piston[:, None, :], x_grid=X_GRID,
                                   x0_m=PAPER_X0_M, piston_area_m2=PAPER_PISTON_AREA_M2)


def test_feff_at_x0_is_a_over_p(paper_bands):
    t = table1()
    i0 = int(np.argmin(np.abs(X_GRID - PAPER_X0_M)))
    assert X_GRID[i0] == pytest.approx(PAPER_X0_M)
    for k, tb in enumerate(paper_bands.tests):
        expected = t.force[k, 0] / (t.pressures_bar[k] * 1e5)
        assert tb.feff.mean[i0] == pytest.approx(expected, rel=1e-9)
        assert tb.at_x0["feff_m2"]["mean"] == pytest.approx(expected, rel=1e-12)
    assert paper_bands.at(10).at_x0["feff_m2"]["mean"] == pytest.approx(0.02857, rel=1e-3)


def test_traditional_from_own_volume_curve_at_x0(paper_bands):
    t = table1()
    i0 = int(np.argmin(np.abs(X_GRID - PAPER_X0_M)))
    for k, tb in enumerate(paper_bands.tests):
        expected = t.pressures_bar[k] * 1e5 * (-PAPER_PISTON_AREA_M2 * t.piston[k, 1])
        assert tb.trad_own.mean[i0] == pytest.approx(expected, rel=1e-9)
        assert tb.at_x0["trad_own_N"]["mean"] == pytest.approx(expected, rel=1e-12)


def test_spread_at_x0_matches_physics_md(paper_bands):
    # PHYSICS.md: own volume curve 12-14 % above at 1..10 bar, 22 % at 0.1 bar;
    # 5-bar volume curve: ~21 % at 1 bar, 12 % at 5 bar, 2.5 % at 10 bar.
    own = {tb.pressure_bar: tb.at_x0["spread_own_pct"]["mean"] for tb in paper_bands.tests}
    ref = {tb.pressure_bar: tb.at_x0["spread_ref_pct"]["mean"] for tb in paper_bands.tests}
    assert own[0.1] == pytest.approx(22.3, abs=0.1)
    assert all(11.5 < own[p] < 14.5 for p in own if p >= 1)
    assert paper_bands.reference_bar == 5.0
    assert ref[1.0] == pytest.approx(21.3, abs=0.1)
    assert ref[5.0] == pytest.approx(12.4, abs=0.1)
    assert ref[10.0] == pytest.approx(2.46, abs=0.05)
    i0 = int(np.argmin(np.abs(X_GRID - PAPER_X0_M)))
    tb = paper_bands.at(10)
    assert tb.spread_ref.mean[i0] == pytest.approx(tb.trad_ref.mean[i0] - tb.force.mean[i0])


def test_feff_scatter_matches_table1_numbers(paper_bands):
    sc = paper_bands.scatter_at
    assert paper_bands.scatter_pressures_bar == [float(p) for p in range(1, 11)]
    assert sc["x0"]["mean"] == pytest.approx(8.41, abs=0.005)
    assert sc["x_max"]["mean"] == pytest.approx(26.3, abs=0.05)
    assert sc["x_min"]["height_m"] == pytest.approx(0.065)
    assert sc["x_min"]["mean"] == pytest.approx(9.74, abs=0.005)
    assert sc["75 mm"]["mean"] == pytest.approx(8.51, abs=0.01)
    # the band on the grid agrees with the point values at its ends
    assert paper_bands.scatter.mean[-1] == pytest.approx(sc["x_max"]["mean"])
    assert paper_bands.scatter.mean[0] == pytest.approx(sc["x_min"]["mean"])


def test_volume_increment_is_zero_at_x_max_and_positive_below(paper_bands):
    for tb in paper_bands.tests:
        assert tb.dV.mean[-1] == pytest.approx(0.0, abs=1e-15)
        assert np.all(tb.dV.mean[:-1] > 0)


def test_feff_scatter_definition():
    f = np.array([[1.0, 2.0], [3.0, 2.0]])  # two tests, two heights
    np.testing.assert_allclose(feff_scatter(f), [50.0, 0.0])


def test_reference_without_5_bar_uses_middle_of_range():
    i, note = choose_reference([1.0, 3.0, 4.0, 10.0])
    assert i == 2 and "nearest to the middle" in note and "4-bar" in note
    i, note = choose_reference([1.0, 5.0, 10.0])
    assert i == 1 and "Figure 5" in note


def test_bands_contain_truth_for_n50(n50_fit):
    cb = campaign_bands(n50_fit, n_draws=1000, seed=1)
    t = table1()
    assert cb.n_draws == 1000 and len(cb.x_m) == 181
    cover, cover_pred, cover_dV = [], [], []
    for tb in cb.tests:
        k = t.index(tb.pressure_bar)
        u = cb.x_m - cb.x0_m
        truth = cubic(t.force[k], u)
        cover.append(tb.force.contains(truth).mean())
        cover_pred.append(tb.force_pred.contains(truth).mean())
        dV_true = cb.piston_area_m2 * (cubic(t.piston[k], u) - cubic(t.piston[k], np.array(tb.x_max_m - cb.x0_m)))
        cover_dV.append(tb.dV.contains(dV_true).mean())
        assert np.all(tb.force_pred.lo <= tb.force.lo + 1e-9) and np.all(tb.force_pred.hi >= tb.force.hi - 1e-9)
    assert np.mean(cover) > 0.7, cover
    assert np.mean(cover_pred) > 0.97, cover_pred
    assert np.mean(cover_dV) > 0.7, cover_dV
    # the scatter's 90 % interval at x0 is within a point of Table 1's 8.41 %
    sc = cb.scatter_at["x0"]
    assert sc["q05"] - 1.0 < 8.41 < sc["q95"] + 1.0
    assert cb.seed == 1 and cb.summary()["feff_scatter_pct"]["at"]["x0"]["mean"] == sc["mean"]


def test_bands_are_seeded(n50_fit):
    a = campaign_bands(n50_fit, n_draws=200, n_grid=21, seed=3)
    b = campaign_bands(n50_fit, n_draws=200, n_grid=21, seed=3)
    np.testing.assert_array_equal(a.tests[4].force_pred.hi, b.tests[4].force_pred.hi)
    assert a.scatter_at["x0"] == b.scatter_at["x0"]
