"""Derived quantities with bands (uq._derived.bands): exact checks on Table 1, coverage on the n50 fit."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from uq._data.reference import PAPER_PISTON_AREA_M2, PAPER_X0_M, cubic, table1
from uq._derived.bands import (
    bands_from_coefficients,
    campaign_bands,
    choose_reference,
    feff_scatter,
)

X_GRID = np.linspace(0.065, 0.155, 181)


def _table1_bands(**options):
    """The bands of Table 1 itself as a one-draw 'posterior' (``options`` to the bands)."""
    t = table1()
    return bands_from_coefficients(
        t.pressures_bar,
        t.force[:, None, :],
        t.piston[:, None, :],
        x_grid=X_GRID,
        x0_m=PAPER_X0_M,
        piston_area_m2=PAPER_PISTON_AREA_M2,
        **options,
    )


@pytest.fixture(scope="module")
def paper_bands():
    """Table 1 itself as a one-draw 'posterior'."""
    return _table1_bands()


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
    # expected from the paper: own volume curve 12-14 % above at 1..10 bar, 22 % at 0.1 bar;
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
        dV_true = cb.piston_area_m2 * (
            cubic(t.piston[k], u) - cubic(t.piston[k], np.array(tb.x_max_m - cb.x0_m))
        )
        cover_dV.append(tb.dV.contains(dV_true).mean())
        assert np.all(tb.force_pred.lo <= tb.force.lo + 1e-9) and np.all(
            tb.force_pred.hi >= tb.force.hi - 1e-9
        )
    assert np.mean(cover) > 0.7, cover
    assert np.mean(cover_pred) > 0.97, cover_pred
    assert np.mean(cover_dV) > 0.7, cover_dV
    # the scatter's 90 % interval at x0 is within a point of Table 1's 8.41 %
    sc = cb.scatter_at["x0"]
    assert sc["q05"] - 1.0 < 8.41 < sc["q95"] + 1.0
    assert cb.seed == 1 and cb.to_json()["feff_scatter_pct"]["at"]["x0"]["mean"] == sc["mean"]


def test_bands_are_seeded(n50_fit):
    a = campaign_bands(n50_fit, n_draws=200, n_grid=21, seed=3)
    b = campaign_bands(n50_fit, n_draws=200, n_grid=21, seed=3)
    np.testing.assert_array_equal(a.tests[4].force_pred.hi, b.tests[4].force_pred.hi)
    assert a.scatter_at["x0"] == b.scatter_at["x0"]


# --------------------------------------------------------------------------- pointwise vs simultaneous
#
# Binomial tolerances: each count below is allowed a two-sided region that a correct band
# leaves with probability < 1e-3 (the test's own false-failure rate), from scipy.stats.binom.

TABLE1_POINTS = Path(__file__).resolve().parents[2] / "fits" / "n50" / "table1_points.json"


def _region(n: int, q: float, level: float = 1e-3) -> tuple[int, int]:
    """[lo, hi] with P(X < lo) + P(X > hi) < level for X ~ Binomial(n, q)."""
    from scipy.stats import binom

    lo, hi = int(binom.ppf(level / 2, n, q)), int(binom.isf(level / 2, n, q))
    while binom.cdf(lo - 1, n, q) + binom.sf(hi, n, q) >= level:
        lo, hi = lo - 1, hi + 1
    return lo, hi


def _gaussian_draws(pressures, n, rng):
    """Coefficient draws about Table 1 with the covariance of the paper's own estimator."""
    doc = {t["pressure_bar"]: t for t in json.loads(TABLE1_POINTS.read_text())["tests"]}
    t = table1()
    F, L = [], []
    for p in pressures:
        k = t.index(p)
        F.append(rng.multivariate_normal(t.force[k], doc[p]["covariance"]["force"], n))
        L.append(rng.multivariate_normal(t.piston[k], doc[p]["covariance"]["piston"], n))
    return np.stack(F), np.stack(L)


def _curves(force, piston, p_bar, u):
    """F_eff and spread (own volume curve) of coefficient draws (D, 4) on u (G,): (D, G) each."""
    P = force[:, :1] + u * (force[:, 1:2] + u * (force[:, 2:3] + u * force[:, 3:4]))
    dLdx = piston[:, 1:2] + u * (2 * piston[:, 2:3] + 3 * u * piston[:, 3:4])
    return P / (p_bar * 1e5), p_bar * 1e5 * (-PAPER_PISTON_AREA_M2 * dLdx) - P


