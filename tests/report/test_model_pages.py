"""The pages of the models over all tests (surface.html, thermodynamic.html): what they say about
which description to use, and the command that writes them.

The screenshots of the pages themselves are in test_pages_in_a_browser.py.
"""

from __future__ import annotations

import pytest

from uq._cli.main import main
from uq._report.model_page import NOISE_WORDS, noise_rows, preference
from uq._report.thermo import PHYSICS_NOTES


def _comparison(better: str, d: float, se: float, name: str = "surface") -> dict:
    part = {"elpd_loo": -100.0, "se": 10.0, "p_loo": 20.0, "max_pareto_k": 0.4}
    return {
        name: part | {"n_coefficients": 23, "n_pareto_k_above_0.7": 0},
        "cubics": part | {"n_coefficients": 32, "n_pareto_k_above_0.7": 0},
        "elpd_diff": d,
        "elpd_diff_se": se,
        "better": better,
        "reason": f"ELPD difference {d:.1f} +- {se:.1f}",
        "rule": "better only if |diff| > 2 SE and > 4, and every Pareto k <= 0.7",
    }


@pytest.mark.parametrize(
    "better, d, prefers, first_words",
    [
        ("per-pressure cubics", -27.6, "cubics", "The recordings prefer the per-pressure cubics"),
        ("surface", 17.8, "model", "The recordings prefer the surface model to the per-pressure"),
        ("indistinguishable", 1.2, "neither", "The recordings prefer neither"),
        ("refused", 3.0, "no verdict", "No verdict"),
    ],
)
def test_the_page_says_which_description_to_use(better, d, prefers, first_words):
    p = preference(_comparison(better, d, 5.0), "surface", "the surface model")
    assert p["prefers"] == prefers and p["headline"].startswith(first_words)
    assert f"{d:+.1f} ± 5.0" in p["headline"] or prefers == "no verdict"
    if prefers == "cubics":  # the reader is told to read the cubics and what the surface is for
        assert "read force and volume from the cubics" in p["meaning"] and p["css"] == "warn"
    if prefers == "model":
        assert "use its curves and bands" in p["meaning"] and p["css"] == "ok"


def test_the_thermodynamic_page_says_what_a_preference_means_for_the_physics():
    words = ("thermodynamic", "the thermodynamic model", PHYSICS_NOTES)
    cubics = preference(_comparison("per-pressure cubics", -9.0, 2.0, "thermodynamic"), *words)
    assert "Maxwell" in cubics["meaning"] and "thermodynamic model" in cubics["headline"]
    model = preference(_comparison("thermodynamic", 9.0, 2.0, "thermodynamic"), *words)
    assert model["prefers"] == "model" and "one potential" in model["meaning"]


def test_without_a_comparison_the_page_says_so():
    p = preference(None, "surface", "the surface model")
    assert p["prefers"] == "not compared" and "--no-compare" in p["headline"]


def test_noise_rows_are_words_in_units():
    noise = {
        "s0_N": {"mean": 2.5, "q05": 1.0, "q95": 4.0},
        "rel_load": {"mean": 0.005, "q05": 0.004, "q95": 0.006},
        "sL_m": {"mean": 1.2e-4, "q05": 1e-4, "q95": 1.4e-4},
        "V0_m3": {"mean": 6.2e-3, "q05": 5e-3, "q95": 7e-3},
    }
    rows = noise_rows(noise)
    assert [r["words"] for r in rows] == ["floor", "load cell", "piston floor", "gas volume"]
    assert [r["unit"] for r in rows] == ["N", "%", "mm", "L"]
    assert [r["mean"] for r in rows] == pytest.approx([2.5, 0.5, 0.12, 6.2])
    assert set(NOISE_WORDS) == {"s0_N", "rel_load", "k_p", "sL_m", "V0_m3"}


@pytest.fixture(scope="module")
def six_pressures_csv(tmp_path_factory):
    csv = tmp_path_factory.mktemp("six") / "r.csv"
    assert (
        main(
            [
                "simulate",
                "--out",
                str(csv),
                "--pressures",
                "1,2.5,4,5.5,7,10",
                "--step-mm",
                "10",
                "--seed",
                "3",
            ]
        )
        == 0
    )
    return csv


def test_thermodynamic_out_saves_a_model_margin_answers_from(six_pressures_csv, tmp_path, capsys):
    """``uq surface --model thermodynamic --out DIR`` writes DIR/thermodynamic.nc; ``uq margin
    --fit`` answers from it (short chains: this checks the saved format, not the sampler)."""
    import json

    quick = ["--no-compare", "--max-steps", "200", "--ensembles", "2", "--quiet"]
    quick.append("--allow-unconverged")  # the short chains' fit says NOT CONVERGED and goes on
    argv = ["surface", str(six_pressures_csv), "--model", "thermodynamic", *quick]
    assert main([*argv, "--out", str(tmp_path), "--json", str(tmp_path / "t.json")]) == 0
    saved = tmp_path / "thermodynamic.nc"
    assert f"saved fit: {saved}" in capsys.readouterr().out
    query = ["--height-mm", "110", "--load-N", "9000", "--json", str(tmp_path / "m.json")]
    assert main(["margin", "--fit", str(saved), *query, "--allow-unconverged"]) == 0
    res = json.loads((tmp_path / "m.json").read_text())
    assert res["model"]["name"] == "thermodynamic" and 1.0 < res["pressure_bar_for_prob"] < 10.0


@pytest.mark.slow
def test_thermodynamic_report_from_the_command_line(six_pressures_csv, tmp_path, capsys):
    out = tmp_path / "page"
    argv = ["surface", str(six_pressures_csv), "--model", "thermodynamic", "--report", str(out)]
    assert main([*argv, "--max-steps", "400", "--allow-unconverged"]) == 0
    assert f"report: {out / 'thermodynamic.html'}" in capsys.readouterr().out
    names = sorted(p.name for p in out.iterdir())
    assert names == [
        "thermo_areas.png",
        "thermo_force.png",
        "thermo_maxwell.png",
        "thermo_piston_area.png",
        "thermodynamic.html",
    ]
    text = (out / "thermodynamic.html").read_text(encoding="utf-8")
    assert "the per-pressure cubics" in text and "Maxwell ratio" in text
