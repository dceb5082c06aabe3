"""Design margins on the sealed spring (uq._derived.design.design_margin, ``uq margin
--max-frequency-hz/--rate-target-N-per-m/--force-limit-N``) against closed forms.

The model is a cylinder whose area differs per posterior draw, A_s: P = p_u A_s, dV/dx = A_s.
Carrying W at x_c needs p_s = W / A_s; closed there with volume V_c (+ V_r) the rate is
k_s = n (p_s + p_atm) A_s^2 / (V_c + V_r) and f_s = sqrt(k_s g / W) / 2 pi, so every probability
the margin states is a count over these closed-form draws. The stroke to a force limit F along the
isothermal sealed curve: (p_F + p_atm)(V_c + V_r - A s) = (p_s + p_atm)(V_c + V_r), p_F = F / A.
"""

from __future__ import annotations

import numpy as np
import pytest
from model_doubles import ForceOnlyDouble, ModelDouble

from uq._derived.design import SealedDesign, design_margin
from uq._io.errors import InputError

BAR, P_ATM, G = 1e5, 101325.0, 9.80665
X_C, W = 0.112, 12000.0


class Cylinders(ModelDouble):
    """S cylinders, one per draw, areas spread like a posterior."""

    label = "cylinders"
    height_range_m = (0.065, 0.155)
    pressure_range_bar = (0.5, 10.0)

    def __init__(self, n_draws=400, seed=0):
        self.A = 0.025 * (1 + 0.01 * np.random.default_rng(seed).standard_normal(n_draws))

    def _b(self, a, shape):
        return np.broadcast_to(a.reshape(-1, *([1] * len(shape))), (a.size, *shape)).copy()

    def force_draws(self, x, p):
        x, p = np.broadcast_arrays(np.asarray(x, float), np.asarray(p, float))
        return self._b(self.A, x.shape) * p * BAR

    def volume_area_draws(self, x, p):
        x, _ = np.broadcast_arrays(np.asarray(x, float), np.asarray(p, float))
        return self._b(self.A, x.shape)


def _closed(model, v_c, n=1.0, v_r=0.0):
    p = W / model.A / BAR
    k = n * (p * BAR + P_ATM) * model.A**2 / (v_c + v_r)
    return p, k, np.sqrt(k * G / W) / (2 * np.pi)


@pytest.mark.parametrize("n, v_r_l", [(1.0, 0.0), (1.4, 0.0), (1.0, 1.5)])
def test_rate_frequency_and_their_probabilities_are_the_closed_forms(n, v_r_l):
    m = Cylinders()
    v_c = 3.0e-3
    p, k, f = _closed(m, v_c, n, v_r_l / 1e3)
    f_max, k_target = float(np.median(f)), float(np.mean(k)) * 1.004
    res = design_margin(
        m,
        X_C,
        W,
        SealedDesign(X_C, 5.0, 3.0, polytropic=n, reservoir_l=v_r_l),
        0.9,
        max_frequency_Hz=f_max,
        rate_target_N_per_m=k_target,
        rate_tolerance_pct=1.0,
    )
    assert res["charge_bar"]["mean"] == pytest.approx(p.mean(), rel=1e-9)
    assert res["rate_N_per_m"]["mean"] == pytest.approx(k.mean(), rel=1e-7)
    assert res["natural_frequency_Hz"]["q95"] == pytest.approx(np.quantile(f, 0.95), rel=1e-7)
    fb = res["frequency_below"]
    assert fb["probability"] == pytest.approx(np.mean(f < f_max), abs=1.5 / f.size)
    assert fb["frequency_for_prob_Hz"] == pytest.approx(np.quantile(f, 0.9), rel=1e-7)
    assert fb["meets_prob"] is False  # half the draws lie above the median
    rw = res["rate_within"]
    assert rw["probability"] == pytest.approx(
        np.mean(np.abs(k / k_target - 1) <= 0.01), abs=1.5 / k.size
    )
    assert res["load_check_N"]["mean"] == pytest.approx(W, rel=1e-9)


