"""Design-margin queries (``uq margin``, docs/formats.md section 2), answered by the model the data prefer.

Which model answers. Two descriptions of a campaign can answer "at which overpressure does
the element carry W at height x": the pressure-coupled surface model (uq/_models/surface.py,
smooth in pressure) and the per-pressure cubics (uq/_models/cubic.py, eqs. 8, 9 of the paper, one
independent curve per tested pressure). ``uq margin`` fits both and compares them by PSIS-LOO
(``uq._derived.comparison``: the ELPD difference with its SE, Pareto k of both). The surface
answers unless the cubics are better by more than 2 SE with every Pareto k <= 0.7; an
indistinguishable or refused comparison keeps the surface, whose coverage is proven by
simulation for truths in its class (reports/surface-coverage/, the default orders). The JSON
says which model answered and why (``model``), with the comparison's numbers.

Cubics between tested pressures. The cubics say nothing between the tested pressures, so
they are interpolated: the paper's effective area F_eff = P / p_u at the height is taken
linear in p_u between the two neighbouring tests, and P = p_u F_eff. Its uncertainty has two
parts: (1) the posterior draws of both neighbouring cubics (independent tests, so draws are
paired at random); (2) the interpolation error, which is zero at the tested pressures and
(F'' / 2) (p - p_i)(p_i+1 - p) between them. F'' in pressure is estimated at every interior
tested pressure from its two neighbours (the curvature the data show: 2 e_j / ((p_j - p_j-1)
(p_j - p_j+1)) with e_j the test's F_eff minus the line through its neighbours); the error of
an interval is a normal draw per posterior draw with that parabola's shape and the rms
curvature of the interval's end tests as its sd. The assumption is stated: the curvature
between two tested pressures is no larger than at the neighbouring tested pressures.

All probabilities are over the posterior of the element's *mean* characteristic (the stand's
reading noise excluded: the load cell's and the pressure holding's scatter belong to the
stand, not to the element in service). ``pressure_bar_for_prob`` is exact: the force grows
with pressure at a fixed height, so "the element carries at least W at p" holds for a draw iff
p >= that draw's required pressure, and the smallest p with probability ``prob`` is the
``prob`` quantile of ``pressure_bar_needed``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from uq._inference.convergence import CLI_ADVICE
from uq._inference.summary import band, estimate
from uq._io.errors import InputError
from uq._io.files import sha256_of  # noqa: F401  (uq margin checks the file against the saved hash)
from uq._models.pair import refuse_extrapolation
from uq._models.surface import SurfaceFit
from uq._physics.quantities import BAR_PA

N_P_GRID = 801
N_CUBIC_DRAWS = 2000
SURFACE_NOISE = ("s0_N", "rel_load", "k_p", "sL_m", "V0_m3")
MODEL_CHOICES = ("auto", "surface", "thermodynamic", "cubics")


class _Ranges:
    """Tested ranges of a campaign and the refusal to extrapolate, shared by both answers."""

    def __init__(self, recordings=None, *, height_range_m=None, pressure_range_bar=None):
        if recordings is not None:
            p = recordings.pressures_bar
            pressure_range_bar, height_range_m = (
                (float(p.min()), float(p.max())),
                recordings.height_range_m,
            )
        self.pressure_range_bar = tuple(float(v) for v in pressure_range_bar)
        self.height_range_m = tuple(float(v) for v in height_range_m)

    def check_range(self, height_m, p_bar, param: str | None = None) -> None:
        refuse_extrapolation(
            height_m, p_bar, self.height_range_m, self.pressure_range_bar, param, "the model"
        )


class ThermoAnswer(_Ranges):
    """The thermodynamic model (uq._models.thermo.ThermoFit) as a margin answer: its force
    P = -dG/dx and volume-derived area on one fixed set of at most ``max_draws`` posterior draws
    (``uq margin --model thermodynamic``; not saved to a file)."""

    name = "thermodynamic"

    def __init__(self, fit, max_draws: int = 4000):
        super().__init__(fit.recordings)
        self.fit, self.beta = fit, fit.flat_beta(max_draws)
        self.label = f"thermodynamic model ({fit.orders.label})"

    def force_draws(self, height_m, p_bar):
        return self.fit.force_draws(height_m, p_bar, beta=self.beta)

    def volume_area_draws(self, height_m, p_bar):
        return self.fit.volume_area_draws(height_m, p_bar, beta=self.beta)


def _flat_draws(beta, max_draws):
    """The draws an answer uses: chains flattened, thinned evenly to at most ``max_draws`` (as SurfaceFit.flat_beta)."""
    b = np.asarray(beta).reshape(-1, np.shape(beta)[-1])
    if max_draws and b.shape[0] > max_draws:
        b = b[:: int(np.ceil(b.shape[0] / max_draws))]
    return b


class SurfaceAnswer(_Ranges):
    """The surface model's mean force on a fixed set of posterior draws (plain numpy, no JAX).

    Built from a SurfaceFit, or from a saved answer (``load_answer``): all it needs is the
    orders, the geometry (x0, p_mid, p_half), the number of tests and the coefficient draws.
    A force-only surface (a campaign without piston readings, ``force_only``) has no
    ``volume_area_draws`` (``hasattr`` is False: design margins are refused for it).
    """

    name = "surface"

    def __init__(self, fit: SurfaceFit, max_draws: int = 4000):
        super().__init__(fit.recordings)
        names = SURFACE_NOISE[:3] if fit.force_only else SURFACE_NOISE
        noise = {n: np.asarray(fit.idata.posterior[n]) for n in names}
        self._setup(
            fit.orders,
            fit.geometry,
            fit.recordings.pressures_bar,
            fit.beta,
            max_draws,
            noise,
            force_only=fit.force_only,
        )
        self.fit = fit

    def _setup(
        self, orders, geometry, test_pressures_bar, beta, max_draws, noise, force_only=False
    ):
        from uq._models.surface import SCALE_C, SCALE_D, SCALE_E, _sizes, force_label

        self.force_only = bool(force_only)
        self.orders, self.geometry, self.max_draws = orders, geometry, max_draws
        self.test_pressures_bar = np.asarray(test_pressures_bar, float)
        self.posterior_beta, self.noise = (
            np.asarray(beta, float),
            noise,
        )  # (C, D, k): what a saved file holds
        self.beta = _flat_draws(self.posterior_beta, max_draws)
        nc, ne, nd, _ = _sizes(orders, self.test_pressures_bar.size)
        self._c, self._e = self.beta[:, :nc] * SCALE_C, self.beta[:, nc : nc + ne] * SCALE_E
        self._d = self.beta[:, nc + ne : nc + ne + nd] * SCALE_D
        self.label = f"surface model ({force_label(orders) if force_only else orders.label})"

    def force_draws(self, height_m, p_bar):
        """P = p_u F_p + E, the same arithmetic as ``SurfaceFit.force_draws`` (tested equal to it), (S, *shape)."""
        from uq._models.surface import _poly, _tq

        h, p = np.broadcast_arrays(np.asarray(height_m, float), np.asarray(p_bar, float))
        shape, g, o = h.shape, self.geometry, self.orders
        t, q = g.t(h.ravel()), g.q(p.ravel())
        fe = (self._c @ _tq(t, q, o.K, o.Lp).T).reshape(-1, *shape)
        E = (self._e @ _poly(t, o.Ke).T).reshape(-1, *shape)
        return p * BAR_PA * fe + E

    def thinned(self, max_draws: int) -> SurfaceAnswer:
        """The same answer on at most ``max_draws`` of its draws (thinned evenly)."""
        new = SurfaceAnswer.__new__(SurfaceAnswer)
        _Ranges.__init__(
            new, height_range_m=self.height_range_m, pressure_range_bar=self.pressure_range_bar
        )
        new._setup(
            self.orders,
            self.geometry,
            self.test_pressures_bar,
            self.posterior_beta,
            max_draws,
            self.noise,
            force_only=self.force_only,
        )
        new.fit = getattr(self, "fit", None)
        return new

    @property
    def volume_area_draws(self):
        """The volume-derived area dV/dx = F_p + D, the same arithmetic as
        ``SurfaceFit.volume_area_draws`` (tested equal to it), (S, *shape): with it a saved surface
        answer is a design model (uq._derived.design) and answers design margins without a refit.
        A force-only surface has none (AttributeError, so ``hasattr`` says so)."""
        if self.force_only:
            raise AttributeError(
                "volume_area_draws: the surface was fitted to the force alone (no piston readings)"
            )
        return self._volume_area_draws

    def _volume_area_draws(self, height_m, p_bar):
        from uq._models.surface import _tq

        h, p = np.broadcast_arrays(np.asarray(height_m, float), np.asarray(p_bar, float))
        shape, g, o = h.shape, self.geometry, self.orders
        t, q = g.t(h.ravel()), g.q(p.ravel())
        area = self._c @ _tq(t, q, o.K, o.Lp).T
        if o.Dk >= 0:
            area = area + self._d @ _tq(t, q, o.Dk, o.Dl).T
        return area.reshape(-1, *shape)

    def coefficient_names(self) -> list[str]:
        o = self.orders
        names = [f"c_{k}{lq}" for k in range(o.K + 1) for lq in range(o.Lp + 1)]
        names += [f"e_{m}" for m in range(o.Ke + 1)]
        if o.Dk >= 0:
            names += [f"d_{k}{lq}" for k in range(o.Dk + 1) for lq in range(o.Dl + 1)]
        if self.force_only:
            return names
        return names + [f"r_{p:g}bar" for p in self.test_pressures_bar]


class CubicInterpolation(_Ranges):
    """Per-pressure cubics, F_eff = P / p_u linear in p_u between tested pressures (module docstring)."""

    name = "per-pressure cubics"
    label = "per-pressure cubics, F_eff = P/p_u interpolated linearly in pressure"

    def __init__(self, cubic_fit, n_draws: int = N_CUBIC_DRAWS, seed: int = 0):
        rec = cubic_fit.recordings
        super().__init__(rec)
        tests = sorted(cubic_fit.tests, key=lambda t: t.pressure_bar)
        rng = np.random.default_rng(seed)
        self.x0_m = rec.x0_m
        self.p = np.array([t.pressure_bar for t in tests])
        coefs = []
        for t in (
            tests
        ):  # independent tests: each test's draws thinned and shuffled, so pairs are random
            f = t.flat("force")
            f = f[np.linspace(0, f.shape[0] - 1, n_draws).astype(int)]
            coefs.append(f[rng.permutation(n_draws)])
        self.coef = np.stack(coefs, axis=1)  # (S, T, 4), paper basis in u = x - x0, SI
        self.z = rng.standard_normal(
            (n_draws, max(len(tests) - 1, 1))
        )  # interpolation error per interval

    @classmethod
    def from_draws(cls, coef, z, pressures_bar, x0_m, *, height_range_m, pressure_range_bar):
        """The answer from its stored parts (a saved answer): paired draws, interpolation normals, tests."""
        self = cls.__new__(cls)
        _Ranges.__init__(self, height_range_m=height_range_m, pressure_range_bar=pressure_range_bar)
        self.coef, self.z = np.asarray(coef, float), np.asarray(z, float)
        self.p, self.x0_m = np.asarray(pressures_bar, float), float(x0_m)
        return self

    def _feff(self, coef, u, p):
        return (coef[..., 0] + coef[..., 1] * u + coef[..., 2] * u**2 + coef[..., 3] * u**3) / (
            p * BAR_PA
        )

    def curvature_sd(self, height_m, interval):
        """sd of d^2 F_eff / dp^2 (m^2/bar^2) on ``interval`` from its end tests' neighbours."""
        u = np.asarray(height_m, float) - self.x0_m
        mean = self.coef.mean(axis=0)  # (T, 4)
        T = self.p.size
        F = np.stack([self._feff(mean[j], u, self.p[j]) for j in range(T)])  # (T, n)
        kap = np.full_like(F, np.nan)
        for j in range(1, T - 1):
            a, b, c = self.p[j - 1], self.p[j], self.p[j + 1]
            line = (F[j - 1] * (c - b) + F[j + 1] * (b - a)) / (c - a)
            kap[j] = 2.0 * (F[j] - line) / ((b - a) * (b - c))
        ends = np.stack(
            [
                kap[np.clip(interval, 0, T - 1), np.arange(u.size)],
                kap[np.clip(interval + 1, 0, T - 1), np.arange(u.size)],
            ]
        )
        with np.errstate(invalid="ignore"):
            return np.sqrt(np.nanmean(ends**2, axis=0)) if T > 2 else np.zeros(u.size)

    def force_draws(self, height_m, p_bar):
        h, p = np.broadcast_arrays(np.asarray(height_m, float), np.asarray(p_bar, float))
        shape, h, p = h.shape, h.ravel(), p.ravel()
        T = self.p.size
        i = np.clip(np.searchsorted(self.p, p, side="right") - 1, 0, max(T - 2, 0))
        u = h - self.x0_m
        if T == 1:
            return (p * BAR_PA * self._feff(self.coef[:, 0][:, None, :], u, self.p[0])).reshape(
                -1, *shape
            )
        pa, pb = self.p[i], self.p[i + 1]
        w = (p - pa) / (pb - pa)
        Fa = self._feff(self.coef[:, i], u, pa)  # (S, n)
        Fb = self._feff(self.coef[:, i + 1], u, pb)
        err = self.z[:, i] * (self.curvature_sd(h, i) * 0.5 * (p - pa) * (pb - p))[None, :]
        return (p * BAR_PA * ((1 - w) * Fa + w * Fb + err)).reshape(-1, *shape)


