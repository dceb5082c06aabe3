"""Design-margin queries (uq margin) on the surface model of data/n50."""

from __future__ import annotations

import json

import numpy as np
import pytest

from uq._errors import InputError
from uq._margin import margin
from uq._surface import fit_surface


@pytest.fixture(scope="module")
def n50_surface(n50_recordings):
    return fit_surface(n50_recordings, seed=20201)


def test_table1_force_at_x0_and_5_bar(n50_surface):
    res = margin(n50_surface, 0.112, 13020.0, 0.95)
    e = res["pressure_bar_needed"]
    assert e["q05"] <= 5.0 <= e["q95"], e
    assert res["pressure_bar_for_prob"] >= e["mean"]
    assert set(e) == {"mean", "sd", "q05", "q95"}


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
    with pytest.raises(InputError, match="--prob"):
        margin(n50_surface, 0.112, 13020.0, prob=1.5)


def test_cli_refuses_height(tmp_path, capsys):
    from uq.cli import main

    assert main(["margin", "data/n50/recordings.csv", "--height-mm", "300", "--load-N", "1000"]) == 2
    assert "outside the tested heights" in capsys.readouterr().err


@pytest.mark.slow
def test_cli_json(tmp_path):
    from uq.cli import main

    out = tmp_path / "m.json"
    assert main(["margin", "data/n50/recordings.csv", "--height-mm", "112", "--load-N", "13020", "--json", str(out)]) == 0
    d = json.loads(out.read_text())
    assert {"height_m", "load_N", "prob", "pressure_bar_needed", "pressure_bar_for_prob"} <= set(d)
    assert np.isclose(d["height_m"], 0.112)
