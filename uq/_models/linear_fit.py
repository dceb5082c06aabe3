"""The fitted models over all tests whose mean force and volume are linear in their coefficients.

A model over all tests of a campaign (the surface, the force surface, the thermodynamic potential,
a model plugged in from outside) predicts the mean force and the volume-derived area at any
(x, p_u) as fixed functions of (x, p_u) times its coefficients, given its sampled parameters theta:

    P(x, p_u) = sum_j beta_j f_j(x, p_u),        dV/dx(x, p_u) = sum_j beta_j a_j(x, p_u)

:class:`LinearFit` is everything such a fit offers downstream (the :class:`uq._models.fitted.
FittedModel` protocol) from four things its subclass gives:

* ``block_layout()``: the named coefficient blocks (:class:`BlockSpec`: names, the prior scale that
  turns the likelihood's standardised coefficients into physical units, the unit, the basis);
* ``force_columns(x, p)`` and ``area_columns(x, p)`` (optionally ``dvdp_columns``): the columns
  f_j and a_j at points, (n, k), multiplying the physical coefficients;
* ``orders`` and ``geometry``: small frozen dataclasses of numbers (:class:`Params`) that save and
  load themselves;
* the likelihood, a :class:`uq._inference.collapsed.CollapsedModel` in its own module (JAX lives
  there, never here: a fitted or loaded model evaluates in numpy), named by ``likelihood``.

The base gives the draws on a fixed set of posterior draws (``force_draws``, ``feff_draws``,
``volume_area_draws``, ``volume_pressure_draws``), ``on_draws``, ``blocks``, the JSON document's
common parts and the one saved format (``save``; :func:`uq._models.registry.load` reads it back).
"""

from __future__ import annotations

import dataclasses
import functools
import json
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from uq._inference.convergence import CLI_ADVICE
from uq._inference.summary import band, estimate, thin_rows
from uq._io.errors import InputError
from uq._io.values import resolve
from uq._models import saved
from uq._models.fitted import Block, Verdict, refuse_extrapolation
from uq._physics.quantities import BAR_PA

LEVEL = 0.90


@dataclass(frozen=True)
class Params:
    """A small frozen dataclass of numbers (a model's orders or geometry) that saves and loads
    itself: ``values()`` in field order, ``from_values`` back (ints stay ints)."""

    def values(self) -> tuple[tuple[str, ...], np.ndarray]:
        names = tuple(f.name for f in dataclasses.fields(self))
        return names, np.array([getattr(self, n) for n in names])

    @classmethod
    def from_values(cls, names, values) -> Params:
        kinds = {f.name: f.type for f in dataclasses.fields(cls)}
        cast = {"int": int, "float": float}
        return cls(**{n: cast[kinds[n]](v) for n, v in zip(names, values, strict=True)})


@dataclass(frozen=True)
class BlockSpec:
    """A named block of coefficients: ``names``, ``scale`` (physical value = standardised value x
    scale), ``unit`` and ``basis`` (what the coefficients multiply, one line)."""

    name: str
    names: tuple[str, ...]
    scale: float
    unit: str
    basis: str = ""


