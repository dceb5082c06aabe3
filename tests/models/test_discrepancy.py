"""The surface with a discrepancy in pressure (uq/_models/discrepancy.py): its collapsed density
against the dense design and against brute-force Gaussian integration, its leave-one-out
densities, and the Gaussian process between tested pressures (uq/_models/discrepancy_gp.py)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from uq._data.recordings import read_recordings
from uq._inference.float64 import jax, jnp
from uq._inference.linear import linear_posterior
from uq._models import discrepancy as dm
from uq._models import discrepancy_gp as gp
from uq._models import pair, surface, surface_force, surface_likelihood
from uq._physics.quantities import BAR_PA, BASIS_SCALE_M
from uq._stand.shapes import catalogue_recordings
from uq._stand.simulator import Layout, recordings_from_tests, simulate

TINY = Layout(pressures_bar=(1.0, 4.0, 6.0), step_m=0.015)
ORDERS = surface.Orders(3, 1, 2, 1, 1)
FORCE_ORDERS = surface.Orders(3, 1, 2, -1, -1)
ROOT = Path(__file__).resolve().parents[2]
BENCH = ROOT / "benchmarks" / "discrepancy.py"


@pytest.fixture(scope="module")
def tiny():
    """Three tests of 13 readings each (39 readings, 42 coefficients)."""
    rec = recordings_from_tests(
        simulate("n50-kink", seed=3, layout=TINY), x0_m=0.112, piston_area_m2=54.82e-4
    )
    return rec, dm.dev_data(rec, ORDERS)


@pytest.fixture(scope="module")
def tiny_force():
    rec = catalogue_recordings(
        "n50", seed=4, layout=Layout(pressures_bar=(3.0, 5.0, 7.0), step_m=0.015)
    )
    return rec, dm.force_dev_data(rec, FORCE_ORDERS)


def theta_of(d, a=(3e-4, 2e-4, 1.5e-4), length=2.0):
    """theta with amplitudes ``a`` of (delta, eps, phi) (without piston: of delta and phi)."""
    a = a if dm.has_piston(d) else (a[0], a[2])
    theta = dm.theta_of(np.asarray(d.prior_mean), a, length)
    amps, ell = dm.hyper_draws(theta[None], d)
    np.testing.assert_allclose(amps[0], a, rtol=1e-12)  # the sampled coordinates invert exactly
    np.testing.assert_allclose(ell, [length], rtol=1e-12)
    return jnp.asarray(theta)


def dense_designs(rec, d, theta):
    """The model's dense (n, K) force and piston designs written from its definition: the surface's
    designs, then a s_k chol(R) times, per block, delta: force p_i t^k and piston
    -(h/S) t^(k+1)/(k+1); eps: that piston alone; phi: force p_ref t^k alone (p_ref the highest
    tested pressure)."""
    piston = dm.has_piston(d)
    g = surface.geometry_of(rec)
    if piston:
        base = surface_likelihood.surface_data(rec, ORDERS, dm.PAPER_STAND)
        Xf, Xl = np.asarray(base.Xf), np.asarray(base.Xl)
    else:
        Xf, Xl = (
            np.asarray(surface_likelihood.surface_force_data(rec, FORCE_ORDERS, dm.PAPER_STAND).X),
            None,
        )
    t, idx, p = np.asarray(d.t), np.asarray(d.test), np.asarray(d.p_bar)
    T, nk = p.size, int(d.s.shape[0])
    _, amps, length = (np.asarray(v) for v in dm._split(np.asarray(theta), d))
    Lr = np.linalg.cholesky(gp.correlation(p, float(length)))
    lever = -BASIS_SCALE_M / g.area_m2
    blocks = ("delta", "eps", "phi") if piston else ("delta", "phi")
    n_c = nk * amps.size
    DF = np.zeros((t.size, n_c * T))
    DL = np.zeros_like(DF)
    for c in range(n_c):
        k, amp, block = c % nk, amps[c // nk], blocks[c // nk]
        for j in range(T):
            fac = amp * Lr[idx, j]
            if block == "delta":
                DF[:, c * T + j] = p[idx] * BAR_PA * t**k * fac
            if block == "phi":
                DF[:, c * T + j] = p.max() * BAR_PA * t**k * fac
            if block in ("delta", "eps"):
                DL[:, c * T + j] = lever * t ** (k + 1) / (k + 1) * fac
    return np.hstack([Xf, DF]), (np.hstack([Xl, DL]) if piston else None)


def brute_log_density(y, X, cov):
    """log N(y; 0, X X^T + cov), rows scaled to unit order first (forces and pistons differ by 1e5)."""
    sc = 1.0 / np.sqrt(np.diag(cov))
    C = (X @ X.T + cov) * sc[:, None] * sc[None, :]
    return stats.multivariate_normal(np.zeros(y.size), C).logpdf(y * sc) + np.sum(np.log(sc))


def pair_cov(noise, d):
    L11, L21, L22 = (np.asarray(v) for v in pair.cov_factors(noise, d))
    n = L11.size
    cov = np.zeros((2 * n, 2 * n))
    cov[np.arange(n), np.arange(n)] = L11**2
    cov[np.arange(n) + n, np.arange(n) + n] = L21**2 + L22**2
    cov[np.arange(n), np.arange(n) + n] = cov[np.arange(n) + n, np.arange(n)] = L11 * L21
    return cov


def test_the_span_reproduces_the_surface_and_the_deviations(tiny):
    """A_i and D_i are exact: Z_i A_i is the surface's design at the test's heights (checked when the
    data are built; here again, and a design outside the span is refused)."""
    rec, d = tiny
    Zf, Zl = dm.z_rows(np.linspace(-0.9, 0.9, 7), 3e5, 3, True)
    Xf = np.random.default_rng(0).standard_normal((7, 2))
    with pytest.raises(ValueError, match="does not reproduce"):
        dm.span_map(Zf, Zl, Xf, np.zeros((7, 2)), "test design")
    assert d.A.shape == (3, 9, 18) and d.D.shape == (3, 9, 12)


@pytest.mark.parametrize("which", ["pair", "force"])
def test_collapsed_density_equals_dense_and_brute_force(which, tiny, tiny_force):
    """log p(y | theta) three ways: the per-test moments in the 9T-space (what the sampler uses),
    the (K x K) Gram of the moments (what the draws use), and the dense design's Gaussian marginal
    N(y; 0, X X^T + Sigma); posterior means equal to the dense linear posterior's."""
    rec, d = tiny if which == "pair" else tiny_force
    theta = theta_of(d)
    fast = float(dm.log_marginal(theta, d))
    post = dm.posterior(theta, d)
    XF, XL = dense_designs(rec, d, theta)
    noise = theta[: 5 if which == "pair" else 3]
    if which == "pair":
        F, L = (np.asarray(v) for v in pair.readings(noise, d))
        X, y, cov = np.vstack([XF, XL]), np.concatenate([F, L]), pair_cov(noise, d)
    else:
        sigma, y = (np.asarray(v) for v in surface_force.sigma_y(noise, d))
        X, cov = XF, np.diag(sigma**2)
    brute = brute_log_density(y, X, cov)
    assert fast == pytest.approx(brute, abs=1e-6)
    assert float(post.log_marginal) == pytest.approx(brute, abs=1e-6)
    Lc = np.linalg.cholesky(cov)
    Xw, yw = np.linalg.solve(Lc, X), np.linalg.solve(Lc, y)
    dense = linear_posterior(
        jnp.asarray(Xw), jnp.asarray(yw), jnp.ones(y.size), jnp.ones(X.shape[1])
    )
    np.testing.assert_allclose(
        post.mean, dense.mean, rtol=1e-7, atol=1e-9 * np.abs(dense.mean).max()
    )


