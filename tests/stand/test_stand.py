"""The virtual test stand: procedure, truth from Table 1, error budget against Table 2."""

from __future__ import annotations

import numpy as np
import pytest

from uq._cli.main import main
from uq._data.recordings import read_recordings
from uq._data.reference import table1, table2
from uq._io.errors import InputError
from uq._physics.mechanisms import MECHANISMS, casing_shape, parse_effects
from uq._stand.simulator import (
    Layout,
    N50Spring,
    TraditionalSpring,
    noise_sd,
    simulate,
    simulate_recordings,
    true_curves,
)


def test_procedure_of_section_3_4():
    heights, comp = Layout().heights()
    assert heights.size == 37 and comp.sum() == 19
    assert (
        heights[0] == pytest.approx(0.155)
        and heights[18] == pytest.approx(0.065)
        and heights[-1] == pytest.approx(0.155)
    )
    assert np.allclose(np.diff(heights[:19]), -0.005) and np.allclose(np.diff(heights[19:]), 0.005)


def test_n50_truth_is_table1():
    s = N50Spring()
    t = table1()
    u = np.linspace(-0.047, 0.043, 7)
    for i, p in enumerate(t.pressures_bar):
        P = t.force[i][0] + t.force[i][1] * u + t.force[i][2] * u**2 + t.force[i][3] * u**3
        assert np.allclose(s.force_N(0.112 + u, p), P)
    assert s.force_N(np.array(0.112), 10.0) == pytest.approx(28570.0)


def test_traditional_spring_obeys_eq1_and_eq2():
    s = TraditionalSpring()
    x = np.linspace(0.065, 0.155, 91)
    for p in (0.5, 3.0, 9.0):
        feff = s.effective_area_m2(x, p)
        assert np.allclose(s.force_N(x, p), p * 1e5 * feff)
        dLdx = np.gradient(s.piston_m(x, p), x)
        assert np.allclose(-54.82e-4 * dLdx[2:-2], feff[2:-2], rtol=1e-4)


def test_budget_scatter_matches_physics_md_and_table2():
    """s_P of a cubic fit: the budget's 27..146 N; Table 2 exceeds it where the budget leaves things out."""
    predicted = {1: 27, 2: 35, 3: 45, 4: 57, 5: 70, 6: 84, 7: 99, 8: 114, 9: 130, 10: 146}
    ps = tuple(float(p) for p in predicted)
    s_P = {p: [] for p in ps}
    for seed in range(12):
        for t in simulate("n50", seed=seed, layout=Layout(pressures_bar=ps)):
            X = np.vander(t["height_m"] - 0.112, 4, increasing=True)
            beta, *_ = np.linalg.lstsq(X, t["force_N"], rcond=None)
            s_P[t["pressure_bar"]].append(np.sqrt(np.mean((t["force_N"] - X @ beta) ** 2)))
    for p, expect in predicted.items():
        got = np.sqrt(np.mean(np.square(s_P[float(p)])))
        # residual rms of a 4-parameter fit is sd*sqrt(33/37); the budget figures are at x0
        assert got == pytest.approx(expect * np.sqrt(33 / 37), rel=0.12), p
        assert table2()[float(p)][0] >= 0.85 * got


def test_noise_sd_is_the_budget():
    s = N50Spring()
    sd_f, sd_l = noise_sd(s, np.array([0.112]), 10.0)
    assert sd_f[0] == pytest.approx(np.hypot(0.005 * 28570, 1000 * 0.02857), rel=0.01)
    assert 0.5e-3 < sd_l[0] < 2e-3  # V_gas dp / (p_abs S): about 1 mm at 10 bar


def test_piston_noise_of_the_pressure_holding_is_the_same_at_every_height():
    """Eq. 4: the air volume V_air (element + receiver + pipe) keeps its value as the element is
    compressed, so a pressure-holding error dp moves the piston by V_air dp / (p_abs S) at x_min
    as at x_max. With the displacement term off (the only term that depends on the height) the
    budget's piston sd is that and the calipers' at every height, from first principles here."""
    from uq._data.stand_description import PAPER_STAND

    stand = PAPER_STAND.replace(displacement_sd_m=0.0)
    x = np.linspace(0.065, 0.155, 19)
    for p in (0.1, 5.0, 10.0):
        _, sd_l = noise_sd(N50Spring(), x, p, stand=stand)
        boyle = stand.gas_volume_at_xmax_m3 * stand.pressure_sd_bar(p) / (p + stand.p_atm_bar)
        expect = np.hypot(boyle / 54.82e-4, stand.caliper_sd_m)
        np.testing.assert_allclose(sd_l, expect, rtol=1e-12)


