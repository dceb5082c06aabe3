"""Design-margin queries (``uq margin``, CONTRACT.md section 3), answered by the model the data prefer.

Which model answers. Two descriptions of a campaign can answer "at which overpressure does
the element carry W at height x": the pressure-coupled surface model (uq/_surface.py,
smooth in pressure) and the per-pressure cubics (uq/_cubic.py, eqs. 8, 9 of the paper, one
independent curve per tested pressure). ``uq margin`` fits both and compares them by PSIS-LOO
(``compare_with_cubics``: the ELPD difference with its SE, Pareto k of both). The surface
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

from ._errors import InputError
from ._physics import BAR_PA
from ._summary import band, estimate
from ._surface import SurfaceFit

N_P_GRID = 801
N_CUBIC_DRAWS = 2000
SURFACE_NOISE = ("s0_N", "rel_load", "k_p", "sL_m", "V0_m3")
MODEL_CHOICES = ("auto", "surface", "cubics")


class _Ranges:
    """Tested ranges of a campaign and the refusal to extrapolate, shared by both answers."""

    def __init__(self, recordings=None, *, height_range_m=None, pressure_range_bar=None):
        if recordings is not None:
            p = recordings.pressures_bar
            pressure_range_bar, height_range_m = (float(p.min()), float(p.max())), recordings.height_range_m
        self.pressure_range_bar = tuple(float(v) for v in pressure_range_bar)
        self.height_range_m = tuple(float(v) for v in height_range_m)

    def check_range(self, height_m, p_bar, what="") -> None:
        lo, hi = self.height_range_m
        h = np.atleast_1d(np.asarray(height_m, float))
        if np.any(h < lo - 1e-9) or np.any(h > hi + 1e-9):
            bad = h[(h < lo - 1e-9) | (h > hi + 1e-9)][0]
            raise InputError(f"{what}height {bad * 1e3:g} mm is outside the tested heights "
                             f"{lo * 1e3:g}..{hi * 1e3:g} mm; the model does not extrapolate")
        plo, phi = self.pressure_range_bar
        p = np.atleast_1d(np.asarray(p_bar, float))
        if np.any(p < plo - 1e-9) or np.any(p > phi + 1e-9):
            bad = p[(p < plo - 1e-9) | (p > phi + 1e-9)][0]
            raise InputError(f"{what}overpressure {bad:g} bar is outside the tested pressures "
                             f"{plo:g}..{phi:g} bar; the model does not extrapolate")


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
    """

    name = "surface"

    def __init__(self, fit: SurfaceFit, max_draws: int = 4000):
        super().__init__(fit.recordings)
        noise = {n: np.asarray(fit.idata.posterior[n]) for n in SURFACE_NOISE}
        self._setup(fit.orders, fit.geometry, fit.recordings.pressures_bar, fit.beta, max_draws, noise)
        self.fit = fit

    def _setup(self, orders, geometry, test_pressures_bar, beta, max_draws, noise):
        from ._surface import SCALE_C, SCALE_E, _sizes

        self.orders, self.geometry, self.max_draws = orders, geometry, max_draws
        self.test_pressures_bar = np.asarray(test_pressures_bar, float)
        self.posterior_beta, self.noise = np.asarray(beta, float), noise  # (C, D, k): what a saved file holds
        self.beta = _flat_draws(self.posterior_beta, max_draws)
        nc, ne, _, _ = _sizes(orders, self.test_pressures_bar.size)
        self._c, self._e = self.beta[:, :nc] * SCALE_C, self.beta[:, nc : nc + ne] * SCALE_E
        self.label = f"surface model ({orders.label})"

    def force_draws(self, height_m, p_bar):
        """P = p_u F_p + E, the same arithmetic as ``SurfaceFit.force_draws`` (tested equal to it), (S, *shape)."""
        from ._surface import _poly, _tq

        h, p = np.broadcast_arrays(np.asarray(height_m, float), np.asarray(p_bar, float))
        shape, g, o = h.shape, self.geometry, self.orders
        t, q = g.t(h.ravel()), g.q(p.ravel())
        fe = (self._c @ _tq(t, q, o.K, o.Lp).T).reshape(-1, *shape)
        E = (self._e @ _poly(t, o.Ke).T).reshape(-1, *shape)
        return p * BAR_PA * fe + E

    def coefficient_names(self) -> list[str]:
        o = self.orders
        names = [f"c_{k}{lq}" for k in range(o.K + 1) for lq in range(o.Lp + 1)]
        names += [f"e_{m}" for m in range(o.Ke + 1)]
        if o.Dk >= 0:
            names += [f"d_{k}{lq}" for k in range(o.Dk + 1) for lq in range(o.Dl + 1)]
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
        for t in tests:  # independent tests: each test's draws thinned and shuffled, so pairs are random
            f = t.flat("force")
            f = f[np.linspace(0, f.shape[0] - 1, n_draws).astype(int)]
            coefs.append(f[rng.permutation(n_draws)])
        self.coef = np.stack(coefs, axis=1)  # (S, T, 4), paper basis in u = x - x0, SI
        self.z = rng.standard_normal((n_draws, max(len(tests) - 1, 1)))  # interpolation error per interval

    @classmethod
    def from_draws(cls, coef, z, pressures_bar, x0_m, *, height_range_m, pressure_range_bar):
        """The answer from its stored parts (a saved answer): paired draws, interpolation normals, tests."""
        self = cls.__new__(cls)
        _Ranges.__init__(self, height_range_m=height_range_m, pressure_range_bar=pressure_range_bar)
        self.coef, self.z = np.asarray(coef, float), np.asarray(z, float)
        self.p, self.x0_m = np.asarray(pressures_bar, float), float(x0_m)
        return self

    def _feff(self, coef, u, p):
        return (coef[..., 0] + coef[..., 1] * u + coef[..., 2] * u**2 + coef[..., 3] * u**3) / (p * BAR_PA)

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
        ends = np.stack([kap[np.clip(interval, 0, T - 1), np.arange(u.size)],
                         kap[np.clip(interval + 1, 0, T - 1), np.arange(u.size)]])
        with np.errstate(invalid="ignore"):
            return np.sqrt(np.nanmean(ends**2, axis=0)) if T > 2 else np.zeros(u.size)

    def force_draws(self, height_m, p_bar):
        h, p = np.broadcast_arrays(np.asarray(height_m, float), np.asarray(p_bar, float))
        shape, h, p = h.shape, h.ravel(), p.ravel()
        T = self.p.size
        i = np.clip(np.searchsorted(self.p, p, side="right") - 1, 0, max(T - 2, 0))
        u = h - self.x0_m
        if T == 1:
            return (p * BAR_PA * self._feff(self.coef[:, 0][:, None, :], u, self.p[0])).reshape(-1, *shape)
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
    model.check_range(height_m, model.pressure_range_bar[0], "option --height-mm: ")
    plo, phi = model.pressure_range_bar
    ps = np.linspace(plo, phi, N_P_GRID)
    P = model.force_draws(np.full_like(ps, height_m), ps)  # (S, G)
    if np.any(np.diff(P, axis=1) < 0):
        frac = float(np.mean(np.any(np.diff(P, axis=1) < 0, axis=1)))
        if frac > 0.01:
            raise InputError(f"option --height-mm: at {height_m * 1e3:g} mm the force does not rise with pressure in "
                             f"{100 * frac:.0f} % of the posterior draws; no unique required pressure")
    lo_load, hi_load = band(P[:, 0])[2], band(P[:, -1])[1]
    if not lo_load <= load_N <= hi_load:
        raise InputError(
            f"option --load-N: {load_N:g} N at {height_m * 1e3:g} mm is outside what the tested pressures "
            f"{plo:g}..{phi:g} bar support there (about {lo_load:.0f}..{hi_load:.0f} N); the model does not extrapolate")
    above = P >= load_N
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
        raise InputError("option --load-N: the load lies at the edge of the tested pressure range for part of the "
                         "posterior; choose a load further inside the supported range")
    return estimate(d)


