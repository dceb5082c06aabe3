"""``uq export`` on the command line (issue 30 item 1): formats, units, refusals in one line.

The model answering is the closed-form model of tests/export_helpers.py, plugged in through the
registry as a model from outside ``uq`` is (uq._models.registry), so these runs fit nothing; the
real fit and saved model run in tests/test_scripts.py (scripts/export_n50.py).
"""

from __future__ import annotations

import json

import numpy as np
import openpyxl
import pandas as pd
import pytest
import scipy.io
from cli_helpers import one_line
from export_helpers import LinearArea

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
    assert code == 0 and doc["model"]["name"] == NAME and doc["out"] == [str(out)]
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
