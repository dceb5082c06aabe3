"""Every ``uq`` command against the import floor, in the same run: wall time, CPU seconds, peak RSS.

Not part of the installed package: run from the repository root with the project installed,

    .venv/bin/python benchmarks/commands.py [--reps 3] [--json reports/bench/commands.json]
    .venv/bin/python benchmarks/commands.py --commands fit,report --reps 5

The goals of issue 32 are ratios to the *import floor*: a fresh interpreter that imports what
every fitting command needs (``import jax, numpy, matplotlib, arviz, optimistix, emcee``) and
does nothing else. Each command runs as the ``uq`` program runs it (``main()`` as the program,
which ends the process without Python's shutdown once its outputs are written and its workers
joined): its wall time is what its user waits for. (Up to the thirteenth session of round 7 the
child called ``main(argv)`` as a library call and let Python shut down after it, 0.4-0.7 s after
JAX's import that no user of ``uq`` waits for.) The machine is shared, so a wall time alone says little; a ratio measured in
the same minute says more. Each repetition runs, for every command, the floor and then the
command, each in a fresh interpreter, and takes the ratio of the pair; the reported ratio is the
median over the repetitions (wall and CPU). CPU seconds are user + system time of the process
and of every process it started and waited for (``uq report``'s figure workers), from
``resource.getrusage``; they are less sensitive to the machine's load than the wall time.

Peak RSS is that of the command's own process and, separately, the largest of the processes it
started (figure workers, Dask workers).

The JAX compilation cache is a folder of this run (``UQ_CACHE_DIR``), warmed by one untimed run
of every command first (``--cold``: not warmed, the first run of each command is timed as
well), so that the ratios are those of a second run on a user's machine.

Workload (``--recordings``, default data/n50/recordings.csv; the outputs go to a scratch folder):

    fit       uq fit FILE
    report    uq report FILE --out DIR
    diagnose  uq diagnose FILE
    surface   uq surface FILE
    design    uq design FILE --height-mm 112 --charge-bar 5 --volume-l 3.4 --forcing-hz 5 --out DIR
    margin    uq margin FILE --height-mm 112 --load-N 13020 --pressure-bar 5 --tolerance-pct 10

``--extra`` adds options to every command (e.g. ``--extra "--max-steps 200 --walkers 8"`` for a
quick check that the script runs; its numbers then mean nothing).
"""

from __future__ import annotations

import argparse
import json
import os
import shlex
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_RECORDINGS = ROOT / "data" / "n50" / "recordings.csv"

#: what the floor imports: every fitting command needs these (issue 32's floor)
FLOOR_MODULES = ("jax", "numpy", "matplotlib", "arviz", "optimistix", "emcee")

#: the commands of issue 32's table and their arguments ({file}: the recordings, {out}: a scratch folder)
COMMANDS = {
    "fit": ["fit", "{file}"],
    "report": ["report", "{file}", "--out", "{out}/report"],
    "diagnose": ["diagnose", "{file}"],
    "surface": ["surface", "{file}"],
    "design": [
        "design",
        "{file}",
        "--height-mm",
        "112",
        "--charge-bar",
        "5",
        "--volume-l",
        "3.4",
        "--forcing-hz",
        "5",
        "--out",
        "{out}/design",
    ],
    "margin": [
        "margin",
        "{file}",
        "--height-mm",
        "112",
        "--load-N",
        "13020",
        "--pressure-bar",
        "5",
        "--tolerance-pct",
        "10",
    ],
}

#: issue 32's goals: the largest ratio to the floor on data/n50 with a warm cache
GOALS = {
    "fit": 1.6,
    "report": 2.9,
    "design": 2.9,
    "diagnose": 3.6,
    "surface": 3.6,
    "margin": 3.6,
}

