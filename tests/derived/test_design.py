"""Sealed-spring design (uq/_derived/design.py): against the virtual stand's truth for a model that
*is* the truth, the grid's discretisation against closed forms, the volume assumption's effect,
refusals, and end to end on a fitted surface model of a simulated n50-thermo campaign."""

from __future__ import annotations

import numpy as np
import pytest
from model_doubles import ForceOnlyDouble, ModelDouble

from uq._derived.design import (
    DesignGrid,
    SealedDesign,
    design_document,
    design_point,
    frequency_chart,
    isobaric_table,
    sealed_curve,
    sealed_curves,
    sealed_draws,
    sealed_paths,
)
from uq._io.errors import InputError
from uq._stand.sealed_test import sealed_truth
from uq._stand.simulator import ThermoSpring

BAR = 1e5


class SpringModel(ModelDouble):
    """A design model whose every draw is the stand's spring itself (S identical draws)."""

    label = "the stand's spring"

    def __init__(self, spring, n_draws=3, own_dvdp=False, p_range=(0.5, 10.0)):
        self.s, self.S = spring, n_draws
        self.height_range_m, self.pressure_range_bar = (0.065, 0.155), p_range
        self.has_dvdp = own_dvdp
        if own_dvdp:
            self.volume_pressure_draws = lambda x, p: self._draws(
                self.s.compliance_m3_per_pa(np.asarray(x, float)) + 0 * np.asarray(p, float)
            )

    def _draws(self, a):
        return np.broadcast_to(a, (self.S, *np.shape(a))).copy()

    def force_draws(self, x, p):
        return self._draws(self.s.force_N(np.asarray(x, float), np.asarray(p, float)))

    def volume_area_draws(self, x, p):
        return self._draws(self.s.volume_area_m2(np.asarray(x, float), np.asarray(p, float)))


def _truth(spring, xs, **kw):
    return sealed_truth("n50-thermo", np.asarray(xs, float), spring=spring, **kw)


@pytest.mark.parametrize(
    "x_c, p_c, n, v_r_l", [(0.112, 5.0, 1.0, 0.0), (0.100, 3.0, 1.4, 1.5), (0.130, 7.0, 1.2, 0.5)]
)
def test_design_of_the_true_model_is_the_stands_truth(x_c, p_c, n, v_r_l):
    """A model equal to the stand's spring (P quadratic and V linear in p_u, both cubic in x: the
    grid's splines are exact) gives the stand's sealed truth: load to 1e-9, rate to 1e-6 (the
    truth's finite-difference rate), frequency to 1e-6, the sealed curve at every height in range.
    The stand's spring has C(x0) = 0, so at x_c != x0 its volume changes with pressure: the user
    gives that (dvdp_l_per_bar), as the contract's option allows."""
    s = ThermoSpring()
    tr = _truth(s, [x_c], charge_bar=p_c, polytropic=n, reservoir_m3=v_r_l / 1e3, height_c_m=x_c)
    d = SealedDesign(
        x_c,
        p_c,
        tr.volume_c_m3 * 1e3,
        polytropic=n,
        reservoir_l=v_r_l,
        dvdp_l_per_bar=tr.dvdp_c_m3_per_pa * 1e3 * BAR,
        dvdp_sd_l_per_bar=0.0,  # the true value, exactly (at x0 it is 0: no prior width)
    )
    out = design_point(SpringModel(s), d)
    assert out["load_N"]["mean"] == pytest.approx(tr.force_N[0], rel=1e-9)
    assert out["rate_N_per_m"]["mean"] == pytest.approx(tr.rate_N_per_m[0], rel=1e-6)
    assert out["natural_frequency_Hz"]["mean"] == pytest.approx(
        tr.natural_frequency_Hz[0], rel=1e-6
    )
    assert out["rate_N_per_m"]["sd"] == 0.0  # identical draws, no volume uncertainty
    curve = sealed_curve(SpringModel(s), d)
    tc = _truth(
        s, curve["height_m"], charge_bar=p_c, polytropic=n, reservoir_m3=v_r_l / 1e3, height_c_m=x_c
    )
    assert np.allclose(curve["pressure_bar"]["mean"], tc.pressure_bar, rtol=1e-9)
    assert np.allclose(curve["load_N"]["mean"], tc.force_N, rtol=1e-9)
    assert np.allclose(curve["rate_N_per_m"]["mean"], tc.rate_N_per_m, rtol=1e-6)
    # the curve stops where the sealed pressure leaves the tested range, and says so
    assert np.all(np.diff(curve["pressure_bar"]["mean"]) < 0)
    if curve["omitted_height_m"].size:
        assert "does not extrapolate" in curve["omitted_reason"]


