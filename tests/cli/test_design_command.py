"""``uq design`` (uq/_cli/cmd_design.py) and its data sheet (uq/_report/design.py).

One small n50-thermo campaign (5 pressures every 10 mm, written by ``uq simulate``) is fitted once
by the library with the coverage script's tiny settings (the spring's own orders, 200 sampler
steps); the command's fit is replaced by that one, so these tests check the command, not the
sampler. The replaced fitter is the default model's (``registry.default("design")``, the surface
with a discrepancy in pressure: ``uq._models.discrepancy.fit_discrepancy``), so a command that
fitted another model than its default would fit for real and fail the tests' speed and answers;
the discrepancy's own design answers are checked in tests/models/test_discrepancy.py. The spring's absolute volume is known, so the answers are checked against the virtual
stand's sealed truth (uq._stand.sealed_test.sealed_truth, brentq on the spring's own volume).
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest
from cli_helpers import one_line, run

ROOT = Path(__file__).resolve().parents[2]
FORCE_ONLY = ROOT / "data" / "n50-force-only" / "recordings.csv"
CONTRACT = (
    "height_m",
    "charge_bar",
    "volume_l",
    "polytropic",
    "reservoir_l",
    "load_N",
    "rate_N_per_m",
    "natural_frequency_Hz",
)
ESTIMATES = ("load_N", "rate_N_per_m", "natural_frequency_Hz")


@pytest.fixture(scope="module")
def thermo_campaign(tmp_path_factory):
    """(folder, CSV, the surface fit of it, the spring's true volume at 112 mm and 5 bar, litres)."""
    from uq._data.recordings import read_recordings
    from uq._inference.sampler import Settings
    from uq._models.surface import Orders
    from uq._models.surface_likelihood import fit_surface
    from uq._stand.sealed_test import sealed_truth

    d = tmp_path_factory.mktemp("design")
    path = d / "thermo.csv"
    argv = ["simulate", "--spring", "n50-thermo", "--pressures", "1,3,5,7,9"]
    assert run([*argv, "--step-mm", "10", "--seed", "11", "--out", path]) == 0
    fit = fit_surface(
        read_recordings(path),
        Orders(3, 1, 2, 2, 1),
        seed=11,
        settings=Settings(max_steps=200),
        max_draws=1000,
    )
    v_c = sealed_truth("n50-thermo", np.array([0.112]), charge_bar=5.0).volume_c_m3 * 1e3
    return d, path, fit, v_c


@pytest.fixture
def given_fit(thermo_campaign, monkeypatch):
    """The command's fit (its default model's fitter) is the fixture's (no sampler run)."""
    import uq._models.discrepancy as default_model

    fit = thermo_campaign[2]
    monkeypatch.setattr(default_model, "fit_discrepancy", lambda rec, **k: fit)
    return fit


@pytest.fixture
def no_fitting(monkeypatch):
    """Every fit fails the test: bad input must be refused before any fitting."""
    # imported before the patch: a module that binds a fitter by name when first imported (the
    # comparison's `from uq._models.cubic_fit import fit_campaign`) would otherwise keep the
    # forbidden one for every later test of this process
    import uq._derived.comparison  # noqa: F401
    import uq._models.cubic_fit
    import uq._models.discrepancy
    import uq._models.surface_likelihood
    import uq._models.thermo_likelihood

    def forbidden(*a, **k):
        raise AssertionError("a fit started before the options were validated")

    monkeypatch.setattr(uq._models.surface_likelihood, "fit_surface", forbidden)
    monkeypatch.setattr(uq._models.discrepancy, "fit_discrepancy", forbidden)
    monkeypatch.setattr(uq._models.thermo_likelihood, "fit_thermo", forbidden)
    monkeypatch.setattr(uq._models.cubic_fit, "fit_campaign", forbidden)


def _truth(x_m, **kw):
    from uq._stand.sealed_test import sealed_truth

    return sealed_truth("n50-thermo", np.asarray(x_m, float), **kw)


@pytest.fixture(scope="module")
def sheet(thermo_campaign, tmp_path_factory):
    """One ``uq design --json --out`` run on the campaign: (its JSON, the sheet folder, stdout)."""
    import uq._models.discrepancy as default_model

    d, path, fit, v_c = thermo_campaign
    out = tmp_path_factory.mktemp("sheet")
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(default_model, "fit_discrepancy", lambda rec, **k: fit)
        import contextlib
        import io

        buf = io.StringIO()
        with contextlib.redirect_stdout(buf):
            status = run(
                [
                    "design",
                    path,
                    "--height-mm",
                    112,
                    "--charge-bar",
                    5,
                    "--volume-l",
                    f"{v_c:.6f}",
                    "--forcing-hz",
                    4,
                    "--charges-bar",
                    "3,5,7,9",
                    "--polytropic",
                    1,  # the truth's (slow strokes); the default is the dynamic 1.3..1.4
                    "--draws",
                    500,
                    "--json",
                    out / "result.json",
                    "--out",
                    out / "sheet",
                    "--quiet",
                    "--allow-unconverged",  # the fixture's short chains
                ]
            )
    assert status == 0, buf.getvalue()
    return json.loads((out / "result.json").read_text()), out / "sheet", buf.getvalue()


def test_json_has_the_contract_keys_and_states_the_volume_assumption(sheet, thermo_campaign):
    res, _, _ = sheet
    assert list(res)[: len(CONTRACT)] == list(CONTRACT)
    assert res["height_m"] == 0.112 and res["charge_bar"] == 5.0 and res["polytropic"] == 1.0
    assert res["reservoir_l"] == 0.0 and res["volume_l"] == pytest.approx(thermo_campaign[3])
    for key in ESTIMATES:
        e = res[key]
        assert set(e) == {"mean", "sd", "q05", "q95"}
        assert e["q05"] < e["mean"] < e["q95"] and e["sd"] > 0
    words = " ".join(res["assumptions"])
    assert "ASSUMED: the volume at 112 mm does not change with pressure" in words
    # with an honest width from the recordings (issue 29): 0 +- sd L/bar, drawn per draw
    assert res["dvdp_l_per_bar"] == 0.0 and res["dvdp_sd_from"] == "recordings"
    assert res["dvdp_sd_l_per_bar"] > 0 and "give or take" in words
    check = res["model_check"]
    assert check["available"] and check["model"] == res["model"]
    assert [r["pressure_bar"] for r in check["by_pressure"]] == [1.0, 3.0, 5.0, 7.0, 9.0]
    assert "measured by the user" in words and "isothermal" in words
    assert res["transmissibility"]["forcing_Hz"] == 4.0


def test_answers_against_the_stands_sealed_truth(sheet, thermo_campaign):
    """Load within 1 %, rate 3 %, frequency 2 % of the stand's truth (the spring's own volume; its
    dV/dp_u at x0 is 0, so the contract's assumption is exact here); f = sqrt(k g / P) / 2 pi
    holds between the reported estimates; the transmissibility is that of the mean frequency."""
    res, _, _ = sheet
    tr = _truth([0.112], charge_bar=5.0)
    for key, true, tol in (
        ("load_N", tr.force_N[0], 0.01),
        ("rate_N_per_m", tr.rate_N_per_m[0], 0.03),
        ("natural_frequency_Hz", tr.natural_frequency_Hz[0], 0.02),
    ):
        assert res[key]["mean"] == pytest.approx(true, rel=tol), key
    f = math.sqrt(res["rate_N_per_m"]["mean"] * 9.80665 / res["load_N"]["mean"]) / (2 * math.pi)
    assert res["natural_frequency_Hz"]["mean"] == pytest.approx(f, rel=2e-3)
    r = 4.0 / res["natural_frequency_Hz"]["mean"]
    assert res["transmissibility"]["transmissibility"]["mean"] == pytest.approx(
        1 / abs(1 - r**2), rel=0.01
    )


def test_isobaric_table_against_the_spring(sheet):
    """Loads and areas of the table near the spring's own (1.5 %), the volume increment from the
    design height near the spring's V(x, p) - V(112 mm, p) (2 % of the spring's volume)."""
    from uq._stand.simulator import ThermoSpring

    res, _, _ = sheet
    s = ThermoSpring()
    rows = res["isobaric"]
    assert {r["pressure_bar"] for r in rows} == {1.0, 3.0, 5.0, 7.0, 9.0}
    v112 = {p: float(s.volume_m3(np.array(0.112), p)) for p in (1.0, 3.0, 5.0, 7.0, 9.0)}
    for r in rows:
        x, p = r["height_m"], r["pressure_bar"]
        assert r["load_N"]["mean"] == pytest.approx(float(s.force_N(np.array(x), p)), rel=0.015)
        assert r["feff_m2"]["mean"] == pytest.approx(r["load_N"]["mean"] / (p * 1e5), rel=1e-9)
        true_dv = (float(s.volume_m3(np.array(x), p)) - v112[p]) * 1e3
        assert abs(r["volume_increment_l"]["mean"] - true_dv) < 0.02 * v112[p] * 1e3, (x, p)
        if x == 0.112:
            assert r["volume_increment_l"]["sd"] == 0.0


def test_summary_is_short_and_the_sheet_is_complete(sheet):
    res, folder, text = sheet
    lines = [ln for ln in text.splitlines() if ln.strip()]
    assert 4 <= len(lines) <= 10, text
    assert "natural frequency" in lines[1] and "ASSUMED" in text and "data sheet" in text
    names = sorted(p.name for p in folder.iterdir())
    assert names == sorted(
        [
            "design.csv",
            "design.html",
            "design.json",
            "design_frequency.png",
            "design_isobaric.png",
            "design_sealed.png",
        ]
    ), names  # no staging folder left behind
    assert json.loads((folder / "design.json").read_text()) == res
    with open(folder / "design.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    n_iso, n_chart = len(res["isobaric"]), len(res["frequency_chart"]["rows"])
    # the design point's own rows: load, rate, frequency, transmissibility and isolation at 4 Hz
    assert len(rows) == 4 * n_iso + 3 * n_chart + 5
    assert {r["quantity"] for r in rows if r["table"] == "design_point"} == {
        "load",
        "rate",
        "natural_frequency",
        "transmissibility_at_4Hz",
        "isolation_at_4Hz",
    }
    rate_at_5 = [
        r
        for r in rows
        if r["quantity"] == "rate" and r["charge_bar"] == "5" and r["table"] != "isobaric"
    ]
    assert float(rate_at_5[0]["mean"]) == pytest.approx(res["rate_N_per_m"]["mean"], rel=1e-5)
    page = (folder / "design.html").read_text()
    assert "Reconstructed data" in page and "not measured" in page
    # the fixture's short chains: the sheet opens with the banner (issue 29)
    assert res["source"]["converged"] is False and "NOT CONVERGED: surface model" in page
    assert "ASSUMED: the volume at 112 mm" in page
    assert "the model at the tested points" in page and "inside their 90% predictive" in page
    assert page.count("data:image/png;base64,") == 3


def test_sheet_shows_a_design_charge_that_was_not_tested_and_ranks_the_model(
    thermo_campaign, given_fit, tmp_path
):
    """A charge between the tested pressures (6 bar of 1, 3, 5, 7, 9): the sheet draws the design
    point on the frequency chart and its sealed curve, tabulates it (the chart's row in bold, the
    isobaric table's column at 6 bar marked "not tested", design.csv's design_point rows), and
    says which model answered and how PSIS-LOO ranks it against the per-pressure cubics."""
    _, path, _, v_c = thermo_campaign
    out = tmp_path / "sheet"
    argv = ["design", path, "--height-mm", 112, "--charge-bar", 6, "--volume-l", f"{v_c:.6f}"]
    argv += ["--charges-bar", "3,5,7", "--draws", 200, "--out", out, "--json", tmp_path / "r.json"]
    assert run([*argv, "--quiet", "--allow-unconverged"]) == 0
    res = json.loads((tmp_path / "r.json").read_text())
    assert res["tested_pressures_bar"] == [1.0, 3.0, 5.0, 7.0, 9.0]
    assert {r["pressure_bar"] for r in res["isobaric"]} == {1.0, 3.0, 5.0, 6.0, 7.0, 9.0}
    c = res["comparison"]
    assert c["better"] in ("surface", "per-pressure cubics", "indistinguishable", "refused")
    page = (out / "design.html").read_text()
    assert "6 bar is not a tested pressure" in page and "design charge, not tested" in page
    assert "how the data rank it" in page and res["model"] in page
    assert "<span class='small'>design, not tested</span>" in page  # the chart's design row
    with open(out / "design.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    design = {r["quantity"]: r for r in rows if r["table"] == "design_point"}
    assert design["load"]["charge_bar"] == "6"
    assert float(design["natural_frequency"]["mean"]) == pytest.approx(
        res["natural_frequency_Hz"]["mean"], rel=1e-5
    )
    assert {r["pressure_bar"] for r in rows if r["table"] == "isobaric_design_charge"} == {"6"}
    # the same run without the ranking says so
    argv2 = [*argv[:-4], "--json", tmp_path / "n.json", "--no-compare", "--quiet"]
    assert run([*argv2, "--allow-unconverged"]) == 0
    assert json.loads((tmp_path / "n.json").read_text())["comparison"] is None


def test_figures_drawn_by_the_worker_are_the_ones_drawn_here(
    thermo_campaign, given_fit, tmp_path, monkeypatch
):
    """With a comparison worker, ``uq design --out`` has it draw the sheet's figures after it has
    compared (uq._report.design.compare_then_draw); the sheet is the one drawn without a worker,
    file for file and byte for byte, and the comparison the same."""
    from uq._derived import comparison_worker

    _, path, _, v_c = thermo_campaign
    argv = ["design", path, "--height-mm", 112, "--charge-bar", 5, "--volume-l", f"{v_c:.6f}"]
    argv += ["--charges-bar", "3,7", "--draws", 200, "--quiet", "--allow-unconverged"]
    monkeypatch.setattr(comparison_worker, "WORKER_MIN_READINGS", 0)
    sheets = {}
    for n in (1, 2):  # one CPU: no worker; two: the worker compares and draws
        monkeypatch.setattr(comparison_worker, "cores", lambda n=n: n)
        out = tmp_path / f"cores{n}"
        assert run([*argv, "--out", out / "sheet", "--json", out / "r.json"]) == 0
        sheets[n] = {f.name: f.read_bytes() for f in sorted((out / "sheet").iterdir())}
        sheets[n]["r.json"] = (out / "r.json").read_bytes()
    assert sheets[1] == sheets[2]
    assert {"design_isobaric.png", "design_sealed.png", "design_frequency.png"} <= set(sheets[2])


def test_sheet_in_a_browser(sheet, tmp_path):
    """The data sheet rendered by headless Chromium: a real page with figures, nothing off the edge."""
    from browser import assert_real_page, screenshot

    _, folder, _ = sheet
    png = screenshot(folder / "design.html", tmp_path / "design.png")
    assert_real_page(png)


def test_polytropic_range_reservoir_and_given_dvdp(thermo_campaign, given_fit, tmp_path):
    """A range of n is stated and drawn; a reservoir softens the rate as the truth does; a given
    dV/dp_u is stated as GIVEN and changes the rate in the direction the gas law says."""
    _, path, _, v_c = thermo_campaign
    base = ["design", path, "--height-mm", 112, "--charge-bar", 5, "--volume-l", f"{v_c:.6f}"]
    base += ["--allow-unconverged"]  # the fixture's short chains
    base += ["--draws", 400, "--charges-bar", "3,5"]  # fewer draws and charges: quicker
    out = {}
    for name, extra in (
        ("range", ["--polytropic", "1.0..1.4"]),
        ("reservoir", ["--polytropic", "1.4", "--reservoir-l", "2"]),
        ("dvdp", ["--polytropic", "1.4", "--dvdp-l-per-bar", "0.05"]),
        ("adiabatic", ["--polytropic", "1.4"]),
    ):
        assert run([*base, *extra, "--json", tmp_path / f"{name}.json", "--quiet"]) == 0
        out[name] = json.loads((tmp_path / f"{name}.json").read_text())
    assert out["range"]["polytropic"] == pytest.approx(1.2) and out["range"][
        "polytropic_range"
    ] == [1.0, 1.4]
    assert "uniform in 1..1.4" in " ".join(out["range"]["assumptions"])
    k = {n: out[n]["rate_N_per_m"]["mean"] for n in out}
    tr = _truth([0.112], charge_bar=5.0, polytropic=1.4, reservoir_m3=0.002)
    assert k["reservoir"] == pytest.approx(tr.rate_N_per_m[0], rel=0.03)
    assert k["reservoir"] < k["adiabatic"]
    assert k["dvdp"] < k["adiabatic"]  # a casing whose volume grows with pressure softens the gas
    assert "GIVEN: the volume at 112 mm changes by 0.05 L per bar" in " ".join(
        out["dvdp"]["assumptions"]
    )
    assert out["range"]["rate_N_per_m"]["sd"] > out["adiabatic"]["rate_N_per_m"]["sd"]


@pytest.mark.parametrize(
    "extra, words",
    [
        ([], ["--volume-l", "water"]),
        (["--volume-l", 3.4, "--polytropic", "1.6"], ["--polytropic"]),
        (["--volume-l", 3.4, "--polytropic", "1.4..1.0"], ["--polytropic"]),
        (["--volume-l", 3.4, "--polytropic", "x"], ["--polytropic"]),
        (["--volume-l", 0], ["--volume-l"]),
        (["--volume-l", 3.4, "--volume-sd-l", 1.0], ["--volume-sd-l", "quarter"]),
        (["--volume-l", 3.4, "--reservoir-l", -1], ["--reservoir-l"]),
        (["--volume-l", 3.4, "--dvdp-l-per-bar", "model"], ["--dvdp-l-per-bar", "thermodynamic"]),
        (["--volume-l", 3.4, "--dvdp-l-per-bar", "abc"], ["--dvdp-l-per-bar"]),
        (["--volume-l", 3.4, "--forcing-hz", 0], ["--forcing-hz"]),
        (["--volume-l", 3.4, "--charges-bar", "2,20"], ["--charges-bar", "20"]),
        (["--volume-l", 3.4, "--sheet-heights-mm", "200"], ["--sheet-heights-mm", "200"]),
    ],
)
def test_bad_input_one_line_exit_2_before_fitting(
    extra, words, thermo_campaign, no_fitting, tmp_path, capsys
):
    _, path, _, _ = thermo_campaign
    out = tmp_path / "r.json"
    argv = ["design", path, "--height-mm", 112, "--charge-bar", 5, *extra, "--json", out]
    assert run(argv) == 2
    line = one_line(capsys.readouterr().err)
    for w in words:
        assert w in line, line
    assert not out.exists()


@pytest.mark.parametrize(
    "height, charge, option",
    [(200, 5, "--height-mm"), (112, 12, "--charge-bar"), (112, 0.5, "--charge-bar")],
)
def test_outside_the_tested_ranges_refused(
    height, charge, option, thermo_campaign, no_fitting, capsys
):
    _, path, _, _ = thermo_campaign
    argv = ["design", path, "--height-mm", height, "--charge-bar", charge, "--volume-l", 3.4]
    assert run(argv) == 2
    line = one_line(capsys.readouterr().err)
    assert option in line and "does not extrapolate" in line


def test_force_only_campaign_gives_isobaric_loads_and_says_why(tmp_path, capsys):
    """data/n50-force-only: no piston, so no volume: the isobaric loads (the per-pressure cubics of
    ``uq fit``, its force-only cubic per test, interpolated in pressure), the sealed keys null and
    one line saying why. The loads are checked against the spring's truth (Table 1's cubics, from
    which the stand made the file)."""
    out = tmp_path / "f.json"
    argv = ["design", FORCE_ONLY, "--height-mm", 112, "--charge-bar", 5, "--json", out]
    argv += ["--max-steps", 600, "--quiet"]  # short chains: the wiring, not the sampler
    assert run([*argv, "--out", tmp_path / "sheet"]) == 0
    text = capsys.readouterr().out
    assert sum("omitted" in ln for ln in text.splitlines()) == 1
    assert "force-only" in text and "no piston_mm column" in text
    res = json.loads(out.read_text())
    assert list(res)[: len(CONTRACT)] == list(CONTRACT)
    assert res["rate_N_per_m"] is None and res["natural_frequency_Hz"] is None
    assert "volume-derived area" in res["omitted"]
    table = json.loads((ROOT / "fits" / "n50" / "table1_points.json").read_text())["tests"]
    truth = {t["pressure_bar"]: t["force"] for t in table}
    z = []
    for r in res["isobaric"]:
        c, u = truth[r["pressure_bar"]], r["height_m"] - 0.112
        true = c["a_P"] + c["b_P"] * u + c["c_P"] * u**2 + c["d_P"] * u**3
        z.append((r["load_N"]["mean"] - true) / r["load_N"]["sd"])
        assert "volume_increment_l" not in r
    z = np.array(z)
    assert np.sqrt(np.mean(z**2)) < 2.0 and np.abs(z).max() < 5.0, z
    assert res["load_N"]["mean"] == pytest.approx(13020.0, rel=0.005)
    page = (tmp_path / "sheet" / "design.html").read_text()
    assert "volume-derived area" in page and "design_sealed" not in page


def test_json_dash_prints_only_json(thermo_campaign, given_fit, capsys):
    _, path, _, v_c = thermo_campaign
    argv = ["design", path, "--height-mm", 112, "--charge-bar", 5, "--volume-l", f"{v_c:.4f}"]
    argv += ["--draws", 200, "--charges-bar", "5", "--allow-unconverged"]
    assert run([*argv, "--json", "-"]) == 0
    captured = capsys.readouterr()
    assert json.loads(captured.out)["charge_bar"] == 5.0
    assert "natural frequency" in captured.err


def test_same_seed_same_numbers(thermo_campaign, given_fit, tmp_path):
    """The drawn inputs (V_c with its sd, n in a range) are seeded: a rerun gives the same bytes."""
    _, path, _, v_c = thermo_campaign
    argv = ["design", path, "--height-mm", 112, "--charge-bar", 5, "--volume-l", f"{v_c:.4f}"]
    argv += ["--volume-sd-l", "0.05", "--polytropic", "1.0..1.4", "--charges-bar", "3,5"]
    argv += ["--draws", 300, "--allow-unconverged"]
    texts = []
    for i in range(2):
        assert run([*argv, "--json", tmp_path / f"{i}.json", "--quiet"]) == 0
        texts.append((tmp_path / f"{i}.json").read_bytes())
    assert texts[0] == texts[1]


@pytest.mark.slow  # a thermodynamic fit: about 1-3 min on 2 cores
def test_thermodynamic_model_with_its_own_dvdp(thermo_campaign, tmp_path):
    """``--model thermodynamic --dvdp-l-per-bar model``: the potential's own dV/dp_u (gauge 0 at
    x0, exact for this spring, whose volume at x0 does not change with pressure), stated as such;
    the answers near the stand's truth; 'model' with the surface model refused."""
    _, path, _, v_c = thermo_campaign
    out = tmp_path / "t.json"
    argv = ["design", path, "--height-mm", 112, "--charge-bar", 5, "--volume-l", f"{v_c:.6f}"]
    argv += ["--model", "thermodynamic", "--dvdp-l-per-bar", "model", "--max-steps", 300]
    argv += ["--allow-unconverged", "--polytropic", 1]  # the truth's n (the default is 1.3..1.4)
    assert run([*argv, "--json", out, "--quiet"]) == 0
    res = json.loads(out.read_text())
    assert res["dvdp_l_per_bar"] == "model" and res["model"].startswith("thermodynamic model")
    assert "ASSUMED 0 at x0" in " ".join(res["assumptions"])
    tr = _truth([0.112], charge_bar=5.0)
    assert res["load_N"]["mean"] == pytest.approx(tr.force_N[0], rel=0.01)
    assert res["rate_N_per_m"]["mean"] == pytest.approx(tr.rate_N_per_m[0], rel=0.03)
    assert res["natural_frequency_Hz"]["mean"] == pytest.approx(
        tr.natural_frequency_Hz[0], rel=0.02
    )
