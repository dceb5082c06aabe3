"""Render an HTML file in a headless browser and check that the screenshot is a real page.

Debian's chromium (``/usr/bin/chromium``; ``scripts/test.sh`` installs it when missing). Without
it, :func:`require_browser` fails the test when the environment variable ``CI`` is set (a CI
machine must check the pages) and skips it otherwise, saying why.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import pytest

WINDOW = (1280, 2000)  # width, height in pixels


def browser() -> str | None:
    """The chromium executable, or None."""
    return shutil.which("chromium") or shutil.which("chromium-browser")


def require_browser() -> str:
    found = browser()
    if found is None:
        why = "chromium is not installed (scripts/test.sh installs it with apt-get, as root)"
        if os.environ.get("CI"):
            pytest.fail(f"{why}; CI must check the pages in a browser")
        pytest.skip(why)
    return found


def screenshot(html: Path, png: Path, window: tuple[int, int] = WINDOW) -> Path:
    """Render ``html`` (a local file) headless into ``png``, ``window`` pixels (width, height)."""
    exe = require_browser()
    with tempfile.TemporaryDirectory(prefix="uq-browser-") as profile:
        argv = [
            exe,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--hide-scrollbars",
            f"--user-data-dir={profile}",
            f"--screenshot={png}",
            f"--window-size={window[0]},{window[1]}",
            Path(html).resolve().as_uri(),
        ]
        proc = subprocess.run(argv, capture_output=True, text=True, timeout=180)
    assert proc.returncode == 0 and Path(png).exists(), f"chromium failed: {proc.stderr[-800:]}"
    return Path(png)


MARGIN_PX = 10  # the right edge of the window that a page in the style sheet leaves blank


def page_stats(png: Path) -> dict:
    """What is on a screenshot: its size, the share of pixels that are not (near) white, the
    share that are coloured (figures, not only black text), and the rows with ink in the
    right-hand ``MARGIN_PX`` columns (text or tables running off the page)."""
    import matplotlib.image

    image = matplotlib.image.imread(png)[..., :3].astype(float)
    if image.max() > 1.0:
        image = image / 255.0
    inked = image.min(axis=2) < 0.9
    coloured = (image.max(axis=2) - image.min(axis=2)) > 0.25
    return {
        "size": (image.shape[1], image.shape[0]),
        "inked": float(inked.mean()),
        "coloured": float(coloured.mean()),
        "rows_inked": float(inked.any(axis=1).mean()),
        "rows_off_the_page": int(inked[:, -MARGIN_PX:].any(axis=1).sum()),
    }


def assert_real_page(png: Path, window: tuple[int, int] = WINDOW, figures: bool = True) -> dict:
    """The screenshot has the window's size, is not blank (ink on a good part of it, spread over
    the page), nothing runs off its right edge and, with ``figures``, it shows coloured figures."""
    stats = page_stats(png)
    assert stats["size"] == window, stats
    assert stats["inked"] > 0.04 and stats["rows_inked"] > 0.3, f"a blank page? {stats}"
    assert stats["rows_off_the_page"] == 0, f"text runs off the page? {stats}"
    if figures:
        assert stats["coloured"] > 0.0005, f"no figure drawn? {stats}"
    return stats
