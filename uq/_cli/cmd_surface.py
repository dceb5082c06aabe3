"""``uq surface``: the command line of the models over all tests at once: the pressure-coupled
surface (:mod:`uq._models.surface`, the default) and the thermodynamic potential
(:mod:`uq._models.thermo`, ``--model thermodynamic``)."""

from __future__ import annotations

import time

from uq._cli.common import add_stand, record_convergence, stand_from
from uq._derived.comparison import FITTERS
from uq._derived.comparison import words as comparison_words
from uq._models import surface as _surface
from uq._models import thermo as _thermo
from uq._models.thermo import THETA_NAMES


def configure_surface(p) -> None:
    from uq._cli.common import add_json, add_recordings, add_sampling

    add_recordings(p)
    add_sampling(p)
    add_json(p)
    p.add_argument(
        "--model",
        choices=("surface", "thermodynamic"),
        default="surface",
        help="surface: force and volume surfaces smooth in pressure (no link between them); "
        "thermodynamic: force and volume from one potential G(x, p_u) (the Maxwell relation holds)",
    )
    p.add_argument(
        "--select",
        action="store_true",
        help="rank the candidate polynomial orders by PSIS-LOO and keep the best (slower)",
    )
    p.add_argument(
        "--no-compare",
        action="store_true",
        help="skip the PSIS-LOO comparison with the per-pressure cubics",
    )
    p.add_argument(
        "--report",
        metavar="DIR",
        help="write the model's page and its PNGs to DIR: surface.html (heat maps, each test "
        "against the surface, comparison), or thermodynamic.html with --model thermodynamic "
        "(force and dV/dx by test, Maxwell ratio, implied piston area, comparison)",
    )
    p.add_argument(
        "--out",
        metavar="DIR",
        help="the folder to write: surface.nc, the surface posterior as a saved answer for uq margin --fit (docs/formats.md)",
    )
    add_stand(p)


def command_surface(args) -> int:
    from uq._cli.common import load, settings_from
    from uq._derived.comparison import fit_both
    from uq._io.files import emit_json

    t0 = time.perf_counter()
    stand = stand_from(
        args
    )  # a bad --stand file or --walkers is refused before the recordings are read
    settings = settings_from(args)
    settings.require_walkers(len(THETA_NAMES))
    if args.model == "thermodynamic" and args.out is not None:
        from uq._io.errors import InputError

        raise InputError(
            "option --out: not yet with --model thermodynamic (the saved answer is the surface "
            "model's); use --json or --report"
        )
    rec = load(args)
    module = _thermo if args.model == "thermodynamic" else _surface
    if args.select:
        fit, _ = module.select_orders(rec, seed=args.seed, settings=settings, stand=stand)
    else:
        fit = FITTERS[args.model](rec, seed=args.seed, settings=settings, stand=stand)
    comparison = None
    if not args.no_compare:
        _, _, comparison = fit_both(
            rec, seed=args.seed, settings=settings, stand=stand, surface_fit=fit
        )
    res = fit.to_json(comparison)
    if args.model == "thermodynamic":
        _print_thermo(rec, fit, res, comparison)
    else:
        _print_surface(rec, fit, res, comparison)
    for w in res["warnings"]:
        print(f"  warning: {w}")
    if args.report:
        if args.model == "thermodynamic":
            from uq._report.thermo import write_thermo_report as write_page
        else:
            from uq._report.surface import write_surface_report as write_page

        print(f"  report: {write_page(fit, res, args.report)}")
    if args.out:
        from uq._derived.margin import save_surface_answer

        print(
            f"  saved fit: {save_surface_answer(fit, comparison, args.out, seed=args.seed, settings=settings, stand=stand)} "
            "(uq margin --fit answers from it)"
        )
    # printed, not in the JSON: reruns give identical bytes
    print(f"  {time.perf_counter() - t0:.1f} s (fit {fit.seconds:.1f} s)")
    emit_json(res, args.json)
    record_convergence(args, res["converged"], f"the {args.model} model's sampler")
    return 0


