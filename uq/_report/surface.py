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
from uq._io.files import write_bytes_atomic, write_text_atomic
from uq._models.surface import SurfaceFit, spread_region, volume_omitted_reason
from uq._report.html import Figure, _plt, check_format, encode, render, stamp_unconverged


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


def figure_residual_overlay(fit, model: str = "surface"):
    """Readings minus the model's mean force, with its 90 % band, one panel per test (``fit``: a
    surface or thermodynamic fit; ``model`` names it in the legend)."""
    plt = _plt()
    tests = fit.recordings.tests
    n = len(tests)
    cols = min(4, n)
    rows = int(np.ceil(n / cols))
    fig, axes = plt.subplots(
        rows, cols, figsize=(3.2 * cols, 2.4 * rows + 0.5), squeeze=False, layout="constrained"
    )
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
            label=f"{model} 90 % band",
        )
        ax.axhline(0, color="k", lw=0.6)
        comp = t.compression
        if comp is None:  # one pass in unknown order (a catalogue table)
            ax.plot(t.height_m * 1e3, t.force_N - at_pts, ".", ms=3, color="k", label="readings")
        else:
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
    handles, labels = axes.flat[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside upper center", ncol=3, fontsize=7, frameon=False)
    fig.supxlabel("height x, mm", fontsize=9)
    fig.supylabel(f"reading - {model} mean force, N", fontsize=9)
    return fig


# ----------------------------------------------------------------------------- shared with the
# thermodynamic model's page

#: The noise parameters of the models over all tests under the words the pages use:
#: JSON name -> (words, what it is, unit, factor from SI to the unit).
NOISE_WORDS = {
    "s0_N": ("floor", "the force error that does not grow with the force", "N", 1.0),
    "rel_load": ("load cell", "the load cell's error, a share of the force", "%", 100.0),
    "k_p": (
        "pressure holding",
        "the pressure-holding error, as a multiple of the stand's stated one",
        "×",
        1.0,
    ),
    "sL_m": ("piston floor", "the piston reading's error", "mm", 1e3),
    "V0_m3": (
        "gas volume",
        "element, receiver and pipe: what a pressure error compresses, moving the piston",
        "L",
        1e3,
    ),
}


def noise_rows(noise: dict) -> list[dict]:
    """The noise table: one row per parameter of ``noise`` (name -> estimate), in words and units."""
    rows = []
    for name, est in noise.items():
        words, what, unit, f = NOISE_WORDS[name]
        rows.append(
            {
                "words": words,
                "what": what,
                "unit": unit,
                "mean": est["mean"] * f,
                "q05": est["q05"] * f,
                "q95": est["q95"] * f,
                "r_hat": est.get("r_hat"),
            }
        )
    return rows


#: what a model over all tests is, in words, by its short name (the comparison's key)
MODEL_WORDS = {"surface": "the surface model", "thermodynamic": "the thermodynamic model"}


def preference(comparison: dict | None, name: str) -> dict:
    """Which model the recordings prefer, the one named ``name`` ("surface" or "thermodynamic",
    the key of the :func:`uq._derived.comparison.compare` document) or the per-pressure cubics,
    and what that means for the reader: {"prefers": "model" | "cubics" | "neither" | "no
    verdict" | "not compared", "headline", "meaning", "css"}."""
    what = MODEL_WORDS[name]
    if not comparison:
        return {
            "prefers": "not compared",
            "headline": f"Not compared with the per-pressure cubics (--no-compare): nothing on this "
            f"page says whether {what} or the cubics describe the recordings better.",
            "meaning": "Run without --no-compare to know which description to use.",
            "css": "note",
        }
    d, se, better = comparison["elpd_diff"], comparison["elpd_diff_se"], comparison["better"]
    n_model, n_cubics = comparison[name]["n_coefficients"], comparison["cubics"]["n_coefficients"]
    diff = f"ELPD difference {d:+.1f} ± {se:.1f}, {what} minus the cubics"
    if better == "per-pressure cubics":
        return {
            "prefers": "cubics",
            "headline": f"The recordings prefer the per-pressure cubics to {what}: the cubics "
            f"predict left-out readings better ({diff}).",
            "meaning": f"At the tested pressures, read force and volume from the cubics (the main "
            f"report, eqs. 8 and 9). {what.capitalize()} is smoother over pressure than these "
            "recordings allow: the figures below show its trend over height and pressure, but its "
            "bands are too narrow where it misses the readings (see each test against the model), "
            "and its values between the tested pressures rest on a description the data rank "
            "lower." + _physics_note(name, "cubics"),
            "css": "warn",
        }
    if better == name:
        return {
            "prefers": "model",
            "headline": f"The recordings prefer {what} to the per-pressure cubics: it predicts "
            f"left-out readings better ({diff}), with {n_model} coefficients against "
            f"{n_cubics}.",
            "meaning": f"One smooth description over height and pressure fits these recordings "
            f"better than an independent cubic per test: use its curves and bands, also between "
            "the tested pressures within its valid range. Where the cubics of the main report "
            f"differ from it, {what} is the better description of these recordings."
            + _physics_note(name, "model"),
            "css": "ok",
        }
    if better == "indistinguishable":
        return {
            "prefers": "neither",
            "headline": f"The recordings prefer neither: {what} and the per-pressure cubics "
            f"predict left-out readings equally well ({diff}, within the rule).",
            "meaning": f"At the tested pressures either may be read; {what} also answers between "
            f"them (within its valid range) with {n_model} coefficients against the cubics' "
            f"{n_cubics}. Where the two differ, the difference is part of the uncertainty.",
            "css": "note",
        }
    return {
        "prefers": "no verdict",
        "headline": f"No verdict: the comparison of {what} with the per-pressure cubics is not "
        f"reliable for these recordings ({comparison['reason']}).",
        "meaning": "Some readings weigh so much in a fit that leaving them out cannot be estimated "
        "from it. Read both models; where they disagree, the disagreement is part of the "
        "uncertainty. The cubics of the main report are the paper's method and assume no "
        "smoothness over pressure.",
        "css": "warn",
    }


def _physics_note(name: str, prefers: str) -> str:
    if name != "thermodynamic":
        return ""
    if prefers == "cubics":
        return (
            " The thermodynamic model ties force and volume through one potential (the Maxwell "
            "relation dP/dp_u = dV/dx); recordings that break it (relaxation, hysteresis: the "
            "Maxwell table of uq diagnose) or need higher orders (--select) are fitted better "
            "by the cubics, which tie nothing."
        )
    return (
        " The force and the volume obey one potential (the Maxwell relation dP/dp_u = dV/dx) "
        "to within the noise, as a casing that stores energy elastically does."
    )


def comparison_rows(comparison: dict, name: str) -> list[dict]:
    """The comparison table: one row per model (ELPD-LOO, SE, effective parameters,
    coefficients, Pareto k)."""
    return [
        {"model": label, **comparison[key]}
        for key, label in ((name, MODEL_WORDS[name]), ("cubics", "the per-pressure cubics"))
    ]


def unconverged_words(result: dict, name: str) -> str:
    """ "" when the model's sampler passed its convergence rules, else which fit failed, in words
    (for the page's banner and the figures' stamps)."""
    return "" if result["converged"] else f"{MODEL_WORDS[name]}'s sampler"


def write_figures(figs: dict, out: Path, figure_format: str, unconverged: str = "") -> dict:
    """Encode ``figs`` (stem -> (matplotlib figure, alt text)) as ``figure_format``, write each
    beside the page; returns stem -> :class:`Figure`. ``unconverged``: which fit failed its
    convergence rules, in words; every figure is then stamped NOT CONVERGED."""
    figures = {}
    for stem, (fig, alt) in figs.items():
        if unconverged:
            stamp_unconverged(fig, unconverged)
        name = f"{stem}.{figure_format}"
        figures[stem] = Figure(name, encode(fig, figure_format), alt)
        write_bytes_atomic(out / name, figures[stem].data)
    return figures


# ----------------------------------------------------------------------------- the page


def write_surface_report(
    fit: SurfaceFit, result: dict, out_dir, *, figure_format: str = "png"
) -> Path:
    """``out_dir/surface.html`` (the template ``surface.html``) and its three figures (PNG or
    SVG, ``figure_format``), from the fit and its :func:`uq._models.surface.summary` ``result``;
    returns the page's path."""
    check_format(figure_format)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    figs = {
        "surface_pressure_area": (
            figure_pressure_area(fit),
            "pressure area F_p(x, p_u) heat map",
        ),
        "surface_residuals": (figure_residual_overlay(fit), "readings against the surface band"),
    }
    if not fit.force_only:  # the spread needs the volume
        figs["surface_spread"] = (figure_spread(fit), "spread traditional minus measured")
    figures = write_figures(figs, out, figure_format, unconverged_words(result, "surface"))
    comp = result.get("comparison")
    page = render(
        "surface.html",
        path=fit.recordings.path,
        result=result,
        comparison=comp,
        rows=comparison_rows(comp, "surface") if comp else [],
        preference=preference(comp, "surface"),
        order_selection=result.get("order_selection") or [],
        noise=noise_rows(result["noise"]),
        figures=figures,
        volume_omitted=volume_omitted_reason(fit.recordings),
        not_converged=unconverged_words(result, "surface"),
    )
    return write_text_atomic(out / "surface.html", page)
