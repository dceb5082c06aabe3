"""Derived quantities of a campaign with credible bands (the paper's Figures 2-5 and section 5).

Pure numpy on posterior draws of the per-pressure cubics (``uq._models.cubic``). For every test, on
a common height grid x (m), u = x - x0:

* force P(x) (eq. 8): the 90 % band of the mean curve, and the posterior predictive band of a
  new reading (mean curve plus noise with the test's heteroscedastic sd
  sqrt(sigma0^2 + (rel |P(x)|)^2));
* piston coordinate L(x) (eq. 9), mean band and predictive band (sd sigma_L);
* volume increment dV(x) = S [L(x) - L(x_max)] (eq. 10), x_max the test's largest height;
* effective area from the force, F_eff(x) = P(x) / p_u (eq. 1, p_u in Pa);
* the traditional force characteristic p_u F_eff,V(x) with F_eff,V = -d dV/dx = -S dL/dx
  (eq. 1, second formula), (a) from the volume curve of one reference test (5 bar, as in the
  paper's Figure 5) and (b) from the test's own volume curve, and the spread traditional minus
  experimental, absolute (N) and relative (% of the experimental force).

Across tests: the paper's scatter of F_eff among the tests from 1 to 10 bar (all tests with
p_u >= 1 bar): half the range over the mean, at each height and for each joint draw.

Pointwise and simultaneous. Every band above is *pointwise*: at each height separately it holds
the curve's value with 90 % posterior probability, so the whole curve leaves it somewhere far
more often than 10 % of the time. For F_eff(x) and the spread (traditional minus experimental,
N and %) there is also a *simultaneous* band (:class:`SimultaneousBand`), which holds the
whole curve over the grid with the stated posterior probability: per draw i the largest
standardized deviation M_i = max_x |f_i(x) - mean(x)| / sd(x), c = the 90 % quantile of M,
band mean(x) +/- c sd(x) (the max-t band; c is about 1.6 for a pointwise 90 % band and 2-3 for
the curve as a whole). tests/derived/test_bands.py checks both promises: on posterior draws, and by
coverage of a known truth in simulation.

Tests are fitted independently, so a "joint draw" pairs the i-th subsampled draw of every test.
Everything is seeded. The core, :func:`bands_from_coefficients`, takes coefficient arrays, so
the same code runs on Table 1 itself (one "draw" per test) or on a posterior.
"""

from __future__ import annotations

import copy
import dataclasses
from dataclasses import dataclass, field
from types import SimpleNamespace

import numpy as np

from uq._inference.summary import band
from uq._inference.summary import estimate as _estimate
from uq._physics.cubic import cubic, cubic_slope
from uq._physics.quantities import BAR_PA, force_noise_var

LEVEL = 0.90
REFERENCE_BAR = 5.0  # the paper's Figure 5 uses the 5-bar volume curve
SCATTER_MIN_BAR = 1.0  # the paper's Figure 4 / scatter: tests from 1 to 10 bar
EXTRA_HEIGHT_M = 0.075  # Table 1 gives the paper's "8.51 % at x_min" at 75 mm


@dataclass(frozen=True, repr=False)
class Band:
    """Posterior mean and equal-tailed 90 % band on the grid (arrays of the grid's shape)."""

    mean: np.ndarray
    lo: np.ndarray
    hi: np.ndarray

    @classmethod
    def of(cls, draws: np.ndarray, level: float = LEVEL) -> Band:
        """The band of ``draws`` (D, ...) over its first axis (``uq._inference.summary.band``)."""
        return cls(*band(draws, axis=0, level=level))

    def contains(self, values) -> np.ndarray:
        v = np.asarray(values)
        return (self.lo <= v) & (v <= self.hi)

    def __repr__(self) -> str:
        return f"{type(self).__name__}({np.size(self.mean)} points)"


