"""Linear-Gaussian coefficients under noise with a low-dimensional latent part.

For y = Z beta + U z + e with e ~ N(0, diag(v)) independent, z ~ N(0, Q^-1) a latent Gaussian
of precision Q (m x m), and beta ~ N(0, diag(tau^2)), the readings' covariance given the noise is
Sigma = diag(v) + U Q^-1 U^T. By the Woodbury identity and the matrix determinant lemma,

    Sigma^-1 = D - D U M^-1 U^T D,          M = Q + U^T D U,   D = diag(1/v),
    log det Sigma = sum log v + log det M - log det Q,

so the coefficients' Gaussian posterior (``uq._inference.linear.posterior_from_moments``) needs
only an m x m Cholesky factor, and beta stays conjugate (exact draws) whatever the latent's
correlation (``latent_posterior``, the dense reference).

The per-pressure cubic with an AR(1) pressure-holding error (z = the holding errors in recording
order; ``uq._models.cubic``, its pressure-holding section) does not use that form: D - D U M^-1
U^T D subtracts numbers of the order of (reading / sd)^2, which lose every digit where a reading's
independent sd is tiny beside the reading (a piston coordinate of 0.3 m, the latent taking all
of its scatter). It whitens instead (``paired_ar1_whiten``): the Kalman filter of the latent
series turns the readings and the design into innovations over their sds, W y and W Z with
W^T W = Sigma^-1, in one O(n) scan in which nothing cancels, and the conjugate posterior is that
of the whitened regression.

``weight`` (the readings' rows, 1 fitted, 0 held out) leaves the held-out rows out: the result is
then the density of the fitted rows alone (the latent still integrated out).
All functions are pure and jittable.
"""

from __future__ import annotations

import numpy as np

