"""Instrument exports in (issue 30 item 4): a units row, a column map, a header below a title;
the reader without pint and pandas (issue 32); the recordings' hash and comments taken when read
(issue 28 item 4)."""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from uq._cli.main import main
from uq._data import units
from uq._data.recordings import (
    read_recordings,
    recordings_from_text,
    write_recordings_csv,
)
from uq._data.writing import write_bluehill_csv
from uq._io.errors import InputError
from uq._io.files import sha256_of
from uq._stand import shapes
from uq._stand.simulator import Layout, simulate, simulate_recordings

ROOT = Path(__file__).resolve().parents[2]
BLUEHILL = ROOT / "data" / "n50-bluehill" / "recordings.csv"
MAP = "height=Position,force=Load"

# The paper's format of a small campaign, and the same readings under other names and shapes.
TESTS = simulate("n50", seed=5, layout=Layout(pressures_bar=(1.0, 5.0), step_m=0.01))
PAPER = write_recordings_csv(TESTS).splitlines()


def _write(tmp_path, lines, name="r.csv") -> Path:
    p = tmp_path / name
    p.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return p


def _renamed(lines, names: dict[str, str], units_row: str | None = None, title=()) -> list[str]:
    """``lines`` with header names replaced, a units row under the header, title rows above."""
    header = [names.get(h, h) for h in lines[0].split(",")]
    out = list(title) + [",".join(header)]
    if units_row is not None:
        out.append(units_row)
    return out + lines[1:]


def _same_readings(a, b) -> bool:
    return all(
        np.array_equal(getattr(x, k), getattr(y, k))
        for x, y in zip(a.tests, b.tests, strict=True)
        for k in ("height_m", "force_N", "piston_m", "compression", "step")
    ) and [t.pressure_bar for t in a.tests] == [t.pressure_bar for t in b.tests]


def _cli_error(argv, capsys) -> str:
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    err = capsys.readouterr().err.strip()
    assert code == 2 and "\n" not in err and "Traceback" not in err, err
    return err


# ----------------------------------------------------------------------------- units table


def test_unit_factors_are_the_definitions_and_pints():
    """The closed list of units as a table: the exact definitions (inch 0.0254 m, lbf 0.45359237 kg
    x g_n) to 15 digits, equal to the factors pint gave (the reader's former source)."""
    assert units.factor("pressure", "psi") == 0.0689475729316836
    assert units.factor("force", "lbf") == 4.4482216152605
    assert units.factor("volume", "in3") == 1.6387064e-05
    assert units.factor("volume", "l") == 1e-3 and units.factor("volume", "cm3") == 1e-6
    pint = pytest.importorskip("pint")
    reg = pint.UnitRegistry()
    spelled = {"in": "inch", "l": "L", "cm3": "cm**3", "m3": "m**3", "in3": "inch**3"}
    inside = {"bar": "bar", "m": "m", "N": "N", "m^3": "m**3"}
    for q, (unit, suffixes) in units.QUANTITIES.items():
        for s in suffixes:
            v = reg.Quantity(1.0, spelled.get(s, s)).to(inside[unit]).magnitude
            assert units.factor(q, s) == float(f"{v:.15g}"), (q, s)


