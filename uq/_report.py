"""``uq report FILE.csv --out DIR``: one self-contained HTML page (+ PNG figures) per campaign.

The page redraws the paper's Figures 2-5 with credible bands, sets Tables 1 and 2 beside the
posterior, gives the scatter of the effective area, the sampler's diagnostics and a section
per pressure. Figures are embedded as base64 PNG and also written beside the page; every
write is atomic (``uq._io``).
"""

from __future__ import annotations

import html
import os
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from ._bands import CampaignBands, campaign_bands
from ._html import CSS, _img, _plt, _png
from ._io import remove_stale, write_bytes_atomic, write_text_atomic
from ._physics import BAR_PA
from ._recordings import leading_comments
from ._reference import table1, table2

#: Names of the files write_report and the surface page write (uq._io.remove_stale prunes the rest).
REPORT_FIGURES = ("fig2_*.png", "fig3_*.png", "fig4_*.png", "fig5_*.png", "fig_*.png", "test_*bar.png")
SURFACE_OUTPUTS = ("surface_*.png", "surface.html")
MM = 1e3
BRANCH_COLORS = {True: "tab:blue", False: "tab:orange"}  # compression, rebound
#: Table 1 as printed: (name, unit, factor SI -> printed unit).
TABLE1_COLUMNS = [
    ("a_P", "kN", 1e-3), ("b_P", "kN/m", 1e-3), ("c_P", "kN/m²", 1e-3), ("d_P", "10³ kN/m³", 1e-6),
    ("a_L", "m", 1.0), ("b_L", "–", 1.0), ("c_L", "1/m", 1.0), ("d_L", "1/m²", 1.0),
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
    for tf, tb, c in zip(cf.tests, cb.tests, _colors([t.pressure_bar for t in cb.tests]), strict=True):
        _fill(ax, x, tb.force, 1e-3, c, label=f"{tb.pressure_bar:g} bar")
        ax.plot(tf.test.height_m * MM, tf.test.force_N * 1e-3, ".", color=c, ms=3)
    _mark_x0(ax, cb.x0_m * MM)
    ax.set(xlabel="height x (mm)", ylabel="force P (kN)", title="Fig. 2: force characteristics (eq. 8), pointwise 90 % bands")
    ax.legend(fontsize=7, ncol=2, title="p_u", title_fontsize=7)
    ax.grid(alpha=0.3)
    return _png(fig)


def _dV_points(tf, tb, S):
    """Recorded volume increments S [L_k - L(x_max)] with the posterior-mean curve's L(x_max)."""
    L_top = np.mean(_cubic_at(tf.flat("piston"), tb.x_max_m - tf.x0_m))
    return S * (tf.test.piston_m - L_top)


def _cubic_at(coef, u):
    c = np.asarray(coef)
    return c[..., 0] + u * (c[..., 1] + u * (c[..., 2] + u * c[..., 3]))


def fig_volume(cf, cb: CampaignBands) -> bytes:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7.5, 5))
    x = cb.x_m * MM
    for tf, tb, c in zip(cf.tests, cb.tests, _colors([t.pressure_bar for t in cb.tests]), strict=True):
        _fill(ax, x, tb.dV, 1e3, c, label=f"{tb.pressure_bar:g} bar")
        ax.plot(tf.test.height_m * MM, _dV_points(tf, tb, cb.piston_area_m2) * 1e3, ".", color=c, ms=3)
    _mark_x0(ax, cb.x0_m * MM)
    ax.set(xlabel="height x (mm)", ylabel="volume increment ΔV (dm³ = litre)",
           title="Fig. 3: volume increment ΔV = S [L(x) − L(x_max)] (eq. 10), pointwise 90 % bands")
    ax.legend(fontsize=7, ncol=2, title="p_u", title_fontsize=7)
    ax.grid(alpha=0.3)
    return _png(fig)


