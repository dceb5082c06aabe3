"""The virtual stand closes the spring: a sealed test, and the sealed spring's truth.

Procedure. The element (plus an optional reservoir) is charged at height x_c to overpressure p_c,
the valve to the hydraulic cylinder is closed, and the grip steps the element through the
heights (by default the paper's 155 -> 65 -> 155 mm in 5 mm steps, whatever x_c). The gas mass
is fixed and each step is slow enough to be quasi-static, so the gas follows the polytrope
p_abs (V(x, p_u) + V_r)^n = p_abs,c (V_c + V_r)^n at every height (n = 1: heat exchange keeps the
temperature; n = 1.4: no heat exchange); the state depends on the height, not on the path.

Truth. The spring's absolute volume V(x, p_u) is known to the stand (``true_volume_m3``), so the
gas law is solved by scipy's brentq height by height (independently of uq._physics.sealed, which
the design answers use); the true rate is a central difference of the true sealed force
(step 1e-5 m; truncation about 1e-8 relative), the natural frequency sqrt(k g / P) / (2 pi).

Readings. The stand's error budget (section 3.2) less the pressure holding (nothing holds the
pressure now): the element stands at x + dx (displacement sd), the load cell reads the force
times (1 + e); the overpressure is read by the gauge with the stand's pressure sd (taken as the
gauge's uncertainty, an assumption: the paper states the gauge at 0.1 %).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import brentq

from uq._data.reference import PAPER_PISTON_AREA_M2, PAPER_X0_M, PAPER_X_MAX_M
from uq._data.stand_description import PAPER_STAND, StandDescription
from uq._io.errors import InputError
from uq._physics.mechanisms import elastic_casing_compliance
from uq._physics.quantities import BAR_PA
from uq._physics.sealed import G_STANDARD
from uq._stand.simulator import (
    Layout,
    casing_reference_area_m2,
    make_spring,
    reading_errors,
    true_curves,
)

#: effects a sealed truth can carry: each changes force and volume as functions of (x, p_u) alone
SEALED_EFFECTS = ("elastic_casing", "casing_force", "force_offset", "pressure_dependent_area")
RATE_STEP_M = 1.0e-5


def true_volume_m3(
    spring,
    effects: dict[str, float],
    height_m,
    p_bar: float,
    piston_area_m2: float = PAPER_PISTON_AREA_M2,
    stand: StandDescription = PAPER_STAND,
):
    """The element's absolute internal volume V(x, p_u), m^3, as the stand knows it.

    A spring with a potential (``volume_m3``) gives its own. Otherwise eq. 5 from its piston, with
    the volume at x_max the stand's ``element_volume_at_xmax_m3`` at every pressure:
    V = V(x_max) - S (L(x, p) - L(x_max, p)). Effects as ``true_curves``: pressure_dependent_area
    scales the volume change from x0 by (1 + m p_u), elastic_casing adds p_u C(x) (C(x0) = 0).
    """
    bad = [k for k in effects if k not in SEALED_EFFECTS]
    if bad:
        raise InputError(
            f"effects: {', '.join(bad)} has no sealed truth (a volume that is a function of height "
            f"and pressure alone); a sealed test takes {', '.join(SEALED_EFFECTS)}",
            param="effects",
        )
    x = np.asarray(height_m, float)
    x0 = np.array(spring.x0_m)

    def base(h):
        if hasattr(spring, "volume_m3"):
            return np.asarray(spring.volume_m3(h, p_bar), float)
        top = spring.piston_m(np.array(PAPER_X_MAX_M), p_bar)
        return stand.element_volume_at_xmax_m3 - piston_area_m2 * (spring.piston_m(h, p_bar) - top)

    v = base(x)
    if "pressure_dependent_area" in effects:
        v0 = base(x0)
        v = v0 + (v - v0) * (1.0 + effects["pressure_dependent_area"] * p_bar)
    if "elastic_casing" in effects:
        m, area = effects["elastic_casing"], casing_reference_area_m2(spring)
        v = v + p_bar * BAR_PA * elastic_casing_compliance(x, spring.x0_m, m, area)
    return v


def _force(spring, effects, height_m, p_bar, piston_area_m2):
    x = np.atleast_1d(np.asarray(height_m, float))
    f, _ = true_curves(
        spring, effects, x, p_bar, np.ones(x.size, bool), np.zeros(x.size), piston_area_m2
    )
    return f


@dataclass(frozen=True)
class SealedTruth:
    """The true sealed characteristics at ``height_m`` (H,): overpressure (bar), force (N), rate
    (N/m), natural frequency (Hz; NaN where rate or load is not positive), and at the charge the
    volume V_c (m^3) and dV/dp_u (m^3/Pa) a user would have to measure."""

    height_m: np.ndarray
    pressure_bar: np.ndarray
    force_N: np.ndarray
    rate_N_per_m: np.ndarray
    natural_frequency_Hz: np.ndarray
    volume_c_m3: float
    dvdp_c_m3_per_pa: float


def sealed_truth(
    spring_name: str,
    height_m,
    *,
    height_c_m: float = PAPER_X0_M,
    charge_bar: float = 5.0,
    polytropic: float = 1.0,
    reservoir_m3: float = 0.0,
    effects: dict[str, float] | None = None,
    piston_area_m2: float = PAPER_PISTON_AREA_M2,
    stand: StandDescription = PAPER_STAND,
    spring=None,
) -> SealedTruth:
    """Solve the gas law at each height with brentq (module docstring); ``spring`` overrides the
    named one (e.g. a ThermoSpring with another compliance at x0)."""
    effects = dict(effects or {})
    spring = spring if spring is not None else make_spring(spring_name, piston_area_m2)
    p_atm = stand.p_atm_bar * BAR_PA
    lo_bar, hi_bar = spring.pressure_range_bar

    def volume(x, p_bar):
        return float(true_volume_m3(spring, effects, np.array(x), p_bar, piston_area_m2, stand))

    v_c = volume(height_c_m, charge_bar)
    log_k = np.log(charge_bar * BAR_PA + p_atm) + polytropic * np.log(v_c + reservoir_m3)

    def pressure(x):
        def gap(p_bar):
            return (
                np.log(p_bar * BAR_PA + p_atm)
                + polytropic * np.log(volume(x, p_bar) + reservoir_m3)
                - log_k
            )

        if gap(lo_bar) > 0 or gap(hi_bar) < 0:
            raise InputError(
                f"sealed test: at {x * 1e3:g} mm the sealed pressure leaves {lo_bar:g}..{hi_bar:g} bar, "
                f"where the {spring.name} spring is defined"
            )
        return brentq(gap, lo_bar, hi_bar, xtol=1e-13, rtol=1e-14)

    def force(x):
        return float(_force(spring, effects, x, pressure(x), piston_area_m2)[0])

    xs = np.asarray(height_m, float).reshape(-1)
    p = np.array([pressure(x) for x in xs])
    f = np.array(
        [
            float(_force(spring, effects, x, pb, piston_area_m2)[0])
            for x, pb in zip(xs, p, strict=True)
        ]
    )
    h = RATE_STEP_M
    k = np.array([-(force(x + h) - force(x - h)) / (2 * h) for x in xs])
    ok = (k > 0) & (f > 0)
    freq = np.where(
        ok, np.sqrt(np.where(ok, k, 1.0) * G_STANDARD / np.where(ok, f, 1.0)) / (2 * np.pi), np.nan
    )
    dp = 1e-4
    dvdp = (volume(height_c_m, charge_bar + dp) - volume(height_c_m, charge_bar - dp)) / (
        2 * dp * BAR_PA
    )
    return SealedTruth(xs, p, f, k, freq, v_c, dvdp)


@dataclass(frozen=True)
class SealedTest:
    """A sealed test's readings in recording order and the truth at the commanded heights."""

    spring: str
    height_c_m: float
    charge_bar: float
    polytropic: float
    reservoir_m3: float
    height_m: np.ndarray  # commanded
    force_N: np.ndarray  # load-cell readings
    pressure_bar: np.ndarray  # gauge readings
    step: np.ndarray
    truth: SealedTruth
    effects: dict = field(default_factory=dict)