def test_csv_reader_imports_neither_pandas_nor_pint():
    code = (
        "import sys; from uq._data.recordings import read_recordings; "
        f"read_recordings({str(ROOT / 'data' / 'n50' / 'recordings.csv')!r}); "
        f"read_recordings({str(BLUEHILL)!r}, columns={MAP!r}, compression='negative'); "
        "print(sorted(m for m in ('pandas', 'pint') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


# ----------------------------------------------------------------------------- hash and comments


def test_recordings_carry_their_hash_and_comments_from_reading(tmp_path):
    p = _write(tmp_path, ["# made on stand 2", "#  operator: b"] + PAPER)
    rec = read_recordings(p)
    assert rec.sha256 == sha256_of(p) == hashlib.sha256(p.read_bytes()).hexdigest()
    assert rec.comments == ("made on stand 2", "operator: b")
    text = p.read_text()
    assert recordings_from_text(text, "t").sha256 == rec.sha256  # the file a text would be
    # a simulated campaign's is that of the file `uq simulate` writes from it
    sim = simulate_recordings("n50", seed=3, layout=Layout(pressures_bar=(1.0, 5.0), step_m=0.01))
    assert sim.sha256 is not None and sim.comments[0].startswith("RECONSTRUCTED")


def test_report_and_saved_answers_take_the_hash_read_with_the_recordings(tmp_path):
    """The callers point at the field: the report's footer does not hash the file again."""
    from uq._data.stand_description import PAPER_STAND
    from uq._report.campaign import provenance

    p = _write(tmp_path, PAPER)
    rec = read_recordings(p)
    p.write_text("changed since\n")  # what the page names is what was read, not what is there now
    assert provenance(rec, PAPER_STAND)["sha256"] == rec.sha256 != sha256_of(p)


# ----------------------------------------------------------------------------- the Bluehill example


def test_bundled_bluehill_export_regenerates_byte_for_byte(tmp_path):
    lines = BLUEHILL.read_text().splitlines()
    note = next(ln for ln in lines if "Regenerate: uq simulate" in ln)
    cmd = note.split("Regenerate: ", 1)[1].rstrip('"')
    assert cmd in (ROOT / "data" / "n50-bluehill" / "README.md").read_text()
    argv = cmd.removeprefix("uq ").split()
    out = tmp_path / "again.csv"
    argv[argv.index("--out") + 1] = str(out)
    assert main(argv) == 0
    again = out.read_text().splitlines()
    assert [ln for ln in again if "Regenerate" not in ln] == [
        ln for ln in lines if "Regenerate" not in ln
    ]


def test_bundled_bluehill_export_reads_as_the_stands_readings():
    rec = read_recordings(BLUEHILL, columns=MAP, compression="negative")
    assert any("RECONSTRUCTED" in c for c in rec.comments)  # the title rows are its comments
    assert len(rec.notes) == 2
    assert "the header is row 9 (rows 1-7 above it: a title" in rec.notes[0]
    assert (
        "row 10: a units row under the header: Position in mm, Load in kN, Pressure in bar"
        in (rec.notes[1])
    )
    assert rec.units == {"height": "mm", "force": "kN", "pressure": "bar"}
    assert rec.columns == {"height": "Position", "force": "Load", "pressure": "Pressure"}
    assert rec.extra_columns == ("Time",) and not rec.has_volume and not rec.order_known
    assert rec.pressure_measured and [t.pressure_bar for t in rec.tests] == [3, 4, 5, 6, 7]
    stand = simulate("n50", seed=20201, layout=Layout(pressures_bar=(3.0, 4.0, 5.0, 6.0, 7.0)))
    read = shapes.record_pressure(stand, seed=20201)
    for t, s in zip(rec.tests, read, strict=True):
        comp = s["compression"]
        assert np.allclose(t.height_m, s["height_m"][comp], rtol=0, atol=5e-7)
        assert np.allclose(t.force_N, s["force_N"][comp], rtol=0, atol=5e-3)  # kN to 5 decimals
        assert np.allclose(t.measured_pressure_bar, s["measured_pressure_bar"][comp], atol=5e-6)


def test_bluehill_export_in_us_units_reads_the_same(tmp_path):
    tests = shapes.record_pressure(TESTS, seed=5)
    si = recordings_from_text(
        write_bluehill_csv(tests), "si.csv", columns=MAP, compression="negative"
    )
    us = recordings_from_text(
        write_bluehill_csv(tests, units={"pressure": "psi", "height": "in", "force": "lbf"}),
        "us.csv",
        columns=MAP,
        compression="negative",
    )
    assert us.units == {"height": "in", "force": "lbf", "pressure": "psi"}
    for a, b in zip(si.tests, us.tests, strict=True):  # set values: rounded in the file's unit
        assert a.pressure_bar == pytest.approx(
            b.pressure_bar, abs=0.1 * units.factor("pressure", "psi")
        )
        assert np.allclose(a.height_m, b.height_m, atol=5e-7)
        assert np.allclose(a.force_N, b.force_N, atol=5e-3)


def test_simulate_instrument_refuses_the_shape_options_it_sets(tmp_path, capsys):
    err = _cli_error(
        ["simulate", "--out", str(tmp_path / "x.csv"), "--instrument", "bluehill", "--catalogue"],
        capsys,
    )
    assert "--instrument bluehill" in err and "drop --catalogue" in err
    assert not (tmp_path / "x.csv").exists()


# ----------------------------------------------------------------------------- units row


@pytest.mark.parametrize(
    "row, option",
    [
        ("(bar),(mm),(N),(mm),,", "auto"),  # Bluehill's parentheses
        ("[bar],[mm],[N],[mm],,", "auto"),  # brackets
        ("bar,mm,N,mm,,", "yes"),  # bare units: only when told
    ],
)
def test_units_row_gives_the_units_of_quantity_named_columns(tmp_path, row, option):
    names = {"pressure_bar": "Pressure", "height_mm": "Height", "force_N": "Force"}
    names["piston_mm"] = "Piston"
    p = _write(tmp_path, _renamed(PAPER, names, row))
    rec = read_recordings(p, units_row=option)
    assert _same_readings(rec, recordings_from_text("\n".join(PAPER), "ref"))
    assert rec.tests[0].rows[0] == 3  # the units row is row 2: rows stay the file's
    assert rec.notes == (
        f"{p}, row 2: a units row under the header: Pressure in bar, Height in mm, Force in N, Piston in mm",
    )


def test_units_row_converts_and_must_agree_with_a_named_unit(tmp_path):
    kn = [PAPER[0]] + [
        ",".join(f"{float(c) / 1000:.5f}" if i == 2 else c for i, c in enumerate(ln.split(",")))
        for ln in PAPER[1:]
    ]
    rec = read_recordings(_write(tmp_path, _renamed(kn, {"force_N": "force"}, ",,(kN),,,")))
    ref = recordings_from_text("\n".join(PAPER), "ref")
    assert rec.units["force"] == "kN"
    assert all(
        np.allclose(a.force_N, b.force_N, atol=5e-3)
        for a, b in zip(rec.tests, ref.tests, strict=True)
    )
    p = _write(tmp_path, _renamed(PAPER, {}, "(bar),(mm),(kN),(mm),,"))
    with pytest.raises(InputError, match=r"row 2, column 'force_N': the units row says kN but"):
        read_recordings(p)
    p = _write(tmp_path, _renamed(PAPER, {"force_N": "Force"}, "(bar),(mm),(kgf),(mm),,"))
    with pytest.raises(
        InputError,
        match=r"row 2, column 'Force': unknown unit 'kgf' for the force; one of N, kN, lbf",
    ):
        read_recordings(p)


def test_units_row_no_reads_it_as_data(tmp_path):
    p = _write(tmp_path, _renamed(PAPER, {}, "(bar),(mm),(N),(mm),,"))
    assert read_recordings(p).tests[0].n_points == TESTS[0]["height_m"].size  # auto: detected
    with pytest.raises(
        InputError, match=r"row 2, column 'pressure_bar': '\(bar\)' is not a number"
    ):
        read_recordings(p, units_row="no")
    with pytest.raises(InputError, match="units_row: expected auto, yes or no"):
        read_recordings(p, units_row="maybe")


# ----------------------------------------------------------------------------- column map


def test_column_map_names_the_files_columns(tmp_path):
    names = {"pressure_bar": "p", "height_mm": "Extension", "force_N": "Load", "piston_mm": "L"}
    p = _write(tmp_path, _renamed(PAPER, names))
    spec = "pressure_bar=p, height_mm=Extension, force_N=Load, piston_mm=L"
    rec = read_recordings(p, columns=spec)
    assert _same_readings(rec, recordings_from_text("\n".join(PAPER), "ref"))
    assert rec.columns["force"] == "Load" and rec.notes == ()
    as_dict = read_recordings(p, columns=dict(x.strip().split("=") for x in spec.split(",")))
    assert _same_readings(as_dict, rec)
    lines = _renamed(PAPER, names)
    fields = lines[4].split(",")
    lines[4] = ",".join(fields[:2] + ["abc"] + fields[3:])
    with pytest.raises(InputError, match=r"row 5, column 'Load': 'abc' is not a number"):
        read_recordings(_write(tmp_path, lines), columns=spec)  # the file's name


@pytest.mark.parametrize(
    "spec, expect",
    [
        ("force_X=Load", "unknown unit 'X' for force"),
        ("load=Load", "'load' is not a recordings column"),
        ("force_N=Load,force_kN=Extension", "the force is already mapped (force_N=Load)"),
        ("force_N=Load,height_mm=Load", "column 'Load' is already mapped (to force_N)"),
        ("force_N", "expected TARGET=SOURCE"),
    ],
)
def test_bad_column_maps_are_usage_errors(tmp_path, capsys, spec, expect):
    p = _write(tmp_path, PAPER)
    err = _cli_error(["fit", str(p), "--columns", spec], capsys)
    assert "argument --columns" in err and expect in err
    with pytest.raises(InputError, match="columns: ") as exc:
        read_recordings(p, columns=spec)
    assert exc.value.param == "columns"


def test_column_map_errors_name_the_file_and_row(tmp_path, capsys):
    p = _write(tmp_path, _renamed(PAPER, {"force_N": "Load"}))
    err = _cli_error(["fit", str(p), "--columns", "force_N=Lod"], capsys)
    assert err == (
        f"uq fit: error: {p}, row 1: --columns force_N=Lod: no column 'Lod' in the header "
        "(header has: pressure_bar, height_mm, Load, piston_mm, branch, step)"
    )
    err = _cli_error(["fit", str(p), "--columns", "force=Load"], capsys)
    assert (
        "column 'Load': no unit for the force (--columns force=Load): the file has no units row"
        in err
    )
    err = _cli_error(["fit", str(p)], capsys)
    assert "missing column 'force_N'" in err and "--columns (force_N=NAME)" in err
    err = _cli_error(["fit", str(p), "--columns", "force_N=Load,force=force_N"], capsys)
    assert "the force is already mapped" in err


def test_a_mapped_quantity_and_a_named_one_clash(tmp_path):
    lines = [PAPER[0] + ",Load"] + [ln + ",1" for ln in PAPER[1:]]
    with pytest.raises(InputError, match="columns 'force_N' and 'Load' both give the force"):
        read_recordings(_write(tmp_path, lines), columns="force_N=Load")


# ----------------------------------------------------------------------------- title rows


def test_header_below_a_title_is_found_and_said(tmp_path):
    title = ["Air spring N-50, specimen 3", "Operator,a. n. other", ""]
    p = _write(tmp_path, _renamed(PAPER, {}, None, title))
    rec = read_recordings(p)
    assert _same_readings(rec, recordings_from_text("\n".join(PAPER), "ref"))
    assert rec.notes == (
        f"{p}: the header is row 4 (rows 1-2 above it: a title, kept with the comments)",
    )
    assert rec.comments == ("Air spring N-50, specimen 3", "Operator, a. n. other")
    assert rec.tests[0].rows[0] == 5
    given = read_recordings(p, header_row=4)
    assert _same_readings(given, rec) and given.notes == ()  # given, not found: nothing to say


def test_header_row_option_is_checked(tmp_path, capsys):
    p = _write(tmp_path, ["# a comment"] + PAPER)
    with pytest.raises(InputError, match="header_row: 1: row 1 of .* is blank or a comment"):
        read_recordings(p, header_row=1)
    err = _cli_error(["fit", str(p), "--header-row", "999"], capsys)
    assert "option --header-row: 999: row 999" in err and "beyond the last row" in err
    err = _cli_error(["fit", str(p), "--header-row", "0"], capsys)
    assert "argument --header-row" in err


def test_workbook_with_title_and_units_rows_reads_like_csv(tmp_path):
    """The same shapes in an .xlsx sheet: a caption row above the header, a units row under it."""
    names = {"pressure_bar": "Pressure", "height_mm": "Height", "force_N": "Force"}
    lines = _renamed(PAPER, names, "(bar),(mm),(N),(mm),,", ["N-50 characteristic"])

    def cell(text):
        try:
            return float(text)
        except ValueError:
            return text or None

    rows = [[cell(c) for c in ln.split(",")] for ln in lines]
    width = max(len(r) for r in rows)
    path = tmp_path / "r.xlsx"
    frame = pd.DataFrame([r + [None] * (width - len(r)) for r in rows])
    frame.to_excel(path, header=False, index=False, sheet_name="Data", engine="openpyxl")
    rec = read_recordings(path)
    assert _same_readings(rec, recordings_from_text("\n".join(PAPER), "ref"))
    assert rec.comments == ("N-50 characteristic",) and len(rec.notes) == 2
    assert rec.sha256 == sha256_of(path) and rec.tests[0].rows[0] == 4


# ----------------------------------------------------------------------------- every command


@pytest.mark.parametrize("command", ["fit", "report", "surface", "margin", "diagnose", "design"])
def test_every_command_that_reads_recordings_takes_the_options(command):
    from uq._cli.main import build_parser

    sub = build_parser([command])._uq_commands[command]
    options = {o for a in sub._actions for o in a.option_strings}
    assert {"--columns", "--units-row", "--header-row"} <= options


def test_units_row_modes_equal_the_library():
    from uq._cli import common
    from uq._data.rows import UNITS_ROW_MODES

    for mode in UNITS_ROW_MODES:
        assert common.units_row(mode) == mode


def test_the_bluehill_export_through_the_command_line(tmp_path, capsys):
    """Notes on stderr, the readings fitted (a short run: the reading is the point here), and the
    summary and coefficient table in the units the file came in (``--units input --csv``)."""
    out, table = tmp_path / "fit.json", tmp_path / "coefficients.csv"
    argv = ["fit", str(BLUEHILL), "--columns", MAP, "--compression", "negative", "--json", str(out)]
    argv += ["--max-steps", "300", "--quiet", "--units", "input", "--csv", str(table)]
    assert main(argv) in (0, 1)
    captured = capsys.readouterr()
    assert captured.err.count("note: ") == 2 and "a units row under the header" in captured.err
    assert "p_u bar" in captured.out and "a_P kN" in captured.out and "x0 = 112 mm" in captured.out
    got = pd.read_csv(table)
    assert list(got.columns) == [
        "pressure_bar",
        "block",
        "coefficient",
        "unit",
        "mean",
        "sd",
        "q05",
        "q50",
        "q95",
        "r_hat",
        "ess_bulk",
        "x0_mm",
    ]
    assert set(got.block) == {"force"} and len(got) == 4 * 5  # force-only: no piston rows
    assert list(got.unit[:4]) == ["kN", "kN/mm", "kN/mm^2", "kN/mm^3"]
    doc = json.loads(out.read_text())  # the JSON stays SI
    a_si = doc["tests"][0]["force"]["a_P"]["mean"]
    assert got.iloc[0]["mean"] == pytest.approx(a_si / 1000.0, rel=1e-9)
