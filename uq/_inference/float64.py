"""JAX set-up in one place: float64 always (the cubic coefficients span 10 orders of magnitude).

JAX computes in float32 unless its process-wide flag ``jax_enable_x64`` is on. uq's models need
float64 (coefficients from about 1e4 N down to 1e-6 N/m^3 in one solve, log-densities summed over
hundreds of readings), so every module that uses JAX imports this one first, and importing it
calls :func:`enable_x64`. The flag belongs to the process: once a uq model is loaded, other JAX
code in the same process computes in float64 too (its default dtypes become 64-bit). ``import uq``
alone loads no JAX; the switch happens when a JAX-using part of uq is first used.

Importing it also turns on JAX's persistent compilation cache (``uq._inference.jax_cache``:
``~/.cache/airspring-uq/jax``, ``UQ_CACHE_DIR`` to move it or ``off``), as the ``uq`` command
does, unless a cache directory was set for JAX already, and sets glibc's malloc to keep JAX's
large temporaries in the heap (``uq._inference.allocator``; ``UQ_MALLOC=default`` to leave it).
"""

from uq._inference import allocator

allocator.tune()  # before JAX allocates anything

import jax  # noqa: E402

from uq._inference.jax_cache import configure  # noqa: E402


def enable_x64() -> None:
    """Switch JAX to float64 for this process (``jax_enable_x64``); idempotent, prints nothing.

    uq calls it before any of its models traces, so calling it yourself is only needed to make the
    switch explicit, or to restore it after other code turned it off.

    >>> import uq
    >>> uq.enable_x64()
    >>> import jax.numpy as jnp
    >>> jnp.zeros(1).dtype
    dtype('float64')
    """
    if not jax.config.read("jax_enable_x64"):
        jax.config.update("jax_enable_x64", True)


enable_x64()
configure(jax)

import jax.numpy as jnp  # noqa: E402

__all__ = ["enable_x64", "jax", "jnp"]
