"""The cells of a recordings file: which column is which quantity in which unit, and each
value parsed, converted (uq._data.units) and held against the ranges of an air spring.

A range error names the likely unit slip (kPa in a bar column, micrometres in a mm column) and
shows the value both in the file's unit and in the unit the range is stated in.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from uq._data import column_map as _column_map
from uq._data import units as _units
from uq._data.rows import DELIMITERS, Table
from uq._io.errors import InputError, where

BRANCHES = ("compression", "rebound")
#: The first comment of a recordings template ``uq plan --template`` writes: its empty force and
#: piston cells are readings still to be made, and the reader says so.
PLANNED_MARK = "uq plan template"

# ----------------------------------------------------------------------------- plausibility
# Ranges no air spring on a stand like the paper's leaves; wide on purpose, so other springs,
# pressures and stands pass, while the usual unit slips (mm x 1000, kN, kPa, m) do not.
MAX_PRESSURE_BAR = 60.0  # rubber-cord air springs burst far below; kPa for bar gives 100x
MAX_HEIGHT_MM = 5000.0  # also the upper end of --x0-mm; micrometres for mm give 1000x
MAX_ABS_FORCE_N = 1.0e8  # 100 MN, far above any air spring (10 bar on 3 m^2 is 3 MN)
MAX_ABS_PISTON_MM = 1.0e6
MAX_VOLUME_M3 = 10.0  # a 2.5 m bellows 1 m high holds about 5 m^3
#: Heights all below this (mm) are metres written in a mm column.
MIN_LARGEST_HEIGHT_MM = 2.0


def number(
    text, path: str, row: int, column: str, decimal_comma: bool = False, workbook: bool = False
) -> float:
    text = "" if text is None else str(text)
    shown = text.strip() or "(empty)"
    if "," in text and not decimal_comma:
        hint = (
            "a decimal comma in a text cell? enter it as a number"
            if workbook
            else "a decimal comma? in a comma-separated file write a decimal point"
        )
        raise InputError(f"{where(path, row, column)}: '{shown}' is not a number ({hint})")
    if decimal_comma:
        # in a file of decimal commas a point can only be a thousands separator or a slip
        if "." in text:
            raise InputError(
                f"{where(path, row, column)}: '{shown}' has a '.' in a file that writes decimal commas (a thousands separator?); write plain numbers"
            )
        text = text.replace(",", ".")
    try:
        value = float(text)
    except ValueError:
        raise InputError(f"{where(path, row, column)}: '{shown}' is not a number") from None
    if not math.isfinite(value):
        raise InputError(f"{where(path, row, column)}: '{shown}' is not a finite number")
    return value


def integer(text, path: str, row: int, column: str, decimal_comma: bool = False) -> int:
    value = number(text, path, row, column, decimal_comma)
    if value != int(value) or value < 0:
        raise InputError(
            f"{where(path, row, column)}: '{str(text).strip()}' is not a step number (0, 1, 2, ...)"
        )
    return int(value)


# ----------------------------------------------------------------------------- columns


@dataclass(frozen=True)
class Column:
    """One recordings column of the file: its quantity, header, position and unit."""

    quantity: str  # pressure, set_pressure, height, force, piston, volume, branch, step
    name: str
    index: int
    suffix: str | None = None  # the unit as the name writes it; None for branch and step
    factor: float = 1.0  # file unit -> bar (pressures) or SI

    @property
    def unit(self) -> str:
        return _units.shown(self.suffix or "")

    def shown(self, raw: float, si: float, si_unit: str, si_scale: float = 1.0) -> str:
        """``raw`` in the file's unit, with its value in ``si_unit`` when the units differ."""
        if self.unit == si_unit:
            return f"{raw:g} {self.unit}"
        return f"{raw:g} {self.unit} ({si * si_scale:g} {si_unit})"


def is_column(name: str) -> bool:
    """Whether a header name is a recordings column (used to choose the CSV delimiter)."""
    if name in ("branch", "step"):
        return True
    q = _units.split_name(name)
    return q is not None and _units.known(*q)


def column_test(mapping: dict | None):
    """:func:`is_column`, also true for the sources of a column map and for headers that name a
    quantity without a unit (``Pressure``: its unit comes from a units row): what finds the header
    below a title and the CSV delimiter."""
    mapping = mapping or {}
    return lambda name: (
        is_column(name) or name in mapping or _column_map.bare_quantity(name) is not None
    )


