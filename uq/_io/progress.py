"""One progress display for long runs (fits, surface, margin, diagnose, calibrate).

Use it around any loop whose items take seconds::

    from uq._io.progress import progress

    for test in progress(tests, desc="fits", unit="test"):
        ...

or, when the work is not a loop over a sequence, as a counter::

    with progress(total=n_steps, desc="sampling", unit="step") as bar:
        ...
        bar.update(chunk)

The bar goes to stderr (stdout stays clean for ``--json -`` and pipes). It is shown only when
stderr is a terminal and the user did not pass ``--quiet`` (the CLI calls :func:`set_enabled`);
library callers get no bar unless they enable it. Where no bar is shown, tqdm's disabled bar
stands in (the same calls, no output), so the display costs nothing in tests, CI logs or pipes.
"""

from __future__ import annotations

import sys
from collections.abc import Iterable

from tqdm import tqdm

_enabled = False  # the CLI turns it on; a library user's loops stay silent by default


def set_enabled(on: bool) -> None:
    """Allow progress bars (they still appear only when stderr is a terminal)."""
    global _enabled
    _enabled = bool(on)


def active() -> bool:
    """True when a bar would be drawn: enabled and stderr is a terminal."""
    stream = sys.stderr
    return _enabled and stream is not None and hasattr(stream, "isatty") and stream.isatty()


def progress(
    iterable: Iterable | None = None, *, total: int | None = None, desc: str = "", unit: str = "it"
):
    """A tqdm bar on stderr over ``iterable`` (or a counter to ``total``) named ``desc``, or, when
    none is shown (no ``desc``, or not :func:`active`), tqdm's disabled bar."""
    if not desc or not active():
        return tqdm(iterable, total=total, disable=True)

    if total is None and iterable is not None and hasattr(iterable, "__len__"):
        total = len(iterable)
    return tqdm(
        iterable,
        total=total,
        desc=desc,
        unit=unit,
        file=sys.stderr,
        leave=False,
        dynamic_ncols=True,
    )
