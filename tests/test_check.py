"""``uq check``: the Mahalanobis/Bonferroni rule, its CLI contract, and its false-failure rate.

Binomial bounds used below (a correct fit fails one check with probability <= alpha = 0.01):
* 6 seeded campaigns, at most 1 failure allowed: P(>= 2 of 6) <= 1 - 0.99^6 - 6 * 0.01 * 0.99^5
  = 0.0015.
* 2000 Gaussian draws of the point estimates: failures ~ Binomial(2000, <= 0.01), mean <= 20,
  sd 4.4; allowed up to 34 (P(X > 34 | p = 0.01) = 0.0007), and at least 8, so the rule is
  not vacuously loose (P(X < 8 | p = 0.00998) = 0.001).
* 100 plug-in replications (slow): P(>= 5 of 100 | p = 0.01) = 0.0034.
"""

from __future__ import annotations

import copy
import json
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import chi2, norm

from uq._check import check, read_points, read_result, threshold
from uq._io import dumps_json
from uq._reference import FORCE_NAMES, PISTON_NAMES, table1
from uq.cli import main

ROOT = Path(__file__).resolve().parents[1]
POINTS = ROOT / "fits" / "n50" / "table1_points.json"
U = np.linspace(-0.047, 0.043, 37)  # the stand's heights, 65..155 mm, against x0 = 112 mm


def _write(path: Path, doc) -> Path:
    path.write_text(doc if isinstance(doc, str) else dumps_json(doc), encoding="utf-8")
    return path


def _estimate(mean, cov) -> dict:
    sd = np.sqrt(np.diag(cov))
    return {"mean": mean, "sd": sd, "q05": mean + norm.ppf(0.05) * sd, "q95": mean + norm.ppf(0.95) * sd}


def _test_json(p: float, mean_f, cov_f, mean_l, cov_l) -> dict:
    ef, el = _estimate(mean_f, cov_f), _estimate(mean_l, cov_l)
    return {
        "pressure_bar": p,
        "force": {n: {k: float(v[j]) for k, v in ef.items()} for j, n in enumerate(FORCE_NAMES)},
        "piston": {n: {k: float(v[j]) for k, v in el.items()} for j, n in enumerate(PISTON_NAMES)},
        "covariance": {"force": np.asarray(cov_f).tolist(), "piston": np.asarray(cov_l).tolist()},
    }


def _ols_cov(sd: float) -> np.ndarray:
    X = np.vander(U, 4, increasing=True)
    return sd**2 * np.linalg.inv(X.T @ X)


def synthetic_result(pressures=(1.0, 5.0, 10.0)) -> dict:
    """A RESULT centred on Table 1 with realistic least-squares covariances (50 N, 20 um)."""
    t = table1()
    cov_f, cov_l = _ols_cov(50.0), _ols_cov(2e-5)
    tests = [_test_json(p, t.force[t.index(p)], cov_f, t.piston[t.index(p)], cov_l) for p in pressures]
    return {"x0_m": 0.112, "tests": tests}


def points_doc(pressures=(1.0, 5.0, 10.0)) -> dict:
    doc = json.loads(POINTS.read_text())
    doc["tests"] = [t for t in doc["tests"] if t["pressure_bar"] in pressures]
    return doc


# --------------------------------------------------------------------------- bundled data


@pytest.fixture(scope="module")
def n50_result(n50_fit, tmp_path_factory):
    from uq._results import fit_json

    return _write(tmp_path_factory.mktemp("check") / "fit.json", fit_json(n50_fit))


def test_points_file_is_table1_in_si():
    doc = json.loads(POINTS.read_text())
    t = table1()
    assert doc["source"] == "Table 1 of the paper, converted to SI"
    assert [x["pressure_bar"] for x in doc["tests"]] == t.pressures_bar.tolist()
    np.testing.assert_allclose([[x["force"][n] for n in FORCE_NAMES] for x in doc["tests"]], t.force, rtol=1e-12)
    np.testing.assert_allclose([[x["piston"][n] for n in PISTON_NAMES] for x in doc["tests"]], t.piston, rtol=1e-12)
    assert doc["tests"][-1]["force"]["a_P"] == 28570.0  # PHYSICS.md: P(x0) = 28.57 kN at 10 bar


def test_bundled_fit_agrees_with_table1(n50_result, tmp_path, capsys):
    out = tmp_path / "verdict.json"
    assert main(["check", str(n50_result), "--against", str(POINTS), "--json", str(out)]) == 0
    v = json.loads(out.read_text())
    assert v["agree"] and v["n_blocks"] == 22 and v["n_disagree"] == 0
    assert v["threshold2"] == pytest.approx(chi2.isf(0.01 / 22, 4))
    assert "OK: all agree" in capsys.readouterr().out


