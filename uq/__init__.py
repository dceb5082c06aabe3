"""airspring-uq: Bayesian uncertainty quantification of air-spring test-stand recordings.

The flow, module by module: recordings (``_recordings``) -> virtual stand (``_stand``) ->
models and posteriors (``_cubic``, ``_linear``, ``_sampler``) -> results (``_results``) ->
derived quantities, reports, checks and queries (``_bands``, ``_report``, ``_check``,
``_surface``, ``_margin``, ``_diagnose``). The public API is re-exported here.

The re-exports are loaded on first use (PEP 562), so ``import uq`` and the ``uq`` command's
``--help`` do not import JAX, ArviZ or matplotlib; every module that uses JAX imports
``uq._jax`` first, which switches on float64 before anything traces.
"""

from __future__ import annotations

import importlib

__version__ = "0.1.0"

#: public name -> module that defines it
_API = {
    "CampaignFit": "_cubic", "TestFit": "_cubic", "fit_campaign": "_cubic", "fit_test": "_cubic",
    "least_squares": "_cubic", "InputError": "_errors", "MECHANISMS": "_mechanisms",
    "Recordings": "_recordings", "Test": "_recordings", "read_recordings": "_recordings",
    "table1": "_reference", "table2": "_reference", "fit_json": "_results", "Settings": "_sampler",
    "Layout": "_stand", "simulate": "_stand", "true_curves": "_stand",
}

__all__ = sorted(_API) + ["__version__"]


def __getattr__(name: str):
    if name not in _API:
        raise AttributeError(f"module 'uq' has no attribute '{name}'")
    value = getattr(importlib.import_module(f"uq.{_API[name]}"), name)
    globals()[name] = value  # later look-ups skip this function
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_API))
