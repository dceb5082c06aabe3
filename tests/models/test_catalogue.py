"""A catalogue of closed-form problems, run through every model with the public API.

Each problem is an air spring whose characteristics are known exactly: the effective area is a
polynomial A(u) = A0 + A1 u + A2 u^2 in u = x - x0, the same at every pressure, and the
traditional theory holds (eq. 1: the force is p A(x), and the volume's slope is the same A(x)).
So, in the paper's basis (u in m, SI),

    force:  a_P = p A0,  b_P = p A1,  c_P = p A2,  d_P = 0
    piston: L(u) = a_L - (A0 u + A1 u^2 / 2 + A2 u^3 / 3) / S   (dV = S [L - L(x_max)], -S dL/dx = A)

The recordings are these curves plus Gaussian reading noise of known, constant size (not the
virtual stand, and not the noise family the models assume: a floor only). Every model must find
the answer in closed form: the cubic posteriors' 90 % intervals contain the coefficients, the
bands contain A(x) and a zero traditional-minus-experimental spread, the surface model's force
and the margin query's needed pressure (load / A(x)) are recovered, the thermodynamic model's
force, volume-derived area, Maxwell ratio (1) and piston area are recovered, and diagnose names
nothing.

The cylinder (A1 = A2 = 0) runs through the cubic model, the bands, the thermodynamic model and
diagnose in the fast suite; its surface and margin, and the other problems through every model, are marked slow.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest

import uq

X0 = 0.112
S = 54.82e-4
BAR = 1e5
FORCE_SD_N = 25.0
PISTON_SD_M = 0.05e-3
PRESSURES = (2.0, 5.0, 8.0)


@dataclass(frozen=True)
class Problem:
    name: str
    A: tuple[float, float, float]  # A0 m^2, A1 m, A2 (dimensionless): A(u) = A0 + A1 u + A2 u^2

    def area(self, x):
        u = np.asarray(x, float) - X0
        return self.A[0] + self.A[1] * u + self.A[2] * u**2

    def force_coefs(self, p_bar: float) -> np.ndarray:
        return p_bar * BAR * np.array([*self.A, 0.0])

    def piston_slopes(self) -> np.ndarray:
        """b_L, c_L, d_L: the piston's cubic without its arbitrary offset a_L."""
        return -np.array([self.A[0], self.A[1] / 2, self.A[2] / 3]) / S

    def recordings(self, seed: int) -> uq.Recordings:
        rng = np.random.default_rng(seed)
        down = np.round(np.arange(0.155, 0.065 - 1e-9, -0.005), 6)
        x = np.concatenate([down, down[::-1][1:]])
        compression = np.arange(x.size) < down.size
        u = x - X0
        tests = []
        for i, p in enumerate(PRESSURES):
            a_L = 0.05 + 0.01 * i  # each test's piston reference is arbitrary
            force = np.polyval(self.force_coefs(p)[::-1], u) + FORCE_SD_N * rng.standard_normal(
                x.size
            )
            piston = (
                a_L
                + np.polyval([*self.piston_slopes()[::-1], 0.0], u)
                + PISTON_SD_M * rng.standard_normal(x.size)
            )
            tests.append(
                uq.PressureTest(
                    p, x, force, piston, compression, np.arange(x.size), np.arange(x.size) + 2
                )
            )
        return uq.Recordings(f"closed form: {self.name}", tuple(tests), x0_m=X0, piston_area_m2=S)


CATALOGUE = [
    Problem("cylinder", (0.025, 0.0, 0.0)),  # rolling-lobe ideal: constant area
    Problem("cone", (0.025, -0.10, 0.0)),  # area falls linearly with height
    Problem("bulge", (0.025, -0.10, -1.5)),  # area with a maximum below x0 (balloon-like)
]
QUICK = uq.Settings(max_steps=3000)


def _inside(draws, truth, level=0.90) -> bool:
    lo, hi = np.quantile(draws, [(1 - level) / 2, (1 + level) / 2])
    return bool(lo <= truth <= hi)


