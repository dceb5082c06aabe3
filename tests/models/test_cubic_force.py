"""The force-only per-pressure cubic (``FORCE_ONLY``): the force block of ``MODEL`` on its own.

Given the noise, ``MODEL``'s force and piston blocks are independent and sigma_L has its own
prior, so p(force coefficients, sigma0, r | forces) is the same distribution under both models.
Checked exactly (the collapsed densities differ by the piston block's term alone, the force
coefficients' conditional posteriors are equal) and by sampling (the posteriors agree within
Monte Carlo error).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from uq._data.recordings import PressureTest
from uq._data.stand_description import PAPER_STAND
from uq._inference.float64 import jnp
from uq._inference.linear import posterior_cov
from uq._inference.sampler import Settings
from uq._models.cubic import (
    MODEL,
    NOISE_PRIOR_SD,
    conditional_posteriors,
    piston_coordinate,
    prepare,
)
from uq._models.cubic_fit import fit_tests
from uq._models.cubic_force import FORCE_ONLY, _force_post, force_data
from uq._stand.simulator import Layout, recordings_from_tests, simulate

X0 = 0.112
S = 54.82e-4
FAST = Settings(n_walkers=16, min_steps=200, chunk=100, max_steps=2000)


def _test(pressure=5.0, seed=3) -> PressureTest:
    tests = simulate("n50", seed=seed, layout=Layout(pressures_bar=(pressure,)))
    return recordings_from_tests(tests).tests[0]


def test_force_only_density_is_the_force_block_of_the_full_model():
    test = _test()
    full, *_ = prepare(test, X0, "budget", PAPER_STAND)
    force, *_ = force_data(dataclasses.replace(test, piston_m=None), X0, "budget", PAPER_STAND)
    rng = np.random.default_rng(0)
    for theta in np.array([7.0, 0.3, -8.0]) + rng.normal(0, 0.7, (5, 3)):
        th = jnp.asarray(theta)
        pf, pl = conditional_posteriors(th, full)
        # the full density less the piston block: its marginal and sigma_L's prior term
        piston_term = (
            pl.log_marginal - 0.5 * ((theta[2] - full.prior_mean[2]) / NOISE_PRIOR_SD[2]) ** 2
        )
        expected = float(MODEL.log_prob(th, full) - piston_term)
        assert float(FORCE_ONLY.log_prob(th[:2], force)) == pytest.approx(expected, rel=1e-12)
        post = _force_post(th[:2], force)[0]
        assert np.allclose(post.mean, pf.mean, rtol=1e-10)
        assert np.allclose(posterior_cov(post), posterior_cov(pf), rtol=1e-8)


@pytest.mark.slow  # the exact density test above proves the equivalence; this samples both
def test_force_only_posterior_equals_the_full_models_force_posterior():
    """Sampled: a_P..d_P, sigma0 and r of the force-only fit and of the full fit on the same
    readings agree within 5 Monte Carlo standard errors (means) and 10 % (sds)."""
    test = _test()
    full, alone = fit_tests(
        [test, dataclasses.replace(test, piston_m=None)], X0, seed=11, settings=FAST
    )
    assert full.has_piston and not alone.has_piston
    assert alone.piston is None and alone.lsq_piston is None and alone.noise.shape[-1] == 2
    var_full, var_alone = full.convergence.variables, alone.convergence.variables
    names = ("a_P", "b_P", "c_P", "d_P", "sigma0_N", "rel_force")
    for name in names:
        a, b = full.posterior.flat(name), alone.posterior.flat(name)
        mcse = np.hypot(var_full[name]["mcse_mean"], var_alone[name]["mcse_mean"])
        assert abs(a.mean() - b.mean()) < 5 * mcse, name
        assert b.std() == pytest.approx(a.std(), rel=0.1), name


def test_volume_column_fits_as_a_piston_coordinate():
    """A test with the element's volume instead of piston coordinates fits L = -V / S: its
    volume-derived slope -S b_L equals the one from the piston readings it was made from."""
    test = _test()
    volume = -S * test.piston_m  # V = -S L up to a constant (eq. 10)
    as_volume = dataclasses.replace(test, piston_m=None, volume_m3=volume + 4.2e-3)
    L, source = piston_coordinate(as_volume, S)
    assert source == "volume" and np.allclose(np.diff(L), np.diff(test.piston_m))
    assert piston_coordinate(dataclasses.replace(test, piston_m=None), S) == (None, None)
    (fit,) = fit_tests([as_volume], X0, seed=2, settings=FAST, piston_area_m2=S)
    assert fit.piston_source == "volume" and fit.has_piston
    entry = fit.to_json()
    assert "piston" in entry and "omitted" not in entry and "volume" in entry["piston_from"]
    b_L = entry["piston"]["b_L"]
    lsq = np.polynomial.polynomial.polyfit(test.height_m - X0, test.piston_m, 3)[1]
    assert b_L["q05"] < lsq < b_L["q95"]


def test_force_only_json_omits_the_piston_with_its_reason():
    test = dataclasses.replace(_test(), piston_m=None, step=None, compression=None)
    short = Settings(n_walkers=8, min_steps=12, chunk=4, max_steps=16)
    (fit,) = fit_tests([test], X0, seed=1, settings=short)
    entry = fit.to_json()
    assert "piston" not in entry and "piston" not in entry["least_squares"]
    assert "piston" not in entry["covariance"] and set(entry["noise"]) == {"sigma0_N", "rel_force"}
    assert "force-only" in entry["omitted"]["piston"]
    # no recording order: the order check is skipped with its reason, not passed
    assert set(entry["residual_order"]) == {"skipped", "alpha"} and fit.model_warnings() == []
    with pytest.raises(ValueError, match="force-only"):
        fit.mean_residuals("piston")
