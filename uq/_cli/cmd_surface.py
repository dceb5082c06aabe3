"""``uq surface``: the command line of the models over all tests at once (the registry's,
``uq._models.registry``: the pressure-coupled surface by default, the thermodynamic potential, a
model plugged in from outside): fit, compare with the per-pressure cubics, print, and write the
JSON, the model's page (``uq._report.pages``) and the saved model (``--out``)."""

from __future__ import annotations

import time
from pathlib import Path

from uq._cli.common import add_stand, record_convergence, stand_from
from uq._io.errors import InputError
from uq._models import registry


def configure_surface(p) -> None:
    from uq._cli.common import add_json, add_recordings, add_sampling

    add_recordings(p)
    add_sampling(p)
    add_json(p)
    p.add_argument(
        "--model",
        choices=registry.names(over_all_tests=True),
        default=registry.default("surface"),
        help=registry.help_words(over_all_tests=True),
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
        help="write the model's page and its PNGs to DIR: MODEL.html (surface.html: heat maps, "
        "each test against the surface, comparison; thermodynamic.html: force and dV/dx by test, "
        "Maxwell ratio, implied piston area, comparison)",
    )
    p.add_argument(
        "--out",
        metavar="DIR",
        help="the folder to write: MODEL.nc (surface.nc, thermodynamic.nc), the fitted model "
        "saved for uq margin --fit and uq design --fit (docs/formats.md)",
    )
    add_stand(p)


def command_surface(args) -> int:
    from uq._cli.common import load, settings_from
    from uq._derived import comparison_worker

    t0 = time.perf_counter()
    entry = registry.entry(args.model)
    # a bad --stand file or --walkers is refused before the recordings are read
    stand = stand_from(args)
    settings = settings_from(args)
    settings.require_walkers(entry.n_sampled)
    if args.select and entry.select_orders is None:
        raise InputError(f"option --select: the {entry.name} model has no candidate orders to rank")
    rec = load(args)
    # the cubics fitted beside the model, and compared, in a worker that starts before this
    # process imports JAX (uq._derived.comparison_worker)
    beside = not args.no_compare and not args.select
    kw = {"seed": args.seed, "settings": settings, "stand": stand}
    with comparison_worker.running(rec, beside, **kw) as worker:
        return _surface(args, entry, rec, worker, t0, **kw)


def _surface(args, entry, rec, worker, t0: float, **kw) -> int:
    """The fit (``kw``: its seed, settings and stand), its comparison, what is printed and written."""
    from uq._derived.comparison import fit_both, sampler_words
    from uq._derived.margin import describe
    from uq._derived.model_check import predictive_check
    from uq._inference.convergence import CLI_ADVICE
    from uq._io.files import emit_json
    from uq._report.pages import write_model_page

    fit = comparison = None
    if args.select:
        fit, _ = entry.order_selection()(rec, **kw)
    elif args.no_compare:
        fit = entry.fit_function()(rec, **kw)
    if not args.no_compare:
        fit, _, comparison = fit_both(
            rec, surface_fit=fit, model=args.model, jobs=None, worker=worker, **kw
        )
    res = fit.to_json(comparison)
    PRINTERS.get(fit.name, _print_model)(rec, fit, res)
    if comparison:
        _print_comparison(fit.name, comparison)
    if line := sampler_words(fit):
        print(f"  {line}")
    for w in res["warnings"]:
        print(f"  warning: {w}")
    if args.report:
        print(f"  report: {write_model_page(fit, res, args.report)}")
    if args.out:
        why = (
            f"saved by uq surface --out: {fit.words} answers (uq margin FILE.csv --save-fit "
            "chooses between the models)"
        )
        if comparison is not None:
            why += f"; PSIS-LOO verdict '{comparison['better']}': {comparison['reason']}"
        path = fit.save(
            Path(args.out) / f"{fit.name}.nc",
            written_by="uq surface --out",
            model_info=describe(fit, comparison, why),
            comparison=comparison,
            warnings=fit.convergence.messages(CLI_ADVICE),
            # the check at the tested points, for uq margin --fit to repeat (docs/design.md 8)
            model_check=predictive_check(fit, seed=args.seed),
        )
        print(f"  saved fit: {path} (uq margin --fit answers from it)")
    # printed, not in the JSON: reruns give identical bytes
    print(f"  {time.perf_counter() - t0:.1f} s (fit {fit.seconds:.1f} s)")
    emit_json(res, args.json)
    record_convergence(args, res["converged"], f"the {args.model} model's sampler")
    return 0


