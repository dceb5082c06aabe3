"""The preposterior that also updates theta (uq._derived.plan_theta): the closed-form reweighting
against dense Gaussian algebra on a toy model with theta on a grid, its calibration by simulation,
its reduction to uq plan's closed form when every draw of theta is the same, and the frames' noise
factors against their whitened rows.
"""

from __future__ import annotations

import numpy as np
import pytest
from plan_helpers import cubic_builder, discrepancy_builder, surface_builder
from scipy.stats import multivariate_normal

import uq
from uq._derived import plan_search as E
from uq._derived import plan_theta as PT
from uq._derived.plan_targets import parse_target

HEIGHTS = np.round(np.arange(0.065, 0.1551, 0.015), 6)


# ----------------------------------------------------------------------------- a toy model


def _toy(seed=0):
    """k = 3 coefficients, prior N(0, I); theta on a grid of 5 points; given theta_s: a pilot of 6
    readings with sd sigma_s, then 4 planned readings of 2 rows each, rows that depend on theta
    (like the discrepancy's) and correlated noise with factor C_s (like the (force, piston) pair's);
    a linear target g_s' beta with an irreducible variance e_s."""
    rng = np.random.default_rng(seed)
    S, k, n0, n, r = 5, 3, 6, 4, 2
    X0 = rng.standard_normal((n0, k)) * np.array([1.0, 4.0, 0.3])  # an anisotropic posterior
    R0 = rng.standard_normal((n, r, k))
    sig0 = np.linspace(0.4, 1.2, S)
    R = np.stack([R0 * np.array([1.0, 1.0, 1.0 + 0.4 * s]) for s in range(S)])  # (S, n, r, k)
    C = np.zeros((S, n, r, r))
    C[..., 0, 0] = (0.3 + 0.2 * np.arange(S))[:, None]
    C[..., 1, 0] = -0.1 * np.arange(S)[:, None]
    C[..., 1, 1] = (0.5 - 0.05 * np.arange(S))[:, None]
    g = np.stack([np.array([1.0, -0.5, 0.3 + 0.1 * s]) for s in range(S)])  # (S, k)
    e = 0.01 * np.arange(S)
    y0 = X0 @ np.array([0.5, -1.0, 0.8]) + 0.6 * rng.standard_normal(n0)
    return dict(S=S, k=k, X0=X0, R=R, C=C, sig0=sig0, g=g, e=e, y0=y0, n=n, r=r)


def _pilot(t):
    """Precision and mean of the coefficients given each theta and the pilot's readings."""
    A = np.stack([np.eye(t["k"]) + t["X0"].T @ t["X0"] / s**2 for s in t["sig0"]])
    m = np.stack(
        [np.linalg.solve(A[i], t["X0"].T @ t["y0"] / t["sig0"][i] ** 2) for i in range(t["S"])]
    )
    return A, m


def _parts(t, idx):
    """plan_theta's parts of the toy on the draws ``idx`` (indices into the grid)."""
    A, m = _pilot(t)
    # Z = C^-1 R, reading by reading
    Z = np.stack(
        [
            np.stack([np.linalg.solve(t["C"][s, i], t["R"][s, i]) for i in range(t["n"])])
            for s in range(t["S"])
        ]
    )
    value = np.einsum("sk,sk->s", t["g"], m)[:, None]
    return PT.parts_of(
        Z[idx],
        t["C"][idx],
        A[idx],
        m[idx],
        value[idx],
        t["g"][idx][..., None],
        t["e"][idx][:, None],
    )


