"""Tables as the plain file formats other tools read: CSV text (the standard library's writer).

Numbers are written to 10 significant digits (far below any posterior's spread, and files stay
byte-reproducible); text cells are quoted only where they must be.
"""

from __future__ import annotations

import csv
import io
import math

DIGITS = 10


def cell(value) -> str:
    """A table cell as text: numbers to DIGITS significant digits, NaN empty, text as it is."""
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float) or hasattr(value, "dtype"):
        v = float(value)
        return "" if math.isnan(v) else f"{v:.{DIGITS}g}"
    return str(value)


def csv_text(header: list[str], rows, comments: list[str] = ()) -> str:
    """CSV text: ``#`` comment lines, the header, one line per row (``\\n`` line ends)."""
    out = io.StringIO()
    for line in comments:
        out.write(f"# {line}".rstrip() + "\n")
    w = csv.writer(out, lineterminator="\n")
    w.writerow(header)
    for row in rows:
        w.writerow([cell(v) for v in row])
    return out.getvalue()


def xlsx_bytes(sheets: list[tuple[str, list[list]]], when=None) -> bytes:
    """An .xlsx workbook, one sheet per (name, rows); numbers stay numbers. ``when`` (a datetime)
    is written as the workbook's created/modified time, so a rerun gives the same cells."""
    import openpyxl  # reason: 0.5 s to import, and only a workbook needs it

    book = openpyxl.Workbook()
    book.remove(book.active)
    for name, rows in sheets:
        sheet = book.create_sheet(name)
        for row in rows:
            sheet.append([_xlsx_cell(v) for v in row])
    if when is not None:
        book.properties.created = book.properties.modified = when
    buf = io.BytesIO()
    book.save(buf)
    return buf.getvalue()


def _xlsx_cell(v):
    if v is None or isinstance(v, str | bool | int):
        return v
    f = float(v)
    return None if math.isnan(f) else f
