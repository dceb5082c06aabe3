"""The discrepancy surface's study scripts run with tiny settings (tests/test_scripts.py's rule):
scripts/between_coverage.py, scripts/between_decomposition.py and scripts/n50_bands.py."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]


def _run(*argv, timeout=900):
    return subprocess.run(
        [sys.executable, *map(str, argv)], cwd=ROOT, capture_output=True, text=True, timeout=timeout
    )


def test_between_coverage_tiny(tmp_path):
    """One campaign, three models, two heights by two pressures: counts by pressure and height
    with their exact intervals, and the summary page."""
    proc = _run("scripts/between_coverage.py", "--tiny", "--out", tmp_path)
    assert proc.returncode == 0, proc.stderr
    doc = json.loads((tmp_path / "coverage.json").read_text())
    assert doc["replications"] == {"n50-kink/1-3-5": 1} and doc["grids"] == ["1-3-5"]
    assert {r["model"] for r in doc["rows"]} == {"discrepancy", "surface", "cubics"}
    assert {(r["pressure_bar"], r["height_mm"]) for r in doc["rows"]} == {
        (p, h) for p in (2.0, 4.0) for h in (90.0, 150.0)
    }
    assert all(r["covered"] + r["refused"] <= 1 and 0 <= r["interval"][0] for r in doc["rows"])
    # the model check uq margin runs, per campaign: flagged or not, coverage with and without it
    check = doc["model_check"]["n50-kink/1-3-5"]
    assert check["campaigns"] == 1 and set(check) == {"campaigns", "discrepancy", "surface"}
    assert check["discrepancy"]["flagged"] in (0, 1)
    run = doc["runs"]["n50-kink/1-3-5"][0]
    assert set(run["check_misses"]) == {"discrepancy", "surface"}
    text = (tmp_path / "summary.md").read_text()
    assert "By pressure and height" in text and "## The model check" in text


def test_between_decomposition_tiny(tmp_path):
    """One campaign taken apart at the query and its two tested neighbours: the smooth surface's
    part and the deviation's add up to the band's force, and a pressure that is tested is refused
    with one line and status 2."""
    out = tmp_path / "decomposition.json"
    proc = _run("scripts/between_decomposition.py", "--tiny", "--out", out)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("RECONSTRUCTED")
    doc = json.loads(out.read_text())
    rows = doc["seeds"][0]["rows"]
    assert [(r["pressure_bar"], r["tested"]) for r in rows] == [
        (3.0, True),
        (4.5, False),
        (5.0, True),
    ]
    for r in rows:
        lo, hi = r["band_N"]
        centre = r["true_force_N"] + r["surface_minus_truth_N"] + r["deviation_N"]
        assert lo < centre < hi
        assert r["covered"] == (lo <= r["true_force_N"] <= hi)
    bad = _run("scripts/between_decomposition.py", "--tiny", "--pressure-bar", 3)
    assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1
    assert "--pressure-bar" in bad.stderr


def test_n50_bands_tiny(tmp_path):
    proc = _run("scripts/n50_bands.py", "--tiny", "--out", tmp_path)
    assert proc.returncode == 0, proc.stderr
    doc = json.loads((tmp_path / "n50-bands.json").read_text())
    assert doc["tested_33"]["discrepancy"]["of"] == 9  # 3 tests x 3 heights
    assert doc["between"]["surface"]["of"] == 6
    assert "Table 1's curves" in (tmp_path / "n50-bands.md").read_text()


def _script(name: str):
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, ROOT / "scripts" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_between_coverage_records_on_another_stand():
    """--stand: the campaign is recorded on that stand (same seed, other readings, its comments
    say so); the models are still fitted assuming the paper's budget (fit_models' PAPER_STAND)."""
    from uq._data.stand_description import read_stand

    bc = _script("between_coverage")
    rough = read_stand(ROOT / "data/stands/slow-pressure-control.toml")
    grid = bc.GRIDS["1-3-5"]
    paper = bc.campaign("n50-kink", grid, bc.FIRST_SEED, False)
    other = bc.campaign("n50-kink", grid, bc.FIRST_SEED, False, rough)
    assert [t.pressure_bar for t in other.tests] == [t.pressure_bar for t in paper.tests]
    assert other.n_points == paper.n_points
    f_paper = [t.force_N for t in paper.tests]
    f_other = [t.force_N for t in other.tests]
    assert not all(np.array_equal(a, b) for a, b in zip(f_paper, f_other, strict=True))
    assert any("error_df = 5" in c for c in other.comments)
    assert not any("error_df" in c for c in paper.comments)


def test_between_coverage_refuses_a_missing_stand_in_one_line(tmp_path):
    proc = _run("scripts/between_coverage.py", "--tiny", "--stand", tmp_path / "no.toml")
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "option --stand" in lines[0] and "no.toml" in lines[0]


def test_between_coverage_says_which_way_a_count_misses():
    """Over 40 replications: 40 covered excludes 0.90 from above (too wide), 30 from below (too
    narrow: the summary's bold), 36 neither."""
    bc = _script("between_coverage")

    def runs(covered: int):
        def q(hit):
            entry = {"force": {"covered": hit, "width_N": 1.0}, "margin": {"covered": hit}}
            return {"height_mm": 90.0, "pressure_bar": 2.0} | {m: entry for m in bc.MODELS}

        return [
            {
                "cpu_seconds": dict.fromkeys(bc.MODELS, 1.0),
                "converged": dict.fromkeys(bc.CHECKED, True),
                "queries": [q(i < covered)],
            }
            for i in range(40)
        ]

    rows = bc.summarise({"a/7": runs(40), "b/7": runs(30), "c/7": runs(36)})["rows"]
    side = {r["spring"]: r["side"] for r in rows if r["model"] == "discrepancy"}
    assert side == {"a": "above", "b": "below", "c": "inside"}