def test_simultaneous_band_holds_whole_draw_curves_and_pointwise_does_not():
    """(a) On 2000 draws: >= 90 % of the whole curves inside the simultaneous band (by
    construction), far fewer inside the pointwise band; on 2000 fresh draws of the same
    posterior the simultaneous share is 0.90 +/- 0.04. Its sd is sqrt(2 x 0.09 / 2000) = 0.0095
    (binomial sd of the fresh share, doubled in variance because the band's critical value is
    itself a quantile of 2000 draws), so 0.04 is 4.2 sd: P(outside) = 3e-5 per comparison,
    2e-4 for the six."""
    rng = np.random.default_rng(11)
    pressures = (1.0, 5.0, 10.0)
    F, L = _gaussian_draws(pressures, 2000, rng)
    cb = bands_from_coefficients(
        pressures, F, L, x_grid=X_GRID, x0_m=PAPER_X0_M, piston_area_m2=PAPER_PISTON_AREA_M2
    )
    F2, L2 = _gaussian_draws(pressures, 2000, rng)
    u = X_GRID - PAPER_X0_M
    for k, tb in enumerate(cb.tests):
        for name, curves, fresh in zip(
            ("feff", "spread_own"),
            _curves(F[k], L[k], tb.pressure_bar, u),
            _curves(F2[k], L2[k], tb.pressure_bar, u),
            strict=True,
        ):
            sim, pw = tb.simultaneous[name], getattr(tb, name)
            assert sim.contains_curve(curves).mean() >= 0.9
            assert (
                np.all(pw.contains(curves), axis=1).mean() < 0.8
            )  # pointwise: a band per height, not per curve
            assert abs(sim.contains_curve(fresh).mean() - 0.9) <= 0.04, (tb.pressure_bar, name)
            assert (
                1.8 < sim.critical < 3.5
                and np.all(sim.lo <= pw.lo + 1e-12)
                and np.all(sim.hi >= pw.hi - 1e-12)
            )


def _plugin_draws(test, x0_m, n, rng):
    """Closed-form posterior of the coefficients at the noise mode (the sampler's exact
    conditional draws without the noise parameters' spread): (n, 4) force and piston draws."""
    from uq._data.stand_description import PAPER_STAND
    from uq._inference.collapsed import find_map
    from uq._inference.float64 import jnp
    from uq._inference.linear import posterior_cov
    from uq._models.cubic import MODEL, conditional_posteriors, prepare
    from uq._physics.quantities import BASIS_SCALE_M

    data = prepare(test, x0_m, "budget", PAPER_STAND)[0]
    theta = jnp.asarray(find_map(MODEL, data).theta)
    D = np.diag(1.0 / BASIS_SCALE_M ** np.arange(4))
    return [
        rng.multivariate_normal(
            D @ np.asarray(post.mean), D @ np.asarray(posterior_cov(post)) @ D, n
        )
        for post in conditional_posteriors(theta, data)
    ]


def _truth_coverage(seeds, pressure_bar: float = 5.0, n_draws: int = 1000):
    """Per seed: does the known truth's whole F_eff / spread curve lie inside the simultaneous
    band (and inside the pointwise band)? Returns counts (sim_feff, sim_spread, pw_feff)."""
    from uq._stand.simulator import Layout, N50Spring, simulate

    spring, x = N50Spring(), X_GRID
    truth_feff = spring.force_N(x, pressure_bar) / (pressure_bar * 1e5)
    truth_spread = pressure_bar * 1e5 * (
        -PAPER_PISTON_AREA_M2 * spring.piston_slope(x, pressure_bar)
    ) - spring.force_N(x, pressure_bar)
    counts = np.zeros(3, int)
    for seed in seeds:
        sim = simulate("n50", seed=seed, layout=Layout(pressures_bar=(pressure_bar,)))[0]
        test = SimpleNamespace(
            height_m=sim["height_m"], force_N=sim["force_N"], piston_m=sim["piston_m"]
        )
        F, L = _plugin_draws(test, PAPER_X0_M, n_draws, np.random.default_rng(seed))
        tb = bands_from_coefficients(
            (pressure_bar,),
            F[None],
            L[None],
            x_grid=x,
            x0_m=PAPER_X0_M,
            piston_area_m2=PAPER_PISTON_AREA_M2,
        ).tests[0]
        counts += [
            tb.simultaneous["feff"].contains_curve(truth_feff),
            tb.simultaneous["spread_own"].contains_curve(truth_spread),
            np.all(tb.feff.contains(truth_feff)),
        ]
    return counts


def test_simultaneous_band_covers_the_known_truth_as_claimed():
    """(b) 60 simulated 5-bar tests: the truth's whole F_eff and spread curves lie inside the
    simultaneous 90 % band in at least 45 of them (P(X < 45) < 1e-3 at 90 %; no upper limit
    at n = 60); the pointwise band holds the whole F_eff curve much less often (below 45)."""
    n = 60
    lo, hi = _region(n, 0.9)
    assert (lo, hi) == (45, 60)
    sim_feff, sim_spread, pw_feff = _truth_coverage(range(300, 300 + n))
    assert lo <= sim_feff <= hi and lo <= sim_spread <= hi, (sim_feff, sim_spread)
    assert pw_feff < lo, pw_feff


@pytest.mark.slow
def test_simultaneous_band_coverage_400_replications():
    n = 400
    lo, hi = _region(n, 0.9)
    sim_feff, sim_spread, pw_feff = _truth_coverage(range(1000, 1000 + n), pressure_bar=8.0)
    assert lo <= sim_feff <= hi and lo <= sim_spread <= hi and pw_feff < lo, (
        sim_feff,
        sim_spread,
        pw_feff,
        lo,
        hi,
    )


