"""The paper's cubic (eqs. 8, 9), evaluated in one place.

P(x) = a_P + b_P u + c_P u^2 + d_P u^3 and L(x) = a_L + ... against u = x - x0 in metres, SI
coefficients (Table 1 converted). Every module that evaluates a cubic in the paper's basis calls
these: coefficient arrays ``coef`` (..., 4) broadcast against ``u`` the NumPy way, so
``cubic(coef, u)`` with coef (4,) and u (n,) gives (n,), and ``cubic(coef[..., None, :], u)``
with coef (S, 4) gives (S, n). They work on NumPy and JAX arrays alike.
"""

from __future__ import annotations


def cubic(coef, u):
    """a + b u + c u^2 + d u^3 (Horner), coef (..., 4) broadcast against u."""
    return coef[..., 0] + u * (coef[..., 1] + u * (coef[..., 2] + u * coef[..., 3]))


def cubic_slope(coef, u):
    """d/du of the cubic: b + 2 c u + 3 d u^2."""
    return coef[..., 1] + u * (2.0 * coef[..., 2] + 3.0 * u * coef[..., 3])
