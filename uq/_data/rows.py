"""A recordings file as rows of text fields, numbered as an editor or a spreadsheet shows them.

Two sources give the same :class:`Table`, so one set of checks and messages serves both:

* CSV text: UTF-8 with or without BOM (Excel's "CSV UTF-8") or UTF-16 with BOM; columns
  separated by ',' or, when the header splits better that way, ';' or tab (then a decimal
  comma is understood as well); ``#`` lines are comments. Tokenised by the standard library's
  csv module, one file line at a time (a quoted field may not run over a line end).
* A workbook (.xlsx through openpyxl, .ods through odfpy, both read by pandas, imported only
  here): one sheet is one campaign. Rows are numbered as the spreadsheet shows them; a row whose
  first filled cell starts with ``#`` is a comment; numbers are read as the spreadsheet holds
  them (no decimal-comma guessing: a number typed as text with a comma is refused).

Instrument exports (an Instron Bluehill RawData file, a logger's CSV) put other rows around the
header, and both sources understand them the same way:

* **a title above the header** (``Text Inputs : Specimen label,...``, a sheet's caption): the
  header is the first row holding a recordings column; when the first row holds none, the first
  of the next MAX_TITLE_ROWS rows that holds one is taken and a note says so, or the
  header's row is given (``header_row``). The rows above it are the title, kept with the comments;
* **a units row under the header** (``(bar),(mm),(N),...``): with ``units_row`` "auto" (the
  default) the row under the header is one when each of its filled cells is a unit in
  parentheses or brackets, and a note says so; "yes": the row under the header is the units
  row (brackets optional); "no": never (the row is data).

Every defect of the file itself (encoding, quotes, a missing or unknown sheet, a header row that
is not there) raises :class:`InputError` naming the file and the row.
"""

from __future__ import annotations

import csv
import hashlib
import io
import math
import re
import warnings
import zipfile
from dataclasses import dataclass, field, replace
from pathlib import Path

from uq._io.errors import InputError, where

DELIMITERS = {",": "','", ";": "';'", "\t": "tab"}
WORKBOOK_SUFFIXES = (".xlsx", ".xlsm", ".ods")
UNITS_ROW_MODES = ("auto", "yes", "no")
#: How many rows under a title the header is looked for when the first row holds no column.
MAX_TITLE_ROWS = 20
#: A units row's cell: a unit in parentheses or brackets, as instrument software writes it.
_BRACKETED = re.compile(r"^\s*[(\[](.*)[)\]]\s*$")


@dataclass(frozen=True)
class Table:
    """The rows of one campaign: the header and the data rows, each with its file row number.

    ``fields`` are strings; a missing field (a CSV row shorter than the header) is absent from
    the row's list. ``sep`` is the CSV delimiter, None for a workbook. ``name`` stands for the
    file in messages (a workbook's adds the sheet). ``title``: the rows above the header that
    are not comments, as text; ``units``: the units row's cells (brackets removed, one per
    header column, '' where empty) and ``units_row`` its row, or None; ``notes``: what the
    reading decided by itself (a header found below a title, a units row), one line each;
    ``sha256``: of the file's bytes (of the text's UTF-8 for text given in memory).
    """

    name: str
    header_row: int
    header: list[str]
    body: list[tuple[int, list]]
    sep: str | None
    comments: list[str] = field(default_factory=list)
    sheet: str | None = None
    title: list[str] = field(default_factory=list)
    units: list[str] | None = None
    units_row: int | None = None
    notes: list[str] = field(default_factory=list)
    sha256: str | None = None


def check_shape_options(header_row: int | None, units_row: str) -> None:
    """Validate ``header_row`` and ``units_row`` (names the parameter on failure)."""
    if header_row is not None and (
        isinstance(header_row, bool) or not isinstance(header_row, int) or header_row < 1
    ):
        raise InputError(
            f"header_row: expected the header's row number (1, 2, ...), got {header_row!r}",
            param="header_row",
        )
    if units_row not in UNITS_ROW_MODES:
        raise InputError(
            f"units_row: expected auto, yes or no, got {units_row!r}", param="units_row"
        )


