"""The (force, piston) reading pair: the likelihood shared by the models over all tests at once.

A model of a whole campaign (the surface model, the thermodynamic model) predicts both readings
of every point linearly in its coefficients beta: force = Xf beta, piston = s Xl beta, with Xf and
Xl fixed designs and s an optional scale of the piston's travel (the thermodynamic model's
piston-area factor 1 + m; 1 otherwise). The noise is the stand's error budget (paper section
3.2): one pressure-holding error dp moves the force by +dp F_hat and the piston by
-V_gas dp / (p_abs S) at once (a higher pressure compresses the gas, so the piston stands short
of its isobaric position), so each reading pair is bivariate normal with covariance

    [[s0^2 + (r Phat)^2 + b^2,  -b c], [-b c, c^2 + sL^2]],
    b = k_p dp_i F_hat,  c = k_p dp_i V0 / (p_abs S)

with dp_i the stand's holding sd (0.01 bar, 0.001 bar at 0.1 bar), k_p its multiplier and V0
the stand's gas volume (element, receiver and pipe: in isobaric-isothermal conditions it keeps its
value, the gas/water boundary moving inside the receiver, eq. 4). The sampled noise parameters
are the logs of (s0 [N], r, k_p, sL [m], V0 [m^3]) with priors centred on the stand's description
(``--stand``; default the paper's stand): log s0 ~ N(log 10, 1.5), log r ~ N(log
stand.load_cell_rel_sd, 0.5), log k_p ~ N(0, 0.5), log sL ~ N(log 1e-4, 1.5), log V0 ~
N(log stand.gas_volume_at_xmax_m3, 0.5). Coefficients are standardised, beta ~ N(0, I).

With measured pressures (a ``set_pressure_*`` column) the readings are corrected instead,
force - dp_hat F_hat and piston + V0 dp_hat / (p_abs S) with dp_hat each reading's measured
deviation less its test's common offset (``measured_deviation``, ``readings``): linear in the
readings given V0, so still conjugate; dp_i in the covariance then shrinks to the sensor's
resolution (k_p and the coupling become negligible), and V0 is identified by the correction. The
sensor's common offset that remains per test is not modelled here (the per-pressure cubics carry
it: uq._models.cubic, its pressure-holding section).

Given the noise the coefficients are Gaussian; the Gram matrix of the whitened pair is formed from
a :class:`uq._inference.linear.GramPlan` of the fixed designs with per-reading weights, so a log
posterior costs a few weighted sums, not a (2n x k) product.
"""

from __future__ import annotations

import dataclasses
import warnings
from typing import NamedTuple

import numpy as np

from uq._data.stand_description import PAPER_STAND, StandDescription
from uq._inference.collapsed import fit_collapsed
from uq._inference.float64 import jax, jnp
from uq._inference.latent import common_offset
from uq._inference.linear import (
    LOG_2PI,
    GramPlan,
    draw_exact,
    gram_plan,
    posterior_cov,
    posterior_from_moments,
    reading_forms,
    weighted_gram,
)
from uq._inference.loo import loglik_idata
from uq._inference.sampler import INDEPENDENCE_MIX
from uq._models.saved import provenance_of
from uq._physics.quantities import BAR_PA, force_noise_var

NOISE_NAMES = ("log_s0_N", "log_rel_load", "log_k_p", "log_sL_m", "log_V0_m3")
#: the natural noise parameters reported (exp of the sampled logs)
NATURAL_NAMES = ("s0_N", "rel_load", "k_p", "sL_m", "V0_m3")
NOISE_PRIOR_SD = np.array([1.5, 0.5, 0.5, 1.5, 0.5])


def noise_prior_mean(stand: StandDescription = PAPER_STAND) -> np.ndarray:
    """Prior centres of the five noise logs from the stand's description (a stand declaring a
    perfect load cell still gets a 0.01 % floor: log 0 has no prior)."""
    rel = max(stand.load_cell_rel_sd, 1e-4)
    return np.array(
        [np.log(10.0), np.log(rel), 0.0, np.log(1e-4), np.log(stand.gas_volume_at_xmax_m3)]
    )


