"""Every script of the repository (scripts/, fits/, benchmarks/) runs, with tiny settings, so none rots.

The scripts are run as a user runs them: ``python PATH ARGS`` in a fresh interpreter, from the
repository root unless a test says otherwise. Their numbers are not checked here (they are
proofs and measurements, reviewed where their results are committed), only that they run to
the end and write what they promise, where they promise it.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import openpyxl
import pytest
import scipy.io

ROOT = Path(__file__).resolve().parents[1]

#: Every script and the test that runs it (test_every_script_is_run_by_a_test checks the list).
RUN_BY = {
    "benchmarks/bench.py": "test_bench_tiny_run_writes_only_where_asked",
    "benchmarks/commands.py": "test_commands_bench_tiny_run",
    "benchmarks/discrepancy.py": "test_discrepancy_bench_tiny_run",
    "benchmarks/bench_tables.py": "test_bench_tables_one_row_formatter (imported by bench.py and "
    "readme_numbers.py, whose --check tests/test_docs.py runs)",
    "fits/n50/make_points.py": "test_make_points_reproduces_the_committed_file",
    "scripts/diagnose_proof.py": "test_diagnose_proof_small",
    "scripts/diagnose_power.py": "test_diagnose_power_tiny",
    "scripts/readme_numbers.py": "tests/test_docs.py (--check, and every run block rerun)",
    "scripts/docs_figure.py": "test_docs_figure_from_a_small_report",
    "scripts/export_n50.py": "test_export_n50_from_a_saved_model",
    "scripts/mkdocs_hooks.py": "tests/test_docs.py::test_api_reference_lists_every_public_name "
    "(and the mkdocs build of scripts/test.sh)",
    "scripts/sbc_piston_exact.py": "test_sbc_piston_exact_few_replications",
    "scripts/margin_coverage.py": "test_margin_coverage_tiny",
    "scripts/plan_proof.py": "test_plan_proof_tiny",
    "scripts/between_coverage.py": "tests/models/test_discrepancy_scripts.py",
    "scripts/coverage_tables.py": "imported by between_coverage.py (its tests) and readme_numbers.py "
    "(tests/test_docs.py's --check regenerates docs/validation.md's model-check table with it)",
    "scripts/n50_bands.py": "tests/models/test_discrepancy_scripts.py",
    "scripts/between_decomposition.py": "tests/models/test_discrepancy_scripts.py",
    "scripts/importance_coverage.py": "test_importance_coverage_tiny",
    "scripts/maxwell_table1.py": "test_maxwell_table1_reproduces_the_committed_report",
    "scripts/noise_check_study.py": "test_noise_check_study_tiny",
    "scripts/sealed_coverage.py": "tests/derived/test_design.py::test_coverage_script_runs_with_tiny_settings",
    "scripts/install.sh": "test_shell_scripts_parse (and every CI run: scripts/test.sh calls it)",
    "scripts/main.sh": "test_shell_scripts_parse",
    "scripts/test.sh": "test_shell_scripts_parse (and every CI run)",
}


def _run(*argv, cwd=ROOT, timeout=900) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, *map(str, argv)], cwd=cwd, capture_output=True, text=True, timeout=timeout
    )


def test_every_script_is_run_by_a_test():
    found = {
        str(p.relative_to(ROOT))
        for folder in ("scripts", "fits", "benchmarks")
        for p in (ROOT / folder).rglob("*")
        if p.suffix in (".py", ".sh") and "__pycache__" not in p.parts
    }
    assert found == set(RUN_BY), "scripts without a test (add one here): " + str(
        sorted(found ^ set(RUN_BY))
    )


def test_bench_tables_one_row_formatter():
    """The memory table's cells, once: as docs/speed.md shows them (markdown) and on the console
    (right-aligned columns), the console's extra column added by the caller."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        from bench_tables import MEMORY, table
    finally:
        sys.path.pop(0)
    runs = [
        {"readings": 6347, "peak_rss_mb": 575.6, "line_error_mb": -36.4, "fit_model_mb": 884.0},
        {"readings": 12683, "peak_rss_mb": 465.2, "line_error_mb": 54.0, "fit_model_mb": 1005.3},
    ]
    assert table(MEMORY, runs, True) == [
        "| readings | peak RSS | the measured line minus the peak | uq fit's model (the check) |",
        "| --- | --- | --- | --- |",
        "| 6347 | 576 MB | -36 MB | 884 MB |",
        "| 12683 | 465 MB | +54 MB | 1005 MB |",
    ]
    assert table(MEMORY[:2] + (("s", lambda x: "7"),), runs, False) == [
        "  readings  peak RSS  s",
        "      6347    576 MB  7",
        "     12683    465 MB  7",
    ]