def test_volume_assumption_at_the_design_height_and_its_effect():
    """A spring whose volume at x0 grows with pressure (C(x0) = 40 cm^3/bar): the contract's default
    (dV/dp_u = 0 there) misses the casing term and overstates the rate; giving the value, or taking
    the model's own, recovers the truth. The statement says which was used."""
    s = ThermoSpring(compliance_at_x0_m3_per_pa=40e-6 / BAR)
    tr = _truth(s, [0.112], charge_bar=6.0, polytropic=1.4)
    base = dict(height_m=0.112, charge_bar=6.0, volume_l=tr.volume_c_m3 * 1e3, polytropic=1.4)
    assumed = design_point(SpringModel(s), SealedDesign(**base))
    given = design_point(SpringModel(s), SealedDesign(**base, dvdp_l_per_bar=0.04))
    own = design_point(SpringModel(s, own_dvdp=True), SealedDesign(**base, dvdp_l_per_bar="model"))
    k = tr.rate_N_per_m[0]
    assert given["rate_N_per_m"]["mean"] == pytest.approx(k, rel=1e-6)
    assert own["rate_N_per_m"]["mean"] == pytest.approx(k, rel=1e-6)
    assert assumed["rate_N_per_m"]["mean"] > k * 1.01  # the assumption's effect: more than 1 %
    assert "ASSUMED" in assumed["assumptions"][0] and "GIVEN" in given["assumptions"][0]
    assert "own" in own["assumptions"][0]


def test_grid_discretisation_of_a_model_quintic_in_pressure():
    """A model far from the spline's cubics (force and area with a (p/10 bar)^5 term): the design
    height's rate against the closed form -P_x + n p_abs P_p dV/dx / (V_c + V_r), to 1e-5."""
    a, b = 0.027, -0.22

    class Quintic(ModelDouble):
        label, height_range_m, pressure_range_bar = "quintic", (0.065, 0.155), (0.1, 10.0)

        def _g(self, p):
            return 1.0 + 0.3 * (np.asarray(p, float) / 10.0) ** 5

        def force_draws(self, x, p):
            u = np.asarray(x, float) - 0.112
            return np.stack([np.asarray(p, float) * BAR * (a + b * u) * self._g(p)] * 2)

        def volume_area_draws(self, x, p):
            u = np.asarray(x, float) - 0.112
            return np.stack([(a + b * u) * self._g(p) * 1.1] * 2)

    p, n, v_c, v_r = 6.3, 1.3, 3.4e-3, 1e-3
    d = SealedDesign(0.112, p, v_c * 1e3, polytropic=n, reservoir_l=1.0, dvdp_sd_l_per_bar=0.0)
    out = design_point(Quintic(), d)
    g, dg = 1 + 0.3 * (p / 10) ** 5, 0.3 * 5 * (p / 10) ** 4 / (10 * BAR)
    P_x, P_p, A = p * BAR * b * g, a * (g + p * BAR * dg), a * g * 1.1
    want = -P_x + n * (p * BAR + 101325.0) * P_p * A / (v_c + v_r)
    assert out["rate_N_per_m"]["mean"] == pytest.approx(want, rel=1e-5)


