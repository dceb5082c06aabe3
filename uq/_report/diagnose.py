"""``uq diagnose --report DIR``: the discrepancy diagnosis as an HTML section (``diagnose.html``)
and its residual plots (``diagnose_residuals.png``), from a :func:`uq._diagnose.engine.diagnose`
result. The page is the template ``templates/diagnose.html``; every write is atomic.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from uq._diagnose.engine import _residuals, summary_text
from uq._io.files import write_figure_atomic, write_text_atomic
from uq._report.html import _plt, render

FIGURE = "diagnose_residuals.png"


def _residual_figure(res, path: Path) -> None:
    """Force and volume residuals of the traditional and the final model, by height, written to ``path``."""
    plt = _plt()
    base, final, meta, d = res.baseline, res.final, res.meta, res.data
    fig, axes = plt.subplots(2, 2, figsize=(11, 7), sharex=True)
    cmap = plt.get_cmap("viridis")
    pmax = meta["pressure_bar"].max()
    for col, (fit, title) in enumerate(
        ((base, "traditional"), (final, " + ".join(["traditional", *final.names])))
    ):
        r = _residuals(fit, meta, d)
        for row, (q, scale, unit) in enumerate((("force", 1.0, "N"), ("volume", 1e6, "cm^3"))):
            ax = axes[row, col]
            for pb in np.unique(meta["pressure_bar"]):
                for comp, mk in ((True, "v"), (False, "^")):
                    s = (meta["pressure_bar"] == pb) & (meta["compression"] == comp)
                    ax.plot(
                        meta["height_m"][s] * 1e3,
                        r[q][0][s] * scale,
                        mk,
                        ms=3,
                        color=cmap(pb / pmax),
                        label=f"{pb:g} bar" if comp else None,
                    )
            ax.axhline(0, color="k", lw=0.6)
            ax.set_title(f"{q} residual, {title}", fontsize=9)
            ax.set_ylabel(unit)
            if row == 1:
                ax.set_xlabel("height x, mm")
    axes[0, 0].legend(fontsize=6, ncol=2)
    fig.tight_layout()
    write_figure_atomic(fig, path)
    plt.close(fig)


def write_diagnose_report(res, out_dir) -> Path:
    """``out_dir/diagnose.html`` and ``out_dir/diagnose_residuals.png`` for the diagnosis ``res``
    (a :class:`uq._diagnose.engine.Diagnosis`); returns the page's path."""
    out = Path(out_dir)
    _residual_figure(res, out / FIGURE)
    page = render(
        "diagnose.html",
        summary=summary_text(res.document),
        mechanisms=res["mechanisms"],
        baseline=res["baseline"],
        final=res["final"],
        rule=res["selection"]["rule"],
        figure=FIGURE,
    )
    return write_text_atomic(out / "diagnose.html", page)
