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

from uq._inference.summary import band
from uq._io.files import write_bytes_atomic, write_text_atomic
from uq._models.surface import SurfaceFit, comparison_words, figure_pressure_area, figure_spread
from uq._report.html import Figure, _plt, _png, render


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


def write_surface_report(fit: SurfaceFit, result: dict, out_dir) -> Path:
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