def as_answer(model):
    return SurfaceAnswer(model) if isinstance(model, SurfaceFit) else model


def pressure_needed(model, height_m: float, load_N: float) -> np.ndarray:
    """Posterior draws of the overpressure (bar) at which the element carries ``load_N``."""
    model = as_answer(model)
    refuse_extrapolation(  # as _Ranges.check_range, for any model with the tested ranges
        height_m,
        model.pressure_range_bar[0],
        model.height_range_m,
        model.pressure_range_bar,
        "height_m",
        "the model",
    )
    plo, phi = model.pressure_range_bar
    ps = np.linspace(plo, phi, N_P_GRID)
    P = model.force_draws(np.full_like(ps, height_m), ps)  # (S, G)
    above = P >= load_N
    # The answer is unique where the force crosses the load once; a force that does not rise with
    # pressure elsewhere (at 150 mm the casing's tension makes the 0.1-bar force negative, which
    # bends the cubics' interpolation below 1 bar) does not matter to a load it never equals there.
    crossings = np.count_nonzero(np.diff(above.astype(np.int8), axis=1), axis=1)
    frac = float(np.mean(crossings > 1))
    if frac > 0.01:
        raise InputError(
            f"load_N: at {height_m * 1e3:g} mm the force equals {load_N:g} N at more than one "
            f"overpressure in {100 * frac:.0f} % of the posterior draws (it does not rise with "
            "pressure there); no unique required pressure",
            param="load_N",
        )
    lo_load, hi_load = band(P[:, 0])[2], band(P[:, -1])[1]
    if not lo_load <= load_N <= hi_load:
        raise InputError(
            f"load_N: {load_N:g} N at {height_m * 1e3:g} mm is outside what the tested pressures "
            f"{plo:g}..{phi:g} bar support there (about {lo_load:.0f}..{hi_load:.0f} N); the model does not extrapolate",
            param="load_N",
        )
    first = np.argmax(above, axis=1)
    ok = above.any(axis=1) & ~above[:, 0]
    out = np.full(P.shape[0], np.nan)
    i = first[ok]
    rows = np.flatnonzero(ok)
    p0, p1 = ps[i - 1], ps[i]
    f0, f1 = P[rows, i - 1], P[rows, i]
    out[rows] = p0 + (load_N - f0) / (f1 - f0) * (p1 - p0)
    out[above[:, 0]] = plo  # already carried at the lowest pressure (within the band edge)
    out[~above.any(axis=1)] = np.inf  # not carried in the tested range
    return out


