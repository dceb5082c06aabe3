"""Linear-Gaussian coefficients under noise with a low-dimensional latent part (Woodbury).

For y = Z beta + U z + e with e ~ N(0, diag(v)) independent, z ~ N(0, Q^-1) a latent Gaussian
of precision Q (m x m), and beta ~ N(0, diag(tau^2)), the readings' covariance given the noise is
Sigma = diag(v) + U Q^-1 U^T. By the Woodbury identity and the matrix determinant lemma,

    Sigma^-1 = D - D U M^-1 U^T D,          M = Q + U^T D U,   D = diag(1/v),
    log det Sigma = sum log v + log det M - log det Q,

so the coefficients' Gaussian posterior (``uq._inference.linear.posterior_from_moments``) needs
only an m x m Cholesky factor, and beta stays conjugate (exact draws) whatever the latent's
correlation. The per-pressure cubic with an AR(1) pressure-holding error (z = the holding errors
in recording order, Q tridiagonal) is one use (``uq._models.cubic``, its pressure-holding section).

``weight`` (the readings' rows, 1 fitted, 0 held out) sets D's held-out entries to zero: the
result is then the density of the fitted rows alone (the latent still integrated out).
All functions are pure and jittable.
"""

from __future__ import annotations

import numpy as np

from uq._inference.float64 import jax, jnp
from uq._inference.linear import LOG_2PI, LinearPosterior, posterior_from_moments
from uq._stand.shapes import SENSOR_GAIN_SD, SENSOR_RESOLUTION_PA


def _factor(U, v, Q, w):
    D = w / v
    DU = D[:, None] * U
    M = Q + U.T @ DU
    return D, DU, jnp.linalg.cholesky(M)


def latent_posterior(Z, y, v, U, Q, log_det_Q, prior_sd, weight=None) -> LinearPosterior:
    """Posterior of beta (and the log marginal likelihood of y) given the noise.

    Z (N, k), y (N,), v (N,) the independent variances, U (N, m), Q (m, m) the latent's precision
    with ``log_det_Q`` its log determinant, prior_sd (k,), weight (N,) or None."""
    w = jnp.ones_like(y) if weight is None else weight
    D, DU, chol = _factor(U, v, Q, w)
    A = jax.scipy.linalg.solve_triangular(chol, DU.T @ Z, lower=True)  # (m, k)
    a = jax.scipy.linalg.solve_triangular(chol, DU.T @ y, lower=True)  # (m,)
    gram = Z.T @ (D[:, None] * Z) - A.T @ A
    rhs = Z.T @ (D * y) - A.T @ a
    yy = jnp.sum(D * y**2) - a @ a
    log_det = jnp.sum(w * jnp.log(v)) + 2.0 * jnp.sum(jnp.log(jnp.diag(chol))) - log_det_Q
    return posterior_from_moments(gram, rhs, yy, jnp.sum(w), log_det, prior_sd)


def paired_ar1_precision(v, uf, ul, rho):
    """Sigma^-1 (2n, 2n), dense, of the paired AR(1) covariance of ``paired_ar1_posterior``
    (for pointwise densities), from the tridiagonal factor: D - B^T B, B = L^-1 U^T D."""
    n = uf.shape[0]
    D = 1.0 / v
    c = 1.0 - rho**2
    q_diag = jnp.full(n, 1.0 + rho**2).at[0].set(1.0).at[-1].set(1.0) / c
    m_diag = q_diag + uf**2 * D[:n] + ul**2 * D[n:]
    G = jnp.concatenate([jnp.diag(uf * D[:n]), jnp.diag(ul * D[n:])], axis=1)  # U^T D, (n, 2n)
    _, B = _tridiagonal_cholesky_solve(m_diag, -rho / c, G)
    return jnp.diag(D) - B.T @ B


def ar1_series(rho, z):
    """The stationary AR(1) series of unit variance driven by standard normal ``z`` (n,): z_0,
    then rho x_(i-1) + sqrt(1 - rho^2) z_i (a scan, no factorisation)."""

    def step(x, e):
        x = rho * x + jnp.sqrt(1.0 - rho**2) * e
        return x, x

    _, rest = jax.lax.scan(step, z[0], z[1:])
    return jnp.concatenate([z[:1], rest])


def block_conditional_logpdf(P, r, blocks):
    """log p(r_b | r_rest) of each 2-row block b of a zero-mean Gaussian with precision P,
    (n_blocks,). ``blocks`` (n_blocks, 2) integer rows of each block. With P's block P_bb and
    (P r)_b, the conditional is N(r_b - P_bb^-1 (P r)_b, P_bb^-1). The 2 x 2 algebra is written
    out (no batched Cholesky factorisation: XLA on CPU can hang on those inside vmapped maps)."""
    Pr = P @ r
    a = P[blocks[:, 0], blocks[:, 0]]
    b = P[blocks[:, 0], blocks[:, 1]]
    d = P[blocks[:, 1], blocks[:, 1]]
    g0, g1 = Pr[blocks[:, 0]], Pr[blocks[:, 1]]
    det = a * d - b * b
    quad = (d * g0**2 - 2.0 * b * g0 * g1 + a * g1**2) / det
    return -0.5 * quad + 0.5 * jnp.log(det) - LOG_2PI


def ar1_precision(rho, n: int):
    """The precision R^-1 (n, n) of a stationary AR(1) series with unit variance and lag-one
    correlation rho (tridiagonal), and its log determinant -(n - 1) log(1 - rho^2)."""
    c = 1.0 - rho**2
    diag = jnp.full(n, 1.0 + rho**2).at[0].set(1.0).at[-1].set(1.0) / c
    off = jnp.full(n - 1, -rho / c)
    Q = jnp.diag(diag) + jnp.diag(off, 1) + jnp.diag(off, -1)
    return Q, -(n - 1) * jnp.log(c)


