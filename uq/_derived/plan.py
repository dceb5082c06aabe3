"""Where to measure next: the plan ``uq plan`` answers (docs/plan.md).

The engine (``uq._derived.plan_search``) evaluates the targets' posterior variance after any set of
readings in closed form, per draw of the noise parameters, and searches greedily for the readings
that make it smallest for the stand time. Here: how the planned readings are laid out at the stand
(recording order, a uniform grid, the paper's protocol), the plan itself (:func:`make_plan`: a
search per number of new tests, each plan evaluated exactly in the frame of the model fitted after
it) and its JSON document (:func:`plan_document`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from uq._data.reference import PAPER_PRESSURES_BAR, PAPER_X_MAX_M, PAPER_X_MIN_M
from uq._derived.plan_search import (
    COST_PER_PRESSURE,
    MAX_PER_HEIGHT,
    MIN_TEST_READINGS,
    SEARCH_DRAWS,
    Frame,
    PlanPath,
    Reading,
    evaluate,
    search,
    target_values,
)
from uq._derived.plan_theta import SMALL_ESS, THETA_POOL, theta_updated
from uq._io.errors import InputError

# ----------------------------------------------------------------------------- layouts


def recording_order(readings, new_bar):
    """The planned tests in recording order (ascending pressure; in each, compression from the
    highest height down, then rebound up: a height read twice is read once on each branch):
    [{"test": j, "pressure_bar", "heights_m", "branches"}]."""
    by: dict[int, list[float]] = {}
    for r in readings:
        by.setdefault(r.test, []).append(r.height_m)
    out = []
    for j in sorted(by, key=lambda j: new_bar[j]):
        hs = np.asarray(by[j])
        uniq, count = np.unique(np.round(hs, 9), return_counts=True)
        down = uniq[::-1]
        up = uniq[count >= 2]
        heights = np.concatenate([down, up])
        branches = ["compression"] * down.size + ["rebound"] * up.size
        out.append(
            {
                "test": j,
                "pressure_bar": float(new_bar[j]),
                "heights_m": heights.tolist(),
                "branches": branches,
            }
        )
    return out


def spread(n: int, values) -> np.ndarray:
    """``n`` of ``values`` (sorted) spread evenly, ends included."""
    values = np.sort(np.asarray(values, float))
    if n >= values.size:
        return values
    if n == 1:
        return values[[values.size // 2]]
    return values[np.round(np.linspace(0, values.size - 1, n)).astype(int)]


def uniform_pressures(n: int, pressures_bar) -> np.ndarray:
    """``n`` of ``pressures_bar`` spread evenly: the candidates nearest the midpoints of ``n`` equal
    parts of their range (distinct)."""
    values = np.sort(np.asarray(pressures_bar, float))
    if n >= values.size:
        return values
    lo, hi = values[0], values[-1]
    want = lo + (hi - lo) * (np.arange(n) + 0.5) / n
    left = list(values)
    out = []
    for w in want:
        i = int(np.argmin(np.abs(np.asarray(left) - w)))
        out.append(left.pop(i))
    return np.sort(np.asarray(out))


def uniform_readings(n_readings: int, n_tests: int, pressures_bar, heights_m, min_heights: int = 0):
    """A uniform grid of ``n_readings`` readings over ``n_tests`` new tests: the tests' pressures
    spread evenly over ``pressures_bar`` (:func:`uniform_pressures`); in each test its share of the
    readings at heights spread evenly, down then up (each height at most once per branch), at
    least ``min_heights`` of them on the way down (distinct heights the model needs in a test).
    Returns (pressures, [(p, heights)])."""
    ps = uniform_pressures(n_tests, pressures_bar)
    share = np.full(ps.size, n_readings // ps.size)
    share[: n_readings % ps.size] += 1
    tests = []
    for p, m in zip(ps, share, strict=True):
        m = int(min(m, MAX_PER_HEIGHT * len(heights_m)))
        n_down = min(max((m + 1) // 2, int(min_heights)), m, len(heights_m))
        down = spread(n_down, heights_m)
        up = spread(m - n_down, heights_m)
        tests.append((float(p), np.concatenate([down[::-1], up])))
    return ps, tests


def readings_at(frame: Frame, tests) -> list[Reading]:
    """Readings of ``tests`` [(pressure_bar, heights_m)] as :class:`Reading` of the frame's new tests."""
    out = []
    for p, hs in tests:
        j = int(np.argmin(np.abs(frame.new_bar - p)))
        if abs(frame.new_bar[j] - p) > 1e-9:
            raise ValueError(f"the frame has no new test at {p:g} bar")
        out += [Reading(j, float(h)) for h in hs]
    return out


