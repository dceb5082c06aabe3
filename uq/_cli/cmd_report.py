"""``uq report``: the command line of :mod:`uq._report.campaign` (fit the recordings, write the page)."""

from __future__ import annotations

import sys
import time

from uq._cli.common import (
    add_output_units,
    add_pressure_ar1,
    add_recordings,
    add_sampling,
    add_stand,
    load,
    output_units,
    positive_int,
    record_convergence,
    settings_from,
    stand_from,
)
from uq._derived.bands import campaign_bands
from uq._inference.convergence import CLI_ADVICE
from uq._io.files import emit_json
from uq._models import registry
from uq._report.campaign import MIN_DRAWS, FigureWorkers, omitted_lines, write_report
from uq._report.html import FIGURE_FORMATS


def configure_report(p) -> None:
    add_recordings(p)
    add_sampling(p)
    p.add_argument(
        "--out", required=True, metavar="DIR", help="folder for report.html and its figures"
    )
    p.add_argument(
        "--json",
        metavar="PATH",
        help="also write the fit's JSON (as uq fit --json, plus the derived bands' summary)",
    )
    p.add_argument(
        "--draws",
        type=positive_int,
        default=2000,
        help="joint posterior draws used for the bands (default 2000)",
    )
    p.add_argument(
        "--figures",
        choices=FIGURE_FORMATS,
        default="png",
        help="format of the figures, embedded in the page and written beside it: png (default) "
        "or svg (vector: sharp at any zoom and in print)",
    )
    p.add_argument(
        "--surface",
        action="store_true",
        help=f"also fit a model over all tests (--model, default the {registry.default('report')} "
        "model), compare it with the per-pressure cubics and write its page beside the report, "
        "linked from it (adds minutes on data/n50: docs/discrepancy.md)",
    )
    p.add_argument(
        "--model",
        choices=registry.names(over_all_tests=True),
        default=None,
        help=f"with --surface: which model over all tests (default {registry.default('report')}; "
        f"{registry.help_words(over_all_tests=True)})",
    )
    p.add_argument(
        "--reference",
        default="auto",
        metavar="FILE|paper|none|auto",
        help="what Tables 1 and 2 compare the posteriors with: a point-estimates JSON file (the format "
        "uq check reads, with s_P_N and eps_P_pct per test for Table 2), the paper's tables, or nothing; "
        "auto (default): the paper's tables for the bundled N-50 reconstruction, nothing otherwise",
    )
    add_stand(p)
    add_output_units(p)
    add_pressure_ar1(p)


def _reference(value: str):
    """``--reference``: read before any fitting, so a bad file fails at once."""
    if value in ("auto", "paper"):
        return value
    if value == "none":
        return None
    from uq._derived.check import reference_from_points

    return reference_from_points(value)


def command_report(args) -> int:
    from uq._io.errors import InputError
    from uq._models.cubic_fit import fit_campaign

    if args.draws < MIN_DRAWS:
        raise InputError(f"option --draws: at least {MIN_DRAWS} draws, got {args.draws}")
    stand = stand_from(args)
    reference = _reference(args.reference)
    rec = load(args)
    if args.model is not None and not args.surface:
        raise InputError(f"option --model {args.model}: only with --surface (the model it fits)")
    # the figure workers (one per further CPU) start now: their imports run beside the fit
    with FigureWorkers(None, len(rec.tests)) as workers:
        t0 = time.perf_counter()
        settings = settings_from(args)
        cf = fit_campaign(
            rec, seed=args.seed, settings=settings, stand=stand, pressure_ar1=args.pressure_ar1
        )
        surface = comparison = None
        if args.surface:
            from uq._derived.comparison import fit_both

            surface, _, comparison = fit_both(
                rec,
                seed=args.seed,
                settings=settings,
                stand=stand,
                cubic_fit=cf,
                model=args.model or registry.default("report"),
            )
        t_fit = time.perf_counter() - t0
        units = output_units(rec, "input") if args.units == "input" else None
        # each test's figure goes to the workers as soon as its bands are made
        cb = campaign_bands(
            cf, n_draws=args.draws, seed=args.seed, on_test=workers.ahead(cf, args.figures, units)
        )
        path = write_report(
            cf,
            args.out,
            bands=cb,
            seed=args.seed,
            comments=list(rec.comments),
            surface=surface,
            comparison=comparison,
            jobs=workers,
            figure_format=args.figures,
            reference=reference,
            units=units,
        )
    t_all = time.perf_counter() - t0
    print(
        f"{rec.path}: {len(rec.tests)} tests, {rec.n_points} points; fit {t_fit:.1f} s, report {t_all - t_fit:.1f} s"
    )
    if rec.reconstructed:
        print("RECONSTRUCTED recordings (the file's header says so), not measured data")
    sc = cb.scatter_at
    if sc:
        parts = ", ".join(
            f"{k} {v['mean']:.2f} % [{v['q05']:.2f}, {v['q95']:.2f}]" for k, v in sc.items()
        )
        print(
            f"F_eff scatter across {', '.join(f'{p:g}' for p in cb.scatter_pressures_bar)} bar (half range / mean): {parts}"
        )
    if cb.has_volume:
        print(f"traditional force from {cb.reference_note}")
    for line in omitted_lines(cf, cb):
        print(line)
    for t in cb.tests:
        a = t.at_x0
        trad = ""
        if "spread_ref_pct" in a:
            trad = f", traditional {a['spread_ref_pct']['mean']:+6.1f} %"
        if "spread_own_pct" in a:
            trad += f" (own volume curve {a['spread_own_pct']['mean']:+6.1f} %)"
        print(
            f"  {t.pressure_bar:>5g} bar at x0: P = {a['force_N']['mean']:9.1f} N, "
            f"F_eff = {a['feff_m2']['mean']:.5f} m^2{trad}"
        )
    for w in cf.warnings(CLI_ADVICE):
        print(f"WARNING: {w}", file=sys.stderr)
    for w in cf.model_warnings():
        print(f"WARNING (model): {w}", file=sys.stderr)
    print(f"report: {path}")
    if args.json:
        emit_json(cf.to_json() | {"bands": cb.to_json(), "report": str(path)}, args.json)
    from uq._cli.cmd_basic import unconverged_tests

    record_convergence(args, cf.converged, unconverged_tests(cf.to_json()))
    if surface is not None:
        record_convergence(args, surface.convergence.converged, f"{surface.words}'s sampler")
    return 0
