"""Traced programs kept across processes (uq._inference.exported): the same numbers as jax.jit,
loaded without tracing, keyed by shapes and statics, robust to a damaged file."""

from __future__ import annotations

import os
import time

import jax
import jax.monitoring
import numpy as np
import pytest

from uq._data.stand_description import PAPER_STAND
from uq._inference import collapsed, exported
from uq._inference.exported import _Persistent
from uq._models.cubic import MODEL, prepare
from uq._stand.simulator import Layout, recordings_from_tests, simulate

TRACE_EVENT = "/jax/core/compile/jaxpr_trace_duration"


@pytest.fixture
def folder(tmp_path, monkeypatch):
    monkeypatch.setattr(exported, "folder", lambda: tmp_path)
    return tmp_path


def _data(step_m=0.01):
    rec = recordings_from_tests(
        simulate("n50", seed=2, layout=Layout(pressures_bar=(5.0,), step_m=step_m))
    )
    return prepare(rec.tests[0], rec.x0_m, "budget", PAPER_STAND)[0]


def _bfgs_args(data):
    return MODEL.log_prob, jax.numpy.asarray(MODEL.start(data)), jax.numpy.ones(3), data


def _traced(fn):
    """The names of the functions traced while ``fn`` runs."""
    seen = []

    def listener(event, duration, **kw):
        if event == TRACE_EVENT:
            seen.append(str(kw.get("fun_name")))

    jax.monitoring.register_event_duration_secs_listener(listener)
    try:
        out = fn()
    finally:
        jax.monitoring.unregister_event_duration_listener(listener)
    return out, seen


def _equal(a, b):
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b), strict=True):
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y))


def test_exported_program_is_jax_jit_to_the_bit_and_loads_without_tracing(folder):
    """The optimiser through a kept program: jax.jit's result to the bit, on its first use
    (exported, written) and in a 'new process' (a fresh wrapper, nothing in memory: read from the
    file, and nothing of the function traced again)."""
    args = _bfgs_args(_data())
    plain = jax.jit(collapsed._bfgs.fun, static_argnums=0)(*args)
    first = _Persistent(collapsed._bfgs.fun, (0,))(*args)
    files = list(folder.rglob("_bfgs-*.jaxexport"))
    assert len(files) == 1
    again, traced = _traced(lambda: _Persistent(collapsed._bfgs.fun, (0,))(*args))
    assert not [n for n in traced if "_bfgs" in n or "flat" in n], traced
    _equal(plain, first)
    _equal(plain, again)


def test_programs_are_keyed_by_shape_and_static_arguments(folder):
    """Another number of readings is another program (another file); a static argument that
    cannot be named the same in every process (a lambda) keeps nothing, and is still right."""
    fn = _Persistent(collapsed._bfgs.fun, (0,))
    fn(*_bfgs_args(_data(0.01)))
    fn(*_bfgs_args(_data(0.015)))
    assert len(list(folder.rglob("_bfgs-*.jaxexport"))) == 2

    rows = np.linspace(-1.0, 1.0, 32)[:, None]
    lp = _Persistent(collapsed._log_prob_problems.fun, (0,))
    out = lp(lambda th, d: -0.5 * jax.numpy.sum(th**2) * d, rows[None], np.ones(1))
    np.testing.assert_allclose(out[0], -0.5 * rows[:, 0] ** 2)
    assert not list(folder.rglob("_log_prob_problems-*"))


def test_a_damaged_file_is_exported_again(folder):
    args = _bfgs_args(_data())
    plain = jax.jit(collapsed._bfgs.fun, static_argnums=0)(*args)
    _Persistent(collapsed._bfgs.fun, (0,))(*args)
    (path,) = folder.rglob("_bfgs-*.jaxexport")
    path.write_bytes(b"not a program")
    _equal(plain, _Persistent(collapsed._bfgs.fun, (0,))(*args))
    _equal(plain, _Persistent(collapsed._bfgs.fun, (0,))(*args))  # the rewritten file
    assert path.stat().st_size > 1000


