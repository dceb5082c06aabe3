"""Design-margin queries (uq margin) on data/n50: the surface model, the per-pressure cubics
interpolated in pressure, and the choice between them."""

from __future__ import annotations

import json

import numpy as np
import pytest

from uq._derived.margin import choose, margin, pressure_needed
from uq._io.errors import InputError
from uq._models import registry
from uq._models.cubic_interpolation import CubicInterpolation


def test_table1_force_at_x0_and_5_bar(n50_surface):
    res = margin(n50_surface, 0.112, 13020.0, 0.95)
    e = res["pressure_bar_needed"]
    assert e["q05"] <= 5.0 <= e["q95"], e
    assert res["pressure_bar_for_prob"] >= e["mean"]
    assert set(e) == {"mean", "sd", "q05", "q95"}
    assert res["model"]["name"] == "surface" and "no comparison" in res["model"]["why"]


def test_force_band_and_stroke(n50_surface):
    res = margin(n50_surface, 0.112, 13020.0, 0.9, pressure_bar=5.0, tolerance_pct=10.0)
    f = res["force_at_pressure"]["force_N"]
    assert f["q05"] < 13020.0 * 1.01 and f["q95"] > 13020.0 * 0.99
    s = res["usable_stroke"]["stroke_credible"]
    assert s and s["from_m"] < 0.112 < s["to_m"]


def test_refusals(n50_surface):
    with pytest.raises(InputError, match="outside what the tested pressures"):
        margin(n50_surface, 0.112, 60000.0)
    with pytest.raises(InputError, match="outside the tested heights"):
        margin(n50_surface, 0.20, 13020.0)
    # the library names its own parameters (a notebook has no command-line options)
    with pytest.raises(InputError, match="^prob: ") as exc:
        margin(n50_surface, 0.112, 13020.0, prob=1.5)
    assert exc.value.param == "prob" and "--" not in str(exc.value)


def test_cli_refuses_height(tmp_path, capsys):
    from uq._cli.main import main

    assert (
        main(["margin", "data/n50/recordings.csv", "--height-mm", "300", "--load-N", "1000"]) == 2
    )
    assert "outside the tested heights" in capsys.readouterr().err


@pytest.mark.slow
def test_cli_json(tmp_path):
    from uq._cli.main import main

    out = tmp_path / "m.json"
    assert (
        main(
            [
                "margin",
                "data/n50/recordings.csv",
                "--height-mm",
                "112",
                "--load-N",
                "13020",
                "--json",
                str(out),
            ]
        )
        == 0
    )
    d = json.loads(out.read_text())
    assert {
        "height_m",
        "load_N",
        "prob",
        "pressure_bar_needed",
        "pressure_bar_for_prob",
        "model",
    } <= set(d)
    assert np.isclose(d["height_m"], 0.112)
    c = d["model"]["comparison"]
    default = registry.default("margin")
    assert d["model"]["name"] == ("cubics" if c["better"] == "per-pressure cubics" else default)


@pytest.fixture(scope="module")
def n50_cubics(n50_fit):
    return CubicInterpolation.of(n50_fit)


def test_cubic_interpolation_is_exact_at_tested_pressures(n50_cubics, n50_fit):
    """At a tested pressure the answer is that test's cubic, draw for draw, with no interpolation error."""
    xs = np.array([0.08, 0.112, 0.15])
    got = n50_cubics.force_draws(xs, 5.0)
    coef = n50_fit.at(5.0).flat("force")
    u = xs - n50_fit.recordings.x0_m
    want = coef[:, 0:1] + coef[:, 1:2] * u + coef[:, 2:3] * u**2 + coef[:, 3:4] * u**3
    assert got.mean(0) == pytest.approx(want.mean(0), rel=2e-4)
    assert got.std(0) == pytest.approx(want.std(0), rel=0.1)


def test_cubic_interpolation_error_between_tested_pressures(n50_cubics):
    """Between tested pressures the band carries the interpolation error: wider than the two
    neighbouring tests' posteriors alone, zero-mean, largest mid-interval."""
    x = np.array(0.14)
    mid = n50_cubics.force_draws(x, 4.5).ravel()
    z = n50_cubics.z.copy()
    n50_cubics.z[:] = 0.0
    try:
        no_err = n50_cubics.force_draws(x, 4.5).ravel()
    finally:
        n50_cubics.z[:] = z
    assert mid.std() > no_err.std()
    assert n50_cubics.curvature_sd(np.array([0.14]), np.array([4]))[0] > 0
    assert abs(mid.mean() - no_err.mean()) < 3 * mid.std() / np.sqrt(mid.size) + 1e-9 * abs(
        mid.mean()
    )


def test_margin_from_the_cubics(n50_cubics):
    res = margin(n50_cubics, 0.112, 13020.0, 0.95)
    e = res["pressure_bar_needed"]
    assert e["q05"] <= 5.0 <= e["q95"], e
    assert res["model"]["name"] == "cubics"
    # between tested pressures: Table 1's 4- and 5-bar forces at x0 bracket the answer
    res = margin(n50_cubics, 0.112, 0.5 * (10270.0 + 13020.0), 0.95)
    assert 4.0 < res["pressure_bar_needed"]["q05"] < res["pressure_bar_needed"]["q95"] < 5.0


