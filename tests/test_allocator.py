"""glibc's malloc thresholds (uq._inference.allocator): set once a JAX-using part of uq is imported,
left alone with UQ_MALLOC=default or the user's own GLIBC_TUNABLES."""

import os
import platform
import subprocess
import sys

import pytest

PROBE = (
    "import ctypes, uq._inference.float64; from uq._inference import allocator; "
    "print(allocator._done)"
)


def _probe(**env) -> str:
    run = subprocess.run(
        [sys.executable, "-c", PROBE],
        env={k: v for k, v in os.environ.items() if k not in ("UQ_MALLOC", "GLIBC_TUNABLES")} | env,
        capture_output=True,
        text=True,
        check=True,
    )
    return run.stdout.strip()


glibc = pytest.mark.skipif(
    platform.libc_ver()[0] != "glibc",
    reason="mallopt is glibc's",
)


@glibc
def test_importing_the_jax_layer_sets_the_thresholds():
    assert _probe() == "True"


@glibc
def test_the_user_can_leave_malloc_alone():
    assert _probe(UQ_MALLOC="default") == "False"
    assert _probe(GLIBC_TUNABLES="glibc.malloc.mmap_threshold=65536") == "False"


@glibc
def test_tune_is_idempotent():
    from uq._inference import allocator

    if os.environ.get("UQ_MALLOC", "").lower() == "default":
        pytest.skip("malloc left alone in this process")
    assert allocator.tune() is True
    assert allocator.tune() is True
