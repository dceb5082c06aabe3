"""The convergence statistics in numpy (uq/_inference/convergence.py) are ArviZ's: R-hat, ESS and
MCSE of the mean on the project's chains, compared with ArviZ itself on chains of every kind a
run can give (independent, autocorrelated, sticky with repeated values, drifting, short, odd
lengths, constant, with a NaN)."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from uq._inference import convergence as C


def _chains(rng, C_, T, W, rho=0.0, sticky=0.0):
    """(C, T * W) in storage order: W walkers an AR(1) series each, repeating a value with
    probability ``sticky`` (a rejected move)."""
    x = np.zeros((C_, T, W))
    e = rng.standard_normal((C_, T, W))
    x[:, 0] = e[:, 0]
    for t in range(1, T):
        x[:, t] = rho * x[:, t - 1] + np.sqrt(1 - rho**2) * e[:, t]
        stay = rng.random((C_, W)) < sticky
        x[:, t][stay] = x[:, t - 1][stay]
    return x.reshape(C_, T * W)


def _arviz(x: np.ndarray, n_walkers: int) -> dict:
    """The statistics of one scalar as ArviZ computes them (the project's definitions in the
    module docstring: R-hat of the draws, ESS of the ensemble-mean chains)."""
    import arviz as az
    from scipy import stats

    def of_summary(v, per_step):
        var_m = float(np.var(per_step))
        if not var_m > 0:
            return float("nan")
        ess_m = float(az.ess(np.ascontiguousarray(per_step), method="mean"))
        return min(ess_m * float(np.var(v)) / var_m, float(v.size))

    steps = x.reshape(x.shape[0], -1, n_walkers)
    ranks = stats.rankdata(x, axis=None).reshape(x.shape)
    z = stats.norm.ppf((ranks - 0.375) / (x.size + 0.25))
    tail = []
    for q in (0.05, 0.95):
        ind = (x <= np.quantile(x, q)).astype(float)
        tail.append(of_summary(ind, ind.reshape(steps.shape).mean(axis=2)))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return {
            "r_hat": float(az.rhat(np.ascontiguousarray(x))),
            "ess_bulk": of_summary(z, z.reshape(steps.shape).mean(axis=2)),
            "ess_tail": float(np.min(tail)),
            "mcse_mean": float(az.mcse(np.ascontiguousarray(steps.mean(axis=2)), method="mean")),
        }


CASES = {
    "independent": dict(C_=4, T=250, W=32),
    "autocorrelated": dict(C_=4, T=250, W=32, rho=0.9),
    "sticky": dict(C_=4, T=300, W=8, rho=0.5, sticky=0.7),
    "very sticky": dict(C_=4, T=400, W=8, sticky=0.97),
    "odd length": dict(C_=3, T=101, W=4, rho=0.8),
    "short": dict(C_=2, T=3, W=4, rho=0.3),
    "too short": dict(C_=2, T=2, W=4),
    "one chain": dict(C_=1, T=100, W=8, rho=0.5),
}


@pytest.mark.parametrize("case", list(CASES))
def test_statistics_are_arviz_s(case):
    rng = np.random.default_rng(list(CASES).index(case))
    W = CASES[case]["W"]
    x = _chains(rng, **CASES[case])
    if case == "independent":  # and a drift: the split R-hat must see it
        x = x + np.linspace(0.0, 0.5, x.shape[1])
    want, got = _arviz(x, W), C.chain_diagnostics(x, W)
    for k, v in want.items():
        if np.isnan(v):
            assert np.isnan(got[k]), (k, got[k])
        else:
            assert got[k] == pytest.approx(v, rel=1e-9, abs=1e-12), k


def test_constant_and_nan_draws_are_undefined_as_in_arviz():
    rng = np.random.default_rng(7)
    const = np.ones((4, 64))
    nan = rng.standard_normal((4, 64))
    nan[1, 5] = np.nan
    for x in (const, nan):
        want, got = _arviz(x, 8), C.chain_diagnostics(x, 8)
        for k, v in want.items():
            assert (np.isnan(v) and np.isnan(got[k])) or got[k] == pytest.approx(v), (k, v, got[k])


def test_many_scalars_at_once_equal_one_at_a_time():
    """``diagnostics`` vectorised over scalars gives each scalar's own numbers."""
    rng = np.random.default_rng(3)
    xs = np.stack([_chains(rng, 4, 60, 8, rho=r) for r in (0.0, 0.5, 0.95)])
    many = C.diagnostics(xs, 8)
    for i, x in enumerate(xs):
        one = C.chain_diagnostics(x, 8)
        for k in one:
            assert many[k][i] == pytest.approx(one[k], rel=1e-12)
