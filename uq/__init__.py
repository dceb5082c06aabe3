"""airspring-uq: Bayesian uncertainty quantification of air-spring test-stand recordings.

Python API
----------
Every ``uq`` command is a function here, and no step needs a file in between::

    import uq
    rec = uq.simulate("n50", seed=1)          # Recordings, as `uq simulate` + reading the CSV
    # rec = uq.read_recordings("recordings.csv")            the same, from a file
    fit = uq.fit_campaign(rec, seed=1)        # per-pressure Bayesian cubics       (uq fit)
    uq.write_report(fit, "out/")              # out/report.html and its figures     (uq report)
    bands = uq.campaign_bands(fit)            # Figures 2-5 with 90 % credible bands
    verdict = uq.check(fit.to_json(), points)  # posterior vs stored estimates       (uq check)
    surface = uq.fit_surface(rec, seed=1)     # one model over height and pressure  (uq surface)
    answer = uq.margin(surface, 0.112, 20e3)  # pressure that carries 20 kN at 112 mm (uq margin)
    answer = uq.margin(fit, 0.112, 20e3)      # ... from any fitted model: here the cubics
    surface.save("surface.nc")                # one saved format; uq.load_model("surface.nc")
    found = uq.diagnose(rec, seed=1)          # the physics the traditional theory misses (uq diagnose)

Every fitted model (the cubics, the surface, the thermodynamic model, one loaded from a file or
plugged in from outside) is a ``uq.FittedModel``: draws of the mean force and the volume-derived
area on a fixed set of posterior draws, its tested ranges, named coefficient blocks, ``to_json``
and ``save``; margins and the sealed spring take any of them. The models ``--model`` takes are
the registry's (``uq.model_names()``; ``uq.register_model(uq.ModelEntry(...))`` adds one).

The library is layered, each layer a subpackage of private modules, bottom to top: ``_io``
(atomic writes, JSON, errors), ``_physics`` (units, basis scale, the noise formula, the
mechanisms), ``_data`` (recordings, the paper's tables, stand descriptions), ``_stand`` (the
virtual test stand), ``_inference`` (exact linear-Gaussian draws, the emcee edge, convergence),
``_models`` (the fitted-model protocol and registry; cubic, surface, thermodynamic and diagnose
models), ``_diagnose`` (the discrepancy engine),
``_derived`` (bands, margins, checks, result documents), ``_report`` (HTML pages and figures),
``_drivers`` (batch, calibration) and ``_cli`` (one module per command). A module imports
only from its own layer or below (tests/test_layers.py). The names below are the public API.

Float64. uq's models need JAX in double precision (the cubics' coefficients span ten orders of
magnitude in one solve), and JAX's switch for it, ``jax_enable_x64``, holds for the whole
process: the first use of a model (any name below that loads JAX: ``fit_campaign``,
``fit_surface``, ``diagnose``, ...) calls :func:`enable_x64`, after which all JAX code in the
process computes in float64 by default. ``import uq`` itself loads no JAX, NumPy, ArviZ or
matplotlib: the names below are loaded on first use (PEP 562). Call ``uq.enable_x64()`` to make
the switch explicit, or to restore it after other code turned it off.

The examples below use small settings (few pressures, short chains); drop ``layout=``,
``settings=`` and ``max_draws=`` for the paper's procedure and converged chains.

>>> import uq
>>> small = uq.Layout(pressures_bar=(1.0, 4.0, 8.0), step_m=0.01)
>>> rec = uq.simulate("n50", seed=3, layout=small)
>>> quick = uq.Settings(max_steps=200)

Surface model and a margin query (``orders`` kept small for three tests):

>>> surface = uq.fit_surface(rec, uq.Orders(3, 2, 2, 1, 1), seed=3, settings=quick, max_draws=400)
>>> answer = uq.margin(surface, height_m=0.112, load_N=15e3, prob=0.95)
>>> 4.0 < answer["pressure_bar_for_prob"] < 8.0, answer["model"]["name"]
(True, 'surface')
>>> draws = surface.force_draws(0.112, 5.0)   # posterior draws of the force, N (FittedModel)
>>> draws.ndim, bool(10e3 < draws.mean() < 16e3)
(1, True)

Mechanism search against the traditional theory (``sample_final=False``: screening only):

>>> found = uq.diagnose(rec, seed=3, settings=quick, sample_final=False)
>>> found["mismatch_detected"]
True

Compiling the surface model and the mechanism search takes about a minute each on a laptop
(the first call only); tests/test_api.py runs these examples under ``-m slow``.
"""

from __future__ import annotations

import importlib

from uq._io.version import __version__

#: public name -> module that defines it, or (module, name there)
_API = {
    "CampaignFit": "_models.cubic_results",
    "PressureFit": "_models.cubic_results",
    "fit_campaign": "_models.cubic_fit",
    "fit_campaigns": "_models.cubic_fit",
    "fit_test": "_models.cubic_fit",
    "least_squares": "_models.cubic",
    "InputError": "_io.errors",
    "MECHANISMS": "_physics.mechanisms",
    "Recordings": "_data.recordings",
    "PressureTest": "_data.recordings",
    "read_recordings": "_data.recordings",
    "table1": "_data.reference",
    "table2": "_data.reference",
    "compare_models": ("_derived.comparison", "compare"),
    "CollapsedModel": "_inference.collapsed",
    "Posterior": "_inference.collapsed",
    "fit_collapsed": "_inference.collapsed",
    "Convergence": "_inference.convergence",
    "Diagnosis": "_diagnose.engine",
    "Settings": "_inference.sampler",
    "Layout": "_stand.simulator",
    "simulate": ("_stand.simulator", "simulate_recordings"),
    "true_curves": "_stand.simulator",
    "enable_x64": "_inference.float64",
    "write_report": "_report.campaign",
    "campaign_bands": "_derived.bands",
    "CampaignBands": "_derived.bands",
    "fit_surface": "_models.surface_likelihood",
    "fit_thermo": "_models.thermo_likelihood",
    "ThermoFit": "_models.thermo",
    "ThermoOrders": "_models.thermo",
    "SurfaceFit": "_models.surface",
    "Orders": "_models.surface",
    "FittedModel": "_models.fitted",
    "Block": "_models.fitted",
    "LinearFit": "_models.linear_fit",
    "CubicInterpolation": "_models.cubic_interpolation",
    "ModelEntry": "_models.registry",
    "register_model": ("_models.registry", "register"),
    "model_names": ("_models.registry", "names"),
    "load_model": ("_models.saved", "load"),
    "margin": "_derived.margin",
    "diagnose": "_diagnose.engine",
    "check": ("_derived.check", "check_documents"),
    "StandDescription": "_data.stand_description",
    "PAPER_STAND": "_data.stand_description",
    "read_stand": "_data.stand_description",
    "SealedDesign": "_derived.design",
    "design_document": "_derived.design",
    "design_margin": "_derived.design",
    "simulate_sealed": "_stand.sealed_test",
}

__all__ = sorted(_API) + ["__version__"]


def __getattr__(name: str):
    if name not in _API:
        raise AttributeError(f"module 'uq' has no attribute '{name}'")
    module, attr = _API[name] if isinstance(_API[name], tuple) else (_API[name], name)
    value = getattr(importlib.import_module(f"uq.{module}"), attr)
    globals()[name] = value  # later look-ups skip this function
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_API))
