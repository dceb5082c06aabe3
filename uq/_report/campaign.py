"""``uq report FILE.csv --out DIR``: one self-contained HTML page (+ PNG figures) per campaign.

The page redraws the paper's Figures 2-5 with credible bands, sets Tables 1 and 2 beside the
posterior, gives the scatter of the effective area, the sampler's diagnostics and a section
per pressure. Figures are embedded as base64 PNG and also written beside the page; every
write is atomic (``uq._io.files``). The page is the template ``templates/report.html``
(``uq._report.html.render``); this module gives it numbers and figures, not markup.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from uq._data.recordings import leading_comments
from uq._data.reference import table1, table2
from uq._derived.bands import CampaignBands, campaign_bands
from uq._inference.convergence import CLI_ADVICE
from uq._io.files import remove_stale, staged_folder, write_bytes_atomic, write_text_atomic
from uq._physics.cubic import cubic
from uq._physics.quantities import BAR_PA
from uq._report.html import Figure, _plt, _png, render

#: Names of the files write_report and the surface page write (uq._io.files.remove_stale prunes the rest).
REPORT_FIGURES = (
    "fig2_*.png",
    "fig3_*.png",
    "fig4_*.png",
    "fig5_*.png",
    "fig_*.png",
    "test_*bar.png",
)
SURFACE_OUTPUTS = ("surface_*.png", "surface.html")
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


def read_comments(path) -> list[str]:
    """The leading ``#`` lines of a recordings file, without the ``#``."""
    with open(path, encoding="utf-8", errors="replace") as fh:
        return leading_comments(fh)


# ----------------------------------------------------------------------------- figures


def _colors(pressures):
    plt = _plt()
    cmap = plt.get_cmap("viridis")
    p = np.asarray(pressures, float)
    span = max(p.max() - p.min(), 1e-9)
    return [cmap(0.9 * (v - p.min()) / span) for v in p]


def _fill(ax, x, b, scale, color, alpha=0.25, label=None, line=True, ls="-"):
    ax.fill_between(x, b.lo * scale, b.hi * scale, color=color, alpha=alpha, lw=0)
    if line:
        ax.plot(x, b.mean * scale, color=color, lw=1.2, ls=ls, label=label)


def _simultaneous(ax, x, b, scale, color):
    """Dashed bounds of a simultaneous band (the whole curve inside with the band's probability)."""
    for edge in (b.lo, b.hi):
        ax.plot(x, edge * scale, color=color, lw=0.8, ls="--")


def _mark_x0(ax, x0_mm):
    ax.axvline(x0_mm, color="0.6", lw=0.6, ls=":")


def fig_force(cf, cb: CampaignBands) -> bytes:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7.5, 5))
    x = cb.x_m * MM
    for tf, tb, c in zip(
        cf.tests, cb.tests, _colors([t.pressure_bar for t in cb.tests]), strict=True
    ):
        _fill(ax, x, tb.force, 1e-3, c, label=f"{tb.pressure_bar:g} bar")
        ax.plot(tf.test.height_m * MM, tf.test.force_N * 1e-3, ".", color=c, ms=3)
    _mark_x0(ax, cb.x0_m * MM)
    ax.set(
        xlabel="height x (mm)",
        ylabel="force P (kN)",
        title="Fig. 2: force characteristics (eq. 8), pointwise 90 % bands",
    )
    ax.legend(fontsize=7, ncol=2, title="p_u", title_fontsize=7)
    ax.grid(alpha=0.3)
    return _png(fig)


def _dV_points(tf, tb, S):
    """Recorded volume increments S [L_k - L(x_max)] with the posterior-mean curve's L(x_max)."""
    L_top = np.mean(cubic(tf.flat("piston"), tb.x_max_m - tf.x0_m))
    return S * (tf.test.piston_m - L_top)


