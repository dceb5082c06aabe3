"""``uq design``: the sealed spring from one campaign (:mod:`uq._derived.design`): load, vertical rate
and natural frequency at the design height with credible intervals, the catalogue's isobaric table,
and with ``--out DIR`` the data sheet (:mod:`uq._report.design`: HTML + CSV + JSON + figures).

The model is the registry's (``--model``, default ``uq._models.registry.default("design")``),
any fitted model with a volume-derived area. A force-only campaign (no piston column) has no
volume: it is fitted by the per-pressure cubics (the force-only cubic of ``uq fit``), the isobaric
loads are given and one line says why the sealed outputs are omitted. Without ``--volume-l`` the
sealed outputs are refused with one line saying what to measure.
"""

from __future__ import annotations

import sys
import time
from contextlib import nullcontext
from types import SimpleNamespace

from uq._cli.common import (
    add_misfit,
    nonnegative_float,
    option_type,
    positive_float,
    record_convergence,
    record_misfit,
)
from uq._models import registry

#: the default polytropic exponent: the natural frequency is a dynamic quantity (docs/design.md)
DEFAULT_POLYTROPIC = (1.3, 1.4)
POLYTROPIC_HELP = (
    "polytropic exponent n: 1 isothermal (slow strokes) .. 1.4 adiabatic (fast strokes), or a range "
    "LO..HI (n drawn uniformly per posterior draw: the stroke's heat exchange unknown); default "
    "1.3..1.4, the oscillation at the natural frequency (near adiabatic; manufacturers use 1.38); "
    "give 1 for slow load changes"
)
DVDP_HELP = (
    "how the volume at the design height changes with pressure, L/bar (isobaric tests cannot tell; "
    "default 0 give or take --dvdp-sd-l-per-bar, an assumption every output states), or 'model' "
    "for a model's own"
)
DVDP_SD_HELP = (
    "sd of --dvdp-l-per-bar, L/bar, drawn per posterior draw (default: with the default 0, the "
    "largest change of dV/dp_u between the design height and the tested heights that the "
    "recordings show; with a value given, 0 unless given; 0 makes the assumption exact)"
)


def _polytropic(text: str):
    """A value, or a range ``LO..HI`` within 1 .. 1.4."""
    from uq._physics.sealed import POLYTROPIC_RANGE

    parts = text.split("..")
    if len(parts) > 2:
        raise ValueError(f"expected a value or a range LO..HI, got '{text}'")
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        raise ValueError(f"expected a value or a range LO..HI, got '{text}'") from None
    lo, hi = POLYTROPIC_RANGE
    if not all(lo <= v <= hi for v in vals) or (len(vals) == 2 and vals[0] > vals[1]):
        raise ValueError(
            f"expected {lo:g} (isothermal) .. {hi:g} (adiabatic), or a range LO..HI within it, got '{text}'"
        )
    return vals[0] if len(vals) == 1 or vals[0] == vals[1] else (vals[0], vals[1])


def _dvdp(text: str):
    """Litres per bar, or ``model``."""
    if text.strip() == "model":
        return "model"
    try:
        v = float(text)
    except ValueError:
        raise ValueError(
            f"expected litres per bar, or 'model' (with --model thermodynamic), got '{text}'"
        ) from None
    if v != v or v in (float("inf"), float("-inf")):
        raise ValueError(f"expected a finite number of litres per bar, got '{text}'")
    return v


def _number_list(text: str) -> tuple[float, ...]:
    try:
        vals = tuple(float(t) for t in text.split(",") if t.strip())
    except ValueError:
        raise ValueError(f"expected comma-separated numbers, got '{text}'") from None
    if not vals or not all(v > 0 and v != float("inf") for v in vals):
        raise ValueError(f"expected comma-separated positive numbers, got '{text}'")
    return vals


polytropic = option_type(_polytropic)
dvdp = option_type(_dvdp)
number_list = option_type(_number_list)


