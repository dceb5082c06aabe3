"""Force-only campaigns and catalogue tables through ``uq fit``, ``report``, ``check`` and ``batch``
(issue 21 items 2 and 3), on the bundled examples the virtual stand made: data/n50-force-only (no
piston column, measured pressures) and data/n50-catalogue (one pass in unknown order, a volume
column at 5 bar only). Volume results are omitted with one line saying why, never crash or pass
silently. Short chains: these tests check what the commands give, not the posteriors
(tests/models/test_cubic_force.py does)."""

from __future__ import annotations

import contextlib
import csv
import io
import json

import pytest
from browser import assert_real_page, screenshot
from cli_helpers import run
from conftest import ROOT

DATA = {
    "force-only": ROOT / "data" / "n50-force-only" / "recordings.csv",
    "catalogue": ROOT / "data" / "n50-catalogue" / "recordings.csv",
}
FAST = ["--walkers", "8", "--ensembles", "2", "--max-steps", "40", "--quiet", "--allow-unconverged"]


def _run(argv) -> tuple[int, str]:
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        code = run(argv)
    return code, out.getvalue()


@pytest.fixture(scope="module", params=sorted(DATA))
def fitted(request, tmp_path_factory):
    """(kind, folder, uq fit's stdout, its JSON)."""
    d = tmp_path_factory.mktemp(request.param)
    code, out = _run(["fit", DATA[request.param], *FAST, "--json", d / "fit.json"])
    assert code == 0, out
    return request.param, d, out, json.loads((d / "fit.json").read_text())


def test_fit_json_has_force_blocks_and_omits_the_piston_with_its_reason(fitted):
    kind, _, out, result = fitted
    tests = {t["pressure_bar"]: t for t in result["tests"]}
    for p, t in tests.items():
        assert set(t["force"]) == {"a_P", "b_P", "c_P", "d_P"}
        assert 12e3 < tests[5.0]["force"]["a_P"]["mean"] < 14e3  # Table 1: 13.02 kN
        if kind == "catalogue" and p == 5.0:  # the volume column, fitted as L = -V / S
            assert "piston" in t and "omitted" not in t and "volume" in t["piston_from"]
            assert set(t["covariance"]) == {"force", "piston"}
            # -S b_L at x0: the volume-derived area, 12-14 % above P / p_u (PHYSICS.md)
            ratio = -54.82e-4 * t["piston"]["b_L"]["mean"] / (t["force"]["a_P"]["mean"] / 5e5)
            assert 1.08 < ratio < 1.18
            continue
        assert "piston" not in t and "piston" not in t["covariance"]
        assert "piston" not in t["least_squares"] and "sigma_L_m" not in t["noise"]
        assert "force-only" in t["omitted"]["piston"]
    assert "volume results omitted" in out
    if kind == "catalogue":
        assert all("skipped" in t["residual_order"] for t in tests.values())
        assert "recording-order check skipped: one pass in unknown order" in out
    else:  # measured pressures: the sensor's offset is a parameter of the force-only model
        assert all(t["pressure_holding"]["model"] == "measured" for t in tests.values())
        assert all("V_gas_m3" not in t["pressure_holding"] for t in tests.values())


def test_report_writes_the_page_and_says_what_is_omitted(fitted, tmp_path):
    kind, _, _, _ = fitted
    out_dir = tmp_path / "report"
    code, out = _run(["report", DATA[kind], *FAST, "--draws", "20", "--out", out_dir])
    assert code == 0, out
    page = (out_dir / "report.html").read_text(encoding="utf-8")
    if kind == "force-only":
        line = "Volume results omitted: force-only campaign (no piston_* or volume_* column)"
        assert line in out and line in page
        assert not (out_dir / "fig3_volume.png").exists()
        # and the page renders: a real page in a browser, nothing off its right edge
        assert_real_page(screenshot(out_dir / "report.html", tmp_path / "report.png"))
        assert not (out_dir / "fig5_traditional.png").exists()
        assert "Figure 5 (traditional vs measured force) omitted" in page
    else:
        line = "Volume results of the 3, 4, 6, 7 bar tests omitted: force-only tests"
        assert line in out and line in page
        assert (out_dir / "fig3_volume.png").exists()  # the 5-bar volume column's curve
        at_x0 = [ln for ln in out.splitlines() if "bar at x0" in ln]
        assert len(at_x0) == 5 and all("traditional" in ln for ln in at_x0)  # the 5-bar curve
        order = "One pass in unknown order (no branch and step columns): no compression/rebound"
        assert order in out and order in page


