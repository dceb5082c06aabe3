"""Calibration: coverage of the per-pressure intervals on simulations with known truth."""

from __future__ import annotations

import json

import pytest

from uq._calibrate import _region, calibrate
from uq.cli import main


def test_binomial_region_matches_the_issue():
    assert _region(100, 0.9) == (82, 97)


def test_fast_coverage_from_the_prior():
    """SBC setting: the model is exactly right, so 90 % intervals must cover about 90 %."""
    res = calibrate(12, truth="prior", seed=1)
    s = res.summary()
    covered = sum(q["covered90"] for q in s["quantities"].values())
    total = 12 * len(s["quantities"])
    # 132 intervals, nominal 118.8; correlated within a replication, so wide but failing bounds
    assert 0.78 * total <= covered <= 0.98 * total, covered
    assert s["converged_fraction"] == 1.0


def test_fast_coverage_on_the_n50_stand():
    res = calibrate(6, truth="n50", seed=2)
    covered = int(res.inside90.sum())
    assert 0.7 * res.inside90.size <= covered, covered
    pc = res.summary()["predictive_coverage90"]  # fresh readings, low and high forces alike
    assert 0.75 <= pc["low_force_third"] <= 1.0 and 0.75 <= pc["high_force_third"] <= 1.0, pc


def test_calibrate_cli_writes_results(tmp_path):
    assert main(["calibrate", "--reps", "2", "--truth", "n50", "--noise", "budget,constant", "--out", str(tmp_path)]) == 0
    res = json.loads((tmp_path / "calibration.json").read_text())
    assert [s["noise_model"] for s in res["settings"]] == ["budget", "constant"]
    assert (tmp_path / "calibration.md").exists() and (tmp_path / "sbc_n50_budget.png").exists()
    assert main(["calibrate", "--reps", "1", "--truth", "bogus"]) == 2


@pytest.mark.slow
def test_full_calibration_suite(tmp_path):
    """100 replications per setting: coverage inside the 99 % binomial region for every coefficient."""
    res = calibrate(100, truth="prior", seed=3).summary()
    bad = [k for k, q in res["quantities"].items() if not (q["in_region90"] and q["in_region50"])]
    assert not bad, bad
