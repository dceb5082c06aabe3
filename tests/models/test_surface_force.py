"""The force surface: the surface model of campaigns without piston readings (force-only stands,
catalogue tables; uq/_models/surface_force.py), its orders, its JSON and its margins against the
stand's truth."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from uq._derived.margin import margin, pressure_needed
from uq._inference.sampler import Settings
from uq._io.errors import InputError
from uq._models.surface import DEFAULT_ORDERS, Orders, default_orders, orders_for
from uq._models.surface_likelihood import fit_surface
from uq._stand.shapes import catalogue_recordings
from uq._stand.simulator import SPRINGS, Layout

ROOT = Path(__file__).resolve().parents[2]
CATALOGUE_LAYOUT = Layout(pressures_bar=(3.0, 4.0, 5.0, 6.0, 7.0), step_m=0.010)
#: between the tabulated pressures (3..7 bar) and heights (every 10 mm)
BETWEEN = ((0.080, 3.5), (0.100, 4.5), (0.112, 5.5), (0.140, 6.5))


@pytest.fixture(scope="module")
def catalogue_fit():
    """data/n50-catalogue as the stand makes it (its seed and command), fitted once."""
    rec = catalogue_recordings("n50", seed=20201, layout=CATALOGUE_LAYOUT, volume_at_bar=5.0)
    return fit_surface(rec, seed=1, settings=Settings(max_steps=2000))


def test_the_helper_makes_the_bundled_catalogue():
    """catalogue_recordings is ``uq simulate --catalogue``: the bundled file's readings exactly."""
    from uq._data.recordings import read_recordings

    made = catalogue_recordings("n50", seed=20201, layout=CATALOGUE_LAYOUT, volume_at_bar=5.0)
    bundled = read_recordings(ROOT / "data" / "n50-catalogue" / "recordings.csv")
    assert len(made.tests) == len(bundled.tests) == 5
    for a, b in zip(made.tests, bundled.tests, strict=True):
        assert np.array_equal(a.height_m, b.height_m) and np.array_equal(a.force_N, b.force_N)
        assert (a.volume_m3 is None) == (b.volume_m3 is None)
        if a.volume_m3 is not None:
            assert np.array_equal(a.volume_m3, b.volume_m3)


def test_default_orders_leave_each_test_residuals():
    """Few heights a test (a catalogue table): the height degree stays below the heights and
    leaves a residual per test; the paper's two-branch tests keep the default."""
    assert default_orders(11, min_heights=19, min_points=37) == DEFAULT_ORDERS
    assert default_orders(5, min_heights=10, min_points=10, volume=False) == Orders(3, 3, 3, -1, -1)
    assert default_orders(5, min_heights=5, min_points=5, volume=False).K == 3
    o = default_orders(4, min_heights=4, min_points=4, volume=False)
    assert (o.K, o.Ke, o.Lp) == (2, 2, 2)
    # 4 heights on two branches: 8 readings a test, the cubic stays
    assert default_orders(11, min_heights=4, min_points=8).K == 3


def test_too_small_a_table_is_refused_naming_what_is_short():
    """Two tests of six heights: 12 readings for 8 force coefficients and 3 noise terms."""
    import dataclasses

    full = catalogue_recordings("n50", seed=1, layout=CATALOGUE_LAYOUT)
    six = [
        dataclasses.replace(
            t,
            height_m=t.height_m[:6],
            force_N=t.force_N[:6],
            rows=t.rows[:6],
            measured_pressure_bar=t.measured_pressure_bar[:6],
        )
        for t in (full.tests[0], full.tests[-1])
    ]
    rec = dataclasses.replace(full, tests=tuple(six))
    assert orders_for(rec) == Orders(3, 0, 3, -1, -1)
    with pytest.raises(
        InputError, match=r"12 readings cannot fix .* 8 coefficients .* at least 13"
    ):
        fit_surface(rec)


def test_catalogue_surface_json_and_volume_omitted(catalogue_fit):
    fit = catalogue_fit
    assert fit.force_only and fit.orders == Orders(3, 3, 3, -1, -1)
    assert fit.convergence.converged
    doc = fit.to_json()
    assert "spread_credibly_nonzero_fraction" not in doc and "sL_m" not in doc["noise"]
    assert set(doc["coefficients"]) == {"pressure_area_m2", "casing_N"}
    assert set(doc["noise"]) == {"s0_N", "rel_load", "k_p"}
    assert all("spread_N" not in r for r in doc["at_x0"].values())
    reasons = set(doc["omitted"].values())
    assert len(reasons) == 1 and "volume_* column (at 5 bar only)" in reasons.pop()
    with pytest.raises(InputError, match="volume results omitted"):
        fit.volume_area_draws(0.112, 5.0)
    assert not fit.has_volume and "volume_* column" in fit.omitted_reason


def test_catalogue_margin_covers_the_stand_between_tabulated_points(catalogue_fit):
    """The stand knows its spring's force everywhere: between the tabulated pressures and heights
    the pressure needed for the true force there is the query's pressure, and lies within the
    99 % interval (one replication; scripts/margin_coverage.py --grids catalogue counts coverage
    over many)."""
    truth = SPRINGS["n50"]()
    ans = catalogue_fit
    for h, p in BETWEEN:
        load = float(truth.force_N(np.array(h), p))
        need = pressure_needed(ans, h, load).values
        lo, hi = np.quantile(need, [0.005, 0.995])
        assert lo <= p <= hi, (h, p, lo, hi)
        assert hi - lo < 0.3, (h, p, lo, hi)  # a band, not a shrug
        force = ans.force_draws(np.array(h), p)
        assert np.quantile(force, 0.005) <= load <= np.quantile(force, 0.995), (h, p)
    res = margin(ans, 0.100, 12000.0, 0.95, pressure_bar=4.5, model_info={"name": "surface"})
    assert 3.0 < res["pressure_bar_needed"]["mean"] < 7.0
