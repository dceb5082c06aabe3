"""The page of any fitted model over all tests, and what the models' pages share.

:func:`write_model_page` writes a model's page, dispatching on the fit's class
(``functools.singledispatch``): the surface and the thermodynamic model have pages of their own
(:mod:`uq._report.surface`, :mod:`uq._report.thermo`; registered in :mod:`uq._report.pages`);
any other :class:`uq._models.fitted.FittedModel` of a campaign gets the generic page
``<name>.html`` (the template ``model.html``): which description the recordings prefer, this model
or the per-pressure cubics (:func:`preference`, the PSIS-LOO table), each test's force readings
against the model's band, and the sampled parameters with the sampler's verdict. A model plugged
in from outside registers a page of its own with ``write_model_page.register(ItsFitClass)``.
"""

from __future__ import annotations

import functools
from pathlib import Path

import numpy as np

from uq._inference.summary import band
from uq._io.files import write_bytes_atomic, write_text_atomic
from uq._models.registry import CUBICS
from uq._report.html import Figure, check_format, encode, pyplot, render, stamp_unconverged


def panels_by_test(n: int, panel_in: float, extra_in: float):
    """A figure of ``n`` panels, one per test, four to a row (constrained layout; the row's height
    ``panel_in``, plus ``extra_in`` inches), the panels after the n-th off: (figure, axes)."""
    cols = min(4, n)
    rows = -(-n // cols)
    fig, axes = pyplot().subplots(
        rows,
        cols,
        figsize=(3.2 * cols, panel_in * rows + extra_in),
        squeeze=False,
        layout="constrained",
    )
    for ax in list(axes.flat)[n:]:
        ax.axis("off")
    return fig, axes


def figure_residual_overlay(fit):
    """Readings minus the model's mean force, with its 90 % band, one panel per test (``fit``: any
    fitted model of the recordings, named in the legend by its name)."""
    tests = fit.recordings.tests
    fig, axes = panels_by_test(len(tests), 2.4, 0.5)
    some = fit.on_draws(1000)
    lo, hi = fit.height_range_m
    xs = np.linspace(lo, hi, 80)
    named = f"{fit.name} 90 % band"
    for ax, t in zip(axes.flat, tests, strict=False):
        m, lo_b, hi_b = band(some.force_draws(xs, t.pressure_bar), axis=0)
        r = t.force_N - some.force_draws(t.height_m, t.pressure_bar).mean(axis=0)
        ax.fill_between(
            xs * 1e3, lo_b - m, hi_b - m, alpha=0.35, color="tab:blue", lw=0, label=named
        )
        ax.axhline(0, color="k", lw=0.6)
        comp = t.compression
        if comp is None:  # one pass in unknown order (a catalogue table)
            ax.plot(t.height_m * 1e3, r, ".", ms=3, color="k", label="readings")
        else:
            for sel, mark, color, label in (
                (comp, ".", "tab:red", "compression"),
                (~comp, "x", "tab:green", "rebound"),
            ):
                ax.plot(t.height_m[sel] * 1e3, r[sel], mark, ms=3, color=color, label=label)
        ax.set_title(f"{t.pressure_bar:g} bar", fontsize=9)
        ax.tick_params(labelsize=7)
    legend = axes.flat[0].get_legend_handles_labels()
    fig.legend(*legend, loc="outside upper center", ncol=3, fontsize=7, frameon=False)
    fig.supxlabel("height x, mm", fontsize=9)
    fig.supylabel(f"reading - {fit.name} mean force, N", fontsize=9)
    return fig


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
    """The noise table: one row per parameter of ``noise`` (name -> estimate), in words and units
    (a parameter without words of its own under its name)."""
    rows = []
    for name, est in noise.items():
        words, what, unit, f = NOISE_WORDS.get(name, (name, "", "", 1.0))
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


def preference(comparison: dict | None, name: str, what: str, notes: dict | None = None) -> dict:
    """Which model the recordings prefer, the one named ``name`` (the key of the
    :func:`uq._derived.comparison.compare` document; ``what``: it in words, "the surface model")
    or the per-pressure cubics, and what that means for the reader: {"prefers": "model" |
    "cubics" | "neither" | "no verdict" | "not compared", "headline", "meaning", "css"}.
    ``notes``: a model's own sentence for when the cubics (key ``CUBICS``) or it ("model") is
    preferred."""
    notes = notes or {}
    if not comparison:
        return {
            "prefers": "not compared",
            "headline": f"Not compared with the per-pressure cubics (--no-compare): nothing on this "
            f"page says whether {what} or the cubics describe the recordings better.",
            "meaning": "Run without --no-compare to know which description to use.",
            "css": "note",
        }
    d, se, better = comparison["elpd_diff"], comparison["elpd_diff_se"], comparison["better"]
    n_model, n_cubics = comparison[name]["n_coefficients"], comparison[CUBICS]["n_coefficients"]
    diff = f"ELPD difference {d:+.1f} ± {se:.1f}, {what} minus the cubics"
    if better == "per-pressure cubics":
        return {
            "prefers": CUBICS,
            "headline": f"The recordings prefer the per-pressure cubics to {what}: the cubics "
            f"predict left-out readings better ({diff}).",
            "meaning": f"At the tested pressures, read force and volume from the cubics (the main "
            f"report, eqs. 8 and 9). {what.capitalize()} is smoother over pressure than these "
            "recordings allow: the figures below show its trend over height and pressure, but its "
            "bands are too narrow where it misses the readings (see each test against the model), "
            "and its values between the tested pressures rest on a description the data rank "
            "lower." + notes.get(CUBICS, ""),
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
            + notes.get("model", ""),
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


def comparison_rows(comparison: dict, name: str, what: str) -> list[dict]:
    """The comparison table: one row per model (ELPD-LOO, SE, effective parameters,
    coefficients, Pareto k)."""
    return [
        {"model": label, **comparison[key]}
        for key, label in ((name, what), (CUBICS, "the per-pressure cubics"))
    ]


def unconverged_words(result: dict, what: str) -> str:
    """ "" when the model's sampler passed its convergence rules, else which fit failed, in words
    (``what``: the model in words, ``fit.words``; for the page's banner and the figures' stamps)."""
    return "" if result.get("converged", True) else f"{what}'s sampler"


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


# ----------------------------------------------------------------------------- the generic page


@functools.singledispatch
def write_model_page(fit, result: dict, out_dir, *, figure_format: str = "png") -> Path:
    """``out_dir/<name>.html`` and its figure (PNG or SVG, ``figure_format``) for any fitted model
    of a campaign, from the fit and its ``to_json`` document ``result`` (module docstring);
    returns the page's path."""
    what = fit.words
    return write_page(
        "model.html",
        f"{fit.name}.html",
        fit,
        result,
        out_dir,
        figure_format,
        lambda: {
            f"{fit.name}_force": (figure_residual_overlay(fit), f"readings against {what}'s band")
        },
        label=fit.label,
        what=what,
        name=fit.name,
    )


def write_page(
    template, page, fit, result, out_dir, figure_format, figures, *, notes=None, **extra
) -> Path:
    """``out_dir/page`` from ``template`` with what every model's page shows (the comparison
    with the cubics and the preference, with the model's own ``notes``; the order selection; the
    noise table; the convergence banner) and ``extra``; ``figures()`` (stem -> (figure, alt
    text)) written beside it as ``figure_format`` and given to the template as ``figures``."""
    check_format(figure_format)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    unconverged = unconverged_words(result, fit.words)
    comp = result.get("comparison")
    html = render(
        template,
        path=fit.recordings.path,
        result=result,
        comparison=comp,
        rows=comparison_rows(comp, fit.name, fit.words) if comp else [],
        preference=preference(comp, fit.name, fit.words, notes),
        order_selection=result.get("order_selection") or [],
        noise=noise_rows(result.get("noise") or {}),
        figures=write_figures(figures(), out, figure_format, unconverged),
        not_converged=unconverged,
        **extra,
    )
    return write_text_atomic(out / page, html)