# The child: run the code, then write its own and its reaped children's rusage as JSON. A command
# runs as the uq program runs it: main() ends the process by uq._io.processes.exit_now (its workers
# joined, outputs flushed, without Python's shutdown), so the usage is written there, just before.
_CHILD = (
    "import json, resource, sys, time\n"
    "t0, out = time.perf_counter(), sys.argv[1]\n"
    "def done(rc):\n"
    "    wall = time.perf_counter() - t0\n"
    "    s = resource.getrusage(resource.RUSAGE_SELF)\n"
    "    c = resource.getrusage(resource.RUSAGE_CHILDREN)\n"
    "    open(out, 'w').write(json.dumps({'rc': rc, 'inner_wall_s': wall,\n"
    "        'cpu_self_s': s.ru_utime + s.ru_stime, 'cpu_children_s': c.ru_utime + c.ru_stime,\n"
    "        'self_mb': s.ru_maxrss / 1024.0, 'children_mb': c.ru_maxrss / 1024.0}))\n"
    "if sys.argv[2] == 'floor':\n"
    "    import importlib\n"
    "    for m in sys.argv[3:]:\n"
    "        importlib.import_module(m)\n"
    "    done(0)\n"
    "    sys.exit(0)\n"
    "import uq._io.processes as processes\n"
    "end = processes.exit_now\n"
    "def exit_now(status=0, **kw):\n"
    "    done(status)\n"
    "    end(status, **kw)\n"
    "processes.exit_now = exit_now\n"
    "from uq._cli.main import main\n"
    "sys.argv = ['uq', *sys.argv[3:]]\n"
    "main()\n"
)


def run_child(what: list[str], env: dict) -> dict:
    """``what`` (``["floor", modules...]`` or ``["uq", argv...]``) in a fresh interpreter: wall
    time (start of the interpreter to its exit), CPU seconds (self + reaped children), peak RSS."""
    fd, out = tempfile.mkstemp(suffix=".json")
    os.close(fd)
    try:
        t0 = time.perf_counter()
        proc = subprocess.run(
            [sys.executable, "-c", _CHILD, out, *what],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
            # not the checkout's root: ``python -c`` puts the working directory first on sys.path,
            # ahead of PYTHONPATH, and a root holding uq/ would shadow the baseline's
            cwd=tempfile.gettempdir(),
        )
        wall = time.perf_counter() - t0
        r = json.loads(Path(out).read_text() or "{}")
    finally:
        os.unlink(out)
    if proc.returncode not in (0, 1) or not r:
        raise RuntimeError(
            f"{' '.join(what[:2])} failed in the benchmark (exit {proc.returncode}): "
            f"{proc.stderr.strip()[-400:]}"
        )
    return {
        "wall_s": wall,
        "cpu_s": r["cpu_self_s"] + r["cpu_children_s"],
        "cpu_self_s": r["cpu_self_s"],
        "cpu_children_s": r["cpu_children_s"],
        "peak_rss_mb": r["self_mb"],
        "children_peak_rss_mb": r["children_mb"],
        "exit": proc.returncode,
    }


def argv_of(name: str, recordings: Path, out: Path, extra: list[str]) -> list[str]:
    return [a.format(file=recordings, out=out) for a in COMMANDS[name]] + extra + ["--quiet"]


