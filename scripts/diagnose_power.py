"""Power of ``uq diagnose`` near its detection limit, against an oracle: regenerates reports/diagnose-power/.

    .venv/bin/python scripts/diagnose_power.py [--seeds 10] [--jobs 2] [--budget-minutes 30]

(``--tiny --out DIR``: a small layout, short chains, two seeds on one rung of one mechanism, to
check that the script runs; tests/test_scripts.py does so. Not a measurement.)

For each mechanism of docs/formats.md section 3 (uq._physics.mechanisms.MECHANISMS), campaigns of the
paper's layout (0.1, 1..10 bar, 155..65 mm in 5 mm steps, both branches) from the virtual stand
(spring ``n50-traditional``, the paper's stand: Gaussian errors of the engine's own budget) with
the mechanism concealed at a magnitude on a coarse ladder (factor 2 between rungs). On every
campaign two detectors:

* the engine: ``uq._diagnose.engine.diagnose`` on the recordings alone (the settings of
  scripts/diagnose_proof.py); found = the true mechanism is among those it names;
* the oracle: knows the stand's noise exactly (each reading's 2x2 covariance of force and piston
  from the error budget, first order, at the true curves) and which mechanism to test; its
  statistic is delta chi^2 = min chi^2(traditional) - min chi^2(traditional + the true
  mechanism), both generalised least squares with that covariance, the mechanism in the engine's
  own parametrisation (uq._physics.mechanisms: a cubic casing force, the elastic casing's cubic
  compliance, a scale factor profiled over its magnitude), the traditional area a cubic in height
  (the spring's own class). A likelihood-ratio test: found = delta chi^2 above the chi^2 quantile
  (k = the mechanism's number of parameters) at the engine's nominal false-alarm rate, the tail
  of one one-sided 4-SE test (engine.GAIN_SE): alpha = 3.2e-5.

The ladder is searched, not swept: each mechanism starts at the rung of MAGNITUDES marked as its
start (the proof's near-limit magnitude); a rung passes when the engine finds the mechanism in at
least 9 of the seeds (of 10; scaled for fewer), and the search goes down while rungs pass and up
while they fail. A rung stops early once it can no longer pass. The oracle is scored on the same
campaigns, and its own 90 % limit is also computed exactly: with known noise the statistic is a
noncentral chi^2 whose noncentrality is delta chi^2 of the noise-free readings (for a scale factor,
to first order), so power(m) follows and the magnitude of 90 % power is solved for.

Writes power.json (every campaign, per-rung counts, the two limits per mechanism) and README.md.
Runs already in power.json with the same key are reused (``--fresh`` to redo).
"""

from __future__ import annotations

import argparse
import json
import math
import multiprocessing as mp
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

#: mechanism -> ladder (units of docs/formats.md section 3), factor 2 apart; START its first rung.
LADDERS = {
    "pressure_dependent_area": (0.0005, 0.001, 0.002, 0.004),
    "casing_force": (10.0, 20.0, 40.0, 80.0),
    "elastic_casing": (0.0005, 0.001, 0.002, 0.004),
    "hysteresis": (0.00125, 0.0025, 0.005, 0.01),
    "force_offset": (3.0, 6.0, 12.0, 24.0),
    "volume_excess": (0.005, 0.01, 0.02, 0.04),
    "thermal_drift": (0.125, 0.25, 0.5, 1.0),
}
START = 2  # index of the first rung tried: the proof's near-limit magnitude (or near it)
LAYOUT = dict(
    pressures_bar=(0.1, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10), x_max_m=0.155, x_min_m=0.065, step_m=0.005
)
TINY_LAYOUT = dict(pressures_bar=(1.0, 5.0, 9.0), x_max_m=0.155, x_min_m=0.065, step_m=0.01)
SEED0 = 3000
POWER = 0.9
ORACLE_ORDER = 3  # the traditional area of n50-traditional is a cubic in height


def alpha() -> float:
    """The engine's nominal false-alarm rate of one mechanism: one one-sided GAIN_SE-sd test."""
    from scipy.stats import norm

    from uq._diagnose.engine import GAIN_SE

    return float(norm.sf(GAIN_SE))


