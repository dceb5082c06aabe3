"""``uq batch``: the options and the progress lines of uq._drivers.batch (the catalogue and Dask live there)."""

from __future__ import annotations

import sys
import time
from pathlib import Path

from uq._cli.common import exit_policy, positive_int
from uq._drivers import batch as B
from uq._io.errors import InputError


def configure_batch(p) -> None:
    p.add_argument(
        "catalogue",
        metavar="CATALOGUE",
        help="TOML or CSV listing campaign files and the tasks to run (docs/batch.md)",
    )
    p.add_argument(
        "--out",
        required=True,
        metavar="DIR",
        help="folder for the outputs: DIR/<campaign>/<task>/ and summary.csv, summary.json, index.html",
    )
    p.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="run on the Dask cluster at ADDRESS (tcp://host:8786); default: in this process, "
        "the campaigns' fits batched through one driver call",
    )
    p.add_argument(
        "--workers",
        type=positive_int,
        default=None,
        help="run on a Dask LocalCluster of N worker processes, one thread each (ignored with "
        "--scheduler); default: in this process",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="rerun every task, even those finished with the same inputs",
    )
    p.add_argument(
        "--serial",
        action="store_true",
        help="run the tasks one after another in this process, each campaign fitted on its own "
        "(no batching; the reference of benchmarks/bench.py --batch)",
    )
    p.add_argument(
        "--json", metavar="PATH", help="also write the summary JSON to PATH ('-' for stdout)"
    )
    p.add_argument(
        "--allow-unconverged",
        action="store_true",
        help="exit status 0 when every task ran but some fit failed its convergence rules (its "
        "outputs still say NOT CONVERGED); without it the exit status is 1",
    )


def command_batch(args) -> int:
    from uq._io.files import emit_json
    from uq._io.progress import progress

    campaigns = B.read_catalogue(args.catalogue)  # every problem reported before a cluster starts
    n_jobs = sum(len(c.tasks) for c in campaigns)
    if args.serial and (args.scheduler or args.workers):
        option = "--scheduler" if args.scheduler else "--workers"
        raise InputError(f"options --serial and {option}: choose one (--serial runs without Dask)")
    if args.serial:
        where_ = "in this process, one after another"
    elif args.scheduler:
        where_ = f"scheduler {args.scheduler}"
    elif args.workers:
        where_ = f"LocalCluster, {args.workers} workers x 1 thread"
    else:
        where_ = f"in this process, fits batched ({B.BATCH_CAMPAIGNS} campaigns per sampling run)"
    print(f"{args.catalogue}: {len(campaigns)} campaigns, {n_jobs} tasks; {where_}")
    with progress(total=n_jobs, desc="batch", unit="task") as bar:

        def on_row(row):
            bar.update(1)
            print(_row_line(row), flush=True)

        t0 = time.perf_counter()
        res = B.run_batch(
            args.catalogue,
            args.out,
            scheduler=args.scheduler,
            workers=args.workers,
            force=args.force,
            serial=args.serial,
            on_row=on_row,
        )
        bar.update(res["counts"]["skipped"])
    c = res["counts"]
    for r in res["campaigns"]:
        if r["status"] == "skipped":
            print(_row_line(r))
    print(
        f"{c['done']} done, {c['skipped']} skipped, {c['failed']} failed in {time.perf_counter() - t0:.1f} s; "
        f"summary: {Path(args.out) / 'index.html'}"
    )
    for v in res["verdicts"]:
        print(f"  {v['campaign']}: {v['verdict']}" + (f" ({v['why']})" if v["why"] else ""))
    emit_json(res, args.json)
    if c["failed"]:
        print(f"uq batch: {c['failed']} task(s) failed (see the summary)", file=sys.stderr)
        return 1
    head = "uq batch: NOT CONVERGED: {} task(s) finished with a fit that failed its convergence rules (see the summary); "
    return exit_policy(
        0,
        [str(res["not_converged"])] if res["not_converged"] else [],
        getattr(args, "allow_unconverged", False),
        head + "accepted with --allow-unconverged: exit 0",
        head + "exit 1 (--allow-unconverged to accept them)",
    )


def _row_line(r: dict) -> str:
    secs = "" if r.get("seconds") is None else f" {r['seconds']:.1f} s"
    tail = r["error"] if r["status"] == "failed" else r.get("result", "")
    if r["status"] != "failed" and r.get("converged") is False:
        tail = f"NOT CONVERGED; {tail}"
    return f"  {r['status']:<7} {r['campaign']}/{r['task']}{secs}: {tail}"
