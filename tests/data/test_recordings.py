"""The recordings reader: every bad input is one line naming the place, exit status 2."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from uq._cli.main import main
from uq._data.recordings import read_recordings, write_recordings_csv
from uq._io.errors import InputError
from uq._stand.simulator import Layout, simulate

HEADER = "pressure_bar,height_mm,force_N,piston_mm,branch,step"


def _good_lines(pressures=(1.0, 5.0)) -> list[str]:
    tests = simulate("n50", seed=3, layout=Layout(pressures_bar=pressures))
    return write_recordings_csv(tests).splitlines()


def _write(tmp_path, lines) -> str:
    p = tmp_path / "rec.csv"
    p.write_text("\n".join(lines) + "\n")
    return str(p)


def _err(tmp_path, lines) -> str:
    with pytest.raises(InputError) as exc:
        read_recordings(_write(tmp_path, lines))
    msg = str(exc.value)
    assert "\n" not in msg
    return msg


def test_valid_file_round_trips(tmp_path):
    rec = read_recordings(_write(tmp_path, _good_lines()))
    assert [t.pressure_bar for t in rec.tests] == [1.0, 5.0]
    t = rec.tests[0]
    assert t.n_points == 37 and t.compression.sum() == 19
    assert np.isclose(t.height_m[0], 0.155) and np.isclose(t.height_m.min(), 0.065)
    assert rec.x0_m == pytest.approx(0.112) and rec.piston_area_m2 == pytest.approx(54.82e-4)


def test_column_order_free_extra_columns_and_comments(tmp_path):
    lines = _good_lines((2.0,))
    cols = lines[0].split(",")
    order = [5, 3, 0, 4, 1, 2]
    out = ["# a comment", ",".join(cols[i] for i in order) + ",operator"]
    for ln in lines[1:]:
        f = ln.split(",")
        out.append(",".join(f[i] for i in order) + ",anna")
    rec = read_recordings(_write(tmp_path, out))
    assert rec.extra_columns == ("operator",) and rec.tests[0].n_points == 37


@pytest.mark.parametrize(
    "mutate, expect",
    [
        (lambda L: [L[0].replace("force_N", "force")] + L[1:], "missing column 'force_N'"),
        (
            lambda L: L[:3] + [L[3].replace(L[3].split(",")[2], "abc", 1)] + L[4:],
            "row 4, column 'force_N': 'abc' is not a number",
        ),
        (
            lambda L: L[:3] + [L[3].replace(L[3].split(",")[3], "nan", 1)] + L[4:],
            "column 'piston_mm': 'nan' is not a finite number",
        ),
        (
            lambda L: L[:2] + [L[2].replace("compression", "down")] + L[3:],
            "row 3, column 'branch': 'down' is not a branch",
        ),
        (lambda L: L[:6], "needs at least 6 points"),
        (lambda L: L + [L[5]], "duplicated row"),
        (lambda L: [HEADER], "no data rows"),
        (lambda L: [], "empty file"),
        (
            lambda L: L[:4] + [L[4].replace(L[4].split(",")[0] + ",", "-1,", 1)] + L[5:],
            "not positive",
        ),
        (lambda L: L[:5] + L[6:], "step 4 is missing"),
    ],
    ids=[
        "missing-column",
        "non-numeric",
        "nan",
        "unknown-branch",
        "too-few-points",
        "duplicated-row",
        "no-rows",
        "empty",
        "negative-pressure",
        "gap-in-steps",
    ],
)
def test_bad_input_is_named(tmp_path, mutate, expect):
    msg = _err(tmp_path, mutate(_good_lines((1.0,))))
    assert expect in msg
    assert "rec.csv" in msg


def test_heights_in_metres_are_refused(tmp_path):
    lines = _good_lines((1.0,))
    out = [lines[0]]
    for ln in lines[1:]:
        f = ln.split(",")
        f[1] = f"{float(f[1]) / 1000:.6f}"
        out.append(",".join(f))
    assert "looks like metres" in _err(tmp_path, out)


def test_heights_out_of_order_within_a_branch(tmp_path):
    lines = _good_lines((1.0,))
    f = lines[4].split(",")
    f[1] = "152.000"  # compression goes 155, 150, 145 -> 155, 150, 152
    lines[4] = ",".join(f)
    assert "must decrease" in _err(tmp_path, lines)


def test_single_height_per_test(tmp_path):
    lines = [HEADER] + [f"1,100,{1000 + i},{i},compression,{i}" for i in range(8)]
    assert "single height" in _err(tmp_path, lines)


def test_cli_exit_status_2_and_one_line(tmp_path, capsys):
    path = _write(tmp_path, _good_lines((1.0,))[:6])
    assert main(["fit", path]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith("uq fit: error:")


def test_bad_option_exit_2(tmp_path):
    path = _write(tmp_path, _good_lines((1.0,)))
    r = subprocess.run(
        [sys.executable, "-m", "uq._cli.main", "fit", path, "--piston-area-cm2", "-3"],
        capture_output=True,
        text=True,
    )
    assert (
        r.returncode == 2 and "--piston-area-cm2" in r.stderr and r.stderr.strip().count("\n") == 0
    )
