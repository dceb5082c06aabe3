"""Planning frames of the fitted models (``uq._derived.plan.Frame``): what the planner needs of a
model, built from its fit.

A frame is the model as it will be fitted after the plan: the same draws of the sampled
parameters theta, the coefficients of the campaign with the planned tests in it (for the models over
all tests the orders and pressure scaling :func:`uq._models.surface.default_orders` gives that
campaign, a piston reference per new test; for the per-pressure cubics a new cubic per new test, from
its prior), the file's readings in that basis. Three kinds of model, told apart by the fit's class
(never by a name):

* over all tests, with the (force, piston) pair likelihood (the surface and the thermodynamic
  model, ``uq._models.pair``) or the force alone (the force surface of a campaign without piston
  readings): :class:`PairFrames`. A planned reading's noise is the stand's error budget at its
  point, with the pilot's posterior-mean force and pressure lever as the budget's references.
* the surface with a discrepancy in pressure (``uq._models.discrepancy``): :class:`DiscrepancyFrames`,
  the surface's frame plus each test's deviation, a Gaussian process in p_u over the file's and the
  planned pressures. Given theta (its amplitudes and length scale among it) the deviations are
  linear in standard normals z, so the design rows depend on the draw; at a pressure without a test
  the deviation is the process's prediction from the tests (kriging) and its conditional variance
  is variance no reading elsewhere reduces (``extra_force_var``).
* the per-pressure cubics (eqs. 8, 9) with F_eff = P / p_u linear in p_u between tests
  (``uq._models.cubic_interpolation``): :class:`CubicFrames`. A new test's noise is that of the
  tested pressure nearest to it (draw by draw), at its own force level; the interpolation error
  between tests uses the curvature in pressure the file's tests show (pooled over its interior
  tests).

What the frames read of a fit beyond the FittedModel protocol: the sampled parameters' draws and the
likelihood's data of its posterior (``fit.posterior.theta``, ``fit.posterior.data``), its orders,
geometry, stand and recordings (public attributes of ``uq._models.linear_fit.LinearFit`` and
``uq._models.cubic_results.CampaignFit``). A model plugged in from outside is refused by
:func:`frames_of` in one line: the planner needs the model's design for a campaign it has not seen.
"""

from __future__ import annotations

import copy
from typing import NamedTuple

import numpy as np

from uq._derived.plan_search import MIN_TEST_READINGS, Frame
from uq._inference.float64 import jax, jnp
from uq._io.errors import InputError
from uq._models import cubic, pair, registry, surface, thermo
from uq._models import discrepancy as dev
from uq._models import discrepancy_gp as gp
from uq._models.cubic_interpolation import bracket, curvatures, feff
from uq._models.cubic_results import CampaignFit
from uq._models.discrepancy_fit import DiscrepancyFit, p_ref_pa
from uq._models.surface import SurfaceFit
from uq._models.thermo import ThermoFit
from uq._physics.quantities import BAR_PA, BASIS_SCALE_M, force_noise_var

DRAWS = 200  # draws of theta behind every frame
CHUNK = 25  # draws per block when the file's readings are whitened (memory)
STEP_X_M = 1.0e-5  # dV/dx = -S dL/dx by central differences of the (polynomial) piston design
REFERENCE_DRAWS = 400  # draws of the fit behind the error budget's references at new points


def _thin_index(size: int, n: int) -> np.ndarray:
    """Indices of ``size`` entries thinned evenly to at most ``n``."""
    if size <= n:
        return np.arange(size)
    return np.linspace(0, size - 1, n).round().astype(int)


def _thin(a: np.ndarray, n: int) -> np.ndarray:
    """The first axis thinned evenly to at most ``n`` entries."""
    return a[_thin_index(a.shape[0], n)]


def held_out(all_theta: np.ndarray, n_used: int, n: int) -> np.ndarray:
    """``n`` of a fit's draws ``all_theta`` (N, ...) thinned evenly from those that are not among the
    ``n_used`` a frame builder took (:func:`_thin`): the reweighting pool of the preposterior that
    updates theta (``uq._derived.plan_theta``), disjoint from the draws the planned readings are
    simulated from."""
    rest = np.ones(all_theta.shape[0], bool)
    rest[_thin_index(all_theta.shape[0], n_used)] = False
    return _thin(all_theta[rest], n)


def _new_index(new_bar, tested_bar) -> None:
    tested = np.asarray(tested_bar, float)
    for p in np.asarray(new_bar, float):
        if np.any(np.abs(tested - p) < 1e-9):
            raise ValueError(f"{p:g} bar is tested already: a campaign holds one test per pressure")