@dataclass(frozen=True, repr=False)
class SimultaneousBand(Band):
    """mean +/- critical sd: contains a whole draw curve (every grid height at once) for a
    ``level`` share of the draws it was built from. ``critical`` is the level-quantile of the
    draws' largest standardized deviation over the grid."""

    critical: float = 0.0
    level: float = LEVEL

    @classmethod
    def of(cls, draws: np.ndarray, level: float = LEVEL) -> SimultaneousBand:
        """draws (D, G) -> the max-t band; heights where any draw is not finite are left out (nan)."""
        d = np.asarray(draws, float)
        ok = np.all(np.isfinite(d), axis=0)
        m = np.where(ok, np.mean(np.where(ok, d, 0.0), axis=0), np.nan)
        sd = np.where(ok, np.std(np.where(ok, d, 0.0), axis=0), np.nan)
        dev = np.abs(d[:, ok] - m[ok])
        # sd = 0 where every draw agrees (dV at x_max): no deviation there, nothing to scale.
        z = np.divide(dev, sd[ok], out=np.zeros_like(dev), where=sd[ok] > 0)
        crit = float(np.quantile(z.max(axis=1), level)) if z.size else 0.0
        return cls(m, m - crit * sd, m + crit * sd, crit, level)

    def contains_curve(self, curves) -> np.ndarray:
        """curves (..., G) -> (...): True where the whole curve is inside (nan heights skipped)."""
        v = np.asarray(curves, float)
        ok = np.isfinite(self.mean)
        return np.all(((self.lo <= v) & (v <= self.hi))[..., ok], axis=-1)


#: Quantities that also get a simultaneous band, and their JSON names.
SIMULTANEOUS = {
    "feff": "feff_m2",
    "spread_own": "spread_own_N",
    "spread_ref": "spread_ref_N",
    "spread_own_pct": "spread_own_pct",
    "spread_ref_pct": "spread_ref_pct",
}
#: The quantities that need the test's own volume curve (None for a force-only test), and those
#: that need the reference test's (None when no test of the campaign has a volume curve).
OWN_VOLUME = (
    "piston",
    "piston_pred",
    "dV",
    "feff_volume",
    "trad_own",
    "spread_own",
    "spread_own_pct",
)
REF_VOLUME = ("trad_ref", "spread_ref", "spread_ref_pct")
FORCE_ONLY_WHY = "force-only (no piston_* or volume_* column)"
NO_VOLUME_WHY = "no test has a piston_* or volume_* column (force-only campaign)"


@dataclass(eq=False, frozen=True, repr=False)
class PressureBands:
    """Bands of one test on the campaign grid ``x_m`` (SI: N, m, m^3, m^2, %).

    A force-only test (no piston_* or volume_* column) has None for every ``OWN_VOLUME``
    quantity; when no test of the campaign has a volume curve, the ``REF_VOLUME`` ones are None
    too (``at_x0`` and ``simultaneous`` then lack them as well)."""

    pressure_bar: float
    x_max_m: float
    force: Band  # mean curve P(x), N
    force_pred: Band  # posterior predictive of a new reading, N
    feff: Band  # P / p_u, m^2
    piston: Band | None = None  # mean curve L(x), m
    piston_pred: Band | None = None  # predictive, m
    dV: Band | None = None  # volume increment S [L(x) - L(x_max)], m^3
    feff_volume: Band | None = None  # -S dL/dx from the own volume curve, m^2
    trad_own: Band | None = None  # p_u (-S dL/dx), own volume curve, N
    trad_ref: Band | None = None  # p_u (-S dL_ref/dx), reference test's volume curve, N
    spread_own: Band | None = None  # trad_own - P, N
    spread_own_pct: Band | None = None  # 100 (trad_own - P) / P, %
    spread_ref: Band | None = None  # trad_ref - P, N
    spread_ref_pct: Band | None = None  # 100 (trad_ref - P) / P, %
    at_x0: dict = field(default_factory=dict)  # name -> {"mean","sd","q05","q95"} at x0
    simultaneous: dict = field(default_factory=dict)  # name in SIMULTANEOUS -> SimultaneousBand

    @property
    def has_volume(self) -> bool:
        """The test has its own volume curve (piston_* or volume_* column)."""
        return self.dV is not None

    def __repr__(self) -> str:
        return f"PressureBands({self.pressure_bar:g} bar, {self.force.mean.size} heights)"


