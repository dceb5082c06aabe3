"""The shapes real recordings come in, made by the virtual stand (``uq simulate`` options).

The stand (uq._stand.simulator) records the paper's full format. Real stands and catalogues give
less, or other units; these functions turn the stand's readings into those shapes, so that every
shape the reader accepts can be made with a known truth:

* :func:`record_pressure`: the pressure each reading was taken at, as a sensor reads it
  (``--record-pressure``);
* :func:`catalogue`: a manufacturer's data sheet: one compression pass at a few heights, a
  volume column at one stated pressure (``--catalogue``);
* :data:`CATALOGUE_ROUNDING`: how catalogues print their numbers.

Units, a missing piston column and the sign of force are the writer's business
(uq._data.writing.write_recordings_csv).
"""

from __future__ import annotations

import numpy as np

from uq._data.recordings import recordings_from_text
from uq._data.stand_description import PAPER_STAND, StandDescription
from uq._data.writing import write_recordings_csv
from uq._physics.quantities import BAR_PA
from uq._stand.simulator import PAPER_PISTON_AREA_M2, Layout, make_spring, simulate, true_curves

#: The pressure sensor of ``--record-pressure`` is the stand's (``StandDescription.
#: pressure_sensor_*``; the paper's resolves 1 Pa and is accurate to 0.1 %, section 3.2): a reading
#: shows the held pressure p + dp times (1 + g), to the resolution, where g ~ N(0, gain sd) is drawn
#: once per campaign (a calibration error, the same for every reading) from a random stream of its
#: own, so the other readings of a seed are the same with and without the sensor.
SENSOR_STREAM = 21  # the issue that asked for it; any fixed number would do

#: quantity -> unit suffix -> the step catalogues print to (whole mm, 10 N, 0.01 L and the like).
CATALOGUE_ROUNDING = {
    "height": {"mm": 1.0, "m": 0.001, "in": 0.01},
    "force": {"N": 10.0, "kN": 0.01, "lbf": 1.0},
    "volume": {"l": 0.01, "cm3": 10.0, "m3": 0.00001, "in3": 1.0},
}


def sensor_gain(seed: int, stand: StandDescription = PAPER_STAND) -> float:
    """The relative gain error g of the campaign's pressure sensor (drawn once per seed)."""
    rng = np.random.default_rng([seed, SENSOR_STREAM])
    return float(rng.normal(0.0, stand.pressure_sensor_gain_sd))


def record_pressure(
    tests: list[dict], seed: int, stand: StandDescription = PAPER_STAND
) -> list[dict]:
    """The stand's tests with ``measured_pressure_bar``: each reading's pressure as the sensor read it.

    The stand holds p + dp during a reading (``pressure_error_bar``, its holding error); the sensor
    shows (p + dp)(1 + g) rounded to the stand's ``pressure_sensor_resolution_pa``, g from
    :func:`sensor_gain`.
    """
    g = sensor_gain(seed, stand)
    step = stand.pressure_sensor_resolution_pa
    out = []
    for t in tests:
        held_Pa = (t["pressure_bar"] + t["pressure_error_bar"]) * BAR_PA
        shown_Pa = np.round(held_Pa * (1.0 + g) / step) * step
        out.append(dict(t, measured_pressure_bar=shown_Pa / BAR_PA))
    return out


def catalogue(
    tests: list[dict],
    spring_name: str,
    effects: dict[str, float],
    *,
    volume_at_bar: float,
    x_max_m: float,
    element_volume_at_xmax_m3: float,
    piston_area_m2: float,
) -> list[dict]:
    """The stand's tests cut to a data sheet: the compression pass only, and the element's volume
    at ``volume_at_bar``.

    A catalogue lists one pass (heights from x_max down), in no recorded order. The volume is the
    element's own, V(x) = V(x_max) - S [L(x) - L(x_max)] (eq. 5 integrated) from the spring's true
    piston curve with the concealed ``effects`` (except thermal_drift, an artefact of the piston
    stand, not a property of the element), noise-free: a catalogue prints a smoothed value, rounded.
    V(x_max) is the stand's element volume (4.2 L for the paper's stand, assumed).
    """

    spring = make_spring(spring_name, piston_area_m2)
    physical = {k: v for k, v in effects.items() if k != "thermal_drift"}
    out = []
    for t in tests:
        keep = np.asarray(t["compression"], bool)
        d = {
            k: (v[keep] if isinstance(v, np.ndarray) and v.shape == keep.shape else v)
            for k, v in t.items()
        }
        d["volume_m3"] = None
        p = float(t["pressure_bar"])
        if abs(p - volume_at_bar) < 1e-9:  # the piston at the heights and, last, at x_max
            x = np.append(np.asarray(d["height_m"], float), x_max_m)
            comp, step = np.append(d["compression"], True), np.append(d["step"], 0)
            _, L = true_curves(spring, physical, x, p, comp, step, piston_area_m2)
            d["volume_m3"] = element_volume_at_xmax_m3 - piston_area_m2 * (L[:-1] - L[-1])
        out.append(d)
    return out


def catalogue_rounding(units: dict) -> dict:
    """The writer's ``rounding`` for a catalogue in ``units`` (quantity -> suffix)."""
    return {q: steps[units[q]] for q, steps in CATALOGUE_ROUNDING.items() if q in units}


def catalogue_recordings(
    spring: str = "n50",
    *,
    seed: int = 0,
    layout=None,
    volume_at_bar: float | None = None,
    stand=None,
):
    """A catalogue table made by the stand, as :class:`uq.Recordings` in memory: what
    ``uq simulate --catalogue [--volume-at-bar P]`` writes (the same tests, cut and rounded the
    same way) and a reader reads. ``volume_at_bar``: default the middle pressure, as the command;
    ``layout`` default: the paper's pressures, 10 mm steps."""

    stand = PAPER_STAND if stand is None else stand
    layout = Layout(step_m=0.010) if layout is None else layout
    p = tuple(layout.pressures_bar)
    volume_at_bar = p[len(p) // 2] if volume_at_bar is None else volume_at_bar
    tests = simulate(spring, seed=seed, layout=layout, stand=stand)
    tests = catalogue(
        tests,
        spring,
        {},
        volume_at_bar=volume_at_bar,
        x_max_m=layout.x_max_m,
        element_volume_at_xmax_m3=stand.element_volume_at_xmax_m3,
        piston_area_m2=PAPER_PISTON_AREA_M2,
    )
    text = write_recordings_csv(
        tests,
        "RECONSTRUCTED catalogue table from the virtual test stand",
        order=False,
        piston=False,
        volume=True,
        rounding=catalogue_rounding({"height": "mm", "force": "N", "volume": "l"}),
    )
    return recordings_from_text(
        text, f"catalogue seed {seed}", piston_area_cm2=PAPER_PISTON_AREA_M2 * 1e4
    )