def _finite_estimate(d):
    d = np.asarray(d, float)
    if not np.all(np.isfinite(d)):
        raise InputError(
            "load_N: the load lies at the edge of the tested pressure range for part of the "
            "posterior; choose a load further inside the supported range",
            param="load_N",
        )
    return estimate(d)


def _run_around(ok: np.ndarray, j: int) -> tuple[np.ndarray, np.ndarray]:
    """First and last index of each row's run of True through column ``j`` (rows (S, n); meaningful where ok[:, j])."""
    n = ok.shape[1]
    left, right = ~ok[:, :j][:, ::-1], ~ok[:, j + 1 :]  # left: column j-1 first
    a = (
        np.where(left.any(axis=1), j - np.argmax(left, axis=1), 0)
        if j > 0
        else np.zeros(ok.shape[0], int)
    )
    b = (
        np.where(right.any(axis=1), j + np.argmax(right, axis=1), n - 1)
        if j < n - 1
        else np.full(ok.shape[0], n - 1)
    )
    return a, b


def usable_stroke(
    model,
    height_m: float,
    pressure_bar: float,
    target_N: float,
    tolerance_pct: float,
    prob: float,
    *,
    n_x: int = 361,
) -> dict:
    """Height range around ``height_m`` over which the force at ``pressure_bar`` stays within tolerance."""
    model = as_answer(model)
    lo, hi = model.height_range_m
    xs = np.linspace(lo, hi, n_x)
    P = model.force_draws(xs, pressure_bar)  # (S, n_x)
    ok = np.abs(P - target_N) <= tolerance_pct / 100.0 * abs(target_N)
    j = int(np.argmin(np.abs(xs - height_m)))
    a_s, b_s = _run_around(ok, j)
    lengths = np.where(ok[:, j], xs[b_s] - xs[a_s], 0.0)
    p_in = ok.mean(axis=0)
    a = b = j
    if p_in[j] >= prob:
        while a > 0 and p_in[a - 1] >= prob:
            a -= 1
        while b < n_x - 1 and p_in[b + 1] >= prob:
            b += 1
        joint = float(np.mean(np.all(ok[:, a : b + 1], axis=1)))
        credible = {
            "from_m": float(xs[a]),
            "to_m": float(xs[b]),
            "length_m": float(xs[b] - xs[a]),
            "prob_whole_range_within": joint,
        }
    else:
        credible = None
    return {
        "pressure_bar": pressure_bar,
        "target_N": target_N,
        "tolerance_pct": tolerance_pct,
        "prob_within_at_height": float(p_in[j]),
        "stroke_length_m": estimate(lengths),
        "stroke_credible": credible,
        "at_edge_of_tested_heights": bool(
            credible and (credible["from_m"] <= lo + 1e-9 or credible["to_m"] >= hi - 1e-9)
        ),
    }


