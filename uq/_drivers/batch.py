"""``uq batch CATALOGUE --out DIR``: many campaigns, one command: in this process by default,
on Dask distributed for more machines.

A catalogue (TOML or CSV, docs/batch.md) lists recordings files and the tasks to run on each
(``fit``, ``report``, ``surface``, ``diagnose``) with per-campaign options (seed, sampler,
stand constants). By default the jobs run in this process and the fits of the ``fit`` and
``report`` tasks are batched: the tests of up to ``BATCH_CAMPAIGNS`` campaigns with the same
sampler settings and stand are sampled in one driver call (``fit_campaigns``,
:func:`run_batched`). With ``--workers N`` (a ``LocalCluster`` of worker processes, one thread
each, because JAX dispatch and emcee hold the GIL) or ``--scheduler ADDRESS`` each Dask task
is a chunk of jobs run the same way in a worker. ``--serial``: one job after another, each
campaign fitted on its own. The work calls the library directly (``read_recordings``,
``fit_campaigns``, ``write_report``, ``fit_surface``, ``diagnose``).

Outputs: ``DIR/<campaign>/<task>/`` per pair, with a stamp ``batch.json`` written last, holding
the content hash of (recordings bytes, stand file bytes, task, options, package version); a
rerun skips every pair whose stamp matches. ``DIR/summary.csv``, ``summary.json`` and
``index.html`` list every pair (done, skipped or failed with its one-line error), all written
atomically, with one verdict per campaign (passed, failed, not converged). A failed pair does
not stop the others; the command exits 1 at the end if any failed, or if a fit did not converge
(unless ``--allow-unconverged``).

The catalogue is validated before any work: an unknown task or option, a missing file or a
duplicate name is one line naming the catalogue and the row (exit 2).
"""

from __future__ import annotations

import csv
import hashlib
import io
import json
import logging
import math
import os
import re
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import uq._inference.float64  # noqa: F401  float64 in every worker, before any array is made
from uq._data.recordings import READING_OPTIONS, read_recordings
from uq._data.stand_description import stand_or_paper
from uq._derived.bands import campaign_bands
from uq._diagnose.engine import diagnose, shorter_sampling
from uq._inference.sampler import Settings
from uq._io.errors import InputError, where
from uq._io.files import dumps_json, emit_json, write_text_atomic
from uq._io.values import boolean, compression, positive_float, positive_int, seed, walkers
from uq._io.version import __version__
from uq._models import registry
from uq._models.cubic_fit import fit_campaign, fit_campaigns
from uq._report.campaign import write_report
from uq._report.diagnose import write_diagnose_report
from uq._report.html import render
from uq._report.pages import write_model_page

TASKS = ("fit", "report", "surface", "diagnose")
#: Per-campaign options: name -> parser (the same checks as the single-campaign commands' options).
OPTIONS = {
    "seed": seed,
    "walkers": walkers,
    "ensembles": positive_int,
    "max_steps": positive_int,
    "x0_mm": positive_float,
    "piston_area_cm2": positive_float,
    "draws": positive_int,
    "stand": str,
    "compression": compression,
    "sheet": str,
    "absolute_pressure": boolean,
    "p_atm_bar": positive_float,
    "pressure_tolerance_bar": positive_float,
    "columns": str,  # a column map, checked by the reader (uq._data.column_map)
    "units_row": str,  # auto, yes or no, checked by the reader
    "header_row": positive_int,
    "pointwise": boolean,  # fit: the pointwise groups in the NetCDF files (default no; docs/batch.md)
}
DEFAULT_SEED = 20201  # as every command's --seed
STAMP = "batch.json"
SUMMARY_COLUMNS = (
    "campaign",
    "task",
    "status",
    "seconds",
    "converged",
    "result",
    "output",
    "error",
    "file",
)
# becomes a folder name: no separators, no dot-files
_NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9._-]*\Z")


# ----------------------------------------------------------------------------- catalogue