@pytest.mark.parametrize("block,name", [("force", "a_P"), ("piston", "b_L")])
def test_perturbed_point_estimate_fails_and_is_named(n50_result, tmp_path, capsys, block, name):
    result = json.loads(n50_result.read_text())
    sd = next(t for t in result["tests"] if t["pressure_bar"] == 5.0)[block][name]["sd"]
    doc = json.loads(POINTS.read_text())
    five = next(t for t in doc["tests"] if t["pressure_bar"] == 5.0)
    five[block][name] += 10.0 * sd  # d^2 >= (10 - sqrt(d^2 before))^2 > 50 > threshold 20.2
    assert main(["check", str(n50_result), "--against", str(_write(tmp_path / "p.json", doc))]) == 1
    out = capsys.readouterr().out
    lines = [ln for ln in out.splitlines() if ln.startswith("DISAGREE")]
    assert len(lines) == 1 and f"5 bar {block}" in lines[0] and "Mahalanobis distance" in lines[0]
    assert "threshold" in lines[0]
    assert f"{name}: point" in out and "[90%" in out and "FAIL: 1 of 22" in out


# --------------------------------------------------------------------------- bad input


def _bad_cases():
    def drop_coef(pts, res):
        del pts["tests"][1]["force"]["c_P"]

    def text_value(pts, res):
        pts["tests"][0]["piston"]["b_L"] = "abc"

    def absent_test(pts, res):
        pts["tests"].append(copy.deepcopy(pts["tests"][0]) | {"pressure_bar": 7.0})

    def singular(pts, res):
        res["tests"][1]["covariance"]["force"] = np.ones((4, 4)).tolist()

    def no_cov(pts, res):
        del res["tests"][2]["covariance"]

    def nan_mean(pts, res):
        res["tests"][0]["force"]["d_P"]["mean"] = None

    def no_tests(pts, res):
        del pts["tests"]

    return [
        ("drop_coef", drop_coef, "p", "tests[1] (5 bar).force.c_P: missing"),
        ("text_value", text_value, "p", "tests[0] (1 bar).piston.b_L: expected a finite number"),
        ("absent_test", absent_test, "p", "no test at 7 bar in"),
        ("singular", singular, "r", "tests[1] (5 bar).covariance.force: singular covariance"),
        ("no_cov", no_cov, "r", "tests[2] (10 bar).covariance: missing (uq check needs the posterior covariance"),
        ("nan_mean", nan_mean, "r", "tests[0] (1 bar).force.d_P.mean: expected a finite number, got null"),
        ("no_tests", no_tests, "p", "'tests': missing"),
    ]


