"""A model over all tests against the per-pressure cubics: one workflow, one set of cubic settings.

``uq surface``, ``uq report --surface`` and ``uq margin`` all ask the same question: do the
recordings prefer one smooth model over height and pressure (a model of the registry over all
tests, ``uq._models.registry``: the surface, the thermodynamic potential, one plugged in) or an
independent cubic per tested pressure (``uq._models.cubic``, eqs. 8, 9)? :func:`compare` answers
it the same way for all of them:

* Both models are linear in their coefficients given the noise, so each reading's leave-one-out
  density given the noise is exact (the models' ``pointwise_loo``) and PSIS only reweights the
  noise draws (``uq._inference.loo.psis``); the plain PSIS-LOO at drawn coefficients is reported
  beside it.
* Readings still at Pareto k > 0.7 are dealt with by the one remedy (``uq._inference.loo.remedy``):
  up to ``MAX_REFITS`` of them in a model, the cubics' are replaced by exact refits of their test
  without the reading (a refit of the model over all tests takes minutes: its unreliable readings
  stay so and refuse a verdict); more, both models are scored by 10-fold cross-validation on the
  same folds of readings, each refitted by its Laplace approximation.
* The verdict (``uq._inference.loo.verdict``): a model is named only beyond 2 SE and 4 nats with
  every Pareto k <= 0.7; otherwise "indistinguishable" or "refused".

:func:`fit_both` fits what a comparison needs with one set of sampler settings, the caller's;
:func:`fit_and_choose` is ``uq margin``'s: fit, compare, and choose the answering model
(``uq._derived.margin.choose``).
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools

import numpy as np
from scipy.special import logsumexp

from uq._data.stand_description import PAPER_STAND
from uq._derived import comparison_worker
from uq._derived.margin import AUTO, choose
from uq._inference.collapsed import fit_collapsed
from uq._inference.convergence import CLI_ADVICE
from uq._inference.loo import (
    MAX_REFITS,
    PARETO_K_MAX,
    Loo,
    held_out_density,
    kfold,
    psis,
    reloo,
    remedy,
    verdict,
)
from uq._inference.sampler import Settings
from uq._models import registry
from uq._models.cubic_fit import collapsed_model, fit_campaign


def _concat(parts) -> np.ndarray:
    """Pointwise arrays (C, D_i, n_i) of the tests side by side on their common draws."""
    C = min(p.shape[0] for p in parts)
    D = min(p.shape[1] for p in parts)
    return np.concatenate([p[:C, :D] for p in parts], axis=-1)


def _lppd(loglik) -> float:
    """The log pointwise predictive density at the drawn coefficients, summed over readings."""
    ll = np.asarray(loglik).reshape(-1, np.shape(loglik)[-1])
    return float(np.sum(logsumexp(ll, axis=0) - np.log(ll.shape[0])))


def _part(loo: Loo, n_coefficients: int, lppd: float) -> dict:
    """One model's LOO in the JSON; p_loo = lppd (at the drawn coefficients) - elpd_loo."""
    return {
        "elpd_loo": loo.elpd,
        "se": loo.se,
        "p_loo": lppd - loo.elpd,
        "max_pareto_k": float(np.max(loo.pareto_k)),
        "n_pareto_k_above_0.7": loo.n_bad,
        "n_coefficients": int(n_coefficients),
    }


def _cubic_refit(cubic_fit, settings: Settings, seed: int):
    """``refit(j)``: log p(reading j | its test's other readings), the test refitted without it
    (with the test's own variant of the cubics: the force-only one for a test without piston)."""
    offsets = np.cumsum([0] + [t.test.n_points for t in cubic_fit.tests])

    def refit(j: int) -> float:
        ti = int(np.searchsorted(offsets, j, side="right") - 1)
        i = j - int(offsets[ti])
        data = cubic_fit.tests[ti].posterior.data
        model = collapsed_model(data)  # the test's own variant (force-only, measured, ...)
        held = np.arange(data.force.shape[0]) == i
        post = fit_collapsed(
            model, model.hold_out(data, held), seed=seed + j, settings=settings, predictive=False
        )
        return float(held_out_density(post.loglik_total(), [i])[0])

    return refit


