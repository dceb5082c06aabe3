"""The per-pressure cubics as one fitted model of the campaign: interpolated between the tested pressures.

The cubics (eqs. 8, 9, ``uq._models.cubic``) say nothing between the tested pressures, so
:class:`CubicInterpolation`, the cubic fit's :class:`uq._models.fitted.FittedModel`, interpolates
them on a fixed set of paired posterior draws:

* force: the paper's effective area F_eff = P / p_u at the height is taken linear in p_u between
  the two neighbouring tests, and P = p_u F_eff;
* volume-derived area dV/dx = -S dL/dx (eq. 1's second formula, from each test's piston cubic):
  linear in p_u between the neighbouring tests in the same way (a test without piston readings
  has none, and neither has the campaign's interpolation).

Each has two parts of uncertainty: (1) the posterior draws of both neighbouring cubics
(independent tests, so each test's draws are thinned to the fixed number and shuffled: draw s of
every test is one random pairing); (2) the interpolation error, zero at the tested pressures and
(F'' / 2) (p - p_i)(p_i+1 - p) between them. F'' in pressure is estimated at every interior tested
pressure from its two neighbours (the curvature the data show: 2 e_j / ((p_j - p_j-1)(p_j - p_j+1))
with e_j the test's posterior-mean value minus the line through its neighbours); the error of an
interval is a normal draw per posterior draw (one for the force, one for the area) with that
parabola's shape and the rms curvature of the interval's end tests as its sd. The assumption is
stated: the curvature between two tested pressures is no larger than at the neighbouring tested
pressures.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from uq._data.reference import FORCE_NAMES, PISTON_NAMES
from uq._inference.convergence import CLI_ADVICE
from uq._inference.summary import thin_rows
from uq._io.errors import InputError
from uq._models import saved
from uq._models.fitted import Block, Verdict, refuse_extrapolation
from uq._physics.quantities import BAR_PA

N_DRAWS = 2000
NAME = "cubics"
LABEL = "per-pressure cubics, F_eff = P/p_u interpolated linearly in pressure"
INTERPOLATION = (
    "F_eff = P/p_u linear in p_u between neighbouring tested pressures (dV/dx likewise); "
    "uncertainty: both tests' posteriors plus an interpolation error from the curvature in "
    "pressure at the neighbouring tested pressures (zero at tested pressures)"
)
NO_VOLUME = (
    "volume results omitted: force-only campaign (no piston_* or volume_* column): a test without "
    "piston readings has no piston cubic, so the cubics give no volume-derived area dV/dx"
)


@dataclass(frozen=True)
class TestsVerdict:
    """The sampler's verdict over every test of a campaign (a campaign fit's ``convergence``):
    converged when every test is, the warnings prefixed with each test's pressure."""

    tests: tuple

    @property
    def converged(self) -> bool:
        return all(t.convergence.converged for t in self.tests)

    def messages(self, advice: str = CLI_ADVICE) -> list[str]:
        return [
            f"{t.pressure_bar:g} bar cubic: {w}"
            for t in self.tests
            for w in t.convergence.messages(advice)
        ]


def feff(coef, u, p):
    """F_eff = P / p_u of force cubics ``coef`` (..., 4) at u (m) and p (bar)."""
    return (coef[..., 0] + coef[..., 1] * u + coef[..., 2] * u**2 + coef[..., 3] * u**3) / (
        p * BAR_PA
    )


def bracket(tested_bar, p):
    """The interval between tested pressures (``tested_bar`` ascending, two or more; the end
    intervals extended) of each pressure ``p`` (n,): its index i, its ends pa and pb, and the
    weight w = (p - pa) / (pb - pa) of its upper end, each (n,)."""
    i = np.clip(np.searchsorted(tested_bar, p, side="right") - 1, 0, tested_bar.size - 2)
    pa, pb = tested_bar[i], tested_bar[i + 1]
    return i, pa, pb, (p - pa) / (pb - pa)


def curvatures(F, tested_bar):
    """d^2 F / dp^2 at every interior tested pressure of values ``F`` (T, ...) at ``tested_bar``
    (T,): 2 e_j / ((p_j - p_j-1)(p_j - p_j+1)), e_j the value minus the line through the two
    neighbours (module docstring); NaN at the end tests."""
    kap = np.full_like(F, np.nan)
    for j in range(1, tested_bar.size - 1):
        a, b, c = tested_bar[j - 1], tested_bar[j], tested_bar[j + 1]
        line = (F[j - 1] * (c - b) + F[j + 1] * (b - a)) / (c - a)
        kap[j] = 2.0 * (F[j] - line) / ((b - a) * (b - c))
    return kap


def _area(coef, u, area_m2):
    """dV/dx = -S dL/dx of piston cubics ``coef`` (..., 4) at u (m)."""
    return -area_m2 * (coef[..., 1] + 2.0 * coef[..., 2] * u + 3.0 * coef[..., 3] * u**2)


