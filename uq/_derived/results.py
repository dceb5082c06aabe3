"""The JSON of ``uq fit`` (docs/formats.md section 2) and the saved posteriors (NetCDF).

Extends the contract with each test's posterior covariance of the coefficients (used by
``uq check``), the least-squares coefficients, the noise parameters and the convergence
diagnostics. SI units throughout.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from uq._data.reference import FORCE_NAMES, PISTON_NAMES
from uq._derived.residuals import campaign_order_warnings, order_check
from uq._inference.summary import estimate
from uq._models.cubic import NOISE_NAMES, CampaignFit, PressureFit


def _coef_block(draws: np.ndarray, names, diag: dict) -> dict:
    out = {}
    for i, n in enumerate(names):
        e = estimate(draws[..., i])
        v = diag["variables"][n]
        e |= {
            "r_hat": v["r_hat"],
            "ess_bulk": v["ess_bulk"],
            "ess_tail": v["ess_tail"],
            "mcse_mean": v["mcse_mean"],
        }
        out[n] = e
    return out


def test_json(fit: PressureFit) -> dict:
    d = fit.diagnostics
    s_P, eps_P = fit.deviation_measures()
    f, p = fit.flat("force"), fit.flat("piston")
    return {
        "pressure_bar": fit.pressure_bar,
        "n_points": fit.test.n_points,
        "force": _coef_block(fit.force, FORCE_NAMES, d),
        "piston": _coef_block(fit.piston, PISTON_NAMES, d),
        "s_P_N": s_P,
        "eps_P_pct": eps_P,
        "noise": {
            n: estimate(fit.noise[..., i])
            | {"r_hat": d["variables"][n]["r_hat"], "ess_bulk": d["variables"][n]["ess_bulk"]}
            for i, n in enumerate(NOISE_NAMES)
        },
        "least_squares": {
            "force": dict(zip(FORCE_NAMES, fit.lsq_force.tolist(), strict=True)),
            "piston": dict(zip(PISTON_NAMES, fit.lsq_piston.tolist(), strict=True)),
        },
        "covariance": {"force": np.cov(f, rowvar=False), "piston": np.cov(p, rowvar=False)},
        "convergence": {k: v for k, v in d.items() if k != "variables"},
        "residual_order": order_check(fit),
    }


def fit_json(cf: CampaignFit) -> dict:
    """What ``uq fit --json`` writes for a fit (docs/formats.md): per test the coefficients' and
    noise's posterior summaries, the coefficient blocks' covariance, least squares and diagnostics.
    Values are NumPy; ``uq._io.files.dumps_json`` gives the file's text. See :func:`uq.check` for a use."""
    rec = cf.recordings
    tests = [test_json(t) for t in cf.tests]
    warnings = [f"{t.pressure_bar:g} bar: {w}" for t in cf.tests for w in t.diagnostics["warnings"]]
    return {
        "x0_m": rec.x0_m,
        "piston_area_m2": rec.piston_area_m2,
        "source": os.path.basename(rec.path),
        "seed": cf.seed,
        "converged": cf.converged,
        "warnings": warnings,
        "model_warnings": campaign_order_warnings(cf),
        "tests": tests,
    }


def save_posteriors(cf: CampaignFit, out_dir: str | Path) -> list[Path]:
    """One NetCDF file (ArviZ InferenceData) per test, made in memory and written atomically
    (a full disk is a one-line error, not a crash inside HDF5: ``uq._io.files.netcdf_bytes``)."""
    from uq._io.files import write_netcdf_atomic

    out_dir = Path(out_dir)
    return [
        write_netcdf_atomic(out_dir / f"posterior_{t.pressure_bar:g}bar.nc", t.idata)
        for t in cf.tests
    ]