def _run_around(ok: np.ndarray, j: int) -> tuple[np.ndarray, np.ndarray]:
    """First and last index of each row's run of True through column ``j`` (rows (S, n); meaningful where ok[:, j])."""
    n = ok.shape[1]
    left, right = ~ok[:, :j][:, ::-1], ~ok[:, j + 1 :]  # left: column j-1 first
    a = np.where(left.any(axis=1), j - np.argmax(left, axis=1), 0) if j > 0 else np.zeros(ok.shape[0], int)
    b = np.where(right.any(axis=1), j + np.argmax(right, axis=1), n - 1) if j < n - 1 else np.full(ok.shape[0], n - 1)
    return a, b


def usable_stroke(model, height_m: float, pressure_bar: float, target_N: float, tolerance_pct: float,
                  prob: float, *, n_x: int = 361) -> dict:
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
        credible = {"from_m": float(xs[a]), "to_m": float(xs[b]), "length_m": float(xs[b] - xs[a]),
                    "prob_whole_range_within": joint}
    else:
        credible = None
    return {
        "pressure_bar": pressure_bar, "target_N": target_N, "tolerance_pct": tolerance_pct,
        "prob_within_at_height": float(p_in[j]),
        "stroke_length_m": estimate(lengths),
        "stroke_credible": credible,
        "at_edge_of_tested_heights": bool(credible and (credible["from_m"] <= lo + 1e-9 or credible["to_m"] >= hi - 1e-9)),
    }


COVERAGE_NOTE = ("the fallback when the data do not decide; its coverage for truths inside the default orders' class "
                 "is checked by tests/test_surface.py::test_fast_coverage (10 replications); the committed "
                 "100-replication report predates the pressure-error sign fix (README, known gap)")