def fig_feff(cf, cb: CampaignBands) -> bytes:
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7.5, 5))
    x = cb.x_m * MM
    for tf, tb, c in zip(cf.tests, cb.tests, _colors([t.pressure_bar for t in cb.tests]), strict=True):
        if tb.pressure_bar not in cb.scatter_pressures_bar:
            continue
        _fill(ax, x, tb.feff, 1e4, c, label=f"{tb.pressure_bar:g} bar")
        _simultaneous(ax, x, tb.simultaneous["feff"], 1e4, c)
        ax.plot(tf.test.height_m * MM, tf.test.force_N / (tb.pressure_bar * BAR_PA) * 1e4, ".", color=c, ms=3)
    _mark_x0(ax, cb.x0_m * MM)
    ax.set(xlabel="height x (mm)", ylabel="effective area F_eff = P / p_u (cm²)",
           title="Fig. 4: effective area from the force, tests with p_u ≥ 1 bar,\n"
                 "pointwise 90 % bands (shaded), simultaneous 90 % bands (dashed)")
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
        ax.errorbar(x[::step], tb.trad_ref.mean[::step] * 1e-3,
                    yerr=[(tb.trad_ref.mean - tb.trad_ref.lo)[::step] * 1e-3, (tb.trad_ref.hi - tb.trad_ref.mean)[::step] * 1e-3],
                    fmt="o", color=c, ms=3, lw=0.8)
        _fill(ax2, x, tb.spread_ref_pct, 1.0, c, label=f"{tb.pressure_bar:g} bar")
        _simultaneous(ax2, x, tb.simultaneous["spread_ref_pct"], 1.0, c)
    ax.set(xlabel="height x (mm)", ylabel="force (kN)",
           title=f"Fig. 5: measured (lines) vs traditional (points), {cb.reference_bar:g}-bar volume curve")
    ax2.axhline(0, color="k", lw=0.6)
    ax2.set(xlabel="height x (mm)", ylabel="(traditional − measured) / measured (%)",
            title="spread of the traditional force: pointwise (shaded) and simultaneous (dashed) 90 % bands")
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
        ax.errorbar([v["height_m"] * MM], [v["mean"]], yerr=[[v["mean"] - v["q05"]], [v["q95"] - v["mean"]]],
                    fmt="o", color="tab:purple", ms=4)
        ax.annotate(f"{label}: {v['mean']:.2f} %", (v["height_m"] * MM, v["mean"]), textcoords="offset points",
                    xytext=(4, 6), fontsize=7)
    paper = [(cb.x0_m, 8.41), (cb.x_m.max(), 26.3), (cb.x_m.min(), 8.51)]
    ax.plot([h * MM for h, _ in paper], [v for _, v in paper], "kx", ms=7, label="paper: 8.41 % (x0), 26.3 % (x_max), 8.51 % ('x_min')")
    _mark_x0(ax, cb.x0_m * MM)
    ax.set(xlabel="height x (mm)", ylabel="half range / mean of F_eff (%)",
           title=f"Scatter of F_eff across the {len(cb.scatter_pressures_bar)} tests with p_u ≥ 1 bar")
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
                ax.plot(h[m], y[m], "o", ms=3.5, mfc="none" if not is_comp else BRANCH_COLORS[is_comp],
                        color=BRANCH_COLORS[is_comp], label=name)

    ax = axs[0, 0]
    _fill(ax, x, tb.force_pred, 1e-3, "0.5", alpha=0.2, line=False)
    _fill(ax, x, tb.force, 1e-3, "tab:green", alpha=0.5, label="mean curve, pointwise 90 % band")
    points(ax, t.force_N * 1e-3)
    ax.plot([], [], color="0.5", alpha=0.4, lw=6, label="pointwise 90 % predictive band")
    ax.set(xlabel="height x (mm)", ylabel="force P (kN)", title="force (eq. 8)")
    ax.legend(fontsize=7)

    ax = axs[0, 1]
    fit_pts = _cubic_at(force_mean, t.height_m - x0_m)
    ax.fill_between(x, tb.force_pred.lo - tb.force.mean, tb.force_pred.hi - tb.force.mean, color="0.5", alpha=0.2, lw=0)
    ax.fill_between(x, tb.force.lo - tb.force.mean, tb.force.hi - tb.force.mean, color="tab:green", alpha=0.5, lw=0)
    points(ax, t.force_N - fit_pts)
    ax.axhline(0, color="k", lw=0.6)
    ax.set(xlabel="height x (mm)", ylabel="force − posterior-mean curve (N)", title="force residuals")

    ax = axs[0, 2]
    _fill(ax, x, tb.piston_pred, MM, "0.5", alpha=0.2, line=False)
    _fill(ax, x, tb.piston, MM, "tab:green", alpha=0.5)
    points(ax, t.piston_m * MM)
    ax.set(xlabel="height x (mm)", ylabel="piston coordinate L (mm)", title="piston (eq. 9)")

    ax = axs[1, 0]
    _fill(ax, x, tb.feff, 1e4, "tab:green", label="P / p_u (force)")
    _fill(ax, x, tb.feff_volume, 1e4, "tab:red", label="−S dL/dx (own volume curve)", ls="--")
    ax.plot(h, t.force_N / p_pa * 1e4, ".", color="k", ms=3, label="recorded P / p_u")
    ax.set(xlabel="height x (mm)", ylabel="effective area (cm²)", title="effective area, two ways (eq. 1)")
    ax.legend(fontsize=7)

    ax = axs[1, 1]
    _fill(ax, x, tb.force, 1e-3, "tab:green", label="measured P(x)")
    _fill(ax, x, tb.trad_own, 1e-3, "tab:red", label="p_u (−S dL/dx), own volume", ls="--")
    _fill(ax, x, tb.trad_ref, 1e-3, "tab:purple", label=f"p_u (−S dL/dx), {cb.reference_bar:g}-bar volume", ls=":")
    ax.set(xlabel="height x (mm)", ylabel="force (kN)", title="traditional vs measured force")
    ax.legend(fontsize=7)

    ax = axs[1, 2]
    _fill(ax, x, tb.spread_own, 1.0, "tab:red", label="own volume curve", ls="--")
    _fill(ax, x, tb.spread_ref, 1.0, "tab:purple", label=f"{cb.reference_bar:g}-bar volume curve", ls=":")
    ax.axhline(0, color="k", lw=0.6)
    ax.set(xlabel="height x (mm)", ylabel="traditional − measured force (N)", title="spread")
    ax.legend(fontsize=7)
    for a in axs.flat:
        _mark_x0(a, cb.x0_m * MM)
        a.grid(alpha=0.3)
    fig.suptitle(f"test at p_u = {tb.pressure_bar:g} bar", fontsize=11)
    fig.subplots_adjust(left=0.06, right=0.99, bottom=0.07, top=0.92, wspace=0.25, hspace=0.3)
    return _png(fig)


