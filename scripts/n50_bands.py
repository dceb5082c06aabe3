"""data/n50 against its own truth: the 90 % force bands of the surface with a discrepancy in
pressure, the smooth surface and the per-pressure cubics at the tested (pressure, height) points
and half-way between tested pressures, against Table 1's curves (exact at the tested pressures,
PCHIP between them: the truth data/n50 was simulated from). Writes n50-bands.json and
n50-bands.md into ``--out`` (default reports/between-coverage).

    .venv/bin/python scripts/n50_bands.py [--tiny]

Points: the 11 tested pressures at 70, 110 and 150 mm (33 points, tested heights near both ends
and the middle of the stroke), every tested (pressure, height) point (209), and the 10 pressures
half-way between tested ones at the same three heights (30 points). Counted: the band holds the
truth. At the tested points the discrepancy surface's band is set beside the cubics' (the
per-pressure posteriors): the ratio of widths and the difference of centres in the cubics' sd.

``--tiny`` (tests): a 3-test campaign of the stand instead of data/n50, 100 sampler steps.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # see scripts/between_coverage.py

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from scripts.between_coverage import TINY, fit_models  # noqa: E402
from uq._cli.common import DEFAULT_SEED  # noqa: E402
from uq._data.recordings import read_recordings  # noqa: E402
from uq._inference.sampler import Settings  # noqa: E402
from uq._inference.summary import band  # noqa: E402
from uq._io.files import dumps_json, write_text_atomic  # noqa: E402
from uq._models import discrepancy_gp as gp  # noqa: E402
from uq._stand.simulator import SPRINGS, Layout, simulate_recordings  # noqa: E402

HEIGHTS_MM = (70.0, 110.0, 150.0)
MODELS = ("discrepancy", "surface", "cubics")
LEVEL = 0.90


def bands_at(ans, h_m, p_bar):
    d = ans.force_draws(np.asarray(h_m, float), np.asarray(p_bar, float))
    m, lo, hi = band(d, axis=0, level=LEVEL)
    return m, lo, hi, d.std(axis=0)


def count(answers, truth, h_m, p_bar) -> dict:
    t = (
        truth.force_N(h_m, p_bar)
        if np.ndim(p_bar) == 0
        else np.array(
            [float(truth.force_N(np.array(h), p)) for h, p in zip(h_m, p_bar, strict=True)]
        )
    )
    out = {}
    for name, ans in answers.items():
        m, lo, hi, _ = bands_at(ans, h_m, p_bar)
        inside = (lo <= t) & (t <= hi)
        out[name] = {
            "covered": int(inside.sum()),
            "of": int(inside.size),
            "mean_width_N": float(np.mean(hi - lo)),
            "missed": [
                [float(h * 1e3), float(p)]
                for h, p, ok in zip(np.ravel(h_m), np.ravel(p_bar), inside.ravel(), strict=True)
                if not ok
            ],
        }
    return out


def between_nodes(fit) -> dict:
    """What the two-point mean between the virtual pressures neglects on this fit's draws: the share
    of draws with a short length scale, and the neglected conditional variance half-way between
    nodes relative to the deviation's prior variance, averaged over the draws."""
    length = fit.hyper["length"]
    step = float(np.diff(fit.nodes[0]).max())
    neglected = np.array([gp.interpolation_sd(step / v) ** 2 for v in length])
    return {
        "node_step_bar": step,
        "share_length_below_0.5_bar": float(np.mean(length < 0.5)),
        "share_length_below_0.25_bar": float(np.mean(length < 0.25)),
        "mean_neglected_variance": float(neglected.mean()),
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", help="output folder (default reports/between-coverage)")
    ap.add_argument("--tiny", action="store_true")
    args = ap.parse_args(argv)
    t0 = time.time()
    if args.tiny:
        rec = simulate_recordings("n50", seed=1, layout=Layout(pressures_bar=(1.0, 3.0, 5.0)))
        settings, source = TINY, "a 3-test campaign of the stand (tiny)"
    else:
        rec = read_recordings(ROOT / "data" / "n50" / "recordings.csv")
        settings, source = Settings(), "data/n50/recordings.csv"
    answers, cpu = fit_models(rec, DEFAULT_SEED, settings)
    truth = SPRINGS["n50"]()
    tested = rec.pressures_bar
    hs = np.array(HEIGHTS_MM) / 1e3
    H, P = np.meshgrid(hs, tested, indexing="ij")
    all_h = np.unique(np.round(np.concatenate([t.height_m for t in rec.tests]), 9))
    AH, AP = np.meshgrid(all_h, tested, indexing="ij")
    mids = (tested[:-1] + tested[1:]) / 2
    MH, MP = np.meshgrid(hs, mids, indexing="ij")
    at_tested = {}
    c_m, _, _, c_sd = bands_at(answers["cubics"], H.ravel(), P.ravel())
    for name in ("discrepancy", "surface"):
        m, lo, hi, _ = bands_at(answers[name], H.ravel(), P.ravel())
        _, clo, chi, _ = bands_at(answers["cubics"], H.ravel(), P.ravel())
        ratio = (hi - lo) / (chi - clo)
        shift = np.abs(m - c_m) / c_sd
        at_tested[name] = {
            "width_over_cubics_median": float(np.median(ratio)),
            "width_over_cubics_range": [float(ratio.min()), float(ratio.max())],
            "centre_shift_in_cubic_sd_median": float(np.median(shift)),
            "centre_shift_in_cubic_sd_max": float(shift.max()),
        }
    doc = {
        "source": source,
        "seed": DEFAULT_SEED,
        "level": LEVEL,
        "heights_mm": list(HEIGHTS_MM),
        "tested_33": count(answers, truth, H.ravel(), P.ravel()),
        "tested_all": count(answers, truth, AH.ravel(), AP.ravel()),
        "between": count(answers, truth, MH.ravel(), MP.ravel()),
        "at_tested_against_cubics": at_tested,
        "cpu_seconds": cpu,
        "hyperparameters": {
            k: answers["discrepancy"].to_json()["discrepancy"][k]
            for k in ("a_F_m2", "a_V_m2", "a_P_m2", "length_bar")
        },
        "between_nodes": between_nodes(answers["discrepancy"]),
        "converged": bool(answers["discrepancy"].convergence.converged),
        "warnings": answers["discrepancy"].convergence.messages(),
        "command": "python scripts/n50_bands.py "
        + " ".join(argv if argv is not None else sys.argv[1:]),
        "seconds": time.time() - t0,
    }
    out = Path(args.out or ROOT / "reports" / "between-coverage")
    out.mkdir(parents=True, exist_ok=True)
    write_text_atomic(out / "n50-bands.json", dumps_json(doc))
    write_text_atomic(out / "n50-bands.md", markdown(doc))
    print(markdown(doc))
    return 0


def markdown(doc: dict) -> str:
    lines = [
        "# data/n50: 90 % force bands against Table 1's curves",
        "",
        f"Generated by `{doc['command'].strip()}` (scripts/n50_bands.py) from {doc['source']}, seed "
        f"{doc['seed']}. Truth: Table 1's cubics at the tested pressures, PCHIP between them.",
        "",
        "| points | " + " | ".join(MODELS) + " |",
        "|---|---|---|---|",
    ]
    for key, words in (
        ("tested_33", f"tested pressures x {', '.join(f'{h:g}' for h in doc['heights_mm'])} mm"),
        ("tested_all", "every tested (pressure, height)"),
        ("between", "half-way between tested pressures, same heights"),
    ):
        cells = [
            f"{doc[key][m]['covered']} of {doc[key][m]['of']} (width {doc[key][m]['mean_width_N']:.0f} N)"
            for m in MODELS
        ]
        lines.append(f"| {words} | " + " | ".join(cells) + " |")
    d = doc["at_tested_against_cubics"]["discrepancy"]
    s = doc["at_tested_against_cubics"]["surface"]
    lines += [
        "",
        "At the tested points against the cubics' bands: the discrepancy surface's width is "
        f"{d['width_over_cubics_median']:.2f} times the cubics' (median; "
        f"{d['width_over_cubics_range'][0]:.2f}-{d['width_over_cubics_range'][1]:.2f}), its centre "
        f"{d['centre_shift_in_cubic_sd_median']:.2f} cubic sd away (median; at most "
        f"{d['centre_shift_in_cubic_sd_max']:.2f}); the smooth surface's centre "
        f"{s['centre_shift_in_cubic_sd_median']:.2f} (at most {s['centre_shift_in_cubic_sd_max']:.2f}).",
        "",
        "Hyperparameters: "
        + ", ".join(
            f"{k} {v['mean']:.3g} [{v['q05']:.3g}, {v['q95']:.3g}]"
            for k, v in doc["hyperparameters"].items()
        )
        + f"; converged: {doc['converged']}.",
    ]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    raise SystemExit(main())