def simulate_sealed(
    spring_name: str = "n50-thermo",
    *,
    height_c_m: float = PAPER_X0_M,
    charge_bar: float = 5.0,
    polytropic: float = 1.0,
    reservoir_m3: float = 0.0,
    heights_m=None,
    effects: dict[str, float] | None = None,
    seed: int = 0,
    stand: StandDescription = PAPER_STAND,
    piston_area_m2: float = PAPER_PISTON_AREA_M2,
    spring=None,
) -> SealedTest:
    """Close the spring at (x_c, p_c) and step it through ``heights_m`` (default: the paper's
    155 -> 65 -> 155 mm in 5 mm steps); readings with the stand's load-cell, displacement and gauge
    noise (module docstring), and the true sealed characteristics at the commanded heights."""
    effects = dict(effects or {})
    spring = spring if spring is not None else make_spring(spring_name, piston_area_m2)
    x_cmd = Layout().heights()[0] if heights_m is None else np.asarray(heights_m, float).reshape(-1)
    kw = dict(
        height_c_m=height_c_m,
        charge_bar=charge_bar,
        polytropic=polytropic,
        reservoir_m3=reservoir_m3,
        effects=effects,
        piston_area_m2=piston_area_m2,
        stand=stand,
        spring=spring,
    )
    truth = sealed_truth(spring_name, x_cmd, **kw)
    rng = np.random.default_rng(seed)
    n = x_cmd.size
    x_true = x_cmd + reading_errors(rng, stand.displacement_sd_m, n, stand.error_df)
    at_true = sealed_truth(spring_name, x_true, **kw)
    e_load = reading_errors(rng, stand.load_cell_rel_sd, n, stand.error_df)
    e_gauge = reading_errors(rng, stand.pressure_sd_bar(at_true.pressure_bar), n, stand.error_df)
    return SealedTest(
        spring=spring_name,
        height_c_m=height_c_m,
        charge_bar=charge_bar,
        polytropic=polytropic,
        reservoir_m3=reservoir_m3,
        height_m=x_cmd,
        force_N=at_true.force_N * (1.0 + e_load),
        pressure_bar=at_true.pressure_bar + e_gauge,
        step=np.arange(n),
        truth=truth,
        effects=effects,
    )