def _kfold_both(model_fit, cubic_fit, *, seed: int):
    """``kfold_both()`` of :func:`uq._inference.loo.remedy`: 10-fold cross-validation of both
    models on the same folds of readings, each fold held out of both and every model refitted by
    its Laplace approximation (MAP, Laplace draws of the sampled parameters, exact coefficient
    draws), the held-out readings scored by their log predictive density."""
    offsets = np.cumsum([0] + [t.test.n_points for t in cubic_fit.tests])
    n = int(offsets[-1])

    def refit(model, data, held, s):
        post = fit_collapsed(
            model, model.hold_out(data, held), seed=s, method="laplace", predictive=False
        )
        return held_out_density(post.loglik_total(), np.flatnonzero(held))

    def score_model(held):
        out = np.full(n, np.nan)
        out[held] = refit(model_fit.collapsed(), model_fit.posterior.data, held, seed)
        return out

    def score_cubics(held):
        out = np.full(n, np.nan)
        for i, t in enumerate(cubic_fit.tests):
            h = held[offsets[i] : offsets[i + 1]]
            if h.any():
                data = t.posterior.data
                out[offsets[i] : offsets[i + 1]][h] = refit(
                    collapsed_model(data), data, h, seed + i
                )
        return out

    return lambda: (kfold(n, score_model, seed=seed), kfold(n, score_cubics, seed=seed))


def force_side(rec):
    """The recordings the per-pressure cubics are fitted to for a comparison: ``rec`` itself, or,
    for a campaign with a volume column but no piston (a catalogue table), ``rec`` without its
    volume column: the force surface leaves the volume out, so both models are compared on the
    force readings alone."""
    if rec.has_piston or not rec.has_volume:
        return rec
    return dataclasses.replace(
        rec, tests=tuple(dataclasses.replace(t, volume_m3=None) for t in rec.tests)
    )


def cubic_terms(cubic_fit, *, seed: int, settings: Settings) -> tuple[Loo, Loo, float, Loo | None]:
    """The cubics' side of :func:`compare`, which needs no model fit (a worker makes it while the
    model is fitted): their PSIS-LOO, their plain PSIS-LOO at the drawn coefficients, their lppd,
    and their PSIS-LOO with its terms of Pareto k > 0.7 refitted exactly (the remedy's refits;
    None where there are more than ``MAX_REFITS``, whose remedy is K-fold)."""
    plain = _concat([t.posterior.loglik_total() for t in cubic_fit.tests])
    loo = psis(_concat([t.posterior.loglik_loo for t in cubic_fit.tests]))
    refitted = None
    if loo.n_bad <= MAX_REFITS:
        refitted = reloo(loo, _cubic_refit(cubic_fit, settings, seed))
    return loo, psis(plain), _lppd(plain), refitted


