"""``uq plan``: where to measure next (:mod:`uq._derived.plan`, docs/plan.md): the readings to add to
what FILE holds so that each target's posterior sd is smallest for the readings and set-pressure
changes spent, with the same numbers for a uniform grid and the paper's full protocol, the
recordings template the operator fills in at the stand (``--template``) and a figure (``--plot``).

Every option and target is checked before the (minutes-long) fit.
"""

from __future__ import annotations

import sys
import time

from uq._cli.common import option_type
from uq._derived.margin import AUTO
from uq._models import registry


def _grid(text: str, what: str):
    """``A,B,C`` or ``A:B:STEP`` (ends included) -> a sorted tuple of positive numbers."""
    text = text.strip()
    try:
        if ":" in text:
            parts = [float(t) for t in text.split(":")]
            if len(parts) != 3:
                raise ValueError
            a, b, step = parts
            if not (step > 0 and b >= a):
                raise ValueError(f"expected A:B:STEP with A <= B and STEP > 0, got '{text}'")
            n = int(round((b - a) / step))
            vals = [a + i * step for i in range(n + 1)]
            if vals[-1] < b - 1e-9 * max(1.0, abs(b)):
                vals.append(b)
        else:
            vals = [float(t) for t in text.split(",") if t.strip()]
    except ValueError as exc:
        if str(exc).startswith("expected"):
            raise
        raise ValueError(
            f"expected a list A,B,C or a range A:B:STEP of {what}, got '{text}'"
        ) from None
    if not vals or not all(v > 0 and v != float("inf") for v in vals):
        raise ValueError(f"expected positive {what}, got '{text}'")
    if len(vals) > 2000:
        raise ValueError(f"expected at most 2000 {what}, got {len(vals)}")
    return tuple(sorted({round(v, 9) for v in vals}))


def _theta_updates(text: str) -> int:
    """``--theta-updates``: 0 (off) or a number of simulated sets, at most ``MAX_THETA_UPDATES``."""
    try:
        value = int(text)
    except ValueError:
        raise ValueError(
            f"expected a whole number of simulated sets (0: off), got '{text}'"
        ) from None
    if not 0 <= value <= MAX_THETA_UPDATES:
        raise ValueError(f"expected 0 (off) to {MAX_THETA_UPDATES} simulated sets, got '{text}'")
    return value


MAX_THETA_UPDATES = 20000
theta_updates_count = option_type(_theta_updates)
pressures_grid = option_type(lambda text: _grid(text, "pressures in bar"))
heights_grid = option_type(lambda text: _grid(text, "heights in mm"))