# ----------------------------------------------------------------------------- the campaigns


def campaign(mech: str, magnitude: float, seed: int, tiny: bool):
    """The stand's tests (dicts of arrays) and the noise-free true curves at the nominal heights."""
    from uq._stand.simulator import SPRINGS, Layout, simulate, true_curves

    layout = Layout(**(TINY_LAYOUT if tiny else LAYOUT))
    effects = {mech: magnitude} if magnitude else {}
    tests = simulate("n50-traditional", seed=seed, effects=effects, layout=layout)
    spring = SPRINGS["n50-traditional"]()
    truth = [
        true_curves(spring, effects, t["height_m"], t["pressure_bar"], t["compression"], t["step"])
        for t in tests
    ]
    return tests, truth


def recordings(tests):
    from uq._stand.simulator import recordings_from_tests

    return recordings_from_tests(tests, "power")


# ----------------------------------------------------------------------------- the oracle


class Oracle:
    """GLS with each reading's true 2x2 noise covariance (the stand's budget, first order).

    Built once per layout and mechanism from the noise-free curves of the traditional spring
    (the covariance depends on the curves only through the force, its slope and the pressure
    lever; a concealed effect near the detection limit changes them by under 1 %, far below
    what matters to a covariance)."""

    def __init__(self, mech: str, tests, stand=None):
        from uq._data.stand_description import PAPER_STAND
        from uq._physics.mechanisms import MECHANISMS, DesignContext, ScaleTerm
        from uq._physics.quantities import BAR_PA, BASIS_SCALE_M
        from uq._stand.simulator import PAPER_PISTON_AREA_M2, SPRINGS

        stand = stand or PAPER_STAND
        spring = SPRINGS["n50-traditional"]()
        S = PAPER_PISTON_AREA_M2
        x = np.concatenate([t["height_m"] for t in tests])
        p = np.concatenate([np.full(t["height_m"].size, t["pressure_bar"]) for t in tests])
        comp = np.concatenate([t["compression"] for t in tests])
        step = np.concatenate([t["step"] for t in tests]).astype(float)
        ti = np.concatenate([np.full(t["height_m"].size, i) for i, t in enumerate(tests)])
        n = x.size
        # covariance of (force, piston) of each reading
        F = np.concatenate([spring.force_N(t["height_m"], t["pressure_bar"]) for t in tests])
        lever = np.concatenate(
            [spring.effective_area_m2(t["height_m"], t["pressure_bar"]) for t in tests]
        )
        dFdx = p * BAR_PA * lever_slope(spring, x, p)
        dLdx = np.concatenate(
            [spring.piston_slope(t["height_m"], t["pressure_bar"]) for t in tests]
        )
        sdp = np.asarray(stand.pressure_sd_bar(p), float)
        gF = BAR_PA * lever  # force per bar of pressure error
        gL = -stand.gas_volume_at_xmax_m3 / (p + stand.p_atm_bar) / S  # piston per bar
        sdx = stand.displacement_sd_m
        vF = (stand.load_cell_rel_sd * F) ** 2 + (gF * sdp) ** 2 + (dFdx * sdx) ** 2
        vL = (gL * sdp) ** 2 + stand.caliper_sd_m**2 + (dLdx * sdx) ** 2
        cFL = gF * gL * sdp**2 + dFdx * dLdx * sdx**2
        # whitening of each reading's pair: Cholesky of [[vF, cFL], [cFL, vL]]
        l11 = np.sqrt(vF)
        l21 = cFL / l11
        l22 = np.sqrt(vL - l21**2)
        self._l = (l11, l21, l22)
        # design: traditional area (force and piston), piston references, the mechanism's columns
        t = (x - spring.x0_m) / BASIS_SCALE_M
        pw = np.arange(ORACLE_ORDER + 1)
        T = t[:, None] ** pw
        self._base_force = (p * BAR_PA)[:, None] * T
        self._base_piston = -(BASIS_SCALE_M / S) * t[:, None] ** (pw + 1) / (pw + 1)
        R = np.eye(len(tests))[ti]
        term = MECHANISMS[mech].term
        self.k = MECHANISMS[mech].n_params
        ctx = DesignContext(t, p, np.where(comp, 1.0, -1.0), step, S)
        self._R = R
        if isinstance(term, ScaleTerm):
            self._scale = (
                {"pressure": p, "branch": ctx.sgn, "one": np.ones(n)}[term.variable],
                "feff.force" in term.scales,
                "feff.volume" in term.scales,
            )
            self._extra = None
        else:
            self._scale = None
            f, q = term.columns(ctx)
            width = (f if f is not None else q).shape[1]
            self._extra = (
                np.zeros((n, width)) if f is None else np.asarray(f, float),
                np.zeros((n, width)) if q is None else np.asarray(q, float),
            )

    def _whiten(self, yF, yL):
        l11, l21, l22 = self._l
        a = yF / l11[..., None] if yF.ndim == 2 else yF / l11
        if yF.ndim == 2:
            b = (yL - l21[:, None] * a) / l22[:, None]
        else:
            b = (yL - l21 * a) / l22
        return np.concatenate([a, b])

    def _chi2(self, XF, XL, yF, yL) -> float:
        A = self._whiten(XF, XL)
        y = self._whiten(yF, yL)
        coef, *_ = np.linalg.lstsq(A, y, rcond=None)
        r = y - A @ coef
        return float(r @ r)

    def _design(self, m: float | None):
        n = self._R.shape[0]
        bF, bL = self._base_force, self._base_piston
        if m is not None and self._scale is not None:
            g, on_force, on_volume = self._scale
            k = (1.0 + m * g)[:, None]
            bF = bF * k if on_force else bF
            bL = bL * k if on_volume else bL
        XF = np.hstack([bF, np.zeros((n, self._R.shape[1]))])
        XL = np.hstack([bL, self._R])
        if m is not None and self._scale is None:
            XF = np.hstack([XF, self._extra[0]])
            XL = np.hstack([XL, self._extra[1]])
        return XF, XL

    def delta_chi2(self, force, piston) -> float:
        """min chi^2 of the traditional model minus that of traditional + the mechanism (>= 0)."""
        from scipy.optimize import minimize_scalar

        base = self._chi2(*self._design(None), force, piston)
        if self._scale is None:
            return base - self._chi2(*self._design(0.0), force, piston)
        res = minimize_scalar(
            lambda m: self._chi2(*self._design(m), force, piston),
            bounds=(-0.5, 0.5),
            method="bounded",
            options={"xatol": 1e-7},
        )
        return base - min(res.fun, base)