@dataclass(eq=False, frozen=True, repr=False)
class LinearFit:
    """A fitted (or loaded) model over all tests, linear in its coefficients (module docstring).

    ``coefficients`` (C, D, k): the coefficient draws in physical units, the blocks side by side;
    ``reported`` {name: (C, D)}: the sampled parameters as the likelihood reports them (noise);
    ``posterior``: the driver's :class:`uq._inference.collapsed.Posterior` (None when loaded);
    ``max_draws``: the fixed draws are the chains flattened and thinned evenly to at most this
    (:func:`uq._inference.summary.thin_rows`; None: all of them)."""

    orders: Params
    geometry: Params
    coefficients: np.ndarray
    reported: dict
    tested_pressures_bar: np.ndarray
    height_range_m: tuple[float, float]
    recordings: Any = None
    posterior: Any = None
    stand: Any = None
    convergence: Any = None
    provenance: dict = field(default_factory=dict)
    selection: tuple = ()
    max_draws: int | None = None
    #: a loaded model's JSON document as saved (``to_json`` of a loaded model returns it)
    document: dict | None = None

    #: the registry name (``uq._models.registry``); a subclass sets it
    name = "model"
    #: the model in messages ("the surface model")
    words = "the model"
    #: the module holding the likelihood (``MODEL``) and the fit, loaded only to fit or refit
    likelihood = ""

    # ---- what a subclass gives
    def block_layout(self) -> tuple[BlockSpec, ...]:
        raise NotImplementedError

    def force_columns(self, x_m, p_bar) -> np.ndarray:
        raise NotImplementedError

    def area_columns(self, x_m, p_bar) -> np.ndarray:
        raise NotImplementedError

    def dvdp_columns(self, x_m, p_bar) -> np.ndarray:
        raise NotImplementedError

    #: the types of ``orders`` and ``geometry`` (what a saved file's constant data load into)
    orders_type = Params
    geometry_type = Params

    @property
    def orders_label(self) -> str:
        """The orders in words (e.g. "F_p 3x5, casing 3, D 2x3")."""
        return self.orders.label

    @property
    def label(self) -> str:
        """The model in words with its orders, e.g. "surface model (F_p 3x5, casing 3, D 2x3)"."""
        return f"{self.words.removeprefix('the ')} ({self.orders_label})"

    @property
    def has_volume(self) -> bool:
        return True

    has_dvdp = False

    @property
    def dvdp_words(self) -> str:
        """What the model's own dV/dp_u is, for the design's statement (where ``has_dvdp``)."""
        return f"{self.label}'s own"

    @property
    def omitted_reason(self) -> str | None:
        return None if self.has_volume else f"{self.label}: no volume-derived area"

    # ---- construction
    @classmethod
    def from_posterior(
        cls, posterior, recordings, orders, geometry, stand, *, provenance=None
    ) -> LinearFit:
        """The fit of ``recordings`` from the driver's posterior (standardised coefficients
        ``posterior.beta`` times each block's scale)."""
        shell = cls.shell(orders, geometry, recordings.pressures_bar)
        scales = np.concatenate([np.full(len(b.names), b.scale) for b in shell.block_layout()])
        beta = np.asarray(posterior.beta) * scales
        return shell.fitted(beta, posterior, recordings, stand, provenance)

    @classmethod
    def shell(cls, orders, geometry, tested_pressures_bar) -> LinearFit:
        """A fit without draws: what its block layout and columns need."""
        tested = np.asarray(tested_pressures_bar, float)
        return cls(orders, geometry, np.zeros((1, 1, 0)), {}, tested, (0.0, 0.0))

    def fitted(self, coefficients, posterior, recordings, stand, provenance) -> LinearFit:
        """This shell with the driver's posterior of ``recordings``: ``coefficients`` (C, D, k)
        in physical units, the reported parameters, the verdict and the provenance."""
        return dataclasses.replace(
            self,
            coefficients=coefficients,
            reported={n: np.asarray(v) for n, v in posterior.reported.items()},
            height_range_m=tuple(float(v) for v in recordings.height_range_m),
            recordings=recordings,
            posterior=posterior,
            stand=stand,
            convergence=posterior.convergence,
            provenance=dict(provenance or {}),
        )

    # ---- the protocol
    @property
    def pressure_range_bar(self) -> tuple[float, float]:
        p = self.tested_pressures_bar
        return float(p.min()), float(p.max())

    @functools.cached_property
    def coef(self) -> np.ndarray:
        """The fixed draws of the coefficients, physical units, (S, k)."""
        c = self.coefficients
        return thin_rows(c.reshape(-1, c.shape[-1]), self.max_draws)

    @property
    def n_draws(self) -> int:
        return int(self.coef.shape[0])

    @property
    def n_coefficients(self) -> int:
        return int(self.coefficients.shape[-1])

    @property
    def idata(self):
        return None if self.posterior is None else self.posterior.idata

    @property
    def x0_m(self) -> float:
        return float(self.geometry.x0_m)

    def on_draws(self, n: int) -> LinearFit:
        """The same model on at most ``n`` of its draws, thinned evenly from all of them."""
        return dataclasses.replace(self, max_draws=min(int(n), self.max_draws or int(n)))

    def check_range(self, height_m, p_bar, param: str | None = None) -> None:
        """Refuse heights/pressures outside the tested ranges (no extrapolation)."""
        refuse_extrapolation(
            height_m, p_bar, self.height_range_m, self.pressure_range_bar, param, self.words
        )

    def evaluate(self, columns, height_m, p_bar, *, check: bool = True) -> np.ndarray:
        """``columns(x, p)`` (n, k) times the fixed coefficient draws: (S, *broadcast shape)."""
        h, p = np.broadcast_arrays(np.asarray(height_m, float), np.asarray(p_bar, float))
        if check:
            self.check_range(h, p)
        return (self.coef @ columns(h.ravel(), p.ravel()).T).reshape(-1, *h.shape)

    def force_draws(self, height_m, p_bar, *, check: bool = True) -> np.ndarray:
        """The mean force P(x, p_u) (reading noise excluded), N, (S, *shape)."""
        return self.evaluate(self.force_columns, height_m, p_bar, check=check)

    def feff_draws(self, height_m, p_bar, *, check: bool = True) -> np.ndarray:
        """The paper's effective area F_eff = P / p_u (eq. 1) of the mean force, m^2."""
        p = np.broadcast_to(
            np.asarray(p_bar, float), np.broadcast(np.asarray(height_m), np.asarray(p_bar)).shape
        )
        return self.force_draws(height_m, p_bar, check=check) / (p * BAR_PA)

    def volume_area_draws(self, height_m, p_bar, *, check: bool = True) -> np.ndarray:
        """The volume-derived area dV/dx = -S dL/dx (eq. 1's second formula), m^2."""
        if not self.has_volume:
            raise InputError(self.omitted_reason)
        return self.evaluate(self.area_columns, height_m, p_bar, check=check)

    def volume_pressure_draws(self, height_m, p_bar, *, check: bool = True) -> np.ndarray:
        """dV/dp_u at fixed height, m^3/Pa, where the model has its own (``has_dvdp``)."""
        if not self.has_dvdp:
            raise InputError(
                f"{self.label} has no dV/dp_u of its own (isobaric tests do not give it)"
            )
        return self.evaluate(self.dvdp_columns, height_m, p_bar, check=check)

    def blocks(self) -> dict[str, Block]:
        """The named coefficient blocks on the fixed draws, physical units."""
        out, start = {}, 0
        for b in self.block_layout():
            k = len(b.names)
            out[b.name] = Block(b.names, self.coef[:, start : start + k], b.unit, b.basis)
            start += k
        return out

    def band(self, draws_fn, height_m, p_bar, level: float = LEVEL) -> dict:
        """{"mean", "lower", "upper"}: a pointwise band of ``draws_fn(height_m, p_bar)``."""
        m, lo, hi = band(draws_fn(height_m, p_bar), axis=0, level=level)
        return {"mean": m, "lower": lo, "upper": hi}

    # ---- what the fit of a campaign has besides (None for a loaded model)
    def collapsed(self):
        """The likelihood (:class:`uq._inference.collapsed.CollapsedModel`) this fit's posterior
        is of: its module's ``collapsed_model(data)`` (imported now: JAX), for refits."""
        return resolve(f"{self.likelihood}:collapsed_model")(self.posterior.data)

    def predictive_force_draws(self, n_draws: int, seed: int = 0) -> list[np.ndarray] | None:
        """Posterior-predictive replicates of every force reading, one (S, n_t) array per test of
        ``recordings`` in its order (the likelihood's ``predict``: the mean force plus the
        reading noise of each draw; JAX is imported now), for the check of the model at the
        tested points (``uq._derived.model_check``); None for a loaded model (no readings, no
        noise draws) or a likelihood without replicates."""
        if self.posterior is None or self.recordings is None or self.posterior.data is None:
            return None
        model = self.collapsed()
        reps = resolve("uq._inference.collapsed:replicates")(model, self.posterior, n_draws, seed)
        if reps is None or "force_N" not in reps or model.observed is None:
            return None
        tests = self.recordings.tests
        observed = np.asarray(model.observed(self.posterior.data)["force_N"])
        readings = np.concatenate([t.force_N for t in tests])
        if observed.shape != readings.shape or not np.array_equal(observed, readings):
            return None  # not the recordings' readings in their order: no per-test split
        return np.split(reps["force_N"], np.cumsum([t.force_N.size for t in tests])[:-1], axis=1)

    @property
    def loglik_loo(self):
        return self.posterior.loglik_loo

    @property
    def seconds(self) -> float:
        return 0.0 if self.posterior is None else self.posterior.seconds

    def summary(self):
        """ArviZ-style table (pandas DataFrame) of the sampled parameters."""
        return self.posterior.summary()

    def __repr__(self) -> str:
        state = "converged" if self.convergence.converged else "NOT converged"
        where = (
            f"{len(self.tested_pressures_bar)} tests, {self.recordings.n_points} readings"
            if self.recordings is not None
            else f"{len(self.tested_pressures_bar)} tests, loaded"
        )
        return (
            f"{type(self).__name__}({self.label}; {where}, {self.n_coefficients} coefficients, "
            f"{self.n_draws} draws, {state})"
        )

    # ---- the JSON document
    def coefficient_summary(self) -> dict:
        """{block: {coefficient: estimate}} over every draw."""
        return {
            name: {n: estimate(b.draws[:, i]) for i, n in enumerate(b.names)}
            for name, b in dataclasses.replace(self, max_draws=None).blocks().items()
        }

    def noise_summary(self, names) -> dict:
        """The estimates of the sampled parameters ``names`` with their R-hat and bulk ESS."""
        diag = getattr(self.convergence, "variables", {})
        out = {}
        for n in names:
            est = estimate(self.reported[n])
            est |= {k: diag[n][k] for k in ("r_hat", "ess_bulk") if k in diag.get(n, {})}
            out[n] = est
        return out

    def json_head(self) -> dict:
        """The document's first keys, common to every model over all tests."""
        o = dataclasses.asdict(self.orders)
        return {
            "model": self.name,
            "x0_m": self.x0_m,
            "piston_area_m2": float(getattr(self.geometry, "area_m2", np.nan)),
            "orders": o,
            "orders_label": self.orders_label,
        }

    def json_tail(self, comparison: dict | None, advice: str) -> dict:
        """The document's last keys: order selection, comparison, the sampler's verdict."""
        conv = self.convergence
        out = {"order_selection": list(self.selection), "comparison": comparison}
        out["converged"] = bool(conv.converged)
        if hasattr(conv, "worst"):
            r_hat_max, ess_bulk_min = conv.worst()
            out["convergence"] = conv.to_json(advice, variables=False) | {
                "r_hat_max": r_hat_max,
                "ess_bulk_min": ess_bulk_min,
            }
        out["warnings"] = conv.messages(advice)
        return out

    def to_json(self, comparison: dict | None = None, advice: str | None = None) -> dict:
        """The model's JSON document: its orders, stand, valid range, coefficient blocks, sampled
        parameters and the sampler's verdict (a subclass adds its own quantities)."""
        if self.document is not None:
            return self.document | ({"comparison": comparison} if comparison else {})
        return self.fitted_document(comparison, CLI_ADVICE if advice is None else advice)

    def fitted_document(self, comparison: dict | None, advice: str) -> dict:
        """:meth:`to_json` of a model fitted in this process (a loaded one keeps its document); a
        subclass with quantities of its own gives its own."""
        plo, phi = self.pressure_range_bar
        return (
            self.json_head()
            | {
                "label": self.label,
                "stand": dataclasses.asdict(self.stand) if self.stand is not None else None,
                "valid_range": {"height_m": list(self.height_range_m), "pressure_bar": [plo, phi]},
                "coefficients": self.coefficient_summary(),
                "noise": self.noise_summary(self.reported),
            }
            | self.json_tail(comparison, advice)
        )

    # ---- the saved format
    def save(self, path, **provenance):
        """Write the model to ``path`` in the one saved format (:mod:`uq._models.saved`): its
        blocks as named variables (chain, draw, coefficient), its sampled parameters, orders,
        geometry and tested ranges as constant data, provenance as root attributes."""
        C, D, _ = self.coefficients.shape
        variables, start = {}, 0
        for b in self.block_layout():
            k = len(b.names)
            variables[b.name] = (
                ("chain", "draw", f"{b.name}_coefficient"),
                self.coefficients[..., start : start + k],
                {"unit": b.unit, "basis": b.basis},
                b.names,
            )
            start += k
        for n, v in self.reported.items():
            variables[n] = (("chain", "draw"), np.asarray(v, float), {}, None)
        document = self.to_json(provenance.pop("comparison", None))
        return saved.write(
            path,
            self,
            variables,
            {"orders": self.orders.values(), "geometry": self.geometry.values()},
            document,
            **provenance,
        )

    @classmethod
    def from_saved(cls, attrs: dict, groups: dict) -> LinearFit:
        """The model a file of :meth:`save` holds (no recordings, no posterior); a file missing
        any block of the layout is refused in one line naming them."""
        post, const = groups["posterior"], groups["constant_data"]
        shell = cls.shell(
            _params(cls, const, "orders"),
            _params(cls, const, "geometry"),
            const["tested_pressure_bar"].values,
        )
        layout = [b.name for b in shell.block_layout()]
        saved.require_blocks(post, layout)
        blocks = [np.asarray(post[name].values, float) for name in layout]
        return dataclasses.replace(
            shell,
            coefficients=np.concatenate(blocks, axis=-1),
            reported={n: np.asarray(post[n].values) for n in post.data_vars if n not in layout},
            height_range_m=tuple(float(v) for v in const["tested_height_range_m"].values),
            convergence=Verdict(
                bool(int(attrs["converged"])), tuple(json.loads(attrs["warnings_json"]))
            ),
            provenance=saved.provenance_from(attrs),
            max_draws=saved.max_draws_of(attrs),
            document=json.loads(str(const["json_document"].values)),
        )


def _params(cls, const, what: str) -> Params:
    kind = cls.orders_type if what == "orders" else cls.geometry_type
    return kind.from_values([str(v) for v in const[f"{what}_field"].values], const[what].values)
