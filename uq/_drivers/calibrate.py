"""Calibration of the per-pressure posteriors: do 50 % and 90 % intervals mean what they say?

``uq calibrate`` simulates campaigns whose truth is known, fits them, and reports for each
estimated quantity the empirical coverage of the central 50 % and 90 % intervals, with the
99 % binomial acceptance region around the nominal rate, and a simulation-based-calibration
(SBC) rank histogram (rank of the truth among L thinned posterior draws; uniform when the
posterior is calibrated; chi-square test of uniformity).

Truths:
* ``--truth prior``: parameters drawn from the model's own priors (uq/_models/cubic.py) and data
  drawn from the model: the SBC setting, where calibration must hold exactly.
* ``--truth n50``: the N-50 spring of Table 1 on the virtual stand, whose noise comes from
  the error budget rather than from the model: realistic, and the model is only approximately
  right about the noise. ``--stand FILE.toml`` (``stand=``) runs it on another stand, e.g. one
  whose errors are heavy-tailed and whose pressure errors are correlated in recording order
  (``error_df``, ``pressure_error_corr``): noise that differs in form from the model's
  independent Gaussian errors, so the check does not pass merely because the stand and the
  likelihood share an assumption.
``--noise constant`` refits with one force sd per test, to show what heteroscedastic noise
modelled as constant does to the intervals (the default models do not do this).

The pressure-holding error (uq._models.cubic, its pressure-holding section), n50 truth only:
* ``--pressure recorded``: the stand records each reading's pressure with the paper's sensor
  (uq._stand.shapes.record_pressure) and the fit uses it as a covariate; the same replications
  as ``--pressure set`` (the sensor has a random stream of its own), so the mean interval widths
  of the two settings (``mean_width90``) show how much the measured pressure shrinks them.
* ``--pressure-ar1 on``: the fit models the holding errors as an AR(1) series in recording order.
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
from scipy import stats

from uq._data.recordings import PressureTest
from uq._data.reference import FORCE_NAMES, PISTON_NAMES, table1
from uq._data.stand_description import PAPER_STAND, StandDescription
from uq._inference.sampler import Settings
from uq._io.errors import InputError
from uq._io.progress import progress
from uq._models.cubic import (
    FORCE_PRIOR_SD_N,
    NOISE_PRIOR_MEAN,
    NOISE_PRIOR_SD,
    PISTON_PRIOR_SD_M,
    basis,
    to_paper_basis,
)
from uq._models.cubic_fit import fit_test
from uq._models.cubic_results import NOISE_NAMES
from uq._physics.cubic import cubic
from uq._physics.quantities import force_noise_var
from uq._stand.shapes import record_pressure
from uq._stand.simulator import Layout, simulate

QUANTITIES = FORCE_NAMES + PISTON_NAMES
N_RANKS = 99  # draws per replication for SBC ranks -> ranks 0..99, 10 bins of 10


def _test_from_model(
    rng, pressure_bar: float, x0_m: float
) -> tuple[PressureTest, np.ndarray, np.ndarray]:
    """A test drawn from the per-pressure model's priors; returns (test, truth (8,), noise (3,))."""
    heights, comp = Layout(pressures_bar=(pressure_bar,)).heights()
    u = heights - x0_m
    X = np.asarray(basis(u))
    alpha_f = rng.normal(0.0, FORCE_PRIOR_SD_N, 4)
    alpha_l = rng.normal(0.0, PISTON_PRIOR_SD_M, 4)
    log_noise = rng.normal(NOISE_PRIOR_MEAN, NOISE_PRIOR_SD)
    s0, rel, sL = np.exp(log_noise)
    mu_f, mu_l = X @ alpha_f, X @ alpha_l
    force = mu_f + np.sqrt(force_noise_var(s0, rel, mu_f)) * rng.standard_normal(u.size)
    piston = mu_l + sL * rng.standard_normal(u.size)
    truth = np.concatenate([to_paper_basis(alpha_f), to_paper_basis(alpha_l)])
    steps = np.arange(u.size)
    return (
        PressureTest(pressure_bar, heights, force, piston, comp, steps, steps + 2),
        truth,
        np.array([s0, rel, sL]),
    )


