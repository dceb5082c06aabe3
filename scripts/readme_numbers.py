"""Regenerate every command output and number the documentation quotes, so none of them is typed by hand.

README.md and the pages of docs/ mark each generated block:

    <!-- generated: NAME -->
    ...whatever this script wrote...
    <!-- end generated: NAME -->

Two kinds of blocks:

* ``run`` blocks paste what a command prints (the command is shown above its output, after
  ``$``). They are made in a scratch copy of the repository's data (data/, fits/ and the
  example files of docs/examples/), so a block may overwrite its inputs or write its outputs
  without touching the repository. They take minutes: ``python scripts/readme_numbers.py``
  runs them all, ``--only NAME`` some. tests/test_docs.py reruns the command of every run block
  and compares with the page (numbers within a small relative tolerance, timings masked): the
  quick commands in the fast suite, the slow ones under ``-m slow``.
* ``report`` blocks summarise committed results in reports/ (calibration, surface coverage,
  diagnose proof and power, benchmarks, the timings of the run blocks). They are cheap; ``--check``
  recomputes them and fails when a page disagrees with reports/ (the test suite runs that).

Usage (from the project root, with the project installed):

    python scripts/readme_numbers.py [--only NAME ...] [--reports-only] [--check]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DATA = "data/n50/recordings.csv"
BLOCK = re.compile(
    r"(<!-- generated: (?P<name>[\w-]+) -->\n)(?P<body>.*?)(<!-- end generated: (?P=name) -->)",
    re.S,
)
TIMINGS = ROOT / "reports" / "readme-timings.json"
#: What a workspace holds: copies, so that a block may write anywhere in it.
WORKSPACE_COPIES = ("data", "fits", "docs/examples")

sys.path.insert(0, str(ROOT / "benchmarks"))
from bench_tables import MEMORY, SCALING, table  # noqa: E402  (benchmarks/ is no package)

sys.path.insert(0, str(ROOT / "scripts"))
from coverage_tables import model_check_table  # noqa: E402  (scripts/ is no package)


def pages() -> list[Path]:
    """Every page that may hold generated blocks: README.md and the Markdown pages of docs/."""
    return [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]


# ----------------------------------------------------------------------------- running commands


def make_workspace(folder: Path) -> Path:
    """A scratch folder with copies of the data the run blocks read, and an empty reports/."""
    folder = Path(folder)
    for rel in WORKSPACE_COPIES:
        if (ROOT / rel).exists():
            shutil.copytree(ROOT / rel, folder / rel, dirs_exist_ok=True)
    (folder / "reports").mkdir(parents=True, exist_ok=True)
    return folder


def _uq() -> list[str]:
    venv = ROOT / ".venv" / "bin" / "uq"
    return [str(venv)] if venv.exists() else [sys.executable, "-m", "uq._cli.main"]


def run_command(args: str, cwd: Path, statuses=(0, 1)) -> tuple[list[str], float]:
    """Run ``uq ARGS`` in ``cwd``: its output lines (stdout, then stderr) and wall time."""
    t0 = time.perf_counter()
    proc = subprocess.run(_uq() + shlex.split(args), cwd=cwd, capture_output=True, text=True)
    seconds = time.perf_counter() - t0
    if proc.returncode not in statuses:
        raise RuntimeError(f"`uq {args}` exited {proc.returncode}: {proc.stderr.strip()[-500:]}")
    return (proc.stdout + proc.stderr).rstrip().splitlines(), seconds


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


# ----------------------------------------------------------------------------- the blocks


@dataclasses.dataclass(frozen=True)
class Block:
    """One generated block. ``run`` blocks: the ``uq`` commands (arguments after ``uq``) whose
    output they show, the blocks whose outputs they read (run first, in the same workspace), how
    many output lines they keep, the exit statuses that are expected, and whether their check
    belongs to the slow suite. ``report`` blocks: ``summarise()`` makes the text."""

    kind: str
    commands: tuple[str, ...] = ()
    requires: tuple[str, ...] = ()
    keep: int | None = None
    statuses: tuple[int, ...] = (0, 1)
    slow: bool = False
    summarise: Callable[[], str] | None = None


def run_block(*commands, requires=(), keep=None, statuses=(0, 1), slow=False) -> Block:
    return Block("run", tuple(commands), tuple(requires), keep, tuple(statuses), slow)


def maxwell_summary(rel: str) -> Callable[[], str]:
    """The Maxwell check on Table 1 (scripts/maxwell_table1.py): r by pressure in the middle of the
    stroke, and the reading."""

    def make() -> str:
        d = _load(rel)
        if d is None:
            return f"(no results: {rel} is missing)\n"
        middle = d["interpretation"]["middle"]
        levels = middle["mean_r_by_pressure"]
        sds = middle.get("sd_r_by_pressure", {})
        rows = ["| p_u bar | " + " | ".join(levels) + " |", "| --- |" + " --- |" * len(levels)]
        rows.append(
            "| r (middle of the stroke) | "
            + " | ".join(f"{v:+.3f}" for v in levels.values())
            + " |"
        )
        if sds:
            rows.append("| sd | " + " | ".join(f"{sds[p]:.3f}" for p in levels) + " |")
        shapes = middle.get("shapes", {})
        table = ""
        if shapes:
            names = {
                "zero": "zero (the relation holds)",
                "constant": "one value (a piston-area error alone)",
                "step": "a step between two tested pressures",
                "fade": "a fade (a straight line in p_u)",
            }
            lines = [
                "| shape of r over pressure | chi^2 | dof | p | fits |",
                "| --- | --- | --- | --- | --- |",
            ]
            for k, v in shapes.items():
                where = (
                    f" ({v['between_bar'][0]:g} and {v['between_bar'][1]:g} bar)"
                    if k == "step"
                    else ""
                )
                lines.append(
                    f"| {names[k]}{where} | {v['chi2']:.1f} | {v['dof']} | {v['p']:.1e} | "
                    f"{'yes' if v['fits'] else 'no'} |"
                )
            corr = middle.get("most_negative_correlation")
            table = (
                "\n\nThe levels' joint covariance (from the draws) enters every chi^2; the most "
                f"negative correlation between two levels is {corr:+.2f}.\n\n" + "\n".join(lines)
            )
        return (
            f"From `{rel}` (`{d['command']}`):\n\n"
            + "\n".join(rows)
            + table
            + "\n\n"
            + d["interpretation"]["words"]
            + ".\n"
        )

    return make


def report_block(summarise: Callable[[], str]) -> Block:
    return Block("report", summarise=summarise)


EXPORT = "reports/export"  # scripts/export_n50.py


def _cut(line: str, width: int = 150) -> str:
    return line if len(line) <= width else line[: width - 4] + " ..."


def export_text(
    name: str, start: str | None = None, lines: int = 12, pick=None
) -> Callable[[], str]:
    """Lines of a committed export (reports/export/NAME), as a code block: from the first line
    that starts with ``start`` (or the top), ``lines`` of them, or the lines ``pick`` keeps."""

    def make() -> str:
        path = ROOT / EXPORT / name
        if not path.exists():
            return f"(no export yet: {EXPORT}/{name} is missing; python scripts/export_n50.py)\n"
        text = path.read_text().splitlines()
        if pick is not None:
            text = [ln for ln in text if pick(ln)]
        elif start is not None:
            text = text[next(i for i, ln in enumerate(text) if ln.startswith(start)) :]
        shown = [_cut(ln) for ln in text[:lines]]
        if len(text) > lines:
            shown.append(f"... ({len(text) - lines} more lines)")
        return body_of([f"{EXPORT}/{name}:", *shown])

    return make


def export_csv_summary() -> str:
    """The table's first rows, the contract's nine columns, and the names of the others."""
    path = ROOT / EXPORT / "n50.csv"
    if not path.exists():
        return f"(no export yet: {EXPORT}/n50.csv is missing; python scripts/export_n50.py)\n"
    rows = [ln.split(",") for ln in path.read_text().splitlines()]
    shown = [",".join(r[:9]) for r in rows[:4]]
    return body_of(
        [
            f"{EXPORT}/n50.csv, the first rows, the contract's columns ({len(rows) - 1} rows):",
            *shown,
            f"... then the columns {', '.join(rows[0][9:])}",
        ]
    )


def export_xlsx_summary() -> str:
    import openpyxl

    path = ROOT / EXPORT / "n50.xlsx"
    if not path.exists():
        return f"(no export yet: {EXPORT}/n50.xlsx is missing; python scripts/export_n50.py)\n"
    book = openpyxl.load_workbook(path, read_only=True)
    rows = list(book["force_N q50"].iter_rows(values_only=True))
    shown = [
        " | ".join(f"{v:g}" if isinstance(v, float) else str(v) for v in r[:7]) + " | ..."
        for r in rows[:4]
    ]
    rows = list(book["provenance"].iter_rows(values_only=True))[1:]
    provenance = [f"{k}: {v}" for k, v in rows[:5]] + ["..."]
    provenance += [f"{k}: {v}" for k, v in rows if k == "note"]
    return body_of(
        [
            f"{EXPORT}/n50.xlsx: {len(book.sheetnames)} sheets: {', '.join(book.sheetnames[:6])}, ..., "
            f"{book.sheetnames[-1]}",
            "sheet 'force_N q50' (the first rows and columns):",
            *shown,
            "sheet 'provenance' (the first rows, and the notes):",
            *provenance,
        ]
    )


def export_json_summary() -> str:
    path = ROOT / EXPORT / "n50.json"
    if not path.exists():
        return f"(no export yet: {EXPORT}/n50.json is missing; python scripts/export_n50.py)\n"
    doc = json.loads(path.read_text())
    point = doc["grid"][len(doc["heights_m"]) * 5 + 9]
    lines = json.dumps(
        {k: point[k] for k in ("pressure_bar", "height_m", "force_N", "feff_m2")}, indent=1
    )
    return body_of(
        [
            f"{EXPORT}/n50.json: model {doc['model']['label']}; one of {len(doc['grid'])} grid points:"
        ]
        + [_cut(ln) for ln in lines.splitlines()]
    )


def shown(args: str, lines: list[str], keep: int | None) -> list[str]:
    """The lines a block shows for one command: ``$ uq ARGS`` and its output (maybe cut short)."""
    if keep is not None and len(lines) > keep:
        lines = lines[:keep] + [f"... ({len(lines) - keep} more lines)"]
    return [f"$ uq {args}", *lines]


def body_of(lines: list[str]) -> str:
    """A block's text: every line indented by four spaces (a Markdown code block)."""
    return "\n".join("    " + ln if ln else "" for ln in lines) + "\n"