def distinct_heights(heights_m) -> int:
    """How many distinct heights a test's readings visit."""
    return int(np.unique(np.round(np.asarray(heights_m, float), 9)).size)


def complete_tests(builder, tests, heights_m, what: str = "plan"):
    """``tests`` [(pressure_bar, heights)] with every test holding the distinct heights the model
    of the combined campaign (the file's tests and these, with the orders that campaign gets:
    ``builder.heights_needed``) needs per test, so that the campaign read at the stand can be
    fitted: a test with too few gets readings on compression at heights of ``heights_m`` it does
    not visit yet, spread evenly (repeated until the orders, which follow the fewest heights in a
    test, settle). Returns (tests, need, notes): the notes say what was added (none: nothing)."""
    tests = [(float(p), np.asarray(h, float)) for p, h in tests]
    heights = np.asarray(heights_m, float)
    ps = [p for p, _ in tests]
    added: dict[int, list] = {}
    for _ in range(heights.size + 1):
        need = builder.heights_needed(ps, [h for _, h in tests]) if tests else 0
        short = [i for i, (_, h) in enumerate(tests) if distinct_heights(h) < need]
        if not short:
            notes = [
                f"the {what}'s {tests[i][0]:g}-bar test: {len(a)} reading(s) on compression added "
                f"at {', '.join(f'{x * 1e3:g}' for x in sorted(a, reverse=True))} mm, so that it "
                f"has the {need} distinct heights the model of the combined campaign needs per test"
                for i, a in sorted(added.items())
            ]
            return tests, need, notes
        for i in short:
            p, h = tests[i]
            seen = np.round(h, 9)
            free = heights[~np.isin(np.round(heights, 9), seen)]
            add = spread(need - distinct_heights(h), free)
            if add.size < need - distinct_heights(h):
                raise InputError(
                    f"heights_m: the {what}'s {p:g}-bar test needs {need} distinct heights for the "
                    f"model of the combined campaign and only {distinct_heights(h) + add.size} are "
                    "candidates: give more heights",
                    param="heights_m",
                )
            down = np.sort(np.concatenate([h[: _n_down(h)], add]))[::-1]
            tests[i] = (p, np.concatenate([down, h[_n_down(h) :]]))
            added.setdefault(i, []).extend(add.tolist())
    raise RuntimeError("the orders of the combined campaign did not settle")  # pragma: no cover


def _n_down(h) -> int:
    """Readings of a test laid out down then up (``recording_order``) taken on the way down: the
    leading run of strictly falling heights."""
    h = np.asarray(h, float)
    rise = np.flatnonzero(np.diff(h) >= 0)
    return h.size if rise.size == 0 else int(rise[0] + 1)


def required_tests(targets, tested_bar, candidates_bar) -> np.ndarray:
    """(J,) bool: the candidate tests the targets need because they lie beyond the tested pressures
    (for each target pressure outside them, the nearest candidate at or beyond it); InputError when
    no candidate reaches one."""
    tested = np.asarray(tested_bar, float)
    cand = np.asarray(candidates_bar, float)
    need = np.zeros(cand.size, bool)
    for t in targets:
        for p in t.fixed_pressures():
            if tested.min() - 1e-9 <= p <= tested.max() + 1e-9:
                continue
            above = p > tested.max()
            ok = cand >= p - 1e-9 if above else cand <= p + 1e-9
            if (need & ok).any():  # a test already needed covers it
                continue
            if not ok.any():
                side = "at or above" if above else "at or below"
                raise InputError(
                    f"candidates_bar: target {t.spec}: {p:g} bar lies outside the tested pressures "
                    f"{tested.min():g}..{tested.max():g} bar and no candidate pressure is {side} it "
                    "(the models do not extrapolate): add one",
                    param="candidates_bar",
                )
            idx = np.flatnonzero(ok)
            need[idx[np.argmin(np.abs(cand[idx] - p))]] = True
    return need


# ----------------------------------------------------------------------------- the plan


