"""``fit_both``'s cubics fitted in a worker process beside the model (``jobs``): the same fits and
comparison, to the bit, as fitted in this process with the same seed."""

from __future__ import annotations

import numpy as np

from uq._data.stand_description import PAPER_STAND
from uq._derived import comparison
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
    monkeypatch.setattr(comparison, "WORKER_MIN_READINGS", 0)  # the small campaign: a worker
    started, beside = [], comparison.Beside
    monkeypatch.setattr(comparison, "Beside", lambda *a: started.append(a[0]) or beside(*a))
    there = both(2)
    assert started, "the cubics were not fitted in a worker"
    assert there[2] == here[2]  # the comparison document, every float to the bit
    assert here[1].tests[0].posterior is not there[1].tests[0].posterior
    for a, b in zip(_arrays(here[1]), _arrays(there[1]), strict=True):
        np.testing.assert_array_equal(a, b)
    for a, b in zip(here[1].tests, there[1].tests, strict=True):
        assert a.convergence.converged == b.convergence.converged
    assert dumps_json(here[1].to_json()) == dumps_json(there[1].to_json())