def _test_from_stand(
    seed: int, pressure_bar: float, stand: StandDescription, recorded: bool = False
) -> tuple[PressureTest, np.ndarray]:
    tests = simulate("n50", seed=seed, layout=Layout(pressures_bar=(pressure_bar,)), stand=stand)
    if recorded:
        tests = record_pressure(tests, seed, stand)
    t = tests[0]
    t1 = table1()
    i = t1.index(pressure_bar)
    steps = t["step"]
    test = PressureTest(
        pressure_bar,
        t["height_m"],
        t["force_N"],
        t["piston_m"],
        t["compression"],
        steps,
        steps + 2,
        t.get("measured_pressure_bar"),
    )
    return test, np.concatenate([t1.force[i], t1.piston[i]])


@dataclass
class CalibrationResult:
    truth_kind: str
    noise: str
    names: list[str]
    inside50: np.ndarray  # (reps, q) bool
    inside90: np.ndarray
    ranks: np.ndarray  # (reps, q) int in 0..N_RANKS
    pressures: np.ndarray
    converged: np.ndarray  # (reps,) bool
    seconds: float
    # n50 truth only: coverage of 90 % predictive intervals of a fresh replicate's readings,
    # for the lowest and the highest third of the forces of each test, (reps, 2)
    predictive: np.ndarray | None = None
    stand: StandDescription = PAPER_STAND  # of the n50 truth's stand
    width90: np.ndarray | None = None  # (reps, q) width of the central 90 % interval
    pressure: str = "set"  # "recorded": the stand recorded each reading's pressure, the fit used it
    ar1: str = "off"  # "on": the fit modelled AR(1) pressure-holding errors

    def summary(self) -> dict:
        n = self.inside90.shape[0]
        p_sbc = [_sbc_p(self.ranks[:, j]) for j in range(len(self.names))]
        p_holm = _holm(p_sbc)
        region = {"50": _region(n, 0.5), "90": _region(n, 0.9)}
        out = {
            "truth": self.truth_kind,
            "noise_model": self.noise,
            "pressure": self.pressure,
            "pressure_ar1": self.ar1,
            "replications": n,
            "stand": self.stand.changes(),
            "converged_fraction": float(self.converged.mean()),
            "predictive_coverage90": None
            if self.predictive is None
            else {
                "low_force_third": float(self.predictive[:, 0].mean()),
                "high_force_third": float(self.predictive[:, 1].mean()),
            },
            "acceptance_region_99pct": region,
            "quantities": {},
        }
        for j, name in enumerate(self.names):
            hist = np.histogram(self.ranks[:, j], bins=10, range=(0, N_RANKS + 1))[0]
            c50, c90 = int(self.inside50[:, j].sum()), int(self.inside90[:, j].sum())
            out["quantities"][name] = {
                "coverage50": float(self.inside50[:, j].mean()),
                "coverage90": float(self.inside90[:, j].mean()),
                "covered50": c50,
                "covered90": c90,
                "in_region50": region["50"][0] <= c50 <= region["50"][1],
                "in_region90": region["90"][0] <= c90 <= region["90"][1],
                "mean_width90": None if self.width90 is None else float(self.width90[:, j].mean()),
                "sbc_rank_histogram": hist.tolist(),
                "sbc_uniformity_p": p_sbc[j],
                "sbc_uniformity_p_holm": p_holm[j],
            }
        return out


def _sbc_p(ranks: np.ndarray) -> float | None:
    """Chi-square p-value of uniform SBC ranks in 10 bins (None below 20 replications)."""
    if ranks.size < 20:
        return None
    return float(stats.chisquare(np.histogram(ranks, bins=10, range=(0, N_RANKS + 1))[0]).pvalue)


def _holm(ps: list[float | None]) -> list[float | None]:
    """Holm-adjusted p-values over the quantities of one setting.

    Each setting tests 8-11 quantities, so one raw p near 0.01 is expected by chance about one
    time in ten; only an adjusted p below 0.01 is evidence of miscalibration.
    """
    idx = [i for i, p in enumerate(ps) if p is not None]
    out: list[float | None] = [None] * len(ps)
    running = 0.0
    for k, i in enumerate(sorted(idx, key=lambda i: ps[i])):
        running = max(running, min(1.0, (len(idx) - k) * ps[i]))
        out[i] = running
    return out


