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
from uq._data.stand_description import PAPER_STAND, StandDescription
from uq._inference.collapsed import CollapsedModel, fit_collapsed
from uq._inference.convergence import CLI_ADVICE
from uq._inference.float64 import jnp
from uq._inference.sampler import Settings
from uq._inference.summary import band, estimate
from uq._io.errors import InputError
from uq._models import pair
from uq._models.pair import NATURAL_NAMES, NOISE_NAMES, PairData, PairFit, pair_data
from uq._physics.quantities import BAR_PA, BASIS_SCALE_M

MAX_DRAWS = 4000
G_SCALE_J = 1.0e4  # prior scale of the potential's standardised coefficients
R_SCALE_M = 1.0  # prior scale of the piston references
TRAVEL_PRIOR_SD = 0.3  # log(1 + m): the piston area is known to about 30 % a priori
THETA_NAMES = (*NOISE_NAMES, "log_travel_factor")
LEVEL = 0.90


@dataclass(frozen=True)
class ThermoOrders:
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
class ThermoGeometry:
    x0_m: float
    area_m2: float  # the nominal piston area S the recordings were converted with
    p_ref_bar: float

    def t(self, x_m):
        return (np.asarray(x_m, float) - self.x0_m) / BASIS_SCALE_M

    def s(self, p_bar):
        return np.asarray(p_bar, float) / self.p_ref_bar


def _powers(o: ThermoOrders):
    return [(k, l) for k in range(1, o.K + 1) for l in range(o.L + 1)]


def potential_columns(o: ThermoOrders, g: ThermoGeometry, x_m, p_bar):
    """The columns of G, -dG/dx (force) and -dG/dp_u (volume) for unit standardised coefficients,
    each (n, K (L + 1)): J, N and m^3."""
    t = np.asarray(g.t(x_m), float)[..., None]
    s = np.asarray(g.s(p_bar), float)[..., None]
    k = np.array([k for k, _ in _powers(o)], float)
    l = np.array([l for _, l in _powers(o)], float)
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


# ----------------------------------------------------------------------------- the model


def _scale(theta):
    return jnp.exp(theta[5])


def log_prob(theta, d: PairData):
    """Log posterior of the noise parameters and the travel factor, coefficients integrated out."""
    prior_m = -0.5 * (theta[5] / TRAVEL_PRIOR_SD) ** 2
    return (
        pair.log_prior(theta[:5], d)
        + prior_m
        + pair.posterior(theta[:5], d, _scale(theta)).log_marginal
    )


def draw_linear(theta, key, d: PairData):
    return pair.draw(theta[:5], key, d, _scale(theta))


def pointwise(theta, beta, d: PairData):
    return {"reading": pair.pointwise(theta[:5], beta, d, _scale(theta))}


def predict(theta, beta, key, d: PairData):
    return pair.predict(theta[:5], beta, key, d, _scale(theta))


def pointwise_loo(theta, d: PairData):
    return pair.pointwise_loo(theta[:5], d, _scale(theta))


def start(d: PairData) -> np.ndarray:
    return np.concatenate([np.asarray(d.prior_mean), [0.0]])


def report(theta, beta, d: PairData) -> dict:
    theta = np.asarray(theta)
    noise = np.exp(theta[:, :5])
    out = {n: noise[:, i] for i, n in enumerate(NATURAL_NAMES)}
    out["travel_factor"] = np.exp(theta[:, 5])
    out["piston_area_m2"] = float(d.area) / np.exp(theta[:, 5])
    return out


MODEL = CollapsedModel(
    name="thermodynamic potential G(x, p_u)",
    theta_names=THETA_NAMES,
    log_prob=log_prob,
    draw_linear=draw_linear,
    pointwise=pointwise,
    start=start,
    report=report,
    predict=predict,
    observed=pair.observed,
    pointwise_loo=pointwise_loo,
    hold_out=pair.hold_out,
)


# ----------------------------------------------------------------------------- fit


