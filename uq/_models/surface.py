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
from uq._data.stand_description import PAPER_STAND, StandDescription
from uq._inference.collapsed import CollapsedModel, fit_collapsed
from uq._inference.convergence import CLI_ADVICE
from uq._inference.sampler import Settings
from uq._inference.summary import band, estimate
from uq._io.errors import InputError
from uq._models import pair, surface_force
from uq._models.pair import (
    NATURAL_NAMES,
    NOISE_NAMES,
    PairData,
    PairFit,
    noise_prior_mean,
    pair_data,
)
from uq._physics.quantities import BAR_PA, BASIS_SCALE_M

MAX_DRAWS = 4000
SCALE_C = 0.1  # m^2
SCALE_E = 1.0e4  # N
SCALE_D = 0.1  # m^2
SCALE_R = 1.0  # m
NOISE_PRIOR_MEAN = noise_prior_mean(PAPER_STAND)
LEVEL = 0.90


@dataclass(frozen=True)
class Orders:
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


def _tq(t, q, kmax, lmax, integrate=False):
    t = np.asarray(t, float)[..., None, None]
    q = np.asarray(q, float)[..., None, None]
    k = np.arange(kmax + 1)[:, None]
    lq = np.arange(lmax + 1)[None, :]
    if integrate:
        cols = t ** (k + 1) / (k + 1) * q**lq
    else:
        cols = t**k * q**lq
    cols = np.broadcast_to(cols, cols.shape)
    return cols.reshape(*cols.shape[:-2], -1)


def _poly(t, m):
    t = np.asarray(t, float)[..., None]
    return t ** np.arange(m + 1)


@dataclass(frozen=True)
class Geometry:
    x0_m: float
    area_m2: float
    p_mid: float
    p_half: float

    def t(self, x_m):
        return (np.asarray(x_m, float) - self.x0_m) / BASIS_SCALE_M

    def q(self, p_bar):
        return (np.asarray(p_bar, float) - self.p_mid) / self.p_half


def _sizes(o: Orders, n_tests: int):
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
    Xf[:, :nc] = p_pa[:, None] * _tq(t, q, o.K, o.Lp) * SCALE_C
    if ne:
        Xf[:, nc : nc + ne] = _poly(t, o.Ke) * SCALE_E
    return Xf


def designs(o: Orders, g: Geometry, x_m, p_bar, test_index, n_tests):
    """Force and piston design matrices in standardised coefficients, (n, k) each."""
    t, q = g.t(x_m), g.q(p_bar)
    n = t.size
    nc, ne, nd, nr = _sizes(o, n_tests)
    Xf = force_design(o, g, x_m, p_bar, nc + ne + nd + nr)
    Xl = np.zeros_like(Xf)
    lever = -BASIS_SCALE_M / g.area_m2
    Xl[:, :nc] = lever * _tq(t, q, o.K, o.Lp, integrate=True) * SCALE_C
    if nd:
        Xl[:, nc + ne : nc + ne + nd] = lever * _tq(t, q, o.Dk, o.Dl, integrate=True) * SCALE_D
    Xl[np.arange(n), nc + ne + nd + np.asarray(test_index)] = SCALE_R
    return Xf, Xl


# ----------------------------------------------------------------------------- likelihood


def log_prob(theta, d: PairData):
    """Log posterior of the noise parameters (coefficients integrated out); theta (5,)."""
    return pair.log_prior(theta, d) + pair.posterior(theta, d).log_marginal


def draw_linear(theta, key, d: PairData):
    """One exact coefficient draw given the noise theta."""
    return pair.draw(theta, key, d)


def pointwise(theta, beta, d: PairData):
    return {"reading": pair.pointwise(theta, beta, d)}


def predict(theta, beta, key, d: PairData):
    return pair.predict(theta, beta, key, d)


def pointwise_loo(theta, d: PairData):
    return pair.pointwise_loo(theta, d)


def start(d: PairData) -> np.ndarray:
    return np.asarray(d.prior_mean)


