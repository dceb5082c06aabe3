"""Recordings: the CSV format of docs/formats.md section 1, read and validated in one place.

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
import io
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from uq._io.errors import InputError, where
from uq._physics.quantities import BAR_PA

REQUIRED_COLUMNS = ("pressure_bar", "height_mm", "force_N", "piston_mm", "branch", "step")
BRANCHES = ("compression", "rebound")

#: Default stand constants (the paper's): piston area S = 54.82 cm^2, basis height x0 = 112 mm.
DEFAULT_PISTON_AREA_CM2 = 54.82
DEFAULT_X0_MM = 112.0


@dataclass(frozen=True, eq=False)
class PressureTest:
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
    tests: tuple[PressureTest, ...]
    x0_m: float = DEFAULT_X0_MM * 1e-3
    piston_area_m2: float = DEFAULT_PISTON_AREA_CM2 * 1e-4
    extra_columns: tuple[str, ...] = field(default=())
    #: the file's leading ``#`` lines, without the ``#`` (what made the recordings, if it says)
    comments: tuple[str, ...] = field(default=())

    @property
    def pressures_bar(self) -> np.ndarray:
        return np.array([t.pressure_bar for t in self.tests])

    @property
    def n_points(self) -> int:
        return sum(t.n_points for t in self.tests)

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


def check_stand_options(piston_area_cm2: float, x0_mm: float) -> None:
    """Validate the stand constants given as options (names the option on failure)."""
    if not (math.isfinite(piston_area_cm2) and piston_area_cm2 > 0):
        raise InputError(
            f"option --piston-area-cm2: expected a positive area in cm^2, got {piston_area_cm2}"
        )
    if not (math.isfinite(x0_mm) and 1.0 <= x0_mm <= 5000.0):
        raise InputError(
            f"option --x0-mm: expected a reference height in mm (1..5000), got {x0_mm}"
        )


# ----------------------------------------------------------------------------- plausibility
# Ranges no air spring on a stand like the paper's leaves; wide on purpose, so other springs,
# pressures and stands pass, while the usual unit slips (mm x 1000, kN, kPa, m) do not.
MAX_PRESSURE_BAR = 60.0  # rubber-cord air springs burst far below; kPa for bar gives 100x
MAX_HEIGHT_MM = 5000.0  # also the upper end of --x0-mm; micrometres for mm give 1000x
MAX_ABS_FORCE_N = 1.0e8  # 100 MN, far above any air spring (10 bar on 3 m^2 is 3 MN)
MAX_ABS_PISTON_MM = 1.0e6
#: Effective areas of air springs: from a 12 mm bellows to a 2.5 m one (m^2).
AREA_RANGE_M2 = (1.0e-4, 5.0)
#: P/p_u and S|dL/dx| are the same curve in theory and within tens of percent in practice.
AREA_RATIO_MAX = 4.0
#: A reading is a gross outlier when it sits this far off the robust cubic of its branch, both
#: in robust standard deviations and as a share of the branch's range.
OUTLIER_SDS, OUTLIER_RANGE_SHARE, OUTLIER_MIN_POINTS = 10.0, 0.2, 8
DELIMITERS = {",": "','", ";": "';'", "\t": "tab"}


def _number(text, path: str, row: int, column: str, decimal_comma: bool = False) -> float:
    text = "" if text is None else str(text)
    shown = text.strip() or "(empty)"
    if "," in text and not decimal_comma:
        raise InputError(
            f"{where(path, row, column)}: '{shown}' is not a number (a decimal comma? in a comma-separated file write a decimal point)"
        )
    if decimal_comma:
        if (
            "." in text
        ):  # in a file of decimal commas a point can only be a thousands separator or a slip
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


def _integer(text, path: str, row: int, column: str, decimal_comma: bool = False) -> int:
    value = _number(text, path, row, column, decimal_comma)
    if value != int(value) or value < 0:
        raise InputError(
            f"{where(path, row, column)}: '{str(text).strip()}' is not a step number (0, 1, 2, ...)"
        )
    return int(value)


# ----------------------------------------------------------------------------- reading


def _decode(path: str) -> str:
    """The file's text: UTF-8 with or without BOM (Excel's "CSV UTF-8"), or UTF-16 with BOM."""
    try:
        with open(path, "rb") as fh:
            raw = fh.read()
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise InputError(f"{path}: is a folder, expected a recordings CSV file") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read the file ({exc.strerror or exc})") from None
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
        encoding = "utf-16"
    else:
        encoding = "utf-8-sig"
    try:
        return raw.decode(encoding)
    except UnicodeDecodeError as exc:
        row = raw[: exc.start].count(b"\n") + 1
        raise InputError(
            f"{where(path, row)}: not {encoding.upper().replace('-SIG', '')} text (byte 0x{raw[exc.start]:02x}); save the file as 'CSV UTF-8'"
        ) from None


def _delimiter(header_line: str) -> str:
    """The delimiter that splits the header into the most required column names (',' on a tie)."""

    def hits(sep: str) -> int:
        names = {h.strip().strip('"').strip() for h in header_line.split(sep)}
        return len(names & set(REQUIRED_COLUMNS))

    return max(DELIMITERS, key=hits)  # max keeps the first of equals: ','


def _table(path: str, numbered: list[tuple[int, str]], sep: str) -> list[tuple[int, list]]:
    """Tokenise the rows with pandas' CSV reader; each row as (file line, fields).

    Every line is prefixed with its file line number as an extra first field, so rows keep
    their line numbers through the reader, also those it sets aside for too many fields.
    Short rows come back padded with NaN, which the caller counts as missing fields.
    """
    import pandas as pd

    text = "\n".join(f"{n}{sep}{line}" for n, line in numbered)
    extra: list[list[str]] = []
    try:
        df = pd.read_csv(
            io.StringIO(text),
            sep=sep,
            header=None,
            dtype=str,
            keep_default_na=False,
            na_filter=False,
            engine="python",
            skip_blank_lines=False,
            quoting=csv.QUOTE_MINIMAL,
            on_bad_lines=lambda fields: extra.append(fields) or None,
        )
    except (pd.errors.ParserError, csv.Error) as exc:
        raise InputError(
            f"{path}: cannot split the rows into columns ({' '.join(str(exc).split())})"
        ) from None
    rows = [(r[0], list(r[1:])) for r in df.itertuples(index=False, name=None)] + [
        (r[0], list(r[1:])) for r in extra
    ]
    out = []
    for line, fields in rows:
        if not str(line).isdigit() or any("\n" in str(f) for f in fields if isinstance(f, str)):
            first = next((n for n, ln in numbered if ln.count('"') % 2), numbered[0][0])
            raise InputError(
                f'{where(path, first)}: a quote (") opened on this line is not closed on it'
            )
        out.append((int(line), fields))
    return sorted(out, key=lambda r: r[0])


def _fields_found(fields: list) -> int:
    return sum(1 for f in fields if isinstance(f, str))


def read_recordings(
    path: str | Path,
    *,
    piston_area_cm2: float = DEFAULT_PISTON_AREA_CM2,
    x0_mm: float = DEFAULT_X0_MM,
    min_points: int = 6,
) -> Recordings:
    """Read and validate a recordings CSV (docs/formats.md section 1).

    Parameters
    ----------
    path : the CSV file: UTF-8 (a BOM is fine), columns separated by ',' (or ';' or tab,
        where a decimal comma is then also understood).
    piston_area_cm2 : area S of the hydraulic cylinder's piston cavity (eq. 5), cm^2.
    x0_mm : reference height x0 of the polynomial basis u = x - x0 (eqs. 8, 9), mm; must lie
        within the recorded heights.
    min_points : the fewest points a test may have (the model's parameter count).

    Raises
    ------
    InputError : one line naming file, row and column of the first defect found: format
        defects, values beyond any air spring, unit slips (heights in m or um, force in kN,
        pressure in kPa, piston in m) and gross outliers (docs/formats.md).
    """
    check_stand_options(piston_area_cm2, x0_mm)
    path = str(path)
    return recordings_from_text(
        _decode(path), path, piston_area_cm2=piston_area_cm2, x0_mm=x0_mm, min_points=min_points
    )


def recordings_from_text(
    text: str,
    name: str = "<text>",
    *,
    piston_area_cm2: float = DEFAULT_PISTON_AREA_CM2,
    x0_mm: float = DEFAULT_X0_MM,
    min_points: int = 6,
) -> Recordings:
    """:func:`read_recordings` on CSV text already in memory; ``name`` stands for the file in
    messages and becomes ``Recordings.path``."""
    check_stand_options(piston_area_cm2, x0_mm)
    path = str(name)
    lines = text.splitlines()
    numbered = [
        (i + 1, line)
        for i, line in enumerate(lines)
        if line.strip() and not line.lstrip().startswith("#")
    ]
    if not numbered:
        raise InputError(
            f"{path}: empty file, expected a header row with columns {', '.join(REQUIRED_COLUMNS)}"
        )
    sep = _delimiter(numbered[0][1])
    table = _table(path, numbered, sep)
    (header_row, header_fields), body = table[0], table[1:]
    header = [str(h).strip() for h in header_fields if isinstance(h, str)]
    seen = _header_index(path, header_row, header, sep)
    body = [
        (row, fields)
        for row, fields in body
        if any(isinstance(f, str) and f.strip() for f in fields)
    ]
    if not body:
        raise InputError(f"{path}: no data rows after the header")
    decimal_comma = sep != "," and any(
        "," in str(fields[seen[c]])
        for _, fields in body
        for c in REQUIRED_COLUMNS
        if c != "branch" and seen[c] < len(fields)
    )
    groups: dict[float, list[tuple]] = {}
    for row, fields in body:
        p, r = _parse_row(path, row, fields, header, seen, sep, decimal_comma)
        groups.setdefault(p, []).append(r)

    all_heights = np.array([r[1] for g in groups.values() for r in g])
    if all_heights.max() < 2.0:
        row = next(r[0] for g in groups.values() for r in g)
        raise InputError(
            f"{where(path, row, 'height_mm')}: heights are at most {all_heights.max():g}, which looks like metres; the column height_mm is in mm"
        )

    tests = [
        _make_test(path, p, rows, min_points)
        for p, rows in sorted(groups.items(), key=lambda kv: kv[0])
    ]
    _check_x0(path, tests, x0_mm)
    _check_units(path, tests, piston_area_cm2 * 1e-4)
    for t in tests:
        _check_outliers(path, t)
    extra = tuple(h for h in header if h and h not in REQUIRED_COLUMNS)
    return Recordings(
        path=path,
        tests=tuple(tests),
        x0_m=x0_mm * 1e-3,
        piston_area_m2=piston_area_cm2 * 1e-4,
        extra_columns=extra,
        comments=tuple(leading_comments(lines)),
    )


def leading_comments(lines) -> list[str]:
    """The ``#`` lines before the first other non-blank line, without the ``#``."""
    out = []
    for line in lines:
        s = line.strip()
        if not s:
            continue
        if not s.startswith("#"):
            break
        out.append(s.lstrip("#").strip())
    return out


def _header_index(path: str, header_row: int, header: list[str], sep: str) -> dict[str, int]:
    seen: dict[str, int] = {}
    for i, h in enumerate(header):
        if h in seen and h:  # unnamed columns (Excel pads with them) are ignored like extra ones
            raise InputError(f"{where(path, header_row)}: column '{h}' appears twice in the header")
        seen.setdefault(h, i)
    for col in REQUIRED_COLUMNS:
        if col not in seen:
            if col == "height_mm" and "height_m" in seen:
                raise InputError(
                    f"{where(path, header_row)}: column 'height_mm' missing; found 'height_m': heights must be given in mm"
                )
            hint = "" if len(header) > 1 else "; columns must be separated by ',' (or ';' or tab)"
            raise InputError(
                f"{where(path, header_row)}: missing column '{col}' (header has: {', '.join(header)}){hint}"
            )
    return seen


def _parse_row(path, row, fields, header, idx, sep, decimal_comma) -> tuple[float, tuple]:
    found = _fields_found(fields)
    if found != len(header):
        hint = (
            " (a decimal comma? use decimal points, or separate the columns by ';')"
            if sep == "," and found > len(header)
            else ""
        )
        raise InputError(
            f"{where(path, row)}: expected {len(header)} fields as in the header (separated by {DELIMITERS[sep]}), found {found}{hint}"
        )
    p = _number(fields[idx["pressure_bar"]], path, row, "pressure_bar", decimal_comma)
    x = _number(fields[idx["height_mm"]], path, row, "height_mm", decimal_comma)
    f = _number(fields[idx["force_N"]], path, row, "force_N", decimal_comma)
    L = _number(fields[idx["piston_mm"]], path, row, "piston_mm", decimal_comma)
    br = str(fields[idx["branch"]]).strip()
    st = _integer(fields[idx["step"]], path, row, "step", decimal_comma)
    if p <= 0:
        raise InputError(
            f"{where(path, row, 'pressure_bar')}: overpressure {p:g} bar is not positive; tests run at a set overpressure above 0 bar"
        )
    if p > MAX_PRESSURE_BAR:
        raise InputError(
            f"{where(path, row, 'pressure_bar')}: {p:g} bar is beyond the overpressures air springs are tested at (at most {MAX_PRESSURE_BAR:g} bar): kPa or Pa given instead of bar?"
        )
    if x <= 0:
        raise InputError(f"{where(path, row, 'height_mm')}: height {x:g} mm is not positive")
    if x > MAX_HEIGHT_MM:
        raise InputError(
            f"{where(path, row, 'height_mm')}: height {x:g} mm is beyond any air spring (at most {MAX_HEIGHT_MM:g} mm): micrometres given instead of mm, or a typo?"
        )
    if abs(f) > MAX_ABS_FORCE_N:
        raise InputError(
            f"{where(path, row, 'force_N')}: force {f:g} N is beyond any air spring (at most {MAX_ABS_FORCE_N:g} N in magnitude): a typo or a wrong unit?"
        )
    if abs(L) > MAX_ABS_PISTON_MM:
        raise InputError(
            f"{where(path, row, 'piston_mm')}: piston coordinate {L:g} mm is beyond any stand (at most {MAX_ABS_PISTON_MM:g} mm in magnitude): a typo or a wrong unit?"
        )
    if br not in BRANCHES:
        raise InputError(
            f"{where(path, row, 'branch')}: '{br}' is not a branch; expected 'compression' or 'rebound'"
        )
    return p, (row, x, f, L, br == "compression", st)


def _make_test(path: str, p: float, rows: list[tuple], min_points: int) -> PressureTest:
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
        after = min(s for s in steps if s > missing)
        raise InputError(
            f"{where(path, by_step[after][0], 'step')}: steps of the {label} should run 0, 1, 2, ... without gaps; step {missing} is missing before this row's step {after}"
        )
    ordered = [by_step[s] for s in steps]
    row_ids = np.array([r[0] for r in ordered])
    height = np.array([r[1] for r in ordered]) * 1e-3
    comp = np.array([r[4] for r in ordered], dtype=bool)

    if len(ordered) < min_points or np.unique(np.round(height, 9)).size < 4:
        raise InputError(
            f"{where(path, rows[0][0])}: the {label} has {len(ordered)} points at {np.unique(np.round(height, 9)).size} heights; the model needs at least {min_points} points at 4 or more heights"
        )
    _check_branch_order(path, label, height, comp, row_ids)
    return PressureTest(
        pressure_bar=float(p),
        height_m=height,
        force_N=np.array([r[2] for r in ordered], dtype=float),
        piston_m=np.array([r[3] for r in ordered], dtype=float) * 1e-3,
        compression=comp,
        step=np.array(steps, dtype=int),
        rows=row_ids,
    )


def _check_branch_order(path: str, label: str, height, comp, row_ids) -> None:
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
        name = "compression" if branch_is_comp else "rebound"
        before = f"{h[j - 1] * 1e3:g} mm before it" if j > 0 else "first of its branch"
        after = f"{h[j + 1] * 1e3:g} mm after it" if j + 1 < h.size else "last of its branch"
        raise InputError(
            f"{where(path, int(row_ids[sel[j]]), 'height_mm')}: heights on the {name} branch of the {label} must {word} step by step, but this row's {h[j] * 1e3:g} mm does not ({before}, {after})"
        )


def _odd_one(h: np.ndarray, k: int) -> int:
    """Of the pair (k, k+1) that breaks a monotone run, the index that fits its neighbours worst."""
    step = float(np.median(np.diff(h)))

    def misfit(j: int) -> float:
        if 0 < j < h.size - 1:
            return abs(h[j] - 0.5 * (h[j - 1] + h[j + 1]))
        return abs(h[j] - (h[j + 1] - step if j == 0 else h[j - 1] + step))

    return k if misfit(k) > misfit(k + 1) else k + 1


def _check_x0(path: str, tests: list[PressureTest], x0_mm: float) -> None:
    lo = min(float(t.height_m.min()) for t in tests) * 1e3
    hi = max(float(t.height_m.max()) for t in tests) * 1e3
    if not lo - 1e-9 <= x0_mm <= hi + 1e-9:
        raise InputError(
            f"{path}: option --x0-mm: the reference height {x0_mm:g} mm lies outside the recorded heights {lo:g}..{hi:g} mm; "
            f"the coefficients would describe the element where it was never measured (try --x0-mm {0.5 * (lo + hi):g})"
        )


def _volume_slope(t: PressureTest) -> float:
    """Median |dL/dx| over consecutive readings of one branch (robust to a stray reading)."""
    same = t.compression[1:] == t.compression[:-1]
    dx, dL = np.diff(t.height_m)[same], np.diff(t.piston_m)[same]
    ok = dx != 0
    return float(np.median(np.abs(dL[ok] / dx[ok]))) if ok.any() else float("nan")


def _check_units(path: str, tests: list[PressureTest], piston_area_m2: float) -> None:
    """Unit slips seen through the effective area (eqs. 1, 5) of the highest-pressure test.

    Force over overpressure and piston travel times S are both the effective area; each must be
    an air spring's, and they must agree within a factor AREA_RATIO_MAX. The highest pressure is
    used because there the casing's own force matters least.
    """
    t = max(tests, key=lambda t: t.pressure_bar)
    first = where(path, int(t.rows[0]))
    lo, hi = AREA_RANGE_M2
    rng = f"{lo * 1e4:g} cm^2 .. {hi:g} m^2"
    a_force = float(np.median(t.force_N)) / t.pressure_Pa
    a_volume = piston_area_m2 * _volume_slope(t)
    if a_force > 0 and not lo <= a_force <= hi:
        raise InputError(
            f"{first}, column 'force_N': the {t.label} test's forces over its overpressure give an effective area P/p_u of "
            f"{a_force * 1e4:.3g} cm^2, outside any air spring's ({rng}): force in kN instead of N, or pressure not in bar?"
        )
    if math.isfinite(a_volume) and a_volume > 0 and not lo <= a_volume <= hi:
        raise InputError(
            f"{first}, column 'piston_mm': the {t.label} test's piston travel gives a volume-derived effective area S|dL/dx| of "
            f"{a_volume * 1e4:.3g} cm^2, outside any air spring's ({rng}): piston coordinate in m instead of mm, or a wrong --piston-area-cm2?"
        )
    if (
        a_force > 0
        and a_volume > 0
        and not 1 / AREA_RATIO_MAX <= a_force / a_volume <= AREA_RATIO_MAX
    ):
        raise InputError(
            f"{first}: the {t.label} test's force gives an effective area P/p_u of {a_force * 1e4:.3g} cm^2 but its piston travel "
            f"S|dL/dx| {a_volume * 1e4:.3g} cm^2; eqs. 1 and 5 make them nearly equal: a unit slip in force_N, pressure_bar "
            f"or piston_mm, or a wrong --piston-area-cm2?"
        )


def _robust_cubic(x: np.ndarray, y: np.ndarray, iterations: int = 40) -> np.ndarray:
    """Least-absolute-deviation cubic of y over x (IRLS): one wild reading cannot pull it."""
    t = (x - x.mean()) / max(float(np.ptp(x)) / 2, 1e-12)
    A = np.vander(t, 4)
    tiny = 1e-9 * (float(np.ptp(y)) + float(np.median(np.abs(y))) + 1e-12)
    w = np.ones_like(y)
    for _ in range(iterations):
        sw = np.sqrt(w)
        beta = np.linalg.lstsq(A * sw[:, None], y * sw, rcond=None)[0]
        w = 1.0 / np.maximum(np.abs(y - A @ beta), tiny)
    return A @ beta


def _check_outliers(path: str, t: PressureTest) -> None:
    """A gross outlier (a slipped decimal point, a stray key) in force or piston is an error.

    Per branch, against a least-absolute-deviation cubic in height: a reading that sits more than
    OUTLIER_SDS robust standard deviations (1.4826 MAD) *and* more than OUTLIER_RANGE_SHARE of the
    branch's range off it. Branches with fewer than OUTLIER_MIN_POINTS readings are not checked.
    """
    columns = (("force_N", t.force_N, 1.0, "N"), ("piston_mm", t.piston_m, 1e3, "mm"))
    for comp in (True, False):
        sel = np.flatnonzero(t.compression == comp)
        if sel.size < OUTLIER_MIN_POINTS:
            continue
        for column, values, scale, unit in columns:
            y = values[sel] * scale
            fitted = _robust_cubic(t.height_m[sel], y)
            r = y - fitted
            sd = 1.4826 * float(np.median(np.abs(r)))
            limit = max(OUTLIER_SDS * sd, OUTLIER_RANGE_SHARE * float(np.ptp(fitted)))
            worst = int(np.argmax(np.abs(r)))
            if abs(r[worst]) > limit:
                k = sel[worst]
                branch = "compression" if comp else "rebound"
                raise InputError(
                    f"{where(path, int(t.rows[k]), column)}: {y[worst]:g} {unit} is a gross outlier: the {branch} branch of the "
                    f"{t.label} test runs through about {fitted[worst]:.4g} {unit} at {t.height_m[k] * 1e3:g} mm "
                    f"({abs(r[worst]) / max(sd, 1e-300):.0f} robust SDs off); correct the value (a slipped decimal point?) "
                    f"or remove the row and renumber the test's steps"
                )


def write_recordings_csv(tests: list[dict], header_comment: str = "") -> str:
    """Format recordings as CSV text (docs/formats.md section 1).

    ``tests``: dicts with keys pressure_bar, height_m, force_N, piston_m, compression, step
    (arrays). Numbers are printed at a fixed precision so that files are byte-reproducible.
    """
    out = []
    for line in header_comment.splitlines():
        out.append(f"# {line}".rstrip())
    out.append(",".join(REQUIRED_COLUMNS))
    for t in tests:
        for x, f, L, c, s in zip(
            t["height_m"], t["force_N"], t["piston_m"], t["compression"], t["step"], strict=True
        ):
            out.append(
                f"{t['pressure_bar']:g},{x * 1e3:.3f},{f:.2f},{L * 1e3:.3f},{'compression' if c else 'rebound'},{int(s)}"
            )
    return "\n".join(out) + "\n"
