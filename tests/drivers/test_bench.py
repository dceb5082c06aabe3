"""``uq bench`` with tiny settings: structure and positive rates only, never timing."""

from __future__ import annotations

import json

from uq._cli.main import main


def test_bench_tiny_run_writes_both_rates(tmp_path, capsys):
    out = tmp_path / "bench.json"
    rc = main(
        [
            "bench",
            "--seconds",
            "0",
            "--seed",
            "3",
            "--walkers",
            "8",
            "--max-steps",
            "60",
            "--baseline-walkers",
            "12",
            "--json",
            str(out),
            "--bench-dir",
            str(tmp_path / "bench"),
        ]
    )
    assert rc == 0
    r = json.loads(out.read_text())
    assert (
        json.loads((tmp_path / "bench" / "ess.json").read_text()) == r
    )  # the record under reports/bench/ by default
    assert r["cores"] >= 1 and r["load_average_1min"] >= 0
    assert r["n_points"] == 37 and r["seed"] == 3 and "5 bar" in r["workload"]
    for name in ("project", "baseline"):
        block = r[name]
        assert block["runs"] >= 1 and block["wall_s"] > 0
        assert block["ess_bulk_min"] > 0 and block["ess_per_s"] > 0
    assert r["ratio"] > 0
    assert r["ratio"] == r["project"]["ess_per_s"] / r["baseline"]["ess_per_s"]
    names = ("a_P", "b_P", "c_P", "d_P", "sigma0_N", "rel_force")
    assert tuple(r["ratio_each"]) == names and r["ratio_min_all"] == min(r["ratio_each"].values())
    for n in names:
        assert (
            r["ratio_each"][n]
            == r["project"]["ess_per_s_each"][n] / r["baseline"]["ess_per_s_each"][n]
        )
    text = capsys.readouterr().out
    assert "project" in text and "baseline" in text and "ratio project / baseline" in text


def test_bench_bad_options_exit_2(capsys):
    assert main(["bench", "--seconds", "-1"]) == 2
    assert main(["bench", "--baseline-walkers", "7"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 2 and all("uq bench: error: option --" in e for e in err)
