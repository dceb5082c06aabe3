"""``uq surface``: the command line of :mod:`uq._models.surface`."""

from __future__ import annotations

import time

from uq._cli.common import add_stand, stand_from
from uq._derived.comparison import words as comparison_words
from uq._models import surface as _surface
from uq._models.surface import NOISE_NAMES, summary


def configure_surface(p) -> None:
    from uq._cli.common import add_json, add_recordings, add_sampling

    add_recordings(p)
    add_sampling(p)
    add_json(p)
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
        help="write surface.html (heat maps, overlays, comparison) and its PNGs to DIR",
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
    settings.require_walkers(len(NOISE_NAMES))
    rec = load(args)
    if args.select:
        fit, _ = _surface.select_orders(rec, seed=args.seed, settings=settings, stand=stand)
    else:
        fit = _surface.fit_surface(rec, seed=args.seed, settings=settings, stand=stand)
    comparison = None
    if not args.no_compare:
        _, _, comparison = fit_both(
            rec, seed=args.seed, settings=settings, stand=stand, surface_fit=fit
        )
    res = summary(fit, comparison)
    seconds_total = (
        time.perf_counter() - t0
    )  # printed, not in the JSON: reruns give identical bytes
    print(
        f"{rec.path}: surface model over {len(rec.tests)} tests, {rec.n_points} readings "
        f"({fit.orders.label}; {fit.beta.shape[-1]} coefficients)"
    )
    for row in fit.selection:
        print(
            f"  candidate {row['orders']}: elpd_loo {row['elpd_loo']:.1f}, diff {row['elpd_diff']:.1f} +- {row['dse']:.1f}"
        )
    for pb, r in res["at_x0"].items():
        f, s = r["force_N"], r["spread_N"]
        print(
            f"  x0, {pb} bar: F_p {r['pressure_area_m2']['mean'] * 1e4:.2f} cm^2, F_eff = P/p_u {r['feff_m2']['mean'] * 1e4:.2f} cm^2, "
            f"force {f['mean']:.0f} N "
            f"[{f['q05']:.0f}, {f['q95']:.0f}], traditional - measured {s['mean']:.0f} N [{s['q05']:.0f}, {s['q95']:.0f}]"
        )
    nz = res["noise"]
    print(
        f"  noise: floor {nz['s0_N']['mean']:.1f} N, load cell {100 * nz['rel_load']['mean']:.2f} %, "
        f"pressure holding x{nz['k_p']['mean']:.2f}, piston floor {nz['sL_m']['mean'] * 1e3:.3f} mm"
    )
    print(
        f"  spread credibly non-zero over {100 * res['spread_credibly_nonzero_fraction']:.0f} % of the (x, p_u) range"
    )
    if comparison:
        c = comparison
        print(
            f"  PSIS-LOO: surface {c['surface']['elpd_loo']:.1f} ({c['surface']['n_coefficients']} coef., "
            f"max Pareto k {c['surface']['max_pareto_k']:.2f}), cubics {c['cubics']['elpd_loo']:.1f} "
            f"({c['cubics']['n_coefficients']} coef., max Pareto k {c['cubics']['max_pareto_k']:.2f}): "
            f"{comparison_words(c)}"
        )
    for w in res["warnings"]:
        print(f"  warning: {w}")
    if args.report:
        from uq._report.surface import write_surface_report

        print(f"  report: {write_surface_report(fit, res, args.report)}")
    if args.out:
        from uq._derived.margin import save_surface_answer

        print(
            f"  saved fit: {save_surface_answer(fit, comparison, args.out, seed=args.seed, settings=settings, stand=stand)} "
            "(uq margin --fit answers from it)"
        )
    print(f"  {seconds_total:.1f} s (fit {fit.seconds:.1f} s)")
    emit_json(res, args.json)
    return 1 if (getattr(args, "strict", False) and not res["converged"]) else 0