@dataclass(eq=False, frozen=True, repr=False)
class CampaignBands:
    x_m: np.ndarray  # (G,) height grid
    x0_m: float
    piston_area_m2: float
    tests: list[PressureBands]
    #: pressure of the test whose volume curve gives the traditional force (None: no test has one)
    reference_bar: float | None
    reference_note: str  # how the reference test was chosen, or why there is none
    scatter_pressures_bar: list[float]  # tests entering the F_eff scatter
    scatter: Band | None  # half range / mean of F_eff across those tests, % (None if < 2 tests)
    scatter_at: dict  # label -> {"height_m", "mean", "sd", "q05", "q95"} (%)
    n_draws: int
    seed: int

    def at(self, pressure_bar: float) -> PressureBands:
        for t in self.tests:
            if abs(t.pressure_bar - pressure_bar) < 1e-9:
                return t
        raise KeyError(pressure_bar)

    def summary(self):
        """The values at x0 of every test (mean, sd, q05, q95 of each banded quantity), a pandas
        DataFrame indexed by (pressure, quantity)."""
        import pandas as pd  # reason: optional and heavy, loaded only where used

        rows = {(t.pressure_bar, name): est for t in self.tests for name, est in t.at_x0.items()}
        return pd.DataFrame.from_dict(rows, orient="index").rename_axis(
            ["pressure_bar", "quantity"]
        )

    @property
    def has_volume(self) -> bool:
        """Some test has a volume curve (so the traditional force can be formed)."""
        return self.reference_bar is not None

    def __repr__(self) -> str:
        ref = f"{self.reference_bar:g} bar" if self.has_volume else "none: force only"
        return (
            f"CampaignBands({len(self.tests)} tests, {self.x_m.size} heights "
            f"{self.x_m.min() * 1e3:g}..{self.x_m.max() * 1e3:g} mm, {self.n_draws} joint draws, "
            f"reference {ref})"
        )

    def to_json(self) -> dict:
        """JSON-ready summary (SI, % where named): scatter and the x0 values of every test."""
        return {
            "n_draws": self.n_draws,
            "seed": self.seed,
            "reference_bar": self.reference_bar,
            "reference_note": self.reference_note,
            "feff_scatter_pct": {
                "pressures_bar": self.scatter_pressures_bar,
                "definition": "half the range of F_eff = P/p_u across the tests over their mean, per joint draw",
                "at": self.scatter_at,
            },
            "tests_at_x0": [{"pressure_bar": t.pressure_bar} | t.at_x0 for t in self.tests],
            "intervals": "q05/q95 in tests_at_x0 and feff_scatter_pct are pointwise 90 % intervals (one height at a time)",
            "curve_bands": self.curve_bands(),
        } | self._omitted()

    def _omitted(self) -> dict:
        """Why volume quantities are missing (force-only tests), as ``{"omitted": {...}}``."""
        without = [t.pressure_bar for t in self.tests if not t.has_volume]
        if not without:
            return {}
        out = {
            "own_volume": f"{', '.join(f'{p:g}' for p in without)} bar: {FORCE_ONLY_WHY}: no L(x), "
            "volume increment, -S dL/dx, or traditional force from the test's own volume curve"
        }
        if not self.has_volume:
            out["traditional_force"] = (
                f"{NO_VOLUME_WHY}: no traditional force p_u (-S dL/dx) and no spread"
            )
        return {"omitted": out}

    def curve_bands(self, n_heights: int = 19) -> dict:
        """Pointwise and simultaneous 90 % bands of F_eff and the spread on ``n_heights`` heights."""
        idx = np.unique(np.linspace(0, self.x_m.size - 1, n_heights).round().astype(int))
        tests = []
        for t in self.tests:
            row = {"pressure_bar": t.pressure_bar}
            for name, key in SIMULTANEOUS.items():
                if name not in t.simultaneous:  # a volume quantity of a force-only test
                    continue
                pw, sim = getattr(t, name), t.simultaneous[name]
                row[key] = {
                    "mean": pw.mean[idx],
                    "pointwise_q05": pw.lo[idx],
                    "pointwise_q95": pw.hi[idx],
                    "simultaneous_lo": sim.lo[idx],
                    "simultaneous_hi": sim.hi[idx],
                    "simultaneous_critical_sd": sim.critical,
                }
            tests.append(row)
        return {
            "height_m": self.x_m[idx],
            "level": self.tests[0].simultaneous["feff"].level if self.tests else LEVEL,
            "pointwise": "pointwise_q05/q95: at each height separately, the curve's value lies inside with 90 % "
            "posterior probability; the whole curve leaves such a band much more often",
            "simultaneous": f"simultaneous_lo/hi = mean +/- c sd over all {self.x_m.size} grid heights, c the 90 % "
            "quantile of the draws' largest |f(x) - mean(x)| / sd(x): the whole curve lies inside "
            "with 90 % posterior probability (values here at a subset of the heights)",
            "tests": tests,
        }