def geometry_of(rec: Recordings) -> ThermoGeometry:
    return ThermoGeometry(rec.x0_m, rec.piston_area_m2, float(rec.pressures_bar.max()))


def thermo_data(rec: Recordings, orders: ThermoOrders, stand: StandDescription) -> PairData:
    """The model's arrays: designs, readings, and the noise references from a weighted
    least-squares fit of the same potential (force, and the force's pressure derivative as the
    lever of a pressure-holding error)."""
    g = geometry_of(rec)
    x, p, F, L, idx = pair.arrays(rec)
    Xf, Xl = designs(orders, g, x, p, idx, len(rec.tests))
    wf = 1.0 / (0.005 * np.abs(F) + 20.0)
    wl = np.full_like(L, 1.0 / 1e-3)
    A = np.concatenate([Xf * wf[:, None], Xl * wl[:, None]])
    beta, *_ = np.linalg.lstsq(A, np.concatenate([F * wf, L * wl]), rcond=None)
    phat = np.abs(Xf @ beta)
    lever = np.abs(_force_pressure_slope(orders, g, x, p, beta[: orders.n_potential]))
    return pair_data(Xf, Xl, F, L, phat, lever, p, g.area_m2, stand, pair.measured_deviation(rec))


def _force_pressure_slope(o: ThermoOrders, g: ThermoGeometry, x_m, p_bar, coef):
    """dP/dp_u (m^2) of the potential with standardised coefficients ``coef`` (..., K (L + 1))."""
    t = np.asarray(g.t(x_m), float)[..., None]
    s = np.asarray(g.s(p_bar), float)[..., None]
    k = np.array([k for k, _ in _powers(o)], float)
    l = np.array([l for _, l in _powers(o)], float)
    cols = (
        -G_SCALE_J
        / BASIS_SCALE_M
        * k
        * t ** (k - 1)
        * l
        * s ** np.maximum(l - 1, 0)
        / (g.p_ref_bar * BAR_PA)
    )
    return cols @ np.asarray(coef).T


