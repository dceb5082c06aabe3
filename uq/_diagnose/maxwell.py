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

What a pattern is consistent with, and what it is not (``interpret``):
* r the same (and non-zero) at every pressure: a piston-area error (S off by the factor 1 + r),
  or a volume excess at every pressure; not relaxation, which fades with pressure.
* r non-zero at the low pressures only, fading towards the high ones: a casing that is not
  conservative where its own force is a large share of the total (relaxation of the rubber-cord
  composite, as the paper reports at low overpressures); not a piston-area error, which would
  scale every pressure alike.
* otherwise the tests and bands that break it are listed without a reading.
"""

from __future__ import annotations

import numpy as np
from scipy.stats import chi2

from uq._physics.cubic import cubic, cubic_slope
from uq._physics.quantities import BAR_PA

Z_FLAG = 3.29
N_BANDS = 5


def least_squares_draws(u_m, y, n_draws: int, rng, coef=None, cov=None) -> np.ndarray:
    """Draws (n_draws, 4) of a cubic's paper-basis coefficients from its ordinary least-squares
    estimate and covariance s^2 (X^T X)^-1 (s^2 the residual variance, n - 4 degrees of freedom),
    or from the given ``coef`` and ``cov``."""
    if coef is None:
        X = np.vander(np.asarray(u_m, float), 4, increasing=True)
        coef, *_ = np.linalg.lstsq(X, y, rcond=None)
        res = y - X @ coef
        s2 = float(res @ res) / max(y.size - 4, 1)
        cov = s2 * np.linalg.inv(X.T @ X)
    return rng.multivariate_normal(np.asarray(coef, float), np.asarray(cov, float), n_draws)


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
    breaks the relation (|mean| > Z_FLAG sd). Returns {"rows": [...], "rule": ..., "summary": ...}."""
    lo, hi = height_range_m
    edges = np.linspace(lo, hi, n_bands + 1)
    grid = np.linspace(lo, hi, 8 * n_bands + 1)
    r = ratio_draws(p_bar, force, piston, area_m2, x0_m, grid)
    rows = []
    for i, p in enumerate(np.asarray(p_bar, float)):
        for b in range(n_bands):
            sel = (grid >= edges[b]) & (grid <= edges[b + 1])
            band = r[i][:, sel].mean(axis=1)
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
        "interpretation": interpret(rows),
    }


def interpret(rows: list[dict]) -> dict:
    """Which pressures break the relation, in the middle of the stroke and at its ends (the first
    and last height bands, where a cubic's slope is least certain), and what the middle's pattern
    is and is not consistent with."""
    bands = sorted({tuple(r["height_mm"]) for r in rows})
    ends = {bands[0], bands[-1]} if len(bands) > 2 else set()
    out = {}
    for region, keep in (("middle", lambda b: b not in ends), ("ends", lambda b: b in ends)):
        sel = [r for r in rows if keep(tuple(r["height_mm"]))]
        if sel:
            out[region] = _pattern(sel, region)
    words = out["middle"]["words"]
    if "ends" in out and out["ends"]["breaks_at_bar"]:
        words += (
            f"; at the ends of the stroke ({bands[0][0]:g}-{bands[0][1]:g} and {bands[-1][0]:g}-"
            f"{bands[-1][1]:g} mm) it breaks at {_list(out['ends']['breaks_at_bar'])} bar "
            f"({out['ends']['pattern']})"
        )
    out["words"] = words
    return out


def _pattern(rows: list[dict], region: str) -> dict:
    """The region's pressure-level residuals (mean r over its bands, with sd) and their pattern:
    the same at every pressure (a chi-square test of one common value), or falling with pressure
    (a weighted straight line in p_u whose slope is negative beyond ``Z_FLAG`` sd), or neither."""
    by_p: dict[float, list] = {}
    for row in rows:
        by_p.setdefault(row["pressure_bar"], []).append(row)
    pressures = np.array(sorted(by_p))
    breaks = [float(p) for p in pressures if any(r["breaks"] for r in by_p[p])]
    holds = [float(p) for p in pressures if p not in breaks]
    level = np.array([np.mean([r["r"]["mean"] for r in by_p[p]]) for p in pressures])
    sd = np.array([np.sqrt(np.mean([r["r"]["sd"] ** 2 for r in by_p[p]])) for p in pressures])
    out = {
        "holds_at_bar": holds,
        "breaks_at_bar": breaks,
        "mean_r_by_pressure": {f"{p:g}": float(v) for p, v in zip(pressures, level, strict=True)},
    }
    where = "in the middle of the stroke" if region == "middle" else "at the ends of the stroke"
    if not breaks:
        out["pattern"] = "holds"
        out["words"] = f"{where} the recordings obey the Maxwell relation at every tested pressure"
        return out

    w = 1.0 / sd**2
    common = float(np.sum(w * level) / np.sum(w))
    same = chi2.sf(float(np.sum(w * (level - common) ** 2)), pressures.size - 1) > 1e-3
    X = np.column_stack([np.ones_like(pressures), pressures])
    cov = np.linalg.inv(X.T @ (w[:, None] * X))
    slope_coef = cov @ X.T @ (w * level)
    z_slope = float(slope_coef[1] / np.sqrt(cov[1, 1]))
    run = 0  # the low pressures where dV/dx exceeds dP/dp_u: the first run of positive levels
    while run < pressures.size and level[run] > 0:
        run += 1
    positive_low = [float(p) for p in pressures[:run] if p in breaks]
    if same:
        out["pattern"] = "every pressure alike"
        out["words"] = (
            f"{where} the relation breaks by about the same factor ({common:+.1%}) at every pressure: "
            "consistent with a piston area off by that factor (the recordings' S / (1 + r)) or a volume "
            "excess at every pressure; not consistent with relaxation, which fades with pressure"
        )
    elif z_slope < -Z_FLAG and positive_low:
        rng_low = [v for p, v in zip(pressures, level, strict=True) if p in positive_low]
        high = [float(p) for p in pressures if p > max(positive_low)]
        out["pattern"] = "fades with pressure"
        out["words"] = (
            f"{where} dV/dx exceeds dP/dp_u at the low pressures ({_list(positive_low)} bar: "
            f"{min(rng_low):+.1%}..{max(rng_low):+.1%}) and the excess fades with pressure"
            + (
                f" (to {np.mean(level[pressures > max(positive_low)]):+.1%} on average at {_list(high)} bar)"
                if high
                else ""
            )
            + ": consistent with a casing that is not conservative where its own force is a large "
            "share of the total (relaxation of the rubber-cord composite, which the paper reports at "
            "low overpressures); not consistent with a piston-area error, which would break it by the "
            "same factor at every pressure"
        )
    else:
        out["pattern"] = "no single reading"
        out["words"] = (
            f"{where} the relation breaks at {_list(breaks)} bar"
            + (f" and holds at {_list(holds)} bar" if holds else "")
            + "; the pattern matches neither a piston-area error (the same factor everywhere) nor "
            "relaxation fading with pressure"
        )
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
