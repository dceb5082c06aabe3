"""The report's figures: no text on top of other text, bands the reader can see, PNG or SVG.

Overlaps are found with matplotlib's own renderer: every title, axis label and colour-bar label
is laid out as on the page and their boxes must not intersect (nor a title another axes).
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from figure_text import overlaps

import uq
from uq._derived.bands import campaign_bands
from uq._report import campaign
from uq._report.html import encode, pyplot


@pytest.fixture(scope="module")
def small_fit(small_cubics):
    """The shared small campaign's cubics (tests/conftest.py, fitted once per session)."""
    return small_cubics, campaign_bands(small_cubics, n_draws=100, seed=0)


def test_the_overlap_check_finds_two_long_titles_side_by_side():
    plt = pyplot()
    fig, (a, b) = plt.subplots(1, 2, figsize=(6, 3))
    a.set_title("a long title that runs well over into the neighbouring panel")
    b.set_title("and a second long title that starts under it")
    assert any("title" in o for o in overlaps(fig))
    plt.close(fig)
    fig, (a, b) = plt.subplots(1, 2, figsize=(6, 3), layout="constrained")
    a.set_title("short")
    b.set_title("short too")
    assert overlaps(fig) == []
    plt.close(fig)


@pytest.mark.parametrize("name", ["force", "volume", "feff", "traditional", "scatter", "test"])
def test_no_text_overlaps_in_a_figure(small_fit, name):
    cf, cb = small_fit
    if name == "scatter":
        fig = campaign.figure_scatter(cb)
    elif name == "test":
        tf, tb = cf.tests[0], cb.tests[0]
        fig = campaign.figure_test(tf.test, tf.flat("force").mean(0), tf.x0_m, tb, cb)
    else:
        fig = getattr(campaign, f"figure_{name}")(cf, cb)
    try:
        assert overlaps(fig) == []
    finally:
        pyplot().close(fig)


def test_widest_band_in_points_is_the_axes_scale():
    """An axes 4 in tall showing 0..10: a band 1 unit wide is 4 * 72 / 10 = 28.8 pt."""
    plt = pyplot()
    fig = plt.figure(figsize=(4, 4), dpi=100)
    ax = fig.add_axes((0, 0, 1, 1))
    ax.set_ylim(0, 10)
    assert campaign.widest_band_pt(ax, [0.5, 1.0]) == pytest.approx(28.8)
    plt.close(fig)


def test_figures_2_and_3_say_how_wide_the_bands_are_and_show_residual_panels(small_fit):
    cf, cb = small_fit
    for name, unit in (("force", "N"), ("volume", "cm³")):
        fig = getattr(campaign, f"figure_{name}")(cf, cb)
        title = fig.axes[0].get_title()
        widest = re.search(r"at most ([0-9.e+]+) (\S+) wide", title)
        assert widest and widest.group(2) == unit, title
        assert "minus the mean" in title
        # one residual panel per test, titled by its pressure, centred on the mean curve
        panels = [ax for ax in fig.axes if ax.get_title().endswith(" bar")]
        assert [ax.get_title() for ax in panels] == [f"{t.pressure_bar:g} bar" for t in cb.tests]
        pyplot().close(fig)
    force_widest = max(np.max(t.force.hi - t.force.lo) for t in cb.tests)
    fig = campaign.figure_force(cf, cb)
    assert f"at most {force_widest:.3g} N" in fig.axes[0].get_title()
    pyplot().close(fig)


def test_figures_4_and_5_use_a_colour_bar_not_dashed_bounds(small_fit):
    cf, cb = small_fit
    for fn in (campaign.figure_feff, campaign.figure_traditional):
        fig = fn(cf, cb)
        bars = [ax for ax in fig.axes if ax.get_label() == "<colorbar>"]
        assert len(bars) == 1 and "p_u (bar)" in bars[0].get_ylabel()
        n = len(cb.scatter_pressures_bar)
        assert len(bars[0].lines) == n  # the tested pressures marked on the bar
        plots = [ax for ax in fig.axes if ax not in bars]
        dashed = [ln for ax in plots for ln in ax.lines if ln.get_linestyle() == "--"]
        # Figure 5 draws the traditional force dashed (one line per test), no dashed bounds
        assert len(dashed) == (n if fn is campaign.figure_traditional else 0)
        pyplot().close(fig)


def test_svg_figures_are_vector_and_reproducible(small_fit):
    cf, cb = small_fit
    one = encode(campaign.figure_feff(cf, cb), "svg")
    two = encode(campaign.figure_feff(cf, cb), "svg")
    assert one.lstrip().startswith(b"<?xml") and b"<svg" in one
    assert one == two
    # vector paths; the one bitmap is the colour bar's gradient (matplotlib rasterizes it)
    assert one.count(b"<image") == 1


def test_an_unknown_figure_format_is_refused(small_fit, tmp_path):
    cf, _ = small_fit
    with pytest.raises(uq.InputError, match="figure_format: one of png, svg, got 'jpg'"):
        uq.write_report(cf, tmp_path / "r", draws=20, figure_format="jpg")
    assert not (tmp_path / "r").exists()


def test_report_with_svg_figures_replaces_the_png_ones(small_fit, tmp_path):
    cf, cb = small_fit
    out = tmp_path / "rep"
    uq.write_report(cf, out, bands=cb)
    pngs = sorted(p.name for p in out.glob("*.png"))
    assert len(pngs) == 5 + len(cf.tests)
    page = uq.write_report(cf, out, bands=cb, figure_format="svg").read_text(encoding="utf-8")
    assert not list(out.glob("*.png"))  # the earlier run's PNGs are not left to pass for these
    svgs = sorted(p.name for p in out.glob("*.svg"))
    assert svgs == [n.replace(".png", ".svg") for n in pngs]
    assert page.count("data:image/svg+xml;base64,") == len(svgs)
    assert "data:image/png" not in page
    assert f"the same SVG files ({len(svgs)})" in page