def test_stroke_to_a_force_limit_is_the_isothermal_closed_form():
    m = Cylinders()
    v_c, limit = 3.0e-3, 18000.0
    p, _, _ = _closed(m, v_c)
    p_lim = limit / m.A
    s_true = v_c * (1 - (p * BAR + P_ATM) / (p_lim + P_ATM)) / m.A
    res = design_margin(
        m, X_C, W, SealedDesign(X_C, 5.0, 3.0, polytropic=1.0), 0.95, force_limit_N=limit
    )
    st = res["stroke_to_force_limit"]
    assert st["direction"].startswith("compression") and st["prob_reached_in_tested_range"] == 1.0
    # linear between the grid's 2 mm heights: within 0.1 % of the closed form
    assert st["stroke_m"]["mean"] == pytest.approx(s_true.mean(), rel=1e-3)
    assert st["stroke_for_prob_m"] == pytest.approx(np.quantile(s_true, 0.05), rel=1e-3)
    # rebound: a limit below the load is reached as the spring extends
    res = design_margin(
        m, X_C, W, SealedDesign(X_C, 5.0, 3.0, polytropic=1.0), 0.95, force_limit_N=9000.0
    )
    p_lim = 9000.0 / m.A
    s_true = -v_c * (1 - (p * BAR + P_ATM) / (p_lim + P_ATM)) / m.A
    st = res["stroke_to_force_limit"]
    assert st["direction"].startswith("rebound")
    assert st["stroke_m"]["mean"] == pytest.approx(s_true.mean(), rel=1e-3)


def test_a_limit_beyond_the_tested_range_is_said_not_reached():
    res = design_margin(
        Cylinders(),
        X_C,
        W,
        SealedDesign(X_C, 5.0, 3.0, polytropic=1.0),
        0.95,
        force_limit_N=240000.0,
    )
    st = res["stroke_to_force_limit"]
    assert st["prob_reached_in_tested_range"] == 0.0
    assert st["stroke_m"] is None and st["stroke_for_prob_m"] is None


def test_given_dvdp_softens_as_the_gas_law_says():
    """dV/dp_u at x_c enters (S2): k = n p_abs A^2 / (V + n p_abs V_p) for a cylinder."""
    m = Cylinders()
    v_c, vp = 3.0e-3, 0.02e-3 / BAR  # 0.02 L/bar
    p, _, _ = _closed(m, v_c)
    k = (p * BAR + P_ATM) * m.A**2 / (v_c + (p * BAR + P_ATM) * vp)
    res = design_margin(
        m, X_C, W, SealedDesign(X_C, 5.0, 3.0, polytropic=1.0, dvdp_l_per_bar=0.02), 0.95
    )
    assert res["rate_N_per_m"]["mean"] == pytest.approx(k.mean(), rel=1e-6)
    assert "GIVEN" in " ".join(res["assumptions"])


def test_refusals():
    m = Cylinders()
    d = SealedDesign(X_C, 5.0, 3.0, polytropic=1.0)
    from uq._cli.main import PARAM_OPTIONS

    with pytest.raises(InputError, match="max_frequency_Hz") as exc:
        design_margin(m, X_C, W, d, 0.95, max_frequency_Hz=-1.0)
    assert str(exc.value.for_cli(PARAM_OPTIONS)).startswith("option --max-frequency-hz:")
    with pytest.raises(InputError, match="load_N"):
        design_margin(m, X_C, 1e7, d, 0.95)  # not carried within the tested pressures

    class ForceOnly(ForceOnlyDouble):
        label = "force only"
        height_range_m, pressure_range_bar = Cylinders.height_range_m, Cylinders.pressure_range_bar
        force_draws = Cylinders().force_draws

    with pytest.raises(InputError, match="volume-derived area"):
        design_margin(ForceOnly(), X_C, W, d, 0.95)


class Balloons(Cylinders):
    """Areas that grow with pressure, quintic in p_u (the grids interpolate cubics exactly only)."""

    @staticmethod
    def _g(p):
        return 1 + 0.03 * p + 0.002 * p**2 - 0.0003 * p**3 + 1e-5 * p**5

    def force_draws(self, x, p):
        return super().force_draws(x, p) * self._g(np.asarray(p, float))

    def volume_area_draws(self, x, p):
        return super().volume_area_draws(x, p) * self._g(np.asarray(p, float))


def test_the_margins_coarse_grid_agrees_with_the_design_grid():
    """MARGIN_PRESSURES (21) and the neighbourhood of x_c against the full DesignGrid (41 pressures,
    every tested height): rate, frequency and stroke within 1e-4."""
    from uq._derived.design import DesignGrid

    m = Balloons()
    d = SealedDesign(X_C, 5.0, 3.0, polytropic=1.4, dvdp_sd_l_per_bar=0.0)  # the grids alone
    kw = dict(max_frequency_Hz=2.0, force_limit_N=18000.0)
    coarse = design_margin(m, X_C, W, d, 0.95, **kw)
    fine = design_margin(m, X_C, W, d, 0.95, grid=DesignGrid(m, X_C), **kw)
    for key in ("rate_N_per_m", "natural_frequency_Hz"):
        assert coarse[key]["mean"] == pytest.approx(fine[key]["mean"], rel=1e-4), key
    a, b = coarse["stroke_to_force_limit"], fine["stroke_to_force_limit"]
    assert a["stroke_m"]["mean"] == pytest.approx(b["stroke_m"]["mean"], rel=1e-4)
