"""``uq export``: the characteristic as tables for the tools engineers use (docs/export.md).

From recordings (fitted here, the registry's default model unless ``--model``) or from a saved model
(``uq surface --out``, ``uq margin --save-fit``: loaded, no refit), the posterior of the force, the
effective areas and the volume on a grid of heights and pressures, written as the contract's CSV
table, a workbook in the catalogue's shape, a Simscape script or MAT-file, TeimOrbit property
files (one per statistic) or JSON; ``--sealed`` adds the closed spring of ``uq design``'s options.
"""

from __future__ import annotations

import sys
from pathlib import Path

from uq._cli.common import (
    add_json,
    add_output_units,
    add_recordings,
    add_sampling,
    add_stand,
    option_type,
    positive_float,
    positive_int,
    say,
)
from uq._io.errors import InputError
from uq._models import registry

FORMATS = ("csv", "xlsx", "simscape", "teimorbit", "json")  # uq._derived.export.FORMATS (tested)
#: --out's suffix -> the format it names when --format is not given
SUFFIX_FORMATS = {
    ".csv": "csv",
    ".xlsx": "xlsx",
    ".m": "simscape",
    ".mat": "simscape",
    ".json": "json",
    ".tpf": "teimorbit",
}
#: library parameters -> this command's options (the global table maps some names to others)
EXPORT_OPTIONS = {
    "heights_m": "--heights-mm",
    "pressures_bar": "--pressures-bar",
    "extrapolate": "--extrapolate",
    "model": "--model",
    "height_m": "--height-mm",
    "charge_bar": "--charge-bar",
}


def _parsed(parse: str):
    """An option type parsing its text with ``uq._derived.export``'s function ``parse`` (imported
    when an option is parsed)."""

    def check(text: str):
        from uq._derived import export

        return getattr(export, parse)(text)

    return option_type(check)


def configure_export(p) -> None:
    from uq._cli.cmd_design import add_sealed_options  # the same closed spring as uq design

    add_recordings(p)
    p.set_defaults(file=None)
    p.add_argument(
        "--out",
        required=True,
        metavar="PATH",
        help="the file to write (teimorbit: one file per statistic, PATH with _mean, _q05, ... "
        "before its suffix); its suffix names the format when --format is not given (.csv, "
        ".xlsx, .m or .mat, .tpf, .json)",
    )
    p.add_argument(
        "--format",
        choices=FORMATS,
        help="csv: the contract's table; xlsx: heights down, pressures across, a sheet per "
        "quantity and statistic and a provenance sheet; simscape: the Air Spring block's vectors "
        "(a MATLAB script, or a MAT-file for --out *.mat); teimorbit: Adams/Car and Altair "
        "MotionView air-spring property files; json: the grid with estimate objects",
    )
    p.add_argument(
        "--model",
        choices=registry.names(),
        help=f"the model that answers (default {registry.default('export')}, the model every "
        f"answer between tested pressures uses; {registry.help_words()}); with a saved model, "
        "its own",
    )
    p.add_argument(
        "--heights-mm",
        type=_parsed("parse_heights_mm"),
        metavar="LIST|A:B:STEP",
        help="heights of the grid, mm: 65,80,100 or 65:155:5 (default: every tested height)",
    )
    p.add_argument(
        "--pressures-bar",
        type=_parsed("parse_pressures_bar"),
        metavar="LIST",
        help="overpressures of the grid, bar (default: the tested pressures); between tested "
        "pressures the model answers",
    )
    p.add_argument(
        "--quantiles",
        type=_parsed("parse_quantiles"),
        default="0.05,0.5,0.95",
        metavar="LIST",
        help="posterior quantiles written beside the mean",
    )
    add_output_units(p)
    p.add_argument(
        "--extrapolate",
        action="store_true",
        help="allow heights and pressures beyond the tested ones (refused otherwise); every format "
        "says which are extrapolated",
    )
    p.add_argument(
        "--draws",
        type=positive_int,
        default=4000,
        help="posterior draws behind every estimate (the model's fixed draws, thinned evenly)",
    )
    g = p.add_argument_group("the closed spring (--sealed, uq design's options: docs/design.md)")
    g.add_argument(
        "--sealed",
        action="store_true",
        help="also the closed spring's force, stiffness (load/height, Simscape's stiffness "
        "parameterisation) and rate against height, charged at --height-mm to --charge-bar",
    )
    g.add_argument("--height-mm", type=positive_float, help="design height x_c, mm")
    g.add_argument("--charge-bar", type=positive_float, help="charge overpressure at x_c, bar")
    add_sealed_options(
        g,
        "internal volume at x_c and the charge, litres",
        "sd of --volume-l, litres",
        "extra reservoir, litres",
    )
    add_sampling(p)
    _export_allow_unconverged_help(p)
    add_stand(p)
    add_json(p)