@dataclass(eq=False, frozen=True, repr=False)
class CubicInterpolation:
    """The per-pressure cubics on fixed paired draws, interpolated in pressure (module docstring).

    ``force`` (S, T, 4) and ``piston`` (S, T, 4) or None: each test's cubic coefficients in the
    paper's basis (SI, u = x - x0), tests ascending in pressure; ``z`` and ``z_area`` (S, T - 1):
    the standard normals of the interpolation errors."""

    force: np.ndarray
    piston: np.ndarray | None
    z: np.ndarray
    z_area: np.ndarray | None
    tested_pressures_bar: np.ndarray
    x0_m: float
    area_m2: float
    height_range_m: tuple[float, float]
    recordings: Any = None
    convergence: Any = None
    provenance: dict = field(default_factory=dict)
    #: the campaign fit it interpolates (None when loaded) and a loaded one's ``uq fit`` document
    campaign: Any = None
    document: dict | None = None

    name = NAME
    label = LABEL
    words = "the per-pressure cubics"
    has_dvdp = False
    idata = None
    max_draws = None

    @classmethod
    def of(cls, campaign, n_draws: int = N_DRAWS, seed: int = 0) -> CubicInterpolation:
        """The interpolation of a :class:`uq._models.cubic_results.CampaignFit` on ``n_draws`` paired
        draws (``seed``: the pairing and the interpolation errors)."""
        rec = campaign.recordings
        tests = sorted(campaign.tests, key=lambda t: t.pressure_bar)
        rng = np.random.default_rng(seed)
        force, piston = [], []
        for t in tests:  # independent tests: each test's draws thinned and shuffled
            take = np.linspace(0, t.flat("force").shape[0] - 1, n_draws).astype(int)
            order = rng.permutation(n_draws)
            force.append(t.flat("force")[take][order])
            if t.has_piston:
                piston.append(t.flat("piston")[take][order])
        n_int = max(len(tests) - 1, 1)
        z = rng.standard_normal((n_draws, n_int))
        with_volume = len(piston) == len(tests)
        return cls(
            np.stack(force, axis=1),
            np.stack(piston, axis=1) if with_volume else None,
            z,
            rng.standard_normal((n_draws, n_int)) if with_volume else None,
            np.array([t.pressure_bar for t in tests], float),
            float(rec.x0_m),
            float(rec.piston_area_m2),
            tuple(float(v) for v in rec.height_range_m),
            rec,
            TestsVerdict(tuple(tests)),
            dict(getattr(campaign, "provenance", {})),
            campaign,
        )

    # ---- the protocol
    @property
    def pressure_range_bar(self) -> tuple[float, float]:
        p = self.tested_pressures_bar
        return float(p.min()), float(p.max())

    @property
    def has_volume(self) -> bool:
        return self.piston is not None

    @property
    def omitted_reason(self) -> str | None:
        return None if self.has_volume else NO_VOLUME

    @property
    def n_draws(self) -> int:
        return int(self.force.shape[0])

    def on_draws(self, n: int) -> CubicInterpolation:
        """The same model on at most ``n`` of its draws, thinned evenly."""
        if self.n_draws <= n:
            return self
        thin = {
            k: None if getattr(self, k) is None else thin_rows(getattr(self, k), n)
            for k in ("force", "piston", "z", "z_area")
        }
        return dataclasses.replace(self, **thin)

    def check_range(self, height_m, p_bar, param: str | None = None) -> None:
        refuse_extrapolation(
            height_m, p_bar, self.height_range_m, self.pressure_range_bar, param, "the model"
        )

    def curvature_sd(self, height_m, interval):
        """sd of d^2 F_eff / dp^2 (m^2/bar^2) on ``interval`` from its end tests' neighbours."""
        return self._curvature_sd(height_m, np.asarray(interval), feff, self.force)

    def _curvature_sd(self, height_m, interval, curve, coef):
        u = np.asarray(height_m, float) - self.x0_m
        mean = coef.mean(axis=0)  # (T, 4)
        p = self.tested_pressures_bar
        T = p.size
        kap = curvatures(np.stack([curve(mean[j], u, p[j]) for j in range(T)]), p)  # (T, n)
        ends = np.stack(
            [
                kap[np.clip(interval, 0, T - 1), np.arange(u.size)],
                kap[np.clip(interval + 1, 0, T - 1), np.arange(u.size)],
            ]
        )
        with np.errstate(invalid="ignore"):
            return np.sqrt(np.nanmean(ends**2, axis=0)) if T > 2 else np.zeros(u.size)

    def _interpolate(self, curve, coef, z, height_m, p_bar, check):
        """``curve`` of each test, linear in p_u between the neighbouring tests plus the
        interpolation error: (S, n) on the flattened points, and their shape."""
        h, p = np.broadcast_arrays(np.asarray(height_m, float), np.asarray(p_bar, float))
        if check:
            self.check_range(h, p)
        shape, h, p = h.shape, h.ravel(), p.ravel()
        tp = self.tested_pressures_bar
        T = tp.size
        u = h - self.x0_m
        if T == 1:
            return curve(coef[:, 0][:, None, :], u, tp[0]), shape
        i, pa, pb, w = bracket(tp, p)
        Fa = curve(coef[:, i], u, pa)  # (S, n)
        Fb = curve(coef[:, i + 1], u, pb)
        sd = self._curvature_sd(h, i, curve, coef)
        err = z[:, i] * (sd * 0.5 * (p - pa) * (pb - p))[None, :]
        return (1 - w) * Fa + w * Fb + err, shape

    def force_draws(self, height_m, p_bar, *, check: bool = True) -> np.ndarray:
        """P = p_u F_eff, F_eff interpolated (module docstring), N, (S, *shape)."""
        F, shape = self._interpolate(feff, self.force, self.z, height_m, p_bar, check)
        p = np.broadcast_to(np.asarray(p_bar, float), shape).ravel()
        return (p * BAR_PA * F).reshape(-1, *shape)

    def feff_draws(self, height_m, p_bar, *, check: bool = True) -> np.ndarray:
        F, shape = self._interpolate(feff, self.force, self.z, height_m, p_bar, check)
        return F.reshape(-1, *shape)

    def volume_area_draws(self, height_m, p_bar, *, check: bool = True) -> np.ndarray:
        """dV/dx = -S dL/dx of the piston cubics, interpolated (module docstring), m^2."""
        if not self.has_volume:
            raise InputError(NO_VOLUME)

        def area(coef, u, _p):
            return _area(coef, u, self.area_m2)

        out, shape = self._interpolate(area, self.piston, self.z_area, height_m, p_bar, check)
        return out.reshape(-1, *shape)

    def volume_pressure_draws(self, height_m, p_bar, *, check: bool = True) -> np.ndarray:
        raise InputError(
            "the per-pressure cubics have no dV/dp_u of their own (isobaric tests do not give it)"
        )

    def blocks(self) -> dict[str, Block]:
        """Each test's force (and piston) cubic on the fixed draws, ``force_<p>bar``,
        ``piston_<p>bar``."""
        out = {}
        for j, p in enumerate(self.tested_pressures_bar):
            out[f"force_{p:g}bar"] = Block(
                FORCE_NAMES, self.force[:, j], "N/m^j", "P = a_P + b_P u + c_P u^2 + d_P u^3"
            )
            if self.has_volume:
                out[f"piston_{p:g}bar"] = Block(
                    PISTON_NAMES,
                    self.piston[:, j],
                    "m^(1-j)",
                    "L = a_L + b_L u + c_L u^2 + d_L u^3",
                )
        return out

    def to_json(self, comparison: dict | None = None, advice: str | None = None) -> dict:
        """The ``uq fit --json`` document of the cubics (a loaded model: as saved)."""
        if self.campaign is not None:
            return self.campaign.to_json(advice=CLI_ADVICE if advice is None else advice)
        return self.document

    def __repr__(self) -> str:
        return (
            f"CubicInterpolation({len(self.tested_pressures_bar)} tests at "
            f"{', '.join(f'{p:g}' for p in self.tested_pressures_bar)} bar, {self.n_draws} paired "
            f"draws{'' if self.has_volume else ', force only'})"
        )

    # ---- the saved format
    def save(self, path, **provenance):
        """Write the interpolation (its paired draws and interpolation normals) in the one saved
        format (:mod:`uq._models.saved`)."""
        dims = ("chain", "draw", "test")
        variables = {
            "force": (dims + ("force_coefficient",), self.force[None], {}, FORCE_NAMES),
            "interpolation_z": (("chain", "draw", "interval"), self.z[None], {}, None),
        }
        if self.has_volume:
            variables["piston"] = (
                dims + ("piston_coefficient",),
                self.piston[None],
                {},
                PISTON_NAMES,
            )
            variables["interpolation_z_area"] = (
                ("chain", "draw", "interval"),
                self.z_area[None],
                {},
                None,
            )
        params = {"geometry": (("x0_m", "area_m2"), np.array([self.x0_m, self.area_m2]))}
        provenance.pop("comparison", None)
        document = self.to_json()
        return saved.write(path, self, variables, params, document, **provenance)

    @classmethod
    def from_saved(cls, attrs: dict, groups: dict) -> CubicInterpolation:
        post, const = groups["posterior"], groups["constant_data"]
        volume = "piston" in post or "interpolation_z_area" in post
        needed = ("force", "interpolation_z") + (
            ("piston", "interpolation_z_area") if volume else ()
        )
        saved.require_blocks(post, needed)
        x0, area = (float(v) for v in const["geometry"].values)
        piston = post["piston"].values[0] if volume else None
        return cls(
            post["force"].values[0],
            piston,
            post["interpolation_z"].values[0],
            post["interpolation_z_area"].values[0] if piston is not None else None,
            np.asarray(const["tested_pressure_bar"].values, float),
            x0,
            area,
            tuple(float(v) for v in const["tested_height_range_m"].values),
            convergence=Verdict(
                bool(int(attrs["converged"])), tuple(json.loads(attrs["warnings_json"]))
            ),
            provenance=saved.provenance_from(attrs),
            document=json.loads(str(const["json_document"].values)),
        )
