"""The data sheet of a sealed spring (``uq design --out DIR``): rendering only, from the document
``uq design --json`` writes (:func:`uq._derived.design.design_document` plus the isobaric table)
and the sealed curves of the chart's charge pressures.

What a catalogue prints, each value as posterior mean and 90 % interval: the isobaric load at the
tested pressures and chosen heights, the volume increment and the effective area; at the design
height, per charge pressure, the sealed load, rate and natural frequency; figures of the sealed
load-deflection curves with their bands and of the natural frequency against the load (the
catalogue's most read chart). Every assumption (the volume, how it changes with pressure, the
polytropic exponent) is stated on the page. A force-only campaign gets the isobaric loads and the
line saying why the rest is omitted.

Written whole or not at all (:func:`uq._io.files.staged_folder`): ``design.html`` (figures
embedded), ``design.csv`` (every table, long format), ``design.json`` (the document) and the
figures beside them. The template is ``templates/design.html``.
"""

from __future__ import annotations

import csv
import io
from pathlib import Path

import numpy as np

from uq._derived.comparison import cubics_then_compare, words
from uq._derived.model_check import words as check_words
from uq._io.files import dumps_json, remove_stale, staged_folder
from uq._report.html import Figure, check_format, encode, pyplot, render, stamp_unconverged

PAGE = "design.html"
#: the files the sheet writes, by pattern (for pruning what an earlier run left)
OUTPUTS = ("design_*.png", "design_*.svg", PAGE, "design.csv", "design.json")


#: the figures' margins, inches (left, right, bottom, top) and the gap between two panels: fixed,
#: room for a title, axis labels and five-digit tick labels (a layout pass, matplotlib's
#: constrained layout, drew every figure twice for margins that come out about the same)
MARGINS_IN = (0.8, 0.2, 0.55, 0.35)
GAP_IN = 0.85


def _subplots(ncols: int, size_in: tuple[float, float]):
    """A figure of ``ncols`` panels side by side with the sheet's fixed margins."""
    w, h = size_in
    left, right, bottom, top = MARGINS_IN
    fig, axes = pyplot().subplots(1, ncols, figsize=size_in)
    panel = (w - left - right - (ncols - 1) * GAP_IN) / ncols
    fig.subplots_adjust(
        left=left / w,
        right=1 - right / w,
        bottom=bottom / h,
        top=1 - top / h,
        wspace=GAP_IN / panel,
    )
    return fig, axes


def _colours(n: int):
    plt = pyplot()
    cmap = plt.get_cmap("viridis")
    return [cmap(0.85 * i / max(n - 1, 1)) for i in range(n)]


def _is_tested(doc: dict, p: float) -> bool:
    """Whether ``p`` (bar) is one of the tested pressures (``doc["tested_pressures_bar"]``)."""
    tested = doc.get("tested_pressures_bar")
    return tested is None or any(abs(p - t) < 1e-9 for t in tested)


def figure_sealed_curves(doc: dict, curves: dict):
    """The sealed load-deflection curves, one per charge pressure of the chart (charged at the
    design height), each with its 90 % band, and the design charge's own curve in black (dashed
    when the charge was not a tested pressure); the design height dotted."""
    fig, (ax, ax2) = _subplots(2, (11.0, 4.4))
    cols = _colours(len(curves))
    design = doc.get("sealed_curve")
    drawn = [
        (c, cv, f"{p:g} bar", 1.2, "-")
        for c, (p, cv) in zip(cols, sorted(curves.items()), strict=True)
    ]
    if design is not None:
        ls = "-" if _is_tested(doc, doc["charge_bar"]) else "--"
        drawn.append(("k", design, f"design: {doc['charge_bar']:g} bar", 2.0, ls))
    for c, cv, label, lw, ls in drawn:
        x = np.asarray(cv["height_m"]) * 1e3
        if x.size == 0:
            continue
        for a, key, scale in ((ax, "load_N", 1e-3), (ax2, "rate_N_per_m", 1e-3)):
            b = {k: np.asarray(cv[key][k]) * scale for k in ("mean", "q05", "q95")}
            a.fill_between(x, b["q05"], b["q95"], color=c, alpha=0.3 if c != "k" else 0.15, lw=0)
            a.plot(x, b["mean"], color=c, lw=lw, ls=ls, label=label)
    for a in (ax, ax2):
        a.axvline(doc["height_m"] * 1e3, color="k", ls=":", lw=1)
        a.set_xlabel("height x, mm")
        a.grid(alpha=0.3)
    ax.set_ylabel("sealed load, kN")
    ax2.set_ylabel("sealed vertical rate, kN/m")
    ax.set_title("Sealed load-deflection curves, 90 % bands", fontsize=10)
    ax2.set_title("Sealed rate along the stroke, 90 % bands", fontsize=10)
    ax.legend(title="charge", fontsize=7, title_fontsize=7, ncol=2)
    return fig