def _export_allow_unconverged_help(p) -> None:
    """``--allow-unconverged`` (uq._cli.common.add_convergence, via the sampling options) says what
    it means here: uq export writes nothing for such a fit without it."""
    for action in p._actions:
        if "--allow-unconverged" in action.option_strings:
            action.help = (
                "export a fit that failed its convergence rules (R-hat, ESS, chain length), from "
                "recordings or saved so: every file then says NOT CONVERGED and the exit status is "
                "0; without it such a fit is refused, nothing is written, exit status 1"
            )


def _format(args) -> str:
    suffix = Path(args.out).suffix.lower()
    named = SUFFIX_FORMATS.get(suffix)
    if args.format:
        if named is not None and named != args.format:  # an xlsx named .csv opens as nonsense
            raise InputError(
                f"option --format {args.format}: --out's suffix '{suffix}' names {named}; give "
                f"--out a suffix of {args.format} ("
                + ", ".join(s for s, f in SUFFIX_FORMATS.items() if f == args.format)
                + ") or leave --format out"
            )
        return args.format
    if suffix not in SUFFIX_FORMATS:
        raise InputError(
            f"option --format: needed, --out's suffix '{suffix}' names no format "
            f"({', '.join(f'{s} {f}' for s, f in SUFFIX_FORMATS.items())})"
        )
    return SUFFIX_FORMATS[suffix]


def _is_saved(path: str) -> bool:
    """A saved model (NetCDF: HDF5 or classic) rather than recordings, by its first bytes."""
    try:
        with open(path, "rb") as fh:
            head = fh.read(8)
    except OSError:
        return False
    return head.startswith((b"\x89HDF\r\n\x1a\n", b"CDF\x01", b"CDF\x02"))


def _saved_in(folder: Path) -> str:
    """The one saved model in a folder ``uq surface --out`` wrote (its ``*.nc``); one line else."""
    found = sorted(str(p) for p in folder.glob("*.nc") if _is_saved(str(p)))
    if len(found) != 1:
        raise InputError(
            f"{folder}: a folder; give the recordings or a saved model"
            + (
                f" (it holds {len(found)} .nc files: name one)"
                if found
                else " (it holds no .nc file)"
            )
        )
    return found[0]


def _check_usage(args) -> None:
    if args.file is None:
        raise InputError("give the recordings (FILE.csv) or a saved model (SAVED.nc) to export")
    if Path(args.file).is_dir():  # uq surface --out's folder: the model saved in it
        args.file = _saved_in(Path(args.file))
    closed = (("--height-mm", args.height_mm), ("--charge-bar", args.charge_bar))
    closed += (("--volume-l", args.volume_l),)
    missing = [o for o, v in closed if v is None]
    if args.sealed and missing:
        raise InputError(
            f"option --sealed: needs {', '.join(missing)} (where the spring is closed, at which "
            "charge, with what volume inside)"
        )
    given = [o for o, v in closed if v is not None]
    if not args.sealed and given:
        raise InputError(f"option {given[0]}: only with --sealed (the closed spring)")
    teimorbit = args.format == "teimorbit" or Path(args.out).suffix.lower() == ".tpf"
    if teimorbit and str(args.out) == "-":
        raise InputError("option --out: teimorbit writes one file per statistic; give a path")


def _model(args, saved: bool):
    """The fitted model, its recordings (None for a saved one) and the provenance it brings."""
    from uq._cli.common import load, settings_from, stand_from

    if saved:
        from uq._models.saved import load as load_saved
        from uq._models.saved import read

        model = load_saved(args.file)
        if args.model is not None and args.model != model.name:
            raise InputError(
                f"option --model {args.model}: {args.file} holds the {model.label}; export it as it "
                f"is, or fit the recordings again with --model {args.model}"
            )
        attrs, _ = read(args.file)
        provenance = {
            "recordings_path": Path(str(attrs.get("recordings_path", ""))).name,
            "recordings_sha256": str(attrs.get("recordings_sha256", "")),
            "seed": int(attrs["seed"]) if int(attrs.get("seed", -1)) >= 0 else "",
            "source": f"saved model {Path(args.file).name} (written by {attrs.get('written_by', '?')}, "
            f"uq {attrs.get('uq_version', '?')}); no refit",
        }
        return model, None, provenance
    name = args.model or registry.default("export")
    entry = registry.entry(name)
    stand = stand_from(args)
    settings = settings_from(args)
    settings.require_walkers(entry.n_sampled)
    rec = load(args)
    if entry.needs_volume and not rec.has_volume:
        raise InputError(
            f"option --model {name}: needs the volume readings (piston_* or volume_*), which "
            f"{rec.path} has not; export with the default model"
        )
    model = registry.fit(name, rec, seed=args.seed, settings=settings, stand=stand)
    provenance = {
        "recordings_path": Path(rec.path).name,
        "recordings_sha256": rec.sha256 or "",
        "seed": args.seed,
    }
    return model, rec, provenance