def add_sealed_options(
    g, volume_help: str, volume_sd_help: str, reservoir_help: str, with_dvdp=True
):
    """The closed spring's volume options (--volume-l, --volume-sd-l, --polytropic, --reservoir-l
    and, ``with_dvdp``, --dvdp-l-per-bar and --dvdp-sd-l-per-bar), as uq design, export and plan
    take them."""
    g.add_argument("--volume-l", type=positive_float, help=volume_help)
    g.add_argument("--volume-sd-l", type=nonnegative_float, default=0.0, help=volume_sd_help)
    g.add_argument(
        "--polytropic", type=polytropic, default=DEFAULT_POLYTROPIC, help=POLYTROPIC_HELP
    )
    g.add_argument("--reservoir-l", type=nonnegative_float, default=0.0, help=reservoir_help)
    if with_dvdp:
        g.add_argument("--dvdp-l-per-bar", type=dvdp, default=None, help=DVDP_HELP)
        g.add_argument(
            "--dvdp-sd-l-per-bar", type=nonnegative_float, default=None, help=DVDP_SD_HELP
        )


def configure_design(p) -> None:
    from uq._cli.common import add_json, add_recordings, add_sampling, add_stand, positive_int

    add_recordings(p)
    add_sampling(p)
    add_json(p)
    g = p.add_argument_group("the sealed spring (docs/design.md)")
    g.add_argument(
        "--height-mm",
        type=positive_float,
        required=True,
        help="design height x_c, mm: where the spring is charged and closed",
    )
    g.add_argument(
        "--charge-bar",
        type=positive_float,
        required=True,
        help="charge overpressure p_c at the design height, bar",
    )
    add_sealed_options(
        g,
        "internal volume at the design height and charge pressure, litres, MEASURED (e.g. by "
        "filling the element with water: the stand gives only volume changes); required for the "
        "sealed outputs",
        "standard deviation of --volume-l, litres (drawn per posterior draw; default 0: exact)",
        "extra reservoir volume joined to the element, litres",
    )
    g.add_argument(
        "--forcing-hz",
        type=positive_float,
        help="forcing frequency, Hz: also give the transmissibility and isolation there",
    )
    g.add_argument(
        "--model",
        choices=registry.names(),
        default=registry.default("design"),
        help=f"the model of the element ({registry.help_words()}); a model with its own dV/dp_u "
        "offers --dvdp-l-per-bar model",
    )
    g.add_argument(
        "--no-compare",
        action="store_true",
        help="skip ranking the model against the per-pressure cubics by PSIS-LOO (saves the "
        "cubics' fit; the sheet and the JSON then say the answer was not ranked)",
    )
    s = p.add_argument_group("the data sheet")
    s.add_argument(
        "--charges-bar",
        type=number_list,
        help="charge pressures of the frequency chart, bar, comma-separated (default: the tested "
        "pressures from 1 bar up, within the tested range)",
    )
    s.add_argument(
        "--sheet-heights-mm",
        type=number_list,
        help="heights of the isobaric table, mm, comma-separated (default: every 10 mm of the tested "
        "range and the design height)",
    )
    s.add_argument(
        "--draws",
        type=positive_int,
        default=1000,
        help="posterior draws behind every estimate (default 1000)",
    )
    s.add_argument(
        "--out",
        metavar="DIR",
        help="folder for the data sheet: design.html, design.csv, design.json and the figures",
    )
    s.add_argument(
        "--figures",
        choices=("png", "svg"),
        default="png",
        help="format of the data sheet's figures (default png)",
    )
    add_stand(p)
    add_misfit(p)


def _planned(rec, model: str):
    """What the options are checked against before the fit: the campaign's tested ranges and
    what the model will offer (the registry's class of it)."""
    kind = registry.entry(model).model_class()
    p = [t.pressure_bar for t in rec.tests]
    return SimpleNamespace(
        height_range_m=tuple(float(v) for v in rec.height_range_m),
        pressure_range_bar=(float(min(p)), float(max(p))),
        label=kind.words,
        has_volume=True,
        has_dvdp=bool(kind.has_dvdp),
    )


