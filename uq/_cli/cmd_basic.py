"""``uq simulate`` and ``uq fit`` (and ``uq fit --config FILE``, the fit definitions in fits/)."""

from __future__ import annotations

import sys
import tomllib
from pathlib import Path

from uq._cli.common import (
    DEFAULT_PISTON_AREA_CM2,
    DEFAULT_SEED,
    add_json,
    add_recordings,
    add_sampling,
    add_stand,
    load,
    positive_float,
    positive_int,
    seed,
    settings_from,
    stand_from,
    walkers,
)
from uq._io.errors import InputError

PAPER_PRESSURES = (
    "0.1,1,2,3,4,5,6,7,8,9,10"  # uq._data.reference.PAPER_PRESSURES_BAR (tested equal)
)
SPRING_NAMES = (
    "n50",
    "n50-traditional",
    "n50-smooth",
)  # uq._stand.simulator.SPRINGS (tested equal)


def configure_simulate(p) -> None:
    p.add_argument(
        "--out", required=True, metavar="FILE.csv", help="the recordings file (CSV) to write"
    )
    p.add_argument(
        "--spring",
        default="n50",
        choices=SPRING_NAMES,
        help="true element (n50: Table 1's cubics; n50-traditional; n50-smooth)",
    )
    p.add_argument("--seed", type=seed, default=DEFAULT_SEED, help="random seed")
    p.add_argument(
        "--effect",
        action="append",
        metavar="NAME=VALUE",
        help="conceal a mechanism (docs/formats.md, mechanisms; repeatable)",
    )
    p.add_argument(
        "--pressures", default=PAPER_PRESSURES, help="comma-separated set overpressures, bar"
    )
    p.add_argument(
        "--x-max-mm", type=positive_float, default=155.0, help="start (maximum) height, mm"
    )
    p.add_argument("--x-min-mm", type=positive_float, default=65.0, help="minimum height, mm")
    p.add_argument("--step-mm", type=positive_float, default=5.0, help="height step, mm")
    p.add_argument(
        "--piston-area-cm2",
        type=positive_float,
        default=DEFAULT_PISTON_AREA_CM2,
        help="piston area S, cm^2",
    )
    add_stand(
        p,
        help="the stand that makes the noise: error budget and gas volumes (TOML, keys of "
        "uq._data.stand_description.StandDescription; default the paper's stand, section 3.2)",
    )
    add_json(p)


