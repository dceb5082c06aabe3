"""Every HTML page ``uq`` writes, rendered by a headless browser: a real page, not a blank one,
with nothing running off its right edge, and saying what it should.

The screenshots are checked for size, ink, coloured figures and an empty right margin
(tests/browser.py); without chromium these tests skip locally and fail in CI. Small fits (four
pressures, short chains) keep the report, thermodynamic and diagnose pages in the fast suite.
"""

from __future__ import annotations

import dataclasses
import re

import pytest
from browser import WINDOW, assert_real_page, page_stats, screenshot
from figure_text import overlaps

import uq
from uq._derived.comparison import compare

QUICK = uq.Settings(max_steps=200)
NOISE_CODE_NAMES = ("s0_N", "rel_load", "k_p", "sL_m", "V0_m3", "σ0", "σ_L")


# small_campaign and small_cubics (four pressures, 200 steps) are shared with the figure tests:
# tests/conftest.py fits them once per session


def test_the_checker_refuses_a_blank_page(tmp_path):
    page = tmp_path / "blank.html"
    page.write_text("<!doctype html><html><body></body></html>")
    stats = page_stats(screenshot(page, tmp_path / "blank.png"))
    assert stats["size"] == WINDOW and stats["inked"] < 0.01
    with pytest.raises(AssertionError, match="blank"):
        assert_real_page(tmp_path / "blank.png")


def test_the_checker_refuses_text_that_runs_off_the_page(tmp_path):
    """diagnose.html had no style sheet: its summary ran off the right edge of the window."""
    page = tmp_path / "wide.html"
    line = "force residual by height band, " * 12
    page.write_text(f"<!doctype html><html><body><pre>{(line + chr(10)) * 150}</pre></body></html>")
    with pytest.raises(AssertionError, match="runs off"):
        assert_real_page(screenshot(page, tmp_path / "wide.png"), figures=False)


def _words_not_code(text: str) -> None:
    """Noise parameters appear under words (floor, load cell, piston floor), not code names."""
    for words in ("floor", "load cell", "piston floor"):
        assert words in text, words
    for code in NOISE_CODE_NAMES:
        assert code not in text, code


@pytest.mark.parametrize("figure_format", ["png", "svg"])
def test_report_page(small_cubics, tmp_path, figure_format):
    page = uq.write_report(
        small_cubics, tmp_path / "report", draws=100, figure_format=figure_format
    )
    assert_real_page(screenshot(page, tmp_path / "report.png"))
    text = page.read_text(encoding="utf-8")
    mime = {"png": "image/png", "svg": "image/svg+xml"}[figure_format]
    assert text.count(f"data:{mime};base64,") == 5 + len(small_cubics.tests)
    assert "too narrow to see" in text and "colour bar" in text
    _words_not_code(text)


def _readable(*figures) -> None:
    """No title or label of these figures on another (tests/figure_text.py)."""
    from uq._report.html import pyplot

    for fig in figures:
        try:
            assert overlaps(fig) == [], fig.axes[0].get_title()
        finally:
            pyplot().close(fig)


def _comparison_checks(text: str, comparison: dict, name: str) -> None:
    """The page says which model the recordings prefer, as the comparison does, and its table
    holds both models' numbers."""
    what = {"surface": "the surface model", "thermodynamic": "the thermodynamic model"}[name]
    better = comparison["better"]
    if better == "per-pressure cubics":
        assert f"The recordings prefer the per-pressure cubics to {what}" in text
    elif better == name:
        assert f"The recordings prefer {what} to the per-pressure cubics" in text
    elif better == "indistinguishable":
        assert "The recordings prefer neither" in text
    else:
        assert "No verdict" in text
    for label, key in ((what, name), ("the per-pressure cubics", "cubics")):
        row = re.search(rf"<td class='l'>{label}</td><td>(-?[0-9.]+)</td>", text)
        assert row and float(row.group(1)) == pytest.approx(comparison[key]["elpd_loo"], abs=0.06)
    assert f"{comparison['elpd_diff']:+.1f}" in text