class _TestFigures:
    """The per-test figures (the slow part of a report: about 1 s each), drawn by ``jobs``
    spawned worker processes while the page and the campaign figures are made in this one.
    Workers get plain data (recordings, mean coefficients, bands) and import only matplotlib and
    this module, not JAX; the PNG bytes are the same as drawn here (tested)."""

    MIN_TESTS = 4  # below this, starting workers costs more than it saves

    def __init__(self, cf, cb: CampaignBands, jobs: int):
        grid = SimpleNamespace(x_m=cb.x_m, x0_m=cb.x0_m, reference_bar=cb.reference_bar)
        self._work = [(tf.test, tf.flat("force").mean(0), tf.x0_m, tb, grid)
                      for tf, tb in zip(cf.tests, cb.tests, strict=True)]
        self._pool, self._futures = None, []
        if jobs > 1 and len(self._work) >= self.MIN_TESTS:
            import concurrent.futures
            import multiprocessing

            # spawn, not fork: this process may hold a JAX runtime, which fork can deadlock
            self._pool = concurrent.futures.ProcessPoolExecutor(
                max_workers=min(jobs, len(self._work)), mp_context=multiprocessing.get_context("spawn"))
            self._futures = [self._pool.submit(fig_test, *w) for w in self._work]

    def result(self, i: int) -> bytes:
        return self._futures[i].result() if self._pool else fig_test(*self._work[i])

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if self._pool:
            self._pool.shutdown(cancel_futures=True)


