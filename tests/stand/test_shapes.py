"""The shapes real recordings come in, made by the virtual stand and read back (issue 21)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from uq._cli.main import main
from uq._data.recordings import read_recordings, recordings_from_text, write_recordings_csv
from uq._physics.quantities import BAR_PA
from uq._stand import shapes
from uq._stand.simulator import Layout, TraditionalSpring, simulate

ROOT = Path(__file__).resolve().parents[2]
PAPER = (0.1, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0, 10.0)


def test_sensor_reads_the_held_pressure_to_1_pa_with_one_gain_per_campaign():
    tests = simulate("n50", seed=7, layout=Layout(pressures_bar=(1.0, 5.0)))
    read = shapes.record_pressure(tests, seed=7)
    g = shapes.sensor_gain(7)
    for t, r in zip(tests, read, strict=True):
        held_Pa = (t["pressure_bar"] + t["pressure_error_bar"]) * BAR_PA
        assert np.abs(r["measured_pressure_bar"] * BAR_PA - held_Pa * (1 + g)).max() <= 0.5 + 1e-6
        assert all(np.array_equal(r[k], t[k]) for k in t)  # the other readings are untouched
    gains = np.array([shapes.sensor_gain(s) for s in range(4000)])
    assert abs(gains.mean()) < 4 * 0.001 / np.sqrt(4000)
    assert gains.std() == pytest.approx(0.001, rel=0.05)  # 5 % is 4.5 standard errors of an sd


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_measured_pressures_cluster_into_the_paper_tests(seed):
    tests = shapes.record_pressure(simulate("n50", seed=seed), seed=seed)
    rec = recordings_from_text(write_recordings_csv(tests, pressure="measured"), "m.csv")
    g = shapes.sensor_gain(seed)
    assert rec.pressure_measured and len(rec.tests) == 11
    for t, p in zip(rec.tests, PAPER, strict=True):
        assert t.pressure_bar == pytest.approx(p, abs=0.001 + 2 * abs(g) * p), (p, g)
    both = recordings_from_text(write_recordings_csv(tests, pressure="both"), "b.csv")
    assert [t.pressure_bar for t in both.tests] == list(PAPER)
    for t, r in zip(tests, both.tests, strict=True):
        assert np.array_equal(r.measured_pressure_bar, np.round(t["measured_pressure_bar"], 5))


def test_catalogue_volume_is_the_elements_from_its_top():
    layout = Layout(pressures_bar=(3.0, 5.0), step_m=0.01)
    tests = simulate("n50-traditional", seed=4, layout=layout)
    cat = shapes.catalogue(
        tests,
        "n50-traditional",
        {},
        volume_at_bar=5.0,
        x_max_m=0.155,
        element_volume_at_xmax_m3=4.2e-3,
        piston_area_m2=54.82e-4,
    )
    low, high = cat
    assert low["volume_m3"] is None and np.all(np.diff(high["height_m"]) < 0)
    assert high["height_m"].size == 10 and high["volume_m3"][0] == pytest.approx(4.2e-3, abs=1e-15)
    # the traditional spring: dV/dx = F_eff(x) exactly, so V(x) = V(top) - int_x^top F_eff
    spring = TraditionalSpring()
    x = high["height_m"]
    fine = np.linspace(x, 0.155, 2001)
    integral = np.trapezoid(spring.effective_area_m2(fine, 5.0), fine, axis=0)
    assert np.allclose(high["volume_m3"], 4.2e-3 - integral, rtol=0, atol=1e-9)
    text = write_recordings_csv(
        cat,
        order=False,
        piston=False,
        volume=True,
        rounding=shapes.catalogue_rounding({"height": "mm", "force": "N", "volume": "l"}),
    )
    assert text.splitlines()[0] == "pressure_bar,height_mm,force_N,volume_l"
    rec = recordings_from_text(text, "cat.csv")
    t = rec.tests[1]
    assert np.allclose(t.volume_m3, high["volume_m3"], atol=0.005e-3 + 1e-12)
    assert np.all(np.round(t.force_N) % 10 == 0) and not rec.order_known


def _simulate(tmp_path, name, *options):
    out = tmp_path / name
    assert main(["simulate", "--out", str(out), "--pressures", "1,5", *options]) == 0
    return out


def test_simulate_writes_every_shape_the_reader_takes(tmp_path):
    ref = read_recordings(_simulate(tmp_path, "ref.csv"))
    us = read_recordings(_simulate(tmp_path, "us.csv", "--units", "psi,in,lbf"))
    assert us.units == {"pressure": "psi", "height": "in", "force": "lbf", "piston": "in"}
    assert [t.pressure_bar for t in us.tests] == [1.0, 5.0]
    assert np.allclose(us.tests[1].force_N, ref.tests[1].force_N, atol=0.003)
    fo = read_recordings(_simulate(tmp_path, "fo.csv", "--force-only"))
    assert not fo.has_volume and np.array_equal(fo.tests[1].force_N, ref.tests[1].force_N)
    cat = read_recordings(
        _simulate(tmp_path, "cat.csv", "--catalogue", "--step-mm", "10", "--units", "in3")
    )
    assert not cat.order_known and cat.units["volume"] == "in3"
    assert cat.tests[0].volume_m3 is None and cat.tests[1].volume_m3[0] == pytest.approx(
        4.2e-3, abs=0.5 * 16.387e-6
    )  # rounded to 1 in^3
    neg = _simulate(tmp_path, "neg.csv", "--compression-negative", "--record-pressure")
    rec = read_recordings(neg, compression="negative")
    assert rec.pressure_measured and np.array_equal(rec.tests[1].force_N, ref.tests[1].force_N)
    text = neg.read_text()
    assert "--compression-negative" in text and "set_pressure_bar,pressure_bar" in text


@pytest.mark.parametrize(
    "options, names",
    [
        (["--units", "psi,atm"], "--units"),
        (["--units", "psi,bar"], "--units"),
        (["--volume-at-bar", "5"], "--volume-at-bar"),
        (["--catalogue", "--volume-at-bar", "3"], "--volume-at-bar"),
        (["--record-pressure", "sometimes"], "--record-pressure"),
    ],
)
def test_simulate_shape_options_refused_in_one_line(tmp_path, capsys, options, names):
    out = tmp_path / "r.csv"
    try:
        status = main(["simulate", "--out", str(out), "--pressures", "1,5", *options])
    except SystemExit as exc:
        status = exc.code
    err = capsys.readouterr().err.strip()
    assert status == 2 and err.count("\n") == 0 and names in err, err
    assert not out.exists()


@pytest.mark.parametrize("name", ["n50-force-only", "n50-catalogue"])
def test_bundled_shapes_regenerate_byte_for_byte(tmp_path, name):
    bundled = ROOT / "data" / name / "recordings.csv"
    lines = bundled.read_text().splitlines()
    cmd = next(ln for ln in lines if ln.startswith("# Regenerate: uq "))
    assert lines[0].startswith("# RECONSTRUCTED")
    assert cmd.removeprefix("# ") in (ROOT / "data" / name / "README.md").read_text().replace(
        "    uq simulate", "Regenerate: uq simulate"
    )
    argv = cmd.removeprefix("# Regenerate: uq ").split()
    out = tmp_path / "again.csv"
    argv[argv.index("--out") + 1] = str(out)
    assert main(argv) == 0
    again = out.read_text().splitlines()
    assert [ln for ln in again if "Regenerate" not in ln] == [
        ln for ln in lines if "Regenerate" not in ln
    ]


def test_bundled_force_only_campaign_reads():
    rec = read_recordings(ROOT / "data" / "n50-force-only" / "recordings.csv")
    paper = read_recordings(ROOT / "data" / "n50" / "recordings.csv")
    assert not rec.has_volume and rec.order_known and rec.pressure_measured
    assert [t.pressure_bar for t in rec.tests] == list(PAPER)
    for t, p in zip(rec.tests, paper.tests, strict=True):
        assert np.array_equal(t.force_N, p.force_N) and np.array_equal(t.height_m, p.height_m)
        dp = t.measured_pressure_bar - t.pressure_bar
        assert (
            np.abs(dp).max() < 5 * (0.001 if t.pressure_bar < 1 else 0.01) + 0.002 * t.pressure_bar
        )


def test_bundled_catalogue_reads():
    rec = read_recordings(ROOT / "data" / "n50-catalogue" / "recordings.csv")
    assert [t.pressure_bar for t in rec.tests] == [3.0, 4.0, 5.0, 6.0, 7.0]
    assert not rec.order_known and rec.has_volume and not rec.has_piston
    assert [t.volume_m3 is not None for t in rec.tests] == [False, False, True, False, False]
    t = rec.tests[2]
    assert t.n_points == 10 and t.height_m[0] == pytest.approx(0.155)
    assert t.volume_m3[0] == pytest.approx(4.2e-3) and np.all(np.diff(t.volume_m3) < 0)
    # the paper measured about 2.6 L of volume change from 155 to 65 mm
    assert 2.0e-3 < t.volume_m3[0] - t.volume_m3[-1] < 3.2e-3