COVERAGE_NOTE = (
    "the fallback when the data do not decide; its coverage for truths inside the default orders' class "
    "is checked by tests/models/test_surface.py (reports/surface-coverage/coverage.json: 100 replications "
    "on the paper's layout)"
)


def choose_model(
    fit: SurfaceFit | None, cubic_fit=None, comparison: dict | None = None, forced: str = "auto"
):
    """(answer, model description) from the PSIS-LOO comparison, or the user's ``--model``."""
    info = {"comparison": comparison}
    if forced == "thermodynamic":
        ans = ThermoAnswer(fit)
        return ans, {
            "name": ans.name,
            "label": ans.label,
            **info,
            "why": "chosen by the user (model thermodynamic); no comparison made",
        }
    if forced == "cubics" or (
        forced == "auto" and comparison and comparison["better"] == "per-pressure cubics"
    ):
        ans = CubicInterpolation(cubic_fit)
        info["why"] = (
            "chosen by the user (--model cubics)"
            if forced == "cubics"
            else f"the data prefer the per-pressure cubics: {comparison['reason']}"
        )
        info["interpolation"] = (
            "F_eff = P/p_u linear in p_u between neighbouring tested pressures; uncertainty: "
            "both tests' posteriors plus an interpolation error from the curvature in pressure "
            "at the neighbouring tested pressures (zero at tested pressures)"
        )
    else:
        return surface_answer(fit, comparison, forced=forced)
    return ans, {"name": ans.name, "label": ans.label, **info}