def _load(rel: str) -> dict | None:
    path = ROOT / rel
    return json.loads(path.read_text()) if path.exists() else None


def speed_table() -> str:
    """Wall times of the run blocks (reports/readme-timings.json), with the load they ran under."""
    t = _load_timings()
    commands = [c for b in BLOCKS.values() for c in b.commands]
    rows = [(c, t[c]) for c in commands if c in t]
    if not rows:
        return "(no timings yet: python scripts/readme_numbers.py runs the commands)\n"
    out = [
        "| command | wall time | load average (1 min), the larger of start and end | date |",
        "| --- | --- | --- | --- |",
    ]
    for args, v in sorted(rows):
        out.append(
            f"| `uq {args}` | {v['seconds']:.0f} s | {v['load_average_1min']:.1f} on {v['cpus']} CPUs "
            f"| {v['date']} |"
        )
    return "\n".join(out) + "\n"


def width_ratio_summary(rel: str) -> Callable[[], str]:
    """Mean 90 % interval widths of the settings of one calibration run (the same replications),
    and each setting's ratio to the first: how much recorded pressure shrinks the intervals."""

    def make() -> str:
        data = _load(rel)
        if data is None:
            return f"(no results: {rel} is missing)\n"
        settings = data["settings"]
        names = list(settings[0]["quantities"])
        label = [
            "recorded pressure" if s.get("pressure") == "recorded" else "set pressure only"
            for s in settings
        ]
        out = [
            f"Mean width of the central 90 % interval over the {settings[0]['replications']} "
            f"replications of `{rel}` (SI units; the same simulated tests in every column):",
            "",
            "| quantity | " + " | ".join(label) + " | ratio |",
            "| --- |" + " --- |" * (len(settings) + 1),
        ]
        for n in names:
            w = [s["quantities"][n].get("mean_width90") for s in settings]
            if any(v is None for v in w):
                continue
            ratio = w[-1] / w[0]
            out.append(f"| {n} | " + " | ".join(f"{v:.4g}" for v in w) + f" | {ratio:.2f} |")
        return "\n".join(out) + "\n"

    return make


def calibration_summary(rel: str) -> Callable[[], str]:
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
            holm_text = f"{min(holm):.3f}" if holm else "-"
            model = s["noise_model"] + (
                ", measured pressure" if s.get("pressure", "set") == "recorded" else ""
            )
            model += ", AR(1) holding errors" if s.get("pressure_ar1", "off") == "on" else ""
            out.append(
                f"| {truth} | {model} | {s['replications']} | {s['converged_fraction']:.0%} "
                f"| {min(cov)}..{max(cov)} of {s['replications']} | {', '.join(outside) or 'none'} "
                f"| {pmin[0]:.3f} ({pmin[1]}) | {holm_text} | {pred} |"
            )
        return "\n".join(out) + "\n"

    return make


def surface_coverage_summary(rel: str) -> Callable[[], str]:
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

    return make


def sealed_coverage_summary(rel: str) -> Callable[[], str]:
    """scripts/sealed_coverage.py's counts: per scenario, covered of evaluable for each quantity."""

    def make() -> str:
        d = _load(rel)
        if d is None:
            return f"(no results: {rel} is missing)\n"
        lines = [
            f"From `{rel}` (`{d['command']}`; spring `{d['spring']}`, {d['replications']} replications, "
            + (f"model `{d['model']}`, " if "model" in d else "")
            + f"model orders {d['model_orders']}; {d['acceptance_rule']}, false failure < {d['false_failure_rate']:g}): "
            f"**{'passed' if d['passed'] else 'FAILED'}**; rms z of the sealed readings against the widened band "
            f"{d['reading_z_rms']:.2f}; {d['converged']} of {d['replications']} fits converged.",
            "",
            "| scenario | evaluable | accepted | "
            + " | ".join(d["counts"][next(iter(d["counts"]))]["covered"])
            + " |",
            "| --- | --- | --- |" + " --- |" * len(d["counts"][next(iter(d["counts"]))]["covered"]),
        ]
        for name, c in d["counts"].items():
            lo, hi = c["acceptance"]
            cells = " | ".join(
                f"{v}" + ("" if lo <= v <= hi else " (out)") for v in c["covered"].values()
            )
            lines.append(f"| {name} | {c['evaluable']} | {lo}-{hi} | {cells} |")
        if d.get("relative_width"):
            lines += [
                "",
                "Mean width of the 90 % intervals, in % of the truth:",
                "",
                "| scenario | " + " | ".join(next(iter(d["relative_width"].values()))) + " |",
                "| --- |" + " --- |" * len(next(iter(d["relative_width"].values()))),
            ]
            for name, w in d["relative_width"].items():
                lines.append(
                    f"| {name} | " + " | ".join(f"{100 * v:.1f}" for v in w.values()) + " |"
                )
        return "\n".join(lines) + "\n"

    return make


