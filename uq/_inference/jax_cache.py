"""JAX's persistent compilation cache, for the ``uq`` command and the library alike.

A fit compiles a few dozen XLA programs (log posteriors, exact draws, the optimiser); kept on
disk, a second run in a new process loads them instead of compiling them again. The cache is
``$UQ_CACHE_DIR`` (default ``$XDG_CACHE_HOME/airspring-uq/jax``, i.e.
``~/.cache/airspring-uq/jax``); ``UQ_CACHE_DIR=off`` turns it off. A cache location the user
set for JAX (``JAX_COMPILATION_CACHE_DIR`` or ``jax.config``) wins.

Every program is kept, however fast it compiled (``MIN_COMPILE_SECONDS`` 0; JAX's default of
1 s left 35 of a fit's 53 programs to be compiled again on every run; a cached program loads
in a few milliseconds).

This module imports nothing heavy: the command line calls :func:`set_environment` before JAX is
imported (JAX reads these variables on import); ``uq._inference.float64``, which every
JAX-using module of uq imports first, calls :func:`configure` on the imported JAX, so that
library users get the same cache. It takes effect for the programs compiled after it (uq's
own: it runs before uq compiles anything).
"""

from __future__ import annotations

import os
import sys

#: programs that compiled faster than this are not cached (JAX's default: 1 s)
MIN_COMPILE_SECONDS = 0.0
OFF = ("off", "0", "none")


def cache_dir() -> str | None:
    """Where the cache is (``UQ_CACHE_DIR`` or the default), None when it is turned off."""
    where = os.environ.get("UQ_CACHE_DIR", "")
    if where.lower() in OFF:
        return None
    if where:
        return where
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return os.path.join(base, "airspring-uq", "jax")


def set_environment() -> None:
    """The cache through JAX's environment variables (the command line, before JAX is imported;
    nothing is done once JAX is imported or when the user set JAX's own variable)."""
    where = cache_dir()
    if where is None or "JAX_COMPILATION_CACHE_DIR" in os.environ or "jax" in sys.modules:
        return
    os.environ["JAX_COMPILATION_CACHE_DIR"] = where
    os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", str(MIN_COMPILE_SECONDS))
    os.environ.setdefault("JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES", "0")


def configure(jax) -> None:
    """The cache through ``jax.config`` (the library: JAX is imported), unless the user set a
    cache directory of their own or turned uq's off."""
    where = cache_dir()
    if where is None or jax.config.jax_compilation_cache_dir:
        return
    jax.config.update("jax_compilation_cache_dir", where)
    if "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS" not in os.environ:
        jax.config.update("jax_persistent_cache_min_compile_time_secs", MIN_COMPILE_SECONDS)
    if "JAX_PERSISTENT_CACHE_MIN_ENTRY_SIZE_BYTES" not in os.environ:
        jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