def test_volume_uncertainty_and_polytropic_range_are_propagated():
    """V_c +- sd drawn per posterior draw and n uniform in 1..1.4: the rate's spread follows
    k(n, V) of the true spring at the draws' own V_c and n (same seed, same draws)."""
    s = ThermoSpring()
    tr = _truth(s, [0.112], charge_bar=5.0)
    d = SealedDesign(
        0.112,
        5.0,
        tr.volume_c_m3 * 1e3,
        volume_sd_l=0.1,
        polytropic=(1.0, 1.4),
        seed=3,
        dvdp_sd_l_per_bar=0.0,
    )
    m = SpringModel(s, n_draws=400)
    grid = DesignGrid(m, 0.112)
    path, _ = sealed_draws(grid, d, heights_m=[0.112])
    v_c, n = grid.draw_inputs(d)
    assert np.std(v_c) == pytest.approx(1e-4, rel=0.15) and 1.0 <= n.min() < n.max() <= 1.4
    # closed form at x_c with dV/dp = 0: k = -P_x + n p_abs P_p A / V_c (P_p = A: Maxwell)
    P_x = (s.force_N(np.array(0.112 + 1e-6), 5.0) - s.force_N(np.array(0.112 - 1e-6), 5.0)) / 2e-6
    A = s.volume_area_m2(np.array(0.112), 5.0)
    want = -P_x + n * (5 * BAR + 101325.0) * A * A / v_c
    assert np.allclose(path.rate_N_per_m[:, 0], want, rtol=1e-6)
    # several charges in one pass give each charge's own path and curve, to the bit (the element's
    # splines are per column; more than one block of draws: CHUNK_DRAWS = 250 < 400)
    charges = [3.0, None, 7.5]
    many, _ = sealed_paths(grid, d, charges, heights_m=[0.1, 0.112])
    for c, got in zip(charges, many, strict=True):
        one, _ = sealed_draws(grid, d, c, heights_m=[0.1, 0.112])
        assert all(np.array_equal(a, b) for a, b in zip(got, one, strict=True))
    curves = sealed_curves(m, d, [3.0, 7.5], grid)
    for c, got in zip([3.0, 7.5], curves, strict=True):
        want = sealed_curve(m, d, grid, charge_bar=c)
        assert got["omitted_reason"] == want["omitted_reason"]
        assert np.array_equal(got["load_N"]["q95"], want["load_N"]["q95"])
    with pytest.raises(InputError, match="12 bar is outside"):
        sealed_paths(grid, d, [5.0, 12.0])
    # one charge per draw (a design margin's): the first outside the range is named, NaN too
    per_draw = np.full(grid.n_draws, 5.0)
    per_draw[[7, 9]] = np.nan, 12.0
    with pytest.raises(InputError, match="^charge pressure nan bar is outside"):
        sealed_draws(grid, d, per_draw, heights_m=[0.112])
    per_draw[7] = 5.0
    with pytest.raises(InputError, match="^charge pressure 12 bar is outside"):
        sealed_draws(grid, d, per_draw, heights_m=[0.112])
    out = design_point(m, d)
    assert (
        out["polytropic"] == pytest.approx(1.2)
        and out["polytropic_range"] == [1.0, 1.4]
        and "uniform" in out["assumptions"][1]
    )


def test_dvdp_prior_sd_is_the_change_of_the_compliance_over_the_tested_heights():
    """The default sd of dV/dp_u at x_c: the stand's spring has V linear in p_u (dV/dp_u = C(x)),
    so the pressure slope of its area is exactly C'(x) and the sd is the rms of C(x) - C(x_c)
    over the tested heights (to 1e-6: the spline's integral of a cubic C' is exact)."""
    from uq._derived.design import PRIOR_HEIGHTS, dvdp_prior_sd

    s = ThermoSpring()
    m = SpringModel(s)
    for x_c in (0.075, 0.112, 0.140):
        xs = np.linspace(0.065, 0.155, PRIOR_HEIGHTS)
        c = s.compliance_m3_per_pa(xs) - s.compliance_m3_per_pa(np.array(x_c))
        want = float(np.sqrt(np.mean(c**2))) * 1e3 * BAR
        assert dvdp_prior_sd(m, x_c, 5.0) == pytest.approx(want, rel=1e-6)
        assert want > 1e-3  # L/bar: a width that matters, not zero


