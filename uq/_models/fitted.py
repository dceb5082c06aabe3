"""What every fitted model of a campaign offers downstream: the :class:`FittedModel` protocol.

Margins, design, the model comparison, saved answers, exports, plans, report pages and the command
line take a fitted model through this protocol and nothing else (optimistix's
``AbstractMinimiser`` style: any object that implements it works; no caller asks for a model by
its name). The per-pressure cubics (their interpolation between tested pressures included), the
pressure-coupled surface, the force surface, the thermodynamic potential and the surface with a
discrepancy in pressure all implement it; a model defined outside ``uq`` does too, and is made
known to the command line by the registry (``uq._models.registry``).

Conventions (every method):

* heights in m, pressures in bar (gauge), forces in N, areas in m^2, volumes in m^3;
* ``height_m`` and ``p_bar`` broadcast against each other; a ``*_draws`` method returns
  ``(S, *broadcast shape)`` on the model's **fixed** set of S posterior draws (the same draws on
  every call, so quantities computed by different calls pair draw by draw);
* ``check=True`` (the default) refuses heights and pressures outside what the recordings support
  with a one-line :class:`uq._io.errors.InputError` naming ``param``; ``check=False`` extrapolates
  (``uq export --extrapolate``), and the caller says so;
* a quantity the model does not have (the volume of a force-only fit, the model's own dV/dp_u)
  raises :class:`uq._io.errors.InputError` with the one-line reason (``omitted_reason``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Protocol, runtime_checkable

import numpy as np

from uq._io.errors import InputError


@dataclass(frozen=True)
class Block:
    """A named block of coefficient draws in physical units.

    ``names`` (k,) the coefficients' names (e.g. ``("c_00", "c_01", ...)``), ``draws`` (S, k) on the
    model's fixed draws, ``unit`` the unit of every coefficient (``"m^2"``, ``"N"``, ...) and
    ``basis`` one line saying what the coefficients multiply."""

    names: tuple[str, ...]
    draws: np.ndarray
    unit: str
    basis: str = ""


@runtime_checkable
class FittedModel(Protocol):
    """A fitted model of one campaign, evaluated on a fixed set of posterior draws.

    Attributes
    ----------
    name: the registry name (``uq._models.registry``), e.g. the word ``uq margin --model`` takes.
    label: the model in words for every output, with its orders,
        e.g. ``"surface model (F_p 3x5, casing 3, D 2x3)"``.
    recordings: the :class:`uq._data.recordings.Recordings` it was fitted to, or None for a model
        loaded from a saved file (``provenance`` then says where it came from).
    provenance: ``{"recordings_path", "recordings_sha256", "seed", "uq_version", ...}``.
    height_range_m, pressure_range_bar: ``(lo, hi)``, what the recordings support.
    tested_pressures_bar: (T,) the set pressures of the tests, ascending.
    has_volume: the model has the volume-derived area dV/dx (a force-only fit has not).
    has_dvdp: the model has its own dV/dp_u at fixed height (``volume_pressure_draws``).
    n_draws: S, the number of draws every ``*_draws`` method returns.
    convergence: the sampler's :class:`uq._inference.convergence.Convergence` (None when the
        draws are exact and independent).
    idata: the ArviZ ``InferenceData`` of the fit (None for a loaded model without one).
    omitted_reason: one line saying why the volume results are left out (None when it has them).
    """

    name: str
    label: str
    recordings: Any
    provenance: dict
    height_range_m: tuple[float, float]
    pressure_range_bar: tuple[float, float]
    tested_pressures_bar: np.ndarray
    has_volume: bool
    has_dvdp: bool
    n_draws: int
    convergence: Any
    idata: Any
    omitted_reason: str | None

    def check_range(self, height_m, p_bar, param: str | None = None) -> None:
        """Refuse heights or pressures outside the tested ranges (one line naming ``param``)."""

    def force_draws(self, height_m, p_bar, *, check: bool = True) -> np.ndarray:
        """The element's mean force P(x, p_u) (reading noise excluded), N, (S, *shape)."""

    def feff_draws(self, height_m, p_bar, *, check: bool = True) -> np.ndarray:
        """The paper's effective area F_eff = P / p_u (eq. 1), m^2, (S, *shape)."""

    def volume_area_draws(self, height_m, p_bar, *, check: bool = True) -> np.ndarray:
        """The volume-derived area dV/dx = -S dL/dx (eq. 1's second formula), m^2, (S, *shape)."""

    def volume_pressure_draws(self, height_m, p_bar, *, check: bool = True) -> np.ndarray:
        """dV/dp_u at fixed height, m^3/Pa, (S, *shape), only where ``has_dvdp``."""

    def on_draws(self, n: int) -> FittedModel:
        """The same model on at most ``n`` of its draws, thinned evenly (deterministic)."""

    def blocks(self) -> dict[str, Block]:
        """The named coefficient blocks on the fixed draws (no positional slicing downstream)."""

    def to_json(self, comparison: dict | None = None, advice: str | None = None) -> dict:
        """The model's JSON document (``uq surface --json`` for models over all tests)."""

    def save(self, path, **provenance) -> Any:
        """Write the model atomically to ``path`` in the one saved format (NetCDF: named blocks,
        constant data, ``uq_file_kind``, ``uq_format_version``, provenance); ``uq._models.saved.
        load(path)`` (``uq.load_model``) reads it back without a refit."""


# ----------------------------------------------------------------------------- shared by the fits


def refuse_extrapolation(
    height_m, p_bar, height_range_m, pressure_range_bar, param: str | None, model: str
) -> None:
    """InputError naming the first height or overpressure outside the tested ranges: models of the
    stand's recordings answer only where it measured. ``param``: the caller's parameter the value
    came from (the message starts with it), or None."""
    for values, (lo, hi), scale, unit, name, tested in (
        (height_m, height_range_m, 1e3, "mm", "height", "heights"),
        (p_bar, pressure_range_bar, 1.0, "bar", "overpressure", "pressures"),
    ):
        v = np.atleast_1d(np.asarray(values, float))
        out = (v < lo - 1e-9) | (v > hi + 1e-9)
        if np.any(out):
            raise InputError(
                f"{param + ': ' if param else ''}{name} {v[out][0] * scale:g} {unit} is outside the "
                f"tested {tested} {lo * scale:g}..{hi * scale:g} {unit}; {model} does not extrapolate",
                param=param,
            )


@dataclass(frozen=True)
class Verdict:
    """The sampler's verdict a saved model keeps (its ``convergence``): whether every rule passed
    and the warnings the fit printed, in the words of the command that saved it."""

    converged: bool
    warnings: tuple[str, ...] = ()

    def messages(self, advice: str | None = None) -> list[str]:
        return list(self.warnings)
