"""The bad-input table (issue 10): every row exits 2 with one line naming the place, writes nothing.

Plus the reading rules (BOM, delimiters, decimal comma, the row named) and the writing rules
(modes, symbolic links, devices, stale figures) of uq._data.recordings and uq._io.files.
"""

from __future__ import annotations

import os
import stat

import numpy as np
import pytest

from uq._cli.main import main
from uq._data.recordings import read_recordings, write_recordings_csv
from uq._io.errors import InputError
from uq._io.files import remove_stale, write_text_atomic
from uq._stand.simulator import Layout, simulate

GOOD = write_recordings_csv(
    simulate("n50", seed=5, layout=Layout(pressures_bar=(1.0, 5.0)))
).splitlines()
COLS = GOOD[0].split(",")
FIRST = 2  # file line of the first data row (line 1 is the header)


def _cell(lines, i, col, fn):
    """Lines with data row ``i`` (0-based) of column ``col`` replaced by ``fn(old text)``."""
    lines = list(lines)
    f = lines[1 + i].split(",")
    k = COLS.index(col)
    f[k] = fn(f[k])
    lines[1 + i] = ",".join(f)
    return lines


def _column(lines, col, fn):
    out = list(lines)
    for i in range(len(lines) - 1):
        out = _cell(out, i, col, fn)
    return out


def _run(argv) -> int:
    """The CLI's exit status; usage errors leave argparse through SystemExit."""
    try:
        return main(argv)
    except SystemExit as exc:
        return exc.code


def _scaled(factor):
    return lambda text: f"{float(text) * factor:.6g}"


def _heights_down_up(
    lines, i, text
):  # a mistyped height that still fits the compression branch's order
    return _cell(lines, i, "height_mm", lambda _: text)


# (id, lines of the file, extra options, what the one line must name)
RECORDINGS = [
    ("force-1e300", _cell(GOOD, 10, "force_N", lambda _: "1e300"), [], ["row 12", "'force_N'"]),
    ("one-force-1e9", _cell(GOOD, 3, "force_N", lambda _: "1e9"), [], ["row 5", "'force_N'"]),
    (
        "one-height-1e12",
        _cell(GOOD, 3, "height_mm", lambda _: "1e12"),
        [],
        ["row 5", "'height_mm'"],
    ),
    (
        "heights-in-micrometres",
        _column(GOOD, "height_mm", _scaled(1000)),
        [],
        ["row 2", "'height_mm'", "micrometres"],
    ),
    (
        "heights-in-metres",
        _column(GOOD, "height_mm", _scaled(0.001)),
        [],
        ["row 2", "'height_mm'", "metres"],
    ),
    ("force-in-kN", _column(GOOD, "force_N", _scaled(0.001)), [], ["row 39", "'force_N'", "kN"]),
    (
        "piston-in-m",
        _column(GOOD, "piston_mm", _scaled(0.001)),
        [],
        ["row 39", "'piston_mm'", "in m"],
    ),
    (
        "pressure-in-kPa",
        _column(GOOD, "pressure_bar", _scaled(100)),
        [],
        ["row 2", "'pressure_bar'", "kPa"],
    ),
    (
        "low-pressures-in-kPa",
        _column(
            write_recordings_csv(
                simulate("n50-traditional", seed=5, layout=Layout(pressures_bar=(0.1, 0.3)))
            ).splitlines(),
            "pressure_bar",
            _scaled(100),
        ),
        [],
        ["row 39", "unit slip"],
    ),
    ("x0-outside-heights", GOOD, ["--x0-mm", "40"], ["--x0-mm", "65..155"]),
    (
        "force-outlier-x10",
        _cell(GOOD, 47, "force_N", _scaled(10)),
        [],
        ["row 49", "'force_N'", "outlier"],
    ),
    (
        "force-outlier-x0.1",
        _cell(GOOD, 20, "force_N", _scaled(0.1)),
        [],
        ["row 22", "'force_N'", "outlier"],
    ),
    (
        "piston-outlier-x10",
        _cell(GOOD, 60, "piston_mm", _scaled(10)),
        [],
        ["row 62", "'piston_mm'", "outlier"],
    ),
    (
        "mistyped-height-named",
        _heights_down_up(GOOD, 2, "14.5"),
        [],
        ["row 4", "'height_mm'", "14.5 mm"],
    ),
    (
        "decimal-comma-in-csv",
        [GOOD[0]] + ['"1,5"' + GOOD[1][1:]] + GOOD[2:],
        [],
        ["row 2", "'pressure_bar'", "decimal comma"],
    ),
    (
        "extra-field-hint",
        GOOD[:5] + [GOOD[5].replace(".", ",", 1)] + GOOD[6:],
        [],
        ["row 6", "decimal comma"],
    ),
    ("step-gap-named", GOOD[:8] + GOOD[9:], [], ["row 9", "'step'", "step 7 is missing"]),
]


# ----------------------------------------------------------------------------- issue 21
# Real recordings: measured pressure, force-only stands, catalogue tables, units, signs. Each row
# of the issue's table has rows here (ISSUE_21_ROWS below says which) that either read (the
# tests after the table) or exit 2 with one line naming the place.


