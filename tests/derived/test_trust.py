"""Trust: corrupted inputs never crash or drop rows silently; outputs are atomic."""

from __future__ import annotations

import os

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from uq._data.recordings import read_recordings, write_recordings_csv
from uq._io.errors import InputError
from uq._io.files import write_text_atomic
from uq._stand.simulator import Layout, simulate

VALID = write_recordings_csv(
    simulate("n50", seed=4, layout=Layout(pressures_bar=(1.0, 4.0)))
).splitlines()
N_ROWS = len(VALID) - 1

corruptions = st.one_of(
    st.tuples(
        st.just("cell"),
        st.integers(1, N_ROWS),
        st.integers(0, 5),
        st.sampled_from(
            ["", "abc", "nan", "inf", "-", "1e999", "0x10", "1,2", " ", "NaN", "--5", "1.2.3"]
        ),
    ),
    st.tuples(st.just("drop_field"), st.integers(1, N_ROWS), st.integers(0, 5), st.just("")),
    st.tuples(st.just("duplicate"), st.integers(1, N_ROWS), st.just(0), st.just("")),
    st.tuples(st.just("delete"), st.integers(1, N_ROWS), st.just(0), st.just("")),
    st.tuples(
        st.just("header"),
        st.just(0),
        st.integers(0, 5),
        st.sampled_from(["", "Force_N", "height_m", "x"]),
    ),
    st.tuples(st.just("truncate"), st.integers(0, N_ROWS), st.just(0), st.just("")),
)


def _apply(lines: list[str], kind: str, row: int, col: int, text: str) -> list[str]:
    lines = list(lines)
    if not lines:
        return lines
    row = min(row, len(lines) - 1)
    col = min(col, len(lines[row].split(",")) - 1)
    if kind == "cell":
        f = lines[row].split(",")
        f[col] = text
        lines[row] = ",".join(f)
    elif kind == "drop_field":
        f = lines[row].split(",")
        del f[col]
        lines[row] = ",".join(f)
    elif kind == "duplicate":
        lines.insert(row + 1, lines[row])
    elif kind == "delete":
        del lines[row]
    elif kind == "header":
        f = lines[0].split(",")
        f[col] = text
        lines[0] = ",".join(f)
    elif kind == "truncate":
        lines = lines[: row + 1]
        if row < N_ROWS and lines:
            lines[-1] = lines[-1][: len(lines[-1]) // 2]
    return lines


@settings(
    max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(corruption=st.lists(corruptions, min_size=1, max_size=3))
def test_corrupted_files_fail_with_one_line_or_keep_every_row(tmp_path_factory, corruption):
    lines = VALID
    for c in corruption:
        lines = _apply(lines, *c)
    path = tmp_path_factory.mktemp("h") / "r.csv"
    path.write_text("\n".join(lines) + "\n")
    try:
        rec = read_recordings(path)
    except InputError as exc:
        msg = str(exc)
        assert "\n" not in msg and str(path) in msg
        return
    # Accepted: then every data row must be in it (nothing dropped silently).
    data_rows = [ln for ln in lines[1:] if ln.strip() and not ln.startswith("#")]
    assert rec.n_points == len(data_rows)


def test_atomic_write_leaves_no_partial_file(tmp_path, monkeypatch):
    target = tmp_path / "result.json"
    write_text_atomic(target, "old")

    def boom(fd):
        raise OSError("disk full")

    monkeypatch.setattr(os, "fsync", boom)
    with pytest.raises(OSError):
        write_text_atomic(target, "new content that must not appear half-written")
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["result.json"]


def test_interrupted_report_leaves_no_partial_files(tmp_path, monkeypatch):
    """A failure mid-way through writing figures leaves no half-written or temp files."""
    import uq._io.files as io

    calls = {"n": 0}
    real = io.write_bytes_atomic

    def flaky(path, data):
        calls["n"] += 1
        if calls["n"] == 3:
            raise KeyboardInterrupt
        return real(path, data)

    monkeypatch.setattr(io, "write_bytes_atomic", flaky)
    with pytest.raises(KeyboardInterrupt):
        for i in range(5):
            io.write_text_atomic(tmp_path / f"f{i}.txt", "x" * 1000)
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["f0.txt", "f1.txt"]
    assert all((tmp_path / n).read_text() == "x" * 1000 for n in names)


def test_reading_is_deterministic():
    a = read_recordings_from_lines(VALID)
    b = read_recordings_from_lines(VALID)
    assert all(np.array_equal(x.force_N, y.force_N) for x, y in zip(a.tests, b.tests, strict=True))


def read_recordings_from_lines(lines):
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        p = os.path.join(d, "r.csv")
        with open(p, "w") as fh:
            fh.write("\n".join(lines) + "\n")
        return read_recordings(p)


@settings(max_examples=40, deadline=None)
@given(
    sep=st.sampled_from([",", ";", "\t"]),
    bom=st.booleans(),
    crlf=st.booleans(),
    comma=st.booleans(),
    order=st.permutations(range(6)),
    extra=st.booleans(),
)
def test_same_recordings_in_any_spreadsheet_dialect_read_the_same(
    sep, bom, crlf, comma, order, extra
):
    """BOM, ';' or tab with decimal commas, CRLF, column order, extra columns: the same numbers."""
    rows = [ln.split(",") for ln in VALID]
    out = []
    for i, f in enumerate(rows):
        cells = [f[k] for k in order] + (["operator" if i == 0 else "anna"] if extra else [])
        if comma and sep != "," and i > 0:
            cells = [c.replace(".", ",") for c in cells]
        out.append(sep.join(cells))
    data = ("\r\n" if crlf else "\n").join(["# made by a spreadsheet", *out]) + "\n"
    import tempfile

    with tempfile.TemporaryDirectory() as d:
        p = os.path.join(d, "r.csv")
        with open(p, "wb") as fh:
            fh.write((b"\xef\xbb\xbf" if bom else b"") + data.encode())
        rec = read_recordings(p)
    ref = read_recordings_from_lines(VALID)
    assert rec.extra_columns == (("operator",) if extra else ())
    for a, b in zip(rec.tests, ref.tests, strict=True):
        assert a.pressure_bar == b.pressure_bar and np.array_equal(a.rows, b.rows + 1)
        for k in ("height_m", "force_N", "piston_m", "compression", "step"):
            assert np.array_equal(getattr(a, k), getattr(b, k)), k
