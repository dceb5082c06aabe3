"""Recordings as CSV text: the paper's full format by default, or the shapes real stands and
catalogues give (other units, measured pressure, no piston, one pass, rounded values).

The virtual stand (``uq simulate``) writes through here, so every shape the reader accepts can be
made and read back in the tests.
"""

from __future__ import annotations

import csv
import io

from uq._data import units as _units

#: Printed decimals per (quantity, unit): 0.001 mm, 0.01 N and their equivalents (about 1e-3
#: of a typical reading's scatter), so that files are byte-reproducible.
_DECIMALS = {
    ("height", "mm"): 3,
    ("height", "m"): 6,
    ("height", "in"): 5,
    ("force", "N"): 2,
    ("force", "kN"): 5,
    ("force", "lbf"): 3,
    ("piston", "mm"): 3,
    ("piston", "m"): 6,
    ("piston", "in"): 5,
    ("volume", "l"): 5,
    ("volume", "cm3"): 2,
    ("volume", "m3"): 8,
    ("volume", "in3"): 3,
}
#: Measured pressure to 1 Pa (the paper's sensor resolution) in bar; other units to 15 digits (read back to 12, the exact bar value).
_MEASURED_BAR_DECIMALS = 5
WRITE_PRESSURE = ("set", "measured", "both")


def _decimals(step: float) -> int:
    """Decimals that print multiples of ``step`` exactly (10 -> 0, 0.5 -> 1, 0.25 -> 2)."""
    return len(f"{step:f}".rstrip("0").split(".")[1])


def write_recordings_csv(
    tests: list[dict],
    header_comment: str = "",
    *,
    units: dict | None = None,
    pressure: str = "set",
    order: bool = True,
    piston: bool = True,
    volume: bool = False,
    compression_negative: bool = False,
    rounding: dict | None = None,
) -> str:
    """Format recordings as CSV text (docs/formats.md section 1).

    ``tests``: dicts of arrays with keys pressure_bar (the set value, a float), height_m,
    force_N, piston_m, compression, step, and where used measured_pressure_bar (n,) and
    volume_m3 ((n,) or None). With the defaults the paper's full format in bar, mm and N.

    units : quantity -> unit suffix (uq._data.units) for pressure, height, force, piston,
        volume; the paper's units (and litres) where not given. Length units apply to height
        and piston alike unless given separately.
    pressure : "set" (the pressure column holds the test's set value), "measured" (each
        reading's measured pressure, no set column) or "both" (set_pressure_* and the measured
        pressure_*).
    order, piston, volume : write branch and step; the piston column; a volume column (empty
        on the rows of tests without volume_m3).
    compression_negative : write force with compression negative (a load frame's convention).
    rounding : quantity -> step in the file's unit to round to, as catalogues print (e.g.
        {"force": 10.0, "height": 1.0, "volume": 0.01}).

    Numbers are printed at a fixed precision (_DECIMALS) so that files are byte-reproducible.
    """
    if pressure not in WRITE_PRESSURE:
        raise ValueError(f"pressure must be one of {WRITE_PRESSURE}, got {pressure!r}")
    u = dict(_units.PAPER_UNITS, volume="l") | dict(units or {})
    if "height" in (units or {}) and "piston" not in units:
        u["piston"] = units["height"]
    u.setdefault("set_pressure", u["pressure"])
    rounding = dict(rounding or {})

    def fmt(quantity: str, value: float) -> str:
        suffix = u[quantity]
        v = value * (1.0 / _units.factor(quantity, suffix))
        if quantity in rounding:
            step = rounding[quantity]
            return f"{round(v / step) * step:.{_decimals(step)}f}"
        if quantity in ("pressure", "set_pressure"):
            if measured_column and quantity == "pressure":
                return f"{v:.{_MEASURED_BAR_DECIMALS}f}" if suffix == "bar" else f"{v:.15g}"
            return f"{v:g}" if suffix == "bar" else f"{v:.15g}"
        return f"{v:.{_DECIMALS[(quantity, suffix)]}f}"

    measured_column = pressure != "set"
    columns = (["set_pressure"] if pressure == "both" else []) + ["pressure", "height", "force"]
    columns += (["piston"] if piston else []) + (["volume"] if volume else [])
    header = [f"{q}_{u[q]}" for q in columns] + (["branch", "step"] if order else [])
    out = [f"# {line}".rstrip() for line in header_comment.splitlines()]
    out.append(",".join(header))
    sign = -1.0 if compression_negative else 1.0
    for t in tests:
        n = len(t["height_m"])
        p_set = float(t["pressure_bar"])
        measured = t.get("measured_pressure_bar") if measured_column else None
        vol = t.get("volume_m3") if volume else None
        for i in range(n):
            cells = []
            for q in columns:
                if q == "set_pressure":
                    cells.append(fmt(q, p_set))
                elif q == "pressure":
                    cells.append(fmt(q, measured[i] if measured is not None else p_set))
                elif q == "height":
                    cells.append(fmt(q, t["height_m"][i]))
                elif q == "force":
                    cells.append(fmt(q, sign * t["force_N"][i]))
                elif q == "piston":
                    cells.append(fmt(q, t["piston_m"][i]))
                else:
                    cells.append("" if vol is None else fmt(q, vol[i]))
            if order:
                cells += [
                    "compression" if t["compression"][i] else "rebound",
                    str(int(t["step"][i])),
                ]
            out.append(",".join(cells))
    return "\n".join(out) + "\n"


