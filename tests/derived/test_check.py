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

from uq._cli.main import main
from uq._data.reference import FORCE_NAMES, PISTON_NAMES, table1
from uq._derived.check import check, read_points, read_result, threshold
from uq._io.files import dumps_json

ROOT = Path(__file__).resolve().parents[2]
POINTS = ROOT / "fits" / "n50" / "table1_points.json"
U = np.linspace(-0.047, 0.043, 37)  # the stand's heights, 65..155 mm, against x0 = 112 mm


def _write(path: Path, doc) -> Path:
    path.write_text(doc if isinstance(doc, str) else dumps_json(doc), encoding="utf-8")
    return path


def _estimate(mean, cov) -> dict:
    sd = np.sqrt(np.diag(cov))
    return {
        "mean": mean,
        "sd": sd,
        "q05": mean + norm.ppf(0.05) * sd,
        "q95": mean + norm.ppf(0.95) * sd,
    }


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
    tests = [
        _test_json(p, t.force[t.index(p)], cov_f, t.piston[t.index(p)], cov_l) for p in pressures
    ]
    return {"x0_m": 0.112, "tests": tests}


def points_doc(pressures=(1.0, 5.0, 10.0)) -> dict:
    doc = json.loads(POINTS.read_text())
    doc["tests"] = [t for t in doc["tests"] if t["pressure_bar"] in pressures]
    return doc


# --------------------------------------------------------------------------- bundled data


@pytest.fixture(scope="module")
def n50_result(n50_fit, tmp_path_factory):
    return _write(tmp_path_factory.mktemp("check") / "fit.json", n50_fit.to_json())


def test_points_file_is_table1_in_si():
    doc = json.loads(POINTS.read_text())
    t = table1()
    assert doc["source"] == "Table 1 of the paper, converted to SI"
    assert [x["pressure_bar"] for x in doc["tests"]] == t.pressures_bar.tolist()
    np.testing.assert_allclose(
        [[x["force"][n] for n in FORCE_NAMES] for x in doc["tests"]], t.force, rtol=1e-12
    )
    np.testing.assert_allclose(
        [[x["piston"][n] for n in PISTON_NAMES] for x in doc["tests"]], t.piston, rtol=1e-12
    )
    assert doc["tests"][-1]["force"]["a_P"] == 28570.0  # Table 1: P(x0) = 28.57 kN at 10 bar


def test_points_file_carries_the_paper_estimators_covariance():
    """Table 1's own error: OLS on the 37 readings at Table 2's s_P (force), the budget (piston)."""
    from uq._data.reference import table2

    doc = json.loads(POINTS.read_text())
    five = next(t for t in doc["tests"] if t["pressure_bar"] == 5.0)
    heights = (
        np.r_[np.arange(155, 64, -5), np.arange(70, 156, 5)] * 1e-3
    )  # section 3.4, 37 readings
    X = np.vander(heights - 0.112, 4, increasing=True)
    s2 = table2()[5.0][0] ** 2 * 37 / 33  # s_P has divisor N; the unbiased residual variance N - 4
    np.testing.assert_allclose(five["covariance"]["force"], s2 * np.linalg.inv(X.T @ X), rtol=1e-9)
    assert np.sqrt(five["covariance"]["force"][0][0]) == pytest.approx(
        21.9, abs=0.1
    )  # a_P +/- 22 N
    # piston: the budget's ~1.9 mm per reading at 5 bar (air volume x 0.01 bar / p_abs / S) -> a_L +/- 0.47 mm
    assert 3e-4 < np.sqrt(five["covariance"]["piston"][0][0]) < 5e-4
    assert "covariance_source" in doc


