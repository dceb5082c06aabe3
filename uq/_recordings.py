"""Recordings: the CSV format of CONTRACT.md section 1, read and validated in one place.

One file is one test campaign: rows of ``pressure_bar, height_mm, force_N, piston_mm,
branch, step`` (column order free, extra columns kept but ignored, ``#`` comment lines).
Rows with the same ``pressure_bar`` form one test. Everything is converted to SI here:
heights and piston coordinates in m, pressures in Pa (the bar value is kept as the
test's label).

Every defect raises :class:`uq.InputError` with a one-line message naming the file, the
row (the line number an editor shows) and the column; nothing is dropped or guessed.
"""

from __future__ import annotations

import csv
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ._errors import InputError, where

REQUIRED_COLUMNS = ("pressure_bar", "height_mm", "force_N", "piston_mm", "branch", "step")
BRANCHES = ("compression", "rebound")
BAR_PA = 1.0e5

#: Default stand constants (the paper's): piston area S = 54.82 cm^2, basis height x0 = 112 mm.
DEFAULT_PISTON_AREA_CM2 = 54.82
DEFAULT_X0_MM = 112.0


@dataclass(frozen=True, eq=False)
class Test:
    """One isobaric test: all rows recorded at one set overpressure, in recording order.

    Arrays have shape (n,) and are sorted by ``step``.
    """

    pressure_bar: float
    height_m: np.ndarray
    force_N: np.ndarray
    piston_m: np.ndarray
    compression: np.ndarray  # bool: True on the compression branch (height decreasing)
    step: np.ndarray  # int recording order 0..n-1
    rows: np.ndarray  # line numbers in the file, for messages

    @property
    def pressure_Pa(self) -> float:
        return self.pressure_bar * BAR_PA

    @property
    def n_points(self) -> int:
        return int(self.height_m.size)

    @property
    def label(self) -> str:
        return f"{self.pressure_bar:g} bar"


@dataclass(frozen=True, eq=False)
class Recordings:
    """A campaign: its tests sorted by pressure, and the stand constants (SI)."""

    path: str
    tests: tuple[Test, ...]
    x0_m: float = DEFAULT_X0_MM * 1e-3
    piston_area_m2: float = DEFAULT_PISTON_AREA_CM2 * 1e-4
    extra_columns: tuple[str, ...] = field(default=())

    @property
    def pressures_bar(self) -> np.ndarray:
        return np.array([t.pressure_bar for t in self.tests])

    @property
    def n_points(self) -> int:
        return sum(t.n_points for t in self.tests)

    def test_at(self, pressure_bar: float) -> Test:
        for t in self.tests:
            if abs(t.pressure_bar - pressure_bar) < 1e-9:
                return t
        raise KeyError(pressure_bar)

    @property
    def height_range_m(self) -> tuple[float, float]:
        lo = min(float(t.height_m.min()) for t in self.tests)
        hi = max(float(t.height_m.max()) for t in self.tests)
        return lo, hi


def check_stand_options(piston_area_cm2: float, x0_mm: float) -> None:
    """Validate the stand constants given as options (names the option on failure)."""
    if not (math.isfinite(piston_area_cm2) and piston_area_cm2 > 0):
        raise InputError(f"option --piston-area-cm2: expected a positive area in cm^2, got {piston_area_cm2}")
    if not (math.isfinite(x0_mm) and 1.0 <= x0_mm <= 5000.0):
        raise InputError(f"option --x0-mm: expected a reference height in mm (1..5000), got {x0_mm}")


def _number(text: str, path: str, row: int, column: str) -> float:
    try:
        value = float(text)
    except ValueError:
        shown = text if text.strip() else "(empty)"
        raise InputError(f"{where(path, row, column)}: '{shown}' is not a number") from None
    if not math.isfinite(value):
        raise InputError(f"{where(path, row, column)}: '{text.strip()}' is not a finite number")
    return value


def _integer(text: str, path: str, row: int, column: str) -> int:
    value = _number(text, path, row, column)
    if value != int(value) or value < 0:
        raise InputError(
            f"{where(path, row, column)}: '{text.strip()}' is not a step number (0, 1, 2, ...)"
        )
    return int(value)