def fig_volume(cf, cb: CampaignBands) -> bytes:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7.5, 5))
    x = cb.x_m * MM
    for tf, tb, c in zip(
        cf.tests, cb.tests, _colors([t.pressure_bar for t in cb.tests]), strict=True
    ):
        _fill(ax, x, tb.dV, 1e3, c, label=f"{tb.pressure_bar:g} bar")
        ax.plot(
            tf.test.height_m * MM, _dV_points(tf, tb, cb.piston_area_m2) * 1e3, ".", color=c, ms=3
        )
    _mark_x0(ax, cb.x0_m * MM)
    ax.set(
        xlabel="height x (mm)",
        ylabel="volume increment ΔV (dm³ = litre)",
        title="Fig. 3: volume increment ΔV = S [L(x) − L(x_max)] (eq. 10), pointwise 90 % bands",
    )
    ax.legend(fontsize=7, ncol=2, title="p_u", title_fontsize=7)
    ax.grid(alpha=0.3)
    return _png(fig)


def fig_feff(cf, cb: CampaignBands) -> bytes:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7.5, 5))
    x = cb.x_m * MM
    for tf, tb, c in zip(
        cf.tests, cb.tests, _colors([t.pressure_bar for t in cb.tests]), strict=True
    ):
        if tb.pressure_bar not in cb.scatter_pressures_bar:
            continue
        _fill(ax, x, tb.feff, 1e4, c, label=f"{tb.pressure_bar:g} bar")
        _simultaneous(ax, x, tb.simultaneous["feff"], 1e4, c)
        ax.plot(
            tf.test.height_m * MM,
            tf.test.force_N / (tb.pressure_bar * BAR_PA) * 1e4,
            ".",
            color=c,
            ms=3,
        )
    _mark_x0(ax, cb.x0_m * MM)
    ax.set(
        xlabel="height x (mm)",
        ylabel="effective area F_eff = P / p_u (cm²)",
        title="Fig. 4: effective area from the force, tests with p_u ≥ 1 bar,\n"
        "pointwise 90 % bands (shaded), simultaneous 90 % bands (dashed)",
    )
    ax.legend(fontsize=7, ncol=2, title="p_u", title_fontsize=7)
    ax.grid(alpha=0.3)
    return _png(fig)


def fig_traditional(cf, cb: CampaignBands) -> bytes:
    plt = _plt()
    fig, (ax, ax2) = plt.subplots(1, 2, figsize=(12, 5))
    x = cb.x_m * MM
    step = max(1, len(x) // 19)
    for tb, c in zip(cb.tests, _colors([t.pressure_bar for t in cb.tests]), strict=True):
        if tb.pressure_bar not in cb.scatter_pressures_bar:
            continue
        _fill(ax, x, tb.force, 1e-3, c, label=f"{tb.pressure_bar:g} bar")
        ax.errorbar(
            x[::step],
            tb.trad_ref.mean[::step] * 1e-3,
            yerr=[
                (tb.trad_ref.mean - tb.trad_ref.lo)[::step] * 1e-3,
                (tb.trad_ref.hi - tb.trad_ref.mean)[::step] * 1e-3,
            ],
            fmt="o",
            color=c,
            ms=3,
            lw=0.8,
        )
        _fill(ax2, x, tb.spread_ref_pct, 1.0, c, label=f"{tb.pressure_bar:g} bar")
        _simultaneous(ax2, x, tb.simultaneous["spread_ref_pct"], 1.0, c)
    ax.set(
        xlabel="height x (mm)",
        ylabel="force (kN)",
        title=f"Fig. 5: measured (lines) vs traditional (points), {cb.reference_bar:g}-bar volume curve",
    )
    ax2.axhline(0, color="k", lw=0.6)
    ax2.set(
        xlabel="height x (mm)",
        ylabel="(traditional − measured) / measured (%)",
        title="spread of the traditional force: pointwise (shaded) and simultaneous (dashed) 90 % bands",
    )
    for a in (ax, ax2):
        _mark_x0(a, cb.x0_m * MM)
        a.grid(alpha=0.3)
        a.legend(fontsize=7, ncol=2)
    fig.subplots_adjust(left=0.07, right=0.99, bottom=0.1, top=0.92, wspace=0.22)
    return _png(fig)


def fig_scatter(cb: CampaignBands) -> bytes:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7.5, 4.5))
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
    paper = [(cb.x0_m, 8.41), (cb.x_m.max(), 26.3), (cb.x_m.min(), 8.51)]
    ax.plot(
        [h * MM for h, _ in paper],
        [v for _, v in paper],
        "kx",
        ms=7,
        label="paper: 8.41 % (x0), 26.3 % (x_max), 8.51 % ('x_min')",
    )
    _mark_x0(ax, cb.x0_m * MM)
    ax.set(
        xlabel="height x (mm)",
        ylabel="half range / mean of F_eff (%)",
        title=f"Scatter of F_eff across the {len(cb.scatter_pressures_bar)} tests with p_u ≥ 1 bar",
    )
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    return _png(fig)


