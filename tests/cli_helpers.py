"""Helpers of the command-line tests (tests/ is on sys.path: pytest puts the root conftest's folder there)."""

from __future__ import annotations

from uq._cli.main import main


def run(argv) -> int:
    """main() as the console script sees it: argparse's SystemExit becomes its status."""
    try:
        return main([str(a) for a in argv])
    except SystemExit as exc:
        return exc.code


def one_line(text: str) -> str:
    lines = [ln for ln in text.splitlines() if ln.strip()]
    assert len(lines) == 1, text
    return lines[0]
