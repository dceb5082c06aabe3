"""``uq calibrate``: the options, the printed lines and the files of uq._drivers.calibrate."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from uq._cli.common import add_stand, choice_list, positive_int, seed, stand_from
from uq._drivers import calibrate as C
from uq._io.errors import InputError
from uq._io.files import emit_json, remove_stale, write_figure_atomic, write_text_atomic


def configure_calibrate(p) -> None:
    p.add_argument(
        "--reps", type=positive_int, default=100, help="replications per setting (default 100)"
    )
    p.add_argument(
        "--truth",
        type=choice_list("prior", "n50"),
        default="prior,n50",
        help="comma list of truths: prior, n50",
    )
    p.add_argument(
        "--noise",
        type=choice_list("budget", "constant"),
        default="budget",
        help="comma list of force-noise models to fit: budget, constant",
    )
    p.add_argument(
        "--pressure",
        type=choice_list("set", "recorded"),
        default="set",
        help="comma list: set (the stand records set pressures only), recorded (it records each "
        "reading's pressure with the paper's sensor, and the fit uses it as a covariate); n50 truth "
        "(default: set)",
    )
    p.add_argument(
        "--pressure-ar1",
        type=choice_list("off", "on"),
        default="off",
        help="comma list: fit the pressure-holding errors as independent noise (off) or as an "
        "AR(1) series in recording order (on); n50 truth (default: off)",
    )
    p.add_argument("--seed", type=seed, default=20201, help="random seed")
    p.add_argument(
        "--out",
        metavar="DIR",
        help="the folder to write: calibration.json, calibration.md and rank histograms",
    )
    p.add_argument("--json", metavar="PATH", help="machine-readable result ('-' for stdout)")
    add_stand(
        p,
        help="stand description (TOML) of the virtual stand that makes the n50 truth's recordings "
        "(default: the paper's; error_df and pressure_error_corr give noise unlike the model's)",
    )


def command_calibrate(args) -> int:
    stand = stand_from(args, model=False)
    # the lists are checked and cleaned as they are read (uq._cli.common.choice_list)
    truths, pressures, ar1s = (v.split(",") for v in (args.truth, args.pressure, args.pressure_ar1))
    if args.stand and "prior" in truths:
        raise InputError(
            "option --stand: only the n50 truth runs on a stand; use it with --truth n50"
        )
    pressure_settings = [(pr, ar) for pr in pressures for ar in ar1s]
    if "prior" in truths and pressure_settings != [("set", "off")]:
        raise InputError(
            "options --pressure/--pressure-ar1: only the n50 truth records pressure or fits AR(1) "
            "holding errors; use them with --truth n50"
        )
    results = []
    for truth, noise, (pressure, ar1) in (
        (t, n, s) for t in truths for n in args.noise.split(",") for s in pressure_settings
    ):
        res = C.calibrate(
            args.reps,
            truth=truth,
            noise=noise,
            seed=args.seed,
            stand=stand,
            pressure=pressure,
            ar1=ar1,
        )
        results.append(res)
        s = res.summary()
        worst = min(s["quantities"].items(), key=lambda kv: kv[1]["coverage90"])
        label = "" if (pressure, ar1) == ("set", "off") else f" pressure {pressure} ar1 {ar1}"
        print(
            f"truth {truth:5s} noise {noise:8s}{label}: {args.reps} reps in {res.seconds:.0f} s; 90 % coverage "
            f"{min(q['coverage90'] for q in s['quantities'].values()):.2f}..{max(q['coverage90'] for q in s['quantities'].values()):.2f} "
            f"(lowest: {worst[0]}); outside the 99 % region: "
            f"{[k for k, q in s['quantities'].items() if not (q['in_region90'] and q['in_region50'])] or 'none'}"
        )
    command = (
        "uq " + " ".join(sys.argv[1:])
        if sys.argv and sys.argv[0].endswith("uq")
        else "uq calibrate"
    )
    result = {"command": command, "settings": [r.summary() for r in results]}
    if args.out:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        out = Path(args.out)
        emit_json(result, str(out / "calibration.json"))
        write_text_atomic(out / "calibration.md", C.markdown(results, command))
        for res in results:
            fig, axes = plt.subplots(
                1, len(res.names), figsize=(1.6 * len(res.names), 2.0), sharey=True
            )
            for ax, j in zip(np.atleast_1d(axes), range(len(res.names)), strict=True):
                ax.hist(res.ranks[:, j], bins=10, range=(0, C.N_RANKS + 1), color="tab:blue")
                ax.axhline(res.ranks.shape[0] / 10, color="k", lw=0.8)
                ax.set_title(res.names[j], fontsize=8)
                ax.set_xticks([])
            fig.suptitle(
                f"SBC ranks, truth {res.truth_kind}, noise {res.noise}{_suffix(res, ', ')}",
                fontsize=9,
            )
            fig.tight_layout()
            write_figure_atomic(fig, out / _figure_name(res), dpi=80)
            plt.close(fig)
        # rank histograms of settings an earlier run had and this one has not would pass for current
        remove_stale(out, ("sbc_*.png",), keep={_figure_name(r) for r in results})
        print(f"wrote {out}/calibration.json, calibration.md and rank histograms")
    emit_json(result, args.json)
    return 0


def _suffix(res, sep: str = "_") -> str:
    """The pressure settings of a result in names, empty for the default (set, off)."""
    parts = ([f"pressure-{res.pressure}"] if res.pressure != "set" else []) + (
        ["ar1"] if res.ar1 == "on" else []
    )
    return "".join(sep + p for p in parts)


def _figure_name(res) -> str:
    return f"sbc_{res.truth_kind}_{res.noise}{_suffix(res)}.png"