def diagnose_proof_summary(rel: str) -> Callable[[], str]:
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
        shaped = fa.get("shaped", {})
        if shaped:
            lines.insert(
                3,
                "- clean campaigns in the shapes that leave mechanisms unidentifiable: "
                + "; ".join(
                    f"{shape}: mismatch detected in {v['mismatch_detected']} of {v['runs']}, "
                    f"a mechanism named in {v['mechanism_named']}"
                    for shape, v in shaped.items()
                )
                + " (one-branch: compression only; one-pass: a catalogue, one compression pass in "
                "unknown order, the volume at one pressure)",
            )
        elastic = {k: v for k, v in det.items() if k.startswith("elastic_casing|")}
        if elastic:
            cov90 = d.get("coverage_90", {})
            lines.append(
                "- elastic casing (energy from a potential): found in "
                + ", ".join(
                    f"{v['named']} of {v['runs']} ({k.split('|', 1)[1].replace('|', ', ')}; truth in the "
                    f"90 % interval in {cov90.get(k, {}).get('true_in_90', 0)} of {v['named']})"
                    for k, v in elastic.items()
                )
            )
        return "\n".join(lines) + "\n"

    return make


def noise_check_summary(rel: str) -> Callable[[], str]:
    """scripts/noise_check_study.py: false alarms at the budget, and power."""

    def make() -> str:
        d = _load(rel)
        if d is None:
            return f"(no results: {rel} is missing)\n"
        s = d["summary"]
        lines = [
            f"From `{rel}` (`{d['command']}`): the check fails when q05 of a noise scale factor k "
            f"exceeds {s['noise_excess']:g} (before: {s['old_excess']:g}).",
            "",
            "| campaigns | how many | check fails | old rule fails | posterior mean of k (force) |",
            "| --- | --- | --- | --- | --- |",
        ]
        f = s["null"]["force"]
        lines.append(
            f"| at 1.0x the budget, the model they were made with | {s['n_null']} | "
            f"{s['null_alarms']} | {s['null_alarms_old']} | {f['k_mean_range'][0]:.2f} .. "
            f"{f['k_mean_range'][1]:.2f} |"
        )
        for what, p in s["power"].items():
            ks = p["k_force_mean"]
            lines.append(
                f"| {what} | {p['runs']} | {p['caught']} | {p['caught_old']} | "
                f"{min(ks):.2f} .. {max(ks):.2f} |"
            )
        q = max(t["q05_max"] for t in s["null"].values())
        lines += [
            "",
            f"False-alarm rate at the budget: at most {s['null_rate_upper_95']:.1%} per campaign "
            f"(one-sided 95 % binomial bound on {s['null_alarms']} of {s['n_null']}); the largest "
            f"q05 of k among them was {q:.2f}.",
        ]
        return "\n".join(lines) + "\n"

    return make


def diagnose_power_summary(rel: str) -> Callable[[], str]:
    def make() -> str:
        d = _load(rel)
        if d is None:
            return f"(no results: {rel} is missing)\n"
        n, k = d["seeds_per_rung"], d["needed"]

        def fmt(v):
            return "-" if v is None else f"{v:g}"

        lines = [
            f"From `{rel}` (`{d.get('command', 'scripts/diagnose_power.py')}`; {d['n_campaigns']} "
            f"campaigns, {n} seeds a rung, found = at least {k} of {n}; oracle: delta chi^2 with the "
            f"true noise, alpha = {d['alpha']:.1e}):",
            "",
            "| mechanism | engine: largest rung failing | engine: smallest rung found | "
            "oracle on the same campaigns: smallest rung found | oracle, exact 90 % power |",
            "| --- | --- | --- | --- | --- |",
        ]
        for mech, v in d["mechanisms"].items():
            ex = v.get("oracle_exact_90")
            lines.append(
                f"| {mech} | {fmt(v['engine_largest_failing'])} | {fmt(v['engine_smallest_passing'])} "
                f"| {fmt(v['oracle_smallest_passing'])} | "
                f"{'-' if ex is None else format(ex['magnitude_90'], '.3g')} |"
            )
        return "\n".join(lines) + "\n"

    return make


def _bench_missing(rel: str, flag: str) -> str:
    return f"(no benchmark yet: `python benchmarks/bench.py {flag}--json {rel}` writes it)\n"


def ess_bench_summary(rel: str) -> Callable[[], str]:
    def make() -> str:
        r = _load(rel)
        if r is None:
            return _bench_missing(rel, "")
        p, b = r["project"], r["baseline"]
        lines = [
            f"From `{rel}` (`python benchmarks/bench.py`, {r['cores']} cores at load average "
            f"{r['load_average_1min']:.1f}): {r['workload']}, {r['n_points']} points; force posterior, "
            "min bulk ESS of a_P..d_P per second",
            "",
            f"- project: {p['ess_per_s']:.1f} ESS/s ({p['ess_bulk_min']:.0f} ESS in {p['wall_s']:.2f} s, "
            f"{p['runs']} run(s))",
            f"- baseline (plain emcee): {b['ess_per_s']:.1f} ESS/s ({b['ess_bulk_min']:.0f} ESS in "
            f"{b['wall_s']:.2f} s, {b['n_steps']} steps x {b['n_walkers']} walkers, tau {b['tau_max']:.0f})",
            f"- ratio project / baseline: {r['ratio']:.1f}; per quantity: "
            + ", ".join(f"{n} {v:.1f}" for n, v in r["ratio_each"].items())
            + f"; smallest {r['ratio_min_all']:.1f}",
        ]
        return "\n".join(lines) + "\n"

    return make


def discrepancy_bench_summary(rel: str) -> Callable[[], str]:
    """``benchmarks/discrepancy.py``: a call of the discrepancy log posterior with malloc's
    defaults and with uq's thresholds (``uq._inference.allocator``), in one process."""

    def make() -> str:
        r = _load(rel)
        if r is None:
            return _bench_missing(rel, "")
        lines = [
            f"From `{rel}` (`python benchmarks/discrepancy.py`, {r['cores']} cores at load average "
            f"{r['load_average_1min']:.1f}): {r['workload']}.",
            "",
            "| malloc | user CPU a call | kernel CPU a call | wall a call | page faults a call |",
            "| --- | --- | --- | --- | --- |",
        ]
        names = {"malloc_defaults": "glibc's defaults", "tuned": "uq's thresholds"}
        for key, label in names.items():
            x = r["runs"][key]
            lines.append(
                f"| {label} | {x['user_ms']:.1f} ms | {x['sys_ms']:.1f} ms | {x['wall_ms']:.1f} ms "
                f"| {x['page_faults']:.0f} |"
            )
        lines += [
            "",
            f"A call with glibc's defaults over one with uq's thresholds "
            f"({r['threshold_bytes'] / 2**20:.0f} MB): CPU {r['cpu_ratio']:.2f}x, wall "
            f"{r['wall_ratio']:.2f}x.",
        ]
        if "formulas" in r:  # the previous formula of the density against the current one
            prev, cur = r["formulas"]["previous"], r["formulas"]["current"]
            lines += [
                "",
                f"The previous formula of the same density (commit c8f9c5f) against the current one, "
                f"with uq's thresholds, in alternating rounds: CPU a call {prev['user_ms'] + prev['sys_ms']:.1f} "
                f"ms against {cur['user_ms'] + cur['sys_ms']:.1f} ms ({r['formula_cpu_ratio']:.2f}x), "
                f"wall {r['formula_wall_ratio']:.2f}x; the two agree to "
                f"{r['formula_max_rel_diff']:.0e} relative.",
            ]
        return "\n".join(lines) + "\n"

    return make