def configure_plan(p) -> None:
    from uq._cli.cmd_design import add_sealed_options
    from uq._cli.common import (
        add_json,
        add_recordings,
        add_sampling,
        add_stand,
        finite_float,
        nonnegative_float,
        positive_float,
        positive_int,
    )

    add_recordings(p)
    add_sampling(p)
    add_json(p)
    g = p.add_argument_group("what to plan for (docs/plan.md)")
    g.add_argument(
        "--target",
        action="append",
        required=True,
        metavar="SPEC",
        help="a quantity to know better, repeatable: force@H mm,P bar (force@110mm,6.5bar), "
        "feff@H mm,P bar, pressure_for@H mm,W N (pressure_for@110mm,9000N), "
        "natural_frequency@H mm,P bar (with --volume-l ...), elastic_casing[@P1bar,P2bar]",
    )
    stop = g.add_mutually_exclusive_group(required=True)
    stop.add_argument("--max-readings", type=positive_int, help="add at most this many readings")
    stop.add_argument(
        "--target-sd",
        type=positive_float,
        action="append",
        metavar="VALUE",
        help="add readings until each target's predicted sd is at most VALUE, in the target's unit "
        "(N, m^2, Pa, Hz, 1/bar); one per --target in order, or one for a single target",
    )
    g.add_argument(
        "--pressures-bar",
        type=pressures_grid,
        help="candidate pressures of new tests, bar: a list A,B,C or a range A:B:STEP (default: the "
        "paper's 0.1, 1..10 bar and the targets' pressures); pressures FILE has tested are left out "
        "(a campaign holds one test per pressure)",
    )
    g.add_argument(
        "--heights-mm",
        type=heights_grid,
        help="candidate heights, mm: a list or a range A:B:STEP (default: FILE's height range every "
        "5 mm, and the targets' heights)",
    )
    g.add_argument(
        "--cost-per-pressure-readings",
        type=nonnegative_float,
        default=10.0,
        help="stand time of one set-pressure change (charging and settling), in readings",
    )
    g.add_argument(
        "--model",
        choices=(AUTO, *registry.names()),
        default=registry.default("plan"),
        help=f"the model to plan with (default {registry.default('plan')}): a registered model "
        f"({registry.help_words()}), or {AUTO}: the one uq margin would choose (the "
        f"{registry.default('margin')} model or the per-pressure cubics by PSIS-LOO)",
    )
    g.add_argument(
        "--draws",
        type=positive_int,
        default=200,
        help="posterior draws of the noise parameters the prediction averages over (default 200)",
    )
    from uq._derived.plan_theta import THETA_POOL, THETA_UPDATES

    g.add_argument(
        "--theta-updates",
        type=theta_updates_count,
        default=THETA_UPDATES,
        metavar="M",
        help="also predict the sd with theta updated by the planned readings: M simulated sets of "
        "them, the pilot's draws of theta reweighted by each set's likelihood; the median, 10-90 %% "
        f"range and mean of the sd over the sets (default {THETA_UPDATES}; 0: off; docs/plan.md)",
    )
    g.add_argument(
        "--theta-pool",
        type=positive_int,
        default=THETA_POOL,
        metavar="N",
        help="the pilot's draws of theta the simulated sets are reweighted over, held out of the "
        f"--draws they are simulated from (default {THETA_POOL}; more give a finer answer where "
        "the readings pin theta)",
    )
    o = p.add_argument_group("outputs")
    o.add_argument(
        "--template",
        metavar="PATH.csv",
        help="write the recordings template: the planned readings in recording order with force_N and "
        "piston_mm empty, for the operator to fill in at the stand (after FILE's own rows when FILE is "
        "a CSV in the contract's six columns)",
    )
    o.add_argument(
        "--plot",
        metavar="PATH.png",
        help="write the figure: each target's predicted sd against stand time, plan vs uniform grid "
        "vs the paper's protocol",
    )
    d = p.add_argument_group("natural_frequency targets: the sealed spring, as uq design")
    add_sealed_options(
        d,
        "internal volume at the target's height and pressure, litres, measured",
        "its standard deviation, litres",
        "extra reservoir volume, litres",
        with_dvdp=False,  # exact here: the plan's dV/dp_u has no sd
    )
    d.add_argument(
        "--dvdp-l-per-bar",
        type=finite_float,
        default=0.0,
        help="how the volume at the design height changes with pressure, L/bar (default 0, an "
        "assumption the answer states)",
    )
    add_stand(p)


# ----------------------------------------------------------------------------- checks before the fit


def _targets(args):
    from uq._derived.plan_targets import SealedInputs, parse_target
    from uq._io.errors import InputError

    sealed = SealedInputs(
        volume_l=args.volume_l,
        volume_sd_l=args.volume_sd_l,
        polytropic=args.polytropic,
        reservoir_l=args.reservoir_l,
        dvdp_l_per_bar=args.dvdp_l_per_bar,
        p_atm_bar=args.p_atm_bar,
    )
    if args.volume_l is not None and args.volume_sd_l > args.volume_l / 4:
        raise InputError(
            f"option --volume-sd-l: {args.volume_sd_l:g} L is more than a quarter of the volume "
            f"{args.volume_l:g} L: measure V more closely"
        )
    targets = [parse_target(s, sealed) for s in args.target]
    specs = [t.spec for t in targets]
    dup = next((s for s in specs if specs.count(s) > 1), None)
    if dup:
        raise InputError(f"option --target {dup}: given twice")
    if args.target_sd is not None and len(args.target_sd) not in (1, len(targets)):
        raise InputError(
            f"option --target-sd: {len(args.target_sd)} values for {len(targets)} targets; give one "
            "per --target, in order"
        )
    if args.target_sd is not None and len(args.target_sd) == 1 and len(targets) > 1:
        raise InputError(
            "option --target-sd: one value for several targets in different units; give one per "
            "--target, in order"
        )
    return targets


