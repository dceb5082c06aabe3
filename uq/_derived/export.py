"""Tables of a fit for the tools engineers use (issue 30): the coefficient table of ``uq fit --csv``
and the characteristic on a grid of heights and pressures in every format of ``uq export``.

Every table is written in the units asked for (:class:`uq._data.units.OutputUnits`): the
contract's, or the units the recordings came in (``--units input``).
"""

from __future__ import annotations

import datetime
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from uq._data.reference import FORCE_NAMES, PISTON_NAMES
from uq._data.units import OutputUnits
from uq._derived.design import DesignGrid, check_design, sealed_draws
from uq._io import matlab, teimorbit
from uq._io.errors import InputError
from uq._io.files import dumps_json, write_bytes_atomic, write_text_atomic
from uq._io.tables import csv_text, xlsx_bytes
from uq._physics.quantities import BAR_PA

#: The coefficients' units of ``uq fit --json`` (SI, u = x - x0 in metres): ``--units si``.
JSON_UNITS = OutputUnits(height="m", piston="m")
COEFFICIENT_STATS = ("mean", "sd", "q05", "q50", "q95", "r_hat", "ess_bulk")


def coefficient_table(cf, units: OutputUnits = JSON_UNITS) -> tuple[list[str], list[list]]:
    """(header, rows) of ``uq fit --csv``: one row per test and coefficient of the cubics (eqs. 8,
    9), its posterior mean, sd, 5/50/95 % quantiles, R-hat and bulk ESS, in ``units`` against
    u = x - x0 in ``units.height`` (x0 in the last column). A force-only test has no piston rows.

    ``cf``: a fit of the per-pressure cubics (``uq.fit_campaign``).
    """
    rec = cf.recordings
    x0 = float(units.value("height", rec.x0_m))
    header = [
        units.column("pressure"),
        "block",
        "coefficient",
        "unit",
        *COEFFICIENT_STATS,
        f"x0_{units.height}",
    ]
    rows = []
    for t in cf.tests:
        p = float(units.value("pressure", t.pressure_bar))
        variables = t.convergence.variables
        for block, names in (("force", FORCE_NAMES), ("piston", PISTON_NAMES)):
            if block == "piston" and not t.has_piston:
                continue
            draws = t.flat(block)  # (S, 4), SI
            for k, name in enumerate(names):
                scale, unit = units.coefficient(block, k)
                d = draws[:, k] * scale
                v = variables.get(name, {})
                stats = [d.mean(), d.std(ddof=1), *np.quantile(d, (0.05, 0.5, 0.95))]
                stats += [v.get("r_hat", np.nan), v.get("ess_bulk", np.nan)]  # COEFFICIENT_STATS
                rows.append([p, block, name, unit, *map(float, stats), x0])
    return header, rows


# ----------------------------------------------------------------------------- the grid of estimates

#: Gauss-Legendre nodes for the volume increment: exact for a dV/dx polynomial in x of degree <= 15.
N_LEGENDRE = 8
DEFAULT_QUANTILES = (0.05, 0.5, 0.95)
DEFAULT_DRAWS = 4000
#: draws x grid values evaluated at once (the heights are taken in chunks): about 100 MB
MAX_VALUES = 12_000_000


def quantile_name(q: float) -> str:
    """``q05`` for 0.05, ``q50``, ``q95`` (the contract's names); ``q2.5`` for 0.025.

    >>> [quantile_name(q) for q in (0.05, 0.5, 0.95, 0.025, 0.999)]
    ['q05', 'q50', 'q95', 'q2.5', 'q99.9']
    """
    pct = round(100 * q, 6)
    return f"q{int(pct):02d}" if pct == int(pct) else f"q{pct:g}"


@dataclass(frozen=True)
class Quantity:
    """One exported quantity on the grid: its summaries ``stats`` ("mean", "sd" and each
    quantile's name -> (H, P) arrays) in the unit used inside (N, m^2, m^3, N/m; bar for
    pressures); ``kind`` its kind for OutputUnits ("force", "area", "volume", "stiffness",
    "pressure")."""

    key: str
    words: str
    kind: str
    stats: dict


