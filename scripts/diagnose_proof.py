"""Proof of ``uq diagnose`` on concealed effects: regenerates reports/diagnose-proof/.

    .venv/bin/python scripts/diagnose_proof.py [--seeds 2] [--jobs 2] [--out reports/diagnose-proof]

(``--small --limit N --out DIR``: the first N campaigns on small layouts with short chains, to
check that the script runs; tests/test_scripts.py does so. Not a proof.)

For each mechanism of docs/formats.md section 3, among them the elastic
casing whose stored energy follows a potential (force and volume from one G(x, p_u), the Maxwell
relation holds), at two magnitudes (clearly visible; near the detection limit), on two stand
layouts (the paper's; pressures 0.5..6.5 bar, 70..150 mm in 2.5 mm steps), with several seeds;
clean controls; campaigns with two mechanisms at once.
The virtual stand (uq._stand.simulator.simulate, spring 'n50-traditional') conceals the effects with
the exact definitions of that section; the engine is given nothing but the recordings.

Writes results.json (every run), summary.json and README.md (confusion matrix, false-alarm
rate on clean data, detection rates, coverage of the true magnitude by the 90 % interval,
timings). Clean controls include campaigns from a stand noisier than the engine's noise model
(OTHER_STAND) and from one whose errors are heavy-tailed and correlated from reading to reading
(ROUGH_STAND), so the false-alarm rate is not checked against the model's own noise only; and
clean campaigns in the shapes that leave mechanisms unidentifiable (SHAPES): the compression
branch only, and a catalogue (one pass in unknown order, rounded, the volume at one pressure). Runs already in results.json with the same key are reused (``--fresh`` to redo).
"""

from __future__ import annotations

import argparse
import json
import multiprocessing as mp
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

MECHS = (
    "pressure_dependent_area",
    "casing_force",
    "elastic_casing",
    "hysteresis",
    "force_offset",
    "thermal_drift",
    "volume_excess",
)
MAGNITUDES = {  # (clearly visible, near the detection limit), units of docs/formats.md section 3
    "pressure_dependent_area": (0.01, 0.002),
    "casing_force": (200.0, 40.0),
    # a casing whose energy follows a potential (docs/formats.md section 3): Table 1 says about 0.02
    "elastic_casing": (0.02, 0.002),
    "hysteresis": (0.02, 0.005),
    "force_offset": (56.3, 12.0),
    "thermal_drift": (2.0, 0.5),
    "volume_excess": (0.12, 0.02),
}
#: A stand noisier than the engine's noise model assumes (load cell 0.8 % instead of 0.5 %):
#: clean campaigns from it are controls that do not pass by construction.
OTHER_STAND = {"load_cell_rel_sd": 0.008}
#: A stand whose noise differs from the engine's in form (data/stands/slow-pressure-control.toml):
#: heavy-tailed reading errors and pressure errors correlated from reading to reading.
ROUGH_STAND = {"error_df": 5.0, "pressure_error_corr": 0.7}
LAYOUTS = {
    "paper": dict(
        pressures_bar=(0.1, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10),
        x_max_m=0.155,
        x_min_m=0.065,
        step_m=0.005,
    ),
    "alt": dict(
        pressures_bar=(0.5, 1.5, 2.5, 3.5, 4.5, 5.5, 6.5),
        x_max_m=0.150,
        x_min_m=0.070,
        step_m=0.0025,
    ),
}
#: Clean campaigns in the shapes that leave mechanisms unidentifiable (uq._physics.mechanisms
#: ``needs``): "one-branch" keeps the compression branch only (recording order known, no rebound:
#: no hysteresis, no drift); "one-pass" is a catalogue (uq._stand.shapes.catalogue: one compression
#: pass in unknown order, values rounded as data sheets print them, the element's volume at the
#: middle pressure only, no piston).
SHAPES = ("one-branch", "one-pass")
#: --small: the same layout names with few pressures and 10 mm steps, and short chains.
SMALL_LAYOUTS = {
    "paper": dict(pressures_bar=(1.0, 5.0, 9.0), x_max_m=0.155, x_min_m=0.065, step_m=0.01),
    "alt": dict(pressures_bar=(1.5, 4.5), x_max_m=0.150, x_min_m=0.070, step_m=0.01),
}
PAIRS = [
    {"hysteresis": 0.02, "thermal_drift": 2.0},
    {"pressure_dependent_area": 0.01, "force_offset": 56.3},
]