def commands_bench_summary(rel: str) -> Callable[[], str]:
    """The before/after table of ``benchmarks/commands.py --baseline`` (issue 32's goals)."""

    def make() -> str:
        r = _load(rel)
        if r is None:
            return (
                f"(no benchmark yet: `python benchmarks/commands.py --baseline MAIN --json {rel}` "
                "writes it)\n"
            )
        lines = [
            f"From `{rel}` (`python benchmarks/commands.py`, {r['cores']} cores at load average "
            f"{r['load_average_1min']:.1f}, {r['date']}): {r['workload']}, warm compilation cache, "
            f"median of {r['reps']} repetitions; each command and the import floor "
            f"(`import {', '.join(r['floor_modules'])}`: median {r['floor_wall_s']:.1f} s wall, "
            f"{r['floor_cpu_s']:.1f} s CPU) in fresh interpreters, back to back. Before: "
            f"{r.get('baseline_label') or 'the baseline checkout'}; after: commit {r['commit']}.",
            "",
            "| command | goal (x floor) | wall x floor, before | after | CPU x floor, before | after "
            "| CPU s, before | after | peak RSS MB, before | after | largest worker MB, before | after |",
            "| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |",
        ]
        for n, c in r["commands"].items():
            b = c.get("baseline") or {}

            def pair(key, fmt, b=b, c=c):
                before = format(b[key], fmt) if key in b else "-"
                return f"{before} | {format(c[key], fmt)}"

            goal = f"{c['goal_ratio']:.1f}" if c.get("goal_ratio") else "-"
            lines.append(
                f"| `uq {n}` | {goal} | {pair('ratio_wall', '.2f')} | {pair('ratio_cpu', '.2f')} "
                f"| {pair('cpu_s', '.1f')} | {pair('peak_rss_mb', '.0f')} "
                f"| {pair('children_peak_rss_mb', '.0f')} |"
            )
        if r.get("note"):
            lines += ["", f"Note: {r['note']}"]
        return "\n".join(lines) + "\n"

    return make


def margin_bench_summary(rel: str) -> Callable[[], str]:
    def make() -> str:
        d = _load(rel)
        if d is None:
            return _bench_missing(rel, "--margin ")
        f, s, q, c = (
            d["full_query"],
            d["from_saved_file"],
            d["queries_from_saved_file"],
            d["cold_cli_from_saved_file"],
        )
        return (
            f"From `{rel}` (`python benchmarks/bench.py --margin`, one process, {d['cores']} cores at load average "
            f"{d['load_average_1min']:.1f}; answered by the {d['answered_by']}): full query (fit both models, "
            f"compare, answer) {f['wall_s']:.0f} s; the same query from the saved file {s['wall_s']:.2f} s "
            f"(ratio {d['ratio_full_to_saved']:.0f}x, identical answer: {d['identical_answer']}); "
            f"{q['n']} queries from one load of the file {q['per_query_s']:.2f} s each; a cold "
            f"`uq margin --fit` in a fresh interpreter {c['wall_s']:.1f} s, almost all of it imports.\n"
        )

    return make


def batch_bench_summary(rel: str) -> Callable[[], str]:
    def make() -> str:
        r = _load(rel)
        if r is None:
            return _bench_missing(rel, "--batch 20,50,200 ")
        s, p, line = r["serial"], r["pointwise"], r["line"]
        lines = [
            f"From `{rel}` (`python benchmarks/bench.py --batch {','.join(map(str, r['sizes']))}`, "
            f"{r['cores']} cores at load average {r['load_average_1min']:.1f}): {r['workload']}, "
            f"up to {r['batch_campaigns']} campaigns per sampling run; after a warm-up in the same "
            "process (imports and compilation excluded).",
            "",
            "| run | campaigns | wall s a campaign | CPU s a campaign | converged | MB a campaign |",
            "| --- | --- | --- | --- | --- | --- |",
        ]
        rows = [("`--serial` (one by one)", s)]
        rows += [("batched (the default)", b) for b in r["batched"]]
        rows += [("batched, `pointwise = yes`", p)]
        lines += [
            f"| {name} | {x['campaigns']} | {x['wall_per_campaign_s']:.2f} | "
            f"{x['cpu_per_campaign_s']:.2f} | {x['converged']} | {x['mb_per_campaign']:.1f} |"
            for name, x in rows
        ]
        cpu = r["cpu_line"]
        lines += [
            "",
            f"`--serial` / batched ({s['campaigns']} campaigns each): "
            f"{r['cpu_ratio_serial_to_batched']:.2f} in CPU time, "
            f"{r['ratio_serial_to_batched']:.2f} in wall time. The line through the batched runs' "
            f"CPU times: {_per_campaign(cpu)}, so 1000 "
            f"campaigns take about {r['predicted_1000_cpu_min']:.0f} CPU minutes"
            + (
                " (measured: 1000 campaigns in the table)"
                if 1000 in r["sizes"]
                else " (extrapolated from the line)"
            )
            + ", about the wall time on an idle machine, where this process has a core to itself "
            f"(the wall-time line, at this load: {_per_campaign(line)}). "
            f"Peak RSS {r['peak_rss_mb']:.0f} MB.",
        ]
        return "\n".join(lines) + "\n"

    return make


def _per_campaign(line: dict) -> str:
    """A line through a benchmark's times: "a s a campaign + b s"."""
    b = line["intercept_s"]
    return (
        f"{line['seconds_per_campaign']:.2f} s a campaign {'+' if b >= 0 else '-'} {abs(b):.1f} s"
    )


def batch_netcdf_summary(rel: str) -> Callable[[], str]:
    """benchmarks/bench.py --batch: one test's NetCDF file written six ways, and the bytes of
    the batch's campaigns with and without the pointwise groups."""
    names = {
        "by_group_zlib": "h5netcdf, group after group, zlib on every number (two rounds ago)",
        "by_group_no_float_zlib": "h5netcdf, group after group, no zlib on floats",
        "one_pass_h5netcdf": "h5netcdf, one pass, no zlib on floats (before netCDF4)",
        "one_pass_h5netcdf_no_pointwise": "h5netcdf, one pass, without the pointwise groups",
        "one_pass": "netCDF4 in memory, one pass (`uq fit --out`)",
        "one_pass_no_pointwise": "netCDF4 in memory, without the pointwise groups (`uq batch`)",
    }

    def make() -> str:
        r = _load(rel)
        if r is None or "netcdf" not in r:
            return _bench_missing(rel, "--batch 20,50,200 ")
        nc = r["netcdf"]
        base = nc["by_group_zlib"]
        labels = dict(names)
        if "one_pass_h5netcdf" not in nc:  # a run before the netCDF4 engine: h5netcdf's one pass
            labels["one_pass"] = "h5netcdf, one pass, no zlib on floats (`uq fit --out` then)"
            labels["one_pass_no_pointwise"] = "h5netcdf, no pointwise groups (`uq batch` then)"
        lines = [
            f"From `{rel}` (`python benchmarks/bench.py --batch`, load average "
            f"{r['load_average_1min']:.1f}; best of 5): one test's file (the last test of the "
            "first campaign)",
            "",
            "| written | seconds | x before | MB | x before |",
            "| --- | --- | --- | --- | --- |",
        ]
        lines += [
            f"| {labels[k]} | {v['seconds']:.2f} | {v['seconds'] / base['seconds']:.2f} | "
            f"{v['mb']:.1f} | {v['mb'] / base['mb']:.2f} |"
            for k, v in nc.items()
        ]
        full = r["pointwise"]
        slim = next(b for b in r["batched"] if b["campaigns"] == full["campaigns"])
        lines += [
            "",
            f"Without the pointwise groups a file holds {1 - nc['one_pass_no_pointwise']['mb'] / nc['one_pass']['mb']:.0%} "
            f"fewer bytes; {full['campaigns']} batched campaigns wrote {full['mb_per_campaign']:.1f} MB a campaign with "
            f"`pointwise = yes` and {slim['mb_per_campaign']:.1f} MB without (1000 campaigns: "
            f"{full['mb_per_campaign']:.0f} GB against {slim['mb_per_campaign']:.1f} GB), and took "
            f"{full['cpu_per_campaign_s']:.2f} CPU s against {slim['cpu_per_campaign_s']:.2f} CPU s a campaign.",
        ]
        return "\n".join(lines) + "\n"

    return make