# ----------------------------------------------------------------------------- HTML


def _fmt(v: float) -> str:
    if v == 0 or not np.isfinite(v):
        return f"{v:g}"
    return f"{v:.4g}"


def _table1_html(cf) -> tuple[str, int, int]:
    t1 = table1()
    n_out = n_cmp = 0
    head = "".join(f"<th>{n}<br><span class='small'>{html.escape(u)}</span></th>" for n, u, _ in TABLE1_COLUMNS)
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
            m, lo, hi = d.mean(), np.quantile(d, 0.05), np.quantile(d, 0.95)
            txt = f"{_fmt(m)}<br><span class='small'>[{_fmt(lo)}, {_fmt(hi)}]</span>"
            cls = ""
            if paper is not None:
                pv = paper[k] * f
                out = not lo <= pv <= hi
                n_cmp += 1
                n_out += int(out)
                cls = " class='out'" if out else ""
                txt += f"<br>paper {_fmt(pv)}{' ✗' if out else ''}"
            cells.append(f"<td{cls}>{txt}</td>")
        rows.append(f"<tr><th>{tf.pressure_bar:g}</th>{''.join(cells)}</tr>")
    table = f"<table><tr><th>p_u (bar)</th>{head}</tr>{''.join(rows)}</table>"
    return table, n_out, n_cmp


def _table2_html(cf) -> str:
    t2 = table2()
    rows = []
    for tf in cf.tests:
        s, e = tf.deviation_measures()
        ps, pe = t2.get(float(tf.pressure_bar), (np.nan, np.nan))
        rows.append(f"<tr><th>{tf.pressure_bar:g}</th><td>{s:.1f}</td><td>{_fmt(ps)}</td><td>{s / ps:.2f}</td>"
                    f"<td>{e:.2f}</td><td>{_fmt(pe)}</td></tr>")
    return ("<table><tr><th>p_u (bar)</th><th>s_P (N)</th><th>paper s_P (N)</th><th>ratio</th>"
            f"<th>ε_P (%)</th><th>paper ε_P (%)</th></tr>{''.join(rows)}</table>")


def _diag_html(cf) -> str:
    rows = []
    for tf in cf.tests:
        d = tf.diagnostics
        v = d["variables"]
        rhat = max(float(np.max(x["r_hat"])) for x in v.values())
        ess = min(min(float(np.min(x["ess_bulk"])), float(np.min(x["ess_tail"]))) for x in v.values())
        tau = max(d["tau"].values())
        acc = d["acceptance_fraction"]["mean"]
        status = "<span class='ok'>converged</span>" if d["converged"] else "<span class='warn'>NOT converged</span>"
        warns = "<br>".join(f"<span class='warn'>{html.escape(w)}</span>" for w in d["warnings"]) or "–"
        rows.append(f"<tr><th>{tf.pressure_bar:g}</th><td>{d['n_steps']}</td><td>{d['burn_in']}</td><td>{tau:.1f}</td>"
                    f"<td>{acc:.2f}</td><td>{rhat:.4f}</td><td>{ess:.0f}</td><td class='l'>{status}</td><td class='l'>{warns}</td></tr>")
    return ("<table><tr><th>p_u (bar)</th><th>steps</th><th>burn-in</th><th>max τ (steps)</th><th>acceptance</th>"
            f"<th>max R-hat</th><th>min ESS</th><th class='l'>status</th><th class='l'>warnings</th></tr>{''.join(rows)}</table>")