def _drop(lines, *cols):
    """The lines without the columns ``cols``."""
    keep = [i for i, c in enumerate(lines[0].split(",")) if c not in cols]
    return [",".join(ln.split(",")[i] for i in keep) for ln in lines]


def _rename(lines, old, new):
    return [",".join(new if c == old else c for c in lines[0].split(","))] + list(lines[1:])


def _measured(lines, sd_bar=0.01, seed=1, decimals=3):
    """Each reading's pressure as measured: set value + N(0, sd) (4.993, 5.004, ...)."""
    rng = np.random.default_rng(seed)
    return _column(
        lines, "pressure_bar", lambda t: f"{float(t) + rng.normal(0, sd_bar):.{decimals}f}"
    )


def _one_pass(lines):
    """A catalogue-like table: the compression branch only, without branch and step."""
    rows = [ln for ln in lines[1:] if ",compression," in ln]
    return _drop([lines[0]] + rows, "branch", "step")


def _with_set_pressure(lines):
    """set_pressure_bar added in front, the pressure column then read as measured."""
    return ["set_pressure_bar," + lines[0]] + [ln.split(",")[0] + "," + ln for ln in lines[1:]]


def _volume_from_piston(lines, top_l=4.2, area_cm2=54.82):
    """piston_mm replaced by the element's volume_l: V = V(top) - S (L - L(top)) (eq. 5)."""
    k = lines[0].split(",").index("piston_mm")
    out = [lines[0].replace("piston_mm", "volume_l")]
    top = {}
    for ln in lines[1:]:
        f = ln.split(",")
        L = float(f[k])
        top.setdefault(f[0], L)  # each test starts at its highest height
        f[k] = f"{top_l - area_cm2 * 1e-4 * (L - top[f[0]]):.4f}"
        out.append(",".join(f))
    return out


class Book(dict):
    """Sheets of a workbook to write: sheet name -> rows, each a CSV line or a list of cells
    (numbers written as numbers)."""


def _write_book(path, book: Book, engine="openpyxl"):
    import pandas as pd

    def cell(text):
        try:
            return float(text)
        except ValueError:
            return text

    with pd.ExcelWriter(path, engine=engine) as w:
        for name, lines in book.items():
            rows = [ln.split(",") if isinstance(ln, str) else ln for ln in lines]
            width = max(len(r) for r in rows)
            frame = pd.DataFrame([[cell(c) for c in r] + [None] * (width - len(r)) for r in rows])
            frame.to_excel(w, sheet_name=name, header=False, index=False)


ABSOLUTE = _column(GOOD, "pressure_bar", lambda t: f"{float(t) + 1.01325:g}")
NEGATIVE = _column(GOOD, "force_N", lambda t: f"{-float(t):.2f}")

