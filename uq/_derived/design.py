"""The sealed spring from a fitted model: load, rate and natural frequency with credible intervals
(the functions ``uq design`` calls; docs/design.md, docs/formats.md).

What a designer does with isobaric characteristics: charge the spring at the design height x_c to
p_c, close it (optionally with a reservoir), and ask for its load-deflection curve, its vertical
rate and natural frequency. Per posterior draw of the model:

1. the model's force P(x, p_u) and volume-derived area dV/dx(x, p_u) on a grid of heights (the
   tested range, ``HEIGHT_STEP_M``, x_c on it) and pressures (the tested range, ``N_PRESSURES``),
   and dP/dx from a not-a-knot spline in height (exact for cubics in x: the surface model is one);
2. the absolute volume (uq._physics.volume): V_c drawn per posterior draw from the user's value and
   sd, the isobaric increments integrated in height, and at x_c the stated assumption on dV/dp_u
   (0 unless told, with an honest width: Normal(0, sd) per posterior draw, the sd from the
   recordings, :func:`dvdp_prior_sd`; the documented default, docs/design.md), a given value (with
   the sd the user gives), or the model's own (``dvdp="model"``, only for a model offering
   ``volume_pressure_draws``);
3. the sealed path and its rate (uq._physics.sealed: the gas law with the casing's dV/dp_u),
   the natural frequency sqrt(k g / P) / (2 pi), transmissibility of an undamped single degree of
   freedom at a forcing frequency.

The sealed curve is given only where every draw's path pressure stays within the tested
pressures (the model does not extrapolate); beyond, the heights are listed with the reason.

A model here is any fitted model (:class:`uq._models.fitted.FittedModel`) with a volume
(``has_volume``): ``force_draws`` (N) and ``volume_area_draws`` (dV/dx, m^2; the volume-derived
area -S dL/dx) on its fixed posterior draws, and, where it has its own (``has_dvdp``: the
thermodynamic model), ``volume_pressure_draws`` (dV/dp_u, m^3/Pa). ``uq design`` gives it on
``--draws`` of its draws (``on_draws``).
"""

from __future__ import annotations

import itertools
from dataclasses import MISSING, dataclass, fields, replace

import numpy as np

from uq._derived.margin import pressure_needed
from uq._inference.summary import band, estimate
from uq._io.errors import InputError, refuse_outside
from uq._physics import knots
from uq._physics.quantities import BAR_PA
from uq._physics.sealed import (
    POLYTROPIC_RANGE,
    Charge,
    GridElement,
    SealedPath,
    isolation_pct,
    natural_frequency_Hz,
    sealed_path,
    transmissibility,
)
from uq._physics.volume import L_PER_M3, absolute_volume_grid, charge_volume_draws

DEFAULT_DRAWS = 1000
HEIGHT_STEP_M = 0.002
N_PRESSURES = 41
CHUNK_DRAWS = 250  # draws per sealed-path solve: bounds the spline coefficients' memory
LEVEL = 0.90
N_CHART = 6
MARGIN_SPAN_M = 0.008  # heights each side of the design height a design margin evaluates
#: its pressure grid: the answer within 1e-4 of the 41-pressure grid's (tested), in < 2 s
MARGIN_PRESSURES = 21


@dataclass(frozen=True)
class SealedDesign:
    """What the designer asks (SI except where a name says otherwise; ``uq design``'s options).

    height_m        design height x_c, where the spring is charged and closed (--height-mm)
    charge_bar      charge overpressure p_c there (--charge-bar)
    volume_l        internal volume at x_c and p_c, measured (--volume-l)
    volume_sd_l     its standard deviation, drawn per posterior draw (--volume-sd-l)
    polytropic      n, or (lo, hi): n uniform in lo..hi per draw (--polytropic; default
                    ``DYNAMIC_POLYTROPIC``, 1.3..1.4: the natural frequency is a dynamic quantity)
    reservoir_l     extra reservoir joined to the element (--reservoir-l)
    dvdp_l_per_bar  dV/dp_u at x_c: 0 (the documented default), a value, or "model"
    dvdp_sd_l_per_bar  its sd, drawn per posterior draw (--dvdp-sd-l-per-bar): None (the default)
                    takes it from the recordings (:func:`dvdp_prior_sd`) for the default value 0
                    and 0 for a value given; 0 makes the value exact
    forcing_Hz      forcing frequency for transmissibility and isolation (--forcing-hz)
    """

    height_m: float
    charge_bar: float
    volume_l: float
    volume_sd_l: float = 0.0
    polytropic: float | tuple[float, float] = (1.3, 1.4)
    reservoir_l: float = 0.0
    dvdp_l_per_bar: float | str = 0.0
    forcing_Hz: float | None = None
    p_atm_bar: float = 1.01325
    seed: int = 0
    dvdp_sd_l_per_bar: float | None = None

    def __repr__(self) -> str:
        """One line: the design point and every option not at its default."""
        shown = [
            f"{f.name}={getattr(self, f.name)!r}"
            for f in fields(self)
            if f.default is MISSING or getattr(self, f.name) != f.default
        ]
        return f"SealedDesign({', '.join(shown)})"

    @property
    def polytropic_range(self) -> tuple[float, float]:
        n = self.polytropic
        return (float(n[0]), float(n[1])) if isinstance(n, tuple | list) else (float(n), float(n))