def estimate(draws) -> dict:
    """{"mean", "sd", "q05", "q95"} as floats (sd 0 for a single draw)."""
    d = np.asarray(draws, float).reshape(-1)
    if d.size < 2:
        v = float(d[0])
        return {"mean": v, "sd": 0.0, "q05": v, "q95": v}
    return {k: float(v) for k, v in _estimate(d).items()}


def _poly(coef: np.ndarray, u: np.ndarray) -> np.ndarray:
    """coef (..., 4), u (G,) -> (..., G): the paper's cubic at every grid height."""
    return cubic(np.asarray(coef, float)[..., None, :], np.asarray(u, float))


def _slope(coef: np.ndarray, u: np.ndarray) -> np.ndarray:
    """coef (..., 4), u (G,) -> (..., G): the cubic's slope d/du at every grid height."""
    return cubic_slope(np.asarray(coef, float)[..., None, :], np.asarray(u, float))


def choose_reference(
    pressures_bar, preferred: float = REFERENCE_BAR, has_volume=None
) -> tuple[int | None, str]:
    """Index of the test whose volume curve gives the traditional force, and why it was chosen;
    only tests with a volume curve (``has_volume`` (T,) bool, default all) can be chosen, and
    with none the index is None and the reason says so."""
    p_all = np.asarray(pressures_bar, float)
    vol = np.ones(p_all.size, bool) if has_volume is None else np.asarray(has_volume, bool)
    if not vol.any():
        return None, NO_VOLUME_WHY
    i, note = _choose(p_all[vol], preferred)
    if not vol.all():
        only = ", ".join(f"{v:g}" for v in p_all[vol])
        note += f" (tests with a volume curve: {only} bar)"
    return int(np.flatnonzero(vol)[i]), note


def _choose(pressures_bar, preferred: float) -> tuple[int, str]:
    p = np.asarray(pressures_bar, float)
    hit = np.flatnonzero(np.isclose(p, preferred, atol=1e-9))
    if hit.size:
        return int(hit[0]), f"the {preferred:g}-bar test's volume curve, as in the paper's Figure 5"
    mid = 0.5 * (p.min() + p.max())
    i = int(np.argmin(np.abs(p - mid)))
    return i, (
        f"no {preferred:g}-bar test in the data: the {p[i]:g}-bar test's volume curve is used "
        f"(the test nearest to the middle of the pressure range, {mid:g} bar)"
    )


def feff_scatter(feff: np.ndarray) -> np.ndarray:
    """Half range over mean across tests, in %: feff (T, ..., G) -> (..., G)."""
    return 100.0 * 0.5 * (feff.max(axis=0) - feff.min(axis=0)) / feff.mean(axis=0)


