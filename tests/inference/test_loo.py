"""The one remedy for a comparison PSIS-LOO cannot be trusted with (uq._inference.loo.remedy),
used by the model comparison and the discrepancy engine: exact refits of the unreliable terms up
to MAX_REFITS of them in a model, K-fold of both models beyond."""

from __future__ import annotations

import numpy as np

from uq._inference import loo as L


def _loo(n_bad: int, n: int = 60, value: float = -1.0) -> L.Loo:
    k = np.zeros(n)
    k[:n_bad] = 0.9
    return L.Loo(np.full(n, value), k)


def test_reliable_terms_are_kept():
    a, b, how = L.remedy(_loo(0), _loo(0), refit=(None, None), kfold_both=None)
    assert how == "psis-loo" and a.elpd == -60.0 and b.elpd == -60.0


def test_a_few_unreliable_terms_are_refitted_exactly():
    calls = []

    def refit(i):
        calls.append(i)
        return -2.0

    a, b, how = L.remedy(_loo(3), _loo(0), refit=(refit, None), kfold_both=None)
    assert calls == [0, 1, 2] and a.reliable and a.n_refits == 3 and a.elpd == -63.0
    assert how.startswith("psis-loo, k > 0.7 terms refitted exactly") and b.elpd == -60.0
    # a model that offers no refit keeps its unreliable terms: the verdict stays refused
    a, b, _ = L.remedy(_loo(0), _loo(2), refit=(refit, None), kfold_both=None)
    assert not b.reliable and L.verdict(a, b, ("a", "b"))["better"] == "refused"


def test_many_unreliable_terms_send_both_models_to_kfold():
    folds = L.Loo(np.full(60, -1.5), np.zeros(60), "10-fold cross-validation")

    def refit(i):
        raise AssertionError("no refits beyond MAX_REFITS")

    a, b, how = L.remedy(
        _loo(L.MAX_REFITS + 1), _loo(0), refit=(refit, refit), kfold_both=lambda: (folds, folds)
    )
    assert a is folds and b is folds and how == "10-fold cross-validation"
    a, b, how = L.remedy(_loo(L.MAX_REFITS + 1), _loo(0), refit=(refit, refit), kfold_both=None)
    assert not a.reliable and "not refitted" in how


def test_kfold_holds_every_term_out_once():
    held_counts = np.zeros(25, int)

    def score(held):
        held_counts[held] += 1
        return np.where(held, -1.0, np.nan)

    res = L.kfold(25, score, n_folds=5, seed=3)
    assert (
        np.all(held_counts == 1) and res.elpd == -25.0 and res.method == "5-fold cross-validation"
    )


def test_an_undefined_pareto_k_is_unreliable_and_json_safe():
    """ArviZ returns k = inf where it cannot fit the tail: such a term counts as over 0.7, and the
    summary a command writes as JSON carries no infinity (it failed json.dumps(allow_nan=False))."""
    import json

    k = np.array([0.1, np.inf, 0.8, 0.2])
    summary = L.Loo(loo_i=np.zeros(4), pareto_k=k).pareto()
    assert summary == {"max": None, "n_over_0.7": 2, "n_undefined": 1, "n_terms": 4}
    json.dumps(summary, allow_nan=False)
    assert L.Loo(loo_i=np.zeros(2), pareto_k=np.array([0.1, 0.3])).pareto()["max"] == 0.3