def read_recordings(
    path: str | Path,
    *,
    piston_area_cm2: float = DEFAULT_PISTON_AREA_CM2,
    x0_mm: float = DEFAULT_X0_MM,
    min_points: int = 6,
) -> Recordings:
    """Read and validate a recordings CSV (CONTRACT.md section 1).

    Parameters
    ----------
    path : the CSV file.
    piston_area_cm2 : area S of the hydraulic cylinder's piston cavity (eq. 5), cm^2.
    x0_mm : reference height x0 of the polynomial basis u = x - x0 (eqs. 8, 9), mm.
    min_points : the fewest points a test may have (the model's parameter count).

    Raises
    ------
    InputError : one line naming file, row and column of the first defect found.
    """
    check_stand_options(piston_area_cm2, x0_mm)
    path = str(path)
    try:
        with open(path, newline="", encoding="utf-8") as fh:
            lines = fh.read().splitlines()
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: cannot read the file ({exc.__class__.__name__}: {exc})") from None

    numbered = [
        (i + 1, line) for i, line in enumerate(lines) if line.strip() and not line.lstrip().startswith("#")
    ]
    if not numbered:
        raise InputError(f"{path}: empty file, expected a header row with columns {', '.join(REQUIRED_COLUMNS)}")

    parsed = list(csv.reader([line for _, line in numbered]))
    header_row, header = numbered[0][0], [h.strip() for h in parsed[0]]
    seen: dict[str, int] = {}
    for h in header:
        if h in seen:
            raise InputError(f"{where(path, header_row)}: column '{h}' appears twice in the header")
        seen[h] = len(seen)
    for col in REQUIRED_COLUMNS:
        if col not in seen:
            if col == "height_mm" and "height_m" in seen:
                raise InputError(
                    f"{where(path, header_row)}: column 'height_mm' missing; found 'height_m': heights must be given in mm"
                )
            raise InputError(
                f"{where(path, header_row)}: missing column '{col}' (header has: {', '.join(header)})"
            )
    if len(numbered) == 1:
        raise InputError(f"{path}: no data rows after the header")

    idx = {c: seen[c] for c in REQUIRED_COLUMNS}
    groups: dict[float, list[tuple]] = {}
    for (row, _), fields in zip(numbered[1:], parsed[1:], strict=True):
        if len(fields) != len(header):
            raise InputError(f"{where(path, row)}: expected {len(header)} fields as in the header, found {len(fields)}")
        p = _number(fields[idx["pressure_bar"]], path, row, "pressure_bar")
        x = _number(fields[idx["height_mm"]], path, row, "height_mm")
        f = _number(fields[idx["force_N"]], path, row, "force_N")
        L = _number(fields[idx["piston_mm"]], path, row, "piston_mm")
        br = fields[idx["branch"]].strip()
        st = _integer(fields[idx["step"]], path, row, "step")
        if p <= 0:
            raise InputError(
                f"{where(path, row, 'pressure_bar')}: overpressure {p:g} bar is not positive; tests run at a set overpressure above 0 bar"
            )
        if p > 1000:
            raise InputError(f"{where(path, row, 'pressure_bar')}: {p:g} bar is not a plausible overpressure (pascals given instead of bar?)")
        if x <= 0:
            raise InputError(f"{where(path, row, 'height_mm')}: height {x:g} mm is not positive")
        if br not in BRANCHES:
            raise InputError(
                f"{where(path, row, 'branch')}: '{br}' is not a branch; expected 'compression' or 'rebound'"
            )
        groups.setdefault(p, []).append((row, x, f, L, br == "compression", st))

    all_heights = np.array([r[1] for g in groups.values() for r in g])
    if all_heights.max() < 2.0:
        row = next(r[0] for g in groups.values() for r in g)
        raise InputError(
            f"{where(path, row, 'height_mm')}: heights are at most {all_heights.max():g}, which looks like metres; the column height_mm is in mm"
        )

    tests = [
        _make_test(path, p, rows, min_points) for p, rows in sorted(groups.items(), key=lambda kv: kv[0])
    ]
    extra = tuple(h for h in header if h not in REQUIRED_COLUMNS)
    return Recordings(
        path=path,
        tests=tuple(tests),
        x0_m=x0_mm * 1e-3,
        piston_area_m2=piston_area_cm2 * 1e-4,
        extra_columns=extra,
    )