def check_design(model, design: SealedDesign) -> None:
    """One-line refusals naming the option, before anything is computed."""
    if not model.has_volume:
        raise InputError(
            "the sealed rate and natural frequency need the volume-derived area dV/dx: this campaign is "
            "force-only (no piston_mm column); only isobaric loads can be given"
        )
    never = "; the model does not extrapolate"
    for param, kind, (lo, hi) in (
        ("height_m", "heights", model.height_range_m),
        ("charge_bar", "pressures", model.pressure_range_bar),
    ):
        refuse_outside(param, getattr(design, param), lo, hi, kind, never, param=param)
    if design.volume_l is None or not (np.isfinite(design.volume_l) and design.volume_l > 0):
        raise InputError(
            "volume_l: the sealed spring needs the internal volume at the design height and "
            "charge pressure (litres; measure it, e.g. by filling the element with water: the stand gives "
            "only volume changes)",
            param="volume_l",
        )
    lo, hi = design.polytropic_range
    if not (POLYTROPIC_RANGE[0] <= lo <= hi <= POLYTROPIC_RANGE[1]):
        raise InputError(
            f"polytropic: expected a value or a range within {POLYTROPIC_RANGE[0]:g} (isothermal) .. "
            f"{POLYTROPIC_RANGE[1]:g} (adiabatic), got {lo:g}..{hi:g}",
            param="polytropic",
        )
    if not (np.isfinite(design.reservoir_l) and design.reservoir_l >= 0):
        raise InputError(
            f"reservoir_l: expected a volume >= 0 L, got {design.reservoir_l:g}",
            param="reservoir_l",
        )
    d = design.dvdp_l_per_bar
    if isinstance(d, str):
        if d != "model" or not model.has_dvdp:
            raise InputError(
                f"dvdp_l_per_bar: '{d}': expected a number (L/bar), or 'model' for a model with its "
                f"own dV/dp_u ({model.label} has none)",
                param="dvdp_l_per_bar",
            )
    elif not np.isfinite(d):
        raise InputError(
            "dvdp_l_per_bar: expected a finite number of litres per bar", param="dvdp_l_per_bar"
        )
    sd = design.dvdp_sd_l_per_bar
    if sd is not None and not (np.isfinite(sd) and sd >= 0):
        raise InputError(
            f"dvdp_sd_l_per_bar: expected a standard deviation >= 0 in litres per bar, got {sd:g}",
            param="dvdp_sd_l_per_bar",
        )
    if design.forcing_Hz is not None and not (
        np.isfinite(design.forcing_Hz) and design.forcing_Hz > 0
    ):
        raise InputError(
            f"forcing_Hz: expected a positive frequency, got {design.forcing_Hz:g}",
            param="forcing_Hz",
        )


def _heights(lo: float, hi: float, x_c: float, step: float) -> np.ndarray:
    """x_c + k step over lo..hi, with the ends lo and hi exactly (a last step shorter than step/4
    is merged into the end)."""
    down = x_c - step * np.arange(1, int(np.floor((x_c - lo) / step)) + 1)
    up = x_c + step * np.arange(1, int(np.floor((hi - x_c) / step)) + 1)
    xs = np.concatenate([down[::-1], [x_c], up])
    if xs[0] - lo > step / 4:
        xs = np.concatenate([[lo], xs])
    elif xs[0] != x_c:
        xs[0] = lo
    if hi - xs[-1] > step / 4:
        xs = np.concatenate([xs, [hi]])
    elif xs[-1] != x_c:
        xs[-1] = hi
    return xs


