"""TeimOrbit property files: the text format Adams/Car and Altair MotionView/MotionSolve read.

The format (Adams Tire, "About the TeimOrbit format"; Altair MotionView, "About TeimOrbit Files",
"TeimOrbit Format"): blocks in square brackets ``[UNITS]``, sub-blocks in parentheses
``(XY_DATA)``, parameters ``NAME = value`` (a number, or a string in quotes), tables whose column
labels sit in curly braces ``{height force}`` followed by rows of values; a table ends at the next
table, sub-block or block, at a comment or a blank line; comments start with ``$`` or ``!``. Files
start with ``[MDI_HEADER]`` (FILE_TYPE, FILE_VERSION, FILE_FORMAT) and a ``[UNITS]`` block.
docs/export.md cites the pages.
"""

from __future__ import annotations

from dataclasses import dataclass, field

RULE_WIDTH = 80
#: The unit names a [UNITS] block takes (Altair's SPD/TeimOrbit documentation), by our suffixes.
LENGTH_UNITS = {"mm": "mm", "m": "meter", "in": "inch"}
FORCE_UNITS = {"N": "newton", "kN": "knewton", "lbf": "pound_force"}


@dataclass
class SubBlock:
    name: str
    parameters: list[tuple[str, object]] = field(default_factory=list)
    labels: list[str] | None = None
    rows: list[list] = field(default_factory=list)


@dataclass
class Block:
    name: str
    parameters: list[tuple[str, object]] = field(default_factory=list)
    comments: list[str] = field(default_factory=list)
    sub_blocks: list[SubBlock] = field(default_factory=list)


def _value(v) -> str:
    if isinstance(v, str):
        return "'" + v.replace("'", '"') + "'"
    if isinstance(v, int) and not isinstance(v, bool):
        return str(v)
    text = f"{float(v):.10g}"
    return text if any(c in text for c in ".eEn") else text + ".0"  # a real stays a real


def _rule(name: str) -> str:
    return "$" + name.rjust(RULE_WIDTH - 1, "-")


def _table(labels: list[str], rows: list[list]) -> list[str]:
    """A table: labels in braces, then the rows; numbers right-aligned in columns of one width."""
    cells = [[_value(v) for v in row] for row in rows]
    if any(isinstance(v, str) for row in rows for v in row):
        return ["{" + " ".join(labels) + "}", *(" ".join(r) for r in cells)]
    width = max([len(label) for label in labels] + [len(c) for r in cells for c in r] + [1])
    out = ["{" + " ".join(label.rjust(width) for label in labels) + "}"]
    out += [" " + " ".join(c.rjust(width) for c in r) for r in cells]
    return out


def text(blocks: list[Block], comments: list[str] = ()) -> str:
    """The file's text: ``$`` comment lines, then each block with its rule line."""
    lines = [f"$ {c}".rstrip() for c in comments]
    for b in blocks:
        lines.append(_rule(b.name))
        lines.append(f"[{b.name}]")
        lines += [f"$ {c}".rstrip() for c in b.comments]
        lines += [f"{k} = {_value(v)}" for k, v in b.parameters]
        for s in b.sub_blocks:
            lines.append(f"({s.name})")
            lines += [f"{k} = {_value(v)}" for k, v in s.parameters]
            if s.labels is not None:
                lines += _table(s.labels, s.rows)
    return "\n".join(lines) + "\n"


def header(file_type: str, comments: list[str], version: float = 1.0) -> Block:
    """The ``[MDI_HEADER]`` block, with a (COMMENTS) table of quoted strings."""
    return Block(
        "MDI_HEADER",
        [("FILE_TYPE", file_type), ("FILE_VERSION", version), ("FILE_FORMAT", "ASCII")],
        sub_blocks=[SubBlock("COMMENTS", labels=["comment_string"], rows=[[c] for c in comments])],
    )


def units(length: str, force: str) -> Block:
    """The ``[UNITS]`` block for lengths and forces given as our suffixes (mm, in; N, lbf)."""
    return Block(
        "UNITS",
        [
            ("LENGTH", LENGTH_UNITS[length]),
            ("FORCE", FORCE_UNITS[force]),
            ("ANGLE", "degree"),
            ("MASS", "kg"),
            ("TIME", "second"),
        ],
    )
