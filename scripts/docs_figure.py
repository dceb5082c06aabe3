"""The README's picture: Figure 2 of the report on the bundled campaign, as docs/figures/fig2_force.png.

    .venv/bin/python scripts/docs_figure.py [--recordings data/n50/recordings.csv]
                                            [--out docs/figures/fig2_force.png] [REPORT OPTIONS]

Runs ``uq report`` on the recordings in a temporary folder (any further options, e.g.
``--max-steps 200 --draws 50``, are passed to it) and copies the report's ``fig2_force.png``, so
the picture is exactly what the report shows. Rerun it when the report's figures change.
"""

from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FIGURE = "fig2_force.png"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--recordings", default=str(ROOT / "data" / "n50" / "recordings.csv"))
    ap.add_argument("--out", default=str(ROOT / "docs" / "figures" / FIGURE))
    args, report_options = ap.parse_known_args(argv)
    with tempfile.TemporaryDirectory(prefix="uq-docs-figure-") as tmp:
        argv = ["report", args.recordings, "--out", tmp, "--quiet", *report_options]
        proc = subprocess.run(
            [sys.executable, "-m", "uq._cli.main", *argv], stdout=subprocess.DEVNULL
        )
        if proc.returncode != 0:
            print(f"docs_figure: uq report exited {proc.returncode}", file=sys.stderr)
            return proc.returncode
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(Path(tmp) / FIGURE, args.out)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