def choose_model(fit: SurfaceFit | None, cubic_fit=None, comparison: dict | None = None, forced: str = "auto"):
    """(answer, model description) from the PSIS-LOO comparison, or the user's ``--model``."""
    info = {"comparison": comparison}
    if forced == "cubics" or (forced == "auto" and comparison and comparison["better"] == "per-pressure cubics"):
        ans = CubicInterpolation(cubic_fit)
        info["why"] = ("chosen by the user (--model cubics)" if forced == "cubics" else
                       f"the data prefer the per-pressure cubics: {comparison['reason']}")
        info["interpolation"] = ("F_eff = P/p_u linear in p_u between neighbouring tested pressures; uncertainty: "
                                 "both tests' posteriors plus an interpolation error from the curvature in pressure "
                                 "at the neighbouring tested pressures (zero at tested pressures)")
    else:
        return surface_answer(fit, comparison, forced=forced)
    return ans, {"name": ans.name, "label": ans.label, **info}


def surface_answer(fit: SurfaceFit, comparison: dict | None = None, *, forced: str = "auto", why: str | None = None):
    """(SurfaceAnswer, model description) for a surface fit; ``why`` overrides the stated reason."""
    ans = SurfaceAnswer(fit)
    info = {"comparison": comparison, "orders": fit.orders.label}
    if why is not None:
        info["why"] = why
    elif forced == "surface":
        info["why"] = "chosen by the user (--model surface); no comparison made"
    elif comparison is None:
        info["why"] = "surface model given; no comparison with the per-pressure cubics made"
    else:
        info["why"] = f"PSIS-LOO verdict '{comparison['better']}': {comparison['reason']}; the surface answers ({COVERAGE_NOTE})"
    return ans, {"name": ans.name, "label": ans.label, **info}


# ----------------------------------------------------------------------------- saved answers (NetCDF)

#: the root attribute ``uq_file_kind`` of a saved answer (docs/formats.md, "Saved margin answers")
ANSWER_KIND = "uq margin answer"
ANSWER_FORMAT_VERSION = 1
_ANSWER_NAMES = {"surface": "surface", "per-pressure cubics": "cubics"}


def sha256_of(path) -> str:
    import hashlib

    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def answer_idata(ans, info: dict, *, recordings, seed: int, written_by: str, settings=None, stand=None,
                 diagnostics: dict | None = None):
    """The answer as an ArviZ InferenceData: posterior draws, constant data, provenance in the root attributes."""
    import json
    from dataclasses import asdict

    import arviz as az
    import xarray as xr

    from . import __version__
    from ._io import dumps_json

    bounds = {"bound": ["min", "max"]}
    const = {"tested_height_range_m": ("bound", list(ans.height_range_m)),
             "tested_pressure_range_bar": ("bound", list(ans.pressure_range_bar))}
    if isinstance(ans, SurfaceAnswer):
        from ._surface import SCALE_C, SCALE_D, SCALE_E, SCALE_R, _sizes

        o, g = ans.orders, ans.geometry
        C, D, k = ans.posterior_beta.shape
        names = ans.coefficient_names()
        nc, ne, nd, nr = _sizes(o, ans.test_pressures_bar.size)
        scale = np.concatenate([np.full(nc, SCALE_C), np.full(ne, SCALE_E), np.full(nd, SCALE_D), np.full(nr, SCALE_R)])
        coords = {"chain": np.arange(C), "draw": np.arange(D), "coefficient": names}
        post = {"surface_coefficient": (("chain", "draw", "coefficient"), ans.posterior_beta)}
        post |= {n: (("chain", "draw"), np.asarray(v, float)) for n, v in (ans.noise or {}).items()}
        const |= {"coefficient_scale": ("coefficient", scale),
                  "orders": ("order", np.array([o.K, o.Lp, o.Ke, o.Dk, o.Dl], np.int64)),
                  "x0_m": ((), g.x0_m), "piston_area_m2": ((), g.area_m2),
                  "p_mid_bar": ((), g.p_mid), "p_half_bar": ((), g.p_half),
                  "test_pressure_bar": ("test", ans.test_pressures_bar)}
        const_coords = bounds | {"coefficient": names, "order": ["K", "Lp", "Ke", "Dk", "Dl"]}
        extra = {"max_draws": int(ans.max_draws)}
    else:
        S, T, _ = ans.coef.shape
        coords = {"chain": [0], "draw": np.arange(S), "test": np.arange(T), "coefficient": ["a_P", "b_P", "c_P", "d_P"],
                  "interval": np.arange(ans.z.shape[1])}
        post = {"force_coefficient": (("chain", "draw", "test", "coefficient"), ans.coef[None]),
                "interpolation_z": (("chain", "draw", "interval"), ans.z[None])}
        const |= {"x0_m": ((), ans.x0_m), "test_pressure_bar": ("test", ans.p)}
        const_coords = bounds
        extra = {}
    posterior = xr.Dataset(post, coords=coords)
    constant = xr.Dataset(const, coords=const_coords)
    diagnostics = diagnostics or {"warnings": [], "converged": True}
    attrs = {
        "uq_file_kind": ANSWER_KIND, "uq_format_version": ANSWER_FORMAT_VERSION,
        "answer": _ANSWER_NAMES[ans.name], "label": ans.label,
        "model_info_json": dumps_json(info),
        "recordings_path": str(Path(recordings.path).resolve()),
        "recordings_sha256": sha256_of(recordings.path),
        "x0_mm": recordings.x0_m * 1e3, "piston_area_cm2": recordings.piston_area_m2 * 1e4,
        "uq_version": __version__, "seed": int(seed), "written_by": written_by,
        "settings_json": json.dumps(asdict(settings) if settings is not None else None),
        "stand_json": json.dumps(asdict(stand) if stand is not None else None),
        "sampler_converged": int(bool(diagnostics["converged"])),
        "sampler_warnings_json": json.dumps(list(diagnostics["warnings"])),
        **extra,
    }
    return az.InferenceData(attrs=attrs, posterior=posterior, constant_data=constant)