def test_choice_follows_the_loo_verdict(n50_surface, n50_fit):
    def comparison(better):
        return {
            "better": better,
            "reason": f"made-up verdict {better}",
            "elpd_diff": -50.0,
            "elpd_diff_se": 10.0,
        }

    ans, info = choose(n50_surface, n50_fit, comparison("per-pressure cubics"))
    assert ans is n50_fit and "made-up verdict" in info["why"] and "interpolation" in info
    for verdict in ("indistinguishable", "refused", "surface"):
        ans, info = choose(n50_surface, n50_fit, comparison(verdict))
        assert (
            info["name"] == "surface"
            and info["comparison"]["better"] == verdict
            and "coverage" in info["why"]
        )
    res = margin(ans, 0.112, 13020.0, model_info=info)
    assert res["model"]["comparison"]["better"] == "surface"


@pytest.mark.slow
def test_cubic_interpolation_coverage(tmp_path):
    """The cubics' answer between tested pressures on the n50 spring (Table 1 cubics, PCHIP in
    pressure: the bundled data's truth): the 90 % interval of pressure_bar_needed at 4.5 bar
    covers the truth in a binomial region (UQ_COVERAGE_REPS, default 20; false failure < 1e-3)."""
    import os

    from scipy import stats

    from uq._data.recordings import read_recordings, write_recordings_csv
    from uq._models.cubic_fit import fit_campaign
    from uq._stand.simulator import N50Spring, simulate

    n = int(os.environ.get("UQ_COVERAGE_REPS", "20"))
    truth, p = N50Spring(), 4.5
    load = float(truth.force_N(np.array(0.112), p))
    covered = []
    for s in range(2000, 2000 + n):
        path = tmp_path / f"n50-{s}.csv"
        path.write_text(write_recordings_csv(simulate("n50", seed=s)))
        cub = fit_campaign(read_recordings(path), seed=s)
        q05, q95 = np.quantile(
            pressure_needed(CubicInterpolation.of(cub, seed=s), 0.112, load).values, [0.05, 0.95]
        )
        covered.append(bool(q05 <= p <= q95))
    b = stats.binom(n, 0.9)  # accepted counts: each tail <= 5e-4
    lo = min(k for k in range(n + 1) if b.cdf(k) > 5e-4)
    hi = max(k for k in range(n + 1) if b.sf(k - 1) > 5e-4)
    assert lo <= sum(covered) <= hi, covered


def test_pressure_needed_where_the_force_dips_away_from_the_load():
    """A force that falls with pressure at low pressures (the 0.1-bar test's negative force near
    x_max bends the cubics' interpolation) is no reason to refuse a load it reaches once; a load
    it reaches at two pressures is refused with that cause."""

    class Dip:
        height_range_m, pressure_range_bar = (0.065, 0.155), (0.1, 10.0)

        def check_range(self, *args):
            pass

        def force_draws(self, x, p):
            p = np.asarray(p, float)
            scale = np.linspace(0.99, 1.01, 50)[:, None]
            return scale * (1000.0 * p + 800.0 / p)  # falls below 0.894 bar, rises above

    d = pressure_needed(Dip(), 0.150, 9000.0).values  # crossed once, near 8.9 bar
    truth = [
        (9000.0 / s + np.sqrt((9000.0 / s) ** 2 - 4 * 1000 * 800)) / 2000 for s in (0.99, 1.01)
    ]
    assert np.all((d >= min(truth) - 0.02) & (d <= max(truth) + 0.02))
    with pytest.raises(InputError, match="more than one overpressure"):
        pressure_needed(Dip(), 0.150, 5000.0)  # down through 5000 N below 1 bar, up again at 4.2


def test_pressure_needed_widens_when_a_few_draws_cross_the_load_twice():
    """Up to NOT_RISING_MAX of the draws may cross the load more than once (a band between tested
    pressures that does not know the force rises there): each answers with its lowest crossing,
    and the share is returned; above that share the query is refused."""
    from uq._derived.margin import NOT_RISING_MAX

    class Bump:
        height_range_m, pressure_range_bar = (0.065, 0.155), (1.0, 10.0)

        def __init__(self, n_bumped):
            self.n_bumped = n_bumped

        def check_range(self, *args):
            pass

        def force_draws(self, x, p):
            p = np.asarray(p, float)
            bump = np.zeros((100, 1))
            bump[: self.n_bumped] = 3000.0  # up through 5000 N before 3 bar, down, up again at 5
            return 1000.0 * p + bump * np.exp(-(((p - 3.0) / 0.3) ** 2))

    d, share = pressure_needed(Bump(5), 0.15, 5000.0)
    assert share == pytest.approx(0.05)
    np.testing.assert_allclose(d[5:], 5.0, atol=0.02)  # the draws that rise: one crossing
    assert np.all((d[:5] > 2.0) & (d[:5] < 3.0))  # the lowest of their three crossings
    assert np.array_equal(pressure_needed(Bump(5), 0.15, 5000.0).values, d)
    n_refused = int(100 * NOT_RISING_MAX) + 1
    with pytest.raises(InputError, match="more than one overpressure in 11 %"):
        pressure_needed(Bump(n_refused), 0.15, 5000.0)
