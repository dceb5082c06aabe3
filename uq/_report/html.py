"""What the HTML pages share: the jinja2 templates and their one renderer, matplotlib off-screen,
PNG bytes, embedded figures.

Every page (``report.html``, ``surface.html``, ``diagnose.html``, the batch ``index.html``) is a
template in ``uq/_report/templates/``, rendered by :func:`render` with autoescaping on: a value
put on a page is escaped unless it was deliberately marked safe (``markupsafe.Markup``), and a
variable the template names but the caller did not give fails (``StrictUndefined``). The style
sheet is ``templates/page.css``; an embedded figure is the ``img`` macro of ``templates/macros.html``
given a :class:`Figure`. Imported by the report modules (``uq._report.campaign``, ``surface``,
``diagnose``) and the batch driver; it imports nothing of uq, so any module may use it.
"""

from __future__ import annotations

import base64
import functools
import html
import io
import math
from dataclasses import dataclass

from markupsafe import Markup

DPI = 90


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


@dataclass(frozen=True)
class Figure:
    """A PNG to embed (base64, so that the page stands alone) under its file name, with its alt text."""

    name: str
    png: bytes
    alt: str

    @property
    def base64(self) -> str:
        return base64.b64encode(self.png).decode()


def sig4(v: float) -> str:
    """Four significant digits (``0``, ``nan``, ``inf`` as ``g`` prints them): the ``sig4`` filter."""
    if v == 0 or not math.isfinite(v):
        return f"{v:g}"
    return f"{v:.4g}"


def _escape(value):
    """Autoescaping as ``html.escape`` does it (``'`` as ``&#x27;``, ``"`` as ``&quot;``), which the
    pages have always used, rather than markupsafe's ``&#39;``/``&#34;``: the same bytes as before
    the templates. Markup marked safe (``__html__``) passes unchanged."""
    if hasattr(value, "__html__"):
        return value
    return Markup(html.escape(str(value)))


@functools.cache
def _environment():
    from jinja2 import Environment, PackageLoader, StrictUndefined

    env = Environment(
        loader=PackageLoader("uq", "_report/templates"),
        autoescape=True,
        undefined=StrictUndefined,
        finalize=_escape,
        trim_blocks=True,
        lstrip_blocks=True,
        keep_trailing_newline=True,
    )
    env.filters["fmt"] = format  # {{ x|fmt(".1f") }} is f"{x:.1f}"
    env.filters["sig4"] = sig4
    return env


def render(template: str, **context) -> str:
    """The page ``templates/<template>`` rendered with ``context`` (autoescaped; missing names fail)."""
    return _environment().get_template(template).render(**context)