#: The column names of the Bluehill-shaped export (uq simulate --instrument bluehill): Bluehill's
#: own channel names for time and load, and the names a method gives the frame's position (set
#: to read the distance between the flanges) and an auxiliary pressure transducer.
BLUEHILL_HEADER = {"time": "Time", "height": "Position", "force": "Load", "pressure": "Pressure"}
BLUEHILL_UNITS = {"pressure": "bar", "height": "mm", "force": "kN"}
#: Seconds between two readings (a step and its dwell), for the export's Time column.
BLUEHILL_DWELL_S = 20.0


def write_bluehill_csv(
    tests: list[dict], header_comment: str = "", *, units: dict | None = None
) -> str:
    """Recordings in the shape of an Instron Bluehill RawData export (docs/recordings.md).

    What such a file looks like (an exported ``Specimen_RawData_1.csv``): title rows ``Text Inputs
    : ...`` and ``General : ...`` (here one per line of ``header_comment``), a blank line, the
    header ``Time,Position,Load,Pressure``, a units row ``(s),(mm),(kN),(bar)``, then one row per
    reading in recording order, compressive load negative (the frame's convention). A load frame
    records no piston and no branch or step, so each test is written as its compression pass
    only (one pass per pressure, heights decreasing), with each reading's measured pressure
    (``measured_pressure_bar`` of the tests, else the set value). ``units``: pressure, height and
    force units (uq._data.units suffixes); Bluehill's usual bar, mm and kN when not given.

    Read it with ``--columns height=Position,force=Load --compression negative``: the header below
    the title and the units row are found and noted.
    """
    u = dict(BLUEHILL_UNITS) | dict(units or {})
    out = io.StringIO()
    w = csv.writer(out, lineterminator="\n")
    lines = [ln for ln in header_comment.splitlines() if ln.strip()]
    w.writerow(["Text Inputs : Specimen label", "N-50 air spring (RECONSTRUCTED)"])
    for i, line in enumerate(lines, 1):
        w.writerow([f"Text Inputs : Note {i}", line])
    out.write("\n")
    w.writerow([BLUEHILL_HEADER[q] for q in ("time", "height", "force", "pressure")])
    w.writerow(["(s)"] + [f"({_units.shown(u[q])})" for q in ("height", "force", "pressure")])
    k = 0
    for t in tests:
        measured = t.get("measured_pressure_bar")
        for i in range(len(t["height_m"])):
            if not t["compression"][i]:
                continue
            p = measured[i] if measured is not None else t["pressure_bar"]
            cells = [
                f"{k * BLUEHILL_DWELL_S:.5f}",
                f"{t['height_m'][i] / _units.factor('height', u['height']):.{_DECIMALS[('height', u['height'])]}f}",
                f"{-t['force_N'][i] / _units.factor('force', u['force']):.{_DECIMALS[('force', u['force'])]}f}",
                _pressure_text(p, u["pressure"]),
            ]
            w.writerow(cells)
            k += 1
    return out.getvalue()


def _pressure_text(p_bar: float, suffix: str) -> str:
    """A measured pressure as the writers print it: to 1 Pa in bar, to 15 digits in other units."""
    v = p_bar / _units.factor("pressure", suffix)
    return f"{v:.{_MEASURED_BAR_DECIMALS}f}" if suffix == "bar" else f"{v:.15g}"
