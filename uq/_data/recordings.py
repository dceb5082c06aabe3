"""Recordings: the format of docs/formats.md section 1, read and validated in one place.

One file (CSV, or one sheet of an .xlsx/.ods workbook) is one test campaign. The paper's full
format has the columns ``pressure_bar, height_mm, force_N, piston_mm, branch, step``; real stands
and catalogues give less or other units (docs/formats.md, section 1):

* the suffix of a column name is its unit (``pressure_psi``, ``height_in``, ``force_lbf``, ...),
  converted on reading (uq._data.units): heights, forces, piston coordinates and volumes in SI,
  pressures in bar (a test's label);
* no ``piston_*`` and no ``volume_*`` column: a force-only campaign (``PressureTest.piston_m``
  None); a ``volume_*`` column: the element's internal volume, on the rows of the tests it was
  measured at (``PressureTest.volume_m3``);
* no ``branch`` and no ``step``: each test is one pass in unknown order (``compression`` and
  ``step`` None);
* a ``set_pressure_*`` column groups the tests and makes ``pressure_*`` each reading's measured
  overpressure; without it, scattered measured pressures are clustered (uq._data.pressure_groups).

Every defect raises :class:`uq.InputError` with a one-line message naming the file, the
row (the line number an editor shows, or the spreadsheet's row) and the column; nothing is
dropped or guessed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from uq._data import checks
from uq._data import column_map as _column_map
from uq._data import units as _units
from uq._data.cells import BRANCHES as BRANCHES
from uq._data.cells import (
    MIN_LARGEST_HEIGHT_MM,
    Column,
    Readings,
    column_test,
    columns,
    parse,
    units_note,
)
from uq._data.pressure_groups import PressureColumns, group
from uq._data.rows import UNITS_ROW_MODES as UNITS_ROW_MODES
from uq._data.rows import Table, check_shape_options, read_table, table_from_text
from uq._data.rows import leading_comments as leading_comments
from uq._data.writing import write_recordings_csv as write_recordings_csv
from uq._io.errors import InputError, where
from uq._physics.quantities import BAR_PA

#: How a file may sign compression (``compression``).
COMPRESSION_CONVENTIONS = ("positive", "negative")

#: Default stand constants (the paper's): piston area S = 54.82 cm^2, basis height x0 = 112 mm.
DEFAULT_PISTON_AREA_CM2 = 54.82
DEFAULT_X0_MM = 112.0
DEFAULT_P_ATM_BAR = 1.01325
#: the options of :func:`read_recordings` that say how a file is read (the commands' reading
#: options, the batch catalogue's)
READING_OPTIONS = (
    "piston_area_cm2",
    "x0_mm",
    "compression",
    "sheet",
    "absolute_pressure",
    "p_atm_bar",
    "pressure_tolerance_bar",
    "columns",
    "units_row",
    "header_row",
)


@dataclass(frozen=True, eq=False)
class PressureTest:
    """One isobaric test: all rows recorded at one set overpressure, in recording order.

    Arrays have shape (n,) and are sorted by ``step``; a test in unknown order (no branch and
    step columns) is sorted by decreasing height, and its ``compression`` and ``step`` are None.

    pressure_bar           set overpressure p_u (bar), the test's label
    height_m, force_N      height x (m) and force P (N, compression positive) of each reading
    piston_m               piston coordinate L (m), or None in a force-only campaign
    compression            True on the compression branch (height decreasing), or None
    step                   recording order 0..n-1, or None
    rows                   the readings' rows in the file, for messages
    measured_pressure_bar  each reading's measured overpressure (bar); the set value repeated
                           when the file gives only set values
    volume_m3              the element's internal volume (m^3) at each reading, or None
    volume_step_m3         the step the volume column was printed to (m^3: its last digit, e.g.
                           0.01 L), read from its values; None when unknown (a test made in code)
    """

    pressure_bar: float
    height_m: np.ndarray
    force_N: np.ndarray
    piston_m: np.ndarray | None
    compression: np.ndarray | None  # bool: True on the compression branch (height decreasing)
    step: np.ndarray | None  # int recording order 0..n-1
    rows: np.ndarray  # line numbers in the file, for messages
    measured_pressure_bar: np.ndarray | None = None
    volume_m3: np.ndarray | None = None
    volume_step_m3: float | None = None

    def __post_init__(self):
        if self.measured_pressure_bar is None:
            object.__setattr__(
                self,
                "measured_pressure_bar",
                np.full(self.height_m.shape, float(self.pressure_bar)),
            )

    @property
    def pressure_Pa(self) -> float:
        return self.pressure_bar * BAR_PA

    @property
    def n_points(self) -> int:
        return int(self.height_m.size)

    @property
    def label(self) -> str:
        return f"{self.pressure_bar:g} bar"

    def __repr__(self) -> str:
        lo, hi = float(self.height_m.min()) * 1e3, float(self.height_m.max()) * 1e3
        kind = "force only" if self.piston_m is None and self.volume_m3 is None else "force, volume"
        return f"PressureTest({self.label}, {self.n_points} readings, {lo:g}..{hi:g} mm, {kind})"


@dataclass(frozen=True, eq=False)
class Recordings:
    """A campaign: its tests sorted by pressure, and the stand constants (SI).

    units                  quantity -> the unit its column had in the file ("pressure": "psi",
                           "height": "mm", ...; also "set_pressure", "piston", "volume" when given)
    pressure_measured      the tests' readings carry measured pressures (a set_pressure_* column,
                           or pressures that scatter around set points)
    sheet                  the workbook sheet read, None for CSV
    conventions            "compression": "positive" or "negative" (as the file wrote force);
                           "pressure": "gauge", or "absolute" (converted with "p_atm_bar")
    comments               the file's leading ``#`` lines without the ``#``, then the title rows
                           above a header found lower down (what made the recordings, if it says)
    sha256                 the SHA-256 of the file's bytes as read (of the CSV text for recordings
                           made in memory: a simulated campaign's is that of the file ``uq
                           simulate`` writes), the recordings' provenance; None when unknown
    columns                quantity -> the file's header of its column (``{"force": "Load"}``
                           when a column map named it)
    notes                  what the reader decided by itself, one line each (a header found below
                           a title, a units row under the header): the command line prints them
    """

    path: str
    tests: tuple[PressureTest, ...]
    x0_m: float = DEFAULT_X0_MM * 1e-3
    piston_area_m2: float = DEFAULT_PISTON_AREA_CM2 * 1e-4
    extra_columns: tuple[str, ...] = field(default=())
    comments: tuple[str, ...] = field(default=())
    units: dict = field(default_factory=lambda: dict(_units.PAPER_UNITS))
    pressure_measured: bool = False
    sheet: str | None = None
    conventions: dict = field(
        default_factory=lambda: {"compression": "positive", "pressure": "gauge"}
    )
    sha256: str | None = None
    columns: dict = field(default_factory=dict)
    notes: tuple[str, ...] = field(default=())

    def __repr__(self) -> str:
        p = ", ".join(f"{t.pressure_bar:g}" for t in self.tests)
        lo, hi = (v * 1e3 for v in self.height_range_m) if self.tests else (0.0, 0.0)
        kind = "with piston" if self.has_piston else "force only"
        return (
            f"Recordings({self.path}: {len(self.tests)} tests at {p} bar, {self.n_points} "
            f"readings, {lo:g}..{hi:g} mm, {kind})"
        )

    @property
    def pressures_bar(self) -> np.ndarray:
        return np.array([t.pressure_bar for t in self.tests])

    @property
    def n_points(self) -> int:
        return sum(t.n_points for t in self.tests)

    @property
    def reconstructed(self) -> bool:
        """The file's header says its readings are RECONSTRUCTED (made by a virtual stand, as
        data/n50's are), not measured."""
        return any("RECONSTRUCTED" in c.upper() for c in self.comments)

    @property
    def has_piston(self) -> bool:
        """Every test has piston coordinates (the paper's volume measurement)."""
        return all(t.piston_m is not None for t in self.tests)

    @property
    def has_volume(self) -> bool:
        """The campaign measured volume: piston coordinates, or a volume column on some test."""
        return any(t.piston_m is not None or t.volume_m3 is not None for t in self.tests)

    @property
    def order_known(self) -> bool:
        """Every test has branch and step (recording order); False for a one-pass table."""
        return all(t.step is not None for t in self.tests)

    @property
    def has_both_branches(self) -> bool:
        """Every test has readings on both branches (compression and rebound), so a branch
        difference (hysteresis) can be seen; False for one pass or a compression-only campaign."""
        return self.order_known and all(
            t.compression.any() and not t.compression.all() for t in self.tests
        )

    def test_at(self, pressure_bar: float) -> PressureTest:
        for t in self.tests:
            if abs(t.pressure_bar - pressure_bar) < 1e-9:
                return t
        raise KeyError(pressure_bar)

    @property
    def height_range_m(self) -> tuple[float, float]:
        lo = min(float(t.height_m.min()) for t in self.tests)
        hi = max(float(t.height_m.max()) for t in self.tests)
        return lo, hi


