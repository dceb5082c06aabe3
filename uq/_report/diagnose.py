"""``uq diagnose --report DIR``: the discrepancy diagnosis as a page (``diagnose.html``) with its
residual plots (``diagnose_residuals.png``, or ``.svg``), from a :func:`uq._diagnose.engine.diagnose`
result.

The page says first whether the traditional theory explains the recordings; then the mechanisms
found, as a table with their magnitude and 90 % interval, what each means and, for one
confounded with a stand constant, the other reading of the same numbers; the mechanisms that
were tried and dropped, and those not offered with why (what the campaign lacks); the traditional
and the final model side by side with the noise check; the Maxwell table (dV/dx against dP/dp_u,
test by test and height band, with what its pattern is and is not consistent with); the residual
figure; the selection rule and the plain-text summary. The page uses the project's style sheet
(``templates/page.css``) and is the template ``templates/diagnose.html``; the figure is embedded
and written beside it; every write is atomic.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from uq._diagnose.engine import residuals_of, summary_text
from uq._io.files import write_bytes_atomic, write_text_atomic
from uq._report.html import Figure, check_format, encode, pyplot, render, stamp_unconverged

FIGURE = "diagnose_residuals"


def _residual_figure(res):
    """Force and volume residuals of the traditional and the final model, by height (force only
    for a campaign without volume readings)."""
    plt = pyplot()
    base, final, meta, d = res.baseline, res.final, res.meta, res.data
    quantities = (("force", 1.0, "N"), ("volume", 1e6, "cm³"))[: 1 + meta["has_volume"]]
    fig, axes = plt.subplots(
        len(quantities),
        2,
        figsize=(11, 3.5 * len(quantities) + 0.5),
        sharex=True,
        squeeze=False,
        layout="constrained",
    )
    cmap = plt.get_cmap("viridis")
    pmax = meta["pressure_bar"].max()
    for col, (fit, title) in enumerate(
        ((base, "traditional"), (final, " + ".join(["traditional", *final.names])))
    ):
        r = residuals_of(fit, meta, d)
        for row, (q, scale, unit) in enumerate(quantities):
            ax = axes[row, col]
            for pb in np.unique(meta["pressure_bar"]):
                for comp, mk in ((True, "v"), (False, "^")):
                    s = (meta["pressure_bar"] == pb) & (meta["compression"] == comp)
                    ax.plot(
                        meta["height_m"][s] * 1e3,
                        r[q][0][s] * scale,
                        mk,
                        ms=3,
                        color=cmap(0.9 * pb / pmax),
                        label=f"{pb:g} bar" if comp else None,
                    )
            ax.axhline(0, color="k", lw=0.6)
            ax.set_title(f"{q} residual, {title}", fontsize=9, wrap=True)
            ax.set_ylabel(f"{q} residual ({unit})")
            if row == len(quantities) - 1:
                ax.set_xlabel("height x (mm)")
    axes[0, 0].legend(fontsize=6, ncol=2, title="▼ compression, ▲ rebound", title_fontsize=6)
    return fig


def _mechanism_rows(doc: dict) -> list[dict]:
    """The mechanisms found, with the other reading of a confounded one in words and numbers."""
    rows = []
    for m in doc["mechanisms"]:
        row = dict(m)
        row["unit"] = "" if m["unit"] == "1" else m["unit"]  # a pure number: no unit shown
        other = m.get("other_reading")
        if other:
            extra = None
            if "piston_area_m2" in other:
                a = other["piston_area_m2"]
                extra = {
                    "what": "piston area",
                    "mean": a["mean"] * 1e4,
                    "q05": a["q05"] * 1e4,
                    "q95": a["q95"] * 1e4,
                    "given": other["given_piston_area_m2"] * 1e4,
                    "unit": "cm²",
                }
            pot = other.get("potential")
            row["other"] = {
                "words": other["words"],
                "value": extra,
                "assumes": other.get("assumes"),
                "potential": pot
                and {
                    "area": None
                    if pot["maxwell_piston_area_m2"] is None
                    else {
                        "mean": pot["maxwell_piston_area_m2"]["mean"] * 1e4,
                        "sd": pot["maxwell_piston_area_m2"]["sd"] * 1e4,
                    },
                    "assumes": pot["assumes"],
                    "command": pot["command"],
                },
            }
        else:
            row["other"] = None
        rows.append(row)
    return rows


def _maxwell_view(mx: dict | None) -> dict | None:
    """The Maxwell table as rows by pressure and columns by height band."""
    if not mx:
        return None
    bands = sorted({tuple(r["height_mm"]) for r in mx["rows"]})
    by_p: dict[float, dict] = {}
    for r in mx["rows"]:
        by_p.setdefault(r["pressure_bar"], {})[tuple(r["height_mm"])] = r
    return {
        "bands": bands,
        "rows": [
            {"pressure_bar": p, "cells": [cells.get(b) for b in bands]}
            for p, cells in sorted(by_p.items())
        ],
        "n_breaks": sum(r["breaks"] for r in mx["rows"]),
        "n_cells": len(mx["rows"]),
        "definition": mx["definition"],
        "rule": mx["rule"],
        "coefficients": mx.get("coefficients", ""),
        "words": mx["interpretation"]["words"],
        "shape_rule": mx.get("shape_rule", ""),
        "shapes": [
            {"name": SHAPE_WORDS[k], **v}
            for k, v in mx["interpretation"]["middle"].get("shapes", {}).items()
        ],
    }


#: the shapes of r over pressure the Maxwell check compares (uq._diagnose.maxwell.shapes)
SHAPE_WORDS = {
    "zero": "zero: the relation holds",
    "constant": "one value at every pressure: a piston-area error alone",
    "step": "a step between two tested pressures",
    "fade": "a fade: a straight line in p_u",
}


def write_diagnose_report(res, out_dir, *, figure_format: str = "png") -> Path:
    """``out_dir/diagnose.html`` and its residual figure ``diagnose_residuals.png`` (or ``.svg``,
    ``figure_format``) for the diagnosis ``res`` (a :class:`uq._diagnose.engine.Diagnosis`);
    returns the page's path."""
    check_format(figure_format)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    doc = res.document
    name = f"{FIGURE}.{figure_format}"
    warnings = (doc.get("sampling") or {}).get("warnings") or []
    fig = _residual_figure(res)
    if warnings:
        stamp_unconverged(fig, "the final model's sampler")
    figure = Figure(
        name,
        encode(fig, figure_format),
        "force and volume residuals of the traditional and the final model",
    )
    write_bytes_atomic(out / name, figure.data)
    sel = doc["selection"]
    found = {m["name"] for m in doc["mechanisms"]}
    page = render(
        "diagnose.html",
        doc=doc,
        mechanisms=_mechanism_rows(doc),
        dropped=[m for m in sel["offered"] if m not in found],
        not_offered=sorted(sel["not_offered"].items()),
        maxwell=_maxwell_view(doc.get("maxwell")),
        summary=summary_text(doc),
        figure=figure,
        sampling_warnings=warnings,
    )
    return write_text_atomic(out / "diagnose.html", page)