def test_effects_follow_the_contract():
    s = TraditionalSpring()
    x = np.array([0.155, 0.112, 0.065])
    comp = np.array([True, True, False])
    step = np.array([0, 9, 30])
    f0, l0 = true_curves(s, {}, x, 4.0, comp, step)
    f, _ = true_curves(s, {"force_offset": 56.3}, x, 4.0, comp, step)
    assert np.allclose(f - f0, 56.3)
    f, _ = true_curves(s, {"hysteresis": 0.02}, x, 4.0, comp, step)
    assert np.allclose(f / f0, [1.02, 1.02, 0.98])
    f, _ = true_curves(s, {"casing_force": 200.0}, x, 4.0, comp, step)
    assert np.allclose(f - f0, 200.0 * casing_shape(x, 0.112)) and (f - f0)[1] == pytest.approx(
        200.0
    )
    f, l = true_curves(s, {"pressure_dependent_area": 0.01}, x, 4.0, comp, step)
    assert np.allclose(f / f0, 1.04)
    ref = s.piston_m(np.array(0.112), 4.0)
    assert np.allclose(l - ref, (l0 - ref) * 1.04)
    _, l = true_curves(s, {"thermal_drift": 2.0}, x, 4.0, comp, step)
    assert np.allclose((l - l0) * 54.82e-4 * 1e6, 2.0 * step)


def test_effect_option_parsing():
    assert parse_effects(["hysteresis=0.01", "force_offset=56.3"]) == {
        "hysteresis": 0.01,
        "force_offset": 56.3,
    }
    # the contract's five keep their names; more may be added
    assert {
        "pressure_dependent_area",
        "casing_force",
        "hysteresis",
        "force_offset",
        "thermal_drift",
    } <= set(MECHANISMS)
    for bad in (
        ["hysteresis"],
        ["magic=1"],
        ["hysteresis=x"],
        ["hysteresis=1,2"],
        ["force_offset=1", "force_offset=2"],
    ):
        with pytest.raises(InputError):
            parse_effects(bad)


def test_simulate_is_byte_reproducible_and_other_layouts(tmp_path):
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    args = [
        "simulate",
        "--pressures",
        "0.5,1.5,2.5",
        "--x-max-mm",
        "150",
        "--x-min-mm",
        "70",
        "--step-mm",
        "2.5",
        "--seed",
        "7",
    ]
    assert main(args + ["--out", str(a)]) == 0 and main(args + ["--out", str(b)]) == 0
    data = [ln for ln in a.read_text().splitlines() if not ln.startswith("#")]
    assert data == [ln for ln in b.read_text().splitlines() if not ln.startswith("#")]
    first = a.read_bytes()
    assert (
        main(args + ["--out", str(a)]) == 0 and a.read_bytes() == first
    )  # same command: same bytes
    rec = read_recordings(a)
    assert [t.pressure_bar for t in rec.tests] == [0.5, 1.5, 2.5] and rec.tests[0].n_points == 65
    assert (
        main(["simulate", "--out", str(tmp_path / "c.csv"), "--pressures", "12"]) == 2
    )  # outside Table 1


def test_bundled_data_regenerates_byte_for_byte(tmp_path):
    from pathlib import Path

    bundled = Path(__file__).resolve().parents[2] / "data" / "n50" / "recordings.csv"
    cmd = next(ln for ln in bundled.read_text().splitlines() if ln.startswith("# Regenerate: uq "))
    argv = cmd.removeprefix("# Regenerate: uq ").split()
    out = tmp_path / "again.csv"
    argv[argv.index("--out") + 1] = str(out)
    assert main(argv) == 0
    assert (
        out.read_text().splitlines()[5:] == bundled.read_text().splitlines()[5:]
    )  # the command line differs in --out only


def test_pressure_error_obeys_boyle_force_up_piston_short():
    """A reading taken at p + dp: the force rises by dp F_eff, and by Boyle's law
    (p_abs V = const at the reading) the gas occupies less room, so the piston stands *short*
    of its isobaric position. Checked against the gas law, not against the stand's own formula:
    with every other noise term off, (p_abs + dp) (V_air + S dL) must equal p_abs V_air, where
    V_air, all the air of element, receiver and pipe, is the same at every height (eq. 4: the
    gas/water boundary moves inside the receiver as the element is compressed)."""
    from uq._data.stand_description import PAPER_STAND

    stand = PAPER_STAND.replace(load_cell_rel_sd=0.0, displacement_sd_m=0.0, caliper_sd_m=0.0)
    p = 6.0
    layout = Layout(pressures_bar=(p,))
    (test,) = simulate("n50", seed=3, layout=layout, stand=stand)
    spring = N50Spring()
    x = test["height_m"]
    dp_pa = (test["force_N"] - spring.force_N(x, p)) / spring.effective_area_m2(x, p)
    dL = test["piston_m"] - spring.piston_m(x, p)
    assert np.std(dp_pa) > 0.5 * 0.01e5  # the pressure error is there
    S = 54.82e-4
    v_air = stand.gas_volume_at_xmax_m3
    p_abs = (p + stand.p_atm_bar) * 1e5
    boyle = (p_abs + dp_pa) * (v_air + S * dL) / (p_abs * v_air) - 1.0
    assert np.max(np.abs(boyle)) < 1e-4  # second order in dp / p_abs (first order would be ~3e-3)
    assert np.corrcoef(dp_pa, dL)[0, 1] < -0.9  # force and piston errors anti-correlated