class DesignGrid:
    """The model's draws on a height x pressure grid around one design height (module docstring, 1).

    force, dforce_dx, area: (S, H, Pn); heights (H,) with ``height_m`` on it; pressures (Pn,), Pa.
    ``span_m``: (lo, hi) within the tested heights to cover instead of all of them (at least
    four grid heights: dP/dx is then still exact for a model cubic in x).
    """

    def __init__(
        self,
        model,
        height_m: float,
        *,
        height_step_m: float = HEIGHT_STEP_M,
        n_pressures: int = N_PRESSURES,
        span_m: tuple[float, float] | None = None,
    ):
        self.model, self.height_m = model, float(height_m)
        lo, hi = model.height_range_m
        if span_m is not None:  # only part of the tested heights (a design margin's way)
            lo, hi = max(lo, float(span_m[0])), min(hi, float(span_m[1]))
        plo, phi = model.pressure_range_bar
        self.heights = _heights(lo, hi, self.height_m, height_step_m)
        self.pressures_bar = np.linspace(plo, phi, n_pressures)
        self.pressures_pa = self.pressures_bar * BAR_PA
        X, P = np.meshgrid(self.heights, self.pressures_bar, indexing="ij")
        self.force = np.asarray(model.force_draws(X, P), float)
        self.area = np.asarray(model.volume_area_draws(X, P), float)
        self.dforce_dx = knots.derivative_at_knots(self.heights, self.force, axis=1)
        self.n_draws = self.force.shape[0]
        self._volumes = {}
        self._prior_sd = {}
        self.dvdp_at_c = None
        if model.has_dvdp:
            at_c = np.full(n_pressures, self.height_m)
            self.dvdp_at_c = np.asarray(
                model.volume_pressure_draws(at_c, self.pressures_bar), float
            )

    def draw_inputs(self, design: SealedDesign) -> tuple[np.ndarray, np.ndarray]:
        """V_c (m^3) and n per posterior draw, (S,) each: seeded by ``design.seed``, independent of the
        posterior (they are measured or chosen apart from the isobaric campaign)."""
        rng = np.random.default_rng(design.seed)
        v_c = charge_volume_draws(
            design.volume_l / L_PER_M3, design.volume_sd_l / L_PER_M3, self.n_draws, rng
        )
        lo, hi = design.polytropic_range
        n = np.full(self.n_draws, lo) if lo == hi else rng.uniform(lo, hi, self.n_draws)
        return v_c, n

    def dvdp_sd(self, design: SealedDesign) -> tuple[float, str]:
        """The sd (L/bar) of dV/dp_u at x_c the design draws, and where it comes from ("given",
        or "recordings": :func:`dvdp_prior_sd` of the model at the design's charge); 0 for the
        model's own dV/dp_u (its draws carry their uncertainty)."""
        if design.dvdp_l_per_bar == "model":
            return 0.0, "model"
        if design.dvdp_sd_l_per_bar is not None:
            return float(design.dvdp_sd_l_per_bar), "given"
        if float(design.dvdp_l_per_bar) != 0.0:  # a value the user gives: exact unless its sd is
            return 0.0, "given"
        key = ("sd", float(design.charge_bar))
        if key not in self._prior_sd:
            self._prior_sd[key] = dvdp_prior_sd(self.model, self.height_m, design.charge_bar)
        return self._prior_sd[key], "recordings"

    def volume(self, design: SealedDesign, v_c: np.ndarray):
        """V(x, p_u) on the grid, (S, H, Pn) m^3, and its statement (uq._physics.volume); kept for
        the next call with the same volume inputs (a chart's charges share it)."""
        key = (design.charge_bar, design.volume_l, design.volume_sd_l, design.dvdp_l_per_bar)
        key += (design.dvdp_sd_l_per_bar, design.seed, float(np.sum(v_c)))
        if key not in self._volumes:
            self._volumes = {key: self._volume(design, v_c)}
        return self._volumes[key]

    def _volume(self, design: SealedDesign, v_c: np.ndarray):
        d = design.dvdp_l_per_bar
        sd_l, source = self.dvdp_sd(design)
        prior = None
        if d == "model":
            dvdp, words = self.dvdp_at_c, self.model.dvdp_words
        elif sd_l > 0:  # Normal(value, sd) per posterior draw, seeded apart from V_c and n
            rng = np.random.default_rng([design.seed, DVDP_STREAM])
            per_draw = (float(d) + sd_l * rng.standard_normal(self.n_draws)) / L_PER_M3 / BAR_PA
            dvdp = np.repeat(per_draw[:, None], self.pressures_pa.size, axis=1)
            words = ""
            prior = (float(d), sd_l, DVDP_SD_WORDS[source])
        else:
            dvdp, words = float(d) / L_PER_M3 / BAR_PA, ""
        return absolute_volume_grid(
            self.heights,
            self.pressures_pa,
            self.area,
            design_height_m=self.height_m,
            charge_pa=design.charge_bar * BAR_PA,
            volume_m3=v_c,
            volume_sd_m3=design.volume_sd_l / L_PER_M3,
            dvdp_m3_per_pa=dvdp,
            dvdp_words=words,
            dvdp_prior_l_per_bar=prior,
        )


#: the seed stream of the dV/dp_u draws (apart from V_c's and n's, which stay as they were)
DVDP_STREAM = 29
#: where the sd of dV/dp_u at x_c comes from, in words for the statement
DVDP_SD_WORDS = {
    "recordings": "the sd is the rms change of dV/dp_u from the design height over the tested "
    "heights, as the recordings show it at the charge pressure (docs/design.md section 2)",
    "given": "the sd as given",
}
#: heights over the tested range on which dvdp_prior_sd integrates the area's pressure slope
PRIOR_HEIGHTS = 61