def lever_slope(spring, x, p):
    """dF_eff/dx of the traditional spring (central difference of its cubic)."""
    h = 1e-6
    return np.array(
        [
            (spring.effective_area_m2(xi + h, pi) - spring.effective_area_m2(xi - h, pi)) / (2 * h)
            for xi, pi in zip(x, p, strict=True)
        ]
    )


def oracle_limit(mech: str, tiny: bool, a: float) -> dict:
    """The oracle's exact 90 % limit: power(m) = P(ncx2(k, lambda(m)) > chi2 quantile), lambda(m)
    the noise-free delta chi^2; solved for power 0.9 (lambda rises with |m|)."""
    from scipy.optimize import brentq
    from scipy.stats import chi2, ncx2

    tests, _ = campaign(mech, 0.0, SEED0, tiny)
    oracle = Oracle(mech, tests)
    threshold = float(chi2.isf(a, oracle.k))

    def lam(m):
        _, truth = campaign(mech, m, SEED0, tiny)
        return oracle.delta_chi2(
            np.concatenate([f for f, _ in truth]), np.concatenate([q for _, q in truth])
        )

    def power(m):
        return float(ncx2.sf(threshold, oracle.k, lam(m)))

    hi = LADDERS[mech][0]
    while power(hi) < POWER:
        hi *= 2.0
    lo = hi / 2.0
    while power(lo) >= POWER and lo > 1e-9:
        lo /= 2.0
    m90 = brentq(lambda m: power(m) - POWER, lo, hi, xtol=1e-4 * hi)
    return {
        "k": oracle.k,
        "alpha": a,
        "threshold_chi2": threshold,
        "magnitude_90": m90,
        "power_at_rungs": {f"{m:g}": power(m) for m in LADDERS[mech]},
    }


