"""The bundled campaign's characteristic in every tool's format: reports/export/ (docs/export.md).

data/n50 is not measured data: it is the paper's N-50 spring reconstructed from its Table 1 by the
project's virtual test stand (data/n50/README.md). Its header says so, and every file written here
repeats it (a note in each format, from the recordings' header kept in the saved model).

Fits ``uq export``'s default model (the registry's) to data/n50/recordings.csv once (``uq surface
--model ... --out``), then exports the saved model, without a refit, as the contract's CSV table
(with its provenance beside it), a workbook, a Simscape script and MAT-file, TeimOrbit property
files and JSON, and the closed spring (``--sealed``, charged at 112 mm to 5 bar with 5 L inside)
for Simscape's stiffness parameterisation and TeimOrbit files. Every command is run as a user runs
it (``uq ...``); SOURCE_DATE_EPOCH fixes the date the files carry.

    python scripts/export_n50.py                       # reports/export/ (the fit: 10 min on 2 cores)
    python scripts/export_n50.py --out /tmp/x --saved s.nc --draws 200   # the tests' run: no fit
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from uq._cli.main import main  # noqa: E402  (the repository's uq, also from a plain checkout)
from uq._io.files import write_text_atomic  # noqa: E402
from uq._models import registry  # noqa: E402

DATA = "data/n50/recordings.csv"
SEALED = ["--sealed", "--height-mm", "112", "--charge-bar", "5", "--volume-l", "5"]
#: (file under --out, extra options): every format, and the closed spring for the two tools
#: whose air-spring inputs take it
EXPORTS = [
    ("n50.csv", []),
    ("n50.xlsx", []),
    ("n50.json", []),
    ("n50.m", []),
    ("n50.mat", []),
    ("n50.tpf", []),
    ("n50-sealed.m", SEALED),
    ("n50.tpf", SEALED),  # n50_sealed_q50.tpf, ...
]
README = """# reports/export: data/n50's characteristic for other tools

Made by `python scripts/export_n50.py` (docs/export.md explains every file). **data/n50 is not
measured data**: it is the paper's N-50 spring reconstructed from its Table 1 by airspring-uq's
virtual test stand (data/n50/README.md); every file here says so in its notes.

{listing}
"""


def run(argv: list[str]) -> None:
    print("$ uq " + " ".join(argv), flush=True)
    code = main(argv)
    if code != 0:
        raise SystemExit(f"uq {argv[0]} exited with {code}")


def parse(argv=None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.split("\n", 1)[0])
    p.add_argument("--out", default=str(ROOT / "reports" / "export"), help="folder to write")
    p.add_argument("--max-steps", type=int, default=None, help="cap on the sampler's steps")
    p.add_argument("--draws", type=int, default=4000, help="posterior draws behind each estimate")
    p.add_argument(
        "--saved", help="export this saved model of data/n50 instead of fitting one (the tests)"
    )
    return p.parse_args(argv)


def export_n50(
    out: Path, *, max_steps: int | None, draws: int, saved: str | None = None
) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    os.environ.setdefault("SOURCE_DATE_EPOCH", "1764201600")  # 2025-11-27: the files' date
    with tempfile.TemporaryDirectory() as tmp:
        if saved is None:
            model = registry.default("export")
            fit = ["surface", DATA, "--model", model, "--no-compare", "--out", tmp, "--quiet"]
            run(fit + ([] if max_steps is None else ["--max-steps", str(max_steps)]))
            saved = Path(tmp) / f"{model}.nc"
        for name, extra in EXPORTS:
            argv = ["export", str(saved), "--out", str(out / name), "--draws", str(draws)]
            run(argv + ["--quiet", *extra])
    names = sorted(p.name for p in out.iterdir() if p.name != "README.md")
    listing = "\n".join(f"- `{n}`" for n in names)
    write_text_atomic(out / "README.md", README.format(listing=listing))
    return sorted(out.iterdir())


if __name__ == "__main__":
    args = parse()
    saved = None if args.saved is None else str(Path(args.saved).resolve())
    os.chdir(ROOT)  # the recordings as the repository names them: data/n50/recordings.csv
    for path in export_n50(
        Path(args.out).resolve(), max_steps=args.max_steps, draws=args.draws, saved=saved
    ):
        print(path)
