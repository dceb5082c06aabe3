"""``uq check``: the command line of :mod:`uq._derived.check` (posteriors against stored point estimates)."""

from __future__ import annotations

from uq._cli.common import probability, say
from uq._derived.check import DEFAULT_ALPHA, check_files, summary
from uq._io.files import emit_json


def configure_check(p) -> None:
    p.add_argument(
        "result",
        metavar="RESULT.json",
        help="output of `uq fit --json` (with posterior covariances)",
    )
    p.add_argument(
        "--against",
        required=True,
        metavar="POINTS.json",
        help="point estimates to check (the format of docs/formats.md section 2, e.g. fits/n50/table1_points.json)",
    )
    p.add_argument(
        "--alpha",
        type=probability,
        default=DEFAULT_ALPHA,
        help=f"false-failure rate of the whole check, Bonferroni over blocks (default {DEFAULT_ALPHA:g})",
    )
    p.add_argument(
        "--json", metavar="PATH", help="write the machine-readable verdict to PATH ('-' for stdout)"
    )


def command_check(args) -> int:
    verdict = check_files(args.result, args.against, alpha=args.alpha)
    emit_json(verdict, args.json)
    say(summary(verdict), args.json)
    return 0 if verdict["agree"] else 1
