"""``uq export``'s grid and formats (issue 30 items 1, 5): every format read back by an independent
reader (pandas and openpyxl for the tables, scipy.io for .mat, a MATLAB-assignment reader and a
TeimOrbit parser written here from the formats' documentation) and compared with the model's draws.

The model is a closed-form FittedModel (the protocol of uq._models.fitted) defined here: force
P = p_u A(x) with A(x) = a + b (x - x_r) per draw, dV/dx = (1 + c) A(x) (so dV/dp_u = 0), and every
number the export writes is known.
"""

from __future__ import annotations

import io
import json
from dataclasses import replace

import numpy as np
import openpyxl
import pandas as pd
import pytest
import scipy.io
from export_helpers import X_REF, LinearArea, matlab_assignments, parse_teimorbit

from uq._data.units import OutputUnits
from uq._derived.design import SealedDesign
from uq._derived.export import (
    ExportGrid,
    csv_rows,
    export_grid,
    json_document,
    parse_heights_mm,
    parse_pressures_bar,
    parse_quantiles,
    quantile_name,
    sealed_export,
    simscape_fields,
    teimorbit_files,
    xlsx_sheets,
)
from uq._io import matlab
from uq._io.errors import InputError
from uq._io.tables import csv_text, xlsx_bytes
from uq._models.fitted import FittedModel

CONTRACT = (
    "pressure_bar,height_mm,force_N_mean,force_N_q05,force_N_q50,force_N_q95,"
    "feff_m2_mean,feff_m2_q05,feff_m2_q95"
).split(",")


MODEL = LinearArea()
HEIGHTS = np.array([0.07, 0.09, 0.11, 0.13, 0.15])
PRESSURES = np.array([1.0, 2.5, 5.0, 10.0])


@pytest.fixture(scope="module")
def grid() -> ExportGrid:
    return export_grid(
        MODEL, HEIGHTS, PRESSURES, provenance={"recordings_path": "r.csv", "uq_version": "t"}
    )


def _truth(quantity: str) -> np.ndarray:
    """(S, H, P) draws of a quantity, straight from the model's parameters."""
    h, p = HEIGHTS[None, :, None], PRESSURES[None, None, :]
    a, b, c = (v[:, None, None] for v in (MODEL.a, MODEL.b, MODEL.c))
    area = a + b * (h - X_REF) + 0 * p
    top = HEIGHTS.max()
    return {
        "force": area * p * 1e5,
        "feff": area,
        "feff_volume": area * (1 + c),
        # integral from top to h of (1 + c)(a + b (x - x_r)) dx
        "volume_increment": (1 + c)
        * (a * (h - top) + b / 2 * ((h - X_REF) ** 2 - (top - X_REF) ** 2))
        + 0 * p,
    }[quantity]


def test_the_test_model_follows_the_protocol():
    assert isinstance(MODEL, FittedModel)


def test_grid_holds_the_models_draws_and_the_exact_volume_increment(grid):
    for key in ("force", "feff", "feff_volume", "volume_increment"):
        s, truth = grid.stats(key), _truth(key)
        assert set(s) == {"mean", "sd", "q05", "q50", "q95"}
        for stat, q in (("q05", 0.05), ("q50", 0.5), ("q95", 0.95)):
            assert np.allclose(s[stat], np.quantile(truth, q, axis=0), rtol=1e-12, atol=1e-15)
        assert np.allclose(s["mean"], truth.mean(axis=0), rtol=1e-12, atol=1e-15), key
        assert np.allclose(s["sd"], truth.std(axis=0, ddof=1), rtol=1e-9, atol=1e-15), key
    assert grid.n_draws == MODEL.n_draws
    assert grid.model_name == "linear-area" and grid.notes == ()


def test_grid_refuses_beyond_the_tested_ranges_unless_told():
    with pytest.raises(
        InputError, match=r"heights_m: 160 mm is outside the tested heights 65..155"
    ) as e:
        export_grid(MODEL, np.array([0.1, 0.16]), PRESSURES)
    assert e.value.param == "heights_m" and "`extrapolate`" in str(e.value)
    with pytest.raises(
        InputError, match=r"pressures_bar: 12 bar is outside the tested pressures 1..10"
    ):
        export_grid(MODEL, HEIGHTS, np.array([5.0, 12.0]))
    g = export_grid(MODEL, np.array([0.1, 0.16]), np.array([12.0]), extrapolate=True)
    assert len(g.notes) == 2 and all(n.startswith("extrapolated:") for n in g.notes)


def test_force_only_models_omit_the_volume_with_the_reason():
    g = export_grid(LinearArea(300, volume=False), HEIGHTS, PRESSURES)
    assert [q.key for q in g.quantities] == ["force", "feff"]
    assert g.notes == ("volume results omitted: force-only test model: no volume",)


