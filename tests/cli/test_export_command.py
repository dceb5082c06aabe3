"""``uq export`` on the command line (issue 30 item 1): formats, units, refusals in one line.

The model answering is the closed-form model of tests/export_helpers.py, plugged in through the
registry as a model from outside ``uq`` is (uq._models.registry), so these runs fit nothing; the
shared fit of data/n50 (tests/conftest.py) is exported saved (NetCDF) here and by
scripts/export_n50.py in tests/test_scripts.py.
"""

from __future__ import annotations

import json

import numpy as np
import openpyxl
import pandas as pd
import pytest
import scipy.io
from cli_helpers import one_line
from export_helpers import LinearArea, matlab_assignments, parse_teimorbit

from uq._cli.main import main
from uq._data.recordings import write_recordings_csv
from uq._models import registry
from uq._stand.simulator import Layout, simulate

NAME = "linear-area"


def _fit(recordings, *, seed=0, settings=None, stand=None):
    model = LinearArea(400, seed=seed)
    model.recordings = recordings
    p = recordings.pressures_bar
    model.tested_pressures_bar = p
    model.pressure_range_bar = (float(p.min()), float(p.max()))
    model.height_range_m = recordings.height_range_m
    return model


@pytest.fixture(autouse=True)
def plugged_in():
    registry.register(
        registry.ModelEntry(
            NAME,
            fit=_fit,
            model=LinearArea,
            words="area linear in height (a test's model)",
            n_sampled=1,
        ),
        replace=True,
    )
    yield
    registry.unregister(NAME)


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    d = tmp_path_factory.mktemp("rec")
    tests = simulate("n50", seed=3, layout=Layout(pressures_bar=(1.0, 5.0, 10.0), step_m=0.01))
    (d / "r.csv").write_text(write_recordings_csv(tests))
    us = write_recordings_csv(tests, units={"pressure": "psi", "height": "in", "force": "lbf"})
    (d / "us.csv").write_text(us)
    return d


def _run(argv, capsys) -> tuple[int, str, str]:
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    out = capsys.readouterr()
    return code, out.out, out.err


@pytest.mark.parametrize(
    "name, read",
    [
        ("e.csv", lambda p: pd.read_csv(p)),
        ("e.xlsx", lambda p: openpyxl.load_workbook(p)),
        ("e.json", lambda p: json.loads(p.read_text())),
        ("e.m", lambda p: p.read_text()),
        ("e.mat", lambda p: scipy.io.loadmat(p, simplify_cells=True)),
    ],
)
def test_every_format_from_the_suffix(recordings, tmp_path, capsys, name, read):
    out = tmp_path / name
    argv = ["export", str(recordings / "r.csv"), "--out", str(out), "--model", NAME]
    code, stdout, err = _run(argv + ["--heights-mm", "70:150:20", "--quiet"], capsys)
    assert code == 0, err
    assert "closed-form test model" in stdout and "3 pressures x 5 heights" in stdout
    assert read(out) is not None


