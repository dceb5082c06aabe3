"""What the HTML pages share: the style sheet, matplotlib off-screen, PNG bytes, embedded images.

Imported by the report modules (``uq._report``, ``uq._surface_report``) so that neither has to
import the other; it imports nothing of uq, so any module may use it.
"""

from __future__ import annotations

import base64
import html
import io

DPI = 90

CSS = """
body{font-family:system-ui,Segoe UI,Helvetica,Arial,sans-serif;max-width:1250px;margin:1.5em auto;padding:0 1em;color:#222;line-height:1.45}
h1{font-size:1.6em}h2{border-bottom:2px solid #ccc;padding-bottom:.2em;margin-top:2em}
table{border-collapse:collapse;font-size:.85em;margin:.6em 0}td,th{border:1px solid #ccc;padding:3px 6px;text-align:right;vertical-align:top}
th{background:#f2f2f2}td.l,th.l{text-align:left}.out{background:#fde2e2}.warn{color:#c00}.ok{color:#080}
.note{background:#fff7d6;border-left:4px solid #e6b800;padding:.5em 1em}.small{font-size:.8em;color:#555}
img{max-width:100%;border:1px solid #eee}pre{background:#f6f6f6;padding:.5em;font-size:.8em;white-space:pre-wrap}
"""


def _plt():
    """matplotlib.pyplot on the off-screen Agg backend (imported on first use: it is slow)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _png(fig) -> bytes:
    """The figure as PNG bytes at ``DPI``; the figure is closed."""
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI)
    _plt().close(fig)
    return buf.getvalue()


def _img(name: str, png: bytes, alt: str) -> str:
    """An ``<img>`` paragraph with the PNG embedded as base64 (the page stands alone)."""
    return f'<p><img src="data:image/png;base64,{base64.b64encode(png).decode()}" alt="{html.escape(alt)}" title="{html.escape(name)}"></p>'
