"""The public Python API (uq/__init__.py): the notebook one-liner, and every docstring example.

The examples use small settings (two or three pressures at 10 mm steps, 400 sampler steps), so the
default run stays short; those that compile the surface model or run the mechanism search (about a
minute each on first use) run under ``-m slow``.
"""

from __future__ import annotations

import doctest
import subprocess
import sys
from pathlib import Path

import pytest

import uq

ROOT = Path(__file__).resolve().parents[1]

SMALL = dict(layout=uq.Layout(pressures_bar=(1.0, 5.0), step_m=0.01))
QUICK = uq.Settings(max_steps=200)


def _run_examples(obj, name: str) -> None:
    finder = doctest.DocTestFinder(recurse=False)
    runner = doctest.DocTestRunner(optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    tests = finder.find(obj, name, globs={})
    assert sum(len(t.examples) for t in tests) > 0, f"{name} has no examples"
    for t in tests:
        runner.run(t)
    result = runner.summarize(verbose=False)
    assert result.failed == 0, (
        f"{result.failed} of {result.attempted} examples of {name} failed (output above)"
    )


def test_notebook_one_liner(tmp_path):
    """uq.write_report(uq.fit_campaign(uq.simulate("n50")), "out/"), small."""
    page = uq.write_report(
        uq.fit_campaign(uq.simulate("n50", **SMALL), settings=QUICK), tmp_path / "out", draws=100
    )
    assert page == tmp_path / "out" / "report.html"
    text = page.read_text(encoding="utf-8")
    assert "Reconstructed data" in text and "simulated n50 (seed 0)" in text
    assert sorted(p.name for p in page.parent.glob("*.png")) == [
        "fig2_force.png",
        "fig3_volume.png",
        "fig4_feff.png",
        "fig5_traditional.png",
        "fig_feff_scatter.png",
        "test_1bar.png",
        "test_5bar.png",
    ]


def test_simulate_equals_the_cli_csv_read_back(tmp_path):
    """uq.simulate gives the readings `uq simulate` writes and read_recordings reads, bit for bit."""
    from uq._cli.main import main
    from uq._data.rows import leading_comments
    from uq._io.files import sha256_of

    csv = tmp_path / "r.csv"
    assert (
        main(
            [
                "simulate",
                "--out",
                str(csv),
                "--pressures",
                "1,5",
                "--step-mm",
                "10",
                "--seed",
                "4",
                "--quiet",
            ]
        )
        == 0
    )
    from_file = uq.read_recordings(csv)
    in_memory = uq.simulate("n50", seed=4, **SMALL)
    assert (in_memory.x0_m, in_memory.piston_area_m2) == (from_file.x0_m, from_file.piston_area_m2)
    for a, b in zip(in_memory.tests, from_file.tests, strict=True):
        assert a.pressure_bar == b.pressure_bar
        for field in ("height_m", "force_N", "piston_m", "compression", "step"):
            assert (getattr(a, field) == getattr(b, field)).all(), field
    assert in_memory.comments[:2] == from_file.comments[:2]  # the lines that say what made them
    assert from_file.comments == tuple(leading_comments(csv.read_text().splitlines()))
    assert from_file.sha256 == sha256_of(csv)  # taken when read: the bytes the fit is of


def test_write_report_refuses_too_few_draws(tmp_path):
    with pytest.raises(uq.InputError, match="at least 10 draws"):
        uq.write_report(object(), tmp_path, draws=5)


@pytest.mark.parametrize(
    "name",
    [
        "simulate",
        "fit_campaign",
        "write_report",
        "campaign_bands",
        "check",
        "enable_x64",
        "read_stand",
        "StandDescription",
        "table1",
    ],
)
def test_docstring_examples(name):
    _run_examples(getattr(uq, name), name)


@pytest.mark.slow
def test_package_examples_surface_margin_diagnose():
    """uq/__init__.py's examples: fit_surface, margin, the draws of a FittedModel, diagnose (minutes:
    JIT and screening)."""
    _run_examples(uq, "uq")


def test_public_names_resolve_and_are_documented():
    for name in uq.__all__:
        obj = getattr(uq, name)
        if callable(obj) and name not in ("InputError",):
            assert (obj.__doc__ or "").strip(), f"uq.{name} has no docstring"
    assert (
        uq.simulate is uq._stand.simulator.simulate_recordings
        and uq.check is uq._derived.check.check_documents
    )


def test_import_uq_loads_no_jax_and_leaves_x64_alone():
    code = (
        "import sys, uq; assert 'jax' not in sys.modules and 'numpy' not in sys.modules, sorted(sys.modules); "
        "uq.Layout; import jax; assert not jax.config.read('jax_enable_x64'); "
        "uq.fit_campaign; assert jax.config.read('jax_enable_x64'); "
        "uq.enable_x64(); uq.enable_x64(); assert jax.config.read('jax_enable_x64')"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout == "" and "Warning" not in out.stderr


def test_every_public_result_has_a_short_repr_and_a_summary(n50_fit):
    """Results print in a line (not the 238k characters of a dataclass full of arrays) and give an
    ArviZ-style summary table."""
    import pandas as pd

    bands = uq.campaign_bands(n50_fit, n_draws=200)
    for obj in (n50_fit, n50_fit.tests[0], n50_fit.tests[0].posterior, bands, bands.tests[0]):
        text = repr(obj)
        assert len(text) < 300 and "\n" not in text, text[:300]
    for obj in (n50_fit, n50_fit.tests[0], n50_fit.tests[0].posterior, bands):
        assert isinstance(obj.summary(), pd.DataFrame) and len(obj.summary())
    assert n50_fit.to_json()["tests"] and bands.to_json()["tests_at_x0"]


def test_library_errors_never_name_command_line_options():
    """Every InputError the library raises (outside uq/_cli) speaks of the library's parameters: a
    notebook user has no ``--load-N``. The command line rewrites them (InputError.for_cli)."""
    import ast
    import re
    from pathlib import Path

    option = re.compile(r"(^|[\s(`'\"])--[a-z]")
    root = Path(uq.__file__).parent
    found = []
    for path in sorted(root.rglob("*.py")):
        if path.relative_to(root).parts[0] == "_cli":
            continue
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not (
                isinstance(node, ast.Call)
                and getattr(node.func, "id", getattr(node.func, "attr", None)) == "InputError"
            ):
                continue
            for part in ast.walk(node):
                if isinstance(part, ast.Constant) and isinstance(part.value, str):
                    if option.search(part.value):
                        found.append(f"{path.relative_to(root)}:{node.lineno}: {part.value[:60]}")
    assert not found, "\n".join(found)


def test_cli_words_library_errors_with_its_options():
    from uq._cli.main import PARAM_OPTIONS
    from uq._io.errors import InputError

    e = InputError("sheet: 'Daten': x.xlsx has no such sheet", param="sheet").for_cli(PARAM_OPTIONS)
    assert str(e) == "option --sheet: 'Daten': x.xlsx has no such sheet"
    e = InputError("x.csv: two clusters; give a smaller `pressure_tolerance_bar`").for_cli(
        PARAM_OPTIONS
    )
    assert str(e) == "x.csv: two clusters; give a smaller --pressure-tolerance-bar"


def test_objects_a_user_makes_print_in_one_line(n50_recordings):
    """The recordings, a test, the stand, the settings and the orders print in a line (the
    recordings' dataclass repr was 23,751 characters)."""
    for obj in (
        n50_recordings,
        n50_recordings.tests[0],
        uq.PAPER_STAND,
        uq.PAPER_STAND.replace(load_cell_rel_sd=0.003),
        uq.Settings(),
        uq.Layout(),
        uq.Orders(),
        uq.ThermoOrders(),
        uq.SealedDesign(0.112, 5.0, 3.4),
    ):
        text = repr(obj)
        assert len(text) < 200 and "\n" not in text, text[:300]
    assert repr(n50_recordings).startswith("Recordings(") and "11 tests" in repr(n50_recordings)


def test_the_notebook_api_takes_every_fitted_model(n50_fit):
    """docs/api.md as a notebook user meets it: a margin from the cubics, a pressure without a
    test named with the tested ones, and uq.check of a fit against a file of point estimates."""
    answer = uq.margin(n50_fit, 0.112, 13020.0)
    assert answer["model"]["name"] == "cubics" and 4.9 < answer["pressure_bar_for_prob"] < 5.2
    with pytest.raises(uq.InputError, match=r"no test at 5.5 bar; the tests are at 0.1, 1, 2, "):
        n50_fit.at(5.5)
    verdict = uq.check(n50_fit, ROOT / "fits" / "n50" / "table1_points.json")
    assert verdict["agree"] and verdict["n_blocks"] == 22
    assert isinstance(n50_fit, uq.FittedModel) and n50_fit.on_draws(100).n_draws == 100