# ----------------------------------------------------------------------------- what commands need


def require(rec: Recordings, needs) -> None:
    """Refuse, in one line, a campaign that lacks what the caller ``needs`` ("piston", "order")."""
    needs = set(needs)
    if "piston" in needs and not rec.has_piston:
        if rec.has_volume:
            raise InputError(
                f"{rec.path}: volume_* column without piston_*: this command needs piston_* in every test "
                "(not yet supported for a volume column)"
            )
        raise InputError(
            f"{rec.path}: force-only campaign: this command needs piston_* or volume_* "
            "(not yet supported for force-only campaigns)"
        )
    if "order" in needs and not rec.order_known:
        raise InputError(
            f"{rec.path}: one pass in unknown order (no branch and step columns): this command needs branch "
            "and step (not yet supported for campaigns in unknown order)"
        )


# ----------------------------------------------------------------------------- options


def check_stand_options(piston_area_cm2: float, x0_mm: float) -> None:
    """Validate the stand constants given as options (names the parameter on failure; the CLI its option)."""
    if not (math.isfinite(piston_area_cm2) and piston_area_cm2 > 0):
        raise InputError(
            f"piston_area_cm2: expected a positive area in cm^2, got {piston_area_cm2}",
            param="piston_area_cm2",
        )
    if not (math.isfinite(x0_mm) and 1.0 <= x0_mm <= 5000.0):
        raise InputError(
            f"x0_mm: expected a reference height in mm (1..5000), got {x0_mm}", param="x0_mm"
        )


