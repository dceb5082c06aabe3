"""The physics the traditional model leaves out: each mechanism defined once.

A :class:`Mechanism` holds everything the project says about one departure from the traditional
theory (eqs. 1, 2): its words for an engineer, its magnitude's unit, its forward effect on the
virtual stand (``uq simulate --effect NAME=VALUE``), how the discrepancy engine (``uq diagnose``)
represents it (a :class:`ScaleTerm`, a magnitude multiplying parts of the traditional model, or a
:class:`LinearTerm`, new coefficients with their design columns and the magnitude read from them),
and what a campaign must hold for it to be identifiable (``needs``). A concealed effect and a
diagnosed one mean exactly the same thing because both come from here.

What ``needs`` can name (``uq._data.recordings.Recordings`` tells which a campaign has):
``"volume"`` piston or volume readings; ``"pressures"`` tests at two or more pressures;
``"both_branches"`` compression and rebound in a known recording order (then the recording order
is not the height order, so a drift in time can be told from a shape in height).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from uq._io.errors import InputError
from uq._physics.quantities import BAR_PA

#: Length scale of the casing-force shape E(x) = E(x0) exp(-(x - x0) / CASING_LENGTH_M):
#: the casing resists more the more it is compressed (bulged), smooth in x, and clearly not
#: a constant (which would be a ``force_offset``).
CASING_LENGTH_M = 0.040

#: Height profile of the elastic casing, h(t) = 1 + h1 t + h2 t^2 with t = (x - x0) / 0.05 m: the
#: shape of C'(x) (the growth of the volume-derived area per pascal), 1 at x0. Fitted to Table 1:
#: the slope in pressure (1..10 bar) of -S dL/dx at 19 heights, by least squares, divided by its
#: value at x0 (tests/stand/test_thermo.py recomputes it). The casing's compliance grows towards
#: both ends of the stroke, most towards x_max: Table 1's relative growth of the volume-derived
#: area is about 0.02/bar from 95 to 112 mm, 0.036/bar at 65 mm and 0.12/bar at 155 mm.
ELASTIC_CASING_PROFILE = (1.0, 0.16, 0.95)
ELASTIC_CASING_LENGTH_M = 0.05


@dataclass(frozen=True)
class StandCurves:
    """The noise-free readings of one test on the virtual stand, and what an effect may need."""

    force: np.ndarray  # N
    piston: np.ndarray  # m
    height_m: np.ndarray
    p_bar: float
    compression: np.ndarray  # bool
    step: np.ndarray
    x0_m: float
    piston_area_m2: float
    piston_at_x0_m: float  # the spring's own piston coordinate at x0 (the reference of scalings)
    reference_area_m2: float  # the spring's traditional area V0'(x0) (elastic_casing's scale)


@dataclass(frozen=True)
class DesignContext:
    """Every recorded point of a campaign, as the engine's design needs it ((n,) arrays)."""

    t: np.ndarray  # (x - x0) / 0.05 m
    p_bar: np.ndarray
    sgn: np.ndarray  # +1 compression, -1 rebound
    step: np.ndarray  # recording order within the test
    area_m2: float  # the piston area S


@dataclass(frozen=True)
class ScaleTerm:
    """A magnitude m multiplying parts of the model by (1 + m g): g = p_u in bar ("pressure"),
    +1/-1 on compression/rebound ("branch") or 1 ("one"). ``scales``: the parts it multiplies,
    named "<group>.force" or "<group>.volume" (group "feff" is the traditional area)."""

    variable: str
    scales: frozenset
    prior_sd: float


@dataclass(frozen=True)
class LinearTerm:
    """New coefficients: ``columns(ctx)`` gives the force columns (N per unit coefficient) and the
    piston columns (m per unit coefficient), either None; ``magnitude(coef, feff, ctx)`` the
    magnitude's draws from the coefficient draws (N, k) and the traditional area's (N, K + 1)."""

    columns: Callable
    prior_sd: float
    magnitude: Callable
    n_params: int


@dataclass(frozen=True)
class Mechanism:
    name: str
    physics: str
    changes: str
    unit: str
    #: Plain words for reports: what it means when the engine finds this mechanism.
    meaning: str
    term: ScaleTerm | LinearTerm
    effect: Callable  # (magnitude, StandCurves) -> StandCurves, the virtual stand's
    needs: frozenset = field(default_factory=frozenset)
    #: what else the same readings can mean (a stand constant confounded with it), or ""
    confounded_with: str = ""

    @property
    def n_params(self) -> int:
        return 1 if isinstance(self.term, ScaleTerm) else self.term.n_params


