"""Work in spawned worker processes: the report's figure workers, a fit beside another fit.

JAX programs cannot run side by side in two threads of one process (``uq._inference.threads``:
jaxlib 0.10.2 deadlocks on two concurrent Cholesky programs), so independent fits run side by
side in processes. Workers are spawned, not forked: the calling process may hold a JAX runtime,
which fork can deadlock; a spawned worker imports the calling script again (as
``__mp_main__``: a script that starts workers needs an ``if __name__ == "__main__":`` guard,
which is why the library starts none unless asked). A spawned worker pays for its own imports
(numpy, JAX and uq's modules for a fit: about 1 CPU s), so work goes to one only where it takes
longer than that.

Ctrl-C reaches every process of the terminal's group: workers ignore it from their first
instruction on (:func:`interrupts_ignored`), and the process that started them answers it (one
line, exit 130) and stops them.
"""

from __future__ import annotations

import contextlib
import gc
import multiprocessing
import os
import pickle
import signal
import sys
import threading

from uq._io.progress import set_enabled
from uq._io.values import resolve


def cores() -> int:
    """The CPUs this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def exit_now(status: int = 0, *, broken_pipe: int = 141, unwritable: int = 2) -> None:
    """End this process with ``status`` once stdout and stderr are flushed (``os._exit``), without
    Python's shutdown (after JAX's or matplotlib's import it takes tenths of a second and does
    nothing a finished command or worker needs). A reader of stdout that went away gives
    ``broken_pipe`` (the shell's status for SIGPIPE), stdout closed or its disk full
    ``unwritable`` unless the status already says something went wrong."""
    try:
        sys.stdout.flush()
    except BrokenPipeError:
        status = broken_pipe
    except OSError:
        status = status or unwritable
    with contextlib.suppress(Exception):
        sys.stderr.flush()
    os._exit(status)


def ignore_interrupts() -> None:
    """A worker's initializer: leave Ctrl-C to the process that started it."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


@contextlib.contextmanager
def interrupts_ignored():
    """Processes started in this block ignore Ctrl-C from their first instruction on.

    A spawned worker is still importing when a Ctrl-C arrives: it would print a traceback. Only
    the process that started it may answer it. An ignored signal stays ignored across exec, and
    Python keeps it so. The cost: a Ctrl-C in the few milliseconds the workers take to start is
    ignored here too (press it again). (Only the main thread can set handlers; elsewhere nothing
    is done.)
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    handler = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, handler)


#: the cyclic garbage collector's thresholds in a process of the command line or one of its
#: workers (``short_lived``); Python's default is (700, 10, 10)
SHORT_LIVED_GC = (50_000, 20, 100)


def short_lived() -> None:
    """The cyclic garbage collector set for a process that lives as long as one command: most of
    its objects (the imports', JAX's traced programs) live to its end, and every collection of the
    older generations walks them again (and runs JAX's collection callback). The youngest
    generation is collected every 50000 net allocations instead of 700, so the older ones far
    less often: on ``uq design`` about 30 collections instead of about 500 and no full one instead
    of three (docs/speed.md), the peak memory the same. The library leaves the collector as the
    user set it."""
    gc.set_threshold(*SHORT_LIVED_GC)


class WorkerDied(RuntimeError):
    """A worker process stopped without an answer (killed, out of memory, a crash in C)."""


def _run(send, fn, args, kwargs) -> None:
    """The worker: ``(True, fn(*args, **kwargs))`` or ``(False, the exception it raised)``
    (``fn``: a function, or one named ``"module:attribute"``),
    pickled straight into the pipe (no copy of a large answer held in memory first)."""
    ignore_interrupts()
    short_lived()
    set_enabled(False)  # the calling process draws its own bar on the same terminal
    try:
        # a function named "module:attribute" is imported here, not by the caller (Beside)
        answer = (True, resolve(fn)(*args, **kwargs))
    except BaseException as exc:  # noqa: BLE001 - every failure goes back to the caller
        try:
            pickle.dumps(exc)
            answer = (False, exc)
        except Exception as why:  # an exception that does not pickle: its type and line
            answer = (False, RuntimeError(f"{type(exc).__name__}: {exc} ({why})"))
    with open(send.fileno(), "wb", closefd=False) as out:
        pickle.dump(answer, out, protocol=pickle.HIGHEST_PROTOCOL)


class Beside:
    """``fn(*args, **kwargs)`` computed in a spawned worker process while this one goes on
    (``fn`` named ``"module:attribute"``: imported in the worker alone, so that this process need
    not have imported it, nor what it imports);
    ``what`` names the work in an error (``"fitting the per-pressure cubics"``). A context
    manager: :meth:`result` waits for the answer (an exception raised in the worker is raised
    here; a worker that stops without an answer raises :class:`WorkerDied`), and leaving the
    block stops a worker still running (Ctrl-C, an error in this process). The answer comes back
    pickled through a pipe: the same objects, to the bit, as computed here."""

    def __init__(self, what: str, fn, *args, **kwargs):
        self.what = what
        ctx = multiprocessing.get_context("spawn")
        self._answer, send = ctx.Pipe(duplex=False)
        with interrupts_ignored():
            self._process = ctx.Process(target=_run, args=(send, fn, args, kwargs), daemon=True)
            self._process.start()
        send.close()  # this process's copy: the worker's end alone is left, so its exit is EOF

    def result(self):
        try:
            with open(self._answer.fileno(), "rb", closefd=False) as f:
                ok, answer = pickle.load(f)
        except (EOFError, pickle.UnpicklingError):
            self._process.join()
            code = self._process.exitcode
            how = f"killed by {signal.Signals(-code).name}" if code < 0 else f"exit status {code}"
            raise WorkerDied(
                f"the worker process {self.what} stopped without an answer ({how}"
                f"{'; out of memory?' if code == -signal.SIGKILL else ''})"
            ) from None
        if not ok:
            raise answer
        return answer

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        if self._process.is_alive():
            self._process.terminate()
        self._process.join()
        self._answer.close()