def _load_and_frequency(rows):
    """(load kN, natural frequency Hz) of the chart's rows, (n, 3) each: mean, q05, q95."""
    L = np.array([[r["load_N"][k] for k in ("mean", "q05", "q95")] for r in rows]) * 1e-3
    F = np.array([[r["natural_frequency_Hz"][k] for k in ("mean", "q05", "q95")] for r in rows])
    return L, F


def _with_intervals(ax, L, F, **style) -> None:
    """Points at the mean load and frequency with their 90 % intervals in both directions."""
    xerr = [L[:, 0] - L[:, 1], L[:, 2] - L[:, 0]]
    ax.errorbar(L[:, 0], F[:, 0], xerr=xerr, yerr=[F[:, 0] - F[:, 1], F[:, 2] - F[:, 0]], **style)


def figure_frequency_chart(doc: dict):
    """Natural frequency against load at the design height, one point per charge pressure with
    its 90 % intervals in both directions (the catalogue's chart)."""
    rows = doc["frequency_chart"]["rows"]
    fig, ax = _subplots(1, (7.2, 4.4))
    L, F = _load_and_frequency(rows)
    ax.fill_between(
        L[:, 0], F[:, 1], F[:, 2], color="tab:blue", alpha=0.25, lw=0, label="90 % interval"
    )
    _with_intervals(
        ax, L, F, fmt="o-", color="tab:blue", ms=4, lw=1, capsize=2, label="posterior mean"
    )
    for r, x, y in zip(rows, L[:, 0], F[:, 0], strict=True):
        ax.annotate(
            f"{r['charge_bar']:g} bar",
            (x, y),
            textcoords="offset points",
            xytext=(4, 5),
            fontsize=7,
        )
    d = design_row(doc)
    if d is not None:  # the design point itself, whether or not its charge is one of the chart's
        _with_intervals(
            ax,
            *_load_and_frequency([d]),
            fmt="*",
            color="tab:red",
            ms=12,
            capsize=3,
            zorder=5,
            label=f"design: {doc['charge_bar']:g} bar"
            + ("" if _is_tested(doc, doc["charge_bar"]) else " (not a tested pressure)"),
        )
    ax.set_xlabel("load carried at the design height, kN")
    ax.set_ylabel("natural frequency, Hz")
    ax.set_title(
        f"Natural frequency vs load at {doc['height_m'] * 1e3:g} mm (charged and closed there)",
        fontsize=10,
    )
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    return fig


def figure_isobaric(doc: dict):
    """The isobaric loads of the table against height, one line per pressure, 90 % bands."""
    rows = doc["isobaric"]
    ps = sorted({r["pressure_bar"] for r in rows})
    fig, ax = _subplots(1, (7.2, 4.4))
    for c, p in zip(_colours(len(ps)), ps, strict=True):
        rr = sorted((r for r in rows if r["pressure_bar"] == p), key=lambda r: r["height_m"])
        x = np.array([r["height_m"] for r in rr]) * 1e3
        m, lo, hi = (np.array([r["load_N"][k] for r in rr]) * 1e-3 for k in ("mean", "q05", "q95"))
        tested = _is_tested(doc, p)
        c = c if tested else "k"
        ax.fill_between(x, lo, hi, color=c, alpha=0.3 if tested else 0.15, lw=0)
        label = f"{p:g} bar" if tested else f"{p:g} bar: design charge, not tested"
        ax.plot(x, m, "o-" if tested else "o--", color=c, ms=2.5, lw=1, label=label)
    ax.axvline(doc["height_m"] * 1e3, color="k", ls=":", lw=1)
    ax.set_xlabel("height x, mm")
    ax.set_ylabel("isobaric load, kN")
    ax.set_title(
        "Isobaric load at the tested pressures"
        + ("" if all(_is_tested(doc, p) for p in ps) else " and the design charge")
        + ", 90 % bands",
        fontsize=10,
    )
    ax.legend(fontsize=6, ncol=2)
    ax.grid(alpha=0.3)
    return fig


def _est_row(prefix: dict, quantity: str, unit: str, e: dict | None, scale: float = 1.0) -> dict:
    row = dict(prefix, quantity=quantity, unit=unit)
    for k in ("mean", "sd", "q05", "q95"):
        row[k] = "" if e is None else f"{float(e[k]) * scale:.6g}"
    return row


