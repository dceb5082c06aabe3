"""The thermodynamic model: force and volume of the element from one potential G(x, p_u).

The paper asks for a refined (thermodynamic) method that accounts for the elastic casing. At
constant temperature and overpressure p_u the casing and its gas have a potential

    G(x, p_u) = W - p_u V        (W: elastic energy stored in the casing)

with dG = -P dx - V dp_u, so the force and the internal volume follow from it,

    P = -dG/dx (p_u fixed),      V = -dG/dp_u (x fixed),

and their mixed derivatives agree (Maxwell): dP/dp_u = dV/dx. The traditional theory is W = 0:
G = -p_u V0(x), P = p_u V0', V = V0 (eqs. 1, 2). A casing that stores energy adds terms; with
G = -p_u V0(x) - p_u^2 C(x)/2 + E(x) the force-derived area P/p_u grows with pressure at half
the rate of the volume-derived one dV/dx. This model fits one smooth potential

    G(x, p_u) = G_s sum_{k=1..K, l=0..L} g_kl t^k s^l,   t = (x - x0)/h,  s = p_u / p_ref

(h = 0.05 m, p_ref the highest tested pressure, G_s = 10 kJ) jointly to the force and the piston of
every test: force = -dG/dx, piston L_i(x) = r_i - V(x, p_i) / S_true, with one piston reference
r_i per test (each test's reference is arbitrary, eq. 5) and the volume's constant per pressure
(the k = 0 terms) unobservable from isobaric tests (it joins r_i). Given the noise everything is
linear in (g, r), so the coefficients are integrated out and drawn exactly (``uq._models.pair``).

The piston area. The stand turns the piston's travel into volume with S (eq. 5); a wrong S
scales every volume by the same factor, which the traditional theory cannot tell from a casing
whose volume-derived area exceeds its force-derived one at every pressure ("volume_excess").
Through the Maxwell relation the force fixes how the volume must change, so the potential can
tell them apart: the model samples the travel factor 1 + m = S / S_true (log(1 + m) ~ N(0, 0.3^2))
and reports the piston area the recordings imply, S_true = S / (1 + m), with its interval.

Noise: the (force, piston) pair of every reading with the stand's pressure-holding covariance
(``uq._models.pair``); the force's lever of a pressure error is the model's own dP/dp_u (a
least-squares plug-in).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from uq._data.recordings import Recordings
from uq._inference.convergence import CLI_ADVICE
from uq._inference.summary import estimate, thin_rows
from uq._models.linear_fit import BlockSpec, LinearFit, Params
from uq._physics.quantities import BAR_PA, BASIS_SCALE_M

MAX_DRAWS = 4000
G_SCALE_J = 1.0e4  # prior scale of the potential's standardised coefficients
R_SCALE_M = 1.0  # prior scale of the piston references
TRAVEL_PRIOR_SD = 0.3  # log(1 + m): the piston area is known to about 30 % a priori
#: what the likelihood reports besides the potential: the noise (uq._models.pair.NATURAL_NAMES),
#: the travel factor and the piston area it implies
NATURAL_NAMES = ("s0_N", "rel_load", "k_p", "sL_m", "V0_m3")


@dataclass(frozen=True)
class ThermoOrders(Params):
    """Degrees of the potential: K in height (t^1..t^K; the force is of degree K - 1) and L in
    pressure (s^0..s^L; the force is of degree L, the volume of degree L - 1 in pressure)."""

    K: int = 4
    L: int = 4

    @property
    def label(self) -> str:
        return f"G {self.K}x{self.L}"

    @property
    def n_potential(self) -> int:
        return self.K * (self.L + 1)


#: chosen by PSIS-LOO on data/n50 (``select_orders``; docs/thermo.md: G 4x7 -450.3, 4x8 -452.6
#: +- 1.4, 5x7 -453.7 +- 3.3, 4x6 -484.6 +- 10.3, 4x5 -520.1 +- 13.8); a campaign with fewer tests
#: gets a pressure degree its tests can fix (:func:`default_orders`)
DEFAULT_ORDERS = ThermoOrders(4, 7)
CANDIDATES = (
    ThermoOrders(4, 5),
    ThermoOrders(4, 6),
    ThermoOrders(4, 7),
    ThermoOrders(4, 8),
    ThermoOrders(5, 7),
)


def default_orders(n_tests: int) -> ThermoOrders:
    """``DEFAULT_ORDERS`` with a pressure degree of at most n_tests - 1 (the force has L + 1
    functions of height, one per power of p_u: the tests must be able to tell them apart)."""
    return ThermoOrders(DEFAULT_ORDERS.K, max(1, min(DEFAULT_ORDERS.L, n_tests - 1)))


@dataclass(frozen=True)
class ThermoGeometry(Params):
    x0_m: float
    area_m2: float  # the nominal piston area S the recordings were converted with
    p_ref_bar: float

    def t(self, x_m):
        return (np.asarray(x_m, float) - self.x0_m) / BASIS_SCALE_M

    def s(self, p_bar):
        return np.asarray(p_bar, float) / self.p_ref_bar


def powers(o: ThermoOrders):
    return [(k, l) for k in range(1, o.K + 1) for l in range(o.L + 1)]


def _terms(o: ThermoOrders, g: ThermoGeometry, x_m, p_bar):
    """(t (n, 1), s (n, 1), k, l): the basis t^k s^l's variables and powers, one column a term."""
    t = np.asarray(g.t(x_m), float)[..., None]
    s = np.asarray(g.s(p_bar), float)[..., None]
    k = np.array([k for k, _ in powers(o)], float)
    l = np.array([l for _, l in powers(o)], float)
    return t, s, k, l