def compare(
    surface_fit,
    cubic_fit,
    *,
    seed: int = 0,
    settings: Settings = Settings(),
    cubic_side: tuple[Loo, Loo, float, Loo | None] | None = None,
) -> dict:
    """PSIS-LOO of a model over all tests (its registry ``name`` keys the document) against the
    per-pressure cubics, per (force, piston) reading (module docstring); the ``comparison``
    document of the JSON results. ``cubic_side``: :func:`cubic_terms` of ``cubic_fit``, when
    already made."""
    name = surface_fit.name
    if getattr(surface_fit, "posterior", None) is None:  # a model plugged in without one
        return {
            "model": name,
            "better": "refused",
            "reason": f"the {name} model gives no pointwise log-likelihoods (no posterior) to rank it by",
        }
    force_only = not surface_fit.recordings.has_piston  # the force surface: per force reading
    if force_only and any(t.has_piston for t in cubic_fit.tests):
        raise ValueError(
            "the force surface is compared with cubics fitted to the force alone (force_side)"
        )
    loo_c, plain_c, lppd_c, refitted = cubic_side or cubic_terms(
        cubic_fit, seed=seed, settings=settings
    )
    sur_plain = surface_fit.posterior.loglik_total()
    n_s, n_c = surface_fit.n_coefficients, 8 * len(cubic_fit.tests)
    if force_only:
        n_c = sum(t.posterior.beta.shape[-1] for t in cubic_fit.tests)
    loo_s = psis(surface_fit.loglik_loo)
    k_psis = float(np.max(loo_c.pareto_k))
    loo_s, loo_c, how = remedy(
        loo_s,
        loo_c,
        refit=(None, None if refitted is None else lambda j: float(refitted.loo_i[j])),
        kfold_both=_kfold_both(surface_fit, cubic_fit, seed=seed),
    )
    plain_s, lppd_s = psis(sur_plain), _lppd(sur_plain)
    names = (name, "per-pressure cubics")
    return {
        "model": name,
        name: _part(loo_s, n_s, lppd_s),
        registry.CUBICS: _part(loo_c, n_c, lppd_c)
        | {"max_pareto_k_psis": k_psis, "n_exact_refits": loo_c.n_refits},
        **verdict(loo_s, loo_c, names),
        "method": (
            "PSIS-LOO over the noise draws with the coefficients integrated out exactly per left-out reading; "
            f"cubic readings still at Pareto k > {PARETO_K_MAX:g} (up to {MAX_REFITS}) replaced by exact refits "
            f"of their test without the reading; more, both models by 10-fold cross-validation (here: {how})"
        ),
        "plain_psis_loo": {
            name: _part(plain_s, n_s, lppd_s),
            registry.CUBICS: _part(plain_c, n_c, lppd_c),
            **verdict(plain_s, plain_c, names),
        },
        "unit": f"log density per {'force' if force_only else '(force, piston)'} reading, summed over readings",
        **(
            {
                "note": "the volume_* column is left out of both models: compared on the force readings"
            }
            if force_only and surface_fit.recordings.has_volume
            else {}
        ),
    }


def _cubics(rec, *, seed: int, settings: Settings, stand):
    """The per-pressure cubics of :func:`force_side` of ``rec``."""
    return fit_campaign(force_side(rec), seed=seed, settings=settings, stand=stand)


def cubics_then_compare(rec, asked, *, seed: int, settings: Settings, stand):
    """The worker of :func:`fitting_both`: the cubics, then, once the model's fit comes through
    the pipe ``asked``, the comparison of the two: (cubics, comparison)."""
    cub = _cubics(rec, seed=seed, settings=settings, stand=stand)
    side = cubic_terms(cub, seed=seed, settings=settings)  # while the model is being fitted
    return cub, compare(asked.recv(), cub, seed=seed, settings=settings, cubic_side=side)


@contextlib.contextmanager
def fitting_both(
    rec,
    *,
    seed: int,
    settings: Settings,
    stand,
    model=None,
    jobs: int | None = 1,
    worker: comparison_worker.ComparisonWorker | None = None,
):
    """:func:`fit_both` in two steps, for a caller with work of its own that needs the model's fit
    but not yet the comparison: yields (model fit, ``compared``), ``compared()`` -> (cubics,
    comparison), computed once.

    With a worker (``jobs`` >= 2 and at least ``WORKER_MIN_READINGS`` readings; ``worker``: one
    the caller started already with the same ``rec``, seed, settings and stand,
    ``uq._derived.comparison_worker.start``), the worker fits the cubics beside the model's fit
    here and then, sent the model's fit, compares the two while the caller goes on; without,
    ``compared()`` fits the cubics and compares here. The same fits and comparison, to the bit."""
    name = registry.default("margin") if model is None else model
    kw = {"seed": seed, "settings": settings, "stand": stand}
    given = worker is not None  # a worker the caller started is the caller's to stop
    if not given:
        worker = comparison_worker.start(rec, jobs=jobs, **kw)
    if worker is None:
        fit = registry.fit(name, rec, **kw)

        def here():
            cub = _cubics(rec, **kw)
            return cub, compare(fit, cub, seed=seed, settings=settings)

        yield fit, functools.cache(here)
        return
    with contextlib.nullcontext() if given else worker:
        fit = registry.fit(name, rec, **kw)
        worker.send(fit)  # compared with the cubics there
        yield fit, functools.cache(worker.result)


