"""The ``uq`` command line (docs/commands.md): thin drivers around the library.

Each command lives in the module that owns its concept and exposes ``configure_NAME(parser)``
and ``command_NAME(args) -> int``; this file wires them up. Only the module of the command
being run is imported (``uq --help`` imports no numpy, JAX, ArviZ or matplotlib).

Exit status, the same for every command (docs/commands.md):

* 0  done (for ``uq check``: all agree)
* 1  ``uq check`` found a disagreement, or a fit failed its convergence rules (without
     ``--allow-unconverged``; the policy is :func:`uq._cli.common.convergence_status`, the
     commands only report which fits failed, :func:`uq._cli.common.record_convergence`), or
     ``uq batch``: a task failed or did not converge
* 2  bad input or usage: one line on stderr naming the file, row, column or option; nothing written
* 3  internal error (a bug): one line naming the exception; ``--debug`` or ``UQ_DEBUG=1`` prints the traceback
* 130 interrupted (Ctrl-C): one line

Before a command starts, every output it names (``--json``, ``--out``, ``--report``) is checked
(:func:`uq._cli.common.check_output_path`), so a path that cannot be written fails at once, not
after the fit. With ``--json -`` stdout carries only the JSON: the command's human summary goes
to stderr and the JSON is printed when the command has finished.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import os
import shutil
import signal
import sys
import tempfile
import threading
from pathlib import Path

from uq._io.errors import InputError
from uq._io.version import __version__

#: (command, module, one-line help). Modules are imported only when their command runs.
COMMANDS = [
    (
        "simulate",
        "uq._cli.cmd_basic",
        "virtual test stand: write recordings following the paper's procedure and error budget",
    ),
    (
        "fit",
        "uq._cli.cmd_basic",
        "per-pressure Bayesian cubic fits of force and piston coordinate (eqs. 8, 9)",
    ),
    (
        "report",
        "uq._cli.cmd_report",
        "posterior report: one self-contained HTML page (+ PNG figures) per campaign",
    ),
    (
        "check",
        "uq._cli.cmd_check",
        "check posterior results against stored point estimates (exit 0 agree, 1 disagree, 2 bad input)",
    ),
    ("surface", "uq._cli.cmd_surface", "pressure-coupled surface model over all tests at once"),
    (
        "margin",
        "uq._cli.cmd_margin",
        "design-margin queries (by default on the surface with a discrepancy in pressure)",
    ),
    (
        "design",
        "uq._cli.cmd_design",
        "the sealed spring: load, rate and natural frequency with credible intervals, and a data sheet",
    ),
    (
        "diagnose",
        "uq._cli.cmd_diagnose",
        "locate the mismatch with the traditional model, name and model the missing physics",
    ),
    (
        "export",
        "uq._cli.cmd_export",
        "the characteristic as tables for other tools (CSV, xlsx, Simscape, TeimOrbit, JSON) with quantiles",
    ),
    (
        "calibrate",
        "uq._cli.cmd_calibrate",
        "coverage of the credible intervals on simulated campaigns with known truth",
    ),
    (
        "plan",
        "uq._cli.cmd_plan",
        "where to measure next: the readings that make chosen quantities' sd smallest for the stand time",
    ),
    (
        "batch",
        "uq._cli.cmd_batch",
        "a catalogue of campaigns (fit, report, surface, diagnose) on Dask: summary table, reruns skip finished ones",
    ),
]

#: What each output option names: "file" (the file to write, '-' = stdout for --json) or "dir"
#: (the folder to write into). --out is always "where this command writes": the file for
#: simulate (--out FILE.csv), the folder for every other command.
OUTPUT_KIND = {
    "json": "file",
    "report": "dir",
    "out": "dir",
    "csv": "file",
    "template": "file",
    "plot": "file",
}
OUTPUT_KIND_BY_COMMAND = {("simulate", "out"): "file", ("export", "out"): "file"}

#: the library's parameter names (``InputError.param``) and the options that set them
PARAM_OPTIONS = {
    "n_walkers": "--walkers",
    "n_ensembles": "--ensembles",
    "max_steps": "--max-steps",
    "load_N": "--load-N",
    "height_m": "--height-mm",
    "pressure_bar": "--pressure-bar",
    "prob": "--prob",
    "tolerance_pct": "--tolerance-pct",
    "alpha": "--alpha",
    "sheet": "--sheet",
    "absolute_pressure": "--absolute-pressure",
    "piston_area_cm2": "--piston-area-cm2",
    "x0_mm": "--x0-mm",
    "compression": "--compression",
    "p_atm_bar": "--p-atm-bar",
    "pressure_tolerance_bar": "--pressure-tolerance-bar",
    "columns": "--columns",
    "units_row": "--units-row",
    "header_row": "--header-row",
    "stand": "--stand",
    "scheduler": "--scheduler",
    "spring_name": "--spring",
    "pressures_bar": "--pressures",
    "step_m": "--step-mm",
    "x_min_m": "--x-min-mm",
    "x_max_m": "--x-max-mm",
    "charge_bar": "--charge-bar",
    "volume_l": "--volume-l",
    "volume_sd_l": "--volume-sd-l",
    "polytropic": "--polytropic",
    "reservoir_l": "--reservoir-l",
    "forcing_Hz": "--forcing-hz",
    "dvdp_l_per_bar": "--dvdp-l-per-bar",
    "rate_tolerance_pct": "--rate-tolerance-pct",
    "max_frequency_Hz": "--max-frequency-hz",
    "rate_target_N_per_m": "--rate-target-N-per-m",
    "force_limit_N": "--force-limit-N",
    "effects": "--effect",
    "truth": "--truth",
    "noise": "--noise",
    "pressure": "--pressure",
    "ar1": "--pressure-ar1",
    "reps": "--reps",
    "target": "--target",
    "candidates_bar": "--pressures-bar",
    "heights_m": "--heights-mm",
    "model": "--model",
}

#: exit statuses 0 (done) and 1 (disagreement, unconverged) are the commands' own (module docstring)
EXIT_INPUT, EXIT_INTERNAL, EXIT_INTERRUPTED, EXIT_BROKEN_PIPE = 2, 3, 130, 141

EPILOG = (
    "exit status: 0 done, 1 check disagrees or a fit did not converge (unless --allow-unconverged), "
    "2 bad input or usage, "
    "3 internal error, 130 interrupted. --out is where a command writes: the CSV file for simulate, "
    "the folder for the others. --json - prints the JSON alone on stdout."
)


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, exit 2 (argparse's own status for usage errors)
        message = " ".join(message.split())
        sys.stderr.write(f"{self.prog}: error: {message}\n")
        raise SystemExit(EXIT_INPUT)


class _Formatter(argparse.ArgumentDefaultsHelpFormatter):
    """Show every option's default, unless its help already says it or there is none to show."""

    def _get_help_string(self, action):
        text = action.help or ""
        if (
            "default" in text.lower()
            or action.default in (None, False, argparse.SUPPRESS)
            or not action.option_strings
        ):
            return text
        return super()._get_help_string(action)


