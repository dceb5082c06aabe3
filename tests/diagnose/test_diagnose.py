"""uq diagnose: quiet on clean recordings, names a concealed mechanism with its magnitude.

Fast subset of scripts/diagnose_proof.py; the full suite (all mechanisms, two magnitudes,
two layouts, several seeds) is marked slow.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from uq._data.recordings import PressureTest, Recordings
from uq._stand.simulator import Layout, recordings_from_tests, simulate

ALT = Layout(pressures_bar=(0.5, 2.5, 4.5, 6.5), x_max_m=0.150, x_min_m=0.070, step_m=0.0025)
SMALL = Layout(pressures_bar=(1.0, 3.0, 5.0, 7.0, 9.0))


def _rec(effects, seed=7, layout=Layout(), x0=0.112, area=54.82e-4):
    tests = simulate(
        "n50-traditional", seed=seed, effects=effects, layout=layout, piston_area_m2=area
    )
    return recordings_from_tests(tests, "test", x0_m=x0, piston_area_m2=area)


def _consistent(mag: dict, truth: float) -> bool:
    """The truth within 3.29 posterior sd of the mean: a single campaign's check with a false-failure
    rate of 1e-3 (a 90 % interval misses 1 time in 10 by design; whether the 90 % intervals are 90 %
    intervals is the proof's question, checked below on its committed summary)."""
    return abs(mag["mean"] - truth) <= 3.29 * mag["sd"]


def _run(rec, **kw):
    from uq._diagnose.engine import diagnose
    from uq._inference.sampler import Settings

    return diagnose(
        rec, seed=1, settings=Settings(min_steps=200, chunk=100, tau_multiple=30.0), **kw
    ).to_json()


@pytest.mark.slow  # fast: test_other_stand_noise_names_no_mechanism (a clean campaign)
def test_clean_control_stays_quiet():
    res = _run(_rec({}, layout=SMALL))
    assert res["mismatch_detected"] is False
    assert res["mechanisms"] == []
    assert res["final"]["elpd_loo"] == res["baseline"]["elpd_loo"]


# both slow (a whole diagnosis each, about a minute on 2 loaded cores); fast: a mechanism named
# with its magnitude by test_volume_excess_is_named_with_its_magnitude and the catalogue test,
# thermal_drift named by test_mechanism_is_provisional_while_noise_check_fails, hysteresis by
# test_cli_json_and_report; every mechanism's interval coverage by test_proof_results_committed
@pytest.mark.slow
@pytest.mark.parametrize("name,value", [("hysteresis", 0.02), ("thermal_drift", 2.0)])
def test_visible_mechanism_is_named_with_its_magnitude(name, value):
    res = _run(_rec({name: value}, layout=SMALL))
    assert res["mismatch_detected"] is True
    assert [m["name"] for m in res["mechanisms"]] == [name]
    mag = res["mechanisms"][0]["magnitude"]
    assert _consistent(mag, value), mag
    assert res["final"]["elpd_loo"] > res["baseline"]["elpd_loo"] + 20
    assert set(res) >= {"mismatch_detected", "baseline", "where", "mechanisms", "final"}
    assert {"by_pressure", "by_height", "by_branch", "by_recording_order"} <= set(
        res["where"]["force"]
    )


@pytest.mark.slow  # fast: the other diagnose tests name the mechanism a campaign carries
def test_offset_preferred_over_casing_force_on_other_stand():
    """Robustness: another layout, x0 and piston area; the simpler mechanism wins."""
    res = _run(_rec({"force_offset": 56.3}, layout=ALT, x0=0.100, area=40e-4), max_mechanisms=2)
    assert [m["name"] for m in res["mechanisms"]][:1] == ["force_offset"]
    mag = res["mechanisms"][0]["magnitude"]
    assert _consistent(mag, 56.3), mag


@pytest.mark.slow
@pytest.mark.parametrize(
    "name,value",
    [("pressure_dependent_area", 0.01), ("casing_force", 200.0), ("force_offset", 56.3)],
)
def test_other_mechanisms_paper_layout(name, value):
    res = _run(_rec({name: value}))
    assert [m["name"] for m in res["mechanisms"]] == [name]
    mag = res["mechanisms"][0]["magnitude"]
    assert _consistent(mag, value), mag


def test_proof_results_committed():
    """The committed proof suite shows no false alarms and names visible mechanisms."""
    from pathlib import Path

    path = Path(__file__).resolve().parents[2] / "reports" / "diagnose-proof" / "summary.json"
    if not path.exists():
        pytest.skip("reports/diagnose-proof not generated yet")
    s = json.loads(path.read_text())
    fa = s["false_alarm_rate_clean"]
    assert fa["mechanism_named"] <= max(1, fa["runs"] // 10)
    for k, v in s["detection"].items():
        if "|visible|" in k:
            assert v["named"] == v["runs"], k
    # the 90 % intervals of the named true mechanisms: a binomial acceptance region (false failure
    # < 1e-3; approximate, as the campaigns of one seed share their stand noise)
    from scipy import stats

    cov = s["coverage_90_overall"]
    n = cov["named_true"]
    assert (
        stats.binom.ppf(5e-4, n, 0.9) <= cov["true_in_90"] <= stats.binom.ppf(1 - 5e-4, n, 0.9)
    ), cov


@pytest.mark.parametrize(
    "argv,needle",
    [
        (["--gain-se", "0"], "--gain-se"),
        (["--max-mechanisms", "9"], "--max-mechanisms"),
        (["--walkers", "3"], "--walkers"),
    ],
)
def test_bad_options_exit_2(tmp_path, capsys, argv, needle):
    from uq._cli.main import main
    from uq._data.recordings import write_recordings_csv

    f = tmp_path / "r.csv"
    f.write_text(write_recordings_csv(simulate("n50-traditional", seed=1, layout=SMALL)))
    try:  # a value argparse rejects exits 2 itself; one rejected later returns 2
        status = main(["diagnose", str(f), *argv])
    except SystemExit as exc:
        status = exc.code
    assert status == 2
    assert needle in capsys.readouterr().err


def test_cli_json_and_report(tmp_path, capsys):
    from uq._cli.main import main
    from uq._data.recordings import write_recordings_csv

    f = tmp_path / "r.csv"
    f.write_text(
        write_recordings_csv(
            simulate("n50-traditional", seed=2, layout=SMALL, effects={"hysteresis": 0.02})
        )
    )
    assert (
        main(
            [
                "diagnose",
                str(f),
                "--json",
                str(tmp_path / "d.json"),
                "--report",
                str(tmp_path / "rep"),
            ]
        )
        == 0
    )
    out = capsys.readouterr().out
    assert "hysteresis" in out
    res = json.loads((tmp_path / "d.json").read_text())
    assert res["mechanisms"][0]["name"] == "hysteresis"
    assert (tmp_path / "rep" / "diagnose.html").exists()
    assert (tmp_path / "rep" / "diagnose_residuals.png").exists()


@pytest.mark.slow  # fast: uq fit's byte-identical JSON for a seed (test_cubic)
def test_same_seed_gives_byte_identical_json(tmp_path):
    from uq._cli.main import main
    from uq._data.recordings import write_recordings_csv

    csv = tmp_path / "r.csv"
    csv.write_text(
        write_recordings_csv(
            simulate("n50-traditional", seed=3, effects={"force_offset": 56.3}, layout=SMALL)
        )
    )
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    for out in (a, b):
        assert (
            main(
                [
                    "diagnose",
                    str(csv),
                    "--json",
                    str(out),
                    "--seed",
                    "5",
                    "--max-steps",
                    "400",
                    "--allow-unconverged",
                ]
            )
            == 0
        )
    assert a.read_bytes() == b.read_bytes()


# ----------------------------------------------------------------------------- issue 9


def _rec_stand(effects, stand, seed=7, layout=SMALL):
    tests = simulate("n50-traditional", seed=seed, effects=effects, layout=layout, stand=stand)
    return recordings_from_tests(tests, "test")


def test_pressure_error_cancels_in_the_decorrelated_force():
    """z = P + cL: the pressure-holding error raises P by dp F_eff and leaves L short by
    V_gas dp / (p_abs S), so c L takes dp F_eff off again. With the wrong sign (P - cL) the
    pressure term doubles instead. A stand with only (enlarged) pressure-holding noise."""
    from uq._data.stand_description import PAPER_STAND
    from uq._models import diagnose as M
    from uq._stand.simulator import TraditionalSpring, true_curves

    stand = PAPER_STAND.replace(
        pressure_holding_bar=0.05, load_cell_rel_sd=0.0, displacement_sd_m=0.0, caliper_sd_m=0.0
    )
    rec = _rec_stand({}, stand)
    d, _ = M.prepare(rec, stand)
    spring = TraditionalSpring()
    F_true, L_true = map(
        np.concatenate,
        zip(
            *(
                true_curves(spring, {}, t.height_m, t.pressure_bar, t.compression, t.step)
                for t in rec.tests
            ),
            strict=True,
        ),
    )
    y_noisy = np.asarray(M.decorrelated_force(d))
    y_true = np.asarray(M.decorrelated_force(d._replace(force=F_true, piston=L_true)))
    scatter_z = np.std(y_noisy - y_true)
    scatter_P = np.std(np.asarray(d.force) - F_true)
    assert scatter_P > 100.0  # the pressure term is there to cancel
    assert scatter_z < 0.1 * scatter_P


def test_volume_excess_is_named_with_its_magnitude():
    """The paper's finding concealed: the volume-derived area 12 % above the force-derived one."""
    from uq._data.stand_description import PAPER_STAND

    res = _run(_rec_stand({"volume_excess": 0.12}, PAPER_STAND))
    assert [m["name"] for m in res["mechanisms"]] == ["volume_excess"]
    m = res["mechanisms"][0]
    # one seed: a 90 % interval misses 1 time in 10 by design, so ask for the truth within 4 sd;
    # interval coverage over many seeds is the proof suite's job (scripts/diagnose_proof.py)
    assert abs(m["magnitude"]["mean"] - 0.12) <= 4.0 * m["magnitude"]["sd"]
    assert m["status"] == "found" and res["provisional"] is False
    assert res["final"]["noise_check"]["passes"] is True


def test_other_stand_noise_names_no_mechanism():
    """Recordings from a stand noisier than the model assumes (load cell 0.8 %, pressure held
    within 0.03 bar): the learned noise scales absorb it; no mechanism is invented."""
    from uq._data.stand_description import PAPER_STAND

    other = PAPER_STAND.replace(load_cell_rel_sd=0.008, pressure_holding_bar=0.03)
    res = _run(_rec_stand({}, other, seed=11))
    assert res["mechanisms"] == []
    assert res["final"]["model"] == ["traditional"]


def test_mechanism_is_provisional_while_noise_check_fails():
    """A visible drift in a campaign whose force scatter is 10x the budget (an unmodelled noise
    source): the drift is named, but only provisionally, and the report says what is left."""
    from uq._data.stand_description import PAPER_STAND
    from uq._diagnose.engine import summary_text

    noisy = PAPER_STAND.replace(load_cell_rel_sd=0.05)
    res = _run(_rec_stand({"thermal_drift": 2.0}, noisy))
    assert "thermal_drift" in [m["name"] for m in res["mechanisms"]]
    assert res["final"]["noise_check"]["passes"] is False
    assert "force" in res["final"]["noise_check"]["failing"]
    assert res["provisional"] is True
    assert all(m["status"] == "provisional" for m in res["mechanisms"])
    assert "PROVISIONAL" in summary_text(res) and "found thermal_drift" not in summary_text(res)


def test_pareto_k_reported_and_bad_psis_comparison_replaced_by_kfold():
    from dataclasses import replace

    from uq._data.stand_description import PAPER_STAND
    from uq._diagnose import engine as D
    from uq._inference.loo import MAX_REFITS, reloo
    from uq._models import diagnose as M

    d, _ = M.prepare(_rec_stand({"force_offset": 56.3}, PAPER_STAND), PAPER_STAND)
    old, new = D.Fit((), 3, d, 1), D.Fit(("force_offset",), 3, d, 2)
    scoring = D.Scoring(d, 3, seed=3, n_folds=5)
    good = D._compare(new, old, scoring)
    assert good["method"] == "psis-loo" and good["pareto_k"]["n_terms"] == 2 * d.force.size
    # exact K-fold agrees with PSIS-LOO where PSIS is reliable (a check of the refits)
    for f in (old, new):
        assert abs(scoring.kfold(f.names).elpd - f.elpd) < 10.0
    k = new.loo.pareto_k.copy()
    k[0] = 0.9  # one unreliable term: PSIS-LOO must not be used for it
    new.loo = replace(new.loo, pareto_k=k)
    bad = D._compare(new, old, scoring)
    assert bad["pareto_k"]["n_over_0.7"] == 1 and "psis_loo_refused" in bad
    assert bad["method"] == "psis-loo, k > 0.7 terms refitted exactly"
    # the exact refit of a benign term
    assert abs(reloo(new.loo, scoring.refit(new)).loo_i[0] - new.loo.loo_i[0]) < 0.5
    assert bad["delta_elpd"] > 4 * bad["delta_elpd_se"]
    k = k.copy()
    k[: MAX_REFITS + 1] = 0.9  # many unreliable terms: K-fold for both models
    new.loo = replace(new.loo, pareto_k=k)
    many = D._compare(new, old, scoring)
    assert many["method"] == "5-fold cross-validation" and "psis_loo_refused" in many
    assert many["delta_elpd"] > 4 * many["delta_elpd_se"]


@pytest.mark.slow
def test_n50_no_stand_in_offset_and_force_fit_not_worse(n50_recordings):
    from uq._diagnose.engine import diagnose
    from uq._inference.sampler import Settings

    res = diagnose(
        n50_recordings, seed=0, settings=Settings(min_steps=200, chunk=100, tau_multiple=30.0)
    ).to_json()
    names = [m["name"] for m in res["mechanisms"]]
    assert "force_offset" not in names
    assert "volume_excess" in names
    assert res["final"]["rms_N"] <= res["baseline"]["rms_N"]
    for key in ("baseline", "final"):
        assert {"max", "n_over_0.7"} <= set(res[key]["pareto_k"])
    if not res["final"]["noise_check"]["passes"]:
        assert res["provisional"] and res["final"]["left"]


def test_nested_mechanisms_the_larger_goes_first():
    """A casing force (4 parameters) can stand in for a constant offset (1): when both cost little
    to leave out, the casing force is removed first, whichever is cheaper by a few nats."""
    from uq._diagnose.engine import GAIN_MIN, _to_remove

    table = {
        "force_offset": {"delta_elpd": 0.4},
        "casing_force": {"delta_elpd": 1.5},
        "hysteresis": {"delta_elpd": 30.0},
    }
    assert _to_remove(["force_offset", "casing_force", "hysteresis"], table) == "casing_force"
    table["casing_force"]["delta_elpd"] = (
        0.4 + GAIN_MIN + 1.0
    )  # clearly costlier: the cheapest goes
    assert _to_remove(["force_offset", "casing_force"], table) == "force_offset"
    table = {"hysteresis": {"delta_elpd": 2.0}, "thermal_drift": {"delta_elpd": 1.0}}
    assert (
        _to_remove(["hysteresis", "thermal_drift"], table) == "thermal_drift"
    )  # equal size: cheapest


# ----------------------------------------------------------------------------- real data shapes


def _force_only(rec: Recordings) -> Recordings:
    """``rec`` as a stand that measures no volume writes it: no piston column."""
    from dataclasses import replace

    return replace(rec, tests=tuple(replace(t, piston_m=None) for t in rec.tests))


def _catalogue(effects, seed=7, volume_at_bar=5.0):
    """A data sheet: one compression pass at 3..7 bar every 10 mm, no recorded order, the
    element's volume at ``volume_at_bar`` only (the stand's catalogue shape)."""
    from uq._data.stand_description import PAPER_STAND
    from uq._stand.shapes import catalogue

    layout = Layout(pressures_bar=(3.0, 4.0, 5.0, 6.0, 7.0), step_m=0.010)
    tests = catalogue(
        simulate("n50-traditional", seed=seed, effects=effects, layout=layout),
        "n50-traditional",
        effects,
        volume_at_bar=volume_at_bar,
        x_max_m=layout.x_max_m,
        element_volume_at_xmax_m3=PAPER_STAND.element_volume_at_xmax_m3,
        piston_area_m2=54.82e-4,
    )
    return Recordings(
        "catalogue",
        tuple(
            PressureTest(
                t["pressure_bar"],
                t["height_m"],
                t["force_N"],
                None,
                None,
                None,
                np.arange(t["height_m"].size),
                volume_m3=t["volume_m3"],
            )
            for t in tests
        ),
    )


def test_force_only_campaign_names_force_side_mechanism_without_volume_outputs(tmp_path):
    """No piston column (most stands): the casing's own force is still found from the force at
    several pressures; mechanisms only the volume shows are not offered, with the reason, and no
    volume result is reported (none is made up from the empty piston rows), on the page either."""
    from uq._diagnose.engine import diagnose
    from uq._inference.sampler import Settings
    from uq._report.diagnose import write_diagnose_report

    diagnosis = diagnose(
        _force_only(_rec({"casing_force": -60.0}, layout=SMALL)),
        seed=1,
        settings=Settings(min_steps=200, chunk=100, tau_multiple=30.0),
    )
    res = diagnosis.to_json()
    page = write_diagnose_report(diagnosis, tmp_path).read_text()
    assert "No volume results" in page and "volume rms" not in page
    names = [m["name"] for m in res["mechanisms"]]
    assert names == ["casing_force"], names
    assert _consistent(res["mechanisms"][0]["magnitude"], -60.0)
    not_offered = res["selection"]["not_offered"]
    for name in ("volume_excess", "elastic_casing", "thermal_drift"):
        assert "piston or volume readings" in not_offered[name]
    assert res["baseline"]["volume_rms_cm3"] is None and res["final"]["volume_rms_cm3"] is None
    assert "volume" not in res["where"] and "piston" not in res["where"]["noise_scale_vs_budget"]
    assert res["final"]["noise_check"]["piston_scale"] is None
    assert res["final"]["pareto_k"]["n_terms"] == sum(
        t.n_points for t in _rec({}, layout=SMALL).tests
    )
    json.dumps(res, allow_nan=False)


def test_catalogue_table_names_the_growing_area_without_order_mechanisms():
    """A catalogue table (one pass, order unknown, volume printed at 5 bar only) of a spring
    whose area grows 2 %/bar: found with its magnitude; neither hysteresis nor a drift is
    offered; the volume residuals are those of the 5 bar rows only. (A 12 % volume excess in the
    same shape is seen, ratio 1.12 at x0, but with ten volume rows its ELPD gain is 3.5 SE, short
    of the 4 SE asked: a catalogue's single volume column is little evidence.)"""
    res = _run(_catalogue({"pressure_dependent_area": 0.02}))
    assert [m["name"] for m in res["mechanisms"]] == ["pressure_dependent_area"]
    assert _consistent(res["mechanisms"][0]["magnitude"], 0.02)
    for name in ("hysteresis", "thermal_drift"):
        assert "known recording order" in res["selection"]["not_offered"][name]
    volume = res["where"]["volume"]
    assert [g["pressure_bar"] for g in volume["by_pressure"]] == [5.0]
    assert volume["by_branch"] == [] and volume["by_recording_order"] == []
    assert res["final"]["pareto_k"]["n_terms"] == 5 * 10 + 10
    json.dumps(res, allow_nan=False)
