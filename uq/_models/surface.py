"""Pressure-coupled surface model: one model of force and volume over all tests of a campaign.

Model (u = x - x0, t = u / h with h = 0.05 m, q = (p_u - p_mid) / p_half in -1..1 over the
tested pressures, p_u in Pa where it multiplies):

    force_ij  = p_i F_p(u_ij, p_i) + E(u_ij)
    piston_ij = r_i - (1/S) int_0^u [F_p(u', p_i) + D(u', p_i)] du'

    F_p(u, p) = sum_{k<=K, l<=Lp} c_kl t^k q^l   (pressure area, grows smoothly with p)
    E(u)      = sum_{m<=Ke} e_m t^m               (casing force, the same at every pressure)
    D(u, p)   = sum_{k<=Dk, l<=Dl} d_kl t^k q^l   (volume excess -dV/dx - F_p; 0 = traditional)

Names. F_p = (P - E) / p_u is the area on which the pressure acts once the casing's own force
is removed ("pressure area", ``pressure_area_m2`` in JSON). It is *not* the paper's effective
area F_eff = P / p_u (eq. 1), which includes the casing force: F_eff = F_p + E / p_u. Both are
reported, each under its own name (``feff_m2`` is always the paper's P / p_u).

r_i is one piston reference per test (nuisance). Everything is linear in (c, e, d, r) given
the noise: the model is a :class:`uq._inference.collapsed.CollapsedModel` (``MODEL``) fitted by the
one driver, emcee on the five noise parameters with exact coefficient draws.

Noise (stand's error budget, paper section 3.2): the pressure-holding error dp of one
reading moves the force by +dp F_p and the piston by -V_gas dp / (p_abs S) at once (a
higher pressure compresses the gas, so the piston stands short of its isobaric position),
so each reading (force, piston) is bivariate normal with covariance

    [[s0^2 + (r Phat)^2 + b^2,  -b c], [-b c, c^2 + sL^2]],
    b = k_p dp_i F_p_hat,  c = k_p dp_i V0 / (p_abs S)

with dp_i the stand's holding sd (0.01 bar, 0.001 bar at 0.1 bar), k_p its multiplier and V0
the stand's gas volume (element, receiver and pipe: in isobaric-isothermal conditions it keeps its
value, the gas/water boundary moving inside the receiver, eq. 4). The stand's constants
come from a ``StandDescription`` (``--stand FILE.toml``; default the paper's stand): dp_i from
its pressure holding, p_atm, and the centres of the priors
log s0[N] ~ N(log 10, 1.5), log r ~ N(log stand.load_cell_rel_sd, 0.5), log k_p ~ N(0, 0.5),
log sL[m] ~ N(log 1e-4, 1.5), log V0[m^3] ~ N(log stand.gas_volume_at_xmax_m3, 0.5) (paper:
0.5 %, 6.2 L); standardised coefficients ~ N(0, 1) with physical scales (c, d: 0.1 m^2;
e: 10 kN; r: 1 m).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from uq._data.recordings import Recordings
from uq._inference.convergence import CLI_ADVICE
from uq._inference.summary import band, estimate
from uq._models.linear_fit import BlockSpec, LinearFit, Params
from uq._physics.quantities import BAR_PA, BASIS_SCALE_M

MAX_DRAWS = 4000
SCALE_C = 0.1  # m^2
SCALE_E = 1.0e4  # N
SCALE_D = 0.1  # m^2
SCALE_R = 1.0  # m
LEVEL = 0.90
#: the sampled noise parameters as reported (uq._models.pair.NATURAL_NAMES; the force surface has
#: the first three)
NATURAL_NAMES = ("s0_N", "rel_load", "k_p", "sL_m", "V0_m3")


@dataclass(frozen=True)
class Orders(Params):
    """Polynomial orders: pressure area F_p degree K in t and Lp in q, casing degree Ke, D degrees (Dk, Dl).

    Dk = -1 means D = 0 (the traditional theory for the volume); Ke = -1 means no casing term;
    Dk = Dl = -1: no volume at all, the force surface of a campaign without piston readings.
    """

    K: int = 3
    Lp: int = 2
    Ke: int = 2
    Dk: int = 1
    Dl: int = 1

    @property
    def label(self) -> str:
        if self.Dk < 0 and self.Dl < 0:
            return force_label(self)
        d = "none" if self.Dk < 0 else f"{self.Dk}x{self.Dl}"
        return f"F_p {self.K}x{self.Lp}, casing {self.Ke}, D {d}"


#: chosen by PSIS-LOO on data/n50 (docs/surface.md): elpd_loo -262.3 against -299.0 (dse 13.8)
#: for the next best (F_p 3x4, casing 3, D 2x2) and -431.2 for F_p 3x2, casing 2, D 1x1
DEFAULT_ORDERS = Orders(3, 5, 3, 2, 3)


def default_orders(
    n_tests: int,
    *,
    min_heights: int | None = None,
    min_points: int | None = None,
    volume: bool = True,
) -> Orders:
    """``DEFAULT_ORDERS`` with its pressure degrees capped by what ``n_tests`` tests can fix: the
    force p_u F_p(x, p_u) + E(x) has Lp + 2 coefficients in pressure at a height (Lp <= n - 2),
    the volume's D has Dl + 1 (Dl <= n - 1). Campaigns of 7 tests or more get ``DEFAULT_ORDERS``
    itself; a coarse grid (3 to 5 pressures) a surface of lower degree in pressure.

    The height degrees K and Ke are capped by the test with the fewest distinct heights
    (``min_heights``: a degree below it) and the fewest readings (``min_points``: a degree that
    leaves each test at least one residual), so a catalogue table of 5 heights a pressure keeps
    its cubic and one of 4 gets a quadratic; the paper's two-branch tests are never capped.
    ``volume`` False: no volume block (Dk = Dl = -1), the force surface of a campaign without volume
    readings (uq._models.surface_force)."""
    o = DEFAULT_ORDERS
    cap = min(
        o.K,
        o.Ke,
        *(() if min_heights is None else (min_heights - 1,)),
        *(() if min_points is None else (min_points - 2,)),
    )
    K, Ke = min(o.K, cap), min(o.Ke, cap)
    Lp = max(0, min(o.Lp, n_tests - 2))
    if not volume:
        return Orders(K, Lp, Ke, -1, -1)
    return Orders(K, Lp, Ke, o.Dk, max(0, min(o.Dl, n_tests - 1)))


def orders_for(rec: Recordings) -> Orders:
    """:func:`default_orders` for a campaign: its number of tests, its fewest heights and readings
    in a test, and whether it has piston readings."""
    return default_orders(
        len(rec.tests),
        min_heights=min(np.unique(np.round(t.height_m, 9)).size for t in rec.tests),
        min_points=min(t.n_points for t in rec.tests),
        volume=rec.has_piston,
    )


#: the small candidate set ranked by PSIS-LOO (``select_orders``, ``uq surface --select``)
CANDIDATES = (
    Orders(3, 2, 2, 1, 1),
    Orders(3, 4, 2, 1, 1),
    Orders(3, 7, 2, 1, 1),
    Orders(3, 4, 3, 2, 2),
    Orders(3, 5, 3, 2, 3),
)


# ----------------------------------------------------------------------------- design


def tq_columns(t, q, kmax, lmax, integrate=False):
    t = np.asarray(t, float)[..., None, None]
    q = np.asarray(q, float)[..., None, None]
    k = np.arange(kmax + 1)[:, None]
    lq = np.arange(lmax + 1)[None, :]
    cols = t ** (k + 1) / (k + 1) * q**lq if integrate else t**k * q**lq
    cols = np.broadcast_to(cols, cols.shape)
    return cols.reshape(*cols.shape[:-2], -1)


def poly_columns(t, m):
    t = np.asarray(t, float)[..., None]
    return t ** np.arange(m + 1)


@dataclass(frozen=True)
class Geometry(Params):
    x0_m: float
    area_m2: float
    p_mid: float
    p_half: float

    def t(self, x_m):
        return (np.asarray(x_m, float) - self.x0_m) / BASIS_SCALE_M

    def q(self, p_bar):
        return (np.asarray(p_bar, float) - self.p_mid) / self.p_half


def sizes(o: Orders, n_tests: int):
    nc = (o.K + 1) * (o.Lp + 1)
    ne = o.Ke + 1
    nd = 0 if o.Dk < 0 else (o.Dk + 1) * (o.Dl + 1)
    return nc, ne, nd, n_tests


def force_design(o: Orders, g: Geometry, x_m, p_bar, n_columns: int | None = None):
    """The force design p_u F_p + E in standardised coefficients, (n, n_columns): the pressure-area
    and casing columns first, zeros after them (default: those columns alone)."""
    t, q = g.t(x_m), g.q(p_bar)
    p_pa = np.asarray(p_bar, float) * BAR_PA
    nc, ne = (o.K + 1) * (o.Lp + 1), o.Ke + 1
    Xf = np.zeros((t.size, nc + ne if n_columns is None else n_columns))
    Xf[:, :nc] = p_pa[:, None] * tq_columns(t, q, o.K, o.Lp) * SCALE_C
    if ne:
        Xf[:, nc : nc + ne] = poly_columns(t, o.Ke) * SCALE_E
    return Xf


def designs(o: Orders, g: Geometry, x_m, p_bar, test_index, n_tests):
    """Force and piston design matrices in standardised coefficients, (n, k) each."""
    t, q = g.t(x_m), g.q(p_bar)
    n = t.size
    nc, ne, nd, nr = sizes(o, n_tests)
    Xf = force_design(o, g, x_m, p_bar, nc + ne + nd + nr)
    Xl = np.zeros_like(Xf)
    lever = -BASIS_SCALE_M / g.area_m2
    Xl[:, :nc] = lever * tq_columns(t, q, o.K, o.Lp, integrate=True) * SCALE_C
    if nd:
        Xl[:, nc + ne : nc + ne + nd] = (
            lever * tq_columns(t, q, o.Dk, o.Dl, integrate=True) * SCALE_D
        )
    Xl[np.arange(n), nc + ne + nd + np.asarray(test_index)] = SCALE_R
    return Xf, Xl


# ----------------------------------------------------------------------------- fit


@dataclass(eq=False, frozen=True, repr=False)
class SurfaceFit(LinearFit):
    """The surface model fitted to a campaign (or loaded from a saved file): force, pressure area,
    casing force, volume excess and the volume-derived area on the fixed posterior draws
    (:class:`uq._models.linear_fit.LinearFit`). Fitted by ``uq._models.surface_likelihood.
    fit_surface``."""

    name = "surface"
    words = "the surface model"
    likelihood = "uq._models.surface_likelihood"
    orders_type = Orders
    geometry_type = Geometry
    #: why it answers margins when the data do not prefer the cubics (uq._derived.margin.choose)
    coverage_note = (
        "the fallback when the data do not decide; its coverage for truths inside the default "
        "orders' class is checked by tests/models/test_surface.py (reports/surface-coverage/"
        "coverage.json: 100 replications on the paper's layout)"
    )

    @property
    def force_only(self) -> bool:
        """Fitted to the force alone (no piston readings: uq._models.surface_force); the volume
        methods then refuse with :attr:`omitted_reason`."""
        return self.orders.Dk < 0 and self.orders.Dl < 0

    @property
    def has_volume(self) -> bool:
        return not self.force_only

    @property
    def omitted_reason(self) -> str | None:
        if not self.force_only:
            return None
        if self.recordings is not None:
            return volume_omitted_reason(self.recordings)
        return "volume results omitted: the surface was fitted to the force alone"

    # ---- the coefficient blocks and their columns
    def block_layout(self) -> tuple[BlockSpec, ...]:
        o = self.orders
        ckl = tuple(f"c_{k}{lq}" for k in range(o.K + 1) for lq in range(o.Lp + 1))
        out = [
            BlockSpec("pressure_area_m2", ckl, SCALE_C, "m^2", "F_p = sum c_kl t^k q^l"),
            BlockSpec(
                "casing_N",
                tuple(f"e_{m}" for m in range(o.Ke + 1)),
                SCALE_E,
                "N",
                "E = sum e_m t^m",
            ),
        ]
        if self.force_only:
            return tuple(out)
        dkl = (
            tuple(f"d_{k}{lq}" for k in range(o.Dk + 1) for lq in range(o.Dl + 1))
            if o.Dk >= 0
            else ()
        )
        refs = tuple(f"r_{p:g}bar" for p in self.tested_pressures_bar)
        return (
            *out,
            BlockSpec("volume_excess_m2", dkl, SCALE_D, "m^2", "D = sum d_kl t^k q^l"),
            BlockSpec("piston_reference_m", refs, SCALE_R, "m", "one piston reference per test"),
        )

    def _columns(self, x_m, p_bar, c=0.0, e=0.0, d=0.0) -> np.ndarray:
        """[c x F_p's columns, e x E's, d x D's, zeros for the references], (n, k); c, d may be
        arrays (n,) (p_u in Pa for the force)."""
        o, g = self.orders, self.geometry
        t, q = g.t(x_m), g.q(p_bar)
        parts = [np.asarray(c)[..., None] * tq_columns(t, q, o.K, o.Lp), e * poly_columns(t, o.Ke)]
        if not self.force_only:
            nd = 0 if o.Dk < 0 else (o.Dk + 1) * (o.Dl + 1)
            D = tq_columns(t, q, o.Dk, o.Dl) if nd else np.zeros((t.size, 0))
            parts += [
                np.asarray(d)[..., None] * D,
                np.zeros((t.size, len(self.tested_pressures_bar))),
            ]
        return np.concatenate([np.broadcast_to(a, (t.size, a.shape[-1])) for a in parts], axis=1)

    def force_columns(self, x_m, p_bar):
        """P = p_u F_p + E."""
        return self._columns(x_m, p_bar, c=np.asarray(p_bar, float) * BAR_PA, e=1.0)

    def area_columns(self, x_m, p_bar):
        """-dV/dx = F_p + D."""
        return self._columns(x_m, p_bar, c=1.0, d=1.0)

    # ---- the surface's own quantities, draws (S, *broadcast shape)
    def pressure_area_draws(self, height_m, p_bar, *, check=True):
        """Pressure area F_p(x, p_u) = (P - E) / p_u draws, m^2."""
        return self.evaluate(lambda x, p: self._columns(x, p, c=1.0), height_m, p_bar, check=check)

    def casing_draws(self, height_m, *, check=True):
        """The casing's own force E(x), N (the same at every pressure)."""
        p = self.pressure_range_bar[0]
        return self.evaluate(lambda x, _: self._columns(x, p, e=1.0), height_m, p, check=check)

    def volume_excess_draws(self, height_m, p_bar, *, check=True):
        """D(x, p_u) = -dV/dx - F_p draws, m^2 (0 in the traditional theory)."""
        # refuses force only
        self.volume_area_draws(self.x0_m, self.pressure_range_bar[0], check=False)
        return self.evaluate(lambda x, p: self._columns(x, p, d=1.0), height_m, p_bar, check=check)

    def spread_draws(self, height_m, p_bar, *, check=True):
        """Traditional characteristic p_u (-dV/dx) minus the experimental force: p_u D - E, N."""
        self.volume_area_draws(self.x0_m, self.pressure_range_bar[0], check=False)
        return self.evaluate(
            lambda x, p: self._columns(x, p, e=-1.0, d=np.asarray(p, float) * BAR_PA),
            height_m,
            p_bar,
            check=check,
        )

    def bands(self, height_m, p_bar, level: float = LEVEL) -> dict:
        """Pointwise 90 % bands of F_p, the paper's F_eff, force and spread (refuses extrapolation;
        no spread for a force-only fit)."""
        out = {}
        for name, fn in (
            ("pressure_area_m2", self.pressure_area_draws),
            ("feff_m2", self.feff_draws),
            ("force_N", self.force_draws),
            *(() if self.force_only else (("spread_N", self.spread_draws),)),
        ):
            out[name] = self.band(fn, height_m, p_bar, level)
        return out

    def fitted_document(self, comparison: dict | None, advice: str) -> dict:
        """What ``uq surface --json`` writes (docs/formats.md)."""
        return summary(self, comparison, advice)


def geometry_of(rec: Recordings) -> Geometry:
    p = rec.pressures_bar
    mid, half = (p.max() + p.min()) / 2, max((p.max() - p.min()) / 2, 1e-3)
    return Geometry(rec.x0_m, rec.piston_area_m2, float(mid), float(half))


def force_label(o: Orders) -> str:
    """The orders of a force-only surface in words (no volume block)."""
    return f"F_p {o.K}x{o.Lp}, casing {o.Ke}, force only"


def volume_omitted_reason(rec: Recordings) -> str:
    """One line: why a surface fitted to ``rec`` has no volume results (None when it has them)."""
    if rec.has_piston:
        return None
    with_volume = [t for t in rec.tests if t.volume_m3 is not None]
    if not with_volume:
        return "volume results omitted: force-only campaign (no piston_* or volume_* column)"
    at = ", ".join(f"{t.pressure_bar:g}" for t in with_volume)
    return (
        f"volume results omitted: the volume_* column (at {at} bar only) cannot fix how the volume "
        "changes with pressure, so the surface is fitted to the force alone (uq fit and uq diagnose "
        "read the column)"
    )


# ----------------------------------------------------------------------------- summaries

DEFINITIONS = {
    "pressure_area_m2": "F_p = (P - E) / p_u: the area on which the pressure acts, the casing force E removed "
    "(the surface model's own quantity, not the paper's F_eff)",
    "feff_m2": "F_eff = P / p_u: the paper's effective area (eq. 1) of the model's mean force, casing force included",
    "casing_N": "E(x): the casing's own force, the same at every pressure",
    "volume_excess_m2": "D = -dV/dx - F_p: volume-derived area beyond the pressure area (0 in the traditional theory)",
    "spread_N": "p_u (-dV/dx) - P = p_u D - E: traditional minus measured force",
}


def coefficient_summary(fit: SurfaceFit) -> dict:
    """The coefficient blocks' estimates, the piston references keyed by their test's pressure."""
    out = LinearFit.coefficient_summary(fit)
    if "piston_reference_m" in out:
        refs = out["piston_reference_m"].values()
        out["piston_reference_m"] = {
            f"{p:g} bar": e for p, e in zip(fit.tested_pressures_bar, refs, strict=True)
        }
    return out


def spread_region(fit: SurfaceFit, n_x: int = 46, n_p: int = 41, level: float = LEVEL) -> dict:
    """Grid of the spread's band over (x, p_u) and where it excludes zero."""
    lo, hi = fit.height_range_m
    plo, phi = fit.pressure_range_bar
    xs = np.linspace(lo, hi, n_x)
    ps = np.linspace(plo, phi, n_p)
    X, P = np.meshgrid(xs, ps, indexing="ij")
    m, lo_b, hi_b = band(fit.on_draws(2000).spread_draws(X, P), axis=0, level=level)
    nonzero = (lo_b > 0) | (hi_b < 0)
    return {
        "height_m": xs,
        "pressure_bar": ps,
        "mean": m,
        "lower": lo_b,
        "upper": hi_b,
        "credibly_nonzero": nonzero,
    }


def summary(fit: SurfaceFit, comparison: dict | None = None, advice: str = CLI_ADVICE) -> dict:
    """The JSON document of ``uq surface`` (:meth:`SurfaceFit.to_json`). A force-only fit has no
    volume keys (volume excess, piston references, piston noise, spread) and an ``omitted`` object
    naming each with the one-line reason."""
    g = fit.geometry
    plo, phi = fit.pressure_range_bar
    ref = {}
    some = fit.on_draws(2000)
    x0 = np.array(g.x0_m)
    for pb in sorted({plo, (plo + phi) / 2, phi}):
        ref[f"{pb:g}"] = {
            "pressure_area_m2": estimate(some.pressure_area_draws(x0, pb)),
            "feff_m2": estimate(some.feff_draws(x0, pb)),
            "force_N": estimate(some.force_draws(x0, pb)),
        }
        if not fit.force_only:
            ref[f"{pb:g}"]["spread_N"] = estimate(some.spread_draws(x0, pb))
    basis = "t = (x - x0) / 0.05 m; F_p = sum c_kl t^k q^l; E = sum e_m t^m"
    out = fit.json_head() | {
        "pressure_scaling": {
            "q": "(p_bar - p_mid) / p_half",
            "p_mid_bar": g.p_mid,
            "p_half_bar": g.p_half,
        },
        "basis": basis if fit.force_only else basis + "; D = sum d_kl t^k q^l",
        "definitions": {
            k: v
            for k, v in DEFINITIONS.items()
            if not (fit.force_only and k in ("volume_excess_m2", "spread_N"))
        },
        "stand": asdict(fit.stand),
        "valid_range": {"height_m": list(fit.height_range_m), "pressure_bar": [plo, phi]},
        "coefficients": coefficient_summary(fit),
        "noise": fit.noise_summary(NATURAL_NAMES[:3] if fit.force_only else NATURAL_NAMES),
        "at_x0": ref,
    }
    if fit.force_only:
        why = fit.omitted_reason
        out["omitted"] = {
            k: why
            for k in (
                "volume_excess_m2",
                "piston_reference_m",
                "sL_m",
                "V0_m3",
                "spread_N",
                "spread_credibly_nonzero_fraction",
            )
        }
    else:
        reg = spread_region(fit, 19, 21)
        out["spread_credibly_nonzero_fraction"] = float(reg["credibly_nonzero"].mean())
    return out | fit.json_tail(comparison, advice)
