"""uq._inference.summary: the bands' quantiles are numpy's, to the bit."""

from __future__ import annotations

import numpy as np
import pytest

from uq._inference.summary import band, quantiles


@pytest.mark.parametrize("n", [1, 2, 3, 20, 21, 101, 2000])
@pytest.mark.parametrize("shape", [(), (7,), (3, 4)])
def test_quantiles_are_numpys(n, shape):
    """The same numbers and shape as np.quantile (linear method) along any axis, for levels whose
    ranks fall between two draws or on one (n = 21: 20 * 0.05 = 1), with ties, infinities and
    columns holding a NaN (NaN there, as numpy gives)."""
    rng = np.random.default_rng(n * 10 + len(shape))
    for trial in range(5):
        d = rng.standard_normal((n, *shape)) * 10.0 ** rng.uniform(-6, 6)
        if trial == 1:
            d = np.round(d * 3) + 1.0  # ties (no zeros: -0.0 and 0.0 tie, either may come out)
        if trial >= 2 and d.size > 1:
            d.flat[rng.integers(d.size, size=3)] = [np.nan, np.inf, -np.inf][trial - 2]
        for level in (0.9, 0.5, 0.68, 0.99, 1.0):
            qs = ((1 - level) / 2, (1 + level) / 2)
            for axis in range(d.ndim):
                with np.errstate(invalid="ignore"):  # inf - inf, numpy's own interpolation too
                    want = np.quantile(d, qs, axis=axis)
                    got = quantiles(d, qs, axis)
                assert got.shape == want.shape
                np.testing.assert_array_equal(got, want)


def test_quantiles_refuse_what_numpy_refuses():
    d = np.arange(10.0)
    for q in (-0.1, 1.5):
        with pytest.raises(ValueError):
            quantiles(d, (q,))
    with pytest.raises(IndexError):
        np.quantile(np.empty(0), 0.5)
    with pytest.raises(IndexError):
        quantiles(np.empty(0), (0.5,))


def test_band_is_the_mean_and_equal_tailed_quantiles():
    d = np.random.default_rng(0).standard_normal((2000, 181))
    m, lo, hi = band(d, axis=0, level=0.9)
    np.testing.assert_array_equal(m, d.mean(axis=0))
    a = (1.0 - 0.9) / 2.0  # 0.04999999999999999, as band computes it
    np.testing.assert_array_equal(np.stack([lo, hi]), np.quantile(d, [a, 1.0 - a], axis=0))
