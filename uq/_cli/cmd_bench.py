"""``uq bench``: the options and the printed summaries of uq._drivers.bench (the measurements live there)."""

from __future__ import annotations

import math
import os
from pathlib import Path

from uq._cli.common import positive_float, positive_int, say, seed
from uq._drivers import bench as B  # looked up at call time: tests may replace its functions
from uq._inference.sampler import Settings
from uq._io.errors import InputError
from uq._io.files import emit_json


def summary(r: dict) -> str:
    p, b = r["project"], r["baseline"]
    return "\n".join(
        [
            f"uq bench: {r['workload']}, {r['n_points']} points; force posterior, min bulk ESS of a_P..d_P per second",
            f"  project  : {p['ess_per_s']:10.1f} ESS/s  ({p['ess_bulk_min']:.0f} ESS in {p['wall_s']:.2f} s, {p['runs']} run(s))",
            f"  baseline : {b['ess_per_s']:10.1f} ESS/s  ({b['ess_bulk_min']:.0f} ESS in {b['wall_s']:.2f} s, "
            f"{b['n_steps']} steps x {b['n_walkers']} walkers, tau {b['tau_max']:.0f})",
            f"  ratio project / baseline: {r['ratio']:.1f}",
            "  per quantity: "
            + ", ".join(f"{n} {v:.1f}" for n, v in r["ratio_each"].items())
            + f"; smallest {r['ratio_min_all']:.1f}",
        ]
    )


def configure_bench(p) -> None:
    p.add_argument(
        "--seconds",
        type=float,
        default=10.0,
        help="minimum timed wall time of each sampler, s (default 10; the project runs whole fits)",
    )
    p.add_argument(
        "--seed",
        type=seed,
        default=20201,
        help="random seed (workload and samplers; default 20201)",
    )
    p.add_argument(
        "--recordings",
        metavar="FILE",
        help="take the test from this recordings CSV instead of the virtual stand",
    )
    p.add_argument(
        "--pressure-bar",
        type=positive_float,
        default=B.BENCH_PRESSURE_BAR,
        help="pressure of the test (default 5)",
    )
    p.add_argument(
        "--walkers",
        type=positive_int,
        default=Settings.n_walkers,
        help="project: emcee walkers per ensemble",
    )
    p.add_argument(
        "--max-steps",
        type=positive_int,
        default=Settings.max_steps,
        help="project: cap on emcee steps per ensemble",
    )
    p.add_argument(
        "--baseline-walkers",
        type=positive_int,
        default=B.BASELINE_WALKERS,
        help="baseline: emcee walkers (>= 12, even)",
    )
    p.add_argument(
        "--json", metavar="PATH", help="write the machine-readable result to PATH ('-' for stdout)"
    )
    p.add_argument(
        "--scaling",
        action="store_true",
        help="instead: uq fit at 1x, 4x, 16x the points per test (time and peak-RSS ratios) and the peak RSS of "
        "uq report, written to BENCH_DIR/scaling.json",
    )
    p.add_argument(
        "--batch",
        type=positive_int,
        metavar="N",
        help="instead: uq batch of N simulated campaigns on a LocalCluster against one process, written to "
        "BENCH_DIR/batch.json (speed-up, peak RSS)",
    )
    p.add_argument(
        "--margin",
        action="store_true",
        help="instead: one full uq margin query (fit + answer) against the same query and 100 queries from "
        "a saved fit (--fit), written to BENCH_DIR/margin.json; the campaign is --recordings or the "
        "paper's from the virtual stand",
    )
    p.add_argument(
        "--bench-dir",
        default="reports/bench",
        metavar="BENCH_DIR",
        help="folder for ess.json, scaling.json, batch.json and margin.json",
    )