# ----------------------------------------------------------------------------- one campaign


def key(mech, magnitude, seed, tiny) -> str:
    return f"{mech}={magnitude:g}|{seed}" + ("|tiny" if tiny else "")


def run_one(job: dict) -> dict:
    from scipy.stats import chi2

    from uq._diagnose.engine import diagnose
    from uq._inference.sampler import Settings

    mech, mag, seed, tiny, a = job["mech"], job["magnitude"], job["seed"], job["tiny"], job["alpha"]
    tests, _ = campaign(mech, mag, seed, tiny)
    oracle = Oracle(mech, tests)
    force = np.concatenate([t["force_N"] for t in tests])
    piston = np.concatenate([t["piston_m"] for t in tests])
    dchi2 = oracle.delta_chi2(force, piston)
    settings = (
        Settings(max_steps=200) if tiny else Settings(min_steps=300, chunk=200, tau_multiple=30.0)
    )
    t0 = time.time()
    res = diagnose(recordings(tests), seed=seed, settings=settings).to_json()
    named = [m["name"] for m in res["mechanisms"]]
    return {
        "key": key(mech, mag, seed, tiny),
        "mechanism": mech,
        "magnitude": mag,
        "seed": seed,
        "engine_named": named,
        "engine_found": mech in named,
        "engine_seconds": time.time() - t0,
        "oracle_delta_chi2": dchi2,
        "oracle_found": bool(dchi2 > chi2.isf(a, oracle.k)),
    }


# ----------------------------------------------------------------------------- the search


def need(n_seeds: int) -> int:
    """Finds a rung needs to pass: 9 of 10, the same share of fewer (rounded up)."""
    return math.ceil(POWER * n_seeds - 1e-9)


def run_rung(pool, mech, mag, n_seeds, jobs, tiny, done, path, deadline, a) -> bool | None:
    """Run one rung's seeds (``jobs`` at a time) until it passes, can no longer pass, or the time
    is spent; True / False, or None when stopped by the time budget."""
    from uq._io.files import dumps_json, write_text_atomic

    seeds = [SEED0 + s for s in range(n_seeds)]
    hits = misses = 0
    for batch in range(0, n_seeds, jobs):
        if time.time() > deadline:
            return None
        todo = [
            dict(mech=mech, magnitude=mag, seed=s, tiny=tiny, alpha=a)
            for s in seeds[batch : batch + jobs]
        ]
        new = [j for j in todo if key(mech, mag, j["seed"], tiny) not in done]
        for r in pool.map(run_one, new):
            done[r["key"]] = r
            print(
                f"{r['key']}: engine {'found' if r['engine_found'] else 'missed'} "
                f"({', '.join(r['engine_named']) or 'nothing'}), oracle delta chi2 "
                f"{r['oracle_delta_chi2']:.1f} ({r['engine_seconds']:.0f} s)",
                flush=True,
            )
        write_text_atomic(
            path, dumps_json({"campaigns": sorted(done.values(), key=lambda r: r["key"])})
        )
        got = [done[key(mech, mag, j["seed"], tiny)] for j in todo]
        hits += sum(r["engine_found"] for r in got)
        misses += sum(not r["engine_found"] for r in got)
        if misses > n_seeds - need(n_seeds):
            return False  # this rung can no longer pass
    return hits >= need(n_seeds)


