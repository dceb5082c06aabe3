"""Coverage of the design-margin answers (``uq margin``) on coarse pressure grids, over the whole
stroke. Writes coverage.json and summary.md into ``--out`` (default reports/margin-coverage/SPRING;
committed: reports/margin-coverage/n50/summary.md and reports/margin-coverage/n50-smooth/summary.md).

    .venv/bin/python scripts/margin_coverage.py --spring n50-smooth --reps 8 [--grids ...] [--tiny]

Each replication: the virtual stand records the N-50 spring (Table 1's cubics at the tested
pressures, PCHIP between them: the truth of data/n50) at a coarse grid of set pressures (3 to 5
tests instead of the paper's 11); both answering models are fitted as ``uq margin`` fits them
(the surface model and the per-pressure cubics, same settings, compared by PSIS-LOO). Queries:
at heights across the whole stroke and at overpressures half-way between tested ones (where the
cubics must interpolate), the load is the spring's true force there, so the true answer of
"which overpressure carries this load at this height" is the query's overpressure. Covered: the
equal-tailed 90 % interval of ``pressure_bar_needed`` holds it. Counted for each model and for
the one ``uq margin`` would answer with (the PSIS-LOO choice). A query a model refuses (the
force does not rise with pressure, or the load lies outside what the tested pressures support)
is counted as refused, not as covered.

Accepted: for every (grid, model, query) the count of covered replications lies in its exact
binomial region for 90 % (Bonferroni over every count, false failure < 1e-3 overall). The
queries of one campaign share its noise, so only counts across replications are binomial;
the pooled share is reported as a summary.

Catalogue tables (``--grids catalogue``): the stand's readings cut to a data sheet as
``uq simulate --catalogue`` cuts them (uq._stand.shapes.catalogue_recordings: 3..7 bar, one
compression pass every 10 mm, forces to 10 N, a volume column at 5 bar), so the heights queried
(70, 90, 112, 130, 150 mm) lie between the tabulated ones as well as the pressures. The force
surface and the per-pressure cubics are compared on the force readings as ``uq margin`` compares
them (the volume column left out of both). Write these under their own folder
(``--out reports/margin-coverage/catalogue-n50``).

``--tiny`` (tests): one replication of the smallest grid, three queries, 200 sampler steps.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from scipy import stats  # noqa: E402

from uq._data.recordings import read_recordings, write_recordings_csv  # noqa: E402
from uq._data.stand_description import PAPER_STAND  # noqa: E402
from uq._derived.comparison import fit_both  # noqa: E402
from uq._derived.margin import choose, pressure_needed  # noqa: E402
from uq._inference.sampler import Settings  # noqa: E402
from uq._io.errors import InputError  # noqa: E402
from uq._io.files import dumps_json, write_text_atomic  # noqa: E402
from uq._models.cubic_interpolation import CubicInterpolation  # noqa: E402
from uq._stand.shapes import catalogue_recordings  # noqa: E402
from uq._stand.simulator import SPRINGS, Layout, simulate  # noqa: E402

#: coarse grids of set overpressures (bar): 3, 4 and 5 tests
GRIDS = {
    "1-3-5": (1.0, 3.0, 5.0),
    "1-4-7-10": (1.0, 4.0, 7.0, 10.0),
    "2-4-6-8-10": (2.0, 4.0, 6.0, 8.0, 10.0),
    "catalogue": (3.0, 4.0, 5.0, 6.0, 7.0),
}
#: grids recorded as catalogue tables (one pass every 10 mm, rounded, volume at 5 bar)
CATALOGUE_GRIDS = ("catalogue",)
#: heights over the whole stroke (65..155 mm), mm
HEIGHTS_MM = (70.0, 90.0, 112.0, 130.0, 150.0)
LEVEL = 0.90
FALSE_FAILURE = 1e-3
MODELS = ("surface", "cubics", "chosen")


def queries(grid: tuple[float, ...], heights_mm) -> list[tuple[float, float]]:
    """(height mm, overpressure bar) pairs: every height, half-way between neighbouring tests."""
    mids = [(a + b) / 2 for a, b in zip(grid[:-1], grid[1:], strict=True)]
    return [(h, p) for h in heights_mm for p in mids]


def one_campaign(
    spring: str, grid, seed: int, settings: Settings, qs, workdir: Path, catalogue: bool = False
) -> dict:
    """Fit both models to one simulated campaign and answer every query with each."""
    if catalogue:  # the force surface against force-only cubics, as uq margin compares them
        rec = catalogue_recordings(
            spring, seed=seed, layout=Layout(pressures_bar=grid, step_m=0.010)
        )
    else:
        path = workdir / f"campaign-{seed}.csv"
        layout = Layout(pressures_bar=grid)
        path.write_text(write_recordings_csv(simulate(spring, seed=seed, layout=layout)))
        rec = read_recordings(str(path))
    surface, cubics, comparison = fit_both(rec, seed=seed, settings=settings, stand=PAPER_STAND)
    chosen, info = choose(surface, cubics, comparison)
    answers = {
        "surface": surface,
        "cubics": CubicInterpolation.of(cubics, seed=seed),
        "chosen": chosen,
    }
    truth = SPRINGS[spring]()
    out = {"seed": seed, "chosen": info["name"], "better": comparison["better"], "queries": []}
    for h_mm, p in qs:
        load = float(truth.force_N(np.array(h_mm / 1e3), p))
        row = {"height_mm": h_mm, "pressure_bar": p, "load_N": load}
        for name, ans in answers.items():
            try:
                d = pressure_needed(ans, h_mm / 1e3, load).values
            except InputError as exc:
                row[name] = {"refused": str(exc)}
                continue
            d = d[np.isfinite(d)]
            q05, q95 = np.quantile(d, [(1 - LEVEL) / 2, (1 + LEVEL) / 2])
            row[name] = {
                "q05": float(q05),
                "q95": float(q95),
                "covered": bool(q05 <= p <= q95),
                "width_bar": float(q95 - q05),
            }
        out["queries"].append(row)
    return out


def binomial_region(n: int, level: float, tail: float) -> tuple[int, int]:
    b = stats.binom(n, level)
    lo = min(k for k in range(n + 1) if b.cdf(k) > tail)
    hi = max(k for k in range(n + 1) if b.sf(k - 1) > tail)
    return lo, hi


def summarise(results: dict, reps: int) -> dict:
    """Counts per (grid, model, query), their binomial regions and the verdict."""
    n_counts = sum(len(r[0]["queries"]) for r in results.values()) * len(MODELS)
    tail = FALSE_FAILURE / (2 * n_counts)
    lo, hi = binomial_region(reps, LEVEL, tail)
    rows, ok = [], True
    for gname, runs in results.items():
        for name in MODELS:
            for j, q in enumerate(runs[0]["queries"]):
                answers = [r["queries"][j][name] for r in runs]
                refused = sum("refused" in a for a in answers)
                covered = sum(bool(a.get("covered")) for a in answers)
                inside = refused == 0 and lo <= covered <= hi
                ok &= inside
                rows.append(
                    {
                        "grid": gname,
                        "model": name,
                        "height_mm": q["height_mm"],
                        "pressure_bar": q["pressure_bar"],
                        "covered": covered,
                        "refused": refused,
                        "mean_width_bar": float(
                            np.mean(
                                [a["width_bar"] for a in answers if "width_bar" in a] or [np.nan]
                            )
                        ),
                        "inside_region": bool(inside),
                    }
                )
    pooled = {
        f"{g}/{m}": float(
            np.mean([r["covered"] / reps for r in rows if r["grid"] == g and r["model"] == m])
        )
        for g in results
        for m in MODELS
    }
    chosen = {
        g: {n: sum(r["chosen"] == n for r in runs) for n in ("surface", "cubics")}
        for g, runs in results.items()
    }
    return {
        "replications": reps,
        "level": LEVEL,
        "acceptance": [lo, hi],
        "false_failure_rate": FALSE_FAILURE,
        "all_inside": bool(ok),
        "pooled_coverage": pooled,
        "chosen_model": chosen,
        "rows": rows,
    }


def markdown(summary: dict, command: str, seconds: float) -> str:
    lo, hi = summary["acceptance"]
    lines = [
        "# Coverage of the design-margin answers on coarse pressure grids",
        "",
        "RECONSTRUCTED data: every campaign is made by the virtual stand, at a coarse grid of "
        f"pressures; the truth is the spring `{summary['spring']}` (n50: Table 1's cubics at the "
        "paper's pressures, PCHIP between them, the truth of data/n50; n50-smooth: a spring smooth "
        "in pressure, in the surface model's class).",
        "",
        *(
            [
                "Grid `catalogue`: catalogue tables made by the stand (one compression pass every 10 mm, "
                "forces to 10 N, volume at 5 bar; uq._stand.shapes.catalogue_recordings); the heights "
                "queried lie between the tabulated ones; the force surface and the cubics are "
                "compared on the force readings (the volume left out of both), as `uq margin` compares "
                "them.",
                "",
            ]
            if any(g in CATALOGUE_GRIDS for g in summary.get("grids", ()))
            else []
        ),
        f"Generated by `{command}` (scripts/margin_coverage.py) in {seconds / 60:.1f} min. "
        f"{summary['replications']} replications per grid; query = the overpressure that carries the "
        "spring's true force at a height, half-way between tested pressures; covered = inside the "
        f"90 % interval of `pressure_bar_needed`; accepted region {lo}-{hi} of "
        f"{summary['replications']} (exact binomial, Bonferroni over all counts, false failure < 1e-3).",
        "",
        f"Verdict: {'every count inside its region' if summary['all_inside'] else 'SOME COUNTS OUTSIDE THEIR REGION (rows marked)'}.",
        "",
        "| grid (bar) | model | height mm | p bar | covered | refused | mean 90 % width bar | |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for r in summary["rows"]:
        mark = "" if r["inside_region"] else "**outside**"
        lines.append(
            f"| {r['grid']} | {r['model']} | {r['height_mm']:g} | {r['pressure_bar']:g} | "
            f"{r['covered']} | {r['refused']} | {r['mean_width_bar']:.3f} | {mark} |"
        )
    lines += [
        "",
        "Pooled share covered (queries of one campaign are correlated: a summary only):",
        "",
    ]
    lines += [f"- {k}: {v:.3f}" for k, v in summary["pooled_coverage"].items()]
    lines += ["", "Model `uq margin` chose (PSIS-LOO), per grid:", ""]
    lines += [f"- {g}: {c}" for g, c in summary["chosen_model"].items()]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--reps", type=int, default=20)
    ap.add_argument("--out", help="output folder (default reports/margin-coverage/SPRING)")
    ap.add_argument(
        "--spring",
        choices=("n50", "n50-smooth"),
        default="n50",
        help="the truth: n50 (Table 1's cubics, PCHIP in pressure) or n50-smooth (smooth in pressure)",
    )
    ap.add_argument(
        "--grids",
        nargs="+",
        choices=sorted(GRIDS),
        default=[g for g in GRIDS if g not in CATALOGUE_GRIDS],
        help="pressure grids (default: the coarse full-format grids; 'catalogue': catalogue tables)",
    )
    ap.add_argument("--tiny", action="store_true", help="one replication, one grid, three queries")
    args = ap.parse_args(argv)
    settings, heights, grids, reps = Settings(), HEIGHTS_MM, args.grids, args.reps
    if args.tiny:
        settings, heights, grids, reps = Settings(max_steps=200), (90.0, 150.0), ["1-3-5"], 1
    import tempfile

    t0, results = time.time(), {}
    with tempfile.TemporaryDirectory() as work:
        for gname in grids:
            grid = GRIDS[gname]
            qs = queries(grid, heights)[: 3 if args.tiny else None]
            runs = []
            for seed in range(7000, 7000 + reps):
                runs.append(
                    one_campaign(
                        args.spring, grid, seed, settings, qs, Path(work), gname in CATALOGUE_GRIDS
                    )
                )
                print(f"{gname} seed {seed}: {time.time() - t0:.0f} s", file=sys.stderr, flush=True)
            results[gname] = runs
    seconds = time.time() - t0
    summary = {**summarise(results, reps), "spring": args.spring, "grids": list(results)}
    command = "python scripts/margin_coverage.py " + " ".join(
        argv if argv is not None else sys.argv[1:]
    )
    out = Path(args.out or ROOT / "reports" / "margin-coverage" / args.spring)
    out.mkdir(parents=True, exist_ok=True)
    write_text_atomic(
        out / "coverage.json",
        dumps_json({**summary, "command": command.strip(), "seconds": seconds, "runs": results}),
    )
    write_text_atomic(out / "summary.md", markdown(summary, command.strip(), seconds))
    print(
        f"{'all inside' if summary['all_inside'] else 'SOME OUTSIDE'}; pooled {summary['pooled_coverage']}"
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
