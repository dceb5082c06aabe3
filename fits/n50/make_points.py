"""Write table1_points.json: Table 1 of the paper in SI, the point estimates for ``uq check``.

Run from the repository root:  .venv/bin/python fits/n50/make_points.py
The values come from uq._reference.table1() (the paper's table shipped in uq/_data,
converted to SI there); this script only reshapes them (and rounds away the
binary noise of the conversion at 12 significant digits) into CONTRACT.md section 3's
point-estimate format, so rerunning it reproduces the JSON byte for byte.
"""

from __future__ import annotations

from pathlib import Path

from uq._io import dumps_json, write_text_atomic
from uq._reference import FORCE_NAMES, PISTON_NAMES, table1

HERE = Path(__file__).resolve().parent


def _clean(v: float) -> float:
    """Drop the binary noise of the unit conversion (e.g. 130.89 * 1e3 = 130889.99999999999)."""
    return float(f"{v:.12g}")


def points() -> dict:
    t = table1()
    tests = []
    for i, p in enumerate(t.pressures_bar):
        tests.append({
            "pressure_bar": float(p),
            "force": {n: _clean(v) for n, v in zip(FORCE_NAMES, t.force[i], strict=True)},
            "piston": {n: _clean(v) for n, v in zip(PISTON_NAMES, t.piston[i], strict=True)},
        })
    return {"source": "Table 1 of the paper, converted to SI", "tests": tests}


def main() -> None:
    target = HERE / "table1_points.json"
    write_text_atomic(target, dumps_json(points()))
    print(f"wrote {target}")


if __name__ == "__main__":
    main()