@dataclass(eq=False, frozen=True, repr=False)
class ThermoFit(PairFit):
    """Posterior of the thermodynamic model (``uq._models.pair.PairFit``): force, volume and
    their derivatives from one potential, with posterior draws."""

    orders: ThermoOrders = DEFAULT_ORDERS
    geometry: ThermoGeometry | None = None
    selection: tuple = ()

    model_name = "the thermodynamic model"
    short_name = "thermodynamic"

    def __repr__(self) -> str:
        state = "converged" if self.convergence.converged else "NOT converged"
        return (
            f"ThermoFit({self.orders.label}; {len(self.recordings.tests)} tests, "
            f"{self.recordings.n_points} readings, {self.beta.shape[-1]} coefficients, "
            f"{self.beta.shape[0] * self.beta.shape[1]} draws, {state})"
        )

    def _coef(self, beta):
        beta = self.flat_beta() if beta is None else beta
        return beta[:, : self.orders.n_potential]

    def _columns(self, height_m, p_bar, check, which: int):
        h, p = np.broadcast_arrays(np.asarray(height_m, float), np.asarray(p_bar, float))
        if check:
            self.check_range(h, p)
        cols = potential_columns(self.orders, self.geometry, h.ravel(), p.ravel())[which]
        return h.shape, cols

    def _evaluate(self, height_m, p_bar, check, beta, which):
        shape, cols = self._columns(height_m, p_bar, check, which)
        return (self._coef(beta) @ cols.T).reshape(-1, *shape)

    def potential_draws(self, height_m, p_bar, *, check=True, beta=None):
        """G(x, p_u) draws, J (up to a function of p_u alone, which isobaric tests cannot see)."""
        return self._evaluate(height_m, p_bar, check, beta, 0)

    def force_draws(self, height_m, p_bar, *, check=True, beta=None):
        """Force P = -dG/dx draws (mean curve, no reading noise), N, (S, *shape)."""
        return self._evaluate(height_m, p_bar, check, beta, 1)

    def volume_change_draws(self, height_m, p_bar, *, check=True, beta=None):
        """V(x, p_u) - V_(p_u) draws, m^3: the volume up to a constant per pressure (isobaric tests
        fix volume differences between heights, not the absolute volume)."""
        return self._evaluate(height_m, p_bar, check, beta, 2)

    def feff_draws(self, height_m, p_bar, *, check=True, beta=None):
        """The paper's effective area F_eff = P / p_u (eq. 1), m^2."""
        p = np.broadcast_to(
            np.asarray(p_bar, float), np.broadcast(np.asarray(height_m), np.asarray(p_bar)).shape
        )
        return self.force_draws(height_m, p_bar, check=check, beta=beta) / (p * BAR_PA)

    def volume_area_draws(self, height_m, p_bar, *, check=True, beta=None):
        """The volume-derived area dV/dx = -d2G/dx dp_u draws, m^2 (the second formula of eq. 1);
        by the Maxwell relation equal to the force's pressure derivative dP/dp_u."""
        h, p = np.broadcast_arrays(np.asarray(height_m, float), np.asarray(p_bar, float))
        if check:
            self.check_range(h, p)
        out = _force_pressure_slope(
            self.orders, self.geometry, h.ravel(), p.ravel(), self._coef(beta)
        )  # (points, draws)
        return out.T.reshape(-1, *h.shape)

    def volume_pressure_draws(self, height_m, p_bar, *, check=True, beta=None):
        """dV/dp_u at fixed height, m^3/Pa, up to a function of p_u alone (the same at every
        height): how the casing's compliance differs between heights. Its value at one height
        needs a separate measurement (docs/design.md)."""
        h, p = np.broadcast_arrays(np.asarray(height_m, float), np.asarray(p_bar, float))
        if check:
            self.check_range(h, p)
        o, g = self.orders, self.geometry
        t = np.asarray(g.t(h.ravel()), float)[..., None]
        s = np.asarray(g.s(p.ravel()), float)[..., None]
        k = np.array([k for k, _ in _powers(o)], float)
        l = np.array([l for _, l in _powers(o)], float)
        p_ref = g.p_ref_bar * BAR_PA
        cols = -G_SCALE_J / p_ref**2 * l * (l - 1) * t**k * s ** np.maximum(l - 2, 0)
        return (self._coef(beta) @ cols.T).reshape(-1, *h.shape)

    def maxwell_ratio_draws(self, height_m, p_bar, *, check=True, beta=None):
        """(dV/dx) / (P / p_u): how far the volume-derived area exceeds the force-derived one
        (1 in the traditional theory; grows with p_u for an elastic casing)."""
        return self.volume_area_draws(height_m, p_bar, check=check, beta=beta) / self.feff_draws(
            height_m, p_bar, check=False, beta=beta
        )

    def piston_area_draws(self) -> np.ndarray:
        """The piston area the recordings imply, S / (1 + m), m^2 (flattened draws)."""
        return self.posterior.flat("piston_area_m2")

    def bands(self, height_m, p_bar, level: float = LEVEL) -> dict:
        """Pointwise 90 % bands of force, F_eff = P/p_u and dV/dx (refuses extrapolation)."""
        out = {}
        for name, fn in (
            ("force_N", self.force_draws),
            ("feff_m2", self.feff_draws),
            ("volume_area_m2", self.volume_area_draws),
        ):
            m, lo, hi = band(fn(height_m, p_bar), axis=0, level=level)
            out[name] = {"mean": m, "lower": lo, "upper": hi}
        return out

    def to_json(self, comparison: dict | None = None, advice: str = CLI_ADVICE) -> dict:
        """What ``uq surface --model thermodynamic --json`` writes (docs/formats.md)."""
        return summary(self, comparison, advice)