def bands_from_coefficients(
    pressures_bar,
    force,
    piston,
    *,
    x_grid,
    x0_m: float,
    piston_area_m2: float,
    x_max_m=None,
    noise=None,
    noise_ref_force=None,
    reference_bar: float = REFERENCE_BAR,
    seed: int = 0,
    on_test=None,
) -> CampaignBands:
    """Bands from coefficient draws.

    pressures_bar (T,); force, piston (T, D, 4) paper-basis coefficients (SI, u in m), draw i
    of every test forming joint draw i (D = 1 for point values such as Table 1); a force-only
    test has NaN piston coefficients (the volume quantities of its bands are then None), and
    ``piston`` None means no test has any; noise
    (T, D, 3) = sigma0_N, rel_force, sigma_L_m or None (predictive bands then equal the mean
    bands); noise_ref_force (T, G): the force level F_ref of the relative noise term on the grid,
    as the fit used it (its least-squares curve; default: each draw's own |force|); x_max_m (T,) each test's largest height (default: the grid's end); the scatter
    is also reported at x0, x_max and x_min of the grid and at 75 mm; on_test(t, bands, grid): called with each test's index and
    :class:`PressureBands` as soon as they are made (grid: x_m, x0_m, reference_bar), so that
    its figure can be drawn while the next test's bands are made (``uq report`` does).
    """
    p_bar = np.asarray(pressures_bar, float)
    force = np.asarray(force, float)
    T = force.shape[0]
    piston = np.full(force.shape, np.nan) if piston is None else np.asarray(piston, float)
    has_vol = np.all(np.isfinite(piston), axis=(1, 2))
    x = np.asarray(x_grid, float)
    S = float(piston_area_m2)
    x_max = np.full(T, x.max()) if x_max_m is None else np.asarray(x_max_m, float)
    ref, note = choose_reference(p_bar, reference_bar, has_vol)
    grid = SimpleNamespace(
        x_m=x, x0_m=float(x0_m), reference_bar=None if ref is None else float(p_bar[ref])
    )
    u, u_top = x - x0_m, x_max - x0_m
    normals = (
        None if noise is None else _normals(np.random.default_rng(seed), force.shape[:2], x.size)
    )
    feff_ref = None if ref is None else -S * _slope(piston[ref], u)
    sel = np.flatnonzero(p_bar >= SCATTER_MIN_BAR - 1e-9)
    across = _Across()  # F_eff's largest, smallest and summed value over the tests in sel
    tests = []
    for t in range(T):
        q = _curve_quantities(
            p_bar[t],
            force[t],
            piston[t],
            u,
            u_top[t],
            S,
            feff_ref,
            None if noise is None else np.asarray(noise, float)[t],
            None if noise_ref_force is None else np.asarray(noise_ref_force, float)[t],
            None if normals is None else next(normals),
        )
        B, sim = {}, {}
        for n, curves in q:  # each quantity's (D, G) curves reduced to bands, then dropped
            if n == "feff" and t in sel:
                across.add(curves)
            if (n in OWN_VOLUME and not has_vol[t]) or (n in REF_VOLUME and ref is None):
                continue
            B[n] = Band.of(curves)
            if n in SIMULTANEOUS:
                sim[n] = SimultaneousBand.of(curves)
            del curves
        sim = {n: sim[n] for n in SIMULTANEOUS if n in sim}
        at0 = _at_x0(
            p_bar[t],
            force[t],
            piston[t, :, 1] if has_vol[t] else None,
            None if ref is None else piston[ref, :, 1],
            S,
        )
        tests.append(
            PressureBands(float(p_bar[t]), float(x_max[t]), at_x0=at0, simultaneous=sim, **B)
        )
        if on_test is not None:
            on_test(t, tests[-1], grid)
    heights = {
        "x0": x0_m,
        "x_max": float(x.max()),
        "x_min": float(x.min()),
        "75 mm": EXTRA_HEIGHT_M,
    }
    scatter, scatter_at = _scatter(p_bar[sel], force[sel], across, heights, x0_m)
    return CampaignBands(
        x,
        float(x0_m),
        S,
        tests,
        None if ref is None else float(p_bar[ref]),
        note,
        [float(v) for v in p_bar[sel]],
        scatter,
        scatter_at,
        int(force.shape[1]),
        int(seed),
    )


def _normals(rng: np.random.Generator, shape: tuple[int, int], n_grid: int):
    """The predictive draws' normals, one test's (2, D, G) block (force's, piston's) a ``next``,
    from the stream the bands have always used: ``rng.standard_normal((2, T, D, G))``, every
    test's force normals first, then every test's piston normals. Two generators read that stream,
    one from its start (force) and a copy moved past the T force blocks (piston), so that a
    campaign holds one test's normals instead of all of them (64 MB on data/n50 at 2000 draws);
    numpy's generator draws a block of normals as the same values whether in one call or in
    consecutive ones (tested)."""
    size = (int(shape[1]), int(n_grid))
    piston = copy.deepcopy(rng)
    for _ in range(int(shape[0])):  # past the force normals, one block at a time
        piston.standard_normal(size)
    while True:
        yield np.stack([rng.standard_normal(size), piston.standard_normal(size)])


