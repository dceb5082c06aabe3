"""The Maxwell check (uq/_diagnose/maxwell.py): quiet where force and volume come from one
potential, "every pressure alike" for a piston-area error, "fades with pressure" on Table 1."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np

import uq
from uq._diagnose.maxwell import _derivative_weights, campaign_table

ROOT = Path(__file__).resolve().parents[2]
LAYOUT = uq.Layout(pressures_bar=(1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0))


def test_derivative_weights_are_exact_for_a_quadratic():
    p = np.array([0.1, 1.0, 2.0])
    f = 3.0 + 2.0 * p - 0.5 * p**2
    for at in p:
        assert np.isclose(_derivative_weights(p, at) @ f, 2.0 - at, rtol=1e-12)


def test_quiet_on_the_stands_potential_spring():
    """n50-thermo: force and volume from one potential, so the relation holds; with 8 tests x 5
    bands at p < 0.001 each, more than one breaking band would be a false alarm (P < 0.001)."""
    t = campaign_table(uq.simulate("n50-thermo", seed=31, layout=LAYOUT), seed=1)
    assert sum(r["breaks"] for r in t["rows"]) <= 1, [r for r in t["rows"] if r["breaks"]]
    assert t["interpretation"]["middle"]["pattern"] == "holds"


def test_a_piston_area_error_breaks_it_alike_at_every_pressure():
    """The same recordings read with a piston area 8 % too large: dV/dx exceeds dP/dp_u by 8 % at
    every pressure, which the check reads as a piston-area error, not relaxation."""
    rec = uq.simulate("n50-thermo", seed=32, layout=LAYOUT)
    wrong = dataclasses.replace(rec, piston_area_m2=rec.piston_area_m2 * 1.08)
    middle = campaign_table(wrong, seed=1)["interpretation"]["middle"]
    assert middle["pattern"] == "every pressure alike", middle
    levels = np.array(list(middle["mean_r_by_pressure"].values()))
    assert np.all(np.abs(levels - 0.08) < 0.02), levels


def test_table1_committed_report_fades_with_pressure():
    """reports/maxwell-table1 (scripts/maxwell_table1.py on Table 1 and its covariance): in the
    middle of the stroke dV/dx exceeds dP/dp_u at 1-5 bar and the excess fades with pressure."""
    res = json.loads((ROOT / "reports" / "maxwell-table1" / "maxwell.json").read_text())
    middle = res["interpretation"]["middle"]
    assert middle["pattern"] == "fades with pressure"
    assert {1.0, 2.0, 3.0, 4.0, 5.0} <= set(middle["breaks_at_bar"])
    assert "relaxation" in res["interpretation"]["words"]