def surface_answer(
    fit: SurfaceFit, comparison: dict | None = None, *, forced: str = "auto", why: str | None = None
):
    """(SurfaceAnswer, model description) for a surface fit; ``why`` overrides the stated reason."""
    ans = SurfaceAnswer(fit)
    info = {"comparison": comparison, "orders": fit.label}
    if why is not None:
        info["why"] = why
    elif forced == "surface":
        info["why"] = "chosen by the user (--model surface); no comparison made"
    elif comparison is None:
        info["why"] = "surface model given; no comparison with the per-pressure cubics made"
    else:
        info["why"] = (
            f"PSIS-LOO verdict '{comparison['better']}': {comparison['reason']}; the surface answers ({COVERAGE_NOTE})"
        )
    return ans, {"name": ans.name, "label": ans.label, **info}


# ----------------------------------------------------------------------------- saved answers (NetCDF)

#: the root attribute ``uq_file_kind`` of a saved answer (docs/formats.md, "Saved margin answers")
ANSWER_KIND = "uq margin answer"
ANSWER_FORMAT_VERSION = 1
_ANSWER_NAMES = {"surface": "surface", "per-pressure cubics": "cubics"}


def answer_idata(
    ans,
    info: dict,
    *,
    recordings,
    seed: int,
    written_by: str,
    settings=None,
    stand=None,
    diagnostics: dict | None = None,
):
    """The answer as an ArviZ InferenceData: posterior draws, constant data, provenance in the root attributes."""
    import json
    from dataclasses import asdict

    import arviz as az
    import xarray as xr

    from uq._io.files import dumps_json
    from uq._io.version import __version__

    bounds = {"bound": ["min", "max"]}
    const = {
        "tested_height_range_m": ("bound", list(ans.height_range_m)),
        "tested_pressure_range_bar": ("bound", list(ans.pressure_range_bar)),
    }
    if isinstance(ans, SurfaceAnswer):
        from uq._models.surface import SCALE_C, SCALE_D, SCALE_E, SCALE_R, _sizes

        o, g = ans.orders, ans.geometry
        C, D, k = ans.posterior_beta.shape
        names = ans.coefficient_names()
        nc, ne, nd, nr = _sizes(o, 0 if ans.force_only else ans.test_pressures_bar.size)
        scale = np.concatenate(
            [np.full(nc, SCALE_C), np.full(ne, SCALE_E), np.full(nd, SCALE_D), np.full(nr, SCALE_R)]
        )
        coords = {"chain": np.arange(C), "draw": np.arange(D), "coefficient": names}
        post = {"surface_coefficient": (("chain", "draw", "coefficient"), ans.posterior_beta)}
        post |= {n: (("chain", "draw"), np.asarray(v, float)) for n, v in (ans.noise or {}).items()}
        const |= {
            "coefficient_scale": ("coefficient", scale),
            "orders": ("order", np.array([o.K, o.Lp, o.Ke, o.Dk, o.Dl], np.int64)),
            "x0_m": ((), g.x0_m),
            "piston_area_m2": ((), g.area_m2),
            "p_mid_bar": ((), g.p_mid),
            "p_half_bar": ((), g.p_half),
            "test_pressure_bar": ("test", ans.test_pressures_bar),
        }
        const_coords = bounds | {"coefficient": names, "order": ["K", "Lp", "Ke", "Dk", "Dl"]}
        extra = {"max_draws": int(ans.max_draws)}
    else:
        S, T, _ = ans.coef.shape
        coords = {
            "chain": [0],
            "draw": np.arange(S),
            "test": np.arange(T),
            "coefficient": ["a_P", "b_P", "c_P", "d_P"],
            "interval": np.arange(ans.z.shape[1]),
        }
        post = {
            "force_coefficient": (("chain", "draw", "test", "coefficient"), ans.coef[None]),
            "interpolation_z": (("chain", "draw", "interval"), ans.z[None]),
        }
        const |= {"x0_m": ((), ans.x0_m), "test_pressure_bar": ("test", ans.p)}
        const_coords = bounds
        extra = {}
    posterior = xr.Dataset(post, coords=coords)
    constant = xr.Dataset(const, coords=const_coords)
    diagnostics = diagnostics or {"warnings": [], "converged": True}
    attrs = {
        "uq_file_kind": ANSWER_KIND,
        "uq_format_version": ANSWER_FORMAT_VERSION,
        "answer": _ANSWER_NAMES[ans.name],
        "label": ans.label,
        "model_info_json": dumps_json(info),
        "recordings_path": str(Path(recordings.path).resolve()),
        "recordings_sha256": recordings.sha256 or sha256_of(recordings.path),
        "x0_mm": recordings.x0_m * 1e3,
        "piston_area_cm2": recordings.piston_area_m2 * 1e4,
        "uq_version": __version__,
        "seed": int(seed),
        "written_by": written_by,
        "settings_json": json.dumps(asdict(settings) if settings is not None else None),
        "stand_json": json.dumps(asdict(stand) if stand is not None else None),
        "sampler_converged": int(bool(diagnostics["converged"])),
        "sampler_warnings_json": json.dumps(list(diagnostics["warnings"])),
        **extra,
    }
    return az.InferenceData(attrs=attrs, posterior=posterior, constant_data=constant)


