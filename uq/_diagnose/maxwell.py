"""Does the element obey the Maxwell relation dP/dp_u = dV/dx? Where it does not, and what that means.

A casing whose force and volume come from one potential G(x, p_u) (an elastic casing, or no
casing at all: the traditional theory) satisfies dP/dp_u (x fixed) = dV/dx (p_u fixed) at every
height and pressure (the thermodynamic view; uq/_models/thermo.py). Recordings that break it show
behaviour that is not conservative on the time scale of the test (relaxation, hysteresis, drift,
leakage) or a stand constant that is off (the piston area S turns travel into volume).

This module checks the relation test by test from the per-pressure cubics (eqs. 8, 9), with their
uncertainty, at every height band:

    r_i(x) = (dV/dx)_i / (dP/dp_u)_i - 1,   dV/dx = -S dL_i/dx,

dP/dp_u at test i from the quadratic through it and its neighbouring tests in pressure (exact for
a force quadratic in pressure; the ends use their two nearest neighbours). The coefficient draws
are the caller's: posterior draws of the cubics, or draws from a least-squares estimate and its
covariance (:func:`least_squares_draws`, also how Table 1 itself is judged with the covariance the
paper's procedure implies). r = 0 where the relation holds; a band breaks it when its mean is more
than ``Z_FLAG`` standard deviations from 0 (two-sided p < 0.001 for each of the T x bands checks).

What a pattern is consistent with, and what it is not (``interpret``). In the middle of the stroke
(the central height band, where both cubics' slopes are best known) and at its ends, each tested
pressure's level of r is read by its sign (dV/dx above, below or at dP/dp_u, at ``Z_FLAG`` sd), and
the levels are compared with four shapes over pressure by generalised least squares with their
joint covariance (``shapes``): levels whose dP/dp_u stencils share tests are correlated (on Table
1 those two tested pressures apart, down to -0.56), and treating them as independent misstates
every chi-square.
* zero fits: the relation holds.
* one value fits: a piston-area error (the recordings' S / (1 + r) is the area that makes it
  hold) or a volume excess at every pressure.
* neither: not a piston-area error alone, and the cause is not identified: a step between two
  tested pressures and a fade with pressure (a straight line in p_u) are compared and the better
  named, but a shape over pressure does not say which physics made it (relaxation, hysteresis,
  a drift, a stand constant that changed between tests all can). Where the levels above the step
  agree with one value, the piston area they imply is given with its assumption (the casing is
  conservative there).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.special import chdtr, chdtrc, gammaincinv

from uq._physics.cubic import cubic, cubic_slope
from uq._physics.quantities import BAR_PA

Z_FLAG = 3.29
N_BANDS = 5


def chi2_sf(x: float, dof: int) -> float:
    """``scipy.stats.chi2.sf(x, dof)`` by scipy.special's ``chdtrc``, the function scipy.stats
    evaluates (the same numbers, tested): scipy.stats costs about 1.5 CPU s to import, which
    ``uq diagnose`` otherwise does not need. 1 below the support, NaN for dof <= 0, as scipy.stats."""
    if not dof > 0:
        return math.nan
    return float(chdtrc(dof, x)) if not x < 0 else 1.0


def chi2_logsf(x: float, dof: int) -> float:
    """``scipy.stats.chi2.logsf(x, dof)`` as scipy.stats computes it: log of ``chdtrc`` above the
    median, log1p of minus ``chdtr`` below (tested against it)."""
    if not dof > 0:
        return math.nan
    if x < 0:
        return 0.0
    if x > 2.0 * gammaincinv(dof / 2.0, 0.5):
        with np.errstate(divide="ignore"):
            return float(np.log(chdtrc(dof, x)))
    return float(np.log1p(-chdtr(dof, x)))


def least_squares_draws(u_m, y, n_draws: int, rng) -> np.ndarray:
    """Draws (n_draws, 4) of a cubic's paper-basis coefficients from its ordinary least-squares
    estimate and covariance s^2 (X^T X)^-1 (s^2 the residual variance, n - 4 degrees of freedom)."""
    X = np.vander(np.asarray(u_m, float), 4, increasing=True)
    coef, *_ = np.linalg.lstsq(X, y, rcond=None)
    res = y - X @ coef
    s2 = float(res @ res) / max(y.size - 4, 1)
    return rng.multivariate_normal(coef, s2 * np.linalg.inv(X.T @ X), n_draws)


def _neighbours(p: np.ndarray, i: int) -> np.ndarray:
    T = p.size
    if T < 3:
        return np.arange(T)
    lo = min(max(i - 1, 0), T - 3)
    return np.arange(lo, lo + 3)


def _derivative_weights(p: np.ndarray, at: float) -> np.ndarray:
    """Weights w_j with sum_j w_j f(p_j) = f'(at) for the interpolating polynomial through p."""
    w = np.zeros(p.size)
    for j in range(p.size):
        others = np.delete(p, j)
        denom = np.prod(p[j] - others)
        # d/dp of prod_k (p - p_k), k != j, at ``at``
        w[j] = sum(np.prod(at - np.delete(others, k)) for k in range(others.size)) / denom
    return w


