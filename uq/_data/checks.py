"""Plausibility of a campaign as a whole: unit slips, conventions, stand constants, outliers.

Each check sees the tests in SI (after the units of the column names are converted), so a file
in psi and inches is held to the same physics as one in bar and mm, and each names the column
with the unit the file used. The physics behind them (eqs. 1, 2, 5 of the paper):

* force over overpressure, P/p_u, is the effective area of an air spring (1 cm^2 .. 5 m^2);
* the volume-derived area dV/dx = S |dL/dx| is the same curve up to what the casing explains:
  the paper's spring has S|dL/dx| / (P/p_u) = 1.14 at 10 bar (averaged over the heights), the
  project's mechanisms (elastic casing, volume excess) move it by tens of percent, not by 1.5x;
* force grows with pressure and vanishes near p_u = 0, so forces that mostly read negative
  mean the other sign convention, and forces that extrapolate to zero near p_u = +1 bar mean
  absolute pressure in the gauge column.
"""

from __future__ import annotations

import math

import numpy as np
from numpy.polynomial import Polynomial

from uq._io.errors import InputError, where

#: Effective areas of air springs: from a 12 mm bellows to a 2.5 m one (m^2).
AREA_RANGE_M2 = (1.0e-4, 5.0)
#: S|dL/dx| / (P/p_u) at the highest pressure: what a casing can explain. From 1 bar up the
#: casing's own force is small against p_u F_eff (the paper's spring: 1.06 at 1 bar, 1.14 at 10).
AREA_RATIO_RANGE = (1 / 1.5, 1.5)
#: Below 1 bar the casing's force can rival p_u F_eff; only unit slips (factor 4) are caught.
AREA_RATIO_RANGE_LOW_PRESSURE = (0.25, 4.0)
AREA_RATIO_MIN_PRESSURE_BAR = 1.0
#: A reading is a gross outlier when it sits this far off the robust cubic of its branch, both
#: in robust standard deviations and as a share of the branch's range.
OUTLIER_SDS, OUTLIER_RANGE_SHARE, OUTLIER_MIN_POINTS = 10.0, 0.2, 8
#: Heights (as a share of the heights all tests cover) at which the zero-force pressure is read.
ZERO_FORCE_HEIGHTS = np.linspace(0.25, 0.75, 5)


def check_x0(name: str, tests, x0_mm: float) -> None:
    lo = min(float(t.height_m.min()) for t in tests) * 1e3
    hi = max(float(t.height_m.max()) for t in tests) * 1e3
    if not lo - 1e-9 <= x0_mm <= hi + 1e-9:
        raise InputError(
            f"{name}: `x0_mm` {x0_mm:g}: the reference height {x0_mm:g} mm lies outside the recorded heights {lo:g}..{hi:g} mm; "
            f"the coefficients would describe the element where it was never measured (try `x0_mm` {0.5 * (lo + hi):g})"
        )


def passes(t) -> list[np.ndarray]:
    """Indices of each monotone pass of a test: its compression and rebound branches, or the
    whole test when the order is unknown."""
    if t.compression is None:
        return [np.arange(t.n_points)]
    return [np.flatnonzero(t.compression == c) for c in (True, False)]