def previous_log_marginal(monkeypatch):
    """The previous formula of log p(y | theta), kept by benchmarks/discrepancy.py as its baseline
    (which sets UQ_MALLOC when loaded: undone after the test)."""
    monkeypatch.setenv("UQ_MALLOC", "default")
    spec = importlib.util.spec_from_file_location("bench_discrepancy", BENCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.previous_log_marginal


def test_the_samplers_density_on_data_n50_equals_the_previous_formula_and_the_dense_route(
    monkeypatch,
):
    """data/n50 (11 tests, the 99 x 99 matrix of the sampler) at 24 random thetas around the start:
    log p(y | theta) equals the previous implementation and the (K x K) Gram route to 1e-9
    relative (measured: 2e-10 and 1e-10, about 1e-7 absolute; the formula's own rounding floor,
    y'Wy of about 1e9 less |u|^2, is 4e-11 relative: the previous formula against itself with the
    readings in reverse order), and a held-out reading (weight 0) drops out alike."""
    previous = previous_log_marginal(monkeypatch)
    rec = read_recordings(ROOT / "data" / "n50" / "recordings.csv")
    d = dm.dev_data(rec, surface.orders_for(rec))
    start = dm.start(d)[0]
    thetas = jnp.asarray(start + 0.5 * np.random.default_rng(7).standard_normal((24, start.size)))
    new = np.asarray(jax.jit(jax.vmap(lambda t: dm.log_marginal(t, d)))(thetas))
    old = np.asarray(jax.jit(jax.vmap(lambda t: previous(t, d)))(thetas))
    dense = np.asarray(jax.vmap(lambda t: dm.posterior(t, d).log_marginal)(thetas[:6]))
    np.testing.assert_allclose(new, old, rtol=1e-9)
    np.testing.assert_allclose(new[:6], dense, rtol=1e-9)
    held = d._replace(weight=d.weight.at[::7].set(0.0))
    np.testing.assert_allclose(
        dm.log_marginal(thetas[0], held), previous(thetas[0], held), rtol=1e-9
    )


@pytest.mark.parametrize("which", ["pair", "force"])
def test_leave_one_out_equals_brute_force(which, tiny, tiny_force):
    """log p(reading_i | theta, the other readings) from the per-test leverages equals the Gaussian
    conditional of the dense marginal, for three readings of different tests."""
    rec, d = tiny if which == "pair" else tiny_force
    theta = theta_of(d)
    loo = np.asarray(dm.pointwise_loo(theta, d))
    XF, XL = dense_designs(rec, d, theta)
    noise = theta[: 5 if which == "pair" else 3]
    n = XF.shape[0]
    if which == "pair":
        F, L = (np.asarray(v) for v in pair.readings(noise, d))
        X, y, cov = np.vstack([XF, XL]), np.concatenate([F, L]), pair_cov(noise, d)
    else:
        sigma, y = (np.asarray(v) for v in surface_force.sigma_y(noise, d))
        X, cov = XF, np.diag(sigma**2)
    C = X @ X.T + cov
    for i in (0, n // 2, n - 1):
        held = [i, n + i] if which == "pair" else [i]
        keep = np.setdiff1d(np.arange(y.size), held)
        S12 = C[np.ix_(held, keep)]
        mu = S12 @ np.linalg.solve(C[np.ix_(keep, keep)], y[keep])
        cv = C[np.ix_(held, held)] - S12 @ np.linalg.solve(C[np.ix_(keep, keep)], S12.T)
        assert loo[i] == pytest.approx(stats.multivariate_normal(mu, cv).logpdf(y[held]), abs=1e-5)


def test_pointwise_at_the_posterior_mean_is_the_readings_loglik(tiny):
    """pointwise() at beta gives the pair likelihood of the dense design at the same beta."""
    rec, d = tiny
    theta = theta_of(d)
    beta = np.asarray(dm.posterior(theta, d).mean)
    XF, XL = dense_designs(rec, d, theta)
    ll = np.asarray(dm.pointwise(theta, beta, d)["reading"])
    base = surface_likelihood.surface_data(rec, ORDERS, dm.PAPER_STAND)
    dense = base._replace(Xf=jnp.asarray(XF), Xl=jnp.asarray(XL))
    np.testing.assert_allclose(ll, pair.pointwise(theta[:5], beta, dense), rtol=1e-9, atol=1e-9)


def test_priors_are_normalised_and_as_stated():
    """The amplitude's prior (in log a) and the length scale's PC prior integrate to one, and their
    stated tails hold: P(a > U) = 0.05, P(l < 1 bar) = 0.25."""
    rate = gp.amplitude_rate(0.025)
    u = np.linspace(-25.0, 5.0, 200001) + np.log(1.0 / rate)
    pa = np.exp(gp.log_prior_amplitude(u, rate))
    assert np.trapezoid(pa, u) == pytest.approx(1.0, abs=1e-6)
    U = gp.AMPLITUDE_UPPER_REL * 0.025
    assert np.trapezoid(np.where(u > np.log(U), pa, 0.0), u) == pytest.approx(0.05, abs=1e-4)
    v = np.linspace(-12.0, 60.0, 400001)
    pl = np.exp(gp.log_prior_length(v))
    assert np.trapezoid(pl, v) == pytest.approx(1.0, abs=1e-4)
    assert np.trapezoid(np.where(v < 0.0, pl, 0.0), v) == pytest.approx(0.25, abs=1e-4)


def test_force_amplitudes_prior_in_polar_coordinates_is_the_two_exponentials(tiny_force):
    """The force blocks' amplitudes are sampled as (log r, u) (``force_amplitudes``); the model's
    prior there is the two independent exponentials of a_F and a_P times the Jacobian: it
    integrates to one over (log r, u), and P(a_F > U) and P(a_P > U) are the stated 0.05."""
    _, d = tiny_force
    rate = float(d.rates[0])
    lr = np.linspace(-6.0, 4.0, 801) + np.log(1.0 / rate)
    u = np.linspace(-30.0, 30.0, 1201)
    LR, UU = np.meshgrid(lr, u, indexing="ij")
    noise = np.asarray(d.prior_mean)
    theta = np.concatenate(
        [
            np.broadcast_to(noise, LR.shape + noise.shape),
            LR[..., None],
            UU[..., None],
            np.zeros(LR.shape + (1,)),
        ],
        axis=-1,
    ).reshape(-1, noise.size + 3)
    lp = np.asarray(jax.vmap(lambda t: dm.log_prior(t, d))(jnp.asarray(theta))).reshape(LR.shape)
    lp = lp - float(gp.log_prior_length(0.0))  # the noise logs sit at their centres: 0
    dens = np.exp(lp)
    cell = (lr[1] - lr[0]) * (u[1] - u[0])
    assert dens.sum() * cell == pytest.approx(1.0, abs=2e-3)
    a_F, a_P = dm.force_amplitudes(LR, UU)
    U = -np.log(gp.AMPLITUDE_TAIL) / rate  # the exponential's 95 % point
    for a in (a_F, a_P):
        assert (dens * (a > U)).sum() * cell == pytest.approx(gp.AMPLITUDE_TAIL, abs=2e-3)


def test_two_point_mean_is_exact_at_nodes_and_linear_in_the_long_limit():
    nodes = np.array([1.0, 1.5, 2.5])
    i, w = gp.two_point_weights(nodes, nodes, np.array([0.7, 1e9]))
    np.testing.assert_allclose(w[:, :2, 0], 1.0, atol=1e-12)
    np.testing.assert_allclose(w[:, :2, 1], 0.0, atol=1e-12)
    np.testing.assert_allclose(w[:, 2, 1], 1.0, atol=1e-12)  # the last node: the right weight
    _, w = gp.two_point_weights(np.array([1.125]), nodes, np.array([1e9]))
    np.testing.assert_allclose(w[0, 0], [0.75, 0.25], atol=1e-6)


def test_interpolation_error_between_nodes_is_small():
    """What the two-point mean neglects between 0.1-bar nodes: under 5 % of the amplitude for
    l >= 0.5 bar (the docstring's figure), 2 % for l >= 1 bar."""
    assert gp.interpolation_sd(0.1 / 0.5) < 0.055
    assert gp.interpolation_sd(0.1 / 1.0) < 0.02


def test_draws_on_the_grid_have_the_conditional_law():
    """The grid's values given the tested ones: mean R_GT R_TT^-1 v and covariance a^2 (R_GG -
    R_GT R_TT^-1 R_TG), by 20000 seeded draws (tolerance 5 sd of the Monte Carlo error)."""
    tested, grid = np.array([1.0, 3.0, 5.0]), np.array([2.0, 4.0])
    S, length, a = 20000, 1.5, 2.0
    v = np.tile(np.array([[0.5], [-1.0], [0.3]])[None], (S, 1, 1))
    xi = np.random.default_rng(5).standard_normal((S, 2, 1))
    out = gp.draw_on_grid(v, np.full((S, 1), a), np.full(S, length), tested, grid, xi)[..., 0]
    R = gp.matern32(np.subtract.outer(np.r_[tested, grid], np.r_[tested, grid]), length)
    W = np.linalg.solve(R[:3, :3], R[:3, 3:])
    mean = W.T @ v[0, :, 0]
    cov = a**2 * (R[3:, 3:] - R[3:, :3] @ W)
    np.testing.assert_allclose(out.mean(0), mean, atol=5 * np.sqrt(np.diag(cov).max() / S))
    np.testing.assert_allclose(np.cov(out.T), cov, atol=5 * 2 * np.diag(cov).max() / np.sqrt(S))


def test_grid_nodes_leave_out_tested_pressures():
    g = gp.grid_nodes([1.0, 2.5, 10.0])
    assert g.min() > 1.0 and g.max() < 10.0
    assert np.min(np.abs(g - 2.5)) > 0.02
    nodes = np.sort(np.r_[g, 1.0, 2.5, 10.0])
    assert np.all(np.diff(g) > 0) and np.diff(nodes).max() <= gp.GRID_STEP_BAR + 1e-12


@pytest.mark.parametrize("which", ["pair", "force"])
def test_exact_draws_have_the_posterior_law(which, tiny, tiny_force):
    """The draws (Matheron's rule in the Z-space) are affine in their normals: at zero they give the
    posterior mean, and their Jacobian J has J J^T = the posterior covariance, both of the (K x K)
    Gram route."""
    import jax

    _, d = tiny if which == "pair" else tiny_force
    theta = theta_of(d)
    post = dm.posterior(theta, d)
    K = dm.n_coefficients(d)
    e0 = jnp.zeros(K + d.A.shape[0] * d.A.shape[1])
    np.testing.assert_allclose(dm.draw_from_normals(theta, e0, d), post.mean, rtol=1e-7, atol=1e-9)
    J = np.asarray(jax.jacfwd(lambda e: dm.draw_from_normals(theta, e, d))(e0))
    Linv = np.linalg.inv(np.asarray(post.chol))
    np.testing.assert_allclose(J @ J.T, Linv.T @ Linv, rtol=1e-6, atol=1e-10)


# ----------------------------------------------------------------------------- the fitted model


@pytest.fixture(scope="module")
def small_fit():
    """A 4-test campaign of the kinked spring, fitted with a short run (the draws' plumbing, not
    the posterior's quality, is under test here)."""
    from uq._inference.sampler import Settings
    from uq._stand.simulator import simulate_recordings

    rec = simulate_recordings(
        "n50-kink", seed=11, layout=Layout(pressures_bar=(2.0, 4.0, 6.0, 8.0), step_m=0.015)
    )
    return dm.fit_discrepancy(
        rec, seed=3, settings=Settings(n_walkers=16, n_ensembles=2, max_steps=200), max_draws=400
    )


def test_draws_are_fixed_and_coherent_in_pressure(small_fit):
    from uq._models.surface import SurfaceFit

    """The same draws on every call and on thinned views; each draw's force is a continuous curve
    in pressure (at every node, tested or virtual, its value from the left and from the right
    agree); at a tested pressure the force is the surface's plus p_u times the draw's pressure-area
    deviation there plus p_ref times its force deviation (phi)."""
    fit = small_fit
    ps = np.linspace(2.0, 8.0, 801)
    h = np.full(801, 0.15)
    F1 = fit.force_draws(h, ps)
    np.testing.assert_array_equal(F1, fit.force_draws(h, ps))
    half = fit.on_draws(fit.n_draws // 2)
    rows = np.searchsorted(fit.rows, half.rows)
    assert np.all(fit.rows[rows] == half.rows)
    np.testing.assert_allclose(half.force_draws(h, ps), F1[rows], rtol=1e-12)
    nodes = fit.nodes[0][1:-1]
    eps = 1e-9
    every = fit.symbols
    below = fit.deviation_draws(np.full(nodes.size, 0.15), nodes - eps, every)
    above = fit.deviation_draws(np.full(nodes.size, 0.15), nodes + eps, every)
    scale = np.abs(fit.tested_deviations).max()
    assert np.abs(above - below).max() < 1e-6 * scale
    one = {b: fit.deviation_draws(np.full(ps.size, 0.15), ps, (b,)) for b in every}
    for some in (("delta",), ("eps",), ("delta", "eps"), ("delta", "phi"), ("eps", "phi")):
        np.testing.assert_allclose(  # only the blocks asked for, summed
            fit.deviation_draws(np.full(ps.size, 0.15), ps, some),
            sum(one[b] for b in some),
            rtol=1e-12,
            atol=1e-12 * scale,
        )
    # on a grid of heights x pressures (one matrix product) as point by point (scattered points)
    X, P = np.meshgrid(np.linspace(0.07, 0.15, 9), np.linspace(2.0, 8.0, 13), indexing="ij")
    grid = fit.deviation_draws(X, P, every)
    assert grid.shape == (fit.n_draws, 9, 13)
    for j in range(9):
        np.testing.assert_allclose(
            grid[:, j],
            fit.deviation_draws(X[j] + 1e-13 * np.arange(13), P[j], every),  # scattered
            rtol=1e-9,
            atol=1e-9 * scale,
        )
    ratio = {"delta": lambda p: p * 1e5, "phi": lambda p: np.full(p.shape, fit.p_ref_pa)}
    np.testing.assert_allclose(
        fit.deviation_draws(X, P, tuple(ratio), factors=ratio),
        P * 1e5 * fit.deviation_draws(X, P) + fit.p_ref_pa * fit.deviation_draws(X, P, ("phi",)),
        rtol=1e-9,
        atol=1e-9 * scale * fit.p_ref_pa,
    )
    base = SurfaceFit.force_draws(fit, 0.15, 4.0)
    t = fit.geometry.t(0.15)
    tk = t ** np.arange(fit.n_k)
    delta = fit.tested_deviations[:, 1, : fit.n_k] @ tk
    phi = fit.tested_deviations[:, 1, fit.symbols.index("phi") * fit.n_k :][:, : fit.n_k] @ tk
    p_ref = fit.tested_pressures_bar.max() * 1e5
    np.testing.assert_allclose(
        fit.force_draws(0.15, 4.0), base + 4e5 * delta + p_ref * phi, rtol=1e-9
    )


def test_protocol_quantities(small_fit):
    from uq._io.errors import InputError

    fit = small_fit
    assert fit.name == "discrepancy" and "discrepancy in pressure" in fit.label
    va = fit.volume_area_draws(np.array([0.1, 0.12]), 5.0)
    assert va.shape == (fit.n_draws, 2) and np.all(va > 0.01)
    with pytest.raises(InputError, match="outside the tested"):
        fit.force_draws(0.1, 9.0)
    with pytest.raises(InputError, match="no dV/dp_u"):
        fit.volume_pressure_draws(0.1, 5.0)
    blocks = fit.blocks()
    assert blocks["pressure_area_deviation_m2"].draws.shape == (fit.n_draws, 4 * fit.n_k)
    assert blocks["volume_area_deviation_m2"].names[0] == "eps_0_2bar"
    doc = fit.to_json()
    assert set(doc["discrepancy"]) >= {
        "a_F_m2",
        "a_V_m2",
        "a_P_m2",
        "length_bar",
        "kernel",
        "priors",
    }
    at = doc["discrepancy"]["at_x0"]
    assert at["3"]["tested"] is False and at["4"]["tested"] is True


def test_refuses_campaigns_it_cannot_fit():
    from uq._io.errors import InputError

    rec = recordings_from_tests(
        simulate("n50", seed=1, layout=Layout(pressures_bar=(3.0,), step_m=0.015)),
        x0_m=0.112,
        piston_area_m2=54.82e-4,
    )
    with pytest.raises(InputError, match="needs at least 2"):
        dm.fit_discrepancy(rec, orders=surface.Orders(3, 0, 2, 1, 0))
    rec = recordings_from_tests(
        simulate(
            "n50", seed=1, layout=Layout(pressures_bar=(3.0, 5.0), x_min_m=0.14, step_m=0.005)
        ),
        x0_m=0.112,
        piston_area_m2=54.82e-4,
    )
    with pytest.raises(InputError, match="distinct heights"):
        dm.fit_discrepancy(rec, orders=surface.Orders(3, 0, 2, 1, 0))


def test_saved_and_loaded_it_answers_the_same(small_fit, tmp_path):
    """The one saved format: the deviation blocks and the sampled amplitudes and length scale are
    saved, the curves between tested pressures are made again from the seed, so a loaded model's
    force between tested pressures is the fitted one's, draw by draw."""
    from uq._models.saved import load

    path = small_fit.save(tmp_path / "d.nc", seed=3)
    loaded = load(path)
    assert type(loaded) is type(small_fit) and loaded.recordings is None
    ps = np.array([2.0, 3.0, 4.7, 8.0])
    np.testing.assert_allclose(
        loaded.force_draws(np.full(4, 0.1), ps), small_fit.force_draws(np.full(4, 0.1), ps)
    )


def test_a_file_saved_before_the_force_deviation_is_refused_in_one_line(
    small_fit, tmp_path, monkeypatch
):
    """A discrepancy surface saved without the force's deviation block (phi; saved before it was
    added) is not today's model: refused in one line naming the file and the block, not loaded
    wrongly (the check every saved model's load makes, ``saved.require_blocks``)."""
    from saved_helpers import refusal_without

    message = refusal_without(small_fit, tmp_path / "d.nc", monkeypatch, "force_deviation_m2")
    assert "d.nc: incomplete saved model: no block force_deviation_m2 " in message


def test_its_page_shows_the_discrepancy(small_fit, tmp_path):
    """uq report --surface / uq surface --report: the surface's page with the discrepancy's section
    (the deviation at x0 at and between tested pressures)."""
    from uq._report.pages import write_model_page

    page = write_model_page(small_fit, small_fit.to_json(), tmp_path).read_text()
    assert "Surface with a discrepancy in pressure" in page
    assert "what the smooth surface misses" in page and "between" in page
