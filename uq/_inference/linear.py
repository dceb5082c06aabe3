"""Collapsed linear-Gaussian kernel: the coefficients of a model that is linear in them.

For y ~ N(X beta, diag(sigma^2)) with prior beta ~ N(0, diag(tau^2)), the posterior of beta
given the noise scales is Gaussian, N(m, A^-1) with precision A = X^T W X + T^-1 and mean
m = A^-1 X^T W y (W = diag(sigma^-2), T = diag(tau^2)), and beta integrates out of the
likelihood in closed form:

    log p(y | sigma) = -1/2 [ y^T W y - m^T A m + sum log sigma^2 + sum log tau^2
                             + log det A + n log 2 pi ]          (Woodbury / matrix determinant lemma)

So emcee only has to explore the noise (and any nonlinear mechanism) parameters; the
coefficients are drawn exactly for every retained sample (docs/methods.md).
All functions are pure and jittable; shapes in the docstrings.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from uq._inference.exported import persistent_jit
from uq._inference.float64 import jax, jnp

LOG_2PI = 1.8378770664093453


class LinearPosterior(NamedTuple):
    mean: jnp.ndarray  # (k,)
    chol: jnp.ndarray  # (k, k) lower Cholesky factor of the precision A
    log_marginal: jnp.ndarray  # () log p(y | sigma)


def linear_posterior(X, y, sigma, prior_sd, weight=None) -> LinearPosterior:
    """Posterior of beta given noise scales. X (n, k), y (n,), sigma (n,), prior_sd (k,).

    ``weight`` (n,) of 1 (fitted) and 0 (held out, e.g. for an exact leave-one-out refit): a
    held-out reading is left out of the posterior and of the marginal likelihood."""
    w = 1.0 / sigma**2 if weight is None else weight / sigma**2
    n = y.size if weight is None else jnp.sum(weight)
    log_det = jnp.sum(jnp.log(sigma**2) if weight is None else weight * jnp.log(sigma**2))
    return posterior_from_moments(
        X.T @ (w[:, None] * X), X.T @ (w * y), jnp.sum(w * y**2), n, log_det, prior_sd
    )


def loo_given_noise(X, y, sigma, prior_sd):
    """log p(y_i | sigma, y_-i) of every reading of a linear-Gaussian model with independent noise,
    coefficients integrated out exactly (no refit: the leave-one-out predictive follows from the
    full posterior by the Woodbury identity), (n,)."""
    Xw, yw = X / sigma[:, None], y / sigma
    post = linear_posterior(Xw, yw, jnp.ones_like(yw), prior_sd)
    Z = jax.scipy.linalg.solve_triangular(post.chol, Xw.T, lower=True)
    m = 1.0 - jnp.sum(Z**2, 0)
    r = yw - Xw @ post.mean
    return -0.5 * r**2 / m + 0.5 * jnp.log(m) - 0.5 * LOG_2PI - jnp.log(sigma)


def posterior_from_moments(gram, rhs, yy, n, log_noise_det, prior_sd) -> LinearPosterior:
    """The same posterior from the data's sufficient statistics: gram = X^T W X (k, k),
    rhs = X^T W y (k,), yy = y^T W y, n readings, log_noise_det = log det of the noise
    covariance (sum log sigma^2 for independent readings). For models whose Gram matrix is
    cheaper to form than the weighted design (``GramPlan``)."""
    A = gram + jnp.diag(1.0 / prior_sd**2)
    chol = jnp.linalg.cholesky(A)
    mean = jax.scipy.linalg.cho_solve((chol, True), rhs)
    quad = yy - rhs @ mean
    logdet = 2.0 * jnp.sum(jnp.log(jnp.diag(chol)))
    log_marginal = -0.5 * (
        quad + log_noise_det + jnp.sum(jnp.log(prior_sd**2)) + logdet + n * LOG_2PI
    )
    return LinearPosterior(mean, chol, log_marginal)


class GramPlan(NamedTuple):
    """``sum_g sum_(A, B) in group g  A^T diag(w_g) B`` for designs fixed during sampling and weights
    w_g that change with every noise draw (``gram_plan``, ``weighted_gram``).

    Entry (j, k) of ``A^T diag(w) B`` is ``w @ (A[:, j] * B[:, k])``. Polynomial designs repeat the
    same column products up to a constant many times over (t^a t^b = t^(a+b)), so each group keeps
    only its distinct products (``products[g]``, (n, m_g)) and every Gram entry gathers its terms
    from them (``index``, ``coef``: (E, T) for E entries, pointing into the concatenated moments
    w_g @ products[g] followed by one zero). For the surface model this is 420 moments instead of a 51 x 51 Gram
    from 814 rows: about 12 times fewer operations per noise draw, and one matrix product for all
    walkers at once. A plan of a symmetric sum (``symmetric=True``) holds the lower triangle's
    entries only, half the gathers, and ``full`` mirrors them, so the matrix is exactly symmetric."""

    products: tuple  # (n, m_g) per weight group
    index: np.ndarray  # (E, T) int: E = k*k entries, or k (k + 1) / 2 of a symmetric plan
    coef: np.ndarray  # (E, T)
    full: np.ndarray  # (k*k,) int: the entry of each element of the (k, k) matrix


def gram_plan(groups, *, rtol: float = 1e-12, symmetric: bool = False) -> GramPlan:
    """Plan for ``weighted_gram``: ``groups`` is a sequence, one entry per weight vector, of
    sequences of (A, B) design pairs (each (n, k), numpy, the same k). Column products equal up
    to a constant (checked to ``rtol`` of their norm, not just hashed) share one moment.
    ``symmetric``: every group's sum is symmetric for any weights (pairs (A, A), or (A, B) with
    (B, A)); only the lower triangle is planned (checked: ValueError otherwise)."""
    k = np.shape(groups[0][0][0])[1]
    if symmetric:
        _require_symmetric(groups, rtol)
    lower = np.tril_indices(k)
    position = np.arange(k * k).reshape(k, k)
    if symmetric:
        position[lower] = np.arange(lower[0].size)
        position.T[lower] = np.arange(lower[0].size)
    products, entries, offset = [], [[] for _ in range(int(position.max()) + 1)], 0
    for pairs in groups:
        unique, buckets = [], {}
        for A, B in pairs:
            A, B = np.asarray(A, float), np.asarray(B, float)
            for j in range(k):
                cols = A[:, j : j + 1] * (B[:, : j + 1] if symmetric else B)
                norms = np.linalg.norm(cols, axis=0)
                for kk in np.flatnonzero(norms > 0):
                    v = cols[:, kk] / norms[kk]
                    v = v * np.sign(v[np.flatnonzero(np.abs(v) > 1e-8)[0]])
                    key = np.round(v * 1e8).astype(np.int64).tobytes()
                    for u in buckets.setdefault(key, []):
                        if np.max(np.abs(unique[u][0] - v)) <= rtol * 10:
                            break
                    else:
                        u = len(unique)
                        unique.append((v, cols[:, kk]))
                        buckets[key].append(u)
                    ref = unique[u][1]
                    scale = (cols[:, kk] @ ref) / (ref @ ref)
                    entries[position[j, kk]].append((offset + u, scale))
        products.append(
            np.stack([col for _, col in unique], axis=1) if unique else np.zeros((A.shape[0], 0))
        )
        offset += len(unique)
    width = max(1, max(len(e) for e in entries))
    index = np.full((len(entries), width), offset, dtype=np.int32)  # ``offset``: the zero moment
    coef = np.zeros((len(entries), width))
    for i, e in enumerate(entries):
        for t, (u, scale) in enumerate(e):
            index[i, t], coef[i, t] = u, scale
    return GramPlan(tuple(products), index, coef, position.reshape(-1).astype(np.int32))


def _require_symmetric(groups, rtol: float) -> None:
    """Each group's sum at random weights is a symmetric matrix (to ``rtol`` of its scale)."""
    rng = np.random.default_rng(0)
    for pairs in groups:
        n = np.shape(pairs[0][0])[0]
        w = rng.uniform(0.5, 1.5, n)
        G = sum(np.asarray(A, float).T @ (w[:, None] * np.asarray(B, float)) for A, B in pairs)
        if not np.allclose(G, G.T, rtol=0.0, atol=rtol * 10 * max(np.max(np.abs(G)), 1e-300)):
            raise ValueError("gram_plan(symmetric=True): a group's sum is not symmetric")


