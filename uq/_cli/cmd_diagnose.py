"""``uq diagnose``: the command line of :mod:`uq._diagnose.engine`."""

from __future__ import annotations

import argparse
import math
import sys

from uq._cli.common import (
    add_json,
    add_recordings,
    add_sampling,
    add_stand,
    load,
    record_convergence,
    settings_from,
    stand_from,
)
from uq._diagnose import engine as _diagnose
from uq._diagnose.engine import GAIN_SE, shorter_sampling, summary_text
from uq._io.errors import InputError
from uq._io.files import emit_json
from uq._models import diagnose as M
from uq._report.diagnose import write_diagnose_report


def configure_diagnose(p: argparse.ArgumentParser) -> None:
    add_recordings(p)
    add_sampling(p)
    add_json(p)
    p.add_argument(
        "--report", metavar="DIR", help="write the HTML section and residual plots to DIR"
    )
    p.add_argument(
        "--gain-se",
        type=float,
        default=GAIN_SE,
        help=f"ELPD gain, in standard errors, a mechanism must exceed (default {GAIN_SE:g})",
    )
    p.add_argument(
        "--max-mechanisms",
        type=int,
        default=len(M.MECHS),
        help=f"stop after this many mechanisms (default {len(M.MECHS)})",
    )
    add_stand(p)


def command_diagnose(args) -> int:
    if not (math.isfinite(args.gain_se) and args.gain_se > 0):
        raise InputError(f"option --gain-se: expected a positive number, got {args.gain_se:g}")
    if not 0 <= args.max_mechanisms <= len(M.MECHS):
        raise InputError(
            f"option --max-mechanisms: expected 0..{len(M.MECHS)}, got {args.max_mechanisms}"
        )
    settings = shorter_sampling(settings_from(args))
    rec = load(args)
    stand = stand_from(args)
    res = _diagnose.diagnose(
        rec,
        seed=args.seed,
        settings=settings,
        max_mechanisms=args.max_mechanisms,
        gain_se=args.gain_se,
        stand=stand,
    )
    if args.json != "-":
        sys.stdout.write(summary_text(res.document))
        print(f"time: {res.seconds['total']:.1f} s (screening {res.seconds['screening']:.1f} s)")
    emit_json(res.to_json(), args.json)
    if args.report:
        write_diagnose_report(res, args.report)
    warn = (res["sampling"] or {}).get("warnings") or []
    record_convergence(args, not warn, "the final model's sampler")
    return 0