def potential_columns(o: ThermoOrders, g: ThermoGeometry, x_m, p_bar):
    """The columns of G, -dG/dx (force) and -dG/dp_u (volume) for unit standardised coefficients,
    each (n, K (L + 1)): J, N and m^3."""
    t, s, k, l = _terms(o, g, x_m, p_bar)
    p_ref_pa = g.p_ref_bar * BAR_PA
    G = G_SCALE_J * t**k * s**l
    force = -G_SCALE_J / BASIS_SCALE_M * k * t ** (k - 1) * s**l
    volume = -G_SCALE_J / p_ref_pa * l * t**k * np.where(l > 0, s ** np.maximum(l - 1, 0), 0.0)
    return G, force, volume


def designs(o: ThermoOrders, g: ThermoGeometry, x_m, p_bar, test_index, n_tests):
    """Force and piston designs (n, K (L + 1) + n_tests): force = -dG/dx, piston
    L = r_i - V / S (before the travel factor, which the pair likelihood applies)."""
    _, force, volume = potential_columns(o, g, x_m, p_bar)
    n = force.shape[0]
    R = np.zeros((n, n_tests))
    R[np.arange(n), np.asarray(test_index)] = R_SCALE_M
    return (np.hstack([force, np.zeros((n, n_tests))]), np.hstack([-volume / g.area_m2, R]))


# ----------------------------------------------------------------------------- fit


def geometry_of(rec: Recordings) -> ThermoGeometry:
    return ThermoGeometry(rec.x0_m, rec.piston_area_m2, float(rec.pressures_bar.max()))


def force_pressure_slope(o: ThermoOrders, g: ThermoGeometry, x_m, p_bar, coef):
    """dP/dp_u (m^2) of the potential with standardised coefficients ``coef`` (..., K (L + 1))."""
    return slope_columns(o, g, x_m, p_bar) @ np.asarray(coef).T


def slope_columns(o: ThermoOrders, g: ThermoGeometry, x_m, p_bar):
    """The columns of dP/dp_u = dV/dx (Maxwell) for unit standardised coefficients, (n, K (L + 1)),
    m^2."""
    t, s, k, l = _terms(o, g, x_m, p_bar)
    return (
        -G_SCALE_J
        / BASIS_SCALE_M
        * k
        * t ** (k - 1)
        * l
        * s ** np.maximum(l - 1, 0)
        / (g.p_ref_bar * BAR_PA)
    )