def ratio_draws(p_bar, force, piston, area_m2: float, x0_m: float, heights_m) -> np.ndarray:
    """r = (dV/dx) / (dP/dp_u) - 1 draws, (T, N, H): ``force``, ``piston`` (T, N, 4) paper-basis
    coefficient draws of each test (draw n of every test forms joint draw n)."""
    p = np.asarray(p_bar, float)
    u = np.asarray(heights_m, float) - x0_m
    P = cubic(np.asarray(force)[..., None, :], u)  # (T, N, H)
    dVdx = -area_m2 * cubic_slope(np.asarray(piston)[..., None, :], u)
    out = np.empty_like(P)
    for i in range(p.size):
        nb = _neighbours(p, i)
        w = _derivative_weights(p[nb], p[i]) / BAR_PA  # per Pa
        dPdp = np.tensordot(w, P[nb], axes=(0, 0))
        out[i] = dVdx[i] / dPdp - 1.0
    return out


def table(p_bar, force, piston, area_m2: float, x0_m: float, height_range_m, n_bands=N_BANDS):
    """The Maxwell residual r by test and height band: mean, sd, q05, q95 and whether the band
    breaks the relation (|mean| > Z_FLAG sd), and what the pattern over pressure is and is not
    consistent with (:func:`interpret`, on the joint draws). Returns {"rows": [...], "rule": ...,
    "interpretation": ...}."""
    lo, hi = height_range_m
    edges = np.linspace(lo, hi, n_bands + 1)
    grid = np.linspace(lo, hi, 8 * n_bands + 1)
    r = ratio_draws(p_bar, force, piston, area_m2, x0_m, grid)
    bands = np.stack(
        [r[:, :, (grid >= edges[b]) & (grid <= edges[b + 1])].mean(axis=2) for b in range(n_bands)],
        axis=-1,
    )  # (T, N, B): draw n of every test and band is one joint draw
    rows = []
    for i, p in enumerate(np.asarray(p_bar, float)):
        for b in range(n_bands):
            band = bands[i, :, b]
            m, sd = float(band.mean()), float(band.std(ddof=1))
            q05, q95 = (float(v) for v in np.quantile(band, [0.05, 0.95]))
            rows.append(
                {
                    "pressure_bar": float(p),
                    "height_mm": [round(edges[b] * 1e3, 2), round(edges[b + 1] * 1e3, 2)],
                    "r": {"mean": m, "sd": sd, "q05": q05, "q95": q95},
                    "breaks": bool(abs(m) > Z_FLAG * sd),
                }
            )
    return {
        "rows": rows,
        "definition": "r = (dV/dx) / (dP/dp_u) - 1 with dV/dx = -S dL/dx of each test's cubic and "
        "dP/dp_u from the quadratic in pressure through the test and its neighbours; 0 where the "
        "Maxwell relation holds",
        "rule": f"a band breaks the relation when |mean r| > {Z_FLAG:g} sd (two-sided p < 0.001)",
        "shape_rule": SHAPE_RULE,
        "interpretation": interpret(rows, bands, area_m2),
    }


#: a shape of r over pressure fits when its chi-square (the levels' joint covariance) has p above this
P_SHAPE = 1e-3
SHAPE_RULE = (
    "the pressure levels of r (mean over the region's height bands) are compared with four shapes by "
    "generalised least squares with their joint covariance from the draws (levels whose dP/dp_u "
    "stencils share tests are correlated): zero (the relation holds), one "
    "common value (a piston-area error alone, or a volume excess at every pressure), a step between "
    "two tested pressures (its place chosen by the fit; the p-value Bonferroni-adjusted over the "
    "places) and a straight line in p_u (a fade with pressure); a shape fits when its chi-square has "
    f"p > {P_SHAPE:g}. Each level's sign is read at {Z_FLAG:g} sd"
)


