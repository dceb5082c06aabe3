"""Atomic output: write to a temporary file beside the target, then rename.

A crash mid-write leaves the previous file (or nothing), never half a file. New files get mode
0666 less the umask (as any program's output), a replaced file keeps its mode, a symbolic link is
never replaced, and a device such as /dev/null is written to, not replaced.
"""

from __future__ import annotations

import contextlib
import errno
import hashlib
import io
import json
import math
import os
import shutil
import stat
import sys
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from uq._io.errors import InputError


def _refuse(path: Path, why: str) -> InputError:
    return InputError(f"cannot write {path}: {why}")


#: Write failures that are the place's fault, not the program's: no space, a file-size limit, a quota.
_NO_ROOM = {errno.ENOSPC, errno.EFBIG, getattr(errno, "EDQUOT", errno.ENOSPC)}


def _no_room(path: Path, exc: BaseException) -> InputError | None:
    """The one-line error for a full disk (or a file-size limit, a quota) while writing ``path``."""
    if isinstance(exc, OSError) and exc.errno in _NO_ROOM:
        return _refuse(path, f"{exc.strerror or os.strerror(exc.errno)} (nothing was written)")
    return None


def _target_mode(path: Path) -> tuple[bool, int | None]:
    """(write in place?, mode to give the new file) for ``path``; refuses what must not be replaced.

    A regular file is replaced and its mode kept; a device, pipe or socket (``/dev/null``, a
    FIFO) is written to in place, never replaced, also through a symbolic link (``/dev/stdout``);
    any other symbolic link, and a folder, is refused. A new file gets 0666 less the umask.
    """
    try:
        st = os.stat(path)  # follows links
    except FileNotFoundError:
        st = None
    except NotADirectoryError:
        raise _refuse(path, "a part of its folder path is a file, not a folder") from None
    except OSError as exc:
        raise _refuse(path, exc.strerror or str(exc)) from None
    if st is not None and not (stat.S_ISREG(st.st_mode) or stat.S_ISDIR(st.st_mode)):
        return True, None
    if path.is_symlink():
        raise _refuse(path, "it is a symbolic link; refusing to replace it (give the real path)")
    if st is None:
        return False, None
    if stat.S_ISDIR(st.st_mode):
        raise _refuse(path, "it is a folder")
    return False, stat.S_IMODE(st.st_mode)


def _make_parent(path: Path) -> None:
    parent = path.parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except FileExistsError:
        raise _refuse(path, f"{parent} is a file, not a folder") from None
    except NotADirectoryError:
        raise _refuse(path, "a part of its folder path is a file, not a folder") from None
    except OSError as exc:
        raise _refuse(path, f"cannot create the folder {parent}: {exc.strerror or exc}") from None


def _open_tmp_beside(path: Path) -> tuple[int, Path]:
    """A new file beside ``path``, created with mode 0666 so that the umask applies (mkstemp's 0600 would not)."""
    for _ in range(100):
        tmp = path.parent / f".{path.name[:200]}.{os.urandom(4).hex()}.tmp"
        try:
            return os.open(
                tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0), 0o666
            ), tmp
        except FileExistsError:
            continue
        except OSError as exc:
            raise _refuse(
                path, f"cannot create a file in {path.parent}: {exc.strerror or exc}"
            ) from None
    raise _refuse(path, f"cannot create a temporary file in {path.parent}")


def _fsync_folder(folder: Path) -> None:
    """Make the rename itself durable; some file systems cannot open a folder for that, which is fine."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def write_bytes_atomic(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (temp file in the same folder, fsync, rename).

    The file gets mode 0666 less the umask when new, and keeps its mode when replaced. A symbolic
    link or a folder is refused, and a device or pipe is written to in place (see _target_mode);
    every refusal is an :class:`InputError` naming the path.
    """
    path = Path(path)
    in_place, mode = _target_mode(path)
    if in_place:
        try:
            fh = open(path, "wb")
        except OSError as exc:
            raise _refuse(path, exc.strerror or str(exc)) from None
        try:
            with fh:
                fh.write(data)
        except OSError as exc:
            raise (_no_room(path, exc) or exc) from None
        return path

    # a temporary file beside path, written, fsynced and renamed over it, the folder fsynced; on
    # any failure the temporary file is removed
    _make_parent(path)
    fd, tmp = _open_tmp_beside(path)
    try:
        with os.fdopen(fd, "wb") as fh:
            if mode is not None:
                os.fchmod(fh.fileno(), mode)
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        if os.path.exists(tmp):
            os.unlink(tmp)
        full = _no_room(path, exc)
        if full is not None:
            raise full from None
        raise
    _fsync_folder(path.parent)
    return path