def test_options_parse_and_refuse_in_one_line():
    assert parse_heights_mm("65:155:45").tolist() == [65.0, 110.0, 155.0]
    assert parse_heights_mm("100, 70,80").tolist() == [70.0, 80.0, 100.0]
    assert parse_pressures_bar("5,1").tolist() == [1.0, 5.0]
    assert parse_quantiles("0.95,0.05,0.5") == (0.05, 0.5, 0.95)
    for bad, f in (
        ("65:60:5", parse_heights_mm),
        ("a,b", parse_heights_mm),
        ("70,70", parse_heights_mm),
        ("0,1", parse_pressures_bar),
        ("1.5", parse_quantiles),
    ):
        with pytest.raises(ValueError):
            f(bad)
    assert [quantile_name(q) for q in (0.05, 0.5, 0.95, 0.025)] == ["q05", "q50", "q95", "q2.5"]


# ----------------------------------------------------------------------------- CSV


def test_csv_has_the_contracts_columns_first_and_the_models_numbers(grid):
    header, rows = csv_rows(grid)
    table = pd.read_csv(io.StringIO(csv_text(header, rows)))
    assert list(table.columns[: len(CONTRACT)]) == CONTRACT
    assert len(table) == HEIGHTS.size * PRESSURES.size
    force, feff = _truth("force"), _truth("feff")
    for j, p in enumerate(PRESSURES):
        for i, h in enumerate(HEIGHTS):
            r = table[(table.pressure_bar == p) & np.isclose(table.height_mm, h * 1e3)].iloc[0]
            assert r.force_N_mean == pytest.approx(force[:, i, j].mean(), rel=1e-9)
            assert r.force_N_q95 == pytest.approx(np.quantile(force[:, i, j], 0.95), rel=1e-9)
            assert r.feff_m2_q05 == pytest.approx(np.quantile(feff[:, i, j], 0.05), rel=1e-9)
            assert r.volume_increment_l_q50 == pytest.approx(
                np.quantile(_truth("volume_increment")[:, i, j], 0.5) * 1e3, rel=1e-8, abs=1e-12
            )


def test_csv_in_the_recordings_units(grid):
    us = OutputUnits.of({"pressure": "psi", "height": "in", "force": "lbf"}, "input")
    header, rows = csv_rows(grid, us)
    table = pd.read_csv(io.StringIO(csv_text(header, rows)))
    assert list(table.columns[:4]) == [
        "pressure_psi",
        "height_in",
        "force_lbf_mean",
        "force_lbf_q05",
    ]
    assert "feff_in2_mean" in table and "volume_increment_in3_q50" in table
    r = table.iloc[0]
    assert r.pressure_psi == pytest.approx(PRESSURES[0] / 0.0689475729316836, rel=1e-9)
    assert r.height_in == pytest.approx(HEIGHTS[0] / 0.0254, rel=1e-9)
    assert r.force_lbf_mean == pytest.approx(
        _truth("force")[:, 0, 0].mean() / 4.4482216152605, rel=1e-9
    )


# ----------------------------------------------------------------------------- xlsx


def test_xlsx_is_the_catalogues_wide_shape_with_provenance(grid):
    book = openpyxl.load_workbook(io.BytesIO(xlsx_bytes(xlsx_sheets(grid))))
    assert "force_N q95" in book.sheetnames and book.sheetnames[-1] == "provenance"
    sheet = book["force_N q95"]
    rows = list(sheet.iter_rows(values_only=True))
    assert rows[0][0] == "height_mm \\ pressure_bar" and list(rows[0][1:]) == PRESSURES.tolist()
    assert [r[0] for r in rows[1:]] == pytest.approx((HEIGHTS * 1e3).tolist())
    q95 = np.quantile(_truth("force"), 0.95, axis=0)
    assert np.allclose(np.array([r[1:] for r in rows[1:]], float), q95, rtol=1e-12)
    provenance = dict(list(book["provenance"].iter_rows(values_only=True))[1:])
    assert provenance["recordings"] == "r.csv" and "linear-area" in provenance["model"]
    assert {"recordings sha256", "date", "between tested pressures", "made by"} <= set(provenance)


# ----------------------------------------------------------------------------- JSON