def _candidates(args, rec, targets):
    """Candidate pressures and heights, checked against the file and the targets (one line each)."""
    import numpy as np

    from uq._data.reference import PAPER_PRESSURES_BAR
    from uq._io.errors import InputError

    tested = np.array([t.pressure_bar for t in rec.tests])
    if args.pressures_bar is None:
        ps = set(PAPER_PRESSURES_BAR) | {p for t in targets for p in t.fixed_pressures()}
        where = "the default candidates (the paper's pressures and the targets')"
    else:
        ps, where = set(args.pressures_bar), "option --pressures-bar"
    cand = np.array(sorted(p for p in ps if not np.any(np.abs(tested - p) < 1e-9)))
    if cand.size == 0:
        raise InputError(
            f"{where}: every pressure is tested in {rec.path} already; a campaign holds one test per "
            "pressure: give untested pressures"
        )
    lo, hi = rec.height_range_m
    if args.heights_mm is None:
        grid = np.arange(np.ceil(lo * 200 - 1e-6), np.floor(hi * 200 + 1e-6) + 1) / 200.0
        extra = [t.height_m for t in targets if t.height_m is not None and lo <= t.height_m <= hi]
        heights = np.unique(np.round(np.concatenate([grid, [lo, hi], extra]), 9))
    else:
        heights = np.asarray(args.heights_mm, float) * 1e-3
    hlo, hhi = min(lo, heights.min()), max(hi, heights.max())
    for t in targets:
        if t.height_m is not None and not hlo - 1e-9 <= t.height_m <= hhi + 1e-9:
            raise InputError(
                f"option --target {t.spec}: {t.height_m * 1e3:g} mm is outside the tested and candidate "
                f"heights {hlo * 1e3:g}..{hhi * 1e3:g} mm; the models do not extrapolate"
            )
    return cand, heights


def _check_model(args, rec, targets) -> None:
    from uq._io.errors import InputError

    volume = [t.spec for t in targets if t.needs_volume]
    if volume and not rec.has_piston:
        raise InputError(
            f"option --target {volume[0]}: {rec.path} has no piston readings (force-only campaign or "
            "catalogue table), so the volume-derived area it needs is not known"
        )
    if volume and args.model == registry.CUBICS:
        raise InputError(
            f"option --target {volume[0]}: the per-pressure cubics do not interpolate the volume-derived "
            "area between tested pressures; plan with --model surface or thermodynamic"
        )
    if args.model == registry.CUBICS and rec.pressure_measured:
        raise InputError(
            f"option --model cubics: {rec.path} gives measured pressures, which the per-pressure cubics "
            "take as a covariate with a sensor offset per test; uq plan plans with the plain cubics "
            "only: plan with --model surface"
        )
    if args.model in (registry.THERMODYNAMIC, registry.DISCREPANCY) and len(rec.tests) < 2:
        raise InputError(
            f"option --model {args.model}: {rec.path} holds one test; the {args.model} model needs "
            f"tests at two pressures or more (plan with --model {registry.SURFACE} or "
            f"{registry.CUBICS})"
        )


# ----------------------------------------------------------------------------- the fit


def _fit(args, rec, targets, stand, settings):
    """(fit to plan with, model description with ``converged``): the model ``uq margin`` would
    choose, or the user's."""
    fit, info = _choose(args, rec, targets, stand, settings)
    conv = getattr(fit, "converged", None)
    info["converged"] = bool(fit.convergence.converged if conv is None else conv)
    return fit, info


def _choose(args, rec, targets, stand, settings):
    from uq._derived.comparison import fit_both, force_side
    from uq._derived.margin import choose

    if args.model != AUTO:
        data = force_side(rec) if args.model == registry.CUBICS else rec
        fit = registry.fit(args.model, data, seed=args.seed, settings=settings, stand=stand)
        return fit, {"name": fit.name, "why": f"chosen by the user (--model {args.model})"}
    fit, cub, comparison = fit_both(rec, seed=args.seed, settings=settings, stand=stand, jobs=None)
    ans, info = choose(fit, cub, comparison)
    info = {k: v for k, v in info.items() if k in ("why", "comparison")}
    reason = None  # why the cubics that answer uq margin cannot be planned with
    if ans is cub and any(t.needs_volume for t in targets):
        reason = "the targets need the volume-derived area between tested pressures, which the cubics do not interpolate"
    elif ans is cub and rec.pressure_measured:
        reason = "uq plan plans with the plain cubics, and these take the measured pressures as a covariate"
    if reason:
        info["why"] += f"; but {reason}: planned with the {fit.name} model"
        ans = fit
    info["name"] = ans.name
    return ans, info