def fig_test(t, force_mean, x0_m: float, tb, cb: CampaignBands) -> bytes:
    """Six panels for one test: force, residuals, piston, F_eff, traditional vs measured, spread.

    ``t`` the test's recordings (PressureTest), ``force_mean`` the posterior-mean force
    coefficients (paper basis): plain data, so that the figure can be drawn in another process.
    """
    plt = _plt()
    fig, axs = plt.subplots(2, 3, figsize=(14, 7.6))
    x = cb.x_m * MM
    h = t.height_m * MM
    comp = t.compression
    p_pa = tb.pressure_bar * BAR_PA

    def points(ax, y):
        for is_comp, name in ((True, "compression"), (False, "rebound")):
            m = comp == is_comp
            if m.any():
                ax.plot(
                    h[m],
                    y[m],
                    "o",
                    ms=3.5,
                    mfc="none" if not is_comp else BRANCH_COLORS[is_comp],
                    color=BRANCH_COLORS[is_comp],
                    label=name,
                )

    ax = axs[0, 0]
    _fill(ax, x, tb.force_pred, 1e-3, "0.5", alpha=0.2, line=False)
    _fill(ax, x, tb.force, 1e-3, "tab:green", alpha=0.5, label="mean curve, pointwise 90 % band")
    points(ax, t.force_N * 1e-3)
    ax.plot([], [], color="0.5", alpha=0.4, lw=6, label="pointwise 90 % predictive band")
    ax.set(xlabel="height x (mm)", ylabel="force P (kN)", title="force (eq. 8)")
    ax.legend(fontsize=7)

    ax = axs[0, 1]
    fit_pts = cubic(force_mean, t.height_m - x0_m)
    ax.fill_between(
        x,
        tb.force_pred.lo - tb.force.mean,
        tb.force_pred.hi - tb.force.mean,
        color="0.5",
        alpha=0.2,
        lw=0,
    )
    ax.fill_between(
        x,
        tb.force.lo - tb.force.mean,
        tb.force.hi - tb.force.mean,
        color="tab:green",
        alpha=0.5,
        lw=0,
    )
    points(ax, t.force_N - fit_pts)
    ax.axhline(0, color="k", lw=0.6)
    ax.set(
        xlabel="height x (mm)", ylabel="force − posterior-mean curve (N)", title="force residuals"
    )

    ax = axs[0, 2]
    _fill(ax, x, tb.piston_pred, MM, "0.5", alpha=0.2, line=False)
    _fill(ax, x, tb.piston, MM, "tab:green", alpha=0.5)
    points(ax, t.piston_m * MM)
    ax.set(xlabel="height x (mm)", ylabel="piston coordinate L (mm)", title="piston (eq. 9)")

    ax = axs[1, 0]
    _fill(ax, x, tb.feff, 1e4, "tab:green", label="P / p_u (force)")
    _fill(ax, x, tb.feff_volume, 1e4, "tab:red", label="−S dL/dx (own volume curve)", ls="--")
    ax.plot(h, t.force_N / p_pa * 1e4, ".", color="k", ms=3, label="recorded P / p_u")
    ax.set(
        xlabel="height x (mm)",
        ylabel="effective area (cm²)",
        title="effective area, two ways (eq. 1)",
    )
    ax.legend(fontsize=7)

    ax = axs[1, 1]
    _fill(ax, x, tb.force, 1e-3, "tab:green", label="measured P(x)")
    _fill(ax, x, tb.trad_own, 1e-3, "tab:red", label="p_u (−S dL/dx), own volume", ls="--")
    _fill(
        ax,
        x,
        tb.trad_ref,
        1e-3,
        "tab:purple",
        label=f"p_u (−S dL/dx), {cb.reference_bar:g}-bar volume",
        ls=":",
    )
    ax.set(xlabel="height x (mm)", ylabel="force (kN)", title="traditional vs measured force")
    ax.legend(fontsize=7)

    ax = axs[1, 2]
    _fill(ax, x, tb.spread_own, 1.0, "tab:red", label="own volume curve", ls="--")
    _fill(
        ax,
        x,
        tb.spread_ref,
        1.0,
        "tab:purple",
        label=f"{cb.reference_bar:g}-bar volume curve",
        ls=":",
    )
    ax.axhline(0, color="k", lw=0.6)
    ax.set(xlabel="height x (mm)", ylabel="traditional − measured force (N)", title="spread")
    ax.legend(fontsize=7)
    for a in axs.flat:
        _mark_x0(a, cb.x0_m * MM)
        a.grid(alpha=0.3)
    fig.suptitle(f"test at p_u = {tb.pressure_bar:g} bar", fontsize=11)
    fig.subplots_adjust(left=0.06, right=0.99, bottom=0.07, top=0.92, wspace=0.25, hspace=0.3)
    return _png(fig)