def scaling_bench_summary(rel: str) -> Callable[[], str]:
    def make() -> str:
        r = _load(rel)
        if r is None:
            return _bench_missing(rel, "--scaling ")
        lines = [
            f"From `{rel}` (`python benchmarks/bench.py --scaling`, load average "
            f"{r['load_average_1min']:.1f}): {r['workload']}",
            "",
            *table(SCALING, r["runs"], True),
        ]
        rep = r["report"]
        lines += [
            "",
            f"`uq report` on the paper's campaign in a fresh process: {rep['wall_s']:.1f} s, peak RSS "
            f"{rep['peak_rss_mb']:.0f} MB.",
        ]
        return "\n".join(lines) + "\n"

    return make


def memory_bench_summary(rel: str) -> Callable[[], str]:
    """benchmarks/bench.py --memory: uq fit's peak RSS against the readings, the line through them,
    the model uq fit checks campaigns with, the 0.01 mm ramp, the largest campaign then."""

    def make() -> str:
        r = _load(rel)
        if r is None:
            return _bench_missing(rel, "--memory ")
        m, ramp = r["model"], r["ramp"]
        lines = [
            f"From `{rel}` (`python benchmarks/bench.py --memory`, {r['cores']} cores at load "
            f"average {r['load_average_1min']:.1f}): {r['workload']}",
            "",
            *table(MEMORY, r["runs"], True),
        ]
        room = r["available_gb"]
        peaks = [x["peak_rss_mb"] for x in r["runs"]]
        sizes = [x["readings"] for x in r["runs"]]
        spread = max(peaks) - min(peaks)
        lines += [
            "",
            f"Measured: the line's slope {r['measured_bytes_per_reading'] / 1e3:.1f} kB a reading and "
            f"constant {r['measured_constant_gb']:.2f} GB; the peaks lie within {spread:.0f} MB of each "
            f"other over {max(sizes) - min(sizes)} readings, "
            f"{spread * 1024**2 / (max(sizes) - min(sizes)) / 1e3:.0f} kB a reading: at these sizes "
            "what a reading costs is lost in how much a run's constant moves (a run that compiles "
            "against one that finds its programs cached). The model `uq fit` and `uq report` check a campaign "
            f"against before fitting (`uq._io.memory.FIT`): {m['bytes_per_reading'] / 1e3:.0f} kB a "
            f"reading and {m['constant_gb']:.2f} GB, "
            + ("above every measured peak" if m["covers_every_run"] else "BELOW a measured peak")
            + f". The {ramp['step_mm']:g} mm ramp of `uq simulate` ({ramp['readings']} readings): "
            f"{ramp['model_gb']:.1f} GB by the model"
            + (
                f" ({ramp['line_gb']:.1f} GB on the measured line)"
                if r["measured_bytes_per_reading"] > 0
                else ""
            )
            + (
                "."
                if room is None
                else f"; with the {room:.1f} GB available when measured, the largest campaign "
                f"`uq fit` takes is about {r['largest_readings_now']} readings."
            ),
        ]
        o = r.get("out")
        if o is not None:
            lines += [
                "",
                f"`uq fit --out` at {o['readings']} readings ({o['largest_test']} in each test): peak "
                f"RSS {o['peak_rss_mb']:.0f} MB, {o['measured_bytes_per_test_reading'] / 1e3:.0f} kB a "
                "reading of the largest test above the line (one test's InferenceData and NetCDF "
                "bytes, and the imports of ArviZ and xarray); the model it is checked against "
                f"(`uq._io.memory.FIT_OUT`) adds {o['model_bytes_per_test_reading'] / 1e3:.0f} kB a "
                f"reading of the largest test ({o['fit_out_model_mb']:.0f} MB here): "
                f"{o['ramp_model_gb']:.1f} GB for the {ramp['step_mm']:g} mm ramp"
                + (
                    "."
                    if room is None
                    else f", at most about {r['largest_readings_now_out']} readings in tests like "
                    "these on this machine then."
                ),
            ]
        return "\n".join(lines) + "\n"

    return make


def plan_proof_summary(rel: str) -> Callable[[], str]:
    """scripts/plan_proof.py: achieved against predicted sd, coverage, plan against uniform grid."""

    def make() -> str:
        d = _load(rel)
        if d is None:
            return f"(no results: {rel} is missing)\n"
        lo, hi = d["binomial_region_95"]
        lines = [
            f"From `{rel}` (`{d['command']}`; {d['replications']} replications):",
            "",
            f"- 90 % intervals holding the truth: {d['covered']} of {d['intervals']} (exact binomial "
            f"95 % region {lo}-{hi}).",
            f"- Achieved over predicted posterior sd: mean {d['ratio_mean']:.2f}, range "
            f"{d['ratio_min']:.2f}-{d['ratio_max']:.2f}.",
        ]
        from plan_proof import claim_lines, theta_lines, theta_updated_lines  # the proof's own

        lines += claim_lines(d)
        lines += [
            f"- Fits converged: {d['converged']['plan']} of {d['replications']} after the plan, "
            f"{d['converged']['uniform']} after the uniform grid.",
            "",
            "| scenario | target | replications | achieved / predicted sd: mean (range) | truth covered "
            "| uniform grid's sd over the plan's | plan better |",
            "| --- | --- | --- | --- | --- | --- | --- |",
        ]
        for t in d["by_target"]:
            lines.append(
                f"| {t['scenario']} | `{t['spec']}` | {t['n']} | {t['ratio_mean']:.2f} "
                f"({t['ratio_min']:.2f}-{t['ratio_max']:.2f}) | {t['covered']}/{t['n']} | "
                f"{t['uniform_over_plan_sd']:.2f} | {t['plan_better']}/{t['n']} |"
            )
        lines += [
            "",
            "Flagged (a mean ratio outside 0.8-1.25, a replication outside 0.6-1.6, coverage "
            "below its binomial region, a model choice that changed):",
            "",
        ]
        lines += [f"- {w}" for w in d.get("poor", [])] or ["- none"]
        if d.get("model_choice"):
            lines += ["", f"{d['model_choice'][0].upper()}{d['model_choice'][1:]}."]
        lines += theta_updated_lines(d)
        lines += theta_lines(d)
        if d.get("notes"):
            lines += ["", "Notes on the runs:", ""] + [f"- {n}" for n in d["notes"]]
        return "\n".join(lines) + "\n"

    return make