BASIS_M = 0.05  # t = (x - x0) / BASIS_M, the engine's and the stand's height variable
CASING_DEG = 3  # the engine's casing force E(x): a cubic in t
ELASTIC_DEG = 3  # the engine's casing compliance C(x): c_1 t + c_2 t^2 + c_3 t^3 (C(x0) = 0)


def _scale_piston(curves: StandCurves, k) -> np.ndarray:
    ref = curves.piston_at_x0_m
    return ref + (curves.piston - ref) * k


def _pda(m, c: StandCurves) -> StandCurves:
    k = 1.0 + m * c.p_bar
    return replace(c, force=c.force * k, piston=_scale_piston(c, k))


def _casing(m, c: StandCurves) -> StandCurves:
    return replace(c, force=c.force + m * casing_shape(c.height_m, c.x0_m))


def _elastic(m, c: StandCurves) -> StandCurves:
    p_pa = c.p_bar * BAR_PA
    area = c.reference_area_m2
    force = c.force + p_pa**2 * elastic_casing_slope(c.height_m, c.x0_m, m, area) / 2
    piston = (
        c.piston - p_pa * elastic_casing_compliance(c.height_m, c.x0_m, m, area) / c.piston_area_m2
    )
    return replace(c, force=force, piston=piston)


def _hysteresis(m, c: StandCurves) -> StandCurves:
    return replace(c, force=c.force * np.where(c.compression, 1.0 + m, 1.0 - m))


def _offset(m, c: StandCurves) -> StandCurves:
    return replace(c, force=c.force + m)


def _volume_excess(m, c: StandCurves) -> StandCurves:
    return replace(c, piston=_scale_piston(c, 1.0 + m))


def _drift(m, c: StandCurves) -> StandCurves:
    return replace(c, piston=c.piston + np.asarray(c.step) * m * 1e-6 / c.piston_area_m2)


def _casing_columns(ctx: DesignContext):
    return ctx.t[:, None] ** np.arange(CASING_DEG + 1), None


def _offset_columns(ctx: DesignContext):
    return np.ones((ctx.t.size, 1)), None


def _drift_columns(ctx: DesignContext):
    return None, (ctx.step * 1e-6 / ctx.area_m2)[:, None]


def _elastic_columns(ctx: DesignContext):
    """Force p^2 C'(x)/2 and piston -p C(x)/S for C = sum_j c_j t^j (m^3/Pa), j = 1..3."""
    j = np.arange(1, ELASTIC_DEG + 1)
    p_pa = (ctx.p_bar * BAR_PA)[:, None]
    force = p_pa**2 * j * ctx.t[:, None] ** (j - 1) / BASIS_M / 2
    piston = -p_pa * ctx.t[:, None] ** j / ctx.area_m2
    return force, piston


def _first(coef, feff, ctx):
    return coef[:, 0]