def save_answer(path, ans, info: dict, **provenance) -> Path:
    """Write the answer atomically to ``path`` (NetCDF, ``answer_idata``); returns the path."""
    from ._io import write_file_atomic

    idata = answer_idata(ans, info, **provenance)
    return write_file_atomic(path, lambda tmp: idata.to_netcdf(str(tmp), engine="h5netcdf"))


def save_surface_answer(fit: SurfaceFit, comparison: dict | None, out_dir, *, seed: int, settings=None, stand=None) -> Path:
    """``uq surface --out DIR``: DIR/surface.nc, the surface model as a saved answer (whatever the comparison says)."""
    why = "saved by uq surface --out: the surface model answers (uq margin FILE.csv --save-fit chooses between the models)"
    if comparison is not None:
        why += f"; PSIS-LOO verdict '{comparison['better']}': {comparison['reason']}"
    ans, info = surface_answer(fit, comparison, why=why)
    return save_answer(Path(out_dir) / "surface.nc", ans, info, recordings=fit.recordings, seed=seed,
                       written_by="uq surface --out", settings=settings, stand=stand, diagnostics=fit.diagnostics)


def load_answer(path):
    """(answer, model description, provenance) from a file ``save_answer`` wrote; InputError naming the file otherwise.

    Reads with xarray (no JAX compilation, no refit); the answer computes on the stored draws."""
    import json

    import xarray as xr

    path = str(path)
    if not Path(path).is_file():
        raise InputError(f"{path}: no such file (option --fit names a file written by uq margin --save-fit or uq surface --out)")
    try:
        with xr.open_dataset(path, engine="h5netcdf") as root:
            attrs = dict(root.attrs)
    except Exception as exc:  # h5py/h5netcdf raise OSError, ValueError, KeyError... on a file that is not NetCDF-4
        raise InputError(f"{path}: not a readable NetCDF file ({type(exc).__name__}: {' '.join(str(exc).split())[:120]})") from None
    if attrs.get("uq_file_kind") != ANSWER_KIND:
        raise InputError(f"{path}: not a saved margin answer (no uq_file_kind = '{ANSWER_KIND}'); "
                         "write one with uq margin --save-fit or uq surface --out")
    version = int(attrs.get("uq_format_version", -1))
    if version != ANSWER_FORMAT_VERSION:
        raise InputError(f"{path}: saved-answer format version {version}; this uq reads version {ANSWER_FORMAT_VERSION}")
    try:
        groups = {}
        for g in ("posterior", "constant_data"):
            with xr.open_dataset(path, group=g, engine="h5netcdf") as ds:
                groups[g] = ds.load()
        post, const = groups["posterior"], groups["constant_data"]
        info = json.loads(attrs["model_info_json"])
        ranges = {"height_range_m": const["tested_height_range_m"].values,
                  "pressure_range_bar": const["tested_pressure_range_bar"].values}
        if attrs["answer"] == "surface":
            from ._surface import Geometry, Orders

            ans = SurfaceAnswer.__new__(SurfaceAnswer)
            _Ranges.__init__(ans, **ranges)
            noise = {n: post[n].values for n in SURFACE_NOISE if n in post}
            g = Geometry(float(const["x0_m"]), float(const["piston_area_m2"]), float(const["p_mid_bar"]),
                         float(const["p_half_bar"]))
            ans._setup(Orders(*(int(v) for v in const["orders"].values)), g, const["test_pressure_bar"].values,
                       post["surface_coefficient"].values, int(attrs["max_draws"]), noise)
            ans.fit = None
        elif attrs["answer"] == "cubics":
            ans = CubicInterpolation.from_draws(post["force_coefficient"].values[0], post["interpolation_z"].values[0],
                                                const["test_pressure_bar"].values, float(const["x0_m"]), **ranges)
        else:
            raise KeyError(f"answer = {attrs['answer']!r}")
    except Exception as exc:  # a damaged or hand-edited file: say so in one line
        raise InputError(f"{path}: damaged saved margin answer ({type(exc).__name__}: {' '.join(str(exc).split())[:120]})") from None
    meta = {k: attrs[k] for k in ("answer", "recordings_path", "recordings_sha256", "uq_version", "seed", "written_by")}
    meta["converged"] = bool(int(attrs.get("sampler_converged", 1)))
    meta["warnings"] = json.loads(attrs.get("sampler_warnings_json", "[]"))
    return ans, info, meta


