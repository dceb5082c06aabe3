"""Margins from a saved fit (``uq margin --save-fit`` / ``--fit`` / ``--queries``, ``uq surface --out``).

One small simulated campaign (6 tests, 15 mm steps) is fitted three times with short chains: the
surface model and the per-pressure cubics through ``uq margin --save-fit``, and the surface model
through ``uq surface --out``. Everything else answers from the saved files, without a refit.
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path

import numpy as np
import pytest
from cli_helpers import one_line, run

QUICK = ["--ensembles", "2", "--max-steps", "200", "--quiet", "--allow-unconverged"]
#: answers from a saved fit made with QUICK's short chains: they say so, and exit 0 only when asked
UNCONV = ["--quiet", "--allow-unconverged"]
QUERY = ["--height-mm", "110", "--load-N", "8000", "--pressure-bar", "5", "--tolerance-pct", "5"]


def assert_same(a, b, path="result"):
    """Same JSON shape and the same numbers to floating-point tolerance (in practice they are identical)."""
    assert type(a) is type(b), path
    if isinstance(a, dict):
        assert list(a) == list(b), path
        for k in a:
            assert_same(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, list):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_same(x, y, f"{path}[{i}]")
    elif isinstance(a, float):
        assert a == pytest.approx(b, rel=1e-12, abs=1e-15), path
    else:
        assert a == b, path


@pytest.fixture(scope="module")
def campaign(tmp_path_factory):
    d = tmp_path_factory.mktemp("saved")
    csv = d / "r.csv"
    assert (
        run(
            [
                "simulate",
                "--out",
                csv,
                "--pressures",
                "1,2,4,6,8,10",
                "--step-mm",
                "15",
                "--seed",
                "3",
            ]
        )
        == 0
    )
    return d, csv


def _fit_and_save(d: Path, csv: Path, model: str, walkers: int):
    """``uq margin --model MODEL --save-fit``; returns (saved file, the run's JSON, the SurfaceFit it made or None)."""
    import uq._models.surface_likelihood

    fit, out = d / f"{model}.nc", d / f"{model}.json"
    argv = [
        "margin",
        csv,
        *QUERY,
        "--model",
        model,
        "--walkers",
        walkers,
        *QUICK,
        "--save-fit",
        fit,
        "--json",
        out,
    ]
    made = []
    real = uq._models.surface_likelihood.fit_surface
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(
            uq._models.surface_likelihood,
            "fit_surface",
            lambda *a, **k: made.append(real(*a, **k)) or made[-1],
        )
        assert run(argv) == 0
    return fit, json.loads(out.read_text()), (made or [None])[0]


@pytest.fixture(scope="module")
def surface_saved(campaign):
    return _fit_and_save(
        *campaign, "surface", 12
    )  # 5 sampled noise parameters: >= 10 walkers, a multiple of 4


@pytest.fixture(scope="module")
def cubics_saved(campaign):
    return _fit_and_save(*campaign, "cubics", 8)


@pytest.mark.parametrize("which", ["surface_saved", "cubics_saved"])
def test_saved_fit_gives_the_same_answer(which, request, tmp_path, capsys):
    fit, original, _ = request.getfixturevalue(which)
    out = tmp_path / "again.json"
    assert run(["margin", "--fit", fit, *QUERY, "--json", out, *UNCONV]) == 0
    assert_same(json.loads(out.read_text()), original)
    text = capsys.readouterr().out
    assert "no refit" in text and "answered by the" in text
    # the check at the tested points made when the fit was saved, with the answer (issue 29)
    assert original["model_check"]["available"] and "the model at the tested points" in text
    assert original["model"]["name"] == ("surface" if which == "surface_saved" else "cubics")
    assert "usable_stroke" in original and "force_at_pressure" in original


def test_saved_file_is_netcdf_inference_data(surface_saved, cubics_saved, campaign):
    import arviz as az

    from uq._io.files import sha256_of
    from uq._models.saved import FILE_KIND, FORMAT_VERSION

    d, csv = campaign
    for fit, kind in ((surface_saved[0], "surface"), (cubics_saved[0], "cubics")):
        idata = az.from_netcdf(fit)
        a = idata.attrs
        assert a["uq_file_kind"] == FILE_KIND and a["uq_format_version"] == FORMAT_VERSION
        assert a["model"] == kind and a["seed"] == 20201
        assert (
            a["recordings_sha256"] == sha256_of(csv) and Path(a["recordings_path"]) == csv.resolve()
        )
        assert json.loads(a["model_info_json"])["name"] == kind
        c = idata.constant_data
        assert list(c["tested_pressure_range_bar"].values) == [1.0, 10.0]
        lo, hi = c["tested_height_range_m"].values
        assert 0.05 < lo < hi < 0.2
        names = {"pressure_area_m2", "casing_N", "volume_excess_m2", "piston_reference_m"}
        assert (names if kind == "surface" else {"force", "piston"}) <= set(idata.posterior)
        assert oct(os.stat(fit).st_mode & 0o777) == oct(0o666 & ~_umask())
    assert not list(d.glob(".*.tmp"))  # the atomic writer left no temporary file


def _umask() -> int:
    m = os.umask(0)
    os.umask(m)
    return m


def test_a_loaded_model_is_the_fits_own(surface_saved, tmp_path):
    """A saved and loaded surface computes the fit's own force and volume-derived area (the same
    draws, the same arithmetic: identical) and keeps its JSON document."""
    from uq._derived.margin import load_answer

    fit = surface_saved[2]
    h, p = np.linspace(0.08, 0.15, 7)[:, None], np.array([1.0, 3.3, 10.0])[None, :]
    fit.save(tmp_path / "lib" / "surface.nc", seed=7)
    back, info, meta = load_answer(tmp_path / "lib" / "surface.nc")
    np.testing.assert_array_equal(back.force_draws(h, p), fit.force_draws(h, p))
    np.testing.assert_array_equal(back.volume_area_draws(h, p), fit.volume_area_draws(h, p))
    for name, block in fit.blocks().items():
        np.testing.assert_array_equal(back.blocks()[name].draws, block.draws)
    assert back.height_range_m == fit.height_range_m
    assert back.pressure_range_bar == fit.pressure_range_bar
    assert meta["seed"] == 7 and info["orders"] == fit.orders_label
    assert json.dumps(back.to_json(), default=float) == json.dumps(fit.to_json(), default=float)


def test_the_previous_format_is_refused_with_how_to_resave(tmp_path, capsys):
    """A saved answer of format version 1 (uq margin --save-fit, uq surface --out up to round 6)
    is refused in one line saying how to save it again."""
    import xarray as xr

    old = tmp_path / "old.nc"
    attrs = {"uq_file_kind": "uq margin answer", "uq_format_version": 1, "uq_version": "0.1.0"}
    attrs["recordings_path"] = "/data/r.csv"
    xr.Dataset(attrs=attrs).to_netcdf(old, engine="h5netcdf")
    assert run(["margin", "--fit", old, "--height-mm", 110, "--load-N", 8000]) == 2
    line = one_line(capsys.readouterr().err)
    assert "format version 1" in line and "/data/r.csv again and save it" in line, line


def test_uq_surface_out_writes_a_saved_answer(
    campaign, surface_saved, monkeypatch, tmp_path, capsys
):
    """``uq surface --out DIR`` writes DIR/surface.nc, which ``uq margin --fit`` answers from (the fit is the
    margin run's, handed in, so this checks the wiring, not the sampler)."""
    import uq._models.surface_likelihood

    monkeypatch.setattr(
        uq._models.surface_likelihood, "fit_surface", lambda *a, **k: surface_saved[2]
    )
    assert (
        run(
            [
                "surface",
                campaign[1],
                "--no-compare",
                "--walkers",
                12,
                *QUICK,
                "--out",
                tmp_path / "s",
            ]
        )
        == 0
    )
    assert "saved fit" in capsys.readouterr().out
    out = tmp_path / "m.json"
    assert (
        run(["margin", "--fit", tmp_path / "s" / "surface.nc", *QUERY, "--json", out, *UNCONV]) == 0
    )
    res, original = json.loads(out.read_text()), surface_saved[1]
    assert res["model"]["name"] == "surface" and "uq surface --out" in res["model"]["why"]
    res["model"] = original["model"]  # same fit, same draws: only the stated reason differs
    assert_same(res, original)


def test_queries_file(surface_saved, tmp_path, capsys):
    fit, original, _ = surface_saved
    q = tmp_path / "q.csv"
    q.write_text(
        "# three queries\nheight_mm,load_N,prob,pressure_bar,tolerance_pct\n"
        "110,8000,,5,5\n"
        "100,9000,0.9,,\n"
        "\n"
        "120,7000,0.99,4,\n"
    )
    out = tmp_path / "q.json"
    assert run(["margin", "--fit", fit, "--queries", q, "--json", out, *UNCONV]) == 0
    res = json.loads(out.read_text())
    assert isinstance(res, list) and len(res) == 3
    assert_same(res[0], original)  # row 3 is the saved run's own query (prob from --prob's default)
    assert res[1]["prob"] == 0.9 and "force_at_pressure" not in res[1]
    assert res[2]["force_at_pressure"]["pressure_bar"] == 4.0 and "usable_stroke" not in res[2]
    table = capsys.readouterr().out
    assert "3 queries" in table and re.search(
        r"^\s+6\s+120\s", table, re.M
    )  # rows as an editor counts lines


def test_queries_without_saved_fit_fits_once(campaign, cubics_saved, monkeypatch, tmp_path, capsys):
    """Without --fit: one fit (here the saved cubics handed in, to skip the sampler) answers every row."""
    import uq._derived.comparison
    import uq._derived.margin

    q = tmp_path / "q.csv"
    q.write_text("height_mm,load_N\n110,8000\n100,9000\n")
    calls = []
    saved = uq._derived.margin.load_answer(cubics_saved[0])
    monkeypatch.setattr(
        uq._derived.comparison,
        "fit_and_choose",
        lambda *a, **k: calls.append(1) or (*saved[:2], saved[2]),
    )
    out = tmp_path / "q.json"
    assert (
        run(["margin", campaign[1], "--queries", q, "--model", "cubics", "--json", out, *QUICK])
        == 0
    )
    res = json.loads(out.read_text())
    assert (
        calls == [1] and len(res) == 2 and res[0]["height_m"] == 0.11 and res[1]["load_N"] == 9000.0
    )
    capsys.readouterr()


@pytest.mark.parametrize(
    "body, row, column, words",
    [
        ("height_mm,load_N\n110,8000\n100,abc\n", 3, "load_N", ["expected a number", "abc"]),
        ("height_mm,load_N,prob\n110,8000,1.5\n", 2, "prob", ["probability"]),
        ("height_mm,load_N\n110,8000\n,9000\n", 3, "height_mm", ["empty"]),
        ("height_mm,load_N,tolerance_pct\n110,8000,5\n", 2, "tolerance_pct", ["pressure_bar"]),
        ("height_mm,load_N\n110,8000\n300,8000\n", 3, "height_mm", ["outside the tested heights"]),
        (
            "height_mm,load_N,pressure_bar\n110,8000,20\n",
            2,
            "pressure_bar",
            ["outside the tested pressures"],
        ),
        # a load the tested pressures cannot carry is the row's own refusal, not the file's:
        # test_queries_row_the_model_cannot_answer_gets_its_own_refusal
        ("height_mm,load\n110,8000\n", 1, "load", ["unknown column"]),
    ],
)
def test_queries_bad_row_exit_2(body, row, column, words, surface_saved, tmp_path, capsys):
    q = tmp_path / "q.csv"
    q.write_text(body)
    out = tmp_path / "q.json"
    assert run(["margin", "--fit", surface_saved[0], "--queries", q, "--json", out, "--quiet"]) == 2
    line = one_line(capsys.readouterr().err)
    assert line.startswith("uq margin: error: ") and f"{q}, row {row}, column '{column}'" in line, (
        line
    )
    for w in words:
        assert w in line
    assert not out.exists()


def test_bad_row_refused_before_reading_or_fitting(campaign, monkeypatch, tmp_path, capsys):
    import uq._cli.common
    import uq._derived.comparison

    calls = []
    monkeypatch.setattr(uq._cli.common, "load", lambda *a, **k: calls.append("load"))
    monkeypatch.setattr(
        uq._derived.comparison, "fit_and_choose", lambda *a, **k: calls.append("fit")
    )
    q = tmp_path / "q.csv"
    q.write_text("height_mm,load_N\n110,8000\n110,-1\n")
    assert run(["margin", campaign[1], "--queries", q]) == 2
    assert calls == [] and "row 3, column 'load_N'" in one_line(capsys.readouterr().err)


def _not_answers(tmp_path: Path, good: Path) -> dict[str, Path]:
    import xarray as xr

    garbage = tmp_path / "garbage.nc"
    garbage.write_bytes(b"not a NetCDF file\n" * 10)
    truncated = tmp_path / "truncated.nc"
    truncated.write_bytes(good.read_bytes()[:3000])
    other = tmp_path / "other.nc"
    xr.Dataset({"x": ("d", np.arange(3.0))}).to_netcdf(other, engine="h5netcdf")
    return {
        "garbage": garbage,
        "truncated": truncated,
        "other": other,
        "missing": tmp_path / "missing.nc",
    }


@pytest.mark.parametrize("kind", ["garbage", "truncated", "other", "missing"])
def test_bad_fit_file_exit_2(kind, surface_saved, tmp_path, capsys):
    path = _not_answers(tmp_path, surface_saved[0])[kind]
    out = tmp_path / "m.json"
    assert run(["margin", "--fit", path, "--height-mm", 110, "--load-N", 8000, "--json", out]) == 2
    line = one_line(capsys.readouterr().err)
    assert line.startswith(f"uq margin: error: {path}: ") and "Traceback" not in line
    assert not out.exists()


@pytest.mark.parametrize(
    "extra, words",
    [
        (
            ["--height-mm", 300, "--load-N", 8000],
            ["--height-mm", "300 mm", "outside the tested heights"],
        ),
        (
            ["--height-mm", 110, "--load-N", 8000, "--pressure-bar", 20],
            ["--pressure-bar", "outside the tested pressures"],
        ),
        (
            ["--height-mm", 110, "--load-N", 90000],
            ["--load-N", "outside what the tested pressures"],
        ),
        (
            ["--height-mm", 110, "--load-N", 8000, "--model", "cubics"],
            ["--model cubics", "surface model"],
        ),
    ],
)
def test_saved_fit_refuses_what_a_fit_refuses(extra, words, surface_saved, capsys):
    assert run(["margin", "--fit", surface_saved[0], *extra]) == 2
    line = one_line(capsys.readouterr().err)
    for w in words:
        assert w in line, line


@pytest.fixture
def no_fitting(monkeypatch):
    # imported before the patch: imported while patched, the comparison would keep the forbidden
    # fitter it binds by name (`from uq._models.cubic_fit import fit_campaign`) for later tests
    import uq._cli.common
    import uq._derived.comparison  # noqa: F401
    import uq._models.cubic_fit
    import uq._models.discrepancy
    import uq._models.surface_likelihood

    def forbidden(*a, **k):
        raise AssertionError("read or fitted before the options were checked")

    for mod, name in (
        (uq._models.cubic_fit, "fit_campaign"),
        (uq._models.surface_likelihood, "fit_surface"),
        (uq._models.discrepancy, "fit_discrepancy"),
        (uq._cli.common, "load"),
    ):
        monkeypatch.setattr(mod, name, forbidden)


def test_exactly_one_source_exit_2(surface_saved, campaign, tmp_path, capsys, no_fitting):
    fit, csv = surface_saved[0], campaign[1]
    q = tmp_path / "q.csv"
    q.write_text("height_mm,load_N\n110,8000\n")
    rows = [
        (["margin", "--height-mm", 110, "--load-N", 8000], ["exactly one of FILE.csv", "--fit"]),
        (
            ["margin", csv, "--fit", fit, "--height-mm", 110, "--load-N", 8000],
            ["--fit", "FILE.csv"],
        ),
        (
            [
                "margin",
                "--fit",
                fit,
                "--save-fit",
                tmp_path / "x.nc",
                "--height-mm",
                110,
                "--load-N",
                8000,
            ],
            ["--save-fit"],
        ),
        (["margin", csv, "--save-fit", "-", "--height-mm", 110, "--load-N", 8000], ["--save-fit"]),
        (
            ["margin", csv, "--save-fit", tmp_path, "--height-mm", 110, "--load-N", 8000],
            ["--save-fit", "folder"],
        ),
        (["margin", "--fit", fit, "--load-N", 8000], ["--height-mm", "required"]),
        (
            ["margin", "--fit", fit, "--queries", q, "--height-mm", 110],
            ["--height-mm", "--queries"],
        ),
        (["margin", "--fit", fit, "--queries", tmp_path / "none.csv"], ["none.csv", "cannot read"]),
    ]
    for argv, words in rows:
        assert run(argv) == 2, argv
        line = one_line(capsys.readouterr().err)
        assert line.startswith("uq margin: error: "), line
        for w in words:
            assert w in line, (argv, line)
    assert not (tmp_path / "x.nc").exists()


def test_stroke_runs_match_the_walk_they_replace():
    """``_run_around`` (vectorised) gives each draw's run through the query height as the per-draw walk did."""
    from uq._derived.margin import _run_around

    rng = np.random.default_rng(5)
    for n, j in ((1, 0), (9, 0), (9, 8), (9, 4), (361, 170)):
        ok = rng.random((300, n)) < rng.uniform(0.5, 0.99, (300, 1))
        a, b = _run_around(ok, j)
        for s in np.flatnonzero(ok[:, j]):
            lo = j
            while lo > 0 and ok[s, lo - 1]:
                lo -= 1
            hi = j
            while hi < n - 1 and ok[s, hi + 1]:
                hi += 1
            assert (a[s], b[s]) == (lo, hi)


# ----------------------------------------------------------------------------- design margins (sealed spring)

DESIGN = [
    "--max-frequency-hz",
    "2.3",
    "--rate-target-N-per-m",
    "150000",
    "--force-limit-N",
    "12000",
]


def test_design_margins_from_the_saved_fit(surface_saved, tmp_path, capsys):
    """``uq margin --fit`` with the sealed spring's questions: the margin's keys stay as they were,
    and the rate at the design height is (S3) evaluated directly on the saved draws (each draw at
    its own charge pressure, derivatives by central differences), not through the design grid."""
    from uq._derived.margin import load_answer, pressure_needed

    fit, original, _ = surface_saved
    out = tmp_path / "d.json"
    argv = ["margin", "--fit", fit, *QUERY, *DESIGN, "--volume-l", "3.0", "--json", out]
    argv += ["--polytropic", "1", "--dvdp-sd-l-per-bar", "0"]  # the closed form's n and dV/dp_u
    assert run([*argv, *UNCONV]) == 0
    text = capsys.readouterr().out
    res = json.loads(out.read_text())
    d = res.pop("design")
    assert_same(res, original)  # every existing key and number unchanged
    assert "natural frequency below 2.3 Hz with probability" in text and "stroke to 12000 N" in text
    full, _, _ = load_answer(fit)
    ans = full.on_draws(1000)  # the design margin's draws (at most 1000 of the saved ones)
    p = pressure_needed(ans, 0.110, 8000.0).values
    h, dp = 1e-5, 1e-4
    idx = np.arange(p.size)

    def at(x, pp):  # draw s at its own pressure
        return ans.force_draws(np.full(p.size, x), pp)[idx, idx]

    Px = (at(0.110 + h, p) - at(0.110 - h, p)) / (2 * h)
    Pp = (at(0.110, p + dp) - at(0.110, p - dp)) / (2 * dp * 1e5)
    Vx = ans.volume_area_draws(np.full(p.size, 0.110), p)[idx, idx]
    k = -Px + Pp * (p * 1e5 + 101325.0) * Vx / 3.0e-3
    assert d["rate_N_per_m"]["mean"] == pytest.approx(k.mean(), rel=2e-4)
    f = np.sqrt(k * 9.80665 / 8000.0) / (2 * np.pi)
    assert d["frequency_below"]["probability"] == pytest.approx(np.mean(f < 2.3), abs=0.01)
    assert d["charge_bar"]["mean"] == pytest.approx(p.mean(), rel=1e-12)
    e = res["pressure_bar_needed"]  # the margin's own, on all the saved draws
    assert abs(d["charge_bar"]["mean"] - e["mean"]) < 0.2 * e["sd"]
    assert d["stroke_to_force_limit"]["direction"].startswith("compression")
    assert "ASSUMED" in " ".join(d["assumptions"])


def test_design_margins_need_the_volume(surface_saved, capsys):
    fit = surface_saved[0]
    assert run(["margin", "--fit", fit, *QUERY, "--max-frequency-hz", "2"]) == 2
    line = one_line(capsys.readouterr().err)
    assert "--volume-l" in line and "water" in line


def test_design_margin_time_from_the_saved_fit(surface_saved, capsys):
    """Not an assertion on time (machines differ): the benchmark line the docs quote, printed."""
    import os
    import time

    from uq._derived.design import SealedDesign, design_margin
    from uq._derived.margin import load_answer

    t0 = time.perf_counter()
    ans, _, _ = load_answer(surface_saved[0])
    t1 = time.perf_counter()
    res = design_margin(
        ans,
        0.110,
        8000.0,
        SealedDesign(0.110, 5.0, 3.0),
        0.95,
        max_frequency_Hz=2.3,
        rate_target_N_per_m=150000.0,
        force_limit_N=12000.0,
    )
    t2 = time.perf_counter()
    with capsys.disabled():
        print(
            f"\nbenchmark: design margin from a saved fit: load {t1 - t0:.2f} s, answer (frequency, rate, "
            f"stroke) {t2 - t1:.2f} s, load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs"
        )
    assert res["frequency_below"]["max_frequency_Hz"] == 2.3


def test_queries_row_the_model_cannot_answer_gets_its_own_refusal(surface_saved, tmp_path, capsys):
    """A row whose load the tested pressures cannot carry is refused on its own row (named by file
    and row); the other rows are answered, and the JSON says which is which."""
    fit, original, _ = surface_saved
    q = tmp_path / "q.csv"
    q.write_text("height_mm,load_N\n110,8000\n110,9000000\n100,9000\n")
    out = tmp_path / "q.json"
    assert run(["margin", "--fit", fit, "--queries", q, "--json", out, *UNCONV]) == 0
    res = json.loads(out.read_text())
    assert [("refused" in r) for r in res] == [False, True, False]
    assert "row 3" in res[1]["refused"] and "load_N" in res[1]["refused"]
    assert res[1]["row"] == 3 and res[1]["load_N"] == 9000000.0
    assert res[0]["pressure_bar_needed"]["mean"] > 0 and res[2]["pressure_bar_needed"]["mean"] > 0
    captured = capsys.readouterr()
    assert re.search(r"^\s+3\s+110\s+9e\+06\s+refused: ", captured.out, re.M)
    assert "1 of 3 queries refused (rows 3)" in captured.err


def test_an_answer_whose_model_misses_its_readings_exits_1_unless_allowed(
    surface_saved, tmp_path, monkeypatch, capsys
):
    """The command's wiring of the check (issue 29): a saved fit whose check at the tested points
    missed (made to by patching what the file says) still answers, with the check in its JSON and
    the per-pressure table on stdout, and exits 1; --allow-misfit exits 0."""
    import uq._cli.cmd_margin as cmd

    fit = surface_saved[0]
    real = cmd.load_answer

    def missing(path):
        ans, info, meta = real(path)
        rows = meta["model_check"]["by_pressure"]
        p = rows[len(rows) // 2]["pressure_bar"]  # one tested pressure, said to be missed
        check = dict(meta["model_check"], misses=True, missed_pressures_bar=[p])
        check["by_pressure"] = [dict(r, misses=r["pressure_bar"] == p) for r in rows]
        return ans, info, dict(meta, model_check=check)

    monkeypatch.setattr(cmd, "load_answer", missing)
    out = tmp_path / "m.json"
    assert run(["margin", "--fit", fit, *QUERY, "--json", out, *UNCONV]) == 1
    captured = capsys.readouterr()
    res = json.loads(out.read_text())
    p = res["model_check"]["missed_pressures_bar"][0]
    assert f"MISSES the readings at {p:g} bar" in captured.out
    flagged = [ln for ln in captured.out.splitlines() if ln.rstrip().endswith("MISSES")]
    assert len(flagged) == 1 and flagged[0].split()[0] == f"{p:g}"  # the table's row
    assert "misses the readings" in captured.err and "--allow-misfit" in captured.err
    assert res["model_check"]["misses"] and "pressure_bar_needed" in res  # answered all the same
    assert run(["margin", "--fit", fit, *QUERY, *UNCONV, "--allow-misfit"]) == 0
