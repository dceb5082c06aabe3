"""``uq report``: the HTML page, its figures, and the CLI end to end."""

from __future__ import annotations

import base64
import re

import pytest

from uq._cli.main import main
from uq._data.rows import leading_comments
from uq._derived.bands import campaign_bands
from uq._report.campaign import FigureWorkers, write_report


def _check_page(out, n_tests):
    page = (out / "report.html").read_text(encoding="utf-8")
    imgs = re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', page)
    assert len(imgs) == 5 + n_tests  # Figs 2-5, scatter, one per pressure
    assert all(base64.b64decode(s)[:8] == b"\x89PNG\r\n\x1a\n" for s in imgs)
    pngs = sorted(p.name for p in out.glob("*.png"))
    assert len(pngs) == 5 + n_tests
    assert not [p.name for p in out.iterdir() if p.name.startswith(".") or p.suffix == ".tmp"]
    return page


def test_report_on_n50_fixture(n50_fit, tmp_path):
    cb = campaign_bands(n50_fit, n_draws=300, seed=0)
    path = write_report(n50_fit, tmp_path / "rep", bands=cb)
    assert path == tmp_path / "rep" / "report.html"
    page = _check_page(tmp_path / "rep", len(n50_fit.tests))
    assert "Reconstructed data" in page  # data/n50's comment lines say RECONSTRUCTED
    for text in (
        "Table 1",
        "Table 2",
        "Sampler diagnostics",
        "8.41",
        "75 mm",
        "hysteresis",
        "kN/m²",
        "10³ kN/m³",
    ):
        assert text in page, text
    # Table 1 beside the paper's values, one row per pressure, a paper value in every cell
    assert page.count("paper ") >= 8 * len(n50_fit.tests)
    assert "5-bar test" in page and "Figure 5" in page
    for p in (0.1, 5, 10):
        assert f"test_{p:g}bar.png" in page
    assert n50_fit.converged and "NOT CONVERGED" not in page  # no banner on a converged fit


def test_an_unconverged_fit_opens_with_a_banner_and_every_figure_is_stamped(tmp_path, monkeypatch):
    """Issue 29: a fit whose convergence rules fail cannot pass as a result: the page opens with
    the NOT CONVERGED banner naming the tests and their failed rules, and every figure drawn from
    the fit (the campaign's, and the failing tests' own) carries the stamp, also as a file."""
    import uq
    import uq._report.campaign as campaign
    from uq._report.html import stamp_unconverged

    rec = uq.simulate("n50", seed=3, layout=uq.Layout(pressures_bar=(2.0, 6.0), step_m=0.01))
    short = uq.Settings(n_walkers=8, n_ensembles=2, min_steps=12, chunk=4, max_steps=16)
    fit = uq.fit_campaign(rec, seed=3, settings=short)
    assert not fit.converged
    stamped = []

    def stamp(fig, what):
        stamped.append(what)
        stamp_unconverged(fig, what)
        assert any("NOT CONVERGED" in t.get_text() for t in fig.texts)

    monkeypatch.setattr(campaign, "stamp_unconverged", stamp)
    write_report(fit, tmp_path / "rep", draws=200)
    page = (tmp_path / "rep" / "report.html").read_text(encoding="utf-8")
    head = page[: page.index("<h2")]
    assert "NOT CONVERGED: 2 of 2 tests (2, 6 bar)" in head and "R-hat" in page
    assert "--allow-unconverged" in head
    n_figures = len(list((tmp_path / "rep").glob("*.png")))
    assert len(stamped) == n_figures  # the campaign's figures and both tests' own
    assert stamped.count("the 2 bar test") == 1 and stamped.count("the 6 bar test") == 1


def test_figures_drawn_by_workers_are_the_figures_drawn_here(n50_fit, tmp_path, monkeypatch):
    """write_report's worker processes (the default on a multi-core machine) change nothing:
    every PNG and the page are byte for byte those of jobs=1 (the footer's date fixed, as
    SOURCE_DATE_EPOCH does for a reproducible page: the two pages may be written a minute apart).
    The workers are started ahead and given each test's figure as soon as its bands are made, as
    uq report does (jobs=2 makes the same FigureWorkers(2, n) itself and asks for the figures in
    write_report); the figures they have not started when this process is done with the
    campaign's are drawn here (which ones depends on timing: every figure must be the same)."""
    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1764115200")
    cb = campaign_bands(n50_fit, n_draws=200, seed=0)
    write_report(n50_fit, tmp_path / "one", bands=cb, jobs=1)
    with FigureWorkers(2, len(n50_fit.tests)) as workers:
        assert workers.pool is not None
        ahead = campaign_bands(n50_fit, n_draws=200, seed=0, on_test=workers.ahead(n50_fit))
        write_report(n50_fit, tmp_path / "two", bands=ahead, jobs=workers)
    names = sorted(p.name for p in (tmp_path / "one").iterdir())
    assert names == sorted(p.name for p in (tmp_path / "two").iterdir()) and len(names) == 6 + len(
        n50_fit.tests
    )
    for n in names:
        assert (tmp_path / "one" / n).read_bytes() == (tmp_path / "two" / n).read_bytes(), n