def test_every_format_reads_back_to_the_models_numbers(recordings, tmp_path, capsys):
    """Each file, read by a reader that is not uq's (pandas, openpyxl, json, scipy.io, a reader of
    MATLAB assignments, a TeimOrbit parser from the format's rules), holds the model's q95 force."""
    from uq._cli.common import DEFAULT_SEED

    heights = np.arange(70.0, 151.0, 20.0)
    pressures = np.array([1.0, 5.0, 10.0])
    X, P = np.meshgrid(heights * 1e-3, pressures, indexing="ij")
    truth = np.quantile(LinearArea(400, seed=DEFAULT_SEED).force_draws(X, P), 0.95, axis=0)
    for name in ("e.csv", "e.xlsx", "e.json", "e.m", "e.mat", "e.tpf"):
        argv = ["export", str(recordings / "r.csv"), "--out", str(tmp_path / name), "--quiet"]
        assert _run(argv + ["--model", NAME, "--heights-mm", "70:150:20"], capsys)[0] == 0
    t = pd.read_csv(tmp_path / "e.csv").pivot(
        index="height_mm", columns="pressure_bar", values="force_N_q95"
    )
    assert np.allclose(t.to_numpy(), truth, rtol=1e-9)
    rows = list(
        openpyxl.load_workbook(tmp_path / "e.xlsx")["force_N q95"].iter_rows(values_only=True)
    )
    assert list(rows[0][1:]) == pressures.tolist()
    assert np.allclose(np.array([r[1:] for r in rows[1:]], float), truth, rtol=1e-12)
    grid = json.loads((tmp_path / "e.json").read_text())["grid"]
    q95 = np.array([g["force_N"]["q95"] for g in grid]).reshape(pressures.size, heights.size)
    assert np.allclose(q95.T, truth, rtol=1e-12)
    script = matlab_assignments((tmp_path / "e.m").read_text())
    assert np.allclose(script["airspring.load.q95"], truth, rtol=1e-9)
    mat = scipy.io.loadmat(tmp_path / "e.mat", simplify_cells=True)["airspring"]
    assert np.allclose(mat["load"]["q95"], truth, rtol=1e-12)
    tpf = parse_teimorbit((tmp_path / "e_q95.tpf").read_text())
    assert tpf["UNITS"]["params"]["LENGTH"] == "mm" and tpf["UNITS"]["params"]["FORCE"] == "newton"
    z = np.array(tpf["AIRSPRING"]["Z_DATA"]["table"]["rows"]).ravel()
    assert np.allclose(z, pressures * 0.1)  # bar in N/mm^2
    xy = np.array(tpf["AIRSPRING"]["XY_DATA"]["table"]["rows"])
    assert np.allclose(xy[:, 0], heights) and np.allclose(xy[:, 1:], truth, rtol=1e-9)


def test_csv_reads_as_the_contract_says(recordings, tmp_path, capsys):
    out = tmp_path / "e.csv"
    argv = ["export", str(recordings / "r.csv"), "--out", str(out), "--model", NAME, "--quiet"]
    assert _run(argv + ["--pressures-bar", "1,2.5,10"], capsys)[0] == 0
    t = pd.read_csv(out)
    assert list(t.columns[:9]) == [
        "pressure_bar",
        "height_mm",
        "force_N_mean",
        "force_N_q05",
        "force_N_q50",
        "force_N_q95",
        "feff_m2_mean",
        "feff_m2_q05",
        "feff_m2_q95",
    ]
    assert sorted(set(t.pressure_bar)) == [1.0, 2.5, 10.0]  # 2.5 bar: between the tests
    assert sorted(set(t.height_mm)) == list(np.arange(65.0, 156.0, 10.0))  # every tested height


def test_teimorbit_one_file_per_statistic(recordings, tmp_path, capsys):
    out = tmp_path / "air.tpf"
    argv = ["export", str(recordings / "r.csv"), "--out", str(out), "--model", NAME, "--quiet"]
    code, stdout, _ = _run(argv + ["--quantiles", "0.1,0.9"], capsys)
    assert code == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "air_mean.tpf",
        "air_q10.tpf",
        "air_q90.tpf",
    ]


def test_units_input_names_the_columns_in_the_recordings_units(recordings, tmp_path, capsys):
    out = tmp_path / "us.csv"
    argv = ["export", str(recordings / "us.csv"), "--out", str(out), "--model", NAME, "--quiet"]
    assert _run(argv + ["--units", "input"], capsys)[0] == 0
    t = pd.read_csv(out)
    assert list(t.columns[:3]) == ["pressure_psi", "height_in", "force_lbf_mean"]
    assert "feff_in2_mean" in t and "volume_increment_in3_mean" in t


def test_the_json_summary(recordings, tmp_path, capsys):
    out = tmp_path / "e.csv"
    argv = ["export", str(recordings / "r.csv"), "--out", str(out), "--model", NAME, "--quiet"]
    code, stdout, _ = _run(argv + ["--json", "-"], capsys)
    doc = json.loads(stdout)
    assert code == 0 and doc["model"]["name"] == NAME
    assert doc["out"] == [str(out), str(tmp_path / "e_provenance.csv")]
    assert doc["format"] == "csv" and doc["n_draws"] == 400