def save_answer(path, ans, info: dict, **provenance) -> Path:
    """Write the answer atomically to ``path`` (NetCDF, ``answer_idata``); returns the path."""
    from uq._io.files import write_netcdf_atomic

    return write_netcdf_atomic(path, answer_idata(ans, info, **provenance))


def save_surface_answer(
    fit: SurfaceFit, comparison: dict | None, out_dir, *, seed: int, settings=None, stand=None
) -> Path:
    """``uq surface --out DIR``: DIR/surface.nc, the surface model as a saved answer (whatever the comparison says)."""
    why = "saved by uq surface --out: the surface model answers (uq margin FILE.csv --save-fit chooses between the models)"
    if comparison is not None:
        why += f"; PSIS-LOO verdict '{comparison['better']}': {comparison['reason']}"
    ans, info = surface_answer(fit, comparison, why=why)
    return save_answer(
        Path(out_dir) / "surface.nc",
        ans,
        info,
        recordings=fit.recordings,
        seed=seed,
        written_by="uq surface --out",
        settings=settings,
        stand=stand,
        diagnostics={
            "warnings": fit.convergence.messages(CLI_ADVICE),
            "converged": fit.convergence.converged,
        },
    )


def load_answer(path):
    """(answer, model description, provenance) from a file ``save_answer`` wrote; InputError naming the file otherwise.

    Reads with xarray (no JAX compilation, no refit); the answer computes on the stored draws."""
    import json

    import xarray as xr

    path = str(path)
    if not Path(path).is_file():
        raise InputError(
            f"{path}: no such file (saved answers are written by uq.save_answer, by uq margin and by uq surface)"
        )
    try:
        with xr.open_dataset(path, engine="h5netcdf") as root:
            attrs = dict(root.attrs)
    except (
        Exception
    ) as exc:  # h5py/h5netcdf raise OSError, ValueError, KeyError... on a file that is not NetCDF-4
        raise InputError(
            f"{path}: not a readable NetCDF file ({type(exc).__name__}: {' '.join(str(exc).split())[:120]})"
        ) from None
    if attrs.get("uq_file_kind") != ANSWER_KIND:
        raise InputError(
            f"{path}: not a saved margin answer (no uq_file_kind = '{ANSWER_KIND}'); "
            "write one with uq.save_answer, uq margin or uq surface"
        )
    version = int(attrs.get("uq_format_version", -1))
    if version != ANSWER_FORMAT_VERSION:
        raise InputError(
            f"{path}: saved-answer format version {version}; this uq reads version {ANSWER_FORMAT_VERSION}"
        )
    try:
        groups = {}
        for g in ("posterior", "constant_data"):
            with xr.open_dataset(path, group=g, engine="h5netcdf") as ds:
                groups[g] = ds.load()
        post, const = groups["posterior"], groups["constant_data"]
        info = json.loads(attrs["model_info_json"])
        ranges = {
            "height_range_m": const["tested_height_range_m"].values,
            "pressure_range_bar": const["tested_pressure_range_bar"].values,
        }
        if attrs["answer"] == "surface":
            from uq._models.surface import Geometry, Orders, _sizes

            ans = SurfaceAnswer.__new__(SurfaceAnswer)
            _Ranges.__init__(ans, **ranges)
            noise = {n: post[n].values for n in SURFACE_NOISE if n in post}
            orders = Orders(*(int(v) for v in const["orders"].values))
            g = Geometry(
                float(const["x0_m"]),
                float(const["piston_area_m2"]),
                float(const["p_mid_bar"]),
                float(const["p_half_bar"]),
            )
            beta = post["surface_coefficient"].values
            nc, ne, nd, _ = _sizes(orders, 0)
            ans._setup(  # a force-only surface has no piston references
                orders,
                g,
                const["test_pressure_bar"].values,
                beta,
                int(attrs["max_draws"]),
                noise,
                force_only=beta.shape[-1] == nc + ne + nd,
            )
            ans.fit = None
        elif attrs["answer"] == "cubics":
            ans = CubicInterpolation.from_draws(
                post["force_coefficient"].values[0],
                post["interpolation_z"].values[0],
                const["test_pressure_bar"].values,
                float(const["x0_m"]),
                **ranges,
            )
        else:
            raise KeyError(f"answer = {attrs['answer']!r}")
    except Exception as exc:  # a damaged or hand-edited file: say so in one line
        raise InputError(
            f"{path}: damaged saved margin answer ({type(exc).__name__}: {' '.join(str(exc).split())[:120]})"
        ) from None
    meta = {
        k: attrs[k]
        for k in (
            "answer",
            "recordings_path",
            "recordings_sha256",
            "uq_version",
            "seed",
            "written_by",
        )
    }
    meta["converged"] = bool(int(attrs.get("sampler_converged", 1)))
    meta["warnings"] = json.loads(attrs.get("sampler_warnings_json", "[]"))
    return ans, info, meta


