"""``uq surface`` and ``uq margin`` on the bundled campaigns without piston readings: the
force-only stand (data/n50-force-only) and the catalogue table (data/n50-catalogue)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from cli_helpers import one_line, run

ROOT = Path(__file__).resolve().parents[2]
FORCE_ONLY = ROOT / "data" / "n50-force-only" / "recordings.csv"
CATALOGUE = ROOT / "data" / "n50-catalogue" / "recordings.csv"
QUICK = [
    "--max-steps",
    "300",
    "--allow-unconverged",
]  # a short chain: the shape of the output, not its precision
CAMPAIGNS = pytest.mark.parametrize(
    "path, why",
    [(FORCE_ONLY, "force-only campaign"), (CATALOGUE, "volume_* column (at 5 bar only)")],
    ids=["force-only", "catalogue"],
)


@CAMPAIGNS
def test_surface(path, why, tmp_path, capsys):
    """The force-only campaign without the comparison (uq margin makes it, test_margin); the
    catalogue compared on its force readings (its volume column left out of both models)."""
    out = tmp_path / "s.json"
    compare = [] if path == CATALOGUE else ["--no-compare"]
    assert run(["surface", path, *QUICK, *compare, "--json", out]) == 0
    text = capsys.readouterr().out
    omitted = [ln for ln in text.splitlines() if "volume results omitted" in ln]
    assert len(omitted) == 1 and why in omitted[0]
    assert ("PSIS-LOO: surface" in text) == (path == CATALOGUE)
    doc = json.loads(out.read_text())
    assert doc["orders"]["Dk"] == doc["orders"]["Dl"] == -1 and doc["orders_label"].endswith(
        "force only"
    )
    assert set(doc["omitted"]) == {
        "volume_excess_m2",
        "piston_reference_m",
        "sL_m",
        "V0_m3",
        "spread_N",
        "spread_credibly_nonzero_fraction",
    }
    if path == CATALOGUE:
        c = doc["comparison"]
        assert (
            c["unit"].startswith("log density per force reading") and "volume_* column" in c["note"]
        )
        assert c["cubics"]["n_coefficients"] == 4 * 5  # force-only cubics: the volume left out
    else:
        assert doc["comparison"] is None
    for r in doc["at_x0"].values():
        assert set(r) == {"pressure_area_m2", "feff_m2", "force_N"}


@CAMPAIGNS
def test_margin(path, why, tmp_path, capsys):
    """Between the tested pressures and heights (the catalogue's are 3..7 bar, every 10 mm): the
    pressure needed, the force band, a queries file; the omitted-volume line; the force surface
    compared with the per-pressure cubics per force reading."""
    queries = tmp_path / "q.csv"
    queries.write_text("height_mm,load_N,pressure_bar\n103,12000,4.5\n137,13000,6.5\n88,10000,\n")
    out = tmp_path / "m.json"
    assert run(["margin", path, *QUICK, "--queries", queries, "--json", out]) == 0
    text = capsys.readouterr().out
    assert "why: " in text
    assert sum("volume results omitted" in ln for ln in text.splitlines()) == 1
    rows = json.loads(out.read_text())
    assert len(rows) == 3 and all("refused" not in r for r in rows)
    for r in rows:
        e = r["pressure_bar_needed"]
        assert 3.0 < e["q05"] < e["mean"] < e["q95"] < 7.5
        assert why in r["model"]["omitted"]
        c = r["model"]["comparison"]
        assert c["unit"].startswith("log density per force reading")
        # a cubic a test, and the pressure sensor's offset where pressures are measured
        assert c["cubics"]["n_coefficients"] == (4 * 5 if path == CATALOGUE else 5 * 11)
    f = rows[0]["force_at_pressure"]["force_N"]
    assert f["q05"] < f["mean"] < f["q95"]


def test_design_margins_refused_for_force_only_before_fitting(capsys):
    argv = ["margin", FORCE_ONLY, "--height-mm", 112, "--load-N", 13000, "--volume-l", 5]
    assert run([*argv, "--max-frequency-hz", 2]) == 2
    err = one_line(capsys.readouterr().err)
    assert "option --max-frequency-hz" in err and "no piston readings" in err


def test_saved_force_surface_answers_and_refuses_design_margins(tmp_path, capsys):
    """--save-fit keeps the force surface (no piston references); --fit answers from it as the
    fit did and refuses a design margin in one line."""
    fit = tmp_path / "fit.nc"
    argv = ["--height-mm", 112, "--load-N", 13000]
    assert (
        run(["margin", CATALOGUE, *QUICK, *argv, "--save-fit", fit, "--json", tmp_path / "a.json"])
        == 0
    )
    # QUICK's short chains: the saved fit is unconverged too, and says so on every answer
    saved_argv = [*argv, "--allow-unconverged"]
    assert run(["margin", "--fit", fit, *saved_argv, "--json", tmp_path / "b.json"]) == 0
    capsys.readouterr()
    fresh, saved = (json.loads((tmp_path / n).read_text()) for n in ("a.json", "b.json"))
    assert "force only" in saved["model"]["label"]
    assert saved["pressure_bar_needed"] == pytest.approx(fresh["pressure_bar_needed"], rel=1e-12)
    assert run(["margin", "--fit", fit, *saved_argv, "--volume-l", 5, "--max-frequency-hz", 2]) == 2
    err = one_line(capsys.readouterr().err)
    assert "fitted to the force alone" in err
