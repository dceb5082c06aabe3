"""The results of the per-pressure cubics (numpy only): one test's posterior (:class:`PressureFit`)
and a campaign's (:class:`CampaignFit`), the campaign's :class:`uq._models.fitted.FittedModel`.

They are made by ``uq._models.cubic_fit`` (the models' likelihoods are ``uq._models.cubic`` and its
variants) and need no JAX afterwards: a fit's draws, JSON, bands and interpolation are numpy.
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from uq._data.recordings import PressureTest, Recordings
from uq._data.reference import FORCE_NAMES, PISTON_NAMES
from uq._data.stand_description import PAPER_STAND, StandDescription
from uq._inference.convergence import CLI_ADVICE, LIBRARY_ADVICE
from uq._inference.summary import estimate
from uq._io.errors import InputError
from uq._io.netcdf import write_netcdf_atomic
from uq._models.cubic_interpolation import LABEL as CUBICS_LABEL
from uq._models.cubic_interpolation import NAME as CUBICS_NAME
from uq._models.cubic_interpolation import CubicInterpolation, TestsVerdict
from uq._models.residual_order import order_warnings
from uq._physics.cubic import cubic

NOISE_NAMES = ("sigma0_N", "rel_force", "sigma_L_m")
FORCE_NOISE_NAMES = NOISE_NAMES[:2]
AR_EXTRA_NAMES = ("k_p", "V_gas_m3", "rho")
MEASURED_EXTRA_NAMES = ("V_gas_m3", "pressure_offset_Pa")
#: what a campaign fit answers by its interpolation on fixed paired draws (CampaignFit.__getattr__)
PROTOCOL = frozenset(
    (
        "height_range_m pressure_range_bar tested_pressures_bar has_volume omitted_reason n_draws "
        "check_range force_draws feff_draws volume_area_draws volume_pressure_draws on_draws "
        "blocks save"
    ).split()
)
#: Why a force-only test has no piston block (``uq fit --json``'s "omitted", the report's line).
NO_VOLUME = (
    "force-only test: no piston_* or volume_* column, so no piston coordinate, volume increment "
    "or volume-derived effective area"
)
#: How a test with a volume column gets its piston block (``uq fit --json``'s "piston_from").
VOLUME_AS_PISTON = (
    "from the volume_* column: L = -V / S (eq. 10, S the stand's piston area), the test's piston "
    "reference arbitrary (a_L has no meaning of its own)"
)


def noise_reference(lsq_force, u, noise: str) -> np.ndarray:
    """Force level of the relative noise term at u: the least-squares curve's |P| ("budget"), or
    its mean over these points ("constant")."""
    ref = np.abs(cubic(lsq_force, u))
    return np.full_like(ref, ref.mean()) if noise == "constant" else ref


@dataclass(eq=False, frozen=True, repr=False)
class PressureFit:
    """Posterior of one test: the driver's :class:`~uq._inference.collapsed.Posterior` and what the
    test's quantities need. Draw arrays are (chains, draws, ...) in the paper's basis, SI.

    A force-only test (no piston_* and no volume_* column) has no volume block: ``piston``,
    ``lsq_piston`` and ``piston_m`` are None, ``noise`` holds sigma0_N and rel_force only, and
    ``has_piston`` is False. A test with a volume column fits L = -V / S (``piston_source``
    "volume", :func:`piston_coordinate`), so every volume quantity works on it unchanged."""

    test: PressureTest
    x0_m: float
    lsq_force: np.ndarray  # (4,)
    lsq_piston: np.ndarray | None  # (4,), None for a force-only test
    posterior: object  # the driver's uq._inference.collapsed.Posterior
    ref_force_N: np.ndarray  # (n,) force level of the relative noise term at each point
    noise_model: str  # "budget" or "constant" (fit_test's noise)
    force: np.ndarray  # (C, D, 4) a_P..d_P
    piston: np.ndarray | None  # (C, D, 4) a_L..d_L, None for a force-only test
    noise: np.ndarray  # (C, D, 3) sigma0_N, rel_force, sigma_L_m (C, D, 2 without the piston)
    #: the recording-order check of the residuals (uq._models.residual_order): force, piston,
    #: alpha; for a test in unknown order {"alpha", "skipped": why}
    order_check: dict
    #: the pressure-holding error: "plain" (in the noise), "measured" (measured pressure as a
    #: covariate) or "ar1" (AR(1) in recording order); the pressure-holding section below
    variant: str = "plain"
    #: where the volume block's L readings come from: "piston" (piston_* column), "volume"
    #: (L = -V / S from a volume_* column) or None (force-only test)
    piston_source: str | None = "piston"
    #: the L readings (m) the volume block fits, as read (None for a force-only test)
    piston_m: np.ndarray | None = None

    @classmethod
    def of(
        cls, test, x0_m, lsq_force, lsq_piston, posterior, ref_force_N, noise_model, variant="plain"
    ):
        post = posterior.reported
        has_piston = lsq_piston is not None

        def stack(names):
            return np.stack([np.asarray(post[n]) for n in names], axis=-1)

        noise = stack(NOISE_NAMES if has_piston else FORCE_NOISE_NAMES)
        fields = (test, x0_m, lsq_force, lsq_piston, posterior, ref_force_N, noise_model)
        if not has_piston:
            return cls(*fields, stack(FORCE_NAMES), None, noise, {}, variant, None, None)
        source = "piston" if test.piston_m is not None else "volume"
        piston_m = np.asarray(posterior.data.piston, float)
        # the recording-order check ({}) is uq._models.cubic_fit.with_order_check's
        return cls(
            *fields, stack(FORCE_NAMES), stack(PISTON_NAMES), noise, {}, variant, source, piston_m
        )

    @property
    def has_piston(self) -> bool:
        """The test has a volume block (piston_* or volume_* column); False: force only."""
        return self.piston is not None

    @property
    def pressure_bar(self) -> float:
        return self.test.pressure_bar

    @property
    def idata(self):
        return self.posterior.idata

    @property
    def convergence(self):
        return self.posterior.convergence

    @property
    def chains(self):
        return self.posterior.chains

    def flat(self, name: str) -> np.ndarray:
        arr = getattr(self, name)
        return arr.reshape(-1, *arr.shape[2:])

    def ref_force_at(self, height_m) -> np.ndarray:
        """The force level of the relative noise term at any heights, by the rule the fit used at
        the data: the report's predictive bands use it on their grid."""
        u = np.asarray(height_m, float) - self.x0_m
        if self.noise_model == "constant":
            return np.full(u.shape, float(np.mean(self.ref_force_N)))
        return noise_reference(self.lsq_force, u, self.noise_model)

    def mean_residuals(self, block: str) -> np.ndarray:
        """Readings minus the posterior-mean curve of ``block`` ("force" N or "piston" m), (n,)."""
        if block == "piston" and not self.has_piston:
            raise ValueError(f"the {self.test.label} test is force-only: it has no piston block")
        y = self.test.force_N if block == "force" else self.piston_m
        return y - cubic(self.flat(block).mean(0), self.test.height_m - self.x0_m)

    def deviation_measures(self) -> tuple[float, float]:
        """The paper's s_P (N) and eps_P (%) of the posterior-mean curve (section 5)."""
        res = self.mean_residuals("force")
        return float(np.sqrt(np.mean(res**2))), float(
            100.0 * np.mean(np.abs(res / self.test.force_N))
        )

    def model_warnings(self) -> list[str]:
        """The recording-order check's warnings (none when the residuals look independent)."""
        return order_warnings(self.order_check)

    def summary(self):
        """ArviZ's summary table (pandas DataFrame) of the coefficients and noise parameters."""
        return self.posterior.summary()

    def to_json(self, advice: str = CLI_ADVICE) -> dict:
        """One entry of ``tests`` in ``uq fit --json`` (docs/formats.md). A force-only test has no
        "piston" blocks (estimates, least squares, covariance) and says why under "omitted"; a
        test whose L comes from a volume column says so under "piston_from"."""
        conv = self.convergence.to_json(advice, variables=False)
        var = self.convergence.variables
        s_P, eps_P = self.deviation_measures()
        noise_names = NOISE_NAMES if self.has_piston else FORCE_NOISE_NAMES

        def block(draws, names):
            return {
                n: estimate(draws[..., i])
                | {k: var[n][k] for k in ("r_hat", "ess_bulk", "ess_tail", "mcse_mean")}
                for i, n in enumerate(names)
            }

        out = {
            "pressure_bar": self.pressure_bar,
            "n_points": self.test.n_points,
            "force": block(self.force, FORCE_NAMES),
        }
        if self.has_piston:
            out["piston"] = block(self.piston, PISTON_NAMES)
        out |= {
            "s_P_N": s_P,
            "eps_P_pct": eps_P,
            "noise": {
                n: estimate(self.noise[..., i])
                | {"r_hat": var[n]["r_hat"], "ess_bulk": var[n]["ess_bulk"]}
                for i, n in enumerate(noise_names)
            },
            "least_squares": {
                "force": dict(zip(FORCE_NAMES, self.lsq_force.tolist(), strict=True))
            },
            "covariance": {"force": np.cov(self.flat("force"), rowvar=False)},
            "convergence": conv,
            "residual_order": self.order_check,
        }
        if self.has_piston:
            out["least_squares"]["piston"] = dict(
                zip(PISTON_NAMES, self.lsq_piston.tolist(), strict=True)
            )
            out["covariance"]["piston"] = np.cov(self.flat("piston"), rowvar=False)
        else:
            out["omitted"] = {"piston": NO_VOLUME}
        if self.piston_source == "volume":
            out["piston_from"] = VOLUME_AS_PISTON
        return out | self._pressure_holding_json(var)

    def _pressure_holding_json(self, var) -> dict:
        """How the model treated the pressure-holding error, and its extra parameters."""

        if self.variant == "plain":
            return {}
        names = AR_EXTRA_NAMES if self.variant == "ar1" else MEASURED_EXTRA_NAMES
        post = self.posterior.reported
        block = {"model": self.variant}
        for n in (n for n in names if n in post):  # a force-only test has no gas volume
            block[n] = estimate(np.asarray(post[n])) | {
                k: var[n][k] for k in ("r_hat", "ess_bulk") if k in var.get(n, {})
            }
        return {"pressure_holding": block}

    def __repr__(self) -> str:
        state = "converged" if self.convergence.converged else "NOT converged"
        return (
            f"PressureFit({self.pressure_bar:g} bar, {self.test.n_points} readings, "
            f"{self.flat('force').shape[0]} draws, {state})"
        )