@pytest.mark.parametrize("name,edit,blamed,message", _bad_cases(), ids=[c[0] for c in _bad_cases()])
def test_bad_input_exits_2_with_one_line(tmp_path, capsys, name, edit, blamed, message):
    pts, res = points_doc(), synthetic_result()
    edit(pts, res)
    p, r = _write(tmp_path / "points.json", pts), _write(tmp_path / "result.json", res)
    assert main(["check", str(r), "--against", str(p)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "Traceback" not in err
    assert str(p if blamed == "p" else r) in err and message in err, err


@pytest.mark.parametrize("content,message", [(None, "RESULT file not found"), ("{not json", "invalid JSON at line 1"),
                                             ("[1, 2]", "expected a JSON object")])
def test_unreadable_result_exits_2(tmp_path, capsys, content, message):
    r = tmp_path / "result.json"
    if content is not None:
        r.write_text(content)
    assert main(["check", str(r), "--against", str(POINTS)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(r) in err and message in err


def test_synthetic_result_agrees_and_alpha_is_validated(tmp_path, capsys):
    r = _write(tmp_path / "r.json", synthetic_result())
    p = _write(tmp_path / "p.json", points_doc())
    assert main(["check", str(r), "--against", str(p)]) == 0
    assert main(["check", str(r), "--against", str(p), "--alpha", "1.5"]) == 2
    assert "option --alpha" in capsys.readouterr().err


# --------------------------------------------------------------------------- the rule itself


def test_rule_false_failure_rate_on_gaussian_draws():
    """Point estimates drawn from the (Gaussian) posterior itself fail at a rate <= alpha."""
    pressures = (1.0, 5.0, 10.0)  # K = 6 blocks
    res_doc = synthetic_result(pressures)
    result = read_result(res_doc, "r")
    base = read_points(points_doc(pressures), "p")
    rng = np.random.default_rng(7)
    chol = {b: np.linalg.cholesky(result[1.0][b]["cov"]) for b in ("force", "piston")}
    n_draws, fails = 2000, 0
    for _ in range(n_draws):
        pts = []
        for pt in base:
            m = result[pt["pressure_bar"]]
            pts.append(pt | {b: m[b]["mean"] + chol[b] @ rng.standard_normal(4) for b in ("force", "piston")})
        fails += not check(result, pts, alpha=0.01)["agree"]
    assert 8 <= fails <= 34, fails


def test_threshold_is_bonferroni_chi2():
    assert threshold(0.01, 1) == pytest.approx(13.2767, rel=1e-4)
    assert threshold(0.01, 22) == pytest.approx(chi2.ppf(1 - 0.01 / 22, 4))
    assert threshold(0.01, 22) > threshold(0.01, 6) > threshold(0.05, 6)


# --------------------------------------------------------------------------- seeded simulations


def _simulated(seed: int, pressures=(1.0, 5.0, 10.0)):
    from uq._recordings import Recordings, Test
    from uq._stand import Layout, simulate

    tests = simulate("n50", seed=seed, layout=Layout(pressures_bar=pressures))
    return Recordings(f"simulated seed {seed}", tuple(
        Test(t["pressure_bar"], t["height_m"], t["force_N"], t["piston_m"], t["compression"], t["step"],
             np.arange(t["step"].size)) for t in tests))


def _check_fit(cf, tmp_path: Path, tag: str) -> bool:
    from uq._results import fit_json

    r = _write(tmp_path / f"fit_{tag}.json", fit_json(cf))
    p = _write(tmp_path / "points.json", points_doc(tuple(cf.recordings.pressures_bar)))
    rc = main(["check", str(r), "--against", str(p)])
    assert rc in (0, 1)
    return rc == 0


def test_correct_fits_pass_on_seeded_simulations(tmp_path):
    """6 seeded 3-pressure campaigns fitted with reduced settings: at most 1 failure (P <= 0.0015)."""
    from uq._cubic import fit_campaign
    from uq._sampler import Settings

    settings = Settings(tau_multiple=25.0, min_steps=250, chunk=50)
    passed, ess = [], []
    for seed in range(6):
        cf = fit_campaign(_simulated(1000 + seed), seed=seed, settings=settings)
        ess += [min(t.diagnostics["variables"][n]["ess_bulk"] for n in FORCE_NAMES + PISTON_NAMES) for t in cf.tests]
        passed.append(_check_fit(cf, tmp_path, str(seed)))
    assert min(ess) >= 400  # the coefficients' posterior is well sampled even with reduced settings
    assert sum(not p for p in passed) <= 1, passed


def _plugin_result(rec) -> dict:
    """Closed-form shortcut: the Gaussian coefficient posterior at the noise parameters' mode."""
    from uq._cubic import (
        BASIS_SCALE_M,
        _cubic_eval,
        _mode_cov,
        _posteriors,
        _start,
        basis,
        least_squares,
    )
    from uq._jax import jnp

    tests = []
    D = np.diag(1.0 / BASIS_SCALE_M ** np.arange(4))
    for t in rec.tests:
        u = t.height_m - rec.x0_m
        lsq_f, lsq_l = least_squares(u, t.force_N), least_squares(u, t.piston_m)
        ref = np.abs(_cubic_eval(lsq_f, u))
        X = basis(u)
        args = (X, jnp.asarray(t.force_N), jnp.asarray(t.piston_m), jnp.asarray(ref))
        theta = jnp.asarray(_start(X, t.force_N, t.piston_m, ref, lsq_f, lsq_l, u))
        pf, pl = _posteriors(theta, *args)
        cf, cl = _mode_cov(theta, *args)
        tests.append(_test_json(t.pressure_bar, D @ np.asarray(pf.mean), D @ np.asarray(cf) @ D,
                                D @ np.asarray(pl.mean), D @ np.asarray(cl) @ D))
    return {"tests": tests}


@pytest.mark.slow
def test_false_failure_rate_over_100_plugin_replications():
    """100 simulated campaigns, posterior in closed form at the noise mode: <= 4 failures (P <= 0.0034)."""
    pressures = (1.0, 5.0, 10.0)
    pts = read_points(points_doc(pressures), "p")
    fails = 0
    for seed in range(100):
        result = read_result(_plugin_result(_simulated(5000 + seed, pressures)), "r")
        fails += not check(result, pts, alpha=0.01)["agree"]
    assert fails <= 4, fails


@pytest.mark.slow
def test_false_failure_rate_over_30_full_fits(tmp_path):
    """30 full default-settings fits: P(>= 3 failures of 30 | p = 0.01) = 0.0033."""
    from uq._cubic import fit_campaign

    fails = sum(not _check_fit(fit_campaign(_simulated(9000 + s), seed=s), tmp_path, str(s)) for s in range(30))
    assert fails <= 2, fails