def margin(model, height_m: float, load_N: float, prob: float = 0.95, *, pressure_bar: float | None = None,
           tolerance_pct: float | None = None, model_info: dict | None = None) -> dict:
    """The margin query on ``model`` (a SurfaceFit, SurfaceAnswer or CubicInterpolation)."""
    if not 0.0 < prob < 1.0:
        raise InputError(f"option --prob: expected a probability between 0 and 1, got {prob:g}")
    if not load_N > 0:
        raise InputError(f"option --load-N: expected a positive load in N, got {load_N:g}")
    if tolerance_pct is not None and pressure_bar is None:
        raise InputError("option --tolerance-pct: needs --pressure-bar (the stroke is taken at one pressure)")
    if model_info is None:
        model, model_info = choose_model(model) if isinstance(model, SurfaceFit) else (
            model, {"name": model.name, "label": model.label, "why": "given by the caller"})
    need = pressure_needed(model, height_m, load_N)
    est = _finite_estimate(need)
    plo, phi = model.pressure_range_bar
    res = {
        "height_m": height_m, "load_N": load_N, "prob": prob,
        "pressure_bar_needed": est,
        "pressure_bar_for_prob": float(np.quantile(need, prob)),
        "model": model_info,
        "distribution": "posterior of the mean characteristic (stand reading noise excluded)",
        "tested_pressure_range_bar": [plo, phi],
        "tested_height_range_m": list(model.height_range_m),
    }
    if pressure_bar is not None:
        model.check_range(height_m, pressure_bar, "option --pressure-bar: ")
        P = model.force_draws(np.array(height_m), pressure_bar)
        res["force_at_pressure"] = {"pressure_bar": pressure_bar, "force_N": estimate(P),
                                    "prob_carries_load": float(np.mean(P >= load_N))}
        if tolerance_pct is not None:
            if not tolerance_pct > 0:
                raise InputError(f"option --tolerance-pct: expected a positive tolerance, got {tolerance_pct:g}")
            res["usable_stroke"] = usable_stroke(model, height_m, pressure_bar, load_N, tolerance_pct, prob)
    return res


def configure_margin(p) -> None:
    from ._cmd_common import add_json, add_recordings, add_sampling, positive_float, probability

    add_recordings(p, file_optional=True)
    add_sampling(p)
    add_json(p)
    p.add_argument("--height-mm", type=positive_float, help="height x of the element, mm")
    p.add_argument("--load-N", type=positive_float, help="load the element has to carry, N")
    p.add_argument("--prob", type=probability, default=0.95, help="probability of carrying at least the load (default 0.95)")
    p.add_argument("--pressure-bar", type=positive_float, help="also give the force band at this overpressure")
    p.add_argument("--tolerance-pct", type=positive_float,
                   help="with --pressure-bar: usable stroke where the force stays within this %% of the load")
    p.add_argument("--model", choices=MODEL_CHOICES, default=None,
                   help="which model answers: auto (default) fits the surface model and the per-pressure cubics and "
                        "takes the one PSIS-LOO prefers by more than 2 SE (the surface when indistinguishable); "
                        "surface or cubics skip the comparison")
    p.add_argument("--save-fit", metavar="FIT.nc",
                   help="after fitting, save the answering model's posterior draws to FIT.nc (NetCDF) for --fit")
    p.add_argument("--fit", metavar="FIT.nc",
                   help="answer from a saved fit (uq margin --save-fit, uq surface --out) instead of FILE.csv: no refit")
    p.add_argument("--queries", metavar="Q.csv",
                   help="many queries: a CSV with columns height_mm, load_N and optional prob, pressure_bar, "
                        "tolerance_pct (empty cells take the options' values); the JSON is a list, one result a row")
    from ._surface import add_stand

    add_stand(p)


QUERY_COLUMNS = ("height_mm", "load_N", "prob", "pressure_bar", "tolerance_pct")
_OPTION_OF = {"height_mm": "--height-mm", "load_N": "--load-N", "prob": "--prob", "pressure_bar": "--pressure-bar",
              "tolerance_pct": "--tolerance-pct"}