def dvdp_prior_sd(model, height_m: float, charge_bar: float) -> float:
    """The sd (L/bar) of the default assumption on dV/dp_u at the design height: the root mean
    square over the tested heights x of dV/dp_u(x, p_c) - dV/dp_u(x_c, p_c), from the
    posterior-mean volume-derived area (``model.volume_area_draws``).

    Isobaric tests cannot give dV/dp_u at one height, but they give how it changes with height:
    d/dx (dV/dp_u) = d/dp_u (dV/dx), the pressure slope of the volume-derived area, so
    dV/dp_u(x) - dV/dp_u(x_c) = int_{x_c}^{x} d(dV/dx)/dp_u dx' (uq._physics.volume). The default
    takes the volume at x_c not to change with pressure (the contract's assumption); where the
    casing's volume does not change with pressure is what the tests cannot tell, so the height x*
    where it does not is taken anywhere over the tested heights, uniformly: dV/dp_u(x_c) =
    -[dV/dp_u(x*) - dV/dp_u(x_c)], whose root mean square over x* is this sd (the Normal(0, sd)
    the design draws has that second moment). The pressure slope is the central difference over
    +-5 % of the tested pressure range (within it). A model whose area does not depend on
    pressure gives 0 (its statement says so)."""
    (hlo, hhi), (plo, phi) = model.height_range_m, model.pressure_range_bar
    xs = np.union1d(np.linspace(hlo, hhi, PRIOR_HEIGHTS), [height_m])
    dp = 0.05 * (phi - plo)
    p_lo, p_hi = max(plo, charge_bar - dp), min(phi, charge_bar + dp)
    if not p_hi > p_lo:
        return 0.0
    a_lo = np.asarray(model.volume_area_draws(xs, np.full(xs.shape, p_lo)), float).mean(axis=0)
    a_hi = np.asarray(model.volume_area_draws(xs, np.full(xs.shape, p_hi)), float).mean(axis=0)
    slope = (a_hi - a_lo) / ((p_hi - p_lo) * BAR_PA)  # d(dV/dx)/dp_u, m^2/Pa
    uniform = np.linspace(hlo, hhi, PRIOR_HEIGHTS)  # x* uniform over the tested heights
    # dV/dp_u(x*) - dV/dp_u(x_c), m^3/Pa
    change = knots.integral_from(xs, slope, axis=0, start=height_m, to=uniform)
    return float(np.sqrt(np.mean(change**2)) * L_PER_M3 * BAR_PA)


def sealed_draws(
    grid: DesignGrid, design: SealedDesign, charge_bar: float | None = None, heights_m=None
) -> tuple[SealedPath, str]:
    """Per-draw sealed path (S, H) at ``heights_m`` (default: the grid's) for a charge at the design
    height (default ``design.charge_bar``; another charge pressure keeps the design's volume
    assumption: V(x_c, p') = V_c + [V(x_c, p') - V(x_c, p_c)]), and the volume statement.
    ``charge_bar`` may hold one charge pressure per posterior draw, (S,) (a design margin: the
    pressure at which each draw carries the load); V_c is then the volume at each draw's own charge
    (measured in the loaded state)."""
    (path,), statement = sealed_paths(grid, design, [charge_bar], heights_m)
    return path, statement


def _check_charge(grid: DesignGrid, design: SealedDesign, charge_bar) -> np.ndarray:
    p_c = np.asarray(design.charge_bar if charge_bar is None else charge_bar, float)
    if p_c.ndim not in (0, 1) or (p_c.ndim == 1 and p_c.size != grid.n_draws):
        raise ValueError(f"charge_bar: a number or one per draw ({grid.n_draws}), got {p_c.shape}")
    plo, phi = grid.model.pressure_range_bar
    outside = p_c[~((plo - 1e-9 <= p_c) & (p_c <= phi + 1e-9))]  # NaN too
    if outside.size:
        raise InputError(
            f"charge pressure {float(outside[0]):g} bar is outside the tested pressures {plo:g}..{phi:g} bar"
        )
    return p_c


def sealed_paths(
    grid: DesignGrid, design: SealedDesign, charges_bar, heights_m=None
) -> tuple[list[SealedPath], str]:
    """:func:`sealed_draws` for several charges (each as its ``charge_bar``) at once: the element's
    pressure splines, most of the cost, are made once per block of draws for all of them."""
    if grid.height_m != design.height_m:
        raise ValueError("the grid was built for another design height")
    charges = [_check_charge(grid, design, c) for c in charges_bar]
    heights = grid.heights if heights_m is None else np.asarray(heights_m, float).reshape(-1)
    v_c, n = grid.draw_inputs(design)
    vol = grid.volume(design, v_c)
    # the gas law is solved height by height: the element is needed only at the asked heights and x_c
    sub = np.unique([int(np.argmin(np.abs(grid.heights - x))) for x in (*heights, grid.height_m)])
    if sub.size == grid.heights.size:  # every height: the grid's arrays as they are, not copies
        sub = slice(None)
    parts = [[] for _ in charges]
    x_c = np.array([grid.height_m])
    for lo in range(0, grid.n_draws, CHUNK_DRAWS):
        sl = slice(lo, lo + CHUNK_DRAWS)
        el = GridElement(
            grid.heights[sub],
            grid.pressures_pa,
            grid.force[sl][:, sub],
            grid.dforce_dx[sl][:, sub],
            vol.volume_m3[sl][:, sub],
            grid.area[sl][:, sub],
        )
        S, p_all, v_all = el.n_draws, [], []
        for p_c in charges:
            p_here = np.broadcast_to(p_c if p_c.ndim == 0 else p_c[sl], (S,)) * BAR_PA
            # one charge per draw (a design margin): V_c was measured in the loaded state, at that charge
            v_all.append(v_c[sl] if p_c.ndim == 1 else el.volume_m3(x_c, p_here[:, None])[:, 0])
            p_all.append(p_here)
        # every charge in one solve: the block's draws repeated, charge after charge (the same
        # numbers: the gas law is solved point by point)
        charge = Charge(
            grid.height_m,
            np.concatenate(p_all),
            np.concatenate(v_all),
            np.tile(n[sl], len(charges)),
            design.reservoir_l / L_PER_M3,
            design.p_atm_bar * BAR_PA,
        )
        rows = np.tile(np.arange(S), len(charges))
        path = sealed_path(
            el.on_rows(rows), heights, charge, pressure_bounds_pa=el.pressure_bounds_pa
        )
        for j, out in enumerate(parts):
            out.append(SealedPath(path.height_m, *(a[j * S : (j + 1) * S] for a in path[1:])))
    paths = [
        SealedPath(
            heights, *(np.concatenate([getattr(p, f) for p in ps]) for f in SealedPath._fields[1:])
        )
        for ps in parts
    ]
    return paths, vol.statement


