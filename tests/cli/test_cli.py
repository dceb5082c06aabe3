"""The command line's promises (README, "The command line"): exit status, one-line errors before
any work, output paths checked up front, ``--json -``, progress display, ``--help`` and
``--version``, ``fit --config``, and the locked install."""

from __future__ import annotations

import argparse
import io
import json
import os
import re
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
from cli_helpers import one_line, run

from uq._cli import cmd_basic as _cmd_basic
from uq._cli import common as _cmd_common
from uq._cli.main import COMMANDS, build_parser, main
from uq._io import progress as _progress

ROOT = Path(__file__).resolve().parents[2]
N50 = str(ROOT / "data" / "n50" / "recordings.csv")
HEAVY = ("jax", "arviz", "matplotlib", "numpy", "scipy", "emcee", "optimistix")


@pytest.fixture
def no_fitting(monkeypatch):
    """Make every model fit fail the test: usage errors must be found before any fitting."""

    def forbidden(*a, **k):
        raise AssertionError("a fit started before the options were validated")

    # modules that bind a fitter by name at import are imported first: imported while it is
    # patched, they would keep the patched one for the rest of the session
    import uq._derived.comparison  # noqa: F401
    import uq._diagnose.engine
    import uq._drivers.batch  # noqa: F401
    import uq._drivers.calibrate
    import uq._models.cubic_fit
    import uq._models.discrepancy
    import uq._models.surface_likelihood
    import uq._models.thermo_likelihood

    monkeypatch.setattr(uq._models.cubic_fit, "fit_campaign", forbidden)
    monkeypatch.setattr(uq._models.surface_likelihood, "fit_surface", forbidden)
    monkeypatch.setattr(uq._models.discrepancy, "fit_discrepancy", forbidden)
    monkeypatch.setattr(uq._models.thermo_likelihood, "fit_thermo", forbidden)
    monkeypatch.setattr(uq._drivers.calibrate, "calibrate", forbidden)
    monkeypatch.setattr(uq._diagnose.engine, "diagnose", forbidden)


# ----------------------------------------------------------------------------- exit status 2


def _bad_usage_rows(tmp: Path):
    afile = tmp / "existing.txt"
    link = tmp / "link.json"
    return [
        # (argv, words the one line must contain)
        (["margin", N50, "--height-mm", 112, "--load-N", 13000, "--prob", 1.5], ["--prob", "1.5"]),
        (["margin", N50, "--height-mm", 112, "--load-N", 13000, "--prob", 0], ["--prob"]),
        (["margin", N50, "--height-mm", 112, "--load-N", -5], ["--load-N"]),
        (
            ["margin", N50, "--height-mm", 112, "--load-N", 13000, "--tolerance-pct", 5],
            ["--tolerance-pct", "--pressure-bar"],
        ),
        (
            ["margin", N50, "--height-mm", 112, "--load-N", 13000, "--pressure-bar", 20],
            ["--pressure-bar", "20"],
        ),
        (["margin", N50, "--height-mm", "nan", "--load-N", 13000], ["--height-mm"]),
        (["fit", N50, "--seed", -1], ["--seed"]),
        (["fit", N50, "--walkers", 3], ["--walkers"]),
        (["fit", N50, "--max-steps", "1e3"], ["--max-steps", "integer"]),
        (["fit", N50, "--x0-mm", "inf"], ["--x0-mm"]),
        (["fit", N50, "--json", tmp], ["--json", "folder"]),
        (["fit", N50, "--json", afile / "x.json"], ["--json", "not a folder"]),
        (["fit", N50, "--json", "/proc/uq-test/x.json"], ["--json", "cannot write"]),
        (["fit", N50, "--json", link], ["--json", "symbolic link"]),
        (["fit", N50, "--out", afile], ["--out", "existing file"]),
        (["fit"], ["recordings", "--config"]),
        (["report", N50, "--out", afile], ["--out", "existing file"]),
        (["report", N50, "--out", tmp / "r", "--draws", 0], ["--draws"]),
        (["surface", N50, "--report", afile], ["--report"]),
        (
            ["surface", N50, "--walkers", 8],
            ["--walkers", "12"],
        ),  # 5 noise parameters: emcee needs >= 10, a multiple of 4
        (
            ["margin", N50, "--height-mm", 112, "--load-N", 13000, "--walkers", 8],
            ["--walkers", "16"],
        ),  # the default model (the discrepancy surface) samples 8 parameters: >= 16 walkers
        (["diagnose", N50, "--report", afile], ["--report"]),
        (["diagnose", N50, "--json", tmp], ["--json"]),
        (["calibrate", "--truth", "prior,bogus"], ["--truth", "bogus"]),
        (["calibrate", "--reps", 0], ["--reps"]),
        (["calibrate", "--out", afile], ["--out"]),
        (["check", afile, "--against", afile, "--alpha", 2], ["--alpha"]),
        (["simulate", "--out", tmp], ["--out", "folder"]),
        (["simulate", "--out", tmp / "s.csv", "--step-mm", 0], ["--step-mm"]),
        (["simulate", "--out", tmp / "s.csv", "--pressures", "1,inf"], ["--pressures"]),
        (["simulate", "--out", tmp / "s.csv", "--spring", "n51"], ["--spring"]),
        (["fitt", N50], ["fitt"]),
        ([], ["COMMAND"]),
    ]


