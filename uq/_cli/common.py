"""Options shared by several commands, so they read and validate the same way everywhere.

This module is imported while the parser is built, so it imports nothing heavy (no numpy,
JAX, ArviZ): ``uq --help`` stays fast. Option values are checked by the argparse ``type=``
functions below, so a bad value is a usage error (one line, exit 2) before any data is read
or any model fitted; output paths are checked by :func:`check_output_path` (the CLI calls it
for every ``--json``, ``--out`` and ``--report`` before the command starts).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

from uq._io import values
from uq._io.errors import InputError

DEFAULT_SEED = 20201  # fixed: a rerun gives the same numbers
# The paper's stand constants and the sampler's defaults, repeated here so that building the
# parser does not import numpy/ArviZ; tests/cli/test_cli.py checks they equal the library's.
DEFAULT_PISTON_AREA_CM2 = 54.82
DEFAULT_X0_MM = 112.0
DEFAULT_P_ATM_BAR = 1.01325
DEFAULT_WALKERS = 32
DEFAULT_ENSEMBLES = 4  # independent, overdispersed ensembles for R-hat (uq/_inference/sampler.py)
DEFAULT_MAX_STEPS = 20000


# ----------------------------------------------------------------------------- option types


def option_type(check):
    """``check`` as an argparse ``type=``: its ValueError becomes a usage error with the same message."""

    def parse(text: str):
        try:
            return check(text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None

    parse.__name__ = check.__name__
    return parse


positive_float = option_type(values.positive_float)
nonnegative_float = option_type(values.nonnegative_float)
finite_float = option_type(values.finite_float)
positive_int = option_type(values.positive_int)
compression = option_type(values.compression)
boolean = option_type(values.boolean)
walkers = option_type(values.walkers)
seed = option_type(values.seed)


def probability(text: str) -> float:
    value = finite_float(text)
    if not 0.0 < value < 1.0:
        raise argparse.ArgumentTypeError(
            f"expected a probability strictly between 0 and 1, got '{text}'"
        )
    return value


def column_map(text: str) -> str:
    """A column map (``force_N=Load,height_mm=Position``), checked before any file is read."""
    from uq._data import column_map as _column_map  # pure Python: the units' table, no numpy

    try:
        _column_map.parse(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text


def units_row(text: str) -> str:
    if text not in ("auto", "yes", "no"):  # uq._data.rows.UNITS_ROW_MODES (tested equal)
        raise argparse.ArgumentTypeError(f"expected auto, yes or no, got '{text}'")
    return text


def choice_list(*allowed: str):
    """A comma-separated list of names from ``allowed`` (checked at parse time, before any work)."""

    def parse(text: str) -> str:
        names = [t.strip() for t in text.split(",") if t.strip()]
        bad = [n for n in names if n not in allowed]
        if not names or bad:
            raise argparse.ArgumentTypeError(
                f"expected a comma-separated list of {', '.join(allowed)}, got '{text}'"
            )
        return ",".join(names)

    parse.__name__ = "list"
    return parse


# ----------------------------------------------------------------------------- shared options


def add_recordings(p: argparse.ArgumentParser, file_optional: bool = False) -> None:
    p.add_argument(
        "file",
        nargs="?" if file_optional else None,
        help="recordings: CSV, .xlsx or .ods (format: docs/formats.md)",
    )
    p.add_argument(
        "--piston-area-cm2",
        type=positive_float,
        default=DEFAULT_PISTON_AREA_CM2,
        help="area S of the hydraulic cylinder's piston cavity, cm^2 (the paper's value)",
    )
    p.add_argument(
        "--x0-mm",
        type=positive_float,
        default=DEFAULT_X0_MM,
        help="reference height x0 of the polynomial basis, mm (the paper's value)",
    )
    g = p.add_argument_group("reading the recordings (docs/formats.md, section 1)")
    g.add_argument(
        "--compression",
        type=compression,
        default="positive",
        metavar="positive|negative",
        help="sign of a compressive force in the file: negative for a load frame that records "
        "compression negative (forces are negated on reading)",
    )
    g.add_argument(
        "--sheet",
        metavar="NAME",
        help="the sheet holding the campaign, for an .xlsx/.ods workbook with several sheets",
    )
    g.add_argument(
        "--absolute-pressure",
        action="store_true",
        help="the pressure columns hold absolute pressure: --p-atm-bar is subtracted to get the "
        "gauge overpressure",
    )
    g.add_argument(
        "--p-atm-bar",
        type=positive_float,
        default=DEFAULT_P_ATM_BAR,
        help="atmospheric pressure, bar (used with --absolute-pressure)",
    )
    g.add_argument(
        "--pressure-tolerance-bar",
        type=positive_float,
        default=None,
        metavar="BAR",
        help="how far a reading's measured pressure may lie from its test's set pressure "
        "(default max(0.05 bar, 2 %% of the pressure))",
    )
    g.add_argument(
        "--columns",
        type=column_map,
        default=None,
        metavar="MAP",
        help="which of the file's columns is which recordings column, for an instrument's export: "
        "force_N=Load,height_mm=Position,... (force=Load: the unit from the units row)",
    )
    g.add_argument(
        "--units-row",
        type=units_row,
        default="auto",
        metavar="auto|yes|no",
        help="a row of units under the header, (bar),(mm),(N),...: auto detects one in brackets "
        "(and says so), yes takes the row under the header as units, no reads it as data",
    )
    g.add_argument(
        "--header-row",
        type=positive_int,
        default=None,
        metavar="N",
        help="the header's row in the file, under a title (default: the first row, or the first "
        "naming recordings columns below a title, which a note then names)",
    )


def add_output_units(p: argparse.ArgumentParser) -> None:
    """``--units si|input``: tables and labels in the contract's units or in the recordings' own."""
    p.add_argument(
        "--units",
        choices=("si", "input"),  # uq._data.units.OUTPUT_CHOICES (tested equal)
        default="si",
        help="units of the tables and labels: si (bar, mm, N; coefficients in SI as the JSON) or "
        "input, the units the recordings came in (pressure_psi, height_in, force_lbf give psi, in, "
        "lbf); JSON stays SI",
    )


def output_units(rec, which: str):
    """The :class:`uq._data.units.OutputUnits` of ``--units`` for recordings ``rec``."""
    from uq._data.units import OutputUnits

    return OutputUnits.of(getattr(rec, "units", None), which)


def add_sampling(p: argparse.ArgumentParser) -> None:
    p.add_argument("--seed", type=seed, default=DEFAULT_SEED, help="random seed")
    p.add_argument(
        "--walkers",
        type=walkers,
        default=DEFAULT_WALKERS,
        help="emcee walkers per ensemble (a multiple of 4)",
    )
    p.add_argument(
        "--ensembles",
        type=positive_int,
        default=DEFAULT_ENSEMBLES,
        help="independent ensembles (>= 2, for R-hat)",
    )
    p.add_argument(
        "--max-steps",
        type=positive_int,
        default=DEFAULT_MAX_STEPS,
        help="cap on emcee steps per ensemble",
    )
    add_convergence(p)


def add_convergence(p: argparse.ArgumentParser) -> None:
    """``--allow-unconverged`` (and ``--strict``, its opposite and the default): one name for every
    command that samples (docs/commands.md, exit status)."""
    g = p.add_argument_group("convergence (exit status)").add_mutually_exclusive_group()
    g.add_argument(
        "--allow-unconverged",
        action="store_true",
        help="exit status 0 when a fit fails its convergence rules (R-hat, ESS, chain length): its "
        "results are still written and printed with the warnings and a NOT CONVERGED banner, as "
        "without the option; without it the exit status is 1",
    )
    g.add_argument(
        "--strict",
        action="store_true",
        help="exit status 1 when a fit fails its convergence rules: the default since round 7 "
        "(kept so that scripts which pass it keep working)",
    )


def record_convergence(args, converged: bool, what: str) -> None:
    """Tell the command line whether a fit behind this command's results passed its convergence
    rules (``what``: which fit, in words). The command writes and prints its results either way
    (with the warnings and the NOT CONVERGED banner); ``uq._cli.main`` turns a failure into the
    exit status (:func:`convergence_status`)."""
    if not converged:
        args.unconverged_fits = [*getattr(args, "unconverged_fits", []), what]


def add_misfit(p: argparse.ArgumentParser) -> None:
    """``--allow-misfit`` for the commands that check their model at the tested points before
    answering (``uq design``, ``uq margin``; uq._derived.model_check)."""
    p.add_argument(
        "--allow-misfit",
        action="store_true",
        help="exit status 0 when the model that answers misses the readings it was fitted to (its "
        "posterior-predictive check at the tested pressures fails): the answer is still printed and "
        "written with the check; without it the exit status is 1",
    )


def record_misfit(args, check: dict) -> None:
    """Tell the command line that the model behind this command's answer missed its readings
    (``check``: :func:`uq._derived.model_check.predictive_check`); :func:`convergence_status`
    turns it into the exit status."""
    if check.get("misses"):
        bars = ", ".join(f"{p:g}" for p in check["missed_pressures_bar"])
        args.misfits = [*getattr(args, "misfits", []), f"{check['model']} at {bars} bar"]


def convergence_status(args, name: str, status: int) -> int:
    """The exit-status policy for fits that failed their convergence rules (one place for every
    command): a command that finished (``status`` 0) with such a fit exits 1 with one line on
    stderr saying so, or 0 with ``--allow-unconverged``; any other status stands."""
    return exit_policy(
        misfit_status(args, name, status),
        getattr(args, "unconverged_fits", []),
        getattr(args, "allow_unconverged", False),
        f"uq {name}: NOT CONVERGED ({{}}), accepted with --allow-unconverged: exit 0; the results "
        "carry the warnings and the NOT CONVERGED banner",
        f"uq {name}: NOT CONVERGED ({{}}): the convergence rules failed, so what was written and "
        "printed is not a result yet (each output says so); exit 1. Raise --max-steps or use more "
        "walkers, or pass --allow-unconverged to accept it",
    )


def exit_policy(status: int, failed: list, allowed: bool, accepted: str, refused: str) -> int:
    """An exit-status policy: a command that finished (``status`` 0) with ``failed`` (in words)
    exits 0 with ``accepted`` on stderr when ``allowed``, else 1 with ``refused`` (each with the
    failures at its ``{}``); any other status stands."""
    if status != 0 or not failed:
        return status
    sys.stderr.write((accepted if allowed else refused).format("; ".join(failed)) + "\n")
    return 0 if allowed else 1


def settings_from(args):
    from uq._inference.sampler import Settings

    s = Settings(n_walkers=args.walkers, n_ensembles=args.ensembles, max_steps=args.max_steps)
    s.validate()
    return s


def add_json(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--json", metavar="PATH", help="write the machine-readable result to PATH ('-' for stdout)"
    )


def load(args, min_points: int = 6, needs=()):
    """The recordings of ``args.file`` read with the command's reading options.

    ``needs``: what the command cannot do without ("piston", "order"; ``uq._data.recordings.
    require``): every command takes force-only campaigns and campaigns in unknown order but
    ``uq design`` with a model of the volume.
    """
    from uq._data.recordings import READING_OPTIONS, read_recordings, require

    rec = read_recordings(
        args.file,
        min_points=min_points,
        on_note=_note,  # what the reader decided by itself (a units row, a title), said at once
        **{k: getattr(args, k) for k in READING_OPTIONS if hasattr(args, k)},
    )
    require(rec, needs)
    check_memory(args, rec)
    return rec


#: the commands whose peak memory is at least uq fit's for the same campaign (they run its fit,
#: uq report then its bands and figures): checked against uq._io.memory's models before fitting
MEMORY_CHECKED = {"fit": "uq fit", "report": "uq report (at least what uq fit needs)"}


def check_memory(args, rec) -> None:
    """Refuse, before any fitting, a campaign whose predicted peak memory exceeds what the
    machine has available (uq._io.memory; the commands of ``MEMORY_CHECKED``; ``uq fit --out``
    also holds one test's InferenceData at a time)."""
    command = MEMORY_CHECKED.get(getattr(args, "_name", ""))
    if command is None:
        return
    from uq._io.memory import FIT, FIT_OUT, check_fits_in_memory

    saving = args._name == "fit" and getattr(args, "out", None)
    sizes = [t.n_points for t in rec.tests]
    check_fits_in_memory(
        args.file,
        sum(sizes),
        "uq fit --out" if saving else command,
        FIT_OUT if saving else FIT,
        largest_test=max(sizes) if saving else 0,
    )


def _note(text: str) -> None:
    sys.stderr.write(f"note: {text}\n")


def say(text: str, json_target: str | None) -> None:
    """Print the human summary; to stderr when the JSON goes to stdout, so both stay readable."""
    (sys.stderr if json_target == "-" else sys.stdout).write(text + "\n")


# ----------------------------------------------------------------------------- output paths


def _probe_writable(folder: Path, option: str, path) -> None:
    """Create and remove a temporary file in ``folder``: the only sure test (root, /proc, read-only mounts)."""
    try:
        fd, tmp = tempfile.mkstemp(prefix=".uq-probe-", dir=folder)
    except OSError as exc:
        raise InputError(
            f"option {option} {path}: cannot write in {folder}: {exc.strerror}"
        ) from None
    os.close(fd)
    os.unlink(tmp)


def check_output_path(path, option: str, kind: str = "file") -> None:
    """Refuse, before any work, an output the command could not write; writes nothing.

    ``kind`` "file": ``path`` is the file to write ('-' = stdout); it must not be a folder or a
    symbolic link, and its folder (or the nearest existing ancestor, since missing folders are
    created) must be a writable folder. An existing device such as /dev/null is written to.
    ``kind`` "dir": ``path`` is the folder to write into; it must not be an existing file.
    """
    if kind == "file" and str(path) == "-":
        return
    if not str(path).strip():
        raise InputError(f"option {option}: empty path")
    p = Path(path)
    what = "file" if kind == "file" else "folder"
    if kind == "file" and p.is_symlink():
        raise InputError(
            f"option {option} {path}: is a symbolic link; refusing to replace it (give the real path)"
        )
    if p.exists():
        if kind == "dir":
            if not p.is_dir():
                raise InputError(
                    f"option {option} {path}: is an existing file; {option} names the folder to write into"
                )
            _probe_writable(p, option, path)
        elif p.is_dir():
            raise InputError(
                f"option {option} {path}: is a folder; {option} names the {what} to write"
            )
        elif p.is_file():
            _probe_writable(p.absolute().parent, option, path)
        elif not os.access(p, os.W_OK):  # a device or pipe is written to in place
            raise InputError(f"option {option} {path}: not writable")
        return
    ancestor = p.absolute() if kind == "dir" else p.absolute().parent
    while not ancestor.exists() and ancestor != ancestor.parent:
        ancestor = ancestor.parent
    if not ancestor.is_dir():
        raise InputError(f"option {option} {path}: {ancestor} is a file, not a folder")
    _probe_writable(ancestor, option, path)


STAND_HELP = (
    "the stand the recordings were taken on: load-cell accuracy, pressure holding, gas volume, "
    "p_atm (TOML, keys of uq._data.stand_description.StandDescription; default the paper's stand)"
)


PRESSURE_AR1_HELP = (
    "the pressure-holding errors when the recordings give no measured pressure: off (independent "
    "noise), on (an AR(1) series in recording order, shared by force and piston), auto (AR(1) for "
    "the tests whose residuals the recording-order check flags) (default: off)"
)


def pressure_ar1(text: str) -> str:
    if text not in ("off", "on", "auto"):
        raise argparse.ArgumentTypeError(f"expected off, on or auto, got '{text}'")
    return text


def add_pressure_ar1(p: argparse.ArgumentParser) -> None:
    """``--pressure-ar1 off|on|auto`` (uq fit, uq report)."""
    p.add_argument("--pressure-ar1", type=pressure_ar1, default="off", help=PRESSURE_AR1_HELP)


def add_stand(p: argparse.ArgumentParser, help: str = STAND_HELP) -> None:
    """``--stand FILE.toml`` (one option for every command)."""
    p.add_argument("--stand", metavar="FILE.toml", help=help)


def stand_from(args, model: bool = True):
    """The StandDescription of ``--stand`` (the paper's stand without it); a bad file is InputError.

    ``model``: the stand is given to a model (not to the virtual stand), which uses its budget and
    gas volumes but cannot use the fields of the noise's form: a note on stderr says so."""
    from uq._data.stand_description import stand_or_paper

    stand = stand_or_paper(getattr(args, "stand", None))
    if model and stand.noise_form_fields():
        sys.stderr.write(
            f"note: --stand {args.stand}: {', '.join(stand.noise_form_fields())} describe the noise's "
            "form for the virtual stand; the models assume independent Gaussian errors and do not use "
            "them\n"
        )
    return stand


def misfit_status(args, name: str, status: int) -> int:
    """The exit-status policy for an answer whose model missed its readings (``record_misfit``):
    exit 1 with one line on stderr, or 0 with ``--allow-misfit``; any other status stands."""
    return exit_policy(
        status,
        getattr(args, "misfits", []),
        getattr(args, "allow_misfit", False),
        f"uq {name}: the model misses the readings ({{}}), accepted with --allow-misfit: exit 0; "
        "the answer carries the check",
        f"uq {name}: the model misses the readings ({{}}): its posterior-predictive check at the "
        "tested pressures fails, so the answer printed and written is not to be trusted there; "
        "exit 1. Use a model that follows them (see --model), or pass --allow-misfit to accept it",
    )
