"""HTML section of the surface model (``uq surface --report DIR``).

Heat maps of the pressure area F_p(x, p_u) and of the spread traditional - measured with the region where
its 90 % band excludes zero outlined, every test's readings against the surface model's
band (as residuals from the surface's mean curve, where the differences are visible), the
PSIS-LOO comparison with the per-pressure cubics, the noise posterior and the sampler's
diagnostics. One self-contained page (PNG files beside it), written atomically; the page is the
template ``templates/surface.html``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from uq._derived.comparison import words as comparison_words
from uq._inference.summary import band
from uq._io.files import write_bytes_atomic, write_text_atomic
from uq._models.surface import SurfaceFit, spread_region
from uq._report.html import Figure, _plt, _png, render


def figure_pressure_area(fit: SurfaceFit, n_x: int = 46, n_p: int = 41):
    """Heat map of the posterior-mean pressure area F_p(x, p_u) with the 90 % band's relative width."""
    plt = _plt()
    lo, hi = fit.height_range_m
    plo, phi = fit.pressure_range_bar
    xs, ps = np.linspace(lo, hi, n_x), np.linspace(plo, phi, n_p)
    X, P = np.meshgrid(xs, ps, indexing="ij")
    m, lo_b, hi_b = band(fit.pressure_area_draws(X, P, beta=fit.flat_beta(2000)), axis=0)
    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    im = ax.pcolormesh(xs * 1e3, ps, (m * 1e4).T, shading="auto", cmap="viridis")
    cs = ax.contour(xs * 1e3, ps, (100 * (hi_b - lo_b) / np.abs(m)).T, colors="w", linewidths=0.8)
    ax.clabel(cs, fmt="%.2g %%", fontsize=7)
    fig.colorbar(im, ax=ax, label="F_p posterior mean, cm^2")
    ax.set_xlabel("height x, mm")
    ax.set_ylabel("overpressure p_u, bar")
    ax.set_title(
        "Pressure area F_p = (P - E)/p_u (casing force removed; not the paper's F_eff = P/p_u)\n"
        "(white contours: pointwise 90 % band width, % of F_p)",
        fontsize=8,
    )
    for t in fit.recordings.tests:
        ax.axhline(t.pressure_bar, color="k", lw=0.3, alpha=0.4)
    fig.tight_layout()
    return fig


def figure_spread(fit: SurfaceFit, n_x: int = 46, n_p: int = 41):
    """Heat map of the spread traditional - experimental, the credibly non-zero region outlined."""
    plt = _plt()
    reg = spread_region(fit, n_x, n_p)
    xs, ps = reg["height_m"] * 1e3, reg["pressure_bar"]
    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    vmax = float(np.max(np.abs(reg["mean"])))
    im = ax.pcolormesh(xs, ps, reg["mean"].T, shading="auto", cmap="RdBu_r", vmin=-vmax, vmax=vmax)
    if reg["credibly_nonzero"].any() and not reg["credibly_nonzero"].all():
        ax.contour(
            xs,
            ps,
            reg["credibly_nonzero"].T.astype(float),
            levels=[0.5],
            colors="k",
            linewidths=1.5,
        )
    fig.colorbar(im, ax=ax, label="p_u (-dV/dx) - P, N (posterior mean)")
    ax.set_xlabel("height x, mm")
    ax.set_ylabel("overpressure p_u, bar")
    share = 100 * reg["credibly_nonzero"].mean()
    ax.set_title(
        f"Traditional minus measured force\noutlined: 90 % band excludes 0 ({share:.0f} % of the range)",
        fontsize=9,
    )
    fig.tight_layout()
    return fig


def figure_overlay(fit: SurfaceFit, pressure_bar: float, ax=None):
    """One test's force readings with the surface model's 90 % band at that pressure."""
    plt = _plt()
    t = fit.recordings.test_at(pressure_bar)
    lo, hi = fit.height_range_m
    xs = np.linspace(lo, hi, 120)
    m, lo_b, hi_b = band(fit.force_draws(xs, pressure_bar, beta=fit.flat_beta(2000)), axis=0)
    fig = None
    if ax is None:
        fig, ax = plt.subplots(figsize=(6.0, 4.0))
    ax.fill_between(xs * 1e3, lo_b, hi_b, alpha=0.35, label="surface model 90 % band")
    ax.plot(xs * 1e3, m, lw=1)
    ax.plot(t.height_m * 1e3, t.force_N, "k.", ms=3, label="readings")
    ax.set_xlabel("height x, mm")
    ax.set_ylabel("force P, N")
    ax.set_title(f"{pressure_bar:g} bar")
    ax.legend(fontsize=7)
    return fig if fig is not None else ax.figure


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
        ax.fill_between(
            xs * 1e3,
            lo_b - m,
            hi_b - m,
            alpha=0.35,
            color="tab:blue",
            lw=0,
            label="surface 90 % band",
        )
        ax.axhline(0, color="k", lw=0.6)
        comp = t.compression
        ax.plot(
            t.height_m[comp] * 1e3,
            (t.force_N - at_pts)[comp],
            ".",
            ms=3,
            color="tab:red",
            label="compression",
        )
        ax.plot(
            t.height_m[~comp] * 1e3,
            (t.force_N - at_pts)[~comp],
            "x",
            ms=3,
            color="tab:green",
            label="rebound",
        )
        ax.set_title(f"{t.pressure_bar:g} bar", fontsize=9)
        ax.tick_params(labelsize=7)
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=6)
    fig.supxlabel("height x, mm", fontsize=9)
    fig.supylabel("reading - surface mean force, N", fontsize=9)
    fig.tight_layout()
    return fig


def write_surface_report(
    fit: SurfaceFit, result: dict, out_dir, *, figure_format: str = "png"
) -> Path:
    """``out_dir/surface.html`` (the template ``surface.html``) and its three PNG figures, from the
    fit and its :func:`uq._models.surface.summary` ``result``; returns the page's path."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    figs = {
        "surface_pressure_area.png": (
            figure_pressure_area(fit),
            "pressure area F_p(x, p_u) heat map",
        ),
        "surface_spread.png": (figure_spread(fit), "spread traditional minus measured"),
        "surface_residuals.png": (
            figure_residual_overlay(fit),
            "readings against the surface band",
        ),
    }
    figures = {}
    for name, (fig, alt) in figs.items():
        figures[name] = Figure(name, _png(fig), alt)
        write_bytes_atomic(out / name, figures[name].png)
    comp = result.get("comparison")
    page = render(
        "surface.html",
        path=fit.recordings.path,
        result=result,
        comparison=comp,
        verdict=comparison_words(comp) if comp else None,
        order_selection=result.get("order_selection") or [],
        figures=figures,
    )
    return write_text_atomic(out / "surface.html", page)
