"""Atomic output: write to a temporary file beside the target, then rename.

A crash mid-write leaves the previous file (or nothing), never half a file.
"""

from __future__ import annotations

import json
import math
import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np


def _tmp_beside(path: Path) -> tuple[int, str]:
    path.parent.mkdir(parents=True, exist_ok=True)
    return tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)


def write_bytes_atomic(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically (temp file in the same folder, fsync, rename)."""
    path = Path(path)
    fd, tmp = _tmp_beside(path)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path


def write_text_atomic(path: str | os.PathLike, text: str) -> Path:
    return write_bytes_atomic(path, text.encode("utf-8"))


def _plain(obj: Any) -> Any:
    """Convert numpy/jax scalars and arrays to JSON-ready Python objects; NaN/inf become None."""
    if isinstance(obj, dict):
        return {str(k): _plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_plain(v) for v in obj]
    if hasattr(obj, "__array__") and not isinstance(obj, (str, bytes)):
        arr = np.asarray(obj)
        if arr.ndim == 0:
            return _plain(arr.item())
        return [_plain(v) for v in arr.tolist()]
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, (np.integer,)):
        return int(obj)
    if isinstance(obj, (np.floating,)):
        return _plain(float(obj))
    if isinstance(obj, np.bool_):
        return bool(obj)
    return obj


def dumps_json(result: Any) -> str:
    """Deterministic JSON text (sorted keys off: the contract's key order reads better)."""
    return json.dumps(_plain(result), indent=1, allow_nan=False) + "\n"


def emit_json(result: Any, target: str | None) -> None:
    """Write ``result`` to ``target``: a path (atomically), ``-`` for stdout, None for nothing."""
    if target is None:
        return
    text = dumps_json(result)
    if target == "-":
        import sys

        sys.stdout.write(text)
        sys.stdout.flush()
    else:
        write_text_atomic(target, text)


def write_figure_atomic(fig, path: str | os.PathLike, **kwargs) -> Path:
    """Save a matplotlib figure atomically as PNG and return the path."""
    import io

    buf = io.BytesIO()
    kwargs.setdefault("dpi", 110)
    fig.savefig(buf, format="png", **kwargs)
    return write_bytes_atomic(path, buf.getvalue())