@dataclass
class Plan:
    """What ``uq plan`` answers (docs/plan.md, docs/formats.md): the readings to add in recording
    order, what they cost, each target's predicted sd now and after them, and the same for a uniform
    grid of the same size and for the paper's full protocol. sd values are per target, in its unit
    (None where the model cannot answer: a target outside the tested pressures now)."""

    model: str
    label: str
    label_now: str
    targets: list
    readings: list
    tests: list
    n_readings: int
    n_pressure_changes: int
    cost_per_pressure: float
    value_now: list
    sd_now: list
    sd_now_theta_spread: list
    sd_predicted: list
    uniform: dict
    paper: dict
    path: PlanPath
    curves: dict
    target_sd: list | None = None
    n_draws: int = 0
    tried: list = field(default_factory=list)
    min_heights_per_test: int = 0
    heights_added: list = field(default_factory=list)
    theta_updates: int = 0
    sd_after_theta_updated: list | None = None
    sd_uniform_theta_updated: list | None = None

    @property
    def cost(self) -> float:
        return self.n_readings + self.cost_per_pressure * self.n_pressure_changes

    @property
    def reached(self) -> list | None:
        if self.target_sd is None:
            return None
        return [
            bool(s <= t * (1 + 1e-9))
            for s, t in zip(self.sd_predicted, self.target_sd, strict=True)
        ]


def _sd(v) -> list:
    """Mean variance over draws -> sd per target (None where undefined)."""
    m = np.mean(v, axis=0)
    return [float(np.sqrt(x)) if np.isfinite(x) and x >= 0 else None for x in m]


def _now(builder, targets):
    """The targets as the fitted model answers now: value, theta-averaged sd, spread over theta."""
    frame = builder.frame()
    lo, hi = frame.pressure_range(np.zeros(0, bool))
    v = evaluate(frame, targets)
    vals = target_values(frame, targets, np.zeros(0, bool))
    out = {"value": [], "sd": [], "spread": []}
    for i, t in enumerate(targets):
        inside = all(lo - 1e-9 <= p <= hi + 1e-9 for p in t.fixed_pressures())
        ok = inside and np.all(np.isfinite(vals[:, i])) and np.isfinite(v[:, i]).all()
        out["value"].append(float(np.mean(vals[:, i])) if ok else None)
        out["sd"].append(float(np.sqrt(np.mean(v[:, i]))) if ok else None)
        out["spread"].append(float(np.std(vals[:, i])) if ok else None)
    return frame, out


def _layout(builder, targets, tests) -> tuple[list, np.ndarray, Frame]:
    """Readings of ``tests`` [(pressure_bar, heights)] in their own frame (the orders the combined
    campaign, laid out so, gets), and the variances."""
    frame = _frame_of(builder, tests)
    readings = readings_at(frame, tests)
    return readings, evaluate(frame, targets, readings), frame


def _frame_of(builder, tests) -> Frame:
    """The frame of ``tests`` [(pressure_bar, heights)] added to the file (their own orders)."""
    return builder.frame(np.array([p for p, _ in tests], float), new_heights=[h for _, h in tests])


def paper_tests(tested_bar):
    """The paper's protocol (section 3.4) at its pressures not yet tested: 155 -> 65 -> 155 mm in
    5 mm steps (37 readings a test)."""
    down = np.round(np.arange(PAPER_X_MAX_M, PAPER_X_MIN_M - 1e-9, -0.005), 6)
    hs = np.concatenate([down, down[::-1][1:]])
    tested = np.asarray(tested_bar, float)
    return [(float(p), hs) for p in PAPER_PRESSURES_BAR if not np.any(np.abs(tested - p) < 1e-9)]


class _Objective:
    """What the plans are ranked by: with a budget, sum over targets of the predicted variance over a
    reference variance (the paper's protocol's, or now's where the protocol does not reach it); with
    target sds, first whether every target is reached, then the stand time (or how far from them)."""

    def __init__(self, scale2, target_sd):
        self.scale2 = np.asarray(scale2, float)
        self.tau2 = None if target_sd is None else np.asarray(target_sd, float) ** 2

    def __call__(self, vbar) -> float:
        if self.tau2 is None:
            return float(np.sum(vbar / self.scale2))
        return float(np.sum(np.maximum(vbar, self.tau2) / self.tau2))

    def score(self, vbar, cost: float) -> tuple:
        met = self.tau2 is not None and bool(np.all(vbar <= self.tau2 * (1 + 1e-9)))
        return (0 if met else 1, cost if met else self(vbar))