def _available() -> list[tuple[str, str, str]]:
    return [c for c in COMMANDS if importlib.util.find_spec(c[1]) is not None]


def _add_general(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("general")
    g.add_argument(
        "--quiet",
        action="store_true",
        help="no progress display (it is also off when stderr is not a terminal)",
    )
    g.add_argument(
        "--debug",
        action="store_true",
        help="on an internal error, print the traceback (or set UQ_DEBUG=1)",
    )


def build_parser(argv: list[str] | None = None) -> argparse.ArgumentParser:
    """The ``uq`` parser. Only the command named in ``argv`` is configured (its module imported);
    the others are listed with their one-line help, which is all ``uq --help`` shows."""
    wanted = _command_in(argv or [])
    parser = _Parser(
        prog="uq",
        description="Bayesian uncertainty quantification of air-spring test-stand recordings",
        epilog=EPILOG,
        formatter_class=_Formatter,
    )
    parser.add_argument("--version", action="version", version=f"uq {__version__}")
    sub = parser.add_subparsers(dest="cmd", required=True, metavar="COMMAND", parser_class=_Parser)
    parser._uq_commands = {}
    for name, module, help_ in _available():
        p = sub.add_parser(
            name, help=help_, description=help_, epilog=EPILOG, formatter_class=_Formatter
        )
        p.set_defaults(_module=module, _name=name)
        if name == wanted:
            getattr(importlib.import_module(module), f"configure_{name}")(p)
            _add_general(p)
        parser._uq_commands[name] = p
    return parser


def _command_in(argv: list[str]) -> str | None:
    """The command named in ``argv``: the first word that is not an option."""
    names = {c[0] for c in COMMANDS}
    for word in argv:
        if not word.startswith("-"):
            return word if word in names else None
    return None


def _parse(parser: argparse.ArgumentParser, argv: list[str]) -> argparse.Namespace:
    args = parser.parse_args(argv)
    if getattr(args, "config", None):  # a fit definition sets defaults; the command line still wins
        from uq._cli.cmd_basic import read_fit_config

        try:
            values = read_fit_config(args.config)
        except InputError as exc:
            parser._uq_commands[args._name].error(str(exc))
        parser._uq_commands[args._name].set_defaults(**values)
        args = parser.parse_args(argv)
    return args


def check_outputs(args: argparse.Namespace) -> None:
    """Every output path of the command, checked before it starts (nothing is written)."""
    from uq._cli.common import check_output_path

    for dest, kind in OUTPUT_KIND.items():
        value = getattr(args, dest, None)
        if value is not None:
            kind = OUTPUT_KIND_BY_COMMAND.get((args._name, dest), kind)
            check_output_path(value, f"--{dest}", kind)


@contextlib.contextmanager
def _json_on_stdout(args: argparse.Namespace):
    """With ``--json -``: run with stdout sent to stderr, then print the JSON alone on stdout."""
    if getattr(args, "json", None) != "-":
        yield
        return
    stdout = sys.stdout
    folder = tempfile.mkdtemp(prefix="uq-json-")
    args.json = str(Path(folder) / "result.json")
    try:
        with contextlib.redirect_stdout(sys.stderr):
            yield
        if os.path.exists(args.json):
            stdout.write(Path(args.json).read_text(encoding="utf-8"))
            stdout.flush()
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def _fail(name: str, text: str, status: int) -> int:
    sys.stderr.write(f"uq {name}: {text}\n")
    return status


def _compile_cache() -> None:
    """JAX's persistent compilation cache (``uq._inference.jax_cache``): only environment
    variables are set, before any command module is imported (JAX reads them when first
    imported), so commands that never import JAX stay fast; a cache location set by the user
    wins; ``UQ_CACHE_DIR=off`` turns it off."""
    from uq._inference import blas
    from uq._inference.jax_cache import set_environment

    set_environment()
    blas.set_environment()  # numpy's BLAS on one thread (uq._inference.blas), before numpy loads


def _interrupts_are_not_lost() -> None:
    """A Ctrl-C that lands while Python runs a garbage-collection callback (JAX registers one) or a
    finaliser raises KeyboardInterrupt there, where Python cannot propagate it: it prints
    "Exception ignored in ..." and carries on as if nothing was pressed. Deliver it again to the
    main thread instead, from another thread a moment later (raised here, it would be lost the same
    way; if it lands in a callback again, it comes back here), so the command stops with its one
    line and exit 130."""
    import _thread

    previous = sys.unraisablehook
    if getattr(previous, "delivers_interrupts", False):
        return

    def hook(unraisable):
        if isinstance(unraisable.exc_value, KeyboardInterrupt):
            timer = threading.Timer(0.05, _thread.interrupt_main)
            timer.daemon = True
            timer.start()
            return
        previous(unraisable)

    hook.delivers_interrupts = True
    sys.unraisablehook = hook


def _caused_by_interrupt(exc: BaseException) -> bool:
    """``exc`` was raised because of a KeyboardInterrupt: Python wraps one that lands while a
    class body is being created (``RuntimeError: Error calling __set_name__ ...``, seen while
    matplotlib was imported) and some libraries re-raise it as their own error; either way the
    user pressed Ctrl-C, and the answer is the interrupted line and 130, not an internal error."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return True
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


def _interrupted(name: str, as_program: bool) -> int:
    """The one line and status 130 of a command stopped by Ctrl-C.

    When ``main`` is the program (the ``uq`` script, ``python -m``), the process then exits at
    once (``os._exit`` after flushing stdout and stderr), without Python's shutdown: the command
    has stopped, its outputs are written atomically or not at all and its figure workers are
    joined, and Python's shutdown (joining threads, running finalisers, resetting the signal
    handlers) is where a second Ctrl-C, or the first delivered again by
    ``_interrupts_are_not_lost``'s timer, could still end the process by SIGINT: exit status -2
    instead of 130, after the one line was printed (seen about once in ten runs of
    ``uq report``'s Ctrl-C test on a loaded machine, with SIGINT already ignored from here on).
    When a caller runs ``main(argv)`` in its own process, the status is returned."""
    if not as_program:
        return _fail(name, "interrupted", EXIT_INTERRUPTED)
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    _exit_now(_fail(name, "interrupted", EXIT_INTERRUPTED))


def _exit_now(status: int) -> None:
    """End the program with ``status`` (``uq._io.processes.exit_now``: stdout and stderr flushed,
    without Python's shutdown). That shutdown does nothing a command needs: its outputs are written
    atomically and closed, its worker processes joined and a Dask cluster closed before it returns;
    but after JAX's import it takes 0.5-0.7 s of wall time, which the user waited for, and a
    Ctrl-C that lands in it ends the process by SIGINT."""
    from uq._io.processes import exit_now  # reason: multiprocessing, needed only at the end

    exit_now(status, broken_pipe=EXIT_BROKEN_PIPE, unwritable=EXIT_INPUT)


def main(argv: list[str] | None = None) -> int:
    """The ``uq`` command line: ``argv`` without the program's name (default ``sys.argv[1:]``,
    and then ``main`` is taken to be the program: it ends the process when the command is done,
    :func:`_exit_now`)."""
    as_program = argv is None
    status = _command(sys.argv[1:] if as_program else list(argv), as_program)
    if as_program:
        _exit_now(status)
    return status


def _command(argv: list[str], as_program: bool) -> int:
    _interrupts_are_not_lost()
    if as_program:  # the process is the command's: its collector set for that (not the library's)
        from uq._io.processes import short_lived  # reason: multiprocessing; exit_now needs it too

        short_lived()
    _compile_cache()  # before the command's module is imported: JAX reads the settings on its import
    parser = build_parser(argv)
    args = _parse(parser, argv)
    name = args._name
    debug = args.debug or os.environ.get("UQ_DEBUG", "") not in ("", "0")
    from uq._io.progress import set_enabled

    set_enabled(not args.quiet)
    try:
        check_outputs(args)
        from uq._cli.common import convergence_status

        with _json_on_stdout(args):
            status = int(
                getattr(importlib.import_module(args._module), f"command_{name}")(args) or 0
            )
        return convergence_status(args, name, status)
    except InputError as exc:
        exc = exc.for_cli(PARAM_OPTIONS)
        return _fail(name, f"error: {exc}", EXIT_INPUT)
    except KeyboardInterrupt:
        return _interrupted(name, as_program)
    # the reader of stdout went away (`| head`): the shell's status for SIGPIPE
    except BrokenPipeError:
        with contextlib.suppress(OSError):
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return EXIT_BROKEN_PIPE
    except OSError as exc:  # a file the command could not read or write (disk full, permissions)
        where = f": {exc.filename}" if exc.filename else ""
        return _fail(name, f"error: {exc.strerror or exc}{where}", EXIT_INPUT)
    except Exception as exc:
        if _caused_by_interrupt(exc):  # a Ctrl-C that Python wrapped (e.g. inside __set_name__)
            return _interrupted(name, as_program)
        if debug:
            import traceback

            traceback.print_exc()
        first = (str(exc).splitlines() or [""])[0]
        hint = "" if debug else "; rerun with --debug (or UQ_DEBUG=1) for the traceback"
        return _fail(
            name,
            f"internal error: {type(exc).__name__}: {first} (a bug, please report it{hint})",
            EXIT_INTERNAL,
        )


if __name__ == "__main__":
    raise SystemExit(main())