@dataclass(frozen=True)
class ExportGrid:
    """Estimates on heights x pressures: each quantity's draws, and what answered.

    heights_m (H,), pressures_bar (P,); ``model_name``/``model_label``: the fitted model that
    answered (between tested pressures too); ``notes``: one line each, what was left out and why,
    what was extrapolated; ``provenance``: file, hash, model, uq version, date, seed.
    """

    heights_m: np.ndarray
    pressures_bar: np.ndarray
    quantities: tuple[Quantity, ...]
    quantiles: tuple[float, ...]
    model_name: str
    model_label: str
    notes: tuple[str, ...]
    provenance: dict
    n_draws: int = 0
    sealed: dict | None = None

    def stats(self, key: str) -> dict[str, np.ndarray]:
        """ "mean", "sd" and each quantile's name -> (H, P) arrays, in the unit used inside."""
        return next(q for q in self.quantities if q.key == key).stats


#: the quantiles every JSON estimate object carries whatever ``--quantiles`` asks (the contract's
#: ``{"mean", "sd", "q05", "q95"}``)
CONTRACT_QUANTILES = (0.05, 0.95)


def summarise(draws: np.ndarray, quantiles) -> dict[str, np.ndarray]:
    """Mean, sd and quantiles over the first axis (the draws): those asked, and the contract's
    q05 and q95 (the JSON's estimate objects carry them; the tables show only those asked)."""
    out = {"mean": draws.mean(axis=0), "sd": draws.std(axis=0, ddof=1)}
    every = sorted(set(quantiles) | set(CONTRACT_QUANTILES))
    qs = np.quantile(draws, every, axis=0)
    return out | {quantile_name(q): qs[i] for i, q in enumerate(every)}


def with_notes(grid: ExportGrid, notes) -> ExportGrid:
    """``grid`` with ``notes`` (one line each) before its own: every format carries them."""
    return replace(grid, notes=(*notes, *grid.notes)) if notes else grid


def parse_heights_mm(text: str) -> np.ndarray:
    """``65,80,100`` or ``A:B:STEP`` (A to B inclusive) -> heights in mm, ascending, distinct.
    ValueError with one line on a bad list.

    >>> parse_heights_mm("70:80:2.5").tolist()
    [70.0, 72.5, 75.0, 77.5, 80.0]
    """
    text = text.strip()
    if ":" in text:
        parts = text.split(":")
        if len(parts) != 3:
            raise ValueError(f"'{text}': expected A:B:STEP (e.g. 65:155:5) or a list 65,80,100")
        a, b, step = (_float(p, text) for p in parts)
        if not step > 0 or not b >= a:
            raise ValueError(f"'{text}': expected A <= B and a positive STEP")
        n = int(np.floor((b - a) / step + 1e-9))
        if n > 10000:
            raise ValueError(f"'{text}': {n + 1} heights; at most 10001")
        values = a + step * np.arange(n + 1)
        values = np.round(values, 9)
    else:
        values = np.array([_float(p, text) for p in text.split(",") if p.strip()])
    if values.size == 0:
        raise ValueError(f"'{text}': no heights")
    if not np.all(values > 0):
        raise ValueError(f"'{text}': heights must be positive (mm)")
    if np.unique(values).size != values.size:
        raise ValueError(f"'{text}': a height is listed twice")
    return np.sort(values)


def parse_pressures_bar(text: str) -> np.ndarray:
    """``1,2.5,4`` -> pressures in bar, ascending, distinct, positive."""
    values = np.array([_float(p, text) for p in text.split(",") if p.strip()])
    if values.size == 0 or not np.all(values > 0):
        raise ValueError(f"'{text}': expected positive overpressures in bar, e.g. 1,2.5,4")
    if np.unique(values).size != values.size:
        raise ValueError(f"'{text}': a pressure is listed twice")
    return np.sort(values)


def parse_quantiles(text: str) -> tuple[float, ...]:
    """``0.05,0.5,0.95`` -> the quantiles, ascending, each strictly between 0 and 1."""
    values = sorted({_float(p, text) for p in text.split(",") if p.strip()})
    if not values or not all(0 < v < 1 for v in values):
        raise ValueError(
            f"'{text}': expected quantiles strictly between 0 and 1, e.g. 0.05,0.5,0.95"
        )
    return tuple(values)


def _float(p: str, text: str) -> float:
    try:
        v = float(p)
    except ValueError:
        raise ValueError(f"'{text}': '{p.strip()}' is not a number") from None
    if not np.isfinite(v):
        raise ValueError(f"'{text}': '{p.strip()}' is not a finite number")
    return v


