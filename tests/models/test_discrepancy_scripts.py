"""The discrepancy surface's study scripts run with tiny settings (tests/test_scripts.py's rule):
scripts/between_coverage.py and scripts/n50_bands.py."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

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
    assert "By pressure and height" in (tmp_path / "summary.md").read_text()


def test_n50_bands_tiny(tmp_path):
    proc = _run("scripts/n50_bands.py", "--tiny", "--out", tmp_path)
    assert proc.returncode == 0, proc.stderr
    doc = json.loads((tmp_path / "n50-bands.json").read_text())
    assert doc["tested_33"]["discrepancy"]["of"] == 9  # 3 tests x 3 heights
    assert doc["between"]["surface"]["of"] == 6
    assert "Table 1's curves" in (tmp_path / "n50-bands.md").read_text()