N_BAD_USAGE = 33


def test_bad_usage_table_size(tmp_path):
    assert len(_bad_usage_rows(tmp_path)) == N_BAD_USAGE


@pytest.mark.parametrize("row", range(N_BAD_USAGE))
def test_bad_usage_exits_2_with_one_line_before_any_work(row, tmp_path, capsys, no_fitting):
    (tmp_path / "existing.txt").write_text("keep me\n")
    os.symlink(tmp_path / "existing.txt", tmp_path / "link.json")
    before = sorted(p.name for p in tmp_path.rglob("*"))
    argv, words = _bad_usage_rows(tmp_path)[row]
    assert run(argv) == 2
    out, err = capsys.readouterr()
    line = one_line(err)
    assert line.startswith("uq") and "error" in line and "Traceback" not in err
    for w in words:
        assert w in line
    assert out == ""
    assert sorted(p.name for p in tmp_path.rglob("*")) == before  # nothing written
    assert (tmp_path / "existing.txt").read_text() == "keep me\n"


def test_margin_prob_refused_before_reading_or_fitting(monkeypatch, capsys):
    """The issue's example: --prob 1.5 used to fail only after 30 s of fitting."""
    import uq._cli.common
    import uq._models.discrepancy
    import uq._models.surface_likelihood

    calls = []
    monkeypatch.setattr(
        uq._models.surface_likelihood, "fit_surface", lambda *a, **k: calls.append("fit")
    )
    monkeypatch.setattr(
        uq._models.discrepancy, "fit_discrepancy", lambda *a, **k: calls.append("fit")
    )
    monkeypatch.setattr(uq._cli.common, "load", lambda *a, **k: calls.append("load"))
    assert run(["margin", N50, "--height-mm", 112, "--load-N", 13020, "--prob", 1.5]) == 2
    assert calls == []
    assert "--prob" in one_line(capsys.readouterr().err)


# ----------------------------------------------------------------------------- 0, 1, 3, 130


def _raise(exc):
    def command(args):
        raise exc

    return command


@pytest.mark.parametrize(
    "exc, status, words",
    [
        (
            RuntimeError("boom\nsecond line"),
            3,
            ["internal error", "RuntimeError", "boom", "--debug"],
        ),
        (KeyboardInterrupt(), 130, ["interrupted"]),
        (
            PermissionError(13, "Permission denied", "/somewhere/x.json"),
            2,
            ["Permission denied", "/somewhere/x.json"],
        ),
    ],
)
def test_exit_status_of_failures(monkeypatch, capsys, exc, status, words):
    monkeypatch.setattr(_cmd_basic, "command_simulate", _raise(exc))
    assert run(["simulate", "--out", os.devnull]) == status
    line = one_line(capsys.readouterr().err)
    assert line.startswith("uq simulate: ")
    for w in words:
        assert w in line