def test_reading_errors_keep_their_sd_in_every_form():
    """Gaussian by default (the very draws of rng.normal, so the bundled data stay byte-identical);
    Student t scaled to the same sd, with the t's heavier tails (excess kurtosis 6 / (df - 4));
    AR(1) with the requested lag-one correlation and the same sd. 200 000 draws: tolerances are
    several standard errors wide (fixed seed)."""
    from scipy import stats

    from uq._stand.simulator import ar1, reading_errors

    n = 200_000
    a = reading_errors(np.random.default_rng(1), 0.5, n)
    assert np.array_equal(a, np.random.default_rng(1).normal(0.0, 0.5, n))
    t = reading_errors(np.random.default_rng(2), 0.5, n, df=7.0)
    assert abs(np.std(t) / 0.5 - 1.0) < 0.02
    assert abs(stats.kurtosis(t) - 6.0 / 3.0) < 0.5  # a Gaussian gives 0 +- 0.01
    r = ar1(np.random.default_rng(3).normal(0.0, 2.0, n), 0.6)
    assert abs(np.std(r) / 2.0 - 1.0) < 0.02
    assert abs(np.corrcoef(r[:-1], r[1:])[0, 1] - 0.6) < 0.01
    assert ar1(a, 0.0) is a


def test_stand_of_another_noise_form(tmp_path):
    """A stand whose errors are heavy-tailed and whose pressure errors are correlated in recording
    order: the force errors from the pressure holding (the only term left on) follow an AR(1) in
    the step order; the file says which fields differ; impossible values are one-line errors."""
    from uq._data.stand_description import PAPER_STAND, read_stand

    stand = PAPER_STAND.replace(
        load_cell_rel_sd=0.0, displacement_sd_m=0.0, caliper_sd_m=0.0, pressure_error_corr=0.8
    )
    spring = N50Spring()
    lag1 = []
    for seed in range(20):
        (test,) = simulate("n50", seed=seed, layout=Layout(pressures_bar=(6.0,)), stand=stand)
        dp = (test["force_N"] - spring.force_N(test["height_m"], 6.0)) / spring.effective_area_m2(
            test["height_m"], 6.0
        )
        lag1.append(np.corrcoef(dp[:-1], dp[1:])[0, 1])
    assert (
        0.6 < np.mean(lag1) < 0.85
    )  # 37 readings per test: the estimate is biased low by about 0.1
    assert (
        stand.noise_form_fields() == ["pressure_error_corr"]
        and PAPER_STAND.noise_form_fields() == []
    )
    rec = simulate_recordings(
        "n50", seed=1, layout=Layout(pressures_bar=(1.0,)), stand=PAPER_STAND.replace(error_df=5.0)
    )
    assert "except error_df = 5" in rec.comments[2]
    for text, what in (
        ("error_df = 1.5", "error_df must be 0"),
        ("pressure_error_corr = 1.0", "pressure_error_corr"),
        ("error_df = -3", "non-negative"),
    ):
        f = tmp_path / "s.toml"
        f.write_text(text + "\n")
        with pytest.raises(InputError, match=what) as exc:
            read_stand(f)
        assert str(f) in str(exc.value) and "\n" not in str(exc.value)


@pytest.mark.parametrize("name", ["n50-traditional", "n50-thermo", "n50-kink"])
def test_a_spring_refuses_the_pressure_outside_its_range_by_name(name):
    """A spring defined beyond Table 1's pressures refuses, in one line, the first pressure outside
    its range (not the first it is given), a NaN as well."""
    from uq._stand.simulator import SPRINGS

    spring = SPRINGS[name]()
    lo, hi = spring.pressure_range_bar
    x = 0.11
    assert np.all(np.isfinite(spring.effective_area_m2(x, np.array([lo, hi]))))  # the ends are in
    with pytest.raises(InputError, match=f"^pressures_bar: {hi + 1:g} bar is outside "):
        spring.effective_area_m2(x, np.array([1.0, hi + 1, 2.0]))
    with pytest.raises(InputError, match="^pressures_bar: nan bar is outside "):
        spring.effective_area_m2(x, float("nan"))