def _test_figure_kinds(cf, cb):
    """One test's figure inputs (as a worker gets them) in the shapes a report can show: a y axis
    with an offset text, with its volume curve, force-only beside other tests' volume, force-only
    in a force-only campaign, in unknown order, and not converged (stamped)."""
    from dataclasses import replace
    from types import SimpleNamespace

    tf, tb = cf.tests[1], cb.tests[1]
    grid = SimpleNamespace(x_m=cb.x_m, x0_m=cb.x0_m, reference_bar=cb.reference_bar)
    own = dict.fromkeys(("piston", "piston_pred", "dV", "feff_volume", "trad_own", "spread_own"))
    force_only = replace(tb, **own, spread_own_pct=None)
    no_volume = replace(force_only, trad_ref=None, spread_ref=None, spread_ref_pct=None)
    unordered = replace(tf.test, compression=None, step=None)
    far = 1000.0  # m: the piston panel's ticks share their leading digits (an offset text)
    offset = replace(
        tb,
        piston=campaign.Band(tb.piston.mean + far, tb.piston.lo + far, tb.piston.hi + far),
        piston_pred=campaign.Band(
            tb.piston_pred.mean + far, tb.piston_pred.lo + far, tb.piston_pred.hi + far
        ),
    )
    mean = tf.flat("force").mean(0)
    kinds = [
        (tf.test, offset, tf.piston_m + far, True),
        (tf.test, tb, tf.piston_m, True),
        (replace(tf.test, piston_m=None), force_only, None, True),
        (replace(tf.test, piston_m=None), no_volume, None, True),
        (unordered, tb, tf.piston_m, True),
        (tf.test, tb, tf.piston_m, False),
        (cf.tests[0].test, cb.tests[0], cf.tests[0].piston_m, True),
    ]
    return [(t, mean, tf.x0_m, b, grid, piston, ok) for t, b, piston, ok in kinds]


def test_per_test_figures_on_the_kept_figure_are_those_of_a_new_figure(small_fit, monkeypatch):
    """The per-test figures are drawn on one figure kept per process (campaign.test_canvas), its
    last test's data taken off first: every figure, whatever the previous one showed (volume
    panels or their reasons, branch markers, the NOT CONVERGED stamp), has the bytes of the same
    figure drawn on a new figure, as PNG and as SVG. The kept figure's titles stay at the top of
    their axes; a figure with an offset text on a y axis, which can make matplotlib move a title,
    is drawn on a new figure instead (the first kind)."""
    cf, cb = small_fit
    kinds = _test_figure_kinds(cf, cb)
    figure_test, on = campaign.figure_test, []

    def drawn_on(*args):
        on.append("kept" if args[-1] is not None else "new")
        return figure_test(*args)

    for fmt, drawn in (("png", kinds), ("svg", kinds[:3])):
        for t, mean, x0, tb, grid, piston, ok in drawn:
            on.clear()
            with monkeypatch.context() as m:
                m.setattr(campaign, "figure_test", drawn_on)
                kept = campaign.encoded_test_figure(t, mean, x0, tb, grid, fmt, piston, ok)
            assert on == (["kept", "new"] if tb is kinds[0][3] else ["kept"])
            fig = campaign.figure_test(t, mean, x0, tb, grid, piston)
            if not ok:
                campaign.stamp_unconverged(fig, f"the {t.pressure_bar:g} bar test")
            fig.canvas.draw()
            offsets = [ax.yaxis.offsetText.get_text() for ax in fig.axes]
            assert any(offsets) == (tb is kinds[0][3]), offsets
            assert kept == encode(fig, fmt), (fmt, tb.has_volume, t.compression is None, ok)


@pytest.mark.parametrize("name", ["force", "volume", "feff", "traditional", "scatter"])
def test_campaign_figures_with_titles_fixed_at_the_top_are_matplotlibs(small_fit, name):
    """The campaign's figures are made with their titles at the top of their axes (campaign.
    _encoded, as the per-test figures are): the bytes of the figure made as matplotlib places
    its titles, stamped NOT CONVERGED or not, as PNG and SVG."""
    cf, cb = small_fit

    def make(_=None):
        if name == "scatter":
            return campaign.figure_scatter(cb)
        return getattr(campaign, f"figure_{name}")(cf, cb)

    for fmt, stamp in (("png", ""), ("png", "1 of 3 tests (5 bar)"), ("svg", "")):
        fig = make()
        if stamp:
            campaign.stamp_unconverged(fig, stamp)
        assert campaign._encoded(make, fmt, None, stamp) == encode(fig, fmt), (fmt, stamp)


def test_a_figure_with_an_offset_text_is_made_again_where_matplotlib_places_titles():
    """An offset text on a y axis (+1e6) can make matplotlib move a title: such a figure is made
    a second time without the fixed titles, and its bytes are those of matplotlib's placement."""
    made = []

    def make(fixed=False):
        made.append(fixed)
        fig = pyplot().figure(figsize=(4, 3))
        ax = fig.add_subplot()
        ax.plot([0.0, 1.0], [1e6, 1e6 + 1.0])
        ax.set_title("a title over an offset text")
        return fig

    data = campaign._encoded(make, "png")
    assert made == [True, False]
    assert data == encode(make(), "png")
