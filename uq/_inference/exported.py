"""Traced programs kept across processes: ``jax.export`` beside the persistent compilation cache.

JAX's persistent compilation cache (``uq._inference.jax_cache``) keeps the *compiled* programs, but
every new process still traces each jitted function to a jaxpr and lowers it to StableHLO before
it can even look the program up: about 1.5 s of a ``uq fit`` on data/n50, most of it the
optimiser's program (optimistix BFGS, traced through equinox). :func:`persistent_jit` is
``jax.jit`` for the few large programs of the fits (the log posterior over all problems, the
optimiser, the mapped draws): the first time a program is needed for a given set of static
arguments and argument shapes, it is exported (``jax.export``: traced and lowered once), and its
serialised form is written under ``<compilation cache>/uq-exported/``; a later process
deserialises it instead of tracing (a few milliseconds), and the compiled program is then found
in the compilation cache as before.

The file's name is a hash of everything the traced program depends on: the function and its
static arguments (module-level functions by qualified name), the argument tree and every leaf's
shape and dtype, the versions of Python, jax, jaxlib, optimistix, equinox, lineax and numpy
(whose constants are traced in), the JAX flags that change tracing, and every file of the ``uq``
package, code and data (any change to uq's code makes new names, so a stale program is never
loaded). The files of one such environment are kept in a subfolder of their own, named by the
environment's hash and marked as used by every process that uses it; the first time a process
uses the folder, the subfolders of other environments (other versions of uq or of its
dependencies, other code) that no process has used for ``KEEP_DAYS`` days are deleted.
Files are written atomically (``uq._io.files``), so a reader sees a whole program or none; one
that cannot be read is exported again and overwritten. Nothing is kept when the compilation
cache is off (``UQ_CACHE_DIR=off``), for arguments that are not all arrays, or for static
arguments this module cannot name stably; then, and on any failure to export or to write, the
call is ``jax.jit``'s. An exported program computes what the jitted function computes (the same
StableHLO, compiled by the same XLA): a fit's results are the same to the bit (tested).

Serialising needs the ``flatbuffers`` package (a dependency of uq).
"""

from __future__ import annotations

import functools
import hashlib
import importlib.metadata
import importlib.util
import os
import shutil
import sys
import time
import types
from pathlib import Path

import numpy as np

from uq._inference.float64 import jax
from uq._io.files import write_bytes_atomic

Tracer = jax.core.Tracer
export = jax.export

#: the subfolder of JAX's compilation cache the exported programs are kept in
FOLDER = "uq-exported"
#: days after which another environment's programs, unused, are deleted
KEEP_DAYS = 30
#: distributions whose code is traced into uq's programs
TRACED_PACKAGES = ("jax", "jaxlib", "optimistix", "equinox", "lineax", "numpy")
#: JAX flags that change what a function traces to
TRACE_FLAGS = (
    "jax_enable_x64",
    "jax_threefry_partitionable",
    "jax_default_matmul_precision",
    "jax_numpy_rank_promotion",
    "jax_numpy_dtype_promotion",
    "jax_default_prng_impl",
    "jax_enable_checks",
    "jax_debug_nans",
    "jax_debug_infs",
    "jax_disable_jit",
)


def folder() -> Path | None:
    """Where the exported programs are (None: JAX's compilation cache is off, or ``flatbuffers``
    is missing: then nothing is exported, and every program is traced as ``jax.jit`` does)."""
    where = jax.config.jax_compilation_cache_dir
    if not where or importlib.util.find_spec("flatbuffers") is None:
        return None
    return Path(where) / FOLDER


@functools.cache
def environment_key() -> str:
    """A hash of what every traced program depends on besides its own arguments: versions,
    flags, and every file of the uq package (its code and its data)."""
    h = hashlib.sha256()
    h.update(sys.version.encode())
    for name in TRACED_PACKAGES:
        try:
            h.update(f"{name}={importlib.metadata.version(name)};".encode())
        except importlib.metadata.PackageNotFoundError:
            h.update(f"{name}=none;".encode())
    for flag in TRACE_FLAGS:
        h.update(f"{flag}={getattr(jax.config, flag, None)!r};".encode())
    h.update(jax.default_backend().encode())
    root = Path(__file__).resolve().parents[1]  # the uq package: its code and data files
    for path in sorted(p for p in root.rglob("*") if p.is_file() and p.suffix != ".pyc"):
        h.update(str(path.relative_to(root)).encode())
        h.update(path.read_bytes())
    return h.hexdigest()


@functools.cache
def _environment_folder(where: Path, key: str) -> Path:
    """This environment's subfolder of ``where``, marked as used now; other environments'
    entries that were not used for ``KEEP_DAYS`` days are deleted (module docstring). Once a
    process."""
    here = where / key[:24]
    try:
        here.mkdir(parents=True, exist_ok=True)
        os.utime(here)
        others = [p for p in where.iterdir() if p != here]
    except OSError:  # a cache that cannot be written: its programs are still read
        return here
    cutoff = time.time() - KEEP_DAYS * 86400.0
    for other in others:
        try:
            if other.stat().st_mtime < cutoff:
                shutil.rmtree(other) if other.is_dir() else other.unlink()
        except OSError:  # deleted by another process meanwhile, or not ours to delete
            pass
    return here


