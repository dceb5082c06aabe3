"""Physics constants and formulas shared by the models, in one home.

* ``BAR_PA``: 1 bar in Pa (the recordings hold overpressure in bar).
* ``BASIS_SCALE_M``: the length scale h = 0.05 m of every model's polynomial basis,
  t = (x - x0) / h, so that t is within about +-1 over the stand's 65..155 mm. Coefficients
  are reported in the paper's basis (against u = x - x0 in m) by ``to_paper_basis``.
* ``force_noise_var``: the fitted force noise, a floor sigma0 (pressure holding, displacement,
  relaxation) plus the load cell's relative error r on the force level:
  sigma_F^2 = sigma0^2 + (r * F_ref)^2 (the stand's error budget). Every model, the report's
  predictive bands and the calibration suite's prior simulations use this one formula.

Pure functions of arrays; they work on numpy and JAX arrays alike.
"""

from __future__ import annotations

import numpy as np

BAR_PA = 1.0e5
BASIS_SCALE_M = 0.05


def force_noise_var(sigma0_N, rel_force, ref_force_N):
    """Variance (N^2) of a force reading: sigma0^2 + (r * F_ref)^2 (any broadcasting shapes)."""
    return sigma0_N**2 + (rel_force * ref_force_N) ** 2


def to_paper_basis(alpha, scale: float = BASIS_SCALE_M):
    """Scaled-basis coefficients (..., k) of t = u/scale -> paper basis against u in m."""
    alpha = np.asarray(alpha)
    return alpha / scale ** np.arange(alpha.shape[-1])