def cases(n_seeds: int) -> list[dict]:
    out = []
    for layout in LAYOUTS:
        for seed in range(n_seeds):
            s = 1000 + seed
            out.append(dict(layout=layout, seed=s, effects={}, level="clean"))
            out.append(dict(layout=layout, seed=s + 500, effects={}, level="clean"))
            out.append(
                dict(layout=layout, seed=s + 250, effects={}, level="clean", stand=OTHER_STAND)
            )
            out.append(
                dict(layout=layout, seed=s + 750, effects={}, level="clean", stand=ROUGH_STAND)
            )
            for j, shape in enumerate(SHAPES):
                out.append(
                    dict(
                        layout=layout, seed=s + 100 + 50 * j, effects={}, level="clean", shape=shape
                    )
                )
            for m in MECHS:
                for level, mag in zip(("visible", "near-limit"), MAGNITUDES[m], strict=True):
                    out.append(dict(layout=layout, seed=s, effects={m: mag}, level=level))
            for pair in PAIRS:
                out.append(dict(layout=layout, seed=s, effects=pair, level="pair"))
    return out


def key(case: dict) -> str:
    eff = ",".join(f"{k}={v:g}" for k, v in sorted(case["effects"].items())) or "clean"
    stand = ",".join(f"{k}={v:g}" for k, v in sorted(case.get("stand", {}).items()))
    small = "|small" if case.get("small") else ""
    shape = f"|shape:{case['shape']}" if case.get("shape") else ""
    return (
        f"{case['layout']}|{case['seed']}|{eff}"
        + (f"|stand:{stand}" if stand else "")
        + shape
        + small
    )


