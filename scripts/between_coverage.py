"""Coverage between tested pressures: the surface with a discrepancy in pressure beside the smooth
surface and the per-pressure cubics, on springs smooth and not smooth in pressure. Writes
coverage.json and summary.md into ``--out`` (default reports/between-coverage).

    .venv/bin/python scripts/between_coverage.py --reps 10 [--springs ...] [--grids ...] [--resume] [--tiny]

Each replication: the virtual stand records a spring at a grid of set pressures; the three models
are fitted as ``uq margin`` fits them (default orders and sampler settings; the cubics to the
force side as the comparison fits them). Queries, at heights across the stroke (70, 90, 112, 130,
150 mm) and at overpressures half-way between neighbouring tested pressures:

* ``force``: does the model's 90 % band of the mean force P(x, p_u) hold the spring's true force;
* ``margin``: does the equal-tailed 90 % interval of ``pressure_bar_needed`` (``uq margin``) for
  the spring's true force there hold the query's overpressure. A query a model refuses is counted
  as refused, not covered.

Reported BY PRESSURE AND HEIGHT: for every (spring, grid, model, query) the count covered over
the replications with its exact (Clopper-Pearson) 90 % interval, and the mean width of the
model's interval; pooled shares per (spring, grid, model) as a summary only (the queries of one
campaign share its noise, so only the counts across replications are binomial). The added width
of the discrepancy surface over the smooth surface is reported as the ratio of their mean widths.

Springs (docs/stand.md): ``n50-kink``, ``n50-knee``, ``n50-ripple`` (not smooth in pressure, one
potential), ``n50`` (Table 1's cubics at the paper's pressures, PCHIP between them: the truth of
data/n50), ``n50-smooth`` (smooth in pressure, in the surface's class). Grids: ``7`` (1, 2.5, ...,
10 bar), ``1-3-5``, ``paper`` (0.1 and 1..10 bar), ``catalogue`` (3..7 bar, catalogue tables made
by the stand: one compression pass every 10 mm, rounded, the force alone; the heights queried lie
between the tabulated ones).

``--stand FILE`` (e.g. data/stands/slow-pressure-control.toml): the campaigns are recorded on that
stand, while the models still assume the paper's error budget, as a user who does not know better
would fit them: a stand noisier than its budget, or with errors of another form. Its (spring,
grid) keys carry the stand's name (``n50-knee/7@slow-pressure-control``), and the seeds are those of
the paper's stand, so the two are paired campaign by campaign.

``--tiny`` (tests): one replication of one spring on the 1-3-5 grid, two heights, 100 sampler steps.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

# One BLAS thread: on a shared 2-core machine OpenBLAS's threads make the sampler's batched
# Cholesky factorisations of 100 x 100 matrices 10-30 times slower (measured).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from coverage_tables import model_check_table  # noqa: E402  (scripts/ is no package)
from scipy import stats  # noqa: E402

from uq._data.stand_description import PAPER_STAND, read_stand  # noqa: E402
from uq._derived.comparison import force_side  # noqa: E402
from uq._derived.margin import pressure_needed  # noqa: E402
from uq._derived.model_check import predictive_check  # noqa: E402
from uq._inference.sampler import Settings  # noqa: E402
from uq._inference.summary import band  # noqa: E402
from uq._io.errors import InputError  # noqa: E402
from uq._io.files import dumps_json, write_text_atomic  # noqa: E402
from uq._models.cubic_fit import fit_campaign  # noqa: E402
from uq._models.cubic_interpolation import CubicInterpolation  # noqa: E402
from uq._models.discrepancy import fit_discrepancy  # noqa: E402
from uq._models.surface_likelihood import fit_surface  # noqa: E402
from uq._stand.shapes import catalogue_recordings  # noqa: E402
from uq._stand.simulator import SPRINGS, Layout, simulate_recordings  # noqa: E402

GRIDS = {
    "7": (1.0, 2.5, 4.0, 5.5, 7.0, 8.5, 10.0),
    "1-3-5": (1.0, 3.0, 5.0),
    "paper": (0.1, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0),
    "catalogue": (3.0, 4.0, 5.0, 6.0, 7.0),
}
CATALOGUE_GRIDS = ("catalogue",)
SPRING_NAMES = ("n50-kink", "n50-knee", "n50-ripple", "n50", "n50-smooth")
HEIGHTS_MM = (70.0, 90.0, 112.0, 130.0, 150.0)
MODELS = ("discrepancy", "surface", "cubics")
#: the models whose posterior-predictive check (uq._derived.model_check) each campaign records
CHECKED = ("discrepancy", "surface")
LEVEL = 0.90
FIRST_SEED = 29000
#: the tests' settings: a short run (the plumbing is under test, not the posterior)
TINY = Settings(n_ensembles=2, max_steps=100)


def queries(grid, heights_mm) -> list[tuple[float, float]]:
    """(height mm, overpressure bar): every height, half-way between neighbouring tested pressures."""
    mids = [(a + b) / 2 for a, b in zip(grid[:-1], grid[1:], strict=True)]
    return [(h, p) for p in mids for h in heights_mm]


def campaign(spring: str, grid, seed: int, catalogue: bool, stand=PAPER_STAND):
    """One campaign recorded on ``stand`` (the models are fitted assuming the paper's budget)."""
    if catalogue:
        return catalogue_recordings(
            spring, seed=seed, layout=Layout(pressures_bar=grid, step_m=0.010), stand=stand
        )
    return simulate_recordings(spring, seed=seed, layout=Layout(pressures_bar=grid), stand=stand)


def fit_models(rec, seed: int, settings: Settings) -> tuple[dict, dict]:
    """The three answers of one campaign and the CPU seconds each fit took."""
    answers, seconds = {}, {}
    for name in MODELS:
        t0 = time.process_time()
        if name == "discrepancy":
            answers[name] = fit_discrepancy(rec, seed=seed, settings=settings, stand=PAPER_STAND)
        elif name == "surface":
            answers[name] = fit_surface(rec, seed=seed, settings=settings, stand=PAPER_STAND)
        else:
            cubics = fit_campaign(force_side(rec), seed=seed, settings=settings, stand=PAPER_STAND)
            answers[name] = CubicInterpolation.of(cubics, seed=seed)
        seconds[name] = time.process_time() - t0
    return answers, seconds


def one_campaign(
    spring: str, grid, seed: int, settings: Settings, qs, catalogue: bool, stand=PAPER_STAND
) -> dict:
    rec = campaign(spring, grid, seed, catalogue, stand)
    answers, seconds = fit_models(rec, seed, settings)
    truth = SPRINGS[spring]()
    converged = {
        "discrepancy": bool(answers["discrepancy"].convergence.converged),
        "surface": bool(answers["surface"].convergence.converged),
    }
    # what uq margin and uq design print with every answer, and exit 1 on: does the model follow
    # the readings it was fitted to (the posterior-predictive check at the tested points)
    misses = {m: bool(predictive_check(answers[m], seed=seed)["misses"]) for m in CHECKED}
    out = {
        "seed": seed,
        "cpu_seconds": seconds,
        "converged": converged,
        "check_misses": misses,
        "queries": [],
    }
    for h_mm, p in qs:
        h = h_mm / 1e3
        true_force = float(truth.force_N(np.array(h), p))
        row = {"height_mm": h_mm, "pressure_bar": p, "true_force_N": true_force}
        for name, ans in answers.items():
            _, lo, hi = band(ans.force_draws(np.array([h]), np.array([p]))[:, 0], level=LEVEL)
            entry = {
                "force": {
                    "covered": bool(lo <= true_force <= hi),
                    "width_N": float(hi - lo),
                }
            }
            try:
                d = pressure_needed(ans, h, true_force).values
                d = d[np.isfinite(d)]
                q_lo, q_hi = np.quantile(d, [(1 - LEVEL) / 2, (1 + LEVEL) / 2])
                entry["margin"] = {
                    "covered": bool(q_lo <= p <= q_hi),
                    "width_bar": float(q_hi - q_lo),
                }
            except InputError as exc:
                entry["margin"] = {"refused": str(exc)}
            row[name] = entry
        out["queries"].append(row)
    return out


def clopper_pearson(k: int, n: int, level: float = LEVEL) -> tuple[float, float]:
    """Exact binomial interval of a share k/n."""
    a = (1 - level) / 2
    lo = 0.0 if k == 0 else float(stats.beta.ppf(a, k, n - k + 1))
    hi = 1.0 if k == n else float(stats.beta.ppf(1 - a, k + 1, n - k))
    return lo, hi


def summarise(results: dict) -> dict:
    """Per (spring, grid, model, what, query): covered of n, its Clopper-Pearson interval, the mean
    width; pooled shares; the discrepancy surface's width over the surface's."""
    rows, pooled, widths = [], {}, {}
    for key, runs in results.items():
        spring, gname = key.split("/")
        n = len(runs)
        for name in MODELS:
            for what, unit in (("force", "width_N"), ("margin", "width_bar")):
                cov_all, n_all, w_all = 0, 0, []
                for j, q in enumerate(runs[0]["queries"]):
                    answers = [r["queries"][j][name][what] for r in runs]
                    refused = sum("refused" in a for a in answers)
                    covered = sum(bool(a.get("covered")) for a in answers)
                    ws = [a[unit] for a in answers if unit in a]
                    lo, hi = clopper_pearson(covered, n)
                    rows.append(
                        {
                            "spring": spring,
                            "grid": gname,
                            "model": name,
                            "what": what,
                            "height_mm": q["height_mm"],
                            "pressure_bar": q["pressure_bar"],
                            "covered": covered,
                            "refused": refused,
                            "n": n,
                            "interval": [lo, hi],
                            "mean_width": float(np.mean(ws)) if ws else None,
                            "level_inside": bool(lo <= LEVEL <= hi),
                            # which way a count outside misses: "below" (the model's intervals
                            # too narrow there: a user is misled) or "above" (too wide: cautious)
                            "side": "below" if hi < LEVEL else "above" if lo > LEVEL else "inside",
                        }
                    )
                    cov_all, n_all, w_all = cov_all + covered, n_all + n, w_all + ws
                pooled[f"{key}/{name}/{what}"] = cov_all / n_all if n_all else None
                widths[f"{key}/{name}/{what}"] = float(np.mean(w_all)) if w_all else None
    ratios = {
        f"{key}/{what}": widths[f"{key}/discrepancy/{what}"] / widths[f"{key}/surface/{what}"]
        for key in results
        for what in ("force", "margin")
        if widths.get(f"{key}/surface/{what}") and widths.get(f"{key}/discrepancy/{what}")
    }
    cpu = {
        m: float(np.mean([r["cpu_seconds"][m] for runs in results.values() for r in runs]))
        for m in MODELS
    }
    unconverged = {
        m: sum(not r["converged"][m] for runs in results.values() for r in runs)
        for m in ("discrepancy", "surface")
    }
    return {
        "level": LEVEL,
        "rows": rows,
        "pooled_coverage": pooled,
        "mean_width": widths,
        "width_ratio_discrepancy_over_surface": ratios,
        "mean_cpu_seconds_per_fit": cpu,
        "unconverged_fits": unconverged,
        "model_check": _checked(results),
    }


def _checked(results: dict) -> dict:
    """Per (spring, grid) whose runs recorded it: campaigns the model check flagged, per model of
    ``CHECKED``, and the pooled share of force queries covered in all campaigns and in those the
    check passes (what a user who heeds the check's exit status 1 is left with)."""
    out = {}
    for key, runs in results.items():
        runs = [r for r in runs if "check_misses" in r]
        if not runs:
            continue
        out[key] = {"campaigns": len(runs)}
        for m in CHECKED:
            passed = [r for r in runs if not r["check_misses"][m]]

            def share(rs, m=m):
                hits = [q[m]["force"]["covered"] for r in rs for q in r["queries"]]
                return sum(hits) / len(hits) if hits else None

            out[key][m] = {
                "flagged": len(runs) - len(passed),
                "force_covered_all": share(runs),
                "force_covered_when_passed": share(passed),
            }
    return out


def markdown(summary: dict, command: str, seconds: float) -> str:
    reps = summary["replications"]
    n = min(reps.values())
    lo, hi = clopper_pearson(int(round(LEVEL * n)), n)
    counts = ", ".join(f"{k} {v}" for k, v in reps.items())
    lines = [
        "# Coverage between tested pressures",
        "",
        "RECONSTRUCTED data: every campaign is made by the virtual stand (docs/stand.md). Springs "
        "n50-kink, n50-knee, n50-ripple: not smooth in pressure (one potential, the Maxwell "
        "relation exact); n50: Table 1's cubics at the paper's pressures, PCHIP between them (the "
        "truth of data/n50); n50-smooth: smooth in pressure, in the surface's class.",
        "",
        f"Generated by `{command}` (scripts/between_coverage.py) in {seconds / 60:.0f} min of wall "
        f"time. Replications per (spring, grid): {counts}; queries half-way between neighbouring "
        "tested pressures at five heights; `force`: the 90 % band of the mean force holds the true "
        "force; `margin`: the 90 % interval of `pressure_bar_needed` for the true force holds the "
        "query's pressure. Each count has its exact 90 % Clopper-Pearson interval (with "
        f"{n} replications a count of {int(round(LEVEL * n))} has [{lo:.2f}, {hi:.2f}]); **bold**: "
        "0.90 above it (the intervals too narrow there), _italic_: 0.90 below it (too wide)."
        + (
            " A grid `g@name`: the campaigns recorded on the stand of data/stands/ named so (the same "
            "seeds as on the paper's stand), the models fitted assuming the paper's error budget."
            if any("@" in k for k in reps)
            else ""
        ),
        "",
        "## Pooled share covered (a summary: queries of one campaign share its noise)",
        "",
        "| spring | grid | what | discrepancy | surface | cubics | width: discrepancy / surface |",
        "|---|---|---|---|---|---|---|",
    ]
    keys = sorted({k.rsplit("/", 2)[0] for k in summary["pooled_coverage"]})
    for key in keys:
        spring, gname = key.split("/")
        for what in ("force", "margin"):
            vals = [summary["pooled_coverage"].get(f"{key}/{m}/{what}") for m in MODELS]
            ratio = summary["width_ratio_discrepancy_over_surface"].get(f"{key}/{what}")
            lines.append(
                f"| {spring} | {gname} | {what} | "
                + " | ".join("-" if v is None else f"{v:.2f}" for v in vals)
                + f" | {'-' if ratio is None else f'{ratio:.2f}'} |"
            )
    lines += [
        "",
        "CPU seconds per fit (mean): "
        + ", ".join(f"{m} {s:.0f}" for m, s in summary["mean_cpu_seconds_per_fit"].items())
        + "; unconverged fits: "
        + ", ".join(f"{m} {k}" for m, k in summary["unconverged_fits"].items())
        + ".",
        "",
        *_check_lines(summary.get("model_check") or {}),
        "## By pressure and height",
        "",
        "| spring | grid | what | p bar | height mm | discrepancy | surface | cubics |",
        "|---|---|---|---|---|---|---|---|",
    ]
    by = {}
    for r in summary["rows"]:
        by.setdefault((r["spring"], r["grid"], r["what"], r["pressure_bar"], r["height_mm"]), {})[
            r["model"]
        ] = r

    def cell(r):
        if r is None:
            return "-"
        txt = f"{r['covered']}/{r['n']} [{r['interval'][0]:.2f}, {r['interval'][1]:.2f}]"
        if r["refused"]:
            txt += f" ({r['refused']} refused)"
        return {"below": f"**{txt}**", "above": f"_{txt}_"}.get(r.get("side"), txt)

    for (spring, gname, what, p, h), models in by.items():
        lines.append(
            f"| {spring} | {gname} | {what} | {p:g} | {h:g} | "
            + " | ".join(cell(models.get(m)) for m in MODELS)
            + " |"
        )
    return "\n".join(lines) + "\n"


def _check_lines(checked: dict) -> list[str]:
    """The markdown section on the model check, where the runs recorded it."""
    if not checked:
        return []
    return [
        "## The model check",
        "",
        "`uq margin` and `uq design` run a posterior-predictive check at the tested points with "
        "every answer and exit 1 when the model misses the readings (docs/design.md). Campaigns "
        "it flags, and the pooled share of force queries covered in all campaigns and in those it "
        "passes:",
        "",
        *model_check_table(checked, CHECKED),
        "",
    ]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--reps", type=int, default=10)
    ap.add_argument("--out", help="output folder (default reports/between-coverage)")
    ap.add_argument("--springs", nargs="+", choices=SPRING_NAMES, default=list(SPRING_NAMES))
    ap.add_argument("--grids", nargs="+", choices=sorted(GRIDS), default=["7", "1-3-5", "paper"])
    ap.add_argument(
        "--stand",
        help="a stand description (TOML) the campaigns are recorded on; the models still assume "
        "the paper's budget (default: the paper's stand)",
    )
    ap.add_argument(
        "--tiny", action="store_true", help="one replication, one spring, the 1-3-5 grid"
    )
    ap.add_argument(
        "--resume",
        action="store_true",
        help="keep the (spring, grid) runs of --out's partial.json and add what is missing: a study "
        "made of several commands (the summary covers every run in the folder)",
    )
    args = ap.parse_args(argv)
    settings, heights, springs, grids, reps = (
        Settings(),
        HEIGHTS_MM,
        args.springs,
        args.grids,
        args.reps,
    )
    if args.tiny:
        settings, heights, grids, reps = TINY, (90.0, 150.0), ["1-3-5"], 1
        springs = springs[:1]
    try:
        stand = read_stand(args.stand) if args.stand else PAPER_STAND
    except InputError as exc:
        print(f"between_coverage.py: option --stand: {exc}", file=sys.stderr)
        return 2
    on = f"@{Path(args.stand).stem}" if args.stand else ""  # the keys of another stand
    out = Path(args.out or ROOT / "reports" / "between-coverage")
    out.mkdir(parents=True, exist_ok=True)
    partial = out / "partial.json"
    command = "python scripts/between_coverage.py " + " ".join(
        argv if argv is not None else sys.argv[1:]
    )
    done = json.loads(partial.read_text()) if args.resume and partial.exists() else {}
    results, commands = done.get("runs", {}), done.get("commands", [])
    seconds = done.get("seconds", 0.0)
    commands.append(command.strip())
    t0 = time.time()
    for spring in springs:
        for gname in grids:
            key = f"{spring}/{gname}{on}"
            if len(results.get(key, [])) >= reps:
                continue
            grid, qs = GRIDS[gname], queries(GRIDS[gname], heights)
            runs = results.get(key, [])
            for seed in range(FIRST_SEED + len(runs), FIRST_SEED + reps):
                runs.append(
                    one_campaign(spring, grid, seed, settings, qs, gname in CATALOGUE_GRIDS, stand)
                )
                print(f"{key} seed {seed}: {time.time() - t0:.0f} s", file=sys.stderr, flush=True)
                results[key] = runs
                state = {
                    "runs": results,
                    "commands": commands,
                    "seconds": seconds + time.time() - t0,
                }
                write_text_atomic(partial, dumps_json(state))
    seconds += time.time() - t0
    # every (spring, grid) with the replications it has (the queries' counts are per key); a study
    # stopped part-way through a key reports that key's runs so far
    summary = {
        **summarise(results),
        "replications": {k: len(r) for k, r in results.items()},
        "springs": sorted({k.split("/")[0] for k in results}),
        "grids": sorted({k.split("/")[1] for k in results}),
    }
    command = " ; ".join(dict.fromkeys(commands))
    write_text_atomic(
        out / "coverage.json",
        dumps_json({**summary, "command": command, "seconds": seconds, "runs": results}),
    )
    write_text_atomic(out / "summary.md", markdown(summary, command, seconds))
    print(f"pooled {summary['pooled_coverage']}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
