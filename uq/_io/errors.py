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
    parameters, never of command-line options: a parameter named inside a message is written in
    backticks (``"... or give a smaller `pressure_tolerance_bar`"``). The ``uq`` command names its
    options instead (:meth:`for_cli`)."""

    def __init__(self, message: str, *, param: str | None = None):
        message = " ".join(str(message).split())  # one line, always
        super().__init__(message)
        self.param = param

    def __reduce__(self):  # pickled with its param (an error sent back by a worker process)
        return _input_error, (str(self), self.param)

    def for_cli(self, options: dict[str, str]) -> InputError:
        """The same error worded for the command line, ``options`` mapping library parameters to
        command-line options: a leading ``param:`` becomes ``option --x:`` and every backticked
        parameter the option (``--x``)."""
        text = str(self)
        if self.param in options and text.startswith(f"{self.param}:"):
            text = f"option {options[self.param]}:" + text[len(self.param) + 1 :]
        for name, option in options.items():
            text = text.replace(f"`{name}`", option)
        return InputError(text)


def _input_error(message: str, param: str | None) -> InputError:
    return InputError(message, param=param)


def where(path: str, row: int | None = None, column: str | None = None) -> str:
    """Format a location as ``file, row N, column 'c'`` (rows counted as in an editor, 1-based)."""
    parts = [str(path)]
    if row is not None:
        parts.append(f"row {row}")
    if column is not None:
        parts.append(f"column '{column}'")
    return ", ".join(parts)


def refuse_outside(
    place: str, value: float, lo: float, hi: float, kind: str, tail: str = "", param=None
) -> None:
    """InputError ``PLACE: VALUE is outside the tested KIND LO..HI`` + ``tail`` when ``value`` lies
    outside ``lo..hi`` (1e-9 of slack: the tested ends are in); ``kind`` "heights" (metres, said in
    mm) or "pressures" (bar)."""
    if lo - 1e-9 <= value <= hi + 1e-9:
        return
    if kind == "heights":
        text = f"{value * 1e3:g} mm is outside the tested heights {lo * 1e3:g}..{hi * 1e3:g} mm"
    else:
        text = f"{value:g} bar is outside the tested pressures {lo:g}..{hi:g} bar"
    raise InputError(f"{place}: {text}{tail}", param=param)
