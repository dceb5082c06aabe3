"""The rows of the memory and scaling benchmarks' tables, formatted once for both readers: markdown
in docs/speed.md (``scripts/readme_numbers.py``) and aligned columns on the console
(``benchmarks/bench.py --memory``, ``--scaling``). Imported by both; runs nothing itself."""

from __future__ import annotations

from collections.abc import Callable, Sequence

Column = tuple[str, Callable[[dict], str]]  # (header, the cell of one run of the benchmark's JSON)

MEMORY: tuple[Column, ...] = (
    ("readings", lambda x: f"{x['readings']}"),
    ("peak RSS", lambda x: f"{x['peak_rss_mb']:.0f} MB"),
    ("the measured line minus the peak", lambda x: f"{x['line_error_mb']:+.0f} MB"),
    ("uq fit's model (the check)", lambda x: f"{x['fit_model_mb']:.0f} MB"),
)
SCALING: tuple[Column, ...] = (
    ("points per test", lambda x: f"{x['points_per_test']:.0f} ({x['factor']}x)"),
    ("wall time", lambda x: f"{x['wall_s']:.1f} s"),
    ("time ratio", lambda x: f"x{x['time_ratio']:.2f}"),
    ("ms per step", lambda x: f"{x['ms_per_step']:.2f}"),
    ("peak RSS", lambda x: f"{x['peak_rss_mb']:.0f} MB"),
    ("added by the fit", lambda x: f"{x['added_rss_mb']:.0f} MB"),
)


def table(columns: Sequence[Column], runs: Sequence[dict], markdown: bool) -> list[str]:
    """The header and one row a run: markdown (``| a | b |`` under a ``| --- |`` line) or, for
    the console, the cells right-aligned to their column's widest, indented by two spaces."""
    rows = [[h for h, _ in columns]] + [[cell(x) for _, cell in columns] for x in runs]
    if markdown:
        rows.insert(1, ["---"] * len(columns))
        return ["| " + " | ".join(r) + " |" for r in rows]
    widths = [max(len(r[i]) for r in rows) for i in range(len(columns))]
    return ["  " + "  ".join(c.rjust(w) for c, w in zip(r, widths, strict=True)) for r in rows]