def check_reading_options(
    compression: str, p_atm_bar: float, pressure_tolerance_bar: float | None
) -> None:
    """Validate the reading conventions given as options (names the parameter on failure; the CLI its option)."""
    if compression not in COMPRESSION_CONVENTIONS:
        raise InputError(
            f"compression: expected positive or negative, got {compression!r}", param="compression"
        )
    if not (math.isfinite(p_atm_bar) and 0.3 <= p_atm_bar <= 1.2):
        raise InputError(
            f"p_atm_bar: expected the atmospheric pressure in bar (0.3..1.2), got {p_atm_bar}",
            param="p_atm_bar",
        )
    if pressure_tolerance_bar is not None and not (
        math.isfinite(pressure_tolerance_bar) and pressure_tolerance_bar > 0
    ):
        raise InputError(
            f"pressure_tolerance_bar: expected a positive tolerance in bar, got {pressure_tolerance_bar}",
            param="pressure_tolerance_bar",
        )


# ----------------------------------------------------------------------------- reading


def read_recordings(
    path: str | Path,
    *,
    piston_area_cm2: float = DEFAULT_PISTON_AREA_CM2,
    x0_mm: float = DEFAULT_X0_MM,
    min_points: int = 6,
    compression: str = "positive",
    sheet: str | None = None,
    absolute_pressure: bool = False,
    p_atm_bar: float = DEFAULT_P_ATM_BAR,
    pressure_tolerance_bar: float | None = None,
    columns: dict | str | None = None,
    units_row: str = "auto",
    header_row: int | None = None,
    on_note=None,
) -> Recordings:
    """Read and validate recordings (docs/formats.md section 1).

    Parameters
    ----------
    path : a CSV file (UTF-8, a BOM is fine; columns separated by ',', or ';' or tab, where a
        decimal comma is then also understood) or an .xlsx/.ods workbook.
    piston_area_cm2 : area S of the hydraulic cylinder's piston cavity (eq. 5), cm^2.
    x0_mm : reference height x0 of the polynomial basis u = x - x0 (eqs. 8, 9), mm; must lie
        within the recorded heights.
    min_points : the fewest points a test may have (the model's parameter count).
    compression : "positive" (this format's convention) or "negative": the file writes
        compression as negative force (a load-frame convention); forces are then negated.
    sheet : the workbook's sheet holding the campaign; required when it has several.
    absolute_pressure : the pressure columns hold absolute pressure; ``p_atm_bar`` is
        subtracted to get the gauge overpressure the models use.
    p_atm_bar : atmospheric pressure (bar) for ``absolute_pressure``.
    pressure_tolerance_bar : how far a reading's measured pressure may lie from its test's set
        pressure (bar); default max(0.05 bar, 2 % of the pressure). See uq._data.pressure_groups.
    columns : a column map, which of the file's columns is which recordings column:
        ``{"force_N": "Load", "height_mm": "Extension"}`` or the text ``"force_N=Load,..."``; a
        quantity without unit (``"force": "Load"``) takes its unit from the units row.
    units_row : "auto" (a row of units in brackets under the header, ``(bar),(mm),(N)``, is
        detected and noted in ``Recordings.notes``), "yes" (the row under the header gives the
        units) or "no".
    header_row : the header's row in the file (rows above it are a title, kept with the
        comments); by default the first row, or the first naming a recordings column under a
        title of up to 20 rows (noted in ``Recordings.notes``).

    Raises
    ------
    InputError : one line naming file, row and column of the first defect found: format
        defects, values beyond any air spring, unit slips (heights in m or um, force in kN,
        pressure in kPa, piston in m), conventions not declared (compression negative,
        absolute pressure), a piston area the forces contradict, and gross outliers.
    """
    check_stand_options(piston_area_cm2, x0_mm)
    check_reading_options(compression, p_atm_bar, pressure_tolerance_bar)
    check_shape_options(header_row, units_row)
    mapping = column_map(columns)
    path = str(path)
    table = read_table(
        path, column_test(mapping), sheet, header_row=header_row, units_row=units_row
    )
    return _recordings(
        table,
        path,
        mapping,
        on_note,
        piston_area_cm2=piston_area_cm2,
        x0_mm=x0_mm,
        min_points=min_points,
        compression=compression,
        absolute_pressure=absolute_pressure,
        p_atm_bar=p_atm_bar,
        pressure_tolerance_bar=pressure_tolerance_bar,
    )


