"""Which readings form one test: by the set pressure, or by clustering measured pressures.

A test is all readings taken at one set overpressure. Files say which in one of three ways:

1. A ``set_pressure_*`` column: readings with the same set value are one test, and the
   ``pressure_*`` column is each reading's measured overpressure. A measured value farther than
   the tolerance from its set value is refused (a typo, or absolute pressure in one column).
2. No set column, and the pressure column repeats one value per test (the paper's format): each
   value is one test, exactly as the file says. Measured pressure then equals the set value.
3. No set column, and the pressures scatter around set points (4.993, 5.004, ...): the readings
   are clustered. Sorted, they split wherever two neighbours differ by more than the tolerance;
   each cluster is one test, whose set value is the median rounded to the coarsest of 1, 0.5,
   0.1, 0.05, ... units of the file that lies within three standard errors and 0.1 % (a sensor's
   calibration) of the median (so 4.9987 bar gives 5 bar, 80.003 psi gives 80 psi). Refused when ambiguous: a reading farther
   than the tolerance from its cluster's median, a cluster too small for a test, or a value
   shared by most but not all of a cluster's readings (a typo in a file of set pressures).

The tolerance is ``--pressure-tolerance-bar`` when given, otherwise max(0.05 bar, 2 % of the
pressure): wide enough for the paper's holding error (0.01 bar, so readings stay within about
0.04 bar of the set point), far below the spacing of tests in any campaign we know of (0.5 bar
and more from 1 bar up). Tests closer than that need a ``set_pressure_*`` column or a smaller
tolerance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from uq._io.errors import InputError, where

TOLERANCE_FLOOR_BAR = 0.05
TOLERANCE_REL = 0.02
#: A measured pressure this close to 1 atm off its set value suggests absolute pressure.
ATM_HINT_BAR = 0.2


def tolerance_bar(p_bar, tolerance: float | None = None) -> np.ndarray:
    """The grouping tolerance (bar) at overpressure ``p_bar``: the option, or max(0.05, 2 %)."""
    p = np.asarray(p_bar, float)
    if tolerance is not None:
        return np.full_like(p, tolerance)
    return np.maximum(TOLERANCE_FLOOR_BAR, TOLERANCE_REL * np.abs(p))


@dataclass(frozen=True)
class Group:
    """One test's readings: its set overpressure (bar) and their indices in file order."""

    set_bar: float
    index: np.ndarray


@dataclass(frozen=True)
class PressureColumns:
    """What the grouping needs of the file: names and unit factors (file unit -> bar)."""

    name: str  # the file, as messages name it
    column: str  # the pressure column's header, e.g. pressure_psi
    unit: str
    factor: float
    set_column: str | None = None
    p_atm_bar: float = 1.01325


def group(
    cols: PressureColumns,
    rows: np.ndarray,
    pressure_bar: np.ndarray,
    set_bar: np.ndarray | None,
    min_points: int,
    tolerance: float | None = None,
) -> tuple[list[Group], bool]:
    """The tests of a campaign, by set pressure (ascending), and whether pressure was measured.

    ``rows``: file row of each reading (n,); ``pressure_bar``: the pressure column in bar gauge
    (n,); ``set_bar``: the set-pressure column in bar gauge, or None.
    """
    if set_bar is not None:
        return _by_set_pressure(cols, rows, pressure_bar, set_bar, tolerance), True
    clusters = _clusters(pressure_bar, tolerance)
    if all(np.unique(pressure_bar[c]).size == 1 for c in clusters):
        return [Group(float(pressure_bar[c[0]]), np.sort(c)) for c in clusters], False
    return [
        _measured_test(cols, rows, pressure_bar, c, min_points, tolerance) for c in clusters
    ], True


def _by_set_pressure(cols, rows, pressure_bar, set_bar, tolerance) -> list[Group]:
    off = np.abs(pressure_bar - set_bar)
    tol = tolerance_bar(set_bar, tolerance)
    bad = np.flatnonzero(off > tol)
    if bad.size:
        k = bad[np.argmin(rows[bad])]
        hint = (
            "absolute pressure in one of the columns (then `absolute_pressure` applies to both)?"
            if abs(off[k] - cols.p_atm_bar) < ATM_HINT_BAR
            else "a typo?"
        )
        raise InputError(
            f"{where(cols.name, int(rows[k]), cols.column)}: measured {pressure_bar[k]:g} bar is {off[k]:.3g} bar off its "
            f"test's set {set_bar[k]:g} bar ({cols.set_column}), beyond the tolerance +-{tol[k]:.3g} bar "
            f"(`pressure_tolerance_bar`): {hint}"
        )
    return [Group(float(s), np.flatnonzero(set_bar == s)) for s in np.unique(set_bar)]