def _reference_scale(builder, targets, frame_now, v_paper) -> np.ndarray:
    """Each target's reference variance: after the paper's protocol where it answers, else now."""
    ref = np.full(len(targets), np.nan) if v_paper is None else np.mean(v_paper, axis=0)
    ref_now = evaluate(frame_now, targets).mean(0)
    scale2 = np.where(np.isfinite(ref) & (ref > 0), ref, ref_now)
    return np.where(np.isfinite(scale2) & (scale2 > 0), scale2, 1.0)


def _search_tests(builder, targets, cand, heights, n_new, required, scale2, **kw):
    """The search with at most ``n_new`` new tests, in the frame of the campaign it makes (run again
    when the pressures it chose change the model's orders or scaling): (path, [(p, heights)])."""
    after = np.concatenate([builder.tested, spread(n_new, cand), cand[required]])
    for _ in range(2):
        frame = builder.frame(cand, after_bar=after)
        path = search(
            frame, targets, heights, required=required, max_tests=n_new, scale2=scale2, **kw
        )
        chosen = cand[sorted({r.test for r in path.readings})]
        new_after = np.concatenate([builder.tested, chosen])
        if not path.readings or builder.key(new_after) == frame.key:
            break
        after = new_after
    tests = [
        (t["pressure_bar"], np.asarray(t["heights_m"]))
        for t in recording_order(path.readings, frame.new_bar)
    ]
    return path, tests


def _uniform(builder, targets, n_readings, n_tests, cand, heights, need):
    """The uniform grid of the plan's size (at least ``need`` distinct heights a test, completed
    where the combined campaign's orders need more: :func:`complete_tests`), and at other sizes
    for the figure. Returns (same, curve, notes, (its readings, its frame))."""
    ps, tests = uniform_readings(n_readings, n_tests, cand, heights, need)
    tests, _, notes = complete_tests(builder, tests, heights, "uniform grid")
    readings, v, frame = _layout(builder, targets, tests)
    same = {
        "n_readings": int(sum(len(h) for _, h in tests)),
        "n_pressure_changes": len(tests),
        "pressures_bar": [float(p) for p in ps],
        "heights_mm": [[round(x * 1e3, 6) for x in h] for _, h in tests],
        "sd": _sd(v),
    }
    curve = []
    for f in (0.5, 1.0, 2.0, 4.0):
        n = int(round(f * n_readings))
        if MIN_TEST_READINGS * n_tests <= n <= MAX_PER_HEIGHT * heights.size * n_tests:
            _, tl = uniform_readings(n, n_tests, cand, heights, need)
            tl, _, _ = complete_tests(builder, tl, heights, "uniform grid")
            curve.append(
                {
                    "n_readings": n,
                    "n_pressure_changes": n_tests,
                    "sd": _sd(_layout(builder, targets, tl)[1]),
                }
            )
    return same, curve, notes, (tests, readings, frame)


def _theta_updated(builder, targets, layouts, sets: int, pool_draws: int, seed: int) -> list:
    """The prediction with theta updated (``uq._derived.plan_theta``) of each layout (tests,
    readings, frame), seeded ``seed``, ``seed + 1``, ...: the sets simulated from the frame's draws
    and reweighted over ``pool_draws`` of the pilot's held out of them (the frame's own when the
    builder has no others, or ``pool_draws`` is 0); None for each when ``sets`` is 0."""
    if not sets:
        return [None] * len(layouts)
    pool = builder.pool(pool_draws) if pool_draws else None
    return [
        theta_updated(
            frame, targets, rd, sets, seed + i, None if pool is None else _frame_of(pool, ts)
        )
        for i, (ts, rd, frame) in enumerate(layouts)
    ]