def read_table(
    path: str,
    is_column,
    sheet: str | None = None,
    *,
    header_row: int | None = None,
    units_row: str = "auto",
) -> Table:
    """The rows of the file at ``path``: a workbook (by content, whatever its name) or CSV text.

    ``is_column(name)``: whether a header name is a recordings column (finds the header and
    chooses the CSV delimiter). ``sheet``: the workbook sheet to read; required when a workbook
    has more than one. ``header_row``, ``units_row``: see the module docstring.
    """
    check_shape_options(header_row, units_row)
    raw = _read_bytes(path)
    digest = hashlib.sha256(raw).hexdigest()
    kind = _workbook_kind(path, raw)
    if kind is not None:
        rows, comments, chosen = _workbook_rows(path, raw, kind, sheet)
        name = f"{path}, sheet '{chosen}'"
        table = _layout(name, rows, comments, None, is_column, header_row, units_row)
        return replace(table, sheet=chosen, sha256=digest)
    if sheet is not None:
        raise InputError(
            f"sheet: {sheet!r}: {path} is CSV text, not a workbook (.xlsx, .ods)", param="sheet"
        )
    table = table_from_text(
        _decode(path, raw), path, is_column, header_row=header_row, units_row=units_row
    )
    return replace(table, sha256=digest)


def _read_bytes(path: str) -> bytes:
    try:
        return Path(path).read_bytes()
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


def _workbook_rows(
    path: str, raw: bytes, engine: str, sheet: str | None
) -> tuple[list[tuple[int, list]], list[str], str]:
    """The sheet's filled rows that are not comments (row number, cell texts), its leading
    comments, and the sheet's name."""
    import pandas as pd  # reason: heavy; only a workbook needs pandas (and openpyxl or odfpy)

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
    # pandas keeps blank rows and columns before the data, so index i is the sheet's row i + 1.
    rows = [
        (int(i) + 1, [_cell_text(v) for v in values])
        for i, values in zip(frame.index, frame.itertuples(index=False, name=None), strict=True)
    ]
    rows = [(r, f) for r, f in rows if any(c.strip() for c in f)]
    comments: list[str] = []
    kept: list[tuple[int, list]] = []
    for r, fields in rows:
        first = next(c.strip() for c in fields if c.strip())
        if first.startswith("#"):
            if not kept:
                comments.append(first.lstrip("#").strip())
            continue
        kept.append((r, fields))
    if not kept:
        raise InputError(
            f"{path}, sheet '{chosen}': empty sheet, expected a header row and data rows"
        )
    return kept, comments, chosen


# ----------------------------------------------------------------------------- CSV text


def _decode(path: str, raw: bytes) -> str:
    """The file's text: UTF-8 with or without BOM (Excel's "CSV UTF-8"), or UTF-16 with BOM."""
    encoding = "utf-16" if raw.startswith((b"\xff\xfe", b"\xfe\xff")) else "utf-8-sig"
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


def table_from_text(
    text: str, name: str, is_column, *, header_row: int | None = None, units_row: str = "auto"
) -> Table:
    """The rows of CSV text; ``name`` stands for the file in messages."""
    check_shape_options(header_row, units_row)
    lines = text.splitlines()
    numbered = [
        (i + 1, line)
        for i, line in enumerate(lines)
        if line.strip() and not line.lstrip().startswith("#")
    ]
    if not numbered:
        raise InputError(f"{name}: empty file, expected a header row and data rows")
    k = _header_index(name, numbered, lambda line: _hits(line, is_column), header_row)
    sep = _delimiter(numbered[k][1], is_column)
    rows = [(n, _fields(name, n, line, sep)) for n, line in numbered]
    table = _layout(name, rows, leading_comments(lines), sep, is_column, header_row, units_row, k)
    return replace(table, sha256=hashlib.sha256(text.encode("utf-8")).hexdigest())


def _hits(header_line: str, is_column, sep: str | None = None) -> int:
    """How many recordings columns ``header_line`` names, split by ``sep`` (by the best
    delimiter when None)."""
    if sep is None:
        return max(_hits(header_line, is_column, s) for s in DELIMITERS)
    names = {h.strip().strip('"').strip() for h in header_line.split(sep)}
    return sum(1 for n in names if is_column(n))


def _delimiter(header_line: str, is_column) -> str:
    """The delimiter that splits the header into the most recordings columns (',' on a tie)."""
    return max(DELIMITERS, key=lambda sep: _hits(header_line, is_column, sep))  # first of equals


