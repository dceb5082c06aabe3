"""Units of the recordings' columns: the suffix of a column name is its unit (docs/formats.md section 1).

``pressure_psi`` is the pressure in psi, ``height_in`` the height in inches, ``volume_l`` the
element's volume in litres. Each suffix maps to a unit of pint (one module-level registry, made
on first use), which gives the factor to the unit used inside: bar for pressures (the test's
label stays in bar), SI for everything else. Conversions are multiplications by that factor, so a
file in the paper's units (bar, mm, N) is read bit for bit as before units existed.
"""

from __future__ import annotations

import functools

import numpy as np

#: quantity -> (unit inside, {suffix: pint unit}); the suffixes are those of docs/formats.md section 1.
_PRESSURE = {"bar": "bar", "psi": "psi", "kPa": "kPa", "MPa": "MPa", "mbar": "mbar"}
_LENGTH = {"mm": "mm", "m": "m", "in": "inch"}
QUANTITIES: dict[str, tuple[str, dict[str, str]]] = {
    "pressure": ("bar", _PRESSURE),
    "set_pressure": ("bar", _PRESSURE),
    "height": ("m", _LENGTH),
    "force": ("N", {"N": "N", "kN": "kN", "lbf": "lbf"}),
    "piston": ("m", _LENGTH),
    "volume": ("m**3", {"l": "L", "cm3": "cm**3", "m3": "m**3", "in3": "inch**3"}),
}
#: The unit each quantity has in the paper's format (and in Recordings made in code).
PAPER_UNITS = {"pressure": "bar", "height": "mm", "force": "N", "piston": "mm"}
#: How a unit is written in messages and report labels.
SHOWN = {"l": "L", "cm3": "cm^3", "m3": "m^3", "in3": "in^3"}


@functools.cache
def registry():
    """The one pint UnitRegistry, created on first use (importing pint takes a fraction of a
    second, which commands that never read units should not pay)."""
    import pint

    return pint.UnitRegistry()


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


@functools.cache
def factor(quantity: str, suffix: str) -> float:
    """Multiply a value in the column's unit by this to get the unit used inside (bar or SI).

    >>> factor("height", "mm"), factor("pressure", "bar"), round(factor("pressure", "psi"), 8)
    (0.001, 1.0, 0.06894757)
    """
    inside, suffixes = QUANTITIES[quantity]
    value = registry().Quantity(1.0, suffixes[suffix]).to(inside).magnitude
    # pint's factors carry float noise in the last bit (1 L = 0.0010000000000000002 m^3);
    # 15 significant digits restore the defined decimals (L, inch, lbf) and lose nothing else.
    return float(f"{value:.15g}")


def shown(suffix: str) -> str:
    return SHOWN.get(suffix, suffix)


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