def _cubic_and_bands(problem: Problem, rec):
    fit = uq.fit_campaign(rec, seed=11, settings=QUICK)
    inside, total = 0, 0
    for t in fit.tests:
        force, piston = t.flat("force"), t.flat("piston")
        truth_f, truth_l = problem.force_coefs(t.pressure_bar), problem.piston_slopes()
        for j in range(4):
            inside += _inside(force[:, j], truth_f[j])
        for j in range(3):
            inside += _inside(piston[:, j + 1], truth_l[j])
        total += 7
        assert t.convergence.converged, (problem.name, t.pressure_bar)
    # 21 intervals at 90 %: 13 or fewer inside has probability < 0.002 for calibrated intervals
    assert inside >= 14, f"{problem.name}: {inside}/{total} coefficient intervals hold the truth"

    bands = uq.campaign_bands(fit, seed=11)
    x = bands.x_m
    for tb in bands.tests:
        # F_eff from the force and from the volume: both are A(x) within the band (away from the ends)
        mid = (x > 0.075) & (x < 0.145)
        for name in ("feff", "feff_volume"):
            b = getattr(tb, name)
            covered = np.mean(
                (b.lo[mid] <= problem.area(x[mid])) & (problem.area(x[mid]) <= b.hi[mid])
            )
            assert covered > 0.5, (problem.name, tb.pressure_bar, name, covered)
        # the traditional theory holds: the spread at x0 is zero within 3.3 posterior sd (99.9 %)
        est = tb.at_x0["spread_own_pct"]
        assert abs(est["mean"]) <= 3.3 * est["sd"], (problem.name, tb.pressure_bar, est)


def _surface_and_margin(problem: Problem, rec):
    surface = uq.fit_surface(rec, uq.Orders(3, 2, 2, 1, 1), seed=11, settings=QUICK, max_draws=1000)
    answer = surface
    for x, p in ((0.112, 5.0), (0.090, 3.0), (0.135, 7.0)):
        truth = p * BAR * problem.area(x)
        draws = answer.force_draws(x, p)
        sd = draws.std()
        assert abs(draws.mean() - truth) < 4 * sd + 0.002 * truth, (
            problem.name,
            x,
            p,
            draws.mean(),
            truth,
            sd,
        )
    load = 5.0 * BAR * problem.area(0.112)
    res = uq.margin(surface, height_m=0.112, load_N=load, prob=0.95)
    need = res["pressure_bar_needed"]
    assert need["q05"] - 0.02 <= 5.0 <= need["q95"] + 0.02, (problem.name, need)


def _thermo(problem: Problem, rec):
    """The thermodynamic model: force and the volume-derived area dV/dx are A(x) p_u and A(x), the
    Maxwell ratio (dV/dx)/(P/p_u) is 1 (the traditional theory holds) and the piston area the
    recordings imply covers the S they were made with."""
    fit = uq.fit_thermo(rec, uq.ThermoOrders(4, 2), seed=11, settings=QUICK, max_draws=1000)
    assert fit.convergence.converged, fit.convergence.warnings
    for x, p in ((0.112, 5.0), (0.090, 3.0), (0.135, 7.0)):
        for draws, truth in (
            (fit.force_draws(x, p), p * BAR * problem.area(x)),
            (fit.volume_area_draws(x, p), problem.area(x)),
            (fit.maxwell_ratio_draws(x, p), 1.0),
        ):
            lo, hi = np.quantile(draws, [0.0005, 0.9995])
            assert lo <= truth <= hi, (problem.name, x, p, lo, truth, hi)
    assert _inside(fit.piston_area_draws(), S, level=0.999), problem.name


def _diagnose(rec):
    found = uq.diagnose(rec, seed=11, settings=QUICK, sample_final=False)
    assert found["mechanisms"] == [], found["mechanisms"]


@pytest.fixture(scope="module")
def cylinder():
    return CATALOGUE[0], CATALOGUE[0].recordings(seed=11)


def test_cylinder_cubic_and_bands(cylinder):
    _cubic_and_bands(*cylinder)


def test_cylinder_diagnose(cylinder):
    _diagnose(cylinder[1])


@pytest.mark.slow  # fast: the thermodynamic model's own tests (tests/models/test_thermo_model.py)
def test_cylinder_thermodynamic(cylinder):
    _thermo(*cylinder)


@pytest.mark.slow
def test_cylinder_surface_and_margin(cylinder):
    _surface_and_margin(*cylinder)


@pytest.mark.slow
@pytest.mark.parametrize("problem", CATALOGUE[1:], ids=lambda p: p.name)
def test_catalogue_through_every_model(problem):
    rec = problem.recordings(seed=11)
    _cubic_and_bands(problem, rec)
    _surface_and_margin(problem, rec)
    _thermo(problem, rec)
    _diagnose(rec)