def interpret(rows: list[dict], band_draws: np.ndarray, area_m2: float) -> dict:
    """Which pressures break the relation, in the middle of the stroke (the central height band,
    where both cubics' slopes are best known) and at its ends (the first and last bands, where
    they are least certain), and what each region's pattern over pressure is and is not
    consistent with (:func:`_pattern`); the bands between are in the table. ``band_draws`` (T, N,
    B): the joint draws of r by test and height band, in the order of ``rows``' bands."""
    bands = sorted({tuple(r["height_mm"]) for r in rows})
    B = len(bands)
    regions = {
        # the central band (two for an even count): where both cubics' slopes are best known
        "middle": sorted({(B - 1) // 2, B // 2}),
        "ends": [0, B - 1] if B > 2 else [],
    }
    out = {}
    for region, idx in regions.items():
        if idx:
            sel = [r for r in rows if bands.index(tuple(r["height_mm"])) in idx]
            out[region] = _pattern(sel, band_draws[:, :, idx].mean(axis=2), region, area_m2)
    words = out["middle"]["words"]
    if "ends" in out and out["ends"]["breaks_at_bar"]:
        lo, hi = bands[0], bands[-1]
        words += (
            f"; at the ends of the stroke ({lo[0]:g}-{lo[1]:g} and {hi[0]:g}-{hi[1]:g} mm) it "
            f"breaks at {_list(out['ends']['breaks_at_bar'])} bar ({out['ends']['pattern']})"
        )
    out["words"] = words
    return out


def _gls(mean: np.ndarray, W: np.ndarray, X: np.ndarray):
    """Generalised least squares of ``mean`` on the columns of ``X`` with precision ``W``:
    (coefficients, their covariance, chi-square)."""
    A = X.T @ W @ X
    cov = np.linalg.inv(A)
    coef = cov @ X.T @ W @ mean
    res = mean - X @ coef
    return coef, cov, float(res @ W @ res)


def shapes(pressures, mean, cov) -> dict:
    """The four shapes of r over pressure (``SHAPE_RULE``) fitted to the levels ``mean`` (T,) with
    their joint covariance ``cov`` (T, T): each one's chi-square, degrees of freedom, p-value,
    whether it fits, and its coefficients."""
    p = np.asarray(pressures, float)
    T = p.size
    W = np.linalg.inv(cov)
    one = np.ones((T, 1))
    zero_chi2 = float(mean @ W @ mean)
    out = {"zero": {"chi2": zero_chi2, "dof": T, "p": float(chi2_sf(zero_chi2, T))}}
    c, c_cov, c_chi2 = _gls(mean, W, one)
    out["constant"] = {
        "chi2": c_chi2,
        "dof": T - 1,
        "p": float(chi2_sf(c_chi2, T - 1)),
        "value": float(c[0]),
        "sd": float(np.sqrt(c_cov[0, 0])),
    }
    if T >= 3:
        best = None
        for k in range(1, T):
            X = np.column_stack([np.arange(T) < k, np.arange(T) >= k]).astype(float)
            coef, ccov, x2 = _gls(mean, W, X)
            if best is None or x2 < best[2]:
                best = (k, coef, x2, ccov)
        k, coef, x2, ccov = best
        out["step"] = {
            "chi2": x2,
            "dof": T - 2,
            "p": float(min(1.0, (T - 1) * chi2_sf(x2, T - 2))),  # Bonferroni over the places
            "between_bar": [float(p[k - 1]), float(p[k])],
            "below": float(coef[0]),
            "above": float(coef[1]),
            "above_sd": float(np.sqrt(ccov[1, 1])),
        }
        coef, _, x2 = _gls(mean, W, np.column_stack([np.ones(T), p]))
        out["fade"] = {
            "chi2": x2,
            "dof": T - 2,
            "p": float(chi2_sf(x2, T - 2)),
            "at_lowest": float(coef[0] + coef[1] * p[0]),
            "at_highest": float(coef[0] + coef[1] * p[-1]),
            "slope_per_bar": float(coef[1]),
        }
    for v in out.values():
        v["fits"] = bool(v["p"] > P_SHAPE)
    return out


def piston_area_reading(area_m2: float, r_mean: float, r_sd: float) -> dict:
    """The piston area a common Maxwell residual r implies: with the right area S' the relation
    holds, -S' dL/dx = dP/dp_u, so S' = S / (1 + r); mean and sd (delta method), m^2."""
    return {
        "mean": float(area_m2 / (1.0 + r_mean)),
        "sd": float(area_m2 * r_sd / (1.0 + r_mean) ** 2),
        "given": float(area_m2),
    }


def _upper_reading(pressures, mean, cov, from_bar: float, area_m2: float) -> dict | None:
    """The piston area the levels at and above ``from_bar`` imply if the casing is conservative
    there (:func:`piston_area_reading` of their common value, by GLS with their own covariance),
    or None when one value does not fit them (then no single area makes the relation hold there)."""
    sel = np.asarray(pressures) >= from_bar
    if sel.sum() < 2:
        return None
    W = np.linalg.inv(cov[np.ix_(sel, sel)])
    c, c_cov, x2 = _gls(mean[sel], W, np.ones((int(sel.sum()), 1)))
    dof = int(sel.sum()) - 1
    if not chi2_sf(x2, dof) > P_SHAPE:
        return None
    upper = [float(p) for p in np.asarray(pressures)[sel]]
    return piston_area_reading(area_m2, float(c[0]), float(np.sqrt(c_cov[0, 0]))) | {
        "pressures_bar": upper,
        "chi2": x2,
        "dof": dof,
        "assumes": f"the casing is conservative at {_list(upper)} bar: the relation's residual "
        "there is a piston-area error alone",
    }


def _signs(pressures, mean, sd) -> dict:
    """Each pressure level by the sign of r at Z_FLAG sd: dV/dx above, below or at dP/dp_u."""
    z = mean / sd
    return {
        "exceeds_at_bar": [float(p) for p, v in zip(pressures, z, strict=True) if v > Z_FLAG],
        "short_at_bar": [float(p) for p, v in zip(pressures, z, strict=True) if v < -Z_FLAG],
        "agrees_at_bar": [float(p) for p, v in zip(pressures, z, strict=True) if abs(v) <= Z_FLAG],
    }


def _sign_words(signs: dict, pressures, mean) -> str:
    level = dict(zip((float(p) for p in pressures), mean, strict=True))

    def span(ps):
        vals = [level[p] for p in ps]
        return f"{_list(ps)} bar ({min(vals):+.1%}" + (
            f"..{max(vals):+.1%})" if len(vals) > 1 else ")"
        )

    parts = []
    if signs["exceeds_at_bar"]:
        parts.append(f"dV/dx exceeds dP/dp_u at {span(signs['exceeds_at_bar'])}")
    if signs["short_at_bar"]:
        parts.append(f"falls short of it at {span(signs['short_at_bar'])}")
    if signs["agrees_at_bar"]:
        parts.append(f"agrees within {Z_FLAG:g} sd at {_list(signs['agrees_at_bar'])} bar")
    return ", ".join(parts)


def _pattern(rows: list[dict], levels: np.ndarray, region: str, area_m2: float) -> dict:
    """The region's pressure levels of r (``levels`` (T, N): joint draws of each test's mean over
    the region's bands), their signs, and which shape over pressure they follow (:func:`shapes`):
    "holds", "every pressure alike" (a piston-area error alone fits), or "not a piston-area error
    alone" with the shapes compared and the cause left open."""
    pressures = np.array(sorted({r["pressure_bar"] for r in rows}))
    breaks = sorted({float(r["pressure_bar"]) for r in rows if r["breaks"]})
    holds = [float(p) for p in pressures if p not in breaks]
    mean = levels.mean(axis=1)
    cov = np.atleast_2d(np.cov(levels))
    sd = np.sqrt(np.diag(cov))
    corr = cov / np.outer(sd, sd)
    out = {
        "holds_at_bar": holds,
        "breaks_at_bar": breaks,
        "mean_r_by_pressure": {f"{p:g}": float(v) for p, v in zip(pressures, mean, strict=True)},
        "sd_r_by_pressure": {f"{p:g}": float(v) for p, v in zip(pressures, sd, strict=True)},
        "most_negative_correlation": float(corr[np.triu_indices(pressures.size, 1)].min())
        if pressures.size > 1
        else None,
        **_signs(pressures, mean, sd),
    }
    where = "in the middle of the stroke" if region == "middle" else "at the ends of the stroke"
    if pressures.size < 2:
        out["pattern"] = "holds" if not breaks else "no single reading"
        out["words"] = f"{where} one tested pressure: no pattern over pressure to read"
        return out
    sh = shapes(pressures, mean, cov)
    out["shapes"] = sh
    signs = _sign_words(out, pressures, mean)
    c = sh["constant"]
    if not breaks and sh["zero"]["fits"]:
        out["pattern"] = "holds"
        out["piston_area_m2"] = piston_area_reading(area_m2, c["value"], c["sd"])
        out["words"] = f"{where} the recordings obey the Maxwell relation at every tested pressure"
        return out
    if c["fits"]:
        out["pattern"] = "every pressure alike"
        out["piston_area_m2"] = piston_area_reading(area_m2, c["value"], c["sd"])
        a = out["piston_area_m2"]
        out["words"] = (
            f"{where} the relation breaks by about the same factor ({c['value']:+.1%}) at every "
            f"pressure (one value fits: chi2 {c['chi2']:.1f} on {c['dof']} dof): consistent with a "
            f"piston area off by that factor, S / (1 + r) = {a['mean'] * 1e4:.2f} +- "
            f"{a['sd'] * 1e4:.2f} cm^2 instead of the {area_m2 * 1e4:.2f} given, or a volume excess "
            "at every pressure"
        )
        return out
    out["pattern"] = "not a piston-area error alone"
    words = (
        f"{where} {signs}: not a piston-area error alone (one value at every pressure is refuted: "
        f"chi2 {c['chi2']:.0f} on {c['dof']} dof, with the levels' joint covariance)"
    )
    if "step" in sh:
        st, fa = sh["step"], sh["fade"]
        step = f"a step between {st['between_bar'][0]:g} and {st['between_bar'][1]:g} bar ({st['below']:+.1%} below, {st['above']:+.1%} above; chi2 {st['chi2']:.0f} on {st['dof']})"
        fade = f"a fade with pressure (a straight line in p_u, {fa['at_lowest']:+.1%} at {pressures[0]:g} bar to {fa['at_highest']:+.1%} at {pressures[-1]:g}; chi2 {fa['chi2']:.0f} on {fa['dof']})"
        better, worse = (step, fade) if st["chi2"] <= fa["chi2"] else (fade, step)
        out["best_shape"] = "step" if st["chi2"] <= fa["chi2"] else "fade"
        fitting = [n for n in ("step", "fade") if sh[n]["fits"]]
        fit_words = (
            "neither fits within the noise"
            if not fitting
            else (
                "both fit within the noise"
                if len(fitting) == 2
                else f"only the {fitting[0]} fits within the noise"
            )
        )
        words += f"; cause not identified: {better} fits better than {worse}, and {fit_words}"
        if region == "middle" and out["best_shape"] == "step":
            reading = _upper_reading(pressures, mean, cov, st["between_bar"][1], area_m2)
            if reading is not None:
                out["piston_area_m2"] = reading
                a = reading
                words += (
                    f"; if the casing is conservative at {_list(a['pressures_bar'])} bar (one value "
                    f"fits there: chi2 {a['chi2']:.1f} on {a['dof']} dof), the relation there implies a "
                    f"piston area S / (1 + r) = {a['mean'] * 1e4:.2f} +- {a['sd'] * 1e4:.2f} cm^2 "
                    f"(given {area_m2 * 1e4:.2f})"
                )
    else:
        words += "; cause not identified"
    out["words"] = words
    return out


def _list(values) -> str:
    return ", ".join(f"{v:g}" for v in values)


def campaign_table(rec, *, n_draws: int = 2000, seed: int = 0) -> dict | None:
    """The Maxwell table of a campaign from each test's least-squares cubics and their covariance
    (None without piston readings or with fewer than three tests)."""
    if not rec.has_piston or len(rec.tests) < 3:
        return None
    rng = np.random.default_rng(seed)
    force, piston = [], []
    for t in rec.tests:
        u = t.height_m - rec.x0_m
        force.append(least_squares_draws(u, t.force_N, n_draws, rng))
        piston.append(least_squares_draws(u, t.piston_m, n_draws, rng))
    return table(
        rec.pressures_bar,
        np.stack(force),
        np.stack(piston),
        rec.piston_area_m2,
        rec.x0_m,
        rec.height_range_m,
    ) | {"coefficients": "least-squares cubics of each test and their covariance (n - 4 dof)"}