def _pressures(text: str) -> tuple[float, ...]:
    try:
        ps = tuple(float(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise InputError(
            f"option --pressures '{text}': expected comma-separated numbers in bar"
        ) from None
    if not ps or any(not 0 < p < float("inf") for p in ps):
        raise InputError(f"option --pressures '{text}': expected positive overpressures in bar")
    if len(set(ps)) != len(ps):
        raise InputError(f"option --pressures '{text}': a pressure is listed twice")
    return ps


def command_simulate(args) -> int:
    from uq._data.recordings import write_recordings_csv
    from uq._io.files import emit_json, write_text_atomic
    from uq._physics.mechanisms import parse_effects
    from uq._stand.simulator import Layout, simulate, simulation_comment

    stand = stand_from(args, model=False)
    effects = parse_effects(args.effect)
    if not 0 < args.x_min_mm < args.x_max_mm:
        raise InputError(
            f"options --x-min-mm/--x-max-mm: need 0 < x_min < x_max, got {args.x_min_mm:g}, {args.x_max_mm:g}"
        )
    layout = Layout(
        _pressures(args.pressures), args.x_max_mm * 1e-3, args.x_min_mm * 1e-3, args.step_mm * 1e-3
    )
    tests = simulate(
        args.spring,
        seed=args.seed,
        effects=effects,
        layout=layout,
        piston_area_m2=args.piston_area_cm2 * 1e-4,
        stand=stand,
    )
    eff = " ".join(f"--effect {k}={v:g}" for k, v in effects.items())
    cmd = (
        f"uq simulate --out {args.out} --spring {args.spring} --seed {args.seed} --pressures {args.pressures} "
        f"--x-max-mm {args.x_max_mm:g} --x-min-mm {args.x_min_mm:g} --step-mm {args.step_mm:g} "
        f"--piston-area-cm2 {args.piston_area_cm2:g} {eff}{' --stand ' + str(args.stand) if args.stand else ''}"
    ).strip()
    comment = simulation_comment(args.spring, effects, stand, cmd)
    write_text_atomic(args.out, write_recordings_csv(tests, comment))
    n = sum(len(t["height_m"]) for t in tests)
    print(
        f"wrote {args.out}: {len(tests)} tests, {n} points (spring {args.spring}, seed {args.seed}"
        f"{', effects ' + ', '.join(effects) if effects else ''})"
    )
    emit_json(
        {
            "out": str(args.out),
            "spring": args.spring,
            "seed": args.seed,
            "effects": effects,
            "n_tests": len(tests),
            "n_points": n,
            "pressures_bar": [float(t["pressure_bar"]) for t in tests],
        },
        args.json,
    )
    return 0


def configure_fit(p) -> None:
    add_recordings(p, file_optional=True)
    add_sampling(p)
    add_json(p)
    p.add_argument(
        "--out",
        metavar="DIR",
        help="the folder to write: posteriors (NetCDF, one per test) and fit.json",
    )
    p.add_argument(
        "--config",
        metavar="FILE.toml",
        help="fit definition (e.g. fits/n50/fit.toml): recordings, stand constants, sampler; options given on the command line win",
    )


#: fit.toml keys -> (option dest, parser of the option); paths are relative to the TOML file.
CONFIG_KEYS = {
    "data": {
        "recordings": ("file", None),
        "x0_mm": ("x0_mm", positive_float),
        "piston_area_cm2": ("piston_area_cm2", positive_float),
    },
    "sampling": {
        "seed": ("seed", seed),
        "walkers": ("walkers", walkers),
        "ensembles": ("ensembles", positive_int),
        "max_steps": ("max_steps", positive_int),
    },
}
DESCRIPTIVE_SECTIONS = ("model", "check")  # documentation for the reader; not options


def read_fit_config(path) -> dict:
    """Option values from a fit definition (``uq fit --config``); every key checked, one line on error."""
    import argparse

    path = Path(path)
    try:
        with open(path, "rb") as fh:
            raw = tomllib.load(fh)
    except OSError as exc:
        raise InputError(f"option --config {path}: {exc.strerror}") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: not valid TOML: {exc}") from None
    values = {}
    for section, table in raw.items():
        if section in DESCRIPTIVE_SECTIONS:
            continue
        if section not in CONFIG_KEYS or not isinstance(table, dict):
            raise InputError(
                f"{path}: unknown section [{section}]; expected {', '.join(['data', 'sampling', *DESCRIPTIVE_SECTIONS])}"
            )
        for key, value in table.items():
            if key not in CONFIG_KEYS[section]:
                raise InputError(
                    f"{path}: [{section}] unknown key '{key}'; expected {', '.join(CONFIG_KEYS[section])}"
                )
            dest, parse = CONFIG_KEYS[section][key]
            if parse is None:
                values[dest] = str(path.parent / str(value))
                continue
            try:
                values[dest] = parse(str(value))
            except argparse.ArgumentTypeError as exc:
                raise InputError(f"{path}: [{section}] {key}: {exc}") from None
    return values


def command_fit(args) -> int:
    if args.file is None:
        raise InputError(
            "give the recordings CSV (uq fit FILE.csv) or a fit definition (uq fit --config FILE.toml)"
        )
    from uq._derived.results import fit_json, save_posteriors
    from uq._io.files import emit_json, staged_folder
    from uq._models.cubic import fit_campaign

    rec = load(args)
    cf = fit_campaign(rec, seed=args.seed, settings=settings_from(args))
    result = fit_json(cf)
    print(f"{rec.path}: {len(rec.tests)} tests, {rec.n_points} points; x0 = {rec.x0_m * 1e3:g} mm")
    print(
        f"{'p_u bar':>8} {'a_P N':>10} {'90% interval':>23} {'b_L':>8} {'s_P N':>8} {'eps_P %':>8}  R-hat  ESS"
    )
    for t in result["tests"]:
        a = t["force"]["a_P"]
        b = t["piston"]["b_L"]
        rmax = max(v["r_hat"] for v in (t["force"] | t["piston"]).values())
        emin = min(v["ess_bulk"] for v in (t["force"] | t["piston"]).values())
        print(
            f"{t['pressure_bar']:>8g} {a['mean']:>10.1f} [{a['q05']:>10.1f}, {a['q95']:>10.1f}] {b['mean']:>8.3f} "
            f"{t['s_P_N']:>8.2f} {t['eps_P_pct']:>8.2f}  {rmax:.3f} {emin:.0f}"
        )
    for w in result["warnings"]:
        print(f"WARNING: {w}", file=sys.stderr)
    for w in result["model_warnings"]:
        print(f"WARNING (model): {w}", file=sys.stderr)
    if args.out:  # the posteriors and fit.json whole or not at all (a full disk leaves none)
        with staged_folder(args.out, last=("fit.json",)) as stage:
            paths = save_posteriors(cf, stage)
            emit_json(result, str(stage / "fit.json"))
        print(f"posteriors: {len(paths)} NetCDF files and fit.json in {args.out}")
    emit_json(result, args.json)
    if not result["converged"]:
        print(
            "WARNING: sampling did not converge for every test (see above)"
            + ("; --strict: exit 1" if args.strict else ""),
            file=sys.stderr,
        )
        return 1 if args.strict else 0
    return 0