def weighted_gram(plan: GramPlan, weights):
    """``sum_g sum_(A, B) A^T diag(weights[g]) B`` (k, k) from the plan; weights one (n,) per group."""
    moments = jnp.concatenate(
        [w @ Q for w, Q in zip(weights, plan.products, strict=True)] + [jnp.zeros(1)]
    )
    k = int(round(np.sqrt(plan.full.shape[0])))
    entries = jnp.sum(moments[plan.index] * plan.coef, axis=-1)
    return (entries if plan.index.shape[0] == k * k else entries[plan.full]).reshape(k, k)


def reading_forms(plan: GramPlan, M):
    """Per group g and reading i, ``sum_(A, B) in group g  A_i^T M B_i`` (A_i: row i of A), as a
    tuple of (n,) vectors, for a (k, k) matrix M: every reading's quadratic forms (e.g. leverages,
    M the posterior covariance) from the plan's column products, n m_g operations a group
    instead of the n k^2 of forming M's products with the designs."""
    k = int(round(np.sqrt(plan.full.shape[0])))
    sizes = [Q.shape[1] for Q in plan.products]
    terms = jnp.asarray(plan.coef)[plan.full] * jnp.reshape(M, (k * k, 1))
    c = jnp.zeros(sum(sizes) + 1).at[jnp.asarray(plan.index)[plan.full]].add(terms)
    offsets = np.cumsum([0] + sizes)
    return tuple(Q @ c[offsets[g] : offsets[g + 1]] for g, Q in enumerate(plan.products))


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


