"""A column map: which column of an instrument's export is which recordings column.

``force_N=Load,height_mm=Extension`` says the file's column ``Load`` is the force in N and
``Extension`` the height in mm; a quantity without a unit (``force=Load``) takes its unit from
the file's units row (``(kN)``, uq._data.rows). Targets are the recordings columns of
docs/formats.md section 1 (``pressure_*``, ``set_pressure_*``, ``height_*``, ``force_*``,
``piston_*``, ``volume_*``, ``branch``, ``step``); sources are header names as the file writes
them (spaces allowed, no ``,`` or ``=``).

Pure Python (no numpy): the command line checks a map while it builds its parser.
"""

from __future__ import annotations

from uq._data import units as _units

ORDER_COLUMNS = ("branch", "step")


def _target(text: str, pair: str) -> tuple[str, str | None]:
    """(quantity, suffix or None) of a target such as ``force_N``, ``force`` or ``branch``."""
    if text in ORDER_COLUMNS or text in _units.QUANTITIES:
        return text, None
    split = _units.split_name(text)
    if split is not None:
        q, suffix = split
        if _units.known(q, suffix):
            return q, suffix
        raise ValueError(
            f"'{pair}': unknown unit '{suffix}' for {q.replace('_', ' ')}; one of "
            f"{', '.join(_units.names(q))}, or {q} alone to take the unit from the file's units row"
        )
    raise ValueError(
        f"'{pair}': '{text}' is not a recordings column; one of "
        + ", ".join(f"{q}_*" for q in _units.QUANTITIES)
        + ", branch, step (e.g. force_N=Load)"
    )


def parse(spec) -> dict[str, tuple[str, str | None, str]]:
    """``spec`` (the text ``force_N=Load,height_mm=Extension`` or a dict target -> source) as
    source -> (quantity, suffix or None, target as written). ValueError with one line on a bad map.

    >>> parse("force_N=Load, height=Extension")
    {'Load': ('force', 'N', 'force_N'), 'Extension': ('height', None, 'height')}
    """
    if isinstance(spec, dict):
        pairs = [(str(t).strip(), str(s).strip(), f"{t}={s}") for t, s in spec.items()]
    else:
        pairs = []
        for part in str(spec).split(","):
            if not part.strip():
                continue
            if part.count("=") != 1:
                raise ValueError(
                    f"'{part.strip()}': expected TARGET=SOURCE, e.g. force_N=Load (the recordings column, "
                    "then the file's header name)"
                )
            t, s = part.split("=")
            pairs.append((t.strip(), s.strip(), part.strip()))
    if not pairs:
        raise ValueError("empty column map; expected TARGET=SOURCE pairs, e.g. force_N=Load")
    out: dict[str, tuple[str, str | None, str]] = {}
    by_quantity: dict[str, str] = {}
    for target, source, pair in pairs:
        if not target or not source:
            raise ValueError(f"'{pair}': expected TARGET=SOURCE, e.g. force_N=Load")
        q, suffix = _target(target, pair)
        if q in by_quantity:
            raise ValueError(
                f"'{pair}': the {q.replace('_', ' ')} is already mapped ({by_quantity[q]})"
            )
        if source in out:
            raise ValueError(f"'{pair}': column '{source}' is already mapped (to {out[source][2]})")
        by_quantity[q] = pair
        out[source] = (q, suffix, target)
    return out


def text(mapping: dict[str, tuple[str, str | None, str]]) -> str:
    """The map as the option writes it (``force_N=Load,height=Extension``)."""
    return ",".join(f"{target}={source}" for source, (_, _, target) in mapping.items())


def bare_quantity(header: str) -> str | None:
    """The quantity a header names without a unit (``Pressure``, ``Set pressure``), or None:
    such a column takes its unit from the units row."""
    key = "_".join(header.strip().lower().split())
    return key if key in _units.QUANTITIES else None