from uq._data.stand_description import PAPER_STAND, StandDescription
from uq._inference.float64 import jax, jnp
from uq._inference.linear import LOG_2PI, LinearPosterior, posterior_from_moments


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
    (for pointwise densities): W^T W with W the whitening of ``paired_ar1_whiten`` (positive
    definite by construction, whatever the scales)."""
    W, _ = paired_ar1_whiten(jnp.eye(2 * uf.shape[0]), v, uf, ul, rho)
    return W.T @ W


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


def paired_ar1_whiten(cols, v, uf, ul, rho, weight=None):
    """Whitened columns W cols (2n, m) and log det Sigma of the paired AR(1) covariance, by the
    Kalman filter of the latent series (one scalar state, the readings of row i taken one at a
    time: force i, then piston i).

    Rows 0..n-1 and n..2n-1 are the two readings of n rows (force, piston); latent z_i (a
    stationary AR(1) series, unit variance, lag-one correlation rho) enters row i with weight
    uf_i and row n + i with ul_i, and each reading has its own independent variance v. W is the
    inverse of Sigma's Cholesky factor in the filter's order: each reading's innovation (reading
    minus its prediction from the earlier readings) over its sd. Every step is a convex
    combination or a ratio of positive numbers, so nothing cancels: unlike the Woodbury form
    D - D U M^-1 U^T D, which subtracts numbers of the order of (reading / sd)^2 (10^20 for a
    piston coordinate of 0.3 m and an independent sd of 0.01 um, a corner the sampler reaches
    when the latent explains all of the piston's scatter) and there returned garbage, with
    spurious modes of high density and non-finite draws. ``weight`` (2n,): readings with weight
    0 are held out (no innovation, no determinant term: the density of the others, the latent
    still integrated out); a positive weight w gives the reading variance v / w."""
    n = uf.shape[0]
    w = jnp.ones(2 * n) if weight is None else weight
    present = w > 0
    var = jnp.where(present, v / jnp.where(present, w, 1.0), 1.0)
    c = 1.0 - rho**2

    def update(a, P, x, h, s2, on):
        S = h * h * P + s2
        innovation = x - h * a
        e = jnp.where(on, innovation / jnp.sqrt(S), 0.0)
        a = jnp.where(on, a + (P * h / S) * innovation, a)
        P = jnp.where(on, P * s2 / S, P)
        return a, P, e, jnp.where(on, jnp.log(S), 0.0)

    def step(carry, inp):
        a, P = carry
        xf, xl, vf, vl, hf, hl, of, ol = inp
        a, P, ef, ldf = update(a, P, xf, hf, vf, of)
        a, P, el, ldl = update(a, P, xl, hl, vl, ol)
        return (rho * a, rho * rho * P + c), (ef, el, ldf + ldl)

    inputs = (cols[:n], cols[n:], var[:n], var[n:], uf, ul, present[:n], present[n:])
    a0 = jnp.zeros(cols.shape[1:], dtype=cols.dtype)
    _, (ef, el, ld) = jax.lax.scan(step, (a0, jnp.ones((), dtype=cols.dtype)), inputs)
    return jnp.concatenate([ef, el], axis=0), jnp.sum(ld)


def paired_ar1_posterior(Z, y, v, uf, ul, rho, prior_sd, weight=None) -> LinearPosterior:
    """``latent_posterior`` for the AR(1) latent of the paired readings (``paired_ar1_whiten``):
    the design and readings whitened in one O(n k) pass, then the ordinary conjugate posterior
    of the whitened regression. The same result as ``latent_posterior(Z, y, v, U,
    ar1_precision(rho, n))`` where both are accurate (tests/models/test_cubic_pressure.py), and
    accurate where the Woodbury form is not."""
    w = jnp.ones_like(y) if weight is None else weight
    W, log_det = paired_ar1_whiten(jnp.concatenate([Z, y[:, None]], 1), v, uf, ul, rho, w)
    Zw, yw = W[:, :-1], W[:, -1]
    n_obs = jnp.sum(w > 0)
    post = posterior_from_moments(Zw.T @ Zw, Zw.T @ yw, yw @ yw, n_obs, log_det, prior_sd)
    # yw^T yw - m^T A m is a difference of large numbers (the readings over their sd, squared);
    # the same quantity in residual form, |yw - Zw m|^2 + |m / prior_sd|^2, keeps its precision.
    rw = yw - Zw @ post.mean
    quad = rw @ rw + jnp.sum((post.mean / prior_sd) ** 2)
    log_marginal = -0.5 * (
        quad
        + log_det
        + jnp.sum(jnp.log(prior_sd**2))
        + 2.0 * jnp.sum(jnp.log(jnp.diag(post.chol)))
        + n_obs * LOG_2PI
    )
    return post._replace(log_marginal=log_marginal)


def common_offset(
    dp_hat_pa, p_pa: float, *, ordered: bool = True, stand: StandDescription = PAPER_STAND
):
    """Prior mean and sd (Pa) of the common offset delta in dp_hat = dp + delta.

    delta ~ N(0, (p_u g)^2) with g the stand's pressure sensor's gain error
    (``stand.pressure_sensor_gain_sd``); dp a stationary AR(1) series with the sample variance and
    lag-one correlation of dp_hat (iid when the order is unknown), never below the sensor's
    resolution. Returns the Gaussian posterior of delta given dp_hat, (mean, sd)."""
    resolution = stand.pressure_sensor_resolution_pa
    dp_hat = np.asarray(dp_hat_pa, float)
    n = dp_hat.size
    var = max(float(np.var(dp_hat, ddof=1)) if n > 1 else 0.0, resolution**2)
    rho = 0.0
    if ordered and n > 2:
        c = dp_hat - dp_hat.mean()
        den = float(np.sum(c * c))
        rho = float(np.clip(np.sum(c[1:] * c[:-1]) / den, -0.9, 0.95)) if den > 0 else 0.0
    Q = np.asarray(ar1_precision(rho, n)[0]) / var
    one = np.ones(n)
    gain_var = max((p_pa * stand.pressure_sensor_gain_sd) ** 2, resolution**2)
    post_var = 1.0 / (1.0 / gain_var + one @ Q @ one)
    return post_var * float(one @ Q @ dp_hat), float(np.sqrt(post_var))