def _with_path(env: dict, path: Path | None) -> dict:
    """``env`` running the uq package found in ``path`` (a checkout's root) instead of the installed one."""
    if path is None:
        return env
    return dict(
        env, PYTHONPATH=os.pathsep.join([str(path), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    )


def measure(
    names: list[str],
    *,
    reps: int,
    recordings: Path,
    extra: list[str],
    warm: bool,
    log=None,
    cache: Path | None = None,
    code: Path | None = None,
    baseline: Path | None = None,
    warm_baseline: bool = True,
) -> dict:
    """The floor/command pairs, ``reps`` times each (see the module docstring). ``code``: the uq
    to measure (a folder holding ``uq/``; default the installed one); ``baseline``: another one,
    run right after it in every repetition (the "before" of a change, under the same load)."""
    rows: dict[str, list[dict]] = {n: [] for n in names}
    with tempfile.TemporaryDirectory(prefix="uq-bench-commands-") as tmp:
        env = dict(os.environ, UQ_CACHE_DIR=str(cache or Path(tmp) / "jax-cache"))
        env.pop("JAX_COMPILATION_CACHE_DIR", None)
        env.pop("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", None)
        out = Path(tmp) / "out"
        versions = {"command": _with_path(env, code)}
        if baseline is not None:
            versions["baseline"] = _with_path(env, baseline)
        if warm:
            for n in names:
                for which, e in versions.items():
                    if which == "baseline" and not warm_baseline:
                        continue
                    t0 = time.perf_counter()
                    run_child(["uq", *argv_of(n, recordings, out, extra)], e)
                    if log:
                        log(f"warm-up {n} ({which}): {time.perf_counter() - t0:.1f} s")
        for rep in range(reps):
            for n in names:
                floor = run_child(["floor", *FLOOR_MODULES], env)
                row = {"rep": rep, "load_average_1min": os.getloadavg()[0], "floor": floor}
                for which, e in versions.items():
                    cmd = run_child(["uq", *argv_of(n, recordings, out, extra)], e)
                    suffix = "" if which == "command" else "_baseline"
                    row[which] = cmd
                    row["ratio_wall" + suffix] = cmd["wall_s"] / floor["wall_s"]
                    row["ratio_cpu" + suffix] = cmd["cpu_s"] / floor["cpu_s"]
                    if log:
                        log(
                            f"rep {rep + 1}/{reps} {n} ({which}): {cmd['wall_s']:.1f} s (floor "
                            f"{floor['wall_s']:.1f} s, x{cmd['wall_s'] / floor['wall_s']:.2f}), CPU "
                            f"{cmd['cpu_s']:.1f} s (x{cmd['cpu_s'] / floor['cpu_s']:.2f}), "
                            f"peak {cmd['peak_rss_mb']:.0f} MB"
                        )
                rows[n].append(row)
    commands = {}
    for n, rs in rows.items():

        def med(f, rs=rs):
            return statistics.median(f(r) for r in rs)

        if baseline is not None:
            base = {
                "ratio_wall": med(lambda r: r["ratio_wall_baseline"]),
                "ratio_cpu": med(lambda r: r["ratio_cpu_baseline"]),
                "wall_s": med(lambda r: r["baseline"]["wall_s"]),
                "cpu_s": med(lambda r: r["baseline"]["cpu_s"]),
                "peak_rss_mb": med(lambda r: r["baseline"]["peak_rss_mb"]),
                "children_peak_rss_mb": med(lambda r: r["baseline"]["children_peak_rss_mb"]),
            }
        commands[n] = {
            "argv": "uq " + " ".join(argv_of(n, Path("FILE"), Path("OUT"), extra)),
            "ratio_wall": med(lambda r: r["ratio_wall"]),
            "ratio_cpu": med(lambda r: r["ratio_cpu"]),
            "wall_s": med(lambda r: r["command"]["wall_s"]),
            "cpu_s": med(lambda r: r["command"]["cpu_s"]),
            "peak_rss_mb": med(lambda r: r["command"]["peak_rss_mb"]),
            "children_peak_rss_mb": med(lambda r: r["command"]["children_peak_rss_mb"]),
            "floor_wall_s": med(lambda r: r["floor"]["wall_s"]),
            "floor_cpu_s": med(lambda r: r["floor"]["cpu_s"]),
            "goal_ratio": GOALS.get(n),
            "baseline": base if baseline is not None else None,
            "runs": rs,
        }
    return commands


def summary(r: dict) -> str:
    lines = [
        f"bench commands: {r['workload']}; {r['cores']} cores, load average "
        f"{r['load_average_1min']:.1f} at the start; median of {r['reps']} floor/command pairs",
        f"  {'command':<9} {'x floor':>8} {'goal':>5} {'wall s':>7} {'CPU s':>7} {'x floor CPU':>11} "
        f"{'peak MB':>8} {'workers MB':>10}",
    ]
    for n, c in r["commands"].items():
        goal = f"{c['goal_ratio']:.1f}" if c["goal_ratio"] else "-"
        for label, v in ((n, c), (" before", c.get("baseline"))):
            if v:
                lines.append(
                    f"  {label:<9} {v['ratio_wall']:>8.2f} {goal:>5} {v['wall_s']:>7.1f} "
                    f"{v['cpu_s']:>7.1f} {v['ratio_cpu']:>11.2f} {v['peak_rss_mb']:>8.0f} "
                    f"{v['children_peak_rss_mb']:>10.0f}"
                )
    lines.append(
        f"  import floor ({', '.join(FLOOR_MODULES)}): median {r['floor_wall_s']:.2f} s wall, "
        f"{r['floor_cpu_s']:.2f} s CPU"
    )
    return "\n".join(lines)


def git_commit() -> str | None:
    try:
        return subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            cwd=ROOT,
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return None


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="benchmarks/commands.py",
        description=__doc__.splitlines()[0],
        formatter_class=argparse.ArgumentDefaultsHelpFormatter,
    )
    p.add_argument(
        "--commands",
        default=",".join(COMMANDS),
        help=f"comma-separated, of {', '.join(COMMANDS)}",
    )
    p.add_argument("--reps", type=int, default=3, help="floor/command pairs per command")
    p.add_argument("--recordings", type=Path, default=DEFAULT_RECORDINGS, help="the campaign")
    p.add_argument(
        "--extra", default="", help="options added to every command (quoted, shell words)"
    )
    p.add_argument(
        "--cold", action="store_true", help="no untimed warm-up run (cold compilation cache)"
    )
    p.add_argument("--label", default="", help="a name for this run in the JSON (e.g. 'before')")
    p.add_argument(
        "--cache",
        type=Path,
        help="JAX's compilation cache for the run (default: a new folder, warmed by --warm-up)",
    )
    p.add_argument(
        "--code",
        type=Path,
        help="measure the uq package in this folder (its root, holding uq/) instead of the installed one",
    )
    p.add_argument(
        "--baseline-label",
        default="",
        help="what the baseline is, for the table (e.g. 'main at 9034f1e')",
    )
    p.add_argument(
        "--no-baseline-warm-up",
        action="store_true",
        help="warm the cache for the measured uq only (the --cache given is warm for the baseline)",
    )
    p.add_argument(
        "--baseline",
        type=Path,
        help="also measure the uq package in this folder (e.g. an export of main: the 'before' "
        "column), right after the measured one in every repetition",
    )
    p.add_argument(
        "--json", metavar="PATH", help="write the result to PATH ('-' for stdout); nothing without"
    )
    return p


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    names = [n.strip() for n in args.commands.split(",") if n.strip()]
    bad = [n for n in names if n not in COMMANDS]
    if bad or not names:
        print(
            f"benchmarks/commands.py: error: option --commands: unknown {', '.join(bad) or '(none)'}; "
            f"expected some of {', '.join(COMMANDS)}",
            file=sys.stderr,
        )
        return 2
    if args.reps < 1:
        print("benchmarks/commands.py: error: option --reps: at least 1", file=sys.stderr)
        return 2
    if not args.recordings.is_file():
        print(
            f"benchmarks/commands.py: error: option --recordings: no file {args.recordings}",
            file=sys.stderr,
        )
        return 2
    err = sys.stderr

    def log(text):
        print(text, file=err, flush=True)

    load0 = os.getloadavg()[0]
    t0 = time.perf_counter()
    commands = measure(
        names,
        reps=args.reps,
        recordings=args.recordings.resolve(),
        extra=shlex.split(args.extra),
        warm=not args.cold,
        log=log,
        cache=args.cache,
        code=args.code,
        baseline=args.baseline,
        warm_baseline=not args.no_baseline_warm_up,
    )
    floors = [r["floor"] for c in commands.values() for r in c["runs"]]
    try:
        where = str(args.recordings.resolve().relative_to(ROOT))
    except ValueError:
        where = str(args.recordings)
    r = {
        "label": args.label,
        "commit": git_commit(),
        "date": time.strftime("%Y-%m-%d"),
        "workload": where + (f" with {args.extra}" if args.extra else ""),
        "cores": len(os.sched_getaffinity(0))
        if hasattr(os, "sched_getaffinity")
        else os.cpu_count(),
        "load_average_1min": load0,
        "reps": args.reps,
        "warm_cache": not args.cold,
        "floor_modules": list(FLOOR_MODULES),
        "floor_wall_s": statistics.median(f["wall_s"] for f in floors),
        "floor_cpu_s": statistics.median(f["cpu_s"] for f in floors),
        "total_s": time.perf_counter() - t0,
        "code": str(args.code) if args.code else "installed",
        "baseline": str(args.baseline) if args.baseline else None,
        "baseline_label": args.baseline_label,
        "commands": commands,
        "measure": "per command the median over reps of (command / import floor) measured back to back, "
        "each in a fresh interpreter; CPU = user + system of the process and its reaped children",
    }
    if args.json:
        from uq._io.files import emit_json

        emit_json(r, args.json)
    text = summary(r) + (f"\n  written to {args.json}" if args.json not in (None, "-") else "")
    print(text, file=sys.stderr if args.json == "-" else sys.stdout)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