def margin(
    model,
    height_m: float,
    load_N: float,
    prob: float = 0.95,
    *,
    pressure_bar: float | None = None,
    tolerance_pct: float | None = None,
    model_info: dict | None = None,
) -> dict:
    """The margin query on ``model`` (a SurfaceFit, SurfaceAnswer or CubicInterpolation)."""
    if not 0.0 < prob < 1.0:
        raise InputError(
            f"prob: expected a probability between 0 and 1, got {prob:g}", param="prob"
        )
    if not load_N > 0:
        raise InputError(f"load_N: expected a positive load in N, got {load_N:g}", param="load_N")
    if tolerance_pct is not None and pressure_bar is None:
        raise InputError(
            "tolerance_pct: needs a pressure_bar (the stroke is taken at one pressure)",
            param="tolerance_pct",
        )
    if model_info is None:
        model, model_info = (
            choose_model(model)
            if isinstance(model, SurfaceFit)
            else (model, {"name": model.name, "label": model.label, "why": "given by the caller"})
        )
    need = pressure_needed(model, height_m, load_N)
    est = _finite_estimate(need)
    plo, phi = model.pressure_range_bar
    res = {
        "height_m": height_m,
        "load_N": load_N,
        "prob": prob,
        "pressure_bar_needed": est,
        "pressure_bar_for_prob": float(np.quantile(need, prob)),
        "model": model_info,
        "distribution": "posterior of the mean characteristic (stand reading noise excluded)",
        "tested_pressure_range_bar": [plo, phi],
        "tested_height_range_m": list(model.height_range_m),
    }
    if pressure_bar is not None:
        model.check_range(height_m, pressure_bar, "pressure_bar")
        P = model.force_draws(np.array(height_m), pressure_bar)
        res["force_at_pressure"] = {
            "pressure_bar": pressure_bar,
            "force_N": estimate(P),
            "prob_carries_load": float(np.mean(P >= load_N)),
        }
        if tolerance_pct is not None:
            if not tolerance_pct > 0:
                raise InputError(
                    f"tolerance_pct: expected a positive tolerance, got {tolerance_pct:g}",
                    param="tolerance_pct",
                )
            res["usable_stroke"] = usable_stroke(
                model, height_m, pressure_bar, load_N, tolerance_pct, prob
            )
    return res