@contextlib.contextmanager
def staged_folder(out: str | os.PathLike, *, last: tuple[str, ...] = ()):
    """Write a set of files (a report and its figures) whole or not at all.

    Yields a new hidden folder inside ``out``; write the set there. When the block ends without
    an exception every file is moved into ``out`` (renames in one file system: they need no
    space, so a full disk cannot stop them half-way), the names in ``last`` after the others (the
    page that links the figures); on any failure the folder and what it holds are removed and
    ``out`` keeps what it had. The targets get the promises of :func:`write_bytes_atomic`: a
    replaced file keeps its mode, a symbolic link or a folder is refused (before anything is
    moved), a device is written to. Errors name the files in ``out``, not the hidden folder.
    """
    out = Path(out)
    _make_parent(out / "x")
    try:
        stage = Path(tempfile.mkdtemp(prefix=".uq-staging-", dir=out))
    except OSError as exc:
        raise (_no_room(out, exc) or _refuse(out, exc.strerror or str(exc))) from None
    try:
        try:
            yield stage
        except InputError as exc:
            raise InputError(str(exc).replace(f"{stage}{os.sep}", f"{out}{os.sep}")) from None
        files = sorted(stage.iterdir(), key=lambda p: (p.name in last, p.name))
        plan = [(src, out / src.name, *_target_mode(out / src.name)) for src in files]
        for src, dst, in_place, mode in plan:
            if in_place:
                write_bytes_atomic(dst, src.read_bytes())
                continue
            if mode is not None:
                os.chmod(src, mode)
            os.replace(src, dst)
    finally:
        shutil.rmtree(stage, ignore_errors=True)
    _fsync_folder(out)


def remove_stale(folder: str | os.PathLike, patterns: tuple[str, ...], keep) -> list[Path]:
    """Remove files of ``folder`` matching ``patterns`` whose names are not in ``keep``.

    For outputs whose set of names depends on the run (one figure per pressure): a figure an
    earlier run wrote must not pass for one of this run. Only regular files are removed (never a
    link or a folder), and only names that match the caller's own patterns, so a user's files
    in the same folder are left alone. Returns what was removed.
    """
    keep = set(keep)
    removed = []
    for pattern in patterns:
        for p in sorted(Path(folder).glob(pattern)):
            if p.name in keep or p.is_symlink() or not p.is_file():
                continue
            p.unlink()
            removed.append(p)
    return removed


def write_text_atomic(path: str | os.PathLike, text: str) -> Path:
    return write_bytes_atomic(path, text.encode("utf-8"))


def plain(obj: Any) -> Any:
    """Convert numpy/jax scalars and arrays to JSON-ready Python objects; NaN/inf become None."""
    if isinstance(obj, dict):
        return {str(k): plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [plain(v) for v in obj]
    if hasattr(obj, "__array__") and not isinstance(obj, (str, bytes)):
        arr = np.asarray(obj)
        if arr.ndim == 0:
            return plain(arr.item())
        return [plain(v) for v in arr.tolist()]
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.floating,)):
        return plain(float(obj))
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


def dumps_json(result: Any) -> str:
    """Deterministic JSON text (sorted keys off: the contract's key order reads better)."""
    return json.dumps(plain(result), indent=1, allow_nan=False) + "\n"


def emit_json(result: Any, target: str | None) -> None:
    """Write ``result`` to ``target``: a path (atomically), ``-`` for stdout, None for nothing."""
    if target is None:
        return
    text = dumps_json(result)
    if target == "-":
        sys.stdout.write(text)
        sys.stdout.flush()
    else:
        write_text_atomic(target, text)


def write_figure_atomic(fig, path: str | os.PathLike, **kwargs) -> Path:
    """Save a matplotlib figure atomically as PNG and return the path."""
    buf = io.BytesIO()
    kwargs.setdefault("dpi", 110)
    fig.savefig(buf, format="png", **kwargs)
    return write_bytes_atomic(path, buf.getvalue())


def sha256_of(path: str | os.PathLike) -> str:
    """The SHA-256 of a file's bytes, hex (the provenance of a result: which recordings it is of)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()
