"""The element's internal volume V(x, p_u) from what the stand measures and what the user adds.

The stand measures only volume *changes* at constant overpressure (eqs. 3-5): the piston gives
V(x, p_u) - V(x', p_u) between heights of one test, i.e. the volume-derived area dV/dx
(= -S dL/dx) at every pressure. Two things it cannot give (the paper, after eq. 7):

1. the absolute volume at one point: the user measures it (e.g. by filling with water) and gives
   V_c at the design height x_c and the charge overpressure p_c, with an uncertainty; it is drawn
   once per posterior draw (``charge_volume_draws``);
2. how the volume at one fixed height changes with pressure: isobaric tests compare heights at
   one pressure, never pressures at one height. The documented default (docs/design.md) takes V(x_c, p_u) not to
   change with p_u, give or take an sd drawn per posterior draw (``dvdp_prior_l_per_bar``); an
   option gives dV/dp_u there (litres per bar), or a model whose potential fixes it
   (``dvdp="model"`` in uq._derived.design) supplies its own on the pressure grid.

With these, on a grid of heights and pressures (``relative_volume_grid``, ``absolute_volume_grid``):

    V(x, p_u) - V(x_c, p_c) = [V(x_c, p_u) - V(x_c, p_c)] + int_{x_c}^{x} dV/dx(x', p_u) dx'

and V(x, p_u) = V_c + that. Away from x_c, dV/dp_u follows from the pressure dependence of the
volume-derived area (d/dp_u of the integral): the casing's compliance is carried by the
recordings wherever it differs from its value at x_c.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from uq._io.errors import InputError
from uq._physics import knots
from uq._physics.quantities import BAR_PA

L_PER_M3 = 1.0e3


class AbsoluteVolume(NamedTuple):
    """V(x, p_u) on a height x pressure grid, m^3, shape (S, H, Pn), and its assumptions in words."""

    volume_m3: np.ndarray
    statement: str


def charge_volume_draws(volume_m3: float, sd_m3: float, n_draws: int, rng: np.random.Generator):
    """V_c per posterior draw, m^3, shape (n_draws,): Normal(volume, sd), independent of the
    posterior (the volume is measured apart from the isobaric campaign); sd 0 gives the value."""
    if not (np.isfinite(volume_m3) and volume_m3 > 0):
        raise InputError(
            f"volume_l: expected a positive internal volume in litres, got {volume_m3 * L_PER_M3:g}",
            param="volume_l",
        )
    if not (np.isfinite(sd_m3) and sd_m3 >= 0):
        raise InputError(
            f"volume_sd_l: expected a standard deviation >= 0 in litres, got {sd_m3 * L_PER_M3:g}",
            param="volume_sd_l",
        )
    if sd_m3 > volume_m3 / 4:
        raise InputError(
            f"volume_sd_l: {sd_m3 * L_PER_M3:g} L is more than a quarter of the volume "
            f"{volume_m3 * L_PER_M3:g} L; a normal uncertainty would give non-positive volumes: measure V more closely",
            param="volume_sd_l",
        )
    if sd_m3 == 0:
        return np.full(n_draws, float(volume_m3))
    return volume_m3 + sd_m3 * rng.standard_normal(n_draws)


def volume_statement(
    volume_m3: float,
    sd_m3: float,
    height_m: float,
    charge_bar: float,
    dvdp_m3_per_pa,
    prior_l_per_bar: tuple[float, float, str] | None = None,
) -> str:
    """The volume assumption in words, for every output that depends on it. ``prior_l_per_bar``:
    (value, sd, where the sd comes from) when dV/dp_u at x_c is drawn Normal(value, sd)."""
    head = (
        f"internal volume {volume_m3 * L_PER_M3:.4g} L"
        + (
            f" +- {sd_m3 * L_PER_M3:.2g} L (1 sd, drawn per posterior draw)"
            if sd_m3
            else " (exact, as given)"
        )
        + f" at {height_m * 1e3:g} mm and {charge_bar:g} bar, as measured by the user (the stand gives only "
        "volume changes, eq. 5); at other heights the recordings' volume-derived area dV/dx is integrated"
    )
    if prior_l_per_bar is not None:
        value, sd, source = prior_l_per_bar
        drawn = f"1 sd, drawn per posterior draw; isobaric tests cannot tell; {source}"
        how = (
            f"ASSUMED: the volume at {height_m * 1e3:g} mm does not change with pressure, give or "
            f"take {sd:.2g} L per bar (dV/dp_u = 0 +- {sd:.2g} L/bar, {drawn})"
            if value == 0
            else f"GIVEN: the volume at {height_m * 1e3:g} mm changes with pressure by "
            f"{value:.4g} +- {sd:.2g} L per bar ({drawn})"
        )
    elif isinstance(dvdp_m3_per_pa, str):
        how = f"how the volume at {height_m * 1e3:g} mm changes with pressure: the model's own dV/dp_u ({dvdp_m3_per_pa})"
    elif dvdp_m3_per_pa == 0:
        how = (
            f"ASSUMED: the volume at {height_m * 1e3:g} mm does not change with pressure (dV/dp_u = 0 there; "
            "isobaric tests cannot tell; the documented default)"
        )
    else:
        how = (
            f"GIVEN: the volume at {height_m * 1e3:g} mm changes by "
            f"{dvdp_m3_per_pa * L_PER_M3 * BAR_PA:.4g} L per bar (isobaric tests cannot tell)"
        )
    return f"{head}; {how}"


def relative_volume_grid(
    height_m,
    pressure_pa,
    volume_area_m2,
    *,
    design_height_m: float,
    charge_pa: float,
    dvdp_m3_per_pa=0.0,
) -> np.ndarray:
    """V(x, p_u) - V(x_c, p_c), m^3, shape (S, H, Pn), from the volume-derived area on the grid.

    ``volume_area_m2``: dV/dx draws (S, H, Pn) on ``height_m`` (H,) x ``pressure_pa`` (Pn,);
    integrated in height with a not-a-knot cubic spline (exact for areas cubic in x).
    ``dvdp_m3_per_pa``: dV/dp_u at x_c, a number (m^3/Pa; 0 is the contract's assumption) or
    draws (S, Pn) on the pressure grid (a model's own), integrated in pressure from p_c.
    """
    x = np.asarray(height_m, float)
    p = np.asarray(pressure_pa, float)
    A = np.asarray(volume_area_m2, float)
    if A.ndim != 3 or A.shape[1:] != (x.size, p.size):
        raise ValueError(f"volume_area_m2 has shape {A.shape}, expected (S, {x.size}, {p.size})")
    if not x[0] - 1e-12 <= design_height_m <= x[-1] + 1e-12:
        raise ValueError("the design height must lie on the height grid's range")
    along_x = knots.integral_from(x, A, axis=1, start=design_height_m)  # (S, H, Pn)
    d = np.asarray(dvdp_m3_per_pa, float)
    if d.ndim == 0:
        at_c = d * (p - charge_pa)  # (Pn,)
    else:
        if d.shape != (A.shape[0], p.size):
            raise ValueError(f"dV/dp draws have shape {d.shape}, expected ({A.shape[0]}, {p.size})")
        at_c = knots.integral_from(p, d, axis=1, start=charge_pa)[:, None, :]  # (S, 1, Pn)
    return along_x + at_c


def absolute_volume_grid(
    height_m,
    pressure_pa,
    volume_area_m2,
    *,
    design_height_m: float,
    charge_pa: float,
    volume_m3,
    volume_sd_m3: float = 0.0,
    dvdp_m3_per_pa=0.0,
    dvdp_words: str = "",
    dvdp_prior_l_per_bar: tuple[float, float, str] | None = None,
) -> AbsoluteVolume:
    """V(x, p_u) = V_c + [V(x, p_u) - V(x_c, p_c)] on the grid, m^3 (S, H, Pn), with its statement.

    ``volume_m3``: V_c, a number or its draws (S,) (``charge_volume_draws``); ``volume_sd_m3`` the
    sd they were drawn with (for the statement); ``dvdp_m3_per_pa`` as ``relative_volume_grid``
    (draws: a model's own dV/dp_u, described by ``dvdp_words``, or Normal draws of the
    assumption, described by ``dvdp_prior_l_per_bar`` = (value, sd, where the sd comes from)).
    """
    rel = relative_volume_grid(
        height_m,
        pressure_pa,
        volume_area_m2,
        design_height_m=design_height_m,
        charge_pa=charge_pa,
        dvdp_m3_per_pa=dvdp_m3_per_pa,
    )
    v_c = np.asarray(volume_m3, float).reshape(-1, 1, 1)
    d = np.asarray(dvdp_m3_per_pa, float)
    words = float(d) if d.ndim == 0 else (dvdp_words or "its draws")
    statement = volume_statement(
        float(np.mean(v_c)),
        volume_sd_m3,
        design_height_m,
        charge_pa / BAR_PA,
        words,
        dvdp_prior_l_per_bar,
    )
    return AbsoluteVolume(v_c + rel, statement)