@dataclass(eq=False, frozen=True, repr=False)
class CampaignFit:
    """The per-pressure cubics of every test of a campaign (:func:`fit_campaign`), and the
    campaign's :class:`uq._models.fitted.FittedModel`: between the tested pressures the cubics are
    interpolated on fixed paired draws (:class:`uq._models.cubic_interpolation.CubicInterpolation`,
    ``interpolation``), which answer ``force_draws``, ``volume_area_draws`` and the rest."""

    recordings: Recordings
    tests: list[PressureFit]
    seed: int
    stand: StandDescription = PAPER_STAND
    provenance: dict = field(default_factory=dict)

    name = CUBICS_NAME
    label = CUBICS_LABEL
    words = "the per-pressure cubics"
    has_dvdp = False
    idata = None  # one posterior per test: ``tests[i].idata``

    @property
    def converged(self) -> bool:
        return all(t.convergence.converged for t in self.tests)

    @property
    def convergence(self) -> TestsVerdict:
        return TestsVerdict(tuple(self.tests))

    def predictive_force_draws(self, n_draws: int, seed: int = 0) -> list[np.ndarray] | None:
        """Each test's posterior-predictive replicates of its force readings, (S, n_t) on at most
        ``n_draws`` draws thinned evenly (the fit's ``posterior_predictive`` group; ``seed`` is
        not used: the replicates were drawn with the fit's), in the order of ``tests``; None when a
        test's posterior keeps no replicates."""
        out = []
        for t in self.tests:  # on the kept draws only: no (draws x readings) arrays of every draw
            reps = t.posterior.predictive_thinned(n_draws)
            if reps is None or "force_N" not in reps:
                return None
            out.append(reps["force_N"])
        return out

    @property
    def seconds(self) -> float:
        """The fit's wall time (every test in one emcee run)."""
        return max(t.posterior.seconds for t in self.tests)

    def at(self, pressure_bar: float) -> PressureFit:
        """The test at ``pressure_bar``; a pressure without a test is one line naming the tested ones."""
        for t in self.tests:
            if abs(t.pressure_bar - pressure_bar) < 1e-9:
                return t
        raise InputError(
            f"pressure_bar: no test at {pressure_bar:g} bar; the tests are at "
            f"{', '.join(f'{t.pressure_bar:g}' for t in self.tests)} bar",
            param="pressure_bar",
        )

    # ---- the FittedModel protocol, by the interpolation on fixed paired draws
    @functools.cached_property
    def interpolation(self) -> CubicInterpolation:
        return CubicInterpolation.of(self)

    def __getattr__(self, name: str):
        """The rest of the protocol (``PROTOCOL``: the draws, ranges, ``on_draws``, ``blocks``,
        ``save``) is the interpolation's."""
        if name not in PROTOCOL:
            raise AttributeError(f"'CampaignFit' object has no attribute '{name}'")
        return getattr(self.interpolation, name)

    def summary(self):
        """One row per test and coefficient: ArviZ's summary statistics (pandas DataFrame)."""
        import pandas as pd  # reason: pandas, optional and heavy, only for this table

        return pd.concat(
            {f"{t.pressure_bar:g} bar": t.summary() for t in self.tests}, names=["test", "quantity"]
        )

    def warnings(self, advice: str = LIBRARY_ADVICE) -> list[str]:
        """The sampler's failed rules of every test, each prefixed with its pressure."""
        return [
            f"{t.pressure_bar:g} bar: {w}"
            for t in self.tests
            for w in t.convergence.messages(advice)
        ]

    def model_warnings(self) -> list[str]:
        """The recording-order warnings of every test, each prefixed with its pressure."""
        return [f"{t.pressure_bar:g} bar: {w}" for t in self.tests for w in t.model_warnings()]

    def to_json(self, comparison: dict | None = None, advice: str = CLI_ADVICE) -> dict:
        """What ``uq fit --json`` writes (docs/formats.md): per test the coefficients' and noise's
        posterior summaries, the coefficient blocks' covariance, least squares and diagnostics."""
        rec = self.recordings
        return {
            "x0_m": rec.x0_m,
            "piston_area_m2": rec.piston_area_m2,
            "source": os.path.basename(rec.path),
            "seed": self.seed,
            "converged": self.converged,
            "warnings": self.warnings(advice),
            "model_warnings": self.model_warnings(),
            "tests": [t.to_json(advice) for t in self.tests],
        }

    def save_posteriors(self, out_dir, *, pointwise: bool = True) -> list:
        """One NetCDF file per test (ArviZ InferenceData with posterior, log_likelihood,
        posterior_predictive, observed_data and sample_stats groups), made in memory and written
        atomically (a full disk is a one-line error, not a crash inside HDF5:
        ``uq._io.netcdf.netcdf_bytes``); returns the paths (``uq fit --out``). Each test's
        InferenceData is made for its file and dropped after it (unless it was made before): the
        memory of one test's (draws x readings) groups at a time, not of the campaign's.

        ``pointwise=False``: without the log_likelihood and posterior_predictive groups (about
        90 % of the bytes; recomputable exactly from the posterior draws), for ``uq batch``'s
        ``pointwise = false`` (docs/batch.md)."""
        out = Path(out_dir)
        paths = []
        for t in self.tests:
            path = out / f"posterior_{t.pressure_bar:g}bar.nc"
            if not pointwise:
                paths.append(write_netcdf_atomic(path, t.posterior.draws_idata()))
                continue
            with t.posterior.transient():
                paths.append(write_netcdf_atomic(path, t.idata))
        return paths

    def __repr__(self) -> str:
        state = "converged" if self.converged else "NOT converged"
        return (
            f"CampaignFit({len(self.tests)} tests at "
            f"{', '.join(f'{t.pressure_bar:g}' for t in self.tests)} bar, "
            f"{self.recordings.n_points} readings, seed {self.seed}, {state})"
        )
