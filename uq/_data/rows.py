"""A recordings file as rows of text fields, numbered as an editor or a spreadsheet shows them.

Two sources give the same :class:`Table`, so one set of checks and messages serves both:

* CSV text: UTF-8 with or without BOM (Excel's "CSV UTF-8") or UTF-16 with BOM; columns
  separated by ',' or, when the header splits better that way, ';' or tab (then a decimal
  comma is understood as well); ``#`` lines are comments.
* A workbook (.xlsx through openpyxl, .ods through odfpy, both read by pandas): one sheet is one
  campaign. Rows are numbered as the spreadsheet shows them; a row whose first filled cell starts
  with ``#`` is a comment; numbers are read as the spreadsheet holds them (no decimal-comma
  guessing: a number typed as text with a comma is refused).

Every defect of the file itself (encoding, quotes, a missing or unknown sheet) raises
:class:`InputError` naming the file and the row.
"""

from __future__ import annotations

import csv
import io
import math
import warnings
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

from uq._io.errors import InputError, where

DELIMITERS = {",": "','", ";": "';'", "\t": "tab"}
WORKBOOK_SUFFIXES = (".xlsx", ".xlsm", ".ods")


@dataclass(frozen=True)
class Table:
    """The rows of one campaign: the header and the data rows, each with its file row number.

    ``fields`` are strings; a missing field (a CSV row shorter than the header) is not a string.
    ``sep`` is the CSV delimiter, None for a workbook. ``name`` stands for the file in messages
    (a workbook's adds the sheet).
    """

    name: str
    header_row: int
    header: list[str]
    body: list[tuple[int, list]]
    sep: str | None
    comments: list[str] = field(default_factory=list)
    sheet: str | None = None


def read_table(path: str, is_column, sheet: str | None = None) -> Table:
    """The rows of the file at ``path``: a workbook (by content, whatever its name) or CSV text.

    ``is_column(name)``: whether a header name is a recordings column (chooses the CSV delimiter).
    ``sheet``: the workbook sheet to read; required when a workbook has more than one.
    """
    raw = _read_bytes(path)
    kind = _workbook_kind(path, raw)
    if kind is not None:
        return _workbook_table(path, raw, kind, sheet)
    if sheet is not None:
        raise InputError(
            f"sheet: {sheet!r}: {path} is CSV text, not a workbook (.xlsx, .ods)", param="sheet"
        )
    return table_from_text(_decode(path, raw), path, is_column)


def _read_bytes(path: str) -> bytes:
    try:
        with open(path, "rb") as fh:
            return fh.read()
    except FileNotFoundError:
        raise InputError(f"{path}: no such file") from None
    except IsADirectoryError:
        raise InputError(
            f"{path}: is a folder, expected a recordings file (CSV, .xlsx, .ods)"
        ) from None
    except OSError as exc:
        raise InputError(f"{path}: cannot read the file ({exc.strerror or exc})") from None


def _workbook_kind(path: str, raw: bytes) -> str | None:
    """'openpyxl' (xlsx), 'odf' (ods) or None (text), from the file's content."""
    suffix = Path(path).suffix.lower()
    if raw.startswith(b"\xd0\xcf\x11\xe0"):  # OLE2: Excel 97-2003 needs a reader we do not ship
        raise InputError(
            f"{path}: an Excel 97-2003 workbook (.xls); save it as .xlsx, .ods or CSV UTF-8"
        )
    if not raw.startswith(b"PK\x03\x04"):
        if suffix in WORKBOOK_SUFFIXES:
            raise InputError(f"{path}: not a {suffix} workbook (the file is not a zip archive)")
        return None
    try:
        with zipfile.ZipFile(io.BytesIO(raw)) as z:
            names = set(z.namelist())
            mimetype = z.read("mimetype") if "mimetype" in names else b""
    except zipfile.BadZipFile:
        raise InputError(f"{path}: a damaged zip archive, not a readable workbook") from None
    if b"opendocument.spreadsheet" in mimetype:
        return "odf"
    if "xl/workbook.xml" in names:
        return "openpyxl"
    raise InputError(
        f"{path}: a zip archive that is neither an .xlsx nor an .ods workbook; give the recordings as CSV, .xlsx or .ods"
    )


def _cell_text(value) -> str:
    """A spreadsheet cell as the text a CSV would hold ('' for an empty cell)."""
    if value is None or (isinstance(value, float) and math.isnan(value)):
        return ""
    if isinstance(value, bool):
        return str(value).upper()
    if isinstance(value, float):
        return repr(float(value))
    return str(value)


def _column_letter(i: int) -> str:
    """0 -> A, 25 -> Z, 26 -> AA (as spreadsheets name their columns)."""
    out = ""
    i += 1
    while i:
        i, r = divmod(i - 1, 26)
        out = chr(65 + r) + out
    return out


