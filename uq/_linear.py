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


BATCH = 4096  # XLA CPU hangs on vmapped batches of >= 16k small Cholesky factorisations


def batched(fn, *arrays, batch: int = BATCH):
    """Apply a jitted, vmapped ``fn`` over the leading axis in fixed-size padded batches.

    Fixed batches compile once and sidestep the XLA CPU hang on very large batches of small
    linear-algebra calls. Returns numpy arrays (a tuple if ``fn`` returns a tuple).
    """
    import numpy as np

    n = arrays[0].shape[0]
    outs = []
    for start in range(0, n, batch):
        chunk = [a[start : start + batch] for a in arrays]
        m = chunk[0].shape[0]
        if m < batch:
            chunk = [jnp.concatenate([c, jnp.repeat(c[-1:], batch - m, axis=0)]) for c in chunk]
        res = fn(*chunk)
        res = res if isinstance(res, tuple) else (res,)
        outs.append(tuple(np.asarray(r)[:m] for r in res))
    joined = tuple(np.concatenate([o[i] for o in outs]) for i in range(len(outs[0])))
    return joined if len(joined) > 1 else joined[0]


def draw_linear_numpy(X, y, sigma, prior_sd, rng):
    """Exact draws of beta for many noise samples at once, in numpy.

    X (n, k), y (n,), sigma (N, n) noise sd per sample and point, prior_sd (k,); returns
    (N, k), one draw from N(m_s, A_s^-1) per sample s. numpy's batched LAPACK (gufuncs) is
    used here rather than XLA: XLA's CPU batched Cholesky has been seen to stall under load.
    """
    import numpy as np

    X = np.asarray(X)
    w = 1.0 / np.asarray(sigma) ** 2  # (N, n)
    A = np.einsum("nk,sn,nl->skl", X, w, X) + np.diag(1.0 / np.asarray(prior_sd) ** 2)
    rhs = np.einsum("nk,sn->sk", X, w * np.asarray(y))
    chol = np.linalg.cholesky(A)
    mean = np.linalg.solve(A, rhs[..., None])[..., 0]
    z = rng.standard_normal(mean.shape)
    return mean + np.linalg.solve(np.swapaxes(chol, -1, -2), z[..., None])[..., 0]
