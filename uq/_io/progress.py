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
library callers get no bar unless they enable it. Where no bar is shown a silent stand-in takes
its calls (:class:`Silent`), not tqdm's disabled bar: every tqdm bar, disabled or not, takes
tqdm's lock, a multiprocessing lock whose semaphore starts multiprocessing's resource tracker and
which the command's fast exit leaves behind (the tracker then warns of a leaked semaphore on
stderr, in about one run in six of ``uq margin --json FILE``).
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


class Silent:
    """Stands in for a bar when none is shown: same calls, no output, no tqdm lock (module
    docstring)."""

    def __init__(self, iterable: Iterable | None):
        self._iterable = iterable

    def __iter__(self):
        return iter(self._iterable if self._iterable is not None else ())

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        return None

    def update(self, n: int = 1) -> None:
        return None

    def set_postfix_str(self, s: str = "", refresh: bool = True) -> None:
        return None

    def close(self) -> None:
        return None


def progress(
    iterable: Iterable | None = None, *, total: int | None = None, desc: str = "", unit: str = "it"
):
    """A tqdm bar on stderr over ``iterable`` (or a counter to ``total``), or a silent stand-in."""
    if not active():
        return Silent(iterable)

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