class PairData(NamedTuple):
    """A campaign's arrays for the pair likelihood (n readings, k coefficients)."""

    Xf: jnp.ndarray  # (n, k) force design (standardised coefficients)
    Xl: jnp.ndarray  # (n, k) piston design
    F: jnp.ndarray  # (n,) force, N
    L: jnp.ndarray  # (n,) piston coordinate, m
    phat: jnp.ndarray  # (n,) reference force of the load-cell term, N
    feff_hat: jnp.ndarray  # (n,) the lever of a pressure error on the force, dP/dp_u, m^2
    dp_pa: jnp.ndarray  # (n,) the stand's pressure-holding sd, Pa
    p_abs_pa: jnp.ndarray  # (n,) absolute pressure, Pa
    area: jnp.ndarray  # () piston area S, m^2
    prior_mean: jnp.ndarray  # (5,) prior centres of the noise logs
    gram: GramPlan  # the Gram matrix's plan (``posterior``)
    weight: jnp.ndarray  # (n,) 1 = the reading informs the fit, 0 = held out
    #: (n,) measured pressure deviation of each reading, Pa (``measured_deviation``; zeros when
    #: the recordings give set pressures only): the readings are corrected by it (``readings``)
    dp_meas: jnp.ndarray


def holding_sd_Pa(p_bar, stand: StandDescription, *, measured: bool, shape) -> np.ndarray:
    """The sd (Pa) of each reading's pressure-holding error the likelihood carries: the stand's
    holding error at the set pressures ``p_bar``, or, where the readings are corrected by their
    measured pressures, the rounding of the stand's pressure sensor (uniform over its resolution,
    1 Pa on the paper's stand: sd 1/sqrt(12) Pa)."""
    if measured:
        return np.full(shape, stand.pressure_sensor_resolution_pa / np.sqrt(12.0))
    return np.broadcast_to(stand.pressure_sd_bar(np.asarray(p_bar, float)) * BAR_PA, shape)


def pair_data(
    Xf, Xl, F, L, phat, lever, p_bar, area, stand: StandDescription, dp_meas=None
) -> PairData:
    """The pair likelihood's arrays from the designs, the readings and plug-in noise references.

    ``dp_meas`` (n,) Pa: each reading's measured pressure deviation (``measured_deviation``), or
    None. Where given, the readings are corrected by it and the pressure-holding term of the
    covariance shrinks to the sensor's resolution (:func:`holding_sd_Pa`)."""
    hold_pa = holding_sd_Pa(p_bar, stand, measured=dp_meas is not None, shape=np.shape(F))
    dp_meas = np.zeros(np.shape(F)) if dp_meas is None else np.asarray(dp_meas, float)
    return PairData(
        jnp.asarray(Xf),
        jnp.asarray(Xl),
        jnp.asarray(F),
        jnp.asarray(L),
        jnp.asarray(phat),
        jnp.asarray(lever),
        jnp.asarray(hold_pa),
        jnp.asarray((p_bar + stand.p_atm_bar) * BAR_PA),
        jnp.asarray(area),
        jnp.asarray(noise_prior_mean(stand)),
        gram_plan([[(Xf, Xf)], [(Xl, Xl)], [(Xl, Xf), (Xf, Xl)]], symmetric=True),
        jnp.ones(np.size(F)),
        jnp.asarray(dp_meas),
    )


def measured_deviation(rec, stand: StandDescription = PAPER_STAND):
    """Each reading's measured pressure deviation (Pa), in ``arrays`` order, or None when the
    recordings give set pressures only: measured - set less the test's common offset's prior mean
    (``uq._inference.latent.common_offset``: the sensor's gain error and the series' mean).
    The common offset that remains (sd ``common_offset``'s second value, about 0.015 % of p_u from
    5 bar up) is not modelled here, unlike in the per-pressure cubics."""
    if not rec.pressure_measured:
        return None
    out = []
    for t in rec.tests:
        dp_hat = (np.asarray(t.measured_pressure_bar, float) - t.pressure_bar) * BAR_PA
        offset = common_offset(
            dp_hat, t.pressure_bar * BAR_PA, ordered=t.step is not None, stand=stand
        )
        out.append(dp_hat - offset[0])
    return np.concatenate(out)