def _region(n: int, p: float) -> tuple[int, int]:
    """Central 99 % binomial acceptance region for the number of covered intervals."""
    return int(stats.binom.ppf(0.005, n, p)), int(stats.binom.isf(0.005, n, p))


def calibrate(
    reps: int,
    *,
    truth: str = "prior",
    noise: str = "budget",
    seed: int = 0,
    settings: Settings | None = None,
    pressures=(1.0, 5.0, 10.0),
    stand: StandDescription = PAPER_STAND,
    pressure: str = "set",
    ar1: str = "off",
) -> CalibrationResult:
    """``reps`` replications of one setting; ``stand`` is the virtual stand of the n50 truth;
    ``pressure`` "recorded" records each reading's pressure (n50 truth) and fits with it as a
    covariate; ``ar1`` "on" fits AR(1) pressure-holding errors (module docstring)."""
    for name, value, (a, b) in (
        ("truth", truth, ("prior", "n50")),
        ("noise", noise, ("budget", "constant")),
        ("pressure", pressure, ("set", "recorded")),
        ("ar1", ar1, ("off", "on")),
    ):
        if value not in (a, b):
            raise InputError(f"{name}: expected '{a}' or '{b}', got '{value}'", param=name)
    if truth == "prior" and (pressure != "set" or ar1 != "off"):
        raise InputError(
            "`pressure`/`ar1`: the prior truth draws its data from the plain model; use them "
            "with the n50 `truth`"
        )
    if reps < 1:
        raise InputError(f"reps: at least 1 replication, got {reps}", param="reps")
    if truth == "prior" and stand != PAPER_STAND:
        raise InputError(
            "stand: only the n50 truth runs on a stand; the prior truth draws its data from the model",
            param="stand",
        )
    settings = settings or Settings(min_steps=300, chunk=150)
    rng = np.random.default_rng(seed)
    names = list(QUANTITIES) + (list(NOISE_NAMES) if truth == "prior" and noise == "budget" else [])
    in50, in90, ranks, conv, ps, pred, widths = [], [], [], [], [], [], []
    recorded = pressure == "recorded"
    t0 = time.perf_counter()
    for r in progress(range(reps), desc=f"calibrate {truth}, {noise}", unit="rep"):
        p = float(pressures[r % len(pressures)])
        if truth == "prior":
            test, coef, noise_truth = _test_from_model(rng, p, 0.112)
            true = np.concatenate([coef, noise_truth]) if noise == "budget" else coef
        else:
            test, true = _test_from_stand(int(rng.integers(2**31)), p, stand, recorded)
        fit = fit_test(
            test,
            0.112,
            seed=int(rng.integers(2**31)),
            settings=settings,
            noise=noise,
            pressure="measured" if recorded else "set",
            ar1=ar1,
        )
        draws = np.concatenate(
            [fit.flat("force"), fit.flat("piston")]
            + ([fit.flat("noise")] if len(names) > 8 else []),
            axis=1,
        )
        q = np.quantile(draws, [0.05, 0.25, 0.75, 0.95], axis=0)
        in50.append((q[1] <= true) & (true <= q[2]))
        in90.append((q[0] <= true) & (true <= q[3]))
        widths.append(q[3] - q[0])
        thin = draws[np.linspace(0, draws.shape[0] - 1, N_RANKS).astype(int)]
        ranks.append(np.sum(thin < true, axis=0))
        conv.append(fit.convergence.converged)
        ps.append(p)
        if truth == "n50":
            cover = _predictive_coverage(
                fit, _test_from_stand(int(rng.integers(2**31)), p, stand)[0], rng
            )
            if not recorded:  # computed either way (the same random stream: the same
                pred.append(cover)  # replications); with recorded pressure it would need the
                # fresh test's own pressures, so it is not reported
    return CalibrationResult(
        truth,
        noise,
        names,
        np.array(in50),
        np.array(in90),
        np.array(ranks),
        np.array(ps),
        np.array(conv),
        time.perf_counter() - t0,
        np.array(pred) if pred else None,
        stand,
        np.array(widths),
        pressure,
        ar1,
    )