def _polytropic_words(design: SealedDesign) -> str:
    lo, hi = design.polytropic_range
    if lo == hi:
        kind = {1.0: " (isothermal: slow strokes)", 1.4: " (adiabatic: fast strokes)"}.get(lo, "")
        return f"polytropic exponent n = {lo:g}{kind}"
    return f"polytropic exponent n uniform in {lo:g}..{hi:g} per draw (the stroke's heat exchange unknown)"


def _at_design(grid: DesignGrid, design: SealedDesign, charge_bar: float, solved=None):
    """Load, rate and natural-frequency draws (S,) at the design height for one charge (``solved``:
    its (sealed path, statement) at that height when already made)."""
    path, statement = solved or sealed_draws(grid, design, charge_bar, [grid.height_m])
    load, rate = path.force_N[:, 0], path.rate_N_per_m[:, 0]
    where = f"at {grid.height_m * 1e3:g} mm charged to {charge_bar:g} bar"
    return load, rate, natural_frequency_Hz(rate, load, where), statement


def polytropic_keys(polytropic) -> tuple[float, list[float]]:
    """The polytropic exponent (a value or a range (lo, hi)) as the JSON gives it: ``polytropic``
    a number, as the contract has it (the value, or the mean of a range's uniform draws), and
    ``polytropic_range`` [lo, hi] (lo = hi for one value), a key after the contract's."""
    lo, hi = polytropic if isinstance(polytropic, tuple | list) else (polytropic, polytropic)
    return (lo if lo == hi else (lo + hi) / 2), [lo, hi]


def design_point(model, design: SealedDesign, grid: DesignGrid | None = None) -> dict:
    """The contract's ``uq design --json`` keys at the design height (docs/formats.md), each
    estimate {"mean", "sd", "q05", "q95"}, with the transmissibility at ``design.forcing_Hz`` and
    the assumptions in words."""
    check_design(model, design)
    grid = grid or DesignGrid(model, design.height_m)
    load, rate, freq, statement = _at_design(grid, design, design.charge_bar)
    out = {
        "height_m": design.height_m,
        "charge_bar": design.charge_bar,
        "volume_l": design.volume_l,
        "polytropic": polytropic_keys(design.polytropic_range)[0],
        "reservoir_l": design.reservoir_l,
        "load_N": estimate(load),
        "rate_N_per_m": estimate(rate),
        "natural_frequency_Hz": estimate(freq),
        "polytropic_range": polytropic_keys(design.polytropic_range)[1],
        "volume_sd_l": design.volume_sd_l,
        "dvdp_l_per_bar": design.dvdp_l_per_bar,
        "dvdp_sd_l_per_bar": grid.dvdp_sd(design)[0],
        "dvdp_sd_from": grid.dvdp_sd(design)[1],
        "model": model.label,
        "n_draws": int(load.size),
        "level": LEVEL,
        "assumptions": [
            statement,
            _polytropic_words(design),
            "the load is the element's force at the design height: the sealed spring carries it there",
        ],
    }
    if design.forcing_Hz is not None:
        out["transmissibility"] = transmissibility_summary(freq, design.forcing_Hz)
    return out


def transmissibility_summary(natural_Hz, forcing_Hz: float) -> dict:
    """Transmissibility T = 1/|1 - r^2| and isolation 100 (1 - T) %, r = f_forcing / f_n, per draw.

    Undamped single degree of freedom: above r = sqrt 2 damping raises T, so the isolation stated
    is the best the spring can give; near resonance (r = 1) damping caps T, which this does not."""
    T = transmissibility(forcing_Hz, natural_Hz)
    return {
        "forcing_Hz": forcing_Hz,
        "transmissibility": estimate(T),
        "isolation_pct": estimate(isolation_pct(T)),
        "probability_isolating": float(np.mean(T < 1.0)),
        "model": "undamped single degree of freedom, T = 1/|1 - r^2|, r = f_forcing / f_n; "
        "isolation = 100 (1 - T) % (negative: amplification); damping raises T above r = sqrt 2",
    }