_COLUMN_OF = {v: k for k, v in _OPTION_OF.items()}


def _place(q: dict, column: str) -> str:
    """Where a query's value came from: ``option --x`` on the command line, or ``Q.csv, row N, column 'c'``."""
    from ._errors import where

    return f"option {_OPTION_OF[column]}" if q["row"] is None else where(q["file"], q["row"], column)


def _check_query(q: dict) -> None:
    """Values every query must have, checked before anything is read or fitted."""
    for col in ("height_mm", "load_N", "pressure_bar", "tolerance_pct"):
        v = q[col]
        if v is not None and not (np.isfinite(v) and v > 0):
            raise InputError(f"{_place(q, col)}: expected a positive number, got {v:g}")
    if not (np.isfinite(q["prob"]) and 0.0 < q["prob"] < 1.0):
        raise InputError(f"{_place(q, 'prob')}: expected a probability strictly between 0 and 1, got {q['prob']:g}")
    if q["tolerance_pct"] is not None and q["pressure_bar"] is None:
        raise InputError(f"{_place(q, 'tolerance_pct')}: needs --pressure-bar (the stroke is taken at one pressure)"
                         if q["row"] is None else
                         f"{_place(q, 'tolerance_pct')}: needs a pressure_bar on the row (the stroke is taken at one pressure)")


def read_queries(path: str, defaults: dict) -> list[dict]:
    """The rows of a queries CSV (header height_mm, load_N [, prob, pressure_bar, tolerance_pct]).

    Empty optional cells take ``defaults`` (the command-line options). Every defect is an
    InputError naming the file, the row (as an editor counts lines) and the column."""
    import csv

    from ._errors import where

    try:
        with open(path, newline="", encoding="utf-8-sig") as fh:
            lines = fh.read().splitlines()
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a UTF-8 text file (option --queries names a CSV file)") from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read: {exc.strerror or exc} (option --queries)") from None
    rows = [(i + 1, cells) for i, cells in enumerate(csv.reader(lines))
            if cells and any(c.strip() for c in cells) and not cells[0].lstrip().startswith("#")]
    if not rows:
        raise InputError(f"{path}: no header row (expected columns height_mm, load_N and optionally prob, pressure_bar, tolerance_pct)")
    head_row, header = rows[0]
    header = [h.strip() for h in header]
    for j, h in enumerate(header):
        if h not in QUERY_COLUMNS:
            raise InputError(f"{where(path, head_row, h or f'#{j + 1}')}: unknown column; expected height_mm, load_N "
                             "and optionally prob, pressure_bar, tolerance_pct")
        if header.count(h) > 1:
            raise InputError(f"{where(path, head_row, h)}: duplicated column")
    for need in ("height_mm", "load_N"):
        if need not in header:
            raise InputError(f"{path}: missing column '{need}' (expected height_mm, load_N and optionally prob, "
                             "pressure_bar, tolerance_pct)")
    if len(rows) == 1:
        raise InputError(f"{path}: no queries below the header row")
    out = []
    for row, cells in rows[1:]:
        if len(cells) != len(header):
            raise InputError(f"{where(path, row)}: {len(cells)} cells for {len(header)} columns")
        q = {"file": path, "row": row} | {c: defaults[c] for c in QUERY_COLUMNS}
        for col, text in zip(header, cells, strict=True):
            text = text.strip()
            if not text:
                if col in ("height_mm", "load_N"):
                    raise InputError(f"{where(path, row, col)}: empty; every query needs a height and a load")
                continue
            try:
                q[col] = float(text)
            except ValueError:
                raise InputError(f"{where(path, row, col)}: expected a number, got '{text}'") from None
        _check_query(q)
        out.append(q)
    return out


def _queries_from(args) -> list[dict]:
    """The queries of the command line (one, or the rows of --queries); checked before any work."""
    given = {c: getattr(args, c) for c in QUERY_COLUMNS}
    if args.queries:
        for c in ("height_mm", "load_N"):
            if given[c] is not None:
                raise InputError(f"option {_OPTION_OF[c]}: not with --queries (the queries file gives each row's {c})")
        return read_queries(args.queries, given)
    if given["height_mm"] is None and given["load_N"] is None and args.save_fit and args.json is None:
        return []  # only fit and save
    for c in ("height_mm", "load_N"):
        if given[c] is None:
            raise InputError(f"option {_OPTION_OF[c]}: required (or give the queries in a CSV with --queries)")
    q = {"file": None, "row": None} | given
    _check_query(q)
    return [q]