RECORDINGS += [
    (
        "measured-pressure-too-spread",
        _measured(GOOD, sd_bar=0.1),
        [],
        ["'pressure_bar'", "--pressure-tolerance-bar", "set_pressure"],
    ),
    (
        "measured-pressure-cluster-too-small",
        _measured(GOOD[:3] + GOOD[38:]),
        [],
        ["row 2", "'pressure_bar'", "too few for a test", "set_pressure"],
    ),
    (
        "set-pressure-file-with-a-typo",
        _cell(GOOD, 40, "pressure_bar", lambda _: "5.05"),
        [],
        ["row 42", "'pressure_bar'", "5.05", "typo"],
    ),
    (
        "measured-far-from-set",
        _with_set_pressure(GOOD)[:41]
        + [_with_set_pressure(GOOD)[41].replace(",5,", ",6.013,", 1)]
        + _with_set_pressure(GOOD)[42:],
        [],
        ["row 42", "'pressure_bar'", "set_pressure_bar", "absolute"],
    ),
    (
        "piston-column-of-zeros",
        _column(GOOD, "piston_mm", lambda _: "0"),
        [],
        ["row 2", "'piston_mm'", "omit the piston_mm column"],
    ),
    (
        "catalogue-volume-on-some-rows",
        _rename(_drop(GOOD, "piston_mm"), "force_N", "force_N,volume_l")[:1]
        + [
            ",".join(ln.split(",")[:3] + (["4.2"] if i != 5 else [""]) + ln.split(",")[3:])
            for i, ln in enumerate(_drop(GOOD, "piston_mm")[1:])
        ],
        [],
        ["row 7", "'volume_l'", "on every row of a test"],
    ),
    (
        "catalogue-height-twice",
        _one_pass(GOOD)[:5] + [_one_pass(GOOD)[3]] + _one_pass(GOOD)[5:],
        [],
        ["row 6", "'height_mm'", "also row 4"],
    ),
    (
        "catalogue-volume-column-empty",
        [_drop(GOOD, "piston_mm")[0] + ",volume_l"]
        + [ln + "," for ln in _drop(GOOD, "piston_mm")[1:]],
        [],
        ["row 1", "'volume_l'", "the column is empty"],
    ),
    ("branch-without-step", _drop(GOOD, "step"), [], ["rec.csv", "'branch' without 'step'"]),
    ("piston-and-volume", [GOOD[0] + ",volume_l"] + GOOD[1:], [], ["piston_mm", "volume_l"]),
    (
        "compression-negative-undeclared",
        NEGATIVE,
        [],
        ["row 39", "'force_N'", "--compression negative"],
    ),
    (
        "compression-negative-declared-wrongly",
        GOOD,
        ["--compression", "negative"],
        ["row 39", "'force_N'", "--compression negative", "drop the option"],
    ),
    ("compression-option-unknown", GOOD, ["--compression", "down"], ["--compression"]),
    (
        "absolute-pressure-undeclared",
        ABSOLUTE,
        [],
        ["rec.csv", "'pressure_bar'", "--absolute-pressure"],
    ),
    (
        "absolute-pressure-in-a-single-test",  # no zero crossing: the areas disagree by p/(p+1)
        write_recordings_csv(
            [
                dict(t, pressure_bar=t["pressure_bar"] + 1.01325)
                for t in simulate("n50", seed=5, layout=Layout(pressures_bar=(2.0,)))
            ]
        ).splitlines(),
        [],
        ["row 2", "3.01325 bar test", "--absolute-pressure"],
    ),
    (
        "absolute-pressure-declared-on-gauge",
        GOOD,
        ["--absolute-pressure"],
        ["row 2", "'pressure_bar'", "--absolute-pressure"],
    ),
    (
        "psi-in-a-bar-column",
        _column(GOOD, "pressure_bar", _scaled(14.5038)),
        [],
        ["row 39", "'pressure_bar'", "psi"],
    ),
    (
        "unknown-unit",
        _rename(GOOD, "pressure_bar", "pressure_atm"),
        [],
        ["row 1", "'pressure_atm'", "unknown unit 'atm'", "pressure_psi"],
    ),
    (
        "unit-in-wrong-case",
        _rename(GOOD, "force_N", "force_n"),
        [],
        ["row 1", "'force_n'", "case-sensitive", "force_N"],
    ),
    (
        "two-units-for-one-quantity",
        [GOOD[0] + ",pressure_psi"] + [ln + ",14.5" for ln in GOOD[1:]],
        [],
        ["row 1", "pressure_bar", "pressure_psi", "keep one"],
    ),
    (
        "workbook-with-two-sheets-no-sheet-option",
        Book(Data=GOOD, Notes=["a,b"]),
        [],
        ["rec.xlsx", "'Data', 'Notes'", "--sheet"],
    ),
    ("workbook-unknown-sheet", Book(Data=GOOD), ["--sheet", "Daten"], ["--sheet", "'Data'"]),
    (
        "workbook-bad-cell",
        Book(
            Data=[
                ln.split(",") if i != 5 else ["1", "135", "12,5", "1", "compression", "4"]
                for i, ln in enumerate(GOOD)
            ]
        ),
        [],
        ["rec.xlsx, sheet 'Data', row 6", "'force_N'", "12,5"],
    ),
    ("sheet-option-on-csv", GOOD, ["--sheet", "Data"], ["--sheet", "not a workbook"]),
    ("excel-97-workbook", b"\xd0\xcf\x11\xe0" + bytes(100), [], ["rec.xls", ".xlsx"]),
    (
        "piston-area-20-cm2",
        GOOD,
        ["--piston-area-cm2", "20"],
        ["row 39", "--piston-area-cm2", "ratio 0.4"],
    ),
]

#: Every row of issue 21's table, and the rows above (or tests below) that cover it.
ISSUE_21_ROWS = {
    "measured overpressure per reading": [
        "measured-pressure-too-spread",
        "measured-pressure-cluster-too-small",
        "set-pressure-file-with-a-typo",
        "measured-far-from-set",
        "test_measured_pressures_are_clustered_into_tests",
        "test_set_pressure_column_groups_and_keeps_measured",
    ],
    "no piston column": [
        "piston-column-of-zeros",
        "test_force_only_campaign",
        "test_force_only_and_one_pass_tables_read",
        "test_a_command_that_needs_piston_readings_refuses_in_one_line",
    ],
    "catalogue data sheet": [
        "test_force_only_and_one_pass_tables_read",
        "catalogue-volume-on-some-rows",
        "catalogue-volume-column-empty",
        "catalogue-height-twice",
        "branch-without-step",
        "piston-and-volume",
        "test_catalogue_table_reads",
    ],
    "compression recorded negative": [
        "compression-negative-undeclared",
        "compression-negative-declared-wrongly",
        "compression-option-unknown",
        "test_declared_conventions_read_as_the_paper_format",
    ],
    "absolute pressure in the gauge column": [
        "absolute-pressure-undeclared",
        "absolute-pressure-in-a-single-test",
        "absolute-pressure-declared-on-gauge",
        "test_declared_conventions_read_as_the_paper_format",
    ],
    "psi, in, lbf, in^3": [
        "psi-in-a-bar-column",
        "unknown-unit",
        "unit-in-wrong-case",
        "two-units-for-one-quantity",
        "test_units_from_column_suffixes",
    ],
    "an .xlsx file": [
        "workbook-with-two-sheets-no-sheet-option",
        "workbook-unknown-sheet",
        "workbook-bad-cell",
        "sheet-option-on-csv",
        "excel-97-workbook",
        "test_workbooks_read_like_csv",
    ],
    "0.01-0.02 mm steps": ["test_fine_steps_are_accepted"],
    "only the compression branch": ["test_compression_branch_only"],
    "--piston-area-cm2 20": [
        "piston-area-20-cm2",
        "test_piston_area_within_what_a_casing_explains",
    ],
}