@pytest.mark.parametrize(
    "extra, expect",
    [
        (
            ["--heights-mm", "50:160:10"],
            "option --heights-mm: 50 mm is outside the tested heights 65..155 mm",
        ),
        (
            ["--pressures-bar", "12"],
            "option --pressures-bar: 12 bar is outside the tested pressures 1..10 bar",
        ),
        (["--heights-mm", "70:60:5"], "argument --heights-mm: '70:60:5': expected A <= B"),
        (["--quantiles", "0.5,2"], "argument --quantiles"),
        (["--sealed", "--height-mm", "112"], "option --sealed: needs --charge-bar, --volume-l"),
        (["--charge-bar", "5"], "option --charge-bar: only with --sealed"),
        (["--format", "nope"], "argument --format: invalid choice"),
        (["--format", "xlsx"], "option --format xlsx: --out's suffix '.csv' names csv"),
    ],
)
def test_refusals_are_one_line_and_write_nothing(recordings, tmp_path, capsys, extra, expect):
    out = tmp_path / "e.csv"
    argv = ["export", str(recordings / "r.csv"), "--out", str(out), "--model", NAME, *extra]
    code, _, err = _run(argv, capsys)
    assert code == 2 and expect in one_line(err), err
    assert not out.exists()


def test_an_unknown_suffix_needs_the_format(recordings, tmp_path, capsys):
    out = tmp_path / "e.txt"
    argv = ["export", str(recordings / "r.csv"), "--out", str(out), "--model", NAME]
    code, _, err = _run(argv, capsys)
    assert code == 2 and "option --format: needed, --out's suffix '.txt' names no format" in err
    assert _run(argv + ["--format", "csv", "--quiet"], capsys)[0] == 0
    assert pd.read_csv(out).shape[0] == 30


def test_extrapolation_when_asked_is_said(recordings, tmp_path, capsys):
    out = tmp_path / "e.json"
    argv = ["export", str(recordings / "r.csv"), "--out", str(out), "--model", NAME, "--quiet"]
    code, stdout, _ = _run(argv + ["--heights-mm", "60,100", "--extrapolate"], capsys)
    assert code == 0 and "extrapolated: heights 60 mm" in stdout
    assert any(n.startswith("extrapolated") for n in json.loads(out.read_text())["notes"])


def test_a_folder_names_its_saved_model_or_is_refused(tmp_path, capsys):
    empty = tmp_path / "empty"
    empty.mkdir()
    code, _, err = _run(["export", str(empty), "--out", str(tmp_path / "e.csv")], capsys)
    assert (
        code == 2 and "a folder; give the recordings or a saved model (it holds no .nc file)" in err
    )


def _unconverged_fit(recordings, **options):
    from uq._models.fitted import Verdict

    model = _fit(recordings, **options)
    model.convergence = Verdict(False, ("R-hat of c_00 is 1.31 > 1.01 (a test's warning)",))
    return model


@pytest.fixture
def unconverged():
    name = "linear-area-unconverged"
    registry.register(
        registry.ModelEntry(
            name, fit=_unconverged_fit, model=LinearArea, words="a test's model", n_sampled=1
        ),
        replace=True,
    )
    yield name
    registry.unregister(name)


def test_an_unconverged_fit_is_refused_unless_allowed_and_then_said_everywhere(
    recordings, tmp_path, capsys, unconverged
):
    out = tmp_path / "e.csv"
    argv = ["export", str(recordings / "r.csv"), "--out", str(out), "--model", unconverged]
    code, _, err = _run(argv, capsys)
    assert code == 1 and not list(tmp_path.iterdir())
    assert one_line(err).startswith("uq export: NOT CONVERGED (closed-form test model")
    assert "R-hat of c_00 is 1.31" in err and "pass --allow-unconverged" in err
    for name in ("e.csv", "e.json", "e.m", "e.tpf"):
        path = tmp_path / name
        args = ["--out", str(path), "--allow-unconverged", "--quiet"]
        code, stdout, _ = _run([*argv[:2], *argv[4:], *args], capsys)
        assert code == 0 and "NOT CONVERGED" in stdout
    prov = pd.read_csv(tmp_path / "e_provenance.csv")
    assert prov.value[prov.key == "note"].str.startswith("NOT CONVERGED").any()
    assert json.loads((tmp_path / "e.json").read_text())["notes"][0].startswith("NOT CONVERGED")
    assert "airspring.notes = 'NOT CONVERGED" in (tmp_path / "e.m").read_text()
    assert "% note: NOT CONVERGED" in (tmp_path / "e.m").read_text()
    assert "$ note: NOT CONVERGED" in (tmp_path / "e_q50.tpf").read_text()