# ----------------------------------------------------------------------------- outputs


def _fmt(value, unit: str) -> str:
    if value is None:
        return "-"
    if unit == "Pa":
        return f"{value / 1e5:.3g} bar"
    if unit == "m^2":
        return f"{value * 1e4:.4g} cm^2"
    if unit == "N":
        return f"{value:.4g} N"
    return f"{value:.3g} {unit}"


def _print(rec, plan, info) -> None:
    print(
        f"{rec.path}: {len(rec.tests)} tests, {rec.n_points} readings; {plan.label_now} now "
        f"({info.get('why', '')})"
    )
    print(
        f"add {plan.n_pressure_changes} test{'s' if plan.n_pressure_changes != 1 else ''}, "
        f"{plan.n_readings} readings (stand time {plan.cost:g} readings: a set-pressure change counts "
        f"as {plan.cost_per_pressure:g}); model after the plan: {plan.label}"
    )
    for t in plan.tests:
        hs = [h * 1e3 for h in t["heights_m"]]
        down = [f"{h:g}" for h, b in zip(hs, t["branches"], strict=True) if b == "compression"]
        up = [f"{h:g}" for h, b in zip(hs, t["branches"], strict=True) if b == "rebound"]
        line = f"  {t['pressure_bar']:g} bar: down {' '.join(down)} mm"
        if up:
            line += f"; up {' '.join(up)} mm"
        print(line)
    if plan.min_heights_per_test:
        print(
            f"  each new test visits at least {plan.min_heights_per_test} distinct heights: what "
            "the model after the plan needs per test (fewer and it refuses the campaign)"
        )
    for note in plan.heights_added:
        print(f"  note: {note}")
    if len(plan.tried) > 1:
        print("  plans tried (new tests: readings, predicted sd per target):")
        for t in plan.tried:
            sds = ", ".join(_fmt(v, x.unit) for v, x in zip(t["sd"], plan.targets, strict=True))
            mark = " <- chosen" if t["new_tests"] == plan.n_pressure_changes else ""
            print(f"    {t['new_tests']}: {t['n_readings']} readings, {sds} ({t['label']}){mark}")
    u, pp = plan.uniform, plan.paper
    print(
        f"predicted sd (theta-averaged closed form): now | after the plan | uniform grid "
        f"({u['n_readings']} readings, {u['n_pressure_changes']} tests) | paper's protocol "
        f"({pp['n_readings']} readings, {pp['n_pressure_changes']} tests)"
    )
    for i, t in enumerate(plan.targets):
        now = (
            f"{_fmt(plan.value_now[i], t.unit)} sd {_fmt(plan.sd_now[i], t.unit)}"
            if plan.sd_now[i] is not None
            else "not answered now (outside the tested pressures)"
        )
        line = (
            f"  {t.spec}: {now} | {_fmt(plan.sd_predicted[i], t.unit)} | "
            f"{_fmt(u['sd'][i], t.unit)} | {_fmt(pp['sd'][i], t.unit)}"
        )
        if plan.target_sd is not None:
            line += f"  (target {_fmt(plan.target_sd[i], t.unit)}: {'reached' if plan.reached[i] else 'NOT reached'})"
        print(line)
    _print_theta_updated(plan)
    worse = [
        t.spec
        for t, now, after in zip(plan.targets, plan.sd_now, plan.sd_predicted, strict=True)
        if now is not None and after is not None and after > now
    ]
    if worse:
        print(
            f"  note: after the plan {', '.join(worse)} {'is' if len(worse) == 1 else 'are'} less "
            f"certain than now: the model fitted after it ({plan.label}) has more coefficients than "
            f"now's ({plan.label_now}): its orders follow the number of tests (the plans tried, "
            "above, show each number of new tests)"
            if plan.label != plan.label_now
            else f"  note: after the plan {', '.join(worse)} is less certain than now"
        )
    print(
        "  left out: the spread of the estimate over the noise parameters (now, per target: "
        + ", ".join(
            _fmt(s, t.unit) for s, t in zip(plan.sd_now_theta_spread, plan.targets, strict=True)
        )
        + "), and what the new readings teach about the noise itself (docs/plan.md)"
        + (
            "; the prediction with theta updated (above) includes both"
            if plan.theta_updates
            else ""
        )
    )


