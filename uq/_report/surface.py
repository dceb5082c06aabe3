"""The page of the surface model (``uq surface --report DIR``, ``uq report --surface``).

It opens with which model the recordings prefer, the surface or the per-pressure cubics, and
what that means for the reader (:func:`preference`), with the PSIS-LOO comparison as a table;
then heat maps of the pressure area F_p(x, p_u) and of the spread traditional - measured with the
region where its 90 % band excludes zero outlined, every test's readings against the surface
model's band (as residuals from the surface's mean curve, where the differences are visible), the
noise posterior under words and the sampler's diagnostics. One self-contained page (figures
embedded, the same PNG or SVG files beside it), written atomically; the page is the template
``templates/surface.html``. The comparison, the noise table and the residual figure serve the
thermodynamic model's page too (:mod:`uq._report.thermo`).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from uq._inference.summary import band
from uq._models.surface import SurfaceFit, spread_region
from uq._report.html import pyplot
from uq._report.model_page import figure_residual_overlay, write_page


def figure_pressure_area(fit: SurfaceFit, n_x: int = 46, n_p: int = 41):
    """Heat map of the posterior-mean pressure area F_p(x, p_u) with the 90 % band's relative width."""
    plt = pyplot()
    lo, hi = fit.height_range_m
    plo, phi = fit.pressure_range_bar
    xs, ps = np.linspace(lo, hi, n_x), np.linspace(plo, phi, n_p)
    X, P = np.meshgrid(xs, ps, indexing="ij")
    m, lo_b, hi_b = band(fit.on_draws(2000).pressure_area_draws(X, P), axis=0)
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
    plt = pyplot()
    reg = spread_region(fit, n_x, n_p)
    xs, ps = reg["height_m"] * 1e3, reg["pressure_bar"]
    fig, ax = plt.subplots(figsize=(6.4, 4.6))
    vmax = float(np.max(np.abs(reg["mean"])))
    im = ax.pcolormesh(xs, ps, reg["mean"].T, shading="auto", cmap="RdBu_r", vmin=-vmax, vmax=vmax)
    out = reg["credibly_nonzero"]
    if out.any() and not out.all():
        ax.contour(xs, ps, out.T.astype(float), levels=[0.5], colors="k", linewidths=1.5)
    fig.colorbar(im, ax=ax, label="p_u (-dV/dx) - P, N (posterior mean)")
    ax.set_xlabel("height x, mm")
    ax.set_ylabel("overpressure p_u, bar")
    share = 100 * out.mean()
    ax.set_title(
        f"Traditional minus measured force\noutlined: 90 % band excludes 0 ({share:.0f} % of the range)",
        fontsize=9,
    )
    fig.tight_layout()
    return fig


# ----------------------------------------------------------------------------- the page


def write_surface_report(
    fit: SurfaceFit, result: dict, out_dir, *, figure_format: str = "png"
) -> Path:
    """``out_dir/surface.html`` (the template ``surface.html``) and its three figures (PNG or
    SVG, ``figure_format``), from the fit and its :func:`uq._models.surface.summary` ``result``;
    returns the page's path."""

    def figures():
        figs = {
            "surface_pressure_area": (
                figure_pressure_area(fit),
                "pressure area F_p(x, p_u) heat map",
            ),
            "surface_residuals": (
                figure_residual_overlay(fit),
                "readings against the surface band",
            ),
        }
        if not fit.force_only:  # the spread needs the volume
            figs["surface_spread"] = (figure_spread(fit), "spread traditional minus measured")
        return figs

    return write_page(
        "surface.html",
        "surface.html",
        fit,
        result,
        out_dir,
        figure_format,
        figures,
        volume_omitted=fit.omitted_reason,
    )