def _ignore_interrupts() -> None:
    """A figure worker's initializer: leave Ctrl-C to the process that started it."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


@contextlib.contextmanager
def _workers_ignore_interrupts():
    """Processes started in this block ignore Ctrl-C from their first instruction on.

    Ctrl-C reaches every process of the terminal's group, and a spawned worker is still importing
    (matplotlib, this module) when it arrives: it would print a traceback each. Only this process
    may answer it (one line, exit 130). An ignored signal stays ignored across exec, and Python
    keeps it so. The cost: a Ctrl-C in the few milliseconds the workers take to start is ignored
    here too (press it again). (Only the main thread can set handlers; elsewhere nothing is done.)
    """
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    handler = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, handler)


class _TestFigures:
    """The per-test figures (the slow part of a report: about 1 s each), drawn by ``jobs``
    spawned worker processes while the page and the campaign figures are made in this one.
    Workers get plain data (recordings, mean coefficients, bands) and import only matplotlib and
    this module, not JAX; the PNG bytes are the same as drawn here (tested)."""

    MIN_TESTS = 4  # below this, starting workers costs more than it saves

    def __init__(self, cf, cb: CampaignBands, jobs: int):
        grid = SimpleNamespace(x_m=cb.x_m, x0_m=cb.x0_m, reference_bar=cb.reference_bar)
        self._work = [
            (tf.test, tf.flat("force").mean(0), tf.x0_m, tb, grid)
            for tf, tb in zip(cf.tests, cb.tests, strict=True)
        ]
        self._pool, self._futures = None, []
        if jobs > 1 and len(self._work) >= self.MIN_TESTS:
            import concurrent.futures
            import multiprocessing

            with _workers_ignore_interrupts():
                # spawn, not fork: this process may hold a JAX runtime, which fork can deadlock
                self._pool = concurrent.futures.ProcessPoolExecutor(
                    max_workers=min(jobs, len(self._work)),
                    mp_context=multiprocessing.get_context("spawn"),
                    initializer=_ignore_interrupts,
                )
                # the workers start here (spawn launches them all at the first submit)
                self._futures = [self._pool.submit(fig_test, *w) for w in self._work]

    def result(self, i: int) -> bytes:
        return self._futures[i].result() if self._pool else fig_test(*self._work[i])

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if self._pool:
            self._pool.shutdown(cancel_futures=True)


# ----------------------------------------------------------------------------- HTML


def _table1(cf) -> tuple[list[dict], int, int]:
    """Table 1's rows (posterior mean, 90 % interval and the paper's value per coefficient, in the
    paper's units), with how many paper values fall outside the interval, of how many compared."""
    t1 = table1()
    n_out = n_cmp = 0
    rows = []
    for tf in cf.tests:
        try:
            i = t1.index(tf.pressure_bar)
        except KeyError:
            i = None
        cells = []
        draws = np.concatenate([tf.flat("force"), tf.flat("piston")], axis=1)
        paper = None if i is None else np.concatenate([t1.force[i], t1.piston[i]])
        for k, (_, _, f) in enumerate(TABLE1_COLUMNS):
            d = draws[:, k] * f
            cell = {
                "mean": d.mean(),
                "lo": np.quantile(d, 0.05),
                "hi": np.quantile(d, 0.95),
                "paper": None,
                "out": False,
            }
            if paper is not None:
                cell["paper"] = pv = paper[k] * f
                cell["out"] = out = not cell["lo"] <= pv <= cell["hi"]
                n_cmp += 1
                n_out += int(out)
            cells.append(cell)
        rows.append({"pressure_bar": tf.pressure_bar, "cells": cells})
    return rows, n_out, n_cmp