def test_default_dvdp_is_drawn_with_its_sd_and_covers_a_compliance_of_that_size():
    """By default dV/dp_u at x_c is Normal(0, sd) per draw (sd from the recordings): the rate's
    interval widens, V_c and n keep their draws (a stream of their own), sd 0 is the old exact
    assumption bit for bit, and on a spring whose compliance at x0 is as large as its change over
    the stroke the true rate falls inside the 90 % interval where the exact 0 misses it."""
    from uq._derived.design import dvdp_prior_sd

    base = ThermoSpring()
    sd = dvdp_prior_sd(SpringModel(base), 0.112, 6.0)  # L/bar
    s = ThermoSpring(compliance_at_x0_m3_per_pa=0.8 * sd / 1e3 / BAR)
    tr = _truth(s, [0.112], charge_bar=6.0, polytropic=1.4)
    m = SpringModel(s, n_draws=400)
    args = dict(height_m=0.112, charge_bar=6.0, volume_l=tr.volume_c_m3 * 1e3, polytropic=1.4)
    exact = design_point(m, SealedDesign(**args, dvdp_sd_l_per_bar=0.0))
    prior = design_point(m, SealedDesign(**args))
    again = design_point(m, SealedDesign(**args))
    assert prior == again  # seeded
    assert prior["dvdp_sd_from"] == "recordings" and exact["dvdp_sd_from"] == "given"
    assert prior["dvdp_sd_l_per_bar"] == pytest.approx(dvdp_prior_sd(m, 0.112, 6.0))
    assert "+-" in prior["assumptions"][0] and "drawn per posterior draw" in prior["assumptions"][0]
    k, ke, kp = tr.rate_N_per_m[0], exact["rate_N_per_m"], prior["rate_N_per_m"]
    # the exact 0: no spread (to rounding: the grid's splines are matrix products,
    # uq._physics.knots), and it misses the truth
    assert ke["sd"] < 1e-12 * abs(ke["mean"]) and not ke["q05"] <= k <= ke["q95"]
    assert kp["q05"] <= k <= kp["q95"]  # the prior's width covers it
    f = prior["natural_frequency_Hz"]
    assert f["q95"] - f["q05"] > 0.01 * f["mean"]  # an honest width: more than 1 %
    g = DesignGrid(m, 0.112)
    g0 = DesignGrid(m, 0.112)
    d0 = SealedDesign(**args, dvdp_sd_l_per_bar=0.0)
    assert all(
        np.array_equal(a, b)
        for a, b in zip(g.draw_inputs(SealedDesign(**args)), g0.draw_inputs(d0), strict=True)
    )


def test_frequency_chart_transmissibility_and_document():
    s = ThermoSpring()
    tr = _truth(s, [0.112], charge_bar=5.0)
    d = SealedDesign(
        0.112, 5.0, tr.volume_c_m3 * 1e3, polytropic=1.0, forcing_Hz=6.0, dvdp_sd_l_per_bar=0.0
    )
    m = SpringModel(s)
    chart = frequency_chart(m, d, charges_bar=[1.0, 4.0, 8.0])
    loads = [r["load_N"]["mean"] for r in chart["rows"]]
    assert np.all(np.diff(loads) > 0) and not chart["omitted"]
    # a charge refused (the charges are solved together, then one by one): the others as before
    refused = frequency_chart(m, d, charges_bar=[1.0, 4.0, 12.0, 8.0])
    assert refused["rows"] == chart["rows"] and len(refused["omitted"]) == 1
    assert "12 bar is outside" in refused["omitted"][0]["reason"]
    for r in chart["rows"]:
        t = _truth(s, [0.112], charge_bar=r["charge_bar"])  # same volume assumption: C(x0) = 0
        assert r["natural_frequency_Hz"]["mean"] == pytest.approx(
            t.natural_frequency_Hz[0], rel=1e-6
        )
    doc = design_document(m, d)
    keys = (
        "height_m",
        "charge_bar",
        "volume_l",
        "polytropic",
        "reservoir_l",
        "load_N",
        "rate_N_per_m",
        "natural_frequency_Hz",
    )
    assert list(doc)[: len(keys)] == list(keys)
    f = tr.natural_frequency_Hz[0]
    T = doc["transmissibility"]["transmissibility"]["mean"]
    assert T == pytest.approx(1 / abs(1 - (6.0 / f) ** 2), rel=1e-6)
    assert doc["transmissibility"]["isolation_pct"]["mean"] == pytest.approx(100 * (1 - T))
    from uq._io.files import dumps_json

    assert '"natural_frequency_Hz"' in dumps_json(doc)