def _x0_table(cb: CampaignBands) -> str:
    def e(d, scale=1.0, fmt="{:.1f}"):
        return f"{fmt.format(d['mean'] * scale)} <span class='small'>[{fmt.format(d['q05'] * scale)}, {fmt.format(d['q95'] * scale)}]</span>"

    rows = []
    for t in cb.tests:
        a = t.at_x0
        rows.append(f"<tr><th>{t.pressure_bar:g}</th><td>{e(a['force_N'])}</td><td>{e(a['feff_m2'], 1e4, '{:.1f}')}</td>"
                    f"<td>{e(a['feff_volume_m2'], 1e4, '{:.1f}')}</td><td>{e(a['trad_own_N'])}</td><td>{e(a['spread_own_pct'])}</td>"
                    f"<td>{e(a['trad_ref_N'])}</td><td>{e(a['spread_ref_pct'])}</td></tr>")
    return ("<table><tr><th>p_u (bar)</th><th>P(x0) (N)</th><th>P/p_u (cm²)</th><th>−S dL/dx (cm²)</th>"
            "<th>traditional, own volume (N)</th><th>spread (%)</th>"
            f"<th>traditional, {cb.reference_bar:g}-bar volume (N)</th><th>spread (%)</th></tr>{''.join(rows)}</table>")


def write_report(cf, out_dir, *, draws: int = 2000, seed: int | None = None, surface: bool = False,
                 settings=None, bands: CampaignBands | None = None, comments: list[str] | None = None,
                 surface_page: str | None = None, jobs: int | None = None) -> Path:
    """Write ``out_dir/report.html`` and its PNG figures, as ``uq report`` does; return the page's path.

    ``cf`` is a :func:`uq.fit_campaign` result. The bands use ``draws`` joint posterior draws,
    subsampled with ``seed`` (default: the fit's seed, as ``uq report --seed N`` does). With
    ``surface=True`` the surface model is fitted too (``uq.fit_surface`` with ``settings``, default
    ``uq.Settings()``; needs 6 or more tests) and ``surface.html`` is written beside the page, as
    ``uq report --surface`` does. ``bands`` (from :func:`uq.campaign_bands`) replaces ``draws``/``seed``;
    ``comments`` replaces the recordings' leading ``#`` lines (from ``cf.recordings.comments``, or
    read from its file). Every file is written atomically; PNGs an earlier report left behind are
    removed. The per-test figures are drawn by ``jobs`` worker processes (default: one per CPU;
    ``jobs=1`` draws them here), with the same bytes either way.

    >>> import tempfile, uq
    >>> rec = uq.simulate("n50", seed=1, layout=uq.Layout(pressures_bar=(1.0, 5.0), step_m=0.01))
    >>> fit = uq.fit_campaign(rec, seed=1, settings=uq.Settings(max_steps=200))
    >>> page = uq.write_report(fit, tempfile.mkdtemp(), draws=200)
    >>> page.name, "Reconstructed data" in page.read_text(encoding="utf-8")
    ('report.html', True)
    """
    from ._errors import InputError

    if draws < MIN_DRAWS:
        raise InputError(f"write_report: at least {MIN_DRAWS} draws, got {draws}")
    seed = cf.seed if seed is None else seed
    out = Path(out_dir)
    rec = cf.recordings
    if surface:
        from ._sampler import Settings
        from ._surface import compare_with_cubics, fit_surface, summary
        from ._surface_report import write_surface_report

        sf = fit_surface(rec, seed=seed, settings=Settings() if settings is None else settings)
        surface_page = write_surface_report(sf, summary(sf, compare_with_cubics(sf, cf)), out).name
    out.mkdir(parents=True, exist_ok=True)
    cb = bands if bands is not None else campaign_bands(cf, n_draws=draws, seed=seed)
    with _TestFigures(cf, cb, (os.cpu_count() or 1) if jobs is None else jobs) as test_pngs:
        page, names = _write_page(cf, cb, out, test_pngs, comments, surface_page)
    # Figures an earlier run wrote (other pressures, a --surface run) must not pass for this run's.
    stale = REPORT_FIGURES + (() if surface_page else SURFACE_OUTPUTS)
    remove_stale(out, stale, keep=names | {page.name})
    return page


