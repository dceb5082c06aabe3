"""The models a campaign can be fitted with, by name: what ``--model`` takes and what loads a file.

Every command that fits or loads a model asks the registry, never a name of its own: the
``--model`` choices of ``uq surface``, ``uq margin`` and ``uq design``, the models the comparison
can fit, the default of each command, and the class that loads a saved file (``uq._models.saved.
load``). A :class:`ModelEntry` names its parts as ``"module:attribute"`` strings, imported only when
used, so that the command line's options are built without NumPy or JAX.

A model is plugged in from outside ``uq`` (docs/development.md) by registering its entry:

* in code: ``uq.register_model(ModelEntry(...))`` (the tests do this with a model defined in a
  test file);
* by a package: an entry point in the group ``uq.models`` (``ENTRY_POINT_GROUP``) whose object is
  a :class:`ModelEntry` (or a callable returning one), e.g. in its ``pyproject.toml``::

      [project.entry-points."uq.models"]
      rolling_lobe = "my_package.uq_model:ENTRY"

  The registry loads the group on first use; keep that module's imports light (the entry's
  ``fit`` and ``model`` are strings, imported when a campaign is fitted or a file loaded).

The fitted model itself is any :class:`uq._models.fitted.FittedModel` whose ``name`` is the
entry's; its class gives ``from_saved(attrs, groups)`` for the saved format. Report pages dispatch
on that class (``uq._report.pages``): a model without a page of its own gets the generic one.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from importlib import metadata

from uq._io.errors import InputError
from uq._io.values import resolve

#: the entry-point group of models plugged in by other packages
ENTRY_POINT_GROUP = "uq.models"

CUBICS = "cubics"
SURFACE = "surface"
THERMODYNAMIC = "thermodynamic"
DISCREPANCY = "discrepancy"

#: the model over all tests that ``uq margin`` (compared with the cubics), ``uq design``,
#: ``uq report --surface``, ``uq export`` and ``uq plan`` fit when ``--model`` is not given: the
#: surface with a discrepancy in pressure (issue 29), the one whose bands between tested pressures
#: widen by what the data say the smooth surface misses (docs/discrepancy.md)
DEFAULT_MODEL = DISCREPANCY
#: commands whose default is not ``DEFAULT_MODEL`` (``uq surface`` fits the surface model)
_DEFAULTS = {"surface": SURFACE}


@dataclass(frozen=True)
class ModelEntry:
    """One model, by name (``--model NAME``).

    fit            ``"module:function"`` (or the function): ``fit(recordings, *, seed, settings,
                   stand) -> FittedModel``
    model          ``"module:Class"`` (or the class) of the fitted model: its ``from_saved(attrs,
                   groups)`` loads the saved format
    words          one line for ``--help``: what the model is
    n_sampled      how many parameters the sampler moves (emcee needs two walkers per parameter)
    needs_volume   the model fits the volume readings: a force-only campaign is refused
    over_all_tests one model over all tests, compared with the per-pressure cubics by PSIS-LOO
                   (``uq surface --model`` takes it); False for the cubics themselves
    select_orders  ``"module:function"`` ranking candidate orders by PSIS-LOO (``uq surface
                   --select``), or None
    """

    name: str
    fit: str | Callable
    model: str | type
    words: str
    n_sampled: int
    needs_volume: bool = False
    over_all_tests: bool = True
    select_orders: str | Callable | None = None

    def fit_function(self) -> Callable:
        return resolve(self.fit)

    def model_class(self) -> type:
        return resolve(self.model)

    def order_selection(self) -> Callable | None:
        return None if self.select_orders is None else resolve(self.select_orders)


_ENTRIES: dict[str, ModelEntry] = {}
_PLUGINS_LOADED = False


def register(entry: ModelEntry, *, replace: bool = False) -> ModelEntry:
    """Make ``entry`` known by its name (``replace``: over an entry of the same name)."""
    if not isinstance(entry, ModelEntry):
        raise TypeError(f"register: expected a ModelEntry, got {type(entry).__name__}")
    if entry.name in _ENTRIES and not replace:
        raise ValueError(f"a model named '{entry.name}' is registered already")
    _ENTRIES[entry.name] = entry
    return entry


def unregister(name: str) -> None:
    """Forget the model ``name`` (a test's model, after the test)."""
    _ENTRIES.pop(name, None)


def _load_plugins() -> None:
    """The entries of the ``uq.models`` entry-point group, once."""
    global _PLUGINS_LOADED
    if _PLUGINS_LOADED:
        return
    _PLUGINS_LOADED = True
    for ep in metadata.entry_points(group=ENTRY_POINT_GROUP):
        obj = ep.load()
        entry = obj if isinstance(obj, ModelEntry) else obj()
        if entry.name not in _ENTRIES:
            register(entry)


def entries() -> list[ModelEntry]:
    """Every registered model, uq's first, in registration order."""
    _load_plugins()
    return list(_ENTRIES.values())


def names(*, over_all_tests: bool | None = None) -> tuple[str, ...]:
    """The registered names (``over_all_tests``: only those models, or only the others)."""
    return tuple(
        e.name for e in entries() if over_all_tests is None or e.over_all_tests == over_all_tests
    )


def entry(name: str) -> ModelEntry:
    """The entry of ``name``; an unknown name is an InputError listing the known ones."""
    _load_plugins()
    if name not in _ENTRIES:
        raise InputError(
            f"model: unknown model '{name}'; the registered models are {', '.join(_ENTRIES)}",
            param="model",
        )
    return _ENTRIES[name]


def default(command: str) -> str:
    """The model ``command`` fits when none is named (``DEFAULT_MODEL`` but for ``uq surface``)."""
    return _DEFAULTS.get(command, DEFAULT_MODEL)


def fit(name: str, recordings, **options):
    """Fit the model ``name`` to ``recordings`` (``seed``, ``settings``, ``stand``)."""
    return entry(name).fit_function()(recordings, **options)


def help_words(over_all_tests: bool | None = None) -> str:
    """The models in words for ``--help``: "name: words; ...", in registration order."""
    return "; ".join(
        f"{e.name}: {e.words}"
        for e in entries()
        if over_all_tests is None or e.over_all_tests == over_all_tests
    )


register(
    ModelEntry(
        CUBICS,
        fit="uq._models.cubic_fit:fit_campaign",
        model="uq._models.cubic_interpolation:CubicInterpolation",
        words="an independent Bayesian cubic per tested pressure (eqs. 8, 9), F_eff = P/p_u "
        "interpolated linearly in pressure between the tests",
        n_sampled=3,
        over_all_tests=False,
    )
)
register(
    ModelEntry(
        SURFACE,
        fit="uq._models.surface_likelihood:fit_surface",
        model="uq._models.surface:SurfaceFit",
        words="force and volume surfaces smooth in pressure (no link between them)",
        n_sampled=5,
        select_orders="uq._models.surface_likelihood:select_orders",
    )
)
register(
    ModelEntry(
        THERMODYNAMIC,
        fit="uq._models.thermo_likelihood:fit_thermo",
        model="uq._models.thermo:ThermoFit",
        words="force and volume from one potential G(x, p_u) (the Maxwell relation holds; its "
        "own dV/dp_u)",
        n_sampled=6,
        needs_volume=True,
        select_orders="uq._models.thermo_likelihood:select_orders",
    )
)
register(
    ModelEntry(
        DISCREPANCY,
        fit="uq._models.discrepancy:fit_discrepancy",
        model="uq._models.discrepancy_fit:DiscrepancyFit",
        words="the surface plus, per tested pressure, a deviation drawn from a Gaussian process in "
        "p_u: between tested pressures the band widens by what the data say the surface misses",
        n_sampled=8,
    )
)
