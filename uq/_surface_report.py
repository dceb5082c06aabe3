"""HTML section of the surface model (``uq surface --report DIR``).

Heat maps of the pressure area F_p(x, p_u) and of the spread traditional - measured with the region where
its 90 % band excludes zero outlined, every test's readings against the surface model's
band (as residuals from the surface's mean curve, where the differences are visible), the
PSIS-LOO comparison with the per-pressure cubics, the noise posterior and the sampler's
diagnostics. One self-contained page (PNG files beside it), written atomically.
"""

from __future__ import annotations

import html
from pathlib import Path

import numpy as np

from ._html import CSS, _img, _plt, _png
from ._io import write_bytes_atomic, write_text_atomic
from ._summary import band
from ._surface import SurfaceFit, comparison_words, figure_pressure_area, figure_spread


def figure_residual_overlay(fit: SurfaceFit):
    """Readings minus the surface's mean force, with its 90 % band, one panel per test."""
    plt = _plt()
    tests = fit.recordings.tests
    n = len(tests)
    cols = min(4, n)
    rows = int(np.ceil(n / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 2.4 * rows), squeeze=False)
    beta = fit.flat_beta(1000)
    lo, hi = fit.height_range_m
    xs = np.linspace(lo, hi, 80)
    for ax, t in zip(axes.flat, tests, strict=False):
        m, lo_b, hi_b = band(fit.force_draws(xs, t.pressure_bar, beta=beta), axis=0)
        at_pts = fit.force_draws(t.height_m, t.pressure_bar, beta=beta).mean(axis=0)
        ax.fill_between(xs * 1e3, lo_b - m, hi_b - m, alpha=0.35, color="tab:blue", lw=0, label="surface 90 % band")
        ax.axhline(0, color="k", lw=0.6)
        comp = t.compression
        ax.plot(t.height_m[comp] * 1e3, (t.force_N - at_pts)[comp], ".", ms=3, color="tab:red", label="compression")
        ax.plot(t.height_m[~comp] * 1e3, (t.force_N - at_pts)[~comp], "x", ms=3, color="tab:green", label="rebound")
        ax.set_title(f"{t.pressure_bar:g} bar", fontsize=9)
        ax.tick_params(labelsize=7)
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=6)
    fig.supxlabel("height x, mm", fontsize=9)
    fig.supylabel("reading - surface mean force, N", fontsize=9)
    fig.tight_layout()
    return fig


def _cm2(e) -> str:
    return f"{e['mean'] * 1e4:.2f} [{e['q05'] * 1e4:.2f}, {e['q95'] * 1e4:.2f}]"