def command_export(args) -> int:
    try:
        return _export(args)
    except InputError as exc:  # this command's options (the global table names others so)
        raise exc.for_cli(EXPORT_OPTIONS) from None


def _export(args) -> int:
    from uq._cli.cmd_design import sealed_design
    from uq._cli.common import output_units
    from uq._derived import export
    from uq._io.files import emit_json
    from uq._io.version import __version__, date_stamp

    _check_usage(args)
    fmt = _format(args)
    saved = _is_saved(args.file)
    if saved and args.units == "input":
        raise InputError(
            f"option --units input: {args.file} is a saved model, which keeps no units of the "
            "recordings; export from the recordings, or with --units si"
        )
    model, rec, provenance = _model(args, saved)
    if _refused_unconverged(args, model, saved):
        return 1
    units = output_units(rec, args.units)
    heights = None if args.heights_mm is None else args.heights_mm * 1e-3
    provenance |= {
        "uq_version": __version__,
        "date": date_stamp(),
        "between": f"{model.label}: {registry.entry(model.name).words}",
    }
    grid = export.export_grid(
        model,
        heights,
        args.pressures_bar,
        quantiles=args.quantiles,
        extrapolate=args.extrapolate,
        n_draws=args.draws,
        provenance=provenance,
    )
    if args.sealed:
        design = sealed_design(args, args.height_mm * 1e-3, args.charge_bar)
        grid = export.sealed_export(grid, model, design)
    grid = export.with_notes(grid, _source_notes(model, rec))
    paths = export.write(grid, fmt, args.out, units, when=provenance["date"])
    shape = f"{grid.pressures_bar.size} pressures x {grid.heights_m.size} heights"
    say(
        f"{args.file}: exported the {model.label} ({shape}, {grid.n_draws} "
        f"draws; {', '.join(f'{q:g}' for q in grid.quantiles)} quantiles) as {fmt}: "
        + ", ".join(str(p) for p in paths),
        args.json,
    )
    for note in grid.notes:
        say(f"  {note}", args.json)
    if args.json:  # the grid with the contract's estimate objects (SI), and what was written
        doc = export.json_document(grid)
        emit_json(
            {
                "out": [str(p) for p in paths],
                "format": fmt,
                "units": "si" if args.units == "si" else units.__dict__,
                "converged": _converged(model),
                "n_draws": grid.n_draws,
                **doc,
            },
            args.json,
        )
    return 0


def _converged(model) -> bool:
    conv = getattr(model, "convergence", None)
    return conv is None or bool(conv.converged)  # None: exact, independent draws


def _refused_unconverged(args, model, saved: bool) -> bool:
    """A fit that failed its convergence rules: refused (one line on stderr, True: nothing is to
    be written, exit status 1) unless ``--allow-unconverged``, when it is recorded for the command
    line's policy (uq._cli.common.convergence_status: exit 0, said on stderr) and exported with a
    NOT CONVERGED note in every file."""
    from uq._cli.common import record_convergence
    from uq._inference.convergence import CLI_ADVICE

    if _converged(model):
        return False
    if args.allow_unconverged:
        record_convergence(args, False, f"{model.label}'s sampler")
        return False
    warnings = model.convergence.messages(CLI_ADVICE)
    first = warnings[0] if warnings else "its convergence rules failed"
    where = (
        f"{args.file} holds a fit that failed its convergence rules; fit the recordings again with "
        "more steps"
        if saved
        else "raise --max-steps or use more walkers"
    )
    sys.stderr.write(
        f"uq export: NOT CONVERGED ({model.label}: {' '.join(first.split())}); nothing written: "
        f"{where}, or pass --allow-unconverged to export it marked NOT CONVERGED\n"
    )
    return True


def _source_notes(model, rec) -> list[str]:
    """Notes every format carries about where the numbers came from: a fit that failed its
    convergence rules (exported with --allow-unconverged), and recordings that are not measured
    (their header says RECONSTRUCTED, as data/n50's does)."""
    from uq._data.reference import is_n50_reconstruction

    notes = []
    if not _converged(model):
        notes.append(
            "NOT CONVERGED: the fit failed its convergence rules (exported with "
            "--allow-unconverged); these numbers are not a result yet"
        )
    comments = (
        list(rec.comments)
        if rec is not None
        else list(model.provenance.get("recordings_comments", []))
    )
    if is_n50_reconstruction(comments):
        notes.append(
            "not measured data: the recordings are the paper's N-50 spring reconstructed from its "
            "Table 1 by airspring-uq's virtual test stand (their header says so)"
        )
    else:
        for c in comments:
            if "RECONSTRUCTED" in c.upper():
                words = " ".join(c.split())
                notes.append(f"not measured data: the recordings' header says: {words}")
    return notes
