"""The diagnose model's likelihood from the moments of its expanded design equals the model
written out as an explicit design (eq. 1, 2 with every mechanism's columns), built here from
the module docstring of uq._models.diagnose, independently of the moments."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from uq._data.recordings import read_recordings
from uq._inference.float64 import jax, jnp
from uq._inference.linear import gaussian_loglik, linear_posterior
from uq._models import diagnose as M
from uq._physics.quantities import BAR_PA, BASIS_SCALE_M

ROOT = Path(__file__).resolve().parents[2]


def _explicit(theta, mask, d):
    """Stacked design of (z = P + cL, L) rows, written out column by column from the physics
    (the reference): force p F_eff (1 + m_A p)(1 + m_H sgn) + (1 + m_H sgn)(E(x) + p^2 C'(x)/2)
    + offset; piston r_i - (1 + m_V)[(1 + m_A p) int F_eff + p C(x)] / S + drift step, with
    C(x) = sum_j c_j t^j (j = 1..3) and model columns in the order F_eff, references, casing,
    elastic casing, offset, drift."""
    on_mech = dict(zip(M.MECHS, mask[: M.N_MECH], strict=True))
    m_area = on_mech["pressure_dependent_area"] * theta[2]
    m_hyst = on_mech["hysteresis"] * theta[3]
    m_vol = on_mech["volume_excess"] * theta[4]
    g, hy = 1.0 + m_area * d.p_bar, 1.0 + m_hyst * d.sgn
    pw = jnp.arange(M.K_MAX + 1)
    on = mask[M.N_MECH :]
    T = d.t[:, None] ** pw * on
    Tint = d.t[:, None] ** (pw + 1) / (pw + 1) * on
    n = d.t.size
    Tc = d.t[:, None] ** jnp.arange(4)
    j = jnp.arange(1, 4)
    p_pa = d.p_bar * BAR_PA
    C = d.t[:, None] ** j
    dC = j * d.t[:, None] ** (j - 1) / BASIS_SCALE_M
    XF = jnp.concatenate(
        [
            (p_pa * g * hy)[:, None] * T,
            jnp.zeros_like(d.R),
            on_mech["casing_force"] * hy[:, None] * Tc,
            on_mech["elastic_casing"] * (hy * p_pa**2 / 2)[:, None] * dC,
            on_mech["force_offset"] * jnp.ones((n, 1)),
            jnp.zeros((n, 1)),
        ],
        axis=1,
    )
    XL = jnp.concatenate(
        [
            -(BASIS_SCALE_M / d.area) * (g * (1.0 + m_vol))[:, None] * Tint,
            d.R,
            jnp.zeros_like(Tc),
            -on_mech["elastic_casing"] * ((1.0 + m_vol) * p_pa / d.area)[:, None] * C,
            jnp.zeros((n, 1)),
            on_mech["thermal_drift"] * (d.step * 1e-6 / d.area)[:, None],
        ],
        axis=1,
    )
    X = jnp.concatenate([XF + d.c[:, None] * XL, XL])
    y = jnp.concatenate([d.force + d.c * d.piston, d.piston])
    sigma = jnp.concatenate([jnp.exp(theta[0]) * d.sd_z, jnp.exp(theta[1]) * d.sd_L])
    return X, y, sigma, XF, XL


def _explicit_log_post(theta, mask, d):
    X, y, sigma, *_ = _explicit(theta, mask, d)
    keep = d.fit_w > 0
    lp = linear_posterior(X[keep], y[keep], sigma[keep], d.prior_sd).log_marginal
    lp += 0.5 * (np.sum(keep) - y.size) * 1.8378770664093453  # the model counts every row's 2 pi
    on_mech = dict(zip(M.MECHS, mask[: M.N_MECH], strict=True))
    active = jnp.concatenate([jnp.ones(2)] + [jnp.array([on_mech[name]]) for name in M.SCALES])
    return lp - 0.5 * jnp.sum(active * (theta / M.THETA_PRIOR_SD) ** 2)


@pytest.fixture(scope="module")
def data():
    return M.prepare(read_recordings(ROOT / "data" / "n50" / "recordings.csv"))[0]


@pytest.mark.parametrize(
    "names,order",
    [
        ((), 3),
        (("pressure_dependent_area", "volume_excess", "casing_force"), 4),
        (("elastic_casing", "hysteresis", "volume_excess"), 3),
        (M.MECHS, 5),
    ],
)
def test_log_posterior_and_draws_equal_the_explicit_design(data, names, order):
    rng = np.random.default_rng(3)
    mask = M.mask_of(names, order)
    thetas = np.column_stack(
        [rng.normal(1.0, 1.0, (6, 2)), rng.normal(0.0, 0.05, (6, M.N_THETA - 2))]
    )
    held = rng.random(data.force.size) < 0.1
    from uq._inference.linear import map_rows, row_keys

    for d in (data, M.hold_out(data, held)):
        d = d._replace(mask=mask)
        got = np.array([float(M.log_prob(jnp.asarray(t), d)) for t in thetas])
        want = np.array([float(_explicit_log_post(jnp.asarray(t), mask, d)) for t in thetas])
        np.testing.assert_allclose(got, want, rtol=1e-10, atol=1e-6)
    # the draws' means: XF beta and XL beta of the explicit design, and every row's log-likelihood
    d = data._replace(mask=mask)
    beta = map_rows(M.draw_linear, (thetas, row_keys(jax.random.PRNGKey(0), len(thetas))), (d,))
    muF, muL, _ = map_rows(M.means, (thetas, beta), (d,))
    pw = map_rows(M.pointwise, (thetas, beta), (d,))
    ll = np.concatenate([pw["z"], pw["L"]], axis=1)
    for i, t in enumerate(thetas):
        X, y, s, XF, XL = _explicit(jnp.asarray(t), mask, data)
        np.testing.assert_allclose(
            muF[i], XF @ beta[i], rtol=1e-9, atol=1e-6 * np.max(np.abs(muF[i]))
        )
        np.testing.assert_allclose(muL[i], XL @ beta[i], rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(ll[i], gaussian_loglik(y, X @ beta[i], s), rtol=1e-9, atol=1e-9)


def test_force_noise_keeps_the_whole_pressure_term_without_a_piston():
    """z = P + cL cancels the pressure-holding error only where the piston was read on the stand
    (c > 0); a test without piston (force only, or a catalogue's volume) has c = 0, so its force
    budget keeps the whole dp F_eff term, not the DP_RESIDUAL_SHARE left after decorrelation
    (before, a clean catalogue's 0.1-bar force looked 2x noisier than its budget)."""
    from dataclasses import replace

    from uq._data.stand_description import PAPER_STAND
    from uq._stand.simulator import Layout, recordings_from_tests, simulate

    tests = simulate("n50-traditional", seed=4, layout=Layout((0.1, 5.0), 0.155, 0.065, 0.01))
    full = recordings_from_tests(tests, "with piston")
    bare = replace(full, tests=tuple(replace(t, piston_m=None) for t in full.tests))
    d_full, _ = M.prepare(full)
    d_bare, _ = M.prepare(bare)
    assert np.all(np.asarray(d_full.c) > 0) and np.all(np.asarray(d_bare.c) == 0)
    p = np.asarray(d_full.p_bar)
    # the same load-cell, displacement and floor terms; the pressure term differs by (1 - share^2)
    P_hat = np.abs(np.asarray(d_full.force))  # within a few N of the fitted quartic
    feff = P_hat / (p * BAR_PA)
    dp = np.asarray(PAPER_STAND.pressure_sd_bar(p)) * BAR_PA * feff
    extra = np.asarray(d_bare.sd_z) ** 2 - np.asarray(d_full.sd_z) ** 2
    assert np.allclose(extra, (1 - M.DP_RESIDUAL_SHARE**2) * dp**2, rtol=0.05)