THETA_TEACHES = 1.5  # closed form over the theta-updated median beyond which the command says so


def _print_theta_updated(plan) -> None:
    """The preposterior that also updates theta (uq._derived.plan_theta), next to the closed form."""
    if not plan.theta_updates:
        return
    from uq._derived.plan_theta import SMALL_ESS

    print(
        f"predicted sd with theta updated by the readings ({plan.theta_updates} simulated sets of "
        "them, the pilot's theta draws reweighted): median (10-90 %) and mean, after the plan | "
        "uniform grid"
    )
    for i, t in enumerate(plan.targets):
        parts = []
        for d in (plan.sd_after_theta_updated[i], plan.sd_uniform_theta_updated[i]):
            if d is None:
                parts.append("-")
                continue
            parts.append(
                f"{_fmt(d['median'], t.unit)} ({_fmt(d['p10'], t.unit)} to "
                f"{_fmt(d['p90'], t.unit)}), mean {_fmt(d['mean'], t.unit)}"
            )
        print(f"  {t.spec}: {parts[0]} | {parts[1]}")
    for t, closed, d in zip(
        plan.targets, plan.sd_predicted, plan.sd_after_theta_updated, strict=True
    ):
        if d is None or closed is None or not d["median"] > 0:
            continue
        r = closed / d["median"]
        if not 1 / THETA_TEACHES < r < THETA_TEACHES:
            print(
                f"  note: for {t.spec} the closed form is {r:.2g} times the median with theta "
                "updated: the planned readings will also teach theta, and the median is the "
                "typical campaign's sd (docs/plan.md, What it cannot know)"
            )
    d = next((x for x in plan.sd_after_theta_updated if x is not None), None)
    if d is not None:
        line = (
            f"  the weights keep {d['ess_median']:.0f} effective theta draws of {d['draws']} "
            + ("held out of those the sets come from " if d["held_out"] else "")
            + f"(Kish; median over the sets, least {d['ess_min']:.1f})"
        )
        if d["small_ess_share"] > 0:
            line += (
                f"; in {100 * d['small_ess_share']:.0f} % of the sets fewer than {SMALL_ESS:g}: "
                "the readings pin theta more finely than the draws resolve it, and the answer is "
                "as coarse as the few draws left (more --theta-pool)"
            )
        print(line)


def _template(args, rec, plan) -> str:
    """The recordings template (docs/formats.md): FILE's rows first when FILE is a CSV in the
    contract's six columns, then the planned readings in recording order, force and piston empty."""
    from pathlib import Path

    from uq._data.cells import PLANNED_MARK

    columns = ["pressure_bar", "height_mm", "force_N", "piston_mm", "branch", "step"]
    if not rec.has_piston:
        columns.remove("piston_mm")
    lines, order = [], columns
    body = []
    path = Path(args.file)
    if path.suffix.lower() == ".csv":
        text = path.read_text(encoding="utf-8-sig").splitlines()
        data = [ln for ln in text if ln.strip() and not ln.lstrip().startswith("#")]
        header = [h.strip() for h in data[0].split(",")] if data else []
        if sorted(header) == sorted(columns):
            order, body = header, text
    n = sum(len(t["heights_m"]) for t in plan.tests)
    lines.append(
        f"# {PLANNED_MARK}: {n} planned readings in {len(plan.tests)} new tests "
        f"(uq plan {' '.join(f'--target {s}' for s in args.target)}), model {plan.label}"
    )
    lines.append(
        "# fill in force_N"
        + (" and piston_mm" if "piston_mm" in columns else "")
        + " at the stand, then fit this file; uq refuses it while a planned reading is empty"
    )
    if body:
        lines.append(f"# {rec.path}'s own rows follow, then the planned tests")
        lines += body
    else:
        if path.suffix.lower() == ".csv":
            lines.append(
                f"# {rec.path} is not in the contract's columns ({', '.join(columns)}): its rows are "
                "not copied; join them with these (one test per pressure) to fit the campaign"
            )
        lines.append(",".join(order))
    for t in plan.tests:
        for step, (h, b) in enumerate(zip(t["heights_m"], t["branches"], strict=True)):
            cell = {
                "pressure_bar": f"{t['pressure_bar']:g}",
                "height_mm": f"{h * 1e3:.3f}",
                "force_N": "",
                "piston_mm": "",
                "branch": b,
                "step": str(step),
            }
            lines.append(",".join(cell[c] for c in order))
    return "\n".join(lines) + "\n"