def _weak(x) -> bool:
    """Whether a leaf is weakly typed (a JAX array made from a Python scalar): part of the key,
    since an exported program keeps the types it was traced with."""
    return bool(getattr(x, "weak_type", False))


def _hashed(fun) -> bool:
    """Whether ``fun`` is a module-level function of the uq package, whose source the
    :func:`environment_key` covers (a plugin's or a test's function is not: its program is
    traced in every process, as ``jax.jit`` does)."""
    module = getattr(fun, "__module__", None) or ""
    return (module == "uq" or module.startswith("uq.")) and "<" not in fun.__qualname__


def _static_name(value) -> str | None:
    """A name of a static argument that is the same in every process, or None."""
    if value is None or isinstance(value, bool | int | str):
        return repr(value)
    if isinstance(value, types.FunctionType) and _hashed(value):
        return f"{value.__module__}.{value.__qualname__}"
    if isinstance(value, tuple):
        names = [_static_name(v) for v in value]
        return None if None in names else "(" + ",".join(names) + ")"
    return None


class _Persistent:
    """``jax.jit(fun, static_argnums=...)`` whose traced programs are kept on disk (module doc)."""

    def __init__(self, fun, static_argnums: tuple[int, ...]):
        self.fun = fun
        self.static_argnums = tuple(static_argnums)
        self.jitted = jax.jit(fun, static_argnums=self.static_argnums)
        self.programs: dict = {}  # in-process: key -> the jitted call of the exported program
        functools.update_wrapper(self, fun)

    def __call__(self, *args):
        statics = tuple(args[i] for i in self.static_argnums)
        dynamic = tuple(a for i, a in enumerate(args) if i not in self.static_argnums)
        leaves, tree = jax.tree.flatten(dynamic)
        if not all(
            isinstance(x, np.ndarray) or (isinstance(x, jax.Array) and not isinstance(x, Tracer))
            for x in leaves
        ):  # a Python scalar, or a call inside another transformation: jax.jit's own way
            return self.jitted(*args)
        key = (statics, tree, tuple((x.shape, x.dtype, _weak(x)) for x in leaves))
        program = self.programs.get(key)
        if program is None:
            try:
                program = self._program(statics, tree, leaves)
            except Exception:  # e.g. the package's files unreadable: jax.jit's own way
                program = None
            program = self.programs[key] = program or False
        if program is False:
            return self.jitted(*args)
        return program(*leaves)

    def _cache_size(self) -> int:
        """The programs compiled in this process (``jax.jit``'s ``_cache_size``, summed over the
        plain jitted function and the exported programs: what tests of "compiles once" count)."""
        kept = [p for p in self.programs.values() if p is not False]
        return self.jitted._cache_size() + sum(p._cache_size() for p in kept)

    def _program(self, statics, tree, leaves):
        """The exported program for these statics and shapes: read from disk, else exported and
        written; None where it cannot be kept (then the plain jitted function is used)."""
        where = folder()
        names = [_static_name(s) for s in statics]
        if where is None or None in names or not _hashed(self.fun):
            return None
        h = hashlib.sha256()
        h.update(environment_key().encode())
        h.update(f"{self.fun.__module__}.{self.fun.__qualname__};{','.join(names)};".encode())
        h.update(str(tree).encode())
        for x in leaves:
            h.update(f"{x.shape}{np.dtype(x.dtype).str}{_weak(x)};".encode())
        path = _environment_folder(where, environment_key()) / (
            f"{self.fun.__name__}-{h.hexdigest()[:40]}.jaxexport"
        )
        try:
            exported = export.deserialize(bytearray(path.read_bytes()))
        except Exception:  # absent, or unreadable: export it (again)
            exported = None
        if exported is None:
            try:
                exported = export.export(jax.jit(self._flat(statics, tree)))(*leaves)
            except Exception:  # a program export cannot take (e.g. a custom call): jax.jit's
                return None
            try:
                data = exported.serialize()
                write_bytes_atomic(path, bytes(data))
            except Exception:  # not kept (not serialisable, or the cache cannot be written):
                pass  # no reason to fail a fit, nor to trace the function again
        return jax.jit(exported.call)

    def _flat(self, statics, tree):
        """The function of the dynamic arguments' leaves, the statics bound."""
        fun, fixed = self.fun, dict(zip(self.static_argnums, statics, strict=True))

        def flat(*leaves):
            dynamic = jax.tree.unflatten(tree, leaves)
            rest = iter(dynamic)
            n = len(fixed) + len(dynamic)
            return fun(*[fixed[i] if i in fixed else next(rest) for i in range(n)])

        return flat


def persistent_jit(*, static_argnums: tuple[int, ...] = ()):
    """Decorator: ``jax.jit(fun, static_argnums=static_argnums)`` with the traced programs kept
    across processes (module docstring). Call with positional arguments only."""

    def wrap(fun):
        return _Persistent(fun, static_argnums)

    return wrap