CSV_COLUMNS = (
    "table",
    "pressure_bar",
    "height_mm",
    "charge_bar",
    "quantity",
    "unit",
    "mean",
    "sd",
    "q05",
    "q95",
)


def design_row(doc: dict) -> dict | None:
    """The design point as a row of the frequency chart (charge, load, rate, natural frequency),
    None for a campaign without the sealed outputs."""
    if doc.get("rate_N_per_m") is None:
        return None
    return {
        "charge_bar": doc["charge_bar"],
        "load_N": doc["load_N"],
        "rate_N_per_m": doc["rate_N_per_m"],
        "natural_frequency_Hz": doc["natural_frequency_Hz"],
        "design": True,
        "tested": _is_tested(doc, doc["charge_bar"]),
    }


def chart_rows(doc: dict) -> list[dict]:
    """The frequency chart's rows with the design point among them (marked ``design``; it
    replaces the chart's row at the same charge), by charge."""
    rows = [dict(r, design=False) for r in doc["frequency_chart"]["rows"]]
    d = design_row(doc)
    if d is not None:
        rows = [r for r in rows if abs(r["charge_bar"] - d["charge_bar"]) > 1e-9] + [d]
    return sorted(rows, key=lambda r: r["charge_bar"])


def _check(doc: dict) -> dict | None:
    """The answering model's posterior-predictive check at the tested points, for the sheet (None
    for a document written before the check existed)."""
    c = doc.get("model_check")
    if not c:
        return None
    return {"words": check_words(c), "misses": bool(c.get("misses"))}


def ranking(doc: dict) -> dict:
    """Which model answered and how the data rank it (PSIS-LOO against the per-pressure cubics),
    in words, for the sheet."""
    c = doc.get("comparison")
    if c is None:
        why = (
            "not ranked: the per-pressure cubics answer (no model over all tests was fitted)"
            if doc.get("rate_N_per_m") is None
            else "not ranked in this run (--no-compare)"
        )
        return {"model": doc["model"], "words": why, "better": None}
    return {
        "model": doc["model"],
        "words": words(c),
        "better": c.get("better"),
        "rule": c.get("rule"),
    }


def sheet_csv(doc: dict) -> str:
    """Every table of the sheet in one long CSV: one estimate a row (mean, sd, 5 % and 95 %).
    The design point has its own rows ("design_point"), and so does the isobaric column at a
    design charge that was not tested ("isobaric_design_charge")."""
    rows = []
    for r in doc["isobaric"]:
        pre = {
            "table": "isobaric" if _is_tested(doc, r["pressure_bar"]) else "isobaric_design_charge",
            "pressure_bar": f"{r['pressure_bar']:g}",
            "height_mm": f"{r['height_m'] * 1e3:g}",
        }
        rows.append(_est_row(pre, "load", "N", r["load_N"]))
        rows.append(_est_row(pre, "effective_area_P_over_p", "cm2", r["feff_m2"], 1e4))
        if "volume_area_m2" in r:
            rows.append(_est_row(pre, "volume_derived_area_dV_dx", "cm2", r["volume_area_m2"], 1e4))
            rows.append(
                _est_row(pre, "volume_increment_from_design_height", "L", r["volume_increment_l"])
            )
    h = f"{doc['height_m'] * 1e3:g}"
    pre = {"table": "design_point", "height_mm": h, "charge_bar": f"{doc['charge_bar']:g}"}
    rows.append(_est_row(pre, "load", "N", doc["load_N"]))
    if doc.get("rate_N_per_m") is not None:
        rows.append(_est_row(pre, "rate", "N/m", doc["rate_N_per_m"]))
        rows.append(_est_row(pre, "natural_frequency", "Hz", doc["natural_frequency_Hz"]))
        if "transmissibility" in doc:
            t = doc["transmissibility"]
            f = f"{t['forcing_Hz']:g}Hz"
            rows.append(_est_row(pre, f"transmissibility_at_{f}", "1", t["transmissibility"]))
            rows.append(_est_row(pre, f"isolation_at_{f}", "%", t["isolation_pct"]))
        for r in doc["frequency_chart"]["rows"]:
            pre = {
                "table": "sealed_at_design_height",
                "height_mm": h,
                "charge_bar": f"{r['charge_bar']:g}",
            }
            rows.append(_est_row(pre, "load", "N", r["load_N"]))
            rows.append(_est_row(pre, "rate", "N/m", r["rate_N_per_m"]))
            rows.append(_est_row(pre, "natural_frequency", "Hz", r["natural_frequency_Hz"]))
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=CSV_COLUMNS, lineterminator="\n", restval="")
    w.writeheader()
    w.writerows(rows)
    return buf.getvalue()