def test_lsq_covariance_matches_monte_carlo_of_least_squares():
    from uq._derived.check import lsq_covariance

    rng = np.random.default_rng(3)
    sd = 1e-3 * (1.0 + 40.0 * np.abs(U))  # heteroscedastic, as the piston budget is
    X = np.vander(U, 4, increasing=True)
    coefs = np.linalg.lstsq(X, (sd * rng.standard_normal((20000, U.size))).T, rcond=None)[0].T
    emp = np.cov(coefs.T)
    cov = lsq_covariance(U, sd)
    s = np.sqrt(np.diag(cov))
    np.testing.assert_allclose(
        np.sqrt(np.diag(emp)), s, rtol=0.03
    )  # 20000 draws: sd of an sd ~0.5 %
    np.testing.assert_allclose(emp / np.outer(s, s), cov / np.outer(s, s), atol=0.03)
    np.testing.assert_allclose(lsq_covariance(U, 2.0), 4.0 * np.linalg.inv(X.T @ X), rtol=1e-9)


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
    j = (FORCE_NAMES if block == "force" else PISTON_NAMES).index(name)
    sd = np.hypot(
        sd, np.sqrt(five["covariance"][block][j][j])
    )  # the check's scale: posterior + Table 1's own
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

    def point_cov_shape(pts, res):
        pts["tests"][0]["covariance"]["piston"] = [[1.0, 0.0], [0.0, 1.0]]

    return [
        ("drop_coef", drop_coef, "p", "tests[1] (5 bar).force.c_P: missing"),
        ("text_value", text_value, "p", "tests[0] (1 bar).piston.b_L: expected a finite number"),
        ("absent_test", absent_test, "p", "no test at 7 bar in"),
        ("singular", singular, "r", "tests[1] (5 bar).covariance.force: singular covariance"),
        (
            "no_cov",
            no_cov,
            "r",
            "tests[2] (10 bar).covariance: missing (uq check needs the posterior covariance",
        ),
        (
            "nan_mean",
            nan_mean,
            "r",
            "tests[0] (1 bar).force.d_P.mean: expected a finite number, got null",
        ),
        ("no_tests", no_tests, "p", "'tests': missing"),
        (
            "point_cov_shape",
            point_cov_shape,
            "p",
            "tests[0] (1 bar).covariance.piston: expected a 4x4 matrix",
        ),
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


@pytest.mark.parametrize(
    "content,message",
    [
        (None, "RESULT file not found"),
        ("{not json", "invalid JSON at line 1"),
        ("[1, 2]", "expected a JSON object"),
    ],
)
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
    with pytest.raises(SystemExit) as exc:  # argparse refuses the option before any work (exit 2)
        main(["check", str(r), "--against", str(p), "--alpha", "1.5"])
    assert exc.value.code == 2 and "--alpha" in capsys.readouterr().err


def test_assumption_about_point_uncertainty_is_stated(tmp_path, capsys):
    r = _write(tmp_path / "r.json", synthetic_result())
    exact = points_doc()
    for t in exact["tests"]:
        del t["covariance"]
    out = tmp_path / "v.json"
    assert (
        main(
            [
                "check",
                str(r),
                "--against",
                str(_write(tmp_path / "p.json", exact)),
                "--json",
                str(out),
            ]
        )
        == 0
    )
    v = json.loads(out.read_text())
    assert v["point_uncertainty"].startswith("stored estimates treated as exact for all blocks")
    assert len(v["blocks_treated_as_exact"]) == 6 and not any(
        b["point_covariance"] for b in v["blocks"]
    )
    assert "stored estimates treated as exact" in capsys.readouterr().out
    assert (
        main(
            [
                "check",
                str(r),
                "--against",
                str(_write(tmp_path / "q.json", points_doc())),
                "--json",
                str(out),
            ]
        )
        == 0
    )
    v = json.loads(out.read_text())
    assert v["point_uncertainty"].startswith("included") and v["blocks_treated_as_exact"] == []
    assert "point-estimate uncertainty: included" in capsys.readouterr().out


def test_point_covariance_enters_the_distance():
    """d^2 under S + C: a point 3 posterior sd off on a_P with C = 8 S is well inside."""
    res = read_result(synthetic_result((5.0,)), "r")
    pt = read_points(points_doc((5.0,)), "p")[0]
    pt["force"] = res[5.0]["force"]["mean"] + np.array([3.0 * res[5.0]["force"]["sd"][0], 0, 0, 0])
    pt["piston"] = res[5.0]["piston"]["mean"]
    pt["cov"] = {b: 8.0 * res[5.0][b]["cov"] for b in ("force", "piston")}
    d2 = check(res, [pt])["blocks"][0]["mahalanobis2"]
    assert d2 == pytest.approx(check(res, [pt | {"cov": {}}])["blocks"][0]["mahalanobis2"] / 9.0)


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
            # x - m ~ N(0, S) exactly here, so the points carry no covariance of their own
            pts.append(
                pt
                | {"cov": {}}
                | {b: m[b]["mean"] + chol[b] @ rng.standard_normal(4) for b in ("force", "piston")}
            )
        fails += not check(result, pts, alpha=0.01)["agree"]
    assert 8 <= fails <= 34, fails


def test_threshold_is_bonferroni_chi2():
    assert threshold(0.01, 1) == pytest.approx(13.2767, rel=1e-4)
    assert threshold(0.01, 22) == pytest.approx(chi2.ppf(1 - 0.01 / 22, 4))
    assert threshold(0.01, 22) > threshold(0.01, 6) > threshold(0.05, 6)


# --------------------------------------------------------------------------- seeded simulations


def _simulated(seed: int, pressures=(1.0, 5.0, 10.0)):
    from uq._stand.simulator import Layout, recordings_from_tests, simulate

    tests = simulate("n50", seed=seed, layout=Layout(pressures_bar=pressures))
    return recordings_from_tests(tests, f"simulated seed {seed}")


def _check_fit(cf, tmp_path: Path, tag: str) -> bool:
    r = _write(tmp_path / f"fit_{tag}.json", cf.to_json())
    p = _write(tmp_path / "points.json", points_doc(tuple(cf.recordings.pressures_bar)))
    rc = main(["check", str(r), "--against", str(p)])
    assert rc in (0, 1)
    return rc == 0


@pytest.mark.slow  # six campaign fits; fast: the rule's false-failure rate on posterior draws
# (test_rule_false_failure_rate_on_gaussian_draws, and with stored estimates of an independent
# campaign, test_false_failure_rate_with_stored_estimates_from_an_independent_campaign) and a
# real fit checked against Table 1 (tests/test_docs.py reruns docs' `uq check` on data/n50)
def test_correct_fits_pass_on_seeded_simulations(tmp_path):
    """6 seeded 3-pressure campaigns fitted with reduced settings: at most 1 failure (P <= 0.0015)."""
    from uq._inference.sampler import Settings
    from uq._models.cubic_fit import fit_campaign

    settings = Settings(tau_multiple=25.0, min_steps=250, chunk=50)
    passed, ess = [], []
    for seed in range(6):
        cf = fit_campaign(_simulated(1000 + seed), seed=seed, settings=settings)
        ess += [
            min(t.convergence.variables[n]["ess_bulk"] for n in FORCE_NAMES + PISTON_NAMES)
            for t in cf.tests
        ]
        passed.append(_check_fit(cf, tmp_path, str(seed)))
    assert min(ess) >= 400  # the coefficients' posterior is well sampled even with reduced settings
    assert sum(not p for p in passed) <= 1, passed


def _plugin_result(rec) -> dict:
    """Closed-form shortcut: the Gaussian coefficient posterior at the noise parameters' mode."""
    from uq._data.stand_description import PAPER_STAND
    from uq._inference.collapsed import find_map
    from uq._inference.float64 import jnp
    from uq._inference.linear import posterior_cov
    from uq._models.cubic import MODEL, conditional_posteriors, prepare
    from uq._physics.quantities import BASIS_SCALE_M

    tests = []
    D = np.diag(1.0 / BASIS_SCALE_M ** np.arange(4))
    for t in rec.tests:
        data = prepare(t, rec.x0_m, "budget", PAPER_STAND)[0]
        theta = jnp.asarray(find_map(MODEL, data).theta)
        pf, pl = conditional_posteriors(theta, data)
        cf, cl = posterior_cov(pf), posterior_cov(pl)
        tests.append(
            _test_json(
                t.pressure_bar,
                D @ np.asarray(pf.mean),
                D @ np.asarray(cf) @ D,
                D @ np.asarray(pl.mean),
                D @ np.asarray(cl) @ D,
            )
        )
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
    from uq._models.cubic_fit import fit_campaign

    fails = sum(
        not _check_fit(fit_campaign(_simulated(9000 + s), seed=s), tmp_path, str(s))
        for s in range(30)
    )
    assert fails <= 2, fails


# --------------------------------------------------------------------------- stored estimates with their own error
#
# Table 1 is itself a least-squares estimate from one campaign. The simulation below makes
# both sides from one known truth (the n50 spring) with independent seeds: a posterior from
# campaign A, point estimates by ordinary least squares from campaign B with the covariance
# fits/n50/make_points.py derives for Table 1 (force: rms residual s^2 N/(N-4) (X^T X)^-1;
# piston: the stand's budget through the same estimator). Every test is checked on its own
# (K = 2 blocks): tests are independent, so the failures are Binomial(n, q) with q <= alpha
# when the check is right. alpha = 0.1 gives the simulation power at small n; the guarantee
# is the same for every alpha, and Bonferroni over K is a union bound that needs no test.

ALL_PRESSURES = (0.1, *map(float, range(1, 11)))


def _lsq_points(rec) -> list[dict]:
    from uq._derived.check import lsq_covariance
    from uq._stand.simulator import N50Spring, noise_sd

    out = []
    for t in rec.tests:
        u = t.height_m - rec.x0_m
        X = np.vander(u, 4, increasing=True)
        force, piston = (np.linalg.lstsq(X, y, rcond=None)[0] for y in (t.force_N, t.piston_m))
        s2 = (
            np.mean((t.force_N - X @ force) ** 2) * u.size / (u.size - 4)
        )  # Table 2's s_P^2, unbiased
        heights, back = np.unique(t.height_m, return_inverse=True)
        sd_piston = noise_sd(N50Spring(), heights, t.pressure_bar)[1][back]
        out.append(
            {
                "pressure_bar": t.pressure_bar,
                "label": f"{t.pressure_bar:g} bar",
                "force": force,
                "piston": piston,
                "cov": {
                    "force": lsq_covariance(u, np.sqrt(s2)),
                    "piston": lsq_covariance(u, sd_piston),
                },
            }
        )
    return out


def _per_test_failures(pairs, alpha: float) -> tuple[int, int, int]:
    """(checks, failures with the points' covariance, failures treating them as exact)."""
    n = new = old = 0
    for result, points in pairs:
        for pt in points:
            n += 1
            new += not check(result, [pt], alpha=alpha)["agree"]
            old += not check(result, [pt | {"cov": {}}], alpha=alpha)["agree"]
    return n, new, old


def _binomial_limit(n: int, alpha: float, level: float = 1e-3) -> int:
    """Largest failure count allowed: P(X > k) < level for X ~ Binomial(n, alpha)."""
    from scipy.stats import binom

    k = int(binom.ppf(1.0 - level, n, alpha))
    while binom.sf(k, n, alpha) >= level:
        k += 1
    return k


def test_false_failure_rate_with_stored_estimates_from_an_independent_campaign():
    """4 campaign pairs x 11 tests = 44 checks at alpha 0.1: at most 11 failures, P(> 11) = 0.00098.

    The posterior is the closed-form Gaussian of the coefficients at the noise mode (the
    sampler's exact conditional draws, without the small spread of the noise parameters).
    The old check (stored estimates exact) fails here: distances about twice too large,
    about half of the checks fail (expected ~24 of 44).
    """
    alpha = 0.1
    pairs = [
        (
            read_result(_plugin_result(_simulated(7000 + 2 * k, ALL_PRESSURES)), "r"),
            _lsq_points(_simulated(7001 + 2 * k, ALL_PRESSURES)),
        )
        for k in range(4)
    ]
    n, new, old = _per_test_failures(pairs, alpha)
    limit = _binomial_limit(n, alpha)
    assert (n, limit) == (44, 11)
    assert new <= limit, (new, old)
    assert old > limit, (new, old)  # treating Table-1-like estimates as exact breaks the promise


@pytest.mark.slow
def test_false_failure_rate_with_sampled_posteriors_from_an_independent_campaign():
    """6 campaign pairs fitted by the sampler (reduced settings) x 11 tests = 66 checks at
    alpha 0.1 (at most 15 failures, P(> 15) = 0.00064), and 20 closed-form pairs = 220
    checks (at most 37, P(> 37) = 0.00063)."""
    from uq._inference.sampler import Settings
    from uq._models.cubic_fit import fit_campaign

    alpha, settings = 0.1, Settings(tau_multiple=25.0, min_steps=250, chunk=50)
    sampled = [
        (
            read_result(
                json.loads(
                    dumps_json(
                        fit_campaign(
                            _simulated(7100 + 2 * k, ALL_PRESSURES), seed=k, settings=settings
                        ).to_json()
                    )
                ),
                "r",
            ),
            _lsq_points(_simulated(7101 + 2 * k, ALL_PRESSURES)),
        )
        for k in range(6)
    ]
    closed = [
        (
            read_result(_plugin_result(_simulated(7200 + 2 * k, ALL_PRESSURES)), "r"),
            _lsq_points(_simulated(7201 + 2 * k, ALL_PRESSURES)),
        )
        for k in range(20)
    ]
    for pairs in (sampled, closed):
        n, new, old = _per_test_failures(pairs, alpha)
        limit = _binomial_limit(n, alpha)
        assert new <= limit and old > limit, (n, new, old, limit)
