"""What the HTML pages share: the jinja2 templates and their one renderer, matplotlib off-screen,
figure bytes (PNG or SVG), embedded figures.

Every page (``report.html``, ``surface.html``, ``diagnose.html``, the batch ``index.html``) is a
template in ``uq/_report/templates/``, rendered by :func:`render` with autoescaping on: a value
put on a page is escaped unless it was deliberately marked safe (``markupsafe.Markup``), and a
variable the template names but the caller did not give fails (``StrictUndefined``). The style
sheet is ``templates/page.css``; an embedded figure is the ``img`` macro of ``templates/macros.html``
given a :class:`Figure` (PNG or SVG, as a ``data:`` URI, so the page stands alone). Imported by the report modules (``uq._report.campaign``, ``surface``,
``diagnose``) and the batch driver; of uq it imports only ``uq._io`` (the bottom layer).
"""

from __future__ import annotations

import base64
import functools
import html
import io
import math
import re
from dataclasses import dataclass

from jinja2 import Environment, PackageLoader, StrictUndefined
from markupsafe import Markup

from uq._io.errors import InputError

DPI = 90
#: zlib's level for the PNGs: 3 takes about 60 % of the time of Pillow's default 6 (about 20 ms
#: less a figure) for files under 1 % larger; the pixels are the same at every level
PNG_COMPRESSION = 3


def pyplot():
    """matplotlib.pyplot on the off-screen Agg backend (imported on first use: it is slow)."""
    import matplotlib  # reason: optional and heavy, loaded only where used

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # reason: optional and heavy, loaded only where used

    return plt


#: the figure formats a page can embed (``uq report --figures``)
FIGURE_FORMATS = ("png", "svg")
_MIME = {"png": "image/png", "svg": "image/svg+xml"}


def check_format(figure_format: str) -> str:
    """``figure_format`` if it is one of :data:`FIGURE_FORMATS`, else a one-line ``InputError``."""
    if figure_format not in FIGURE_FORMATS:
        raise InputError(
            f"figure_format: one of {', '.join(FIGURE_FORMATS)}, got {figure_format!r}",
            param="figure_format",
        )
    return figure_format


def encode(fig, figure_format: str = "png", units=None) -> bytes:
    """The figure as PNG (at ``DPI``) or SVG bytes; the figure is closed. ``units`` (an
    :class:`uq._data.units.OutputUnits`, ``uq report --units input``): each axis labelled in mm,
    N, kN, cm² or litres gets a second axis in those units (:func:`input_unit_axes`).

    SVG keeps text as paths (the page looks the same in every browser) and is reproducible: no
    date in its metadata and a fixed salt for its element ids, so one figure gives the same bytes.
    """
    import matplotlib  # reason: optional and heavy, loaded only where used

    if units is not None:
        input_unit_axes(fig, units)
    buf = io.BytesIO()
    with matplotlib.rc_context({"svg.hashsalt": "airspring-uq", "svg.fonttype": "path"}):
        if figure_format == "svg":
            fig.savefig(buf, format="svg", metadata={"Date": None})
        else:
            fig.savefig(
                buf,
                format=check_format(figure_format),
                dpi=DPI,
                pil_kwargs={"compress_level": PNG_COMPRESSION},
            )
    pyplot().close(fig)
    return buf.getvalue()


#: A unit as the figures write it in their labels -> (quantity, its factor to the unit inside).
_LABEL_UNITS = {
    "mm": ("height", 1e-3),
    "kN": ("force", 1e3),
    "N": ("force", 1.0),
    "cm²": ("area", 1e-4),
    "dm³ = litre": ("volume", 1e-3),
}
_LABEL = re.compile(r"^(?P<what>.*)\((?P<unit>mm|kN|N|cm²|dm³ = litre)\)\s*$")


def input_unit_axes(fig, units) -> None:
    """For each axis of ``fig`` whose label ends in a unit (``height x (mm)``, ``force P (kN)``)
    that ``units`` writes otherwise, a second axis (top or right) in ``units``' unit, labelled so
    (``height x (in)``): the figure keeps its scale and shows the recordings' own units too."""
    for ax in fig.axes:
        if ax.get_label() == "<colorbar>":
            continue
        for which in ("x", "y"):
            label = ax.get_xlabel() if which == "x" else ax.get_ylabel()
            m = _LABEL.match(label)
            if not m:
                continue
            quantity, to_si = _LABEL_UNITS[m.group("unit")]
            scale = to_si / units.factor(quantity)
            if abs(scale - 1.0) < 1e-12:
                continue  # the figure already shows this unit
            functions = (lambda v, s=scale: v * s, lambda v, s=scale: v / s)
            if which == "x":
                sec = ax.secondary_xaxis("top", functions=functions)
                sec.set_xlabel(f"{m.group('what')}({units.shown(quantity)})", fontsize=7)
            else:
                sec = ax.secondary_yaxis("right", functions=functions)
                sec.set_ylabel(f"{m.group('what')}({units.shown(quantity)})", fontsize=7)
            sec.tick_params(labelsize=7)


#: what a page or figure drawn from a posterior whose convergence rules failed says it is
NOT_CONVERGED = "NOT CONVERGED"


def stamp_unconverged(fig, what: str) -> None:
    """Mark ``fig`` as drawn from a posterior whose convergence rules failed (``what``: which fit,
    e.g. "the 6 bar test"): NOT CONVERGED across it and, under it, which fit and why it is not a
    result, so that the figure cannot pass for a result, also when copied without its page (issue
    29). Both are translucent, over the axes, clear of the labels."""
    common = dict(ha="center", va="center", rotation=20, color="#c00000", zorder=1000)
    width_in = float(fig.get_size_inches()[0])  # the stamp fits the figure: 44 pt on 7.2 in
    big = min(44.0, 6.0 * width_in)
    fig.text(0.5, 0.55, NOT_CONVERGED, fontsize=big, fontweight="bold", alpha=0.25, **common)
    fig.text(
        0.5,
        0.41,
        f"{what}:\nthe sampler's convergence rules failed; not a result",
        fontsize=min(9.0, 1.6 * width_in),
        alpha=0.6,
        **common,
    )


@dataclass(frozen=True)
class Figure:
    """A figure to embed (base64, so that the page stands alone) under its file name (whose
    extension, ``.png`` or ``.svg``, says its format), with its alt text."""

    name: str
    data: bytes
    alt: str

    @property
    def mime(self) -> str:
        return _MIME[self.name.rsplit(".", 1)[-1]]

    @property
    def base64(self) -> str:
        return base64.b64encode(self.data).decode()


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


def _fmt(value, spec: str) -> str:
    """``format(value, spec)``; a quantity the JSON leaves undefined (None, e.g. a Pareto k ArviZ
    could not estimate) prints as "undefined"."""
    return "undefined" if value is None else format(value, spec)


@functools.cache
def _environment():
    env = Environment(
        loader=PackageLoader("uq", "_report/templates"),
        autoescape=True,
        undefined=StrictUndefined,
        finalize=_escape,
        trim_blocks=True,
        lstrip_blocks=True,
        keep_trailing_newline=True,
    )
    env.filters["fmt"] = _fmt  # {{ x|fmt(".1f") }} is f"{x:.1f}"
    env.filters["sig4"] = sig4
    return env


def render(template: str, **context) -> str:
    """The page ``templates/<template>`` rendered with ``context`` (autoescaped; missing names fail)."""
    return _environment().get_template(template).render(**context)