def n50_bands_summary(rel: str) -> Callable[[], str]:
    """scripts/n50_bands.py: the three models' 90 % force bands on data/n50 against Table 1's curves."""

    def make() -> str:
        d = _load(rel)
        if d is None:
            return f"(no results: {rel} is missing)\n"
        models = ("discrepancy", "surface", "cubics")
        heights = ", ".join(f"{h:g}" for h in d["heights_mm"])
        lines = [
            f"From `{rel}` (`{d['command'].strip()}`; {d['source']}, seed {d['seed']}; truth: Table 1's "
            "cubics, PCHIP between the tested pressures). The 90 % force band holds the truth at:",
            "",
            "| points | discrepancy surface | smooth surface | per-pressure cubics |",
            "| --- | --- | --- | --- |",
        ]
        for key, words in (
            ("tested_33", f"the 11 tested pressures at {heights} mm"),
            ("tested_all", "every tested (pressure, height)"),
            ("between", f"half-way between tested pressures at {heights} mm"),
        ):
            cells = " | ".join(
                f"{d[key][m]['covered']} of {d[key][m]['of']} (mean width {d[key][m]['mean_width_N']:.0f} N)"
                for m in models
            )
            lines.append(f"| {words} | {cells} |")
        a = d["at_tested_against_cubics"]["discrepancy"]
        s = d["at_tested_against_cubics"]["surface"]
        hp = d["hyperparameters"]
        lines += [
            "",
            f"At the tested points the discrepancy surface's band is {a['width_over_cubics_median']:.2f} "
            f"times as wide as the cubics' (median; {a['width_over_cubics_range'][0]:.2f}-"
            f"{a['width_over_cubics_range'][1]:.2f}) and its centre {a['centre_shift_in_cubic_sd_median']:.2f} "
            f"cubic sd from theirs (median; at most {a['centre_shift_in_cubic_sd_max']:.2f}); the smooth "
            f"surface's centre is {s['centre_shift_in_cubic_sd_median']:.2f} cubic sd from theirs (at most "
            f"{s['centre_shift_in_cubic_sd_max']:.2f}). Posterior: a_F {hp['a_F_m2']['mean'] * 1e4:.1f} cm^2 "
            f"[{hp['a_F_m2']['q05'] * 1e4:.1f}, {hp['a_F_m2']['q95'] * 1e4:.1f}], a_V "
            f"{hp['a_V_m2']['mean'] * 1e4:.1f} cm^2 [{hp['a_V_m2']['q05'] * 1e4:.1f}, "
            f"{hp['a_V_m2']['q95'] * 1e4:.1f}], "
            + (
                f"a_P {hp['a_P_m2']['mean'] * 1e4:.1f} cm^2 [{hp['a_P_m2']['q05'] * 1e4:.1f}, "
                f"{hp['a_P_m2']['q95'] * 1e4:.1f}], "
                if "a_P_m2" in hp
                else ""
            )
            + f"length scale {hp['length_bar']['mean']:.2f} bar "
            f"[{hp['length_bar']['q05']:.2f}, {hp['length_bar']['q95']:.2f}]; "
            f"{'converged' if d['converged'] else 'NOT converged'}.",
        ]
        b = d.get("between_nodes")
        if b:
            lines += [
                "",
                f"Between the virtual pressures ({b['node_step_bar']:.2f} bar apart): "
                f"{100 * b['share_length_below_0.5_bar']:.0f} % of the draws have a length scale below "
                f"0.5 bar, {100 * b['share_length_below_0.25_bar']:.0f} % below 0.25 bar; the conditional "
                "variance the two-point mean neglects half-way between nodes is, averaged over the draws, "
                f"{100 * b['mean_neglected_variance']:.2f} % of the deviation's prior variance.",
            ]
        return "\n".join(lines) + "\n"

    return make


def between_coverage_summary(rel: str) -> Callable[[], str]:
    """scripts/between_coverage.py: pooled coverage per spring and grid, the width ratio, the
    counts outside their interval."""

    def make() -> str:
        d = _load(rel)
        if d is None:
            return f"(no results: {rel} is missing)\n"
        models = ("discrepancy", "surface", "cubics")
        reps = d["replications"]
        n = ", ".join(f"{k} {v}" for k, v in reps.items()) if isinstance(reps, dict) else reps
        pooled, ratio = d["pooled_coverage"], d["width_ratio_discrepancy_over_surface"]
        lines = [
            f"From `{rel}` (`{d['command'].strip()}`; replications per spring and grid: {n}; "
            f"{d['seconds'] / 3600:.1f} h of wall time; RECONSTRUCTED data). Share of the queries half-way "
            "between tested pressures whose 90 % interval held the truth, pooled over heights, pressures "
            "and replications (a summary: the by-pressure-and-height counts with their binomial "
            "intervals are in `reports/between-coverage/summary.md`):",
            "",
            "| spring | grid | what | discrepancy | surface | cubics | width: discrepancy / surface |",
            "| --- | --- | --- | --- | --- | --- | --- |",
        ]
        keys = sorted({k.rsplit("/", 2)[0] for k in pooled}, key=lambda k: (k.split("/")[1], k))
        for key in keys:
            spring, grid = key.split("/")
            for what in ("force", "margin"):
                vals = [pooled.get(f"{key}/{m}/{what}") for m in models]
                r = ratio.get(f"{key}/{what}")
                lines.append(
                    f"| {spring} | {grid} | {what} | "
                    + " | ".join("-" if v is None else f"{v:.2f}" for v in vals)
                    + f" | {'-' if r is None else f'{r:.2f}'} |"
                )
        # the paper's stand, and stands other than the models assume (grids g@name), apart
        stands = {"@" in r["grid"] for r in d["rows"]}
        counts = []
        for other in sorted(stands):
            rows = [r for r in d["rows"] if ("@" in r["grid"]) == other]
            side = {
                (m, way): sum(r.get("side") == way for r in rows if r["model"] == m)
                for m in models
                for way in ("below", "above")
            }
            total = {m: sum(r["model"] == m for r in rows) for m in models}
            counts.append(
                ("on another stand (g@name): " if other else "on the paper's stand: ")
                + ", ".join(
                    f"{m} {side[m, 'below']} and {side[m, 'above']} of {total[m]}" for m in models
                )
            )
        lines += [
            "",
            "Counts (by spring, grid, pressure, height and force or margin) whose exact 90 % interval "
            "lies below 0.90 (the model's intervals too narrow there: a user is misled) and above "
            "it (too wide: cautious): "
            + "; ".join(counts)
            + ". CPU seconds per fit (mean): "
            + ", ".join(f"{m} {v:.0f}" for m, v in d["mean_cpu_seconds_per_fit"].items())
            + ".",
        ]
        short = [r for r in d["rows"] if r["model"] == "discrepancy" and r.get("side") == "below"]
        lines += [
            "",
            "The discrepancy surface's counts whose interval lies below 0.90, by (spring, grid, "
            "pressure, height): "
            + (
                "; ".join(
                    f"{r['spring']} {r['grid']} {r['what']} at {r['pressure_bar']:g} bar and "
                    f"{r['height_mm']:g} mm: {r['covered']} of {r['n']} "
                    f"[{r['interval'][0]:.2f}, {r['interval'][1]:.2f}]"
                    + (f" ({r['refused']} refused)" if r["refused"] else "")
                    for r in short
                )
                if short
                else "none"
            )
            + ".",
        ]
        checked = d.get("model_check") or {}
        if checked:
            lines += [
                "",
                "The model check `uq margin` and `uq design` run with every answer (exit 1 when the "
                "model misses the readings it was fitted to): campaigns it flagged, and the pooled "
                "share of force queries covered in all campaigns and in those it passed:",
                "",
                *model_check_table(checked),
            ]
        return "\n".join(lines) + "\n"

    return make