@dataclass(frozen=True)
class Campaign:
    name: str
    file: Path  # absolute
    tasks: tuple[str, ...]
    options: dict = field(hash=False)  # parsed values; "stand" an absolute path
    where: str = ""  # "catalogue.csv, row 3": for messages


def _split_tasks(value, loc: str) -> tuple[str, ...]:
    items = value if isinstance(value, list) else re.split(r"[;+,\s]+", str(value))
    tasks = tuple(str(t).strip() for t in items if str(t).strip())
    if not tasks:
        raise InputError(f"{loc}: no task given; expected one or more of {', '.join(TASKS)}")
    for t in tasks:
        if t not in TASKS:
            raise InputError(f"{loc}: unknown task '{t}'; expected {', '.join(TASKS)}")
    if len(set(tasks)) != len(tasks):
        raise InputError(f"{loc}: a task is listed twice in '{value}'")
    return tasks


def _campaign(entry: dict, folder: Path, loc: str) -> Campaign:
    """One catalogue entry (keys already known to be allowed) -> a checked Campaign."""
    if not str(entry.get("file", "")).strip():
        raise InputError(
            f"{loc}: no 'file' given (the recordings CSV, relative to the catalogue's folder)"
        )
    path = (folder / str(entry["file"]).strip()).resolve()
    if not path.is_file():
        raise InputError(f"{where(loc, column='file')}: no such file {path}")
    name = str(entry.get("name") or "").strip() or path.stem
    if not _NAME.match(name):
        raise InputError(
            f"{where(loc, column='name')}: '{name}' cannot name a folder; use letters, digits, '.', '_', '-'"
        )
    if "tasks" not in entry:
        raise InputError(f"{loc}: no 'tasks' given; expected one or more of {', '.join(TASKS)}")
    tasks = _split_tasks(entry["tasks"], where(loc, column="tasks"))
    options = {}
    for key, parse in OPTIONS.items():
        value = entry.get(key)
        if value is None or str(value).strip() == "":
            continue
        if key == "stand":
            stand = (folder / str(value).strip()).resolve()
            if not stand.is_file():
                raise InputError(f"{where(loc, column='stand')}: no such file {stand}")
            options[key] = str(stand)
            continue
        try:
            options[key] = parse(str(value).strip())
        except ValueError as exc:
            raise InputError(f"{where(loc, column=key)}: {exc}") from None
    return Campaign(name, path, tasks, options, loc)


def _check_keys(keys, loc: str, allowed) -> None:
    for k in keys:
        if k not in allowed:
            raise InputError(f"{loc}: unknown column '{k}'; expected {', '.join(allowed)}")


ENTRY_KEYS = ("name", "file", "tasks", *OPTIONS)


def _read_csv(path: Path) -> list[Campaign]:
    """CSV: a header row (name, file, tasks, option columns), one row per campaign; '#' lines are comments."""
    text = _text(path)
    lines = [
        (i, line)
        for i, line in enumerate(text.splitlines(), start=1)
        if line.strip() and not line.lstrip().startswith("#")
    ]
    if not lines:
        raise InputError(
            f"{path}: empty catalogue; expected a header row (name,file,tasks,...) and one row per campaign"
        )
    head_row, head_line = lines[0]
    header = [h.strip() for h in next(csv.reader([head_line]))]
    _check_keys(header, where(str(path), head_row), ENTRY_KEYS)
    if "file" not in header or "tasks" not in header:
        raise InputError(
            f"{where(str(path), head_row)}: the header needs the columns 'file' and 'tasks'"
        )
    out = []
    for row, line in lines[1:]:
        cells = next(csv.reader([line]))
        if len(cells) > len(header):
            raise InputError(
                f"{where(str(path), row)}: {len(cells)} cells for {len(header)} columns"
            )
        entry = dict(zip(header, (c.strip() for c in cells), strict=False))
        out.append(_campaign(entry, path.parent, where(str(path), row)))
    return out