def fit_and_choose(rec, *, model: str = "auto", seed: int = 0, settings=None, stand=None):
    """Fit what ``model`` ("auto", "surface", "thermodynamic" or "cubics") needs and choose the answering model
    (:func:`choose_model`); returns (answer, model description, merged sampler diagnostics).
    With "auto" both models are fitted with the same settings and compared
    (``uq._derived.comparison``)."""
    from uq._data.stand_description import PAPER_STAND
    from uq._derived.comparison import fit_both
    from uq._inference.sampler import Settings
    from uq._models.cubic import fit_campaign
    from uq._models.surface import fit_surface

    settings = Settings() if settings is None else settings
    stand = PAPER_STAND if stand is None else stand
    fit = cub = comparison = None
    if model == "auto":
        fit, cub, comparison = fit_both(rec, seed=seed, settings=settings, stand=stand)
    elif model == "surface":
        fit = fit_surface(rec, seed=seed, settings=settings, stand=stand)
    elif model == "thermodynamic":
        from uq._models.thermo import fit_thermo

        fit = fit_thermo(rec, seed=seed, settings=settings, stand=stand)
    else:
        cub = fit_campaign(rec, seed=seed, settings=settings, stand=stand)
    warnings, converged = [], True
    if fit is not None:
        warnings += fit.convergence.messages(CLI_ADVICE)
        converged &= fit.convergence.converged
    if cub is not None:
        warnings += [
            f"{w.split(': ', 1)[0]} cubic: {w.split(': ', 1)[1]}" for w in cub.warnings(CLI_ADVICE)
        ]
        converged &= cub.converged
    ans, info = choose_model(fit, cub, comparison, forced=model)
    if not rec.has_piston:  # a force-only campaign: compared per force reading
        from uq._models.surface import volume_omitted_reason

        info["omitted"] = volume_omitted_reason(rec)
    return ans, info, {"warnings": warnings, "converged": bool(converged)}
