"""Design-margin queries (``uq margin``, docs/formats.md section 2), answered by the model the data prefer.

Which model answers. Two descriptions of a campaign can answer "at which overpressure does
the element carry W at height x": a model over all tests (the registry's default,
``uq._models.registry.DEFAULT_MODEL``: the surface with a discrepancy in pressure,
``uq._models.discrepancy``, whose band between tested pressures widens by what the data say a
smooth surface misses) and the
per-pressure cubics (eqs. 8, 9 of the paper, one independent curve per tested pressure,
interpolated between them: ``uq._models.cubic_interpolation``). ``uq margin`` fits both and
compares them by PSIS-LOO (``uq._derived.comparison``: the ELPD difference with its SE, Pareto k of
both). The model over all tests answers unless the cubics are better by more than 2 SE with every
Pareto k <= 0.7; an indistinguishable or refused comparison keeps it (its coverage between
tested pressures, on springs smooth and not smooth in pressure: reports/between-coverage/). The
JSON says which model answered and why (``model``), with the comparison's numbers. Any fitted
model (:class:`uq._models.fitted.FittedModel`) answers a query given to :func:`margin` directly.

All probabilities are over the posterior of the element's *mean* characteristic (the stand's
reading noise excluded: the load cell's and the pressure holding's scatter belong to the
stand, not to the element in service). ``pressure_bar_for_prob`` is exact: the force grows
with pressure at a fixed height, so "the element carries at least W at p" holds for a draw iff
p >= that draw's required pressure, and the smallest p with probability ``prob`` is the
``prob`` quantile of ``pressure_bar_needed``. (A draw that does not rise everywhere between tested
pressures answers with its lowest crossing of the load; their share is stated: ``pressure_needed``.)
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from uq._inference.summary import band, estimate
from uq._io.errors import InputError
from uq._models import registry
from uq._models.cubic_interpolation import INTERPOLATION
from uq._models.saved import load

N_P_GRID = 801
#: ``uq margin --model``'s word for "compare the default model with the cubics and take the better"
AUTO = "auto"


def model_choices() -> tuple[str, ...]:
    """What ``uq margin --model`` takes: ``auto`` and every registered model."""
    return (AUTO, *registry.names())


#: the share of posterior draws whose force crosses the load more than once in pressure up to which
#: a margin is answered (their lowest crossing taken, the share stated); above it, refused
NOT_RISING_MAX = 0.10


class Needed(NamedTuple):
    """What :func:`pressure_needed` answers: the draws of the required overpressure (bar) and the
    share of draws whose force crosses the load more than once (``not_rising_share``)."""

    values: np.ndarray
    not_rising_share: float


def pressure_needed(model, height_m: float, load_N: float) -> Needed:
    """Posterior draws of the overpressure (bar) at which the element carries ``load_N``, with the
    share of draws whose force crosses the load more than once (:class:`Needed`).

    The force rises with pressure at a fixed height, and a draw crosses the load once. Between
    tested pressures a band that knows little (coarse grids, the discrepancy's Gaussian process)
    has some draws that do not rise everywhere and cross the load more than once: such a draw
    answers with its lowest crossing, the least pressure at which it carries the load as the
    spring is charged (so the interval is widened towards lower pressures, not narrowed), and the
    share is said (``not_rising_share`` in ``uq margin``'s JSON). Above ``NOT_RISING_MAX`` of the
    draws the model does not know that the force rises with pressure there: refused."""
    model.check_range(height_m, model.pressure_range_bar[0], "height_m")
    plo, phi = model.pressure_range_bar
    ps = np.linspace(plo, phi, N_P_GRID)
    P = model.force_draws(np.full_like(ps, height_m), ps)  # (S, G)
    above = P >= load_N
    # a force that does not rise with pressure elsewhere (at 150 mm the casing's tension makes the
    # 0.1-bar force negative, which bends the cubics' interpolation below 1 bar) does not matter
    # to a load it never equals there: only crossings of the load count
    crossings = np.count_nonzero(np.diff(above.astype(np.int8), axis=1), axis=1)
    frac = float(np.mean(crossings > 1))
    if frac > NOT_RISING_MAX:
        raise InputError(
            f"load_N: at {height_m * 1e3:g} mm the force equals {load_N:g} N at more than one "
            f"overpressure in {100 * frac:.0f} % of the posterior draws (it does not rise with "
            f"pressure there; answered up to {100 * NOT_RISING_MAX:.0f} %); no unique required "
            "pressure",
            param="load_N",
        )
    lo_load, hi_load = band(P[:, 0])[2], band(P[:, -1])[1]
    if not lo_load <= load_N <= hi_load:
        raise InputError(
            f"load_N: {load_N:g} N at {height_m * 1e3:g} mm is outside what the tested pressures "
            f"{plo:g}..{phi:g} bar support there (about {lo_load:.0f}..{hi_load:.0f} N); the model does not extrapolate",
            param="load_N",
        )
    first = np.argmax(above, axis=1)
    ok = above.any(axis=1) & ~above[:, 0]
    out = np.full(P.shape[0], np.nan)
    i = first[ok]
    rows = np.flatnonzero(ok)
    p0, p1 = ps[i - 1], ps[i]
    f0, f1 = P[rows, i - 1], P[rows, i]
    out[rows] = p0 + (load_N - f0) / (f1 - f0) * (p1 - p0)
    out[above[:, 0]] = plo  # already carried at the lowest pressure (within the band edge)
    out[~above.any(axis=1)] = np.inf  # not carried in the tested range
    return Needed(out, frac)


def _finite_estimate(d):
    d = np.asarray(d, float)
    if not np.all(np.isfinite(d)):
        raise InputError(
            "load_N: the load lies at the edge of the tested pressure range for part of the "
            "posterior; choose a load further inside the supported range",
            param="load_N",
        )
    return estimate(d)


def _run_around(ok: np.ndarray, j: int) -> tuple[np.ndarray, np.ndarray]:
    """First and last index of each row's run of True through column ``j`` (rows (S, n); meaningful where ok[:, j])."""
    n = ok.shape[1]
    left, right = ~ok[:, :j][:, ::-1], ~ok[:, j + 1 :]  # left: column j-1 first
    a = (
        np.where(left.any(axis=1), j - np.argmax(left, axis=1), 0)
        if j > 0
        else np.zeros(ok.shape[0], int)
    )
    b = (
        np.where(right.any(axis=1), j + np.argmax(right, axis=1), n - 1)
        if j < n - 1
        else np.full(ok.shape[0], n - 1)
    )
    return a, b


def usable_stroke(
    model,
    height_m: float,
    pressure_bar: float,
    target_N: float,
    tolerance_pct: float,
    prob: float,
    *,
    n_x: int = 361,
) -> dict:
    """Height range around ``height_m`` over which the force at ``pressure_bar`` stays within tolerance."""
    lo, hi = model.height_range_m
    xs = np.linspace(lo, hi, n_x)
    P = model.force_draws(xs, pressure_bar)  # (S, n_x)
    ok = np.abs(P - target_N) <= tolerance_pct / 100.0 * abs(target_N)
    j = int(np.argmin(np.abs(xs - height_m)))
    a_s, b_s = _run_around(ok, j)
    lengths = np.where(ok[:, j], xs[b_s] - xs[a_s], 0.0)
    p_in = ok.mean(axis=0)
    a = b = j
    if p_in[j] >= prob:
        while a > 0 and p_in[a - 1] >= prob:
            a -= 1
        while b < n_x - 1 and p_in[b + 1] >= prob:
            b += 1
        joint = float(np.mean(np.all(ok[:, a : b + 1], axis=1)))
        credible = {
            "from_m": float(xs[a]),
            "to_m": float(xs[b]),
            "length_m": float(xs[b] - xs[a]),
            "prob_whole_range_within": joint,
        }
    else:
        credible = None
    return {
        "pressure_bar": pressure_bar,
        "target_N": target_N,
        "tolerance_pct": tolerance_pct,
        "prob_within_at_height": float(p_in[j]),
        "stroke_length_m": estimate(lengths),
        "stroke_credible": credible,
        "at_edge_of_tested_heights": bool(
            credible and (credible["from_m"] <= lo + 1e-9 or credible["to_m"] >= hi - 1e-9)
        ),
    }


def describe(fit, comparison: dict | None = None, why: str = "given by the caller") -> dict:
    """The ``model`` object of the margin JSON: which model answers, in words, and why."""
    info = {"name": fit.name, "label": fit.label, "comparison": comparison}
    if hasattr(fit, "orders_label"):
        info["orders"] = fit.orders_label
    if fit.name == registry.CUBICS:
        info["interpolation"] = INTERPOLATION
    return info | {"why": why}


def choose(fit, cubic_fit, comparison: dict | None, forced: str = AUTO):
    """(answering model, its description) from the PSIS-LOO comparison of the model over all
    tests ``fit`` with the cubics, or the user's choice ``forced`` (a registry name)."""
    if forced != AUTO:
        chosen = cubic_fit if forced == registry.CUBICS else fit
        return chosen, describe(
            chosen, comparison, f"chosen by the user (--model {forced}); no comparison made"
        )
    if comparison and comparison["better"] == "per-pressure cubics":
        return cubic_fit, describe(
            cubic_fit,
            comparison,
            f"the data prefer the per-pressure cubics: {comparison['reason']}",
        )
    note = f" ({fit.coverage_note})" if getattr(fit, "coverage_note", None) else ""
    why = (
        f"PSIS-LOO verdict '{comparison['better']}': {comparison['reason']}; the {fit.name} "
        f"answers{note}"
    )
    return fit, describe(fit, comparison, why)


def load_answer(path):
    """(model, model description, provenance) from a saved model (``save``: ``uq margin
    --save-fit``, ``uq surface --out``); no refit, no JAX. The description is the one saved with it
    (why ``uq margin`` chose it), or says where the model came from."""
    model = load(path)
    prov = model.provenance
    info = prov.get("model_info") or describe(
        model, why=f"saved by {prov.get('written_by', 'save')}"
    )
    return model, info, prov


def margin(
    model,
    height_m: float,
    load_N: float,
    prob: float = 0.95,
    *,
    pressure_bar: float | None = None,
    tolerance_pct: float | None = None,
    model_info: dict | None = None,
) -> dict:
    """The margin query on ``model``, any fitted model (:class:`uq._models.fitted.FittedModel`:
    a surface or thermodynamic fit, a campaign's cubics, a loaded one); ``model_info`` is the JSON's
    ``model`` object (default: :func:`describe` of the model, given by the caller)."""
    if not 0.0 < prob < 1.0:
        raise InputError(
            f"prob: expected a probability between 0 and 1, got {prob:g}", param="prob"
        )
    if not load_N > 0:
        raise InputError(f"load_N: expected a positive load in N, got {load_N:g}", param="load_N")
    if tolerance_pct is not None and pressure_bar is None:
        raise InputError(
            "tolerance_pct: needs a pressure_bar (the stroke is taken at one pressure)",
            param="tolerance_pct",
        )
    if model_info is None:
        model_info = describe(model, why="given by the caller; no comparison made")
    need, not_rising = pressure_needed(model, height_m, load_N)
    est = _finite_estimate(need)
    plo, phi = model.pressure_range_bar
    res = {
        "height_m": height_m,
        "load_N": load_N,
        "prob": prob,
        "pressure_bar_needed": est,
        "pressure_bar_for_prob": float(np.quantile(need, prob)),
        "model": model_info,
        "distribution": "posterior of the mean characteristic (stand reading noise excluded)",
        "tested_pressure_range_bar": [plo, phi],
        "tested_height_range_m": list(model.height_range_m),
        # the share of draws whose force crosses the load more than once (their lowest crossing
        # taken: pressure_needed)
        "not_rising_share": not_rising,
    }
    if pressure_bar is not None:
        model.check_range(height_m, pressure_bar, "pressure_bar")
        P = model.force_draws(np.array(height_m), pressure_bar)
        res["force_at_pressure"] = {
            "pressure_bar": pressure_bar,
            "force_N": estimate(P),
            "prob_carries_load": float(np.mean(P >= load_N)),
        }
        if tolerance_pct is not None:
            if not tolerance_pct > 0:
                raise InputError(
                    f"tolerance_pct: expected a positive tolerance, got {tolerance_pct:g}",
                    param="tolerance_pct",
                )
            res["usable_stroke"] = usable_stroke(
                model, height_m, pressure_bar, load_N, tolerance_pct, prob
            )
    return res
