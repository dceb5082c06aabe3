"""MATLAB outputs: a script that defines a struct of vectors (``.m``), or the same struct in a
MAT-file (``.mat``, written by scipy.io)."""

from __future__ import annotations

import io

import numpy as np

#: Digits of every number in a script (the tables' own).
DIGITS = 10


def _number(v: float) -> str:
    v = float(v)
    if np.isnan(v):
        return "NaN"
    return f"{v:.{DIGITS}g}"


def literal(value) -> str:
    """A MATLAB literal: a string in single quotes, a number, a column vector ``[a; b]`` for a 1-D
    array, a matrix ``[a b; c d]`` (rows as rows) for a 2-D one."""
    if isinstance(value, str):
        return "'" + value.replace("'", "''") + "'"
    a = np.asarray(value, float)
    if a.ndim == 0:
        return _number(a)
    if a.ndim == 1:
        return "[" + "; ".join(_number(v) for v in a) + "]"
    return "[" + "; ".join(" ".join(_number(v) for v in row) for row in a) + "]"


def script(name: str, fields: list[tuple[str, object, str]], comments: list[str]) -> str:
    """A script assigning ``name.field = value;`` with a trailing ``% note`` per field."""
    lines = [f"% {c}".rstrip() for c in comments]
    lines.append(f"{name} = struct();")
    for field, value, note in fields:
        line = f"{name}.{field} = {literal(value)};"
        lines.append(line + (f"  % {note}" if note else ""))
    return "\n".join(lines) + "\n"


def mat_bytes(name: str, fields: list[tuple[str, object, str]]) -> bytes:
    """The same struct as a MAT-file (version 5, as ``load`` reads it), in memory."""
    struct = {}
    for field, value, _ in fields:
        parts = field.split(".")
        here = struct
        for p in parts[:-1]:
            here = here.setdefault(p, {})
        here[parts[-1]] = value if isinstance(value, str) else np.asarray(value, float)
    from scipy.io import savemat  # reason: scipy.io takes 1 s to import; only a MAT-file needs it

    buf = io.BytesIO()
    savemat(buf, {name: struct}, do_compression=True, oned_as="column")
    return buf.getvalue()
