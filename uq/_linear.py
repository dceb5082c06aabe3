"""Collapsed linear-Gaussian kernel: the coefficients of a model that is linear in them.

For y ~ N(X beta, diag(sigma^2)) with prior beta ~ N(0, diag(tau^2)), the posterior of beta
given the noise scales is Gaussian, N(m, A^-1) with precision A = X^T W X + T^-1 and mean
m = A^-1 X^T W y (W = diag(sigma^-2), T = diag(tau^2)), and beta integrates out of the
likelihood in closed form:

    log p(y | sigma) = -1/2 [ y^T W y - m^T A m + sum log sigma^2 + sum log tau^2
                             + log det A + n log 2 pi ]          (Woodbury / matrix determinant lemma)

So emcee only has to explore the noise (and any nonlinear mechanism) parameters; the
coefficients are drawn exactly for every retained sample (PHYSICS.md, sampling note).
All functions are pure and jittable; shapes in the docstrings.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

from ._jax import jax, jnp

LOG_2PI = 1.8378770664093453


class LinearPosterior(NamedTuple):
    mean: jnp.ndarray  # (k,)
    chol: jnp.ndarray  # (k, k) lower Cholesky factor of the precision A
    log_marginal: jnp.ndarray  # () log p(y | sigma)


def linear_posterior(X, y, sigma, prior_sd) -> LinearPosterior:
    """Posterior of beta given noise scales. X (n, k), y (n,), sigma (n,), prior_sd (k,)."""
    w = 1.0 / sigma**2
    A = X.T @ (w[:, None] * X) + jnp.diag(1.0 / prior_sd**2)
    chol = jnp.linalg.cholesky(A)
    rhs = X.T @ (w * y)
    mean = jax.scipy.linalg.cho_solve((chol, True), rhs)
    quad = jnp.sum(w * y**2) - rhs @ mean
    logdet = 2.0 * jnp.sum(jnp.log(jnp.diag(chol)))
    log_marginal = -0.5 * (
        quad + jnp.sum(jnp.log(sigma**2)) + jnp.sum(jnp.log(prior_sd**2)) + logdet + y.size * LOG_2PI
    )
    return LinearPosterior(mean, chol, log_marginal)


def draw_coefficients(post: LinearPosterior, z):
    """Exact draw beta = m + A^{-1/2} z; z (k,) standard normal."""
    return post.mean + jax.scipy.linalg.solve_triangular(post.chol.T, z, lower=False)


def posterior_cov(post: LinearPosterior):
    """Covariance A^-1 of beta given the noise, (k, k)."""
    k = post.mean.size
    inv_chol = jax.scipy.linalg.solve_triangular(post.chol, jnp.eye(k), lower=True)
    return inv_chol.T @ inv_chol


def gaussian_loglik(y, mu, sigma):
    """Pointwise log N(y | mu, sigma^2), any matching shapes."""
    return -0.5 * (((y - mu) / sigma) ** 2 + 2.0 * jnp.log(sigma) + LOG_2PI)


DRAW_BATCH = 64  # rows per vmapped block inside the map: bounded memory, one compiled program


def draw_exact(post: LinearPosterior, key):
    """One exact draw of the coefficients from ``post`` (a model's posterior given its sampled
    parameters): ``m + A^{-1/2} z``, z ~ N(0, I) from the JAX ``key``. Every model draws with it,
    mapped over posterior samples by ``map_rows``."""
    return draw_coefficients(post, jax.random.normal(key, post.mean.shape))


@functools.partial(jax.jit, static_argnames=("fn", "batch_size"))
def map_rows(fn, rows, args=(), batch_size: int = DRAW_BATCH):
    """``fn(*row, *args)`` for every row of the arrays in ``rows`` (a tuple, leading axis N), as one
    jitted ``jax.lax.map`` over vmapped blocks of ``batch_size`` rows: one compiled program per
    shape, memory bounded by the block, no Python loop. The one way every model maps its exact
    coefficient draws (``draw_exact``) and its pointwise log-likelihoods over posterior samples.
    ``fn`` must be a module-level function (it is a static argument)."""
    return jax.lax.map(lambda r: fn(*r, *args), rows, batch_size=batch_size)