def sealed_curve(
    model, design: SealedDesign, grid: DesignGrid | None = None, charge_bar: float | None = None
) -> dict:
    """The sealed load-deflection curve with 90 % bands: overpressure (bar), load (N) and rate (N/m)
    at the grid heights where every draw's path pressure stays within the tested pressures.
    ``charge_bar``: another charge at the design height, with the design's volume assumption (as
    the frequency chart's charges)."""
    return sealed_curves(model, design, [charge_bar], grid)[0]


def sealed_curves(model, design: SealedDesign, charges_bar, grid: DesignGrid | None = None) -> list:
    """:func:`sealed_curve` for each of ``charges_bar`` (None: the design's charge), in one pass over
    the draws (:func:`sealed_paths`)."""
    check_design(model, design)
    grid = grid or DesignGrid(model, design.height_m)
    paths, statement = sealed_paths(grid, design, charges_bar)
    return [_curve(model, grid, design, path, statement) for path in paths]


def _curve(model, grid: DesignGrid, design: SealedDesign, path: SealedPath, statement: str) -> dict:
    ok = path.in_range.all(axis=0)
    out = {"height_m": grid.heights[ok]}
    for key, draws, scale in (
        ("pressure_bar", path.overpressure_pa, 1.0 / BAR_PA),
        ("load_N", path.force_N, 1.0),
        ("rate_N_per_m", path.rate_N_per_m, 1.0),
    ):
        m, lo, hi = band(draws[:, ok] * scale, axis=0, level=LEVEL)
        out[key] = {"mean": m, "q05": lo, "q95": hi}
    plo, phi = model.pressure_range_bar
    out["omitted_height_m"] = grid.heights[~ok]
    out["omitted_reason"] = (
        f"at {int((~ok).sum())} heights the sealed pressure leaves the tested pressures {plo:g}..{phi:g} bar "
        "in some draws: the model does not extrapolate"
        if (~ok).any()
        else ""
    )
    out["assumptions"] = [statement, _polytropic_words(design)]
    return out


def frequency_chart(
    model, design: SealedDesign, charges_bar=None, grid: DesignGrid | None = None
) -> dict:
    """Natural frequency against load at the design height over several charge pressures (the
    catalogue's chart), each with the design's volume assumption; a charge whose frequency is
    undefined in some draws is listed with the reason instead."""
    check_design(model, design)
    grid = grid or DesignGrid(model, design.height_m)
    plo, phi = model.pressure_range_bar
    if charges_bar is None:
        charges_bar = np.linspace(max(plo, 1.0) if phi > 1.0 else plo, phi, N_CHART)
    charges = np.asarray(charges_bar, float).tolist()
    try:  # every charge in one pass over the draws; a refusal: charge by charge, to say whose
        paths, statement = sealed_paths(grid, design, charges, [grid.height_m])
        solved = [(path, statement) for path in paths]
    except (InputError, RuntimeError):
        solved = [None] * len(charges)
    rows, omitted = [], []
    for p, done in zip(charges, solved, strict=True):
        try:
            load, rate, freq, _ = _at_design(grid, design, p, done)
        except InputError as exc:
            omitted.append({"charge_bar": float(p), "reason": str(exc)})
            continue
        rows.append(
            {
                "charge_bar": float(p),
                "load_N": estimate(load),
                "rate_N_per_m": estimate(rate),
                "natural_frequency_Hz": estimate(freq),
            }
        )
    return {"height_m": design.height_m, "rows": rows, "omitted": omitted}


def design_document(
    model, design: SealedDesign, charges_bar=None, grid: DesignGrid | None = None
) -> dict:
    """Everything ``uq design --json`` writes: the contract's keys at the design height, the sealed
    curve, the frequency chart (one model grid serves all three)."""
    return document_and_curves(model, design, charges_bar, grid, sheet=False)[0]


def document_and_curves(model, design, charges_bar=None, grid=None, *, sheet: bool = True):
    """(:func:`design_document`, {charge: sealed curve} of the chart's charges: the data sheet's,
    made in one pass over the draws with the design's own curve; empty unless ``sheet``)."""
    check_design(model, design)
    grid = grid or DesignGrid(model, design.height_m)
    out = design_point(model, design, grid)
    chart = frequency_chart(model, design, charges_bar, grid)
    charges = [row["charge_bar"] for row in chart["rows"]] if sheet else []
    try:
        out["sealed_curve"], *curves = sealed_curves(model, design, [None, *charges], grid)
    except (InputError, RuntimeError):  # the refusal the design's own curve makes, if any, first
        out["sealed_curve"] = sealed_curve(model, design, grid)
        curves = sealed_curves(model, design, charges, grid)
    out["frequency_chart"] = chart
    return out, dict(zip(charges, curves, strict=True))


# ----------------------------------------------------------------------------- the data sheet's tables