def test_refusals_name_the_option():
    from uq._cli.main import PARAM_OPTIONS

    s = ThermoSpring()
    m = SpringModel(s)
    for kw, opt in (
        (dict(height_m=0.2), "--height-mm"),
        (dict(charge_bar=12.0), "--charge-bar"),
        (dict(volume_l=0.0), "--volume-l"),
        (dict(volume_l=None), "filling the element with water"),
        (dict(polytropic=1.5), "--polytropic"),
        (dict(polytropic=(1.3, 1.1)), "--polytropic"),
        (dict(reservoir_l=-1.0), "--reservoir-l"),
        (dict(dvdp_l_per_bar="model"), "--dvdp-l-per-bar"),
        (dict(forcing_Hz=-2.0), "--forcing-hz"),
        (dict(volume_sd_l=2.0), "--volume-sd-l"),
    ):
        args = dict(height_m=0.112, charge_bar=5.0, volume_l=3.4) | kw
        with pytest.raises(InputError) as exc:
            design_point(m, SealedDesign(**args))
        # the library names its parameter, the command line (for_cli) the option
        assert "--" not in str(exc.value) and opt in str(exc.value.for_cli(PARAM_OPTIONS))

    class ForceOnly(ForceOnlyDouble):
        label, height_range_m, pressure_range_bar = "cubics", (0.065, 0.155), (1.0, 10.0)

    with pytest.raises(InputError, match="force-only"):
        design_point(ForceOnly(), SealedDesign(0.112, 5.0, 3.4))
    # a charge so low that the casing's own tension wins near x_max: the load is not positive
    low = SpringModel(s, p_range=(0.05, 10.0))
    with pytest.raises(InputError, match="the load is not positive in 3 of 3 draws"):
        design_point(low, SealedDesign(0.150, 0.05, 4.0))


# ----------------------------------------------------------------------------- fitted, end to end