def _workbook_table(path: str, raw: bytes, engine: str, sheet: str | None) -> Table:
    import pandas as pd

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            book = pd.ExcelFile(io.BytesIO(raw), engine=engine)
        names = [str(s) for s in book.sheet_names]
        if sheet is None and len(names) > 1:
            raise InputError(
                f"{path}: the workbook has {len(names)} sheets ({', '.join(repr(n) for n in names)}); "
                "choose the campaign's with `sheet`"
            )
        if sheet is not None and sheet not in names:
            raise InputError(
                f"sheet: {sheet!r}: {path} has no such sheet; its sheets are "
                f"{', '.join(repr(n) for n in names)}",
                param="sheet",
            )
        chosen = names[0] if sheet is None else sheet
        with warnings.catch_warnings():
            # openpyxl warns about styles and data validation it does not read: noise on stderr
            # for a user whose cells are read all the same
            warnings.simplefilter("ignore")
            frame = pd.read_excel(book, sheet_name=chosen, header=None, dtype=object)
    except InputError:
        raise
    except Exception as exc:  # openpyxl and odfpy raise many kinds on a damaged file
        raise InputError(
            f"{path}: cannot read the workbook ({type(exc).__name__}: {' '.join(str(exc).split())})"
        ) from None
    name = f"{path}, sheet '{chosen}'"
    # pandas keeps blank rows and columns before the data, so index i is the sheet's row i + 1.
    rows = [
        (int(i) + 1, [_cell_text(v) for v in values])
        for i, values in zip(frame.index, frame.itertuples(index=False, name=None), strict=True)
    ]
    rows = [(r, f) for r, f in rows if any(c.strip() for c in f)]
    comments: list[str] = []
    body: list[tuple[int, list]] = []
    header_row, header = None, []
    for r, fields in rows:
        first = next(c.strip() for c in fields if c.strip())
        if first.startswith("#"):
            if header_row is None:
                comments.append(first.lstrip("#").strip())
            continue
        if header_row is None:
            header_row = r
            width = max(i for i, c in enumerate(fields) if c.strip()) + 1
            header = [c.strip() for c in fields[:width]]
            continue
        beyond = [i for i, c in enumerate(fields) if i >= width and c.strip()]
        if beyond:
            raise InputError(
                f"{where(name, r)}: a value in column {_column_letter(beyond[0])}, right of the header's last column "
                f"('{header[-1]}'); name the column in the header or clear the cell"
            )
        body.append((r, fields[:width]))
    if header_row is None:
        raise InputError(f"{name}: empty sheet, expected a header row and data rows")
    return Table(name, header_row, header, body, None, comments, chosen)


# ----------------------------------------------------------------------------- CSV text


def _decode(path: str, raw: bytes) -> str:
    """The file's text: UTF-8 with or without BOM (Excel's "CSV UTF-8"), or UTF-16 with BOM."""
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
        encoding = "utf-16"
    else:
        encoding = "utf-8-sig"
    try:
        return raw.decode(encoding)
    except UnicodeDecodeError as exc:
        row = raw[: exc.start].count(b"\n") + 1
        raise InputError(
            f"{where(path, row)}: not {encoding.upper().replace('-SIG', '')} text (byte 0x{raw[exc.start]:02x}); save the file as 'CSV UTF-8'"
        ) from None


def leading_comments(lines) -> list[str]:
    """The ``#`` lines before the first other non-blank line, without the ``#``."""
    out = []
    for line in lines:
        s = line.strip()
        if not s:
            continue
        if not s.startswith("#"):
            break
        out.append(s.lstrip("#").strip())
    return out


def table_from_text(text: str, name: str, is_column) -> Table:
    """The rows of CSV text; ``name`` stands for the file in messages."""
    lines = text.splitlines()
    numbered = [
        (i + 1, line)
        for i, line in enumerate(lines)
        if line.strip() and not line.lstrip().startswith("#")
    ]
    if not numbered:
        raise InputError(f"{name}: empty file, expected a header row and data rows")
    sep = _delimiter(numbered[0][1], is_column)
    table = _split(name, numbered, sep)
    (header_row, header_fields), body = table[0], table[1:]
    header = [str(h).strip() for h in header_fields if isinstance(h, str)]
    body = [
        (row, fields)
        for row, fields in body
        if any(isinstance(f, str) and f.strip() for f in fields)
    ]
    return Table(name, header_row, header, body, sep, leading_comments(lines))


def _delimiter(header_line: str, is_column) -> str:
    """The delimiter that splits the header into the most recordings columns (',' on a tie)."""

    def hits(sep: str) -> int:
        names = {h.strip().strip('"').strip() for h in header_line.split(sep)}
        return sum(1 for n in names if is_column(n))

    return max(DELIMITERS, key=hits)  # max keeps the first of equals: ','


def _split(path: str, numbered: list[tuple[int, str]], sep: str) -> list[tuple[int, list]]:
    """Tokenise the rows with pandas' CSV reader; each row as (file line, fields).

    Every line is prefixed with its file line number as an extra first field, so rows keep
    their line numbers through the reader, also those it sets aside for too many fields.
    Short rows come back padded with NaN, which the caller counts as missing fields.
    """
    import pandas as pd

    text = "\n".join(f"{n}{sep}{line}" for n, line in numbered)
    extra: list[list[str]] = []
    try:
        df = pd.read_csv(
            io.StringIO(text),
            sep=sep,
            header=None,
            dtype=str,
            keep_default_na=False,
            na_filter=False,
            engine="python",
            skip_blank_lines=False,
            quoting=csv.QUOTE_MINIMAL,
            on_bad_lines=lambda fields: extra.append(fields) or None,
        )
    except (pd.errors.ParserError, csv.Error) as exc:
        raise InputError(
            f"{path}: cannot split the rows into columns ({' '.join(str(exc).split())})"
        ) from None
    rows = [(r[0], list(r[1:])) for r in df.itertuples(index=False, name=None)] + [
        (r[0], list(r[1:])) for r in extra
    ]
    out = []
    for line, fields in rows:
        if not str(line).isdigit() or any("\n" in str(f) for f in fields if isinstance(f, str)):
            first = next((n for n, ln in numbered if ln.count('"') % 2), numbered[0][0])
            raise InputError(
                f'{where(path, first)}: a quote (") opened on this line is not closed on it'
            )
        out.append((int(line), fields))
    return sorted(out, key=lambda r: r[0])