def test_check_of_a_force_only_result_checks_the_force_and_says_the_piston_is_not(fitted, tmp_path):
    kind, d, _, result = fitted
    table1 = json.loads((ROOT / "fits" / "n50" / "table1_points.json").read_text())
    rows = {t["pressure_bar"]: t for t in table1["tests"]}
    # POINTS with piston entries: the result's own means where it has them (they agree: a volume
    # column's a_L has its own arbitrary reference), Table 1's piston where it has none
    points = {
        "tests": [
            {
                "pressure_bar": t["pressure_bar"],
                "force": {n: e["mean"] for n, e in t["force"].items()},
                "piston": {n: e["mean"] for n, e in t["piston"].items()}
                if "piston" in t
                else rows[t["pressure_bar"]]["piston"],
            }
            for t in result["tests"]
        ]
    }
    (tmp_path / "points.json").write_text(json.dumps(points))
    code, out = _run(["check", d / "fit.json", "--against", tmp_path / "points.json"])
    assert code == 0, out
    not_checked = [ln for ln in out.splitlines() if ln.startswith("NOT CHECKED piston")]
    assert len(not_checked) == 1 and "has none (force-only test" in not_checked[0]
    assert "OK: all agree" in out
    if kind == "catalogue":  # a_L of L = -V/S is an arbitrary reference: not checked, b_L..d_L are
        shifted = json.loads(json.dumps(points))
        next(t for t in shifted["tests"] if t["pressure_bar"] == 5.0)["piston"]["a_L"] += 1.0
        (tmp_path / "shifted.json").write_text(json.dumps(shifted))
        code, out = _run(["check", d / "fit.json", "--against", tmp_path / "shifted.json"])
        assert code == 0 and "NOT CHECKED a_L (5 bar): the arbitrary reference" in out, out
        bent = json.loads(json.dumps(points))
        b5 = next(t for t in bent["tests"] if t["pressure_bar"] == 5.0)["piston"]
        b5["b_L"] *= 1.05
        (tmp_path / "bent.json").write_text(json.dumps(bent))
        code, out = _run(["check", d / "fit.json", "--against", tmp_path / "bent.json"])
        assert code == 1 and "DISAGREE 5 bar piston" in out, out
    # POINTS without piston entries: the force alone; a piston in the result is named unchecked
    for t in points["tests"]:
        del t["piston"]
    (tmp_path / "force.json").write_text(json.dumps(points))
    code, out = _run(["check", d / "fit.json", "--against", tmp_path / "force.json", "--json", "-"])
    assert code == 0, out
    verdict = json.loads(out[: out.rindex("}") + 1])
    assert {b["block"] for b in verdict["blocks"]} == {"force"}
    assert verdict["n_blocks"] == len(result["tests"])
    if kind == "catalogue":
        assert verdict["not_checked"] == [
            {
                "pressure_bar": 5.0,
                "block": "piston",
                "reason": f"{tmp_path / 'force.json'} gives none",
            }
        ]


def test_report_surface_on_a_catalogue_links_the_force_surface_page(tmp_path):
    """`uq report --surface` on a catalogue table: the force surface's page beside the report, its
    volume results omitted with the reason, compared with cubics fitted to the force alone."""
    out = tmp_path / "r"
    code, stdout = _run(["report", DATA["catalogue"], "--surface", "--out", out, *FAST])
    assert code == 0, stdout
    assert "href='surface.html'" in (out / "report.html").read_text()
    page = (out / "surface.html").read_text()
    assert "volume results omitted" in page and "force alone" in page
    # the default model (the surface with a discrepancy in pressure) is importance-sampled, which
    # --max-steps does not limit: its page says it converged and how; the cubics' 40 steps did not
    # converge, and the report says so
    assert "NOT CONVERGED" not in page[: page.index("<h2")]
    assert "the sampled parameters by importance sampling (Pareto k-hat" in page
    assert "NOT CONVERGED" in (out / "report.html").read_text()


def test_batch_runs_force_only_and_catalogue_campaigns(tmp_path):
    cat = tmp_path / "campaigns.csv"
    cat.write_text(
        "name,file,tasks,walkers,ensembles,max_steps\n"
        f"fo,{DATA['force-only']},fit,8,2,40\n"
        f"cat,{DATA['catalogue']},fit,8,2,40\n"
    )
    code, out = _run(["batch", cat, "--out", tmp_path / "out", "--serial", "--quiet"])
    rows = list(csv.DictReader((tmp_path / "out" / "summary.csv").read_text().splitlines()))
    assert [r["status"] for r in rows] == ["done", "done"], rows
    fo = json.loads((tmp_path / "out" / "fo" / "fit" / "fit.json").read_text())
    assert all("piston" in t["omitted"] for t in fo["tests"])
    # 40 steps do not converge: every task ran, but the batch does not pass them as results
    summary = json.loads((tmp_path / "out" / "summary.json").read_text())
    assert [r["converged"] for r in rows] == ["False", "False"]
    assert summary["not_converged"] == 2 and code == 1
    assert [(v["campaign"], v["verdict"]) for v in summary["verdicts"]] == [
        ("fo", "not converged"),
        ("cat", "not converged"),
    ]
    assert "fo: not converged (not converged: fit)" in out and "NOT CONVERGED;" in out
    assert "NOT CONVERGED" in (tmp_path / "out" / "index.html").read_text()
    # asked to continue: the same (skipped, finished) tasks, exit 0
    code, _ = _run(
        ["batch", cat, "--out", tmp_path / "out", "--serial", "--quiet", "--allow-unconverged"]
    )
    assert code == 0