def test_comments_are_read_only_from_the_top(tmp_path):
    f = tmp_path / "r.csv"
    f.write_text(
        "# RECONSTRUCTED by the stand\n#  second\npressure_bar,height_mm\n# not a header comment\n"
    )
    assert leading_comments(f.read_text().splitlines()) == ["RECONSTRUCTED by the stand", "second"]


@pytest.fixture(scope="module")
def small_csv(tmp_path_factory):
    d = tmp_path_factory.mktemp("small")
    csv = d / "r.csv"
    assert main(["simulate", "--out", str(csv), "--pressures", "1,5,10", "--seed", "7"]) == 0
    return csv


def test_report_cli_small_campaign(small_csv, tmp_path, capsys):
    out = tmp_path / "out"
    js = tmp_path / "fit.json"
    rc = main(
        [
            "report",
            str(small_csv),
            "--out",
            str(out),
            "--json",
            str(js),
            "--max-steps",
            "600",
            "--draws",
            "300",
            "--allow-unconverged",
        ]
    )
    assert rc == 0
    printed = capsys.readouterr().out
    assert f"report: {out / 'report.html'}" in printed
    assert "F_eff scatter across 1, 5, 10 bar" in printed
    # the console says it too, not only the page: the stand's file says RECONSTRUCTED
    assert "RECONSTRUCTED recordings (the file's header says so), not measured data" in printed
    page = _check_page(out, 3)
    assert "Reconstructed data" in page
    import json

    data = json.loads(js.read_text())
    assert [t["pressure_bar"] for t in data["tests"]] == [1.0, 5.0, 10.0]
    assert data["bands"]["reference_bar"] == 5.0
    assert set(data["bands"]["feff_scatter_pct"]["at"]) == {"x0", "x_max", "x_min", "75 mm"}
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(".")]


def test_report_cli_bad_input(tmp_path, capsys):
    bad = tmp_path / "bad.csv"
    bad.write_text("pressure_bar,height_mm\n1,100\n")
    assert main(["report", str(bad), "--out", str(tmp_path / "o")]) == 2
    assert "error" in capsys.readouterr().err
    assert not (tmp_path / "o" / "report.html").exists()


@pytest.mark.slow  # fast: report --surface on a catalogue (tests/cli/test_force_only_commands.py)
def test_report_links_the_surface_page(tmp_path):
    """`uq report --surface` writes surface.html beside the report and links it."""
    from uq._cli.main import main
    from uq._data.recordings import write_recordings_csv
    from uq._stand.simulator import Layout, simulate

    csv = tmp_path / "six.csv"
    csv.write_text(
        write_recordings_csv(
            simulate("n50", seed=3, layout=Layout(pressures_bar=(1, 2.5, 4, 5.5, 7, 10)))
        )
    )
    out = tmp_path / "rep"
    assert (
        main(
            [
                "report",
                str(csv),
                "--out",
                str(out),
                "--surface",
                "--draws",
                "200",
                "--max-steps",
                "400",
                "--allow-unconverged",
            ]
        )
        == 0
    )  # short chains: this tests the page, not the posterior
    assert "href='surface.html'" in (out / "report.html").read_text()
    assert (out / "surface.html").read_text().count("data:image/png;base64,") == 3


def test_page_escapes_what_the_recordings_say(n50_fit, tmp_path, monkeypatch):
    """The page is a jinja2 template with autoescaping: a file name or comment line holding
    markup comes out as text (escaped as html.escape does), never as a <script> element."""
    import dataclasses

    from uq._report import campaign
    from uq._report.html import pyplot

    # the figures are not under test here: draw empty ones
    for name in (
        "figure_force",
        "figure_volume",
        "figure_feff",
        "figure_traditional",
        "figure_scatter",
    ):
        monkeypatch.setattr(campaign, name, lambda *a, **k: pyplot().figure(figsize=(1, 1)))
    monkeypatch.setattr(campaign, "encoded_test_figure", lambda *a, **k: b"\x89PNG\r\n\x1a\n")
    evil = "<script>alert('x&y')</script>"
    rec = dataclasses.replace(n50_fit.recordings, path=str(tmp_path / "<script>r.csv"))
    fit = dataclasses.replace(n50_fit, recordings=rec)
    page = write_report(
        fit,
        tmp_path / "rep",
        bands=campaign_bands(n50_fit, n_draws=100, seed=0),
        comments=["RECONSTRUCTED", evil],
        jobs=1,
    ).read_text(encoding="utf-8")
    assert "<script" not in page
    assert "<title>Air-spring report: &lt;script&gt;r.csv</title>" in page
    assert (
        "<pre>RECONSTRUCTED\n&lt;script&gt;alert(&#x27;x&amp;y&#x27;)&lt;/script&gt;</pre>" in page
    )