def fit_both(
    rec,
    *,
    seed: int,
    settings: Settings,
    stand,
    surface_fit=None,
    cubic_fit=None,
    model=None,
    jobs: int | None = 1,
    worker: comparison_worker.ComparisonWorker | None = None,
):
    """A model over all tests (``model``: a registry name, default the registry's default model)
    and the per-pressure cubics of ``rec`` with the same settings (either fit may be given already)
    and their :func:`compare` document: (model fit, cubics, comparison). The cubics compared are
    fitted to :func:`force_side` of ``rec``: a catalogue's own cubic fit (its volume column fitted
    as L) is not the comparison's, and a given one is then replaced.

    ``jobs``: processes that fit (None: one per CPU); with two or more, no fit given and at least
    ``WORKER_MIN_READINGS`` readings (``uq._derived.comparison_worker``), the cubics are fitted in
    a spawned worker process beside the model's fit here and compared with it there
    (:func:`fitting_both`, which ``worker`` is passed to): the same fits and comparison, to the
    bit. A script that asks for it needs an ``if __name__ == "__main__":`` guard."""
    kw = {"seed": seed, "settings": settings, "stand": stand}
    if surface_fit is None and (cubic_fit is None or force_side(rec) is not rec):
        with fitting_both(rec, model=model, jobs=jobs, worker=worker, **kw) as (fit, compared):
            return (fit, *compared())
    if surface_fit is None:
        name = registry.default("margin") if model is None else model
        surface_fit = registry.fit(name, rec, **kw)
    if cubic_fit is None or force_side(rec) is not rec:
        cubic_fit = _cubics(rec, **kw)
    return surface_fit, cubic_fit, compare(surface_fit, cubic_fit, seed=seed, settings=settings)


def words(c: dict) -> str:
    """One line for a :func:`compare` result."""
    if c["better"] in ("refused", "indistinguishable"):
        return f"{c['better']}: {c['reason']}"
    return (
        f"difference {c['elpd_diff']:.1f} +- {c['elpd_diff_se']:.1f} in favour of the {c['better']}"
    )


def fit_and_choose(
    rec,
    *,
    model: str = AUTO,
    seed: int = 0,
    settings=None,
    stand=None,
    jobs: int | None = 1,
    worker: comparison_worker.ComparisonWorker | None = None,
):
    """Fit what ``model`` needs (``auto``: the registry's default model over all tests and the
    per-pressure cubics, compared by PSIS-LOO with the same settings, ``uq._derived.comparison``;
    a registry name: that model alone) and choose the answering model (:func:`choose`); returns
    (answering model, model description, merged sampler diagnostics). ``jobs``, ``worker``:
    :func:`fit_both`'s."""
    settings = Settings() if settings is None else settings
    stand = PAPER_STAND if stand is None else stand
    kw = {"seed": seed, "settings": settings, "stand": stand}
    fit = cub = comparison = None
    if model == AUTO:
        fit, cub, comparison = fit_both(
            rec, model=registry.default("margin"), jobs=jobs, worker=worker, **kw
        )
    elif registry.entry(model).over_all_tests:
        fit = registry.fit(model, rec, **kw)
    else:
        cub = registry.fit(model, rec, **kw)
    fitted = [f for f in (fit, cub) if f is not None]
    warnings = [w for f in fitted for w in f.convergence.messages(CLI_ADVICE)]
    converged = all(f.convergence.converged for f in fitted)
    notes = [w for w in map(sampler_words, fitted) if w]
    ans, info = choose(fit, cub, comparison, forced=model)
    if ans.omitted_reason:  # a campaign without piston readings
        info["omitted"] = ans.omitted_reason
    return ans, info, {"warnings": warnings, "converged": bool(converged), "notes": notes}


def sampler_words(fit) -> str | None:
    """How ``fit``'s sampled parameters were sampled, where importance sampling was tried
    (``Convergence.sampler_words``): a line the command line prints whichever way it went."""
    words = getattr(fit.convergence, "sampler_words", None)
    return words() if words is not None else None