def _draws(X, S: int) -> np.ndarray:
    """Design rows per draw, (S, n, k): rows that do not depend on the draw are broadcast."""
    X = np.asarray(X)
    return np.broadcast_to(X, (S, *X.shape)) if X.ndim == 2 else X


def fit_reference(fit):
    """The error budget's references at new points from a fitted model (the protocol's draws):
    ``reference(x_m, p_bar) -> (|mean force| N, |pressure lever| m^2)``, the lever the model's
    pressure area where it has one, else its volume-derived area."""
    few = fit.on_draws(REFERENCE_DRAWS)
    lever = getattr(few, "pressure_area_draws", None) or few.volume_area_draws

    def reference(x, p):
        force = np.abs(few.force_draws(x, p, check=False).mean(0))
        return force, np.abs(lever(x, p, check=False).mean(0))

    return reference


class Nodes(NamedTuple):
    """The pressures of a discrepancy frame's tests (the file's, then the planned), bar, and per
    draw the Cholesky factor of their correlation, (S, T, T)."""

    p_bar: np.ndarray
    chol: np.ndarray


# ----------------------------------------------------------------------------- over all tests


class PairFrames:
    """Frames of a model over all tests (the surface, the force surface, the thermodynamic model).

    Built from its parts (:meth:`of_fit` takes them from a fit): the recordings, the model's data
    (``PairData``, or the force surface's ``ForceData``), draws of theta (S, n_theta), the stand,
    the orders and scaling of the fit as it is, ``reference(x_m, p_bar) -> (|force| N, lever
    m^2)``: the error budget's references at a new point (the pilot's posterior-mean force and
    pressure lever), and ``model``: the fit's class (``SurfaceFit`` or ``ThermoFit``; its
    ``name`` names the frame)."""

    def __init__(self, rec, data, theta, stand, orders, geometry, reference, model=SurfaceFit):
        if not issubclass(model, SurfaceFit | ThermoFit):
            raise ValueError(f"model must be a SurfaceFit or ThermoFit class, got {model!r}")
        self.rec, self.data, self.stand = rec, data, stand
        self.theta = np.asarray(theta, float)
        self.orders_now, self.geometry_now = orders, geometry
        self.reference = reference
        self.all_theta = None  # the fit's draws the frames' theta were thinned from (of_fit)
        self.model_class = model
        self.thermo = issubclass(model, ThermoFit)
        self.name = model.name
        self.force_only = not rec.has_piston
        self.tested = np.array([t.pressure_bar for t in rec.tests], float)
        if self.force_only:
            self.x, self.p, _ = pair.force_arrays(rec)
            self.test_index = np.concatenate(
                [np.full(t.n_points, i) for i, t in enumerate(rec.tests)]
            )
        else:
            self.x, self.p, _, _, self.test_index = pair.arrays(rec)
        self.fixed_frame = False  # the orders and pressure scaling follow the campaign's tests

    @classmethod
    def of_fit(cls, fit, draws: int = DRAWS):
        """The builder of a fit of this kind, on ``draws`` of its draws of theta."""
        th = np.asarray(fit.posterior.theta)
        th = th.reshape(-1, th.shape[-1])
        out = cls(
            fit.recordings,
            fit.posterior.data,
            _thin(th, draws),
            fit.stand,
            fit.orders,
            fit.geometry,
            fit_reference(fit),
            type(fit),
        )
        out.all_theta = th
        return out

    # ---- the model after the plan
    def model(self, after_bar, new_heights=None):
        """(orders, geometry) of the model fitted to the campaign with tests at ``after_bar``: the
        fit's own for the file as it is, else what the fit would choose by default
        (:func:`uq._models.surface.orders_for` the combined campaign). ``new_heights``: the
        planned tests' heights (one array a test) when the layout is known; else a new test is
        taken to have what the search gives it at least (``MIN_TEST_READINGS`` readings, half as
        many distinct heights)."""
        after = np.unique(np.asarray(after_bar, float))
        if after.size == self.tested.size and np.allclose(np.sort(self.tested), after):
            return self.orders_now, self.geometry_now
        rec = self.rec
        if self.thermo:
            g = thermo.ThermoGeometry(rec.x0_m, rec.piston_area_m2, float(after.max()))
            return thermo.default_orders(after.size), g
        heights = [np.unique(np.round(t.height_m, 9)).size for t in rec.tests]
        points = [t.n_points for t in rec.tests]
        if new_heights is None:
            heights.append(MIN_TEST_READINGS // 2)
            points.append(MIN_TEST_READINGS)
        else:
            heights += [np.unique(np.round(np.asarray(h, float), 9)).size for h in new_heights]
            points += [np.size(h) for h in new_heights]
        o = surface.default_orders(
            after.size, min_heights=min(heights), min_points=min(points), volume=not self.force_only
        )
        mid, half = (after.max() + after.min()) / 2, max((after.max() - after.min()) / 2, 1e-3)
        return o, surface.Geometry(rec.x0_m, rec.piston_area_m2, float(mid), float(half))

    def with_theta(self, theta):
        """The same builder (file, references, model) on other draws of theta (S', n_theta): what
        the plan would predict had the pilot known theta as ``theta`` says (scripts/plan_proof.py
        gives it the draws of the fit after the plan, to measure what the new readings teach
        about theta)."""
        theta = np.asarray(theta, float)
        if theta.ndim != 2 or theta.shape[1] != self.theta.shape[1]:
            raise ValueError(f"theta must be (S, {self.theta.shape[1]}), got {theta.shape}")
        out = copy.copy(self)
        out._set_theta(theta)
        out.all_theta = None  # its draws are not the fit's thinned ones: no pool held out of them
        return out

    def pool(self, n: int):
        """The same builder on ``n`` of the fit's draws of theta that it does not use itself
        (:func:`held_out`), or None when it was not built from a fit (:meth:`of_fit`) or the fit
        has no other draws."""
        if self.all_theta is None or self.all_theta.shape[0] <= self.theta.shape[0]:
            return None
        return self.with_theta(held_out(self.all_theta, self.theta.shape[0], n))

    def _set_theta(self, theta) -> None:
        self.theta = theta

    def label(self, orders) -> str:
        words = self.model_class.words.removeprefix("the ")
        if self.force_only and not self.thermo:
            return f"{words} ({surface.force_label(orders)})"
        return f"{words} ({orders.label})"

    def _designs(self, o, g, x, p, index, n_tests, rows=None, nodes=None):
        """Force and piston design rows (n, k), or (s, n, k) for rows that depend on the draws
        ``rows`` (indices into ``theta``; None: all) and the frame's ``nodes`` (:meth:`prepare`);
        the piston's None for a force-only model."""
        if self.force_only:
            return surface.force_design(o, g, x, p), None
        if self.thermo:
            return thermo.designs(o, g, x, p, index, n_tests)
        return surface.designs(o, g, x, p, index, n_tests)

    def min_test_heights(self, orders) -> int:
        """Distinct heights a new test needs for the model after the plan to be fitted (0: any)."""
        return 0

    # ---- noise: whitening of readings given theta
    def _noise_data(self, x, p):
        """The error budget's references at new points: |force| and the pressure lever of the
        pilot's posterior mean, the stand's holding sd and the absolute pressure."""
        force, lever = self.reference(x, p)
        hold = pair.holding_sd_Pa(
            p, self.stand, measured=bool(self.rec.pressure_measured), shape=np.shape(x)
        )
        p_abs = (np.asarray(p, float) + self.stand.p_atm_bar) * BAR_PA
        return force, lever, hold, p_abs

    def _scale(self, theta) -> np.ndarray:
        """The piston design's factor per draw (the thermodynamic model's travel factor)."""
        return np.exp(theta[:, 5]) if self.thermo else np.ones(theta.shape[0])

    def _whiten(self, theta, Xf, Xl, force, lever, hold, p_abs):
        """Whitened rows (S, n, r, k) of readings with these budget references, per draw: the
        design rows times the inverse of :meth:`_noise_factors`."""
        S = theta.shape[0]
        C = self._noise_factors(theta, force, lever, hold, p_abs)
        zf = _draws(Xf, S) / C[..., 0, 0, None]
        if self.force_only:
            return zf[:, :, None, :]
        zl = (self._scale(theta)[:, None, None] * _draws(Xl, S) - C[..., 1, 0, None] * zf) / C[
            ..., 1, 1, None
        ]
        return np.stack([zf, zl], axis=2)

    def _noise_factors(self, theta, force, lever, hold, p_abs) -> np.ndarray:
        """Per draw the lower-triangular factor C (S, n, r, r) of each reading's noise covariance
        with these budget references, in N and m (``Frame.reading_noise``; :meth:`_whiten`
        divides the design rows by it)."""
        if self.force_only:
            s0, rel, kp = (np.exp(theta[:, i])[:, None] for i in range(3))
            sd = np.sqrt(force_noise_var(s0, rel, force[None]) + (kp * hold * lever) ** 2)
            return sd[..., None, None]
        d = self.data._replace(
            phat=jnp.asarray(force),
            feff_hat=jnp.asarray(lever),
            dp_pa=jnp.asarray(hold),
            p_abs_pa=jnp.asarray(p_abs),
        )
        L11, L21, L22 = (
            np.asarray(a) for a in jax.vmap(lambda th: pair.cov_factors(th[:5], d))(theta)
        )
        C = np.zeros((*L11.shape, 2, 2))
        C[..., 0, 0], C[..., 1, 0], C[..., 1, 1] = L11, L21, L22
        return C

    def _pilot_block(self, rows, o, g, n_tests, nodes):
        """Whitened design (s, n, k) and readings (s, n) of the file's readings for the draws
        ``rows`` (indices into ``theta``)."""
        d = self.data
        Xf, Xl = self._designs(o, g, self.x, self.p, self.test_index, n_tests, rows, nodes)
        th = self.theta[rows]
        Xf = _draws(Xf, th.shape[0])
        if self.force_only:
            phat, lever, hold = (np.asarray(a) for a in (d.phat, d.feff_hat, d.dp_pa))
            sd = self._noise_factors(th, phat, lever, hold, None)[..., 0, 0]
            y = np.asarray(d.F) - np.asarray(d.feff_hat) * np.asarray(d.dp_meas)
            return Xf / sd[..., None], y[None] / sd
        L11, L21, L22 = (np.asarray(a) for a in jax.vmap(lambda t: pair.cov_factors(t[:5], d))(th))
        F, L = (np.asarray(a) for a in jax.vmap(lambda t: pair.readings(t[:5], d))(th))
        zf = Xf / L11[..., None]
        zl = (self._scale(th)[:, None, None] * _draws(Xl, th.shape[0]) - L21[..., None] * zf) / L22[
            ..., None
        ]
        Z = np.concatenate([zf, zl], axis=1)
        yw = np.concatenate([F / L11, (L - L21 * F / L11) / L22], axis=1)
        return Z, yw

    def _pilot(self, o, g, n_tests, nodes):
        """Precision and mean per draw from the file's readings (prior N(0, I) in the standardised
        coefficients), in blocks of ``CHUNK`` draws."""
        S = self.theta.shape[0]
        P = m = None
        for lo in range(0, S, CHUNK):
            Z, yw = self._pilot_block(np.arange(lo, min(lo + CHUNK, S)), o, g, n_tests, nodes)
            k = Z.shape[-1]
            if P is None:
                P, m = np.empty((S, k, k)), np.empty((S, k))
            A = np.einsum("snk,snl->skl", Z, Z) + np.eye(k)
            P[lo : lo + CHUNK] = A
            m[lo : lo + CHUNK] = np.linalg.solve(A, np.einsum("snk,sn->sk", Z, yw)[..., None])[
                ..., 0
            ]
        return P, m

    # ---- the frame
    def frame(self, new_bar=(), after_bar=None, new_heights=None) -> Frame:
        """The frame with new tests at ``new_bar`` (bar), modelled as the fit of the campaign with
        tests at ``after_bar`` would be (default: the file's and the new ones), the new tests read
        at ``new_heights`` when the layout is known (:meth:`model`)."""
        new = np.asarray(new_bar, float).reshape(-1)
        _new_index(new, self.tested)
        after = np.concatenate([self.tested, new]) if after_bar is None else after_bar
        o, g = self.model(after, new_heights)
        T0, J = self.tested.size, new.size
        nodes = self.prepare(new)
        P, m = self._pilot(o, g, T0 + J, nodes)
        area = self.rec.piston_area_m2

        def reading_rows(j, heights_m):
            x = np.asarray(heights_m, float).reshape(-1)
            p = np.full(x.shape, new[j])
            Xf_, Xl_ = self._designs(o, g, x, p, np.full(x.shape, T0 + j), T0 + J, None, nodes)
            return self._whiten(self.theta, Xf_, Xl_, *self._noise_data(x, p))

        def reading_noise(j, heights_m):
            x = np.asarray(heights_m, float).reshape(-1)
            return self._noise_factors(self.theta, *self._noise_data(x, np.full(x.shape, new[j])))

        def force_rows(x, p, open_=None):
            x, p = np.broadcast_arrays(np.asarray(x, float), np.asarray(p, float))
            idx = np.zeros(x.size, int)
            return self._designs(o, g, x.ravel(), p.ravel(), idx, T0 + J, None, nodes)[0]

        def area_rows(x, p, open_=None):
            """dV/dx = -S dL/dx, from the piston design by central differences (exact to
            rounding for these polynomials; the piston references drop out)."""
            x, p = (np.asarray(a, float).ravel() for a in np.broadcast_arrays(x, p))
            idx = np.zeros(x.size, int)
            up = self._designs(o, g, x + STEP_X_M, p, idx, T0 + J, None, nodes)[1]
            down = self._designs(o, g, x - STEP_X_M, p, idx, T0 + J, None, nodes)[1]
            return -area * (np.asarray(up) - np.asarray(down)) / (2 * STEP_X_M)

        return Frame(
            name=self.name,
            label=self.label(o),
            precision=P,
            mean=m,
            tested_bar=self.tested,
            new_bar=new,
            x0_m=self.rec.x0_m,
            reading_rows=reading_rows,
            reading_noise=reading_noise,
            force_rows=force_rows,
            area_rows=None if self.force_only else area_rows,
            extra_force_var=self.extra_force_var(nodes),
            volume_why=surface.volume_omitted_reason(self.rec) if self.force_only else "",
            key=(repr(o), repr(g)),
            min_test_heights=self.min_test_heights(o),
        )

    def prepare(self, new_bar):
        """What the designs of a frame with new tests at ``new_bar`` need besides the orders (None
        here), passed to :meth:`_designs` as ``nodes``."""
        return None

    def extra_force_var(self, nodes):
        """The force's variance no reading reduces, as ``Frame.extra_force_var`` (None: none)."""
        return None

    def key(self, after_bar) -> tuple:
        o, g = self.model(after_bar)
        return (repr(o), repr(g))

    def heights_needed(self, new_bar, new_heights) -> int:
        """Distinct heights each new test of this layout (tests at ``new_bar`` read at
        ``new_heights``) needs for the model of the combined campaign to be fitted: that of the
        orders the campaign gets (:meth:`model`; 0: any)."""
        after = np.concatenate([self.tested, np.asarray(new_bar, float).reshape(-1)])
        return self.min_test_heights(self.model(after, new_heights)[0])


class DiscrepancyFrames(PairFrames):
    """Frames of the surface with a discrepancy in pressure (module docstring): the surface's
    coefficients, then per deviation channel c (delta_k, eps_k, phi_k; uq._models.discrepancy) and
    test j of the frame (the file's, then the planned) a standard normal z_cj; a test i's
    deviation is a_c s_k (L z_c)_i, L the Cholesky factor of the Matern 3/2 correlation of the
    frame's pressures at the draw's length scale. Rows therefore depend on the draw: (S, n, k).
    phi's p_ref is the file's (the pilot's theta draws are of the pilot's fit)."""

    def __init__(self, rec, data, theta, stand, orders, geometry, reference, model=DiscrepancyFit):
        super().__init__(rec, data, theta, stand, orders, geometry, reference, model)
        self.scales = np.asarray(data.s, float)  # s_k
        self._set_theta(self.theta)

    def _set_theta(self, theta) -> None:
        self.theta = theta
        self.amplitudes, self.length = dev.hyper_draws(theta, self.data)  # (S, blocks), (S,)

    def label(self, orders) -> str:
        base = surface.force_label(orders) if self.force_only else orders.label
        return f"{DiscrepancyFit.words.removeprefix('the ')} ({base}; Matern 3/2 in p_u)"

    def min_test_heights(self, orders) -> int:
        return dev.min_heights_needed(orders, not self.force_only)

    def prepare(self, new_bar) -> Nodes:
        """The frame's pressures (the file's tests, then ``new_bar``) and, per draw, the Cholesky
        factor of their correlation."""
        p = np.concatenate([self.tested, np.asarray(new_bar, float)])
        R = gp.matern32(np.abs(p[:, None] - p[None, :])[None], self.length[:, None, None])
        return Nodes(p, np.linalg.cholesky(R + gp.JITTER * np.eye(p.size)))

    def _weights(self, p_bar, rows, nodes: Nodes):
        """(L^-1 r(p)) (s, n, T) and the conditional variance 1 - |L^-1 r|^2 (s, n) of the
        process at pressures ``p_bar`` given the frame's tests, for the draws ``rows``."""
        d = np.asarray(p_bar, float)[None, :, None] - nodes.p_bar[None, None]
        r = gp.matern32(d, self.length[rows][:, None, None])
        w = np.swapaxes(np.linalg.solve(nodes.chol[rows], np.swapaxes(r, 1, 2)), 1, 2)
        return w, np.clip(1.0 - np.sum(w**2, axis=-1), 0.0, None)

    def _channels(self, x, p):
        """The deviations' rows per channel at points: force (n, n_c), piston (n, n_c) or None."""
        t = (np.asarray(x, float) - self.rec.x0_m) / BASIS_SCALE_M
        area = None if self.force_only else self.rec.piston_area_m2
        return dev.deviation_rows(
            t, np.asarray(p, float)[:, None] * BAR_PA, self.scales.size, area, p_ref_pa(self.tested)
        )

    def _channel_scales(self, rows) -> np.ndarray:
        """a s_k per channel and draw, (s, n_c)."""
        a = self.amplitudes[rows]
        return np.concatenate([a[:, b : b + 1] * self.scales for b in range(a.shape[1])], axis=1)

    def _designs(self, o, g, x, p, index, n_tests, rows=None, nodes=None):
        Xf, Xl = super()._designs(o, g, x, p, index, n_tests)
        rows = np.arange(self.theta.shape[0]) if rows is None else rows
        w, _ = self._weights(p, rows, nodes)  # (s, n, T)
        gc = self._channel_scales(rows)  # (s, n_c)
        cf, cl = self._channels(x, p)
        S, n = rows.size, np.size(x)

        def dense(X, c):
            D = np.einsum("nc,sc,snj->sncj", c, gc, w).reshape(S, n, -1)
            return np.concatenate([_draws(X, S), D], axis=-1)

        return dense(Xf, cf), (None if cl is None else dense(Xl, cl))

    def extra_force_var(self, nodes):
        def extra(x, p, open_=None):
            x, p = (np.asarray(a, float).ravel() for a in np.broadcast_arrays(x, p))
            rows = np.arange(self.theta.shape[0])
            _, cv = self._weights(p, rows, nodes)  # (S, n)
            cf, _ = self._channels(x, p)
            gc = self._channel_scales(rows)
            return np.einsum("nc,sc->sn", cf**2, gc**2) * cv

        return extra


# ----------------------------------------------------------------------------- per-pressure cubics


class CubicFrames:
    """Frames of the per-pressure cubics, interpolated linearly in F_eff = P / p_u between tests."""

    name = registry.CUBICS
    fixed_frame = True  # independent tests: the frame does not change with the plan
    label_text = "per-pressure cubics, F_eff = P/p_u interpolated linearly in pressure"

    def __init__(self, rec, datas, thetas, mean_coef):
        """``datas``: each test's model data (``CubicData``, or ``ForceData`` of a force-only test),
        ``thetas``: each test's draws of theta (S, 3 or 2; the same S for all), ``mean_coef``
        (T0, 4): each test's posterior-mean force cubic in the paper's basis (a + b u + c u^2 +
        d u^3, SI): the budget's reference and the curvature in pressure. Tests in ``rec``'s order."""
        self.rec = rec
        p = np.array([t.pressure_bar for t in rec.tests])
        order = np.argsort(p)
        self.datas = [datas[i] for i in order]
        thetas = [np.asarray(thetas[i], float) for i in order]
        self.tested = p[order]
        self.force_only = not hasattr(self.datas[0], "piston")
        self.block = 4 if self.force_only else 8
        self.prior_sd = np.concatenate(
            [np.full(4, cubic.FORCE_PRIOR_SD_N)]
            + ([] if self.force_only else [np.full(4, cubic.PISTON_PRIOR_SD_M)])
        )
        self.x0_m = rec.x0_m
        self._source = None  # (datas, each test's draws of theta, mean_coef) of the fit (of_fit)
        self.theta = thetas
        self.S = thetas[0].shape[0]
        self.mean_coef = np.asarray(mean_coef, float)[order]
        self._noise = []  # per test: (s0 (S,), rel (S,), sL (S,) or None)
        for d, a in zip(self.datas, thetas, strict=True):
            nat = np.asarray(
                jax.vmap(lambda z, d=d: cubic.natural_noise(z, jnp.mean(d.ref_force)))(a)
            )
            s0, rel = np.exp(nat[:, 0]), np.exp(nat[:, 1])
            sL = np.exp(nat[:, 2]) if nat.shape[1] > 2 else None
            self._noise.append((s0, rel, sL))

    @classmethod
    def of_fit(cls, cubic_fit, draws: int = DRAWS) -> CubicFrames:
        """The builder of a CampaignFit, on ``draws`` draws of each test's theta (paired by index:
        the tests' posteriors are independent)."""
        rec = cubic_fit.recordings
        for t in cubic_fit.tests:
            if t.variant != "plain":
                raise InputError(
                    f"{rec.path}: the {t.test.label} test's cubic models the pressure holding "
                    f"('{t.variant}'); uq plan plans with the plain per-pressure cubics or a model over "
                    "all tests (`model` surface)",
                    param="model",
                )
        th = [t.posterior.theta.reshape(-1, t.posterior.theta.shape[-1]) for t in cubic_fit.tests]
        n = min(draws, *(a.shape[0] for a in th))
        datas = [t.posterior.data for t in cubic_fit.tests]
        mean_coef = np.stack([t.flat("force").mean(0) for t in cubic_fit.tests])
        out = cls(rec, datas, [_thin(a, n) for a in th], mean_coef)
        out._source = (datas, th, mean_coef)
        return out

    def pool(self, n: int):
        """The same builder on ``n`` draws of each test's theta that it does not use itself
        (:func:`held_out`), or None when it was not built from a fit or a test has no other draws."""
        if self._source is None:
            return None
        datas, th, mean_coef = self._source
        n = min(n, *(a.shape[0] - self.S for a in th))
        if n < 1:
            return None
        return type(self)(self.rec, datas, [held_out(a, self.S, n) for a in th], mean_coef)

    # ---- the pilot's mean force and its curvature in pressure
    def mean_force(self, x, p):
        """The pilot's interpolated posterior-mean force at (x, p) (F_eff linear in p between its
        tests, the end intervals extended), N: the budget's reference at a new test."""
        u = np.asarray(x, float).ravel() - self.x0_m
        p = np.asarray(p, float).ravel()
        if self.tested.size == 1:
            return p * BAR_PA * feff(self.mean_coef[0], u, self.tested[0])
        i, pa, pb, w = bracket(self.tested, p)
        F = (1 - w) * feff(self.mean_coef[i], u, pa) + w * feff(self.mean_coef[i + 1], u, pb)
        return p * BAR_PA * F

    def curvature_sd(self, x) -> np.ndarray:
        """rms over the file's interior tests of d^2 F_eff / dp^2 at height x (m^2/bar^2), from the
        posterior means (``CubicInterpolation.curvature_sd``'s estimate, pooled); 0 with fewer than
        three tests."""
        u = np.asarray(x, float) - self.x0_m
        if self.tested.size < 3:
            return np.zeros(u.shape)
        F = np.stack([feff(c, u, p) for c, p in zip(self.mean_coef, self.tested, strict=True)])
        return np.sqrt(np.mean(np.square(curvatures(F, self.tested)[1:-1]), axis=0))

    # ---- the frame
    def frame(self, new_bar=(), after_bar=None, new_heights=None) -> Frame:
        new = np.asarray(new_bar, float).reshape(-1)
        _new_index(new, self.tested)
        T0, J, b = self.tested.size, new.size, self.block
        k = b * (T0 + J)
        S = self.S
        P = np.zeros((S, k, k))
        m = np.zeros((S, k))
        prior_prec = 1.0 / self.prior_sd**2
        for j in range(T0 + J):
            P[:, j * b : (j + 1) * b, j * b : (j + 1) * b] = np.diag(prior_prec)

        def condition(sl, Z, y_over_sd):  # one tested block: its readings' precision and mean
            P[:, sl, sl] += np.einsum("snk,snl->skl", Z, Z)
            rhs = np.einsum("snk,sn->sk", Z, y_over_sd)
            m[:, sl] = np.linalg.solve(P[:, sl, sl], rhs[..., None])[..., 0]

        for i, d in enumerate(self.datas):
            X = np.asarray(d.X)[:, :4]
            s0, rel, sL = self._noise[i]
            sf = np.sqrt(force_noise_var(s0[:, None], rel[:, None], np.asarray(d.ref_force)[None]))
            y = np.asarray(d.force if hasattr(d, "piston") else d.y)
            condition(slice(i * b, i * b + 4), X[None] / sf[..., None], y[None] / sf)
            if not self.force_only:
                Zl, yl = X[None] / sL[:, None, None], np.asarray(d.piston)[None] / sL[:, None]
                condition(slice(i * b + 4, i * b + 8), Zl, yl)
        nearest = [int(np.argmin(np.abs(self.tested - p))) for p in new]
        x0 = self.x0_m

        def reading_sds(j, heights_m):
            """The heights, the force's sd of each reading (S, n) and the piston's (S,)."""
            x = np.asarray(heights_m, float).reshape(-1)
            s0, rel, sL = self._noise[nearest[j]]
            ref = np.abs(self.mean_force(x, np.full(x.shape, new[j])))
            return x, np.sqrt(force_noise_var(s0[:, None], rel[:, None], ref[None])), sL

        def reading_rows(j, heights_m):
            x, sf, sL = reading_sds(j, heights_m)
            X = np.asarray(cubic.basis(x - x0))  # (n, 4)
            r = 1 if self.force_only else 2
            Z = np.zeros((S, x.size, r, k))
            o = (T0 + j) * b
            Z[:, :, 0, o : o + 4] = X[None] / sf[..., None]
            if not self.force_only:
                Z[:, :, 1, o + 4 : o + 8] = X[None] / sL[:, None, None]
            return Z

        def reading_noise(j, heights_m):
            """The force's and the piston's sd of each reading (independent), as a diagonal factor."""
            x, sf, sL = reading_sds(j, heights_m)
            r = 1 if self.force_only else 2
            C = np.zeros((S, x.size, r, r))
            C[..., 0, 0] = sf
            if not self.force_only:
                C[..., 1, 1] = sL[:, None]
            return C

        def tests_of(open_):
            o = np.zeros(J, bool) if open_ is None else np.asarray(open_, bool)
            idx = np.concatenate([np.arange(T0), T0 + np.flatnonzero(o)])
            ps = np.concatenate([self.tested, new[o]])
            order = np.argsort(ps)
            return ps[order], idx[order]

        def force_rows(x, p, open_=None):
            x, p = (np.asarray(a, float).ravel() for a in np.broadcast_arrays(x, p))
            ps, idx = tests_of(open_)
            X = np.asarray(cubic.basis(x - x0))
            rows = np.zeros((x.size, k))
            n = np.arange(x.size)
            if ps.size == 1:
                rows[n[:, None], idx[0] * b + np.arange(4)] = X * (p / ps[0])[:, None]
                return rows
            i, pa, pb, w = bracket(ps, p)
            rows[n[:, None], idx[i][:, None] * b + np.arange(4)] += X * ((1 - w) * p / pa)[:, None]
            rows[n[:, None], idx[i + 1][:, None] * b + np.arange(4)] += X * (w * p / pb)[:, None]
            return rows

        def extra_force_var(x, p, open_=None):
            x, p = (np.asarray(a, float).ravel() for a in np.broadcast_arrays(x, p))
            ps, _ = tests_of(open_)
            if ps.size < 2:
                return np.zeros(x.size)
            _, pa, pb, _ = bracket(ps, p)
            bump = 0.5 * np.clip((p - pa) * (pb - p), 0, None)
            return (self.curvature_sd(x) * bump * p * BAR_PA) ** 2

        return Frame(
            name=self.name,
            label=self.label_text,
            precision=P,
            mean=m,
            tested_bar=self.tested,
            new_bar=new,
            x0_m=x0,
            reading_rows=reading_rows,
            reading_noise=reading_noise,
            force_rows=force_rows,
            extra_force_var=extra_force_var,
            rows_follow_tests=True,
            volume_why="the per-pressure cubics do not interpolate the volume-derived area between "
            "tested pressures (plan with `model` surface)",
        )

    def key(self, after_bar) -> tuple:
        return ()

    def heights_needed(self, new_bar, new_heights) -> int:
        """A new cubic is fixed by its prior: any heights do."""
        return 0


def frames_of(fit, draws: int = DRAWS):
    """The frame builder of a fit, by its class: :class:`CubicFrames` for the per-pressure cubics,
    :class:`DiscrepancyFrames` for the surface with a discrepancy, :class:`PairFrames` for the
    surface and the thermodynamic model; InputError for a model the planner has no frame of."""
    if isinstance(fit, CampaignFit):
        return CubicFrames.of_fit(fit, draws)
    if isinstance(fit, DiscrepancyFit):
        return DiscrepancyFrames.of_fit(fit, draws)
    if isinstance(fit, SurfaceFit | ThermoFit):
        return PairFrames.of_fit(fit, draws)
    raise InputError(
        f"model: uq plan has no planning frame for the model '{fit.name}' (it plans with "
        f"{', '.join(registry.names())} but a model plugged in from outside: the planner needs its "
        "design for a campaign with tests it has not seen)",
        param="model",
    )
