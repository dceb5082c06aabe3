"""The page of the thermodynamic model (``uq surface --model thermodynamic --report DIR``).

The model (:mod:`uq._models.thermo`) derives force and volume from one potential G(x, p_u):
P = -dG/dx, V = -dG/dp_u, so the Maxwell relation dP/dp_u = dV/dx holds by construction. The
page opens with which description the recordings prefer, this model or the per-pressure cubics,
and what that means (:func:`uq._report.surface.preference`, the PSIS-LOO table); then, test by
test, the force readings against the model's band (as residuals, where the differences are
visible) and the effective area two ways, F_eff = P/p_u from the force and dV/dx from the volume;
the Maxwell ratio (dV/dx)/(P/p_u) over height and pressure as a heat map (1 in the traditional
theory; where its 90 % band excludes 1 outlined); the piston area the recordings imply, with its
interval, against the one given; the noise under words. One self-contained page
(``thermodynamic.html``, figures embedded and the same PNG or SVG files beside it), written
atomically; the template is ``templates/thermodynamic.html``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from uq._inference.summary import band
from uq._models.registry import CUBICS
from uq._models.thermo import ThermoFit
from uq._physics.quantities import BAR_PA
from uq._report.html import check_format, pyplot
from uq._report.model_page import figure_residual_overlay, panels_by_test, write_page

PAGE = "thermodynamic.html"
#: what the preference means for a model that ties force and volume through one potential
PHYSICS_NOTES = {
    CUBICS: " The thermodynamic model ties force and volume through one potential (the Maxwell "
    "relation dP/dp_u = dV/dx); recordings that break it (relaxation, hysteresis: the Maxwell "
    "table of uq diagnose) or need higher orders (--select) are fitted better by the cubics, "
    "which tie nothing.",
    "model": " The force and the volume obey one potential (the Maxwell relation dP/dp_u = dV/dx) "
    "to within the noise, as a casing that stores energy elastically does.",
}
N_DRAWS = 1000  # posterior draws behind each band


def _grid(fit: ThermoFit, n: int):
    lo, hi = fit.height_range_m
    return np.linspace(lo, hi, n)


def figure_areas(fit: ThermoFit):
    """Per test: the effective area from the force, F_eff = P/p_u (eq. 1), and from the volume,
    dV/dx (eq. 1, second formula), with their 90 % bands, and the readings' P/p_u."""
    tests = fit.recordings.tests
    fig, axes = panels_by_test(len(tests), 2.5, 0.6)
    some = fit.on_draws(N_DRAWS)
    xs = _grid(fit, 80)
    for ax, t in zip(axes.flat, tests, strict=False):
        p = t.pressure_bar
        for fn, colour, label in (
            (some.feff_draws, "tab:green", "P / p_u (force)"),
            (some.volume_area_draws, "tab:red", "dV/dx (volume)"),
        ):
            m, lo, hi = band(fn(xs, p), axis=0)
            ax.fill_between(xs * 1e3, lo * 1e4, hi * 1e4, color=colour, alpha=0.35, lw=0)
            ax.plot(xs * 1e3, m * 1e4, color=colour, lw=1, label=label)
        ax.plot(
            t.height_m * 1e3, t.force_N / (p * BAR_PA) * 1e4, "k.", ms=2.5, label="readings P / p_u"
        )
        ax.set_title(f"{p:g} bar", fontsize=9)
        ax.tick_params(labelsize=7)
        ax.grid(alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("height x, mm", fontsize=8)
    legend = axes.flat[0].get_legend_handles_labels()
    fig.legend(*legend, loc="outside lower center", ncol=3, fontsize=7, frameon=False)
    fig.supylabel("effective area, cm²", fontsize=9)
    fig.suptitle(
        "Effective area two ways, 90 % bands: equal in the traditional theory", fontsize=10
    )
    return fig


def maxwell_region(fit: ThermoFit, n_x: int = 46, n_p: int = 41) -> dict:
    """The Maxwell ratio (dV/dx)/(P/p_u) on a grid over the tested ranges: posterior mean, 90 %
    band, and where the band excludes 1 (the traditional theory's value)."""
    xs = _grid(fit, n_x)
    plo, phi = fit.pressure_range_bar
    ps = np.linspace(plo, phi, n_p)
    X, P = np.meshgrid(xs, ps, indexing="ij")
    m, lo, hi = band(fit.on_draws(N_DRAWS).maxwell_ratio_draws(X, P), axis=0)
    return {
        "height_m": xs,
        "pressure_bar": ps,
        "mean": m,
        "q05": lo,
        "q95": hi,
        "excludes_one": (lo > 1.0) | (hi < 1.0),
    }


def figure_maxwell(fit: ThermoFit, region: dict | None = None):
    """Heat map of the Maxwell ratio over height and pressure, centred on 1, the region where its
    90 % band excludes 1 outlined; the colour scale is clipped at the 98th percentile of |r - 1|
    (P/p_u near zero, at low pressure and full height, makes the ratio run away there)."""
    plt = pyplot()
    reg = region or maxwell_region(fit)
    xs, ps, m = reg["height_m"] * 1e3, reg["pressure_bar"], reg["mean"]
    fig, ax = plt.subplots(figsize=(7.2, 4.8), layout="constrained")
    finite = np.isfinite(m)
    span = float(np.quantile(np.abs(m[finite] - 1.0), 0.98)) if finite.any() else 0.1
    span = max(span, 1e-3)
    im = ax.pcolormesh(xs, ps, m.T, shading="auto", cmap="RdBu_r", vmin=1.0 - span, vmax=1.0 + span)
    out = reg["excludes_one"]
    if out.any() and not out.all():
        ax.contour(xs, ps, out.T.astype(float), levels=[0.5], colors="k", linewidths=1.5)
    bar = fig.colorbar(im, ax=ax, extend="both")
    bar.set_label("(dV/dx) / (P/p_u), posterior mean")
    for t in fit.recordings.tests:
        ax.axhline(t.pressure_bar, color="k", lw=0.3, alpha=0.4)
    ax.set_xlabel("height x, mm")
    ax.set_ylabel("overpressure p_u, bar")
    share = 100 * out.mean()
    ax.set_title(
        "Maxwell ratio: volume-derived over force-derived area (1: traditional theory)\n"
        f"outlined: 90 % band excludes 1 ({share:.0f} % of the range); thin lines: tested pressures",
        fontsize=9,
    )
    return fig


def figure_piston_area(fit: ThermoFit):
    """The posterior of the piston area the recordings imply, S / (1 + m), against the given S."""
    plt = pyplot()
    draws = fit.piston_area_draws() * 1e4
    given = fit.geometry.area_m2 * 1e4
    q05, q95 = np.quantile(draws, [0.05, 0.95])
    fig, ax = plt.subplots(figsize=(6.4, 3.2), layout="constrained")
    ax.hist(draws, bins=50, color="tab:blue", alpha=0.6, density=True, label="posterior")
    ax.axvspan(q05, q95, color="tab:blue", alpha=0.12, lw=0, label="90 % interval")
    ax.axvline(given, color="k", lw=1.2, ls="--", label=f"given S = {given:.2f} cm²")
    ax.set_xlabel("piston area, cm²")
    ax.set_ylabel("posterior density")
    ax.set_title("Piston area the recordings imply, S / (1 + m)", fontsize=9)
    ax.legend(fontsize=7)
    return fig


def piston_words(implied: dict, given_m2: float) -> dict:
    """The implied piston area against the given one, in words for the page."""
    mean, lo, hi = (implied[k] * 1e4 for k in ("mean", "q05", "q95"))
    given = given_m2 * 1e4
    off = 100 * (mean / given - 1.0)
    inside = lo <= given <= hi
    if inside:
        words = (
            f"The given S = {given:.2f} cm² lies inside the 90 % interval: the recordings agree "
            "with the stand's piston area."
        )
    else:
        words = (
            f"The given S = {given:.2f} cm² lies outside the 90 % interval: read through the "
            f"Maxwell relation, the recordings' volumes are those of a piston {off:+.1f} % off "
            "the given area. Check S (eq. 5); if S is right, the volume does not follow the "
            "force as one potential says (see the Maxwell ratio above and uq diagnose)."
        )
    return {"mean": mean, "q05": lo, "q95": hi, "given": given, "inside": inside, "words": words}


def write_thermo_report(
    fit: ThermoFit, result: dict, out_dir, *, figure_format: str = "png"
) -> Path:
    """``out_dir/thermodynamic.html`` (the template ``thermodynamic.html``) and its four figures
    (PNG or SVG, ``figure_format``), from the fit and its :meth:`ThermoFit.to_json` ``result``;
    returns the page's path."""
    check_format(figure_format)  # before the Maxwell ratio's grid is computed
    region = maxwell_region(fit)
    return write_page(
        PAGE,
        PAGE,
        fit,
        result,
        out_dir,
        figure_format,
        lambda: {
            "thermo_force": (
                figure_residual_overlay(fit),
                "force readings against the thermodynamic model's band, by test",
            ),
            "thermo_areas": (figure_areas(fit), "effective area from the force and the volume"),
            "thermo_maxwell": (figure_maxwell(fit, region), "Maxwell ratio heat map"),
            "thermo_piston_area": (figure_piston_area(fit), "implied piston area"),
        },
        notes=PHYSICS_NOTES,
        maxwell_share=float(region["excludes_one"].mean()),
        piston=piston_words(result["implied_piston_area_m2"], result["piston_area_m2"]),
    )