DRAW_BATCH = 64  # rows per vmapped block inside the map: bounded memory
DRAW_CHUNK = 1024  # rows per call of the compiled program: one program whatever the number of rows


def draw_exact(post: LinearPosterior, key):
    """One exact draw of the coefficients from ``post`` (a model's posterior given its sampled
    parameters): ``m + A^{-1/2} z``, z ~ N(0, I) from the JAX ``key``. Every model draws with it,
    mapped over posterior samples by ``map_rows``."""
    return draw_coefficients(post, jax.random.normal(key, post.mean.shape))


def bucket(n: int, size: int = DRAW_BATCH) -> int:
    """``size`` times the power of two that covers ``n``: the padded length of a computation whose
    length changes from run to run (the retained samples follow tau), so that its compiled program
    serves every run in the bucket and JAX's persistent compilation cache finds it again."""
    blocks = max(1, -(-int(n) // size))
    return size * (1 << (blocks - 1).bit_length())


def pad_rows(a, size: int) -> np.ndarray:
    """``a`` (N, ...) with its last row repeated up to ``size`` rows (as numpy)."""
    a = np.asarray(a)
    return (
        np.concatenate([a, np.repeat(a[-1:], size - a.shape[0], axis=0)])
        if size > a.shape[0]
        else a
    )


def row_keys(key, n: int) -> np.ndarray:
    """``jax.random.split(key, n)``, the same keys, computed at the bucket size: JAX's threefry split
    is partitionable (``jax_threefry_partitionable``, the default since JAX 0.5), so the first n
    keys of a longer split are the keys of the short one, and the compiled split is shared."""
    return np.asarray(jax.random.split(key, bucket(n)))[: int(n)]


def seed_row_keys(seed: int, which: int, n: int) -> np.ndarray:
    """``row_keys(jax.random.split(jax.random.PRNGKey(seed))[which], n)``, the same keys, from one
    kept program (``persistent_jit``) instead of the seven one-operation programs JAX looks up for
    those calls in every process."""
    return np.asarray(_seed_keys(np.asarray(seed, dtype=np.int64), which, bucket(n)))[: int(n)]


@persistent_jit(static_argnums=(1, 2))
def _seed_keys(seed, which, size):
    return jax.random.split(jax.random.split(jax.random.PRNGKey(seed))[which], size)


def map_rows(
    fn, rows, args=(), *, static=(), batch_size: int = DRAW_BATCH, chunk: int = DRAW_CHUNK
):
    """``fn(*row, *static, *args)`` for every row of the arrays in ``rows`` (a tuple, leading axis N),
    as numpy (a pytree of arrays if ``fn`` returns one).

    The one way every model maps a function over posterior samples (exact coefficient draws with
    ``draw_exact`` and keys from :func:`row_keys`, pointwise log-likelihoods, log posteriors):
    the rows are padded to a multiple of ``chunk`` (the padding computed and dropped) and each
    chunk goes through one jitted ``jax.lax.map`` over vmapped blocks of ``batch_size`` rows
    (``batch_size=1``: a plain sequential map). So a model compiles one program however many
    rows it maps, memory is bounded by the chunk, and the chunks' loop is the only Python loop.
    ``fn`` and the entries of ``static`` (e.g. a model's functions) must be hashable module-level
    objects: they are static arguments of the compiled program; ``args`` are arrays (traced)."""
    n = int(np.shape(rows[0])[0])
    padded = tuple(pad_rows(r, n + (-n % chunk)) for r in rows)
    args, static = tuple(args), tuple(static)
    parts = [
        _map_rows(fn, static, tuple(r[i : i + chunk] for r in padded), args, batch_size)
        for i in range(0, padded[0].shape[0], chunk)
    ]
    return jax.tree.map(lambda *a: np.concatenate([np.asarray(x) for x in a])[:n], *parts)


@persistent_jit(static_argnums=(0, 1, 4))
def _map_rows(fn, static, rows, args, batch_size):
    return jax.lax.map(lambda r: fn(*r, *static, *args), rows, batch_size=batch_size)
