"""Units of the recordings' columns: the suffix of a column name is its unit (docs/formats.md section 1).

``pressure_psi`` is the pressure in psi, ``height_in`` the height in inches, ``volume_l`` the
element's volume in litres. The list of units is closed (the contract's, docs/formats.md section
1), so a table of factors does the job: each suffix's factor to the unit used inside, bar for pressures
(the test's label stays in bar), SI for everything else, from the units' definitions (the inch
is 0.0254 m and the pound-force 0.45359237 kg x 9.80665 m/s^2, both exact by international
agreement; psi is lbf/in^2). Conversions are multiplications by that factor, so a file in the
paper's units (bar, mm, N) is read bit for bit as before units existed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

INCH_M = 0.0254  # exact (1959 international yard and pound)
LBF_N = 0.45359237 * 9.80665  # exact: the pound mass times standard gravity
PA_PER_BAR = 1e5


def _digits(value: float) -> float:
    """``value`` to 15 significant digits: the defined decimal (1 L = 0.001 m^3, not the
    0.0010000000000000002 that a product of factors leaves), nothing else lost."""
    return float(f"{value:.15g}")


_PRESSURE = {
    "bar": 1.0,
    "psi": _digits(LBF_N / INCH_M**2 / PA_PER_BAR),
    "kPa": 1e3 / PA_PER_BAR,
    "MPa": 1e6 / PA_PER_BAR,
    "mbar": 1e-3,
}
_LENGTH = {"mm": 1e-3, "m": 1.0, "in": INCH_M}
#: quantity -> (unit inside, {suffix: factor to the unit inside}); the suffixes are those of
#: docs/formats.md section 1.
QUANTITIES: dict[str, tuple[str, dict[str, float]]] = {
    "pressure": ("bar", _PRESSURE),
    "set_pressure": ("bar", _PRESSURE),
    "height": ("m", _LENGTH),
    "force": ("N", {"N": 1.0, "kN": 1e3, "lbf": _digits(LBF_N)}),
    "piston": ("m", _LENGTH),
    "volume": ("m^3", {"l": 1e-3, "cm3": 1e-6, "m3": 1.0, "in3": _digits(INCH_M**3)}),
}
#: The unit each quantity has in the paper's format (and in Recordings made in code).
PAPER_UNITS = {"pressure": "bar", "height": "mm", "force": "N", "piston": "mm"}
#: How a unit is written in messages and report labels.
SHOWN = {"l": "L", "cm3": "cm^3", "m3": "m^3", "in3": "in^3"}


def split_name(name: str) -> tuple[str, str] | None:
    """(quantity, suffix) of a column name such as ``set_pressure_psi``, or None when the name
    does not start with a quantity (``branch``, ``step``, an extra column)."""
    for quantity in sorted(QUANTITIES, key=len, reverse=True):  # set_pressure before pressure
        if name.startswith(quantity + "_") and len(name) > len(quantity) + 1:
            return quantity, name[len(quantity) + 1 :]
    return None


def known(quantity: str, suffix: str) -> bool:
    return suffix in QUANTITIES[quantity][1]


def names(quantity: str) -> list[str]:
    """The column names a quantity may have, e.g. ``force_N, force_kN, force_lbf``."""
    return [f"{quantity}_{s}" for s in QUANTITIES[quantity][1]]


def factor(quantity: str, suffix: str) -> float:
    """Multiply a value in the column's unit by this to get the unit used inside (bar or SI).

    >>> factor("height", "mm"), factor("pressure", "bar"), factor("pressure", "psi")
    (0.001, 1.0, 0.0689475729316836)
    >>> factor("force", "lbf"), factor("volume", "l"), factor("volume", "in3")
    (4.4482216152605, 0.001, 1.6387064e-05)
    """
    return QUANTITIES[quantity][1][suffix]


def shown(suffix: str) -> str:
    return SHOWN.get(suffix, suffix)


def suffix_of(quantity: str, text: str) -> str | None:
    """The suffix of ``quantity`` a unit written as ``text`` stands for (a units row's ``(mm)``,
    ``kN``, ``L``, ``cm^3``), or None when it is none of that quantity's units.

    The suffix itself matches, and so does the way a unit is shown (``L`` for ``l``, ``cm^3`` and
    ``cm³`` for ``cm3``); case matters as in column names (``mbar`` is not ``Mbar``).

    >>> suffix_of("volume", "L"), suffix_of("volume", "cm³"), suffix_of("force", "kN"), suffix_of("force", "KN")
    ('l', 'cm3', 'kN', None)
    """
    text = text.strip().replace("³", "^3").replace("**", "^")
    for suffix in QUANTITIES[quantity][1]:
        if text in (suffix, shown(suffix)):
            return suffix
    return None


# ----------------------------------------------------------------------------- output units

#: Areas are no recordings column, but outputs give them (F_eff): suffix -> factor to m^2.
AREAS = {"m2": 1.0, "cm2": 1e-4, "mm2": 1e-6, "in2": _digits(INCH_M**2)}
OUTPUT_CHOICES = ("si", "input")
_SHOWN_AREA = {"m2": "m^2", "cm2": "cm^2", "mm2": "mm^2", "in2": "in^2"}


@dataclass(frozen=True)
class OutputUnits:
    """The units an output's tables and labels are written in.

    ``si`` (``--units si``, the default): the contract's units, bar for pressures, mm for heights
    and piston coordinates, N for forces, m^2 for areas, litres for volumes (a catalogue's table;
    JSON stays SI whatever is chosen). ``input`` (``--units input``): the units the recordings
    came in (``Recordings.units``), areas in in^2 and volumes in in^3 when heights were in
    inches, and the volume column's unit when the file had one.

    >>> u = OutputUnits.of({"pressure": "psi", "height": "in", "force": "lbf"}, "input")
    >>> u.pressure, u.height, u.force, u.area, u.volume, u.column("force")
    ('psi', 'in', 'lbf', 'in2', 'in3', 'force_lbf')
    >>> round(u.value("force", 4448.2216152605), 9), round(u.value("height", 0.0254), 12)
    (1000.0, 1.0)
    """

    pressure: str = "bar"
    height: str = "mm"
    force: str = "N"
    piston: str = "mm"
    area: str = "m2"
    volume: str = "l"

    @classmethod
    def of(cls, recording_units: dict | None, which: str = "si") -> OutputUnits:
        if which not in OUTPUT_CHOICES:
            raise ValueError(f"units: expected si or input, got {which!r}")
        if which == "si" or not recording_units:
            return cls()
        u = dict(PAPER_UNITS) | dict(recording_units)
        inch = u["height"] == "in"
        return cls(
            pressure=u["pressure"],
            height=u["height"],
            force=u["force"],
            piston=u.get("piston", u["height"]),
            area="in2" if inch else "m2",
            volume=u.get("volume", "in3" if inch else "l"),
        )

    def suffix(self, quantity: str) -> str:
        """The unit's suffix in column names (``psi``, ``in2``; ``lbf_per_in`` for a stiffness)."""
        if quantity == "stiffness":
            return f"{self.force}_per_{self.height}"
        return getattr(self, "pressure" if quantity == "set_pressure" else quantity)

    def factor(self, quantity: str) -> float:
        """Output unit -> the unit inside (bar for pressures, SI else)."""
        if quantity == "area":
            return AREAS[self.area]
        if quantity == "stiffness":
            return factor("force", self.force) / factor("height", self.height)
        return factor(quantity, self.suffix(quantity))

    def value(self, quantity: str, inside):
        """``inside`` (bar for pressures, SI else; a number or an array) in the output unit."""
        return inside / self.factor(quantity)

    def shown(self, quantity: str) -> str:
        """The unit as labels write it (``in^2``, ``L``, ``N/mm``)."""
        if quantity == "stiffness":
            return f"{shown(self.force)}/{shown(self.height)}"
        s = self.suffix(quantity)
        return _SHOWN_AREA.get(s, shown(s)) if quantity == "area" else shown(s)

    def column(self, quantity: str) -> str:
        """A column name with the unit as suffix (``force_lbf``, ``height_in``, ``feff_in2``)."""
        return f"{'feff' if quantity == 'area' else quantity}_{self.suffix(quantity)}"

    def coefficient(self, block: str, k: int) -> tuple[float, str]:
        """(factor, unit) that turn coefficient k of the cubic of ``block`` ("force" or "piston"),
        in SI against u = x - x0 in metres, into these units against u in ``height`` units:
        a_k h^k / y for y = P or L, h and y the output units' factors to SI."""
        h = self.factor("height")
        y = self.factor(block)
        per = {0: "", 1: f"/{self.shown('height')}"}.get(k, f"/{self.shown('height')}^{k}")
        unit = f"{self.shown(block)}{per}"
        if block == "piston" and self.piston == self.height and k >= 1:
            unit = "1" if k == 1 else f"1/{self.shown('height')}" + ("" if k == 2 else f"^{k - 1}")
        return h**k / y, unit


def printed_step(values) -> float:
    """The step a column's values were printed to, in the column's unit: the largest power of
    ten (10^-9 .. 10^6) of which every value is a whole multiple (4.20, 3.88, 3.49 L: 0.01).

    A printed value is known only to its last digit: its rounding error is uniform over one step,
    of sd step / sqrt(12). Values with more digits than 10^-9 give 10^-9.

    >>> printed_step([4.2, 3.88, 3.49]), printed_step([2500.0, 3610.0]), printed_step([0.1234567])
    (0.01, 10.0, 1e-07)
    """
    v = np.abs(np.asarray(values, float))
    v = v[np.isfinite(v) & (v > 0)]
    for k in range(6, -10, -1):
        step = 10.0**k
        q = v / step
        whole = np.round(q)
        # a whole multiple up to float error (1e-9 of the value), and not zero for a value that is not
        if v.size and np.all((whole >= 1) & (np.abs(q - whole) < 1e-9 * np.maximum(q, 1e3))):
            return float(f"{step:.0e}")
    return 1e-9
