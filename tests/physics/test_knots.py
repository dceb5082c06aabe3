"""Splines through fixed knots as linear operators (uq._physics.knots) against scipy's
CubicSpline of the same values: every axis, uneven knots, and the caching of the operator."""

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from uq._physics import knots

RNG = np.random.default_rng(7)
#: uneven knots, as a design grid's (the design height on it, a short last step)
X = np.sort(np.concatenate([np.linspace(0.065, 0.155, 19), [0.1123]]))


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_coefficients_are_scipys(axis):
    shape = [5, 6, 7]
    shape[axis] = X.size
    y = RNG.standard_normal(shape) * 1e3
    want = CubicSpline(X, y, axis=axis).c
    got = knots.coefficients(X, y, axis=axis)
    assert got.shape == want.shape
    np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-9 * np.abs(want).max())


@pytest.mark.parametrize("axis", [0, 1, 2])
def test_derivative_and_integral_are_scipys(axis):
    shape = [4, 3, 5]
    shape[axis] = X.size
    y = RNG.standard_normal(shape)
    s = CubicSpline(X, y, axis=axis)
    np.testing.assert_allclose(
        knots.derivative_at_knots(X, y, axis=axis), s.derivative()(X), rtol=1e-9, atol=1e-9
    )
    anti = s.antiderivative()
    start, to = 0.1, np.array([0.07, 0.1, 0.15])
    want = anti(to) - np.expand_dims(anti(start), axis)
    got = knots.integral_from(X, y, axis=axis, start=start, to=to)
    assert got.shape == want.shape
    np.testing.assert_allclose(got, want, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(
        knots.integral_from(X, y, axis=axis, start=start),
        anti(X) - np.expand_dims(anti(start), axis),
        rtol=1e-9,
        atol=1e-12,
    )


def test_exact_for_a_cubic():
    """Not-a-knot through a cubic is the cubic: its derivative and integral exactly."""
    y = 2.0 - 3.0 * X + 5.0 * X**2 + 7.0 * X**3
    np.testing.assert_allclose(
        knots.derivative_at_knots(X, y, axis=0), -3.0 + 10.0 * X + 21.0 * X**2, rtol=1e-10
    )
    F = lambda x: 2.0 * x - 1.5 * x**2 + 5.0 / 3.0 * x**3 + 1.75 * x**4  # noqa: E731
    np.testing.assert_allclose(
        knots.integral_from(X, y, axis=0, start=X[3]), F(X) - F(X[3]), rtol=1e-10, atol=1e-15
    )


def test_the_operator_is_made_once_per_knots():
    knots._basis.cache_clear()
    y = RNG.standard_normal((3, X.size))
    knots.derivative_at_knots(X, y, axis=1)
    knots.coefficients(list(X), y, axis=1)
    info = knots._basis.cache_info()
    assert (info.misses, info.hits) == (1, 1)
