"""``uq simulate`` and ``uq fit`` (and ``uq fit --config FILE``, the fit definitions in fits/)."""

from __future__ import annotations

import sys
import tomllib
from pathlib import Path

from uq._cli.common import (
    DEFAULT_PISTON_AREA_CM2,
    DEFAULT_SEED,
    add_json,
    add_output_units,
    add_pressure_ar1,
    add_recordings,
    add_sampling,
    add_stand,
    boolean,
    column_map,
    compression,
    load,
    output_units,
    positive_float,
    positive_int,
    pressure_ar1,
    record_convergence,
    seed,
    settings_from,
    stand_from,
    units_row,
    walkers,
)
from uq._io.errors import InputError

# uq._data.reference.PAPER_PRESSURES_BAR (tested equal)
PAPER_PRESSURES = "0.1,1,2,3,4,5,6,7,8,9,10"
SPRING_NAMES = (
    "n50",
    "n50-traditional",
    "n50-smooth",
    "n50-thermo",
    "n50-kink",
    "n50-knee",
    "n50-ripple",
)  # uq._stand.simulator.SPRINGS (tested equal)


def configure_simulate(p) -> None:
    p.add_argument(
        "--out", required=True, metavar="FILE.csv", help="the recordings file (CSV) to write"
    )
    p.add_argument(
        "--spring",
        default="n50",
        choices=SPRING_NAMES,
        help="true element (n50: Table 1's cubics; n50-traditional; n50-smooth; n50-thermo: one potential; "
        "n50-kink, n50-knee, n50-ripple: one potential, not smooth in pressure)",
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
    g = p.add_argument_group("the shape of the file (docs/formats.md, section 1)")
    g.add_argument(
        "--units",
        type=unit_list,
        default=None,
        metavar="LIST",
        help="units of the columns, e.g. psi,in,lbf,in3 (pressure: bar, psi, kPa, MPa, mbar; "
        "length, for height and piston: mm, m, in; force: N, kN, lbf; volume: l, cm3, m3, in3); "
        "the paper's bar, mm, N (and l) when not given",
    )
    g.add_argument(
        "--force-only",
        action="store_true",
        help="no piston or volume column: a stand that measures force only",
    )
    g.add_argument(
        "--catalogue",
        action="store_true",
        help="a data sheet: one compression pass without branch and step, values rounded as "
        "catalogues print them, and a volume_* column at --volume-at-bar instead of the piston",
    )
    g.add_argument(
        "--volume-at-bar",
        type=positive_float,
        metavar="P",
        help="with --catalogue: the pressure whose test lists the element's volume (one of "
        "--pressures; default the middle one)",
    )
    g.add_argument(
        "--record-pressure",
        nargs="?",
        const="both",
        choices=("both", "measured"),
        help="record each reading's pressure as a sensor reads it (1 Pa resolution, 0.1 %% gain "
        "error per campaign): 'both' (the default when given) writes set_pressure_* and the measured "
        "pressure_*, 'measured' only the measured pressure_* (the reader then clusters the tests)",
    )
    g.add_argument(
        "--compression-negative",
        action="store_true",
        help="write compression as negative force (a load frame's convention)",
    )
    g.add_argument(
        "--instrument",
        choices=("bluehill",),
        help="write an instrument's export instead: bluehill, an Instron Bluehill RawData file "
        "(title rows, header Time,Position,Load,Pressure, a units row, the compression pass of each "
        "test with its measured pressure, no piston, compression negative; docs/recordings.md)",
    )
    add_json(p)


def unit_list(text: str) -> dict:
    """``psi,in,lbf`` -> {"pressure": "psi", "height": "in", "force": "lbf"} (argparse type)."""
    import argparse

    from uq._data.units import QUANTITIES

    out: dict[str, str] = {}
    for name in (n.strip() for n in text.split(",") if n.strip()):
        quantity = next(
            (q for q in ("pressure", "height", "force", "volume") if name in QUANTITIES[q][1]), None
        )
        if quantity is None:
            known = ", ".join(
                s for q in ("pressure", "height", "force", "volume") for s in QUANTITIES[q][1]
            )
            raise argparse.ArgumentTypeError(f"unknown unit '{name}'; expected some of {known}")
        if quantity in out:
            raise argparse.ArgumentTypeError(
                f"two units for the {quantity}: {out[quantity]} and {name}"
            )
        out[quantity] = name
    if not out:
        raise argparse.ArgumentTypeError(f"expected a comma-separated list of units, got '{text}'")
    return out


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
    from uq._data.writing import write_bluehill_csv
    from uq._io.files import emit_json, write_text_atomic
    from uq._physics.mechanisms import parse_effects
    from uq._stand import shapes
    from uq._stand.simulator import Layout, simulate, simulation_comment

    stand = stand_from(args, model=False)
    effects = parse_effects(args.effect)
    if not 0 < args.x_min_mm < args.x_max_mm:
        raise InputError(
            f"options --x-min-mm/--x-max-mm: need 0 < x_min < x_max, got {args.x_min_mm:g}, {args.x_max_mm:g}"
        )
    pressures = _pressures(args.pressures)
    _check_instrument(args)
    volume_at = _volume_at(args, pressures)
    layout = Layout(pressures, args.x_max_mm * 1e-3, args.x_min_mm * 1e-3, args.step_mm * 1e-3)
    tests = simulate(
        args.spring,
        seed=args.seed,
        effects=effects,
        layout=layout,
        piston_area_m2=args.piston_area_cm2 * 1e-4,
        stand=stand,
    )
    if args.record_pressure or args.instrument:
        tests = shapes.record_pressure(tests, args.seed, stand)
    if args.catalogue:
        tests = shapes.catalogue(
            tests,
            args.spring,
            effects,
            volume_at_bar=volume_at,
            x_max_m=layout.x_max_m,
            element_volume_at_xmax_m3=stand.element_volume_at_xmax_m3,
            piston_area_m2=args.piston_area_cm2 * 1e-4,
        )
    units = dict(args.units or {})
    eff = " ".join(f"--effect {k}={v:g}" for k, v in effects.items())
    shape = _shape_options(args, volume_at)
    cmd = " ".join(
        w
        for w in (
            f"uq simulate --out {args.out} --spring {args.spring} --seed {args.seed} --pressures {args.pressures} "
            f"--x-max-mm {args.x_max_mm:g} --x-min-mm {args.x_min_mm:g} --step-mm {args.step_mm:g} "
            f"--piston-area-cm2 {args.piston_area_cm2:g}",
            eff,
            f"--stand {args.stand}" if args.stand else "",
            shape,
        )
        if w
    )
    comment = simulation_comment(args.spring, effects, stand, cmd)
    described = _shape_comment(args, volume_at, stand)
    if described:
        comment = comment + "\n" + described
    text = (
        write_bluehill_csv(tests, comment, units=units) if args.instrument == "bluehill" else None
    ) or write_recordings_csv(
        tests,
        comment,
        units=units,
        pressure={None: "set", "both": "both", "measured": "measured"}[args.record_pressure],
        order=not args.catalogue,
        piston=not (args.force_only or args.catalogue),
        volume=args.catalogue and not args.force_only,
        compression_negative=args.compression_negative,
        rounding=(
            shapes.catalogue_rounding({"height": "mm", "force": "N", "volume": "l"} | units)
            if args.catalogue
            else None
        ),
    )
    write_text_atomic(args.out, text)
    n = sum(len(t["height_m"]) for t in tests)
    print(
        f"wrote {args.out}: {len(tests)} tests, {n} points (spring {args.spring}, seed {args.seed}"
        f"{', effects ' + ', '.join(effects) if effects else ''}{', ' + shape if shape else ''})"
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
            "shape": {
                "units": {"pressure": "bar", "height": "mm", "force": "N"} | units,
                "force_only": bool(args.force_only),
                "catalogue": bool(args.catalogue),
                "volume_at_bar": volume_at if args.catalogue and not args.force_only else None,
                "record_pressure": args.record_pressure,
                "compression_negative": bool(args.compression_negative),
                "instrument": args.instrument,
            },
        },
        args.json,
    )
    return 0