def report(theta, beta, d: PairData) -> dict:
    noise = np.exp(np.asarray(theta))
    return {n: noise[:, i] for i, n in enumerate(NATURAL_NAMES)}


MODEL = CollapsedModel(
    name="pressure-coupled surface",
    theta_names=NOISE_NAMES,
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


@dataclass(eq=False, frozen=True, repr=False)
class SurfaceFit(PairFit):
    """Posterior of the surface model (``uq._models.pair.PairFit``) and the surfaces evaluated
    from it."""

    orders: Orders = DEFAULT_ORDERS
    geometry: Geometry | None = None
    selection: tuple = ()

    model_name = "the surface model"
    short_name = "surface"

    @property
    def force_only(self) -> bool:
        """Fitted to the force alone (no piston readings: uq._models.surface_force); the volume
        methods then refuse with :func:`volume_omitted_reason`."""
        return not self.recordings.has_piston

    @property
    def label(self) -> str:
        """The orders in words (``Orders.label``; "force only" in place of the volume block)."""
        return force_label(self.orders) if self.force_only else self.orders.label

    def _no_volume(self) -> None:
        if self.force_only:
            raise InputError(volume_omitted_reason(self.recordings))

    def __repr__(self) -> str:
        state = "converged" if self.convergence.converged else "NOT converged"
        return (
            f"SurfaceFit({self.label}; {len(self.recordings.tests)} tests, "
            f"{self.recordings.n_points} readings, {self.beta.shape[-1]} coefficients, "
            f"{self.beta.shape[0] * self.beta.shape[1]} draws, {state})"
        )

    # ---- coefficient blocks (physical units, flattened draws)
    def blocks(self, beta=None):
        beta = self.flat_beta() if beta is None else beta
        nc, ne, nd, nr = _sizes(self.orders, 0 if self.force_only else len(self.recordings.tests))
        c = beta[:, :nc] * SCALE_C
        e = beta[:, nc : nc + ne] * SCALE_E
        d = beta[:, nc + ne : nc + ne + nd] * SCALE_D
        r = beta[:, nc + ne + nd :] * SCALE_R
        return c, e, d, r

    # ---- surfaces at arbitrary points: draws (S, n)
    def _grid(self, height_m, p_bar, check):
        h, p = np.broadcast_arrays(np.asarray(height_m, float), np.asarray(p_bar, float))
        if check:
            self.check_range(h, p)
        g = self.geometry
        return h.shape, g.t(h.ravel()), g.q(p.ravel()), p.ravel()

    def pressure_area_draws(self, height_m, p_bar, *, check=True, beta=None):
        """Pressure area F_p(x, p_u) = (P - E) / p_u draws, m^2, shape (S, *broadcast shape)."""
        shape, t, q, _ = self._grid(height_m, p_bar, check)
        c = self.blocks(beta)[0]
        o = self.orders
        return (c @ _tq(t, q, o.K, o.Lp).T).reshape(-1, *shape)

    def feff_draws(self, height_m, p_bar, *, check=True, beta=None):
        """The paper's effective area F_eff = P / p_u (eq. 1) of the mean force, m^2."""
        p = np.broadcast_to(
            np.asarray(p_bar, float), np.broadcast(np.asarray(height_m), np.asarray(p_bar)).shape
        )
        return self.force_draws(height_m, p_bar, check=check, beta=beta) / (p * BAR_PA)

    def _casing(self, shape, t, beta):
        """E(x) draws on an evaluated grid (shape, t from ``_grid``), N."""
        return (self.blocks(beta)[1] @ _poly(t, self.orders.Ke).T).reshape(-1, *shape)

    def casing_draws(self, height_m, *, check=True, beta=None):
        shape, t, _, _ = self._grid(height_m, self.pressure_range_bar[0], check)
        return self._casing(shape, t, beta)

    def force_draws(self, height_m, p_bar, *, check=True, beta=None):
        """Force P(x, p_u) = p_u F_p + E draws (mean curve, no reading noise), N."""
        p = np.broadcast_to(
            np.asarray(p_bar, float), np.broadcast(np.asarray(height_m), np.asarray(p_bar)).shape
        )
        fe = self.pressure_area_draws(height_m, p_bar, check=check, beta=beta)
        shape, t, _, _ = self._grid(height_m, p_bar, False)
        E = self._casing(shape, t, beta)
        return p * BAR_PA * fe + E

    def volume_excess_draws(self, height_m, p_bar, *, check=True, beta=None):
        """D(x, p_u) = -dV/dx - F_p draws, m^2 (0 in the traditional theory)."""
        self._no_volume()
        shape, t, q, _ = self._grid(height_m, p_bar, check)
        d = self.blocks(beta)[2]
        o = self.orders
        if o.Dk < 0:
            return np.zeros((self.blocks(beta)[0].shape[0], *shape))
        return (d @ _tq(t, q, o.Dk, o.Dl).T).reshape(-1, *shape)

    def volume_area_draws(self, height_m, p_bar, *, check=True, beta=None):
        """The volume-derived area -dV/dx = F_p + D draws, m^2 (the second formula of eq. 1)."""
        self._no_volume()
        return self.pressure_area_draws(
            height_m, p_bar, check=check, beta=beta
        ) + self.volume_excess_draws(height_m, p_bar, check=False, beta=beta)

    def spread_draws(self, height_m, p_bar, *, check=True, beta=None):
        """Traditional characteristic p_u (-dV/dx) minus the experimental force: p_u D - E, N."""
        self._no_volume()
        p = np.broadcast_to(
            np.asarray(p_bar, float), np.broadcast(np.asarray(height_m), np.asarray(p_bar)).shape
        )
        D = self.volume_excess_draws(height_m, p_bar, check=check, beta=beta)
        shape, t, _, _ = self._grid(height_m, p_bar, False)
        E = self._casing(shape, t, beta)
        return p * BAR_PA * D - E

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
            m, lo, hi = band(fn(height_m, p_bar), axis=0, level=level)
            out[name] = {"mean": m, "lower": lo, "upper": hi}
        return out

    def to_json(self, comparison: dict | None = None, advice: str = CLI_ADVICE) -> dict:
        """What ``uq surface --json`` writes (docs/formats.md)."""
        return summary(self, comparison, advice)


def geometry_of(rec: Recordings) -> Geometry:
    p = rec.pressures_bar
    mid, half = (p.max() + p.min()) / 2, max((p.max() - p.min()) / 2, 1e-3)
    return Geometry(rec.x0_m, rec.piston_area_m2, float(mid), float(half))


def _reference(o, g, x, p, F, L, idx, n_tests):
    """Weighted least squares: the reference force and pressure area of the noise terms."""
    Xf, Xl = designs(o, g, x, p, idx, n_tests)
    wf = 1.0 / (0.005 * np.abs(F) + 20.0)
    wl = np.full_like(L, 1.0 / 1e-3)
    A = np.concatenate([Xf * wf[:, None], Xl * wl[:, None]])
    y = np.concatenate([F * wf, L * wl])
    beta, *_ = np.linalg.lstsq(A, y, rcond=None)
    phat = np.abs(Xf @ beta)
    nc = (o.K + 1) * (o.Lp + 1)
    feff = _tq(g.t(x), g.q(p), o.K, o.Lp) @ (beta[:nc] * SCALE_C)
    return beta, phat, np.abs(feff), Xf, Xl


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


def force_arrays(rec: Recordings):
    """Every force reading of a campaign: height (m), set pressure (bar), force (N)."""
    x = np.concatenate([t.height_m for t in rec.tests])
    p = np.concatenate([np.full(t.n_points, t.pressure_bar) for t in rec.tests])
    F = np.concatenate([t.force_N for t in rec.tests])
    return x, p, F


def surface_force_data(rec: Recordings, orders: Orders, stand: StandDescription):
    """The force surface's arrays (uq._models.surface_force.ForceData): the design, the readings and
    the noise references of a weighted least-squares fit of the force."""
    g = geometry_of(rec)
    x, p, F = force_arrays(rec)
    X = force_design(orders, g, x, p)
    w = 1.0 / (0.005 * np.abs(F) + 20.0)
    beta, *_ = np.linalg.lstsq(X * w[:, None], F * w, rcond=None)
    nc = (orders.K + 1) * (orders.Lp + 1)
    feff = np.abs(_tq(g.t(x), g.q(p), orders.K, orders.Lp) @ (beta[:nc] * SCALE_C))
    return surface_force.force_data(
        X, F, np.abs(X @ beta), feff, p, stand, pair.measured_deviation(rec)
    )


def surface_data(rec: Recordings, orders: Orders, stand: StandDescription) -> PairData:
    """The model's arrays for a campaign: designs, readings, the noise references, the Gram plan."""
    g = geometry_of(rec)
    x, p, F, L, idx = pair.arrays(rec)
    _, phat, feff, Xf, Xl = _reference(orders, g, x, p, F, L, idx, len(rec.tests))
    return pair_data(Xf, Xl, F, L, phat, feff, p, g.area_m2, stand, pair.measured_deviation(rec))


def fit_surface(
    rec: Recordings,
    orders: Orders | None = None,
    *,
    seed: int = 0,
    settings: Settings = Settings(),
    max_draws: int = MAX_DRAWS,
    stand: StandDescription = PAPER_STAND,
) -> SurfaceFit:
    """The surface model's posterior: the one driver (optimistix MAP of the noise, emcee over it,
    exact coefficient draws, ArviZ data and convergence verdict).

    ``stand`` is the stand the recordings were taken on: its pressure holding and p_atm enter
    the reading covariance, its load cell and gas volume centre the noise priors. ``orders``:
    the polynomial orders, by default :func:`orders_for` the campaign.

    A campaign without piston readings (force-only, or a catalogue table) is fitted by the force
    surface alone (uq._models.surface_force; ``orders`` without a volume block, Dk = Dl = -1); its
    volume results are omitted with :func:`volume_omitted_reason`."""
    n_tests = len(rec.tests)
    orders = orders_for(rec) if orders is None else orders
    if n_tests < orders.Lp + 1:
        raise InputError(
            f"{rec.path}: {n_tests} tests at different pressures cannot fix an effective area of "
            f"degree {orders.Lp} in pressure; the surface model needs at least {orders.Lp + 1}"
        )
    force_only = not rec.has_piston
    if force_only and (orders.Dk >= 0 or orders.Dl >= 0):
        raise InputError(
            f"orders: {rec.path} has no piston readings; the force surface takes no volume block "
            f"(Dk = Dl = -1), got {orders.label}",
            param="orders",
        )
    if force_only:
        data, model = surface_force_data(rec, orders, stand), surface_force.MODEL
        k = data.X.shape[1]
        if rec.n_points - k < len(surface_force.THETA_NAMES) + 2:
            short = k + len(surface_force.THETA_NAMES) + 2
            raise InputError(
                f"{rec.path}: {rec.n_points} readings cannot fix the force surface's {k} coefficients "
                f"({force_label(orders)}) and leave residuals for its noise: it needs at least {short} "
                f"(more heights per test, or more tests)"
            )
    else:
        data, model = surface_data(rec, orders, stand), MODEL
    post = fit_collapsed(
        model,
        data,
        seed=seed,
        settings=settings,
        max_draws=max_draws,
        seeds=[seed],
        predictive=False,  # 2 x 814 replicates per draw: made when asked for, not on every fit
        desc="surface sampling",
    )
    return SurfaceFit(rec, post, stand, orders, geometry_of(rec))


def select_orders(
    rec: Recordings,
    candidates=CANDIDATES,
    *,
    seed: int = 0,
    settings: Settings | None = None,
    stand: StandDescription = PAPER_STAND,
):
    """Fit each candidate and rank by PSIS-LOO; returns (best fit, comparison rows). For a campaign
    without piston readings the candidates lose their volume block and their degrees are capped
    as :func:`orders_for` caps them (duplicates fitted once)."""
    if not rec.has_piston:
        cap = orders_for(rec)
        candidates = tuple(
            dict.fromkeys(
                Orders(
                    min(o.K, cap.K),
                    max(0, min(o.Lp, len(rec.tests) - 2)),
                    min(o.Ke, cap.Ke),
                    -1,
                    -1,
                )
                for o in candidates
            )
        )
    return pair.select_orders(
        fit_surface, rec, candidates, seed=seed, settings=settings or Settings(), stand=stand
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
    c, e, d, r = fit.blocks()
    o = fit.orders
    out = {"pressure_area_m2": {}, "casing_N": {}, "volume_excess_m2": {}, "piston_reference_m": {}}
    for i, (k, lq) in enumerate((k, lq) for k in range(o.K + 1) for lq in range(o.Lp + 1)):
        out["pressure_area_m2"][f"c_{k}{lq}"] = estimate(c[:, i])
    for m in range(o.Ke + 1):
        out["casing_N"][f"e_{m}"] = estimate(e[:, m])
    if o.Dk >= 0:
        for i, (k, lq) in enumerate((k, lq) for k in range(o.Dk + 1) for lq in range(o.Dl + 1)):
            out["volume_excess_m2"][f"d_{k}{lq}"] = estimate(d[:, i])
    if fit.force_only:
        del out["volume_excess_m2"], out["piston_reference_m"]
        return out
    for i, t in enumerate(fit.recordings.tests):
        out["piston_reference_m"][f"{t.pressure_bar:g} bar"] = estimate(r[:, i])
    return out


def noise_summary(fit: SurfaceFit) -> dict:
    diag = fit.convergence.variables
    out = {}
    for n in surface_force.NATURAL if fit.force_only else NATURAL_NAMES:
        est = estimate(np.asarray(fit.posterior.reported[n]))
        est["r_hat"] = diag[n]["r_hat"]
        est["ess_bulk"] = diag[n]["ess_bulk"]
        out[n] = est
    return out


def spread_region(fit: SurfaceFit, n_x: int = 46, n_p: int = 41, level: float = LEVEL) -> dict:
    """Grid of the spread's band over (x, p_u) and where it excludes zero."""
    lo, hi = fit.height_range_m
    plo, phi = fit.pressure_range_bar
    xs = np.linspace(lo, hi, n_x)
    ps = np.linspace(plo, phi, n_p)
    X, P = np.meshgrid(xs, ps, indexing="ij")
    beta = fit.flat_beta(2000)
    m, lo_b, hi_b = band(fit.spread_draws(X, P, beta=beta), axis=0, level=level)
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
    conv = fit.convergence
    r_hat_max, ess_bulk_min = conv.worst()
    plo, phi = fit.pressure_range_bar
    ref = {}
    beta = fit.flat_beta(2000)
    x0 = np.array(g.x0_m)
    for pb in sorted({plo, (plo + phi) / 2, phi}):
        ref[f"{pb:g}"] = {
            "pressure_area_m2": estimate(fit.pressure_area_draws(x0, pb, beta=beta)),
            "feff_m2": estimate(fit.feff_draws(x0, pb, beta=beta)),
            "force_N": estimate(fit.force_draws(x0, pb, beta=beta)),
        }
        if not fit.force_only:
            ref[f"{pb:g}"]["spread_N"] = estimate(fit.spread_draws(x0, pb, beta=beta))
    basis = "t = (x - x0) / 0.05 m; F_p = sum c_kl t^k q^l; E = sum e_m t^m"
    out = {
        "x0_m": g.x0_m,
        "piston_area_m2": g.area_m2,
        "orders": asdict(fit.orders),
        "orders_label": fit.label,
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
        "noise": noise_summary(fit),
        "at_x0": ref,
    }
    if fit.force_only:
        why = volume_omitted_reason(fit.recordings)
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
    return out | {
        "order_selection": list(fit.selection),
        "comparison": comparison,
        "converged": conv.converged,
        "convergence": conv.to_json(advice, variables=False)
        | {"r_hat_max": r_hat_max, "ess_bulk_min": ess_bulk_min},
        "warnings": conv.messages(advice),
    }