def test_the_json_is_the_contracts_estimate_objects(recordings, tmp_path, capsys):
    """--json: the grid in SI with {"mean", "sd", "q05", "q95"} objects, whatever --quantiles."""
    out = tmp_path / "e.xlsx"
    argv = ["export", str(recordings / "r.csv"), "--out", str(out), "--model", NAME, "--quiet"]
    code, stdout, _ = _run(argv + ["--quantiles", "0.1,0.9", "--json", "-"], capsys)
    doc = json.loads(stdout)
    assert code == 0 and doc["converged"] is True and doc["quantiles"] == [0.1, 0.9]
    point = doc["grid"][0]
    assert set(point) >= {"pressure_bar", "height_m", "force_N", "feff_m2"}
    assert set(point["force_N"]) == {"mean", "sd", "q05", "q10", "q90", "q95"}
    book = openpyxl.load_workbook(out, read_only=True)
    assert "force_N q10" in book.sheetnames and "force_N q05" not in book.sheetnames
    # the workbook's cell (first height, first pressure) is the JSON's first point
    first = list(book["force_N q10"].iter_rows(values_only=True))[1]
    assert first[0] == pytest.approx(point["height_m"] * 1e3)
    assert first[1] == pytest.approx(point["force_N"]["q10"], rel=1e-12)


def test_a_saved_fit_is_exported_without_a_refit(n50_surface, tmp_path, capsys):
    """A saved NetCDF model (uq surface --out's file): its numbers, its provenance, and the
    reconstruction of data/n50 said in every format."""
    saved = tmp_path / "surface.nc"
    n50_surface.save(saved, written_by="the test")
    out = tmp_path / "n.csv"
    argv = ["export", str(saved), "--out", str(out), "--heights-mm", "70:150:40", "--quiet"]
    code, stdout, err = _run(argv + ["--pressures-bar", "2,5.5", "--draws", "500"], capsys)
    assert code == 0, err
    assert "not measured data: the recordings are the paper's N-50 spring reconstructed" in stdout
    t = pd.read_csv(out)
    model = n50_surface.on_draws(500)
    X, P = np.meshgrid([0.07, 0.11, 0.15], [2.0, 5.5], indexing="xy")
    draws = model.force_draws(X.T, P.T)  # (S, H, P)
    for j, p in enumerate((2.0, 5.5)):
        at = t[t.pressure_bar == p].sort_values("height_mm")
        assert np.allclose(at.force_N_mean, draws[:, :, j].mean(axis=0), rtol=1e-9)
        assert np.allclose(at.force_N_q05, np.quantile(draws[:, :, j], 0.05, axis=0), rtol=1e-9)
    prov = dict(pd.read_csv(tmp_path / "n_provenance.csv").values)
    assert prov["recordings"] == "recordings.csv" and len(prov["recordings sha256"]) == 64
    assert "no refit" in prov["loaded from"]
    code, _, err = _run(argv + ["--units", "input"], capsys)
    assert code == 2 and "option --units input" in one_line(err)
    code, _, err = _run(argv + ["--model", "cubics"], capsys)
    assert code == 2 and "option --model cubics" in one_line(err)
    # a fit saved as failing its convergence rules: refused, then exported when allowed
    bad = tmp_path / "bad.nc"
    n50_surface.save(bad, converged=False, warnings=["R-hat of c_00 is 1.2 (a test's warning)"])
    out = tmp_path / "bad.json"
    argv = ["export", str(bad), "--out", str(out), "--heights-mm", "70,110", "--quiet"]
    code, _, err = _run(argv, capsys)
    assert code == 1 and not out.exists()
    assert f"{bad} holds a fit that failed its convergence rules" in one_line(err)
    code, _, err = _run(argv + ["--allow-unconverged"], capsys)
    assert code == 0 and json.loads(out.read_text())["notes"][0].startswith("NOT CONVERGED")