def _dense(t, y, mult):
    """The exact posterior of the target after the pilot and the new readings ``y`` (n, r), by dense
    Gaussian algebra in the readings' units: the prior over the grid is mult_s / p(y0 | theta_s), so
    that the pilot's posterior over it is mult_s (the draws handed to the reweighting: grid point s
    ``mult[s]`` times)."""
    k, n, r = t["k"], t["n"], t["r"]
    logw, means, vars_ = [], [], []
    for s in range(t["S"]):
        X = np.vstack([t["X0"], t["R"][s].reshape(n * r, k)])
        cov_n = np.zeros((X.shape[0], X.shape[0]))
        cov_n[: len(t["y0"]), : len(t["y0"])] = np.eye(len(t["y0"])) * t["sig0"][s] ** 2
        for i in range(n):
            Ci = t["C"][s, i]
            j = len(t["y0"]) + i * r
            cov_n[j : j + r, j : j + r] = Ci @ Ci.T
        yy = np.concatenate([t["y0"], y.ravel()])
        joint = multivariate_normal(np.zeros(yy.size), X @ X.T + cov_n).logpdf(yy)
        n0 = len(t["y0"])
        pilot = multivariate_normal(np.zeros(n0), (X @ X.T + cov_n)[:n0, :n0]).logpdf(t["y0"])
        logw.append(np.log(mult[s]) - pilot + joint)
        post = np.linalg.inv(np.eye(k) + X.T @ np.linalg.solve(cov_n, X))
        mu = post @ X.T @ np.linalg.solve(cov_n, yy)
        means.append(t["g"][s] @ mu)
        vars_.append(t["g"][s] @ post @ t["g"][s] + t["e"][s])
    w = np.exp(np.array(logw) - max(logw))
    w /= w.sum()
    mbar = w @ np.array(means)
    return w @ (np.array(vars_) + (np.array(means) - mbar) ** 2), mbar


def test_reweighting_is_the_exact_posterior_on_a_grid():
    """After a fixed set of new readings, the reweighted mixture's mean and variance of the target
    are the exact posterior's (dense Gaussian algebra over a grid of theta, the pilot's posterior
    over it given as draws with multiplicities): to rounding. Fails if the whitening's Jacobian
    (C depends on theta), the Woodbury quadratic form or the determinant were left out or wrong."""
    t = _toy()
    mult = np.array([1, 3, 2, 1, 2])
    idx = np.repeat(np.arange(t["S"]), mult)
    parts = _parts(t, idx)
    rng = np.random.default_rng(4)
    for _ in range(3):
        y = rng.normal(0.0, 2.0, (t["n"], t["r"]))
        var, mean, ess = PT.mixture(parts, y[None])
        exact_var, exact_mean = _dense(t, y, mult)
        np.testing.assert_allclose(var[0, 0], exact_var, rtol=1e-9)
        np.testing.assert_allclose(mean[0, 0], exact_mean, rtol=1e-9, atol=1e-12)
        assert 1.0 <= ess[0] <= idx.size


def test_simulated_sets_are_calibrated():
    """Sets drawn from the pilot's posterior predictive with their true coefficients and target: the
        reweighted posterior is then the exact posterior, so the mean squared error of its mean equals
        its mean variance (20000 sets: Monte Carlo sd of the ratio about 1.5 %; tolerance 5 %; the
    simulated noise at half its sd gives 0.90). Fails if the
        simulation drew from another distribution than the weights assume. The coefficients' draws are
        checked on their own too: (beta - m_s)' A_s (beta - m_s) averages k (its Monte Carlo sd about
        0.02; tolerance 0.08)."""
    t = _toy(1)
    idx = np.arange(t["S"])
    parts = _parts(t, idx)
    rng = np.random.default_rng(11)
    M = 20000
    y, s, beta = PT.simulate(parts, M, rng)
    A, m = _pilot(t)
    d = beta - m[s]
    assert abs(np.mean(np.einsum("mk,mkl,ml->m", d, A[s], d)) - t["k"]) < 0.08
    truth = np.einsum("mk,mk->m", t["g"][s], beta) + np.sqrt(t["e"][s]) * rng.standard_normal(M)
    var, mean, _ = PT.mixture(parts, y)
    ratio = np.mean((mean[:, 0] - truth) ** 2) / np.mean(var[:, 0])
    assert abs(ratio - 1.0) < 0.05, ratio


def test_simulation_is_deterministic_for_the_seed(pilot):
    builder, _ = surface_builder(pilot, n_draws=4)
    frame = builder.frame(np.array([3.5]))
    readings = [E.Reading(0, h) for h in HEIGHTS]
    targets = [parse_target("force@110mm,3.5bar")]
    a = PT.theta_updated(frame, targets, readings, 30, seed=2)
    b = PT.theta_updated(frame, targets, readings, 30, seed=2)
    c = PT.theta_updated(frame, targets, readings, 30, seed=3)
    assert a == b and a != c


