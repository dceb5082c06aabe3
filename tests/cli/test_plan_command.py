"""``uq plan`` (uq/_cli/cmd_plan.py): refusals before any fit, the JSON's contract keys, the
recordings template (refused by the reader until filled, read once filled) and the figure.

The command's fit is replaced by planning frames built from the model's parts (tests/plan_helpers):
these tests check the command, not the sampler (``test_plan_runs_end_to_end`` fits, in the slow
suite; the engine's claims are carried by tests/derived/test_plan.py).
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from cli_helpers import one_line, run
from plan_helpers import surface_builder

ROOT = Path(__file__).resolve().parents[2]
FORCE_ONLY = ROOT / "data" / "n50-force-only" / "recordings.csv"
SMALL = ["--walkers", "16", "--ensembles", "2", "--max-steps", "300"]


@pytest.fixture(scope="module")
def pilot(tmp_path_factory):
    """A small n50-smooth campaign written by ``uq simulate`` (2, 5 and 8 bar, every 15 mm)."""
    d = tmp_path_factory.mktemp("plan")
    path = d / "pilot.csv"
    argv = ["simulate", "--spring", "n50-smooth", "--pressures", "2,5,8", "--step-mm", "15"]
    assert run([*argv, "--seed", "3", "--x-min-mm", "65", "--x-max-mm", "155", "--out", path]) == 0
    return path


@pytest.fixture
def no_fitting(monkeypatch):
    """Bad input must be refused before any fit."""
    import uq._cli.cmd_plan as cmd

    def forbidden(*a, **k):
        raise AssertionError("a fit started before the options were validated")

    monkeypatch.setattr(cmd, "_fit", forbidden)


@pytest.mark.parametrize(
    "extra, match",
    [
        (["--target", "forces@110mm,6bar"], "option --target: forces@110mm,6bar: unknown target"),
        (["--target", "force@110,6bar"], "not a number with a unit"),
        (["--target", "natural_frequency@112mm,5bar"], "--volume-l"),
        (
            ["--target", "force@110mm,6bar", "--target", "pressure_for@110mm,9000N"],
            "one value for several targets",
        ),
        (["--target", "force@300mm,6bar"], "outside the tested and candidate heights"),
        (["--target", "force@110mm,6bar", "--pressures-bar", "2,5,8"], "every pressure is tested"),
        (
            ["--target", "force@110mm,12bar", "--pressures-bar", "3,4"],
            "option --pressures-bar: target force@110mm,12bar: 12 bar lies outside",
        ),
        (["--target", "elastic_casing", "--model", "cubics"], "do not interpolate the volume"),
        (["--target", "force@110mm,6bar", "--target", "force@110mm,6bar"], "given twice"),
        (["--target", "force@110mm,6bar", "--walkers", "8"], "option --walkers: 8 walkers"),
        (
            ["--target", "force@110mm,6bar", "--theta-updates", "-3"],
            "--theta-updates: expected 0 (off) to 20000 simulated sets, got '-3'",
        ),
        (
            ["--target", "force@110mm,6bar", "--theta-updates", "many"],
            "--theta-updates: expected a whole number of simulated sets (0: off), got 'many'",
        ),
        (
            ["--target", "force@110mm,6bar", "--theta-pool", "0"],
            "--theta-pool: expected a positive integer, got '0'",
        ),
    ],
)
def test_refused_before_the_fit(pilot, no_fitting, capsys, extra, match):
    status = run(["plan", pilot, *extra, "--target-sd", "10"])
    assert status == 2
    assert match in one_line(capsys.readouterr().err)


@pytest.mark.parametrize(
    "argv, match",
    [
        (["--target", "force@110mm,6bar"], "one of the arguments --max-readings --target-sd"),
        (
            ["--target", "force@110mm,6bar", "--max-readings", "5", "--target-sd", "3"],
            "not allowed with argument",
        ),
        (["--target", "force@110mm,6bar", "--max-readings", "0"], "--max-readings"),
        (
            ["--target", "force@110mm,6bar", "--max-readings", "9", "--heights-mm", "90:80:5"],
            "A <= B",
        ),
        (
            ["--target", "force@110mm,6bar", "--max-readings", "9", "--pressures-bar", "1:2"],
            "A:B:STEP",
        ),
    ],
)
def test_usage_errors(pilot, no_fitting, capsys, argv, match):
    assert run(["plan", pilot, *argv]) == 2
    assert match in one_line(capsys.readouterr().err)


def test_volume_targets_need_piston_readings(no_fitting, capsys):
    assert run(["plan", FORCE_ONLY, "--target", "elastic_casing", "--max-readings", "20"]) == 2
    assert "no piston readings" in one_line(capsys.readouterr().err)


def _from_a_fit(builder, n_used=6):
    """A builder as ``of_fit`` makes it: ``n_used`` of its draws thinned, the rest its pool."""
    from uq._derived.plan_frames import _thin

    all_theta = builder.theta
    builder._set_theta(_thin(all_theta, n_used))
    builder.all_theta = all_theta
    return builder


@pytest.fixture(scope="module")
def planned(pilot, tmp_path_factory):
    """One ``uq plan --json --template --plot`` run on frames of the pilot: (JSON, template, figure,
    stdout)."""
    import contextlib
    import io

    import uq._cli.cmd_plan as cmd
    import uq._derived.plan_frames as pf
    from uq._data.recordings import read_recordings

    out = tmp_path_factory.mktemp("planned")
    paths = {k: out / f"plan.{k}" for k in ("json", "csv", "png")}
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(cmd, "_fit", lambda args, *a: (read_recordings(args.file), {"name": "surface"}))
        mp.setattr(pf, "frames_of", lambda rec, draws: _from_a_fit(surface_builder(rec, 14)[0]))
        buf = io.StringIO()
        with contextlib.redirect_stdout(buf):
            status = run(
                [
                    "plan",
                    pilot,
                    "--target",
                    "force@110mm,6.5bar",
                    "--target",
                    "elastic_casing",
                    "--max-readings",
                    "30",
                    "--pressures-bar",
                    "1,3.5,6.5,10",
                    "--heights-mm",
                    "65:155:15",
                    "--json",
                    paths["json"],
                    "--template",
                    paths["csv"],
                    "--plot",
                    paths["png"],
                ]
            )
    assert status == 0, buf.getvalue()
    return json.loads(paths["json"].read_text()), paths["csv"], paths["png"], buf.getvalue()


def test_json_has_the_contracts_keys(planned):
    doc = planned[0]
    assert doc["model"] == "surface"
    assert 1 <= doc["n_pressure_changes"] and doc["n_readings"] <= 30
    assert sum(len(t["heights_mm"]) for t in doc["tests"]) == doc["n_readings"]
    for t in doc["tests"]:
        assert t["pressure_bar"] in (1.0, 3.5, 6.5, 10.0)
        assert len(t["branches"]) == len(t["heights_mm"])
    specs = [t["spec"] for t in doc["targets"]]
    assert specs == ["force@110mm,6.5bar", "elastic_casing"]
    for t in doc["targets"]:
        for key in ("sd_now", "sd_predicted", "sd_uniform_grid", "sd_paper_protocol"):
            assert t[key] is None or t[key] > 0
    assert doc["targets"][0]["unit"] == "N" and doc["targets"][1]["unit"] == "1/bar"
    assert doc["paper_protocol"]["n_readings"] == 8 * 37
    assert doc["uniform_grid"]["n_readings"] == doc["n_readings"]


def test_summary_names_the_plan_and_what_it_leaves_out(planned):
    text = planned[3]
    assert "add " in text and "left out" in text and "paper's protocol" in text
    assert "with theta updated by the readings (200 simulated sets" in text
    assert "effective theta draws of 8 held out of those the sets come from (Kish" in text


def test_json_states_the_prediction_with_theta_updated(planned):
    """Per target the distribution of the sd over the simulated sets, ordered, and the weights'
    effective sample size (at most the pool's draws, 8 here, held out of the 6 the sets come from);
    the same for the uniform grid."""
    doc = planned[0]
    assert doc["theta_updates"]["sets"] == 200
    for t in doc["targets"]:
        for key in ("sd_after_theta_updated", "sd_uniform_grid_theta_updated"):
            d = t[key]
            assert 0 < d["p10"] <= d["median"] <= d["p90"] and d["mean"] > 0
            assert 1.0 <= d["ess_min"] <= d["ess_median"] <= 8.0 + 1e-9
            assert d["draws"] == 8 and d["held_out"] is True
            assert 0.0 <= d["small_ess_share"] <= 1.0


def test_template_is_refused_until_filled_then_read(planned, pilot, tmp_path):
    """The template holds the pilot's rows and the planned ones; the reader refuses it naming the
    first empty cell and counting the planned readings still empty; filled in, it reads."""
    from uq._data.recordings import read_recordings
    from uq._io.errors import InputError
    from uq._stand.simulator import simulate_planned

    doc, template = planned[0], planned[1]
    text = template.read_text()
    n_pilot = read_recordings(pilot).n_points
    with pytest.raises(InputError) as exc:
        read_recordings(template)
    msg = str(exc.value)
    lines = text.splitlines()
    planned_rows = [i for i, ln in enumerate(lines) if ",,," in ln]
    assert len(planned_rows) == doc["n_readings"]
    assert msg.startswith(
        f"{template}, row {planned_rows[0] + 1}, column 'force_N': empty: a reading"
    )
    assert f"({doc['n_readings']} planned readings still empty)" in msg
    sim = simulate_planned("n50-smooth", doc["tests"], seed=1)
    values = iter((f, p) for t in sim for f, p in zip(t["force_N"], t["piston_m"], strict=True))
    for i in planned_rows:
        f, p = next(values)
        lines[i] = lines[i].replace(",,,", f",{f:.2f},{p * 1e3:.3f},", 1)
    filled = tmp_path / "filled.csv"
    filled.write_text("\n".join(lines) + "\n")
    rec = read_recordings(filled)
    assert rec.n_points == n_pilot + doc["n_readings"]
    assert len(rec.tests) == 3 + doc["n_pressure_changes"]


def test_figure_is_a_png(planned):
    assert planned[2].read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.slow  # the command with its fit; the engine's claims: tests/derived/test_plan.py
def test_plan_runs_end_to_end(pilot, tmp_path, capsys):
    out = tmp_path / "plan.json"
    argv = ["plan", pilot, "--target", "pressure_for@110mm,9000N", "--max-readings", "20"]
    assert run([*argv, "--model", "surface", *SMALL, "--json", out, "--draws", "40"]) == 0
    doc = json.loads(out.read_text())
    assert doc["model"] == "surface" and doc["n_readings"] <= 20
    assert np.isfinite(doc["targets"][0]["sd_predicted"])


def test_model_choices_and_default_come_from_the_registry():
    """--model takes auto and every registered model; its default is the registry's for plan."""
    import argparse

    import uq._cli.cmd_plan as cmd
    from uq._derived.margin import AUTO
    from uq._models import registry

    p = argparse.ArgumentParser()
    cmd.configure_plan(p)
    action = next(a for a in p._actions if a.dest == "model")
    assert tuple(action.choices) == (AUTO, *registry.names())
    assert action.default == registry.default("plan")


def test_a_model_without_a_planning_frame_is_refused_in_one_line():
    """A fitted model the planner has no frame of (a model plugged in from outside) is refused
    with an InputError naming it, not an AttributeError deep in the planner."""
    from model_doubles import ModelDouble

    from uq._derived.plan_frames import frames_of
    from uq._io.errors import InputError

    class Outside(ModelDouble):
        name = "rolling_lobe"
        label = "rolling lobe"

    with pytest.raises(InputError, match="no planning frame for the model 'rolling_lobe'"):
        frames_of(Outside())


@pytest.mark.parametrize("median, said", [(2.0, True), (9.0, False)])
def test_says_when_the_closed_form_is_far_from_the_theta_updated_median(capsys, median, said):
    """A closed form 1.5 times the theta-updated median or more (or as far below) gets one line
    saying so; close to it, nothing."""
    from types import SimpleNamespace

    from uq._cli.cmd_plan import _print_theta_updated
    from uq._derived.plan_targets import parse_target

    d = {"median": median, "p10": median / 2, "p90": median * 2, "mean": median}
    d |= {
        "ess_min": 5.0,
        "ess_median": 20.0,
        "small_ess_share": 0.0,
        "draws": 400,
        "held_out": True,
    }
    plan = SimpleNamespace(
        theta_updates=200,
        targets=[parse_target("force@110mm,6bar")],
        sd_predicted=[10.0],
        sd_after_theta_updated=[d],
        sd_uniform_theta_updated=[None],
    )
    _print_theta_updated(plan)
    out = capsys.readouterr().out
    assert ("the closed form is 5 times the median with theta updated" in out) is said
    assert "effective theta draws of 400 held out" in out