def make_plan(
    builder,
    targets,
    heights_m,
    candidates_bar,
    *,
    max_readings: int | None = None,
    target_sd=None,
    cost_per_pressure: float = COST_PER_PRESSURE,
    draws: int = SEARCH_DRAWS,
    theta_updates: int = 0,
    theta_pool: int = THETA_POOL,
    seed: int = 0,
) -> Plan:
    """Plan with a model's frames (``uq._derived.plan_frames``): the readings at ``heights_m`` of new
    tests at ``candidates_bar`` that make the targets' predicted sd smallest for the readings and
    set-pressure changes spent (module docstring).

    A model over all tests is refitted with orders and a pressure scaling that depend on how many
    tests the campaign has and which pressures they span (``uq._models.surface.default_orders``):
    adding tests can widen the model and with it the bands. So the search is run for each number of
    new tests, in the frame of that campaign (twice when the chosen pressures change the scaling),
    and every plan is evaluated exactly in its own frame; the best is kept (least objective at the
    budget, or least stand time reaching ``target_sd``).

    ``theta_updates`` > 0: the chosen plan and the uniform grid of its size also get the prediction
    with theta updated (:func:`_theta_updated`); the search itself keeps the closed form."""
    targets = list(targets)
    cand = np.sort(np.asarray(candidates_bar, float))
    heights = np.asarray(heights_m, float)
    tested = builder.tested
    required = required_tests(targets, tested, cand)
    frame_now, now = _now(builder, targets)
    paper = paper_tests(tested)
    v_paper = _layout(builder, targets, paper)[1] if paper else None
    scale2 = _reference_scale(builder, targets, frame_now, v_paper)
    objective = _Objective(scale2, target_sd)
    counts = (
        [cand.size]
        if getattr(builder, "fixed_frame", False)  # a model whose frame is the same for any plan
        else list(range(max(1, int(required.sum())), cand.size + 1))
    )
    kw = dict(
        max_readings=max_readings,
        target_sd=target_sd,
        cost_per_pressure=cost_per_pressure,
        draws=draws,
    )
    best, tried, stale = None, [], 0
    for n_new in counts:
        path, tests = _search_tests(builder, targets, cand, heights, n_new, required, scale2, **kw)
        if not path.readings:
            break
        n_searched = len(tests)
        tests, need, added = complete_tests(builder, tests, heights)
        readings, v, own = _layout(builder, targets, tests)
        vbar = np.mean(v, axis=0)
        score = objective.score(vbar, len(readings) + cost_per_pressure * len(tests))
        tried.append(
            {
                "new_tests": len(tests),
                "label": own.label,
                "n_readings": len(readings),
                "sd": _sd(v),
                "objective": objective(vbar),
            }
        )
        if best is None or score < best[0]:
            best, stale = (score, path, tests, readings, v, own, need, added), 0
        else:
            stale += 1
        if stale >= 2 or n_searched < n_new:
            break
    if best is None:
        raise InputError(
            "no planned reading reduces the targets' variance: the candidate pressures and heights "
            "do not inform them (`candidates_bar`, `heights_m`)"
        )
    _, path, tests, readings, v, own, need, added = best
    uniform, curve, added_uniform, (uni_tests, uni_readings, uni_frame) = _uniform(
        builder, targets, len(readings), len(tests), cand, heights, need
    )
    layouts = ((tests, readings, own), (uni_tests, uni_readings, uni_frame))
    upd, uni_upd = _theta_updated(builder, targets, layouts, theta_updates, theta_pool, seed)
    return Plan(
        model=builder.name,
        label=own.label,
        label_now=frame_now.label,
        targets=targets,
        readings=readings,
        tests=recording_order(readings, own.new_bar),
        n_readings=len(readings),
        n_pressure_changes=len(tests),
        cost_per_pressure=float(cost_per_pressure),
        value_now=now["value"],
        sd_now=now["sd"],
        sd_now_theta_spread=now["spread"],
        sd_predicted=_sd(v),
        uniform=uniform,
        paper={
            "n_readings": int(sum(len(h) for _, h in paper)),
            "n_pressure_changes": len(paper),
            "pressures_bar": [p for p, _ in paper],
            "sd": _sd(v_paper) if v_paper is not None else [None] * len(targets),
        },
        path=path,
        curves={"uniform": curve},
        target_sd=None if target_sd is None else [float(t) for t in target_sd],
        n_draws=int(v.shape[0]),
        tried=tried,
        min_heights_per_test=int(need),
        heights_added=added + added_uniform,
        theta_updates=int(theta_updates),
        sd_after_theta_updated=upd,
        sd_uniform_theta_updated=uni_upd,
    )