def _clusters(p: np.ndarray, tolerance: float | None) -> list[np.ndarray]:
    """Indices of the readings, split where sorted neighbours differ by more than the tolerance."""
    order = np.argsort(p, kind="stable")
    s = p[order]
    gaps = np.diff(s)
    cut = np.flatnonzero(gaps > tolerance_bar(0.5 * (s[1:] + s[:-1]), tolerance)) + 1
    return np.split(order, cut)


def _measured_test(cols, rows, p, idx, min_points, tolerance) -> Group:
    values, counts = np.unique(p[idx], return_counts=True)
    file_rows = rows[idx]
    first = int(file_rows.min())
    col, unit = cols.column, cols.unit
    mode = int(np.argmax(counts))
    if values.size > 1 and 2 * counts[mode] > idx.size:
        odd = idx[p[idx] != values[mode]]
        k = odd[np.argmin(rows[odd])]
        raise InputError(
            f"{where(cols.name, int(rows[k]), col)}: {p[k] / cols.factor:g} {unit} differs from the "
            f"{values[mode] / cols.factor:g} {unit} of {counts[mode]} other readings at that pressure: a typo? "
            "(measured pressures vary from reading to reading; to give both, add a set_pressure_* column)"
        )
    lo, hi = float(p[idx].min()), float(p[idx].max())
    med = float(np.median(p[idx]))
    tol = float(tolerance_bar(med, tolerance))
    rule = (
        f"without a set_pressure_* column, the {col} column must hold each test's set pressure on "
        f"every row, or each reading's measured pressure within +-{tol:.3g} bar of it "
        f"(--pressure-tolerance-bar)"
    )
    if idx.size < min_points:
        raise InputError(
            f"{where(cols.name, first, col)}: only {idx.size} {'reading has a pressure' if idx.size == 1 else 'readings have pressures'} near {med:g} bar "
            f"({lo:g}..{hi:g} bar), too few for a test (at least {min_points}); {rule}"
        )
    far = np.abs(p[idx] - med)
    if far.max() > tol:
        k = idx[int(np.argmax(far))]
        raise InputError(
            f"{where(cols.name, int(rows[k]), col)}: {p[k]:g} bar lies {far.max():.3g} bar from the median "
            f"{med:g} bar of the readings it clusters with ({lo:g}..{hi:g} bar), beyond the tolerance "
            f"+-{tol:.3g} bar: two tests this close? {rule}; or add a set_pressure_* column"
        )
    return Group(set_value_bar(p[idx], cols.factor), np.sort(idx))


#: The relative accuracy of a pressure sensor (the paper's: 0.1 %), allowed between a cluster's
#: median and the set point it rounds to.
SENSOR_ACCURACY = 0.001
ROUNDING_STEPS = (1.0, 0.5, 0.1, 0.05, 0.01, 0.005, 0.001, 0.0005, 0.0001)


def set_value_bar(p_bar: np.ndarray, factor: float = 1.0) -> float:
    """A cluster's set value: its median rounded as a set point is written, in the file's unit.

    The coarsest of ROUNDING_STEPS (in the unit whose factor to bar is ``factor``) that lies
    within the readings' range and within three standard errors of the median (1.2533 x 1.4826
    MAD / sqrt(n)) plus SENSOR_ACCURACY of it (a sensor's calibration moves every reading of a
    campaign alike, which no standard error shows); the median to 1e-4 units when none does.

    >>> set_value_bar(np.array([4.993, 5.004, 4.998, 5.001, 4.999, 5.002]))
    5.0
    >>> set_value_bar(np.array([1.018, 1.022, 1.021, 1.019, 1.020, 1.020, 1.021]))
    1.02
    """
    v = np.asarray(p_bar, float) / factor
    med = float(np.median(v))
    mad = 1.4826 * float(np.median(np.abs(v - med)))
    se = 1.2533 * mad / math.sqrt(v.size)
    for step in ROUNDING_STEPS:
        r = round(med / step) * step
        if abs(r - med) <= 3.0 * se + SENSOR_ACCURACY * med and v.min() <= r <= v.max() and r > 0:
            return float(f"{r:.10g}") * factor
    return float(f"{round(med, 4):.10g}") * factor
