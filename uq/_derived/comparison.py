"""The surface model against the per-pressure cubics: one workflow, one set of cubic settings.

``uq surface``, ``uq report --surface`` and ``uq margin`` all ask the same question: do the
recordings prefer one smooth model over height and pressure (``uq._models.surface``) or an
independent cubic per tested pressure (``uq._models.cubic``, eqs. 8, 9)? :func:`compare` answers
it the same way for all of them:

* Both models are linear in their coefficients given the noise, so each reading's leave-one-out
  density given the noise is exact (the models' ``pointwise_loo``) and PSIS only reweights the
  noise draws (``uq._inference.loo.psis``); the plain PSIS-LOO at drawn coefficients is reported
  beside it.
* Cubic readings still at Pareto k > 0.7 (up to ``RELOO_MAX``) are replaced by exact refits of
  their test without the reading (``uq._inference.loo.reloo``).
* The verdict (``uq._inference.loo.verdict``): a model is named only beyond 2 SE and 4 nats with
  every Pareto k <= 0.7; otherwise "indistinguishable" or "refused".

:func:`fit_both` fits what a comparison needs with one set of sampler settings, the caller's.
"""

from __future__ import annotations

import numpy as np

from uq._inference.collapsed import fit_collapsed
from uq._inference.loo import PARETO_K_MAX, Loo, held_out_density, psis, reloo, verdict
from uq._inference.sampler import Settings

#: at most this many exact refits for cubic readings whose Pareto k stays > 0.7
RELOO_MAX = 12


def _concat(parts) -> np.ndarray:
    """Pointwise arrays (C, D_i, n_i) of the tests side by side on their common draws."""
    C = min(p.shape[0] for p in parts)
    D = min(p.shape[1] for p in parts)
    return np.concatenate([p[:C, :D] for p in parts], axis=-1)


def _part(loo: Loo, n_coefficients: int, loglik) -> dict:
    """One model's LOO in the JSON; p_loo = lppd (at the drawn coefficients) - elpd_loo."""
    from scipy.special import logsumexp

    ll = np.asarray(loglik).reshape(-1, np.shape(loglik)[-1])
    lppd = float(np.sum(logsumexp(ll, axis=0) - np.log(ll.shape[0])))
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
    from uq._models.cubic import collapsed_model

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


def force_side(rec):
    """The recordings the per-pressure cubics are fitted to for a comparison: ``rec`` itself, or,
    for a campaign with a volume column but no piston (a catalogue table), ``rec`` without its
    volume column: the force surface leaves the volume out, so both models are compared on the
    force readings alone."""
    import dataclasses

    if rec.has_piston or not rec.has_volume:
        return rec
    return dataclasses.replace(
        rec, tests=tuple(dataclasses.replace(t, volume_m3=None) for t in rec.tests)
    )


def compare(surface_fit, cubic_fit, *, seed: int = 0, settings: Settings = Settings()) -> dict:
    """PSIS-LOO of a model over all tests (the surface model, or the thermodynamic one: its
    ``short_name`` keys the document) against the per-pressure cubics, per (force, piston) reading
    (module docstring); the ``comparison`` document of the JSON results."""
    name = surface_fit.short_name
    force_only = not surface_fit.recordings.has_piston  # the force surface: per force reading
    if force_only and any(t.has_piston for t in cubic_fit.tests):
        raise ValueError(
            "the force surface is compared with cubics fitted to the force alone (force_side)"
        )
    cub_plain = _concat([t.posterior.loglik_total() for t in cubic_fit.tests])
    sur_plain = surface_fit.posterior.loglik_total()
    n_s, n_c = surface_fit.beta.shape[-1], 8 * len(cubic_fit.tests)
    if force_only:
        n_c = sum(t.posterior.beta.shape[-1] for t in cubic_fit.tests)
    loo_s = psis(surface_fit.loglik_loo)
    loo_c = psis(_concat([t.posterior.loglik_loo for t in cubic_fit.tests]))
    k_psis = float(np.max(loo_c.pareto_k))
    loo_c = reloo(loo_c, _cubic_refit(cubic_fit, settings, seed), max_refits=RELOO_MAX)
    plain_s, plain_c = psis(sur_plain), psis(cub_plain)
    names = (name, "per-pressure cubics")
    return {
        name: _part(loo_s, n_s, sur_plain),
        "cubics": _part(loo_c, n_c, cub_plain)
        | {"max_pareto_k_psis": k_psis, "n_exact_refits": loo_c.n_refits},
        **verdict(loo_s, loo_c, names),
        "method": (
            "PSIS-LOO over the noise draws with the coefficients integrated out exactly per left-out reading; "
            f"cubic readings still at Pareto k > {PARETO_K_MAX:g} (up to {RELOO_MAX}) replaced by exact refits "
            "of their test without the reading"
        ),
        "plain_psis_loo": {
            name: _part(plain_s, n_s, sur_plain),
            "cubics": _part(plain_c, n_c, cub_plain),
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


def fit_both(
    rec, *, seed: int, settings: Settings, stand, surface_fit=None, cubic_fit=None, model="surface"
):
    """A model over all tests (``model``: "surface" or "thermodynamic") and the per-pressure
    cubics of ``rec`` with the same settings (either fit may be given already) and their
    :func:`compare` document: (model fit, cubics, comparison). The cubics compared are fitted to
    :func:`force_side` of ``rec``: a catalogue's own cubic fit (its volume column fitted as L) is
    not the comparison's, and a given one is then replaced."""
    from uq._models.cubic import fit_campaign

    if surface_fit is None:
        surface_fit = FITTERS[model](rec, seed=seed, settings=settings, stand=stand)
    if cubic_fit is None or force_side(rec) is not rec:
        cubic_fit = fit_campaign(force_side(rec), seed=seed, settings=settings, stand=stand)
    return surface_fit, cubic_fit, compare(surface_fit, cubic_fit, seed=seed, settings=settings)


def _fit_surface(rec, **kw):
    from uq._models.surface import fit_surface

    return fit_surface(rec, **kw)


def _fit_thermo(rec, **kw):
    from uq._models.thermo import fit_thermo

    return fit_thermo(rec, **kw)


#: the models over all tests, by the name ``uq surface --model`` takes
FITTERS = {"surface": _fit_surface, "thermodynamic": _fit_thermo}


def words(c: dict) -> str:
    """One line for a :func:`compare` result."""
    if c["better"] in ("refused", "indistinguishable"):
        return f"{c['better']}: {c['reason']}"
    return (
        f"difference {c['elpd_diff']:.1f} +- {c['elpd_diff_se']:.1f} in favour of the {c['better']}"
    )