def _write_page(cf, cb: CampaignBands, out: Path, test_pngs: _TestFigures, comments, surface_page) -> tuple[Path, set]:
    """report.html and its figures in ``out``; returns the page and the figures' file names."""
    rec = cf.recordings
    if comments is None:
        comments = list(getattr(rec, "comments", ()))
        if not comments:
            try:
                comments = read_comments(rec.path)
            except OSError:
                comments = []
    reconstructed = any("RECONSTRUCTED" in c.upper() for c in comments)
    figures: dict[str, bytes] = {}

    def fig(name, png, alt):
        figures[name] = png
        write_bytes_atomic(out / name, png)
        return _img(name, png, alt)

    lo, hi = rec.height_range_m
    parts = [f"<!DOCTYPE html><html><head><meta charset='utf-8'><title>Air-spring report: {html.escape(Path(rec.path).name)}</title>"
             f"<style>{CSS}</style></head><body>"]
    parts.append(f"<h1>Air-spring posterior report: {html.escape(Path(rec.path).name)}</h1>")
    if reconstructed:
        parts.append("<p class='note'><b>Reconstructed data.</b> These recordings were not measured: they were generated by the "
                     "project's virtual test stand from the cubics of the paper's Table 1, with the noise of its error budget "
                     "(section 3.2). Agreement with the paper's tables is therefore expected by construction, except where the "
                     "stand leaves physics out.</p>")
    if comments:
        parts.append("<p class='small'>Comment lines of the file:</p><pre>" + html.escape("\n".join(comments)) + "</pre>")
    parts.append(
        f"<p>{len(rec.tests)} isobaric tests ({', '.join(f'{t.pressure_bar:g}' for t in rec.tests)} bar), {rec.n_points} recorded points, "
        f"heights {lo * MM:g}–{hi * MM:g} mm; reference height x0 = {rec.x0_m * MM:g} mm (dotted vertical line in the plots), "
        f"piston area S = {rec.piston_area_m2 * 1e4:g} cm². Each test is fitted on its own: force P(x) and piston coordinate L(x) "
        "are cubics in u = x − x0 (eqs. 8, 9) with Bayesian noise models (load-cell error proportional to the force plus a floor, "
        "and a piston-reading error). Shaded bands are pointwise 90 % credible bands of the curve (at each height separately); "
        "the dashed lines in Figures 4 and 5 bound simultaneous 90 % bands, which hold the whole curve with 90 % posterior "
        "probability (mean ± c sd, c the 90 % quantile of the draws' largest standardized deviation over height); the lighter "
        f"grey bands in the per-pressure sections are pointwise 90 % posterior predictive bands for a new reading. Bands use {cb.n_draws} posterior draws per test "
        f"(seed {cb.seed}); sampler seed {cf.seed}.</p>")
    if surface_page:
        parts.append(f"<p class='note'>The pressure-coupled surface model of this campaign (F<sub>eff</sub> and the traditional-minus-measured "
                     f"spread over height and pressure, each test against the surface's band, PSIS-LOO comparison with these "
                     f"per-pressure cubics) is on <a href='{html.escape(surface_page)}'>its own page</a>.</p>")
    parts.append("<p>Contents: <a href='#fig'>Figures 2–5</a> · <a href='#scatter'>F_eff scatter</a> · <a href='#t1'>Table 1</a> · "
                 "<a href='#t2'>Table 2</a> · <a href='#diag'>sampler diagnostics</a> · per pressure: "
                 + " ".join(f"<a href='#p{i}'>{t.pressure_bar:g}</a>" for i, t in enumerate(cb.tests)) + " bar</p>")

    n_bad = sum(not t.diagnostics["converged"] for t in cf.tests)
    if n_bad:
        parts.append(f"<p class='warn'><b>{n_bad} of {len(cf.tests)} tests did not pass the convergence checks</b>; "
                     "see <a href='#diag'>sampler diagnostics</a>. Their bands may be unreliable.</p>")

    parts.append("<h2 id='fig'>The paper's Figures 2–5, redrawn with credible bands</h2>")
    parts.append("<p>Figure 2: the force of the element at each overpressure p_u against its height; points are the recordings, "
                 "lines the posterior-mean cubics.</p>")
    parts.append(fig("fig2_force.png", fig_force(cf, cb), "Figure 2: force vs height"))
    parts.append("<p>Figure 3: the volume increment ΔV(x) = V(x_max) − V(x) = S [L(x) − L(x_max)], the air the hydraulic cylinder "
                 "took up to hold the pressure (eq. 10); x_max is each test's largest height. Points use the recorded piston "
                 "coordinates with the posterior-mean L(x_max).</p>")
    parts.append(fig("fig3_volume.png", fig_volume(cf, cb), "Figure 3: volume increment vs height"))
    parts.append("<p>Figure 4: the effective area from the force, F_eff = P / p_u (eq. 1). If the traditional theory held, "
                 "all curves would coincide.</p>")
    parts.append(fig("fig4_feff.png", fig_feff(cf, cb), "Figure 4: effective area vs height"))
    parts.append(f"<p>Figure 5: the traditional theory also says F_eff = −dΔV/dx = −S dL/dx, so the force would be "
                 f"p_u (−S dL/dx). Here the volume curve is {html.escape(cb.reference_note)}. Left: measured force "
                 "(lines with bands) and the traditional force (points with pointwise 90 % intervals); right: their relative difference.</p>")
    parts.append(fig("fig5_traditional.png", fig_traditional(cf, cb), "Figure 5: traditional vs measured force"))
    parts.append("<p>Values at x0 (posterior mean, [90 % interval]); “own volume” uses each test's own piston curve, so any "
                 "difference there is not due to pressure dependence of the volume curve.</p>")
    parts.append(_x0_table(cb))

    parts.append("<h2 id='scatter'>Scatter of the effective area across the tests</h2>")
    if cb.scatter is not None:
        sc = cb.scatter_at
        rows = "".join(
            f"<tr><th class='l'>{html.escape(k)}</th><td>{v['height_m'] * MM:g}</td><td>{v['mean']:.2f}</td><td>[{v['q05']:.2f}, {v['q95']:.2f}]</td>"
            f"<td>{PAPER_SCATTER_PCT.get(k, '–')}</td></tr>" for k, v in sc.items())
        parts.append(f"<p>The paper measures the disagreement between the F_eff curves of the tests from 1 to 10 bar as half their "
                     f"range over their mean, at a given height. Here it is computed for each joint posterior draw over the tests "
                     f"with p_u ≥ 1 bar ({', '.join(f'{p:g}' for p in cb.scatter_pressures_bar)} bar). The paper quotes 8.41 % at "
                     f"x0, 26.3 % at x_max and 8.51 % “at x_min”; Table 1 itself gives 8.41 %, 26.3 %, 9.74 % at 65 mm and 8.51 % at "
                     f"75 mm, so the paper's “x_min” value is the one at 75 mm. The table reports what these data give at each "
                     f"height.</p>")
        parts.append(f"<table><tr><th class='l'>where</th><th>height (mm)</th><th>scatter (%)</th><th>pointwise 90 % interval (%)</th>"
                     f"<th>paper (%)</th></tr>{rows}</table>")
        parts.append(fig("fig_feff_scatter.png", fig_scatter(cb), "F_eff scatter vs height"))
    else:
        parts.append("<p>Fewer than two tests at p_u ≥ 1 bar: no scatter to compute.</p>")

    t1_html, n_out, n_cmp = _table1_html(cf)
    parts.append("<h2 id='t1'>Table 1: regression coefficients</h2>")
    parts.append("<p>Cubic coefficients of P(x) = a_P + b_P u + c_P u² + d_P u³ and L(x) = a_L + b_L u + c_L u² + d_L u³, "
                 "u = x − x0 in m, in the paper's units. Each cell: posterior mean, [90 % interval], and the paper's value; "
                 "<span class='out'>red cells ✗</span> mark a paper value outside the 90 % interval. a_L is the piston position at x0 "
                 f"from an arbitrary reference, so it need not agree. Outside: {n_out} of {n_cmp} comparisons "
                 f"(about 10 % expected by chance if the data follow Table 1).</p>")
    parts.append(t1_html)
    parts.append("<h2 id='t2'>Table 2: force deviation measures</h2>")
    parts.append("<p>s_P = √(mean (P_k − P(x_k))²) and ε_P = mean |P_k − P(x_k)| / |P_k| (section 5) of the posterior-mean curve "
                 "against the recordings. Note: the stand's error budget (load cell 0.5 %, pressure holding) leaves out hysteresis "
                 "and relaxation of the casing, so the paper's measured values are larger from 4 bar up (compression and rebound "
                 "branches differ) and at 0.1 bar (relaxation dominates); reconstructed data reproduce only the budget.</p>")
    parts.append(_table2_html(cf))
    parts.append("<h2 id='diag'>Sampler diagnostics</h2>")
    parts.append("<p>emcee samples the three noise parameters (the coefficients are drawn exactly given them). Rules: R-hat ≤ 1.01, "
                 "ESS ≥ 400, acceptance 0.15–0.6, chain ≥ 50 autocorrelation times τ. Failures are listed in red.</p>")
    parts.append(_diag_html(cf))

    for i, (tf, tb) in enumerate(zip(cf.tests, cb.tests, strict=True)):
        a = tb.at_x0
        parts.append(f"<h2 id='p{i}'>{tf.pressure_bar:g} bar</h2>")
        s, e = tf.deviation_measures()
        parts.append(
            f"<p>{tf.test.n_points} points ({int(tf.test.compression.sum())} compression, filled; "
            f"{int((~tf.test.compression).sum())} rebound, open). At x0: P = {a['force_N']['mean']:.1f} N "
            f"[{a['force_N']['q05']:.1f}, {a['force_N']['q95']:.1f}], F_eff = {a['feff_m2']['mean'] * 1e4:.1f} cm², "
            f"−S dL/dx = {a['feff_volume_m2']['mean'] * 1e4:.1f} cm²; the traditional force exceeds the measured one by "
            f"{a['spread_own_pct']['mean']:.1f} % with the own volume curve and {a['spread_ref_pct']['mean']:.1f} % with the "
            f"{cb.reference_bar:g}-bar curve. s_P = {s:.1f} N, ε_P = {e:.2f} %. Noise: σ0 = "
            f"{np.mean(tf.flat('noise')[:, 0]):.1f} N, relative {100 * np.mean(tf.flat('noise')[:, 1]):.2f} %, "
            f"σ_L = {1e3 * np.mean(tf.flat('noise')[:, 2]):.3f} mm (posterior means).</p>")
        if tf.diagnostics["warnings"]:
            parts.append("".join(f"<p class='warn'>{html.escape(w)}</p>" for w in tf.diagnostics["warnings"]))
        parts.append(fig(f"test_{tf.pressure_bar:g}bar.png", test_pngs.result(i), f"{tf.pressure_bar:g} bar"))
    parts.append(f"<p class='small'>Generated by <code>uq report</code> (airspring-uq). Figures are embedded; the same PNG files "
                 f"({len(figures)}) are in this folder.</p></body></html>")
    return write_text_atomic(out / "report.html", "\n".join(parts)), set(figures)