def readings(noise, d: PairData):
    """The readings corrected by the measured pressure deviations (unchanged without them): the
    force less dp F_hat (the plug-in lever dP/dp_u), the piston plus V0 dp / (p_abs S) (Boyle, with
    the sampled gas volume V0): linear in the readings given the noise, so beta stays conjugate."""
    V0 = jnp.exp(noise[4])
    return d.F - d.feff_hat * d.dp_meas, d.L + V0 * d.dp_meas / (d.p_abs_pa * d.area)


def cov_factors(noise, d: PairData):
    """Per-point whitening of the (force, piston) pair: (L11, L21, L22), each (n,); noise (5,)."""
    s0, rel, kp, sL, V0 = (jnp.exp(noise[i]) for i in range(5))
    a2 = force_noise_var(s0, rel, d.phat)
    b = kp * d.dp_pa * d.feff_hat
    cc = kp * d.dp_pa * V0 / (d.p_abs_pa * d.area)
    L11 = jnp.sqrt(a2 + b**2)
    L21 = -b * cc / L11  # pressure error: force up, piston down (anti-correlated)
    L22 = jnp.sqrt(cc**2 + sL**2 - L21**2)
    return L11, L21, L22


def posterior(noise, d: PairData, scale=1.0):
    """The coefficients' Gaussian posterior given the noise (log_marginal includes the readings'
    covariance determinant), with the piston design scaled by ``scale``.

    Whitening reading i, a = xf / L11 and b = xl / L22 - s xf with s = L21 / (L11 L22), makes the
    Gram matrix  Xf^T diag(1/L11^2 + s^2) Xf + Xl^T diag(1/L22^2) Xl - (Xl^T diag(s/L22) Xf + its
    transpose): three weight vectors on designs that do not change while sampling. A held-out
    reading (weight 0) drops out of every sum.
    """
    L11, L21, L22 = cov_factors(noise, d)
    F, L = readings(noise, d)
    w = d.weight
    s = L21 / (L11 * L22)
    yf = F / L11
    yl = (L - L21 * yf) / L22
    gram = weighted_gram(
        d.gram, (w * (1.0 / L11**2 + s**2), w * scale**2 / L22**2, -w * scale * s / L22)
    )
    rhs = d.Xf.T @ (w * (yf / L11 - s * yl)) + scale * (d.Xl.T @ (w * yl / L22))
    log_det = 2.0 * jnp.sum(w * (jnp.log(L11) + jnp.log(L22)))
    return posterior_from_moments(
        gram, rhs, jnp.sum(w * (yf**2 + yl**2)), 2 * jnp.sum(w), log_det, jnp.ones(d.Xf.shape[1])
    )


def log_prior(noise, d: PairData):
    z = (noise - d.prior_mean) / NOISE_PRIOR_SD
    return -0.5 * jnp.sum(z**2)


def draw(noise, key, d: PairData, scale=1.0):
    return draw_exact(posterior(noise, d, scale), key)


def pointwise(noise, beta, d: PairData, scale=1.0):
    """Log-likelihood of each (force, piston) reading at one draw, (n,)."""
    L11, L21, L22 = cov_factors(noise, d)
    F, L = readings(noise, d)
    r1 = (F - d.Xf @ beta) / L11
    r2 = (L - scale * (d.Xl @ beta) - L21 * r1) / L22
    return -0.5 * (r1**2 + r2**2) - jnp.log(L11) - jnp.log(L22) - LOG_2PI