class _Across:
    """F_eff's largest, smallest and summed value across the tests added (in order), per draw and
    height: the scatter of :func:`feff_scatter` without holding every test's (D, G) curves."""

    def __init__(self):
        self.n, self.hi, self.lo, self.sum = 0, None, None, None

    def add(self, feff: np.ndarray) -> None:
        if self.n == 0:
            self.hi, self.lo, self.sum = feff.copy(), feff.copy(), feff.copy()
        else:
            np.maximum(self.hi, feff, out=self.hi)
            np.minimum(self.lo, feff, out=self.lo)
            self.sum += feff
        self.n += 1

    def scatter(self) -> np.ndarray:
        """:func:`feff_scatter` of the tests added (the same numbers: numpy sums over the first
        axis of an array one row after the other, as ``add`` does)."""
        return 100.0 * 0.5 * (self.hi - self.lo) / (self.sum / self.n)


def _curve_quantities(p_bar, force, piston, u, u_top, S, feff_ref, noise, f_ref, z):
    """Every banded curve of one test, (name, (D, G) curves) one after the other (so that the
    caller holds only the few curves the next ones are made from), from its coefficient draws
    force, piston (D, 4) on the grid u = x - x0: u_top its largest height, feff_ref (D, G) the
    reference test's -S dL/dx (None: no reference), noise (D, 3) and f_ref (G,) the relative
    noise term's force level (None: each draw's own |force|), z (2, D, G) the predictive draws'
    normals (None: no noise, predictive curves equal to the mean curves)."""
    P = _poly(force, u)  # (D, G)
    yield "force", P
    if noise is not None:
        sd_f = np.sqrt(
            force_noise_var(noise[:, 0:1], noise[:, 1:2], np.abs(P) if f_ref is None else f_ref)
        )
        yield "force_pred", P + sd_f * z[0]
        del sd_f
    else:
        yield "force_pred", P
    L = _poly(piston, u)
    yield "piston", L
    yield "piston_pred", L + noise[:, 2:3] * z[1] if noise is not None else L
    L_top = _poly(piston, np.atleast_1d(u_top))  # (D, 1)
    yield "dV", S * (L - L_top)
    del L
    p_pa = p_bar * BAR_PA
    yield "feff", P / p_pa
    feff_vol = -S * _slope(piston, u)  # NaN for a force-only test
    yield "feff_volume", feff_vol
    trad_own = p_pa * feff_vol
    del feff_vol
    yield "trad_own", trad_own
    trad_ref = p_pa * (feff_ref if feff_ref is not None else np.full_like(trad_own, np.nan))
    yield "trad_ref", trad_ref
    yield "spread_own", trad_own - P
    with np.errstate(divide="ignore", invalid="ignore"):  # not across a yield: the caller's too
        pct = 100.0 * (trad_own - P) / P
    del trad_own
    yield "spread_own_pct", pct
    yield "spread_ref", trad_ref - P
    with np.errstate(divide="ignore", invalid="ignore"):
        pct = 100.0 * (trad_ref - P) / P
    yield "spread_ref_pct", pct


def _at_x0(p_bar: float, force, b_L, b_L_ref, S: float) -> dict:
    """Values at x0 exactly (from the coefficients, whatever the grid): force (D, 4), b_L (D,)
    of the test and of the reference test (None: no volume curve, those values left out)."""
    a_P = force[:, 0]
    out = {"force_N": estimate(a_P), "feff_m2": estimate(a_P / (p_bar * BAR_PA))}
    if b_L is not None:
        tr_own0 = p_bar * BAR_PA * (-S * b_L)
        out |= {"feff_volume_m2": estimate(-S * b_L), "trad_own_N": estimate(tr_own0)}
    if b_L_ref is not None:
        tr_ref0 = p_bar * BAR_PA * (-S * b_L_ref)
        out["trad_ref_N"] = estimate(tr_ref0)
    if b_L is not None:
        out["spread_own_pct"] = estimate(100.0 * (tr_own0 - a_P) / a_P)
    if b_L_ref is not None:
        out["spread_ref_pct"] = estimate(100.0 * (tr_ref0 - a_P) / a_P)
    return out


