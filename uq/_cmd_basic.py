"""``uq simulate`` and ``uq fit``."""

from __future__ import annotations

import sys

from ._cmd_common import DEFAULT_SEED, add_json, add_recordings, add_sampling, load, settings_from
from ._errors import InputError
from ._io import emit_json, write_text_atomic
from ._mechanisms import parse_effects
from ._recordings import DEFAULT_PISTON_AREA_CM2, write_recordings_csv
from ._reference import PAPER_PRESSURES_BAR
from ._stand import SPRINGS, Layout, simulate


def configure_simulate(p) -> None:
    p.add_argument("--out", required=True, help="recordings CSV to write")
    p.add_argument("--spring", default="n50", help=f"true element: {', '.join(SPRINGS)} (default n50: Table 1)")
    p.add_argument("--seed", type=int, default=DEFAULT_SEED, help=f"random seed (default {DEFAULT_SEED})")
    p.add_argument("--effect", action="append", metavar="NAME=VALUE",
                   help="conceal a mechanism of CONTRACT.md section 4 (repeatable)")
    p.add_argument("--pressures", default=",".join(f"{x:g}" for x in PAPER_PRESSURES_BAR),
                   help="comma-separated set overpressures, bar (default: 0.1,1,...,10)")
    p.add_argument("--x-max-mm", type=float, default=155.0, help="start (maximum) height, mm")
    p.add_argument("--x-min-mm", type=float, default=65.0, help="minimum height, mm")
    p.add_argument("--step-mm", type=float, default=5.0, help="height step, mm")
    p.add_argument("--piston-area-cm2", type=float, default=DEFAULT_PISTON_AREA_CM2, help="piston area S, cm^2")


def _pressures(text: str) -> tuple[float, ...]:
    try:
        ps = tuple(float(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise InputError(f"option --pressures '{text}': expected comma-separated numbers in bar") from None
    if not ps or any(not p > 0 for p in ps):
        raise InputError(f"option --pressures '{text}': expected positive overpressures in bar")
    if len(set(ps)) != len(ps):
        raise InputError(f"option --pressures '{text}': a pressure is listed twice")
    return ps


def command_simulate(args) -> int:
    effects = parse_effects(args.effect)
    if not 0 < args.x_min_mm < args.x_max_mm:
        raise InputError(f"options --x-min-mm/--x-max-mm: need 0 < x_min < x_max, got {args.x_min_mm:g}, {args.x_max_mm:g}")
    layout = Layout(_pressures(args.pressures), args.x_max_mm * 1e-3, args.x_min_mm * 1e-3, args.step_mm * 1e-3)
    tests = simulate(args.spring, seed=args.seed, effects=effects, layout=layout, piston_area_m2=args.piston_area_cm2 * 1e-4)
    eff = " ".join(f"--effect {k}={v:g}" for k, v in effects.items())
    cmd = (f"uq simulate --out {args.out} --spring {args.spring} --seed {args.seed} --pressures {args.pressures} "
           f"--x-max-mm {args.x_max_mm:g} --x-min-mm {args.x_min_mm:g} --step-mm {args.step_mm:g} "
           f"--piston-area-cm2 {args.piston_area_cm2:g} {eff}").strip()
    comment = (
        "RECONSTRUCTED recordings from the virtual test stand of airspring-uq, not measured data.\n"
        f"Spring: {SPRINGS[args.spring].description}.\n"
        "Procedure of the paper's section 3.4, noise from its error budget (section 3.2).\n"
        f"Concealed effects: {', '.join(f'{k}={v:g}' for k, v in effects.items()) or 'none'}.\n"
        f"Regenerate: {cmd}"
    )
    write_text_atomic(args.out, write_recordings_csv(tests, comment))
    n = sum(len(t["height_m"]) for t in tests)
    print(f"wrote {args.out}: {len(tests)} tests, {n} points (spring {args.spring}, seed {args.seed}"
          f"{', effects ' + ', '.join(effects) if effects else ''})")
    return 0


def configure_fit(p) -> None:
    add_recordings(p)
    add_sampling(p)
    add_json(p)
    p.add_argument("--out", metavar="DIR", help="folder for the posteriors (NetCDF, one per test) and fit.json")


def command_fit(args) -> int:
    from ._cubic import fit_campaign
    from ._results import fit_json, save_posteriors

    rec = load(args)
    cf = fit_campaign(rec, seed=args.seed, settings=settings_from(args), jobs=args.jobs)
    result = fit_json(cf)
    print(f"{rec.path}: {len(rec.tests)} tests, {rec.n_points} points; x0 = {rec.x0_m * 1e3:g} mm")
    print(f"{'p_u bar':>8} {'a_P N':>10} {'90% interval':>23} {'b_L':>8} {'s_P N':>8} {'eps_P %':>8}  R-hat  ESS")
    for t in result["tests"]:
        a = t["force"]["a_P"]
        b = t["piston"]["b_L"]
        rmax = max(v["r_hat"] for v in (t["force"] | t["piston"]).values())
        emin = min(v["ess_bulk"] for v in (t["force"] | t["piston"]).values())
        print(f"{t['pressure_bar']:>8g} {a['mean']:>10.1f} [{a['q05']:>10.1f}, {a['q95']:>10.1f}] {b['mean']:>8.3f} "
              f"{t['s_P_N']:>8.2f} {t['eps_P_pct']:>8.2f}  {rmax:.3f} {emin:.0f}")
    for w in result["warnings"]:
        print(f"WARNING: {w}", file=sys.stderr)
    if args.out:
        from pathlib import Path

        paths = save_posteriors(cf, args.out)
        emit_json(result, str(Path(args.out) / "fit.json"))
        print(f"posteriors: {len(paths)} NetCDF files and fit.json in {args.out}")
    emit_json(result, args.json)
    if not result["converged"]:
        print("WARNING: sampling did not converge for every test (see above)" + ("; --strict: exit 1" if args.strict else ""), file=sys.stderr)
        return 1 if args.strict else 0
    return 0