@pytest.mark.parametrize("how", [["--debug"], "UQ_DEBUG"])
def test_debug_prints_the_traceback(monkeypatch, capsys, how):
    monkeypatch.setattr(_cmd_basic, "command_simulate", _raise(RuntimeError("boom")))
    argv = ["simulate", "--out", os.devnull]
    if how == "UQ_DEBUG":
        monkeypatch.setenv("UQ_DEBUG", "1")
    else:
        argv += how
    assert run(argv) == 3
    err = capsys.readouterr().err
    assert "Traceback" in err and err.strip().splitlines()[-1].startswith(
        "uq simulate: internal error: RuntimeError: boom"
    )


@pytest.mark.parametrize("returned, status", [(0, 0), (1, 1), (None, 0)])
def test_command_status_passes_through(monkeypatch, returned, status):
    monkeypatch.setattr(_cmd_basic, "command_simulate", lambda args: returned)
    assert run(["simulate", "--out", os.devnull]) == status


def test_version(capsys):
    from importlib.metadata import version

    assert run(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"uq {version('airspring-uq')}"


# ----------------------------------------------------------------------------- help


def test_help_imports_nothing_heavy():
    """`uq --help` must stay fast: building the parser imports no numerical library.

    Checked in a fresh interpreter (this one has them loaded already); not a timed assertion.
    """
    code = (
        "import sys, uq._cli.main\n"
        "for argv in ([], ['fit'], ['simulate']):\n"
        "    uq._cli.main.build_parser(argv).format_help()\n"
        f"print(sorted(m for m in {HEAVY!r} if m in sys.modules))\n"
    )
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True
    ).stdout
    assert out.strip() == "[]"
    r = subprocess.run(
        [sys.executable, "-m", "uq._cli.main", "--help"], capture_output=True, text=True
    )
    assert r.returncode == 0 and all(name in r.stdout for name, _, _ in COMMANDS)


def test_fit_imports_neither_arviz_nor_xarray_nor_matplotlib(tmp_path):
    """`uq fit` without --out builds no InferenceData, saves no NetCDF and draws no figure, so it
    imports none of ArviZ, xarray and matplotlib (about a second of its time, issue 32): a whole
    fit of a tiny campaign in a fresh interpreter, short chains (imports are the point)."""
    csv = tmp_path / "tiny.csv"
    assert main(["simulate", "--out", str(csv), "--pressures", "2,5", "--step-mm", "15"]) == 0
    code = (
        "import sys\n"
        "from uq._cli.main import main\n"
        f"rc = main(['fit', {str(csv)!r}, '--walkers', '8', '--max-steps', '40', '--quiet'])\n"
        "print(rc, sorted(m for m in ('arviz', 'xarray', 'matplotlib') if m in sys.modules))\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert r.stdout.strip().splitlines()[-1] in ("0 []", "1 []"), r.stdout[-500:] + r.stderr[-2000:]


@pytest.mark.parametrize("name", [c[0] for c in COMMANDS])
def test_compilation_cache_is_on_for_every_command(name, tmp_path):
    """The persistent compilation cache must be configured before a command's module is imported
    (some import JAX at the top, and JAX reads its cache settings on import): in a fresh
    interpreter, after `uq NAME --help`, JAX's cache directory is UQ_CACHE_DIR."""
    code = (
        "import sys\n"
        "from uq._cli.main import main\n"
        "try:\n"
        f"    main([{name!r}, '--help'])\n"
        "except SystemExit:\n"
        "    pass\n"
        "import jax\n"
        "print('CACHE', jax.config.jax_compilation_cache_dir)\n"
    )
    env = {**os.environ, "UQ_CACHE_DIR": str(tmp_path)}
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env
    ).stdout
    assert out.strip().splitlines()[-1] == f"CACHE {tmp_path}"


def _subparser(name: str) -> argparse.ArgumentParser:
    return build_parser([name])._uq_commands[name]


