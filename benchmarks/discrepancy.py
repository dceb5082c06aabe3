"""The discrepancy surface's log posterior, the call its sampler makes about half a million times on
data/n50: CPU (user and kernel), wall time and page faults per call with glibc's malloc at its
defaults (``UQ_MALLOC=default`` while uq is imported: the baseline, measured first) and with the
thresholds uq sets (``uq._inference.allocator``, which keep JAX's large temporaries in the heap),
both in one process.

Not part of the installed package: run from the repository root with the project installed,

    .venv/bin/python benchmarks/discrepancy.py [--calls 100] [--json reports/bench/discrepancy.json]
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import time

os.environ["UQ_MALLOC"] = "default"  # the baseline: uq imports JAX with malloc's defaults

import jax  # noqa: E402
import numpy as np  # noqa: E402

from uq._data.recordings import read_recordings  # noqa: E402
from uq._inference import allocator  # noqa: E402
from uq._inference.float64 import jnp  # noqa: E402
from uq._io.files import emit_json  # noqa: E402
from uq._models import discrepancy as dev  # noqa: E402
from uq._models import surface  # noqa: E402

RECORDINGS = "data/n50/recordings.csv"


def timed(fn, thetas, calls: int) -> dict:
    """Per call: user and kernel CPU, wall time (ms) and minor page faults, after a warm-up call."""
    np.asarray(fn(thetas))
    r0, w0 = resource.getrusage(resource.RUSAGE_SELF), time.perf_counter()
    for _ in range(calls):
        np.asarray(fn(thetas))
    r1, wall = resource.getrusage(resource.RUSAGE_SELF), time.perf_counter() - w0
    return {
        "user_ms": 1e3 * (r1.ru_utime - r0.ru_utime) / calls,
        "sys_ms": 1e3 * (r1.ru_stime - r0.ru_stime) / calls,
        "wall_ms": 1e3 * wall / calls,
        "page_faults": (r1.ru_minflt - r0.ru_minflt) / calls,
    }


def cpu(r: dict) -> float:
    return r["user_ms"] + r["sys_ms"]


def measure(calls: int, walkers: int, seed: int) -> dict:
    rec = read_recordings(RECORDINGS)
    d = dev.dev_data(rec, surface.orders_for(rec))
    start = dev.start(d)[0]
    rng = np.random.default_rng(seed)
    thetas = jnp.asarray(start + 0.05 * rng.standard_normal((walkers, start.size)))
    log_prob = jax.jit(jax.vmap(lambda t: dev.log_prob(t, d)))
    runs = {"malloc_defaults": timed(log_prob, thetas, calls)}
    os.environ.pop("UQ_MALLOC")
    tuned = allocator.tune()
    runs["tuned"] = timed(log_prob, thetas, calls)
    return {
        "workload": f"log posterior of the discrepancy surface on {RECORDINGS} ({rec.n_points} "
        f"readings, {len(rec.tests)} tests), {walkers} walkers a call (the sampler's half of four "
        f"ensembles of 92), {calls} calls after a warm-up",
        "load_average_1min": os.getloadavg()[0],
        "cores": os.cpu_count(),
        "allocator_tuned": tuned,
        "threshold_bytes": allocator.THRESHOLD_BYTES,
        "runs": runs,
        "cpu_ratio": cpu(runs["malloc_defaults"]) / cpu(runs["tuned"]),
        "wall_ratio": runs["malloc_defaults"]["wall_ms"] / runs["tuned"]["wall_ms"],
    }


def summary(r: dict) -> str:
    lines = [f"bench discrepancy: {r['workload']}; load average {r['load_average_1min']:.1f}"]
    for name, x in r["runs"].items():
        lines.append(
            f"  {name:18s} user {x['user_ms']:6.1f} ms  sys {x['sys_ms']:6.1f} ms  wall "
            f"{x['wall_ms']:6.1f} ms  page faults {x['page_faults']:8.0f} a call"
        )
    lines.append(
        f"  a call with malloc's defaults over one with uq's thresholds: CPU {r['cpu_ratio']:.2f}x, "
        f"wall {r['wall_ratio']:.2f}x"
    )
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(
        prog="benchmarks/discrepancy.py", description=__doc__.splitlines()[0]
    )
    p.add_argument("--calls", type=int, default=100)
    p.add_argument("--walkers", type=int, default=184)
    p.add_argument("--seed", type=int, default=20201)
    p.add_argument("--json", metavar="PATH")
    args = p.parse_args(argv)
    r = measure(args.calls, args.walkers, args.seed)
    print(summary(r), file=sys.stderr if args.json == "-" else sys.stdout)
    if args.json:
        emit_json(r, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
