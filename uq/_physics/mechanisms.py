"""The physics the traditional model leaves out (docs/formats.md section 3).

One table, shared by the virtual stand (``uq simulate --effect NAME=VALUE``) and the
discrepancy engine (``uq diagnose``), so that a concealed effect and a diagnosed one mean
exactly the same thing.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from uq._io.errors import InputError

#: Length scale of the casing-force shape E(x) = E(x0) exp(-(x - x0) / CASING_LENGTH_M):
#: the casing resists more the more it is compressed (bulged), smooth in x, and clearly not
#: a constant (which would be a ``force_offset``).
CASING_LENGTH_M = 0.040


@dataclass(frozen=True)
class Mechanism:
    name: str
    physics: str
    changes: str
    unit: str
    #: Plain words for reports: what it means when the engine finds this mechanism.
    meaning: str


MECHANISMS: dict[str, Mechanism] = {
    m.name: m
    for m in (
        Mechanism(
            "pressure_dependent_area",
            "elastic stretching of the casing's middle surface",
            "F_eff(x) becomes F_eff(x)(1 + m p_u), p_u in bar, in force and volume alike",
            "1/bar",
            "the casing's middle surface stretches under pressure, so the effective area grows "
            "with overpressure (the paper's conclusion: elastic deformation of the middle surface)",
        ),
        Mechanism(
            "casing_force",
            "elastic force of the rubber-cord casing itself",
            "force gains E(x), the same at every pressure, smooth in x; volume unchanged",
            "N",
            "the rubber-cord casing carries force of its own, independent of the air pressure "
            "(the membrane is not absolutely flexible)",
        ),
        Mechanism(
            "hysteresis",
            "viscoelastic relaxation / friction in the casing",
            "compression-branch force x(1 + m), rebound-branch force x(1 - m); volume unchanged",
            "1",
            "compression and rebound give different forces at the same height: viscoelastic "
            "relaxation or friction in the casing dissipates energy over the cycle",
        ),
        Mechanism(
            "force_offset",
            "a constant force error (flange weight not removed, load-cell zero)",
            "force + m everywhere",
            "N",
            "every force reading is shifted by the same amount: a load-cell zero error or the "
            "upper-flange weight (56.3 N on the paper's stand) not removed",
        ),
        Mechanism(
            "thermal_drift",
            "the gas temperature drifts during a test, so the isothermal premise of eq. 4 fails",
            "the piston cavity S L grows by m per recorded step on top of eq. 5; force unchanged",
            "cm^3 per step",
            "the gas temperature drifts during the test, so the piston has to make room for "
            "thermal expansion (or contraction) on top of the element's volume change",
        ),
        Mechanism(
            "volume_excess",
            "the casing is not an inextensible membrane: part of the pressure load is carried by the "
            "casing's meridional tension (its middle surface lies outside the effective-area circle), so "
            "the volume the element sweeps per unit height exceeds the force-derived effective area",
            "dV/dx becomes F_eff(x)(1 + m) at every pressure: the piston moves by "
            "dL = -(1 + m) F_eff(x) dx / S; force unchanged",
            "1",
            "the volume-derived effective area (-S dL/dx) exceeds the force-derived one (P/p_u) by the same "
            "fraction at every pressure: the casing's own membrane tension carries part of the pressure load, "
            "so eq. 1 and eq. 2 of the traditional theory do not give the same curve (the paper's main finding)",
        ),
    )
}


def casing_shape(height_m: np.ndarray, x0_m: float) -> np.ndarray:
    """Shape of the concealed casing force, 1 at x0 (dimensionless)."""
    return np.exp(-(np.asarray(height_m) - x0_m) / CASING_LENGTH_M)


def parse_effects(specs: list[str] | None, option: str = "--effect") -> dict[str, float]:
    """Parse ``NAME=VALUE`` options into {name: magnitude}; unknown names are refused."""
    out: dict[str, float] = {}
    for spec in specs or []:
        name, sep, value = spec.partition("=")
        name = name.strip()
        if not sep:
            raise InputError(f"option {option} '{spec}': expected NAME=VALUE, e.g. hysteresis=0.01")
        if name not in MECHANISMS:
            raise InputError(
                f"option {option} '{spec}': unknown mechanism '{name}'; expected one of {', '.join(MECHANISMS)}"
            )
        try:
            v = float(value)
        except ValueError:
            raise InputError(f"option {option} '{spec}': '{value}' is not a number") from None
        if not np.isfinite(v):
            raise InputError(f"option {option} '{spec}': the magnitude must be finite")
        if name in out:
            raise InputError(f"option {option}: mechanism '{name}' given twice")
        out[name] = v
    if "hysteresis" in out and not -0.5 < out["hysteresis"] < 0.5:
        raise InputError(
            f"option {option} hysteresis={out['hysteresis']:g}: expected |m| < 0.5 (a fraction, not per cent)"
        )
    if "volume_excess" in out and not -0.5 < out["volume_excess"] < 1.0:
        raise InputError(
            f"option {option} volume_excess={out['volume_excess']:g}: expected -0.5 < m < 1 (a fraction, not per cent)"
        )
    return out