def default_heights_m(model) -> np.ndarray:
    """Every tested height (the recordings'), or 5 mm steps over the tested range, both ends
    included, when the model came without recordings (a saved model)."""
    rec = getattr(model, "recordings", None)
    if rec is not None:
        return np.unique(np.round(np.concatenate([t.height_m for t in rec.tests]), 9))
    lo, hi = model.height_range_m
    return np.round(np.append(np.arange(lo, hi - 1e-9, 0.005), hi), 9)


def _check_grid(
    model, heights_m: np.ndarray, pressures_bar: np.ndarray, extrapolate: bool
) -> list[str]:
    """Refuse, in one line, heights and pressures beyond what the recordings support; with
    ``extrapolate``, the notes saying which are beyond."""
    notes = []
    for param, values, (lo, hi), scale, unit, tail in (
        ("heights_m", heights_m, model.height_range_m, 1e3, "mm",
         "the model is continued there, no reading supports it"),
        ("pressures_bar", pressures_bar, model.pressure_range_bar, 1.0, "bar",
         "no test supports them"),
    ):  # fmt: skip
        what = param.split("_")[0]
        beyond = values[(values < lo - 1e-9) | (values > hi + 1e-9)] * scale
        span = f"{lo * scale:g}..{hi * scale:g} {unit}"
        if beyond.size and not extrapolate:
            raise InputError(
                f"{param}: {beyond[0]:g} {unit} is outside the tested {what} {span} the recordings "
                f"support; give {what} within them, or `extrapolate`",
                param=param,
            )
        if beyond.size:
            shown = ", ".join(f"{v:g}" for v in beyond)
            notes.append(
                f"extrapolated: {what} {shown} {unit} lie outside the tested {span}; {tail}"
            )
    return notes