def test_every_row_of_issue_21_is_covered():
    ids = {r[0] for r in RECORDINGS} | {n for n in globals() if n.startswith("test_")}
    for row, covered_by in ISSUE_21_ROWS.items():
        assert covered_by and set(covered_by) <= ids, (row, set(covered_by) - ids)


def _write_input(tmp_path, content):
    if isinstance(content, Book):
        path = tmp_path / "rec.xlsx"
        _write_book(path, content)
    elif isinstance(content, bytes):
        path = tmp_path / "rec.xls"
        path.write_bytes(content)
    else:
        path = tmp_path / "rec.csv"
        path.write_text("\n".join(content) + "\n")
    return path


@pytest.mark.parametrize(
    "lines, options, names", [r[1:] for r in RECORDINGS], ids=[r[0] for r in RECORDINGS]
)
def test_bad_recordings_exit_2_one_line_nothing_written(tmp_path, capsys, lines, options, names):
    csv = _write_input(tmp_path, lines)
    out = tmp_path / "out"
    status = _run(
        [
            "fit",
            str(csv),
            "--json",
            str(out / "fit.json"),
            "--max-steps",
            "400",
            "--allow-unconverged",
            *options,
        ]
    )
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert status == 2, err
    assert err.count("\n") == 0 and err.startswith("uq fit: error:")
    assert csv.name in err or names[0].startswith("--")
    for name in names:
        assert name in err, (name, err)
    assert not out.exists()


# ----------------------------------------------------------------------------- issue 21: what reads


def _text(lines) -> str:
    return "\n".join(lines) + "\n"


def _from_lines(lines, **kw):
    from uq._data.recordings import recordings_from_text

    return recordings_from_text(_text(lines), "rec.csv", **kw)


def test_measured_pressures_are_clustered_into_tests():
    ref = _reference()
    lines = _measured(GOOD)
    rec = _from_lines(lines)
    assert [t.pressure_bar for t in rec.tests] == [1.0, 5.0] and rec.pressure_measured
    written = [float(ln.split(",")[0]) for ln in lines[1:]]
    assert np.array_equal(np.concatenate([t.measured_pressure_bar for t in rec.tests]), written)
    assert _same(rec, ref)
    # the paper's format: one value per test, measured equals set, nothing clustered
    assert not ref.pressure_measured
    assert all(
        np.array_equal(t.measured_pressure_bar, np.full(37, t.pressure_bar)) for t in ref.tests
    )
    with pytest.raises(InputError, match="too few for a test.*--pressure-tolerance-bar"):
        _from_lines(lines, pressure_tolerance_bar=0.001)


def test_set_value_of_a_cluster_is_its_median_rounded_as_set_points_are_written():
    from uq._data.pressure_groups import set_value_bar

    rng = np.random.default_rng(0)
    assert set_value_bar(5.0 + rng.normal(0, 0.01, 37)) == 5.0
    assert set_value_bar(2.5 + rng.normal(0, 0.01, 37)) == 2.5
    assert set_value_bar(1.02 + rng.normal(0, 0.001, 37)) == 1.02
    psi = 0.0689475729316836
    assert set_value_bar((80 + rng.normal(0, 0.1, 37)) * psi, psi) == pytest.approx(
        80 * psi, rel=1e-12
    )


def test_set_pressure_column_groups_and_keeps_measured():
    measured = _measured(GOOD, decimals=5)
    lines = ["set_pressure_bar," + GOOD[0]] + [
        g.split(",")[0] + "," + m for g, m in zip(GOOD[1:], measured[1:], strict=True)
    ]
    rec = _from_lines(lines)
    assert [t.pressure_bar for t in rec.tests] == [1.0, 5.0] and rec.pressure_measured
    assert rec.units["set_pressure"] == "bar"
    measured = np.concatenate([t.measured_pressure_bar for t in rec.tests])
    assert np.array_equal(measured, [float(ln.split(",")[1]) for ln in lines[1:]])
    assert np.abs(measured - np.repeat([1.0, 5.0], 37)).max() < 0.05
    assert _same(rec, _reference())


def test_force_only_campaign():
    from uq._data.recordings import require

    rec = _from_lines(_drop(GOOD, "piston_mm"))
    ref = _reference()
    assert all(t.piston_m is None for t in rec.tests)
    assert not rec.has_volume and not rec.has_piston and rec.order_known
    assert all(
        np.array_equal(a.force_N, b.force_N) for a, b in zip(rec.tests, ref.tests, strict=True)
    )
    require(rec, {"order"})  # what a force-side command will ask for
    with pytest.raises(InputError, match="force-only campaign: this command needs piston_"):
        require(rec, {"piston"})


