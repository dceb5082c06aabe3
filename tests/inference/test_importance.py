"""Importance sampling of theta (uq/_inference/importance.py): right where the proposal can follow
the posterior, refused (Pareto k-hat above 0.7) where it cannot, and the one driver's fallback to
emcee when it is refused."""

from __future__ import annotations

import numpy as np

import uq
from uq._inference import importance
from uq._inference.collapsed import fit_collapsed

COV = np.array([[1.0, 0.6], [0.6, 2.0]])


def _gaussian(x):
    return -0.5 * np.einsum("ni,ij,nj->n", x, np.linalg.inv(COV), x)


def _funnel(x):
    """Neal's funnel: v ~ N(0, 3^2), each z_i | v ~ N(0, e^v); no t (transformed or not) follows
    the neck, whatever its adaptation."""
    v, z = x[:, 0], x[:, 1:]
    return -0.5 * v**2 / 9.0 - 0.5 * np.sum(z**2, axis=1) * np.exp(-v) - 0.5 * z.shape[1] * v


def test_a_gaussian_is_sampled_right_and_the_same_for_a_seed():
    """From a Laplace covariance 30 % too wide: k-hat far below 0.7, the mean within 0.05 and the
    covariance within 0.1 of the truth (4000 resampled draws: about four standard errors), every
    ESS above the rules' 400, and the same draws for the same seed."""
    a = importance.sample(_gaussian, np.zeros(2), 1.3 * COV, ("x", "y"), seed=1, n_keep=4000)
    b = importance.sample(_gaussian, np.zeros(2), 1.3 * COV, ("x", "y"), seed=1, n_keep=4000)
    assert a.passed and a.pareto_k < 0.5
    assert min(a.ess_bulk.values()) > 400 and min(a.ess_tail.values()) > 400
    np.testing.assert_allclose(a.samples.mean(axis=0), 0.0, atol=0.05)
    np.testing.assert_allclose(np.cov(a.samples.T), COV, atol=0.1)
    np.testing.assert_array_equal(a.samples, b.samples)


def _floored_scale(x):
    """log s of a scale whose 20 readings' variance is s^2 + 1 (sum of squares 80), log s ~ N(0, 1)
    a priori, and a plain normal beside it: as s goes to 0 the likelihood goes flat and the left
    tail is the prior's, the shape of the discrepancy surface's force floor."""
    v = np.exp(2 * x[:, 0]) + 1.0
    return -0.5 * x[:, 0] ** 2 - 10 * np.log(v) - 40.0 / v - 0.5 * x[:, 1] ** 2


def test_a_prior_dominated_tail_is_followed_by_the_pooled_stages():
    """The floored scale from its Laplace approximation (sd 0.21 at the mode, where the left tail
    reaches 2.5 sd by the 1 % quantile): kept, its 1, 5, 50 and 95 % quantiles within 0.03 of
    quadrature's (about three Monte Carlo sd), and every adapted stage's draws in the posterior."""
    g = np.linspace(-8.0, 4.0, 200001)
    dens = np.exp(_floored_scale(np.stack([g, np.zeros_like(g)], axis=1)) - 40.0)
    cdf = np.cumsum(dens) / dens.sum()
    levels = [0.01, 0.05, 0.5, 0.95]
    mode, h = g[np.argmax(dens)], 1e-4
    f = [_floored_scale(np.array([[mode + e, 0.0]]))[0] for e in (-h, 0.0, h)]
    cov = np.diag([h**2 / (2 * f[1] - f[0] - f[2]), 1.0])
    r = importance.sample(
        _floored_scale, np.array([mode, 0.0]), cov, ("s", "z"), seed=1, n_keep=4000
    )
    assert r.passed and r.pareto_k < importance.K_MAX
    assert r.n_draws == importance.REFITS * importance.STAGE_DRAWS
    assert len(r.stages_k) == importance.REFITS
    np.testing.assert_allclose(
        np.quantile(r.samples[:, 0], levels), np.interp(levels, cdf, g), atol=0.03
    )


def test_a_funnel_is_refused_with_its_pareto_k():
    """Neal's funnel in six dimensions: the weights' tail is heavy (k-hat 0.87 for this seed), the
    draws are refused and the reason names the Pareto k-hat."""
    r = importance.sample(_funnel, np.zeros(6), np.eye(6), tuple("vabcde"), seed=1, n_keep=1000)
    assert not r.passed
    assert r.pareto_k > importance.K_MAX
    assert r.problem.startswith("Pareto k-hat")
    assert r.to_json()["passed"] is False


def _cubic_problem():
    from uq._models import cubic

    layout = uq.Layout(pressures_bar=(5.0,), step_m=0.01)
    test = uq.simulate("n50", seed=8, layout=layout).tests[0]
    return cubic.MODEL, cubic.prepare(test, 0.112, "budget", uq.PAPER_STAND)[0]


def test_the_driver_keeps_passing_draws_and_says_so():
    """A per-pressure cubic's noise scales (near Gaussian): the driver keeps the importance draws,
    its verdict says how they were made (method, Pareto k-hat, ESS), and their means agree with
    emcee's within 0.2 posterior sd."""
    model, data = _cubic_problem()
    quick = uq.Settings(max_steps=2000)
    a = fit_collapsed(model, data, seed=3, settings=quick, importance=True)
    b = fit_collapsed(model, data, seed=3, settings=quick)
    conv = a.convergence
    assert a.method == "importance" and conv.method == "importance" and conv.converged
    assert conv.importance["passed"] and conv.importance["pareto_k"] <= importance.K_MAX
    assert conv.to_json()["method"] == "importance"
    assert "importance sampling, Pareto k-hat" in conv.sampler_words()
    # every reported variable has its R-hat and ESS (CONTRACT.md), from the kept draws split into
    # runs, no ESS above the smallest importance ESS of the sampled parameters
    r_hat_max, ess_min = conv.worst()
    assert 1.0 <= r_hat_max < 1.01 and 400 <= ess_min
    cap = min(conv.importance["ess_bulk"].values())
    assert set(conv.variables) == set(a.reported) and conv.n_chains == 4
    for v in conv.variables.values():
        assert np.all(np.asarray(v["ess_bulk"]) <= cap) and np.all(np.isfinite(v["r_hat"]))
    assert b.convergence.sampler_words() is None and "method" not in b.convergence.to_json()
    ta, tb = (p.theta.reshape(-1, p.theta.shape[-1]) for p in (a, b))
    sd = tb.std(axis=0)
    assert np.all(np.abs(ta.mean(axis=0) - tb.mean(axis=0)) < 0.2 * sd)


def test_the_driver_falls_back_to_emcee_when_the_draws_are_refused(monkeypatch):
    """With every Pareto k-hat too high (the limit set below any), the driver samples with emcee:
    the very draws of a fit that never tried, and a verdict that says it was refused and why."""
    model, data = _cubic_problem()
    quick = uq.Settings(max_steps=2000)
    monkeypatch.setattr(importance, "K_MAX", -np.inf)
    a = fit_collapsed(model, data, seed=3, settings=quick, importance=True)
    b = fit_collapsed(model, data, seed=3, settings=quick)
    np.testing.assert_array_equal(a.theta, b.theta)
    conv = a.convergence
    assert a.method == "emcee" and conv.method == "emcee" and conv.n_steps > 0
    assert conv.importance["passed"] is False
    assert conv.importance["reason"].startswith("Pareto k-hat")
    assert "refused" in conv.sampler_words()
    assert conv.to_json()["importance"]["passed"] is False