def shaped(tests: list[dict], case: dict, stand, layout) -> list[dict] | str:
    """The stand's tests in the campaign's shape: as recorded; the compression branch only; or
    a catalogue's CSV text (one pass, no order, rounded, volume at the middle pressure)."""
    from uq._data.writing import write_recordings_csv
    from uq._stand import shapes
    from uq._stand.simulator import PAPER_PISTON_AREA_M2

    shape = case.get("shape")
    if shape is None:
        return tests
    if shape == "one-branch":
        out = []
        for t in tests:
            keep = np.asarray(t["compression"], bool)
            out.append(
                {
                    k: (v[keep] if isinstance(v, np.ndarray) and v.shape == keep.shape else v)
                    for k, v in t.items()
                }
            )
        return out
    assert shape == "one-pass", shape
    ps = sorted(layout.pressures_bar)
    table = shapes.catalogue(
        tests,
        "n50-traditional",
        case["effects"],
        volume_at_bar=ps[len(ps) // 2],
        x_max_m=layout.x_max_m,
        element_volume_at_xmax_m3=stand.element_volume_at_xmax_m3,
        piston_area_m2=PAPER_PISTON_AREA_M2,
    )
    return write_recordings_csv(
        table,
        "a catalogue made by scripts/diagnose_proof.py",
        order=False,
        piston=False,
        volume=True,
        rounding=shapes.catalogue_rounding({"height": "mm", "force": "N", "volume": "l"}),
    )


def run_case(case: dict) -> dict:
    from uq._data.recordings import recordings_from_text
    from uq._data.stand_description import PAPER_STAND
    from uq._diagnose.engine import diagnose
    from uq._inference.sampler import Settings
    from uq._stand.simulator import Layout, recordings_from_tests, simulate

    stand = PAPER_STAND.replace(**case.get("stand", {}))
    layouts, settings = (
        (SMALL_LAYOUTS, Settings(max_steps=200))
        if case.get("small")
        else (LAYOUTS, Settings(min_steps=300, chunk=200, tau_multiple=30.0))
    )
    layout = Layout(**layouts[case["layout"]])
    tests = shaped(
        simulate(
            "n50-traditional",
            seed=case["seed"],
            effects=case["effects"],
            layout=layout,
            stand=stand,
        ),
        case,
        stand,
        layout,
    )
    rec = (
        recordings_from_text(tests, "proof-catalogue")
        if isinstance(tests, str)
        else recordings_from_tests(tests, "proof")
    )
    t0 = time.time()
    res = diagnose(rec, seed=case["seed"], settings=settings).to_json()
    return {
        **case,
        "key": key(case),
        "seconds": time.time() - t0,
        "n_points": rec.n_points,
        "mismatch_detected": res["mismatch_detected"],
        "named": [m["name"] for m in res["mechanisms"]],
        "provisional": res["provisional"],
        "noise_check_passes": res["final"]["noise_check"]["passes"],
        "magnitudes": {m["name"]: m["magnitude"] for m in res["mechanisms"]},
        "gains": {m["name"]: [m["delta_elpd"], m["delta_elpd_se"]] for m in res["mechanisms"]},
        "baseline_rms_N": res["baseline"]["rms_N"],
        "final_rms_N": res["final"]["rms_N"],
        "baseline_elpd": res["baseline"]["elpd_loo"],
        "final_elpd": res["final"]["elpd_loo"],
        "flags": res["where"]["flagged"],
    }


def summarise(results: list[dict]) -> dict:
    rows = ["none", *MECHS]
    conf = {r: {c: 0 for c in [*MECHS, "nothing named"]} for r in rows}
    counts = {r: 0 for r in rows}
    for r in results:
        if r["level"] == "pair":
            continue
        true = next(iter(r["effects"]), "none")
        counts[true] += 1
        for n in r["named"]:
            conf[true][n] += 1
        if not r["named"]:
            conf[true]["nothing named"] += 1
    clean = [r for r in results if r["level"] == "clean"]
    det, cov = {}, {}
    for m in MECHS:
        for level in ("visible", "near-limit"):
            for lay in LAYOUTS:
                rs = [
                    r
                    for r in results
                    if r["level"] == level and r["layout"] == lay and m in r["effects"]
                ]
                if not rs:
                    continue
                hit = [r for r in rs if m in r["named"]]
                inside = [
                    r
                    for r in hit
                    if r["magnitudes"][m]["q05"] <= r["effects"][m] <= r["magnitudes"][m]["q95"]
                ]
                exact = [r for r in rs if r["named"] == [m]]
                det[f"{m}|{level}|{lay}"] = {
                    "runs": len(rs),
                    "named": len(hit),
                    "named_alone": len(exact),
                }
                cov[f"{m}|{level}|{lay}"] = {"named": len(hit), "true_in_90": len(inside)}
    pairs = [r for r in results if r["level"] == "pair"]
    pair_ok = [r for r in pairs if set(r["named"]) == set(r["effects"])]
    all_cov = [(r, m) for r in results for m in r["effects"] if m in r["named"]]
    inside = sum(
        r["magnitudes"][m]["q05"] <= r["effects"][m] <= r["magnitudes"][m]["q95"]
        for r, m in all_cov
    )
    single = [r for r in results if r["level"] in ("visible", "near-limit")]
    spurious = sum(len(set(r["named"]) - set(r["effects"])) > 0 for r in single)
    return {
        "n_runs": len(results),
        "seeds": len({r["seed"] for r in results if r["level"] == "visible"}),
        "confusion": conf,
        "runs_per_true": counts,
        "false_alarm_rate_clean": {
            "runs": len(clean),
            "mismatch_detected": sum(r["mismatch_detected"] for r in clean),
            "mechanism_named": sum(bool(r["named"]) for r in clean),
            "other_stand_runs": sum("stand" in r for r in clean),
            "other_stand_mechanism_named": sum(bool(r["named"]) for r in clean if "stand" in r),
            "shaped": {
                shape: {
                    "runs": sum(r.get("shape") == shape for r in clean),
                    "mismatch_detected": sum(
                        r["mismatch_detected"] for r in clean if r.get("shape") == shape
                    ),
                    "mechanism_named": sum(
                        bool(r["named"]) for r in clean if r.get("shape") == shape
                    ),
                }
                for shape in SHAPES
            },
        },
        "detection": det,
        "coverage_90": cov,
        "coverage_90_overall": {"named_true": len(all_cov), "true_in_90": int(inside)},
        "spurious_extra_mechanism_in_single_runs": {"runs": len(single), "with_extra": spurious},
        "pairs": {
            "runs": len(pairs),
            "both_named_exactly": len(pair_ok),
            "named": [[r["key"], r["named"]] for r in pairs],
        },
        "seconds": {
            "mean": float(np.mean([r["seconds"] for r in results])),
            "max": float(np.max([r["seconds"] for r in results])),
            "paper_layout_mean": float(
                np.mean([r["seconds"] for r in results if r["layout"] == "paper"] or [np.nan])
            ),
        },
    }


SHAPE_WORDS = {
    "one-branch": "compression branch only, recording order known",
    "one-pass": "a catalogue: one compression pass in unknown order, rounded, volume at the middle "
    "pressure only",
}


def markdown(s: dict, results: list[dict]) -> str:
    short = {
        "pressure_dependent_area": "pda",
        "casing_force": "casing",
        "elastic_casing": "elastic",
        "hysteresis": "hyst",
        "force_offset": "offset",
        "thermal_drift": "drift",
        "volume_excess": "vol-excess",
        "nothing named": "nothing",
    }
    lines = [
        "# uq diagnose: proof on concealed effects",
        "",
        f"Regenerate: `.venv/bin/python scripts/diagnose_proof.py --seeds {s.get('seeds', 'N')}`. Spring "
        "`n50-traditional` (obeys the traditional theory exactly) with effects concealed by the virtual "
        "stand (the definitions of docs/formats.md section 3; `elastic_casing`: a casing whose stored "
        "energy follows a potential, so force and volume obey the Maxwell relation).",
        "",
        f"Runs: {s['n_runs']}. Layouts: paper (0.1, 1..10 bar, 155..65 mm, 5 mm steps); alt (0.5..6.5 bar,"
        " 150..70 mm, 2.5 mm steps).",
        "",
        "## Confusion matrix (single-mechanism and clean runs; rows: truth, columns: named)",
        "",
        "| true \\ named | "
        + " | ".join(short[c] for c in [*MECHS, "nothing named"])
        + " | runs |",
        "|---" * (len(MECHS) + 3) + "|",
    ]
    for r, row in s["confusion"].items():
        lines.append(
            f"| {short.get(r, r)} | "
            + " | ".join(str(v) for v in row.values())
            + f" | {s['runs_per_true'][r]} |"
        )
    fa = s["false_alarm_rate_clean"]
    lines += [
        "",
        f"False alarms on clean data: mismatch_detected in {fa['mismatch_detected']}/{fa['runs']} runs, "
        f"a mechanism named in {fa['mechanism_named']}/{fa['runs']} (of them, clean campaigns from a stand "
        f"other than the model assumes, {OTHER_STAND} or {ROUGH_STAND}: named in {fa.get('other_stand_mechanism_named', 0)}/"
        f"{fa.get('other_stand_runs', 0)}; clean campaigns in the shapes that leave mechanisms "
        "unidentifiable: "
        + "; ".join(
            f"{shape} ({SHAPE_WORDS[shape]}): mismatch_detected in {v['mismatch_detected']}/{v['runs']}, "
            f"a mechanism named in {v['mechanism_named']}/{v['runs']}"
            for shape, v in fa.get("shaped", {}).items()
        )
        + ").",
        "",
        "## Detection and coverage of the true magnitude by the 90 % interval",
        "",
        "| mechanism | level | layout | named / runs | named alone | truth in 90 % / named |",
        "|---|---|---|---|---|---|",
    ]
    for k, v in s["detection"].items():
        m, level, lay = k.split("|")
        c = s["coverage_90"][k]
        lines.append(
            f"| {m} | {level} ({MAGNITUDES[m][0 if level == 'visible' else 1]:g}) | {lay} | {v['named']}/{v['runs']} | "
            f"{v['named_alone']} | {c['true_in_90']}/{c['named']} |"
        )
    co = s["coverage_90_overall"]
    sp = s["spurious_extra_mechanism_in_single_runs"]
    lines += [
        "",
        f"Overall coverage: {co['true_in_90']}/{co['named_true']} named true mechanisms have the truth in the"
        " 90 % interval.",
        f"Single-mechanism runs with an extra (wrong) mechanism named: {sp['with_extra']}/{sp['runs']}.",
        "",
        f"Two-mechanism campaigns: both named exactly in {s['pairs']['both_named_exactly']}/{s['pairs']['runs']}:",
        "",
    ]
    lines += [f"- `{k}` -> {', '.join(n) or 'nothing'}" for k, n in s["pairs"]["named"]]
    sec = s["seconds"]
    lines += [
        "",
        f"Time per campaign: mean {sec['mean']:.1f} s, max {sec['max']:.1f} s (paper layout mean "
        f"{sec['paper_layout_mean']:.1f} s; wall time on the shared 2-core machine, including compilation).",
        "",
        "## Every run",
        "",
        "| run | named | baseline rms N | final rms N | s |",
        "|---|---|---|---|---|",
    ]
    for r in results:
        lines.append(
            f"| `{r['key']}` | {', '.join(r['named']) or '-'} | {r['baseline_rms_N']:.1f} | {r['final_rms_N']:.1f} | {r['seconds']:.0f} |"
        )
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=2)
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", default=str(ROOT / "reports" / "diagnose-proof"))
    ap.add_argument("--fresh", action="store_true")
    ap.add_argument(
        "--only-summary", action="store_true", help="rewrite summary and README from results.json"
    )
    ap.add_argument(
        "--small",
        action="store_true",
        help="small layouts and short chains (checks that the script runs; not a proof)",
    )
    ap.add_argument("--limit", type=int, help="run only the first LIMIT campaigns")
    args = ap.parse_args(argv)
    from uq._io.files import dumps_json, write_text_atomic

    out = Path(args.out)
    path = out / "results.json"
    done = (
        {}
        if args.fresh or not path.exists()
        else {r["key"]: r for r in json.loads(path.read_text())}
    )
    todo = [c | ({"small": True} if args.small else {}) for c in cases(args.seeds)]
    todo = [c for c in todo if key(c) not in done]
    if not args.only_summary and todo:
        # Clean controls and visible effects first, so a cut-short run still says something.
        todo.sort(
            key=lambda c: (
                (c["seed"] - 1000) % 250,
                {"clean": 0, "visible": 1, "pair": 2, "near-limit": 3}[c["level"]],
            )
        )
        todo = todo[: args.limit]
        ctx = mp.get_context("spawn")
        with ctx.Pool(args.jobs, maxtasksperchild=None) as pool:
            for r in pool.imap_unordered(run_case, todo):
                done[r["key"]] = r
                print(
                    f"{r['key']}: named {r['named'] or 'nothing'} ({r['seconds']:.0f} s)",
                    flush=True,
                )
                write_text_atomic(path, dumps_json(sorted(done.values(), key=lambda r: r["key"])))
    results = sorted(done.values(), key=lambda r: r["key"])
    s = summarise(results)
    write_text_atomic(out / "summary.json", dumps_json(s))
    write_text_atomic(out / "README.md", markdown(s, results))
    print(markdown(s, results).split("## Every run")[0])
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