def _print_comparison(name: str, c: dict) -> None:
    print(
        f"  PSIS-LOO: {name} {c[name]['elpd_loo']:.1f} ({c[name]['n_coefficients']} coef., "
        f"max Pareto k {c[name]['max_pareto_k']:.2f}), cubics {c['cubics']['elpd_loo']:.1f} "
        f"({c['cubics']['n_coefficients']} coef., max Pareto k {c['cubics']['max_pareto_k']:.2f}): "
        f"{comparison_words(c)}"
    )


def _print_thermo(rec, fit, res, comparison) -> None:
    print(
        f"{rec.path}: thermodynamic model over {len(rec.tests)} tests, {rec.n_points} readings "
        f"({fit.orders.label}; {fit.beta.shape[-1]} coefficients)"
    )
    for row in fit.selection:
        print(
            f"  candidate {row['orders']}: elpd_loo {row['elpd_loo']:.1f}, diff {row['elpd_diff']:.1f} +- {row['dse']:.1f}"
        )
    for pb, r in res["at_x0"].items():
        f, m = r["force_N"], r["maxwell_ratio"]
        print(
            f"  x0, {pb} bar: force {f['mean']:.0f} N [{f['q05']:.0f}, {f['q95']:.0f}], F_eff = P/p_u "
            f"{r['feff_m2']['mean'] * 1e4:.2f} cm^2, dV/dx {r['volume_area_m2']['mean'] * 1e4:.2f} cm^2, "
            f"(dV/dx)/(P/p_u) {m['mean']:.3f} [{m['q05']:.3f}, {m['q95']:.3f}]"
        )
    S = res["implied_piston_area_m2"]
    print(
        f"  piston area the recordings imply: {S['mean'] * 1e4:.2f} cm^2 [{S['q05'] * 1e4:.2f}, "
        f"{S['q95'] * 1e4:.2f}] (given {res['piston_area_m2'] * 1e4:.2f} cm^2)"
    )
    nz = res["noise"]
    print(
        f"  noise: floor {nz['s0_N']['mean']:.1f} N, load cell {100 * nz['rel_load']['mean']:.2f} %, "
        f"pressure holding x{nz['k_p']['mean']:.2f}, piston floor {nz['sL_m']['mean'] * 1e3:.3f} mm"
    )
    if comparison:
        _print_comparison("thermodynamic", comparison)


def _print_surface(rec, fit, res, comparison) -> None:
    print(
        f"{rec.path}: surface model over {len(rec.tests)} tests, {rec.n_points} readings "
        f"({fit.label}; {fit.beta.shape[-1]} coefficients)"
    )
    for row in fit.selection:
        print(
            f"  candidate {row['orders']}: elpd_loo {row['elpd_loo']:.1f}, diff {row['elpd_diff']:.1f} +- {row['dse']:.1f}"
        )
    for pb, r in res["at_x0"].items():
        f, s = r["force_N"], r.get("spread_N")
        spread = (
            f", traditional - measured {s['mean']:.0f} N [{s['q05']:.0f}, {s['q95']:.0f}]"
            if s
            else ""
        )
        print(
            f"  x0, {pb} bar: F_p {r['pressure_area_m2']['mean'] * 1e4:.2f} cm^2, F_eff = P/p_u {r['feff_m2']['mean'] * 1e4:.2f} cm^2, "
            f"force {f['mean']:.0f} N [{f['q05']:.0f}, {f['q95']:.0f}]{spread}"
        )
    nz = res["noise"]
    if "omitted" in res:  # force only: no piston noise, no spread
        print(
            f"  noise: floor {nz['s0_N']['mean']:.1f} N, load cell {100 * nz['rel_load']['mean']:.2f} %, "
            f"pressure holding x{nz['k_p']['mean']:.2f}"
        )
        print(f"  {_surface.volume_omitted_reason(rec)}")
    else:
        print(
            f"  noise: floor {nz['s0_N']['mean']:.1f} N, load cell {100 * nz['rel_load']['mean']:.2f} %, "
            f"pressure holding x{nz['k_p']['mean']:.2f}, piston floor {nz['sL_m']['mean'] * 1e3:.3f} mm"
        )
        print(
            f"  spread credibly non-zero over {100 * res['spread_credibly_nonzero_fraction']:.0f} % of the (x, p_u) range"
        )
    if comparison:
        _print_comparison("surface", comparison)