def fit_thermo(
    rec: Recordings,
    orders: ThermoOrders | None = None,
    *,
    seed: int = 0,
    settings: Settings = Settings(),
    max_draws: int = MAX_DRAWS,
    stand: StandDescription = PAPER_STAND,
) -> ThermoFit:
    """The thermodynamic model's posterior by the one driver: optimistix MAP of the noise and the
    travel factor, emcee over them, exact draws of the potential's coefficients and the piston
    references, ArviZ data and the convergence verdict. ``stand``: the stand the recordings were
    taken on (its pressure holding and gas volume enter the reading covariance and priors).
    ``orders``: the potential's degrees (default: :func:`default_orders` of the campaign)."""
    if len(rec.tests) < 2:
        raise InputError(
            f"{rec.path}: the thermodynamic model relates force and volume through their pressure "
            "derivatives and needs tests at two or more pressures"
        )
    if not rec.has_piston:
        raise InputError(
            f"{rec.path}: force-only campaign: the thermodynamic model fits force and volume "
            "together and needs piston_* or volume_*"
        )
    orders = default_orders(len(rec.tests)) if orders is None else orders
    post = fit_collapsed(
        MODEL,
        thermo_data(rec, orders, stand),
        seed=seed,
        settings=settings,
        max_draws=max_draws,
        seeds=[seed],
        predictive=False,
        desc="thermodynamic sampling",
    )
    return ThermoFit(rec, post, stand, orders, geometry_of(rec))


def select_orders(
    rec: Recordings,
    candidates=CANDIDATES,
    *,
    seed: int = 0,
    settings: Settings | None = None,
    stand: StandDescription = PAPER_STAND,
):
    """Fit each candidate and rank by PSIS-LOO; returns (best fit, comparison rows)."""
    return pair.select_orders(
        fit_thermo, rec, candidates, seed=seed, settings=settings or Settings(), stand=stand
    )


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
    conv = fit.convergence
    r_hat_max, ess_bulk_min = conv.worst()
    plo, phi = fit.pressure_range_bar
    beta = fit.flat_beta(2000)
    at_x0 = {}
    for pb in sorted({plo, (plo + phi) / 2, phi}):
        x0 = np.array(g.x0_m)
        at_x0[f"{pb:g}"] = {
            "force_N": estimate(fit.force_draws(x0, pb, beta=beta)),
            "feff_m2": estimate(fit.feff_draws(x0, pb, beta=beta)),
            "volume_area_m2": estimate(fit.volume_area_draws(x0, pb, beta=beta)),
            "maxwell_ratio": estimate(fit.maxwell_ratio_draws(x0, pb, beta=beta)),
        }
    noise = {}
    for n in NATURAL_NAMES + ("travel_factor", "piston_area_m2"):
        est = estimate(fit.posterior.flat(n))
        est |= {k: conv.variables[n][k] for k in ("r_hat", "ess_bulk")}
        noise[n] = est
    return {
        "model": "thermodynamic",
        "x0_m": g.x0_m,
        "piston_area_m2": g.area_m2,
        "orders": asdict(fit.orders),
        "orders_label": fit.orders.label,
        "basis": "G = 1e4 J sum g_kl t^k s^l, t = (x - x0) / 0.05 m, s = p_u / p_ref; P = -dG/dx, "
        "V = -dG/dp_u",
        "p_ref_bar": g.p_ref_bar,
        "definitions": DEFINITIONS,
        "stand": asdict(fit.stand),
        "valid_range": {"height_m": list(fit.height_range_m), "pressure_bar": [plo, phi]},
        "implied_piston_area_m2": noise["piston_area_m2"],
        "noise": {k: v for k, v in noise.items() if k in NATURAL_NAMES},
        "at_x0": at_x0,
        "order_selection": list(fit.selection),
        "comparison": comparison,
        "converged": conv.converged,
        "convergence": conv.to_json(advice, variables=False)
        | {"r_hat_max": r_hat_max, "ess_bulk_min": ess_bulk_min},
        "warnings": conv.messages(advice),
    }