def test_json_grid_has_the_contracts_estimate_objects(grid):
    doc = json.loads(json.dumps(json_document(grid), default=lambda a: np.asarray(a).tolist()))
    assert (
        doc["model"]["name"] == "linear-area" and len(doc["grid"]) == HEIGHTS.size * PRESSURES.size
    )
    point = doc["grid"][HEIGHTS.size + 2]  # the second pressure, the third height
    assert (point["pressure_bar"], point["height_m"]) == (PRESSURES[1], HEIGHTS[2])
    est = point["force_N"]
    assert {"mean", "sd", "q05", "q95"} <= set(est)
    assert est["sd"] == pytest.approx(_truth("force")[:, 2, 1].std(ddof=1), rel=1e-9)
    assert point["volume_increment_m3"]["mean"] == pytest.approx(
        _truth("volume_increment")[:, 2, 1].mean(), rel=1e-9
    )


# ----------------------------------------------------------------------------- MATLAB


def test_simscape_script_and_mat_file_hold_every_quantile(grid):
    units = OutputUnits()
    fields = simscape_fields(grid, units)
    text = matlab.script("airspring", fields, ["a comment"])
    parsed = matlab_assignments(text)
    assert parsed["airspring.height"].ravel() == pytest.approx((HEIGHTS * 1e3).tolist())
    force = _truth("force")
    for stat, q in (("q05", 0.05), ("q50", 0.5), ("q95", 0.95)):
        assert np.allclose(
            parsed[f"airspring.load.{stat}"], np.quantile(force, q, axis=0), rtol=1e-9
        )
    assert parsed["airspring.source"] == "r.csv"
    mat = scipy.io.loadmat(io.BytesIO(matlab.mat_bytes("airspring", fields)), simplify_cells=True)
    s = mat["airspring"]
    assert np.allclose(s["load"]["q95"], np.quantile(force, 0.95, axis=0), rtol=1e-12)
    assert np.allclose(np.ravel(s["height"]), HEIGHTS * 1e3)
    assert s["model"].startswith("closed-form test model")


# ----------------------------------------------------------------------------- TeimOrbit


def test_teimorbit_files_one_per_statistic_read_back(grid):
    units = OutputUnits()
    files = dict(teimorbit_files(grid, units))
    assert list(files) == ["mean", "q05", "q50", "q95"]
    f = parse_teimorbit(files["q95"])
    assert f["MDI_HEADER"]["params"]["FILE_FORMAT"] == "ASCII"
    assert f["UNITS"]["params"] == {
        "LENGTH": "mm",
        "FORCE": "newton",
        "ANGLE": "degree",
        "MASS": "kg",
        "TIME": "second",
    }
    z = np.array(f["AIRSPRING"]["Z_DATA"]["table"]["rows"]).ravel()
    assert z == pytest.approx(PRESSURES * 1e5 / 1e6)  # bar in N/mm^2
    xy = f["AIRSPRING"]["XY_DATA"]["table"]
    assert xy["labels"][0] == "height" and len(xy["labels"]) == 1 + PRESSURES.size
    data = np.array(xy["rows"])
    assert data[:, 0] == pytest.approx(HEIGHTS * 1e3)
    assert np.allclose(data[:, 1:], np.quantile(_truth("force"), 0.95, axis=0), rtol=1e-9)


def test_teimorbit_in_inches_and_pounds(grid):
    us = OutputUnits.of({"pressure": "psi", "height": "in", "force": "lbf"}, "input")
    f = parse_teimorbit(dict(teimorbit_files(grid, us))["q50"])
    assert (f["UNITS"]["params"]["LENGTH"], f["UNITS"]["params"]["FORCE"]) == (
        "inch",
        "pound_force",
    )
    z = np.array(f["AIRSPRING"]["Z_DATA"]["table"]["rows"]).ravel()
    assert z == pytest.approx(PRESSURES / 0.0689475729316836, rel=1e-9)  # lbf/in^2 = psi
    data = np.array(f["AIRSPRING"]["XY_DATA"]["table"]["rows"])
    assert data[:, 0] == pytest.approx(HEIGHTS / 0.0254)
    assert np.allclose(
        data[:, 1:], np.quantile(_truth("force"), 0.5, axis=0) / 4.4482216152605, rtol=1e-9
    )


# ----------------------------------------------------------------------------- sealed


def test_sealed_spring_force_stiffness_and_rate(grid):
    design = SealedDesign(height_m=0.11, charge_bar=5.0, volume_l=5.0)
    g = sealed_export(grid, MODEL, design)
    s = g.sealed
    assert 0.11 in s["heights_m"].tolist()
    k = s["heights_m"].tolist().index(0.11)
    # at the design height the closed spring carries the isobaric force at its charge
    charge = _truth("force")[:, HEIGHTS.tolist().index(0.11), PRESSURES.tolist().index(5.0)]
    assert s["force"]["mean"][k] == pytest.approx(charge.mean(), rel=1e-6)
    assert np.allclose(s["stiffness"]["mean"], s["force"]["mean"] / s["heights_m"], rtol=1e-12)
    assert np.all(s["rate"]["q05"] > 0)  # a closed spring stiffens as it is compressed
    files = dict(teimorbit_files(g, OutputUnits()))
    sealed = parse_teimorbit(files["sealed_q50"])
    assert np.array(sealed["AIRSPRING"]["Z_DATA"]["table"]["rows"]).ravel() == pytest.approx([0.5])
    fields = {f: v for f, v, _ in simscape_fields(g, OutputUnits())}
    assert np.allclose(fields["sealed.stiffness.q50"], s["stiffness"]["q50"] / 1e3)  # N/mm