def command_scale(args) -> int:
    """``uq bench --scaling`` and/or ``--batch N``: memory and scale, each result in its own JSON file."""
    settings = Settings(n_walkers=args.walkers, max_steps=args.max_steps)
    settings.validate()
    results = {}
    if args.scaling:
        results["scaling"] = B.scaling(seed=args.seed, settings=settings) | {
            "report": B.report_memory(args.seed)
        }
    if args.batch:
        results["batch"] = B.batch_speedup(args.batch, seed=args.seed)
    if args.margin:
        from uq._models.surface import NOISE_NAMES

        settings.require_walkers(
            len(NOISE_NAMES)
        )  # the surface model samples five noise parameters
        results["margin"] = B.margin_speed(
            seed=args.seed, settings=settings, recordings=args.recordings
        )
    for name, r in results.items():
        r = {"load_average_1min": os.getloadavg()[0], "cores": B.cores()} | r
        emit_json(r, str(Path(args.bench_dir) / f"{name}.json"))
        say(
            scale_summary(name, r) + f"\n  written to {Path(args.bench_dir) / f'{name}.json'}",
            args.json,
        )
    emit_json(results, args.json)
    return 0


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
                f"uq bench --margin: {r['workload']}; {r['cores']} cores, load average {r['load_average_1min']:.1f}",
                f"  full query (fit + answer) : {f['wall_s']:8.2f} s (answered by the {r['answered_by']})",
                f"  from the saved file       : {s['wall_s']:8.3f} s (load {s['load_s']:.3f} s, answer {s['answer_s']:.3f} s); "
                f"identical answer: {r['identical_answer']}",
                f"  ratio {r['ratio_full_to_saved']:.0f}x; {m['n']} queries from the saved file {m['wall_s']:.2f} s "
                f"({m['per_query_s']:.3f} s a query)",
                f"  cold uq margin --fit (fresh interpreter, imports included): {c['wall_s']:.1f} s",
            ]
        )
    if name == "batch":
        s, d = r["serial"], r["dask"]
        return "\n".join(
            [
                f"uq bench --batch: {r['workload']}; {r['cores']} cores, load average {r['load_average_1min']:.1f}",
                f"  one process : {s['wall_s']:7.1f} s, peak RSS {s['peak_rss_mb']:.0f} MB",
                f"  Dask        : {d['wall_s']:7.1f} s, peak RSS driver {d['peak_rss_mb']:.0f} MB, largest worker "
                f"{d['children_peak_rss_mb']:.0f} MB ({r['workers']} workers)",
                f"  speed-up {r['speedup']:.2f}x; posterior means of the two runs differ by at most "
                f"{r['max_mean_difference_in_sd']:.2f} posterior sd",
            ]
        )
    lines = [f"uq bench --scaling: {r['workload']}; load average {r['load_average_1min']:.1f}"]
    for x in r["runs"]:
        lines.append(
            f"  {x['factor']:>3}x ({x['n_points']:>5} points): {x['wall_s']:6.1f} s (x{x['time_ratio']:.2f}), "
            f"{x['ms_per_step']:.2f} ms/step (x{x['per_step_time_ratio']:.2f}), peak RSS {x['peak_rss_mb']:.0f} MB, "
            f"added {x['added_rss_mb']:.0f} MB (x{x['added_rss_ratio']:.2f})"
        )
    rep = r["report"]
    lines.append(
        f"  uq report (paper's campaign, cold process): {rep['wall_s']:.1f} s, peak RSS {rep['peak_rss_mb']:.0f} MB"
    )
    return "\n".join(lines)


def command_bench(args) -> int:
    if (
        getattr(args, "scaling", False)
        or getattr(args, "batch", None)
        or getattr(args, "margin", False)
    ):
        return command_scale(args)
    if not (math.isfinite(args.seconds) and args.seconds >= 0):
        raise InputError(
            f"option --seconds: expected a non-negative number of seconds, got {args.seconds:g}"
        )
    if args.baseline_walkers < 12 or args.baseline_walkers % 2:
        raise InputError(
            "option --baseline-walkers: an even number of at least 12 walkers (2 x 6 parameters) is needed"
        )
    settings = Settings(n_walkers=args.walkers, max_steps=args.max_steps)
    settings.validate()
    r = B.bench(
        seconds=args.seconds,
        seed=args.seed,
        settings=settings,
        recordings=args.recordings,
        pressure_bar=args.pressure_bar,
        baseline_walkers=args.baseline_walkers,
    )
    r = {"load_average_1min": os.getloadavg()[0], "cores": B.cores()} | r
    path = Path(args.bench_dir) / "ess.json"
    emit_json(r, str(path))
    emit_json(r, args.json)
    say(summary(r) + f"\n  written to {path}", args.json)
    return 0
