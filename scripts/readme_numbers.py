"""Regenerate every number the README quotes from a run, so none of them is typed by hand.

The README marks each generated block:

    <!-- generated: NAME -->
    ...whatever this script wrote...
    <!-- end generated: NAME -->

Two kinds of blocks:

* ``run`` blocks paste what a `uq` command prints on data/n50 (the command is shown above the
  output). They take minutes: `python scripts/readme_numbers.py` runs them all, `--only NAME`
  one of them.
* ``report`` blocks summarise the committed results in reports/ (calibration, surface coverage,
  diagnose proof, benchmark). They are cheap; `--check` recomputes them and fails when the README
  disagrees with reports/ (the test suite runs that).

Usage (from the project root, with the project installed):

    python scripts/readme_numbers.py [--only NAME ...] [--reports-only] [--check]
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shlex
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DATA = "data/n50/recordings.csv"
BLOCK = re.compile(
    r"(<!-- generated: (?P<name>[\w-]+) -->\n)(?P<body>.*?)(<!-- end generated: (?P=name) -->)",
    re.S,
)


def _uq() -> list[str]:
    venv = ROOT / ".venv" / "bin" / "uq"
    return [str(venv)] if venv.exists() else [sys.executable, "-m", "uq._cli.main"]


TIMINGS = ROOT / "reports" / "readme-timings.json"


def _load_timings() -> dict:
    return json.loads(TIMINGS.read_text()) if TIMINGS.exists() else {}


def _save_timing(args: str, seconds: float, load: float) -> None:
    t = _load_timings()
    t[args] = {
        "seconds": round(seconds, 1),
        "load_average_1min": round(load, 2),
        "cpus": os.cpu_count(),
        "date": time.strftime("%Y-%m-%d"),
    }
    tmp = TIMINGS.with_suffix(".tmp")
    tmp.write_text(json.dumps(t, indent=1, sort_keys=True) + "\n")
    os.replace(tmp, TIMINGS)


def _run(args: str) -> tuple[list[str], float]:
    """Run `uq ARGS` in the project root; its output lines (stdout, then stderr) and wall time."""
    load0 = os.getloadavg()[0]
    t0 = time.perf_counter()
    proc = subprocess.run(
        _uq() + shlex.split(args),
        cwd=ROOT,
        capture_output=True,
        text=True,
        env={**os.environ, "UQ_NO_PROGRESS": "1"},
    )
    seconds = time.perf_counter() - t0
    if proc.returncode not in (0, 1):
        raise SystemExit(
            f"readme_numbers: `uq {args}` exited {proc.returncode}: {proc.stderr.strip()[-500:]}"
        )
    _save_timing(args, seconds, max(load0, os.getloadavg()[0]))
    if load0 > 1.5:
        print(
            f"readme_numbers: load average {load0:.1f} when `uq {args}` started: its time is not an idle one",
            file=sys.stderr,
        )
    return (proc.stdout + proc.stderr).rstrip().splitlines(), seconds


def run_block(*commands: str, keep: int | None = None):
    """A block that shows each `uq ARGS` and what it prints (stdout and stderr, in that order)."""

    def make() -> str:
        shown = []
        for args in commands:
            lines, _ = _run(args)
            if keep is not None and len(lines) > keep:
                lines = lines[:keep] + [f"... ({len(lines) - keep} more lines)"]
            shown += [f"$ uq {args}", *lines]
        return "\n".join("    " + ln if ln else "" for ln in shown) + "\n"

    return "run", make


def speed_table():
    """Wall times of the run blocks (reports/readme-timings.json), with the load they ran under."""

    def make() -> str:
        t = _load_timings()
        if not t:
            return "(no timings yet: python scripts/readme_numbers.py runs the commands)\n"
        out = [
            "| command | wall time | load average (1 min), the larger of start and end | date |",
            "| --- | --- | --- | --- |",
        ]
        for args, v in t.items():
            out.append(
                f"| `uq {args}` | {v['seconds']:.0f} s | {v['load_average_1min']:.1f} on {v['cpus']} CPUs "
                f"| {v['date']} |"
            )
        return "\n".join(out) + "\n"

    return "report", make


def _load(rel: str) -> dict | None:
    path = ROOT / rel
    return json.loads(path.read_text()) if path.exists() else None


def calibration_summary(rel: str):
    def make() -> str:
        data = _load(rel)
        if data is None:
            return f"(no results: {rel} is missing)\n"
        out = [
            f"From `{rel}` (`{data.get('command', 'uq calibrate')}`):",
            "",
            "| truth | noise model | reps | converged | 90 % coverage, min..max over quantities "
            "| outside the 99 % region | smallest SBC p | Holm-adjusted | 90 % predictive, low / high force third |",
            "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
        ]
        for s in data["settings"]:
            q = s["quantities"]
            cov = [v["covered90"] for v in q.values() if "covered90" in v]
            outside = [
                k
                for k, v in q.items()
                if not (v.get("in_region90", True) and v.get("in_region50", True))
            ]
            ps = [
                (v["sbc_uniformity_p"], k)
                for k, v in q.items()
                if v.get("sbc_uniformity_p") is not None
            ]
            pmin = min(ps) if ps else (float("nan"), "-")
            pc = s.get("predictive_coverage90")
            pred = (
                f"{100 * pc['low_force_third']:.1f} % / {100 * pc['high_force_third']:.1f} %"
                if pc
                else "-"
            )
            holm = [
                v.get("sbc_uniformity_p_holm")
                for v in q.values()
                if v.get("sbc_uniformity_p_holm") is not None
            ]
            truth = s["truth"] + (
                "".join(f", {k} {v:g}" for k, v in s["stand"].items()) if s.get("stand") else ""
            )
            out.append(
                f"| {truth} | {s['noise_model']} | {s['replications']} | {s['converged_fraction']:.0%} "
                f"| {min(cov)}..{max(cov)} of {s['replications']} | {', '.join(outside) or 'none'} "
                f"| {pmin[0]:.3f} ({pmin[1]}) | {min(holm):.3f} | {pred} |"
                if holm
                else f"| {truth} | {s['noise_model']} | {s['replications']} | {s['converged_fraction']:.0%} "
                f"| {min(cov)}..{max(cov)} of {s['replications']} | {', '.join(outside) or 'none'} "
                f"| {pmin[0]:.3f} ({pmin[1]}) | - | {pred} |"
            )
        return "\n".join(out) + "\n"

    return "report", make


def surface_coverage_summary(rel: str):
    def make() -> str:
        d = _load(rel)
        if d is None:
            return f"(no results: {rel} is missing)\n"
        lo, hi = d["acceptance"]
        n = d["replications"]
        t = d["truth"]
        lines = [
            f"From `{rel}` (spring `{d['spring']}`, check point {t['x_m'] * 1e3:g} mm and {t['p_bar']:g} bar, "
            f"{n} replications, 99 % binomial acceptance region {lo}-{hi}):",
            "",
        ]
        for key, label in (
            ("feff_covered", "90 % band of F_eff = P/p_u contained the truth"),
            ("pressure_area_covered", "90 % band of the pressure area F_p contained the truth"),
            ("pressure_covered", "90 % interval of the pressure needed contained the truth"),
        ):
            if key in d:
                lines.append(f"- {label}: {d[key]} of {n}")
        for k, p in d.get("sbc_uniformity_p", {}).items():
            lines.append(f"- SBC uniformity of `{k}`: p = {p:.3f}")
        for k, v in d.items():
            if k.startswith("model") and isinstance(v, str):
                lines.append(f"- {k}: {v}")
        return "\n".join(lines) + "\n"

    return "report", make


def diagnose_proof_summary(rel: str):
    def make() -> str:
        d = _load(rel)
        if d is None:
            return f"(no results: {rel} is missing)\n"
        fa = d["false_alarm_rate_clean"]
        det = d.get("detection", {})
        named = sum(v.get("named", 0) for v in det.values())
        runs = sum(v.get("runs", 0) for v in det.values())
        cov = d.get("coverage_90_overall", {})
        missed = [k for k, v in det.items() if v.get("named", 0) < v.get("runs", 0)]
        wrong = sum(
            n
            for true, row in d["confusion"].items()
            for name, n in row.items()
            if name not in (true, "nothing named")
        )
        pairs = d.get("pairs", {})
        extra = d.get("spurious_extra_mechanism_in_single_runs", {})
        lines = [
            f"From `{rel}` ({d['n_runs']} campaigns):",
            "",
            f"- clean campaigns: mismatch detected in {fa['mismatch_detected']} of {fa['runs']}, "
            f"a mechanism named in {fa['mechanism_named']} ({fa.get('other_stand_runs', 0)} of the clean "
            f"campaigns came from stands other than the model assumes: noisier, or with heavy-tailed errors and "
            f"pressure errors correlated from reading to reading)",
            f"- wrong mechanisms named (single-mechanism and clean runs): {wrong}; an extra mechanism "
            f"beside the true one: {extra.get('with_extra', 0)} of {extra.get('runs', 0)} single-mechanism runs",
            f"- concealed single mechanisms found: {named} of {runs} runs; pairs with both named exactly: "
            f"{pairs.get('both_named_exactly', 0)} of {pairs.get('runs', 0)}",
            f"- named true mechanisms with the truth inside the 90 % interval: {cov.get('true_in_90', 0)} of "
            f"{cov.get('named_true', 0)}",
            f"- not always found: {', '.join(missed) or 'none'}",
        ]
        return "\n".join(lines) + "\n"

    return "report", make


def margin_bench_summary(rel: str):
    def make() -> str:
        d = _load(rel)
        if d is None:
            return f"(no benchmark yet: `uq bench --margin --bench-dir {Path(rel).parent}` writes {rel})\n"
        f, s, q, c = (
            d["full_query"],
            d["from_saved_file"],
            d["queries_from_saved_file"],
            d["cold_cli_from_saved_file"],
        )
        return (
            f"From `{rel}` (`uq bench --margin`, one process, {d['cores']} cores at load average "
            f"{d['load_average_1min']:.1f}; answered by the {d['answered_by']}): full query (fit both models, "
            f"compare, answer) {f['wall_s']:.0f} s; the same query from the saved file {s['wall_s']:.2f} s "
            f"(ratio {d['ratio_full_to_saved']:.0f}x, identical answer: {d['identical_answer']}); "
            f"{q['n']} queries from one load of the file {q['per_query_s']:.2f} s each; a cold "
            f"`uq margin --fit` in a fresh interpreter {c['wall_s']:.1f} s, almost all of it imports.\n"
        )

    return "report", make


BLOCKS = {
    "fit-n50": run_block(f"fit {DATA} --json reports/n50-fit.json"),
    "check-n50": run_block("check reports/n50-fit.json --against fits/n50/table1_points.json"),
    "report-n50": run_block(f"report {DATA} --out reports/n50", keep=30),
    "bench-run": run_block("bench"),
    "speed": speed_table(),
    "surface-select": run_block(f"surface {DATA} --select --no-compare"),
    "surface-n50": run_block(f"surface {DATA}"),
    "margin-n50": run_block(
        f"margin {DATA} --height-mm 112 --load-N 13020 --pressure-bar 5 --tolerance-pct 10"
    ),
    "diagnose-n50": run_block(f"diagnose {DATA}", keep=45),
    "calibration": calibration_summary("reports/calibration/calibration.json"),
    "calibration-rough-stand": calibration_summary(
        "reports/calibration-rough-stand/calibration.json"
    ),
    "bench-margin": margin_bench_summary("reports/bench/margin.json"),
    "surface-coverage": surface_coverage_summary("reports/surface-coverage/coverage.json"),
    "diagnose-proof": diagnose_proof_summary("reports/diagnose-proof/summary.json"),
}


def regenerate(
    text: str, names: set[str], bodies: dict[str, str] | None = None
) -> tuple[str, list[str]]:
    """The README with the named blocks rebuilt (from ``bodies`` where given, else made now), and
    the names of blocks whose text changed."""
    changed = []
    bodies = {} if bodies is None else bodies

    def repl(m: re.Match) -> str:
        name = m["name"]
        if name not in names:
            return m[0]
        if name not in BLOCKS:
            raise SystemExit(
                f"readme_numbers: README.md has a block '{name}' this script does not know"
            )
        body = bodies[name] if name in bodies else BLOCKS[name][1]()
        if body != m["body"]:
            changed.append(name)
        return m[1] + body + m[4]

    return BLOCK.sub(repl, text), changed


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="+", choices=sorted(BLOCKS), help="rebuild only these blocks")
    ap.add_argument(
        "--reports-only", action="store_true", help="rebuild only the blocks made from reports/"
    )
    ap.add_argument(
        "--check",
        action="store_true",
        help="rebuild the report blocks in memory; exit 1 if README differs",
    )
    args = ap.parse_args(argv)
    text = README.read_text()
    present = {m["name"] for m in BLOCK.finditer(text)}
    names = set(args.only or BLOCKS) & present
    if args.reports_only or args.check:
        names = {n for n in names if BLOCKS[n][0] == "report"}
    if args.check:
        new, changed = regenerate(text, names)
        if changed:
            print(
                f"README.md is out of date with reports/ in: {', '.join(sorted(changed))}; "
                "run python scripts/readme_numbers.py --reports-only",
                file=sys.stderr,
            )
            return 1
        return 0
    # Run blocks take minutes: make every body first (run blocks in README order, so `fit` comes
    # before `check`; report blocks last, after the runs have written their timings), then
    # re-read the README, so edits made meanwhile are kept.
    order = [m["name"] for m in BLOCK.finditer(text) if m["name"] in names]
    order.sort(key=lambda n: BLOCKS[n][0] == "report")
    bodies = {n: BLOCKS[n][1]() for n in order}
    new, changed = regenerate(README.read_text(), names, bodies)
    fd, tmp = tempfile.mkstemp(dir=ROOT, prefix=".README.", suffix=".tmp")
    with os.fdopen(fd, "w") as f:
        f.write(new)
    os.chmod(tmp, README.stat().st_mode & 0o777)
    os.replace(tmp, README)
    print(
        f"README.md: rebuilt {', '.join(sorted(names)) or 'nothing'}; changed: {', '.join(sorted(changed)) or 'nothing'}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