def _read_toml(path: Path) -> list[Campaign]:
    """TOML: optional [defaults] (any entry key) and one [[campaign]] table per campaign."""
    try:
        raw = tomllib.loads(_text(path))
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{path}: not valid TOML: {exc}") from None
    for key in raw:
        if key not in ("defaults", "campaign"):
            raise InputError(
                f"{path}: unknown key '{key}'; expected [defaults] and [[campaign]] tables"
            )
    defaults = raw.get("defaults", {})
    entries = raw.get("campaign", [])
    if (
        not isinstance(defaults, dict)
        or not isinstance(entries, list)
        or not all(isinstance(e, dict) for e in entries)
    ):
        raise InputError(f"{path}: expected a [defaults] table and [[campaign]] tables")
    _check_keys(defaults, f"{path}, [defaults]", ENTRY_KEYS)
    if not entries:
        raise InputError(f"{path}: no [[campaign]] table")
    out = []
    for i, e in enumerate(entries, start=1):
        loc = f"{path}, campaign {i}" + (f" ('{e['name']}')" if e.get("name") else "")
        _check_keys(e, loc, ENTRY_KEYS)
        out.append(_campaign(defaults | e, path.parent, loc))
    return out


def _text(path: Path) -> str:
    try:
        return path.read_text(encoding="utf-8-sig")
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise InputError(f"{path}: is a folder, expected a catalogue (.toml or .csv)") from None
    except UnicodeDecodeError:
        raise InputError(f"{path}: not a UTF-8 text file") from None


def read_catalogue(path) -> list[Campaign]:
    """Read and check a catalogue before any work: every file exists, every task and option is known,
    names are unique. One line naming the catalogue and its row on the first problem."""
    path = Path(path)
    if path.suffix.lower() not in (".toml", ".csv"):
        raise InputError(f"{path}: a catalogue is a .toml or .csv file")
    campaigns = _read_toml(path) if path.suffix.lower() == ".toml" else _read_csv(path)
    if not campaigns:
        raise InputError(f"{path}: no campaign listed")
    seen: dict[str, str] = {}
    for c in campaigns:
        if c.name.lower() in seen:  # folders: case-insensitive file systems would merge them
            raise InputError(
                f"{c.where}: duplicate campaign name '{c.name}' (also {seen[c.name.lower()]})"
            )
        seen[c.name.lower()] = c.where
    return campaigns


# ----------------------------------------------------------------------------- jobs


def job_hash(c: Campaign, task: str) -> str:
    """Content hash deciding a rerun: recordings bytes, stand bytes, task, options, package version."""
    h = hashlib.sha256()
    h.update(c.file.read_bytes())
    if "stand" in c.options:
        h.update(Path(c.options["stand"]).read_bytes())
    opts = {k: v for k, v in c.options.items() if k != "stand"}
    h.update(
        json.dumps({"task": task, "options": opts, "version": __version__}, sort_keys=True).encode()
    )
    return h.hexdigest()


def jobs_of(campaigns: list[Campaign], out_dir) -> list[dict]:
    """One plain dict per (campaign, task): all a worker needs, picklable, no live objects."""
    out = Path(out_dir).resolve()
    return [
        {
            "campaign": c.name,
            "task": t,
            "file": str(c.file),
            "options": dict(c.options),
            "out": str(out / c.name / t),
            "hash": job_hash(c, t),
        }
        for c in campaigns
        for t in c.tasks
    ]


