"""Shared fixtures. x64 is switched on by importing uq (uq/_inference/float64.py)."""

from __future__ import annotations

import signal
from pathlib import Path

import pytest

import uq._inference.float64  # noqa: F401  (float64 before anything traces)

ROOT = Path(__file__).resolve().parents[1]
N50_CSV = ROOT / "data" / "n50" / "recordings.csv"


@pytest.fixture(scope="session")
def n50_recordings():
    from uq._data.recordings import read_recordings

    return read_recordings(N50_CSV)


@pytest.fixture(scope="session")
def n50_fit(n50_recordings):
    """The bundled campaign fitted once with the default settings and seed (about 35 s)."""
    from uq._cli.common import DEFAULT_SEED
    from uq._models.cubic_fit import fit_campaign

    return fit_campaign(n50_recordings, seed=DEFAULT_SEED)


@pytest.fixture(scope="session")
def n50_surface(n50_recordings):
    """The surface model fitted once to the bundled campaign (the default orders and settings)."""
    from uq._models.surface_likelihood import fit_surface

    return fit_surface(n50_recordings, seed=20201)


#: the small campaign the report's figure and page tests share: four pressures, 10 mm steps
SMALL_LAYOUT_PRESSURES_BAR = (1.0, 3.0, 5.0, 8.0)


@pytest.fixture(scope="session")
def small_campaign():
    """Four pressures of data/n50's spring every 10 mm (seed 4): the report's figures and pages."""
    import uq

    return uq.simulate(
        "n50", seed=4, layout=uq.Layout(pressures_bar=SMALL_LAYOUT_PRESSURES_BAR, step_m=0.01)
    )


@pytest.fixture(scope="session")
def small_cubics(small_campaign):
    """The small campaign's per-pressure cubics on a short run (200 steps: the pages and figures
    need draws of the right shape, not converged ones), fitted once for every module."""
    import uq

    return uq.fit_campaign(small_campaign, seed=4, settings=uq.Settings(max_steps=200))


@pytest.fixture(autouse=True)
def _sigint_handler_kept():
    """No test leaves the process's Ctrl-C handler changed: a later test's subprocesses would
    inherit an ignored SIGINT (tests/cli/test_edges.py checks what a child does with it)."""
    before = signal.getsignal(signal.SIGINT)
    yield
    after = signal.getsignal(signal.SIGINT)
    signal.signal(signal.SIGINT, before)
    assert after is before, f"the test left SIGINT's handler changed: {before!r} -> {after!r}"