def test_template_refuses_a_missing_value():
    """StrictUndefined: a name the template uses but the caller did not give fails, not blank."""
    from jinja2 import UndefinedError

    from uq._report.html import render

    with pytest.raises(UndefinedError):
        render(
            "diagnose.html", summary="s", mechanisms=[], baseline={"rms_N": 1.0, "elpd_loo": 2.0}
        )


def test_paper_columns_only_for_the_paper_spring_or_a_given_reference(n50_fit, tmp_path):
    """Table 1/2 and the scatter compare with the paper only for the N-50 reconstruction (auto) or
    when asked; a reference file of stored point estimates takes its place; none, no columns."""
    from pathlib import Path

    from uq._data.reference import is_n50_reconstruction
    from uq._derived.check import reference_from_points
    from uq._report.campaign import _reference, _table1, _table2

    ours = list(n50_fit.recordings.comments)
    assert is_n50_reconstruction(ours)
    assert _reference("auto", ours).is_paper
    assert _reference("auto", ["# my spring, measured on 2026-11-20"]) is None
    assert _reference("paper", []).is_paper and _reference(None, ours) is None
    rows, n_out, n_cmp = _table1(n50_fit, None)
    assert n_cmp == 0 and all(c["paper"] is None for r in rows for c in r["cells"])
    assert all(r["paper_s"] != r["paper_s"] for r in _table2(n50_fit, None))  # NaN: nothing
    points = Path(__file__).resolve().parents[2] / "fits" / "n50" / "table1_points.json"
    ref = reference_from_points(points)
    rows, n_out, n_cmp = _table1(n50_fit, ref)
    assert n_cmp == 8 * len(n50_fit.tests) and rows[0]["cells"][0]["paper"] is not None
    assert not ref.deviations  # the file has no s_P_N: Table 2 shows the data's own only

    cb = campaign_bands(n50_fit, n_draws=300, seed=0)
    page = write_report(
        n50_fit, tmp_path / "none", bands=cb, reference=None, comments=["# my spring"]
    ).read_text(encoding="utf-8")
    assert "paper s_P" not in page and "paper (%)" not in page and "8.41 %" not in page
    assert "No reference values to compare with" in page
    page = write_report(n50_fit, tmp_path / "file", bands=cb, reference=ref).read_text(
        encoding="utf-8"
    )
    assert page.count("table1_points.json ") == 8 * len(n50_fit.tests)
    assert "Table 1 of the paper, converted to SI" in page and "paper s_P" not in page


def test_footer_names_version_date_file_hash_and_stand(n50_fit, monkeypatch):
    from uq._data.stand_description import PAPER_STAND
    from uq._io.files import sha256_of
    from uq._io.version import __version__
    from uq._report.campaign import provenance

    monkeypatch.setenv("SOURCE_DATE_EPOCH", "1764115200")
    rec = n50_fit.recordings
    f = provenance(rec, PAPER_STAND)
    assert f["version"] == __version__ and f["date"] == "2025-11-26 00:00 UTC"
    assert f["sha256"] == sha256_of(rec.path) and len(f["sha256"]) == 64
    assert "paper's stand" in f["stand"] and " = " not in f["stand"]
    other = provenance(rec, PAPER_STAND.replace(load_cell_rel_sd=0.01))
    assert "load_cell_rel_sd = 0.01" in other["stand"]


def test_reference_option_refused_before_fitting(tmp_path, capsys, monkeypatch):
    from pathlib import Path

    import uq._models.cubic_fit as cubic

    monkeypatch.setattr(cubic, "fit_campaign", lambda *a, **k: pytest.fail("fitted"))
    rc = main(
        [
            "report",
            str(Path(__file__).resolve().parents[2] / "data" / "n50" / "recordings.csv"),
            "--out",
            str(tmp_path / "o"),
            "--reference",
            str(tmp_path / "missing.json"),
        ]
    )
    err = capsys.readouterr().err
    assert rc == 2 and "missing.json" in err and len(err.strip().splitlines()) == 1
