"""Calibration: coverage of the per-pressure intervals on simulations with known truth."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.stats import binom

from uq._cli.main import main
from uq._drivers.calibrate import CalibrationResult, _region, calibrate, markdown


def test_binomial_region_matches_the_issue():
    assert _region(100, 0.9) == (82, 97)


# Every statistical assertion below fails with probability below FALSE_FAILURE when the code is
# right: binomial acceptance regions (scipy.stats.binom), Bonferroni-split over the quantities.
FALSE_FAILURE = 1e-3


def _accept(n: int, p: float, alpha: float) -> tuple[int, int]:
    """Counts k with P(X < k) <= alpha/2 and P(X > k) <= alpha/2 excluded, X ~ Binomial(n, p)."""
    return int(binom.ppf(alpha / 2, n, p)), int(binom.isf(alpha / 2, n, p))


def test_acceptance_region_has_the_stated_false_failure_rate():
    lo, hi = _accept(12, 0.9, FALSE_FAILURE)
    assert binom.cdf(lo - 1, 12, 0.9) + binom.sf(hi, 12, 0.9) <= FALSE_FAILURE


def test_fast_coverage_from_the_prior():
    """SBC setting: the model is exactly right, so for each quantity the number of the 12
    independent replications whose 50 % / 90 % interval covers the truth is Binomial(12, 0.5 / 0.9);
    and the sampler converges (rules of uq/_inference/sampler.py) in at least 95 % of fits."""
    reps = 12
    res = calibrate(reps, truth="prior", seed=1)
    s = res.summary()
    q = s["quantities"]
    alpha = FALSE_FAILURE / (2 * len(q) + 1)  # Bonferroni over 2 levels x quantities + convergence
    lo90, hi90 = _accept(reps, 0.9, alpha)
    lo50, hi50 = _accept(reps, 0.5, alpha)
    bad = {
        k: (v["covered50"], v["covered90"])
        for k, v in q.items()
        if not (lo50 <= v["covered50"] <= hi50 and lo90 <= v["covered90"] <= hi90)
    }
    assert not bad, (bad, (lo50, hi50), (lo90, hi90))
    # one-sided: converged ~ Binomial(12, >= 0.95) if the sampler fails at most 5 % of the time
    n_conv = int(round(s["converged_fraction"] * reps))
    assert n_conv >= int(binom.ppf(alpha, reps, 0.95)), n_conv


def test_sbc_p_values_are_adjusted_for_the_number_of_quantities():
    """One raw p = 0.007 among 11 quantities (b_L in the 100-replication report) is what chance
    gives about once in 13 settings: the report must adjust before calling it a failure."""
    rng = np.random.default_rng(0)
    n, k = 100, 11
    ranks = rng.integers(0, 100, size=(n, k))
    ranks[:, 5] = np.repeat(
        [5, 15, 25, 35, 45, 55, 65, 75, 85, 95], [18, 17, 11, 4, 10, 10, 10, 12, 3, 5]
    )
    names = [f"q{j}" for j in range(k)]
    inside = np.ones((n, k), bool)
    res = CalibrationResult(
        "prior", "budget", names, inside, inside, ranks, np.ones(n), np.ones(n, bool), 1.0
    )
    q = res.summary()["quantities"]["q5"]
    assert q["sbc_uniformity_p"] == pytest.approx(0.007, abs=0.001)
    assert 0.05 < q["sbc_uniformity_p_holm"] <= 1.0
    assert "Holm p" in markdown([res], "uq calibrate")


def test_fast_coverage_on_the_n50_stand():
    res = calibrate(6, truth="n50", seed=2)
    covered = int(res.inside90.sum())
    assert 0.7 * res.inside90.size <= covered, covered
    pc = res.summary()["predictive_coverage90"]  # fresh readings, low and high forces alike
    assert 0.75 <= pc["low_force_third"] <= 1.0 and 0.75 <= pc["high_force_third"] <= 1.0, pc


def test_calibration_on_a_stand_unlike_the_model(tmp_path):
    """`--stand` runs the n50 truth on another stand (here with t-distributed errors) and the
    results say which; the prior truth has no stand, so the option is refused with it (exit 2)."""
    stand = tmp_path / "rough.toml"
    stand.write_text("error_df = 5\n")
    assert (
        main(
            [
                "calibrate",
                "--reps",
                "2",
                "--truth",
                "n50",
                "--stand",
                str(stand),
                "--out",
                str(tmp_path / "c"),
            ]
        )
        == 0
    )
    res = json.loads((tmp_path / "c" / "calibration.json").read_text())
    assert res["settings"][0]["stand"] == {"error_df": 5.0}
    assert "on a stand with error_df = 5" in (tmp_path / "c" / "calibration.md").read_text()
    assert main(["calibrate", "--reps", "2", "--truth", "prior,n50", "--stand", str(stand)]) == 2


def test_calibrate_cli_writes_results(tmp_path):
    assert (
        main(
            [
                "calibrate",
                "--reps",
                "2",
                "--truth",
                "n50",
                "--noise",
                "budget,constant",
                "--out",
                str(tmp_path),
            ]
        )
        == 0
    )
    res = json.loads((tmp_path / "calibration.json").read_text())
    assert [s["noise_model"] for s in res["settings"]] == ["budget", "constant"]
    assert (tmp_path / "calibration.md").exists() and (tmp_path / "sbc_n50_budget.png").exists()
    with pytest.raises(SystemExit) as exc:  # a bad option value is a usage error: exit 2
        main(["calibrate", "--reps", "1", "--truth", "bogus"])
    assert exc.value.code == 2


@pytest.mark.slow
def test_full_calibration_suite(tmp_path):
    """100 replications per setting: coverage inside the 99 % binomial region for every coefficient."""
    res = calibrate(100, truth="prior", seed=3).summary()
    bad = [k for k, q in res["quantities"].items() if not (q["in_region90"] and q["in_region50"])]
    assert not bad, bad