def _fields(path: str, row: int, line: str, sep: str) -> list[str]:
    """One line's fields (the csv module's rules: quotes, doubled quotes, ``sep``)."""
    try:
        (fields,) = list(csv.reader([line + "\n"], delimiter=sep, quotechar='"', strict=False))
    except csv.Error as exc:
        raise InputError(
            f"{where(path, row)}: cannot split the row into columns ({' '.join(str(exc).split())})"
        ) from None
    if any("\n" in f for f in fields):
        raise InputError(f'{where(path, row)}: a quote (") opened on this line is not closed on it')
    return fields


# ----------------------------------------------------------------------------- header, title, units


def _header_index(name: str, rows: list[tuple[int, object]], hits, header_row: int | None) -> int:
    """Index in ``rows`` of the header: the given row, the first row when it names a column, else
    the first of the next MAX_TITLE_ROWS rows naming one (the first row when none does)."""
    if header_row is not None:
        for k, (n, _) in enumerate(rows):
            if n == header_row:
                return k
        last = rows[-1][0]
        what = f"beyond the last row ({last})" if header_row > last else "blank or a comment"
        raise InputError(
            f"header_row: {header_row}: row {header_row} of {name} is {what}; give the row of the "
            "column names",
            param="header_row",
        )
    if hits(rows[0][1]) > 0:
        return 0
    for k in range(1, min(len(rows), MAX_TITLE_ROWS + 1)):
        if hits(rows[k][1]) > 0:
            return k
    return 0


def _units_cells(fields: list[str], mode: str) -> list[str] | None:
    """The unit of each cell of the row under the header, or None when it is not a units row."""
    filled = [f for f in fields if f.strip()]
    if mode == "no" or not filled:
        return None
    if mode == "auto" and not all(_BRACKETED.match(f) for f in filled):
        return None
    out = []
    for f in fields:
        m = _BRACKETED.match(f)
        out.append((m.group(1) if m else f).strip())
    return out


def _layout(
    name: str,
    rows: list[tuple[int, list]],
    comments: list[str],
    sep: str | None,
    is_column,
    header_row: int | None,
    units_row: str,
    found: int | None = None,
) -> Table:
    """Split filled, non-comment ``rows`` into title, header, units row and body.

    ``header_row``: the header's row as given (None: found); ``found``: the header's index when
    the caller has chosen it (CSV text chooses it before tokenising, by the delimiter); otherwise
    it is chosen here the same way.
    """
    if found is None:
        found = _header_index(
            name, rows, lambda f: sum(1 for c in f if is_column(c.strip())), header_row
        )
    k = found
    header_at, header_fields = rows[k]
    workbook = sep is None
    if workbook:
        width = max(i for i, c in enumerate(header_fields) if c.strip()) + 1
        header = [c.strip() for c in header_fields[:width]]
    else:
        header = [str(h).strip() for h in header_fields]
    notes: list[str] = []
    title = [", ".join(c.strip() for c in f if c.strip()) for _, f in rows[:k]]
    if k and header_row is None:
        span = f"row {rows[0][0]}" if k == 1 else f"rows {rows[0][0]}-{rows[k - 1][0]}"
        notes.append(
            f"{name}: the header is row {header_at} ({span} above it: a title, kept with the comments)"
        )
    body_rows = rows[k + 1 :]
    units, units_at = None, None
    if body_rows:
        cells = _units_cells(body_rows[0][1], units_row)
        if cells is not None:
            units_at = body_rows[0][0]
            units = (cells + [""] * len(header))[: len(header)]
            body_rows = body_rows[1:]
    elif units_row == "yes":
        raise InputError(
            f"{where(name, header_at)}: `units_row` yes, but the header is the last row: no units row under it"
        )
    if units_row == "yes" and units is None:
        raise InputError(
            f"{where(name, body_rows[0][0])}: `units_row` yes, but the row under the header is empty"
        )
    body = []
    for r, fields in body_rows:
        if workbook:
            beyond = [i for i, c in enumerate(fields) if i >= width and c.strip()]
            if beyond:
                raise InputError(
                    f"{where(name, r)}: a value in column {_column_letter(beyond[0])}, right of the header's last column "
                    f"('{header[-1]}'); name the column in the header or clear the cell"
                )
            fields = fields[:width]
        elif not any(f.strip() for f in fields):
            continue  # a row of nothing but separators (Excel's padding), like a blank line
        body.append((r, fields))
    return Table(
        name,
        header_at,
        header,
        body,
        sep,
        list(comments) + title,
        None,
        title,
        units,
        units_at,
        notes,
    )
