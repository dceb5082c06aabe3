"""``uq report FILE.csv --out DIR``: one self-contained HTML page (+ its figures) per campaign.

The page redraws the paper's Figures 2-5 with credible bands, sets Tables 1 and 2 beside the
posterior, gives the scatter of the effective area, the sampler's diagnostics and a section
per pressure. Figures are embedded (base64 PNG, or SVG with ``figure_format="svg"``) and also
written beside the page; every write is atomic (``uq._io.files``). The page is the template ``templates/report.html``
(``uq._report.html.render``); this module gives it numbers and figures, not markup.
"""

from __future__ import annotations

import atexit
import collections
import concurrent.futures
import contextlib
import functools
import io
import multiprocessing
import os
import threading
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from uq._data.reference import Reference, is_n50_reconstruction, paper_reference
from uq._derived.bands import Band, CampaignBands, campaign_bands
from uq._inference.convergence import CLI_ADVICE
from uq._io.errors import InputError
from uq._io.files import remove_stale, staged_folder, write_bytes_atomic, write_text_atomic
from uq._io.processes import exit_now, ignore_interrupts, interrupts_ignored
from uq._io.version import __version__, date_stamp
from uq._physics.cubic import cubic
from uq._physics.quantities import BAR_PA
from uq._report.html import (
    DPI,
    FIGURE_FORMATS,
    Figure,
    check_format,
    encode,
    pyplot,
    render,
    stamp_unconverged,
)
from uq._report.pages import write_model_page

#: Names of the files write_report and the surface page write (uq._io.files.remove_stale prunes the rest).
REPORT_FIGURES = tuple(
    f"{stem}.{ext}"
    for ext in FIGURE_FORMATS
    for stem in ("fig2_*", "fig3_*", "fig4_*", "fig5_*", "fig_*", "test_*bar")
)
SURFACE_OUTPUTS = (*(f"surface_*.{ext}" for ext in FIGURE_FORMATS), "surface.html")
MM = 1e3
BRANCH_COLORS = {True: "tab:blue", False: "tab:orange"}  # compression, rebound
#: Table 1 as printed: (name, unit, factor SI -> printed unit).
TABLE1_COLUMNS = [
    ("a_P", "kN", 1e-3),
    ("b_P", "kN/m", 1e-3),
    ("c_P", "kN/m²", 1e-3),
    ("d_P", "10³ kN/m³", 1e-6),
    ("a_L", "m", 1.0),
    ("b_L", "–", 1.0),
    ("c_L", "1/m", 1.0),
    ("d_L", "1/m²", 1.0),
]
PAPER_SCATTER_PCT = {"x0": 8.41, "x_max": 26.3, "x_min": 8.51}
MIN_DRAWS = 10  # fewer posterior draws give no 90 % band worth drawing


# ----------------------------------------------------------------------------- figures
#
# Each figure_* function returns a matplotlib figure; _draw_figures encodes it as PNG or SVG
# (uq._report.html.encode). Tests by pressure share one colour map (viridis, cut before its pale
# end so the last curve stays visible on white) with a colour bar, not a legend of ten entries.
# Legends say loc="best", matplotlib's default: left to the default, a search for the place that
# takes over a second (a loaded machine) warns, which the tests (warnings are errors) then fail on.

LINE_PT = 1.2  # width of the posterior-mean lines, points


def _pressure_colours(pressures):
    """(colour per pressure, the ScalarMappable for a colour bar) from one colour map."""
    plt = pyplot()
    from matplotlib.cm import ScalarMappable  # reason: optional and heavy, loaded only where used
    from matplotlib.colors import (  # reason: optional and heavy, loaded only where used
        ListedColormap,
        Normalize,
    )

    p = np.asarray(pressures, float)
    cmap = ListedColormap(plt.get_cmap("viridis")(np.linspace(0.0, 0.9, 256)))
    lo, hi = float(p.min()), float(p.max())
    norm = Normalize(lo, hi if hi > lo else lo + 1.0)
    return [cmap(norm(v)) for v in p], ScalarMappable(norm=norm, cmap=cmap)


def _colour_bar(fig, axes, mappable, pressures, cax=None) -> None:
    """The pressure colour bar beside ``axes`` (or in ``cax``), the tested pressures marked on it."""
    if cax is not None:
        bar = fig.colorbar(mappable, cax=cax)
    else:
        bar = fig.colorbar(mappable, ax=axes, pad=0.015, fraction=0.04, aspect=30)
    bar.set_label("overpressure p_u (bar); tested pressures marked")
    for p in pressures:
        bar.ax.axhline(p, color="k", lw=0.6)


def _fill(ax, x, b, scale, color, alpha=0.25, label=None, line=True, ls="-"):
    ax.fill_between(x, b.lo * scale, b.hi * scale, color=color, alpha=alpha, lw=0)
    if line:
        ax.plot(x, b.mean * scale, color=color, lw=LINE_PT, ls=ls, label=label)


def _bands(ax, x, pointwise, simultaneous, scale, color, ls="-"):
    """Posterior-mean line, pointwise 90 % band (darker) and simultaneous 90 % band (lighter)."""
    ax.fill_between(
        x, simultaneous.lo * scale, simultaneous.hi * scale, color=color, alpha=0.15, lw=0
    )
    _fill(ax, x, pointwise, scale, color, alpha=0.4, ls=ls)


def _band_key(ax, points: str | None = None) -> None:
    """A legend of what the shades and marks mean (colours are the pressures: the colour bar)."""
    from matplotlib.lines import Line2D  # reason: optional and heavy, loaded only where used
    from matplotlib.patches import Patch  # reason: optional and heavy, loaded only where used

    handles = [Line2D([], [], color="0.3", lw=LINE_PT, label="posterior mean")]
    handles.append(Patch(color="0.3", alpha=0.4, lw=0, label="pointwise 90 % band"))
    handles.append(Patch(color="0.3", alpha=0.15, lw=0, label="simultaneous 90 % band"))
    if points:
        handles.append(Line2D([], [], color="0.3", ls="", marker=".", label=points))
    ax.legend(handles=handles, fontsize=7, loc="best")


def _mark_x0(ax, x0_mm):
    ax.axvline(x0_mm, color="0.6", lw=0.6, ls=":")


def widest_band_pt(ax, widths) -> float:
    """The widest of the bands ``widths`` (data units of ``ax``'s y axis) in points on the page
    (the figure drawn: its layout fixes the axes' size)."""
    y0, y1 = ax.get_ylim()
    return float(np.max(widths)) * ax.bbox.height / abs(y1 - y0) * 72.0 / ax.figure.dpi


def _band_note(ax, widths, factor: float, unit: str) -> str:
    """What the reader can see of the bands (``widths`` in ``ax``'s y units; ``factor`` turns
    them into ``unit``) at this scale, in words, for the figure's title."""
    widest = float(np.max(widths)) * factor
    pt = widest_band_pt(ax, widths)
    if pt < LINE_PT:
        seen = "thinner than the lines at this scale"
    elif pt < 3 * LINE_PT:
        seen = "hardly wider than the lines at this scale"
    else:
        seen = f"{pt:.0f} pt at this scale"
    return f"the curves' 90 % bands are at most {widest:.3g} {unit} wide ({seen})"


