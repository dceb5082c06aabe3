"""``fit_both``'s cubics fitted in a worker process beside the model and compared with it there
(``jobs``): the same fits and comparison, to the bit, as fitted in this process with the same
seed; ``fitting_both`` hands the model's fit over before the comparison is done."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from uq._data.stand_description import PAPER_STAND
from uq._derived import comparison, comparison_worker
from uq._inference.sampler import Settings
from uq._io.files import dumps_json

SHORT = Settings(max_steps=200)  # draws of the right shape; their convergence does not matter


def _arrays(cub):
    for t in cub.tests:
        p = t.posterior
        yield from (p.theta, p.beta, *p.reported.values(), p.loglik_total(), p.loglik_loo)


def test_cubics_fitted_in_a_worker_are_those_fitted_here(small_campaign, monkeypatch):
    def both(jobs):
        return comparison.fit_both(
            small_campaign, seed=4, settings=SHORT, stand=PAPER_STAND, model="surface", jobs=jobs
        )

    here = both(1)
    monkeypatch.setattr(comparison_worker, "WORKER_MIN_READINGS", 0)  # the small campaign
    started, beside = [], comparison_worker.Beside
    monkeypatch.setattr(
        comparison_worker, "Beside", lambda *a, **k: started.append(a[0]) or beside(*a, **k)
    )
    there = both(2)
    assert started, "the cubics were not fitted in a worker"
    assert there[2] == here[2]  # the comparison document, every float to the bit
    assert here[1].tests[0].posterior is not there[1].tests[0].posterior
    for a, b in zip(_arrays(here[1]), _arrays(there[1]), strict=True):
        np.testing.assert_array_equal(a, b)
    for a, b in zip(here[1].tests, there[1].tests, strict=True):
        assert a.convergence.converged == b.convergence.converged
    assert dumps_json(here[1].to_json()) == dumps_json(there[1].to_json())


def test_fitting_both_gives_the_fit_first_and_the_same_comparison(small_campaign, monkeypatch):
    """The caller works with the model's fit while the worker compares; what it then gets is
    fit_both's, and a worker that fails says so here."""
    kw = {"seed": 4, "settings": SHORT, "stand": PAPER_STAND, "model": "surface"}
    monkeypatch.setattr(comparison_worker, "WORKER_MIN_READINGS", 0)
    here = comparison.fit_both(small_campaign, jobs=1, **kw)
    with comparison.fitting_both(small_campaign, jobs=2, **kw) as (fit, compared):
        assert fit.name == "surface" and fit.posterior is not None  # before any comparison
        np.testing.assert_array_equal(fit.posterior.theta, here[0].posterior.theta)
        cub, doc = compared()
        assert compared()[1] is doc  # computed once
    assert doc == here[2]
    assert dumps_json(cub.to_json()) == dumps_json(here[1].to_json())


def test_a_comparison_that_fails_in_the_worker_is_raised_here(small_campaign, monkeypatch):
    monkeypatch.setattr(comparison_worker, "WORKER_MIN_READINGS", 0)
    send = comparison_worker._send  # the worker is sent what it cannot compare
    monkeypatch.setattr(comparison_worker, "_send", lambda conn, fit: send(conn, "not a fit"))
    kw = {"seed": 4, "settings": SHORT, "stand": PAPER_STAND, "model": "surface"}
    with comparison.fitting_both(small_campaign, jobs=2, **kw) as (fit, compared):
        with pytest.raises(AttributeError, match="'str' object has no attribute"):
            compared()


def test_a_worker_started_first_gives_the_same_fits(small_campaign):
    """A command starts the worker before it imports JAX (comparison_worker.start) and hands it
    to fitting_both: the same comparison as a worker fitting_both starts itself."""
    kw = {"seed": 4, "settings": SHORT, "stand": PAPER_STAND}
    here = comparison.fit_both(small_campaign, jobs=1, model="surface", **kw)
    worker = comparison_worker.ComparisonWorker(small_campaign, **kw)  # whatever its size
    with worker:
        there = comparison.fit_both(small_campaign, model="surface", worker=worker, **kw)
    assert there[2] == here[2]
    assert dumps_json(there[1].to_json()) == dumps_json(here[1].to_json())


def test_the_worker_is_named_and_started_without_jax():
    """The module that starts the worker imports neither JAX nor the models: a command starts it
    first, and the worker's imports run beside its own."""
    code = (
        "import sys, uq._derived.comparison_worker as w; "
        "print(sorted(m for m in ('jax', 'uq._derived.comparison', 'uq._models.cubic_fit') "
        "if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