def write_surface_report(fit: SurfaceFit, result: dict, out_dir) -> Path:
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    figs = {
        "surface_pressure_area.png": (figure_pressure_area(fit), "pressure area F_p(x, p_u) heat map"),
        "surface_spread.png": (figure_spread(fit), "spread traditional minus measured"),
        "surface_residuals.png": (figure_residual_overlay(fit), "readings against the surface band"),
    }
    imgs = {}
    for name, (fig, alt) in figs.items():
        png = _png(fig)
        write_bytes_atomic(out / name, png)
        imgs[name] = _img(name, png, alt)
    comp = result.get("comparison")
    if comp:
        s_, c_ = comp["surface"], comp["cubics"]
        comp_html = (
            f"<p>PSIS-LOO (ArviZ), per reading: surface model {s_['elpd_loo']:.1f} "
            f"({s_['n_coefficients']} coefficients; max Pareto k {s_['max_pareto_k']:.2f}, "
            f"{s_['n_pareto_k_above_0.7']} readings above 0.7) against per-pressure cubics "
            f"{c_['elpd_loo']:.1f} ({c_['n_coefficients']} coefficients; max Pareto k {c_['max_pareto_k']:.2f}, "
            f"{c_['n_pareto_k_above_0.7']} above 0.7): ELPD difference {comp['elpd_diff']:.1f} &plusmn; "
            f"{comp['elpd_diff_se']:.1f}. Verdict: <b>{html.escape(comparison_words(comp))}</b> "
            f"({html.escape(comp['rule'])}).</p>"
        )
    else:
        comp_html = "<p>Comparison with the per-pressure cubics skipped (--no-compare).</p>"
    sel = "".join(
        f"<tr><td class=l>{html.escape(r['orders'])}</td><td>{r['elpd_loo']:.1f}</td><td>{r['elpd_diff']:.1f}</td><td>{r['dse']:.1f}</td></tr>"
        for r in result.get("order_selection") or []
    )
    nz = result["noise"]
    noise_rows = "".join(
        f"<tr><td class=l>{html.escape(k)}</td><td>{v['mean']:.4g}</td><td>{v['q05']:.4g}</td><td>{v['q95']:.4g}</td></tr>"
        for k, v in nz.items()
    )
    x0 = "".join(
        f"<tr><td>{html.escape(p)}</td><td>{_cm2(r['pressure_area_m2'])}</td><td>{_cm2(r['feff_m2'])}</td>"
        f"<td>{r['force_N']['mean']:.0f} [{r['force_N']['q05']:.0f}, {r['force_N']['q95']:.0f}]</td>"
        f"<td>{r['spread_N']['mean']:.0f} [{r['spread_N']['q05']:.0f}, {r['spread_N']['q95']:.0f}]</td></tr>"
        for p, r in result["at_x0"].items()
    )
    warn = "".join(f"<li class=warn>{html.escape(w)}</li>" for w in result["warnings"]) or "<li class=ok>converged</li>"
    page = f"""<!doctype html><html><head><meta charset="utf-8"><title>Surface model: {html.escape(fit.recordings.path)}</title>
<style>{CSS}</style></head><body>
<h1>Surface model over height and pressure</h1>
<p class=small>{html.escape(fit.recordings.path)}; orders {html.escape(result['orders_label'])};
valid for heights {result['valid_range']['height_m'][0] * 1e3:.0f}-{result['valid_range']['height_m'][1] * 1e3:.0f} mm and
pressures {result['valid_range']['pressure_bar'][0]:g}-{result['valid_range']['pressure_bar'][1]:g} bar (queries outside are refused).</p>
<p>One model for all tests: force = p<sub>u</sub> F<sub>p</sub>(x, p<sub>u</sub>) + E(x), with the pressure area F<sub>p</sub> growing smoothly with
pressure and E the casing's own force; the volume shares F<sub>p</sub> and adds an excess D(x, p<sub>u</sub>)
(D = 0 and E = 0 is the traditional theory). Bands are pointwise 90 % credible bands of the mean characteristic.</p>
<h2>Which describes the element better</h2>{comp_html}
<table><tr><th class=l>orders (F_p t x q / casing / D)</th><th>elpd_loo</th><th>difference</th><th>SE</th></tr>{sel}</table>
<h2>Pressure area F<sub>p</sub> = (P &minus; E)/p<sub>u</sub></h2>
<p>F<sub>p</sub> is the area on which the pressure acts once the casing's own force E is removed; it is not the paper's
effective area F<sub>eff</sub> = P/p<sub>u</sub> (eq. 1), which includes E: F<sub>eff</sub> = F<sub>p</sub> + E/p<sub>u</sub>. Both are given at x0.</p>
{imgs['surface_pressure_area.png']}
<table><tr><th>p<sub>u</sub>, bar</th><th>F<sub>p</sub>(x0), cm&sup2; [90 %]</th><th>F<sub>eff</sub> = P/p<sub>u</sub> at x0, cm&sup2; [90 %]</th><th>force at x0, N</th><th>traditional &minus; measured at x0, N</th></tr>{x0}</table>
<h2>Where the traditional theory fails</h2>
<p>The spread p<sub>u</sub>(&minus;dV/dx) &minus; P between the traditional and the measured characteristic; the outlined region is where its
90 % band excludes zero ({100 * result['spread_credibly_nonzero_fraction']:.0f} % of the tested range).</p>{imgs['surface_spread.png']}
<h2>Each test against the surface</h2>{imgs['surface_residuals.png']}
<h2>Noise and sampler</h2><table><tr><th class=l>parameter</th><th>mean</th><th>q05</th><th>q95</th></tr>{noise_rows}</table>
<ul>{warn}</ul></body></html>
"""
    return write_text_atomic(out / "surface.html", page)
