"""The worker process of a model comparison (``uq._derived.comparison.fitting_both``), started
without importing JAX.

The worker fits the per-pressure cubics while the command's own process fits the model over all
tests, then compares the two once it is sent the model's fit. A spawned worker pays for its own
imports (numpy, JAX and uq's modules: about 1.4 CPU s); started here, before the command's process
imports JAX itself, those imports run while the command's own run, on the CPU that would otherwise
wait (measured in docs/speed.md). This module imports neither JAX nor the models: the worker's
function is named, not imported (``uq._io.processes.Beside`` resolves it in the worker).
"""

from __future__ import annotations

import contextlib
import multiprocessing
import threading

from uq._io.processes import Beside, cores

#: readings from which the cubics are fitted in a worker process when asked (``jobs``). The
#: cubics' fit and pointwise terms cost about 5 ms CPU a reading (measured: 0.9 s at 185
#: readings, 2.2 s at data/n50's 407); the worker adds about 1.4 CPU s (its imports, sending the fit
#: back), and the model's fit it runs beside can be shorter than its start (the surface: 1.7 s on
#: a 185-reading campaign of five tests). Below about 250 readings the worker would add more CPU
#: than it takes off the command's process, and may be waited for (docs/speed.md).
WORKER_MIN_READINGS = 250

#: what the worker does, in its error messages
WHAT = "fitting the per-pressure cubics and comparing them with the model"


#: the worker's function (``"module:attribute"``, :class:`~uq._io.processes.Beside`): given the
#: recordings and the pipe it is sent the model's fit through, it returns (cubics, comparison, ...)
TARGET = "uq._derived.comparison:cubics_then_compare"


def _send(conn, obj) -> None:
    """``obj`` down the pipe ``conn`` (in a thread: the worker reads it only after its own fit); a
    worker that died is reported by its :meth:`~uq._io.processes.Beside.result`."""
    with contextlib.suppress(OSError):
        conn.send(obj)


class ComparisonWorker:
    """A started worker (:func:`start`): :meth:`send` sends it the model's fit (and then what its
    ``target`` asks for next), :meth:`result` waits for its answer ((cubics, comparison) for the
    default ``TARGET``). A context manager: leaving it stops a worker still running."""

    def __init__(self, rec, *, seed: int, settings, stand, target: str = TARGET):
        asked, self._ask = multiprocessing.get_context("spawn").Pipe(duplex=False)
        kw = {"seed": seed, "settings": settings, "stand": stand}
        self._worker = Beside(WHAT, target, rec, asked, **kw)
        asked.close()  # the worker's copy is left
        self._sender = None

    def send(self, obj) -> None:
        """``obj`` to the worker (the model's fit first, then what its ``target`` asks next),
        sent in a thread after what was sent before."""
        if self._sender is not None:
            self._sender.join()
        self._sender = threading.Thread(target=_send, args=(self._ask, obj), daemon=True)
        self._sender.start()

    def result(self):
        if self._sender is not None:
            self._sender.join()
        return self._worker.result()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        stopped = self._worker.__exit__(*exc)  # a send still under way then fails: no reader
        if self._sender is not None:
            self._sender.join()
        self._ask.close()
        return stopped


def start(rec, *, jobs: int | None = 1, **kw) -> ComparisonWorker | None:
    """The comparison's worker for ``rec`` (``kw``: :class:`ComparisonWorker`'s), started now, or
    None where the cubics are fitted in this process (``jobs``: processes that fit, None for one
    per CPU; a worker from two on and ``WORKER_MIN_READINGS`` readings)."""
    jobs = cores() if jobs is None else jobs
    if jobs < 2 or rec.n_points < WORKER_MIN_READINGS:
        return None
    return ComparisonWorker(rec, **kw)


@contextlib.contextmanager
def running(rec, wanted: bool, **kw):
    """A command's worker for ``rec`` (:func:`start`, one process per CPU) when ``wanted``, else
    None; stopped, if still running, when the block ends."""
    worker = start(rec, jobs=None, **kw) if wanted else None
    with worker or contextlib.nullcontext():
        yield worker
