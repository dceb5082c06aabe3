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


# ----------------------------------------------------------------------------- the held-out pool


def test_held_out_pool_against_quadrature_over_a_continuous_theta():
    """The sets simulated from some of the pilot's draws of a continuous theta (a log noise sd) and
    reweighted over a pool of other draws: after each set, the target's posterior variance is the
    exact one, computed by quadrature over theta (1-D: a coefficient beta ~ N(0, 1), ten readings
    y = beta + sigma e, the pilot's theta ~ N(0, 0.5^2) given by its draws): the median ratio within
    2 % and every set within 12 % (importance sampling with about 800 effective draws of 2000).
    Fails if the pool's weights or the mixture's variance were wrong, or the sets came from other
    draws than they say."""
    rng = np.random.default_rng(7)
    n, M = 10, 300

    def parts(theta):
        sig = np.exp(theta)
        S = sig.size
        Z = np.broadcast_to((1.0 / sig)[:, None, None, None], (S, n, 1, 1)).copy()
        C = np.broadcast_to(sig[:, None, None, None], (S, n, 1, 1)).copy()
        return PT.parts_of(
            Z,
            C,
            np.ones((S, 1, 1)),
            np.zeros((S, 1)),
            np.zeros((S, 1)),
            np.ones((S, 1, 1)),
            np.zeros((S, 1)),
        )

    gen = parts(0.5 * rng.standard_normal(400))
    pool = parts(0.5 * rng.standard_normal(2000))
    y, _, _ = PT.simulate(gen, M, rng)
    var, mean, ess = PT.mixture(pool, y)
    grid = np.linspace(-3.0, 3.0, 4001)  # theta, 6 prior sd either side
    sig2 = np.exp(2 * grid)[:, None]
    ys, yy = y[..., 0].sum(1), (y[..., 0] ** 2).sum(1)
    # y | theta ~ N(0, sig^2 I + 1 1'): log density by the determinant lemma and Sherman-Morrison
    logp = (
        -0.5 * (yy[None] - ys[None] ** 2 / (sig2 + n)) / sig2
        - 0.5 * ((n - 1) * np.log(sig2) + np.log(sig2 + n))
        - 0.5 * grid[:, None] ** 2 / 0.25
    )
    w = np.exp(logp - logp.max(0))
    w /= w.sum(0)
    m_t, v_t = ys[None] / (sig2 + n), sig2 / (sig2 + n)  # beta | theta, y
    mbar = np.sum(w * m_t, 0)
    exact = np.sum(w * (v_t + (m_t - mbar) ** 2), 0)
    ratio = var[:, 0] / exact
    assert abs(np.median(ratio) - 1.0) < 0.02, np.median(ratio)
    assert np.all(np.abs(ratio - 1.0) < 0.12), (ratio.min(), ratio.max())
    np.testing.assert_allclose(mean[:, 0], mbar, atol=0.03 * np.sqrt(exact).max())
    assert np.median(ess) > 300


def test_held_out_draws_are_disjoint_and_spread():
    """held_out: n of the draws a builder did not thin to, spread over the chain, deterministic."""
    from uq._derived.plan_frames import _thin, held_out

    all_ = np.arange(1000.0)[:, None]
    used = _thin(all_, 100)
    pool = held_out(all_, 100, 300)
    assert pool.shape == (300, 1)
    assert not set(pool[:, 0]) & set(used[:, 0])
    assert pool[0, 0] < 10 and pool[-1, 0] > 990  # over the whole chain
    np.testing.assert_array_equal(pool, held_out(all_, 100, 300))
    assert held_out(all_, 100, 5000).shape == (900, 1)  # all that are left


def _with_source(b, n_used):
    """A builder as of_fit makes it: its theta thinned to ``n_used`` of the draws it was given."""
    from uq._derived.plan_frames import _thin

    all_ = b.theta
    b._set_theta(_thin(all_, n_used))
    b.all_theta = all_
    return b


@pytest.mark.parametrize("kind", ["surface", "discrepancy"])
def test_pool_is_the_builder_on_other_draws(pilot, table1_four, kind):
    """builder.pool(n): the same frames on draws of the fit the builder does not use; None for a
    builder not made from a fit's draws (and for one whose theta was replaced: with_theta)."""
    make = surface_builder if kind == "surface" else discrepancy_builder
    rec = pilot if kind == "surface" else table1_four
    b = make(rec, n_draws=12)
    b = b[0] if isinstance(b, tuple) else b
    assert b.pool(4) is None
    b = _with_source(b, 4)
    pool = b.pool(5)
    assert pool.theta.shape == (5, b.theta.shape[1])
    assert not {tuple(r) for r in pool.theta} & {tuple(r) for r in b.theta}
    assert pool.pool(2) is None and b.with_theta(b.theta).pool(2) is None
    new = np.array([5.5]) if kind == "discrepancy" else np.array([3.5])
    f, fp = b.frame(new), pool.frame(new)
    assert fp.precision.shape[1:] == f.precision.shape[1:] and fp.n_draws == 5


def test_cubic_pool_is_paired_by_index(pilot):
    """CubicFrames.pool: each test's held-out draws (paired by index as the frames' own are)."""
    from uq._derived.plan_frames import _thin

    cb = cubic_builder(pilot, n_draws=10)
    assert cb.pool(3) is None
    datas = [cb.datas[i] for i in np.argsort(np.argsort([t.pressure_bar for t in pilot.tests]))]
    th = [cb.theta[i] for i in np.argsort(np.argsort([t.pressure_bar for t in pilot.tests]))]
    small = type(cb)(pilot, datas, [_thin(a, 4) for a in th], cb.mean_coef)
    small._source = (datas, th, cb.mean_coef)
    pool = small.pool(50)
    assert pool.S == 6  # all that are left
    for a, b in zip(pool.theta, small.theta, strict=True):
        assert not {tuple(r) for r in a} & {tuple(r) for r in b}


def test_a_pool_of_the_frames_own_draws_changes_nothing_but_the_flag(pilot):
    """theta_updated with ``pool`` = the same frame: the numbers of no pool (the simulating draw
    among those reweighted), said to be held out."""
    builder, _ = surface_builder(pilot, n_draws=4)
    frame = builder.frame(np.array([3.5]))
    readings = [E.Reading(0, h) for h in HEIGHTS]
    targets = [parse_target("force@110mm,3.5bar")]
    a = PT.theta_updated(frame, targets, readings, 30, seed=2)
    b = PT.theta_updated(frame, targets, readings, 30, seed=2, pool=frame)
    assert not a[0]["held_out"] and b[0]["held_out"] and a[0]["draws"] == b[0]["draws"] == 4
    assert {k: v for k, v in a[0].items() if k != "held_out"} == {
        k: v for k, v in b[0].items() if k != "held_out"
    }
