"""The discrepancy surface's bands between tested pressures as `uq margin` fits them today (theta
importance-sampled first, emcee when refused), against the stored study's (reports/between-coverage,
made when theta was always sampled with emcee), on the study's own campaigns and seeds. Writes
``--out`` (JSON) and prints one line per (spring, grid).

    .venv/bin/python scripts/importance_coverage.py --reps 10 --out reports/between-coverage/importance.json

For every replication of every (spring, grid) of the stored study: the same campaign (the virtual
stand, the study's seed), the discrepancy surface fitted with that seed, and at the study's queries
(heights across the stroke, overpressures half-way between tested pressures) whether the 90 % band
of the mean force holds the true force and whether the 90 % interval of the pressure needed for the
true force holds the query's pressure; the counts beside the stored study's for the same
replications, with the mean band width, how theta was drawn (importance or emcee after a refusal),
the Pareto k-hat, the smallest ESS and the fit's CPU seconds.

reports/between-coverage/importance.json was made against the study as committed until round 7's
twelfth session, whose theta was sampled with emcee (that partial.json is in the git history, e.g.
``git show 456dff8:reports/between-coverage/partial.json``). The study has since been made again as
`uq margin` fits today (importance sampling first), so run against today's partial.json this
script checks that a refit gives the stored counts, no longer that two samplers agree.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # as scripts/between_coverage.py

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts"))

import between_coverage as bc  # noqa: E402

from uq._io.files import dumps_json, write_text_atomic  # noqa: E402

STORED = ROOT / "reports/between-coverage/partial.json"


def one_campaign(spring: str, gname: str, seed: int, heights_mm) -> dict:
    grid = bc.GRIDS[gname]
    rec = bc.campaign(spring, grid, seed, gname in bc.CATALOGUE_GRIDS)
    c0 = time.process_time()
    fit = bc.fit_discrepancy(rec, seed=seed, settings=bc.Settings(), stand=bc.PAPER_STAND)
    cpu = time.process_time() - c0
    truth = bc.SPRINGS[spring]()
    conv = fit.convergence
    imp = conv.importance or {}
    row = {
        "seed": seed,
        "cpu_s": cpu,
        "converged": bool(conv.converged),
        "method": conv.method,
        "pareto_k": imp.get("pareto_k"),
        "ess_min": min([*imp.get("ess_bulk", {}).values(), *imp.get("ess_tail", {}).values()])
        if imp.get("ess_bulk")
        else None,
        "queries": [],
    }
    for h_mm, p in bc.queries(grid, heights_mm):
        h = np.array([h_mm / 1e3])
        tf = float(truth.force_N(h[0], p))
        _, lo, hi = bc.band(fit.force_draws(h, np.array([p]))[:, 0], level=bc.LEVEL)
        q = {"h_mm": h_mm, "p_bar": p, "force": bool(lo <= tf <= hi), "width_N": float(hi - lo)}
        try:
            d = bc.pressure_needed(fit, h[0], tf).values
            ql, qh = np.quantile(d[np.isfinite(d)], [0.05, 0.95])
            q["margin"] = bool(ql <= p <= qh)
        except bc.InputError:
            q["margin"] = None  # refused: not covered
        row["queries"].append(q)
    return row


def compare(runs: list, stored: list, heights_mm) -> dict:
    """Counts over the replications both have, at the queries both asked."""
    n = min(len(runs), len(stored))
    keep = set(heights_mm)
    new = [q for r in runs[:n] for q in r["queries"]]
    old = [q["discrepancy"] for r in stored[:n] for q in r["queries"] if q["height_mm"] in keep]
    return {
        "reps": n,
        "queries": len(new),
        "force_covered": [sum(q["force"] for q in new), sum(q["force"]["covered"] for q in old)],
        "margin_covered": [
            sum(bool(q["margin"]) for q in new),
            sum(bool(q["margin"].get("covered")) for q in old),
        ],
        "mean_width_N": [
            float(np.mean([q["width_N"] for q in new])),
            float(np.mean([q["force"]["width_N"] for q in old])),
        ],
        "emcee_fallbacks": sum(r["method"] != "importance" for r in runs[:n]),
        "converged": sum(r["converged"] for r in runs[:n]),
        "pareto_k_max": max((r["pareto_k"] or 0.0) for r in runs[:n]),
        "ess_min": min((r["ess_min"] or np.inf) for r in runs[:n]),
        "cpu_s_mean": float(np.mean([r["cpu_s"] for r in runs[:n]])),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--reps", type=int, default=10)
    ap.add_argument("--pairs", default=None, help="spring/grid,... (default: the stored study's)")
    ap.add_argument("--heights-mm", default=None, help="query heights (default: the study's)")
    ap.add_argument("--out", type=Path, required=True)
    args = ap.parse_args(argv)
    stored = json.loads(STORED.read_text())["runs"]
    # the paper's stand only: a key g@name was recorded on another stand (between_coverage --stand)
    paper = [k for k in stored if "@" not in k]
    pairs = args.pairs.split(",") if args.pairs else paper
    for key in pairs:
        if key not in paper:
            ap.error(f"--pairs: {key!r} is not in {STORED.relative_to(ROOT)} ({', '.join(paper)})")
    heights = (
        tuple(float(h) for h in args.heights_mm.split(",")) if args.heights_mm else bc.HEIGHTS_MM
    )
    t0 = time.time()
    runs, summary = {}, {}
    for key in pairs:
        spring, gname = key.split("/")
        runs[key] = [
            one_campaign(spring, gname, bc.FIRST_SEED + i, heights) for i in range(args.reps)
        ]
        s = summary[key] = compare(runs[key], stored[key], heights)
        print(
            f"{key}: {s['reps']} reps, {s['queries']} queries; force covered {s['force_covered'][0]} "
            f"(stored {s['force_covered'][1]}), margin {s['margin_covered'][0]} "
            f"({s['margin_covered'][1]}), mean width {s['mean_width_N'][0]:.1f} "
            f"({s['mean_width_N'][1]:.1f}) N; emcee after a refusal {s['emcee_fallbacks']}, "
            f"converged {s['converged']}, k-hat <= {s['pareto_k_max']:.2f}, ESS >= "
            f"{s['ess_min']:.0f}, fit {s['cpu_s_mean']:.1f} CPU s",
            flush=True,
        )
    doc = {
        "command": "python scripts/importance_coverage.py " + " ".join(argv or sys.argv[1:]),
        "seconds": time.time() - t0,
        "summary": summary,
        "runs": runs,
    }
    write_text_atomic(args.out, dumps_json(doc))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
