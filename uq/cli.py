"""The ``uq`` command line (CONTRACT.md section 2): thin drivers around the library.

Each command lives in the module that owns its concept and exposes ``configure(parser)``
and ``command(args) -> int``; this file only wires them up and turns
:class:`InputError` into one line on stderr and exit status 2.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from ._errors import InputError

#: (command, module, one-line help). Modules are imported only when their command runs.
COMMANDS = [
    ("simulate", "uq._cmd_basic", "virtual test stand: write recordings following the paper's procedure and error budget"),
    ("fit", "uq._cmd_basic", "per-pressure Bayesian cubic fits of force and piston coordinate (eqs. 8, 9)"),
    ("report", "uq._report", "posterior report: one self-contained HTML page (+ PNG figures) per campaign"),
    ("check", "uq._check", "check posterior results against stored point estimates (exit 0 agree, 1 disagree, 2 bad input)"),
    ("bench", "uq._bench", "effective samples per second of the project's sampler against a plain emcee baseline"),
    ("surface", "uq._surface", "pressure-coupled surface model over all tests at once"),
    ("margin", "uq._margin", "design-margin queries on the surface model"),
    ("diagnose", "uq._diagnose", "locate the mismatch with the traditional model, name and model the missing physics"),
    ("calibrate", "uq._calibrate", "coverage of the credible intervals on simulated campaigns with known truth"),
]


class _Parser(argparse.ArgumentParser):
    def error(self, message: str):  # one line, exit 2 (argparse's own status for usage errors)
        sys.stderr.write(f"{self.prog}: error: {message}\n")
        raise SystemExit(2)


def _available() -> list[tuple[str, str, str]]:
    out = []
    for name, module, help_ in COMMANDS:
        if importlib.util.find_spec(module) is not None:
            out.append((name, module, help_))
    return out


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="uq", description="Bayesian uncertainty quantification of air-spring test-stand recordings")
    sub = parser.add_subparsers(dest="cmd", required=True, parser_class=_Parser)
    for name, module, help_ in _available():
        p = sub.add_parser(name, help=help_, description=help_)
        p.set_defaults(_module=module, _name=name)
        getattr(importlib.import_module(module), f"configure_{name}")(p)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(getattr(importlib.import_module(args._module), f"command_{args._name}")(args) or 0)
    except InputError as exc:
        sys.stderr.write(f"uq {args._name}: error: {exc}\n")
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