def _make_test(path: str, p: float, rows: list[tuple], min_points: int) -> Test:
    label = f"{p:g} bar test"
    if len({round(r[1], 6) for r in rows}) == 1:
        raise InputError(
            f"{where(path, rows[0][0], 'height_mm')}: the {label} has a single height ({rows[0][1]:g} mm); a characteristic needs the element stepped through several heights"
        )
    by_step: dict[int, tuple] = {}
    by_place: dict[tuple[bool, float], int] = {}
    for r in rows:
        row, x, _, _, comp, st = r
        if st in by_step:
            raise InputError(
                f"{where(path, row, 'step')}: step {st} of the {label} already recorded at row {by_step[st][0]} (duplicated row?)"
            )
        by_step[st] = r
        place = (comp, round(x, 6))
        if place in by_place:
            branch = "compression" if comp else "rebound"
            raise InputError(
                f"{where(path, row, 'height_mm')}: height {x:g} mm recorded twice on the {branch} branch of the {label} (also row {by_place[place]}; duplicated row?)"
            )
        by_place[place] = row
    steps = sorted(by_step)
    if steps != list(range(len(steps))):
        missing = next(i for i in range(len(steps) + 1) if i not in by_step)
        raise InputError(
            f"{where(path, rows[0][0], 'step')}: steps of the {label} should run 0, 1, 2, ... without gaps; step {missing} is missing"
        )
    ordered = [by_step[s] for s in steps]
    row_ids = np.array([r[0] for r in ordered])
    height = np.array([r[1] for r in ordered]) * 1e-3
    comp = np.array([r[4] for r in ordered], dtype=bool)

    if len(ordered) < min_points or np.unique(np.round(height, 9)).size < 4:
        raise InputError(
            f"{where(path, rows[0][0])}: the {label} has {len(ordered)} points at {np.unique(np.round(height, 9)).size} heights; the model needs at least {min_points} points at 4 or more heights"
        )
    # Within a branch, heights must move the way the branch says, in recording order.
    for branch_is_comp, sign, word in ((True, -1.0, "decrease"), (False, 1.0, "increase")):
        sel = np.flatnonzero(comp == branch_is_comp)
        if sel.size > 1:
            d = np.diff(height[sel]) * sign
            bad = np.flatnonzero(d <= 0)
            if bad.size:
                k = sel[bad[0] + 1]
                name = "compression" if branch_is_comp else "rebound"
                raise InputError(
                    f"{where(path, int(row_ids[k]), 'height_mm')}: heights on the {name} branch of the {label} must {word} step by step, but {height[sel[bad[0]]] * 1e3:g} mm is followed by {height[k] * 1e3:g} mm"
                )
    return Test(
        pressure_bar=float(p),
        height_m=height,
        force_N=np.array([r[2] for r in ordered], dtype=float),
        piston_m=np.array([r[3] for r in ordered], dtype=float) * 1e-3,
        compression=comp,
        step=np.array(steps, dtype=int),
        rows=row_ids,
    )


def write_recordings_csv(tests: list[dict], header_comment: str = "") -> str:
    """Format recordings as CSV text (CONTRACT.md section 1).

    ``tests``: dicts with keys pressure_bar, height_m, force_N, piston_m, compression, step
    (arrays). Numbers are printed at a fixed precision so that files are byte-reproducible.
    """
    out = []
    for line in header_comment.splitlines():
        out.append(f"# {line}".rstrip())
    out.append(",".join(REQUIRED_COLUMNS))
    for t in tests:
        for x, f, L, c, s in zip(t["height_m"], t["force_N"], t["piston_m"], t["compression"], t["step"], strict=True):
            out.append(
                f"{t['pressure_bar']:g},{x * 1e3:.3f},{f:.2f},{L * 1e3:.3f},{'compression' if c else 'rebound'},{int(s)}"
            )
    return "\n".join(out) + "\n"