def _isobaric_matrix(doc: dict, key: str, scale: float):
    """(pressures bar, [(height mm, [estimate scaled per pressure])], [whether each pressure was
    tested]) of one isobaric quantity."""
    rows = doc["isobaric"]
    hs = sorted({r["height_m"] for r in rows})
    ps = sorted({r["pressure_bar"] for r in rows})
    cell = {(r["height_m"], r["pressure_bar"]): r.get(key) for r in rows}
    out = []
    for h in hs:
        line = []
        for p in ps:
            e = cell[(h, p)]
            line.append(
                None if e is None else {k: float(e[k]) * scale for k in ("mean", "q05", "q95")}
            )
        out.append((h * 1e3, line))
    return ps, out, [_is_tested(doc, p) for p in ps]


def design_figures(doc: dict, *, curves: dict | None = None, figure_format: str = "png") -> dict:
    """The sheet's figures, encoded ({stem: Figure}): they need the design's numbers and the
    sampler's verdict (``doc["source"]``), not the model comparison, so ``uq design`` draws them
    while the comparison is still running in its worker."""
    check_format(figure_format)
    sealed = doc.get("rate_N_per_m") is not None
    figs = {"design_isobaric": (figure_isobaric(doc), "isobaric load against height by pressure")}
    if sealed:
        if curves:
            figs["design_sealed"] = (
                figure_sealed_curves(doc, curves),
                "sealed load-deflection and rate curves with 90 % bands",
            )
        figs["design_frequency"] = (figure_frequency_chart(doc), "natural frequency against load")
    if not doc["source"]["converged"]:
        for fig, _ in figs.values():
            stamp_unconverged(fig, f"{doc['model']}'s sampler")
    return {
        stem: Figure(f"{stem}.{figure_format}", encode(fig, figure_format), alt)
        for stem, (fig, alt) in figs.items()
    }


def compare_then_draw(rec, asked, **kw):
    """``uq design --out``'s worker (:mod:`uq._derived.comparison_worker`):
    :func:`~uq._derived.comparison.cubics_then_compare`, then matplotlib imported (while the
    command's process still works out its design: earlier, it would take CPU from the model's
    fit), then the sheet's figures of what is sent next ((document, curves, figure format):
    :func:`design_figures`), drawn while the command writes the rest: (None, comparison,
    figures); the cubics are not sent back (the design does not use them)."""
    _, comparison = cubics_then_compare(rec, asked, **kw)
    pyplot()
    doc, curves, figure_format = asked.recv()
    return None, comparison, design_figures(doc, curves=curves, figure_format=figure_format)


def write_design_sheet(
    doc: dict,
    out_dir,
    *,
    curves: dict | None = None,
    reconstructed: bool = False,
    figure_format: str = "png",
    figures: dict | None = None,
) -> Path:
    """``out_dir/design.html`` with ``design.csv``, ``design.json`` and the figures (PNG or SVG;
    ``figures``: :func:`design_figures` of ``doc`` when drawn already), written together into a
    staged folder and moved in at the end; returns the page's path."""
    check_format(figure_format)
    out = Path(out_dir)
    sealed = doc.get("rate_N_per_m") is not None
    if figures is None:
        figures = design_figures(doc, curves=curves, figure_format=figure_format)
    tables = {
        key: _isobaric_matrix(doc, key, scale)
        for key, scale in (
            ("load_N", 1e-3),
            ("feff_m2", 1e4),
            ("volume_area_m2", 1e4),
            ("volume_increment_l", 1.0),
        )
        if key in doc["isobaric"][0]
    }
    page = render(
        PAGE,
        doc=doc,
        sealed=sealed,
        tables=tables,
        figures=figures,
        reconstructed=reconstructed,
        source=doc["source"],
        curve=doc.get("sealed_curve"),
        chart=chart_rows(doc) if sealed else [],
        ranking=ranking(doc),
        check=_check(doc),
        untested_charge=not _is_tested(doc, doc["charge_bar"]),
    )
    with staged_folder(out, last=(PAGE,)) as stage:
        for f in figures.values():
            (stage / f.name).write_bytes(f.data)
        (stage / "design.csv").write_text(sheet_csv(doc), encoding="utf-8")
        (stage / "design.json").write_text(dumps_json(doc), encoding="utf-8")
        (stage / PAGE).write_text(page, encoding="utf-8")
    remove_stale(
        out, OUTPUTS, keep={f.name for f in figures.values()} | {PAGE, "design.csv", "design.json"}
    )
    return out / PAGE