def test_sealed_heights_beyond_the_tested_pressures_are_left_out_and_said(grid):
    design = SealedDesign(height_m=0.11, charge_bar=9.5, volume_l=5.0)
    g = sealed_export(grid, MODEL, design)
    assert any("sealed spring: heights" in n for n in g.notes)
    assert 0.11 in g.sealed["heights_m"].tolist() and g.sealed["heights_m"].min() > 0.07
    with pytest.raises(
        InputError, match="the design height 152 mm lies outside the exported heights 70..150"
    ):
        sealed_export(grid, MODEL, replace(design, height_m=0.152, charge_bar=5.0))


def test_writers_are_deterministic(grid):
    a = csv_text(*csv_rows(grid))
    b = csv_text(*csv_rows(export_grid(MODEL, HEIGHTS, PRESSURES, provenance=grid.provenance)))
    assert a == b


def test_write_every_format_to_its_files(grid, tmp_path):
    from uq._derived.export import FORMATS, write

    g = sealed_export(grid, MODEL, SealedDesign(height_m=0.11, charge_bar=5.0, volume_l=5.0))
    names = {
        "csv": ["t.csv", "t_sealed.csv", "t_provenance.csv"],
        "xlsx": ["t.xlsx"],
        "json": ["t.json"],
        "simscape": ["t.m"],
        "teimorbit": [f"t_sealed_{s}.tpf" for s in ("mean", "q05", "q50", "q95")],
    }
    for fmt in FORMATS:
        suffix = {"simscape": ".m", "teimorbit": ".tpf"}.get(fmt, f".{fmt}")
        paths = write(g, fmt, tmp_path / f"t{suffix}", when="2026-11-27 10:00 UTC")
        assert sorted(p.name for p in paths) == sorted(names[fmt]), fmt
    mat = write(g, "simscape", tmp_path / "t.mat")[0]
    assert "sealed" in scipy.io.loadmat(mat, simplify_cells=True)["airspring"]
    sealed = pd.read_csv(tmp_path / "t_sealed.csv")
    assert list(sealed.columns[:3]) == ["height_mm", "sealed_force_N_mean", "sealed_force_N_q05"]
    book = openpyxl.load_workbook(tmp_path / "t.xlsx")
    assert book.sheetnames[-2:] == ["sealed", "provenance"]
    assert json.loads((tmp_path / "t.json").read_text())["sealed"]["charge_bar"] == 5.0
    provenance = pd.read_csv(tmp_path / "t_provenance.csv")  # the workbook's sheet, row for row
    rows = list(book["provenance"].iter_rows(values_only=True))
    assert list(provenance.columns) == list(rows[0])
    assert [r[0] for r in rows[1:]] == provenance.key.tolist()
    assert pd.read_csv(tmp_path / "t.csv").columns[0] == "pressure_bar"  # the header first


def test_json_objects_carry_the_contracts_quantiles_whatever_is_asked():
    g = export_grid(MODEL, HEIGHTS, PRESSURES, quantiles=(0.25, 0.75))
    point = json_document(g)["grid"][3]
    assert list(point["force_N"]) == ["mean", "sd", "q05", "q25", "q75", "q95"]
    truth = _truth("force")[:, 3, 0]
    assert point["force_N"]["q05"] == pytest.approx(np.quantile(truth, 0.05), rel=1e-12)
    header, _ = csv_rows(g)
    assert "force_N_q25" in header and "force_N_q05" not in header  # the tables: those asked


def test_large_grids_are_evaluated_in_chunks_of_heights(monkeypatch):
    """The draws held at once stay bounded (MAX_VALUES) and the summaries do not change."""
    from uq._derived import export

    whole = export_grid(MODEL, HEIGHTS, PRESSURES)
    monkeypatch.setattr(export, "MAX_VALUES", MODEL.n_draws * PRESSURES.size * 8 * 2)
    chunked = export_grid(MODEL, HEIGHTS, PRESSURES)  # two heights at a time
    for q in whole.quantities:
        for stat, v in q.stats.items():
            assert np.array_equal(v, chunked.stats(q.key)[stat]), (q.key, stat)
