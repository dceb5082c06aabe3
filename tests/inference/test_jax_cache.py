"""The library uses JAX's persistent compilation cache as the command line does
(uq/_inference/jax_cache.py): on, in UQ_CACHE_DIR, every program kept; off with
UQ_CACHE_DIR=off; a cache directory the user gave JAX wins."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

CODE = (
    "import uq._inference.float64\n"
    "import jax\n"
    "print(jax.config.jax_compilation_cache_dir, jax.config.jax_persistent_cache_min_compile_time_secs)\n"
)


def _library(**env) -> list[str]:
    keep = {k: v for k, v in os.environ.items() if not k.startswith("JAX_") and k != "UQ_CACHE_DIR"}
    return subprocess.run(
        [sys.executable, "-c", CODE], capture_output=True, text=True, check=True, env=keep | env
    ).stdout.split()


@pytest.mark.parametrize(
    "env, want",
    [
        ({"UQ_CACHE_DIR": "{tmp}"}, ["{tmp}", "0.0"]),
        ({"UQ_CACHE_DIR": "off"}, ["None", "1.0"]),
        (
            {"UQ_CACHE_DIR": "{tmp}", "JAX_COMPILATION_CACHE_DIR": "{tmp}/mine"},
            ["{tmp}/mine", "1.0"],
        ),
    ],
)
def test_the_library_uses_the_compilation_cache(env, want, tmp_path):
    env = {k: v.format(tmp=tmp_path) for k, v in env.items()}
    assert _library(**env) == [w.format(tmp=tmp_path) for w in want]