@dataclass(eq=False, frozen=True, repr=False)
class ThermoFit(LinearFit):
    """The thermodynamic model fitted to a campaign (or loaded): force, volume and their
    derivatives from one potential on the fixed posterior draws (:class:`uq._models.linear_fit.
    LinearFit`). Fitted by ``uq._models.thermo_likelihood.fit_thermo``."""

    name = "thermodynamic"
    words = "the thermodynamic model"
    likelihood = "uq._models.thermo_likelihood"
    orders_type = ThermoOrders
    geometry_type = ThermoGeometry
    has_dvdp = True

    def block_layout(self) -> tuple[BlockSpec, ...]:
        refs = tuple(f"r_{p:g}bar" for p in self.tested_pressures_bar)
        gkl = tuple(f"g_{k}{l}" for k, l in powers(self.orders))
        return (
            BlockSpec("potential", gkl, 1.0, "1e4 J", "G = 1e4 J sum g_kl t^k s^l"),
            BlockSpec("piston_reference_m", refs, R_SCALE_M, "m", "one piston reference per test"),
        )

    def _padded(self, cols) -> np.ndarray:
        """A potential's columns with zeros for the piston references."""
        return np.concatenate([cols, np.zeros((cols.shape[0], len(self.tested_pressures_bar)))], 1)

    def _potential(self, part: int):
        """The columns of part ``part`` of :func:`potential_columns` (0: G, 1: force, 2: volume),
        padded, as a function of (x, p_u)."""
        return lambda x, p: self._padded(potential_columns(self.orders, self.geometry, x, p)[part])

    def force_columns(self, x_m, p_bar):
        """P = -dG/dx."""
        return self._potential(1)(x_m, p_bar)

    def area_columns(self, x_m, p_bar):
        """dV/dx = -d2G/dx dp_u (= dP/dp_u by the Maxwell relation)."""
        return self._padded(slope_columns(self.orders, self.geometry, x_m, p_bar))

    def dvdp_columns(self, x_m, p_bar):
        """dV/dp_u = -d2G/dp_u^2 at fixed height, up to a function of p_u alone."""
        t, s, k, l = _terms(self.orders, self.geometry, x_m, p_bar)
        p_ref = self.geometry.p_ref_bar * BAR_PA
        return self._padded(-G_SCALE_J / p_ref**2 * l * (l - 1) * t**k * s ** np.maximum(l - 2, 0))

    @property
    def dvdp_words(self) -> str:
        """What the model's own dV/dp_u assumes (``uq design --dvdp-l-per-bar model``): the
        potential's gauge makes it 0 at x0, so the volume at x0 is taken not to change with
        pressure; the differences between heights are the recordings'."""
        return (
            f"{self.label}'s own, ASSUMED 0 at x0 = {self.x0_m * 1e3:g} mm (the potential's "
            "gauge: isobaric tests fix only how it differs between heights)"
        )

    def potential_draws(self, height_m, p_bar, *, check=True):
        """G(x, p_u) draws, J (up to a function of p_u alone, which isobaric tests cannot see)."""
        return self.evaluate(self._potential(0), height_m, p_bar, check=check)

    def volume_change_draws(self, height_m, p_bar, *, check=True):
        """V(x, p_u) - V_(p_u) draws, m^3: the volume up to a constant per pressure (isobaric tests
        fix volume differences between heights, not the absolute volume)."""
        return self.evaluate(self._potential(2), height_m, p_bar, check=check)

    def maxwell_ratio_draws(self, height_m, p_bar, *, check=True):
        """(dV/dx) / (P / p_u): how far the volume-derived area exceeds the force-derived one
        (1 in the traditional theory; grows with p_u for an elastic casing)."""
        return self.volume_area_draws(height_m, p_bar, check=check) / self.feff_draws(
            height_m, p_bar, check=False
        )

    def piston_area_draws(self) -> np.ndarray:
        """The piston area the recordings imply, S / (1 + m), m^2, on the fixed draws."""
        a = np.asarray(self.reported["piston_area_m2"], float)
        return thin_rows(a.reshape(-1), self.max_draws)

    def fitted_document(self, comparison: dict | None, advice: str) -> dict:
        """What ``uq surface --model thermodynamic --json`` writes (docs/formats.md)."""
        return summary(self, comparison, advice)


# ----------------------------------------------------------------------------- summary

DEFINITIONS = {
    "force_N": "P = -dG/dx: the force of the element",
    "feff_m2": "F_eff = P / p_u: the paper's effective area from the force (eq. 1)",
    "volume_area_m2": "dV/dx = -d2G/dx dp_u: the effective area from the volume (eq. 1, second "
    "formula); equal to dP/dp_u by the Maxwell relation",
    "maxwell_ratio": "(dV/dx) / (P/p_u): 1 in the traditional theory",
    "piston_area_m2": "S / (1 + m): the piston area the recordings imply through the Maxwell relation",
}


def summary(fit: ThermoFit, comparison: dict | None = None, advice: str = CLI_ADVICE) -> dict:
    """The JSON document of the thermodynamic model (:meth:`ThermoFit.to_json`)."""
    g = fit.geometry
    plo, phi = fit.pressure_range_bar
    some = fit.on_draws(2000)
    at_x0 = {}
    for pb in sorted({plo, (plo + phi) / 2, phi}):
        x0 = np.array(g.x0_m)
        at_x0[f"{pb:g}"] = {
            "force_N": estimate(some.force_draws(x0, pb)),
            "feff_m2": estimate(some.feff_draws(x0, pb)),
            "volume_area_m2": estimate(some.volume_area_draws(x0, pb)),
            "maxwell_ratio": estimate(some.maxwell_ratio_draws(x0, pb)),
        }
    noise = fit.noise_summary(NATURAL_NAMES + ("travel_factor", "piston_area_m2"))
    return (
        fit.json_head()
        | {
            "basis": "G = 1e4 J sum g_kl t^k s^l, t = (x - x0) / 0.05 m, s = p_u / p_ref; P = -dG/dx, "
            "V = -dG/dp_u",
            "p_ref_bar": g.p_ref_bar,
            "definitions": DEFINITIONS,
            "stand": asdict(fit.stand),
            "valid_range": {"height_m": list(fit.height_range_m), "pressure_bar": [plo, phi]},
            "implied_piston_area_m2": noise["piston_area_m2"],
            "noise": {k: v for k, v in noise.items() if k in NATURAL_NAMES},
            "at_x0": at_x0,
        }
        | fit.json_tail(comparison, advice)
    )
