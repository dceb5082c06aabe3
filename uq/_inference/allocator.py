"""glibc's malloc set to keep large blocks in the heap: JAX's temporaries are not handed back to the
kernel after every call.

A sampler calls the same compiled program thousands of times, and every call allocates
temporaries of a few MB (batched over the walkers: the discrepancy surface's prior covariance and
Cholesky factors for 184 walkers are 14 MB each). glibc serves a block above its mmap threshold
(128 kB, raised dynamically only up to 32 MB) with a fresh ``mmap`` and returns it with
``munmap`` when freed, and trims the heap's free top above 128 kB: each call then faults its
temporaries' pages in again. In one fit of the discrepancy surface to data/n50 that was 74 of 239
CPU seconds, spent in the kernel. With both thresholds at ``THRESHOLD_BYTES`` the blocks stay in
the heap and are reused (``benchmarks/discrepancy.py`` measures a call of that log posterior both
ways in one process: docs/speed.md). The cubics' and the surface's fits, whose temporaries are
small, hardly change.

What it costs: up to ``THRESHOLD_BYTES`` of freed memory may stay with the process (its resident
size after a peak), and a block above it still goes to ``mmap``. The settings belong to the
process, like JAX's float64 switch: :func:`tune` runs when a JAX-using part of uq is first
imported (``uq._inference.float64``), in the command line, the library and ``uq batch``'s
workers alike. ``UQ_MALLOC=default`` leaves malloc as it is; so does a ``GLIBC_TUNABLES`` that
sets malloc's own thresholds, and a C library that is not glibc (nothing is changed there).
"""

from __future__ import annotations

import ctypes
import os

#: both thresholds (bytes): blocks up to this size come from the heap, and the heap keeps up to
#: this much free memory at its top
THRESHOLD_BYTES = 512 * 2**20
#: mallopt's parameter numbers (glibc's malloc.h)
M_TRIM_THRESHOLD, M_MMAP_THRESHOLD = -1, -3

_done = False


def tune() -> bool:
    """Set glibc's mmap and trim thresholds to ``THRESHOLD_BYTES`` once per process; True when set
    (False: turned off, set by the user through ``GLIBC_TUNABLES``, or not glibc)."""
    global _done
    if _done:
        return True
    if os.environ.get("UQ_MALLOC", "").lower() == "default":
        return False
    if "glibc.malloc.mmap_threshold" in os.environ.get("GLIBC_TUNABLES", ""):
        return False
    try:  # the process's own symbols: libc is loaded already (find_library would run ldconfig)
        mallopt = ctypes.CDLL(None).mallopt
    except (OSError, AttributeError):  # not glibc (macOS, musl without mallopt): nothing to tune
        return False
    mallopt.argtypes, mallopt.restype = (ctypes.c_int, ctypes.c_int), ctypes.c_int
    _done = bool(
        mallopt(M_MMAP_THRESHOLD, THRESHOLD_BYTES) and mallopt(M_TRIM_THRESHOLD, THRESHOLD_BYTES)
    )
    return _done
