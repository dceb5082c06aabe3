"""Not-a-knot cubic splines through fixed knots, as linear operators on the values there.

A cubic spline's coefficients, and its derivative and antiderivative at given points, are linear
in its values at the knots. Posterior draws on a height x pressure grid are thousands of curves
through one set of knots: the operator is made once (scipy's ``CubicSpline`` of the identity,
kept for the knots) and applied to every curve as one matrix product, instead of a spline solved
per array. The same numbers as ``CubicSpline`` of the values to rounding (tested); on
``uq design``'s grid of 1000 draws x 47 heights x 41 pressures the derivative costs about 5 ms
instead of 90 (docs/speed.md).
"""

from __future__ import annotations

import functools

import numpy as np
from scipy.interpolate import CubicSpline


@functools.lru_cache(maxsize=16)
def _basis(knots: tuple[float, ...]) -> CubicSpline:
    """The splines of the unit vectors: column j is the spline through 1 at knot j, 0 elsewhere."""
    return CubicSpline(np.asarray(knots), np.eye(len(knots)))


def _spline(knots) -> CubicSpline:
    """:func:`_basis` of ``knots`` (any sequence of numbers), made once per set of knots."""
    return _basis(tuple(np.asarray(knots, float)))


def _along(op: np.ndarray, values: np.ndarray, axis: int) -> np.ndarray:
    """``op`` (M, K) applied to ``values``' ``axis`` (of length K): that axis becomes length M."""
    out = np.tensordot(op, np.asarray(values, float), axes=([1], [axis]))
    return np.moveaxis(out, 0, axis)


def coefficients(knots, values, axis: int) -> np.ndarray:
    """``CubicSpline(knots, values, axis=axis).c``: (4, K - 1, *values' other axes)."""
    c = _spline(knots)
    return np.tensordot(c.c, np.asarray(values, float), axes=([2], [axis]))


def derivative_at_knots(knots, values, axis: int) -> np.ndarray:
    """The spline's first derivative at its own knots, the shape of ``values``."""
    s = _spline(knots)
    return _along(s.derivative()(s.x), values, axis)


def integral_from(knots, values, axis: int, start: float, to=None) -> np.ndarray:
    """The spline's integral from ``start`` to each point of ``to`` (default: the knots), along
    ``axis``, whose length becomes len(to)."""
    s = _spline(knots)
    anti = s.antiderivative()
    to = s.x if to is None else np.asarray(to, float)
    return _along(anti(to) - anti(np.array([start])), values, axis)
