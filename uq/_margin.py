"""Design-margin queries on the surface model (``uq margin``, CONTRACT.md section 3).

All probabilities are over the posterior of the element's *mean* characteristic (the
surface model without the stand's reading noise): the load cell's and the pressure
holding's scatter belong to the stand, not to the element that has to carry the load in
service, so they must not widen a design margin. ``pressure_bar_for_prob`` is then exact:
the force grows with pressure at a fixed height, so "the element carries at least W at p"
holds for a posterior draw iff p >= that draw's required pressure, and the smallest p with
probability ``prob`` is the ``prob`` quantile of ``pressure_bar_needed``.
"""

from __future__ import annotations

import numpy as np

from ._errors import InputError
from ._summary import band, estimate
from ._surface import SurfaceFit

N_P_GRID = 801


def pressure_needed(fit: SurfaceFit, height_m: float, load_N: float, *, beta=None) -> np.ndarray:
    """Posterior draws of the overpressure (bar) at which the element carries ``load_N``."""
    fit.check_range(height_m, fit.pressure_range_bar[0], "option --height-mm: ")
    plo, phi = fit.pressure_range_bar
    ps = np.linspace(plo, phi, N_P_GRID)
    P = fit.force_draws(np.full_like(ps, height_m), ps, beta=beta)  # (S, G)
    if np.any(np.diff(P, axis=1) < 0):
        frac = float(np.mean(np.any(np.diff(P, axis=1) < 0, axis=1)))
        if frac > 0.01:
            raise InputError(f"option --height-mm: at {height_m * 1e3:g} mm the force does not rise with pressure in "
                             f"{100 * frac:.0f} % of the posterior draws; no unique required pressure")
    lo_load, hi_load = band(P[:, 0])[2], band(P[:, -1])[1]
    if not lo_load <= load_N <= hi_load:
        raise InputError(
            f"option --load-N: {load_N:g} N at {height_m * 1e3:g} mm is outside what the tested pressures "
            f"{plo:g}..{phi:g} bar support there (about {lo_load:.0f}..{hi_load:.0f} N); the surface model does not extrapolate")
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


def usable_stroke(fit: SurfaceFit, height_m: float, pressure_bar: float, target_N: float, tolerance_pct: float,
                  prob: float, *, beta=None, n_x: int = 361) -> dict:
    """Height range around ``height_m`` over which the force at ``pressure_bar`` stays within tolerance."""
    lo, hi = fit.height_range_m
    xs = np.linspace(lo, hi, n_x)
    P = fit.force_draws(xs, pressure_bar, beta=beta)  # (S, n_x)
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


def margin(fit: SurfaceFit, height_m: float, load_N: float, prob: float = 0.95, *, pressure_bar: float | None = None,
           tolerance_pct: float | None = None) -> dict:
    if not 0.0 < prob < 1.0:
        raise InputError(f"option --prob: expected a probability between 0 and 1, got {prob:g}")
    if not load_N > 0:
        raise InputError(f"option --load-N: expected a positive load in N, got {load_N:g}")
    beta = fit.flat_beta(4000)
    need = pressure_needed(fit, height_m, load_N, beta=beta)
    est = _finite_estimate(need)
    p_for = float(np.quantile(need, prob))
    plo, phi = fit.pressure_range_bar
    res = {
        "height_m": height_m, "load_N": load_N, "prob": prob,
        "pressure_bar_needed": est,
        "pressure_bar_for_prob": p_for,
        "distribution": "posterior of the mean characteristic (stand reading noise excluded)",
        "tested_pressure_range_bar": [plo, phi],
        "tested_height_range_m": list(fit.height_range_m),
        "surface_orders": fit.orders.label,
    }
    if pressure_bar is not None:
        fit.check_range(height_m, pressure_bar, "option --pressure-bar: ")
        res["force_at_pressure"] = {"pressure_bar": pressure_bar,
                                    "force_N": estimate(fit.force_draws(np.array(height_m), pressure_bar, beta=beta)),
                                    "prob_carries_load": float(np.mean(fit.force_draws(np.array(height_m), pressure_bar, beta=beta) >= load_N))}
        if tolerance_pct is not None:
            if not tolerance_pct > 0:
                raise InputError(f"option --tolerance-pct: expected a positive tolerance, got {tolerance_pct:g}")
            res["usable_stroke"] = usable_stroke(fit, height_m, pressure_bar, load_N, tolerance_pct, prob, beta=beta)
    elif tolerance_pct is not None:
        raise InputError("option --tolerance-pct: needs --pressure-bar (the stroke is taken at one pressure)")
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


def command_margin(args) -> int:
    from ._cmd_common import load, settings_from
    from ._io import emit_json
    from ._surface import fit_surface

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
    fit = fit_surface(rec, seed=args.seed, settings=settings_from(args))
    res = margin(fit, h, args.load_N, args.prob, pressure_bar=args.pressure_bar, tolerance_pct=args.tolerance_pct)
    e = res["pressure_bar_needed"]
    print(f"{rec.path}: {args.load_N:g} N at {args.height_mm:g} mm (surface model {fit.orders.label})")
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
    for w in fit.diagnostics["warnings"]:
        print(f"  warning: {w}")
    emit_json(res, args.json)
    return 1 if (getattr(args, "strict", False) and not fit.diagnostics["converged"]) else 0
