"""Options shared by several commands, so they read and validate the same way everywhere."""

from __future__ import annotations

import argparse

from ._errors import InputError
from ._recordings import DEFAULT_PISTON_AREA_CM2, DEFAULT_X0_MM, read_recordings
from ._sampler import Settings

DEFAULT_SEED = 20201  # fixed: a rerun gives the same numbers


def add_recordings(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", help="recordings CSV (CONTRACT.md section 1)")
    p.add_argument("--piston-area-cm2", type=float, default=DEFAULT_PISTON_AREA_CM2,
                   help="area S of the hydraulic cylinder's piston cavity, cm^2 (default: the paper's 54.82)")
    p.add_argument("--x0-mm", type=float, default=DEFAULT_X0_MM,
                   help="reference height x0 of the polynomial basis, mm (default: the paper's 112)")


def add_sampling(p: argparse.ArgumentParser) -> None:
    p.add_argument("--seed", type=int, default=DEFAULT_SEED, help=f"random seed (default {DEFAULT_SEED})")
    p.add_argument("--walkers", type=int, default=Settings.n_walkers, help="emcee walkers per ensemble")
    p.add_argument("--ensembles", type=int, default=Settings.n_ensembles, help="independent ensembles (>= 2, for R-hat)")
    p.add_argument("--max-steps", type=int, default=Settings.max_steps, help="cap on emcee steps per ensemble")
    p.add_argument("--strict", action="store_true", help="exit status 1 when sampling did not converge")
    p.add_argument("--jobs", type=int, default=1, help="processes for the per-test fits (results do not depend on it)")


def settings_from(args) -> Settings:
    s = Settings(n_walkers=args.walkers, n_ensembles=args.ensembles, max_steps=args.max_steps)
    s.validate()
    return s


def add_json(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", metavar="PATH", help="write the machine-readable result to PATH ('-' for stdout)")


def load(args, min_points: int = 6):
    return read_recordings(args.file, piston_area_cm2=args.piston_area_cm2, x0_mm=args.x0_mm, min_points=min_points)


def positive(name: str, value: float) -> float:
    if not value > 0:
        raise InputError(f"option {name}: expected a positive number, got {value:g}")
    return value


def say(text: str, json_target: str | None) -> None:
    """Print the human summary; to stderr when the JSON goes to stdout, so both stay readable."""
    import sys

    (sys.stderr if json_target == "-" else sys.stdout).write(text + "\n")