# ----------------------------------------------------------------------------- the real frames


@pytest.fixture(scope="module")
def pilot():
    return uq.simulate(
        "n50-smooth", seed=3, layout=uq.Layout(pressures_bar=(2.0, 5.0, 8.0), step_m=0.015)
    )


@pytest.fixture(scope="module")
def table1_four():
    return uq.simulate(
        "n50", seed=5, layout=uq.Layout(pressures_bar=(1.0, 4.0, 7.0, 10.0), step_m=0.015)
    )


def _builders(pilot, table1_four):
    return {
        "surface": surface_builder(pilot, n_draws=4)[0],
        "cubics": cubic_builder(pilot, n_draws=4),
        "discrepancy": discrepancy_builder(table1_four, n_draws=4),
    }


@pytest.mark.parametrize("kind", ["surface", "cubics", "discrepancy"])
def test_noise_factors_unwhiten_the_rows(pilot, table1_four, kind):
    """C Z, reading by reading, is the design row of the reading in its own units: the same for
    every draw of theta where the design does not depend on it (the surface, the cubics), and the
    force row the model's own (C's first row is the force's sd: C Z's force row is X_f)."""
    b = _builders(pilot, table1_four)[kind]
    new = np.array([5.5]) if kind == "discrepancy" else np.array([3.5])
    frame = b.frame(new)
    Z = frame.reading_rows(0, HEIGHTS)
    C = frame.reading_noise(0, HEIGHTS)
    assert C.shape == (*Z.shape[:3], Z.shape[2])
    assert np.all(np.triu(C, 1) == 0) and np.all(np.diagonal(C, axis1=-2, axis2=-1) > 0)
    raw = np.einsum("snrq,snqk->snrk", C, Z)
    if kind != "discrepancy":
        np.testing.assert_allclose(raw, np.broadcast_to(raw[:1], raw.shape), rtol=1e-9, atol=1e-12)
    if kind == "surface":
        o, g = b.model(np.concatenate([b.tested, new]))
        from uq._models import surface

        idx = np.full(HEIGHTS.size, b.tested.size)
        Xf, Xl = surface.designs(o, g, HEIGHTS, np.full(HEIGHTS.size, 3.5), idx, b.tested.size + 1)
        np.testing.assert_allclose(raw[0, :, 0], Xf, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(raw[0, :, 1], Xl, rtol=1e-9, atol=1e-12)
    thin = frame.thinned(2)
    np.testing.assert_array_equal(thin.reading_noise(0, HEIGHTS), C[[0, 3]])


@pytest.mark.parametrize("kind", ["surface", "discrepancy"])
def test_equal_theta_draws_give_the_closed_form(pilot, table1_four, kind):
    """Every draw of theta the same: the weights are equal whatever the simulated readings (Kish
    size = the draws), the target's mean is the same in every draw, and the mixture's sd is uq
    plan's closed form (evaluate) in every simulated set."""
    b = _builders(pilot, table1_four)[kind]
    b = b.with_theta(np.repeat(b.theta[1:2], 5, axis=0))
    new = np.array([5.5]) if kind == "discrepancy" else np.array([3.5])
    frame = b.frame(new)
    readings = [E.Reading(0, h) for h in HEIGHTS] + [E.Reading(0, h) for h in HEIGHTS[::3]]
    targets = [parse_target(f"force@110mm,{new[0]:g}bar"), parse_target("force@80mm,6bar")]
    closed = np.sqrt(E.evaluate(frame, targets, readings)[0])
    out = PT.theta_updated(frame, targets, readings, 25, seed=1)
    for o, c in zip(out, closed, strict=True):
        for key in ("median", "p10", "p90", "mean"):
            np.testing.assert_allclose(o[key], c, rtol=1e-8)
        assert o["ess_min"] == pytest.approx(5.0, rel=1e-12)
