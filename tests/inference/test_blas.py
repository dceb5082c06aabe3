"""numpy's BLAS on one thread in the command line (uq._inference.blas), the user's choice kept."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from uq._inference.blas import THREAD_VARIABLES

PROBE = (
    "import json, os; from uq._cli.main import _compile_cache; _compile_cache(); import numpy; "
    f"print(json.dumps({{v: os.environ.get(v) for v in {THREAD_VARIABLES!r}}}))"
)


def _probe(**env):
    clean = {k: v for k, v in os.environ.items() if k not in THREAD_VARIABLES}
    out = subprocess.run(
        [sys.executable, "-c", PROBE], env=clean | env, capture_output=True, text=True, check=True
    )
    return json.loads(out.stdout)


def test_the_command_line_sets_one_blas_thread_before_numpy_loads():
    assert _probe()["OPENBLAS_NUM_THREADS"] == "1"


@pytest.mark.parametrize("variable", THREAD_VARIABLES)
def test_a_thread_count_the_user_set_wins(variable):
    seen = _probe(**{variable: "2"})
    assert seen[variable] == "2"
    assert all(seen[v] is None for v in THREAD_VARIABLES if v != variable)


def test_nothing_is_set_once_numpy_is_loaded(monkeypatch):
    from uq._inference import blas

    for v in THREAD_VARIABLES:
        monkeypatch.delenv(v, raising=False)
    assert "numpy" in sys.modules  # loaded by the test session
    assert blas.set_environment() is False
    assert "OPENBLAS_NUM_THREADS" not in os.environ