def sealed_design(args, height_m: float, charge_bar: float, forcing_Hz: float | None = None):
    """The sealed spring the options describe (``--volume-l``, ``--volume-sd-l``, ``--polytropic``,
    ``--reservoir-l``, ``--dvdp-l-per-bar``, ``--dvdp-sd-l-per-bar``), closed at ``height_m`` with
    ``charge_bar`` (uq design, and uq margin's design margins). Without ``--dvdp-l-per-bar`` the
    assumption is 0 with the sd the recordings give (or ``--dvdp-sd-l-per-bar``); a value given
    is exact unless ``--dvdp-sd-l-per-bar`` gives its sd."""
    from uq._derived.design import SealedDesign

    dvdp_value = getattr(args, "dvdp_l_per_bar", None)
    sd = getattr(args, "dvdp_sd_l_per_bar", None)
    if dvdp_value is not None and sd is None:
        sd = 0.0  # a value the user gives is theirs: exact unless they give its sd
    return SealedDesign(
        height_m,
        charge_bar,
        args.volume_l,
        volume_sd_l=args.volume_sd_l,
        polytropic=args.polytropic,
        reservoir_l=args.reservoir_l,
        dvdp_l_per_bar=0.0 if dvdp_value is None else dvdp_value,
        forcing_Hz=forcing_Hz,
        p_atm_bar=getattr(args, "p_atm_bar", 1.01325),
        seed=args.seed,
        dvdp_sd_l_per_bar=sd,
    )


def _design_from(args):
    return sealed_design(args, args.height_mm * 1e-3, args.charge_bar, args.forcing_hz)


def _check_before_fit(args, rec) -> None:
    """Every option checked against the campaign before the (minutes-long) fit; one line each."""
    from uq._derived.design import check_design
    from uq._io.errors import InputError, refuse_outside

    ranges = _planned(rec, args.model)
    (lo, hi), (plo, phi) = ranges.height_range_m, ranges.pressure_range_bar
    never = "; the model does not extrapolate"
    refuse_outside("option --height-mm", args.height_mm * 1e-3, lo, hi, "heights", never)
    refuse_outside("option --charge-bar", args.charge_bar, plo, phi, "pressures", never)
    for h in args.sheet_heights_mm or ():
        refuse_outside("option --sheet-heights-mm", h * 1e-3, lo, hi, "heights")
    for c in args.charges_bar or ():
        refuse_outside("option --charges-bar", c, plo, phi, "pressures")
    if not rec.has_piston:
        return  # force-only: isobaric loads only (the sealed options are not used)
    if args.volume_l is None:
        raise InputError(
            "option --volume-l: required for the sealed spring: measure the element's internal volume at "
            f"{args.height_mm:g} mm and {args.charge_bar:g} bar (e.g. fill it with water and weigh it; the stand "
            "gives only volume changes) and give it in litres"
        )
    if args.volume_sd_l > args.volume_l / 4:
        raise InputError(
            f"option --volume-sd-l: {args.volume_sd_l:g} L is more than a quarter of the volume {args.volume_l:g} L; "
            "a normal uncertainty would give non-positive volumes: measure V more closely"
        )
    if args.dvdp_l_per_bar == "model" and not ranges.has_dvdp:
        with_own = [e.name for e in registry.entries() if e.model_class().has_dvdp]
        raise InputError(
            f"option --dvdp-l-per-bar: 'model' needs a model with its own dV/dp_u (--model "
            f"{' or '.join(with_own)}; {ranges.label} has none); give a number of litres per bar"
        )
    check_design(ranges, _design_from(args))


def command_design(args) -> int:
    from uq._cli.common import load, settings_from, stand_from
    from uq._derived import comparison_worker

    t0 = time.perf_counter()
    entry = registry.entry(args.model)
    stand = stand_from(args)
    settings = settings_from(args)
    settings.require_walkers(entry.n_sampled)  # before the recordings are read
    rec = load(args, needs=("piston", "order") if entry.needs_volume else ("order",))
    compare = rec.has_piston and not args.no_compare and entry.over_all_tests
    # how the data rank the model that answers: PSIS-LOO against the per-pressure cubics, fitted
    # beside the model and compared with it in a worker while the design is worked out; the
    # worker starts before this process imports JAX (uq._derived.comparison_worker)
    kw = {"seed": args.seed, "settings": settings, "stand": stand}
    # with --out the worker also draws the sheet's figures once it has compared (the design's
    # own process has the rest of the sheet to make meanwhile)
    target = {"target": "uq._report.design:compare_then_draw"} if args.out else {}
    with comparison_worker.running(rec, compare, **kw, **target) as worker:
        return _design(args, rec, compare, worker, t0, **kw)


