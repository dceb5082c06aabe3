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

import numpy as np

from ._errors import InputError
from ._recordings import BAR_PA
from ._summary import band, estimate
from ._surface import SurfaceFit

N_P_GRID = 801
N_CUBIC_DRAWS = 2000
MODEL_CHOICES = ("auto", "surface", "cubics")


class _Ranges:
    """Tested ranges of a campaign and the refusal to extrapolate, shared by both answers."""

    def __init__(self, recordings):
        p = recordings.pressures_bar
        self.pressure_range_bar = (float(p.min()), float(p.max()))
        self.height_range_m = recordings.height_range_m

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


class SurfaceAnswer(_Ranges):
    """The surface model's mean force on a fixed set of posterior draws."""

    name = "surface"

    def __init__(self, fit: SurfaceFit, max_draws: int = 4000):
        super().__init__(fit.recordings)
        self.fit, self.beta = fit, fit.flat_beta(max_draws)
        self.label = f"surface model ({fit.orders.label})"

    def force_draws(self, height_m, p_bar):
        return self.fit.force_draws(height_m, p_bar, check=False, beta=self.beta)


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


def usable_stroke(model, height_m: float, pressure_bar: float, target_N: float, tolerance_pct: float,
                  prob: float, *, n_x: int = 361) -> dict:
    """Height range around ``height_m`` over which the force at ``pressure_bar`` stays within tolerance."""
    model = as_answer(model)
    lo, hi = model.height_range_m
    xs = np.linspace(lo, hi, n_x)
    P = model.force_draws(xs, pressure_bar)  # (S, n_x)
    ok = np.abs(P - target_N) <= tolerance_pct / 100.0 * abs(target_N)
    j = int(np.argmin(np.abs(xs - height_m)))
    lengths, los, his = np.zeros(P.shape[0]), np.full(P.shape[0], np.nan), np.full(P.shape[0], np.nan)
    for s in range(P.shape[0]):
        if not ok[s, j]:
            continue
        a = j
        while a > 0 and ok[s, a - 1]:
            a -= 1
        b = j
        while b < n_x - 1 and ok[s, b + 1]:
            b += 1
        los[s], his[s], lengths[s] = xs[a], xs[b], xs[b] - xs[a]
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


COVERAGE_NOTE = ("surface coverage proven by simulation for truths inside the default orders' class "
                 "(reports/surface-coverage/coverage.json, tests/test_surface.py::test_slow_coverage)")


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
        ans = SurfaceAnswer(fit)
        info["orders"] = fit.orders.label
        if forced == "surface":
            info["why"] = "chosen by the user (--model surface); no comparison made"
        elif comparison is None:
            info["why"] = "surface model given; no comparison with the per-pressure cubics made"
        else:
            info["why"] = f"PSIS-LOO verdict '{comparison['better']}': {comparison['reason']}; the surface answers ({COVERAGE_NOTE})"
    return ans, {"name": ans.name, "label": ans.label, **info}


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

    add_recordings(p)
    add_sampling(p)
    add_json(p)
    p.add_argument("--height-mm", type=positive_float, required=True, help="height x of the element, mm")
    p.add_argument("--load-N", type=positive_float, required=True, help="load the element has to carry, N")
    p.add_argument("--prob", type=probability, default=0.95, help="probability of carrying at least the load (default 0.95)")
    p.add_argument("--pressure-bar", type=positive_float, help="also give the force band at this overpressure")
    p.add_argument("--tolerance-pct", type=positive_float,
                   help="with --pressure-bar: usable stroke where the force stays within this %% of the load")
    p.add_argument("--model", choices=MODEL_CHOICES, default="auto",
                   help="which model answers: auto (default) fits the surface model and the per-pressure cubics and "
                        "takes the one PSIS-LOO prefers by more than 2 SE (the surface when indistinguishable); "
                        "surface or cubics skip the comparison")
    from ._surface import add_stand

    add_stand(p)


def command_margin(args) -> int:
    from ._cmd_common import load
    from ._io import emit_json
    from ._surface import stand_from

    if args.tolerance_pct is not None and args.pressure_bar is None:  # checked before the fit, not after
        raise InputError("option --tolerance-pct: needs --pressure-bar (the stroke is taken at one pressure)")
    rec = load(args)
    h = args.height_mm * 1e-3
    lo, hi = rec.height_range_m
    if not lo - 1e-9 <= h <= hi + 1e-9:
        raise InputError(f"option --height-mm: {args.height_mm:g} mm is outside the tested heights {lo * 1e3:g}..{hi * 1e3:g} mm")
    tested = [t.pressure_bar for t in rec.tests]
    if args.pressure_bar is not None and not min(tested) - 1e-9 <= args.pressure_bar <= max(tested) + 1e-9:
        raise InputError(f"option --pressure-bar: overpressure {args.pressure_bar:g} bar is outside the tested pressures "
                         f"{min(tested):g}..{max(tested):g} bar; the surface model does not extrapolate")
    ans, info, diagnostics = _fit_and_choose(args, rec, stand_from(args))
    res = margin(ans, h, args.load_N, args.prob, pressure_bar=args.pressure_bar, tolerance_pct=args.tolerance_pct,
                 model_info=info)
    e = res["pressure_bar_needed"]
    print(f"{rec.path}: {args.load_N:g} N at {args.height_mm:g} mm, answered by the {ans.label}")
    print(f"  why: {info['why']}")
    c = info.get("comparison")
    if c:
        print(f"  PSIS-LOO: surface {c['surface']['elpd_loo']:.1f} (max Pareto k {c['surface']['max_pareto_k']:.2f}), "
              f"cubics {c['cubics']['elpd_loo']:.1f} (max Pareto k {c['cubics']['max_pareto_k']:.2f}), "
              f"difference {c['elpd_diff']:.1f} +- {c['elpd_diff_se']:.1f}")
    print(f"  pressure needed: {e['mean']:.3f} bar (sd {e['sd']:.3f}; 90 % interval {e['q05']:.3f}..{e['q95']:.3f})")
    print(f"  carries at least the load with probability {args.prob:g} from {res['pressure_bar_for_prob']:.3f} bar")
    if "force_at_pressure" in res:
        f = res["force_at_pressure"]["force_N"]
        print(f"  force at {args.pressure_bar:g} bar: {f['mean']:.0f} N (90 % {f['q05']:.0f}..{f['q95']:.0f}), "
              f"P(force >= load) = {res['force_at_pressure']['prob_carries_load']:.3f}")
    if "usable_stroke" in res:
        s = res["usable_stroke"]
        c = s["stroke_credible"]
        if c:
            print(f"  usable stroke (within {args.tolerance_pct:g} % with prob >= {args.prob:g} at each height): "
                  f"{c['from_m'] * 1e3:.1f}..{c['to_m'] * 1e3:.1f} mm, whole range within with prob {c['prob_whole_range_within']:.3f}")
        else:
            print(f"  usable stroke: none; force within {args.tolerance_pct:g} % at {args.height_mm:g} mm with prob "
                  f"{s['prob_within_at_height']:.3f} < {args.prob:g}")
    for w in diagnostics["warnings"]:
        print(f"  warning: {w}")
    emit_json(res, args.json)
    return 1 if (getattr(args, "strict", False) and not diagnostics["converged"]) else 0


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