def _pass_means(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """(mean of y, mean of dy/dx) over the heights of one pass, from a least-squares cubic.

    Means over the height range, not over consecutive differences, so that steps of 0.01 mm
    (whose differences are mostly reading noise) give the same slope as steps of 5 mm.
    """
    deg = min(3, np.unique(x).size - 1)
    f = Polynomial.fit(x, y, deg)
    lo, hi = float(x.min()), float(x.max())
    integral = f.integ()
    return float((integral(hi) - integral(lo)) / (hi - lo)), float((f(hi) - f(lo)) / (hi - lo))


def mean_force_and_slope(t, values: np.ndarray) -> tuple[float, float]:
    """Mean force (N) and mean d(values)/dx of a test over its passes of two or more heights."""
    force, slope, weight = 0.0, 0.0, 0
    for sel in passes(t):
        if np.unique(t.height_m[sel]).size < 2:
            continue
        f, _ = _pass_means(t.height_m[sel], t.force_N[sel])
        _, s = _pass_means(t.height_m[sel], values[sel])
        force, slope, weight = force + f * sel.size, slope + s * sel.size, weight + sel.size
    return force / weight, slope / weight


def check_force_sign(name: str, tests, negative_declared: bool, column: str) -> None:
    """Force is compression positive: at the highest pressure most readings are positive."""
    t = max(tests, key=lambda t: t.pressure_bar)
    med = float(np.median(t.force_N))
    if med >= 0:
        return
    first = where(name, int(t.rows[0]), column)
    if negative_declared:
        raise InputError(
            f"{first}: `compression` negative: the {t.label} test's forces, sign reversed, are mostly negative "
            f"(median {med:.4g} N); the file already writes compression positive: drop the option"
        )
    raise InputError(
        f"{first}: the {t.label} test's forces are mostly negative (median {med:.4g} N), but compression is positive "
        "in this format: recorded with compression negative (a load-frame convention)? say so with "
        "`compression` negative"
    )


def zero_force_pressure_bar(tests) -> float:
    """The overpressure (bar) at which the force extrapolates to zero, across tests.

    At heights in the middle of the range all tests share, the force of each test (a cubic in
    height through its readings) against its pressure; a quadratic in pressure through three or
    more tests (a line through two), and its root nearest the lowest pressure; the median over
    the heights. Near 0 for gauge pressure (the casing's own force moves it by tenths of a bar
    at most), near +p_atm when the column holds absolute pressure. NaN with fewer than two
    tests or no common heights.
    """
    ps = np.array([t.pressure_bar for t in tests])
    if np.unique(ps).size < 2:
        return float("nan")
    lo = max(float(t.height_m.min()) for t in tests)
    hi = min(float(t.height_m.max()) for t in tests)
    if not hi > lo:
        return float("nan")
    heights = lo + ZERO_FORCE_HEIGHTS * (hi - lo)
    forces = np.array(
        [
            Polynomial.fit(t.height_m, t.force_N, min(3, np.unique(t.height_m).size - 1))(heights)
            for t in tests
        ]
    )  # (tests, heights)
    roots = []
    for force in forces.T:
        deg = 2 if ps.size >= 3 else 1
        r = Polynomial.fit(ps, force, deg).roots()
        r = r[np.abs(r.imag) < 1e-9].real
        if r.size:
            roots.append(float(r[np.argmin(np.abs(r - ps.min()))]))
    return float(np.median(roots)) if roots else float("nan")


def check_gauge(name: str, tests, column: str, absolute_declared: bool, p_atm_bar: float) -> None:
    """Gauge pressure, as the format says: the forces must extrapolate to zero near p_u = 0.

    Refused when the zero-force pressure lies nearer +p_atm than 0 (absolute pressure in the
    gauge column) or, after --absolute-pressure, nearer -p_atm (the column was gauge already).
    A single test cannot show it (its forces give no zero crossing).
    """
    p0 = zero_force_pressure_bar(tests)
    if not math.isfinite(p0):
        return
    if absolute_declared and p0 < -0.5 * p_atm_bar:
        raise InputError(
            f"{name}, column '{column}': `absolute_pressure`: after subtracting {p_atm_bar:g} bar the forces "
            f"extrapolate to zero at p_u = {p0:.2f} bar, not near 0: the column holds gauge pressure already; drop the option"
        )
    if not absolute_declared and p0 > 0.5 * p_atm_bar:
        raise InputError(
            f"{name}, column '{column}': the forces extrapolate to zero at {p0:.2f} bar, not near 0 bar: the column holds "
            f"absolute pressure (about {p_atm_bar:g} bar too high)? pressures here are gauge (over atmospheric); "
            "convert with `absolute_pressure`"
        )


def check_areas(
    name, tests, piston_area_m2: float, columns: dict, p_atm_bar: float | None = None
) -> None:
    """Unit slips and a wrong piston area, seen through the effective area (eqs. 1, 5).

    In the highest-pressure test: P/p_u (mean force over the height range, over the pressure)
    must be an air spring's area; with a piston, S|dL/dx| (mean slope over each pass) too, and
    their ratio within AREA_RATIO_RANGE (from 1 bar up; a factor 4 below). With a volume column,
    the same for dV/dx in the highest-pressure test that has volumes. ``columns``: quantity ->
    (header name, unit) of the file. ``p_atm_bar`` (None once the pressure is known to be
    absolute and converted): a ratio that absolute pressure in the gauge column would explain
    (P/p_u too small by p_u / (p_u + p_atm)) says so in the message.
    """
    lo, hi = AREA_RANGE_M2
    rng = f"{lo * 1e4:g} cm^2 .. {hi:g} m^2"
    force_col, force_unit = columns["force"]
    t = max(tests, key=lambda t: t.pressure_bar)
    first = where(name, int(t.rows[0]))
    a_force = mean_force_and_slope(t, t.force_N)[0] / t.pressure_Pa
    if a_force > 0 and not lo <= a_force <= hi:
        unit = "kN instead of N" if force_unit == "N" else f"a unit other than {force_unit}"
        raise InputError(
            f"{first}, column '{force_col}': the {t.label} test's forces over its overpressure give an effective area P/p_u of "
            f"{a_force * 1e4:.3g} cm^2, outside any air spring's ({rng}): force in {unit}, or pressure not in "
            f"{columns['pressure'][1]}?"
        )
    if "piston" in columns:
        col, unit = columns["piston"]
        slope = abs(mean_force_and_slope(t, t.piston_m)[1])
        a_volume = piston_area_m2 * slope
        if a_volume > 0 and not lo <= a_volume <= hi:
            slip = "in m instead of mm" if unit == "mm" else f"in a unit other than {unit}"
            raise InputError(
                f"{first}, column '{col}': the {t.label} test's piston travel gives a volume-derived effective area S|dL/dx| of "
                f"{a_volume * 1e4:.3g} cm^2, outside any air spring's ({rng}): piston coordinate {slip}, or a wrong `piston_area_cm2`?"
            )
        _check_ratio(
            first,
            t,
            a_force,
            a_volume,
            f"S|dL/dx| (S = {piston_area_m2 * 1e4:g} cm^2)",
            f"a wrong --piston-area-cm2 (the area S of the piston cavity), or a unit slip in {force_col}, "
            f"{columns['pressure'][0]} or {col}?",
            p_atm_bar,
        )
    if "volume" in columns:
        col, unit = columns["volume"]
        withv = [u for u in tests if u.volume_m3 is not None]
        v = max(withv, key=lambda u: u.pressure_bar)
        where_v = where(name, int(v.rows[0]), col)
        a_force_v, a_volume = mean_force_and_slope(v, v.volume_m3)
        a_force_v /= v.pressure_Pa
        if not a_volume > 0:
            raise InputError(
                f"{where_v}: the {v.label} test's volumes do not grow with the height (mean dV/dx {a_volume * 1e4:.3g} cm^2); "
                "an air spring's internal volume grows with its height (dV/dx = F_eff, eq. 2)"
            )
        if not lo <= a_volume <= hi:
            raise InputError(
                f"{where_v}: the {v.label} test's volumes give a volume-derived effective area dV/dx of {a_volume * 1e4:.3g} cm^2, "
                f"outside any air spring's ({rng}): volumes in a unit other than {unit}?"
            )
        _check_ratio(
            where(name, int(v.rows[0])),
            v,
            a_force_v,
            a_volume,
            "dV/dx",
            f"a unit slip in {force_col}, {columns['pressure'][0]} or {col}, or volumes of another element?",
            p_atm_bar,
        )


def _check_ratio(
    first: str, t, a_force: float, a_volume: float, what: str, cause: str, p_atm_bar=None
) -> None:
    if not (a_force > 0 and a_volume > 0):
        return
    low = t.pressure_bar < AREA_RATIO_MIN_PRESSURE_BAR
    r_lo, r_hi = AREA_RATIO_RANGE_LOW_PRESSURE if low else AREA_RATIO_RANGE
    ratio = a_volume / a_force
    if not r_lo <= ratio <= r_hi:
        p = t.pressure_bar
        if p_atm_bar is not None and p > p_atm_bar:
            gauge = ratio * (p - p_atm_bar) / p  # the ratio were the label p_u + p_atm
            if AREA_RATIO_RANGE[0] <= gauge <= AREA_RATIO_RANGE[1]:
                cause = (
                    cause.rstrip("?")
                    + ", or absolute pressure in the gauge column (--absolute-pressure)?"
                )
        raise InputError(
            f"{first}: the {t.label} test's force gives an effective area P/p_u of {a_force * 1e4:.3g} cm^2 but its "
            f"volume-derived area {what} is {a_volume * 1e4:.3g} cm^2 (ratio {ratio:.2f}; a casing explains "
            f"{r_lo:.2f}..{r_hi:.2f}, eqs. 1, 5): {cause}"
        )


def check_travel(name: str, tests, column: str) -> None:
    """A piston column must show the piston moving: without travel there is no volume."""
    still = [t for t in tests if np.ptp(t.piston_m) == 0]
    if len(still) == len(tests):
        raise InputError(
            f"{where(name, int(tests[0].rows[0]), column)}: the piston never moves (every test's readings are equal): "
            f"a column of zeros? for a force-only campaign omit the {column} column"
        )
    if still:
        t = still[0]
        raise InputError(
            f"{where(name, int(t.rows[0]), column)}: the piston does not move in the {t.label} test (all its readings are "
            f"{t.piston_m[0] * 1e3:g} mm) while it does in other tests: a test without piston readings?"
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


def check_outliers(name: str, t, columns: list[tuple[str, np.ndarray, float, str]]) -> None:
    """A gross outlier (a slipped decimal point, a stray key) in force, piston or volume is an error.

    Per pass (branch, or the whole test when the order is unknown), against a least-absolute-
    deviation cubic in height: a reading that sits more than OUTLIER_SDS robust standard
    deviations (1.4826 MAD) *and* more than OUTLIER_RANGE_SHARE of the pass's range off it.
    Passes with fewer than OUTLIER_MIN_POINTS readings are not checked. ``columns``: (header,
    values in SI, SI -> file unit factor, unit shown).
    """
    for k_pass, sel in enumerate(passes(t)):
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
                part, verb = (
                    ("readings", "run")
                    if t.compression is None
                    else (("compression" if k_pass == 0 else "rebound") + " branch", "runs")
                )
                remedy = (
                    "or remove the row and renumber the test's steps"
                    if t.step is not None
                    else "or remove the row"
                )
                raise InputError(
                    f"{where(name, int(t.rows[k]), column)}: {y[worst]:g} {unit} is a gross outlier: the {part} of the "
                    f"{t.label} test {verb} through about {fitted[worst]:.4g} {unit} at {t.height_m[k] * 1e3:g} mm "
                    f"({abs(r[worst]) / max(sd, 1e-300):.0f} robust SDs off); correct the value (a slipped decimal point?) "
                    f"{remedy}"
                )