@pytest.mark.parametrize("name", [c[0] for c in COMMANDS])
def test_every_default_is_shown_in_help(name):
    p = _subparser(name)
    fmt = p._get_formatter()
    checked = 0
    for action in p._actions:
        if not action.option_strings or action.default in (None, False, argparse.SUPPRESS):
            continue
        text = fmt._get_help_string(action) % {"default": action.default}
        shown = re.search(r"default:? ([^);]*)[);]", text) or re.search(r"(\S+) \(default\)", text)
        assert shown, (
            f"{name} {action.option_strings[0]}: default {action.default!r} not shown: {text!r}"
        )
        value = shown.group(1)
        if isinstance(action.default, tuple):  # a range LO..HI (uq design's --polytropic)
            lo_hi = re.match(r"([\d.]+)\.\.(\d+(?:\.\d+)?)", value)
            assert lo_hi and tuple(map(float, lo_hi.groups())) == action.default, (
                f"{name} {action.option_strings[0]}: help says {value!r}, parser {action.default!r}"
            )
            checked += 1
            continue
        try:
            same = float(value) == float(action.default)
        except (TypeError, ValueError):
            same = value == str(action.default)
        assert same, (
            f"{name} {action.option_strings[0]}: help says default {value!r}, parser uses {action.default!r}"
        )
        checked += 1
    # every command has a defaulted option to check but uq batch, whose options are all switches
    # or unset by default (in this process unless --workers/--scheduler)
    assert checked >= (0 if name == "batch" else 1)


def test_out_has_one_meaning():
    """--out is where the command writes: the CSV file for simulate, a folder elsewhere."""
    from uq._cli.main import OUTPUT_KIND, OUTPUT_KIND_BY_COMMAND

    for name, _, _ in COMMANDS:
        for action in _subparser(name)._actions:
            if "--out" in action.option_strings:
                kind = OUTPUT_KIND_BY_COMMAND.get((name, "out"), OUTPUT_KIND["out"])
                file = "PATH" if name == "export" else "FILE.csv"  # export: any format's file
                assert action.metavar == (file if kind == "file" else "DIR"), name
                assert ("file" if kind == "file" else "folder") in action.help, name


def test_light_constants_equal_the_library():
    from uq._data.recordings import DEFAULT_PISTON_AREA_CM2, DEFAULT_X0_MM
    from uq._data.reference import PAPER_PRESSURES_BAR
    from uq._inference.sampler import Settings
    from uq._stand.simulator import SPRINGS

    assert (_cmd_common.DEFAULT_PISTON_AREA_CM2, _cmd_common.DEFAULT_X0_MM) == (
        DEFAULT_PISTON_AREA_CM2,
        DEFAULT_X0_MM,
    )
    s = Settings()
    assert (
        _cmd_common.DEFAULT_WALKERS,
        _cmd_common.DEFAULT_ENSEMBLES,
        _cmd_common.DEFAULT_MAX_STEPS,
    ) == (s.n_walkers, s.n_ensembles, s.max_steps)
    assert set(_cmd_basic.SPRING_NAMES) == set(SPRINGS)
    assert _cmd_basic._pressures(_cmd_basic.PAPER_PRESSURES) == tuple(PAPER_PRESSURES_BAR)


def test_lazy_package_keeps_the_public_api():
    import uq
    import uq._models.cubic_fit

    assert uq.fit_campaign is uq._models.cubic_fit.fit_campaign
    assert {"fit_campaign", "read_recordings", "simulate", "InputError"} <= set(dir(uq))
    with pytest.raises(AttributeError):
        uq.no_such_thing  # noqa: B018


