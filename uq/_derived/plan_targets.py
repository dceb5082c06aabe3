"""The quantities ``uq plan`` plans for (docs/plan.md): their syntax, and each one linearised in a
model's coefficients.

Every model of ``uq`` is linear in its coefficients beta given its sampled parameters theta, so a
quantity that is linear in beta (the force at a point, the paper's effective area there) has, given
theta, the posterior variance g' A^-1 g exactly (g its row, A the coefficients' posterior precision).
The others are smooth functions of beta and are linearised at the posterior mean given theta
(the delta method): the pressure that carries a load (the root of P(x, p_u) = W), the sealed natural
frequency (uq._physics.sealed: S2 to S4 at the design point), the elastic casing's magnitude. The
planner then needs of a target only ``linearise(frame, beta, open)``: its value, its gradient in
beta and the variance the data cannot reduce (an interpolation error, the spread of a design
input), per draw of theta.

Units: each target's value and sd are in the unit ``unit`` names: N, m^2, Pa, Hz, and 1/bar for the
elastic casing (the magnitude's unit in the mechanisms' table, docs/formats.md section 4).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from uq._io.errors import InputError
from uq._physics.quantities import BAR_PA
from uq._physics.sealed import G_STANDARD, pressure_slope, sealed_rate

KINDS = ("force", "feff", "pressure_for", "natural_frequency", "elastic_casing")
UNITS = {
    "force": "N",
    "feff": "m^2",
    "pressure_for": "Pa",
    "natural_frequency": "Hz",
    "elastic_casing": "1/bar",
}
SYNTAX = {
    "force": "force@H mm,P bar (e.g. force@110mm,6.5bar)",
    "feff": "feff@H mm,P bar (e.g. feff@112mm,5bar)",
    "pressure_for": "pressure_for@H mm,W N (e.g. pressure_for@110mm,9000N)",
    "natural_frequency": "natural_frequency@H mm,P bar (e.g. natural_frequency@112mm,5bar)",
    "elastic_casing": "elastic_casing, or elastic_casing@P1bar,P2bar",
}
#: the units a target's arguments may carry, and their factor to mm, bar or N
_ARG_UNITS = {"mm": ("mm", 1.0), "m": ("mm", 1e3), "bar": ("bar", 1.0), "N": ("N", 1.0)}
_ARG_UNITS["kN"] = ("N", 1e3)
STEP_X_M = 1.0e-4  # central differences of the (polynomial) rows in height
STEP_P_BAR = 1.0e-3  # and in pressure
N_ROOT_GRID = 401


@dataclass(frozen=True)
class SealedInputs:
    """What ``uq design``'s options say of the sealed spring, for ``natural_frequency`` targets:
    the internal volume at the design point (litres) and its sd, the polytropic exponent (a value or
    a range, uniform per draw), a reservoir, and dV/dp_u at the design height (L/bar)."""

    volume_l: float | None = None
    volume_sd_l: float = 0.0
    polytropic: float | tuple[float, float] = 1.0
    reservoir_l: float = 0.0
    dvdp_l_per_bar: float = 0.0
    p_atm_bar: float = 1.01325

    def nodes(self):
        """Quadrature nodes and weights of (polytropic exponent, volume m^3) over their stated
        spread: 3-point Gauss-Legendre on a uniform range, 3-point Gauss-Hermite on a normal volume."""
        n = self.polytropic
        lo, hi = (float(n[0]), float(n[1])) if isinstance(n, tuple | list) else (float(n),) * 2
        if hi > lo:
            x, w = np.polynomial.legendre.leggauss(3)
            ns, wn = lo + (hi - lo) * (x + 1) / 2, w / 2
        else:
            ns, wn = np.array([lo]), np.array([1.0])
        v = float(self.volume_l) * 1e-3
        if self.volume_sd_l > 0:
            x, w = np.polynomial.hermite_e.hermegauss(3)
            vs, wv = v + self.volume_sd_l * 1e-3 * x, w / w.sum()
        else:
            vs, wv = np.array([v]), np.array([1.0])
        N, V = np.meshgrid(ns, vs, indexing="ij")
        return N.ravel(), V.ravel(), np.outer(wn, wv).ravel()


@dataclass(frozen=True)
class Target:
    """One quantity to plan for, parsed from its spec (``parse_target``). Heights in m, pressures in
    bar, loads in N; ``pressures_bar`` of an ``elastic_casing`` target: the two pressures between
    which the volume-derived area's growth is taken (None: the lowest and highest tested ones)."""

    spec: str
    kind: str
    height_m: float | None = None
    pressure_bar: float | None = None
    load_N: float | None = None
    pressures_bar: tuple[float, float] | None = None
    sealed: SealedInputs | None = None

    @property
    def unit(self) -> str:
        return UNITS[self.kind]

    @property
    def needs_volume(self) -> bool:
        return self.kind in ("natural_frequency", "elastic_casing")

    def with_range(self, tested_bar) -> Target:
        """An ``elastic_casing`` target without pressures takes FILE's lowest and highest tested
        pressure (so that it names the same quantity now and after the plan)."""
        if self.kind != "elastic_casing" or self.pressures_bar is not None:
            return self
        p = np.asarray(tested_bar, float)
        if p.size < 2:
            raise InputError(
                f"target: {self.spec}: the casing's magnitude is the volume-derived area's growth "
                "between two pressures, and the file holds one test: write "
                "elastic_casing@P1bar,P2bar with the pressures to compare",
                param="target",
            )
        return Target(self.spec, self.kind, pressures_bar=(float(p.min()), float(p.max())))

    # ---- the pressures a model must have tested to answer (it does not extrapolate)
    def fixed_pressures(self) -> tuple[float, ...]:
        if self.kind == "elastic_casing":
            return tuple(self.pressures_bar or ())
        return () if self.pressure_bar is None else (self.pressure_bar,)

    # ---- value, gradient and irreducible variance per draw of theta
    def linearise(self, frame, beta: np.ndarray, open_: np.ndarray):
        """(value (S,), gradient (S, k), irreducible variance (S,)) at coefficients ``beta`` (S, k)
        (the posterior mean given each draw of theta), in the frame's tests ``open_``."""
        S = beta.shape[0]
        fn = getattr(self, f"_{self.kind}")
        value, grad, extra = fn(frame, beta, open_)
        return (
            np.broadcast_to(value, (S,)).astype(float),
            np.broadcast_to(grad, beta.shape).astype(float),
            np.broadcast_to(extra, (S,)).astype(float),
        )

    def _force(self, frame, beta, open_):
        S = beta.shape[0]
        row = _rows(frame.force_rows, [self.height_m], [self.pressure_bar], open_, S)[:, 0]
        extra = _extra(frame, [self.height_m], [self.pressure_bar], open_, S)[:, 0]
        return np.sum(beta * row, axis=1), row, extra

    def _feff(self, frame, beta, open_):
        value, row, extra = self._force(frame, beta, open_)
        p_pa = self.pressure_bar * BAR_PA
        return value / p_pa, row / p_pa, extra / p_pa**2

    def _pressure_for(self, frame, beta, open_):
        """The root p* of P(x, p) = W per draw (the force rises with pressure), d p*/d beta =
        -f(x, p*) / (dP/dp_u): the implicit function theorem."""
        S = beta.shape[0]
        lo, hi = frame.pressure_range(open_)
        ps = np.linspace(lo, hi, N_ROOT_GRID)
        x = np.full(ps.shape, self.height_m)
        P = np.einsum("sk,sgk->sg", beta, _rows(frame.force_rows, x, ps, open_, S))
        above = P >= self.load_N
        first = np.argmax(above, axis=1)
        ok = above.any(axis=1) & ~above[:, 0]
        if not ok.all():
            return np.nan, np.zeros(beta.shape[1]), np.nan
        i = first
        rows = np.arange(S)
        p0, p1, f0, f1 = ps[i - 1], ps[i], P[rows, i - 1], P[rows, i]
        root = p0 + (self.load_N - f0) / (f1 - f0) * (p1 - p0)
        xs = np.full(root.shape, self.height_m)
        row = _rows_each(frame.force_rows, xs, root, open_, S)  # (S, k)
        up = np.minimum(root + STEP_P_BAR, hi)
        down = np.maximum(root - STEP_P_BAR, lo)
        slope_rows = (
            _rows_each(frame.force_rows, xs, up, open_, S)
            - _rows_each(frame.force_rows, xs, down, open_, S)
        ) / ((up - down)[:, None] * BAR_PA)
        slope = np.sum(beta * slope_rows, axis=1)  # dP/dp_u, N/Pa
        extra = _extra(frame, xs, root, open_, S)[rows, rows] / slope**2
        return root * BAR_PA, -row / slope[:, None], extra

    def _natural_frequency(self, frame, beta, open_):
        """f = sqrt(k g / P) / (2 pi), k = -(P_x + P_p dp_u/dx), dp_u/dx = -n p_abs V_x / (V + V_r +
        n p_abs V_p) at the design point (uq._physics.sealed, S2-S4: what ``uq design`` computes
        there), linearised in beta at the mean polytropic exponent and volume; the spread of those
        over their stated ranges is added as irreducible variance."""
        x, p = self.height_m, self.pressure_bar
        s = self.sealed
        lo, hi = frame.pressure_range(open_)
        xs = np.array([x, x + STEP_X_M, x - STEP_X_M, x, x])
        pu, pd = min(p + STEP_P_BAR, hi), max(p - STEP_P_BAR, lo)
        ps = np.array([p, p, p, pu, pd])
        S = beta.shape[0]
        F = _rows(frame.force_rows, xs, ps, open_, S)
        rows = {
            "P": F[:, 0],
            "Px": (F[:, 1] - F[:, 2]) / (2 * STEP_X_M),
            "Pp": (F[:, 3] - F[:, 4]) / ((pu - pd) * BAR_PA),
            "A": _rows(frame.area_rows, [x], [p], open_, S)[:, 0],
        }  # (S, k) each
        v = {k: np.sum(beta * r, axis=1) for k, r in rows.items()}  # (S,) each
        p_pa, p_atm = p * BAR_PA, s.p_atm_bar * BAR_PA
        vr, vp = s.reservoir_l * 1e-3, s.dvdp_l_per_bar * 1e-3 / BAR_PA
        ns, vs, ws = s.nodes()

        def freq(vals, n, V):
            dpdx = pressure_slope(p_pa, V, vals["A"], vp, n, vr, p_atm)
            k = sealed_rate(vals["Px"], vals["Pp"], dpdx)
            return np.sqrt(np.maximum(k, 0) * G_STANDARD / vals["P"]) / (2 * np.pi), k, dpdx

        n_bar, v_bar = float(ws @ ns), float(ws @ vs)
        f, k, dpdx = freq(v, n_bar, v_bar)
        if not (np.all(k > 0) and np.all(v["P"] > 0)):
            raise InputError(
                f"target: {self.spec}: the sealed rate or the load is not positive at the design point "
                "in part of the posterior; f = sqrt(k g / P) / (2 pi) needs both positive",
                param="target",
            )
        # df = f/2 (dk/k - dP/P); dk = -(dPx + dPp dpdx + Pp d(dpdx)), d(dpdx) = dpdx dA / A
        dk = -(
            rows["Px"] + dpdx[:, None] * rows["Pp"] + (v["Pp"] * dpdx / v["A"])[:, None] * rows["A"]
        )
        grad = (f / 2)[:, None] * (dk / k[:, None] - rows["P"] / v["P"][:, None])
        spread = np.stack([freq(v, n, V)[0] for n, V in zip(ns, vs, strict=True)])  # (nodes, S)
        extra = ws @ (spread - ws @ spread) ** 2
        return f, grad, extra

    def _elastic_casing(self, frame, beta, open_):
        """m = (A_hi - A_lo) / (p_hi A_lo - p_lo A_hi) per bar, A = dV/dx at x0: for a volume-derived
        area V0'(x) + p_u C'(x) (the mechanism elastic_casing, docs/formats.md section 4) exactly
        C'(x0) / V0'(x0), whichever two pressures."""
        p_lo, p_hi = self.pressures_bar
        x0 = frame.x0_m
        rows = _rows(frame.area_rows, [x0, x0], [p_lo, p_hi], open_, beta.shape[0])
        a_lo, a_hi = np.sum(beta * rows[:, 0], axis=1), np.sum(beta * rows[:, 1], axis=1)
        N, D = a_hi - a_lo, p_hi * a_lo - p_lo * a_hi
        value = N / D
        d_hi = (D + N * p_lo) / D**2
        d_lo = -(D + N * p_hi) / D**2
        return value, d_hi[:, None] * rows[:, 1] + d_lo[:, None] * rows[:, 0], 0.0