def column_map(columns: dict | str | None) -> dict:
    """The ``columns`` parameter as source -> (quantity, suffix or None, target) (uq._data.column_map);
    a bad map is one line naming the parameter."""
    if columns is None:
        return {}
    try:
        return _column_map.parse(columns)
    except ValueError as exc:
        raise InputError(f"columns: {exc}", param="columns") from None


def recordings_from_text(
    text: str,
    name: str = "<text>",
    *,
    piston_area_cm2: float = DEFAULT_PISTON_AREA_CM2,
    x0_mm: float = DEFAULT_X0_MM,
    min_points: int = 6,
    compression: str = "positive",
    absolute_pressure: bool = False,
    p_atm_bar: float = DEFAULT_P_ATM_BAR,
    pressure_tolerance_bar: float | None = None,
    columns: dict | str | None = None,
    units_row: str = "auto",
    header_row: int | None = None,
    on_note=None,
) -> Recordings:
    """:func:`read_recordings` on CSV text already in memory; ``name`` stands for the file in
    messages and becomes ``Recordings.path``; ``Recordings.sha256`` is that of the text's UTF-8
    (what a file holding the text has)."""
    check_stand_options(piston_area_cm2, x0_mm)
    check_reading_options(compression, p_atm_bar, pressure_tolerance_bar)
    check_shape_options(header_row, units_row)
    mapping = column_map(columns)
    name = str(name)
    return _recordings(
        table_from_text(
            text, name, column_test(mapping), header_row=header_row, units_row=units_row
        ),
        name,
        mapping,
        on_note,
        piston_area_cm2=piston_area_cm2,
        x0_mm=x0_mm,
        min_points=min_points,
        compression=compression,
        absolute_pressure=absolute_pressure,
        p_atm_bar=p_atm_bar,
        pressure_tolerance_bar=pressure_tolerance_bar,
    )