def _identify(table: Table, i: int, h: str, mapping: dict) -> tuple[str, str | None, str] | None:
    """(quantity, suffix or None, what named it) of header column ``i``, or None (an extra column)."""
    if h in mapping:
        q, suffix, target = mapping[h]
        return q, suffix, f"`columns` {target}={h}"
    if h in ("branch", "step"):
        return h, None, "name"
    split = _units.split_name(h)
    if split is not None:
        return split[0], split[1], "name"
    if table.units is not None and table.units[i] and _column_map.bare_quantity(h):
        return _column_map.bare_quantity(h), None, "name"
    return None


def _unit_from_row(
    table: Table, i: int, h: str, q: str, suffix: str | None, named: str
) -> str | None:
    """The column's suffix: its name's (or the map's), checked against the units row, or the
    units row's when the name gives none."""
    written = table.units[i] if table.units is not None else ""
    if q in ("branch", "step") or not written:
        if suffix is None and q not in ("branch", "step"):
            via = f" ({named})" if named != "name" else ""
            why = (
                "the file has no units row under the header"
                if table.units is None
                else "its cell in the units row is empty"
            )
            raise InputError(
                f"{where(table.name, table.units_row or table.header_row, h)}: no unit for the "
                f"{q.replace('_', ' ')}{via}: {why}; give it in the map ({', '.join(_units.names(q))})"
            )
        return suffix
    said = _units.suffix_of(q, written)
    if said is None:
        raise InputError(
            f"{where(table.name, table.units_row, h)}: unknown unit '{written}' for the "
            f"{q.replace('_', ' ')}; one of {', '.join(_units.shown(s) for s in _units.QUANTITIES[q][1])}"
        )
    if suffix is not None and said != suffix:
        raise InputError(
            f"{where(table.name, table.units_row, h)}: the units row says {written} but {named} "
            f"says {_units.shown(suffix)}; correct one of them"
        )
    return said


def columns(table: Table, column_map: dict | None = None) -> dict[str, Column]:
    """The recordings columns of the header, by quantity (one line naming the defect).

    ``column_map``: source header -> (quantity, suffix or None, target) (uq._data.column_map); a
    units row (``table.units``) gives the unit of columns whose name or map gives none and must
    agree with the others.
    """
    name, header_row, header = table.name, table.header_row, table.header
    mapping = dict(column_map or {})
    seen: set[str] = set()
    for h in header:
        if h in seen and h:  # unnamed columns (Excel pads with them) are ignored like extra ones
            raise InputError(f"{where(name, header_row)}: column '{h}' appears twice in the header")
        seen.add(h)
    absent = [f"{t}={s}" for s, (_, _, t) in mapping.items() if s not in seen]
    if absent:
        raise InputError(
            f"{where(name, header_row)}: `columns` {absent[0]}: no column '{absent[0].split('=', 1)[1]}' "
            f"in the header (header has: {', '.join(header)})"
        )
    found: dict[str, Column] = {}
    unknown: dict[str, list[tuple[str, str]]] = {}
    for i, h in enumerate(header):
        ident = _identify(table, i, h, mapping)
        if ident is None:
            continue
        q, suffix, named = ident
        if q in ("branch", "step"):
            if q in found:
                raise InputError(
                    f"{where(name, header_row)}: columns '{found[q].name}' and '{h}' both give the {q}; keep one"
                )
            found[q] = Column(q, h, i)
            continue
        if suffix is not None and not _units.known(q, suffix):
            unknown.setdefault(q, []).append((h, suffix))
            continue
        suffix = _unit_from_row(table, i, h, q, suffix, named)
        if q in found:
            raise InputError(
                f"{where(name, header_row)}: columns '{found[q].name}' and '{h}' both give the "
                f"{q.replace('_', ' ')}; keep one (the name's suffix is the unit)"
            )
        found[q] = Column(q, h, i, suffix, _units.factor(q, suffix))
    for q in _units.QUANTITIES:
        if q in found:
            continue
        if q in unknown:
            h, suffix = unknown[q][0]
            same = [s for s in _units.QUANTITIES[q][1] if s.lower() == suffix.lower()]
            case = f" (units are case-sensitive: write '{q}_{same[0]}')" if same else ""
            raise InputError(
                f"{where(name, header_row, h)}: unknown unit '{suffix}'; the name's suffix is the unit, "
                f"one of {', '.join(_units.names(q))}{case}"
            )
        if q in ("pressure", "height", "force"):
            hint = "" if len(header) > 1 else "; columns must be separated by ',' (or ';' or tab)"
            others = ", ".join(_units.names(q)[1:])
            raise InputError(
                f"{where(name, header_row)}: missing column '{_units.names(q)[0]}' (or another unit: {others}; "
                f"header has: {', '.join(header)}){hint}; or name the file's column with `columns` "
                f"({_units.names(q)[0]}=NAME)"
            )
    if "piston" in found and "volume" in found:
        raise InputError(
            f"{where(name, header_row)}: columns '{found['piston'].name}' and '{found['volume'].name}' both give the "
            "volume (the piston's coordinate, the element's volume); keep one"
        )
    if ("branch" in found) != ("step" in found):
        have, missing = ("branch", "step") if "branch" in found else ("step", "branch")
        raise InputError(
            f"{where(name, header_row)}: column '{found[have].name}' without '{missing}': give both or neither "
            "(both: the recording order; neither: one pass in unknown order)"
        )
    return found


