"""numpy's BLAS (OpenBLAS) on one thread in the ``uq`` command.

The numpy work of a fit is many small linear-algebra calls: the sampler's proposals (Cholesky
factors and solves of a few dimensions for every ensemble at every move), the recording-order
check's projections (10000 x n by n x 4), least squares, the convergence statistics. OpenBLAS
runs even these on every core, and its threads spin while they wait: on data/n50 the
recording-order checks alone took 0.8 CPU s (1.9 s wall, the machine loaded) with its default
threads and 0.23 CPU s (0.4 s wall) on one. The large computations are JAX's (XLA has its own
threads, which this does not touch). One thread changes no result of uq fit (its JSON is the same
to the bit on data/n50: OpenBLAS splits matrix products by blocks of the output).

This module imports nothing heavy: the command line calls :func:`set_environment` before numpy
is imported (OpenBLAS reads the variable when it is loaded). A thread count the user set
(``OPENBLAS_NUM_THREADS``, ``GOTO_NUM_THREADS`` or ``OMP_NUM_THREADS``) wins; the library leaves
numpy as the caller's program set it. The processes the command starts (figure workers, Dask
workers) inherit the setting; ``uq batch``'s workers had it already.
"""

from __future__ import annotations

import os
import sys

#: the variables OpenBLAS reads its thread count from, in its order
THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "GOTO_NUM_THREADS", "OMP_NUM_THREADS")


def set_environment() -> bool:
    """One BLAS thread, unless the user chose a number or numpy is already loaded; True if set."""
    if "numpy" in sys.modules or any(v in os.environ for v in THREAD_VARIABLES):
        return False
    os.environ["OPENBLAS_NUM_THREADS"] = "1"
    return True
