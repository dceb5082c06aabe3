"""uq diagnose: quiet on clean recordings, names a concealed mechanism with its magnitude.

Fast subset of scripts/diagnose_proof.py; the full suite (all mechanisms, two magnitudes,
two layouts, several seeds) is marked slow.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from uq._recordings import Recordings
from uq._recordings import Test as RecTest
from uq._stand import Layout, simulate

ALT = Layout(pressures_bar=(0.5, 2.5, 4.5, 6.5), x_max_m=0.150, x_min_m=0.070, step_m=0.0025)
SMALL = Layout(pressures_bar=(1.0, 3.0, 5.0, 7.0, 9.0))


def _rec(effects, seed=7, layout=Layout(), x0=0.112, area=54.82e-4):
    tests = simulate("n50-traditional", seed=seed, effects=effects, layout=layout, piston_area_m2=area)
    return Recordings("test", tuple(RecTest(t["pressure_bar"], t["height_m"], t["force_N"], t["piston_m"],
                                         t["compression"], t["step"], np.arange(t["step"].size)) for t in tests),
                      x0_m=x0, piston_area_m2=area)


def _run(rec, **kw):
    from uq._diagnose import diagnose, public
    from uq._sampler import Settings

    return public(diagnose(rec, seed=1, settings=Settings(min_steps=200, chunk=100, tau_multiple=30.0), **kw))


def test_clean_control_stays_quiet():
    res = _run(_rec({}, layout=SMALL))
    assert res["mismatch_detected"] is False
    assert res["mechanisms"] == []
    assert res["final"]["elpd_loo"] == res["baseline"]["elpd_loo"]


@pytest.mark.parametrize("name,value", [pytest.param("hysteresis", 0.02, marks=pytest.mark.slow), ("thermal_drift", 2.0)])
def test_visible_mechanism_is_named_with_its_magnitude(name, value):
    res = _run(_rec({name: value}, layout=SMALL))
    assert res["mismatch_detected"] is True
    assert [m["name"] for m in res["mechanisms"]] == [name]
    mag = res["mechanisms"][0]["magnitude"]
    assert mag["q05"] <= value <= mag["q95"]
    assert res["final"]["elpd_loo"] > res["baseline"]["elpd_loo"] + 20
    assert set(res) >= {"mismatch_detected", "baseline", "where", "mechanisms", "final"}
    assert {"by_pressure", "by_height", "by_branch", "by_recording_order"} <= set(res["where"]["force"])


def test_offset_preferred_over_casing_force_on_other_stand():
    """Robustness: another layout, x0 and piston area; the simpler mechanism wins."""
    res = _run(_rec({"force_offset": 56.3}, layout=ALT, x0=0.100, area=40e-4), max_mechanisms=2)
    assert [m["name"] for m in res["mechanisms"]][:1] == ["force_offset"]
    mag = res["mechanisms"][0]["magnitude"]
    assert mag["q05"] <= 56.3 <= mag["q95"]


@pytest.mark.slow
@pytest.mark.parametrize("name,value", [("pressure_dependent_area", 0.01), ("casing_force", 200.0),
                                        ("force_offset", 56.3)])
def test_other_mechanisms_paper_layout(name, value):
    res = _run(_rec({name: value}))
    assert [m["name"] for m in res["mechanisms"]] == [name]
    mag = res["mechanisms"][0]["magnitude"]
    assert mag["q05"] <= value <= mag["q95"]


def test_proof_results_committed():
    """The committed proof suite shows no false alarms and names visible mechanisms."""
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "reports" / "diagnose-proof" / "summary.json"
    if not path.exists():
        pytest.skip("reports/diagnose-proof not generated yet")
    s = json.loads(path.read_text())
    fa = s["false_alarm_rate_clean"]
    assert fa["mechanism_named"] <= max(1, fa["runs"] // 10)
    for k, v in s["detection"].items():
        if "|visible|" in k:
            assert v["named"] == v["runs"], k


@pytest.mark.parametrize("argv,needle", [
    (["--gain-se", "0"], "--gain-se"),
    (["--max-mechanisms", "9"], "--max-mechanisms"),
    (["--walkers", "3"], "--walkers"),
])
def test_bad_options_exit_2(tmp_path, capsys, argv, needle):
    from uq._recordings import write_recordings_csv
    from uq.cli import main

    f = tmp_path / "r.csv"
    f.write_text(write_recordings_csv(simulate("n50-traditional", seed=1, layout=SMALL)))
    assert main(["diagnose", str(f), *argv]) == 2
    assert needle in capsys.readouterr().err


def test_cli_json_and_report(tmp_path, capsys):
    from uq._recordings import write_recordings_csv
    from uq.cli import main

    f = tmp_path / "r.csv"
    f.write_text(write_recordings_csv(simulate("n50-traditional", seed=2, layout=SMALL, effects={"hysteresis": 0.02})))
    assert main(["diagnose", str(f), "--json", str(tmp_path / "d.json"), "--report", str(tmp_path / "rep")]) == 0
    out = capsys.readouterr().out
    assert "hysteresis" in out
    res = json.loads((tmp_path / "d.json").read_text())
    assert res["mechanisms"][0]["name"] == "hysteresis"
    assert (tmp_path / "rep" / "diagnose.html").exists()
    assert (tmp_path / "rep" / "diagnose_residuals.png").exists()


def test_same_seed_gives_byte_identical_json(tmp_path):
    from uq._recordings import write_recordings_csv
    from uq.cli import main

    csv = tmp_path / "r.csv"
    csv.write_text(write_recordings_csv(simulate("n50-traditional", seed=3, effects={"force_offset": 56.3}, layout=SMALL)))
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    for out in (a, b):
        assert main(["diagnose", str(csv), "--json", str(out), "--seed", "5", "--max-steps", "400"]) == 0
    assert a.read_bytes() == b.read_bytes()