def _elastic_magnitude(coef, feff, ctx):
    """m = C'(x0) / V0'(x0) per bar: c_1 / h over the traditional area at x0."""
    return coef[:, 0] / BASIS_M / feff[:, 0] * BAR_PA


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
            ScaleTerm("pressure", frozenset({"feff.force", "feff.volume"}), 0.1),
            _pda,
            frozenset({"pressures"}),
        ),
        Mechanism(
            "casing_force",
            "elastic force of the rubber-cord casing itself",
            "force gains E(x), the same at every pressure, smooth in x; volume unchanged",
            "N",
            "the rubber-cord casing carries force of its own, independent of the air pressure "
            "(the membrane is not absolutely flexible)",
            LinearTerm(_casing_columns, 1.0e4, _first, CASING_DEG + 1),
            _casing,
            frozenset({"pressures"}),
        ),
        Mechanism(
            "elastic_casing",
            "the casing stores elastic energy that depends on height and pressure, so force and volume "
            "derive from one potential G(x, p_u) = -p_u V0(x) - p_u^2 C(x)/2 + ... (P = -dG/dx, "
            "V = -dG/dp_u; the Maxwell relation dP/dp_u = dV/dx holds)",
            "force gains p_u^2 C'(x)/2, the volume gains p_u C(x); C'(x) = m V0'(x0) h(x) per bar with "
            "h(x) = 1 + 0.16 t + 0.95 t^2, t = (x - x0)/50 mm (Table 1's shape), C(x0) = 0; the "
            "volume-derived area dV/dx exceeds P/p_u",
            "1/bar",
            "the rubber-cord casing stretches under pressure and stores the energy elastically: the volume "
            "the element sweeps per mm of height grows with pressure (most near full extension), the force "
            "grows with pressure at half that rate, and force and volume still come from one energy, so "
            "compression and rebound agree (no hysteresis)",
            LinearTerm(_elastic_columns, 1.0e-8, _elastic_magnitude, ELASTIC_DEG),
            _elastic,
            frozenset({"pressures", "volume"}),
        ),
        Mechanism(
            "hysteresis",
            "viscoelastic relaxation / friction in the casing",
            "compression-branch force x(1 + m), rebound-branch force x(1 - m); volume unchanged",
            "1",
            "compression and rebound give different forces at the same height: viscoelastic "
            "relaxation or friction in the casing dissipates energy over the cycle",
            ScaleTerm(
                "branch",
                frozenset({"feff.force", "casing_force.force", "elastic_casing.force"}),
                0.1,
            ),
            _hysteresis,
            frozenset({"both_branches"}),
        ),
        Mechanism(
            "force_offset",
            "a constant force error (flange weight not removed, load-cell zero)",
            "force + m everywhere",
            "N",
            "every force reading is shifted by the same amount: a load-cell zero error or the "
            "upper-flange weight (56.3 N on the paper's stand) not removed",
            LinearTerm(_offset_columns, 1.0e4, _first, 1),
            _offset,
            frozenset({"pressures"}),
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
            ScaleTerm("one", frozenset({"feff.volume", "elastic_casing.volume"}), 0.3),
            _volume_excess,
            frozenset({"volume"}),
            confounded_with=(
                "a piston-area error: scaling the piston's travel by 1 + m is the same as dividing the "
                "piston area S by 1 + m, so the same readings say that the piston area is S / (1 + m)"
            ),
        ),
        Mechanism(
            "thermal_drift",
            "the gas temperature drifts during a test, so the isothermal premise of eq. 4 fails",
            "the piston cavity S L grows by m per recorded step on top of eq. 5; force unchanged",
            "cm^3 per step",
            "the gas temperature drifts during the test, so the piston has to make room for "
            "thermal expansion (or contraction) on top of the element's volume change",
            LinearTerm(_drift_columns, 100.0, _first, 1),
            _drift,
            frozenset({"volume", "both_branches"}),
            confounded_with=(
                "a slow gas leak or a creeping piston: each moves the piston by the same amount per "
                "recorded step"
            ),
        ),
    )
}


def apply_effects(effects: dict[str, float], curves: StandCurves) -> StandCurves:
    """The stand's readings with concealed ``effects``, applied in the order of ``MECHANISMS``."""
    for name, mech in MECHANISMS.items():
        if name in effects:
            curves = mech.effect(effects[name], curves)
    return curves


def elastic_casing_slope(height_m, x0_m: float, magnitude_per_bar: float, area_m2: float):
    """C'(x) of the elastic casing, m^2/Pa: m V0'(x0) h(x) per bar (``ELASTIC_CASING_PROFILE``);
    ``area_m2`` is V0'(x0), the element's traditional area at x0."""
    t = (np.asarray(height_m, float) - x0_m) / ELASTIC_CASING_LENGTH_M
    h0, h1, h2 = ELASTIC_CASING_PROFILE
    return magnitude_per_bar / BAR_PA * area_m2 * (h0 + h1 * t + h2 * t**2)


def elastic_casing_compliance(height_m, x0_m: float, magnitude_per_bar: float, area_m2: float):
    """C(x) = int_{x0}^{x} C'(x') dx' (C(x0) = 0: the volume at x0 does not change with pressure),
    m^3/Pa; the volume gains p_u C(x)."""
    t = (np.asarray(height_m, float) - x0_m) / ELASTIC_CASING_LENGTH_M
    h0, h1, h2 = ELASTIC_CASING_PROFILE
    integral = h0 * t + h1 * t**2 / 2 + h2 * t**3 / 3
    return magnitude_per_bar / BAR_PA * area_m2 * ELASTIC_CASING_LENGTH_M * integral


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
    if "elastic_casing" in out and not -0.1 < out["elastic_casing"] < 0.1:
        raise InputError(
            f"option {option} elastic_casing={out['elastic_casing']:g}: expected |m| < 0.1 per bar "
            "(Table 1 shows about 0.024/bar at x0)"
        )
    return out