# ----------------------------------------------------------------------------- --json -


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    """A small campaign (6 tests, the fewest the surface model takes; 15 mm steps) and its fit JSON, made through the CLI."""
    d = tmp_path_factory.mktemp("small")
    csv = d / "r.csv"
    assert (
        main(
            [
                "simulate",
                "--out",
                str(csv),
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
    fit = d / "fit.json"
    assert (
        main(["fit", str(csv), "--json", str(fit), "--max-steps", "400", "--allow-unconverged"])
        == 0
    )
    means = [
        {
            "pressure_bar": t["pressure_bar"],
            **{b: {k: v["mean"] for k, v in t[b].items()} for b in ("force", "piston")},
        }
        for t in json.loads(fit.read_text())["tests"]
    ]
    (d / "points.json").write_text(json.dumps({"source": "the fit's own means", "tests": means}))
    (d / "batch.csv").write_text(
        "name,file,tasks,walkers,ensembles,max_steps\nsmall,r.csv,fit,8,2,60\n"
    )
    return d, csv, fit


def _json_rows(d: Path, csv: Path, fit: Path):
    quick = ["--max-steps", "300", "--walkers", "8", "--allow-unconverged"]
    return {
        "simulate": ["simulate", "--out", d / "s.csv", "--pressures", "1,2", "--step-mm", "10"],
        "fit": ["fit", csv, *quick],
        "report": ["report", csv, "--out", d / "rep", "--draws", "50", *quick],
        "check": ["check", fit, "--against", d / "points.json"],
        "surface": [
            "surface",
            csv,
            "--no-compare",
            "--max-steps",
            "300",
            "--allow-unconverged",
        ],  # 5 sampled parameters: >= 10 walkers
        "margin": [
            "margin",
            csv,
            "--height-mm",
            110,
            "--load-N",
            8000,
            "--max-steps",
            "300",
            "--allow-unconverged",
        ],
        "diagnose": ["diagnose", csv, "--max-mechanisms", "0", *quick],
        "design": [
            "design",
            csv,
            "--height-mm",
            110,
            "--charge-bar",
            5,
            "--volume-l",
            3.5,
            "--charges-bar",
            "4,6",
            "--draws",
            200,
            "--max-steps",
            "300",
            "--allow-unconverged",
        ],
        "calibrate": ["calibrate", "--reps", "1", "--truth", "prior"],
        "batch": ["batch", d / "batch.csv", "--out", d / "batch", "--allow-unconverged"],
        "plan": [
            "plan",
            csv,
            "--target",
            "force@110mm,5bar",
            "--max-readings",
            16,
            "--model",
            "surface",
            "--draws",
            30,
            "--max-steps",
            "300",
        ],
        "export": ["export", csv, "--out", d / "e.csv", "--draws", "200", "--max-steps", "300"]
        + ["--allow-unconverged"],
    }


def test_every_command_has_a_json_row():
    assert set(_json_rows(Path("."), Path("."), Path("."))) == {c[0] for c in COMMANDS}


#: commands whose own tests read their --json (test_batch, test_diagnose, test_calibration,
#: test_plan_command, tests/cli/test_export_command.py): their --json - runs with the slow suite
HEAVY = ("batch", "diagnose", "calibrate", "plan", "export")


@pytest.mark.parametrize(
    "name",
    [pytest.param(c[0], marks=pytest.mark.slow) if c[0] in HEAVY else c[0] for c in COMMANDS],
)
def test_json_dash_is_valid_json_on_stdout(name, small, capsys):
    argv = _json_rows(*small)[name]
    status = run([*argv, "--json", "-", "--quiet"])
    out, err = capsys.readouterr()
    assert status == 0, err
    json.loads(out)  # the whole of stdout is one JSON document; the human summary went to stderr
    assert err.strip()


# ----------------------------------------------------------------------------- progress


class FakeTerminal(io.StringIO):
    def isatty(self) -> bool:
        return True


@pytest.fixture
def restore_progress():
    yield
    _progress.set_enabled(False)


def test_progress_only_on_a_terminal_and_not_quiet(monkeypatch, restore_progress):
    tty = FakeTerminal()
    monkeypatch.setattr(sys, "stderr", tty)
    _progress.set_enabled(True)
    assert list(_progress.progress(range(3), desc="fits")) == [0, 1, 2]
    assert "fits" in tty.getvalue()
    _progress.set_enabled(False)  # --quiet
    assert isinstance(_progress.progress(range(3)), _progress.Silent)
    _progress.set_enabled(True)
    monkeypatch.setattr(sys, "stderr", io.StringIO())  # a pipe or a log file
    assert isinstance(_progress.progress(range(3)), _progress.Silent)


def test_no_bar_takes_no_multiprocessing_lock():
    """Where no bar is shown nothing takes tqdm's lock, a multiprocessing semaphore that the
    command's fast exit would leave to the resource tracker's warning (uq._io.progress)."""
    code = (
        "from uq._io.progress import progress\n"
        "list(progress(range(3), desc='fits'))\n"
        "with progress(total=3, desc='steps') as bar: bar.update(3)\n"
        "import multiprocessing.resource_tracker as rt, tqdm\n"
        "print(hasattr(tqdm.tqdm, '_lock'), rt._resource_tracker._pid is not None)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "False"]


@pytest.mark.parametrize("quiet, shown", [([], True), (["--quiet"], False)])
def test_cli_quiet_switches_progress_off(monkeypatch, restore_progress, quiet, shown):
    seen = []
    monkeypatch.setattr(sys, "stderr", FakeTerminal())
    monkeypatch.setattr(
        _cmd_basic, "command_simulate", lambda args: seen.append(_progress.active()) or 0
    )
    assert run(["simulate", "--out", os.devnull, *quiet]) == 0
    assert seen == [shown]


def test_campaign_fit_shows_a_step_bar(monkeypatch, restore_progress):
    """fit_campaign samples all tests in one emcee run: one bar over its steps."""
    import uq._models.cubic_fit as cubic

    seen = {}

    def fake_fit_items(items, *, seed, settings, desc, **kw):
        seen["desc"] = desc
        return [it.test for it in items]

    class Rec:
        path, tests, x0_m, piston_area_m2 = "r.csv", ["t1", "t2", "t3"], 0.112, 54.82e-4

    monkeypatch.setattr(cubic, "_fit_items", fake_fit_items)
    monkeypatch.setattr(cubic, "CampaignFit", lambda rec, fits, seed, stand, prov: fits)
    assert cubic.fit_campaign(Rec(), seed=1) == ["t1", "t2", "t3"]
    assert seen["desc"] == "sampling all tests"


# ----------------------------------------------------------------------------- fit --config


def test_fit_config_is_read_and_the_command_line_wins():
    parser = build_parser(["fit"])
    from uq._cli.main import _parse

    toml = ROOT / "fits" / "n50" / "fit.toml"
    args = _parse(parser, ["fit", "--config", str(toml)])
    assert Path(args.file).resolve() == Path(N50).resolve()
    raw = tomllib.loads(toml.read_text())
    assert (args.seed, args.walkers, args.max_steps, args.x0_mm) == (
        raw["sampling"]["seed"],
        raw["sampling"]["walkers"],
        raw["sampling"]["max_steps"],
        raw["data"]["x0_mm"],
    )
    args = _parse(build_parser(["fit"]), ["fit", "--config", str(toml), "--seed", "7", "other.csv"])
    assert (args.seed, args.file) == (7, "other.csv")


@pytest.mark.parametrize(
    "text, words",
    [
        ("[data]\nrecordings = 'r.csv'\nx0mm = 112\n", ["x0mm"]),
        ("[sampling]\nwalkers = 3\n", ["walkers"]),
        ("[sampler]\nwalkers = 16\n", ["[sampler]"]),
        ("[data\n", ["TOML"]),
    ],
)
def test_bad_fit_config_exits_2(tmp_path, capsys, no_fitting, text, words):
    cfg = tmp_path / "fit.toml"
    cfg.write_text(text)
    assert run(["fit", "--config", cfg]) == 2
    line = one_line(capsys.readouterr().err)
    assert str(cfg) in line and all(w in line for w in words)


# ----------------------------------------------------------------------------- install


def _lock() -> dict[str, str]:
    pins = {}
    for line in (ROOT / "requirements" / "lock.txt").read_text().splitlines():
        m = re.match(r"^([A-Za-z0-9_.-]+)==([^ ;\\]+)", line)
        if m:
            pins[re.sub(r"[-_.]+", "-", m.group(1)).lower()] = m.group(2)
        elif line.strip() and not line.lstrip().startswith(("#", "--hash")):
            raise AssertionError(f"not an exact pin: {line!r}")
    return pins


def test_lock_pins_every_dependency_within_pyproject_ranges():
    from packaging.requirements import Requirement

    pins = _lock()
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    reqs = [
        Requirement(r) for r in project["dependencies"] + project["optional-dependencies"]["test"]
    ]
    for r in reqs:
        name = re.sub(r"[-_.]+", "-", r.name).lower()
        assert name in pins, f"{r.name} is not in requirements/lock.txt"
        assert r.specifier.contains(pins[name], prereleases=True), (
            f"lock {name}=={pins[name]} outside {r}"
        )
    hashes = (ROOT / "requirements" / "lock.txt").read_text().count("--hash=sha256:")
    assert hashes >= len(pins)


def test_set_up_scripts_install_from_the_lock_and_ci_runs_the_test_command():
    install = (ROOT / "scripts" / "install.sh").read_text()
    assert "--require-hashes -r requirements/lock.txt" in install and "--no-deps" in install
    for script in ("main.sh", "test.sh"):
        assert "bash scripts/install.sh" in (ROOT / "scripts" / script).read_text()
    ci = (ROOT / ".ci" / "run").read_text()
    assert "set -euo pipefail" in ci and "bash scripts/test.sh" in ci
    assert "bash scripts/test.sh" in (ROOT / "README.md").read_text()


def test_a_model_says_it_does_not_use_the_noise_form(tmp_path, capsys):
    """A stand file whose noise differs in form (error_df, pressure_error_corr) given to a model
    command: one note on stderr that the model uses the budget but not the form (the stand is
    read before the recordings, so a missing recordings file still ends in exit 2 after it)."""
    stand = tmp_path / "rough.toml"
    stand.write_text("error_df = 5\npressure_error_corr = 0.7\n")
    assert run(["surface", tmp_path / "missing.csv", "--stand", stand]) == 2
    err = capsys.readouterr().err
    assert f"note: --stand {stand}: error_df, pressure_error_corr describe the noise's form" in err
    assert run(["simulate", "--out", tmp_path / "x.csv", "--pressures", "1", "--stand", stand]) == 0
    assert "note:" not in capsys.readouterr().err  # the virtual stand does use the form


def test_simulate_with_another_stand(tmp_path):
    """`uq simulate --stand` makes the noise of the stand described, and the file says so."""
    import numpy as np

    from uq._data.recordings import read_recordings

    stand = tmp_path / "noisy.toml"
    stand.write_text("load_cell_rel_sd = 0.02\n")
    scatter = {}
    for name, extra in (("paper", []), ("noisy", ["--stand", stand])):
        out = tmp_path / f"{name}.csv"
        assert run(["simulate", "--out", out, "--pressures", "8", "--seed", 5, *extra]) == 0
        (t,) = read_recordings(str(out)).tests
        res = t.force_N - np.polyval(np.polyfit(t.height_m, t.force_N, 3), t.height_m)
        scatter[name] = float(np.std(res))
    assert (
        "load_cell_rel_sd = 0.02" in (tmp_path / "noisy.csv").read_text().split("pressure_bar")[0]
    )
    # 2 % against 0.5 % of about 22 kN: the load-cell term dominates, so the scatter is several times larger
    assert scatter["noisy"] > 3 * scatter["paper"]
    bad = tmp_path / "bad.toml"
    bad.write_text("load_cell_rel = 0.02\n")
    assert run(["simulate", "--out", tmp_path / "x.csv", "--stand", bad]) == 2
    assert not (tmp_path / "x.csv").exists()


def test_sampling_runs_show_a_step_bar(monkeypatch, restore_progress):
    """Single sampling runs (surface, diagnose) count emcee steps; per-test fits (desc=None) stay silent."""
    import numpy as np
    from sampling_helpers import run_one

    from uq._inference.sampler import Settings

    def lp(th):
        return -0.5 * np.sum(np.asarray(th) ** 2, axis=1)

    settings = Settings(n_walkers=8, n_ensembles=2, max_steps=60, min_steps=40, chunk=20)
    tty = FakeTerminal()
    monkeypatch.setattr(sys, "stderr", tty)
    _progress.set_enabled(True)
    run_one(
        lp, np.zeros(2), np.eye(2), ("a", "b"), seed=1, settings=settings, desc="surface sampling"
    )
    assert "surface sampling" in tty.getvalue() and "step" in tty.getvalue()
    before = tty.getvalue()
    run_one(lp, np.zeros(2), np.eye(2), ("a", "b"), seed=1, settings=settings)
    assert tty.getvalue() == before