def isobaric_table(model, pressures_bar, heights_m, reference_height_m: float) -> list[dict]:
    """The catalogue's isobaric table: per (pressure, height) the load P, the effective area
    F_eff = P/p_u (eq. 1) and, for a model with a volume, the volume-derived area dV/dx and the
    volume increment V(x, p_u) - V(x_ref, p_u) from ``reference_height_m`` (what the stand
    measures: a change at one pressure), each {mean, sd, q05, q95}."""
    xs = np.asarray(heights_m, float)
    lo, hi = model.height_range_m
    has_volume = model.has_volume
    if has_volume:  # a fine grid through the table's heights and the reference, for the integral;
        # heights equal to 1 nm are one knot (0.07 and 0.07000000000000001 as two knots 1e-17 m
        # apart made the spline's integral lose five digits)
        fine = np.unique(
            np.round(np.concatenate([np.linspace(lo, hi, 91), xs, [reference_height_m]]), 9)
        )
    rows = []
    for p in np.asarray(pressures_bar, float):
        P = np.asarray(model.force_draws(xs, np.full(xs.shape, p)), float)
        if has_volume:
            A = np.asarray(model.volume_area_draws(fine, np.full(fine.shape, p)), float)
            dV = knots.integral_from(fine, A, axis=1, start=reference_height_m, to=xs)
            A_at = A[:, np.searchsorted(fine, np.round(xs, 9))]
        columns = {"load_N": P, "feff_m2": P / (p * BAR_PA)}
        if has_volume:
            columns.update(volume_area_m2=A_at, volume_increment_l=dV * L_PER_M3)
        per_height = {key: _estimates(draws) for key, draws in columns.items()}
        for j, x in enumerate(xs):
            row = {"pressure_bar": float(p), "height_m": float(x)}
            rows.append(row | {key: e[j] for key, e in per_height.items()})
    return rows


def _estimates(draws: np.ndarray) -> list[dict]:
    """``estimate(draws[:, j])`` for every column j of (S, J) draws, in one call: each column is
    made a contiguous row first, so that its sums and quantiles are the same numbers."""
    e = estimate(np.ascontiguousarray(np.asarray(draws, float).T), axis=1)
    return [{k: v[j] for k, v in e.items()} for j in range(draws.shape[1])]


# ----------------------------------------------------------------------------- design margins


def _check_margin_args(
    model, prob, max_frequency_Hz, rate_target_N_per_m, rate_tolerance_pct, force_limit_N
) -> None:
    """:func:`design_margin`'s refusals, before anything is computed."""
    if not 0.0 < prob < 1.0:
        raise InputError(
            f"prob: expected a probability between 0 and 1, got {prob:g}", param="prob"
        )
    if not model.has_volume:
        raise InputError(
            f"design margins need the volume-derived area dV/dx; the {model.label} has none "
            f"({model.omitted_reason}): only the pressure needed and the force band can be given"
        )
    for name, v in (
        ("max_frequency_Hz", max_frequency_Hz),
        ("rate_target_N_per_m", rate_target_N_per_m),
        ("force_limit_N", force_limit_N),
    ):
        if v is not None and not (np.isfinite(v) and v > 0):
            raise InputError(f"{name}: expected a positive number, got {v:g}", param=name)
    if not (np.isfinite(rate_tolerance_pct) and rate_tolerance_pct > 0):
        raise InputError(
            f"rate_tolerance_pct: expected a positive percentage, got {rate_tolerance_pct:g}",
            param="rate_tolerance_pct",
        )