def _check_ranges(q: dict, height_range_m, pressure_range_bar, model_word: str = "the surface model") -> None:
    """Heights and pressures outside the tested ranges, refused before any fitting or answering (no extrapolation)."""
    lo, hi = height_range_m
    h = q["height_mm"] * 1e-3
    if not lo - 1e-9 <= h <= hi + 1e-9:
        raise InputError(f"{_place(q, 'height_mm')}: {q['height_mm']:g} mm is outside the tested heights {lo * 1e3:g}..{hi * 1e3:g} mm")
    plo, phi = pressure_range_bar
    if q["pressure_bar"] is not None and not plo - 1e-9 <= q["pressure_bar"] <= phi + 1e-9:
        raise InputError(f"{_place(q, 'pressure_bar')}: overpressure {q['pressure_bar']:g} bar is outside the tested pressures "
                         f"{plo:g}..{phi:g} bar; {model_word} does not extrapolate")


def answer_query(ans, info: dict, q: dict) -> dict:
    """One query's margin result; a refusal of a --queries row names the file, row and column."""
    try:
        return margin(ans, q["height_mm"] * 1e-3, q["load_N"], q["prob"], pressure_bar=q["pressure_bar"],
                      tolerance_pct=q["tolerance_pct"], model_info=info)
    except InputError as exc:
        text = str(exc)
        if q["row"] is None or not text.startswith("option --"):
            raise
        option, rest = text.split(":", 1)
        column = _COLUMN_OF.get(option.removeprefix("option ").strip(), "height_mm")
        raise InputError(f"{_place(q, column)}:{rest}") from None


def _check_usage(args) -> None:
    """Which sources and outputs go together; before anything is read."""
    from ._cmd_common import check_output_path

    if (args.file is None) == (args.fit is None):
        raise InputError("give exactly one of FILE.csv (fit the recordings) and --fit FIT.nc (answer from a saved fit)"
                         if args.file is None else
                         "option --fit: not with FILE.csv; give either the recordings (to fit) or a saved fit")
    if args.save_fit is not None:
        if args.fit is not None:
            raise InputError("option --save-fit: not with --fit (the saved fit is already saved); give FILE.csv to fit and save")
        if args.save_fit == "-":
            raise InputError("option --save-fit: needs a file name (NetCDF is not written to stdout)")
        check_output_path(args.save_fit, "--save-fit")
    if args.queries is not None and args.json is not None and args.json != "-":
        if Path(args.queries).resolve() == Path(args.json).resolve():
            raise InputError(f"option --json {args.json}: is the queries file; refusing to overwrite it")


def command_margin(args) -> int:
    from ._cmd_common import load
    from ._io import emit_json
    from ._surface import stand_from

    _check_usage(args)
    queries = _queries_from(args)  # checked before the fit, not after
    if args.fit is not None:
        ans, info, meta = load_answer(args.fit)
        if args.model not in (None, "auto") and _ANSWER_NAMES[ans.name] != args.model:
            raise InputError(f"option --model {args.model}: {args.fit} holds the {ans.label}; "
                             f"fit again with FILE.csv --model {args.model} --save-fit")
        for q in queries:
            _check_ranges(q, ans.height_range_m, ans.pressure_range_bar, "the model")
        diagnostics = {"warnings": meta["warnings"], "converged": meta["converged"]}
        source, rec = args.fit, None
    else:
        args.model = args.model or "auto"
        stand = stand_from(args)  # a bad --stand file or --walkers is refused before the recordings are read
        if args.model in ("auto", "surface"):
            from ._cmd_common import settings_from
            from ._surface import NOISE_NAMES

            settings_from(args).require_walkers(len(NOISE_NAMES))
        rec = load(args)
        tested = [t.pressure_bar for t in rec.tests]
        for q in queries:
            _check_ranges(q, rec.height_range_m, (min(tested), max(tested)))
        ans, info, diagnostics = _fit_and_choose(args, rec, stand)
        source = rec.path
    results = [answer_query(ans, info, q) for q in queries]  # every answer before anything is written
    if args.fit is not None:
        print(f"{source}: saved fit of {meta['recordings_path']} (sha256 {meta['recordings_sha256'][:12]}..., "
              f"seed {meta['seed']}, uq {meta['uq_version']}); no refit")
        _warn_if_recordings_changed(meta)
    if args.save_fit is not None:
        from ._cmd_common import settings_from

        save_answer(args.save_fit, ans, info, recordings=rec, seed=args.seed, written_by="uq margin --save-fit",
                    settings=settings_from(args), stand=stand, diagnostics=diagnostics)
        print(f"{source}: saved the {ans.label} to {args.save_fit} (answer later with uq margin --fit {args.save_fit})")
    if args.queries:
        _print_table(source, ans, info, queries, results)
    elif queries:
        _print_one(source, ans, info, queries[0], results[0])
    for w in diagnostics["warnings"]:
        print(f"  warning{' (from the saved fit)' if args.fit is not None else ''}: {w}")
    if queries or args.json is not None:
        emit_json(results if args.queries else results[0], args.json)
    return 1 if (getattr(args, "strict", False) and not diagnostics["converged"]) else 0


