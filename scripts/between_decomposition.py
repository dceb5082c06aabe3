"""Where the discrepancy surface's band between two tested pressures comes from: its smooth
surface and its deviation, each against a made spring's truth.

    .venv/bin/python scripts/between_decomposition.py [--spring n50-kink] [--seeds 29017 ...]
        [--pressure-bar 4.5] [--heights-mm 90 112 130 150] [--out FILE.json] [--tiny]

Each seed: the virtual stand records the spring on the paper's grid (0.1, 1, 2, ..., 10 bar, as
scripts/between_coverage.py's ``paper``), the surface with a discrepancy in pressure is fitted as
``uq margin`` fits it, and at the query pressure and the two tested pressures around it, per
height, it reports: the true force; the 90 % band of the mean force and whether it holds the
truth; the posterior mean of the smooth surface's part minus the truth; the posterior mean of the
deviation's part (the Gaussian process in pressure) and its length scale's median. Written to
answer one question of docs/validation.md: is a band that misses between tests narrow because the
process interpolates too smoothly, or centred wrong because the smooth surface (a polynomial in
pressure) overshoots there while the deviations at the neighbouring tests are small?

``--tiny`` (tests): one seed on 1, 3 and 5 bar, one height, a short sampler run.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

# One BLAS thread (as scripts/between_coverage.py: a shared machine)
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "scripts"))

# the study's grids, level, campaigns and tiny settings (the campaigns it reports on)
import between_coverage as bc  # noqa: E402

from uq._data.stand_description import PAPER_STAND  # noqa: E402
from uq._inference.summary import band  # noqa: E402
from uq._io.files import dumps_json, write_text_atomic  # noqa: E402
from uq._models.discrepancy import fit_discrepancy  # noqa: E402
from uq._models.surface import SurfaceFit  # noqa: E402
from uq._stand.simulator import SPRINGS  # noqa: E402

PAPER, TINY_GRID, LEVEL = bc.GRIDS["paper"], bc.GRIDS["1-3-5"], bc.LEVEL


def decompose(spring: str, seed: int, grid, query_bar: float, heights_mm, settings=None) -> dict:
    """One campaign's fit taken apart at ``query_bar`` and its two neighbouring tested pressures."""
    rec = bc.campaign(spring, grid, seed, catalogue=False)
    fit = fit_discrepancy(rec, seed=seed, settings=settings, stand=PAPER_STAND)
    truth = SPRINGS[spring]()
    tested = np.sort(np.asarray(fit.tested_pressures_bar, float))
    i = int(np.searchsorted(tested, query_bar))
    pressures = [float(tested[i - 1]), float(query_bar), float(tested[i])]
    rows = []
    for h_mm in heights_mm:
        h = np.array([h_mm / 1e3])
        for p in pressures:
            pa = np.array([p])
            total = fit.force_draws(h, pa)[:, 0]
            smooth = SurfaceFit.force_draws(fit, h, pa)[:, 0]
            true_force = float(truth.force_N(h[0], p))
            _, lo, hi = band(total, level=LEVEL)
            rows.append(
                {
                    "height_mm": float(h_mm),
                    "pressure_bar": p,
                    "tested": bool(np.any(np.isclose(p, tested))),
                    "true_force_N": true_force,
                    "band_N": [float(lo), float(hi)],
                    "covered": bool(lo <= true_force <= hi),
                    "surface_minus_truth_N": float(smooth.mean() - true_force),
                    "deviation_N": float((total - smooth).mean()),
                }
            )
    length = np.asarray(fit.reported["length_bar"], float).ravel()
    return {
        "seed": seed,
        "length_bar_median": float(np.median(length)),
        "length_bar_90": np.quantile(length, [0.05, 0.95]).tolist(),
        "rows": rows,
    }


def markdown(spring: str, grid, results: list[dict]) -> str:
    lines = [
        f"RECONSTRUCTED data: {spring} recorded by the virtual stand (docs/stand.md) at "
        f"{', '.join(f'{p:g}' for p in grid)} bar; the surface with a discrepancy in pressure.",
        "",
        "| seed | l bar (median) | height mm | p bar | truth N | band - truth N | covered | "
        "surface - truth N | deviation N |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for res in results:
        for r in res["rows"]:
            lo, hi = (b - r["true_force_N"] for b in r["band_N"])
            lines.append(
                f"| {res['seed']} | {res['length_bar_median']:.2f} | {r['height_mm']:g} | "
                f"{r['pressure_bar']:g}{'' if r['tested'] else ' (between)'} | "
                f"{r['true_force_N']:.1f} | [{lo:+.1f}, {hi:+.1f}] | "
                f"{'yes' if r['covered'] else 'NO'} | {r['surface_minus_truth_N']:+.1f} | "
                f"{r['deviation_N']:+.1f} |"
            )
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--spring", choices=sorted(SPRINGS), default="n50-kink")
    ap.add_argument("--seeds", type=int, nargs="+", default=[29017])
    ap.add_argument("--pressure-bar", type=float, default=4.5)
    ap.add_argument("--heights-mm", type=float, nargs="+", default=[90.0, 112.0, 130.0, 150.0])
    ap.add_argument("--out", type=Path, help="also write the numbers as JSON to this file")
    ap.add_argument("--tiny", action="store_true", help="one seed on 1, 3, 5 bar (tests)")
    args = ap.parse_args(argv)
    grid, settings, seeds, heights = PAPER, None, args.seeds, args.heights_mm
    if args.tiny:
        grid, settings, seeds, heights = TINY_GRID, bc.TINY, seeds[:1], heights[:1]
    if not min(grid) < args.pressure_bar < max(grid) or args.pressure_bar in grid:
        print(
            f"between_decomposition.py: option --pressure-bar: {args.pressure_bar:g} bar is not "
            f"between two tested pressures ({', '.join(f'{p:g}' for p in grid)} bar)",
            file=sys.stderr,
        )
        return 2
    results = [decompose(args.spring, s, grid, args.pressure_bar, heights, settings) for s in seeds]
    print(markdown(args.spring, grid, results), end="")
    if args.out is not None:
        doc = {"spring": args.spring, "grid_bar": list(grid), "level": LEVEL, "seeds": results}
        write_text_atomic(args.out, dumps_json(doc))
    return 0


if __name__ == "__main__":
    sys.exit(main())