def discrepancy_cost(rel: str) -> Callable[[], str]:
    """scripts/between_coverage.py's CPU seconds per fit: the discrepancy surface against the smooth
    surface and the cubics, fitted in one process to the same campaigns."""

    def make() -> str:
        d = _load(rel)
        if d is None:
            return f"(no results: {rel} is missing)\n"
        models = ("discrepancy", "surface", "cubics")
        lines = [
            f"From `{rel}` (CPU seconds of one fit, mean over the replications, one BLAS thread):",
            "",
            "| campaigns | fits | discrepancy | surface | cubics | discrepancy / surface |",
            "| --- | --- | --- | --- | --- | --- |",
        ]
        for key, runs in sorted(d["runs"].items(), key=lambda kv: (kv[0].split("/")[1], kv[0])):
            cpu = {m: sum(r["cpu_seconds"][m] for r in runs) / len(runs) for m in models}
            lines.append(
                f"| {key} | {len(runs)} | "
                + " | ".join(f"{cpu[m]:.1f} s" for m in models)
                + f" | {cpu['discrepancy'] / cpu['surface']:.1f} |"
            )
        return "\n".join(lines) + "\n"

    return make


BLOCKS: dict[str, Block] = {
    "simulate-n50": run_block(
        "simulate --out data/n50/recordings.csv --spring n50 --seed 20201 --pressures "
        "0.1,1,2,3,4,5,6,7,8,9,10 --x-max-mm 155 --x-min-mm 65 --step-mm 5 --piston-area-cm2 54.82"
    ),
    "fit-bad-csv": run_block("fit docs/examples/bad-cell.csv", statuses=(2,)),
    "fit-bluehill-sign": run_block(
        "fit data/n50-bluehill/recordings.csv --columns height=Position,force=Load", statuses=(2,)
    ),
    "fit-n50": run_block(f"fit {DATA} --json reports/n50-fit.json"),
    "check-n50": run_block(
        "check reports/n50-fit.json --against fits/n50/table1_points.json", requires=("fit-n50",)
    ),
    "check-moved": run_block(
        "check reports/n50-fit.json --against docs/examples/table1-a_P-moved.json",
        requires=("fit-n50",),
        keep=8,
    ),
    "report-n50": run_block(f"report {DATA} --out reports/n50", keep=30, slow=True),
    "surface-select": run_block(f"surface {DATA} --select --no-compare", slow=True),
    "surface-n50": run_block(f"surface {DATA}", slow=True),
    "margin-n50": run_block(
        f"margin {DATA} --height-mm 112 --load-N 13020 --pressure-bar 5 --tolerance-pct 10",
        slow=True,
    ),
    "diagnose-n50": run_block(f"diagnose {DATA}", keep=45, slow=True),
    "thermo-n50": run_block(f"surface {DATA} --model thermodynamic", slow=True),
    "thermo-spring": run_block(
        "simulate --spring n50-thermo --seed 5 --out n50-thermo.csv",
        "surface n50-thermo.csv --model thermodynamic",
        slow=True,
    ),
    "design-n50": run_block(
        f"design {DATA} --height-mm 112 --charge-bar 5 --volume-l 3.4 --forcing-hz 5 "
        "--out reports/n50-design",
        slow=True,
    ),
    "sealed-coverage": report_block(
        sealed_coverage_summary("reports/sealed-coverage/coverage.json")
    ),
    "sealed-coverage-user": report_block(
        sealed_coverage_summary("reports/sealed-coverage-user/coverage.json")
    ),
    "sealed-between-kink": report_block(
        sealed_coverage_summary("reports/sealed-between/n50-kink/coverage.json")
    ),
    "sealed-between-knee": report_block(
        sealed_coverage_summary("reports/sealed-between/n50-knee/coverage.json")
    ),
    "sealed-between-ripple": report_block(
        sealed_coverage_summary("reports/sealed-between/n50-ripple/coverage.json")
    ),
    "sealed-between-kink-surface": report_block(
        sealed_coverage_summary("reports/sealed-between/n50-kink-surface/coverage.json")
    ),
    "maxwell-table1": report_block(maxwell_summary("reports/maxwell-table1/maxwell.json")),
    "speed": report_block(speed_table),
    "bench-commands": report_block(commands_bench_summary("reports/bench/commands.json")),
    "bench-ess": report_block(ess_bench_summary("reports/bench/ess.json")),
    "bench-discrepancy": report_block(discrepancy_bench_summary("reports/bench/discrepancy.json")),
    "bench-margin": report_block(margin_bench_summary("reports/bench/margin.json")),
    "bench-batch": report_block(batch_bench_summary("reports/bench/batch.json")),
    "bench-batch-netcdf": report_block(batch_netcdf_summary("reports/bench/batch.json")),
    "bench-scaling": report_block(scaling_bench_summary("reports/bench/scaling.json")),
    "bench-memory": report_block(memory_bench_summary("reports/bench/memory.json")),
    "calibration": report_block(calibration_summary("reports/calibration/calibration.json")),
    "calibration-rough-stand": report_block(
        calibration_summary("reports/calibration-rough-stand/calibration.json")
    ),
    "calibration-rough-stand-ar1": report_block(
        calibration_summary("reports/calibration-rough-stand-ar1/calibration.json")
    ),
    "calibration-measured-pressure": report_block(
        calibration_summary("reports/calibration-measured-pressure/calibration.json")
    ),
    "measured-pressure-widths": report_block(
        width_ratio_summary("reports/calibration-measured-pressure/calibration.json")
    ),
    "surface-coverage": report_block(
        surface_coverage_summary("reports/surface-coverage/coverage.json")
    ),
    "diagnose-proof": report_block(diagnose_proof_summary("reports/diagnose-proof/summary.json")),
    "plan-example": run_block(
        "simulate --spring n50-smooth --pressures 2,5,8 --seed 3 --out pilot.csv",
        "plan pilot.csv --target force@110mm,6.5bar --target pressure_for@110mm,9000N "
        "--max-readings 60 --model surface --json plan.json --template next-tests.csv --plot plan.png",
        slow=True,
    ),
    "plan-proof": report_block(plan_proof_summary("reports/plan-proof/proof.json")),
    "diagnose-power": report_block(diagnose_power_summary("reports/diagnose-power/power.json")),
    "noise-check": report_block(noise_check_summary("reports/noise-check/results.json")),
    "n50-bands": report_block(n50_bands_summary("reports/between-coverage/n50-bands.json")),
    "discrepancy-cost": report_block(discrepancy_cost("reports/between-coverage/coverage.json")),
    "between-coverage": report_block(
        between_coverage_summary("reports/between-coverage/coverage.json")
    ),
    "export-csv": report_block(export_csv_summary),
    "export-xlsx": report_block(export_xlsx_summary),
    "export-simscape": report_block(
        export_text(
            "n50.m",
            pick=lambda ln: (
                ln.startswith(
                    (
                        "% Parameterization",
                        "airspring.height",
                        "airspring.pressure",
                        "airspring.load.q",
                    )
                )
                or ln.startswith("% model:")
            ),
            lines=9,
        )
    ),
    "export-teimorbit": report_block(export_text("n50_q50.tpf", start="$----", lines=34)),
    "export-sealed": report_block(
        export_text(
            "n50-sealed.m",
            pick=lambda ln: ln.startswith(
                (
                    "airspring.sealed.height",
                    "airspring.sealed.load.q50",
                    "airspring.sealed.stiffness.q50",
                    "airspring.sealed.rate.q50",
                )
            ),
            lines=4,
        )
    ),
    "export-json": report_block(export_json_summary),
}