def _coverage_script():
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "scripts" / "sealed_coverage.py"
    spec = importlib.util.spec_from_file_location("sealed_coverage", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_design_on_a_fitted_surface_of_a_simulated_campaign():
    """n50-thermo recorded at 5 pressures every 10 mm, the surface model fitted with 200 sampler
    steps (the script's tiny settings): the design answers are near the stand's truth (loose: load
    1 %, rate 3 %, frequency 2 %, sealed force 2 % along the curve) with informative intervals."""
    from uq._models.surface_likelihood import fit_surface
    from uq._stand.simulator import simulate_recordings

    cfg = _coverage_script().TINY
    rec = simulate_recordings("n50-thermo", seed=11, layout=cfg["layout"])
    fit = fit_surface(
        rec, cfg["orders"], seed=11, settings=cfg["settings"], max_draws=cfg["max_draws"]
    )
    model = fit.on_draws(cfg["max_draws"])
    s = ThermoSpring()
    tr = _truth(s, [0.112], charge_bar=5.0)
    # the truth's n and its exact dV/dp_u at x0 (0): the fit's own propagation, nothing else
    d = SealedDesign(
        0.112, 5.0, tr.volume_c_m3 * 1e3, polytropic=1.0, forcing_Hz=4.0, dvdp_sd_l_per_bar=0.0
    )
    doc = design_document(model, d)
    for key, true, tol in (
        ("load_N", tr.force_N[0], 0.01),
        ("rate_N_per_m", tr.rate_N_per_m[0], 0.03),
        ("natural_frequency_Hz", tr.natural_frequency_Hz[0], 0.02),
    ):
        est = doc[key]
        assert est["mean"] == pytest.approx(true, rel=tol), key
        assert 0 < est["q95"] - est["q05"] < 0.05 * true, key
    curve = doc["sealed_curve"]
    assert curve["height_m"].size > 20 and doc["frequency_chart"]["rows"]
    tc = _truth(s, curve["height_m"], charge_bar=5.0)
    assert np.allclose(curve["load_N"]["mean"], tc.force_N, rtol=0.02)


def test_coverage_script_runs_with_tiny_settings(tmp_path):
    """scripts/sealed_coverage.py end to end (one replication, tiny settings): writes coverage.json
    with the proof's counts, acceptance regions and timings."""
    import json

    mod = _coverage_script()
    assert mod.main(["--reps", "1", "--tiny", "--out", str(tmp_path)]) in (0, 1)
    res = json.loads((tmp_path / "coverage.json").read_text())
    assert res["replications"] == 1 and res["spring"] == "n50-thermo"
    assert set(res["counts"]) == {sc[0] for sc in mod.SCENARIOS}
    for c in res["counts"].values():
        assert c["evaluable"] == 1 and set(c["covered"]) == set(mod.QUANTITIES)
    assert 0.3 < res["reading_z_rms"] < 3.0


@pytest.mark.slow  # about 2 min on 2 busy cores
def test_sealed_bands_cover_the_truth_over_seeded_replications():
    """12 replications with the tiny settings: every count of covered replications (3 scenarios x 6
    quantities) within its exact binomial region, false failure < 1e-3 overall."""
    res = _coverage_script().run(12, first_seed=700, tiny=True)
    assert res["passed"], res["counts"]


def test_docs_example_runs():
    """docs/design.md's example, as written (the numbers in its comment are this run's)."""
    import re
    from pathlib import Path

    text = (Path(__file__).resolve().parents[2] / "docs" / "design.md").read_text()
    (code,) = re.findall(r"```python\n(.*?)```", text, flags=re.S)
    scope: dict = {}
    exec(compile(code, "docs/design.md", "exec"), scope)
    f = scope["doc"]["natural_frequency_Hz"]
    # the page's comment shows these to three decimals; the sampler's Monte Carlo moves the last
    # one, and the interval's ends (n uniform in 1.3..1.4 and dV/dp_u drawn, the defaults) more
    assert abs(float(f["mean"]) - 2.435) < 0.005
    assert abs(float(f["q05"]) - 2.363) < 0.01 and abs(float(f["q95"]) - 2.515) < 0.01
    assert f["q05"] < 2.445 < f["q95"]  # the stand's truth at the manufacturers' n = 1.38


def test_isobaric_volume_increment_is_the_closed_form_at_every_table_height():
    """dV/dx = a (1 + 2 u) per draw: the table's volume increment from 112 mm is a (u + u^2) at
    every height, mean and sd to 1e-12 (the table's heights, every 10 mm, and the integration grid's
    every 1 mm once met as knots 1e-17 m apart, and the spline's integral lost five digits)."""
    rng = np.random.default_rng(0)

    class Quadratic(ModelDouble):
        label, height_range_m, pressure_range_bar = "quadratic", (0.065, 0.155), (1.0, 10.0)
        a = 0.025 * (1 + 0.01 * rng.standard_normal(300))

        def _b(self, values, x):
            return self.a[:, None] * np.broadcast_to(values, np.shape(x))[None]

        def force_draws(self, x, p):
            return self._b(np.asarray(p, float) * BAR, x)

        def volume_area_draws(self, x, p):
            return self._b(1 + 2 * (np.asarray(x, float) - 0.112), x)

    xs = np.unique(np.round(np.concatenate([[0.065, 0.155, 0.112], np.arange(7, 16) / 100]), 6))
    m = Quadratic()
    for r in isobaric_table(m, [5.0], xs, 0.112):
        u = r["height_m"] - 0.112
        exact = m.a * (u + u**2) * 1e3
        got = r["volume_increment_l"]
        assert got["mean"] == pytest.approx(exact.mean(), rel=1e-12, abs=1e-15)
        assert got["sd"] == pytest.approx(exact.std(ddof=1), rel=1e-12, abs=1e-15)


def test_table_estimates_are_each_cells_estimate_to_the_bit():
    """The isobaric table summarises a pressure's heights in one call per quantity; every cell is
    ``estimate`` of that (pressure, height)'s draws, exactly (draws that differ, 50 of them)."""
    from uq._inference.summary import estimate

    wobble = np.random.default_rng(5).standard_normal((50, 3))

    class Wobbly(SpringModel):
        def _draws(self, a):
            a = np.asarray(a, float)[None]
            w0, w1, w2 = (w.reshape(-1, *[1] * (a.ndim - 1)) for w in wobble.T)
            return a * (1 + 0.01 * w0) + 30.0 * w1 + 5.0 * w2 * np.sqrt(np.abs(a))

    m = Wobbly(ThermoSpring(), n_draws=50)
    rows = isobaric_table(m, [1.0, 4.5], np.array([0.07, 0.1, 0.112, 0.15]), 0.112)
    assert len(rows) == 8
    for row in rows:
        load = m.force_draws(np.array([row["height_m"]]), np.array([row["pressure_bar"]]))[:, 0]
        area = m.volume_area_draws(np.array([row["height_m"]]), np.array([row["pressure_bar"]]))
        for key, draws in (
            ("load_N", load),
            ("feff_m2", load / (row["pressure_bar"] * BAR)),
            ("volume_area_m2", area[:, 0]),
        ):
            want = estimate(draws)
            assert all(row[key][k] == want[k] for k in want), key