def predict(noise, beta, key, d: PairData, scale=1.0):
    """A replicate of every reading: the mean surfaces plus the correlated reading noise."""
    L11, L21, L22 = cov_factors(noise, d)
    z = jax.random.normal(key, (2, d.F.shape[0]))
    F, L = readings(noise, d)  # the replicate is of the readings as read: at the same pressures
    return {
        "force_N": d.Xf @ beta + (d.F - F) + L11 * z[0],
        "piston_m": scale * (d.Xl @ beta) + (d.L - L) + L21 * z[0] + L22 * z[1],
    }


def block_loo(X, y, n, chol, mean):
    """log N of each whitened 2-row block (rows i, n+i) under the predictive from the other blocks.

    With unit whitened noise and posterior precision A = L L^T, leaving block i out gives the
    predictive N(X_i m_-i, (I - H_i)^-1) with H_i = X_i A^-1 X_i^T, and y_i - X_i m_-i =
    (I - H_i)^-1 (y_i - X_i m) (Woodbury): no refit needed.
    """
    Z = jax.scipy.linalg.solve_triangular(chol, X.T, lower=True)
    Zf, Zl = Z[:, :n], Z[:, n:]
    a, e, b = 1.0 - jnp.sum(Zf**2, 0), 1.0 - jnp.sum(Zl**2, 0), -jnp.sum(Zf * Zl, 0)
    r = y - X @ mean
    return block_logpdf(a, e, b, r[:n], r[n:])


def block_logpdf(a, e, b, r1, r2):
    """log N((r1, r2); 0, M^-1) of each reading's whitened pair of residuals, M = [[a, b], [b, e]]
    (I - H_i, the precision of its leave-one-out predictive), (n,) each."""
    det = a * e - b * b
    quad = (e * r1**2 - 2.0 * b * r1 * r2 + a * r2**2) / det
    return -0.5 * quad + 0.5 * jnp.log(det) - LOG_2PI


def pointwise_loo(noise, d: PairData, scale=1.0):
    """log p(force_i, piston_i | noise, all other readings), coefficients integrated out, (n,).

    PSIS-LOO over the noise draws with these (instead of the pointwise likelihood at drawn
    coefficients) importance-samples only the noise parameters, which one reading hardly moves;
    the coefficients' leave-one-out is exact. Same ELPD, far smaller Pareto k.

    :func:`block_loo` on the whitened pair, its leverages H_i = X_i A^-1 X_i^T formed from the
    quadratic forms xf' A^-1 xf, xl' A^-1 xl, xf' A^-1 xl of the unwhitened designs' rows, which
    the Gram plan's column products give in n m operations (``reading_forms``) where a triangular
    solve with every row costs n k^2 (tested against :func:`block_loo`).
    """
    L11, L21, L22 = cov_factors(noise, d)
    F, L = readings(noise, d)
    post = posterior(noise, d, scale)
    qff, qll, qfl2 = reading_forms(d.gram, posterior_cov(post))
    c = L21 / L11
    hff = qff / L11**2
    hll = (scale**2 * qll - scale * c * qfl2 + c**2 * qff) / L22**2
    hfl = (0.5 * scale * qfl2 - c * qff) / (L11 * L22)
    mf = d.Xf @ post.mean
    yf = F / L11
    r1 = yf - mf / L11
    r2 = (L - L21 * yf) / L22 - (scale * (d.Xl @ post.mean) - c * mf) / L22
    return block_logpdf(1.0 - hff, 1.0 - hll, -hfl, r1, r2) - jnp.log(L11) - jnp.log(L22)


def observed(d: PairData) -> dict:
    return {"force_N": np.asarray(d.F), "piston_m": np.asarray(d.L)}


def force_arrays(rec):
    """Every force reading of a campaign: height (m), set pressure (bar), force (N)."""
    x = np.concatenate([t.height_m for t in rec.tests])
    p = np.concatenate([np.full(t.n_points, t.pressure_bar) for t in rec.tests])
    return x, p, np.concatenate([t.force_N for t in rec.tests])


def arrays(rec):
    """Every reading of a campaign: height (m), set pressure (bar), force, piston, test index."""
    tests = rec.tests
    L = np.concatenate([t.piston_m for t in tests])
    idx = np.concatenate([np.full(t.n_points, i) for i, t in enumerate(tests)])
    return (*force_arrays(rec), L, idx)