def _design(args, rec, compare: bool, worker, t0: float, **kw) -> int:
    """The fit (``kw``: its seed, settings and stand), the design, what is printed and written."""
    import numpy as np

    from uq._derived import design as D
    from uq._derived.comparison import fitting_both, sampler_words
    from uq._derived.model_check import predictive_check
    from uq._io.files import emit_json

    _check_before_fit(args, rec)
    x_c = args.height_mm * 1e-3
    if args.sheet_heights_mm:
        heights = np.asarray(args.sheet_heights_mm, float) * 1e-3
    else:  # every 10 mm of the tested range, its ends and the design height
        lo, hi = rec.height_range_m
        xs = np.arange(np.ceil(lo * 100 - 1e-9), np.floor(hi * 100 + 1e-9) + 1) / 100.0
        heights = np.unique(np.round(np.concatenate([[lo, hi, x_c], xs]), 6))
    tested = sorted({t.pressure_bar for t in rec.tests})
    # the isobaric table also at the design charge when it was not tested (the sheet marks it)
    pressures = sorted(set(tested) | {float(args.charge_bar)})
    top = [v for v in tested if v >= 1.0]  # the frequency chart's default: from 1 bar up
    charges = args.charges_bar or tuple(top if len(top) >= 2 else tested)
    # a force-only campaign: the per-pressure cubics (uq fit's force-only cubic per test) give
    # the isobaric loads only
    answering = args.model if rec.has_piston else registry.CUBICS
    if compare:
        both = fitting_both(rec, model=answering, worker=worker, **kw)
    else:  # no comparison (None): the cubics have no other model fitted to rank against
        fit = registry.fit(answering, rec, **kw)
        both = nullcontext((fit, lambda: (None, None)))
    with both as (fit, compared):
        check = predictive_check(fit, seed=args.seed)  # at the tested points, before any answer
        model = fit.on_draws(args.draws)
        curves = None
        if rec.has_piston:
            design = _design_from(args)
            grid = D.DesignGrid(model, x_c)
            doc, curves = D.document_and_curves(model, design, charges, grid, sheet=bool(args.out))
        else:
            doc = _force_only(args, model)
        doc["isobaric"] = D.isobaric_table(model, pressures, heights, x_c)
        doc["tested_pressures_bar"] = tested
        source = _source(args, rec, fit)
        drawn = worker is not None and args.out  # the worker draws the sheet's figures
        if drawn:
            worker.send((doc | {"source": source}, curves, args.figures))
        elif args.out:  # the sheet's figures need no comparison: drawn while it runs
            from uq._report.design import design_figures

            figures = design_figures(
                doc | {"source": source}, curves=curves, figure_format=args.figures
            )
        answer = compared()
        doc["comparison"] = answer[1]
        if drawn:
            figures = answer[2]
    doc["model_check"] = check
    doc["source"] = source
    (_print_sealed if rec.has_piston else _print_force_only)(rec, model, doc)
    if args.out:
        from uq._report.design import write_design_sheet

        page = write_design_sheet(
            doc,
            args.out,
            curves=curves,
            reconstructed=rec.reconstructed,
            figure_format=args.figures,
            figures=figures,
        )
        print(f"  data sheet: {page}")
    if line := sampler_words(fit):
        print(f"  {line}")
    print(f"  {time.perf_counter() - t0:.1f} s (fit {fit.seconds:.1f} s)")
    emit_json(doc, args.json)
    record_convergence(args, fit.convergence.converged, f"{model.label}'s sampler")
    record_misfit(args, check)
    return 0


def _source(args, rec, fit) -> dict:
    """The JSON's ``source``: the recordings, the seed and the sampler's verdict."""
    from uq._inference.convergence import CLI_ADVICE

    return {
        "recordings": str(rec.path),
        "n_tests": len(rec.tests),
        "n_readings": int(rec.n_points),
        "seed": args.seed,
        "converged": bool(fit.convergence.converged),
        "warnings": fit.convergence.messages(CLI_ADVICE),
    }


FORCE_ONLY_WHY = (
    "sealed rate, natural frequency and sealed curve omitted: a force-only campaign (no piston_mm column) "
    "has no volume-derived area dV/dx, which the gas law of the sealed spring needs"
)