def _table2(cf) -> list[dict]:
    t2 = table2()
    rows = []
    for tf in cf.tests:
        s, e = tf.deviation_measures()
        ps, pe = t2.get(float(tf.pressure_bar), (np.nan, np.nan))
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
    """Per test, (mean, q05, q95) at x0 of the columns of the values-at-x0 table."""
    cols = (
        ("force_N", 1.0),
        ("feff_m2", 1e4),
        ("feff_volume_m2", 1e4),
        ("trad_own_N", 1.0),
        ("spread_own_pct", 1.0),
        ("trad_ref_N", 1.0),
        ("spread_ref_pct", 1.0),
    )
    return [
        {
            "pressure_bar": t.pressure_bar,
            "cells": [
                {q: t.at_x0[k][q] * scale for q in ("mean", "q05", "q95")} for k, scale in cols
            ],
        }
        for t in cb.tests
    ]


def _sections(cf, cb: CampaignBands, figures: dict) -> list[dict]:
    """One per test: the numbers of its paragraph, its sampler and model warnings and its figure."""
    out = []
    for tf, tb in zip(cf.tests, cb.tests, strict=True):
        a = tb.at_x0
        s, e = tf.deviation_measures()
        noise = tf.flat("noise")
        out.append(
            {
                "pressure_bar": tf.pressure_bar,
                "n_points": tf.test.n_points,
                "n_compression": int(tf.test.compression.sum()),
                "n_rebound": int((~tf.test.compression).sum()),
                "force": a["force_N"],
                "feff_cm2": a["feff_m2"]["mean"] * 1e4,
                "feff_volume_cm2": a["feff_volume_m2"]["mean"] * 1e4,
                "spread_own_pct": a["spread_own_pct"]["mean"],
                "spread_ref_pct": a["spread_ref_pct"]["mean"],
                "s_P": s,
                "eps_P": e,
                "sigma0": np.mean(noise[:, 0]),
                "rel_pct": 100 * np.mean(noise[:, 1]),
                "sigma_L_mm": 1e3 * np.mean(noise[:, 2]),
                "warnings": tf.convergence.messages(CLI_ADVICE) + tf.model_warnings(),
                "figure": figures[f"test_{tf.pressure_bar:g}bar.png"],
            }
        )
    return out


def _scatter(cb: CampaignBands) -> list[dict]:
    return [
        {
            "where": k,
            "height_mm": v["height_m"] * MM,
            "mean": v["mean"],
            "q05": v["q05"],
            "q95": v["q95"],
            "paper": PAPER_SCATTER_PCT.get(k, "–"),
        }
        for k, v in cb.scatter_at.items()
    ]


def _comments(rec, comments) -> list[str]:
    """The comment lines given, else the recordings', else those read from its file (none if unreadable)."""
    if comments is not None:
        return comments
    comments = list(getattr(rec, "comments", ()))
    if not comments:
        try:
            comments = read_comments(rec.path)
        except OSError:
            comments = []
    return comments