def _recordings(
    table: Table,
    path: str,
    mapping: dict,
    on_note,
    *,
    piston_area_cm2: float,
    x0_mm: float,
    min_points: int,
    compression: str,
    absolute_pressure: bool,
    p_atm_bar: float,
    pressure_tolerance_bar: float | None,
) -> Recordings:
    name = table.name
    notes = list(table.notes)
    for note in notes:
        (on_note or _ignore)(note)
    cols = columns(table, mapping)
    if table.units is not None:
        notes.append(units_note(table, cols))
        (on_note or _ignore)(notes[-1])
    if not table.body:
        raise InputError(f"{name}: no data rows after the header")
    r = parse(table, cols, -p_atm_bar if absolute_pressure else 0.0)
    if compression == "negative":
        r.force_N = -r.force_N
    height = cols["height"]
    if r.height_m.max() * 1e3 < MIN_LARGEST_HEIGHT_MM:
        largest = r.height_m.max() / height.factor
        raise InputError(
            f"{where(name, int(r.rows[0]), height.name)}: heights are at most {largest:g} {height.unit}, which looks "
            f"like metres; the column {height.name} is in {height.unit}"
        )

    p_col = cols["pressure"]
    groups, measured = group(
        PressureColumns(
            name,
            p_col.name,
            p_col.unit,
            p_col.factor,
            cols["set_pressure"].name if "set_pressure" in cols else None,
            p_atm_bar,
        ),
        r.rows,
        r.pressure_bar,
        r.set_bar,
        min_points,
        pressure_tolerance_bar,
    )
    clustered = measured and r.set_bar is None
    hint = (
        " (readings were grouped into tests by their measured pressures: add a set_pressure_* column, "
        "or give a smaller `pressure_tolerance_bar`)"
        if clustered
        else ""
    )
    tests = [_make_test(name, g.set_bar, g.index, r, cols, min_points, hint) for g in groups]
    for a, b in zip(tests, tests[1:], strict=False):
        if a.pressure_bar == b.pressure_bar:
            raise InputError(
                f"{where(name, int(b.rows[0]), p_col.name)}: two clusters of measured pressures both round to "
                f"{b.pressure_bar:g} bar{hint}"
            )

    checks.check_x0(name, tests, x0_mm)
    if "piston" in cols:
        checks.check_travel(name, tests, cols["piston"].name)
    if "volume" in cols and all(t.volume_m3 is None for t in tests):
        v = cols["volume"].name
        raise InputError(
            f"{where(name, table.header_row, v)}: the column is empty; fill it on the rows of the test(s) the volume "
            f"was measured at, or omit it"
        )
    checks.check_force_sign(name, tests, compression == "negative", cols["force"].name)
    checks.check_gauge(name, tests, p_col.name, absolute_pressure, p_atm_bar)
    named = {q: (c.name, c.unit) for q, c in cols.items()}
    checks.check_areas(
        name, tests, piston_area_cm2 * 1e-4, named, None if absolute_pressure else p_atm_bar
    )
    for t in tests:
        checks.check_outliers(name, t, _outlier_columns(t, cols))

    used = {c.name for c in cols.values()}
    extra = tuple(h for h in table.header if h and h not in used)
    return Recordings(
        path=path,
        tests=tuple(tests),
        x0_m=x0_mm * 1e-3,
        piston_area_m2=piston_area_cm2 * 1e-4,
        extra_columns=extra,
        comments=tuple(table.comments),
        sha256=table.sha256,
        columns={q: c.name for q, c in cols.items()},
        notes=tuple(notes),
        units={q: c.suffix for q, c in cols.items() if c.suffix is not None},
        pressure_measured=measured,
        sheet=table.sheet,
        conventions={
            "compression": compression,
            "pressure": "absolute" if absolute_pressure else "gauge",
            **({"p_atm_bar": p_atm_bar} if absolute_pressure else {}),
        },
    )