def test_the_key_covers_the_package_source(folder, monkeypatch):
    """A change to uq's code (here: to the environment key it is hashed into) makes new names:
    a program of other code is never loaded."""
    args = _bfgs_args(_data())
    _Persistent(collapsed._bfgs.fun, (0,))(*args)
    monkeypatch.setattr(exported, "environment_key", lambda: "other code")
    _Persistent(collapsed._bfgs.fun, (0,))(*args)
    assert len(list(folder.rglob("_bfgs-*.jaxexport"))) == 2


def test_other_environments_unused_for_keep_days_are_deleted(folder):
    """Programs of other code or versions sit in other subfolders: those unused for KEEP_DAYS
    days (and files of the flat layout before subfolders) are deleted when a process first uses
    the folder; a recently used one is kept, and this environment's folder is marked as used."""
    old_time = time.time() - (exported.KEEP_DAYS + 1) * 86400.0
    stale, recent, flat = folder / ("0" * 24), folder / ("1" * 24), folder / "_bfgs-old.jaxexport"
    for d in (stale, recent):
        d.mkdir()
        (d / "_bfgs-x.jaxexport").write_bytes(b"program")
    flat.write_bytes(b"program")
    for p in (stale / "_bfgs-x.jaxexport", stale, flat):
        os.utime(p, (old_time, old_time))
    _Persistent(collapsed._bfgs.fun, (0,))(*_bfgs_args(_data()))
    here = folder / exported.environment_key()[:24]
    assert sorted(p.name for p in folder.iterdir()) == sorted([recent.name, here.name])
    assert len(list(here.glob("_bfgs-*.jaxexport"))) == 1
    assert here.stat().st_mtime > time.time() - 3600.0


def test_nothing_is_kept_with_the_cache_off(monkeypatch, tmp_path):
    monkeypatch.setattr(exported, "folder", lambda: None)
    args = _bfgs_args(_data())
    _equal(
        jax.jit(collapsed._bfgs.fun, static_argnums=0)(*args),
        _Persistent(collapsed._bfgs.fun, (0,))(*args),
    )
    assert not list(tmp_path.iterdir())


def test_a_second_uq_fit_loads_its_programs_imports_less_and_gives_the_same_json(tmp_path):
    """Two `uq fit`s of a tiny campaign in fresh interpreters sharing a new cache: the first
    exports its programs, the second loads them and never imports optimistix, equinox or
    scipy.stats (nor traces the optimiser); both write the same JSON, to the byte."""
    import json
    import os
    import subprocess
    import sys

    from uq._cli.main import main

    csv = tmp_path / "tiny.csv"
    assert main(["simulate", "--out", str(csv), "--pressures", "2,5", "--step-mm", "15"]) == 0
    env = dict(os.environ, UQ_CACHE_DIR=str(tmp_path / "cache"))
    env.pop("JAX_COMPILATION_CACHE_DIR", None)

    def fit(n):
        out = tmp_path / f"fit{n}.json"
        code = (
            "import json, sys\n"
            "from uq._cli.main import main\n"
            f"rc = main(['fit', {str(csv)!r}, '--walkers', '8', '--max-steps', '40', '--quiet',"
            f" '--json', {str(out)!r}])\n"
            "heavy = ('optimistix', 'equinox', 'lineax', 'scipy.stats')\n"
            "print(json.dumps([rc, [m for m in heavy if m in sys.modules]]))\n"
        )
        r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env)
        assert r.returncode in (0, 1), r.stderr[-2000:]
        return json.loads(r.stdout.strip().splitlines()[-1]), out.read_bytes()

    (rc1, _), first = fit(1)
    assert list((tmp_path / "cache" / exported.FOLDER).rglob("_bfgs-*.jaxexport"))
    (rc2, imported), second = fit(2)
    assert rc1 == rc2 and imported == []
    assert first == second