def units_note(table: Table, cols: dict[str, Column]) -> str | None:
    """One line saying which units the units row gave, or None without one."""
    if table.units is None:
        return None
    used = [c for c in sorted(cols.values(), key=lambda c: c.index) if c.suffix is not None]
    given = ", ".join(f"{c.name} in {c.unit}" for c in used if table.units[c.index])
    return f"{where(table.name, table.units_row)}: a units row under the header" + (
        f": {given}" if given else ""
    )


@dataclass
class Readings:
    """The parsed rows (file order), converted: pressures in bar gauge, the rest SI."""

    rows: np.ndarray
    pressure_bar: np.ndarray
    set_bar: np.ndarray | None
    height_m: np.ndarray
    force_N: np.ndarray
    piston_m: np.ndarray | None
    volume_m3: np.ndarray | None  # NaN where the cell is empty
    compression: np.ndarray | None
    step: np.ndarray | None


def _refuse_unfilled(table: Table, cols: dict[str, Column]) -> None:
    """A ``uq plan`` template with readings not yet made: one line naming the first empty cell and
    how many planned readings are still empty."""
    if not any(c.startswith(PLANNED_MARK) for c in table.comments):
        return
    measured = [cols[q] for q in ("force", "piston") if q in cols]
    empty = [
        (row, c.name)
        for row, fields in table.body
        for c in measured
        if c.index >= len(fields) or not str(fields[c.index]).strip()
    ]
    if empty:
        rows = len({r for r, _ in empty})
        row, name = empty[0]
        raise InputError(
            f"{where(table.name, row, name)}: empty: a reading planned by uq plan and not measured "
            f"yet ({rows} planned reading{'s' if rows > 1 else ''} still empty); fill in "
            f"{' and '.join(c.name for c in measured)} at the stand"
        )