def _check_instrument(args) -> None:
    """An instrument's export has its own shape: the shape options it sets itself are refused."""
    if not args.instrument:
        return
    clash = [
        o
        for o, given in (
            ("--catalogue", args.catalogue),
            ("--force-only", args.force_only),
            ("--record-pressure", args.record_pressure),
            ("--compression-negative", args.compression_negative),
        )
        if given
    ]
    if clash:
        raise InputError(
            f"option --instrument {args.instrument}: writes its own shape (one compression pass per test, "
            f"measured pressure, no piston, compression negative); drop {clash[0]}"
        )
    if args.units and "volume" in args.units:
        raise InputError(
            f"option --units: --instrument {args.instrument} writes no volume column; drop {args.units['volume']}"
        )


def _volume_at(args, pressures: tuple[float, ...]) -> float | None:
    """The pressure of the catalogue's volume column (--volume-at-bar, default the middle one)."""
    if args.volume_at_bar is not None and not args.catalogue:
        raise InputError("option --volume-at-bar: only with --catalogue")
    if not args.catalogue:
        return None
    if args.volume_at_bar is None:
        return sorted(pressures)[len(pressures) // 2]
    if not any(abs(p - args.volume_at_bar) < 1e-9 for p in pressures):
        raise InputError(
            f"option --volume-at-bar {args.volume_at_bar:g}: not one of --pressures {args.pressures}"
        )
    return args.volume_at_bar


def _shape_options(args, volume_at) -> str:
    """The shape options as a command line gives them (for the file's 'Regenerate' line)."""
    words = []
    if args.units:
        words.append("--units " + ",".join(args.units.values()))
    if args.force_only:
        words.append("--force-only")
    if args.catalogue:
        words.append(f"--catalogue --volume-at-bar {volume_at:g}")
    if args.record_pressure:
        words.append(f"--record-pressure {args.record_pressure}")
    if args.compression_negative:
        words.append("--compression-negative")
    if args.instrument:
        words.append(f"--instrument {args.instrument}")
    return " ".join(words)


def _shape_comment(args, volume_at, stand) -> str:
    """Comment lines that say how the file departs from the paper's full format."""
    from uq._stand import shapes

    lines = []
    if args.units:
        lines.append("Units: " + ", ".join(f"{q} in {u}" for q, u in args.units.items()) + ".")
    if args.catalogue:
        vol = (
            ""
            if args.force_only
            else f"; volume at {volume_at:g} bar from the element's {stand.element_volume_at_xmax_m3 * 1e3:g} L "
            "at x_max (assumed) plus the integral of the true volume slope"
        )
        lines.append(
            "Shape: catalogue table, one compression pass without branch and step, rounded as "
            f"catalogues print{vol}."
        )
    if args.force_only:
        lines.append("Shape: force only (no piston column).")
    if args.record_pressure:
        lines.append(
            f"Pressure: measured by a sensor of {stand.pressure_sensor_resolution_pa:g} Pa resolution with a "
            f"gain error drawn once per campaign (sd {stand.pressure_sensor_gain_sd:.1%}; this campaign's "
            f"{shapes.sensor_gain(args.seed, stand):+.4%}) on the held pressure p + dp."
        )
    if args.compression_negative:
        lines.append("Force: compression written negative (read with --compression negative).")
    if args.instrument == "bluehill":
        lines.append(
            "Shape: an Instron Bluehill RawData export, the compression pass of each test with its "
            "measured pressure, compression negative; read with --columns height=Position,force=Load "
            "--compression negative."
        )
    return "\n".join(lines)


def configure_fit(p) -> None:
    add_recordings(p, file_optional=True)
    add_sampling(p)
    add_json(p)
    add_stand(p)
    add_pressure_ar1(p)
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
    p.add_argument(
        "--csv",
        metavar="PATH",
        help="write the coefficient table: one row per test and coefficient, posterior mean, sd, "
        "5/50/95 %% quantiles, R-hat and ESS",
    )
    add_output_units(p)


#: fit.toml keys -> (option dest, parser of the option); paths are relative to the TOML file.
CONFIG_KEYS = {
    "data": {
        "recordings": ("file", None),
        "x0_mm": ("x0_mm", positive_float),
        "piston_area_cm2": ("piston_area_cm2", positive_float),
        "compression": ("compression", compression),
        "sheet": ("sheet", str),
        "absolute_pressure": ("absolute_pressure", boolean),
        "p_atm_bar": ("p_atm_bar", positive_float),
        "pressure_tolerance_bar": ("pressure_tolerance_bar", positive_float),
        "columns": ("columns", column_map),
        "units_row": ("units_row", units_row),
        "header_row": ("header_row", positive_int),
    },
    "sampling": {
        "seed": ("seed", seed),
        "walkers": ("walkers", walkers),
        "ensembles": ("ensembles", positive_int),
        "max_steps": ("max_steps", positive_int),
    },
    "noise": {"pressure_ar1": ("pressure_ar1", pressure_ar1)},
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


def omitted_lines(rec, result: dict) -> list[str]:
    """What a fit of a force-only or one-pass campaign leaves out, one line each (``uq fit``'s
    summary): the volume results of force-only tests, the volume column's use, the order check."""
    lines = []
    tests = result["tests"]
    force_only = [t["pressure_bar"] for t in tests if "piston" in t.get("omitted", {})]
    from_volume = [t["pressure_bar"] for t in tests if "piston_from" in t]
    if force_only:
        which = "every test" if len(force_only) == len(tests) else _bars(force_only)
        lines.append(
            f"volume results omitted ({which}): force-only, no piston_* or volume_* column "
            "(no piston coordinate, volume increment or volume-derived area)"
        )
    if from_volume:
        lines.append(
            f"piston coefficients of {_bars(from_volume)} from the volume column: L = -V / S "
            f"(S = {rec.piston_area_m2 * 1e4:g} cm^2), a_L's reference arbitrary"
        )
    if not rec.order_known:
        lines.append(
            "recording-order check skipped: one pass in unknown order (no branch and step columns)"
        )
    return lines


def _bars(pressures) -> str:
    return ", ".join(f"{p:g}" for p in pressures) + " bar"


def _print_fit_table(rec, result: dict, units) -> None:
    """The per-test summary, in the units asked for (``--units``): the force's a_P with its 90 %
    interval, b_L, the deviation measures and the worst R-hat and ESS."""
    h, f = units.shown("height"), units.shown("force")
    x0 = units.value("height", rec.x0_m)
    a_scale = units.coefficient("force", 0)[0]
    b_scale = units.coefficient("piston", 1)[0]
    print(f"{rec.path}: {len(rec.tests)} tests, {rec.n_points} points; x0 = {x0:g} {h}")
    print(
        f"{'p_u ' + units.shown('pressure'):>8} {'a_P ' + f:>10} {'90% interval':>23} {'b_L':>8} "
        f"{'s_P ' + f:>8} {'eps_P %':>8}  R-hat  ESS"
    )
    for t in result["tests"]:
        a = {k: v * a_scale for k, v in t["force"]["a_P"].items() if k in ("mean", "q05", "q95")}
        blocks = t["force"] | t.get("piston", {})
        b = f"{t['piston']['b_L']['mean'] * b_scale:>8.3f}" if "piston" in t else f"{'-':>8}"
        rmax = max(v["r_hat"] for v in blocks.values())
        emin = min(v["ess_bulk"] for v in blocks.values())
        p = units.value("pressure", t["pressure_bar"])
        flag = "" if t["convergence"]["converged"] else "  NOT CONVERGED"
        print(
            f"{p:>8g} {a['mean']:>10.1f} [{a['q05']:>10.1f}, {a['q95']:>10.1f}] {b} "
            f"{t['s_P_N'] * a_scale:>8.2f} {t['eps_P_pct']:>8.2f}  {rmax:.3f} {emin:.0f}{flag}"
        )


def command_fit(args) -> int:
    if args.file is None:
        raise InputError(
            "give the recordings CSV (uq fit FILE.csv) or a fit definition (uq fit --config FILE.toml)"
        )
    from uq._io.files import emit_json, staged_folder
    from uq._models.cubic_fit import fit_campaign

    stand = stand_from(args)
    rec = load(args)
    cf = fit_campaign(
        rec,
        seed=args.seed,
        settings=settings_from(args),
        stand=stand,
        pressure_ar1=args.pressure_ar1,
    )
    result = cf.to_json()
    units = output_units(rec, args.units)
    _print_fit_table(rec, result, units)
    for line in omitted_lines(rec, result):
        print(line)
    for t in result["tests"]:
        ph = t.get("pressure_holding")
        if ph and ph["model"] == "ar1":
            r = ph["rho"]
            print(
                f"{t['pressure_bar']:g} bar: AR(1) pressure-holding errors, lag-one correlation "
                f"rho = {r['mean']:.2f} (90 % [{r['q05']:.2f}, {r['q95']:.2f}])"
            )
        elif ph and ph["model"] == "measured" and "V_gas_m3" not in ph:
            o = ph["pressure_offset_Pa"]
            print(
                f"{t['pressure_bar']:g} bar: measured pressure as a covariate of the force, sensor "
                f"offset {o['mean']:.0f} Pa (90 % [{o['q05']:.0f}, {o['q95']:.0f}])"
            )
        elif ph and ph["model"] == "measured":
            v = ph["V_gas_m3"]
            print(
                f"{t['pressure_bar']:g} bar: measured pressure as a covariate, gas volume "
                f"{1e3 * v['mean']:.2f} L (90 % [{1e3 * v['q05']:.2f}, {1e3 * v['q95']:.2f}])"
            )
    for w in result["warnings"]:
        print(f"WARNING: {w}", file=sys.stderr)
    for w in result["model_warnings"]:
        print(f"WARNING (model): {w}", file=sys.stderr)
    if args.csv:
        from uq._derived.export import JSON_UNITS, coefficient_table
        from uq._io.files import write_text_atomic
        from uq._io.tables import csv_text

        header, rows = coefficient_table(cf, JSON_UNITS if args.units == "si" else units)
        write_text_atomic(args.csv, csv_text(header, rows))
        words = (
            "units of the recordings, u = x - x0 in their height unit"
            if args.units == "input"
            else "SI, u = x - x0 in m, as uq fit --json"
        )
        print(f"coefficient table: {args.csv} ({len(rows)} rows, {words})")
    if args.out:  # the posteriors and fit.json whole or not at all (a full disk leaves none)
        with staged_folder(args.out, last=("fit.json",)) as stage:
            paths = cf.save_posteriors(stage)
            emit_json(result, str(stage / "fit.json"))
        print(f"posteriors: {len(paths)} NetCDF files and fit.json in {args.out}")
    emit_json(result, args.json)
    record_convergence(args, result["converged"], unconverged_tests(result))
    return 0


def unconverged_tests(result: dict) -> str:
    """The tests of a ``uq fit`` JSON whose fits failed their convergence rules, in words."""
    bad = [t["pressure_bar"] for t in result["tests"] if not t["convergence"]["converged"]]
    return f"the cubics of {len(bad)} of {len(result['tests'])} tests ({_bars(bad)})"
