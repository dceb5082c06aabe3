"""Errors a user can act on.

Every problem with what the user gave us (a file, a row, an option) is raised as
:class:`InputError` with a one-line message that names the place and what was expected.
The CLI turns it into that line on stderr and exit status 2, never a traceback.
"""

from __future__ import annotations


class InputError(ValueError):
    """Bad input: a one-line, actionable message; the CLI exits with status 2.

    ``param``: the library parameter the message is about (e.g. ``"load_N"``), when the message
    starts with it (``"load_N: expected a positive load in N"``). The library speaks of its own
    parameters, never of command-line options; the ``uq`` command names its option instead
    (:meth:`for_option`)."""

    def __init__(self, message: str, *, param: str | None = None):
        message = " ".join(str(message).split())  # one line, always
        super().__init__(message)
        self.param = param

    def for_option(self, option: str) -> InputError:
        """The same error worded for the command line: ``param:`` replaced by ``option --x:``."""
        text = str(self)
        if self.param and text.startswith(f"{self.param}:"):
            text = f"option {option}:" + text[len(self.param) + 1 :]
        return InputError(text)


def where(path: str, row: int | None = None, column: str | None = None) -> str:
    """Format a location as ``file, row N, column 'c'`` (rows counted as in an editor, 1-based)."""
    parts = [str(path)]
    if row is not None:
        parts.append(f"row {row}")
    if column is not None:
        parts.append(f"column '{column}'")
    return ", ".join(parts)