def test_curve_bands_in_the_json_summary(paper_bands):
    rng = np.random.default_rng(2)
    F, L = _gaussian_draws((5.0,), 500, rng)
    cb = bands_from_coefficients(
        (5.0,), F, L, x_grid=X_GRID, x0_m=PAPER_X0_M, piston_area_m2=PAPER_PISTON_AREA_M2
    )
    cv = cb.to_json()["curve_bands"]
    assert (
        len(cv["height_m"]) == 19
        and cv["height_m"][0] == pytest.approx(0.065)
        and cv["level"] == 0.9
    )
    assert "pointwise" in cv["pointwise"] and "whole curve" in cv["simultaneous"]
    row = cv["tests"][0]["feff_m2"]
    assert np.all(np.asarray(row["simultaneous_lo"]) < np.asarray(row["pointwise_q05"]))
    assert "pointwise" in cb.to_json()["intervals"]


def test_predictive_bands_use_one_block_of_normals_per_campaign():
    """The curves are made one test at a time, but the predictive draws' normals are the seed's
    stream as one (2, tests, draws, grid) block, force's then piston's: every test's predictive
    band is the one computed from that block directly (so the per-test path changed no band)."""
    t = table1()
    rng = np.random.default_rng(5)
    D, x = 300, np.linspace(0.07, 0.15, 41)
    force = t.force[:, None, :] * (1.0 + 1e-3 * rng.standard_normal((t.force.shape[0], D, 1)))
    piston = t.piston[:, None, :] * (1.0 + 1e-3 * rng.standard_normal((t.force.shape[0], D, 1)))
    noise = np.broadcast_to([20.0, 0.004, 2e-5], (t.force.shape[0], D, 3))
    cb = bands_from_coefficients(
        t.pressures_bar,
        force,
        piston,
        x_grid=x,
        x0_m=PAPER_X0_M,
        piston_area_m2=PAPER_PISTON_AREA_M2,
        noise=noise,
        seed=11,
    )
    z = np.random.default_rng(11).standard_normal((2, t.force.shape[0], D, x.size))
    u = x - PAPER_X0_M
    for k, tb in enumerate(cb.tests):
        P = cubic(force[k][:, None, :], u)
        L = cubic(piston[k][:, None, :], u)
        P_pred = P + np.sqrt(20.0**2 + (0.004 * np.abs(P)) ** 2) * z[0, k]
        L_pred = L + 2e-5 * z[1, k]
        lo, hi = np.quantile(P_pred, [0.05, 0.95], axis=0)
        # the normals are read test by test, by two generators on that one stream
        np.testing.assert_allclose(tb.force_pred.lo, lo, rtol=1e-12)
        np.testing.assert_allclose(tb.force_pred.hi, hi, rtol=1e-12)
        np.testing.assert_allclose(tb.piston_pred.mean, L_pred.mean(axis=0), rtol=1e-12)
        np.testing.assert_allclose(tb.piston_pred.lo, np.quantile(L_pred, 0.05, axis=0), rtol=1e-12)


def test_scatter_band_is_feff_scatter_of_every_tests_curves():
    """The scatter is summed up test by test (largest, smallest, sum) instead of from every
    test's F_eff curves at once: the same numbers to the bit as feff_scatter of the stacked curves."""
    t = table1()
    rng = np.random.default_rng(3)
    D, x = 200, np.linspace(0.07, 0.15, 31)
    force = t.force[:, None, :] * (1.0 + 1e-3 * rng.standard_normal((t.force.shape[0], D, 1)))
    cb = bands_from_coefficients(
        t.pressures_bar,
        force,
        None,
        x_grid=x,
        x0_m=PAPER_X0_M,
        piston_area_m2=PAPER_PISTON_AREA_M2,
    )
    sel = np.asarray(t.pressures_bar) >= 1.0
    p_pa = np.asarray(t.pressures_bar)[sel] * 1e5
    feff = cubic(force[sel][:, :, None, :], x - PAPER_X0_M) / p_pa[:, None, None]
    s, a = feff_scatter(feff), (1.0 - 0.9) / 2.0  # the tails as the bands compute them
    np.testing.assert_array_equal(cb.scatter.mean, s.mean(axis=0))
    np.testing.assert_array_equal(cb.scatter.lo, np.quantile(s, a, axis=0))
    np.testing.assert_array_equal(cb.scatter.hi, np.quantile(s, 1.0 - a, axis=0))


def test_on_test_gets_each_tests_bands_as_they_are_made():
    """on_test(t, bands, grid) is called once per test, in order, with the PressureBands the
    campaign's bands then hold, and the grid a figure of them needs."""
    seen = []
    cb = _table1_bands(on_test=lambda i, tb, grid: seen.append((i, tb, grid)))
    assert [i for i, _, _ in seen] == list(range(len(cb.tests)))
    assert all(tb is cb.tests[i] for i, tb, _ in seen)
    grid = seen[0][2]
    assert grid.x_m is cb.x_m and grid.x0_m == cb.x0_m and grid.reference_bar == cb.reference_bar