def _rows(fn, x, p, open_, S: int) -> np.ndarray:
    """A frame's rows at points, per draw, (S, n, k): rows that do not depend on the draw ((n, k),
    the models linear in fixed functions) are broadcast without copying; a model whose rows between
    tests depend on its sampled parameters (a Gaussian process in pressure) gives (S, n, k)."""
    r = np.asarray(
        fn(np.atleast_1d(np.asarray(x, float)), np.atleast_1d(np.asarray(p, float)), open_)
    )
    return np.broadcast_to(r, (S, *r.shape)) if r.ndim == 2 else r


def _rows_each(fn, x, p, open_, S: int) -> np.ndarray:
    """Draw s's row at point s, (S, k) (x, p of S points: a root per draw)."""
    r = np.asarray(fn(np.asarray(x, float), np.asarray(p, float), open_))
    return r if r.ndim == 2 else r[np.arange(S), np.arange(S)]


def _extra(frame, x, p, open_, S: int) -> np.ndarray:
    """The force's irreducible variance at points, per draw, (S, n) (zero without one)."""
    fn = getattr(frame, "extra_force_var", None)
    n = np.size(x)
    if fn is None:
        return np.zeros((S, n))
    e = np.asarray(
        fn(np.atleast_1d(np.asarray(x, float)), np.atleast_1d(np.asarray(p, float)), open_), float
    )
    return np.broadcast_to(e, (S, n)) if e.ndim == 1 else e


