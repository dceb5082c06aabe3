"""The thermodynamic model: force and volume from one potential (uq/_models/thermo.py).

Checked against the virtual stand's potential spring (``n50-thermo``: G = -p V0 - p^2 C/2 + E,
the Maxwell relation exact, its truth known), by its own identities (P = -dG/dx, dV/dx =
dP/dp_u), and for the piston area it infers through the Maxwell relation when the stand's S is
given wrongly (the paper names an 80 mm bore, 50.27 cm^2, but uses 54.82 cm^2).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

import uq
from uq._stand.simulator import SPRINGS

LAYOUT = uq.Layout(pressures_bar=(1.0, 3.0, 5.0, 7.0, 9.0), step_m=0.01)
ORDERS = uq.ThermoOrders(4, 3)
SETTINGS = uq.Settings(max_steps=4000)
POINTS = ((0.112, 5.0), (0.085, 2.0), (0.140, 8.0))


@pytest.fixture(scope="module")
def thermo_fit():
    rec = uq.simulate("n50-thermo", seed=21, layout=LAYOUT)
    return uq.fit_thermo(rec, ORDERS, seed=21, settings=SETTINGS, max_draws=2000)


def _covered(draws, truth, level=0.999) -> bool:
    lo, hi = np.quantile(draws, [(1 - level) / 2, (1 + level) / 2])
    return bool(lo <= truth <= hi)


def test_identities_of_the_potential(thermo_fit):
    """P = -dG/dx and dV/dx = -d2G/dx dp_u = dP/dp_u (Maxwell) hold draw by draw, by finite
    differences of the model's own draws (to 1e-5 relative)."""
    fit = thermo_fit.on_draws(50)
    for x, p in POINTS:
        h, dp = 1e-5, 1e-4  # m, bar
        G = fit.potential_draws
        dGdx = (G(x + h, p) - G(x - h, p)) / (2 * h)
        np.testing.assert_allclose(fit.force_draws(x, p), -dGdx, rtol=1e-5)
        dPdp = (fit.force_draws(x, p + dp) - fit.force_draws(x, p - dp)) / (2 * dp * 1e5)
        np.testing.assert_allclose(fit.volume_area_draws(x, p), dPdp, rtol=1e-5)
        dV = fit.volume_change_draws(x + h, p) - fit.volume_change_draws(x - h, p)
        np.testing.assert_allclose(fit.volume_area_draws(x, p), dV / (2 * h), rtol=1e-5)


def test_draws_on_a_grid_are_the_draws_point_by_point(thermo_fit):
    """Every quantity evaluated on a (2, 3) grid of heights and pressures gives, draw by draw,
    what it gives at each point alone (volume_area_draws, and so the Maxwell ratio, once
    returned the draws and the points transposed)."""
    fit = thermo_fit.on_draws(50)
    x = np.array([[0.08, 0.10, 0.12], [0.09, 0.11, 0.13]])
    p = np.array([[2.0, 5.0, 8.0], [3.0, 4.0, 6.0]])
    for fn in (
        fit.potential_draws,
        fit.force_draws,
        fit.volume_change_draws,
        fit.feff_draws,
        fit.volume_area_draws,
        fit.volume_pressure_draws,
        fit.maxwell_ratio_draws,
    ):
        grid = fn(x, p)
        alone = [fn(xi, pi) for xi, pi in zip(x.ravel(), p.ravel(), strict=True)]
        assert grid.shape == (50, 2, 3), fn.__name__
        np.testing.assert_allclose(grid, np.stack(alone, axis=-1).reshape(grid.shape), rtol=1e-12)


def test_recovers_the_stands_potential_spring(thermo_fit):
    """On the stand's potential spring the force, the volume-derived area and the Maxwell ratio
    at three points lie inside the 99.9 % intervals, the sampler converged, and the piston area
    the recordings imply covers the S they were made with."""
    fit = thermo_fit
    assert fit.convergence.converged, fit.convergence.warnings
    spring = SPRINGS["n50-thermo"]()
    for x, p in POINTS:
        force = float(spring.force_N(np.array(x), p))
        area = float(spring.volume_area_m2(np.array(x), p))
        assert _covered(fit.force_draws(x, p), force), (x, p)
        assert _covered(fit.volume_area_draws(x, p), area), (x, p)
        assert _covered(fit.maxwell_ratio_draws(x, p), area / (force / (p * 1e5))), (x, p)
    assert _covered(fit.piston_area_draws(), 54.82e-4)
    doc = fit.to_json()
    assert {"implied_piston_area_m2", "at_x0", "noise", "convergence"} <= set(doc)
    assert doc["model"] == "thermodynamic" and repr(fit).startswith(
        "ThermoFit(thermodynamic model (G 4x3)"
    )


def test_a_wrong_piston_area_is_found():
    """Recordings made with S = 54.82 cm^2 read with the paper's nominal 80 mm bore (50.27 cm^2):
    the traditional theory would call the volume excess a casing property; the potential ties
    the volume to the force, and the implied area covers the true 54.82 cm^2 (not 50.27)."""
    rec = uq.simulate("n50-thermo", seed=22, layout=LAYOUT)
    wrong = dataclasses.replace(rec, piston_area_m2=50.27e-4)
    fit = uq.fit_thermo(wrong, ORDERS, seed=22, settings=SETTINGS, max_draws=1000)
    S = fit.piston_area_draws()
    assert _covered(S, 54.82e-4) and not _covered(S, 50.27e-4), np.quantile(S, [0.05, 0.95])


def test_refuses_force_only_and_single_pressure():
    rec = uq.simulate("n50-thermo", seed=23, layout=uq.Layout(pressures_bar=(5.0,), step_m=0.01))
    with pytest.raises(uq.InputError, match="two or more pressures"):
        uq.fit_thermo(rec, ORDERS)


def test_margins_answered_by_the_thermodynamic_model(thermo_fit):
    """``uq margin --model thermodynamic``: the pressure that carries the spring's true force at a
    height between the tested pressures, its force band and stroke, from the potential's draws;
    the truth (the stand's potential spring) inside the 99.9 % interval."""
    from uq._derived.margin import choose, margin

    ans, info = choose(thermo_fit, None, None, forced="thermodynamic")
    assert ans is thermo_fit and info["name"] == "thermodynamic"
    spring = SPRINGS["n50-thermo"]()
    x, p = 0.100, 4.0
    load = float(spring.force_N(np.array(x), p))
    res = margin(ans, x, load, 0.95, pressure_bar=p, tolerance_pct=10.0, model_info=info)
    e = res["pressure_bar_needed"]
    assert e["q05"] - 3 * e["sd"] <= p <= e["q95"] + 3 * e["sd"]
    assert res["model"]["name"] == "thermodynamic" and "usable_stroke" in res
    assert abs(res["force_at_pressure"]["force_N"]["mean"] - load) < 0.01 * load
    area = ans.volume_area_draws(np.array(x), p)
    assert area.shape[0] == ans.n_draws and np.all(area > 0)


def test_a_saved_file_missing_a_block_is_refused_in_one_line(thermo_fit, tmp_path, monkeypatch):
    """A saved thermodynamic model without its potential is refused in one line naming the file
    and the block."""
    from saved_helpers import refusal_without

    message = refusal_without(thermo_fit, tmp_path / "t.nc", monkeypatch, "potential")
    assert "t.nc: incomplete saved model: no block potential " in message
