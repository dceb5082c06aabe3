"""Surface model: bands and refusals on data/n50; coverage on simulated campaigns with known truth."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from uq._errors import InputError
from uq._recordings import read_recordings, write_recordings_csv
from uq._sampler import Settings
from uq._stand import Layout, SmoothSurfaceSpring, simulate
from uq._surface import (
    Orders,
    compare_with_cubics,
    figure_feff,
    figure_spread,
    fit_surface,
    summary,
)

ROOT = Path(__file__).resolve().parents[1]
FAST = Settings(tau_multiple=20.0, min_steps=200)
LAYOUT = Layout(pressures_bar=(1.0, 2.5, 5.0, 7.5, 10.0), step_m=0.01)
X_CHECK, P_CHECK = 0.100, 4.0  # between the tested pressures
TRUTH_ORDERS = Orders(3, 2, 2, 1, 1)  # the n50-smooth spring's own class


@pytest.fixture(scope="module")
def n50_surface(n50_recordings):
    return fit_surface(n50_recordings, seed=20201)


def _campaign(tmp_path, seed, layout=LAYOUT):
    path = tmp_path / f"smooth-{seed}.csv"
    path.write_text(write_recordings_csv(simulate("n50-smooth", seed=seed, layout=layout)))
    return read_recordings(path)


def coverage_run(tmp_path, seeds, settings=FAST, layout=LAYOUT):
    """Per seed: is the truth inside the 90 % F_eff band and the 90 % pressure_bar_needed interval?"""
    from uq._margin import pressure_needed

    truth = SmoothSurfaceSpring()
    feff_true = float(truth.effective_area_m2(np.array(X_CHECK), P_CHECK))
    load = float(truth.force_N(np.array(truth.x0_m), P_CHECK))
    rows = []
    for s in seeds:
        fit = fit_surface(_campaign(tmp_path, s, layout), TRUTH_ORDERS, seed=s, settings=settings)
        b = fit.bands(np.array(X_CHECK), P_CHECK)["feff_m2"]
        need = pressure_needed(fit, truth.x0_m, load)
        q05, q95 = np.quantile(need, [0.05, 0.95])
        feff = np.ravel(fit.feff_draws(np.array(X_CHECK), P_CHECK))
        thin = np.linspace(0, feff.size - 1, 99).astype(int)  # SBC: rank of the truth among 99 draws
        feff_rank = int(np.sum(feff[thin] < feff_true))
        need_rank = int(np.sum(np.ravel(need)[np.linspace(0, np.size(need) - 1, 99).astype(int)] < P_CHECK))
        rows.append({"seed": s, "feff_covered": bool(b["lower"] <= feff_true <= b["upper"]),
                     "pressure_covered": bool(q05 <= P_CHECK <= q95),
                     "feff_band": [float(b["lower"]), float(b["upper"])], "pressure_interval": [float(q05), float(q95)],
                     "feff_rank": feff_rank, "pressure_rank": need_rank,
                     "converged": fit.diagnostics["converged"]})
    return rows, {"feff_true_m2": feff_true, "load_N": load, "x_m": X_CHECK, "p_bar": P_CHECK}


def test_bands_on_n50(n50_surface):
    fit = n50_surface
    assert fit.diagnostics["converged"], fit.diagnostics["warnings"]
    b = fit.bands(np.array([0.112]), 5.0)
    assert b["force_N"]["lower"][0] < b["force_N"]["upper"][0]
    assert abs(b["feff_m2"]["mean"][0] - 0.026) < 0.002
    # between tested pressures too
    b = fit.bands(np.array([0.1, 0.13]), 4.5)
    assert np.all(b["feff_m2"]["lower"] < b["feff_m2"]["upper"])
    res = summary(fit)
    assert res["coefficients"]["F_eff_m2"] and res["noise"]["rel_load"]["r_hat"] < 1.01
    assert 0.0 <= res["spread_credibly_nonzero_fraction"] <= 1.0


def test_refuses_extrapolation(n50_surface):
    with pytest.raises(InputError, match="outside the tested pressures"):
        n50_surface.bands(np.array([0.112]), 12.0)
    with pytest.raises(InputError, match="outside the tested heights"):
        n50_surface.bands(np.array([0.2]), 5.0)


def test_figures(n50_surface):
    for fig in (figure_feff(n50_surface, 12, 10), figure_spread(n50_surface, 12, 10)):
        assert fig.axes


def test_surface_report_section(n50_surface, tmp_path):
    from uq._surface import summary
    from uq._surface_report import write_surface_report

    path = write_surface_report(n50_surface, summary(n50_surface), tmp_path)
    page = path.read_text()
    assert page.count("data:image/png;base64,") == 3 and "band excludes zero" in page
    assert sorted(p.name for p in tmp_path.iterdir()) == ["surface.html", "surface_feff.png", "surface_residuals.png", "surface_spread.png"]


def test_compare_with_cubics(n50_surface, n50_fit):
    c = compare_with_cubics(n50_surface, n50_fit)
    assert np.isfinite(c["elpd_diff"]) and c["elpd_diff_se"] > 0
    assert c["better"] in ("surface", "per-pressure cubics")


def test_fast_coverage(tmp_path):
    rows, _ = coverage_run(tmp_path, range(10))
    assert sum(r["feff_covered"] for r in rows) >= 6, rows
    assert sum(r["pressure_covered"] for r in rows) >= 6, rows


@pytest.mark.slow
def test_slow_coverage(tmp_path):
    """>= 100 replications: the 99 % binomial acceptance region around 90 % is 82..97 of 100."""
    from uq._io import write_text_atomic

    n = 100
    rows, truth = coverage_run(tmp_path, range(1000, 1000 + n), settings=Settings())
    k_f = sum(r["feff_covered"] for r in rows)
    k_p = sum(r["pressure_covered"] for r in rows)
    from scipy import stats

    hist = {k: np.histogram([r[k] for r in rows], bins=10, range=(0, 100))[0].tolist() for k in ("feff_rank", "pressure_rank")}
    sbc_p = {k: float(stats.chisquare(h).pvalue) for k, h in hist.items()}
    out = {"replications": n, "level": 0.9, "acceptance": [82, 97], "truth": truth,
           "sbc_rank_histograms": hist, "sbc_uniformity_p": sbc_p,
           "feff_covered": k_f, "pressure_covered": k_p, "layout": str(LAYOUT), "spring": "n50-smooth", "rows": rows}
    write_text_atomic(ROOT / "reports" / "surface-coverage" / "coverage.json", json.dumps(out, indent=1) + "\n")
    assert 82 <= k_f <= 97
    assert 82 <= k_p <= 97


def test_reading_covariance_has_the_gas_law_sign():
    """A pressure-holding error dp raises the force by dp F_eff and, by Boyle's law, leaves the
    piston short by V_gas dp / (p_abs S): the model's (force, piston) covariance must be
    -sd_p^2 F_eff V_gas / (p_abs S), negative, built from first principles here."""
    import jax.numpy as jnp

    from uq._surface import _cov_factors

    dp, feff, V0, dv, p_abs, S = 1.0e3, 0.025, 6.2e-3, 1.0e-3, 6.0e5, 54.82e-4
    c = {k: jnp.asarray([v]) for k, v in dict(phat=1.0e4, feff_hat=feff, dv_hat=dv, dp_pa=dp,
                                               p_abs_pa=p_abs, area=S).items()}
    theta = jnp.log(jnp.asarray([10.0, 0.005, 1.0, 1.0e-5, V0]))
    L11, L21, L22 = (float(v[0]) for v in _cov_factors(theta, c))
    cov_fl = L11 * L21
    expected = -(dp**2) * feff * (V0 - dv) / (p_abs * S)
    assert cov_fl == pytest.approx(expected, rel=1e-12)
    var_l = L21**2 + L22**2
    assert var_l == pytest.approx((dp * (V0 - dv) / (p_abs * S)) ** 2 + 1.0e-10, rel=1e-12)