def plot(plan, path) -> None:
    """Each target's predicted sd against stand time: the greedy plan's path, the uniform grid at
    several sizes, the paper's protocol, and the sd now (and the target sd)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from uq._io.files import write_figure_atomic

    T = len(plan.targets)
    fig, axes = plt.subplots(1, T, figsize=(4.6 * T, 3.8), squeeze=False)
    K = plan.cost_per_pressure
    for i, (ax, t) in enumerate(zip(axes[0], plan.targets, strict=True)):
        x = [n + K * c for n, c in zip(plan.path.n_readings, plan.path.n_changes, strict=True)]
        y = [s[i] for s in plan.path.sd]
        ax.step(x, y, where="post", color="C0", label="plan (search)")
        ax.plot([plan.cost], [plan.sd_predicted[i]], "o", color="C0", label="plan (exact)")
        ux = [c["n_readings"] + K * c["n_pressure_changes"] for c in plan.curves["uniform"]]
        uy = [c["sd"][i] for c in plan.curves["uniform"]]
        if ux:
            ax.plot(ux, uy, "s--", color="C1", label="uniform grid")
        pp = plan.paper
        if pp["sd"][i] is not None:
            ax.plot(
                [pp["n_readings"] + K * pp["n_pressure_changes"]],
                [pp["sd"][i]],
                "D",
                color="C2",
                label="paper's protocol",
            )
        if plan.sd_now[i] is not None:
            ax.axhline(plan.sd_now[i], color="0.5", ls=":", label="now")
        if plan.target_sd is not None:
            ax.axhline(plan.target_sd[i], color="C3", ls="-.", label="target sd")
        ax.set_xscale("symlog", linthresh=10)
        ax.set_yscale("log")
        ax.set_title(t.spec, fontsize=9)
        ax.set_xlabel(f"stand time, readings (a pressure change = {K:g})")
        ax.set_ylabel(f"predicted sd ({t.unit})")
        ax.grid(alpha=0.3)
    axes[0][0].legend(fontsize=7)
    fig.suptitle(f"uq plan: {plan.label}", fontsize=9)
    fig.tight_layout()
    write_figure_atomic(fig, path, dpi=110)
    plt.close(fig)


# ----------------------------------------------------------------------------- the command


def command_plan(args) -> int:
    from uq._cli.common import load, settings_from, stand_from
    from uq._derived import plan as P
    from uq._derived.plan_frames import frames_of
    from uq._io.files import emit_json, write_text_atomic

    t0 = time.perf_counter()  # --template and --plot are checked with every output (uq._cli.main)
    targets = _targets(args)
    settings = settings_from(args)
    fitted = (registry.default("margin"), registry.CUBICS) if args.model == AUTO else (args.model,)
    settings.require_walkers(max(registry.entry(m).n_sampled for m in fitted))
    stand = stand_from(args)
    rec = load(args)
    targets = [t.with_range([x.pressure_bar for x in rec.tests]) for t in targets]
    _check_model(args, rec, targets)
    cand, heights = _candidates(args, rec, targets)
    P.required_tests(targets, [t.pressure_bar for t in rec.tests], cand)  # refuses before the fit
    fit, info = _fit(args, rec, targets, stand, settings)
    plan = P.make_plan(
        frames_of(fit, args.draws),
        targets,
        heights,
        cand,
        max_readings=args.max_readings,
        target_sd=None if args.target_sd is None else list(args.target_sd),
        cost_per_pressure=args.cost_per_pressure_readings,
        theta_updates=args.theta_updates,
        theta_pool=args.theta_pool,
        seed=args.seed,
    )
    _print(rec, plan, info)
    doc = P.plan_document(plan, info)
    if args.template:
        write_text_atomic(args.template, _template(args, rec, plan))
        print(f"  template: {args.template}")
    if args.plot:
        plot(plan, args.plot)
        print(f"  figure: {args.plot}")
    print(f"  {time.perf_counter() - t0:.1f} s")
    emit_json(doc, args.json)
    converged = info.get("converged", True)
    if not converged:
        print(
            "  warning: the fit of FILE did not converge (rerun with more --max-steps)",
            file=sys.stderr,
        )
    return 1 if (args.strict and not converged) else 0
