"""PSIS-LOO vectorised over readings (uq/_inference/loo.py) is ArviZ's ``az.loo``: the same
pointwise values, Pareto k and p_loo on log-likelihoods with good and with heavy tails, with
ties, with several chains and with ArviZ's own estimate of the relative efficiency."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from uq._inference.loo import loglik_idata, psis


def _arviz(ll, reff):
    import arviz as az

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        r = az.loo(loglik_idata(ll), pointwise=True, reff=reff)
    return np.asarray(r.loo_i), np.asarray(r.pareto_k), float(r.p_loo)


def _loglik(rng, C, D, n, heavy=0.0):
    """Gaussian log-likelihoods of n readings under C x D draws of a location; ``heavy``: the
    share of readings far out (outliers: Pareto k well above 0.7)."""
    mu = rng.standard_normal((C, D, 1)) * 0.3
    y = rng.standard_normal(n)
    y[: int(heavy * n)] += 6.0
    return -0.5 * (y - mu) ** 2 - 0.9189385332046727


@pytest.mark.parametrize(
    "C, D, n, heavy, reff",
    [
        (1, 1000, 50, 0.0, 1.0),
        (4, 500, 40, 0.1, None),
        (4, 251, 30, 0.2, None),
        (2, 40, 9, 0.3, 0.8),
    ],
)
def test_psis_is_arviz_s_loo(C, D, n, heavy, reff):
    rng = np.random.default_rng(C * D + n)
    ll = _loglik(rng, C, D, n, heavy)
    want_i, want_k, want_p = _arviz(ll, reff)
    got = psis(ll, reff=reff)
    np.testing.assert_allclose(got.loo_i, want_i, rtol=1e-10, atol=1e-10)
    np.testing.assert_allclose(got.pareto_k, want_k, rtol=1e-8, atol=1e-10)
    assert got.p_loo == pytest.approx(want_p, rel=1e-9, abs=1e-9)


def test_psis_with_ties_and_short_tails_follows_arviz():
    """Readings whose tail is cut by tied values, and draws too few for a tail fit (k = inf),
    take ArviZ's own per-reading path: the same values."""
    rng = np.random.default_rng(2)
    ll = _loglik(rng, 1, 300, 12, 0.2)
    ll[0, :, 3] = np.round(ll[0, :, 3], 1)  # many ties
    for x in (ll, ll[:, :15]):
        want_i, want_k, _ = _arviz(x, 1.0)
        got = psis(x, reff=1.0)
        np.testing.assert_allclose(got.loo_i, want_i, rtol=1e-10, atol=1e-10)
        np.testing.assert_allclose(got.pareto_k, want_k, rtol=1e-8)


def test_the_one_reading_path_is_arviz_s_psislw_to_the_bit():
    """The irregular readings' path (ties, as a chain's repeated draws make them; short tails) is
    ArviZ's ``_psislw`` in numpy, without importing ArviZ: the same smoothed weights and k, exactly."""
    from arviz.stats.stats import _psislw

    from uq._inference.loo import _psislw_one

    rng = np.random.default_rng(5)
    cutoffmin = np.log(np.finfo(float).tiny)
    for S, n_tail in ((4000, 190), (300, 52), (15, 3)):
        ll = _loglik(rng, 1, S, 6, 0.3)[0].T
        ll[1] = np.repeat(ll[1, : -(-S // 3)], 3)[:S]  # a chain's repeated draws
        ll[2] = np.round(ll[2], 1)  # many ties
        for row in ll:
            lw = -row - np.max(-row)
            want = _psislw(lw.copy(), -n_tail - 1, cutoffmin, False)
            got = _psislw_one(lw, -n_tail - 1, cutoffmin)
            assert np.array_equal(got[0], want[0])
            assert got[1] == want[1]


def test_psis_is_the_same_for_any_chunks_and_threads():
    """The readings are smoothed in chunks by threads side by side: each reading on its own, so
    every chunking and thread count gives the same loo_i, Pareto k and p_loo, to the bit (with
    tied and short-tailed readings among them, which take the one-reading path)."""
    from uq._inference.loo import psis_loo

    rng = np.random.default_rng(7)
    ll = _loglik(rng, 1, 1200, 700, 0.1)[0].T.copy()
    ll[3] = np.round(ll[3], 1)  # ties: the one-reading path
    want = psis_loo(ll, 1.0, chunk=ll.shape[0], threads=1)
    for chunk, threads in ((256, 2), (100, 3), (1, 2), (333, 1)):
        got = psis_loo(ll, 1.0, chunk=chunk, threads=threads)
        assert np.array_equal(got[0], want[0]) and np.array_equal(got[1], want[1])
        assert got[2] == want[2]
