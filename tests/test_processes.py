"""Work in a spawned worker process (``uq._io.processes.Beside``): answers, errors, a worker that dies."""

from __future__ import annotations

import os
import signal

import pytest

from uq._io.errors import InputError
from uq._io.processes import Beside, WorkerDied


def _refuse(message, param):
    raise InputError(message, param=param)


def test_the_answer_comes_back():
    with Beside("adding", sum, [1, 2, 3], start=4) as w:
        assert w.result() == 10


def test_a_function_named_is_imported_in_the_worker():
    with Beside("joining", "os.path:join", "a", "b") as w:
        assert w.result() == os.path.join("a", "b")
    with Beside("importing", "no_such_module_here:f") as w:
        with pytest.raises(ModuleNotFoundError, match="no_such_module_here"):
            w.result()


def test_an_error_in_the_worker_is_raised_here_with_its_parameter():
    with Beside("refusing", _refuse, "load_N: expected a positive load", "load_N") as w:
        with pytest.raises(InputError, match="^load_N: expected") as e:
            w.result()
    assert e.value.param == "load_N"


@pytest.mark.parametrize(
    "fn, args, why",
    [(os._exit, (3,), r"exit status 3\)"), (signal.raise_signal, (signal.SIGKILL,), "SIGKILL")],
)
def test_a_worker_that_dies_is_an_error_not_a_hang(fn, args, why):
    with Beside("dying", fn, *args) as w:
        with pytest.raises(WorkerDied, match=f"the worker process dying stopped .*{why}"):
            w.result()


def test_leaving_the_block_stops_a_running_worker():
    import time

    with Beside("sleeping", time.sleep, 600) as w:
        process = w._process
    assert not process.is_alive() and process.exitcode == -signal.SIGTERM


def test_a_worker_collects_garbage_as_a_short_lived_process():
    """A worker's cyclic collector is set for a process that lives as long as one command; the
    calling process (the library's) keeps its own."""
    import gc

    from uq._io.processes import SHORT_LIVED_GC

    mine = gc.get_threshold()
    with Beside("asking", "gc:get_threshold") as w:
        assert tuple(w.result()) == SHORT_LIVED_GC
    assert gc.get_threshold() == mine != SHORT_LIVED_GC
