"""Shared fixtures. x64 is switched on by importing uq (uq/_inference/float64.py)."""

from __future__ import annotations

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