def _ignore(note: str) -> None:
    pass


def _outlier_columns(t: PressureTest, cols: dict[str, Column]) -> list:
    readings = (("force", t.force_N), ("piston", t.piston_m), ("volume", t.volume_m3))
    return [
        (cols[q].name, v, 1.0 / cols[q].factor, cols[q].unit) for q, v in readings if v is not None
    ]


def _make_test(
    name: str,
    p: float,
    idx: np.ndarray,
    r: Readings,
    cols: dict[str, Column],
    min_points: int,
    hint: str = "",
) -> PressureTest:
    label = f"{p:g} bar test"
    h = cols["height"]
    rows, height = r.rows[idx], r.height_m[idx]

    def hmm(x: float) -> str:  # a height as the file writes it
        return f"{x / h.factor:g} {h.unit}"

    if np.unique(np.round(height, 9)).size == 1:
        raise InputError(
            f"{where(name, int(rows[0]), h.name)}: the {label} has a single height ({hmm(height[0])}); a characteristic needs the element stepped through several heights{hint}"
        )
    if r.step is not None:
        order = _recording_order(name, label, idx, r, cols, hmm, hint)
    else:
        seen: dict[float, int] = {}
        for row, x in zip(rows, height, strict=True):
            key = round(float(x), 9)
            if key in seen:
                raise InputError(
                    f"{where(name, int(row), h.name)}: height {hmm(x)} recorded twice in the {label} (also row {seen[key]}); "
                    f"without branch and step columns a test is one pass, each height once (duplicated row?){hint}"
                )
            seen[key] = int(row)
        order = idx[np.argsort(-height, kind="stable")]
    n_heights = np.unique(np.round(r.height_m[order], 9)).size
    if order.size < min_points or n_heights < 4:
        raise InputError(
            f"{where(name, int(rows[0]))}: the {label} has {order.size} points at {n_heights} heights; the model needs at least {min_points} points at 4 or more heights{hint}"
        )
    comp = None if r.compression is None else r.compression[order]
    if comp is not None:
        _check_branch_order(name, label, r.height_m[order], comp, r.rows[order], h.name, hmm)
    volume = step = None
    if r.volume_m3 is not None:
        v = r.volume_m3[order]
        given = ~np.isnan(v)
        if given.all():
            volume = v
            factor = cols["volume"].factor
            step = _units.printed_step(v / factor) * factor
        elif given.any():
            c = cols["volume"]
            empty = int(r.rows[order][~given].min())
            full = int(r.rows[order][given].min())
            raise InputError(
                f"{where(name, empty, c.name)}: empty, but other rows of the {label} give a volume (row {full}); "
                "fill the volume on every row of a test, or on none"
            )
    return PressureTest(
        pressure_bar=float(p),
        height_m=r.height_m[order],
        force_N=r.force_N[order],
        piston_m=None if r.piston_m is None else r.piston_m[order],
        compression=comp,
        step=None if r.step is None else np.arange(order.size),
        rows=r.rows[order],
        measured_pressure_bar=r.pressure_bar[order],
        volume_m3=volume,
        volume_step_m3=step,
    )