def design_margin(
    model,
    height_m: float,
    load_N: float,
    design: SealedDesign,
    prob: float = 0.95,
    *,
    max_frequency_Hz: float | None = None,
    rate_target_N_per_m: float | None = None,
    rate_tolerance_pct: float = 10.0,
    force_limit_N: float | None = None,
    grid: DesignGrid | None = None,
) -> dict:
    """Design margins on the sealed spring (``uq margin --max-frequency-hz/--rate-target-N-per-m/
    --force-limit-N``): the spring carries ``load_N`` at ``height_m``, so each posterior draw is
    charged there to the overpressure at which it carries the load (uq._derived.margin.
    pressure_needed) and closed with the design's volume (measured in that loaded state),
    polytropic exponent, reservoir and dV/dp_u assumption. Per draw: the sealed rate and natural
    frequency there, and the stroke to ``force_limit_N`` along the sealed curve (compression when
    the limit exceeds the load, rebound when below). Probabilities are over the posterior of the
    mean characteristic and the design's drawn inputs (``design.seed``)."""
    _check_margin_args(
        model, prob, max_frequency_Hz, rate_target_N_per_m, rate_tolerance_pct, force_limit_N
    )
    if grid is None:  # the model's draws: at most DEFAULT_DRAWS
        model = model.on_draws(DEFAULT_DRAWS)
    p_need = pressure_needed(model, height_m, load_N).values
    if not np.all(np.isfinite(p_need)):
        raise InputError(
            f"load_N: {load_N:g} N at {height_m * 1e3:g} mm lies at the edge of the tested pressures in part "
            "of the posterior; choose a load further inside",
            param="load_N",
        )
    design = replace(design, height_m=height_m, charge_bar=float(np.mean(p_need)), forcing_Hz=None)
    check_design(model, design)
    if grid is None:
        lo, hi = model.height_range_m
        if force_limit_N is None:  # the rate at the design height needs only its neighbourhood
            span = (height_m - MARGIN_SPAN_M, height_m + MARGIN_SPAN_M)
        else:
            span = (
                (lo, height_m + MARGIN_SPAN_M)
                if force_limit_N > load_N
                else (height_m - MARGIN_SPAN_M, hi)
            )
        grid = DesignGrid(model, height_m, span_m=span, n_pressures=MARGIN_PRESSURES)
    if grid.n_draws != p_need.size:
        raise ValueError("the grid and the model hold different draws")
    path, statement = sealed_draws(grid, design, charge_bar=p_need)
    j = int(np.argmin(np.abs(grid.heights - height_m)))
    load, rate = path.force_N[:, j], path.rate_N_per_m[:, j]
    where = f"at {height_m * 1e3:g} mm carrying {load_N:g} N"
    freq = natural_frequency_Hz(rate, load, where)
    out = {
        "charge_bar": estimate(p_need),
        "load_check_N": estimate(load),
        "rate_N_per_m": estimate(rate),
        "natural_frequency_Hz": estimate(freq),
        "volume_l": design.volume_l,
        "volume_sd_l": design.volume_sd_l,
        "polytropic": polytropic_keys(design.polytropic_range)[0],
        "polytropic_range": polytropic_keys(design.polytropic_range)[1],
        "reservoir_l": design.reservoir_l,
        "dvdp_l_per_bar": design.dvdp_l_per_bar,
        "dvdp_sd_l_per_bar": grid.dvdp_sd(design)[0],
        "dvdp_sd_from": grid.dvdp_sd(design)[1],
        "assumptions": [
            f"each posterior draw charged at {height_m * 1e3:g} mm to the overpressure at which it carries "
            f"{load_N:g} N there, then closed",
            statement.replace(f"and {design.charge_bar:g} bar", "in the loaded state"),
            _polytropic_words(design),
        ],
    }
    if max_frequency_Hz is not None:
        p_below = float(np.mean(freq < max_frequency_Hz))
        out["frequency_below"] = {
            "max_frequency_Hz": max_frequency_Hz,
            "probability": p_below,
            "meets_prob": bool(p_below >= prob),
            "frequency_for_prob_Hz": float(np.quantile(freq, prob)),
        }
    if rate_target_N_per_m is not None:
        off = np.abs(rate / rate_target_N_per_m - 1.0) * 100.0
        p_in = float(np.mean(off <= rate_tolerance_pct))
        out["rate_within"] = {
            "target_N_per_m": rate_target_N_per_m,
            "tolerance_pct": rate_tolerance_pct,
            "probability": p_in,
            "meets_prob": bool(p_in >= prob),
            "deviation_pct": estimate(100.0 * (rate / rate_target_N_per_m - 1.0)),
        }
    if force_limit_N is not None:
        out["stroke_to_force_limit"] = _stroke_to_limit(path, j, force_limit_N, load_N, prob)
    return out


def _stroke_to_limit(path: SealedPath, j: int, limit_N: float, load_N: float, prob: float) -> dict:
    """Per draw, the distance from the design height along the sealed curve to where the force
    reaches ``limit_N`` (towards lower heights when the limit exceeds the load, else higher),
    linear between grid heights; a draw whose curve does not reach it within the tested heights
    and pressures has a stroke of at least the range (counted as not reached)."""
    xs, F = path.height_m, path.force_N
    step = -1 if limit_N > load_N else 1
    idx = np.arange(j, -1, -1) if step < 0 else np.arange(j, xs.size)
    sign = 1.0 if limit_N > load_N else -1.0
    S = F.shape[0]
    stroke = np.full(S, np.inf)
    prev = F[:, idx[0]]
    alive = np.ones(S, bool)
    for a, b in itertools.pairwise(idx):
        f = F[:, b]
        alive &= np.isfinite(f)
        hit = alive & np.isinf(stroke) & (sign * (f - limit_N) >= 0)
        frac = np.where(hit, (limit_N - prev) / np.where(f != prev, f - prev, 1.0), 0.0)
        stroke = np.where(hit, abs(xs[a] - xs[j]) + frac * abs(xs[b] - xs[a]), stroke)
        prev = f
    reached = np.isfinite(stroke)
    direction = "compression (height falling)" if step < 0 else "rebound (height rising)"
    available = abs(xs[idx[-1]] - xs[j])
    big = 1e9
    q = float(np.quantile(np.where(reached, stroke, big), 1.0 - prob))
    return {
        "force_limit_N": limit_N,
        "direction": direction,
        "prob_reached_in_tested_range": float(reached.mean()),
        "stroke_m": estimate(stroke) if reached.all() else None,
        "stroke_for_prob_m": None if q >= big else q,
        "meaning": f"with probability {prob:g} the force stays within the limit over at least stroke_for_prob_m of "
        f"{direction} from the design height; the tested heights give at most {available * 1e3:.1f} mm that way"
        + (
            ""
            if reached.all()
            else "; draws not reaching the limit within them count as longer strokes"
        ),
    }