def parse(table: Table, cols: dict[str, Column], pressure_offset_bar: float) -> Readings:
    """Every data row parsed, converted and checked against the ranges above, in file order.

    ``pressure_offset_bar``: added to both pressure columns (-p_atm for absolute pressure).
    """
    name, header, sep = table.name, table.header, table.sep
    numeric = [c for q, c in cols.items() if q != "branch"]
    decimal_comma = sep not in (",", None) and any(
        "," in str(fields[c.index])
        for _, fields in table.body
        for c in numeric
        if c.index < len(fields)
    )
    n = len(table.body)
    _refuse_unfilled(table, cols)
    values = {q: np.empty(n) for q in cols if q not in ("branch", "step")}
    comp = np.empty(n, bool) if "branch" in cols else None
    step = np.empty(n, int) if "step" in cols else None
    rows = np.array([row for row, _ in table.body], dtype=int)
    for i, (row, fields) in enumerate(table.body):
        found = sum(1 for f in fields if isinstance(f, str))
        if found != len(header):
            hint = (
                " (a decimal comma? use decimal points, or separate the columns by ';')"
                if sep == "," and found > len(header)
                else ""
            )
            raise InputError(
                f"{where(name, row)}: expected {len(header)} fields as in the header (separated by {DELIMITERS[sep]}), found {found}{hint}"
            )
        for q, c in cols.items():
            text = fields[c.index]
            if q == "branch":
                br = str(text).strip()
                if br not in BRANCHES:
                    raise InputError(
                        f"{where(name, row, c.name)}: '{br}' is not a branch; expected 'compression' or 'rebound'"
                    )
                comp[i] = br == "compression"
            elif q == "step":
                step[i] = integer(text, name, row, c.name, decimal_comma)
            elif q == "volume" and not str(text).strip():
                values[q][i] = np.nan  # volumes are given only for the tests they were measured at
            else:
                raw = number(text, name, row, c.name, decimal_comma, sep is None)
                si = raw * c.factor
                if q in ("pressure", "set_pressure") and (c.factor != 1.0 or pressure_offset_bar):
                    # 12 digits: a test's label is 1 bar, not the 1.0000000000000002 bar that
                    # 2.01325 - 1.01325 or 14.5037737730 psi leave (1e-7 Pa is no information)
                    si = float(f"{si + pressure_offset_bar:.12g}")
                _check_value(name, row, c, raw, si, pressure_offset_bar)
                values[q][i] = si
    return Readings(
        rows=rows,
        pressure_bar=values["pressure"],
        set_bar=values.get("set_pressure"),
        height_m=values["height"],
        force_N=values["force"],
        piston_m=values.get("piston"),
        volume_m3=values.get("volume"),
        compression=comp,
        step=step,
    )


def _check_value(name: str, row: int, c: Column, raw: float, si: float, offset_bar: float) -> None:
    """One value against the ranges of an air spring on a stand; the message names the unit slip."""
    at = where(name, row, c.name)
    q = c.quantity
    if q in ("pressure", "set_pressure"):
        shown = c.shown(raw, si - offset_bar, "bar")
        if si <= 0:
            if offset_bar:
                raise InputError(
                    f"{at}: absolute pressure {shown} is not above atmospheric ({-offset_bar:g} bar, `absolute_pressure`); "
                    "tests run at a set overpressure above 0 bar"
                )
            raise InputError(
                f"{at}: overpressure {shown} is not positive; tests run at a set overpressure above 0 bar"
            )
        if si > MAX_PRESSURE_BAR:
            raise InputError(
                f"{at}: {shown} is beyond the overpressures air springs are tested at (at most {MAX_PRESSURE_BAR:g} bar): "
                f"kPa, psi or Pa given as {c.unit}?"
            )
    elif q == "height":
        shown = c.shown(raw, si, "mm", 1e3)
        if si <= 0:
            raise InputError(f"{at}: height {shown} is not positive")
        if si * 1e3 > MAX_HEIGHT_MM:
            slip = (
                "micrometres given instead of mm"
                if c.unit == "mm"
                else f"a smaller unit given as {c.unit}"
            )
            raise InputError(
                f"{at}: height {shown} is beyond any air spring (at most {MAX_HEIGHT_MM:g} mm): {slip}, or a typo?"
            )
    elif q == "force":
        if abs(si) > MAX_ABS_FORCE_N:
            raise InputError(
                f"{at}: force {c.shown(raw, si, 'N')} is beyond any air spring (at most {MAX_ABS_FORCE_N:g} N in magnitude): a typo or a wrong unit?"
            )
    elif q == "piston":
        if abs(si) * 1e3 > MAX_ABS_PISTON_MM:
            raise InputError(
                f"{at}: piston coordinate {c.shown(raw, si, 'mm', 1e3)} is beyond any stand (at most {MAX_ABS_PISTON_MM:g} mm in magnitude): a typo or a wrong unit?"
            )
    elif q == "volume":
        shown = c.shown(raw, si, "L", 1e3)
        if si <= 0:
            raise InputError(
                f"{at}: volume {shown} is not positive; the column holds the element's internal volume"
            )
        if si > MAX_VOLUME_M3:
            raise InputError(
                f"{at}: volume {shown} is beyond any air spring (at most {MAX_VOLUME_M3 * 1e3:g} L): a smaller unit given as {c.unit}?"
            )
