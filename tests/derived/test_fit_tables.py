"""``uq fit --csv`` (the coefficient table), ``--units input``, and ``uq check`` with a
``uq fit --json`` result as the stored estimates (issue 30 item 3)."""

from __future__ import annotations

import copy
import json

import numpy as np
import pandas as pd
import pytest
from scipy.stats import binom, chi2

from uq._cli.main import main
from uq._data.reference import FORCE_NAMES, PISTON_NAMES
from uq._data.units import OutputUnits
from uq._derived.check import FIT_RESULT, check, check_documents, read_points, read_result
from uq._derived.export import JSON_UNITS, coefficient_table
from uq._io.files import dumps_json

US = OutputUnits(pressure="psi", height="in", force="lbf", piston="in")


# ----------------------------------------------------------------------------- coefficient table


def test_coefficient_table_is_the_fits_draws(n50_fit):
    header, rows = coefficient_table(n50_fit)
    assert header == [
        "pressure_bar",
        "block",
        "coefficient",
        "unit",
        "mean",
        "sd",
        "q05",
        "q50",
        "q95",
        "r_hat",
        "ess_bulk",
        "x0_m",
    ]
    table = pd.DataFrame(rows, columns=header)
    assert len(table) == 8 * len(n50_fit.tests)
    doc = n50_fit.to_json()
    for t, pf in zip(doc["tests"], n50_fit.tests, strict=True):
        for block, names in (("force", FORCE_NAMES), ("piston", PISTON_NAMES)):
            draws = pf.flat(block)
            for k, n in enumerate(names):
                row = table[(table.pressure_bar == t["pressure_bar"]) & (table.coefficient == n)]
                assert len(row) == 1
                r = row.iloc[0]
                e = t[block][n]
                for key in ("mean", "sd", "q05", "q95", "r_hat", "ess_bulk"):
                    assert r[key] == pytest.approx(e[key], rel=1e-12), (n, key)
                assert r["q50"] == np.quantile(draws[:, k], 0.5)
    units = dict(zip(table.coefficient, table.unit, strict=False))
    assert units == {
        "a_P": "N",
        "b_P": "N/m",
        "c_P": "N/m^2",
        "d_P": "N/m^3",
        "a_L": "m",
        "b_L": "1",
        "c_L": "1/m",
        "d_L": "1/m^2",
    }
    assert (table.x0_m == 0.112).all()


def test_coefficients_in_other_units_give_the_same_curves(n50_fit):
    """The cubic in lbf against inches, evaluated at a height, is the SI cubic there in lbf."""
    si = pd.DataFrame(coefficient_table(n50_fit)[1], columns=coefficient_table(n50_fit)[0])
    header, rows = coefficient_table(n50_fit, US)
    us = pd.DataFrame(rows, columns=header)
    assert header[0] == "pressure_psi" and header[-1] == "x0_in"
    x_m = np.array([0.07, 0.1, 0.15])
    u_m, u_in = x_m - 0.112, (x_m - 0.112) / 0.0254
    for block, names, si_to_us in (
        ("force", FORCE_NAMES, 1 / 4.4482216152605),
        ("piston", PISTON_NAMES, 1 / 0.0254),
    ):
        for p in (1.0, 5.0, 10.0):
            psi = p / 0.0689475729316836
            a = si[(si.pressure_bar == p) & (si.block == block)].set_index("coefficient")
            b = us[(np.isclose(us.pressure_psi, psi)) & (us.block == block)].set_index(
                "coefficient"
            )
            for stat in ("mean", "q05", "q50", "q95"):
                y_si = sum(a.loc[n, stat] * u_m**k for k, n in enumerate(names))
                y_us = sum(b.loc[n, stat] * u_in**k for k, n in enumerate(names))
                assert np.allclose(y_us, y_si * si_to_us, rtol=1e-12), (block, p, stat)
    assert set(us.unit) >= {"lbf", "lbf/in", "lbf/in^2", "lbf/in^3", "in", "1", "1/in", "1/in^2"}
    assert coefficient_table(n50_fit, JSON_UNITS) == coefficient_table(n50_fit)


def test_units_input_of_a_us_file_are_psi_in_lbf(tmp_path, n50_fit):
    """A US catalogue's units in, its units out (the command line's path, `uq fit --units input
    --csv`, runs in tests/data/test_instrument_exports.py on the Bluehill example)."""
    csv = tmp_path / "us.csv"
    argv = ["simulate", "--out", str(csv), "--pressures", "2,5", "--step-mm", "10"]
    assert main(argv + ["--units", "psi,in,lbf,in3", "--quiet"]) == 0
    from uq._data.recordings import read_recordings

    units = OutputUnits.of(read_recordings(csv).units, "input")
    assert units == OutputUnits(
        pressure="psi", height="in", force="lbf", piston="in", area="in2", volume="in3"
    )
    assert OutputUnits.of(read_recordings(csv).units, "si") == OutputUnits()
    assert coefficient_table(n50_fit, units)[0][0] == "pressure_psi"


def test_output_units_choices_equal_the_library():
    from uq._cli.main import build_parser
    from uq._data.units import OUTPUT_CHOICES

    fit = build_parser(["fit"])._uq_commands["fit"]
    (action,) = [a for a in fit._actions if "--units" in a.option_strings]
    assert tuple(action.choices) == OUTPUT_CHOICES


# ----------------------------------------------------------------------------- check: batch against batch


