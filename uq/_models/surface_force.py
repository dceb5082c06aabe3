"""The surface model of a campaign without volume readings: the force surface alone.

A force-only campaign (no ``piston_*`` column) and a catalogue table (one pass, a ``volume_*``
column on at most one test) are fitted by the force half of the pressure-coupled surface
(uq/_models/surface.py):

    force_ij = p_i F_p(u_ij, p_i) + E(u_ij)

with the same bases, scales and priors; there is no piston reference, no volume excess D and no
piston noise. Each force reading is normal with variance

    s0^2 + (r Phat)^2 + (k_p dp_i F_p_hat)^2

(the stand's error budget, paper section 3.2: the floor, the load cell and a pressure-holding
error dp moving the force by dp F_p); without the piston the pressure error shows only on the
force, so it is one more variance term instead of a correlation. The sampled noise parameters
are the first three of the surface's (log s0 [N], log r, log k_p) with the same priors. With
measured pressures the force is corrected by -dp_hat F_p_hat as in the pair likelihood
(uq._models.pair.readings) and dp_i shrinks to the sensor's resolution.

Given the noise the coefficients are Gaussian (uq._inference.linear): the model is a
:class:`uq._inference.collapsed.CollapsedModel` (``MODEL``) fitted by the one driver.

Why the volume column of a catalogue is left out: it is tabulated at one pressure, so it says
nothing of how the volume depends on pressure, which is what the surface's volume block D(x, p_u)
would model between pressures; the height dependence at that one pressure is what the per-test
fits and ``uq diagnose`` read from it. Outputs say so in one line (``uq._models.surface.
volume_omitted_reason``).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from uq._data.stand_description import StandDescription
from uq._inference.collapsed import CollapsedModel, hold_out_by_weight
from uq._inference.float64 import jax, jnp
from uq._inference.linear import draw_exact, gaussian_loglik, linear_posterior, loo_given_noise
from uq._models.pair import (
    NATURAL_NAMES,
    NOISE_NAMES,
    NOISE_PRIOR_SD,
    holding_sd_Pa,
    noise_prior_mean,
)
from uq._physics.quantities import force_noise_var

#: the sampled noise parameters: the surface's floor, load cell and pressure holding
THETA_NAMES = NOISE_NAMES[:3]
NATURAL = NATURAL_NAMES[:3]
PRIOR_SD = NOISE_PRIOR_SD[:3]


class ForceData(NamedTuple):
    """A campaign's force readings for the force surface (n readings, k coefficients)."""

    X: jnp.ndarray  # (n, k) force design (standardised coefficients)
    F: jnp.ndarray  # (n,) force, N
    phat: jnp.ndarray  # (n,) reference force of the load-cell term, N
    feff_hat: jnp.ndarray  # (n,) the lever of a pressure error on the force, dP/dp_u, m^2
    dp_pa: jnp.ndarray  # (n,) the pressure-holding sd, Pa (the sensor's resolution when measured)
    dp_meas: jnp.ndarray  # (n,) measured pressure deviation, Pa (zeros without measured pressures)
    prior_mean: jnp.ndarray  # (3,) prior centres of the noise logs
    weight: jnp.ndarray  # (n,) 1 = the reading informs the fit, 0 = held out


def force_data(X, F, phat, lever, p_bar, stand: StandDescription, dp_meas=None) -> ForceData:
    """The arrays of :class:`ForceData` (as ``uq._models.pair.pair_data`` for the force alone)."""
    hold_pa = holding_sd_Pa(p_bar, stand, measured=dp_meas is not None, shape=np.shape(F))
    return ForceData(
        jnp.asarray(X),
        jnp.asarray(F),
        jnp.asarray(phat),
        jnp.asarray(lever),
        jnp.asarray(hold_pa),
        jnp.asarray(np.zeros(np.shape(F)) if dp_meas is None else np.asarray(dp_meas, float)),
        jnp.asarray(noise_prior_mean(stand)[:3]),
        jnp.ones(np.size(F)),
    )


def sigma_y(theta, d: ForceData):
    """(sd (n,), the readings the mean is fitted to (n,)) of the force surface's noise ``theta[:3]``."""
    s0, rel, kp = (jnp.exp(theta[i]) for i in range(3))
    var = force_noise_var(s0, rel, d.phat) + (kp * d.dp_pa * d.feff_hat) ** 2
    return jnp.sqrt(var), d.F - d.feff_hat * d.dp_meas


def _posterior(theta, d: ForceData):
    sigma, y = sigma_y(theta, d)
    return linear_posterior(d.X, y, sigma, jnp.ones(d.X.shape[1]), d.weight)


def log_prob(theta, d: ForceData):
    """Log posterior of the three noise logs, the coefficients integrated out; theta (3,)."""
    z = (theta - d.prior_mean) / PRIOR_SD
    return -0.5 * jnp.sum(z**2) + _posterior(theta, d).log_marginal


def draw_linear(theta, key, d: ForceData):
    return draw_exact(_posterior(theta, d), key)


def pointwise(theta, beta, d: ForceData):
    sigma, y = sigma_y(theta, d)
    return {"force": gaussian_loglik(y, d.X @ beta, sigma)}


def pointwise_loo(theta, d: ForceData):
    """log p(force_i | noise, the other readings), coefficients integrated out exactly, (n,)."""
    sigma, y = sigma_y(theta, d)
    return loo_given_noise(d.X, y, sigma, jnp.ones(d.X.shape[1]))


def predict(theta, beta, key, d: ForceData):
    sigma, y = sigma_y(theta, d)
    return {"force_N": d.X @ beta + (d.F - y) + sigma * jax.random.normal(key, d.F.shape)}


def observed(d: ForceData) -> dict:
    return {"force_N": np.asarray(d.F)}


def start(d) -> np.ndarray:
    """The prior centres of the noise logs (this model's and the surface's)."""
    return np.asarray(d.prior_mean)


def report(theta, beta, d) -> dict:
    """The noise parameters in their natural units (this model's three, the surface's five)."""
    noise = np.exp(np.asarray(theta))
    return {n: noise[:, i] for i, n in enumerate(NATURAL_NAMES[: noise.shape[1]])}


MODEL = CollapsedModel.of(
    globals(), "pressure-coupled force surface", THETA_NAMES, hold_out=hold_out_by_weight
)