def _predictive_coverage(fit, fresh: PressureTest, rng, n_draws: int = 2000) -> np.ndarray:
    """Share of a fresh replicate's force readings inside the 90 % predictive interval,
    for the lowest and highest third of the forces; (2,). With AR(1) holding errors the replicate
    is the model's own (``posterior_predictive``: a fresh holding-error series at the same
    heights, which the fresh test has)."""
    f, nz = fit.flat("force"), fit.flat("noise")
    idx = rng.choice(f.shape[0], size=min(n_draws, f.shape[0]), replace=False)
    u = fresh.height_m - fit.x0_m
    if fit.variant == "ar1":
        y = np.asarray(fit.idata.posterior_predictive["force_N"]).reshape(-1, u.size)[idx]
    else:
        mu = cubic(f[idx][:, None, :], u)  # (draws, n)
        sd = np.sqrt(nz[idx, 0:1] ** 2 + (nz[idx, 1:2] * fit.ref_force_N) ** 2)
        y = mu + sd * rng.standard_normal(mu.shape)
    lo, hi = np.quantile(y, [0.05, 0.95], axis=0)
    inside = (lo <= fresh.force_N) & (fresh.force_N <= hi)
    order = np.argsort(fresh.force_N)
    third = max(1, u.size // 3)
    return np.array([inside[order[:third]].mean(), inside[order[-third:]].mean()])


def markdown(results: list[CalibrationResult], command: str) -> str:
    lines = [
        "# Calibration of the per-pressure posteriors",
        "",
        "Generated by `"
        + command
        + "` (uq/_drivers/calibrate.py). Coverage = share of replications whose "
        "central interval contains the truth; the 99 % binomial acceptance region is given per setting. "
        "SBC p = chi-square test of uniform ranks (10 bins); Holm p = the same adjusted for testing every "
        "quantity of a setting (only Holm p < 0.01 is evidence of miscalibration).",
        "",
    ]
    for res in results:
        s = res.summary()
        n = s["replications"]
        r50, r90 = s["acceptance_region_99pct"]["50"], s["acceptance_region_99pct"]["90"]
        on = (
            (" on a stand with " + ", ".join(f"{k} = {v:g}" for k, v in s["stand"].items()))
            if s["stand"]
            else ""
        )
        how = ""
        if s["pressure"] == "recorded":
            how += ", pressure recorded and used as a covariate"
        if s["pressure_ar1"] == "on":
            how += ", AR(1) pressure-holding errors"
        lines += [
            f"## truth = {s['truth']}{on}, noise model = {s['noise_model']}{how} ({n} replications, "
            f"{100 * s['converged_fraction']:.0f} % converged, {res.seconds:.0f} s)",
            "",
        ]
        if s["predictive_coverage90"]:
            pc = s["predictive_coverage90"]
            lines += [
                f"90 % predictive intervals of a fresh replicate's force readings cover "
                f"{100 * pc['low_force_third']:.1f} % of the lowest-force third and "
                f"{100 * pc['high_force_third']:.1f} % of the highest-force third of each test.",
                "",
            ]
        lines += [
            f"| quantity | covered of {n} at 50 % (region {r50[0]}-{r50[1]}) | at 90 % (region {r90[0]}-{r90[1]}) "
            "| SBC p | Holm p | mean 90 % width (SI) |",
            "|---|---|---|---|---|---|",
        ]
        for name, q in s["quantities"].items():
            mark50 = "" if q["in_region50"] else " **outside**"
            mark90 = "" if q["in_region90"] else " **outside**"
            p = "-" if q["sbc_uniformity_p"] is None else f"{q['sbc_uniformity_p']:.3f}"
            ph = "-" if q["sbc_uniformity_p_holm"] is None else f"{q['sbc_uniformity_p_holm']:.3f}"
            ph += (
                " **low**"
                if q["sbc_uniformity_p_holm"] is not None and q["sbc_uniformity_p_holm"] < 0.01
                else ""
            )
            w = "-" if q["mean_width90"] is None else f"{q['mean_width90']:.4g}"
            lines.append(
                f"| {name} | {q['covered50']}{mark50} | {q['covered90']}{mark90} | {p} | {ph} | {w} |"
            )
        lines.append("")
    return "\n".join(lines) + "\n"