def _stamp(job: dict) -> dict | None:
    """The finished row of a job run before with the same hash, else None."""
    try:
        stamp = json.loads((Path(job["out"]) / STAMP).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return stamp.get("row") if stamp.get("hash") == job["hash"] else None


def _failed_row(job: dict, seconds, error: str = "") -> dict:
    """A job's summary row, failed until it is done (the keys in the summary's order)."""
    return {k: job[k] for k in ("campaign", "task", "file")} | {
        "status": "failed",
        "seconds": seconds,
        "converged": None,
        "result": "",
        "output": "",
        "error": error,
    }


def _one_line(exc: BaseException) -> str:
    text = " ".join(str(exc).split())
    return text if isinstance(exc, InputError) else f"{type(exc).__name__}: {text}"


def run_job(job: dict, *, fitted=None, fit_seconds: float = 0.0) -> dict:
    """Run one (campaign, task) in this process (a Dask worker or the caller); never raises.

    ``fitted``: for the tasks that fit the per-pressure cubics (``FITTED_TASKS``), the campaign's
    fit made beforehand in a batch (:func:`run_batched`), or the exception that fitting it raised
    (then this row's error); ``fit_seconds``: its share of the batch's time, added to the row's.
    Returns the summary row; on success the stamp is written last, so a crash leaves no stamp."""

    out = Path(job["out"])
    row = _failed_row(job, 0.0)
    t0 = time.perf_counter()
    try:
        # stale stamp of other inputs: gone before new outputs appear
        (out / STAMP).unlink(missing_ok=True)
        out.mkdir(parents=True, exist_ok=True)
        if isinstance(fitted, BaseException):
            raise fitted
        runner = TASK_RUNNERS[job["task"]]
        row |= (runner(job, out) if fitted is None else runner(job, out, fitted)) | {
            "status": "done"
        }
    except Exception as exc:  # the batch goes on: the error is this row's, one line
        row["error"] = _one_line(exc)
    row["seconds"] = round(time.perf_counter() - t0 + fit_seconds, 2)
    if row["status"] == "done":
        write_text_atomic(
            out / STAMP,
            dumps_json(
                {
                    "hash": job["hash"],
                    "version": __version__,
                    "task": job["task"],
                    "options": job["options"],
                    "file": job["file"],
                    "row": row,
                }
            ),
        )
    return row


# ----------------------------------------------------------------------------- tasks


def _recordings(job: dict):
    o = job["options"]
    kw = {k: o[k] for k in READING_OPTIONS if k in o}
    return read_recordings(job["file"], **kw)


def _settings(job: dict):
    o = job["options"]
    kw = {
        "n_walkers": o.get("walkers"),
        "n_ensembles": o.get("ensembles"),
        "max_steps": o.get("max_steps"),
    }
    s = Settings(**{k: v for k, v in kw.items() if v is not None})
    s.validate()
    return s


def _stand(job: dict):
    return stand_or_paper(job["options"].get("stand"))


def _seed(job: dict) -> int:
    return int(job["options"].get("seed", DEFAULT_SEED))


def _fit_options(job: dict) -> dict:
    """The seed, sampler settings and stand of a job's fits."""
    return {"seed": _seed(job), "settings": _settings(job), "stand": _stand(job)}


def _fit(job: dict):
    """The campaign's per-pressure cubics, as ``uq fit`` makes them."""
    return fit_campaign(_recordings(job), **_fit_options(job))


def _task_fit(job: dict, out: Path, cf=None) -> dict:
    cf = cf or _fit(job)
    rec = cf.recordings
    # the pointwise groups only when asked for (docs/batch.md: 92 % of the bytes, about a third
    # of a batched campaign's time)
    cf.save_posteriors(out, pointwise=job["options"].get("pointwise", False))
    emit_json(cf.to_json(), str(out / "fit.json"))
    return {
        "converged": cf.converged,
        "output": "fit.json",
        "result": f"{len(rec.tests)} tests, {rec.n_points} points",
    }


def _task_report(job: dict, out: Path, cf=None) -> dict:
    cf = cf or _fit(job)
    rec = cf.recordings
    cb = campaign_bands(cf, n_draws=int(job["options"].get("draws", 2000)), seed=_seed(job))
    page = write_report(cf, out, bands=cb)
    emit_json(cf.to_json() | {"bands": cb.to_json(), "report": page.name}, str(out / "fit.json"))
    return {
        "converged": cf.converged,
        "output": page.name,
        "result": f"{len(rec.tests)} tests, {rec.n_points} points",
    }


def _task_surface(job: dict, out: Path) -> dict:
    fit = registry.fit(registry.default("surface"), _recordings(job), **_fit_options(job))
    res = fit.to_json()
    page = write_model_page(fit, res, out)
    emit_json(res, str(out / "surface.json"))
    return {
        "converged": bool(res["converged"]),
        "output": page.name,
        "result": f"{fit.orders_label}, {fit.n_coefficients} coefficients",
    }


def _task_diagnose(job: dict, out: Path) -> dict:
    settings = shorter_sampling(_settings(job))  # as `uq diagnose`
    res = diagnose(_recordings(job), seed=_seed(job), settings=settings, stand=_stand(job))
    emit_json(res.to_json(), str(out / "diagnose.json"))
    page = write_diagnose_report(res, out)
    names = ", ".join(m["name"] for m in res["mechanisms"]) or "none"
    warn = (res["sampling"] or {}).get("warnings") or []
    return {
        "converged": not warn,
        "output": Path(page).name if page else "diagnose.json",
        "result": f"mismatch {'yes' if res['mismatch_detected'] else 'no'}; mechanisms: {names}",
    }


TASK_RUNNERS = {
    "fit": _task_fit,
    "report": _task_report,
    "surface": _task_surface,
    "diagnose": _task_diagnose,
}
#: the tasks whose first step is the campaign's per-pressure cubics (``_fit``): batched
FITTED_TASKS = ("fit", "report")
#: campaigns per batched driver call (:func:`run_batched`): the fits of at most this many are
#: held at once; benchmarks/bench.py --batch measures the cost a campaign below and above it
BATCH_CAMPAIGNS = 50


# ----------------------------------------------------------------------------- running


def worker_env() -> dict:
    """Environment of LocalCluster workers: one compute thread each, so two workers fill two cores
    instead of fighting over them (XLA's CPU backend otherwise starts a thread per core)."""
    flags = os.environ.get("XLA_FLAGS", "")
    extra = "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"
    return {
        "XLA_FLAGS": f"{flags} {extra}".strip(),
        "OMP_NUM_THREADS": "1",
        "OPENBLAS_NUM_THREADS": "1",
        "MKL_NUM_THREADS": "1",
    }


def _client(scheduler: str | None, workers: int):
    from distributed import (  # reason: optional and heavy, loaded only where used
        Client,
        LocalCluster,
    )

    if scheduler:
        try:
            return Client(scheduler, timeout="20s")
        except (OSError, TimeoutError, ValueError) as exc:
            raise InputError(
                f"scheduler: {scheduler}: cannot connect: {_one_line(exc)}", param="scheduler"
            ) from None
    cluster = LocalCluster(
        n_workers=workers,
        threads_per_worker=1,
        processes=True,
        dashboard_address=":0",  # any free port: a fixed 8787 fails when another cluster holds it
        silence_logs=logging.ERROR,
        env=worker_env(),
    )
    return Client(cluster)


def run_dask(
    jobs: list[dict],
    *,
    scheduler: str | None = None,
    workers: int = 2,
    on_row=None,
    size: int = BATCH_CAMPAIGNS,
) -> list[dict]:
    """Run ``jobs`` on Dask (a new LocalCluster, or the cluster at ``scheduler``); rows as they
    finish. Each Dask task is a chunk of jobs that :func:`run_batched` runs in the worker (the
    fits batched there): at most ``size`` jobs, and small enough to give every worker thread
    about two chunks, so that the cluster stays busy to the end."""
    from distributed import as_completed  # reason: optional and heavy, loaded only where used

    rows = []
    client = _client(scheduler, workers)
    try:
        slots = max(1, sum(client.nthreads().values()))
        per = max(1, min(size, math.ceil(len(jobs) / (2 * slots))))
        chunks = [jobs[k : k + per] for k in range(0, len(jobs), per)]
        futures = {
            client.submit(
                run_batched,
                c,
                key=f"uq-batch-{c[0]['campaign']}-{c[0]['task']}-{len(c)}-{c[0]['hash'][:12]}",
                pure=False,
            ): c
            for c in chunks
        }
        for fut in as_completed(futures):
            try:
                got = fut.result()
            # the worker itself died (KilledWorker, out of memory): its rows fail
            except Exception as exc:
                got = [_failed_row(j, None, _one_line(exc)) for j in futures[fut]]
            for row in got:
                rows.append(row)
                if on_row:
                    on_row(row)
    finally:
        cluster = getattr(client, "cluster", None)
        client.close()
        if cluster is not None and not scheduler:
            cluster.close()
    return rows


def run_batched(jobs: list[dict], on_row=None, *, size: int = BATCH_CAMPAIGNS) -> list[dict]:
    """The jobs in this process, the fits of ``FITTED_TASKS`` batched: the campaigns with the
    same sampler settings and stand, in catalogue order, ``size`` at a time, go through one
    driver call (:func:`uq._models.cubic_fit.fit_campaigns`), then each job writes its outputs
    from its campaign's fit (one fit for a campaign's ``fit`` and ``report``). A campaign whose recordings cannot be read fails alone; when a
    batched fit raises (one campaign's data), its campaigns are fitted one by one, so each row
    gets its own one-line error. The other tasks run one after another. Never raises.

    A campaign's MCMC draws depend on the campaigns it was batched with (the emcee random stream
    is the run's): deterministic for (catalogue, seeds, ``size``), but not the draws of
    ``--serial``; they agree to Monte Carlo error."""
    rows: list[dict] = []

    def done(row):
        rows.append(row)
        if on_row:
            on_row(row)

    # campaign name -> [its fitted-task jobs, its recordings]; one fit serves them all
    entries: dict[str, list] = {}
    groups: dict[tuple, list[list]] = {}
    for j in jobs:
        if j["task"] not in FITTED_TASKS:
            continue
        (Path(j["out"]) / STAMP).unlink(missing_ok=True)  # stale: gone before any new output
        try:
            key = (_settings(j), j["options"].get("stand"))
            rec = _recordings(j)
        except Exception as exc:  # this campaign's own problem: its row
            done(run_job(j, fitted=exc))
            continue
        if j["campaign"] in entries:
            entries[j["campaign"]][0].append(j)
        else:
            entries[j["campaign"]] = [[j], rec]
            groups.setdefault(key, []).append(entries[j["campaign"]])
    for (settings, stand_file), group in groups.items():
        stand = stand_or_paper(stand_file)
        for k in range(0, len(group), size):
            for row in _run_chunk(group[k : k + size], settings, stand):
                done(row)
    for j in jobs:
        if j["task"] not in FITTED_TASKS:
            done(run_job(j))
    return rows


def _run_chunk(chunk: list[list], settings, stand):
    """Rows of one batched fit of the campaigns ``chunk`` ([their jobs, their recordings]): a
    generator, each campaign's outputs written as it comes."""
    t0 = time.perf_counter()
    seeds = [_seed(js[0]) for js, _ in chunk]
    try:
        fits = fit_campaigns([rec for _, rec in chunk], seeds, settings=settings, stand=stand)
        share = (time.perf_counter() - t0) / len(chunk)
        made = [(f, share) for f in fits]
    except Exception:  # one campaign's data: fit them one by one, each error its rows'
        made = []
        for (_, rec), seed in zip(chunk, seeds, strict=True):
            t1 = time.perf_counter()
            try:
                f = fit_campaign(rec, seed=seed, settings=settings, stand=stand)
            except Exception as exc:
                f = exc
            made.append((f, time.perf_counter() - t1))
    for (js, _), (f, seconds) in zip(chunk, made, strict=True):
        for j in js:
            yield run_job(j, fitted=f, fit_seconds=seconds / len(js))


def run_serial(jobs: list[dict], on_row=None) -> list[dict]:
    """The same jobs one after another in this process (for debugging, and the reference of benchmarks/bench.py --batch)."""
    rows = []
    for j in jobs:
        rows.append(run_job(j))
        if on_row:
            on_row(rows[-1])
    return rows


# ----------------------------------------------------------------------------- summary


def verdicts(rows: list[dict]) -> list[dict]:
    """One verdict per campaign, in the rows' order: "failed" when one of its tasks failed, "not
    converged" when one of its fits (done now or skipped as done before) failed its convergence
    rules, else "passed"; ``why`` names the tasks."""
    out: dict[str, dict] = {}
    for r in rows:
        v = out.setdefault(
            r["campaign"], {"campaign": r["campaign"], "failed": [], "unconverged": []}
        )
        if r["status"] == "failed":
            v["failed"].append(r["task"])
        elif r.get("converged") is False:
            v["unconverged"].append(r["task"])
    result = []
    for v in out.values():
        if v["failed"]:
            verdict, why = "failed", f"failed: {', '.join(v['failed'])}"
        elif v["unconverged"]:
            verdict, why = "not converged", f"not converged: {', '.join(v['unconverged'])}"
        else:
            verdict, why = "passed", ""
        result.append({"campaign": v["campaign"], "verdict": verdict, "why": why})
    return result


def write_summary(rows: list[dict], out_dir, catalogue) -> dict:
    """summary.csv, summary.json and index.html in ``out_dir``, each written atomically."""

    out = Path(out_dir)
    counts = {s: sum(r["status"] == s for r in rows) for s in ("done", "skipped", "failed")}
    result = {
        "catalogue": str(catalogue),
        "version": __version__,
        "counts": counts,
        "not_converged": sum(r["status"] != "failed" and r.get("converged") is False for r in rows),
        "verdicts": verdicts(rows),
        "campaigns": rows,
    }
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=SUMMARY_COLUMNS, extrasaction="ignore", lineterminator="\n")
    w.writeheader()
    w.writerows({k: ("" if r.get(k) is None else r.get(k)) for k in SUMMARY_COLUMNS} for r in rows)
    write_text_atomic(out / "summary.csv", buf.getvalue())
    write_text_atomic(out / "summary.json", dumps_json(result))
    index = render(  # the template batch_index.html of uq._report (autoescaped)
        "batch_index.html",
        rows=rows,
        catalogue=Path(catalogue).name,
        counts=counts,
        not_converged=result["not_converged"],
        verdicts=result["verdicts"],
        version=__version__,
    )
    write_text_atomic(out / "index.html", index)
    return result