def export_grid(
    model,
    heights_m=None,
    pressures_bar=None,
    *,
    quantiles=DEFAULT_QUANTILES,
    extrapolate: bool = False,
    n_draws: int = DEFAULT_DRAWS,
    provenance: dict | None = None,
) -> ExportGrid:
    """The characteristic of a fitted model (uq._models.fitted.FittedModel) on a grid, on its
    fixed draws (at most ``n_draws``, thinned evenly): the force P (mean curve, reading noise
    excluded), the effective area F_eff = P / p_u (eq. 1) and, where the model has volume, the
    volume-derived area dV/dx and the volume increment from the grid's highest height,
    V(x) - V(x_top) = integral of dV/dx (Gauss-Legendre, exact for the models' polynomials).

    ``heights_m`` default: every tested height; ``pressures_bar`` default: the tested pressures.
    Between tested pressures the model answers as it does every between-answer (its own
    interpolation, or its pressure dependence). Heights or pressures beyond the tested ranges are
    refused in one line (``param`` heights_m or pressures_bar) unless ``extrapolate``, which the
    notes then say.
    """
    model = model.on_draws(n_draws) if getattr(model, "n_draws", 0) > n_draws else model
    h = default_heights_m(model) if heights_m is None else np.asarray(heights_m, float).ravel()
    p = (
        np.asarray(model.tested_pressures_bar, float)
        if pressures_bar is None
        else np.asarray(pressures_bar, float).ravel()
    )
    notes = _check_grid(model, h, p, extrapolate)
    check = not extrapolate
    quantiles = tuple(float(q) for q in quantiles)
    words = {
        "force": (
            "force P of the element, mean curve (reading noise excluded), compression positive",
            "force",
        ),
        "feff": ("effective area F_eff = P / p_u (eq. 1)", "area"),
        "feff_volume": ("volume-derived effective area dV/dx (eq. 1's second form)", "area"),
        "volume_increment": (
            f"volume increment V(x) - V({h.max() * 1e3:g} mm) at the test's pressure",
            "volume",
        ),
    }
    keys = ["force", "feff"] + (["feff_volume", "volume_increment"] if model.has_volume else [])
    parts: dict[str, list] = {k: [] for k in keys}
    # heights in chunks, so that the draws held at once stay near MAX_VALUES whatever the grid
    per_height = model.n_draws * p.size * (N_LEGENDRE if model.has_volume else 1)
    step = max(1, MAX_VALUES // max(per_height, 1))
    for lo in range(0, h.size, step):
        hh = h[lo : lo + step]
        X, P = np.meshgrid(hh, p, indexing="ij")
        draws = {
            "force": model.force_draws(X, P, check=check),
            "feff": model.feff_draws(X, P, check=check),
        }
        if model.has_volume:
            draws["feff_volume"] = model.volume_area_draws(X, P, check=check)
            draws["volume_increment"] = _volume_increment(model, hh, p, float(h.max()), check)
        for k in keys:
            parts[k].append(summarise(np.asarray(draws[k], float), quantiles))
    quantities = [
        Quantity(
            k,
            *words[k],
            {stat: np.concatenate([part[stat] for part in parts[k]]) for stat in parts[k][0]},
        )
        for k in keys
    ]
    if not model.has_volume:
        why = model.omitted_reason or "the model has no volume-derived area"
        notes.append(
            why if why.startswith("volume results omitted") else f"volume results omitted: {why}"
        )
    return ExportGrid(
        heights_m=h,
        pressures_bar=p,
        quantities=tuple(quantities),
        quantiles=quantiles,
        model_name=model.name,
        model_label=model.label,
        notes=tuple(notes),
        provenance=dict(provenance or {}),
        n_draws=int(model.n_draws),
    )


def _volume_increment(model, h: np.ndarray, p: np.ndarray, top: float, check: bool) -> np.ndarray:
    """integral from ``top`` to each height of dV/dx, per draw: (S, H, P), m^3."""
    t, w = np.polynomial.legendre.leggauss(N_LEGENDRE)
    # nodes between top and each height: (H, K)
    half = 0.5 * (h - top)
    nodes = top + half[:, None] * (t[None, :] + 1.0)
    X = np.broadcast_to(nodes[:, None, :], (h.size, p.size, t.size))
    P = np.broadcast_to(p[None, :, None], X.shape)
    area = np.asarray(model.volume_area_draws(X, P, check=check), float)  # (S, H, P, K)
    return np.einsum("shpk,k->shp", area, w) * half[None, :, None]


# ----------------------------------------------------------------------------- the formats

FORMATS = ("csv", "xlsx", "simscape", "teimorbit", "json")
#: The export table's units when the contract's are asked (``--units si``): bar, mm, N, m^2, L.
CONTRACT_UNITS = OutputUnits()


def _stem(q: Quantity, units: OutputUnits) -> str:
    return f"{q.key}_{units.suffix(q.kind)}"


def _stat_order(grid: ExportGrid) -> list[str]:
    return ["mean", *(quantile_name(q) for q in grid.quantiles)]


def table_columns(
    grid: ExportGrid, units: OutputUnits = CONTRACT_UNITS
) -> list[tuple[str, str, str]]:
    """(column, quantity key, stat) of the CSV table after its pressure and height columns.

    The contract's columns come first and in its order (docs/formats.md, ``uq export
    --format csv``): force mean and quantiles, F_eff mean and quantiles but the median; then the
    rest (sds, F_eff's median, the volume quantities).
    """
    first, rest = [], []
    median = quantile_name(0.5)
    for q in grid.quantities:
        stem = _stem(q, units)
        for stat in _stat_order(grid):
            col = (f"{stem}_{stat}", q.key, stat)
            if q.key == "force" or (q.key == "feff" and stat != median):
                first.append(col)
            else:
                rest.append(col)
        rest.append((f"{stem}_sd", q.key, "sd"))
    # the sds of force and F_eff first among the rest, in the quantities' order
    rest.sort(key=lambda c: [q.key for q in grid.quantities].index(c[1]))
    return first + rest


def csv_rows(grid: ExportGrid, units: OutputUnits = CONTRACT_UNITS) -> tuple[list[str], list[list]]:
    """The table: one row per (pressure, height), pressures in order, heights ascending."""
    cols = table_columns(grid, units)
    header = [units.column("pressure"), units.column("height"), *(c for c, _, _ in cols)]
    stats = {q.key: grid.stats(q.key) for q in grid.quantities}
    kinds = {q.key: q.kind for q in grid.quantities}
    rows = []
    for j, p in enumerate(grid.pressures_bar):
        for i, h in enumerate(grid.heights_m):
            row = [float(units.value("pressure", p)), float(units.value("height", h))]
            row += [float(units.value(kinds[key], stats[key][stat][i, j])) for _, key, stat in cols]
            rows.append(row)
    return header, rows


def provenance_rows(grid: ExportGrid, units: OutputUnits, fmt: str) -> list[tuple[str, str]]:
    """What every format says about where its numbers came from, as (key, value) pairs."""
    p = grid.provenance
    rows = [
        ("made by", f"uq export --format {fmt} (airspring-uq {p.get('uq_version', '?')})"),
        ("date", str(p.get("date", ""))),
        ("recordings", str(p.get("recordings_path", ""))),
        ("recordings sha256", str(p.get("recordings_sha256", ""))),
        ("model", f"{grid.model_label} ({grid.model_name})"),
        ("between tested pressures", p.get("between", f"the {grid.model_name} model answers")),
        ("seed", str(p.get("seed", ""))),
        ("draws", str(grid.n_draws)),
        ("quantiles", ", ".join(f"{q:g}" for q in grid.quantiles)),
        (
            "units",
            f"pressure {units.shown('pressure')} (gauge), height {units.shown('height')}, force "
            f"{units.shown('force')}, area {units.shown('area')}, volume {units.shown('volume')}",
        ),
        (
            "what",
            "posterior of the element's mean force (reading noise excluded) and effective areas; "
            "mean, sd and quantiles over the posterior draws",
        ),
    ]
    if p.get("source"):
        rows.append(("loaded from", str(p["source"])))
    rows += [("note", n) for n in grid.notes]
    return rows


def xlsx_sheets(
    grid: ExportGrid, units: OutputUnits = CONTRACT_UNITS
) -> list[tuple[str, list[list]]]:
    """The catalogue's wide shape: a sheet per quantity and statistic, heights down, pressures
    across; a last sheet ``provenance``."""
    sheets = []
    hcol, pcol = units.column("height"), units.column("pressure")
    heights = [float(units.value("height", h)) for h in grid.heights_m]
    pressures = [float(units.value("pressure", p)) for p in grid.pressures_bar]
    for q in grid.quantities:
        stats = grid.stats(q.key)
        stem = _stem(q, units)
        for stat in [*_stat_order(grid), "sd"]:
            values = units.value(q.kind, stats[stat])
            rows = [[f"{hcol} \\ {pcol}", *pressures]]
            rows += [[h, *map(float, values[i])] for i, h in enumerate(heights)]
            sheets.append((f"{stem} {stat}"[:31], rows))
    sheets.append(
        ("provenance", [["key", "value"], *map(list, provenance_rows(grid, units, "xlsx"))])
    )
    return sheets


def json_document(grid: ExportGrid) -> dict:
    """The grid with the contract's estimate objects (SI: m, N, m^2, m^3; pressures in bar)."""
    si = {"force": "N", "area": "m2", "volume": "m3", "stiffness": "N_per_m", "pressure": "bar"}
    stats = {q.key: grid.stats(q.key) for q in grid.quantities}
    points = []
    for j, p in enumerate(grid.pressures_bar):
        for i, h in enumerate(grid.heights_m):
            point = {"pressure_bar": float(p), "height_m": float(h)}
            for q in grid.quantities:
                s = stats[q.key]
                point[f"{q.key}_{si[q.kind]}"] = {k: float(v[i, j]) for k, v in s.items()}
            points.append(point)
    doc = {
        "model": {"name": grid.model_name, "label": grid.model_label},
        "heights_m": grid.heights_m,
        "pressures_bar": grid.pressures_bar,
        "quantiles": list(grid.quantiles),
        "quantities": {f"{q.key}_{si[q.kind]}": q.words for q in grid.quantities},
        "notes": list(grid.notes),
        "provenance": grid.provenance,
        "grid": points,
    }
    if grid.sealed is not None:
        doc["sealed"] = grid.sealed["json"]
    return doc


#: how the Simscape block relates its stiffness vector to the load (the sealed.stiffness fields)
RELATION = ": load ./ height, the block's relation"


def simscape_fields(grid: ExportGrid, units: OutputUnits) -> list[tuple[str, object, str]]:
    """The struct ``airspring`` for the Simscape Air Spring block: ``height`` (the block's Height
    vector), ``pressure``, and per statistic ``load.<stat>`` (heights x pressures: column k is the
    Load vector at pressure k), ``feff.<stat>``; with a sealed spring, ``sealed.*`` for the
    stiffness parameterisation."""
    h = units.shown("height")
    fields = [
        ("height", units.value("height", grid.heights_m), f"Height vector ({h})"),
        (
            "pressure",
            units.value("pressure", grid.pressures_bar),
            f"gauge overpressure of each column ({units.shown('pressure')})",
        ),
    ]
    for key, name, kind in (("force", "load", "force"), ("feff", "feff", "area")):
        stats = grid.stats(key)
        for stat in [*_stat_order(grid), "sd"]:
            fields.append(
                (
                    f"{name}.{stat}",
                    units.value(kind, stats[stat]),
                    f"{'Load vector' if name == 'load' else 'effective area'} ({units.shown(kind)}), "
                    f"{stat}; column k at pressure(k)",
                )
            )
    if grid.sealed is not None:
        s = grid.sealed
        fields.append(
            ("sealed.height", units.value("height", s["heights_m"]), f"Height vector ({h})")
        )
        for key, name, kind, words, note in (
            ("force", "load", "force", "Load vector", ""),
            ("stiffness", "stiffness", "stiffness", "Stiffness vector", RELATION),
            ("rate", "rate", "stiffness", "vertical rate -dP/dx", ""),
        ):
            for stat, values in s[key].items():
                value, unit = units.value(kind, values), units.shown(kind)
                fields.append((f"sealed.{name}.{stat}", value, f"{words} ({unit}), {stat}{note}"))
    fields += [
        ("source", str(grid.provenance.get("recordings_path", "")), ""),
        ("sha256", str(grid.provenance.get("recordings_sha256", "")), ""),
        ("model", f"{grid.model_label} ({grid.model_name})", ""),
        ("made_by", f"uq export (airspring-uq {grid.provenance.get('uq_version', '?')})", ""),
        ("notes", " | ".join(grid.notes), "what was left out, extrapolated or not measured"),
    ]
    return fields


def simscape_comments(grid: ExportGrid, units: OutputUnits) -> list[str]:
    h, f = units.shown("height"), units.shown("force")
    out = [
        "Air spring characteristic for the Simscape Air Spring block (Simscape > Driveline > Couplings & Drives)",
        "with posterior quantiles, so nominal and worst-case simulations run side by side.",
        "Parameterization 'Load as a function of height': Height vector = airspring.height "
        f"(unit {h}), Load vector = airspring.load.q50(:, k) (unit {f}) for the k-th pressure of",
        "airspring.pressure; use airspring.load.q05 / .q95 for the bounds. These are isobaric curves",
        "(force at a held overpressure), the pressure characteristic tables the block's documentation",
        "says manufacturers provide; for the closed spring's own curve export with --sealed.",
    ]
    if grid.sealed is not None:
        out += [
            "Parameterization 'Stiffness as a function of height' (the closed spring, --sealed):",
            "Height vector = airspring.sealed.height, Stiffness vector = airspring.sealed.stiffness.q50;",
            "the block's force is the element-wise product of Stiffness vector and Height vector, so the",
            "stiffness written is load ./ height; airspring.sealed.rate is the vertical rate -dP/dx.",
        ]
    out += [f"{k}: {v}" for k, v in provenance_rows(grid, units, "simscape")]
    return out


def teimorbit_files(grid: ExportGrid, units: OutputUnits) -> list[tuple[str, str]]:
    """(statistic, file text) of the TeimOrbit air-spring property files, one per statistic
    (mean and each quantile): ``[MDI_HEADER]``, ``[UNITS]`` (the table's length and force units),
    ``[AIRSPRING]`` with the sub-block ``(Z_DATA)``, the static pressure of each curve in the
    file's force per length squared, and ``(XY_DATA)``, the height then one force column per
    pressure (Altair MotionView, "TeimOrbit File for AirSpring"). With a sealed spring the files
    are the closed spring's curve instead (``sealed_<stat>``), its Z_DATA the charge pressure at
    the design height."""
    s = grid.sealed
    if s is None:
        force, kind = grid.stats("force"), "isobaric"
        heights, pressures, prefix = grid.heights_m, grid.pressures_bar, ""
    else:
        force = {stat: np.asarray(v)[:, None] for stat, v in s["force"].items()}
        heights, pressures, prefix = s["heights_m"], np.array([s["charge_bar"]]), "sealed_"
        kind = "sealed"
    return [
        (prefix + stat, _teimorbit_text(grid, units, heights, pressures, force[stat], stat, kind))
        for stat in _stat_order(grid)
    ]


def _teimorbit_text(grid, units, heights_m, pressures_bar, forces_N, stat: str, kind: str) -> str:
    length_m = units.factor("height")  # metres per file length unit
    force_N = units.factor("force")  # newtons per file force unit
    per_area = force_N / length_m**2  # Pa per file pressure unit (force / length^2)
    z = [[float(p * BAR_PA / per_area)] for p in pressures_bar]
    forces = np.asarray(forces_N, float) / force_N
    rows = [[float(h / length_m), *map(float, forces[i])] for i, h in enumerate(heights_m)]
    labels = ["height", *(f"force_{k + 1}" for k in range(len(pressures_bar)))]
    what = (
        f"the closed spring charged at {grid.sealed['charge_bar']:g} bar at {grid.sealed['design_height_m'] * 1e3:g} mm"
        if kind == "sealed"
        else f"force against height at {len(pressures_bar)} static pressures"
    )
    unit_words = f"{teimorbit.FORCE_UNITS[units.force]}/{teimorbit.LENGTH_UNITS[units.height]}^2"
    blocks = [
        teimorbit.header("airspring", [f"uq export: {what}, posterior {stat}"]),
        teimorbit.units(units.height, units.force),
        teimorbit.Block(
            "AIRSPRING",
            comments=[
                f"Z_DATA: gauge overpressure of each curve ({unit_words}); "
                "XY_DATA: spring height, then the force at each pressure"
            ],
            sub_blocks=[
                teimorbit.SubBlock("Z_DATA", labels=["pressure"], rows=z),
                teimorbit.SubBlock("XY_DATA", labels=labels, rows=rows),
            ],
        ),
    ]
    comments = [
        f"Air spring property file (TeimOrbit): {what}, posterior {stat} of the force",
        *(f"{k}: {v}" for k, v in provenance_rows(grid, units, "teimorbit")),
    ]
    return teimorbit.text(blocks, comments)


def sealed_export(grid: ExportGrid, model, design) -> ExportGrid:
    """``grid`` with the closed spring of ``design`` (uq._derived.design.SealedDesign: charged at
    its height to its pressure, closed, optionally with a reservoir; ``uq design``'s options): its
    force, the stiffness load/height the Simscape block's stiffness parameterisation takes, the
    vertical rate -dP/dx and the overpressure along the stroke, at ``uq design``'s heights (its grid
    of HEIGHT_STEP_M steps about the design height, on which the gas law is solved) within the
    export's height span, where every draw's sealed pressure stays within the tested pressures
    (the heights beyond are said in the notes: the model does not extrapolate there).
    """
    check_design(model, design)
    dgrid = DesignGrid(model, design.height_m)
    lo, hi = float(grid.heights_m.min()), float(grid.heights_m.max())
    h = dgrid.heights[(dgrid.heights >= lo - 1e-9) & (dgrid.heights <= hi + 1e-9)]
    if not lo - 1e-9 <= design.height_m <= hi + 1e-9:
        raise InputError(
            f"height_m: the design height {design.height_m * 1e3:g} mm lies outside the exported heights "
            f"{lo * 1e3:g}..{hi * 1e3:g} mm",
            param="height_m",
        )
    path, statement = sealed_draws(dgrid, design, heights_m=h)
    ok = path.in_range.all(axis=0)
    notes = list(grid.notes)
    if not ok.all():
        notes.append(
            f"sealed spring: heights {', '.join(f'{x * 1e3:g}' for x in h[~ok])} mm left out, where its "
            "pressure leaves the tested pressures in some draws"
        )
    h = h[ok]
    force, rate = path.force_N[:, ok], path.rate_N_per_m[:, ok]
    pressure = path.overpressure_pa[:, ok] / BAR_PA
    stiffness = force / h[None, :]

    def stats(d):  # the tables' statistics in their order (the JSON adds q05 and q95 below)
        out = summarise(d, grid.quantiles)
        return {k: out[k] for k in ("mean", *map(quantile_name, grid.quantiles), "sd")}

    def every(d):
        out = summarise(d, grid.quantiles)
        qs = sorted(set(out) - {"mean", "sd"}, key=lambda k: float(k[1:]))  # q05 -> 5
        return {k: out[k] for k in ("mean", "sd", *qs)}

    sealed = {
        "heights_m": h,
        "design_height_m": design.height_m,
        "charge_bar": design.charge_bar,
        "force": stats(force),
        "stiffness": stats(stiffness),
        "rate": stats(rate),
        "pressure_bar": stats(pressure),
        "assumptions": [statement, *_sealed_words(design)],
    }
    sealed["json"] = {
        "height_m": design.height_m,
        "charge_bar": design.charge_bar,
        "volume_l": design.volume_l,
        "polytropic": list(design.polytropic_range),
        "reservoir_l": design.reservoir_l,
        "assumptions": sealed["assumptions"],
        "heights_m": h,
        "force_N": every(force),
        "stiffness_N_per_m": every(stiffness),
        "rate_N_per_m": every(rate),
        "pressure_bar": every(pressure),
    }
    return replace(grid, sealed=sealed, notes=tuple(notes))


def _sealed_words(design) -> list[str]:
    lo, hi = design.polytropic_range
    n = f"n = {lo:g}" if lo == hi else f"n uniform in {lo:g}..{hi:g}"
    return [
        f"closed at {design.height_m * 1e3:g} mm charged to {design.charge_bar:g} bar with "
        f"{design.volume_l:g} L inside (sd {design.volume_sd_l:g} L), reservoir {design.reservoir_l:g} L, "
        f"polytropic {n}",
        "stiffness = load / height (the Simscape block's relation); rate = -dP/dx along the stroke",
    ]


def sealed_rows(
    grid: ExportGrid, units: OutputUnits = CONTRACT_UNITS
) -> tuple[list[str], list[list]]:
    """The closed spring's table: one row per height, its force, stiffness (load/height), rate
    (-dP/dx) and overpressure, each mean, quantiles and sd."""
    s = grid.sealed
    parts = (
        ("force", "force", s["force"]),
        ("stiffness", "stiffness", s["stiffness"]),
        ("rate", "stiffness", s["rate"]),
        ("pressure", "pressure", s["pressure_bar"]),
    )
    header = [units.column("height")]
    for key, kind, stats in parts:
        header += [f"sealed_{key}_{units.suffix(kind)}_{stat}" for stat in stats]
    rows = []
    for i, h in enumerate(s["heights_m"]):
        row = [float(units.value("height", h))]
        for _, kind, stats in parts:
            row += [float(units.value(kind, v[i])) for v in stats.values()]
        rows.append(row)
    return header, rows


def _beside(out: Path, tag: str) -> Path:
    return out.with_name(f"{out.stem}_{tag}{out.suffix}")


def write(
    grid: ExportGrid, fmt: str, out, units: OutputUnits = CONTRACT_UNITS, when=None
) -> list[Path]:
    """Write ``grid`` as ``fmt`` (one of FORMATS) to ``out``, every file atomically; the paths
    written. teimorbit: one file per statistic, ``out`` with ``_mean``, ``_q05``, ... (and
    ``_sealed_...``) before its suffix; csv: the provenance (key, value) in ``out`` with
    ``_provenance`` (the table itself keeps the contract's header as its first line), with a
    sealed spring its table in ``out`` with ``_sealed``; simscape: a MAT-file when ``out`` ends in ``.mat``, else a MATLAB script.
    ``when``: the provenance's date ("YYYY-MM-DD HH:MM UTC"), a workbook's created time."""
    if fmt not in FORMATS:
        raise InputError(f"format: one of {', '.join(FORMATS)}, got {fmt!r}", param="format")
    out = Path(out)
    if fmt == "csv":  # the table as the contract has it (header first); provenance beside it
        paths = [write_text_atomic(out, csv_text(*csv_rows(grid, units)))]
        if grid.sealed is not None:
            paths.append(
                write_text_atomic(_beside(out, "sealed"), csv_text(*sealed_rows(grid, units)))
            )
        rows = [list(r) for r in provenance_rows(grid, units, "csv")]
        paths.append(
            write_text_atomic(_beside(out, "provenance"), csv_text(["key", "value"], rows))
        )
        return paths
    if fmt == "xlsx":
        sheets = xlsx_sheets(grid, units)
        if grid.sealed is not None:
            header, rows = sealed_rows(grid, units)
            sheets.insert(-1, ("sealed", [header, *rows]))
        stamp = datetime.datetime.strptime(str(when), "%Y-%m-%d %H:%M UTC") if when else None
        return [write_bytes_atomic(out, xlsx_bytes(sheets, when=stamp))]
    if fmt == "json":
        return [write_text_atomic(out, dumps_json(json_document(grid)))]
    if fmt == "simscape":
        fields = simscape_fields(grid, units)
        if out.suffix.lower() == ".mat":
            return [write_bytes_atomic(out, matlab.mat_bytes("airspring", fields))]
        return [
            write_text_atomic(
                out, matlab.script("airspring", fields, simscape_comments(grid, units))
            )
        ]
    return [
        write_text_atomic(_beside(out, stat), text) for stat, text in teimorbit_files(grid, units)
    ]