def campaign_data(rec, stand: StandDescription, area_m2, designs, lever) -> PairData:
    """A campaign's arrays for a model of force and piston over all its tests: the designs
    (``designs(x, p, idx, n_tests)`` -> Xf, Xl), the readings, and the noise references from a
    weighted least-squares fit of the same model (:func:`reference_fit`): its force, and
    ``lever(x, p, beta)`` (the force's lever of a pressure-holding error)."""
    x, p, F, L, idx = arrays(rec)
    Xf, Xl = designs(x, p, idx, len(rec.tests))
    beta = reference_fit(Xf, F, Xl, L)
    phat, lever = np.abs(Xf @ beta), np.abs(lever(x, p, beta))
    return pair_data(Xf, Xl, F, L, phat, lever, p, area_m2, stand, measured_deviation(rec, stand))


def reference_fit(Xf, F, Xl=None, L=None) -> np.ndarray:
    """The coefficients of a weighted least-squares fit of the force (and the piston), whose
    curves are the plug-in references of the noise terms: force sd 0.5 % + 20 N, piston sd 1 mm."""
    wf = 1.0 / (0.005 * np.abs(F) + 20.0)
    if Xl is None:
        return np.linalg.lstsq(Xf * wf[:, None], F * wf, rcond=None)[0]
    wl = np.full_like(L, 1.0 / 1e-3)
    A = np.concatenate([Xf * wf[:, None], Xl * wl[:, None]])
    return np.linalg.lstsq(A, np.concatenate([F * wf, L * wl]), rcond=None)[0]


def fit_over_tests(
    cls,
    model,
    data,
    rec,
    orders,
    geometry,
    *,
    seed,
    settings,
    max_draws,
    stand,
    desc,
    sampler_settings=None,
    mix=INDEPENDENCE_MIX,
    proposal="half",
    importance=False,
):
    """``cls.from_posterior`` of the one driver's fit of ``model`` to ``data`` (one problem, the
    seed's exact draws, no replicates until asked for), with the fit's provenance. ``mix``: the
    sampler's moves (``uq._inference.sampler.INDEPENDENCE_MIX`` unless the model says otherwise),
    ``proposal`` how its independence move fits its proposal (``uq._inference.sampler.run_many``),
    ``importance`` whether importance sampling is tried first (``fit_collapsed``)."""
    post = fit_collapsed(
        model,
        data,
        seed=seed,
        settings=sampler_settings or settings,
        max_draws=max_draws,
        seeds=[seed],
        predictive=False,  # 2 x n replicates per draw: made when asked for, not on every fit
        desc=desc,
        mix=mix,
        proposal=proposal,
        importance=importance,
    )
    prov = provenance_of(rec, seed=seed, settings=settings, stand=stand)
    return cls.from_posterior(post, rec, orders, geometry, stand, provenance=prov)


def select_orders(fitter, rec, candidates, *, seed: int, settings, stand):
    """Fit ``fitter(rec, orders, seed=, settings=, stand=)`` for each candidate and rank them by
    PSIS-LOO per reading (ArviZ's compare); returns (the best fit with its ``selection``, rows)."""
    # reason: ArviZ (and xarray under it) costs about a second to import; only this ranking needs it
    import arviz as az

    fits = {o.label: fitter(rec, o, seed=seed, settings=settings, stand=stand) for o in candidates}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)
        cmp = az.compare({k: loglik_idata(f.loglik_loo) for k, f in fits.items()}, ic="loo")
    rows = [
        {
            "orders": k,
            "elpd_loo": float(r["elpd_loo"]),
            "p_loo": float(r["p_loo"]),
            "elpd_diff": float(r["elpd_diff"]),
            "dse": float(r["dse"]),
            "rank": int(r["rank"]),
            "warning": bool(r["warning"]),
        }
        for k, r in cmp.iterrows()
    ]
    return dataclasses.replace(fits[cmp.index[0]], selection=tuple(rows)), rows