def _fit_doc(means: dict, covs: dict) -> dict:
    """A ``uq fit --json``-shaped document: pressure -> (force mean, piston mean) and covariances."""
    tests = []
    for p, (mf, ml) in means.items():
        cf, cl = covs[p]
        t = {"pressure_bar": p, "covariance": {"force": cf.tolist(), "piston": cl.tolist()}}
        for block, names, m, c in (
            ("force", FORCE_NAMES, mf, cf),
            ("piston", PISTON_NAMES, ml, cl),
        ):
            sd = np.sqrt(np.diag(c))
            t[block] = {
                n: {
                    "mean": m[k],
                    "sd": sd[k],
                    "q05": m[k] - 1.645 * sd[k],
                    "q95": m[k] + 1.645 * sd[k],
                }
                for k, n in enumerate(names)
            }
        tests.append(t)
    return json.loads(dumps_json({"tests": tests}))


def _cov(scale: float, rng) -> np.ndarray:
    a = rng.normal(size=(4, 4))
    d = np.diag(scale * 10.0 ** -np.arange(4.0))
    return d @ (a @ a.T + 4 * np.eye(4)) @ d


def test_a_fit_result_as_the_stored_estimates_adds_both_covariances():
    """d^2 = (m_B - m_A)^T (S_A + S_B)^-1 (m_B - m_A), exactly, and the verdict says what POINTS is."""
    rng = np.random.default_rng(1)
    covs_a = {p: (_cov(50.0, rng), _cov(1e-3, rng)) for p in (1.0, 5.0)}
    covs_b = {p: (_cov(80.0, rng), _cov(2e-3, rng)) for p in (1.0, 5.0)}
    means_a = {p: (rng.normal(size=4) * 100, rng.normal(size=4) * 1e-3) for p in covs_a}
    means_b = {p: (m[0] + rng.normal(size=4) * 30, m[1]) for p, m in means_a.items()}
    new, ref = _fit_doc(means_a, covs_a), _fit_doc(means_b, covs_b)
    verdict = check_documents(new, ref)
    assert verdict["points_kind"] == FIT_RESULT and verdict["n_blocks"] == 4
    assert "`uq fit --json` result" in verdict["point_uncertainty"]
    for b in verdict["blocks"]:
        p, k = b["pressure_bar"], 0 if b["block"] == "force" else 1
        d = means_b[p][k] - means_a[p][k]
        expect = d @ np.linalg.solve(covs_a[p][k] + covs_b[p][k], d)
        assert b["mahalanobis2"] == pytest.approx(expect, rel=1e-9)
        assert b["point_covariance"]
    assert check_documents(new, new)["agree"]  # a batch agrees with itself: d^2 = 0
    assert max(b["mahalanobis2"] for b in check_documents(new, new)["blocks"]) < 1e-18


def test_batches_of_one_part_agree_at_the_promised_rate():
    """Two batches' posteriors about one truth, m ~ N(theta, S) each (the calibrated posterior's
    promise), checked block by block at alpha = 0.1 (K = 1): failures ~ Binomial(1000, 0.1),
    mean 100, sd 9.5; allowed 72..131 (P(outside) < 0.002). Treating the reference batch's means
    as exact (C = 0) fails far more often: d^2 is then 2 chi2_4 at S_A = S_B, which exceeds the
    chi2_4 quantile 7.78 with probability P(chi2_4 > 3.89) = 0.42."""
    rng = np.random.default_rng(7)
    alpha, n = 0.1, 1000
    s = _cov(50.0, rng)
    chol = np.linalg.cholesky(s)
    theta = np.array([13000.0, -1.1e5, -5.8e5, -7.9e6])
    fails = exact_fails = 0
    for _ in range(n):
        m_a, m_b = theta + chol @ rng.normal(size=4), theta + chol @ rng.normal(size=4)
        docs = [_fit_doc({5.0: (m, np.zeros(4))}, {5.0: (s, np.eye(4))}) for m in (m_a, m_b)]
        result = read_result(docs[0], "new")
        points = [
            {k: v for k, v in pt.items() if k != "piston"} for pt in read_points(docs[1], "ref")
        ]
        fails += not check(result, points, alpha=alpha)["agree"]
        exact_fails += not check(result, [points[0] | {"cov": {}}], alpha=alpha)["agree"]
    assert binom.cdf(71, n, alpha) < 1e-3 and binom.sf(131, n, alpha) < 1e-3
    assert 72 <= fails <= 131, fails
    assert chi2.sf(chi2.isf(alpha, 4) / 2, 4) == pytest.approx(0.42, abs=0.005)
    assert exact_fails > 340, exact_fails  # Binomial(1000, 0.42): mean 420, sd 16


def test_check_takes_a_fit_result_through_the_command_line(n50_fit, tmp_path, capsys):
    """``uq check NEW.json --against REFERENCE.json`` with two `uq fit --json` documents: exit 0
    for a batch against itself, 1 with a_P of one test moved by 2 kN, 2 for a result without
    covariances (one line)."""
    ref = tmp_path / "ref.json"
    ref.write_text(dumps_json(n50_fit.to_json()))
    assert main(["check", str(ref), "--against", str(ref)]) == 0
    out = capsys.readouterr().out
    assert "`uq fit --json` result (another batch)" in out and "OK: all agree" in out
    moved = json.loads(ref.read_text())
    moved["tests"][5]["force"]["a_P"]["mean"] += 2000.0
    new = tmp_path / "new.json"
    new.write_text(dumps_json(moved))
    assert main(["check", str(new), "--against", str(ref)]) == 1
    assert "DISAGREE 5 bar force" in capsys.readouterr().out
    broken = copy.deepcopy(moved)
    del broken["tests"][2]["covariance"]
    bad = tmp_path / "bad.json"
    bad.write_text(dumps_json(broken))
    assert main(["check", str(ref), "--against", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "tests[2] (2 bar).covariance: missing" in err
    assert "a fit result as the stored estimates needs its posterior covariance" in err
