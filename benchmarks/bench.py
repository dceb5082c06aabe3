"""Benchmarks of airspring-uq: sampler efficiency, memory and scale, batch speed-up, margin queries.

Not part of the installed package: run from the repository root with the project installed,

    .venv/bin/python benchmarks/bench.py [--seconds 10] [--json reports/bench/ess.json]
    .venv/bin/python benchmarks/bench.py --scaling  [--json reports/bench/scaling.json]
    .venv/bin/python benchmarks/bench.py --batch 20,50,200 [--json reports/bench/batch.json]
    .venv/bin/python benchmarks/bench.py --margin   [--json reports/bench/margin.json]
    .venv/bin/python benchmarks/bench.py --memory   [--json reports/bench/memory.json]

The summary goes to stdout (to stderr with ``--json -``); the JSON goes only where ``--json``
says (the committed records are reports/bench/*.json: pass their path to refresh one).

Default measurement: effective samples per second of the force posterior, project sampler vs plain emcee.

Workload: one 37-point test, the 5 bar test of the virtual stand (``uq._stand.simulator.simulate``,
spring n50, seeded by ``--seed``), or the test at ``--pressure-bar`` of ``--recordings FILE``.

Measure: ESS/s = min over the four force coefficients (a_P, b_P, c_P, d_P) of bulk ESS,
divided by the wall time of the run, and the same ratio for every quantity of the force
posterior both report (the coefficients, sigma0, r). ESS is the project's estimator for both
samplers (``uq._inference.sampler.bulk_ess``: ArviZ's ESS of the ensemble-mean chain converted
to draws, so coupled walkers are not counted as independent chains). Both runs are in the same
process, after a JIT warm-up run that is not timed.

(a) project: ``uq._models.cubic.fit_test`` unchanged (least squares, optimistix start, emcee over
    the three noise parameters with DE and independence-t moves until 50 autocorrelation times, exact Gaussian
    draws of the eight coefficients, ArviZ diagnostics); the timed wall time covers all of
    it, including the piston block it also fits. Repeated with fresh seeds until
    ``--seconds`` have passed (at least once); ESS of independent runs adds up.
(b) baseline: plain emcee (stretch move, ``vectorize=False``: one Python/numpy call per
    walker) over (a_P, b_P, c_P, d_P, log sigma0, log r) in the paper's monomial basis, with
    the project's force likelihood (sd sqrt(sigma0^2 + (r |Phat|)^2), Phat the least-squares
    curve) and priors (the scaled-basis N(0, (100 kN)^2) carried to the monomial basis,
    log sigma0 ~ N(log 10, 2^2), log r ~ N(log 0.005, 1)), 32 walkers started in a small
    ball around the least-squares solution, run for the same wall time as (a); burn-in
    5 autocorrelation times (emcee's estimate), as the project's.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

import emcee
import numpy as np
from bench_tables import MEMORY, SCALING, table

from uq._data.recordings import PressureTest
from uq._data.reference import FORCE_NAMES
from uq._inference.convergence import bulk_ess
from uq._inference.sampler import Settings
from uq._io.errors import InputError
from uq._io.files import emit_json

BENCH_PRESSURE_BAR = 5.0
BASELINE_WALKERS = 32


def bench_test(
    seed: int, recordings: str | None = None, pressure_bar: float = BENCH_PRESSURE_BAR
) -> tuple[PressureTest, float, str]:
    """The workload: (test, x0_m, description)."""
    if recordings:
        from uq._data.recordings import read_recordings

        rec = read_recordings(recordings)
        try:
            return rec.test_at(pressure_bar), rec.x0_m, f"{pressure_bar:g} bar test of {recordings}"
        except KeyError:
            have = ", ".join(f"{p:g}" for p in rec.pressures_bar)
            raise InputError(
                f"{recordings}: no test at {pressure_bar:g} bar (option --pressure-bar); it has {have} bar"
            ) from None
    from uq._data.reference import PAPER_X0_M
    from uq._stand.simulator import Layout, recordings_from_tests, simulate

    tests = simulate("n50", seed=seed, layout=Layout(pressures_bar=(pressure_bar,)))
    test = recordings_from_tests(tests).tests[0]
    return test, PAPER_X0_M, f"{pressure_bar:g} bar test of the virtual stand (n50, seed {seed})"


#: Every quantity of the force posterior both samplers report: the coefficients and the noise
#: (the baseline samples log sigma0 and log r; bulk ESS is rank-based, so the same for sigma0, r).
QUANTITIES = (*FORCE_NAMES, "sigma0_N", "rel_force")


# --------------------------------------------------------------------------- (a) project


def run_project(
    test: PressureTest, x0_m: float, *, seed: int, seconds: float, settings: Settings
) -> dict:
    from uq._models.cubic_fit import fit_test

    # JIT warm-up, not timed: a whole fit, so the draw programs of the timed runs' bucket are compiled too
    fit_test(test, x0_m, seed=seed, settings=settings)
    runs, total_time = 0, 0.0
    each = dict.fromkeys(QUANTITIES, 0.0)
    rs = np.random.SeedSequence(seed)
    while runs == 0 or total_time < seconds:
        s = int(rs.spawn(1)[0].generate_state(1)[0])
        t0 = time.perf_counter()
        fit = fit_test(test, x0_m, seed=s, settings=settings)
        total_time += time.perf_counter() - t0
        for n in QUANTITIES:
            each[n] += float(fit.convergence.variables[n]["ess_bulk"])
        runs += 1
    total_ess = min(each[n] for n in FORCE_NAMES)
    return {
        "name": "project: uq._models.cubic.fit_test (collapsed: emcee DE and independence-t moves on the noise, exact coefficient draws)",
        "runs": runs,
        "wall_s": total_time,
        "ess_bulk_min": total_ess,
        "ess_per_s": total_ess / total_time,
        "ess_per_s_each": {n: e / total_time for n, e in each.items()},
        "n_steps_last": fit.convergence.n_steps,
        "n_chains": fit.convergence.n_chains,
    }


# --------------------------------------------------------------------------- (b) baseline


class PlainForcePosterior:
    """Log posterior of (a, b, c, d, log sigma0, log r), paper basis, plain numpy, one walker a call."""

    def __init__(self, test: PressureTest, x0_m: float):
        from uq._models.cubic import FORCE_PRIOR_SD_N, NOISE_PRIOR_MEAN, NOISE_PRIOR_SD
        from uq._physics.quantities import BASIS_SCALE_M

        u = test.height_m - x0_m
        self.U = np.vander(u, 4, increasing=True)
        self.y = np.asarray(test.force_N, float)
        self.lsq, *_ = np.linalg.lstsq(self.U, self.y, rcond=None)
        self.ref2 = (self.U @ self.lsq) ** 2
        self.prior_sd = FORCE_PRIOR_SD_N / BASIS_SCALE_M ** np.arange(4)
        self.noise_mean = NOISE_PRIOR_MEAN[:2]
        self.noise_sd = NOISE_PRIOR_SD[:2]
        self.n = self.y.size

    def __call__(self, theta: np.ndarray) -> float:
        coef, log_s0, log_r = theta[:4], theta[4], theta[5]
        var = math.exp(2.0 * log_s0) + math.exp(2.0 * log_r) * self.ref2
        res = self.y - self.U @ coef
        ll = -0.5 * float(np.sum(res * res / var + np.log(var)))
        lp = -0.5 * float(np.sum((coef / self.prior_sd) ** 2))
        lp -= 0.5 * float(
            np.sum(((np.array([log_s0, log_r]) - self.noise_mean) / self.noise_sd) ** 2)
        )
        out = ll + lp
        return out if math.isfinite(out) else -math.inf

    def start(self, n_walkers: int, rng: np.random.Generator) -> np.ndarray:
        res = self.y - self.U @ self.lsq
        s2 = float(res @ res) / (self.n - 4)
        se = np.sqrt(np.diag(s2 * np.linalg.inv(self.U.T @ self.U)))
        center = np.concatenate(
            [self.lsq, [math.log(math.sqrt(s2) / math.sqrt(2.0)), math.log(0.005)]]
        )
        spread = np.concatenate([0.1 * se, [0.05, 0.05]])
        return center + spread * rng.standard_normal((n_walkers, 6))


def run_baseline(
    test: PressureTest,
    x0_m: float,
    *,
    seed: int,
    seconds: float,
    n_walkers: int = BASELINE_WALKERS,
    chunk: int = 100,
) -> dict:
    post = PlainForcePosterior(test, x0_m)
    rng = np.random.default_rng(seed)
    sampler = emcee.EnsembleSampler(n_walkers, 6, post, vectorize=False)  # default: stretch move
    sampler.random_state = np.random.RandomState(int(rng.integers(2**31))).get_state()
    state = post.start(n_walkers, rng)
    t0 = time.perf_counter()
    state = sampler.run_mcmc(state, chunk, progress=False)
    while time.perf_counter() - t0 < seconds:
        state = sampler.run_mcmc(state, chunk, progress=False)
    wall = time.perf_counter() - t0
    chain = sampler.get_chain()  # (steps, walkers, 6)
    n = chain.shape[0]
    tau = emcee.autocorr.integrated_time(chain[n // 5 :], tol=0, quiet=True)
    tau_max = float(np.max(tau)) if np.all(np.isfinite(tau)) else float(n)
    burn = min(max(int(math.ceil(5.0 * tau_max)), 20), n // 2)
    draws = np.swapaxes(chain[burn:], 0, 1)  # (walkers, draws, 6): a, b, c, d, log sigma0, log r
    # ESS by the project's own estimator (uq._inference.convergence.chain_diagnostics: the ensemble-mean chain, so
    # coupled walkers do not count as independent chains), as the project's ESS is measured
    stored = chain[burn:].reshape(1, -1, 6)  # one ensemble, storage order step x walker
    each = {}
    for j, name in enumerate(QUANTITIES):
        e = bulk_ess(stored[..., j], n_walkers)
        each[name] = e if np.isfinite(e) else 0.0
    ess = min(each[n] for n in FORCE_NAMES)
    return {
        "name": "baseline: plain emcee, stretch move, per-walker numpy log-prob over 6 parameters",
        "runs": 1,
        "wall_s": wall,
        "ess_bulk_min": ess,
        "ess_per_s": ess / wall,
        "ess_per_s_each": {n: e / wall for n, e in each.items()},
        "n_steps": n,
        "burn_in": burn,
        "n_walkers": n_walkers,
        "tau_max": tau_max,
        "acceptance": float(np.mean(sampler.acceptance_fraction)),
        "posterior_mean_force": dict(
            zip(FORCE_NAMES, draws[..., :4].reshape(-1, 4).mean(0).tolist(), strict=True)
        ),
    }


# --------------------------------------------------------------------------- memory and scale

MB = 1024.0  # ru_maxrss is in KiB on Linux
MIB = 1024.0 * 1024.0  # bytes of the "MB" of peak_rss_mb
SCALING_FACTORS = (1, 4, 16)
SCALING_BASE_STEP_MM = (
    5.0  # the paper's step: 37 points per test; 1.25 and 0.3125 mm give 4x and 16x
)
# Run in a child: the uq command, then its own peak RSS and that of its reaped children (Dask workers).
_CHILD = (
    "import json, resource, sys\n"
    "from uq._cli.main import main\n"
    "rc = main(sys.argv[2:])\n"
    "ru = lambda who: resource.getrusage(who).ru_maxrss / 1024.0\n"
    "open(sys.argv[1], 'w').write(json.dumps({'rc': rc, 'self_mb': ru(resource.RUSAGE_SELF), "
    "'children_mb': ru(resource.RUSAGE_CHILDREN)}))\n"
    "sys.exit(rc)\n"
)


def run_child(argv: list[str]) -> dict:
    """``uq ARGV`` in a fresh interpreter (cold: imports and JIT included): wall time and peak RSS.

    ``peak_rss_mb`` is the command's own process, ``children_peak_rss_mb`` the largest of the
    processes it started and reaped (the Dask workers of ``uq batch``; 0 without any)."""
    import json
    import os
    import subprocess
    import sys
    import tempfile

    fd, out = tempfile.mkstemp(suffix=".json")
    os.close(fd)
    try:
        t0 = time.perf_counter()
        proc = subprocess.run(
            [sys.executable, "-c", _CHILD, out, *map(str, argv), "--quiet"],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        wall = time.perf_counter() - t0
        r = json.loads(open(out).read() or "{}")
    finally:
        os.unlink(out)
    if proc.returncode not in (0, 1) or not r:
        raise RuntimeError(
            f"uq {argv[0]} failed in the bench (exit {proc.returncode}): {proc.stderr.strip()[-300:]}"
        )
    return {
        "command": "uq " + " ".join(map(str, argv)),
        "exit": proc.returncode,
        "wall_s": wall,
        "peak_rss_mb": r["self_mb"],
        "children_peak_rss_mb": r["children_mb"],
    }


class PeakRSS:
    """Peak resident memory of this process while the block runs (psutil, sampled every 10 ms)."""

    def __enter__(self):
        import threading

        import psutil

        self._proc = psutil.Process()
        self.before_mb = self.peak_mb = self._proc.memory_info().rss / MB**2
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._watch, daemon=True)
        self._thread.start()
        return self

    def _watch(self):
        while not self._stop.wait(0.01):
            self.peak_mb = max(self.peak_mb, self._proc.memory_info().rss / MB**2)

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()
        self.peak_mb = max(self.peak_mb, self._proc.memory_info().rss / MB**2)

    @property
    def added_mb(self) -> float:
        return self.peak_mb - self.before_mb


def _scaled_campaign(folder, factor: int, seed: int, pressures: tuple[float, ...]):
    from uq._data.recordings import read_recordings, write_recordings_csv
    from uq._stand.simulator import Layout, simulate

    step = SCALING_BASE_STEP_MM / factor
    tests = simulate("n50", seed=seed, layout=Layout(pressures, step_m=step * 1e-3))
    path = Path(folder) / f"x{factor}.csv"
    path.write_text(write_recordings_csv(tests, f"bench --scaling: step {step:g} mm"))
    return read_recordings(path), step


def scaling(
    *,
    seed: int,
    settings: Settings,
    pressures: tuple[float, ...] = (2.0, 5.0),
    factors=SCALING_FACTORS,
) -> dict:
    """``fit_campaign`` at 1x, 4x, 16x the points per test, one process; ratios against 1x.

    Each size is fitted once untimed with a 20-step chain first (JAX compiles per array shape),
    then timed. The adaptive chain length differs between runs, so the time per sampler step is
    given beside the wall time; memory is the peak RSS the fit added over the RSS before it."""
    import tempfile

    from uq._models.cubic_fit import fit_campaign

    rows = []
    with tempfile.TemporaryDirectory(prefix="uq-bench-scaling-") as tmp:
        for f in factors:
            rec, step = _scaled_campaign(tmp, f, seed, pressures)
            fit_campaign(
                rec,
                seed=seed,
                settings=Settings(
                    n_walkers=settings.n_walkers,
                    n_ensembles=settings.n_ensembles,
                    max_steps=20,
                    min_steps=20,
                ),
            )
            with PeakRSS() as mem:
                t0 = time.perf_counter()
                cf = fit_campaign(rec, seed=seed, settings=settings)
                wall = time.perf_counter() - t0
            steps = sum(int(t.convergence.n_steps) for t in cf.tests)
            rows.append(
                {
                    "factor": f,
                    "step_mm": step,
                    "points_per_test": rec.n_points / len(rec.tests),
                    "n_points": rec.n_points,
                    "wall_s": wall,
                    "sampler_steps": steps,
                    "ms_per_step": 1e3 * wall / steps,
                    "peak_rss_mb": mem.peak_mb,
                    "added_rss_mb": mem.added_mb,
                }
            )
    one = rows[0]
    for r in rows:
        r["points_ratio"] = r["n_points"] / one["n_points"]
        r["time_ratio"] = r["wall_s"] / one["wall_s"]
        r["per_step_time_ratio"] = r["ms_per_step"] / one["ms_per_step"]
        r["peak_rss_ratio"] = r["peak_rss_mb"] / one["peak_rss_mb"]
        r["added_rss_ratio"] = (
            r["added_rss_mb"] / one["added_rss_mb"] if one["added_rss_mb"] > 0 else math.nan
        )
    return {
        "workload": f"uq fit of a simulated n50 campaign at {', '.join(f'{p:g}' for p in pressures)} bar, "
        f"steps {', '.join(format(r['step_mm'], 'g') for r in rows)} mm, seed {seed}",
        "measure": "wall time after a JIT warm-up of the same shape; peak RSS of this process during the fit "
        "(psutil, 10 ms) and the part the fit added",
        "runs": rows,
    }


MEMORY_STEPS_MM = (0.3125, 0.15625, 0.078125)  # 6347, 12683, 25355 readings in 11 tests
RAMP_STEP_MM = 0.01  # the finest step uq simulate writes (docs/formats.md): 198011 readings


def memory_model(*, seed: int, steps_mm=MEMORY_STEPS_MM, extra=()) -> dict:
    """Peak RSS of ``uq fit`` (cold process) on simulated n50 campaigns of the default 11 tests at
    ``steps_mm``, the straight line through them (bytes per reading and a constant, least
    squares), and ``uq._io.memory.FIT``, the model the command checks campaigns against, beside
    it: its prediction at each size (it should not be below what was measured), at the 198k
    readings of a 0.01 mm ramp, and the largest campaign it lets this machine take now. Then
    ``uq fit --out`` at the first step: what it holds beyond the line, per reading of the largest
    test (one test's InferenceData and NetCDF bytes at a time), against ``FIT_OUT``."""
    import tempfile

    from uq._data.recordings import write_recordings_csv
    from uq._io.memory import FIT, FIT_OUT, GB, available_bytes
    from uq._stand.simulator import Layout, simulate

    def readings(step_mm):
        layout = Layout(step_m=step_mm * 1e-3)
        return len(layout.heights()[0]) * len(layout.pressures_bar)

    runs = []
    old = os.environ.get("UQ_MEMORY_GB")
    os.environ["UQ_MEMORY_GB"] = "off"  # measure, do not refuse
    try:
        with tempfile.TemporaryDirectory(prefix="uq-bench-memory-") as tmp:
            for step in steps_mm:
                tests = simulate("n50", seed=seed, layout=Layout(step_m=step * 1e-3))
                csv = Path(tmp) / f"step{step:g}.csv"
                csv.write_text(write_recordings_csv(tests, f"bench --memory: step {step:g} mm"))
                r = run_child(["fit", csv, "--seed", seed, *extra])
                n = readings(step)
                runs.append(
                    {
                        "step_mm": step,
                        "readings": n,
                        "tests": len(tests),
                        "wall_s": r["wall_s"],
                        "peak_rss_mb": r["peak_rss_mb"],
                        "fit_model_mb": FIT.peak_bytes(n) / MIB,
                    }
                )
            step = steps_mm[0]
            out = run_child(
                ["fit", Path(tmp) / f"step{step:g}.csv", "--seed", seed, "--out", Path(tmp) / "o"]
                + list(extra)
            )
    finally:
        if old is None:
            os.environ.pop("UQ_MEMORY_GB", None)
        else:
            os.environ["UQ_MEMORY_GB"] = old
    n = np.array([r["readings"] for r in runs], float)
    peak = np.array([r["peak_rss_mb"] for r in runs]) * MIB  # bytes
    slope, constant = np.polyfit(n, peak, 1) if len(runs) > 1 else (math.nan, peak[0])
    for r, m in zip(runs, peak, strict=True):
        r["line_error_mb"] = float((constant + slope * r["readings"] - m) / MIB)
    ramp = readings(RAMP_STEP_MM)
    room = available_bytes()
    first = runs[0]
    per_test = first["readings"] // first["tests"]  # the tests have equal readings
    held = out["peak_rss_mb"] * MIB - (constant + slope * first["readings"])
    saving = {
        "step_mm": steps_mm[0],
        "readings": first["readings"],
        "largest_test": per_test,
        "wall_s": out["wall_s"],
        "peak_rss_mb": out["peak_rss_mb"],
        "measured_bytes_per_test_reading": float(held / per_test),
        "fit_out_model_mb": FIT_OUT.peak_bytes(first["readings"], per_test) / MIB,
        "model_bytes_per_test_reading": FIT_OUT.bytes_per_test_reading,
        "ramp_model_gb": FIT_OUT.peak_bytes(ramp, ramp // first["tests"]) / GB,
    }
    return {
        "workload": f"uq fit (cold process) of simulated n50 campaigns, 11 tests (0.1-10 bar), steps "
        f"{', '.join(format(s, 'g') for s in steps_mm)} mm, seed {seed}",
        "runs": runs,
        "measured_bytes_per_reading": float(slope),
        "measured_constant_gb": float(constant / GB),
        "model": {
            "bytes_per_reading": FIT.bytes_per_reading,
            "constant_gb": FIT.constant_bytes / GB,
            "covers_every_run": bool(all(r["fit_model_mb"] >= r["peak_rss_mb"] for r in runs)),
        },
        "ramp": {
            "step_mm": RAMP_STEP_MM,
            "readings": ramp,
            "model_gb": FIT.peak_bytes(ramp) / GB,
            "line_gb": float((constant + slope * ramp) / GB),
        },
        "available_gb": None if room is None else room / GB,
        "largest_readings_now": None if room is None else FIT.largest(room),
        "out": saving,
        "largest_readings_now_out": None
        if room is None
        else FIT_OUT.largest(room, 1 / first["tests"]),
    }


def report_memory(seed: int) -> dict:
    """``uq report`` on the paper's campaign (virtual stand, as data/n50) in a fresh process: time and peak RSS."""
    import tempfile

    from uq._data.recordings import write_recordings_csv
    from uq._stand.simulator import simulate

    with tempfile.TemporaryDirectory(prefix="uq-bench-report-") as tmp:
        csv = Path(tmp) / "n50.csv"
        csv.write_text(
            write_recordings_csv(simulate("n50", seed=seed), "bench: the paper's campaign")
        )
        return run_child(["report", csv, "--out", Path(tmp) / "report", "--seed", seed]) | {
            "workload": f"uq report of the paper's campaign from the virtual stand (11 tests, seed {seed}), cold process"
        }


def batch_scaling(
    sizes: tuple[int, ...], *, seed: int, settings: Settings, serial_n: int | None = None
) -> dict:
    """``uq batch``'s default run (this process, the fits batched, ``run_batched``) of the first
    n simulated campaigns for each n in ``sizes``, against ``--serial`` (each campaign fitted on
    its own, ``run_serial``) of the first ``serial_n`` (default the smallest n), all in this
    process after one warm-up of each (compilation and imports are not in the numbers): wall and
    CPU seconds per campaign, their ratio, and a straight line through the batched runs' wall
    times (the cost per campaign is its slope). The fit task with the catalogue's default outputs
    (no pointwise groups), plus one batched run of the smallest n with ``pointwise = yes``."""
    import resource
    import tempfile

    from uq._drivers import batch as B
    from uq._io import progress

    progress.set_enabled(False)
    sizes = tuple(sorted(set(sizes)))
    serial_n = serial_n or sizes[0]
    extra = {}
    if settings.n_walkers != Settings.n_walkers:
        extra["walkers"] = settings.n_walkers
    if settings.max_steps != Settings.max_steps:
        extra["max_steps"] = settings.max_steps
    with tempfile.TemporaryDirectory(prefix="uq-bench-batch-") as tmp:
        cat = bench_catalogue(tmp, max(sizes + (serial_n,)), seed=seed, options=extra)
        campaigns = B.read_catalogue(cat)

        def jobs(n: int, tag: str, **options) -> list[dict]:
            js = B.jobs_of(campaigns[:n], Path(tmp) / tag)
            for j in js:
                j["options"] |= options
            return js

        def timed(run, js) -> dict:
            w, c = time.perf_counter(), time.process_time()
            rows = run(js)
            w, c = time.perf_counter() - w, time.process_time() - c
            out = Path(js[0]["out"]).parents[1]
            size = sum(f.stat().st_size for f in out.rglob("*") if f.is_file())
            return {
                "campaigns": len(js),
                "wall_s": w,
                "cpu_s": c,
                "wall_per_campaign_s": w / len(js),
                "cpu_per_campaign_s": c / len(js),
                "done": sum(r["status"] == "done" for r in rows),
                "converged": sum(bool(r["converged"]) for r in rows),
                "mb_per_campaign": size / len(js) / 1e6,
                "load_average_1min": os.getloadavg()[0],
            }

        B.run_serial(jobs(2, "warm-serial"))  # compilation, imports, caches: out of the numbers
        B.run_batched(jobs(2, "warm-batched"))
        serial = timed(B.run_serial, jobs(serial_n, "serial"))
        batched = [timed(B.run_batched, jobs(n, f"batched-{n}")) for n in sizes]
        pointwise = timed(B.run_batched, jobs(sizes[0], "pointwise", pointwise=True))
        files = netcdf_costs(
            B.fit_campaign(B._recordings(jobs(1, "x")[0]), seed=seed, settings=settings)
        )
    n = np.array([r["campaigns"] for r in batched], float)
    wall = np.array([r["wall_s"] for r in batched])
    cpu = np.array([r["cpu_s"] for r in batched])
    slope, intercept = np.polyfit(n, wall, 1) if len(n) > 1 else (wall[0] / n[0], 0.0)
    cpu_slope, cpu_intercept = np.polyfit(n, cpu, 1) if len(n) > 1 else (cpu[0] / n[0], 0.0)
    same = next(r for r in batched if r["campaigns"] == min(sizes))
    return {
        "workload": f"simulated n50 campaigns (2 and 5 bar, 5 mm steps, 74 points each), task fit, "
        f"seeds {seed}..., uq batch in one process",
        "batch_campaigns": B.BATCH_CAMPAIGNS,
        "sizes": list(sizes),
        "serial": serial,
        "batched": batched,
        "pointwise": pointwise,
        "netcdf": files,
        "ratio_serial_to_batched": serial["wall_per_campaign_s"] / same["wall_per_campaign_s"],
        "cpu_ratio_serial_to_batched": serial["cpu_per_campaign_s"] / same["cpu_per_campaign_s"],
        "line": {"seconds_per_campaign": float(slope), "intercept_s": float(intercept)},
        "predicted_1000_min": float((intercept + 1000 * slope) / 60),
        "cpu_line": {"seconds_per_campaign": float(cpu_slope), "intercept_s": float(cpu_intercept)},
        "predicted_1000_cpu_min": float((cpu_intercept + 1000 * cpu_slope) / 60),
        "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "note": "wall and CPU time (all threads of this process) of the batch's work after a "
        "warm-up (imports "
        "and JIT compilation of the first campaigns excluded); one process, the fits of up to "
        f"{B.BATCH_CAMPAIGNS} campaigns per sampling run",
    }


def cores() -> int:
    import os

    return (
        len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    )


def margin_speed(
    *, seed: int, settings: Settings, recordings: str | None = None, n_queries: int = 100
) -> dict:
    """``uq margin``: one full query (fit + choice + answer) against the same query from the saved file.

    All in this process, in the order a user meets them: the full query first (JAX compilation
    included, as in a fresh ``uq margin`` run), then the answer saved with ``--save-fit``'s
    writer, then the same query answered from the file (load + answer), then ``n_queries``
    queries from one load of the file (heights and pressures spread over the tested ranges,
    each with a force band and a usable stroke, as the reference query). A cold ``uq margin
    --fit`` in a fresh interpreter (imports included) is timed as well."""
    import tempfile

    from uq._data.recordings import read_recordings, write_recordings_csv
    from uq._data.stand_description import PAPER_STAND
    from uq._derived.comparison import fit_and_choose
    from uq._derived.margin import load_answer, margin
    from uq._io.files import dumps_json
    from uq._stand.simulator import simulate

    with tempfile.TemporaryDirectory(prefix="uq-bench-margin-") as tmp:
        if recordings is None:
            csv = Path(tmp) / "n50.csv"
            csv.write_text(
                write_recordings_csv(
                    simulate("n50", seed=seed), "bench --margin: the paper's campaign"
                )
            )
            what = (
                f"the paper's campaign from the virtual stand (11 tests, seed {seed}), as data/n50"
            )
        else:
            csv, what = Path(recordings), f"{recordings}"
        t0 = time.perf_counter()
        rec = read_recordings(csv)
        ans, info, diagnostics = fit_and_choose(
            rec, model="auto", seed=seed, settings=settings, stand=PAPER_STAND
        )
        t_fit = time.perf_counter() - t0
        plo, phi = ans.pressure_range_bar
        if recordings is None:
            h, load, pb = 0.112, 13020.0, 5.0  # the documented query (docs/surface.md)
        else:
            h, pb = rec.x0_m, (plo + phi) / 2
            load = float(ans.force_draws(h, pb).mean())
        query = {
            "height_m": h,
            "load_N": load,
            "prob": 0.95,
            "pressure_bar": pb,
            "tolerance_pct": 10.0,
        }

        def ask(a, i, q=query):
            return margin(
                a,
                q["height_m"],
                q["load_N"],
                q["prob"],
                pressure_bar=q["pressure_bar"],
                tolerance_pct=q["tolerance_pct"],
                model_info=i,
            )

        t0 = time.perf_counter()
        full = ask(ans, info)
        t_answer = time.perf_counter() - t0
        path = Path(tmp) / "fit.nc"
        t0 = time.perf_counter()
        ans.save(
            path,
            written_by="benchmarks/bench.py --margin",
            model_info=info,
            converged=diagnostics["converged"],
            warnings=diagnostics["warnings"],
        )
        t_save = time.perf_counter() - t0
        t0 = time.perf_counter()
        ans2, info2, _ = load_answer(path)
        t_load = time.perf_counter() - t0
        t0 = time.perf_counter()
        again = ask(ans2, info2)
        t_again = time.perf_counter() - t0

        queries = _spread_queries(ans2, n_queries, seed)
        t0 = time.perf_counter()
        many_ans, many_info, _ = load_answer(path)
        for q in queries:
            ask(many_ans, many_info, q)
        t_many = time.perf_counter() - t0
        cold = run_child(
            [
                "margin",
                "--fit",
                path,
                "--height-mm",
                h * 1e3,
                "--load-N",
                load,
                "--pressure-bar",
                pb,
                "--tolerance-pct",
                10,
            ]
        )
        size = path.stat().st_size
    full_s, saved_s = t_fit + t_answer, t_load + t_again
    return {
        "workload": f"uq margin on {what}: {load:g} N at {h * 1e3:g} mm, force band at {pb:g} bar, stroke within 10 %",
        "answered_by": info["name"],
        "settings": {
            "walkers": settings.n_walkers,
            "ensembles": settings.n_ensembles,
            "max_steps": settings.max_steps,
        },
        "full_query": {
            "wall_s": full_s,
            "fit_and_choice_s": t_fit,
            "answer_s": t_answer,
            "note": "read, fit both models, PSIS-LOO comparison, answer; JAX compilation included",
        },
        "save_s": t_save,
        "saved_file_bytes": size,
        "from_saved_file": {"wall_s": saved_s, "load_s": t_load, "answer_s": t_again},
        "identical_answer": dumps_json(full) == dumps_json(again),
        "ratio_full_to_saved": full_s / saved_s,
        "queries_from_saved_file": {
            "n": n_queries,
            "wall_s": t_many,
            "per_query_s": t_many / n_queries,
            "note": "one load of the file, then each query with a force band and a usable stroke",
        },
        "cold_cli_from_saved_file": cold,
        "measure": "wall time in this process (perf_counter) unless named cold: a fresh interpreter, imports included",
    }


def _spread_queries(ans, n: int, seed: int) -> list[dict]:
    """n margin queries spread over the middle 70 % of the tested heights and pressures, each at the
    mean posterior force there (a load the spring can carry)."""
    rng = np.random.default_rng(seed)
    (lo, hi), (plo, phi) = ans.height_range_m, ans.pressure_range_bar
    queries = []
    for _ in range(n):
        x = float(rng.uniform(lo + 0.15 * (hi - lo), hi - 0.15 * (hi - lo)))
        p = float(rng.uniform(plo + 0.15 * (phi - plo), phi - 0.15 * (phi - plo)))
        queries.append(
            {
                "height_m": x,
                "pressure_bar": p,
                "prob": 0.95,
                "tolerance_pct": 10.0,
                "load_N": float(ans.force_draws(x, p).mean()),
            }
        )
    return queries


def bench(
    *,
    seconds: float,
    seed: int,
    settings: Settings | None = None,
    recordings: str | None = None,
    pressure_bar: float = BENCH_PRESSURE_BAR,
    baseline_walkers: int = BASELINE_WALKERS,
) -> dict:
    settings = settings or Settings()
    test, x0_m, what = bench_test(seed, recordings, pressure_bar)
    project = run_project(test, x0_m, seed=seed, seconds=seconds, settings=settings)
    baseline = run_baseline(
        test, x0_m, seed=seed, seconds=max(seconds, project["wall_s"]), n_walkers=baseline_walkers
    )

    def ratio_of(p, b):
        return p / b if b > 0 else math.inf

    each = {
        n: ratio_of(project["ess_per_s_each"][n], baseline["ess_per_s_each"][n]) for n in QUANTITIES
    }
    return {
        "workload": what,
        "n_points": test.n_points,
        "seed": seed,
        "measure": "min over a_P, b_P, c_P, d_P of ArviZ bulk ESS / wall time (s), after JIT warm-up; "
        "ratio_each: the ratio of ESS/s of every reported quantity of the force posterior",
        "project": project,
        "baseline": baseline,
        "ratio": ratio_of(project["ess_per_s"], baseline["ess_per_s"]),
        "ratio_each": each,
        "ratio_min_all": min(each.values()),
    }


def netcdf_costs(fit, repeats: int = 5) -> dict:
    """Seconds (best of ``repeats``) and bytes of one test's NetCDF file (the last test of
    ``fit``) written six ways: as two rounds ago (group after group through h5netcdf, zlib on
    every number), group after group without zlib on floats, in one pass through h5netcdf (the
    way until the netCDF4 engine, with and without the pointwise groups), and as now
    (``uq._io.netcdf.netcdf_bytes``: the netCDF-C library in memory), with and without the
    pointwise groups (``uq batch``'s default)."""
    import io

    import xarray as xr

    from uq._io.netcdf import netcdf_bytes

    test = fit.tests[-1]
    idata = test.idata
    groups = {g: getattr(idata, g) for g in idata.groups()}
    attrs = dict(idata.attrs)

    def by_group(zlib_floats: bool) -> bytes:
        buf, mode = io.BytesIO(), "w"
        xr.Dataset(attrs=attrs).to_netcdf(buf, mode=mode, engine="h5netcdf", group="/")
        for g, d in groups.items():
            kinds = "biuSfc" if zlib_floats else "biuS"
            enc = {k: {"zlib": True} for k, v in d.variables.items() if v.dtype.kind in kinds}
            d.to_netcdf(buf, mode="a", group=f"/{g}", engine="h5netcdf", encoding=enc)
        return buf.getvalue()

    def h5netcdf_one_pass(gs: dict, at: dict) -> bytes:
        buf = io.BytesIO()
        tree = {"/": xr.Dataset(attrs=at)} | {f"/{g}": d for g, d in gs.items()}
        enc = {
            f"/{g}": {k: {"zlib": True} for k, v in d.variables.items() if v.dtype.kind in "biuS"}
            for g, d in gs.items()
        }
        xr.DataTree.from_dict(tree).to_netcdf(buf, engine="h5netcdf", encoding=enc)
        return buf.getvalue()

    slim = test.posterior.draws_idata()
    slim_groups, slim_attrs = {g: getattr(slim, g) for g in slim.groups()}, dict(slim.attrs)
    ways = {
        "by_group_zlib": lambda: by_group(True),
        "by_group_no_float_zlib": lambda: by_group(False),
        "one_pass_h5netcdf": lambda: h5netcdf_one_pass(groups, attrs),
        "one_pass_h5netcdf_no_pointwise": lambda: h5netcdf_one_pass(slim_groups, slim_attrs),
        "one_pass": lambda: netcdf_bytes(groups, attrs),
        "one_pass_no_pointwise": lambda: netcdf_bytes(slim_groups, slim_attrs),
    }
    out = {}
    for name, write in ways.items():
        best, size = math.inf, 0
        for _ in range(repeats):
            t0 = time.perf_counter()
            size = len(write())
            best = min(best, time.perf_counter() - t0)
        out[name] = {"seconds": best, "mb": size / 1e6}
    return out


def bench_catalogue(
    folder,
    n: int,
    *,
    seed: int = 20201,
    pressures: str = "2,5",
    step_mm: float = 5.0,
    options: dict | None = None,
) -> Path:
    """``n`` simulated campaigns (virtual stand, seeds seed+i) and a catalogue running ``fit`` on
    each, with the catalogue ``options`` (e.g. walkers) for every campaign."""
    from uq._data.recordings import write_recordings_csv
    from uq._io.files import write_text_atomic
    from uq._stand.simulator import Layout, simulate

    folder = Path(folder)
    layout = Layout(tuple(float(p) for p in pressures.split(",")), step_m=step_mm * 1e-3)
    options = options or {}
    rows = [",".join(["name", "file", "tasks", "seed", *options])]
    for i in range(n):
        tests = simulate("n50", seed=seed + i, layout=layout)
        write_text_atomic(
            folder / f"c{i:04d}.csv",
            write_recordings_csv(tests, f"benchmark campaign {i}, seed {seed + i}"),
        )
        rows.append(
            ",".join(
                [f"c{i:04d}", f"c{i:04d}.csv", "fit", str(seed + i), *map(str, options.values())]
            )
        )
    return write_text_atomic(folder / "catalogue.csv", "\n".join(rows) + "\n")


# --------------------------------------------------------------------------- the script


def summary(r: dict) -> str:
    p, b = r["project"], r["baseline"]
    return "\n".join(
        [
            f"bench: {r['workload']}, {r['n_points']} points; force posterior, min bulk ESS of a_P..d_P per second",
            f"  project  : {p['ess_per_s']:10.1f} ESS/s  ({p['ess_bulk_min']:.0f} ESS in {p['wall_s']:.2f} s, {p['runs']} run(s))",
            f"  baseline : {b['ess_per_s']:10.1f} ESS/s  ({b['ess_bulk_min']:.0f} ESS in {b['wall_s']:.2f} s, "
            f"{b['n_steps']} steps x {b['n_walkers']} walkers, tau {b['tau_max']:.0f})",
            f"  ratio project / baseline: {r['ratio']:.1f}",
            "  per quantity: "
            + ", ".join(f"{n} {v:.1f}" for n, v in r["ratio_each"].items())
            + f"; smallest {r['ratio_min_all']:.1f}",
        ]
    )


#: --scaling on the console: the ratios of the time a step and of the memory the fit adds, too
SCALING_CONSOLE = (
    ("step ratio", lambda x: f"x{x['per_step_time_ratio']:.2f}"),
    ("added ratio", lambda x: f"x{x['added_rss_ratio']:.2f}"),
)


def scale_summary(name: str, r: dict) -> str:
    if name == "margin":
        f, s, m, c = (
            r["full_query"],
            r["from_saved_file"],
            r["queries_from_saved_file"],
            r["cold_cli_from_saved_file"],
        )
        return "\n".join(
            [
                f"bench --margin: {r['workload']}; {r['cores']} cores, load average {r['load_average_1min']:.1f}",
                f"  full query (fit + answer) : {f['wall_s']:8.2f} s (answered by the {r['answered_by']})",
                f"  from the saved file       : {s['wall_s']:8.3f} s (load {s['load_s']:.3f} s, answer {s['answer_s']:.3f} s); "
                f"identical answer: {r['identical_answer']}",
                f"  ratio {r['ratio_full_to_saved']:.0f}x; {m['n']} queries from the saved file {m['wall_s']:.2f} s "
                f"({m['per_query_s']:.3f} s a query)",
                f"  cold uq margin --fit (fresh interpreter, imports included): {c['wall_s']:.1f} s",
            ]
        )
    if name == "memory":
        m, ramp = r["model"], r["ramp"]
        lines = [f"bench --memory: {r['workload']}; load average {r['load_average_1min']:.1f}"]
        lines += table(
            MEMORY + (("wall time", lambda x: f"{x['wall_s']:.0f} s"),), r["runs"], False
        )
        room = r["available_gb"]
        lines += [
            f"  measured: {r['measured_bytes_per_reading'] / 1e3:.1f} kB a reading + "
            f"{r['measured_constant_gb']:.2f} GB; uq fit's model: {m['bytes_per_reading'] / 1e3:.0f} kB "
            f"a reading + {m['constant_gb']:.2f} GB (covers every run: {m['covers_every_run']})",
            f"  a {ramp['step_mm']:g} mm ramp, {ramp['readings']} readings: {ramp['model_gb']:.1f} GB by "
            f"the model, {ramp['line_gb']:.1f} GB by the measured line",
            "  available now: unknown"
            if room is None
            else f"  available now: {room:.1f} GB, so at most {r['largest_readings_now']} readings "
            f"({r['largest_readings_now_out']} with --out)",
        ]
        o = r["out"]
        lines.append(
            f"  uq fit --out at {o['readings']} readings ({o['largest_test']} in the largest test): "
            f"peak RSS {o['peak_rss_mb']:.0f} MB, {o['measured_bytes_per_test_reading'] / 1e3:.0f} kB "
            f"a reading of the largest test above the line; model {o['fit_out_model_mb']:.0f} MB "
            f"({o['model_bytes_per_test_reading'] / 1e3:.0f} kB); the ramp with --out "
            f"{o['ramp_model_gb']:.1f} GB by the model"
        )
        return "\n".join(lines)
    if name == "batch":
        s, p, line = r["serial"], r["pointwise"], r["line"]
        lines = [
            f"bench --batch: {r['workload']}; {r['cores']} cores, load average {r['load_average_1min']:.1f}",
            f"  --serial        : {s['campaigns']:5d} campaigns {s['wall_per_campaign_s']:6.2f} s a campaign "
            f"(CPU {s['cpu_per_campaign_s']:.2f} s)",
        ]
        lines += [
            f"  batched (default): {b['campaigns']:5d} campaigns {b['wall_per_campaign_s']:6.2f} s a campaign "
            f"(CPU {b['cpu_per_campaign_s']:.2f} s), {b['converged']} converged, {b['mb_per_campaign']:.1f} MB a campaign"
            for b in r["batched"]
        ]
        lines += [
            f"  pointwise = yes  : {p['campaigns']:5d} campaigns {p['wall_per_campaign_s']:6.2f} s a campaign, "
            f"{p['mb_per_campaign']:.1f} MB a campaign",
            "  one test's NetCDF: "
            + "; ".join(
                f"{k} {v['seconds']:.2f} s {v['mb']:.1f} MB" for k, v in r["netcdf"].items()
            ),
            f"  ratio --serial / batched {r['ratio_serial_to_batched']:.2f} (CPU {r['cpu_ratio_serial_to_batched']:.2f}); "
            f"line {line['seconds_per_campaign']:.2f} s a campaign + {line['intercept_s']:.1f} s: 1000 campaigns "
            f"{r['predicted_1000_min']:.1f} min; CPU line {r['cpu_line']['seconds_per_campaign']:.2f} s a "
            f"campaign: 1000 campaigns {r['predicted_1000_cpu_min']:.1f} CPU min; peak RSS {r['peak_rss_mb']:.0f} MB",
        ]
        return "\n".join(lines)
    lines = [f"bench --scaling: {r['workload']}; load average {r['load_average_1min']:.1f}"]
    lines += table(SCALING + SCALING_CONSOLE, r["runs"], False)
    rep = r["report"]
    lines.append(
        f"  uq report (paper's campaign, cold process): {rep['wall_s']:.1f} s, peak RSS {rep['peak_rss_mb']:.0f} MB"
    )
    return "\n".join(lines)


def _seconds(text: str) -> float:
    value = float(text)
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"expected a non-negative number of seconds, got {text}")
    return value


def _sizes(text: str) -> tuple[int, ...]:
    try:
        sizes = tuple(int(t) for t in text.split(","))
    except ValueError:
        sizes = ()
    if not sizes or min(sizes) < 1:
        raise argparse.ArgumentTypeError(f"expected campaign counts like 20,100, got {text}")
    return sizes


def _positive_int(text: str) -> int:
    value = int(text)
    if value <= 0:
        raise argparse.ArgumentTypeError(f"expected a positive whole number, got {text}")
    return value


def _steps_mm(text: str) -> tuple[float, ...]:
    try:
        steps = tuple(float(s) for s in text.split(","))
    except ValueError:
        steps = ()
    if len(steps) < 2 or not all(math.isfinite(s) and s > 0 for s in steps):
        raise argparse.ArgumentTypeError(
            f"expected two or more positive steps in mm, comma-separated, got {text}"
        )
    return steps


def _baseline_walkers(text: str) -> int:
    value = int(text)
    if value < 12 or value % 2:
        raise argparse.ArgumentTypeError(
            f"an even number of at least 12 walkers (2 x 6 parameters) is needed, got {text}"
        )
    return value


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="benchmarks/bench.py",
        description=__doc__.splitlines()[0],
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument(
        "--seconds",
        type=_seconds,
        default=10.0,
        help="minimum timed wall time of each sampler, s (the project runs whole fits)",
    )
    p.add_argument("--seed", type=int, default=20201, help="workload and samplers")
    p.add_argument(
        "--recordings", metavar="FILE", help="the test (or campaign, --margin) from this CSV"
    )
    p.add_argument(
        "--pressure-bar", type=float, default=BENCH_PRESSURE_BAR, help="pressure of the test"
    )
    p.add_argument(
        "--walkers", type=_positive_int, default=Settings.n_walkers, help="project: walkers"
    )
    p.add_argument(
        "--max-steps",
        type=_positive_int,
        default=Settings.max_steps,
        help="project: cap on emcee steps per ensemble",
    )
    p.add_argument(
        "--baseline-walkers",
        type=_baseline_walkers,
        default=BASELINE_WALKERS,
        help="baseline: emcee walkers (>= 12, even)",
    )
    p.add_argument(
        "--json",
        metavar="PATH",
        help="write the result to PATH ('-' for stdout); nothing is written without it",
    )
    mode = p.add_mutually_exclusive_group()
    mode.add_argument(
        "--scaling",
        action="store_true",
        help="instead: uq fit at --factors times the points per test (time and peak-RSS ratios) "
        "and the peak RSS of uq report on the paper's campaign",
    )
    p.add_argument(
        "--factors",
        default=",".join(map(str, SCALING_FACTORS)),
        help="--scaling: points-per-test factors (the step is 5 mm / factor)",
    )
    mode.add_argument(
        "--batch",
        type=_sizes,
        metavar="N[,N...]",
        help="instead: uq batch (one process, fits batched) of N simulated campaigns for each N, "
        "against --serial of the smallest N: seconds a campaign and its line",
    )
    mode.add_argument(
        "--margin",
        action="store_true",
        help="instead: one full uq margin query (fit + answer) against the same query and 100 "
        "queries from a saved fit; the campaign is --recordings or the paper's",
    )
    mode.add_argument(
        "--memory",
        action="store_true",
        help="instead: peak RSS of uq fit at --steps-mm, bytes per reading and a constant, against "
        "the model uq fit checks campaigns with (uq._io.memory.FIT)",
    )
    p.add_argument(
        "--steps-mm",
        type=_steps_mm,
        default=MEMORY_STEPS_MM,
        help="--memory: the height steps of the three (or more) campaigns",
    )
    p.add_argument(
        "--queries", type=_positive_int, default=100, help="--margin: queries from the saved fit"
    )
    return p


def measure(args) -> tuple[str, dict]:
    """Run the benchmark the options ask for: (its name, its result)."""
    settings = Settings(n_walkers=args.walkers, max_steps=args.max_steps)
    settings.validate()
    record = {"load_average_1min": os.getloadavg()[0], "cores": cores()}
    if args.scaling:
        factors = tuple(int(f) for f in args.factors.split(","))
        r = scaling(seed=args.seed, settings=settings, factors=factors)
        return "scaling", record | r | {"report": report_memory(args.seed)}
    if args.batch:
        return "batch", record | batch_scaling(args.batch, seed=args.seed, settings=settings)
    if args.memory:
        steps = args.steps_mm
        extra = [] if args.max_steps == Settings.max_steps else ["--max-steps", args.max_steps]
        extra += [] if args.walkers == Settings.n_walkers else ["--walkers", args.walkers]
        return "memory", record | memory_model(seed=args.seed, steps_mm=steps, extra=extra)
    if args.margin:
        from uq._models import registry

        # the default model samples its noise
        settings.require_walkers(registry.entry(registry.default("margin")).n_sampled)
        r = margin_speed(
            seed=args.seed, settings=settings, recordings=args.recordings, n_queries=args.queries
        )
        return "margin", record | r
    r = bench(
        seconds=args.seconds,
        seed=args.seed,
        settings=settings,
        recordings=args.recordings,
        pressure_bar=args.pressure_bar,
        baseline_walkers=args.baseline_walkers,
    )
    return "ess", record | r


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    try:
        name, r = measure(args)
        emit_json(r, args.json)
    except InputError as exc:
        print(f"benchmarks/bench.py: error: {exc}", file=sys.stderr)
        return 2
    text = summary(r) if name == "ess" else scale_summary(name, r)
    where = f"\n  written to {args.json}" if args.json not in (None, "-") else ""
    print(text + where, file=sys.stderr if args.json == "-" else sys.stdout)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