def _print_comparison(name: str, c: dict) -> None:
    from uq._derived.comparison import words as comparison_words

    print(
        f"  PSIS-LOO: {name} {c[name]['elpd_loo']:.1f} ({c[name]['n_coefficients']} coef., "
        f"max Pareto k {c[name]['max_pareto_k']:.2f}), cubics {c[registry.CUBICS]['elpd_loo']:.1f} "
        f"({c[registry.CUBICS]['n_coefficients']} coef., max Pareto k "
        f"{c[registry.CUBICS]['max_pareto_k']:.2f}): "
        f"{comparison_words(c)}"
    )


def _print_head(rec, fit, what: str) -> None:
    """The model's first line and its order selection's candidates."""
    print(
        f"{rec.path}: {what} over {len(rec.tests)} tests, {rec.n_points} readings "
        f"({fit.orders_label}; {fit.n_coefficients} coefficients)"
    )
    for row in fit.selection:
        print(
            f"  candidate {row['orders']}: elpd_loo {row['elpd_loo']:.1f}, diff {row['elpd_diff']:.1f} +- {row['dse']:.1f}"
        )


def _print_noise(nz: dict) -> None:
    """The noise's line: floor, load cell, pressure holding and, with piston readings, the piston's."""
    piston = f", piston floor {nz['sL_m']['mean'] * 1e3:.3f} mm" if "sL_m" in nz else ""
    print(
        f"  noise: floor {nz['s0_N']['mean']:.1f} N, load cell {100 * nz['rel_load']['mean']:.2f} %, "
        f"pressure holding x{nz['k_p']['mean']:.2f}{piston}"
    )


def _print_thermo(rec, fit, res) -> None:
    _print_head(rec, fit, "thermodynamic model")
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
    _print_noise(res["noise"])


def _print_surface(rec, fit, res, what: str = "surface model") -> None:
    _print_head(rec, fit, what)
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
    _print_noise(res["noise"])
    if "omitted" in res:  # force only: no piston noise, no spread
        print(f"  {fit.omitted_reason}")
    else:
        print(
            f"  spread credibly non-zero over {100 * res['spread_credibly_nonzero_fraction']:.0f} % of the (x, p_u) range"
        )


def _print_discrepancy(rec, fit, res) -> None:
    """The surface's summary, then the discrepancy's amplitudes and length scale."""
    _print_surface(rec, fit, res, what=fit.words.removeprefix("the "))
    d = res["discrepancy"]

    def cm2(e):
        return f"{e['mean'] * 1e4:.2f} cm^2 [{e['q05'] * 1e4:.2f}, {e['q95'] * 1e4:.2f}]"

    vol = f", of the volume-derived area {cm2(d['a_V_m2'])}" if "a_V_m2" in d else ""
    ell = d["length_bar"]
    print(
        f"  discrepancy ({d['kernel']}): amplitude of the pressure-area deviation {cm2(d['a_F_m2'])}"
        f"{vol}, of the force not proportional to p_u {cm2(d['a_P_m2'])} (an area at "
        f"{d['p_ref_bar']:g} bar), length scale {ell['mean']:.2f} bar [{ell['q05']:.2f}, "
        f"{ell['q95']:.2f}]"
    )


def _print_model(rec, fit, res) -> None:
    """Any model without a summary of its own: what it is, its sampled parameters, the comparison."""
    print(
        f"{rec.path}: {fit.label} over {len(rec.tests)} tests, {rec.n_points} readings "
        f"({fit.n_coefficients} coefficients)"
    )
    for name, e in (res.get("noise") or {}).items():
        print(f"  {name}: {e['mean']:.4g} [{e['q05']:.4g}, {e['q95']:.4g}]")


#: the summaries of the models that have their own, by registry name
PRINTERS = {
    registry.SURFACE: _print_surface,
    registry.THERMODYNAMIC: _print_thermo,
    registry.DISCREPANCY: _print_discrepancy,
}
