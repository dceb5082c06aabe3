"""Is the text of a matplotlib figure readable: no title, axis label or colour-bar label on top of
another, on another axes, or off the figure? Laid out by matplotlib's own renderer, as on the page.
"""

from __future__ import annotations

import itertools


def _texts(fig):
    """(label, text artist) of every title, axis label and colour-bar label with text."""
    out = []
    if fig._suptitle is not None:
        out.append(("suptitle", fig._suptitle))
    for i, ax in enumerate(fig.axes):
        for kind in ("title", "_left_title", "_right_title"):
            out.append((f"axes {i} {kind}", getattr(ax, kind)))
        out.append((f"axes {i} xlabel", ax.xaxis.label))
        out.append((f"axes {i} ylabel", ax.yaxis.label))
    return [(k, t) for k, t in out if t.get_visible() and t.get_text().strip()]


def overlaps(fig) -> list[str]:
    """Pairs of texts whose boxes intersect, titles on another axes, texts off the figure."""
    fig.draw_without_rendering()
    r = fig.canvas.get_renderer()
    page = fig.bbox
    boxes = [(k, t.get_window_extent(r)) for k, t in _texts(fig)]
    found = [
        f"{a} / {b}" for (a, ba), (b, bb) in itertools.combinations(boxes, 2) if ba.overlaps(bb)
    ]
    for k, b in boxes:
        if b.x0 < page.x0 - 1 or b.x1 > page.x1 + 1 or b.y0 < page.y0 - 1 or b.y1 > page.y1 + 1:
            found.append(f"{k} off the figure")
        if "title" in k:
            own = int(k.split()[1]) if k.startswith("axes") else None
            for i, ax in enumerate(fig.axes):
                if i != own and b.overlaps(ax.get_window_extent(r)):
                    found.append(f"{k} on axes {i}")
    return found