def _force_only(args, model) -> dict:
    """The document's start for a campaign without piston readings: the isobaric load at the
    design height and charge (``model``: the per-pressure cubics, interpolated in pressure)."""
    from uq._derived import design as D
    from uq._inference.summary import estimate

    x_c = args.height_mm * 1e-3
    load = model.force_draws([x_c], [args.charge_bar])[:, 0]
    return {
        "height_m": x_c,
        "charge_bar": args.charge_bar,
        "volume_l": args.volume_l,
        "polytropic": D.polytropic_keys(args.polytropic)[0],
        "reservoir_l": args.reservoir_l,
        "load_N": estimate(load),
        "rate_N_per_m": None,
        "natural_frequency_Hz": None,
        "polytropic_range": D.polytropic_keys(args.polytropic)[1],
        "omitted": FORCE_ONLY_WHY,
        "model": model.label,
        "n_draws": int(load.size),
        "level": D.LEVEL,
        "assumptions": [
            "the load is the element's isobaric force at the design height and charge pressure",
            model.label,
        ],
    }


def _print_force_only(rec, model, doc) -> None:
    e = doc["load_N"]
    print(
        f"{rec.path}: force-only campaign, {len(rec.tests)} tests, {rec.n_points} readings ({model.label})"
    )
    print(
        f"  isobaric load at {doc['height_m'] * 1e3:g} mm and {doc['charge_bar']:g} bar: "
        f"{e['mean']:.0f} N [{e['q05']:.0f}, {e['q95']:.0f}] (mean [90 % interval])"
    )
    print(f"  {FORCE_ONLY_WHY}")
    print_check(doc["model_check"])


def est(e: dict, scale: float = 1.0, fmt: str = ".0f") -> str:
    return f"{e['mean'] * scale:{fmt}} [{e['q05'] * scale:{fmt}}, {e['q95'] * scale:{fmt}}]"


def print_check(check: dict, named: bool = True) -> None:
    """The model's posterior-predictive check at the tested pressures (uq._derived.model_check),
    with the model's name (``named``) or without (uq margin's, which names it above)."""
    from uq._derived.model_check import table, words

    name = f" ({check['model']})" if named else ""
    print(f"  the model at the tested points{name}: {words(check)}")
    if check["misses"]:  # the per-pressure table where it matters
        for line in table(check):
            print(f"  {line}")


def _print_sealed(rec, model, doc) -> None:
    lo, hi = doc["polytropic_range"]
    n_words = f"n = {lo:g}" if lo == hi else f"n in {lo:g}..{hi:g}"
    res = f", reservoir {doc['reservoir_l']:g} L" if doc["reservoir_l"] else ""
    print(
        f"{rec.path}: {model.label}, {len(rec.tests)} tests, {rec.n_points} readings; sealed at "
        f"{doc['height_m'] * 1e3:g} mm, {doc['charge_bar']:g} bar, {doc['volume_l']:g} L, {n_words}{res}"
    )
    print(
        f"  load {est(doc['load_N'])} N, rate {est(doc['rate_N_per_m'], 1e-3, '.1f')} kN/m, natural frequency "
        f"{est(doc['natural_frequency_Hz'], 1, '.3f')} Hz (mean [90 % interval])"
    )
    if "transmissibility" in doc:
        t = doc["transmissibility"]
        print(
            f"  at {t['forcing_Hz']:g} Hz: transmissibility {est(t['transmissibility'], 1, '.3f')}, isolation "
            f"{est(t['isolation_pct'], 1, '.1f')} % (undamped)"
        )
    statement = doc["assumptions"][0]
    at = min(
        (i for i in (statement.find(k) for k in ("ASSUMED", "GIVEN", "how the volume")) if i >= 0),
        default=0,
    )
    print(f"  {statement[at:]}")
    c = doc["sealed_curve"]
    if len(c["height_m"]):
        print(
            f"  sealed curve {c['height_m'][0] * 1e3:g}..{c['height_m'][-1] * 1e3:g} mm"
            + (f" ({c['omitted_reason']})" if c["omitted_reason"] else "")
        )
    from uq._derived.comparison import words

    c = doc.get("comparison")
    print(
        "  how the data rank it (PSIS-LOO against the per-pressure cubics): "
        + (words(c) if c else "not ranked (--no-compare, or the cubics answered)")
    )
    print_check(doc["model_check"])
    for w in doc["source"]["warnings"]:
        print(f"  warning: {w}", file=sys.stderr)