def _draw_figures(cf, cb: CampaignBands, out: Path, test_pngs: _TestFigures) -> dict[str, Figure]:
    """The page's figures, each also written to ``out`` as a PNG file, by file name."""
    figs = [
        Figure("fig2_force.png", fig_force(cf, cb), "Figure 2: force vs height"),
        Figure("fig3_volume.png", fig_volume(cf, cb), "Figure 3: volume increment vs height"),
        Figure("fig4_feff.png", fig_feff(cf, cb), "Figure 4: effective area vs height"),
        Figure(
            "fig5_traditional.png",
            fig_traditional(cf, cb),
            "Figure 5: traditional vs measured force",
        ),
    ]
    if cb.scatter is not None:
        figs.append(Figure("fig_feff_scatter.png", fig_scatter(cb), "F_eff scatter vs height"))
    figs += [
        Figure(f"test_{tf.pressure_bar:g}bar.png", test_pngs.result(i), f"{tf.pressure_bar:g} bar")
        for i, tf in enumerate(cf.tests)
    ]
    for f in figs:
        write_bytes_atomic(out / f.name, f.png)
    return {f.name: f for f in figs}


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
    jobs: int | None = 1,
) -> Path:
    """Write ``out_dir/report.html`` and its PNG figures, as ``uq report`` does; return the page's path.

    ``cf`` is a :func:`uq.fit_campaign` result. The bands use ``draws`` joint posterior draws,
    subsampled with ``seed`` (default: the fit's seed, as ``uq report --seed N`` does); ``bands``
    (from :func:`uq.campaign_bands`) replaces ``draws``/``seed``. ``surface``: a surface-model fit
    of the same recordings (:func:`uq.fit_surface`) whose page ``surface.html`` is written beside
    the report and linked from it, with ``comparison`` (:func:`uq.compare_models`) on it, as
    ``uq report --surface`` does; this function only renders, it fits nothing. ``comments``
    replaces the recordings' leading ``#`` lines. Every file is written atomically; PNGs an earlier
    report left behind are removed. The per-test figures are drawn in this process by default;
    ``jobs=N`` draws them in N worker processes (``None``: one per CPU; ``uq report`` does so),
    with the same bytes either way. Workers are started by spawning (this process may hold a JAX
    runtime, which forking can deadlock), and a spawned worker imports the calling script again:
    with ``jobs`` other than 1, call ``write_report`` from a script only under
    ``if __name__ == "__main__":``.

    >>> import tempfile, uq
    >>> rec = uq.simulate("n50", seed=1, layout=uq.Layout(pressures_bar=(1.0, 5.0), step_m=0.01))
    >>> fit = uq.fit_campaign(rec, seed=1, settings=uq.Settings(max_steps=200))
    >>> page = uq.write_report(fit, tempfile.mkdtemp(), draws=200)
    >>> page.name, "Reconstructed data" in page.read_text(encoding="utf-8")
    ('report.html', True)
    """
    from uq._io.errors import InputError

    if draws < MIN_DRAWS:
        raise InputError(f"draws: at least {MIN_DRAWS} draws, got {draws}", param="draws")
    seed = cf.seed if seed is None else seed
    out = Path(out_dir)
    cb = bands if bands is not None else campaign_bands(cf, n_draws=draws, seed=seed)
    # All pages and figures go to a hidden folder first and are moved in at the end, so a full
    # disk or a Ctrl-C leaves the previous report (or nothing), never part of a new one.
    with staged_folder(out, last=("surface.html", "report.html")) as stage:
        if surface is not None:
            from uq._models.surface import summary
            from uq._report.surface import write_surface_report

            surface_page = write_surface_report(surface, summary(surface, comparison), stage).name
        with _TestFigures(cf, cb, (os.cpu_count() or 1) if jobs is None else jobs) as test_pngs:
            page, names = _write_page(cf, cb, stage, test_pngs, comments, surface_page)
    # Figures an earlier run wrote (other pressures, a --surface run) must not pass for this run's.
    stale = REPORT_FIGURES + (() if surface_page else SURFACE_OUTPUTS)
    remove_stale(out, stale, keep=names | {page.name})
    return out / page.name


def _write_page(
    cf, cb: CampaignBands, out: Path, test_pngs: _TestFigures, comments, surface_page
) -> tuple[Path, set]:
    """report.html (the template ``report.html``) and its figures in ``out``; returns the page and
    the figures' file names."""
    rec = cf.recordings
    comments = _comments(rec, comments)
    figures = _draw_figures(cf, cb, out, test_pngs)
    lo, hi = rec.height_range_m
    t1_rows, n_out, n_cmp = _table1(cf)
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
        reference_bar=cb.reference_bar,
        reference_note=cb.reference_note,
        scatter_pressures=cb.scatter_pressures_bar,
        scatter=_scatter(cb) if cb.scatter is not None else None,
        table1_columns=[(n, u) for n, u, _ in TABLE1_COLUMNS],
        table1=t1_rows,
        n_out=n_out,
        n_compared=n_cmp,
        table2=_table2(cf),
        diagnostics=_diagnostics(cf),
        at_x0=_at_x0(cb),
        sections=_sections(cf, cb, figures),
        figures=figures,
    )
    return write_text_atomic(out / "report.html", page), set(figures)
