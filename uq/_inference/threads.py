"""numpy work side by side in threads of one process (PSIS-LOO's smoothing, ``uq._inference.loo``).

numpy's element-wise functions, partitions and sorts release the interpreter while they compute,
so chunks of independent work in two threads share two cores without a second process (whose
imports alone cost about a CPU second). :func:`side_by_side` is ``[fn(x) for x in items]`` by a
few threads at once; a caller whose items are computed independently of each other gets the
same results as one after the other, to the bit (each caller tests its own).

Never JAX programs: with jaxlib 0.10.2 (the version installed), two threads that execute
programs with a LAPACK call (a Cholesky factor: nearly every program of the fits) at the same
time deadlock, both waiting for results no worker computes, with or without JAX's asynchronous
CPU dispatch; programs without one ran 3000 times in each of two threads without a hang
(reproduced 2026-11-27: ``uq diagnose`` with its candidate fits in two threads hung on its
first run, and a two-thread loop of a batched Cholesky stopped within seconds in 3 runs of 4).
So ``uq diagnose``'s screening fits run one after the other, and the fits of a model
comparison (the model and the per-pressure cubics) side by side in two processes
(``uq._io.processes.Beside``, ``uq._derived.comparison.fit_both``).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

from uq._io.processes import cores

#: threads of :func:`side_by_side` by default: two (the machines uq is written for have two cores
#: and more, and a third thread mostly waits), one on a one-core machine
THREADS = max(1, min(2, cores()))


def side_by_side(fn: Callable[[Any], Any], items: Iterable, *, threads: int = THREADS) -> list:
    """``[fn(x) for x in items]``, in the same order, by ``threads`` threads at once (one: in
    this thread). ``fn`` must not run JAX programs (module docstring). If one call fails (or a
    Ctrl-C arrives), the calls not started are dropped and the running ones finish before the
    failure goes on."""
    items = list(items)
    if threads <= 1 or len(items) <= 1:
        return [fn(x) for x in items]
    pool = ThreadPoolExecutor(max_workers=min(threads, len(items)), thread_name_prefix="uq")
    try:
        return list(pool.map(fn, items))
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