@pytest.mark.slow  # fast: the report and diagnose pages here, the design sheet in test_design_command
def test_thermodynamic_page(small_campaign, small_cubics, tmp_path):
    from uq._models.thermo import ThermoOrders
    from uq._report import model_page, thermo
    from uq._report.thermo import write_thermo_report

    # room to converge: at 200 steps the fit stopped at ESS 361 on a CPU without AVX2, and the
    # page's sampler warnings then name the parameters by their code names
    fit = uq.fit_thermo(
        small_campaign, ThermoOrders(4, 3), seed=4, settings=uq.Settings(max_steps=2000)
    )
    comparison = compare(fit, small_cubics, seed=4, settings=QUICK)
    result = fit.to_json(comparison)
    page = write_thermo_report(fit, result, tmp_path / "thermo")
    assert page.name == "thermodynamic.html"
    assert_real_page(screenshot(page, tmp_path / "thermo.png"))
    text = page.read_text(encoding="utf-8")
    assert text.count("data:image/png;base64,") == 4
    _comparison_checks(text, comparison, "thermodynamic")
    implied = result["implied_piston_area_m2"]
    assert f"S = <b>{implied['mean'] * 1e4:.2f} cm²</b>" in text
    assert f"{implied['q05'] * 1e4:.2f} – {implied['q95'] * 1e4:.2f} cm²" in text
    for p, r in result["at_x0"].items():  # the Maxwell ratio at x0, per pressure
        assert f"<tr><th>{p}</th>" in text and f"{r['maxwell_ratio']['mean']:.3f}" in text
    _words_not_code(text)
    _readable(
        model_page.figure_residual_overlay(fit),
        thermo.figure_areas(fit),
        thermo.figure_maxwell(fit),
        thermo.figure_piston_area(fit),
    )


@pytest.mark.slow
def test_surface_page(small_campaign, small_cubics, tmp_path):
    from uq._models.surface import summary
    from uq._report import model_page, surface
    from uq._report.surface import write_surface_report

    fit = uq.fit_surface(small_campaign, uq.Orders(3, 2, 2, 1, 1), seed=4, settings=QUICK)
    comparison = compare(fit, small_cubics, seed=4, settings=QUICK)
    page = write_surface_report(fit, summary(fit, comparison), tmp_path / "surface")
    assert_real_page(screenshot(page, tmp_path / "surface.png"))
    text = page.read_text(encoding="utf-8")
    _comparison_checks(text, comparison, "surface")
    _words_not_code(text)
    _readable(
        surface.figure_pressure_area(fit),
        surface.figure_spread(fit),
        model_page.figure_residual_overlay(fit),
    )


@pytest.fixture(scope="module")
def small_diagnosis(small_campaign):
    return uq.diagnose(small_campaign, seed=4, settings=QUICK, sample_final=False)


def test_diagnose_page(small_diagnosis, small_campaign, tmp_path):
    from uq._report.diagnose import write_diagnose_report

    found = small_diagnosis
    page = write_diagnose_report(found, tmp_path / "diagnose")
    assert_real_page(screenshot(page, tmp_path / "diagnose.png"))
    text = page.read_text(encoding="utf-8")
    assert "max-width:1250px" in text  # the project's style sheet
    assert text.count("data:image/png;base64,") == 1
    for m in found["mechanisms"]:  # a row each, with magnitude and interval
        mg = m["magnitude"]
        assert f"<code>{m['name']}</code></td>" in text
        assert f"{mg['q05']:.4g} – {mg['q95']:.4g}" in text
        if "other_reading" in m:
            assert "The other reading of the same numbers" in text
    mx = found["maxwell"]
    assert text.count("<td class='out'>") == sum(r["breaks"] for r in mx["rows"])
    for p in small_campaign.pressures_bar:
        assert f"<tr><th>{p:g}</th><td" in text
    assert mx["interpretation"]["words"].replace("'", "&#x27;") in text
    assert "Every mechanism was offered" in text


def test_diagnose_page_names_what_was_not_offered_and_why(small_diagnosis, tmp_path):
    """A campaign that cannot identify a mechanism: the page lists it with the reason the
    engine gives (here put into a copy of the document)."""
    from uq._report.diagnose import write_diagnose_report

    doc = dict(small_diagnosis.document)
    why = {"hysteresis": "needs compression and rebound in a known recording order"}
    doc["selection"] = doc["selection"] | {"not_offered": why}
    page = write_diagnose_report(dataclasses.replace(small_diagnosis, document=doc), tmp_path)
    text = page.read_text(encoding="utf-8")
    assert "<td class='l'><code>hysteresis</code></td><td class='l'>needs compression" in text
    assert "Every mechanism was offered" not in text


@pytest.mark.parametrize("ci, outcome", [("1", "failed"), ("", "skipped")])
def test_without_a_browser_ci_fails_and_a_laptop_skips(monkeypatch, ci, outcome):
    import browser

    monkeypatch.setattr(browser.shutil, "which", lambda name: None)
    monkeypatch.setenv("CI", ci)
    kind = pytest.fail.Exception if outcome == "failed" else pytest.skip.Exception
    with pytest.raises(kind, match="chromium is not installed"):
        browser.require_browser()
