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


@pytest.mark.parametrize(
    "lines, options, names", [r[1:] for r in RECORDINGS], ids=[r[0] for r in RECORDINGS]
)
def test_bad_recordings_exit_2_one_line_nothing_written(tmp_path, capsys, lines, options, names):
    csv = tmp_path / "rec.csv"
    csv.write_text("\n".join(lines) + "\n")
    out = tmp_path / "out"
    status = _run(
        ["fit", str(csv), "--json", str(out / "fit.json"), "--max-steps", "400", *options]
    )
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert status == 2, err
    assert err.count("\n") == 0 and err.startswith("uq fit: error:")
    assert "rec.csv" in err or names[0].startswith("--")
    for name in names:
        assert name in err, (name, err)
    assert not out.exists()


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


def test_report_removes_stale_figures_of_an_earlier_run(tmp_path):
    from uq._derived.bands import campaign_bands
    from uq._inference.sampler import Settings
    from uq._models.cubic import fit_campaign
    from uq._report.campaign import write_report

    csv = tmp_path / "r.csv"
    csv.write_text(
        write_recordings_csv(simulate("n50", seed=2, layout=Layout(pressures_bar=(3.0,))))
    )
    fit = fit_campaign(
        read_recordings(csv), seed=1, settings=Settings(n_walkers=8, n_ensembles=2, max_steps=400)
    )
    out = tmp_path / "rep"
    out.mkdir()
    for name in ("test_7bar.png", "surface_spread.png", "surface.html", "my_photo.png"):
        (out / name).write_bytes(b"old")
    write_report(fit, out, bands=campaign_bands(fit, n_draws=100, seed=0))
    names = sorted(p.name for p in out.iterdir())
    assert "test_3bar.png" in names and "my_photo.png" in names
    assert not {"test_7bar.png", "surface_spread.png", "surface.html"} & set(names)
