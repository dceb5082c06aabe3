"""``uq batch``: catalogue validation (no cluster), then one real LocalCluster run with a failed
campaign, the summary files, and a rerun that skips the finished campaigns."""

from __future__ import annotations

import csv
import io
import json
import sys

import pytest

from uq._cli.main import main
from uq._drivers import batch as _batch
from uq._io import progress as _progress

FAST = ["--walkers", "8", "--ensembles", "2"]


@pytest.fixture(scope="module")
def campaigns(tmp_path_factory):
    """Two tiny simulated campaigns (2 tests x 10 points) and one with a non-number in row 12."""
    d = tmp_path_factory.mktemp("batch")
    for s in (1, 2):
        assert (
            main(
                [
                    "simulate",
                    "--out",
                    str(d / f"c{s}.csv"),
                    "--seed",
                    str(s),
                    "--pressures",
                    "2,5",
                    "--step-mm",
                    "10",
                ]
            )
            == 0
        )
    lines = (d / "c1.csv").read_text().splitlines()
    row = lines[11].split(",")
    row[1] = "abc"
    lines[11] = ",".join(row)
    (d / "bad.csv").write_text("\n".join(lines) + "\n")
    return d


def _rows(out):
    return list(csv.DictReader((out / "summary.csv").read_text().splitlines()))


def _csv(d, text, name="cat.csv"):
    (d / name).write_text(text)
    return str(d / name)