def _tridiagonal_cholesky_solve(diag, off, B):
    """Lower Cholesky factor of the symmetric tridiagonal matrix (``diag`` (n,), constant
    sub-diagonal ``off``) and L^-1 B for B (n, k), in one pass: O(n k). Returns (l (n,) the
    factor's diagonal, L^-1 B)."""

    def step(carry, inp):
        l_prev, x_prev = carry
        m, b = inp
        s = off / l_prev
        l = jnp.sqrt(m - s**2)
        x = (b - s * x_prev) / l
        return (l, x), (l, x)

    l0 = jnp.sqrt(diag[0])
    x0 = B[0] / l0
    _, (ls, xs) = jax.lax.scan(step, (l0, x0), (diag[1:], B[1:]))
    return jnp.concatenate([l0[None], ls]), jnp.concatenate([x0[None], xs])


def paired_ar1_posterior(Z, y, v, uf, ul, rho, prior_sd, weight=None) -> LinearPosterior:
    """``latent_posterior`` for the AR(1) latent of the paired readings, in O(n k).

    Rows 0..n-1 and n..2n-1 are the two readings of n rows (force, piston); latent z_i (a
    stationary AR(1) series, unit variance, lag-one correlation rho) enters row i with weight
    uf_i and row n + i with ul_i: U = [diag(uf); diag(ul)]. Then M = R^-1 + diag(uf^2 D_f +
    ul^2 D_l) is tridiagonal, and U^T D Z = uf D_f Z_f + ul D_l Z_l row by row, so the Woodbury
    terms need one tridiagonal factorisation (a scan) instead of dense products. The same result
    as ``latent_posterior(Z, y, v, U, ar1_precision(rho, n))`` (tests/models/test_cubic_pressure.py).
    """
    n = uf.shape[0]
    w = jnp.ones_like(y) if weight is None else weight
    D = w / v
    c = 1.0 - rho**2
    q_diag = jnp.full(n, 1.0 + rho**2).at[0].set(1.0).at[-1].set(1.0) / c
    m_diag = q_diag + uf**2 * D[:n] + ul**2 * D[n:]
    G = (uf * D[:n])[:, None] * Z[:n] + (ul * D[n:])[:, None] * Z[n:]  # (n, k)
    g = uf * D[:n] * y[:n] + ul * D[n:] * y[n:]
    l, AB = _tridiagonal_cholesky_solve(m_diag, -rho / c, jnp.concatenate([G, g[:, None]], 1))
    A, a = AB[:, :-1], AB[:, -1]
    gram = Z.T @ (D[:, None] * Z) - A.T @ A
    rhs = Z.T @ (D * y) - A.T @ a
    yy = jnp.sum(D * y**2) - a @ a
    log_det = jnp.sum(w * jnp.log(v)) + 2.0 * jnp.sum(jnp.log(l)) + (n - 1) * jnp.log(c)
    post = posterior_from_moments(gram, rhs, yy, jnp.sum(w), log_det, prior_sd)
    # y^T Sigma^-1 y - m^T A m is a difference of numbers of the order of (reading / noise)^2,
    # 10^10 and more for a piston coordinate of 0.3 m read to 0.01 mm: its rounding error can
    # exceed the result. The same quantity in residual form, (y - Z m)^T Sigma^-1 (y - Z m) +
    # m^T T^-1 m, is of the order of the number of readings and keeps its precision.
    r = y - Z @ post.mean
    gr = uf * D[:n] * r[:n] + ul * D[n:] * r[n:]
    _, ar = _tridiagonal_cholesky_solve(m_diag, -rho / c, gr[:, None])
    quad = jnp.sum(D * r**2) - jnp.sum(ar**2) + jnp.sum((post.mean / prior_sd) ** 2)
    log_marginal = -0.5 * (
        quad
        + log_det
        + jnp.sum(jnp.log(prior_sd**2))
        + 2.0 * jnp.sum(jnp.log(jnp.diag(post.chol)))
        + jnp.sum(w) * LOG_2PI
    )
    return post._replace(log_marginal=jnp.where(quad >= 0.0, log_marginal, -jnp.inf))


def common_offset(dp_hat_pa, p_pa: float, *, ordered: bool = True):
    """Prior mean and sd (Pa) of the common offset delta in dp_hat = dp + delta.

    delta ~ N(0, (p_u SENSOR_GAIN_SD)^2) (the sensor's gain error); dp a stationary AR(1) series
    with the sample variance and lag-one correlation of dp_hat (iid when the order is unknown).
    Returns the Gaussian posterior of delta given dp_hat, (mean, sd)."""
    dp_hat = np.asarray(dp_hat_pa, float)
    n = dp_hat.size
    var = max(float(np.var(dp_hat, ddof=1)) if n > 1 else 0.0, SENSOR_RESOLUTION_PA**2)
    rho = 0.0
    if ordered and n > 2:
        c = dp_hat - dp_hat.mean()
        den = float(np.sum(c * c))
        rho = float(np.clip(np.sum(c[1:] * c[:-1]) / den, -0.9, 0.95)) if den > 0 else 0.0
    Q = np.asarray(ar1_precision(rho, n)[0]) / var
    one = np.ones(n)
    gain_var = max((p_pa * SENSOR_GAIN_SD) ** 2, SENSOR_RESOLUTION_PA**2)
    post_var = 1.0 / (1.0 / gain_var + one @ Q @ one)
    return post_var * float(one @ Q @ dp_hat), float(np.sqrt(post_var))