def test_a_command_that_needs_piston_readings_refuses_in_one_line(tmp_path, capsys):
    import argparse

    from uq._cli.common import load

    path = tmp_path / "rec.csv"
    path.write_text(_text(_drop(GOOD, "piston_mm")))
    # uq design with a model of the volume needs piston readings; every other use takes the file
    argv = ["design", str(path), "--height-mm", "112", "--charge-bar", "5", "--volume-l", "3.4"]
    assert _run([*argv, "--model", "thermodynamic"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith(f"uq design: error: {path}: force-only")
    args = argparse.Namespace(file=str(path), piston_area_cm2=54.82, x0_mm=112.0, _name="surface")
    with pytest.raises(InputError, match="force-only"):
        load(args, needs=("piston", "order"))
    assert load(args).n_points == 74 and not load(args).has_volume


@pytest.mark.parametrize(
    "lines, has_volume",
    [
        (_drop(GOOD, "piston_mm"), False),
        (_one_pass(GOOD), True),
        (_volume_from_piston(_one_pass(GOOD)), True),
    ],
    ids=["no-piston-column", "catalogue-one-pass", "catalogue-with-volume"],
)
def test_force_only_and_one_pass_tables_read(lines, has_volume):
    """Every command takes them (fitted in tests/cli/test_force_only_commands.py and
    tests/cli/test_surface_catalogue.py)."""
    assert _from_lines(lines).has_volume == has_volume


def test_catalogue_table_reads():
    lines = _volume_from_piston(_one_pass(GOOD))
    lines = [ln if not ln.startswith("1,") else ln.rsplit(",", 1)[0] + "," for ln in lines]
    rec = _from_lines(lines)
    assert not rec.order_known and rec.has_volume and not rec.has_piston
    low, high = rec.tests
    assert low.compression is None and low.step is None and low.volume_m3 is None
    assert np.all(np.diff(high.height_m) < 0) and high.n_points == 19
    assert high.volume_m3[0] == pytest.approx(4.2e-3) and np.all(np.diff(high.volume_m3) < 0)
    assert rec.units["volume"] == "l"
    ref = _reference().tests[1]
    comp = ref.compression
    assert np.array_equal(high.force_N, ref.force_N[comp])


def test_declared_conventions_read_as_the_paper_format():
    ref = _reference()
    neg = _from_lines(NEGATIVE, compression="negative")
    assert _same(neg, ref) and neg.conventions["compression"] == "negative"
    absolute = _from_lines(ABSOLUTE, absolute_pressure=True)
    assert [t.pressure_bar for t in absolute.tests] == [1.0, 5.0] and _same(absolute, ref)
    assert absolute.conventions == {
        "compression": "positive",
        "pressure": "absolute",
        "p_atm_bar": 1.01325,
    }
    assert ref.conventions == {"compression": "positive", "pressure": "gauge"}


def test_units_from_column_suffixes():
    from uq._data import units

    # the units' definitions to 15 digits (pint's factors before): the paper's units read bit for bit as before
    assert units.factor("height", "mm") == 1e-3 and units.factor("volume", "l") == 1e-3
    assert (
        units.factor("height", "in") == 0.0254 and units.factor("force", "lbf") == 4.4482216152605
    )
    tests = simulate("n50", seed=5, layout=Layout(pressures_bar=(1.0, 5.0)))
    us = {"pressure": "psi", "height": "in", "force": "lbf"}
    text = write_recordings_csv(tests, units=us)
    assert text.splitlines()[0] == "pressure_psi,height_in,force_lbf,piston_in,branch,step"
    from uq._data.recordings import recordings_from_text

    rec = recordings_from_text(text, "us.csv")
    ref = _reference()
    assert rec.units == {"pressure": "psi", "height": "in", "force": "lbf", "piston": "in"}
    assert [t.pressure_bar for t in rec.tests] == [1.0, 5.0]
    for a, b in zip(rec.tests, ref.tests, strict=True):
        assert np.allclose(a.height_m, b.height_m, atol=0.5e-5 * 0.0254)  # printed to 1e-5 in
        assert np.allclose(a.force_N, b.force_N, atol=0.5e-3 * 4.45 + 0.005)  # 1e-3 lbf, 0.01 N
        assert np.allclose(a.piston_m, b.piston_m, atol=0.5e-5 * 0.0254 + 0.5e-6)
    for q, u in (("pressure", "kPa"), ("pressure", "MPa"), ("pressure", "mbar"), ("force", "kN")):
        other = recordings_from_text(write_recordings_csv(tests, units={q: u}), "o.csv")
        assert [t.pressure_bar for t in other.tests] == [1.0, 5.0] and other.units[q] == u


def test_workbooks_read_like_csv(tmp_path):
    ref = _reference()
    lines = ["# made on the stand", "# operator: a. n. other"] + GOOD
    for engine, suffix in (("openpyxl", "xlsx"), ("odf", "ods")):
        path = tmp_path / f"rec.{suffix}"
        _write_book(path, Book(Data=lines), engine)
        rec = read_recordings(path)
        assert _same(rec, ref) and rec.sheet == "Data"
        assert rec.comments == ("made on the stand", "operator: a. n. other")
        assert rec.tests[0].rows[0] == 4  # the sheet's row: two comments, the header, then data
        _write_book(path, Book(Notes=["a,b"], Data=lines), engine)
        assert _same(read_recordings(path, sheet="Data"), ref)
        bad = _cell(GOOD, 2, "force_N", lambda _: "x")
        _write_book(path, Book(Data=["# note"] + bad), engine)
        with pytest.raises(
            InputError, match=rf"rec.{suffix}, sheet 'Data', row 5, column 'force_N'"
        ):
            read_recordings(path)


def test_fine_steps_are_accepted(tmp_path):
    for step in (0.01e-3, 0.02e-3):
        tests = simulate("n50", seed=5, layout=Layout(pressures_bar=(5.0,), step_m=step))
        rec = _from_lines(write_recordings_csv(tests).splitlines())
        assert rec.n_points == 2 * round(0.09 / step) + 1


def test_compression_branch_only():
    lines = [GOOD[0]] + [ln for ln in GOOD[1:] if ",compression," in ln]
    rec = _from_lines(lines)
    assert rec.order_known and not rec.has_both_branches and rec.tests[0].compression.all()
    assert _reference().has_both_branches


@pytest.mark.parametrize(
    "area, ok", [(30, False), (40, True), (54.82, True), (70, True), (80, False)]
)
def test_piston_area_within_what_a_casing_explains(area, ok):
    # the paper's spring: S|dL/dx| / (P/p_u) = 1.12 at 5 bar with S = 54.82 cm^2; 0.67..1.5 allowed
    if ok:
        assert _from_lines(GOOD, piston_area_cm2=area).piston_area_m2 == pytest.approx(area * 1e-4)
    else:
        with pytest.raises(InputError, match="--piston-area-cm2"):
            _from_lines(GOOD, piston_area_cm2=area)


def test_low_pressure_campaigns_keep_the_unit_slip_bound():
    # below 1 bar the casing's force rivals p_u F_eff: only a factor 4 is refused there
    tests = simulate("n50", seed=5, layout=Layout(pressures_bar=(0.1, 0.3)))
    assert _from_lines(write_recordings_csv(tests).splitlines(), piston_area_cm2=80).n_points == 74


def test_zero_force_pressure_separates_gauge_from_absolute():
    from uq._data.checks import zero_force_pressure_bar

    for pressures in ((1.0, 5.0), (3.0, 4.0, 5.0, 6.0, 7.0), (0.5, 1.5, 2.5), (2.0, 6.0, 10.0)):
        for effects in ({}, {"casing_force": 200.0}, {"pressure_dependent_area": 0.01}):
            tests = simulate("n50", seed=1, effects=effects, layout=Layout(pressures_bar=pressures))
            rec = _from_lines(write_recordings_csv(tests, piston=False).splitlines())
            p0 = zero_force_pressure_bar(rec.tests)
            assert abs(p0) < 0.4, (pressures, effects, p0)
            shifted = [dict(t, pressure_bar=t["pressure_bar"] + 1.01325) for t in tests]
            text = write_recordings_csv(shifted, piston=False).splitlines()
            with pytest.raises(InputError, match="`absolute_pressure`"):
                _from_lines(text)


OPTIONS = [
    ("simulate-step-0", ["simulate", "--out", "{tmp}/r.csv", "--step-mm", "0"], "--step-mm"),
    ("simulate-step-tiny", ["simulate", "--out", "{tmp}/r.csv", "--step-mm", "1e-9"], "--step-mm"),
    ("simulate-out-folder", ["simulate", "--out", "{tmp}"], "--out"),
]


@pytest.mark.parametrize("argv, names", [r[1:] for r in OPTIONS], ids=[r[0] for r in OPTIONS])
def test_bad_options_exit_2_one_line_nothing_written(tmp_path, capsys, argv, names):
    before = sorted(os.listdir(tmp_path))
    status = _run([a.replace("{tmp}", str(tmp_path)) for a in argv])
    err = capsys.readouterr().err.strip()
    assert status == 2 and err.count("\n") == 0 and names in err, err
    assert sorted(os.listdir(tmp_path)) == before


@pytest.mark.parametrize(
    "layout",
    [
        dict(step_m=0.0),
        dict(step_m=float("nan")),
        dict(step_m=1e-12),
        dict(x_min_m=0.2),
        dict(pressures_bar=()),
    ],
)
def test_layout_refuses_what_it_cannot_step(layout):
    with pytest.raises(InputError):
        Layout(**layout)


# ----------------------------------------------------------------------------- reading


def _read(tmp_path, data: bytes, **kw):
    p = tmp_path / "rec.csv"
    p.write_bytes(data)
    return read_recordings(p, **kw)


def _reference():
    return read_recordings_text("\n".join(GOOD) + "\n")


def read_recordings_text(text, tmp=None):
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        p = os.path.join(d, "r.csv")
        with open(p, "w", encoding="utf-8") as fh:
            fh.write(text)
        return read_recordings(p)


def _same(a, b):
    return all(
        np.array_equal(getattr(x, k), getattr(y, k))
        for x, y in zip(a.tests, b.tests, strict=True)
        for k in ("height_m", "force_N", "piston_m", "compression", "step")
    )


def test_utf8_bom_is_read(tmp_path):
    ref = _reference()
    rec = _read(tmp_path, b"\xef\xbb\xbf" + ("\r\n".join(GOOD) + "\r\n").encode())
    assert _same(rec, ref)


def test_utf16_with_bom_is_read(tmp_path):
    rec = _read(tmp_path, ("\r\n".join(GOOD) + "\r\n").encode("utf-16"))
    assert _same(rec, _reference())


@pytest.mark.parametrize("sep", [";", "\t"])
def test_semicolon_and_tab_delimiters_with_decimal_comma(tmp_path, sep):
    lines = [ln.replace(",", sep) for ln in GOOD]
    assert _same(_read(tmp_path, ("\n".join(lines) + "\n").encode()), _reference())
    comma = [lines[0]] + [ln.replace(".", ",") for ln in lines[1:]]
    assert _same(_read(tmp_path, ("\n".join(comma) + "\n").encode()), _reference())


def test_decimal_comma_and_point_mixed_is_refused(tmp_path):
    lines = [ln.replace(",", ";") for ln in GOOD]
    lines = [lines[0]] + [ln.replace(".", ",") for ln in lines[1:]]
    lines[4] = lines[4].replace("1;", "1.0;", 1)  # a point among commas: thousands separator?
    with pytest.raises(InputError, match="row 5, column 'pressure_bar'.*thousands"):
        _read(tmp_path, ("\n".join(lines) + "\n").encode())


def test_rows_are_file_lines_with_comments_bom_and_crlf(tmp_path):
    lines = ["# comment", "", GOOD[0], "# between"] + _cell(GOOD, 4, "force_N", lambda _: "x")[1:]
    data = b"\xef\xbb\xbf" + "\r\n".join(lines).encode()
    # data row 4 (0-based) follows the header (line 3) and the comment on line 4: file line 9
    with pytest.raises(InputError, match=r"rec.csv, row 9, column 'force_N': 'x' is not a number"):
        _read(tmp_path, data)


def test_non_utf8_byte_names_its_row(tmp_path):
    data = (
        ("\n".join(GOOD[:6]) + "\n").encode()
        + b"# Pr\xfcfstand\n"
        + ("\n".join(GOOD[6:]) + "\n").encode()
    )
    with pytest.raises(InputError, match="row 7: not UTF-8"):
        _read(tmp_path, data)


def test_short_row_and_quoted_fields(tmp_path):
    lines = list(GOOD)
    lines[7] = lines[7].rsplit(",", 1)[0]
    with pytest.raises(InputError, match="row 8: expected 6 fields .* found 5"):
        _read(tmp_path, ("\n".join(lines) + "\n").encode())
    quoted = [GOOD[0]] + ['"' + ln.replace(",", '","') + '"' for ln in GOOD[1:]]
    assert _same(_read(tmp_path, ("\n".join(quoted) + "\n").encode()), _reference())


def test_x0_inside_the_heights_is_accepted(tmp_path):
    rec = _read(tmp_path, ("\n".join(GOOD) + "\n").encode(), x0_mm=65.0)
    assert rec.x0_m == pytest.approx(0.065)


# ----------------------------------------------------------------------------- writing


def test_new_files_respect_the_umask_and_replaced_files_keep_their_mode(tmp_path):
    old = os.umask(0o022)
    try:
        p = write_text_atomic(tmp_path / "new.json", "{}")
        assert stat.S_IMODE(p.stat().st_mode) == 0o644
        os.umask(0o027)
        assert (
            stat.S_IMODE(write_text_atomic(tmp_path / "other.json", "{}").stat().st_mode) == 0o640
        )
        p.chmod(0o664)
        write_text_atomic(p, "[]")
        assert stat.S_IMODE(p.stat().st_mode) == 0o664 and p.read_text() == "[]"
    finally:
        os.umask(old)


def test_simulate_output_is_0644(tmp_path, capsys):
    old = os.umask(0o022)
    try:
        assert main(["simulate", "--out", str(tmp_path / "r.csv"), "--pressures", "1"]) == 0
    finally:
        os.umask(old)
    assert stat.S_IMODE((tmp_path / "r.csv").stat().st_mode) == 0o644


def test_symbolic_link_is_not_replaced(tmp_path):
    target = tmp_path / "real.json"
    target.write_text("keep")
    link = tmp_path / "link.json"
    link.symlink_to(target)
    with pytest.raises(InputError, match="link.json.*symbolic link"):
        write_text_atomic(link, "new")
    assert link.is_symlink() and target.read_text() == "keep"
    dangling = tmp_path / "dangling.json"
    dangling.symlink_to(tmp_path / "nowhere.json")
    with pytest.raises(InputError, match="symbolic link"):
        write_text_atomic(dangling, "new")
    assert not (tmp_path / "nowhere.json").exists()


def test_device_is_written_to_not_replaced(monkeypatch):
    real_replace = os.replace

    def guarded(
        src, dst, *a, **kw
    ):  # a broken writer must fail this test, not replace the machine's /dev/null
        if os.path.realpath(dst) == os.path.realpath(os.devnull):
            raise AssertionError("tried to replace /dev/null")
        return real_replace(src, dst, *a, **kw)

    monkeypatch.setattr(os, "replace", guarded)
    before = os.stat(os.devnull)
    write_text_atomic(os.devnull, "discarded")
    after = os.stat(os.devnull)
    assert stat.S_ISCHR(after.st_mode) and (after.st_ino, after.st_rdev) == (
        before.st_ino,
        before.st_rdev,
    )


def test_pipe_is_written_to_not_replaced(tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    # The reading end is opened first, without blocking, so the writer's open cannot wait for a
    # partner (a reader thread could hang the suite if it was scheduled late); the text fits
    # in the pipe's buffer, so the write returns before anything is read.
    rd = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)
    try:
        write_text_atomic(fifo, "through the pipe")
        got = os.read(rd, 1024)
    finally:
        os.close(rd)
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode) and got == b"through the pipe"


@pytest.mark.parametrize(
    "where, expect",
    [
        ("{tmp}", "is a folder"),
        ("{tmp}/file.txt/out.json", "is a file, not a folder"),
        ("/proc/uq-test/out.json", "cannot create the folder"),
    ],
)
def test_unwritable_targets_are_input_errors_naming_the_path(tmp_path, where, expect):
    (tmp_path / "file.txt").write_text("x")
    path = where.replace("{tmp}", str(tmp_path))
    with pytest.raises(InputError, match=expect) as exc:
        write_text_atomic(path, "{}")
    assert path in str(exc.value)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file.txt"]


def test_remove_stale_keeps_the_users_files(tmp_path):
    for name in ("fig2_force.png", "test_3bar.png", "test_5bar.png", "holiday.png", "notes.txt"):
        (tmp_path / name).write_bytes(b"x")
    (tmp_path / "test_9bar.png").symlink_to(tmp_path / "holiday.png")
    removed = remove_stale(
        tmp_path, ("fig2_*.png", "test_*bar.png"), keep={"fig2_force.png", "test_5bar.png"}
    )
    assert [p.name for p in removed] == ["test_3bar.png"]
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "fig2_force.png",
        "holiday.png",
        "notes.txt",
        "test_5bar.png",
        "test_9bar.png",
    ]