@pytest.mark.parametrize(
    "body, says",
    [
        (
            "name,file,tasks\na,c1.csv,fit\nb,c2.csv,fitt\n",
            "row 3, column 'tasks': unknown task 'fitt'",
        ),
        ("name,file,tasks\na,c1.csv,fit\nb,nope.csv,fit\n", "row 3, column 'file': no such file"),
        (
            "name,file,tasks\na,c1.csv,fit\n# comment\na,c2.csv,report\n",
            "row 4: duplicate campaign name 'a' (also",
        ),
        ("name,file,tasks,sed\na,c1.csv,fit,3\n", "row 1: unknown column 'sed'"),
        (
            "name,file,tasks,seed\na,c1.csv,fit,-3\n",
            "row 2, column 'seed': expected an integer seed",
        ),
        (
            "name,file,tasks\n../up,c1.csv,fit\n",
            "row 2, column 'name': '../up' cannot name a folder",
        ),
    ],
)
def test_bad_catalogue_is_one_line_exit_2_before_any_work(campaigns, tmp_path, capsys, body, says):
    cat = _csv(campaigns, body, "bad_cat.csv")
    assert main(["batch", cat, "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and cat in err[0] and says in err[0], err
    assert not (tmp_path / "out").exists()  # nothing run, nothing written


def test_toml_catalogue_defaults_and_relative_paths(campaigns):
    (campaigns / "cat.toml").write_text(
        "[defaults]\ntasks = ['fit']\nseed = 5\n\n[[campaign]]\nfile = 'c1.csv'\n\n"
        "[[campaign]]\nname = 'second'\nfile = 'c2.csv'\ntasks = 'fit, report'\nseed = 9\nwalkers = 8\n"
    )
    a, b = _batch.read_catalogue(campaigns / "cat.toml")
    assert (a.name, a.tasks, a.options) == ("c1", ("fit",), {"seed": 5})
    assert (b.name, b.tasks, b.options) == ("second", ("fit", "report"), {"seed": 9, "walkers": 8})
    assert a.file == (campaigns / "c1.csv").resolve()
    (campaigns / "dup.toml").write_text(
        "[[campaign]]\nfile = 'c1.csv'\ntasks = ['fit']\n[[campaign]]\nfile = 'c1.csv'\ntasks = ['fit']\n"
    )
    with pytest.raises(
        _batch.InputError, match=r"dup.toml, campaign 2: duplicate campaign name 'c1'"
    ):
        _batch.read_catalogue(campaigns / "dup.toml")


def test_hash_changes_with_data_task_options_and_version(campaigns, monkeypatch):
    c = _batch.Campaign("a", campaigns / "c1.csv", ("fit",), {"seed": 1})
    h = _batch.job_hash(c, "fit")
    assert h == _batch.job_hash(
        _batch.Campaign("x", campaigns / "c1.csv", ("fit",), {"seed": 1}), "fit"
    )
    assert h != _batch.job_hash(c, "report")
    assert h != _batch.job_hash(
        _batch.Campaign("a", campaigns / "c1.csv", ("fit",), {"seed": 2}), "fit"
    )
    assert h != _batch.job_hash(
        _batch.Campaign("a", campaigns / "c2.csv", ("fit",), {"seed": 1}), "fit"
    )
    monkeypatch.setattr(_batch, "__version__", "0.0.0-other")
    assert h != _batch.job_hash(c, "fit")


def test_local_cluster_run_failed_campaign_summary_and_rerun_skip(campaigns, tmp_path, capsys):
    cat = _csv(
        campaigns,
        "name,file,tasks,seed,walkers,ensembles,max_steps\n"
        "one,c1.csv,fit,3,8,2,60\nbroken,bad.csv,fit,3,8,2,60\ntwo,c2.csv,fit,4,8,2,60\n",
    )
    out = tmp_path / "out"
    assert (
        main(["batch", cat, "--out", str(out), "--quiet", "--workers", "2"]) == 1
    )  # one failed, the others finished
    text = capsys.readouterr()
    assert "LocalCluster, 2 workers" in text.out and "2 done, 0 skipped, 1 failed" in text.out
    rows = _rows(out)
    assert [(r["campaign"], r["status"]) for r in rows] == [
        ("one", "done"),
        ("broken", "failed"),
        ("two", "done"),
    ]
    assert (
        rows[1]["error"].endswith("row 12, column 'height_mm': 'abc' is not a number")
        and "\n" not in rows[1]["error"]
    )
    for name in ("one", "two"):
        fit = json.loads((out / name / "fit" / "fit.json").read_text())
        assert [t["pressure_bar"] for t in fit["tests"]] == [2.0, 5.0]
        assert (out / name / "fit" / "batch.json").exists()
    assert not (out / "broken" / "fit" / "batch.json").exists()
    summary = json.loads((out / "summary.json").read_text())
    assert summary["counts"] == {"done": 2, "skipped": 0, "failed": 1}
    page = (out / "index.html").read_text()
    assert (
        "href='one/fit/fit.json'" in page
        and "href='two/fit/fit.json'" in page
        and "is not a number" in page
    )

    before = (out / "one" / "fit" / "fit.json").stat().st_mtime_ns
    assert (
        main(["batch", cat, "--out", str(out), "--quiet", "--workers", "2"]) == 1
    )  # the broken one runs (and fails) again
    assert "0 done, 2 skipped, 1 failed" in capsys.readouterr().out
    rows = _rows(out)
    assert [r["status"] for r in rows] == ["skipped", "failed", "skipped"]
    assert (out / "one" / "fit" / "fit.json").stat().st_mtime_ns == before  # not rewritten

    # all finished: no cluster is started, and on a terminal the progress bar is drawn
    cat2 = _csv(
        campaigns,
        "name,file,tasks,seed,walkers,ensembles,max_steps\none,c1.csv,fit,3,8,2,60\n",
        "cat2.csv",
    )
    tty = _Terminal()
    sys_stderr, sys.stderr = sys.stderr, tty
    try:
        assert main(["batch", cat2, "--out", str(out), "--allow-unconverged"]) == 0
    finally:
        sys.stderr = sys_stderr
        _progress.set_enabled(False)
    assert "batch" in tty.getvalue() and "task" in tty.getvalue()
    assert "0 done, 1 skipped, 0 failed" in capsys.readouterr().out


def test_index_page_escapes_names_and_messages(tmp_path):
    """index.html is a jinja2 template with autoescaping: a campaign name or an error message
    holding markup (an error may quote the recordings) is text on the page, never a <script>."""
    evil = "<script>alert('x&y')</script>"
    rows = [
        {
            "campaign": evil,
            "task": "fit",
            "file": "f.csv",
            "status": "failed",
            "seconds": 0.25,
            "converged": None,
            "result": "",
            "output": "",
            "error": f"row 3: {evil} is not a number",
        },
        {
            "campaign": "a&b",
            "task": "report",
            "file": "f.csv",
            "status": "done",
            "seconds": 2.0,
            "converged": False,
            "result": evil,
            "output": "report.html",
            "error": None,
        },
    ]
    _batch.write_summary(rows, tmp_path, tmp_path / "cat<script>.csv")
    page = (tmp_path / "index.html").read_text()
    assert "<script" not in page
    esc = "&lt;script&gt;alert(&#x27;x&amp;y&#x27;)&lt;/script&gt;"
    assert f"<td>{esc}</td><td>fit</td><td>failed</td><td>0.2</td><td></td>" in page
    assert f"<td>row 3: {esc} is not a number</td>" in page
    assert (
        f"<td><b>no</b></td><td>{esc}</td><td><a href='a&amp;b/report/report.html'>report.html</a></td>"
        in page
    )
    assert "<title>uq batch: cat&lt;script&gt;.csv</title>" in page


class _Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_serial_and_scheduler_exclude_each_other(campaigns, tmp_path, capsys):
    cat = _csv(campaigns, "file,tasks\nc1.csv,fit\n", "cat3.csv")
    assert (
        main(
            [
                "batch",
                cat,
                "--out",
                str(tmp_path / "o"),
                "--serial",
                "--scheduler",
                "tcp://127.0.0.1:1",
            ]
        )
        == 2
    )
    assert "--serial and --scheduler" in capsys.readouterr().err


def test_default_in_process_batched_failed_campaign_and_pointwise(campaigns, tmp_path, capsys):
    """By default the fits run in this process, batched: a campaign whose file cannot be read
    fails in its own row, the others are fitted in one driver call and written as `uq fit
    --out` writes them, but without the pointwise groups unless ``pointwise = yes``."""
    import arviz as az

    cat = _csv(
        campaigns,
        "name,file,tasks,seed,walkers,ensembles,max_steps,pointwise\n"
        "one,c1.csv,fit;report,3,8,2,60,\nbroken,bad.csv,fit,3,8,2,60,\ntwo,c2.csv,fit,4,8,2,60,yes\n",
        "cat_batched.csv",
    )
    out = tmp_path / "out"
    assert main(["batch", cat, "--out", str(out), "--quiet", "--allow-unconverged"]) == 1
    text = capsys.readouterr()
    assert "in this process, fits batched" in text.out and "3 done, 0 skipped, 1 failed" in text.out
    rows = _rows(out)
    assert [(r["campaign"], r["task"], r["status"]) for r in rows] == [
        ("one", "fit", "done"),
        ("one", "report", "done"),
        ("broken", "fit", "failed"),
        ("two", "fit", "done"),
    ]
    # one fit serves a campaign's fit and report tasks
    report = json.loads((out / "one" / "report" / "fit.json").read_text())
    fit = json.loads((out / "one" / "fit" / "fit.json").read_text())
    assert report["tests"][0]["force"] == fit["tests"][0]["force"]
    assert (out / "one" / "report" / "report.html").exists()
    assert rows[2]["error"].endswith("row 12, column 'height_mm': 'abc' is not a number")
    for name, seed, groups in (
        ("one", 3, {"posterior"}),
        ("two", 4, {"posterior", "log_likelihood", "posterior_predictive"}),
    ):
        fit = json.loads((out / name / "fit" / "fit.json").read_text())
        assert [t["pressure_bar"] for t in fit["tests"]] == [2.0, 5.0] and fit["seed"] == seed
        idata = az.from_netcdf(out / name / "fit" / "posterior_5bar.nc")
        assert groups | {"observed_data", "sample_stats"} == set(idata.groups())
        assert (out / name / "fit" / "batch.json").exists()
    assert main(["batch", cat, "--out", str(out), "--quiet", "--allow-unconverged"]) == 1
    assert "0 done, 3 skipped, 1 failed" in capsys.readouterr().out


def test_a_failing_batched_fit_falls_back_to_one_by_one(campaigns, tmp_path, monkeypatch):
    """When the batched driver call raises (one campaign's data), its campaigns are fitted one
    by one: the culprit's row gets its own one-line error, the others are done."""
    from uq._io.errors import InputError

    def batched(recordings, seeds, **kw):
        raise InputError("some campaign of the batch")

    real = _batch.fit_campaign

    def one(rec, *, seed, **kw):
        if seed == 4:
            raise InputError("c2.csv: this campaign's own problem")
        return real(rec, seed=seed, **kw)

    monkeypatch.setattr(_batch, "fit_campaigns", batched)
    monkeypatch.setattr(_batch, "fit_campaign", one)
    cat = _csv(
        campaigns,
        "name,file,tasks,seed,walkers,ensembles,max_steps\n"
        "one,c1.csv,fit,3,8,2,60\ntwo,c2.csv,fit,4,8,2,60\n",
        "cat_fallback.csv",
    )
    res = _batch.run_batch(cat, tmp_path / "out")
    rows = res["campaigns"]
    assert [(r["campaign"], r["status"]) for r in rows] == [("one", "done"), ("two", "failed")]
    assert rows[1]["error"] == "c2.csv: this campaign's own problem"
    assert [v["verdict"] for v in res["verdicts"]][1] == "failed"


@pytest.mark.parametrize("allow", [False, True])
def test_unconverged_tasks_exit_by_the_commands_policy(
    campaigns, tmp_path, capsys, monkeypatch, allow
):
    """Tasks that finished with an unconverged fit: exit 1 with one line saying how many, or 0
    with --allow-unconverged (the policy of every command, uq._cli.common.exit_policy)."""
    result = {"counts": {"done": 2, "skipped": 0, "failed": 0}, "campaigns": [], "verdicts": []}
    monkeypatch.setattr(_batch, "run_batch", lambda *a, **k: result | {"not_converged": 2})
    cat = _csv(campaigns, "file,tasks\nc1.csv,fit\n", "cat_nc.csv")
    code = main(
        ["batch", cat, "--out", str(tmp_path / "o"), "--serial"] + ["--allow-unconverged"] * allow
    )
    err = capsys.readouterr().err.strip().splitlines()[-1]
    head = (
        "uq batch: NOT CONVERGED: 2 task(s) finished with a fit that failed its convergence rules"
    )
    assert err.startswith(head)
    if allow:
        assert code == 0 and err.endswith("accepted with --allow-unconverged: exit 0")
    else:
        assert code == 1 and err.endswith("exit 1 (--allow-unconverged to accept them)")