def _scatter(p_bar, force, across: _Across, heights: dict, x0_m: float):
    """Scatter of F_eff over the tests at >= SCATTER_MIN_BAR (None with fewer than two), on the
    grid (``across``: their F_eff curves) and at heights."""
    if p_bar.size < 2:
        return None, {}
    scatter = Band.of(across.scatter())
    hx = np.array(list(heights.values()), float)
    fh = _poly(force, hx - x0_m) / (p_bar * BAR_PA)[:, None, None]  # (T', D, H)
    sh = feff_scatter(fh)  # (D, H)
    return scatter, {
        label: {"height_m": float(h)} | estimate(sh[:, k])
        for k, (label, h) in enumerate(heights.items())
    }


def subsample(n_total: int, n_draws: int, rng: np.random.Generator) -> np.ndarray:
    """Indices of ``n_draws`` posterior draws (all of them, in order, when there are fewer)."""
    if n_total <= n_draws:
        return np.arange(n_total)
    return np.sort(rng.choice(n_total, size=n_draws, replace=False))


def height_grid(recordings, n_grid: int = 181) -> np.ndarray:
    lo, hi = recordings.height_range_m
    return np.linspace(lo, hi, n_grid)


def campaign_bands(
    cf,
    *,
    n_grid: int = 181,
    n_draws: int = 2000,
    seed: int = 0,
    x_grid=None,
    reference_bar: float = REFERENCE_BAR,
    on_test=None,
) -> CampaignBands:
    """Bands of a fitted campaign (:class:`uq._models.cubic_results.CampaignFit`, or anything with ``.recordings``
    and ``.tests`` holding ``pressure_bar``, ``test.height_m`` and ``flat(name)``).

    Subsamples ``n_draws`` draws per test (seeded), evaluates on ``x_grid`` (default: the data's
    height range, ``n_grid`` points); ``on_test``: as :func:`bands_from_coefficients`'.

    >>> import uq
    >>> rec = uq.simulate("n50", seed=1, layout=uq.Layout(pressures_bar=(1.0, 5.0), step_m=0.01))
    >>> bands = uq.campaign_bands(uq.fit_campaign(rec, seed=1, settings=uq.Settings(max_steps=200)), n_draws=200)
    >>> feff = bands.at(5.0).feff     # F_eff = P / p_u (m^2): pointwise 90 % band on the height grid
    >>> feff.mean.shape, bool((feff.lo <= feff.mean).all() and (feff.mean <= feff.hi).all())
    ((181,), True)
    >>> sorted(bands.scatter_at)      # scatter of F_eff across the tests with p_u >= 1 bar, %
    ['75 mm', 'x0', 'x_max', 'x_min']
    """
    rec = cf.recordings
    rng = np.random.default_rng(seed)
    x = height_grid(rec, n_grid) if x_grid is None else np.asarray(x_grid, float)
    draws = [t.flat("force").shape[0] for t in cf.tests]
    D = min(n_draws, min(draws))
    F, L, N = [], [], []
    for t, n in zip(cf.tests, draws, strict=True):
        idx = subsample(n, D, rng)
        F.append(t.flat("force")[idx])
        volume = getattr(t, "has_piston", True)  # False: a force-only test, NaN piston and sigma_L
        L.append(t.flat("piston")[idx] if volume else np.full((idx.size, 4), np.nan))
        noise = t.flat("noise")[idx]
        N.append(noise if volume else np.pad(noise, ((0, 0), (0, 1)), constant_values=np.nan))
    any_volume = any(getattr(t, "has_piston", True) for t in cf.tests)
    cb = bands_from_coefficients(
        [t.pressure_bar for t in cf.tests],
        np.stack(F),
        np.stack(L) if any_volume else None,
        x_grid=x,
        x0_m=rec.x0_m,
        piston_area_m2=rec.piston_area_m2,
        x_max_m=[float(t.test.height_m.max()) for t in cf.tests],
        noise=np.stack(N),
        noise_ref_force=_noise_reference(cf.tests, x),
        reference_bar=reference_bar,
        seed=int(rng.integers(2**31)),
        on_test=on_test,
    )
    return dataclasses.replace(cb, seed=int(seed))


def _noise_reference(tests, x) -> np.ndarray | None:
    """The fits' force level of the relative noise term on the grid x, (T, G), by each fit's own
    rule (``PressureFit.ref_force_at``); None for fits that do not carry one."""
    if not all(hasattr(t, "ref_force_at") for t in tests):
        return None
    return np.stack([t.ref_force_at(x) for t in tests])