# ----------------------------------------------------------------------------- checking a run block

NUMBER = re.compile(r"[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?")
TIMING = re.compile(r"(?<![\w.])\d+(?:\.\d+)? s\b")  # "11.5 s": wall times differ run to run
#: Numbers may differ between machines in their last digits (floating-point sums in another
#: order, another BLAS; XLA compiles for the CPU's own vector instructions, so a seeded chain can
#: leave its twin's path at rounding level on a CPU without AVX2 and its Monte Carlo estimates move
#: a little: an ESS of 7146 on one machine kind was 7124 on another): equal within this relative
#: tolerance or one unit of the last digit shown.
RTOL = 5e-3


def _close(a: str, b: str) -> bool:
    x, y = float(a), float(b)
    decimals = len(a.split(".")[1].split("e")[0].split("E")[0]) if "." in a else 0
    unit = 10.0**-decimals if "e" not in a.lower() else abs(x) * 10.0**-decimals
    return abs(x - y) <= max(RTOL * max(abs(x), abs(y)), unit * 1.0000001)


def _split(line: str) -> tuple[str, list[str]]:
    line = TIMING.sub("<time> s", line)
    return NUMBER.sub("<n>", line), NUMBER.findall(line)


def compare_lines(page: list[str], fresh: list[str]) -> list[str]:
    """Differences between what a page shows and a fresh run, one message each (empty: they agree).
    Text must match exactly, timings are masked, numbers agree within RTOL or the last digit."""
    problems = []
    if page and (m := re.fullmatch(r"\.\.\. \((\d+) more lines\)", page[-1])):
        cut = len(page) - 1
        if len(fresh) - cut != int(m[1]):
            problems.append(f"the page says {m[1]} more lines, the run has {len(fresh) - cut}")
        page, fresh = page[:cut], fresh[:cut]
    if len(page) != len(fresh):
        problems.append(f"the page shows {len(page)} lines, the run printed {len(fresh)}")
    for i, (want, got) in enumerate(zip(page, fresh, strict=False)):
        (t1, n1), (t2, n2) = _split(want), _split(got)
        if t1 != t2 or len(n1) != len(n2) or not all(map(_close, n1, n2)):
            problems.append(f"line {i + 1}:\n  page: {want}\n  run:  {got}")
    return problems


def parse_run_body(body: str) -> list[tuple[str, list[str]]]:
    """(command after ``$ uq``, its shown output lines) for each command of a run block's text."""
    out: list[tuple[str, list[str]]] = []
    for raw in body.splitlines():
        line = raw[4:] if raw.startswith("    ") else raw
        if line.startswith("$ uq "):
            out.append((line[len("$ uq ") :], []))
        elif out:
            out[-1][1].append(line)
    return out


def block_bodies() -> dict[str, tuple[Path, str]]:
    """Every generated block of every page: name -> (page, body)."""
    found = {}
    for page in pages():
        for m in BLOCK.finditer(page.read_text(encoding="utf-8")):
            if m["name"] in found:
                raise SystemExit(f"readme_numbers: block '{m['name']}' appears twice")
            found[m["name"]] = (page, m["body"])
    return found


# ----------------------------------------------------------------------------- regenerating


def make_run_body(name: str, workspace: Path, made: dict[str, str], timed: set[str]) -> str:
    """Run the block's commands in ``workspace`` (after those of the blocks it requires, once
    each: ``made`` keeps the bodies made so far) and return its text. The wall times of the
    blocks named in ``timed`` are recorded for the speed table."""
    if name in made:
        return made[name]
    block = BLOCKS[name]
    for req in block.requires:
        make_run_body(req, workspace, made, timed)
    lines = []
    for args in block.commands:
        load0 = os.getloadavg()[0]
        out, seconds = run_command(args, workspace, block.statuses)
        if name in timed:
            _save_timing(args, seconds, max(load0, os.getloadavg()[0]))
        if load0 > 1.5:
            print(
                f"readme_numbers: load average {load0:.1f} when `uq {args}` started: its time is not an idle one",
                file=sys.stderr,
            )
        lines += shown(args, out, block.keep)
    made[name] = body_of(lines)
    return made[name]


def regenerate(
    text: str, names: set[str], bodies: dict[str, str] | None = None, where: str = "README.md"
) -> tuple[str, list[str]]:
    """The page with the named blocks rebuilt (from ``bodies`` where given, else made now, which
    works for report blocks only), and the names of blocks whose text changed."""
    changed = []
    bodies = {} if bodies is None else bodies

    def repl(m: re.Match) -> str:
        name = m["name"]
        if name not in names:
            return m[0]
        if name not in BLOCKS:
            raise SystemExit(
                f"readme_numbers: {where} has a block '{name}' this script does not know"
            )
        body = bodies[name] if name in bodies else BLOCKS[name].summarise()
        if body != m["body"]:
            changed.append(name)
        return m[1] + body + m[4]

    return BLOCK.sub(repl, text), changed


def _write(page: Path, text: str) -> None:
    fd, tmp = tempfile.mkstemp(dir=page.parent, prefix=f".{page.name}.", suffix=".tmp")
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        f.write(text)
    os.chmod(tmp, page.stat().st_mode & 0o777)
    os.replace(tmp, page)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="+", choices=sorted(BLOCKS), help="rebuild only these blocks")
    ap.add_argument(
        "--reports-only", action="store_true", help="rebuild only the blocks made from reports/"
    )
    ap.add_argument(
        "--check",
        action="store_true",
        help="rebuild the report blocks in memory; exit 1 if a page differs",
    )
    args = ap.parse_args(argv)
    present = block_bodies()
    unknown = sorted(set(present) - set(BLOCKS))
    if unknown:
        raise SystemExit(f"readme_numbers: blocks this script does not know: {', '.join(unknown)}")
    names = set(args.only or BLOCKS) & set(present)
    if args.reports_only or args.check:
        names = {n for n in names if BLOCKS[n].kind == "report"}
    if args.check:
        stale = []
        for page in pages():
            _, changed = regenerate(page.read_text(encoding="utf-8"), names, where=str(page))
            stale += [f"{page.relative_to(ROOT)}: {n}" for n in changed]
        if stale:
            print(
                f"out of date with reports/: {'; '.join(stale)}; "
                "run python scripts/readme_numbers.py --reports-only",
                file=sys.stderr,
            )
            return 1
        return 0
    # Run blocks take minutes: make every body first (report blocks last, after the runs have
    # written their timings), then re-read each page, so edits made meanwhile are kept.
    made: dict[str, str] = {}
    with tempfile.TemporaryDirectory(prefix="uq-readme-numbers-") as tmp:
        workspace = make_workspace(Path(tmp))
        for name in sorted(n for n in names if BLOCKS[n].kind == "run"):
            make_run_body(name, workspace, made, timed=names)
    bodies = {n: made[n] for n in names if n in made}
    for name in names - set(bodies):
        bodies[name] = BLOCKS[name].summarise()
    changed_all = []
    for page in pages():
        text = page.read_text(encoding="utf-8")
        new, changed = regenerate(text, names, bodies, where=str(page))
        if new != text:
            _write(page, new)
        changed_all += changed
    print(
        f"rebuilt {', '.join(sorted(names)) or 'nothing'}; changed: {', '.join(sorted(changed_all)) or 'nothing'}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