# ----------------------------------------------------------------------------- command


def run_batch(
    catalogue,
    out_dir,
    *,
    scheduler: str | None = None,
    workers: int | None = None,
    serial: bool = False,
    force: bool = False,
    on_row=None,
    size: int = BATCH_CAMPAIGNS,
) -> dict:
    """Validate ``catalogue``, skip finished pairs, run the rest, write the summary; return it.

    By default in this process with the fits batched (:func:`run_batched`, ``size`` campaigns
    per driver call); on Dask when given ``workers`` (a LocalCluster) or ``scheduler``;
    ``serial``: one job after another, no batching (the reference of the benchmark)."""
    campaigns = read_catalogue(catalogue)
    jobs = jobs_of(campaigns, out_dir)
    rows, todo = [], []
    for j in jobs:
        done = None if force else _stamp(j)
        if done is not None:
            rows.append(done | {"status": "skipped"})
        else:
            todo.append(j)
    if todo:
        if serial:
            rows += run_serial(todo, on_row)
        elif scheduler or workers:
            rows += run_dask(
                todo, scheduler=scheduler, workers=workers or 2, on_row=on_row, size=size
            )
        else:
            rows += run_batched(todo, on_row, size=size)
    # in catalogue order: Dask finishes them in any order, and the summary should not depend on it
    pos = {(j["campaign"], j["task"]): i for i, j in enumerate(jobs)}
    rows.sort(key=lambda r: pos[(r["campaign"], r["task"])])
    return write_summary(rows, out_dir, catalogue)