_SPEC = re.compile(r"^\s*([a-z_]+)\s*(?:@(.*))?$")
_ARG = re.compile(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([a-zA-Z]+)\s*$")


def _args(spec: str, kind: str, text: str) -> dict[str, float]:
    """``110mm,6.5bar`` -> {"mm": 110, "bar": 6.5}: each argument a number and its unit."""
    out: dict[str, float] = {}
    for part in text.split(","):
        m = _ARG.match(part)
        unit = m and _ARG_UNITS.get(m.group(2))
        if not m or unit is None:
            raise InputError(
                f"target: {spec}: '{part.strip()}' is not a number with a unit (mm, bar or N); "
                f"expected {SYNTAX[kind]}",
                param="target",
            )
        name, factor = unit
        if name in out and kind != "elastic_casing":
            raise InputError(
                f"target: {spec}: two values in {name}; expected {SYNTAX[kind]}", param="target"
            )
        out.setdefault(name, []).append(float(m.group(1)) * factor)
    return out


def parse_target(spec: str, sealed: SealedInputs | None = None) -> Target:
    """A target from its spec (docs/formats.md, ``uq plan`` targets); InputError naming the spec and
    the syntax otherwise. ``sealed``: the design options a ``natural_frequency`` target needs."""
    m = _SPEC.match(spec)
    kind = m.group(1) if m else None
    if kind not in KINDS:
        raise InputError(
            f"target: {spec}: unknown target; expected one of "
            + "; ".join(SYNTAX[k] for k in KINDS),
            param="target",
        )
    text = m.group(2)
    if kind == "elastic_casing":
        if text is None:
            return Target(spec, kind)
        a = _args(spec, kind, text)
        p = a.get("bar", [])
        if set(a) != {"bar"} or len(p) != 2 or not 0 < min(p) < max(p):
            raise InputError(
                f"target: {spec}: expected {SYNTAX[kind]} with two different positive pressures",
                param="target",
            )
        return Target(spec, kind, pressures_bar=(min(p), max(p)))
    if text is None:
        raise InputError(f"target: {spec}: expected {SYNTAX[kind]}", param="target")
    a = _args(spec, kind, text)
    second = "N" if kind == "pressure_for" else "bar"
    if set(a) != {"mm", second}:
        raise InputError(f"target: {spec}: expected {SYNTAX[kind]}", param="target")
    h, v = a["mm"][0], a[second][0]
    if not (h > 0 and v > 0):
        raise InputError(
            f"target: {spec}: the height and the {'load' if second == 'N' else 'pressure'} must be "
            f"positive; expected {SYNTAX[kind]}",
            param="target",
        )
    if kind == "pressure_for":
        return Target(spec, kind, height_m=h * 1e-3, load_N=v)
    if kind == "natural_frequency":
        if sealed is None or sealed.volume_l is None:
            raise InputError(
                f"target: {spec}: the sealed natural frequency needs the element's internal volume at "
                f"{h:g} mm and {v:g} bar (`volume_l`, litres, measured: the stand gives only volume changes)",
                param="volume_l",
            )
        return Target(spec, kind, height_m=h * 1e-3, pressure_bar=v, sealed=sealed)
    return Target(spec, kind, height_m=h * 1e-3, pressure_bar=v)
