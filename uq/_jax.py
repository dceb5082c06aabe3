"""JAX set-up in one place: float64 always (the cubic coefficients span 10 orders of magnitude)."""

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402

__all__ = ["jax", "jnp"]