def _recording_order(name, label, idx, r: Readings, cols, hmm, hint) -> np.ndarray:
    """The test's readings sorted by step; duplicated and missing steps are refused."""
    by_step: dict[int, int] = {}
    by_place: dict[tuple[bool, float], int] = {}
    for i in idx:
        row, st, comp = int(r.rows[i]), int(r.step[i]), bool(r.compression[i])
        if st in by_step:
            raise InputError(
                f"{where(name, row, cols['step'].name)}: step {st} of the {label} already recorded at row {int(r.rows[by_step[st]])} (duplicated row?){hint}"
            )
        by_step[st] = i
        place = (comp, round(float(r.height_m[i]), 9))
        if place in by_place:
            branch = "compression" if comp else "rebound"
            raise InputError(
                f"{where(name, row, cols['height'].name)}: height {hmm(r.height_m[i])} recorded twice on the {branch} branch of the {label} (also row {by_place[place]}; duplicated row?){hint}"
            )
        by_place[place] = row
    steps = sorted(by_step)
    if steps != list(range(len(steps))):
        missing = next(i for i in range(len(steps) + 1) if i not in by_step)
        after = min(s for s in steps if s > missing)
        raise InputError(
            f"{where(name, int(r.rows[by_step[after]]), cols['step'].name)}: steps of the {label} should run 0, 1, 2, ... without gaps; step {missing} is missing before this row's step {after}{hint}"
        )
    return np.array([by_step[s] for s in steps], dtype=int)


def _check_branch_order(name: str, label: str, height, comp, row_ids, column: str, hmm) -> None:
    """Within a branch, heights must move the way the branch says, in recording order.

    The row named is the one that breaks the run (a single mistyped height makes two steps
    go wrong, the one into it and the one out of it; the mistyped row is the one that sits
    farthest from what its neighbours say), not merely the second row of the first bad pair.
    """
    for branch_is_comp, sign, word in ((True, -1.0, "decrease"), (False, 1.0, "increase")):
        sel = np.flatnonzero(comp == branch_is_comp)
        if sel.size < 2:
            continue
        h = height[sel]
        bad = np.flatnonzero(np.diff(h) * sign <= 0)
        if not bad.size:
            continue
        j = _odd_one(h, int(bad[0]))
        branch = "compression" if branch_is_comp else "rebound"
        before = f"{hmm(h[j - 1])} before it" if j > 0 else "first of its branch"
        after = f"{hmm(h[j + 1])} after it" if j + 1 < h.size else "last of its branch"
        raise InputError(
            f"{where(name, int(row_ids[sel[j]]), column)}: heights on the {branch} branch of the {label} must {word} step by step, but this row's {hmm(h[j])} does not ({before}, {after})"
        )


def _odd_one(h: np.ndarray, k: int) -> int:
    """Of the pair (k, k+1) that breaks a monotone run, the index that fits its neighbours worst."""
    step = float(np.median(np.diff(h)))

    def misfit(j: int) -> float:
        if 0 < j < h.size - 1:
            return abs(h[j] - 0.5 * (h[j - 1] + h[j + 1]))
        return abs(h[j] - (h[j + 1] - step if j == 0 else h[j - 1] + step))

    return k if misfit(k) > misfit(k + 1) else k + 1
