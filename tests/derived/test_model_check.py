"""The posterior-predictive check at the tested points (uq/_derived/model_check.py) and the exit
policy of an answer whose model misses its readings (uq._cli.common.misfit_status)."""

from __future__ import annotations

import argparse
from types import SimpleNamespace

import numpy as np
import pytest
from scipy import stats

from uq._cli.common import convergence_status, record_misfit
from uq._derived.model_check import ALPHA, LEVEL, limits, predictive_check, words


class FakeFit:
    """A fitted model whose posterior predictive of every reading is Normal(mean, sd) (S draws),
    with readings given: what the check sees of a fit."""

    label = "a fake model"

    def __init__(self, tests, means, sd, n_draws=400, seed=0):
        self.recordings = SimpleNamespace(tests=tests)
        rng = np.random.default_rng(seed)
        self._reps = [m + sd * rng.standard_normal((n_draws, m.size)) for m in means]

    def predictive_force_draws(self, n_draws, seed=0):
        return [r[:n_draws] for r in self._reps]


def _campaign(rng, pressures=(1.0, 3.0, 5.0, 7.0), n=19, sd=50.0, shift=None):
    tests, means = [], []
    for p in pressures:
        x = np.linspace(0.065, 0.155, n)
        mean = 2000.0 * p + 1e4 * (x - 0.11)
        y = mean + sd * rng.standard_normal(n)
        if shift is not None and p == shift[0]:
            y = y + shift[1] * sd
        tests.append(SimpleNamespace(pressure_bar=p, force_N=y, height_m=x))
        means.append(mean)
    return tests, means


def test_limits_are_the_binomial_and_the_normal_maximum():
    """inside_min: the smallest k with P(K <= k) > a, K ~ Binomial(n, 0.9); z_max: the |z| that the
    largest of n independent normal |z| exceeds with probability a (a = ALPHA / (2 T))."""
    k, z = limits(19, 4)
    a = ALPHA / 8
    b = stats.binom(19, LEVEL)
    assert b.cdf(k) > a >= b.cdf(k - 1)
    assert 1 - (1 - 2 * stats.norm.sf(z)) ** 19 == pytest.approx(a, rel=1e-9)


def test_limits_are_scipy_stats_numbers_exactly():
    """The rule is computed with scipy.special (no scipy.stats import on the commands' path): the
    same numbers as scipy.stats' binom.cdf and norm.isf, to the bit, over many sizes."""
    for n in (1, 2, 5, 19, 37, 80, 407):
        for T in (1, 3, 11):
            a = ALPHA / (2 * T)
            b = stats.binom(n, LEVEL)
            k_ref = min(k for k in range(n + 1) if b.cdf(k) > a)
            z_ref = float(stats.norm.isf((1.0 - (1.0 - a) ** (1.0 / n)) / 2.0))
            assert limits(n, T) == (k_ref, z_ref)


def test_a_model_that_is_right_passes_and_its_false_alarms_stay_within_alpha():
    """200 seeded campaigns read from the model's own predictive: the check passes in all but a
    few (ALPHA = 1 %, so at most 7 of 200: the binomial's 0.999 quantile is 7), and the fraction
    inside is about 90 %."""
    alarms, fractions = 0, []
    for seed in range(200):
        rng = np.random.default_rng(seed)
        tests, means = _campaign(rng)
        c = predictive_check(FakeFit(tests, means, 50.0, seed=seed))
        alarms += c["misses"]
        fractions += [r["fraction_inside"] for r in c["by_pressure"]]
    assert alarms <= stats.binom(200, ALPHA).ppf(0.999)
    assert np.mean(fractions) == pytest.approx(LEVEL, abs=0.02)


def test_a_model_that_misses_one_pressure_is_caught_there_and_says_so():
    """Readings 3 sd off the model's predictive at 5 bar: caught at 5 bar only, in words."""
    rng = np.random.default_rng(1)
    tests, means = _campaign(rng, shift=(5.0, 3.0))
    c = predictive_check(FakeFit(tests, means, 50.0))
    assert c["misses"] and c["missed_pressures_bar"] == [5.0]
    row = next(r for r in c["by_pressure"] if r["pressure_bar"] == 5.0)
    assert row["inside"] < row["inside_min"] and row["worst_z"] > 2.0
    assert "MISSES the readings at 5 bar" in words(c)


def test_a_model_without_replicates_is_not_checked_and_says_why():
    fit = SimpleNamespace(label="a saved model", recordings=None)
    c = predictive_check(fit)
    assert not c["available"] and not c["misses"] and "saved fit" in c["why"]
    fit = SimpleNamespace(label="a plug-in", recordings=SimpleNamespace(tests=[]))
    c = predictive_check(fit)
    assert not c["available"] and "no posterior-predictive replicates" in c["why"]


def test_a_miss_exits_1_unless_allowed(capsys):
    rng = np.random.default_rng(1)
    tests, means = _campaign(rng, shift=(5.0, 3.0))
    check = predictive_check(FakeFit(tests, means, 50.0))
    for allow, status in ((False, 1), (True, 0)):
        args = argparse.Namespace(allow_misfit=allow)
        record_misfit(args, check)
        assert convergence_status(args, "design", 0) == status
        err = capsys.readouterr().err
        assert "misses the readings (a fake model at 5 bar)" in err
        assert ("--allow-misfit to accept" in err) != allow
    args = argparse.Namespace(allow_misfit=False)
    record_misfit(args, {"misses": False})
    assert convergence_status(args, "design", 0) == 0  # a model that follows: nothing recorded
    assert convergence_status(args, "design", 2) == 2  # another failure stands
