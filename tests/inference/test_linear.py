"""The collapsed linear-Gaussian kernel's Gram plan: the compressed weighted Gram matrix equals the
explicit one, merges only proportional column products, and gives the same posterior."""

from __future__ import annotations

import numpy as np
import pytest

from uq._inference.float64 import jnp
from uq._inference.linear import (
    gram_plan,
    linear_posterior,
    posterior_from_moments,
    reading_forms,
    weighted_gram,
)


def _polynomial_designs(rng, n=120, n_tests=4):
    """Two designs like the surface model's: monomials t^k q^l (times p), their integrals, a zero
    column and one indicator column per test (constant q and p within a test)."""
    test = np.repeat(np.arange(n_tests), n // n_tests)
    q = np.linspace(-1, 1, n_tests)[test]
    p = 1e5 * (1 + 4 * (q + 1))
    t = np.tile(np.linspace(-0.9, 0.8, n // n_tests), n_tests) + 1e-3 * rng.standard_normal(n)
    k = 4 * 3 + 2 + n_tests + 1
    A, B = np.zeros((n, k)), np.zeros((n, k))
    cols = [(a, b) for a in range(4) for b in range(3)]
    for i, (a, b) in enumerate(cols):
        A[:, i] = p * t**a * q**b
        B[:, i] = -0.3 * t ** (a + 1) / (a + 1) * q**b
    A[:, 12:14] = np.stack([np.ones(n), t], 1) * 1e4
    B[np.arange(n), 14 + test] = 1.0  # column 14 + n_tests stays zero
    return A, B


def test_gram_plan_equals_the_explicit_gram():
    rng = np.random.default_rng(0)
    A, B = _polynomial_designs(rng)
    plan = gram_plan([[(A, A)], [(B, B)], [(B, A), (A, B)]])
    k = A.shape[1]
    n_moments = sum(Q.shape[1] for Q in plan.products)
    assert n_moments < 0.3 * 3 * k * k  # repeated products are shared
    for _ in range(3):
        w = [rng.normal(size=A.shape[0]) for _ in range(3)]
        explicit = (
            A.T @ (w[0][:, None] * A)
            + B.T @ (w[1][:, None] * B)
            + B.T @ (w[2][:, None] * A)
            + A.T @ (w[2][:, None] * B)
        )
        got = np.asarray(weighted_gram(plan, [jnp.asarray(v) for v in w]))
        scale = np.sqrt(
            np.outer(
                np.diag(np.abs(A.T @ A) + np.abs(B.T @ B)),
                np.diag(np.abs(A.T @ A) + np.abs(B.T @ B)),
            )
        )
        assert np.all(np.abs(got - explicit) <= 1e-12 * scale + 1e-300)


def test_a_symmetric_plan_gathers_the_lower_triangle_and_is_exactly_symmetric():
    """The pair likelihood's plan (``symmetric=True``): half the entries, the explicit Gram to
    rounding, exactly symmetric (the Cholesky factor reads one triangle); a group whose sum is
    not symmetric is refused."""
    rng = np.random.default_rng(3)
    A, B = _polynomial_designs(rng)
    groups = [[(A, A)], [(B, B)], [(B, A), (A, B)]]
    full, half = gram_plan(groups), gram_plan(groups, symmetric=True)
    k = A.shape[1]
    assert half.index.shape[0] == k * (k + 1) // 2 and full.index.shape[0] == k * k
    w = [jnp.asarray(rng.normal(size=A.shape[0])) for _ in range(3)]
    got, want = (np.asarray(weighted_gram(p, w)) for p in (half, full))
    assert np.array_equal(got, got.T)
    assert np.allclose(got, want, rtol=1e-12, atol=1e-12 * np.max(np.abs(want)))
    with pytest.raises(ValueError, match="not symmetric"):
        gram_plan([[(B, A)]], symmetric=True)


def test_reading_forms_are_each_readings_quadratic_forms():
    """``reading_forms``: per group and reading, sum over its pairs of A_i' M B_i, for a full and
    a symmetric plan, against the explicit products."""
    rng = np.random.default_rng(4)
    A, B = _polynomial_designs(rng)
    groups = [[(A, A)], [(B, B)], [(B, A), (A, B)]]
    R = rng.normal(size=(A.shape[1], A.shape[1]))
    M = R @ R.T
    want = [
        np.einsum("ij,jk,ik->i", A, M, A),
        np.einsum("ij,jk,ik->i", B, M, B),
        np.einsum("ij,jk,ik->i", B, M, A) + np.einsum("ij,jk,ik->i", A, M, B),
    ]
    for plan in (gram_plan(groups), gram_plan(groups, symmetric=True)):
        got = reading_forms(plan, jnp.asarray(M))
        for g, w in zip(got, want, strict=True):
            scale = np.einsum(
                "ij,jk,ik->i", np.abs(A) + np.abs(B), np.abs(M), np.abs(A) + np.abs(B)
            )
            assert np.all(np.abs(np.asarray(g) - w) <= 1e-11 * scale + 1e-300)


def test_gram_plan_merges_only_proportional_products():
    """Random columns have no proportional products: every distinct pair keeps its own moment."""
    rng = np.random.default_rng(1)
    A = rng.normal(size=(50, 6))
    A[:, 5] = 2.5 * A[:, 4]  # except these: (4, j) and (5, j) are proportional
    plan = gram_plan([[(A, A)]])
    assert plan.products[0].shape[1] == 5 * 6 // 2
    w = rng.normal(size=50)
    assert np.allclose(
        np.asarray(weighted_gram(plan, [jnp.asarray(w)])),
        A.T @ (w[:, None] * A),
        rtol=1e-12,
        atol=1e-12,
    )


def test_posterior_from_moments_is_linear_posterior():
    rng = np.random.default_rng(2)
    X = rng.normal(size=(40, 5))
    sigma = rng.uniform(0.5, 2.0, 40)
    y = X @ rng.normal(size=5) + sigma * rng.normal(size=40)
    prior = np.full(5, 3.0)
    a = linear_posterior(X, y, sigma, prior)
    w = sigma**-2
    b = posterior_from_moments(
        X.T @ (w[:, None] * X), X.T @ (w * y), np.sum(w * y**2), 40, np.sum(np.log(sigma**2)), prior
    )
    for u, v in zip(a, b, strict=True):
        assert np.allclose(np.asarray(u), np.asarray(v), rtol=1e-12, atol=0)
    assert float(b.log_marginal) == pytest.approx(float(a.log_marginal), rel=1e-12)


def test_seed_row_keys_are_the_split_keys():
    """One kept program for a fit's draw keys: the keys of splitting PRNGKey(seed), to the bit."""
    import jax

    from uq._inference.linear import row_keys, seed_row_keys

    for seed in (0, 20201, 4294967295, 2**40 + 7, -5):
        for which in (0, 1):
            for n in (1, 37, 5000):
                expected = row_keys(jax.random.split(jax.random.PRNGKey(seed))[which], n)
                np.testing.assert_array_equal(seed_row_keys(seed, which, n), expected)