def search(mechs, n_seeds, jobs, tiny, done, path, deadline, a) -> None:
    """Breadth first: one rung of every mechanism per round, so a run cut short by the time
    budget has looked at every mechanism alike. Down the ladder while rungs pass, up while they
    fail, until the limit is bracketed or the ladder ends."""
    state = {m: (0 if tiny else START, {}) for m in mechs}
    ctx = mp.get_context("spawn")
    with ctx.Pool(jobs) as pool:
        while state:
            for mech in list(state):
                i, tried = state[mech]
                ok = run_rung(
                    pool, mech, LADDERS[mech][i], n_seeds, jobs, tiny, done, path, deadline, a
                )
                if ok is None:
                    print("time budget spent: stopping", flush=True)
                    return
                tried[i] = ok
                i = i - 1 if ok else i + 1
                if tiny or not 0 <= i < len(LADDERS[mech]) or i in tried:
                    del state[mech]
                else:
                    state[mech] = (i, tried)


def smallest(rungs: dict, detector: str, n_seeds: int) -> float | None:
    """The smallest rung with every seed run and at least ``need`` finds."""
    ok = [
        float(m) for m, v in rungs.items() if v["runs"] == n_seeds and v[detector] >= need(n_seeds)
    ]
    return min(ok) if ok else None


def largest_failing(rungs: dict, detector: str, n_seeds: int) -> float | None:
    """The largest rung that cannot pass any more (too many misses, the seeds not run counted as finds)."""
    bad = [
        float(m) for m, v in rungs.items() if v[detector] + (n_seeds - v["runs"]) < need(n_seeds)
    ]
    return max(bad) if bad else None


def summarise(results: list[dict], n_seeds: int, limits: dict, a: float) -> dict:
    out = {}
    for mech in LADDERS:
        rungs = {}
        for mag in LADDERS[mech]:
            rs = [r for r in results if r["mechanism"] == mech and r["magnitude"] == mag]
            if rs:
                rungs[f"{mag:g}"] = {
                    "runs": len(rs),
                    "engine_found": sum(r["engine_found"] for r in rs),
                    "oracle_found": sum(r["oracle_found"] for r in rs),
                    "engine_extra_named": sum(bool(set(r["engine_named"]) - {mech}) for r in rs),
                }
        if not rungs:
            continue

        out[mech] = {
            "rungs": rungs,
            "engine_smallest_passing": smallest(rungs, "engine_found", n_seeds),
            "engine_largest_failing": largest_failing(rungs, "engine_found", n_seeds),
            "oracle_smallest_passing": smallest(rungs, "oracle_found", n_seeds),
            "oracle_exact_90": limits.get(mech),
        }
    return {
        "seeds_per_rung": n_seeds,
        "needed": need(n_seeds),
        "alpha": a,
        "n_campaigns": len(results),
        "engine_seconds_mean": float(np.mean([r["engine_seconds"] for r in results]))
        if results
        else None,
        "mechanisms": out,
    }


