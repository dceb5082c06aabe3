"""Units of the recordings' columns: the suffix of a column name is its unit (docs/formats.md section 1).

``pressure_psi`` is the pressure in psi, ``height_in`` the height in inches, ``volume_l`` the
element's volume in litres. The list of units is closed (../shared/CONTRACT.md section 1), so a
table of factors does the job: each suffix's factor to the unit used inside, bar for pressures
(the test's label stays in bar), SI for everything else, from the units' definitions (the inch
is 0.0254 m and the pound-force 0.45359237 kg x 9.80665 m/s^2, both exact by international
agreement; psi is lbf/in^2). Conversions are multiplications by that factor, so a file in the
paper's units (bar, mm, N) is read bit for bit as before units existed.
"""

from __future__ import annotations

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
