"""airspring-uq: Bayesian uncertainty quantification of air-spring test-stand recordings.

The flow, module by module: recordings (``_recordings``) -> virtual stand (``_stand``) ->
models and posteriors (``_cubic``, ``_linear``, ``_sampler``) -> results (``_results``) ->
derived quantities, reports, checks and queries (``_bands``, ``_report``, ``_check``,
``_surface``, ``_margin``, ``_diagnose``). The public API is re-exported here.
"""

from . import _jax  # noqa: F401  (float64 before anything traces)
from ._cubic import CampaignFit as CampaignFit
from ._cubic import TestFit as TestFit
from ._cubic import fit_campaign as fit_campaign
from ._cubic import fit_test as fit_test
from ._cubic import least_squares as least_squares
from ._errors import InputError as InputError
from ._mechanisms import MECHANISMS as MECHANISMS
from ._recordings import Recordings as Recordings
from ._recordings import Test as Test
from ._recordings import read_recordings as read_recordings
from ._reference import table1 as table1
from ._reference import table2 as table2
from ._results import fit_json as fit_json
from ._sampler import Settings as Settings
from ._stand import Layout as Layout
from ._stand import simulate as simulate
from ._stand import true_curves as true_curves

__version__ = "0.1.0"