def _residual_grid(fig, gs, n: int, cols: int):
    """``n`` small axes in the cells of ``gs``, row by row, sharing their x axis."""
    axes = []
    for i in range(n):
        ax = fig.add_subplot(gs[i // cols, i % cols], sharex=axes[0] if axes else None)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
        axes.append(ax)
    return axes


#: Figures 2 and 3's fixed layout, inches: the margins, the colour bar beside the main axes, the
#: residual panels' height and the gaps between them (what constrained layout chose for them on
#: data/n50, with room for the tick labels of any campaign's residuals)
RESIDUAL_LAYOUT = SimpleNamespace(
    left=0.62, right=0.771, top=0.413, bottom=0.66, bar_pad=0.138, bar_width=0.113,
    below_main=0.69, panel=1.063, row_gap=0.61, col_gap=0.44,
)  # fmt: skip


def _with_residuals(n: int):
    """A figure with a main axes on top (a colour bar axes beside it) and a grid of ``n``
    residual panels below it, at fixed places (:data:`RESIDUAL_LAYOUT`): no layout engine, whose
    passes over a dozen panels' tick labels cost about a second each, and the main axes' size,
    which the band note needs, is known before anything is drawn. Returns (figure, main axes,
    colour bar axes, residual axes)."""
    plt = pyplot()
    k = RESIDUAL_LAYOUT
    cols = min(n, 6)
    rows = -(-n // cols)
    W, H = 10.5, 4.8 + 1.55 * rows
    fig = plt.figure(figsize=(W, H))
    grid_top = k.bottom + rows * k.panel + (rows - 1) * k.row_gap  # inches from the bottom
    main_bottom = grid_top + k.below_main
    bottom, height = main_bottom / H, 1 - (main_bottom + k.top) / H  # of the main and bar axes
    main = fig.add_axes((k.left / W, bottom, 1 - (k.left + k.right) / W, height))
    bar = fig.add_axes(((W - k.right + k.bar_pad) / W, bottom, k.bar_width / W, height))
    width = (W - k.left - k.right - (cols - 1) * k.col_gap) / cols
    gs = fig.add_gridspec(
        rows, cols, left=k.left / W, right=1 - k.right / W, bottom=k.bottom / H, top=grid_top / H,
        wspace=k.col_gap / width, hspace=k.row_gap / k.panel,
    )  # fmt: skip
    return fig, main, bar, _residual_grid(fig, gs, n, cols)


def _residual_panel(ax, x, h, r, curve: Band, pred: Band, scale, color, p_bar):
    """Readings ``r`` minus the posterior-mean curve at heights ``h``, with the curve's 90 % band
    (colour) and a new reading's (grey) minus the same mean, on the grid ``x``."""
    for b, c, alpha in ((pred, "0.5", 0.2), (curve, color, 0.7)):
        ax.fill_between(
            x, (b.lo - b.mean) * scale, (b.hi - b.mean) * scale, color=c, alpha=alpha, lw=0
        )
    ax.plot(h, r * scale, ".", color="k", ms=2.5)
    ax.axhline(0, color="k", lw=0.5)
    ax.set_title(f"{p_bar:g} bar", fontsize=8)


def _residual_key(fig) -> None:
    """The residual panels' legend, below them."""
    from matplotlib.lines import Line2D  # reason: optional and heavy, loaded only where used
    from matplotlib.patches import Patch  # reason: optional and heavy, loaded only where used

    handles = [
        Line2D([], [], color="k", ls="", marker=".", label="readings"),
        Patch(color="0.3", alpha=0.7, lw=0, label="the curve's 90 % band (its pressure's colour)"),
        Patch(color="0.5", alpha=0.2, lw=0, label="a new reading's 90 % band"),
    ]
    fig.legend(handles=handles, loc="lower center", ncol=3, fontsize=7, frameon=False)


def _residual_labels(fig, axes, ylabel: str) -> None:
    for a in axes:
        a.set_xlabel("height x (mm)", fontsize=7)
    axes[0].set_ylabel(ylabel, fontsize=7)
    _residual_key(fig)


def _curves_and_residuals(cb, pairs, curve, points, residuals, ylabel, rlabel, title, below, unit):
    """Figures 2 and 3: one quantity's curves by pressure with the readings above; below, per test,
    the readings and bands minus the posterior-mean curve. ``pairs``: (test fit, test bands);
    ``curve(tb)``: (band, scale to the axis' unit); ``points(tf, tb)``: the readings in the band's
    unit; ``residuals(tf, tb)``: :func:`_residual_panel`'s residuals, curve band, new reading's band
    and scale."""
    fig, ax, cax, res = _with_residuals(len(pairs))
    x = cb.x_m * MM
    colours, sm = _pressure_colours([tb.pressure_bar for _, tb in pairs])
    widths = []
    for i, ((tf, tb), c) in enumerate(zip(pairs, colours, strict=True)):
        band, scale = curve(tb)
        _fill(ax, x, band, scale, c, alpha=0.4)
        ax.plot(tf.test.height_m * MM, points(tf, tb) * scale, ".", color=c, ms=3)
        _residual_panel(res[i], x, tf.test.height_m * MM, *residuals(tf, tb), c, tb.pressure_bar)
        widths.append(np.max(band.hi - band.lo) * scale)
    _mark_x0(ax, cb.x0_m * MM)
    ax.set(xlabel="height x (mm)", ylabel=ylabel)
    ax.grid(alpha=0.3)
    _colour_bar(fig, ax, sm, [tb.pressure_bar for _, tb in pairs], cax=cax)
    _residual_labels(fig, res, rlabel)
    note = _band_note(ax, widths, 1e3, unit)  # the layout is fixed: the axes' size is known
    ax.set_title(title.format(f"{note}; below: {below}"), fontsize=9)
    return fig


def figure_force(cf, cb: CampaignBands):
    """Figure 2 (eq. 8): force curves by pressure, readings and bands; below, per test, readings
    and bands minus the posterior-mean curve (the bands are too narrow to see above)."""
    return _curves_and_residuals(
        cb,
        list(zip(cf.tests, cb.tests, strict=True)),
        lambda tb: (tb.force, 1e-3),
        lambda tf, tb: tf.test.force_N,
        lambda tf, tb: (tf.mean_residuals("force"), tb.force, tb.force_pred, 1.0),
        "force P (kN)",
        "reading − mean (N)",
        "Fig. 2: force characteristics (eq. 8): readings (points) and posterior-mean curves\n{}",
        "readings and bands minus the mean curve",
        "N",
    )


def _dV_points(tf, tb, S):
    """Recorded volume increments S [L_k - L(x_max)] with the posterior-mean curve's L(x_max)."""
    L_top = np.mean(cubic(tf.flat("piston"), tb.x_max_m - tf.x0_m))
    return S * (tf.piston_m - L_top)


def figure_volume(cf, cb: CampaignBands):
    """Figure 3 (eq. 10): volume increments by pressure; below, per test, the piston readings and
    bands minus the posterior-mean L(x), as volume S ΔL. Only the tests with a volume curve
    (force-only tests have none)."""
    S = cb.piston_area_m2
    return _curves_and_residuals(
        cb,
        [(tf, tb) for tf, tb in zip(cf.tests, cb.tests, strict=True) if tb.has_volume],
        lambda tb: (tb.dV, 1e3),
        lambda tf, tb: _dV_points(tf, tb, S),
        lambda tf, tb: (
            S * tf.mean_residuals("piston"),
            _scaled(tb.piston, S),
            _scaled(tb.piston_pred, S),
            1e6,
        ),
        "volume increment ΔV (dm³ = litre)",
        "S (L − mean L) (cm³)",
        "Fig. 3: volume increment ΔV = S [L(x) − L(x_max)] (eq. 10): readings and posterior-mean "
        "curves\n{}",
        "piston readings and bands minus the mean L(x), times S",
        "cm³",
    )


def _scaled(b: Band, factor: float) -> Band:
    return Band(b.mean * factor, b.lo * factor, b.hi * factor)


def figure_feff(cf, cb: CampaignBands):
    """Figure 4 (eq. 1): F_eff = P / p_u of the tests with p_u >= 1 bar, by pressure, with
    pointwise and simultaneous 90 % bands shaded."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(9, 5.4), layout="constrained")
    x = cb.x_m * MM
    shown = [
        (tf, tb)
        for tf, tb in zip(cf.tests, cb.tests, strict=True)
        if tb.pressure_bar in cb.scatter_pressures_bar
    ]
    colours, sm = _pressure_colours([tb.pressure_bar for _, tb in shown])
    for (tf, tb), c in zip(shown, colours, strict=True):
        _bands(ax, x, tb.feff, tb.simultaneous["feff"], 1e4, c)
        p_pa = tb.pressure_bar * BAR_PA
        ax.plot(tf.test.height_m * MM, tf.test.force_N / p_pa * 1e4, ".", color=c, ms=2.5)
    _mark_x0(ax, cb.x0_m * MM)
    ax.set(xlabel="height x (mm)", ylabel="effective area F_eff = P / p_u (cm²)")
    ax.set_title(
        "Fig. 4: effective area from the force (eq. 1), tests with p_u ≥ 1 bar", fontsize=10
    )
    ax.grid(alpha=0.3)
    _band_key(ax, points="readings P / p_u")
    _colour_bar(fig, ax, sm, [tb.pressure_bar for _, tb in shown])
    return fig


def figure_traditional(cf, cb: CampaignBands):
    """Figure 5: the traditional force p_u (-S dL/dx) from the reference test's volume curve
    against the measured force (left) and their relative difference (right), by pressure."""
    plt = pyplot()
    from matplotlib.lines import Line2D  # reason: optional and heavy, loaded only where used

    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(13, 5.4), layout="constrained")
    x = cb.x_m * MM
    shown = [tb for tb in cb.tests if tb.pressure_bar in cb.scatter_pressures_bar]
    colours, sm = _pressure_colours([tb.pressure_bar for tb in shown])
    for tb, c in zip(shown, colours, strict=True):
        _fill(ax, x, tb.force, 1e-3, c, alpha=0.4)
        _fill(ax, x, tb.trad_ref, 1e-3, c, alpha=0.2, ls="--")
        _bands(ax2, x, tb.spread_ref_pct, tb.simultaneous["spread_ref_pct"], 1.0, c)
    fig.suptitle(
        f"Fig. 5: traditional force p_u (−S dL/dx), with the {cb.reference_bar:g}-bar test's "
        "volume curve, against the measured force",
        fontsize=10,
    )
    ax.set(xlabel="height x (mm)", ylabel="force (kN)")
    ax.set_title("force: measured and traditional", fontsize=9)
    measured = Line2D([], [], color="0.3", lw=LINE_PT, label="measured P(x), posterior mean")
    trad = Line2D([], [], color="0.3", lw=LINE_PT, ls="--", label="traditional, posterior mean")
    ax.legend(handles=[measured, trad], fontsize=7, loc="best")
    ax2.axhline(0, color="k", lw=0.6)
    ax2.set(xlabel="height x (mm)", ylabel="(traditional − measured) / measured (%)")
    ax2.set_title("spread of the traditional force", fontsize=9)
    _band_key(ax2)
    for a in (ax, ax2):
        _mark_x0(a, cb.x0_m * MM)
        a.grid(alpha=0.3)
    _colour_bar(fig, [ax, ax2], sm, [tb.pressure_bar for tb in shown])
    return fig


def figure_scatter(cb: CampaignBands, paper_values: bool = True):
    """The paper's scatter of F_eff across the tests with p_u >= 1 bar, with its band (and the
    paper's own values when ``paper_values``: the campaign is the paper's spring)."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(8, 4.6), layout="constrained")
    x = cb.x_m * MM
    _fill(ax, x, cb.scatter, 1.0, "tab:purple", label="posterior mean and pointwise 90 % band")
    for label, v in cb.scatter_at.items():
        ax.errorbar(
            [v["height_m"] * MM],
            [v["mean"]],
            yerr=[[v["mean"] - v["q05"]], [v["q95"] - v["mean"]]],
            fmt="o",
            color="tab:purple",
            ms=4,
        )
        ax.annotate(
            f"{label}: {v['mean']:.2f} %",
            (v["height_m"] * MM, v["mean"]),
            textcoords="offset points",
            xytext=(4, 6),
            fontsize=7,
        )
    if paper_values:
        paper = [(cb.x0_m, 8.41), (cb.x_m.max(), 26.3), (cb.x_m.min(), 8.51)]
        ax.plot(
            [h * MM for h, _ in paper],
            [v for _, v in paper],
            "kx",
            ms=7,
            label="paper: 8.41 % (x0), 26.3 % (x_max), 8.51 % ('x_min')",
        )
    _mark_x0(ax, cb.x0_m * MM)
    ax.set(xlabel="height x (mm)", ylabel="half range / mean of F_eff (%)")
    ax.set_title(
        f"Scatter of F_eff across the {len(cb.scatter_pressures_bar)} tests with p_u ≥ 1 bar",
        fontsize=10,
    )
    ax.legend(fontsize=7, loc="best")
    ax.grid(alpha=0.3)
    return fig


#: the per-test figure's size, inches
TEST_FIGSIZE = (14, 7.6)


def figure_test(t, force_mean, x0_m: float, tb, cb: CampaignBands, piston_m=None, fig=None):
    """Six panels for one test: force, residuals, piston, F_eff, traditional vs measured, spread.

    ``t`` the test's recordings (PressureTest), ``force_mean`` the posterior-mean force
    coefficients (paper basis), ``piston_m`` the L readings its volume block fitted (default
    ``t.piston_m``; L = -V / S for a volume column): plain data, so that the figure can be drawn
    in another process. A force-only test's volume panels say so instead; a test in unknown order
    (no branch and step) shows its readings without branch markers. ``fig``: a figure of
    :func:`test_canvas` to draw on (its last test's data are taken off first), else a new one.
    """
    if fig is None:
        fig, axs = pyplot().subplots(2, 3, figsize=TEST_FIGSIZE)
    else:
        axs = _cleared(fig)
    x = cb.x_m * MM
    h = t.height_m * MM
    comp = t.compression
    p_pa = tb.pressure_bar * BAR_PA
    piston_m = t.piston_m if piston_m is None else piston_m
    # the reference test's volume curve (None: no test has one)
    ref = None if cb.reference_bar is None else f"{cb.reference_bar:g}-bar"

    ax = axs[0, 0]
    _fill(ax, x, tb.force_pred, 1e-3, "0.5", alpha=0.2, line=False)
    _fill(ax, x, tb.force, 1e-3, "tab:green", alpha=0.5, label="mean curve, pointwise 90 % band")
    _readings(ax, h, t.force_N * 1e-3, comp)
    ax.plot([], [], color="0.5", alpha=0.4, lw=6, label="pointwise 90 % predictive band")
    ax.set(xlabel="height x (mm)", ylabel="force P (kN)", title="force (eq. 8)")
    ax.legend(fontsize=7, loc="best")

    ax = axs[0, 1]
    fit_pts = cubic(force_mean, t.height_m - x0_m)
    for band, color, alpha in ((tb.force_pred, "0.5", 0.2), (tb.force, "tab:green", 0.5)):
        ax.fill_between(
            x, band.lo - tb.force.mean, band.hi - tb.force.mean, color=color, alpha=alpha, lw=0
        )
    _readings(ax, h, t.force_N - fit_pts, comp)
    ax.axhline(0, color="k", lw=0.6)
    ax.set(
        xlabel="height x (mm)", ylabel="force − posterior-mean curve (N)", title="force residuals"
    )

    ax = axs[0, 2]
    if tb.has_volume:
        _fill(ax, x, tb.piston_pred, MM, "0.5", alpha=0.2, line=False)
        _fill(ax, x, tb.piston, MM, "tab:green", alpha=0.5)
        _readings(ax, h, piston_m * MM, comp)
    else:
        _absent(ax, "no volume: force-only test\n(no piston_* or volume_* column)", x)
    ax.set(xlabel="height x (mm)", ylabel="piston coordinate L (mm)", title="piston (eq. 9)")

    ax = axs[1, 0]
    _fill(ax, x, tb.feff, 1e4, "tab:green", label="P / p_u (force)")
    if tb.has_volume:
        _fill(ax, x, tb.feff_volume, 1e4, "tab:red", label="−S dL/dx (own volume curve)", ls="--")
    ax.plot(h, t.force_N / p_pa * 1e4, ".", color="k", ms=3, label="recorded P / p_u")
    ax.set(
        xlabel="height x (mm)",
        ylabel="effective area (cm²)",
        title="effective area, two ways (eq. 1)",
    )
    ax.legend(fontsize=7, loc="best")

    ax = axs[1, 1]
    _fill(ax, x, tb.force, 1e-3, "tab:green", label="measured P(x)")
    if tb.has_volume:
        _fill(ax, x, tb.trad_own, 1e-3, "tab:red", label="p_u (−S dL/dx), own volume", ls="--")
    if tb.trad_ref is not None:
        _fill(ax, x, tb.trad_ref, 1e-3, "tab:purple", label=f"p_u (−S dL/dx), {ref} volume", ls=":")
    else:
        _absent(ax, "no traditional force:\nno test has a volume curve", x, y=0.15)
    ax.set(xlabel="height x (mm)", ylabel="force (kN)", title="traditional vs measured force")
    ax.legend(fontsize=7, loc="best")

    ax = axs[1, 2]
    if tb.has_volume:
        _fill(ax, x, tb.spread_own, 1.0, "tab:red", label="own volume curve", ls="--")
    if tb.spread_ref is not None:
        _fill(ax, x, tb.spread_ref, 1.0, "tab:purple", label=f"{ref} volume curve", ls=":")
        ax.legend(fontsize=7, loc="best")
    else:
        _absent(ax, "no spread: no test has a volume curve", x)
    ax.axhline(0, color="k", lw=0.6)
    ax.set(xlabel="height x (mm)", ylabel="traditional − measured force (N)", title="spread")
    for a in axs.flat:
        _mark_x0(a, cb.x0_m * MM)
        a.grid(alpha=0.3)
    fig.suptitle(f"test at p_u = {tb.pressure_bar:g} bar", fontsize=11)
    fig.subplots_adjust(left=0.06, right=0.99, bottom=0.07, top=0.92, wspace=0.25, hspace=0.3)
    return fig


_canvas = threading.local()


def test_canvas():
    """This thread's figure for the per-test figures (:func:`figure_test`'s ``fig``), made once.

    A new figure spends about a sixth of its CPU time making its six axes and their ticks; the
    eleven figures of a report are the same six panels with other data, so one figure is kept
    (for the thread's life: a few MB) and its data artists replaced, with the same bytes as a new
    figure's (tested). Not pyplot's: nothing closes it (``encode``'s ``close`` leaves it alone).
    """
    fig = getattr(_canvas, "fig", None)
    if fig is None:
        import matplotlib  # reason: optional and heavy, loaded only where used
        from matplotlib.backends.backend_agg import (  # reason: optional and heavy, loaded only where used
            FigureCanvasAgg,
        )
        from matplotlib.figure import Figure  # reason: optional and heavy, loaded only where used

        # Titles placed at the top of their axes (as _encoded draws every figure of a report)
        with matplotlib.rc_context({"axes.titley": 1.0}):
            fig = _canvas.fig = Figure(figsize=TEST_FIGSIZE)
            fig.subplots(2, 3)
        # its own Agg canvas: the renderer, and the text sizes matplotlib measured with it and
        # keeps by renderer, then last from one figure to the next (a figure without one gets a
        # new canvas and renderer at every save)
        FigureCanvasAgg(fig)
    return fig


def _cleared(fig):
    """The axes of a :func:`test_canvas` figure (2 x 3), emptied as a new figure's are: no lines,
    shades, texts or legend, no data limits, the view (0, 1) autoscaled; the figure's own texts
    but its title (the NOT CONVERGED stamp) removed. The axes, their ticks and labels stay."""
    for text in [t for t in fig.texts if t is not fig._suptitle]:
        text.remove()
    for ax in fig.axes:
        for artist in (*ax.lines, *ax.collections, *ax.texts):
            artist.remove()
        if ax.legend_ is not None:
            ax.legend_.remove()
        ax.relim()  # no artists left: no data limits, the next artist's replace them
        ax.set_xlim(0, 1, auto=True)
        ax.set_ylim(0, 1, auto=True)
    return np.asarray(fig.axes).reshape(2, 3)


def _readings(ax, h, y, comp) -> None:
    """The readings (heights ``h`` mm, values ``y``) marked by branch, or plain for a test in
    unknown order (``comp`` None: one pass, no branches to tell apart)."""
    if comp is None:
        ax.plot(h, y, "o", ms=3.5, color="k", mfc="none", label="readings (order unknown)")
        return
    for is_comp, name in ((True, "compression"), (False, "rebound")):
        m, c = comp == is_comp, BRANCH_COLORS[is_comp]
        if m.any():  # compression filled, rebound open
            ax.plot(h[m], y[m], "o", ms=3.5, mfc=c if is_comp else "none", color=c, label=name)


def _absent(ax, words: str, x, y: float = 0.5) -> None:
    """A panel whose quantity the test does not have: the reason, at height ``y`` of it (axes
    fraction), over the grid's heights ``x`` (mm)."""
    ax.text(0.5, y, words, ha="center", va="center", transform=ax.transAxes, fontsize=9)
    ax.set_xlim(x[0], x[-1])


def encoded_test_figure(
    t,
    force_mean,
    x0_m: float,
    tb,
    cb,
    figure_format: str,
    piston_m=None,
    converged=True,
    units=None,
) -> bytes:
    """:func:`figure_test` as PNG or SVG bytes (what a figure worker returns), stamped NOT
    CONVERGED when the test's fit failed its convergence rules; ``units``: second axes in the
    recordings' units (``uq report --units input``). Drawn on the kept figure (:func:`test_canvas`)
    but with ``units`` (a second axis per unit adds axes) or a title to place (:func:`_encoded`)."""
    return _encoded(
        lambda fixed: figure_test(
            t, force_mean, x0_m, tb, cb, piston_m, test_canvas() if fixed else None
        ),
        figure_format,
        units,
        "" if converged else f"the {t.pressure_bar:g} bar test",
    )


def _encoded(make, figure_format: str, units=None, unconverged: str = "") -> bytes:
    """``make(fixed)``'s figure as PNG or SVG bytes, stamped NOT CONVERGED for ``unconverged``.

    With ``fixed`` its axes put their titles at their top (``axes.titley`` 1.0, as
    :func:`test_canvas` does) instead of checking on every draw whether a top x axis or the y
    axis' offset text (1e3, +2.5e2) is in the way, which lays out the y ticks a second time (about
    a tenth of a campaign figure's CPU time). Without a top x axis (``units`` adds them: the figure
    is then made without ``fixed``) only an offset text can be: a figure with one is made again
    without ``fixed`` and encoded as matplotlib places its titles (the same bytes either way)."""
    import matplotlib  # reason: optional and heavy, loaded only where used

    fixed = units is None
    while True:
        with matplotlib.rc_context({"axes.titley": 1.0} if fixed else {}):
            fig = make(fixed)
        if unconverged:
            stamp_unconverged(fig, unconverged)
        data = encode(fig, figure_format, units)
        if not fixed or not any(ax.yaxis.offsetText.get_text() for ax in fig.axes):
            return data
        fixed = False


def not_converged(cf) -> tuple[str, list[str]]:
    """Which tests of ``cf`` failed their convergence rules, in words ("" when none), and their
    failed rules (for the page's banner and the figures' stamps)."""
    bad = [t for t in cf.tests if not t.convergence.converged]
    if not bad:
        return "", []
    what = (
        f"{len(bad)} of {len(cf.tests)} tests ({', '.join(f'{t.pressure_bar:g}' for t in bad)} bar)"
    )
    return what, [
        f"{t.pressure_bar:g} bar: {m}" for t in bad for m in t.convergence.messages(CLI_ADVICE)
    ]


def _worker_start() -> None:
    """A figure worker's initializer: leave Ctrl-C to the process that started it
    (:func:`uq._io.processes.ignore_interrupts`), and end without the interpreter's teardown of its
    modules and objects (about 0.15 s, for which the command's process waited when it stopped the
    workers): a worker has nothing to close (its figures went back through the pool's pipe), so an
    exit handler flushes its output and ends it at once."""
    ignore_interrupts()
    atexit.register(exit_now, 0)


def _warm_up() -> None:
    """A figure worker's first task, done while the fit runs: import matplotlib (this module is
    imported to run it) and make its :func:`test_canvas`, drawn once (its axes, ticks, renderer
    and fonts made then, not on the first test's figure)."""
    pyplot()
    test_canvas().savefig(io.BytesIO(), format="png", dpi=DPI)


class FigureWorkers:
    """The worker processes that draw a report's per-test figures (``write_report(...,
    jobs=workers)``), started ahead: ``jobs`` processes draw them, this one and ``jobs - 1``
    spawned workers (``None``: one per CPU), none for fewer than ``MIN_TESTS`` tests (starting a
    worker costs more than it saves). The workers start at once and import matplotlib and this
    module (about 0.8 CPU s each) and make and draw their kept per-test figure
    (:func:`test_canvas`), so started before the fit (``uq report`` does) this runs beside the fit
    instead of after it. A context manager: leaving it stops the workers.
    Workers are spawned, not forked: this process may hold a JAX runtime, which fork can
    deadlock; a spawned worker imports the calling script again (hence the ``__main__`` guard
    :func:`write_report` asks of scripts)."""

    MIN_TESTS = 4

    def __init__(self, jobs: int | None = None, n_tests: int | None = None):
        self.jobs = (os.cpu_count() or 1) if jobs is None else int(jobs)
        n = self.jobs - 1 if n_tests is None else min(self.jobs - 1, n_tests)
        self.pool = None
        self._ahead = {}  # test index -> (its bands, format, units, the future of its figure)
        self._lock = threading.RLock()
        self._waiting = collections.deque()  # (future, function, arguments) not yet given out
        self._given = 0  # tasks a worker has and has not finished
        self._n = n
        if n >= 1 and (n_tests is None or n_tests >= self.MIN_TESTS):
            with interrupts_ignored():
                self.pool = concurrent.futures.ProcessPoolExecutor(
                    max_workers=n,
                    mp_context=multiprocessing.get_context("spawn"),
                    initializer=_worker_start,
                )
                for _ in range(n):  # spawn launches the workers at the first submit
                    self.submit(_warm_up)

    def submit(self, fn, *args) -> concurrent.futures.Future:
        """``fn(*args)`` in a worker, given to it only when it has nothing else to do, so that
        until then the task can be cancelled (``Future.cancel``) and done by this process instead.
        (A ``ProcessPoolExecutor`` hands a worker its next tasks ahead, where they can no longer
        be cancelled: the command's process then waited for up to two figures it could have drawn.)
        """
        future = concurrent.futures.Future()
        with self._lock:
            self._waiting.append((future, fn, args))
        self._give_out()
        return future

    def _give_out(self) -> None:
        with self._lock:
            while self._given < self._n and self._waiting:
                future, fn, args = self._waiting.popleft()
                if not future.set_running_or_notify_cancel():
                    continue  # cancelled: this process does it
                try:
                    task = self.pool.submit(fn, *args)
                except RuntimeError as e:  # the pool is shut down (leaving the context)
                    future.set_exception(e)
                    continue
                self._given += 1
                task.add_done_callback(functools.partial(self._finished, future))

    def _finished(self, future, task) -> None:
        """A worker's task is done (called in the pool's thread): its result to ``future``, the
        next waiting task to the worker."""
        with self._lock:
            self._given -= 1
        if task.cancelled():
            future.set_exception(concurrent.futures.CancelledError())
        elif task.exception() is not None:
            future.set_exception(task.exception())
        else:
            future.set_result(task.result())
        self._give_out()

    def ahead(self, cf, figure_format: str = "png", units=None):
        """An ``on_test`` for :func:`uq._derived.bands.campaign_bands`: each test's figure goes
        to the workers as soon as its bands are made, so that they draw while this process makes
        the next test's bands; :func:`write_report` given these workers, the same format and
        units, and those bands uses these figures instead of asking for them again."""

        def on_test(t, tb, grid):
            if self.pool is not None:
                w = _work_item(cf.tests[t], tb, grid, figure_format, units)
                self._ahead[t] = (tb, figure_format, units, self.submit(encoded_test_figure, *w))

        return on_test

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if self.pool:
            with self._lock:
                for future, _, _ in self._waiting:
                    future.cancel()
                self._waiting.clear()
            self.pool.shutdown(cancel_futures=True)


def _work_item(tf, tb, grid, figure_format: str, units) -> tuple:
    """The arguments of :func:`encoded_test_figure` for one test: plain data a worker can take."""
    return (
        tf.test,
        tf.flat("force").mean(0),
        tf.x0_m,
        tb,
        grid,
        figure_format,
        _piston(tf),
        tf.convergence.converged,
        units,
    )


class _TestFigures:
    """The per-test figures (the slow part of a report: about 0.35 CPU s each), drawn by the
    ``workers`` (a :class:`FigureWorkers`), which start on them while the page and the campaign
    figures are made in this process, and by this process, which then draws those no worker has
    started, from the last back (:meth:`results`; a worker is given its next figure only when it
    is done with the last, so that none waits in a worker's queue). Workers get plain data
    (recordings, mean coefficients, bands) and import only matplotlib and this module, not JAX;
    every process draws them on its one kept figure (:func:`test_canvas`), and the bytes (PNG or
    SVG) are the same wherever a figure is drawn (tested)."""

    def __init__(
        self, cf, cb: CampaignBands, workers: FigureWorkers, figure_format="png", units=None
    ):
        grid = SimpleNamespace(x_m=cb.x_m, x0_m=cb.x0_m, reference_bar=cb.reference_bar)
        self._work = [
            _work_item(tf, tb, grid, figure_format, units)
            for tf, tb in zip(cf.tests, cb.tests, strict=True)
        ]
        self._pool = workers.pool if len(self._work) >= FigureWorkers.MIN_TESTS else None
        self._futures = []
        if self._pool:
            for i, tb in enumerate(cb.tests):  # the figures asked for ahead, if of these bands
                tb0, fmt0, units0, future = workers._ahead.get(i, (None, None, None, None))
                if not (tb0 is tb and fmt0 == figure_format and units0 is units):
                    future = workers.submit(encoded_test_figure, *self._work[i])
                self._futures.append(future)

    def results(self) -> list[bytes]:
        """Every test's figure bytes, in order: those no worker has started are drawn here (from
        the last back, while the workers go on from the first: a future that can be cancelled
        was never started)."""
        here = {}
        for i in reversed(range(len(self._work))):
            if not self._pool or self._futures[i].cancel():
                here[i] = encoded_test_figure(*self._work[i])
        return [here[i] if i in here else self._futures[i].result() for i in range(len(self._work))]

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        for f in self._futures:  # the workers may outlive this report (they are the caller's)
            f.cancel()


# ----------------------------------------------------------------------------- HTML


def _table1(cf, ref: Reference | None) -> tuple[list[dict], int, int]:
    """Table 1's rows (posterior mean, 90 % interval and the reference's value per coefficient, in
    the paper's units), with how many reference values fall outside the interval, of how many
    compared (none without a reference)."""
    n_out = n_cmp = 0
    rows = []
    columns = _table1_columns(cf)
    for tf in cf.tests:
        cells = []
        volume = getattr(tf, "has_piston", True)
        nan = np.full_like(tf.flat("force"), np.nan)
        draws = np.concatenate([tf.flat("force"), tf.flat("piston") if volume else nan], axis=1)
        force = None if ref is None else ref.at(ref.force, tf.pressure_bar)
        paper = None  # the reference's coefficients, NaN where it has none
        if force is not None:
            piston = ref.at(ref.piston, tf.pressure_bar)
            paper = np.concatenate([force, np.full(4, np.nan) if piston is None else piston])
        for k, (_, _, f) in enumerate(TABLE1_COLUMNS[:columns]):
            if k >= 4 and not volume:  # a force-only test has no piston coefficients
                cells.append(None)
                continue
            d = draws[:, k] * f
            cell = {
                "mean": d.mean(),
                "lo": np.quantile(d, 0.05),
                "hi": np.quantile(d, 0.95),
                "paper": None,
                "out": False,
            }
            if paper is not None and np.isfinite(paper[k]):
                cell["paper"] = pv = paper[k] * f
                cell["out"] = out = not cell["lo"] <= pv <= cell["hi"]
                n_cmp += 1
                n_out += int(out)
            cells.append(cell)
        rows.append({"pressure_bar": tf.pressure_bar, "cells": cells})
    return rows, n_out, n_cmp


def _table1_columns(cf) -> int:
    """How many of TABLE1_COLUMNS the page shows: the piston's too when some test has them."""
    return 8 if any(getattr(t, "has_piston", True) for t in cf.tests) else 4


def _piston(tf):
    """The L readings a test's volume block fitted (None for a force-only test)."""
    return getattr(tf, "piston_m", None) if getattr(tf, "has_piston", True) else None


def _table2(cf, ref: Reference | None) -> list[dict]:
    rows = []
    for tf in cf.tests:
        s, e = tf.deviation_measures()
        ps, pe = (ref and ref.at(ref.deviations, tf.pressure_bar)) or (np.nan, np.nan)
        rows.append(
            {
                "pressure_bar": tf.pressure_bar,
                "s": s,
                "paper_s": ps,
                "ratio": s / ps,
                "e": e,
                "paper_e": pe,
            }
        )
    return rows


def _diagnostics(cf) -> list[dict]:
    rows = []
    for tf in cf.tests:
        d = tf.convergence
        v = d.variables
        rows.append(
            {
                "pressure_bar": tf.pressure_bar,
                "n_steps": d.n_steps,
                "burn_in": d.burn_in,
                "tau": max(d.tau.values()),
                "acceptance": d.acceptance["mean"],
                "rhat": max(float(np.max(x["r_hat"])) for x in v.values()),
                "ess": min(
                    min(float(np.min(x["ess_bulk"])), float(np.min(x["ess_tail"])))
                    for x in v.values()
                ),
                "converged": d.converged,
                "warnings": d.messages(CLI_ADVICE),
            }
        )
    return rows


def _at_x0(cb: CampaignBands) -> list[dict]:
    """Per test, (mean, q05, q95) at x0 of the columns of the values-at-x0 table (None where the
    test has no such value: a force-only test's own-volume columns)."""
    return [
        {
            "pressure_bar": t.pressure_bar,
            "cells": [
                {q: t.at_x0[k][q] * scale for q in ("mean", "q05", "q95")} if k in t.at_x0 else None
                for k, scale, _ in _at_x0_columns(cb)
            ],
        }
        for t in cb.tests
    ]


def _at_x0_columns(cb: CampaignBands) -> list[tuple[str, float, str]]:
    """(key, scale, heading) of the values-at-x0 table: the volume columns only when some test
    has a volume curve."""
    cols = [("force_N", 1.0, "P(x0) (N)"), ("feff_m2", 1e4, "P/p_u (cm²)")]
    if cb.has_volume:
        ref = f"{cb.reference_bar:g}"
        cols += [
            ("feff_volume_m2", 1e4, "−S dL/dx (cm²)"),
            ("trad_own_N", 1.0, "traditional, own volume (N)"),
            ("spread_own_pct", 1.0, "spread (%)"),
            ("trad_ref_N", 1.0, f"traditional, {ref}-bar volume (N)"),
            ("spread_ref_pct", 1.0, "spread (%)"),
        ]
    return cols


def _sections(cf, cb: CampaignBands, figures: dict) -> list[dict]:
    """One per test: the numbers of its paragraph, its sampler and model warnings and its figure."""
    out = []
    for tf, tb in zip(cf.tests, cb.tests, strict=True):
        a = tb.at_x0
        s, e = tf.deviation_measures()
        noise = tf.flat("noise")
        comp = tf.test.compression

        def mean(key, scale=1.0, a=a):
            return a[key]["mean"] * scale if key in a else None

        out.append(
            {
                "pressure_bar": tf.pressure_bar,
                "n_points": tf.test.n_points,
                "order_known": comp is not None,
                "n_compression": None if comp is None else int(comp.sum()),
                "n_rebound": None if comp is None else int((~comp).sum()),
                "force": a["force_N"],
                "feff_cm2": a["feff_m2"]["mean"] * 1e4,
                "feff_volume_cm2": mean("feff_volume_m2", 1e4),
                "spread_own_pct": mean("spread_own_pct"),
                "spread_ref_pct": mean("spread_ref_pct"),
                "volume_from": getattr(tf, "piston_source", "piston"),
                "s_P": s,
                "eps_P": e,
                "sigma0": np.mean(noise[:, 0]),
                "rel_pct": 100 * np.mean(noise[:, 1]),
                "sigma_L_mm": 1e3 * np.mean(noise[:, 2]) if noise.shape[1] > 2 else None,
                "warnings": tf.convergence.messages(CLI_ADVICE) + tf.model_warnings(),
                "figure": figures[f"test_{tf.pressure_bar:g}bar"],
            }
        )
    return out


def omitted_lines(cf, cb: CampaignBands) -> list[str]:
    """What the report leaves out of a force-only or one-pass campaign, and why: one line each
    (the page's notes and ``uq report``'s summary)."""
    lines = []
    without = [tb.pressure_bar for tb in cb.tests if not tb.has_volume]
    if without and not cb.has_volume:
        lines.append(
            "Volume results omitted: force-only campaign (no piston_* or volume_* column), so no "
            "volume increment (Figure 3), no volume-derived area −S dL/dx, no traditional force "
            "or its spread (Figure 5)."
        )
    elif without:
        lines.append(
            f"Volume results of the {', '.join(f'{p:g}' for p in without)} bar tests omitted: "
            "force-only tests (no piston or volume readings); their traditional force uses the "
            f"{cb.reference_bar:g}-bar test's volume curve."
        )
    vol = [tf.pressure_bar for tf in cf.tests if getattr(tf, "piston_source", None) == "volume"]
    if vol:
        lines.append(
            f"The {', '.join(f'{p:g}' for p in vol)} bar volume curve comes from the volume column: "
            "L = −V / S (eq. 10), its reference arbitrary (a_L means nothing on its own)."
        )
    if not getattr(cf.recordings, "order_known", True):
        lines.append(
            "One pass in unknown order (no branch and step columns): no compression/rebound "
            "markers or hysteresis, and no recording-order check of the residuals."
        )
    return lines


def _scatter(cb: CampaignBands, ref: Reference | None) -> list[dict]:
    paper = PAPER_SCATTER_PCT if ref is not None and ref.is_paper else {}
    return [
        {
            "where": k,
            "height_mm": v["height_m"] * MM,
            "mean": v["mean"],
            "q05": v["q05"],
            "q95": v["q95"],
            "paper": paper.get(k, "–"),
        }
        for k, v in cb.scatter_at.items()
    ]


def _reference(reference, comments) -> Reference | None:
    """What the page compares with (``write_report``'s ``reference``)."""
    if isinstance(reference, Reference) or reference is None:
        return reference
    if reference == "paper" or (reference == "auto" and is_n50_reconstruction(comments)):
        return paper_reference()
    if reference == "auto":
        return None

    raise InputError(
        f"reference: expected 'auto', 'paper', None or a Reference, got {reference!r}",
        param="reference",
    )


def provenance(rec, stand) -> dict:
    """The footer of a page: uq's version, the date (``SOURCE_DATE_EPOCH`` when set, for
    reproducible pages), the recordings' file and SHA-256 (taken when they were read), and the
    stand description used."""
    digest = getattr(rec, "sha256", None)
    changes = stand.changes()
    return {
        "version": __version__,
        "date": date_stamp(),
        "file": Path(rec.path).name,
        "sha256": digest,
        "stand": "the paper's stand (section 3.2: load cell 0.5 %, pressure held within 0.01 bar)"
        if not changes
        else "the paper's stand with "
        + ", ".join(
            f"{k} = {v:g}" if isinstance(v, float) else f"{k} = {v}" for k, v in changes.items()
        ),
    }


def _comments(rec, comments) -> list[str]:
    """The comment lines given, else the recordings' (read with them)."""
    return list(getattr(rec, "comments", ())) if comments is None else comments


def _draw_figures(
    cf,
    cb: CampaignBands,
    out: Path,
    test_figures: _TestFigures,
    figure_format: str,
    ref: Reference | None = None,
    units=None,
) -> dict[str, Figure]:
    """The page's figures, each also written to ``out`` as a PNG or SVG file, by name without
    the extension (``"fig2_force"``); ``units``: second axes in the recordings' units."""
    paper = ref is not None and ref.is_paper
    drawn = [  # (stem, whether drawn, figure, alternative text)
        ("fig2_force", True, lambda _: figure_force(cf, cb), "Figure 2: force vs height"),
        ("fig3_volume", any(tb.has_volume for tb in cb.tests), lambda _: figure_volume(cf, cb),
         "Figure 3: volume increment vs height"),
        ("fig4_feff", True, lambda _: figure_feff(cf, cb), "Figure 4: effective area vs height"),
        ("fig5_traditional", cb.has_volume, lambda _: figure_traditional(cf, cb),
         "Figure 5: traditional vs measured force"),
        ("fig_feff_scatter", cb.scatter is not None, lambda _: figure_scatter(cb, paper),
         "F_eff scatter vs height"),
    ]  # fmt: skip
    what, _ = not_converged(cf)  # the campaign's figures show every test
    figs = {
        stem: Figure(f"{stem}.{figure_format}", _encoded(make, figure_format, units, what), alt)
        for stem, shown, make, alt in drawn
        if shown
    }
    for tf, data in zip(cf.tests, test_figures.results(), strict=True):
        stem = f"test_{tf.pressure_bar:g}bar"
        figs[stem] = Figure(f"{stem}.{figure_format}", data, f"{tf.pressure_bar:g} bar")
    for f in figs.values():
        write_bytes_atomic(out / f.name, f.data)
    return figs


def write_report(
    cf,
    out_dir,
    *,
    draws: int = 2000,
    seed: int | None = None,
    bands: CampaignBands | None = None,
    comments: list[str] | None = None,
    surface=None,
    comparison: dict | None = None,
    surface_page: str | None = None,
    jobs: int | FigureWorkers | None = 1,
    figure_format: str = "png",
    reference: Reference | str | None = "auto",
    units=None,
) -> Path:
    """Write ``out_dir/report.html`` and its figures, as ``uq report`` does; return the page's path.

    ``cf`` is a :func:`uq.fit_campaign` result. The bands use ``draws`` joint posterior draws,
    subsampled with ``seed`` (default: the fit's seed, as ``uq report --seed N`` does); ``bands``
    (from :func:`uq.campaign_bands`) replaces ``draws``/``seed``. ``surface``: a surface-model fit
    of the same recordings (:func:`uq.fit_surface`) whose page ``surface.html`` is written beside
    the report and linked from it, with ``comparison`` (:func:`uq.compare_models`) on it, as
    ``uq report --surface`` does; this function only renders, it fits nothing. ``comments``
    replaces the recordings' leading ``#`` lines. Every file is written atomically; PNGs an earlier
    report left behind are removed. The per-test figures are drawn in this process by default;
    ``jobs=N`` draws them in N processes, this one and N - 1 workers, which start on them while
    this one draws the campaign's figures (``None``: one per CPU; a :class:`FigureWorkers`:
    workers started ahead, as ``uq report`` does before it fits),
    with the same bytes either way. Workers are started by spawning (this process may hold a JAX
    runtime, which forking can deadlock), and a spawned worker imports the calling script again:
    with ``jobs`` other than 1, call ``write_report`` from a script only under
    ``if __name__ == "__main__":``. ``figure_format``: "png" (default, at 90 dpi) or "svg"
    (vector, for print and zoom; ``uq report --figures svg``); the page embeds the figures
    either way and the same files are written beside it (the surface page's too).
    ``reference``: what Tables 1 and 2 and the scatter compare with: ``"auto"`` (default) the
    paper's tables when the recordings are the virtual stand's reconstruction of the paper's N-50
    spring (their header says so) and nothing otherwise, ``"paper"``, ``None``, or a
    :class:`uq._data.reference.Reference` (``uq report --reference FILE``). The page's footer
    names the uq version, the date (``SOURCE_DATE_EPOCH`` when set), the recordings' SHA-256 and
    the stand description used. ``units``: a :class:`uq._data.units.OutputUnits`
    (``uq report --units input``): every figure axis in mm, N, kN, cm² or litres gets a second
    axis in those units (the recordings' own: psi, in, lbf, ...).

    >>> import tempfile, uq
    >>> rec = uq.simulate("n50", seed=1, layout=uq.Layout(pressures_bar=(1.0, 5.0), step_m=0.01))
    >>> fit = uq.fit_campaign(rec, seed=1, settings=uq.Settings(max_steps=200))
    >>> page = uq.write_report(fit, tempfile.mkdtemp(), draws=200)
    >>> page.name, "Reconstructed data" in page.read_text(encoding="utf-8")
    ('report.html', True)
    """

    if draws < MIN_DRAWS:
        raise InputError(f"draws: at least {MIN_DRAWS} draws, got {draws}", param="draws")
    check_format(figure_format)
    seed = cf.seed if seed is None else seed
    out = Path(out_dir)
    cb = bands if bands is not None else campaign_bands(cf, n_draws=draws, seed=seed)
    # All pages and figures go to a hidden folder first and are moved in at the end, so a full
    # disk or a Ctrl-C leaves the previous report (or nothing), never part of a new one.
    with staged_folder(out, last=("surface.html", "report.html")) as stage:
        if surface is not None:  # the model's page (uq._report.pages: by the fit's class)
            surface_page = write_model_page(
                surface, surface.to_json(comparison), stage, figure_format=figure_format
            ).name
        own = None if isinstance(jobs, FigureWorkers) else FigureWorkers(jobs, len(cf.tests))
        with (
            own or contextlib.nullcontext(),
            _TestFigures(cf, cb, own or jobs, figure_format, units) as test_figures,
        ):
            page, names = _write_page(
                cf, cb, stage, test_figures, comments, surface_page, figure_format, reference, units
            )
    # Figures an earlier run wrote (other pressures, a --surface run) must not pass for this run's.
    if surface is not None:  # this run's surface figures, in this run's format
        stale = REPORT_FIGURES + tuple(
            f"surface_*.{ext}" for ext in FIGURE_FORMATS if ext != figure_format
        )
    else:
        stale = REPORT_FIGURES + (() if surface_page else SURFACE_OUTPUTS)
    remove_stale(out, stale, keep=names | {page.name})
    return out / page.name


def _write_page(
    cf,
    cb: CampaignBands,
    out: Path,
    test_figures: _TestFigures,
    comments,
    surface_page,
    figure_format: str = "png",
    reference: Reference | str | None = "auto",
    units=None,
) -> tuple[Path, set]:
    """report.html (the template ``report.html``) and its figures in ``out``; returns the page and
    the figures' file names."""
    rec = cf.recordings
    comments = _comments(rec, comments)
    ref = _reference(reference, comments)
    figures = _draw_figures(cf, cb, out, test_figures, figure_format, ref, units)
    lo, hi = rec.height_range_m
    t1_rows, n_out, n_cmp = _table1(cf, ref)
    page = render(
        "report.html",
        name=Path(rec.path).name,
        comments="\n".join(comments),
        reconstructed=any("RECONSTRUCTED" in c.upper() for c in comments),
        surface_page=surface_page,
        pressures=[t.pressure_bar for t in rec.tests],
        n_points=rec.n_points,
        heights_mm=(lo * MM, hi * MM),
        x0_mm=rec.x0_m * MM,
        piston_cm2=rec.piston_area_m2 * 1e4,
        n_draws=cb.n_draws,
        bands_seed=cb.seed,
        fit_seed=cf.seed,
        n_not_converged=sum(not t.convergence.converged for t in cf.tests),
        not_converged_what=not_converged(cf)[0],
        not_converged_messages=not_converged(cf)[1],
        reference_bar=cb.reference_bar,
        reference_note=cb.reference_note,
        scatter_pressures=cb.scatter_pressures_bar,
        scatter=_scatter(cb, ref) if cb.scatter is not None else None,
        table1_columns=[(n, u) for n, u, _ in TABLE1_COLUMNS[: _table1_columns(cf)]],
        at_x0_columns=[h for _, _, h in _at_x0_columns(cb)],
        omitted=omitted_lines(cf, cb),
        table1=t1_rows,
        n_out=n_out,
        n_compared=n_cmp,
        table2=_table2(cf, ref),
        reference=ref,
        paper=ref is not None and ref.is_paper,
        footer=provenance(rec, cf.stand),
        diagnostics=_diagnostics(cf),
        at_x0=_at_x0(cb),
        sections=_sections(cf, cb, figures),
        figures=figures,
        figure_format=figure_format,
    )
    return write_text_atomic(out / "report.html", page), {f.name for f in figures.values()}
