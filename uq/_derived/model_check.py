"""Does the model that answers follow the readings it was fitted to? The posterior-predictive check
at the tested points that ``uq design`` and ``uq margin`` print with every answer (issue 29).

A margin or a sealed rate is read off the model's mean force between and at the tested pressures;
it can be no better than the model's account of the readings. Per tested pressure, each force
reading is set against the model's posterior predictive of that reading (the mean force of a draw
plus the reading noise of that draw: the fit's own replicates, ``predictive_force_draws``):

* ``inside``: how many readings lie in their equal-tailed 90 % predictive interval;
* ``worst_z``: the largest |standardised residual| (reading minus the replicates' mean, over their
  sd) and the height where it is.

A model that follows the readings has about 90 % of them inside (more, not fewer: the readings
were used to fit it) and no residual far out in the normal tails. ``misses`` is the rule
(``RULE``): at some pressure the count inside is below its binomial region (Binomial(n, 0.9), lower
tail ``ALPHA`` / (2 T) over T pressures) or the worst |z| is beyond what the largest of n normal
|z| reaches with that probability. The rule is one-sided on purpose: a model whose bands are too
wide is cautious; a model whose predictive misses the readings it was fitted to is wrong there, and
its answers between the tested pressures rest on it.

What the commands do with a miss (``uq._cli.common.record_misfit``): they still print and write
the answer, with the check and the words saying the model misses, and exit 1 unless
``--allow-misfit``: they refuse rather than widen, because a widening by a factor read off the
residuals would itself be a model of the discrepancy between tested pressures that nothing checks
(the surface with a discrepancy in pressure, ``uq._models.discrepancy``, is that model, fitted).
"""

from __future__ import annotations

import numpy as np
from scipy.special import bdtr, ndtri

#: the predictive intervals' level
LEVEL = 0.90
#: the rule's false-alarm probability for a model that is right, over every pressure and both
#: statistics (Bonferroni)
ALPHA = 0.01
#: posterior draws the replicates are taken on
N_DRAWS = 400
RULE = (
    f"at a tested pressure with n readings, fewer inside their {LEVEL:.0%} predictive intervals "
    f"than Binomial(n, {LEVEL:g}) gives with probability {ALPHA:g} / (2 T), or a worst |z| beyond "
    f"what the largest of n normal |z| exceeds with that probability (T tested pressures; false "
    f"alarm <= {ALPHA:g} for a model that is right)"
)


def limits(n: int, n_pressures: int, alpha: float = ALPHA) -> tuple[int, float]:
    """The rule at one pressure with ``n`` readings: the fewest readings inside that pass and the
    largest |z| that passes, each at level ``alpha / (2 n_pressures)``."""
    # scipy.special's binomial cdf and normal quantile, the formulas of scipy.stats' binom.cdf and
    # norm.isf (the same numbers, tested): scipy.stats costs about 1.5 CPU s to import
    a = alpha / (2 * n_pressures)
    ks = np.arange(n + 1)
    k_min = int(ks[bdtr(ks, n, LEVEL) > a][0])
    z_max = float(-ndtri((1.0 - (1.0 - a) ** (1.0 / n)) / 2.0))
    return k_min, z_max


def unavailable(fit, why: str) -> dict:
    return {"model": fit.label, "available": False, "why": why, "misses": False, "level": LEVEL}


def predictive_check(fit, *, n_draws: int = N_DRAWS, seed: int = 0) -> dict:
    """The check of ``fit`` (a fitted model with its recordings) at its tested points (module
    docstring): {"model", "available", "level", "rule", "by_pressure": [{"pressure_bar", "n",
    "inside", "fraction_inside", "inside_min", "worst_z", "worst_at_height_m", "z_max",
    "misses"}], "misses", "missed_pressures_bar", "words"}; "available": False with "why" for a
    model that keeps no replicates (a saved fit, a model plugged in without them)."""
    draws = getattr(fit, "predictive_force_draws", None)
    if fit.recordings is None:
        return unavailable(fit, "a saved fit keeps no readings: fit the recordings to check it")
    reps = draws(n_draws, seed) if draws is not None else None
    if reps is None:
        return unavailable(fit, f"{fit.label} offers no posterior-predictive replicates")
    tests = fit.recordings.tests
    rows = []
    for t, r in zip(tests, reps, strict=True):
        lo, hi = np.quantile(r, [(1 - LEVEL) / 2, (1 + LEVEL) / 2], axis=0)
        y = np.asarray(t.force_N, float)
        z = (y - r.mean(axis=0)) / np.maximum(r.std(axis=0, ddof=1), 1e-300)
        inside = int(np.sum((y >= lo) & (y <= hi)))
        k_min, z_max = limits(y.size, len(tests))
        j = int(np.argmax(np.abs(z)))
        rows.append(
            {
                "pressure_bar": float(t.pressure_bar),
                "n": int(y.size),
                "inside": inside,
                "fraction_inside": inside / y.size,
                "inside_min": k_min,
                "worst_z": float(z[j]),
                "worst_at_height_m": float(t.height_m[j]),
                "z_max": z_max,
                "misses": bool(inside < k_min or abs(z[j]) > z_max),
            }
        )
    missed = [r["pressure_bar"] for r in rows if r["misses"]]
    out = {
        "model": fit.label,
        "available": True,
        "level": LEVEL,
        "n_draws": int(reps[0].shape[0]),
        "rule": RULE,
        "by_pressure": rows,
        "misses": bool(missed),
        "missed_pressures_bar": missed,
    }
    out["words"] = words(out)
    return out


def words(check: dict) -> str:
    """One line: what the check says."""
    if not check["available"]:
        return f"not checked: {check['why']}"
    rows = check["by_pressure"]
    n, inside = sum(r["n"] for r in rows), sum(r["inside"] for r in rows)
    worst = max(rows, key=lambda r: abs(r["worst_z"]))
    head = (
        f"{inside} of {n} readings ({inside / n:.0%}) inside their {check['level']:.0%} predictive "
        f"intervals; worst standardised residual {worst['worst_z']:+.1f} at "
        f"{worst['pressure_bar']:g} bar, {worst['worst_at_height_m'] * 1e3:g} mm"
    )
    if not check["misses"]:
        return f"{head}: the model follows the readings"
    return (
        f"{head}: the model MISSES the readings at {_bars(check['missed_pressures_bar'])} bar "
        "(answers between and at these pressures rest on a description the readings refute)"
    )


def table(check: dict) -> list[str]:
    """The per-pressure lines of the check, for the command line."""
    if not check["available"]:
        return []
    out = ["    p_bar   inside/n  (min)  worst z  at mm  (|z| max)"]
    for r in check["by_pressure"]:
        flag = "  MISSES" if r["misses"] else ""
        out.append(
            f"  {r['pressure_bar']:>6g}  {r['inside']:>4}/{r['n']:<4} ({r['inside_min']:>3})  "
            f"{r['worst_z']:+7.2f}  {r['worst_at_height_m'] * 1e3:5.1f}  ({r['z_max']:.2f}){flag}"
        )
    return out


def _bars(ps) -> str:
    return ", ".join(f"{p:g}" for p in ps)