APPROXIMATIONS = (
    "predicted sd: the posterior variance given the sampled parameters theta (noise scales, "
    "travel factor) averaged over their current posterior draws; it does not depend on the "
    "readings' values (a preposterior closed form, no simulation)",
    "left out of sd_predicted: the spread of the posterior mean over theta (reported now as "
    "sd_now_theta_spread), and that the new readings also move theta (a noise scale poorly known "
    "from a small pilot changes the band; the discrepancy's length scale, whose short tail a pilot "
    "with tests far apart keeps from the prior, can carry most of a target's predicted variance "
    "next to a planned test, and tests close together then rule it out: docs/plan.md)",
    "sd_after_theta_updated (unless switched off): the planned readings simulated from the "
    "pilot's posterior predictive, the pilot's theta draws reweighted by each set's likelihood, "
    "the target's sd from the reweighted mixture (both parts of the theta effect); its distribution "
    "over the simulated sets; few effective draws (ess_min, ess_median) make it coarse",
    "pressure_for, natural_frequency and elastic_casing are linearised in the coefficients at the "
    "posterior mean given each theta (the delta method)",
    "the model after the plan is the one the default fit of the combined campaign takes (its orders "
    "and pressure scaling follow the tests); a different model choice after the new data is not "
    "foreseen",
    "every planned test (and every test of the uniform grid) visits at least min_heights_per_test "
    "distinct heights: what the model needs per test with the orders the combined campaign gets; "
    "readings added to reach it are listed in heights_added",
)


def plan_document(plan: Plan, model_info: dict | None = None) -> dict:
    """The JSON document of ``uq plan`` (docs/formats.md): the contract's keys and more."""

    def timed(layout: dict) -> dict:  # a compared layout with its stand time, as Plan.cost
        n, changes = layout["n_readings"], layout["n_pressure_changes"]
        return layout | {"stand_time_readings": n + plan.cost_per_pressure * changes}

    targets = []
    for i, t in enumerate(plan.targets):
        row = {
            "spec": t.spec,
            "unit": t.unit,
            "value_now": plan.value_now[i],
            "sd_now": plan.sd_now[i],
            "sd_now_theta_spread": plan.sd_now_theta_spread[i],
            "sd_predicted": plan.sd_predicted[i],
            "sd_uniform_grid": plan.uniform["sd"][i],
            "sd_paper_protocol": plan.paper["sd"][i],
        }
        now, after = plan.sd_now[i], plan.sd_predicted[i]
        row["less_certain_than_now"] = bool(now is not None and after is not None and after > now)
        row["sd_after_theta_updated"] = (
            None if plan.sd_after_theta_updated is None else plan.sd_after_theta_updated[i]
        )
        row["sd_uniform_grid_theta_updated"] = (
            None if plan.sd_uniform_theta_updated is None else plan.sd_uniform_theta_updated[i]
        )
        if plan.target_sd is not None:
            row["target_sd"] = plan.target_sd[i]
            row["reached"] = plan.reached[i]
        targets.append(row)
    tests = [
        {
            "pressure_bar": t["pressure_bar"],
            "heights_mm": [round(h * 1e3, 6) for h in t["heights_m"]],
            "branches": t["branches"],
        }
        for t in plan.tests
    ]
    return {
        "model": plan.model,
        "model_label": plan.label,
        "model_now": plan.label_now,
        **({"model_choice": model_info} if model_info else {}),
        "n_readings": plan.n_readings,
        "n_pressure_changes": plan.n_pressure_changes,
        "min_heights_per_test": plan.min_heights_per_test,
        "heights_added": list(plan.heights_added),
        "cost_per_pressure_readings": plan.cost_per_pressure,
        "stand_time_readings": plan.cost,
        "tests": tests,
        "targets": targets,
        "uniform_grid": timed(plan.uniform),
        "paper_protocol": timed(plan.paper),
        "search": {
            "stop": plan.path.stop,
            "plans_tried": plan.tried,
            "path": [
                {"n_readings": n, "n_pressure_changes": c, "sd": sd}
                for n, c, sd in zip(
                    plan.path.n_readings, plan.path.n_changes, plan.path.sd, strict=True
                )
            ],
        },
        "theta_draws": plan.n_draws,
        "theta_updates": {"sets": plan.theta_updates, "small_ess": SMALL_ESS},
        "approximations": list(APPROXIMATIONS),
    }