def markdown(s: dict, command: str, wall_min: float, tiny: bool = False) -> str:
    from uq._physics.mechanisms import MECHANISMS

    n, k = s["seeds_per_rung"], s["needed"]
    lines = [
        "# uq diagnose: power near the detection limit, against an oracle",
        "",
        f"Regenerate: `{command}` (scripts/diagnose_power.py; its docstring says how). Spring "
        "`n50-traditional`, the paper's layout (0.1, 1..10 bar, 155..65 mm in 5 mm steps, both "
        "branches) and stand; one mechanism concealed at a time."
        + (
            " (--tiny: 1, 5, 9 bar in 10 mm steps, short chains, two seeds: a check that the "
            "script runs, not a measurement.)"
            if tiny
            else ""
        ),
        "",
        f"A rung passes when the detector finds the mechanism in at least {k} of {n} seeds. The "
        "engine is `uq diagnose` on the recordings alone (found = it names the true mechanism); "
        "the oracle knows each reading's noise covariance and tests the true mechanism alone: "
        "delta chi^2 of the traditional model against the traditional model + that mechanism "
        f"(generalised least squares), a likelihood-ratio test at alpha = {s['alpha']:.1e}, the "
        "engine's nominal false-alarm rate for one mechanism (one one-sided 4-SE test; the engine "
        "also shares it out over the mechanisms it tests, which costs it a little more). "
        "'Exact oracle 90 %' is the magnitude at which the oracle's power is 0.9 computed from "
        "its noncentral chi^2 distribution (no seeds).",
        "",
        f"| mechanism | unit | engine: smallest rung found >= {k}/{n} | engine: largest rung failing | "
        f"oracle: smallest rung >= {k}/{n} | exact oracle 90 % | engine / oracle |",
        "|---|---|---|---|---|---|---|",
    ]

    def fmt(v):
        return "-" if v is None else f"{v:g}"

    for mech, v in s["mechanisms"].items():
        ex = v["oracle_exact_90"]
        e = v["engine_smallest_passing"]
        ratio = "-"
        if ex is not None and e is not None:
            lo = v["engine_largest_failing"]
            ratio = (
                f"{(lo or 0) / ex['magnitude_90']:.1f}..{e / ex['magnitude_90']:.1f}"
                if lo
                else f"<= {e / ex['magnitude_90']:.1f}"
            )
        lines.append(
            f"| {mech} | {MECHANISMS[mech].unit} | {fmt(e)} | {fmt(v['engine_largest_failing'])} | "
            f"{fmt(v['oracle_smallest_passing'])} | "
            f"{'-' if ex is None else format(ex['magnitude_90'], '.3g')} | {ratio} |"
        )
    lines += [
        "",
        "'-': not reached (no rung passed, or none failed, within the ladder tried). The engine's "
        "limit lies between its largest failing and its smallest passing rung; 'engine / oracle' "
        "is that interval over the exact oracle limit.",
        "",
        "## Every rung tried",
        "",
        "| mechanism | magnitude | seeds | engine found | oracle found | engine named another too |",
        "|---|---|---|---|---|---|",
    ]
    for mech, v in s["mechanisms"].items():
        for mag, r in v["rungs"].items():
            lines.append(
                f"| {mech} | {mag} | {r['runs']} | {r['engine_found']} | {r['oracle_found']} | "
                f"{r['engine_extra_named']} |"
            )
    lines += [
        "",
        f"Campaigns: {s['n_campaigns']}; engine time per campaign {s['engine_seconds_mean'] or 0:.1f} s "
        f"on average; this run's wall time {wall_min:.1f} min (the shared 2-core machine).",
    ]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10, help="seeds per rung (default 10)")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", default=str(ROOT / "reports" / "diagnose-power"))
    ap.add_argument(
        "--mechanisms", default=",".join(LADDERS), help="comma list (default: every mechanism)"
    )
    ap.add_argument(
        "--budget-minutes",
        type=float,
        default=30.0,
        help="stop starting campaigns after this long; the report says what was reached",
    )
    ap.add_argument("--fresh", action="store_true")
    ap.add_argument(
        "--tiny",
        action="store_true",
        help="small layout, short chains (a check, not a measurement)",
    )
    args = ap.parse_args(argv)
    from uq._io.files import dumps_json, write_text_atomic

    t_start = time.time()
    mechs = [m.strip() for m in args.mechanisms.split(",") if m.strip()]
    unknown = set(mechs) - set(LADDERS)
    if unknown:
        ap.error(f"unknown mechanisms {sorted(unknown)}; expected some of {', '.join(LADDERS)}")
    n_seeds = 2 if args.tiny else args.seeds
    out = Path(args.out)
    path = out / "power.json"
    a = alpha()
    old = {} if args.fresh or not path.exists() else json.loads(path.read_text())
    done = {r["key"]: r for r in old.get("campaigns", [])}
    limits = {m: oracle_limit(m, args.tiny, a) for m in mechs}
    search(mechs, n_seeds, args.jobs, args.tiny, done, path, t_start + 60 * args.budget_minutes, a)
    results = sorted(done.values(), key=lambda r: r["key"])
    s = summarise(results, n_seeds, limits, a)
    command = ".venv/bin/python scripts/diagnose_power.py " + " ".join(
        argv if argv is not None else sys.argv[1:]
    )
    wall = (time.time() - t_start) / 60
    write_text_atomic(path, dumps_json({**s, "command": command, "campaigns": results}))
    write_text_atomic(out / "README.md", markdown(s, command.strip(), wall, args.tiny))
    print(markdown(s, command.strip(), wall, args.tiny))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