@pytest.mark.parametrize("name", ["install.sh", "main.sh", "test.sh"])
def test_shell_scripts_parse(name):
    proc = subprocess.run(["bash", "-n", ROOT / "scripts" / name], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr


def test_make_points_reproduces_the_committed_file(tmp_path):
    out = tmp_path / "points.json"
    proc = _run("fits/n50/make_points.py", "--out", out)
    assert proc.returncode == 0, proc.stderr
    assert out.read_bytes() == (ROOT / "fits" / "n50" / "table1_points.json").read_bytes()


def test_sbc_piston_exact_few_replications():
    proc = _run("scripts/sbc_piston_exact.py", 12, 7)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert [ln.split(":")[0] for ln in lines] == ["a_L", "b_L", "c_L", "d_L"]
    assert all("chi-square p = " in ln for ln in lines)


def test_diagnose_proof_small(tmp_path):
    proc = _run(
        "scripts/diagnose_proof.py", "--small", "--limit", 1, "--jobs", 1, "--out", tmp_path
    )
    assert proc.returncode == 0, proc.stderr
    results = json.loads((tmp_path / "results.json").read_text())
    assert len(results) == 1 and results[0]["key"].endswith("|small")
    assert json.loads((tmp_path / "summary.json").read_text())["n_runs"] == 1
    assert (tmp_path / "README.md").read_text().startswith("# uq diagnose: proof")


def test_diagnose_proof_shapes_and_elastic_casing():
    """The proof's campaigns include the elastic casing at two magnitudes on every layout and
    seed, and clean one-branch and one-pass controls; the shapes are what they say (no rebound;
    a catalogue read back without order or piston)."""
    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        import diagnose_proof as dp
    finally:
        sys.path.remove(str(ROOT / "scripts"))
    from uq._data.recordings import recordings_from_text
    from uq._data.stand_description import PAPER_STAND
    from uq._stand.simulator import Layout, simulate

    cases = dp.cases(1)
    elastic = [c for c in cases if "elastic_casing" in c["effects"]]
    assert {(c["layout"], c["level"]) for c in elastic} == {
        (lay, lev) for lay in dp.LAYOUTS for lev in ("visible", "near-limit")
    }
    shaped = [c for c in cases if c.get("shape")]
    assert sorted(c["shape"] for c in shaped) == sorted(dp.SHAPES * len(dp.LAYOUTS))
    assert all(c["level"] == "clean" and not c["effects"] for c in shaped)
    assert len({dp.key(c) for c in cases}) == len(cases)
    layout = Layout(**dp.SMALL_LAYOUTS["paper"])
    tests = simulate("n50-traditional", seed=1, layout=layout)
    one = dp.shaped(tests, {"shape": "one-branch", "effects": {}}, PAPER_STAND, layout)
    assert all(
        t["compression"].all() and t["height_m"].size < s["height_m"].size
        for t, s in zip(one, tests, strict=True)
    )
    text = dp.shaped(tests, {"shape": "one-pass", "effects": {}}, PAPER_STAND, layout)
    rec = recordings_from_text(text, "catalogue")
    assert not rec.order_known and not rec.has_piston and rec.has_volume
    assert not rec.has_both_branches


def test_noise_check_study_tiny(tmp_path):
    """The noise-check study on a small layout: the check passes at the budget with the model the
    campaign was made with, and fails at 1.5x the budget (the claim reports/noise-check makes on
    92 campaigns; the full run takes minutes)."""
    proc = _run("scripts/noise_check_study.py", "--tiny", "--out", tmp_path)
    assert proc.returncode == 0, proc.stderr
    d = json.loads((tmp_path / "results.json").read_text())
    verdicts = {r["what"]: r["passes"] for r in d["results"]}
    assert verdicts == {"clean": True, "casing_force": True, "1.5x budget": False}, verdicts
    assert (
        d["summary"]["null_alarms"] == 0
        and "false-alarm rate at most" in (tmp_path / "README.md").read_text()
    )


def test_diagnose_power_tiny(tmp_path):
    proc = _run(
        "scripts/diagnose_power.py",
        "--tiny",
        "--jobs",
        1,
        "--mechanisms",
        "force_offset",
        "--out",
        tmp_path,
    )
    assert proc.returncode == 0, proc.stderr
    d = json.loads((tmp_path / "power.json").read_text())
    assert d["seeds_per_rung"] == 2 and d["campaigns"]
    assert {r["mechanism"] for r in d["campaigns"]} == {"force_offset"}
    v = d["mechanisms"]["force_offset"]
    assert v["oracle_exact_90"]["magnitude_90"] > 0
    assert all(r["oracle_delta_chi2"] >= 0 for r in d["campaigns"])
    assert (tmp_path / "README.md").read_text().startswith("# uq diagnose: power")


def test_diagnose_power_oracle_null_and_power():
    """The oracle's delta chi^2 is chi^2_k on clean campaigns (its mean is k, within 4 SE over
    60 seeds) and above twice its threshold for a mechanism well above its limit: it is the likelihood-ratio test it
    claims to be."""
    sys.path.insert(0, str(ROOT / "scripts"))
    try:
        import diagnose_power as pw
    finally:
        sys.path.remove(str(ROOT / "scripts"))
    import numpy as np
    from scipy.stats import chi2

    for mech in ("force_offset", "elastic_casing", "hysteresis"):
        tests, _ = pw.campaign(mech, 0.0, 0, True)
        oracle = pw.Oracle(mech, tests)
        null = []
        for seed in range(60):
            tests, _ = pw.campaign(mech, 0.0, seed, True)
            force = np.concatenate([t["force_N"] for t in tests])
            piston = np.concatenate([t["piston_m"] for t in tests])
            null.append(oracle.delta_chi2(force, piston))
        k = oracle.k
        assert abs(np.mean(null) - k) < 4 * np.sqrt(2 * k / 60), (mech, np.mean(null), k)
        big = {"force_offset": 50.0, "elastic_casing": 0.02, "hysteresis": 0.05}[mech]
        tests, _ = pw.campaign(mech, big, 0, True)
        force = np.concatenate([t["force_N"] for t in tests])
        piston = np.concatenate([t["piston_m"] for t in tests])
        assert oracle.delta_chi2(force, piston) > 2 * chi2.isf(pw.alpha(), k)


def test_docs_figure_from_a_small_report(tmp_path):
    """The README's figure is the report's Figure 2 (here of a small campaign, short chains)."""
    import matplotlib.image

    csv, png = tmp_path / "small.csv", tmp_path / "fig.png"
    simulate = ["simulate", "--out", csv, "--pressures", "1,5", "--step-mm", 10]
    assert _run("-m", "uq._cli.main", *simulate).returncode == 0
    quick = ["--max-steps", 200, "--walkers", 8, "--draws", 50, "--allow-unconverged"]
    proc = _run("scripts/docs_figure.py", "--recordings", csv, "--out", png, *quick)
    assert proc.returncode == 0, proc.stderr
    image = matplotlib.image.imread(png)
    assert image.ndim == 3 and image.shape[0] > 300 and image.shape[1] > 400
    assert image[..., :3].std() > 0.05  # drawn, not blank


TINY_BENCH = ["--seed", 3, "--walkers", 8, "--max-steps", 60, "--baseline-walkers", 12]


def test_bench_tiny_run_writes_only_where_asked(tmp_path):
    """The ESS benchmark with tiny settings: structure and positive rates, never timing; the JSON
    goes to --json and nowhere else (uq bench also wrote reports/bench/ess.json into the cwd)."""
    out = tmp_path / "result" / "ess.json"
    proc = _run(
        ROOT / "benchmarks" / "bench.py", "--seconds", 0, *TINY_BENCH, "--json", out, cwd=tmp_path
    )
    assert proc.returncode == 0, proc.stderr
    assert [p.relative_to(tmp_path) for p in tmp_path.rglob("*") if p.is_file()] == [
        Path("result/ess.json")
    ]
    r = json.loads(out.read_text())
    assert r["cores"] >= 1 and r["load_average_1min"] >= 0
    assert r["n_points"] == 37 and r["seed"] == 3 and "5 bar" in r["workload"]
    for name in ("project", "baseline"):
        block = r[name]
        assert block["runs"] >= 1 and block["wall_s"] > 0
        assert block["ess_bulk_min"] > 0 and block["ess_per_s"] > 0
    assert r["ratio"] == r["project"]["ess_per_s"] / r["baseline"]["ess_per_s"] > 0
    names = ("a_P", "b_P", "c_P", "d_P", "sigma0_N", "rel_force")
    assert tuple(r["ratio_each"]) == names and r["ratio_min_all"] == min(r["ratio_each"].values())
    for n in names:
        want = r["project"]["ess_per_s_each"][n] / r["baseline"]["ess_per_s_each"][n]
        assert r["ratio_each"][n] == want
    assert "ratio project / baseline" in proc.stdout and f"written to {out}" in proc.stdout


def test_commands_bench_tiny_run(tmp_path):
    """The command benchmark on a small campaign with a short chain, one repetition, the same
    code as its own baseline: the JSON's ratios are the medians of its pairs, the summary names
    every command; never timing."""
    csv, out = tmp_path / "small.csv", tmp_path / "r.json"
    simulate = ["simulate", "--out", csv, "--pressures", "1,5", "--step-mm", 10]
    assert _run("-m", "uq._cli.main", *simulate).returncode == 0
    proc = _run(
        ROOT / "benchmarks" / "commands.py",
        *("--commands", "fit", "--reps", 1, "--cold", "--recordings", csv),
        *("--extra", "--max-steps 100 --walkers 8", "--baseline", ROOT, "--json", out),
        cwd=tmp_path,
    )
    assert proc.returncode == 0, proc.stderr
    r = json.loads(out.read_text())
    fit = r["commands"]["fit"]
    (run,) = fit["runs"]
    assert (
        fit["ratio_wall"] == run["ratio_wall"] == run["command"]["wall_s"] / run["floor"]["wall_s"]
    )
    assert fit["baseline"]["ratio_cpu"] == run["ratio_cpu_baseline"] > 0
    assert fit["goal_ratio"] == 1.6 and fit["peak_rss_mb"] > 0
    assert "fit" in proc.stdout and "import floor" in proc.stdout
    bad = _run(ROOT / "benchmarks" / "commands.py", "--commands", "fit,nope")
    assert bad.returncode == 2 and "--commands" in bad.stderr


def test_discrepancy_bench_tiny_run(tmp_path):
    """The malloc benchmark: a few calls each way in one process, the JSON's ratio is the two
    runs' CPU times' (never timing); with glibc the thresholds are set in its second run; the
    previous formula against the current one likewise, with the same values."""
    import platform

    out = tmp_path / "d.json"
    proc = _run(
        ROOT / "benchmarks" / "discrepancy.py",
        "--calls",
        2,
        "--walkers",
        8,
        "--json",
        out,
        cwd=ROOT,
    )
    assert proc.returncode == 0, proc.stderr
    r = json.loads(out.read_text())
    cpu = {k: v["user_ms"] + v["sys_ms"] for k, v in r["runs"].items()}
    assert r["cpu_ratio"] == pytest.approx(cpu["malloc_defaults"] / cpu["tuned"])
    assert r["allocator_tuned"] is (platform.libc_ver()[0] == "glibc")
    assert "malloc's defaults over one with uq's thresholds" in proc.stdout
    f = {k: v["user_ms"] + v["sys_ms"] for k, v in r["formulas"].items()}
    assert r["formula_cpu_ratio"] == pytest.approx(f["previous"] / f["current"])
    assert r["formula_max_rel_diff"] < 1e-9  # the same density (tests/models/test_discrepancy.py)
    assert "previous formula over one of the current" in proc.stdout


def test_commands_bench_runs_the_baselines_code(tmp_path, monkeypatch):
    """The benchmark's child runs the package its PYTHONPATH names, even when the benchmark is
    started from a checkout's root (``python -c`` puts the working directory first on sys.path):
    a stand-in ``uq`` whose command line writes a mark, and ends the process as the program does,
    is the one run, and its usage is reported."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(
        "bench_commands", ROOT / "benchmarks" / "commands.py"
    )
    commands = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(commands)
    fake = tmp_path / "baseline"
    for sub in ("_cli", "_io"):
        (fake / "uq" / sub).mkdir(parents=True)
        (fake / "uq" / sub / "__init__.py").write_text("")
    (fake / "uq" / "__init__.py").write_text("")
    mark = tmp_path / "mark"
    (fake / "uq" / "_io" / "processes.py").write_text(
        "import os\ndef exit_now(status=0, **kw):\n    os._exit(status)\n"
    )
    (fake / "uq" / "_cli" / "main.py").write_text(  # the program: it ends the process itself
        "import sys\nfrom uq._io import processes\n"
        f"def main():\n    open({str(mark)!r}, 'w').write(' '.join(sys.argv[1:]))\n"
        "    processes.exit_now(0)\n"
    )
    monkeypatch.chdir(ROOT)
    r = commands.run_child(["uq", "fit", "x.csv"], commands._with_path(dict(os.environ), fake))
    assert r["exit"] == 0 and mark.read_text() == "fit x.csv" and r["cpu_s"] > 0


@pytest.mark.parametrize(
    "argv, words",
    [
        (["--seconds", "-1"], "--seconds"),
        (["--baseline-walkers", "7"], "--baseline-walkers"),
        (["--scaling", "--margin"], "not allowed with"),
        (["--memory", "--steps-mm", "1"], "--steps-mm"),
        (["--memory", "--steps-mm", "1,-2"], "--steps-mm"),
        (["--batch", "20,0"], "--batch"),
    ],
)
def test_bench_bad_options_exit_2(argv, words):
    proc = _run(ROOT / "benchmarks" / "bench.py", *argv)
    assert proc.returncode == 2 and words in proc.stderr, proc.stderr


@pytest.mark.slow
@pytest.mark.parametrize(
    "argv, key",
    [
        (["--scaling", "--factors", "1,2", "--walkers", 8, "--max-steps", 200], "runs"),
        (["--batch", "1,2", "--walkers", 8, "--max-steps", 100], "ratio_serial_to_batched"),
        (["--margin", "--queries", 3, "--max-steps", 400], "ratio_full_to_saved"),
        (
            ["--memory", "--steps-mm", "10,5", "--walkers", 8, "--max-steps", 100],
            "measured_bytes_per_reading",
        ),
    ],
)
def test_bench_other_measurements_run(argv, key, tmp_path):
    out = tmp_path / "r.json"
    proc = _run(ROOT / "benchmarks" / "bench.py", *argv, "--json", out, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert key in json.loads(out.read_text())


def test_maxwell_table1_reproduces_the_committed_report(tmp_path):
    """scripts/maxwell_table1.py with its defaults writes reports/maxwell-table1 again: the page
    word for word, the JSON's numbers to 1e-6 (linear algebra on another machine or thread count
    moves the last digits of the Monte Carlo summaries, at about 1e-8)."""
    import math

    proc = _run(ROOT / "scripts" / "maxwell_table1.py", "--out", tmp_path)
    assert proc.returncode == 0, proc.stderr
    here = f"python scripts/maxwell_table1.py --out {tmp_path}"
    committed = (ROOT / "reports" / "maxwell-table1" / "summary.md").read_text()
    assert (tmp_path / "summary.md").read_text() == committed.replace(
        "python scripts/maxwell_table1.py", here
    )

    def same(a, b, where="") -> list[str]:
        if isinstance(a, dict) and isinstance(b, dict) and a.keys() == b.keys():
            return [d for k in a for d in same(a[k], b[k], f"{where}/{k}")]
        if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
            return [
                d
                for i, (x, y) in enumerate(zip(a, b, strict=True))
                for d in same(x, y, f"{where}[{i}]")
            ]
        if isinstance(a, float) and isinstance(b, int | float):
            return [] if math.isclose(a, b, rel_tol=1e-6, abs_tol=1e-12) else [f"{where}: {a} {b}"]
        return [] if a == b else [f"{where}: {a!r} {b!r}"]

    made = json.loads((tmp_path / "maxwell.json").read_text())
    kept = json.loads((ROOT / "reports" / "maxwell-table1" / "maxwell.json").read_text())
    kept["command"] = kept["command"].replace("python scripts/maxwell_table1.py", here)
    assert not same(made, kept)


def test_margin_coverage_tiny(tmp_path):
    """One coarse-grid campaign, both models, three queries: the JSON and the summary page."""
    proc = _run("scripts/margin_coverage.py", "--tiny", "--out", tmp_path)
    assert proc.returncode == 0, proc.stderr
    doc = json.loads((tmp_path / "coverage.json").read_text())
    assert doc["replications"] == 1 and doc["spring"] == "n50"
    assert {r["model"] for r in doc["rows"]} == {"surface", "cubics", "chosen"}
    assert all(r["covered"] + r["refused"] <= 1 for r in doc["rows"])
    assert "coarse pressure grids" in (tmp_path / "summary.md").read_text()


def test_importance_coverage_tiny(tmp_path):
    """One replication of the stored study's quickest pair at two heights: the fit's counts and
    its draws' checks beside the stored study's counts for the same queries; an unknown pair
    is refused naming the option."""
    out = tmp_path / "importance.json"
    argv = ("--pairs", "n50-kink/catalogue", "--reps", "1", "--heights-mm", "90,130")
    proc = _run("scripts/importance_coverage.py", *argv, "--out", out)
    assert proc.returncode == 0, proc.stderr
    s = json.loads(out.read_text())["summary"]["n50-kink/catalogue"]
    assert s["reps"] == 1 and s["queries"] == 8  # two heights x four mid-pressures
    assert 0 <= s["force_covered"][0] <= 8 and 0 <= s["force_covered"][1] <= 8
    assert s["converged"] == 1 and s["mean_width_N"][0] > 0
    assert "force covered" in proc.stdout
    bad = _run("scripts/importance_coverage.py", "--pairs", "n50/none", "--out", out)
    assert bad.returncode == 2 and "--pairs" in bad.stderr


def test_export_n50_from_a_saved_model(n50_surface, tmp_path):
    """reports/export/'s script, exporting the shared surface fit saved (no fit of its own)."""
    saved = tmp_path / "surface.nc"
    n50_surface.save(saved)
    out = tmp_path / "export"
    proc = _run("scripts/export_n50.py", "--out", out, "--saved", saved, "--draws", 200)
    assert proc.returncode == 0, proc.stderr
    stats = ("mean", "q05", "q50", "q95")
    assert sorted(p.name for p in out.iterdir()) == sorted(
        ["README.md", "n50.csv", "n50_provenance.csv", "n50.xlsx", "n50.json", "n50.m", "n50.mat"]
        + [f"n50_{s}.tpf" for s in stats]
        + ["n50-sealed.m"]
        + [f"n50_sealed_{s}.tpf" for s in stats]
    )
    committed = ROOT / "reports" / "export" / "n50.csv"
    assert (out / "n50.csv").read_text().splitlines()[0] == committed.read_text().splitlines()[0]
    # every file says that data/n50 is reconstructed, not measured
    said = "not measured data: the recordings are the paper's N-50 spring reconstructed from its Table 1"
    for name in ("n50_provenance.csv", "n50.json", "n50.m", "n50_q50.tpf", "n50_sealed_q50.tpf"):
        assert said in (out / name).read_text(), name
    sheet = openpyxl.load_workbook(out / "n50.xlsx")["provenance"]
    assert any(said in str(v) for row in sheet.iter_rows(values_only=True) for v in row)
    assert said in scipy.io.loadmat(out / "n50.mat", simplify_cells=True)["airspring"]["notes"]
    assert "reconstructed from its Table 1" in (out / "README.md").read_text()


@pytest.mark.slow  # about 2.5 min; the claims it measures are carried by tests/derived/test_plan.py
def test_plan_proof_tiny(tmp_path):
    """One replication of one scenario with tiny settings: the JSON and the summary page."""
    proc = _run("scripts/plan_proof.py", "--tiny", "--out", tmp_path)
    assert proc.returncode == 0, proc.stderr
    doc = json.loads((tmp_path / "proof.json").read_text())
    assert doc["replications"] == 1 and doc["intervals"] == 2
    assert all(t["sd_achieved"] > 0 and t["sd_predicted"] > 0 for t in doc["rows"][0]["targets"])
    assert "uq plan on the virtual stand" in (tmp_path / "summary.md").read_text()