def _warn_if_recordings_changed(meta: dict) -> None:
    p = Path(meta["recordings_path"])
    if p.is_file() and sha256_of(p) != meta["recordings_sha256"]:
        print(f"  warning: {p} has changed since the fit was saved (sha256 differs); the answer is for the recordings "
              "as they were then")


def _print_one(source, ans, info, q, res) -> None:
    e = res["pressure_bar_needed"]
    print(f"{source}: {q['load_N']:g} N at {q['height_mm']:g} mm, answered by the {ans.label}")
    print(f"  why: {info['why']}")
    c = info.get("comparison")
    if c:
        print(f"  PSIS-LOO: surface {c['surface']['elpd_loo']:.1f} (max Pareto k {c['surface']['max_pareto_k']:.2f}), "
              f"cubics {c['cubics']['elpd_loo']:.1f} (max Pareto k {c['cubics']['max_pareto_k']:.2f}), "
              f"difference {c['elpd_diff']:.1f} +- {c['elpd_diff_se']:.1f}")
    print(f"  pressure needed: {e['mean']:.3f} bar (sd {e['sd']:.3f}; 90 % interval {e['q05']:.3f}..{e['q95']:.3f})")
    print(f"  carries at least the load with probability {q['prob']:g} from {res['pressure_bar_for_prob']:.3f} bar")
    if "force_at_pressure" in res:
        f = res["force_at_pressure"]["force_N"]
        print(f"  force at {q['pressure_bar']:g} bar: {f['mean']:.0f} N (90 % {f['q05']:.0f}..{f['q95']:.0f}), "
              f"P(force >= load) = {res['force_at_pressure']['prob_carries_load']:.3f}")
    if "usable_stroke" in res:
        s = res["usable_stroke"]
        c = s["stroke_credible"]
        if c:
            print(f"  usable stroke (within {q['tolerance_pct']:g} % with prob >= {q['prob']:g} at each height): "
                  f"{c['from_m'] * 1e3:.1f}..{c['to_m'] * 1e3:.1f} mm, whole range within with prob {c['prob_whole_range_within']:.3f}")
        else:
            print(f"  usable stroke: none; force within {q['tolerance_pct']:g} % at {q['height_mm']:g} mm with prob "
                  f"{s['prob_within_at_height']:.3f} < {q['prob']:g}")


def _print_table(source, ans, info, queries, results) -> None:
    print(f"{source}: {len(queries)} queries from {queries[0]['file']}, answered by the {ans.label}")
    print(f"  why: {info['why']}")
    print("   row  height_mm    load_N  prob  p_needed_bar (90 %)        p_for_prob  force at p_bar (90 %)      stroke_mm")
    for q, r in zip(queries, results, strict=True):
        e = r["pressure_bar_needed"]
        force = stroke = ""
        if "force_at_pressure" in r:
            f = r["force_at_pressure"]["force_N"]
            force = f"{f['mean']:.0f} ({f['q05']:.0f}..{f['q95']:.0f}) at {q['pressure_bar']:g}"
        if "usable_stroke" in r:
            c = r["usable_stroke"]["stroke_credible"]
            stroke = f"{c['from_m'] * 1e3:.1f}..{c['to_m'] * 1e3:.1f}" if c else "none"
        print(f"  {q['row']:>4}  {q['height_mm']:9g}  {q['load_N']:8g}  {q['prob']:4g}  "
              f"{e['mean']:6.3f} ({e['q05']:.3f}..{e['q95']:.3f})  {r['pressure_bar_for_prob']:10.3f}  {force:<25}  {stroke}".rstrip())


def _fit_and_choose(args, rec, stand):
    """Fit what ``--model`` needs; returns (answer, model description, merged sampler diagnostics)."""
    from ._cmd_common import settings_from
    from ._cubic import fit_campaign
    from ._surface import compare_with_cubics, fit_surface

    settings = settings_from(args)
    fit = cub = comparison = None
    warnings, converged = [], True
    if args.model in ("auto", "surface"):
        fit = fit_surface(rec, seed=args.seed, settings=settings, stand=stand)
        warnings += fit.diagnostics["warnings"]
        converged &= fit.diagnostics["converged"]
    if args.model in ("auto", "cubics"):
        cub = fit_campaign(rec, seed=args.seed, settings=settings)  # full settings: the cubics may answer
        warnings += [f"{t.pressure_bar:g} bar cubic: {w}" for t in cub.tests for w in t.diagnostics["warnings"]]
        converged &= cub.converged
    if args.model == "auto":
        comparison = compare_with_cubics(fit, cub, seed=args.seed, settings=settings)
    ans, info = choose_model(fit, cub, comparison, forced=args.model)
    return ans, info, {"warnings": warnings, "converged": bool(converged)}