def test_report_removes_stale_figures_of_an_earlier_run(small_cubics, tmp_path):
    """The shared small campaign's fit (tests/conftest.py: 1, 3, 5, 8 bar), reported over a folder
    holding an earlier run's figures of other tests and a file of the user's."""
    from uq._derived.bands import campaign_bands
    from uq._report.campaign import write_report

    fit = small_cubics
    out = tmp_path / "rep"
    out.mkdir()
    for name in ("test_7bar.png", "surface_spread.png", "surface.html", "my_photo.png"):
        (out / name).write_bytes(b"old")
    write_report(fit, out, bands=campaign_bands(fit, n_draws=100, seed=0))
    names = sorted(p.name for p in out.iterdir())
    assert "test_3bar.png" in names and "my_photo.png" in names
    assert not {"test_7bar.png", "surface_spread.png", "surface.html"} & set(names)


# ----------------------------------------------------------------------------- options elsewhere


def test_fit_definition_and_batch_take_the_reading_options(tmp_path):
    from uq._cli.cmd_basic import read_fit_config
    from uq._drivers import batch

    (tmp_path / "rec.csv").write_text(_text(NEGATIVE))
    toml = tmp_path / "fit.toml"
    toml.write_text(
        '[data]\nrecordings = "rec.csv"\ncompression = "negative"\nabsolute_pressure = false\n'
        'pressure_tolerance_bar = 0.02\nsheet = "Data"\n'
    )
    values = read_fit_config(toml)
    assert values["compression"] == "negative" and values["absolute_pressure"] is False
    assert values["pressure_tolerance_bar"] == 0.02 and values["sheet"] == "Data"
    toml.write_text('[data]\ncompression = "down"\n')
    with pytest.raises(InputError, match="compression: expected positive or negative"):
        read_fit_config(toml)

    entry = {"file": "rec.csv", "tasks": "fit", "compression": "negative"}
    c = batch._campaign(entry, tmp_path, "cat.csv, row 2")
    assert c.options == {"compression": "negative"}
    job = {"file": str(c.file), "options": c.options, "task": "fit"}
    assert _same(batch._recordings(job), _reference())
    (tmp_path / "fo.csv").write_text(_text(_drop(GOOD, "piston_mm")))
    for task in ("fit", "surface"):  # each task reads what its command takes: force-only too
        fo = {"file": str(tmp_path / "fo.csv"), "options": {}, "task": task}
        assert not batch._recordings(fo).has_volume
    with pytest.raises(InputError, match="column 'absolute_pressure': expected true or false"):
        batch._campaign(entry | {"absolute_pressure": "maybe"}, tmp_path, "cat.csv, row 2")
