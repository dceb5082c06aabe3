"""Every HTML page ``uq`` writes, rendered by a headless browser: a real page, not a blank one.

The screenshots are checked for size, ink and coloured figures (tests/browser.py); without
chromium these tests skip locally and fail in CI.
"""

from __future__ import annotations

import pytest
from browser import WINDOW, assert_real_page, page_stats, screenshot

import uq

SMALL = uq.Layout(pressures_bar=(1.0, 3.0, 5.0, 8.0), step_m=0.01)
QUICK = uq.Settings(max_steps=200)


@pytest.fixture(scope="module")
def small_campaign():
    return uq.simulate("n50", seed=4, layout=SMALL)


def test_the_checker_refuses_a_blank_page(tmp_path):
    page = tmp_path / "blank.html"
    page.write_text("<!doctype html><html><body></body></html>")
    stats = page_stats(screenshot(page, tmp_path / "blank.png"))
    assert stats["size"] == WINDOW and stats["inked"] < 0.01
    with pytest.raises(AssertionError, match="blank"):
        assert_real_page(tmp_path / "blank.png")


def test_report_page(small_campaign, tmp_path):
    fit = uq.fit_campaign(small_campaign, seed=4, settings=QUICK)
    page = uq.write_report(fit, tmp_path / "report", draws=100)
    assert_real_page(screenshot(page, tmp_path / "report.png"))


@pytest.mark.slow
def test_surface_page(small_campaign, tmp_path):
    from uq._models.surface import summary
    from uq._report.surface import write_surface_report

    fit = uq.fit_surface(small_campaign, uq.Orders(3, 2, 2, 1, 1), seed=4, settings=QUICK)
    page = write_surface_report(fit, summary(fit), tmp_path / "surface")
    assert_real_page(screenshot(page, tmp_path / "surface.png"))


@pytest.mark.slow
def test_diagnose_page(small_campaign, tmp_path):
    from uq._report.diagnose import write_diagnose_report

    found = uq.diagnose(small_campaign, seed=4, settings=QUICK, sample_final=False)
    page = write_diagnose_report(found, tmp_path / "diagnose")
    assert_real_page(screenshot(page, tmp_path / "diagnose.png"))


@pytest.mark.parametrize("ci, outcome", [("1", "failed"), ("", "skipped")])
def test_without_a_browser_ci_fails_and_a_laptop_skips(monkeypatch, ci, outcome):
    import browser

    monkeypatch.setattr(browser.shutil, "which", lambda name: None)
    monkeypatch.setenv("CI", ci)
    kind = pytest.fail.Exception if outcome == "failed" else pytest.skip.Exception
    with pytest.raises(kind, match="chromium is not installed"):
        browser.require_browser()
