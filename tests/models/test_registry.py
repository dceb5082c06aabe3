"""A model plugged in from outside ``uq``: defined in this file, registered, and run through
``uq surface``, ``uq margin``, ``uq design`` and a saved answer without editing ``uq/``.

The model is the traditional theory (eqs. 1, 2 of the paper) in the registry's terms: one
effective-area curve A(x), a polynomial in t = (x - x0)/h, the same at every pressure, with
P = p_u A(x) and dV/dx = A(x), so the piston moves by L = r_i - (h/S) sum a_k t^(k+1)/(k+1) with a
reference r_i per test. Its noise is the stand's budget with one unknown common scale (prior
1/s^2), so the posterior is exact: s^2 from its scaled inverse chi-square, the coefficients from
their Gaussian given it. Three pieces make it a model of ``uq``: the fitted class (a
:class:`uq._models.linear_fit.LinearFit` with its blocks and columns), the fit function, and the
registry entry.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

import numpy as np
import pytest
from cli_helpers import run

from uq._models import registry
from uq._models.fitted import FittedModel, Verdict
from uq._models.linear_fit import BlockSpec, LinearFit, Params
from uq._models.saved import provenance_of
from uq._physics.quantities import BAR_PA, BASIS_SCALE_M

N50 = "data/n50/recordings.csv"
NAME = "traditional-test"


@dataclass(frozen=True)
class AreaOrders(Params):
    K: int = 3

    @property
    def label(self) -> str:
        return f"A {self.K}"


@dataclass(frozen=True)
class AreaGeometry(Params):
    x0_m: float
    area_m2: float


@dataclass(eq=False, frozen=True, repr=False)
class TraditionalFit(LinearFit):
    """P = p_u A(x), dV/dx = A(x): one effective-area curve at every pressure."""

    name = NAME
    words = "the traditional test model"
    orders_type = AreaOrders
    geometry_type = AreaGeometry

    def block_layout(self):
        refs = tuple(f"r_{p:g}bar" for p in self.tested_pressures_bar)
        area = tuple(f"a_{k}" for k in range(self.orders.K + 1))
        return (
            BlockSpec("area_m2", area, 0.1, "m^2", "A = sum a_k t^k"),
            BlockSpec("piston_reference_m", refs, 1.0, "m", "one piston reference per test"),
        )

    def _columns(self, x_m, factor):
        t = (np.asarray(x_m, float) - self.geometry.x0_m) / BASIS_SCALE_M
        cols = np.asarray(factor, float)[:, None] * t[:, None] ** np.arange(self.orders.K + 1)
        return np.hstack([cols, np.zeros((t.size, len(self.tested_pressures_bar)))])

    def force_columns(self, x_m, p_bar):
        return self._columns(x_m, np.asarray(p_bar, float) * BAR_PA)

    def area_columns(self, x_m, p_bar):
        return self._columns(x_m, np.ones(np.size(x_m)))


def fit_traditional(rec, *, seed, settings=None, stand=None, orders=AreaOrders(), n_draws=2000):
    """The exact posterior of the traditional model (module docstring)."""
    x = np.concatenate([t.height_m for t in rec.tests])
    p = np.concatenate([np.full(t.n_points, t.pressure_bar) for t in rec.tests])
    F = np.concatenate([t.force_N for t in rec.tests])
    L = np.concatenate([t.piston_m for t in rec.tests])
    idx = np.concatenate([np.full(t.n_points, i) for i, t in enumerate(rec.tests)])
    t = (x - rec.x0_m) / BASIS_SCALE_M
    k = np.arange(orders.K + 1)
    T, n = len(rec.tests), x.size
    Xf = np.hstack([p[:, None] * BAR_PA * t[:, None] ** k * 0.1, np.zeros((n, T))])
    Xl = np.zeros_like(Xf)
    Xl[:, : k.size] = -BASIS_SCALE_M / rec.piston_area_m2 * t[:, None] ** (k + 1) / (k + 1) * 0.1
    Xl[np.arange(n), k.size + idx] = 1.0
    sd = np.concatenate([20.0 + 0.005 * np.abs(F), np.full(n, 1e-4)])
    X, y = np.vstack([Xf, Xl]) / sd[:, None], np.concatenate([F, L]) / sd
    A = X.T @ X
    mean = np.linalg.solve(A, X.T @ y)
    dof = y.size - mean.size
    s2 = float(np.sum((y - X @ mean) ** 2)) / dof
    rng = np.random.default_rng(seed)
    scale2 = s2 * dof / rng.chisquare(dof, n_draws)
    z = rng.standard_normal((n_draws, mean.size)) @ np.linalg.cholesky(np.linalg.inv(A)).T
    beta = mean + np.sqrt(scale2)[:, None] * z
    scales = np.concatenate([np.full(k.size, 0.1), np.ones(T)])
    return TraditionalFit(
        orders,
        AreaGeometry(rec.x0_m, rec.piston_area_m2),
        (beta * scales)[None],
        {"noise_scale": np.sqrt(scale2)[None]},
        np.asarray(rec.pressures_bar, float),
        rec.height_range_m,
        rec,
        None,
        stand,
        Verdict(True),
        provenance_of(rec, seed=seed, settings=settings, stand=stand),
    )


ENTRY = registry.ModelEntry(
    NAME,
    fit=fit_traditional,
    model=TraditionalFit,
    words="the traditional theory, one effective area at every pressure (a test's model)",
    n_sampled=0,
    needs_volume=True,
)


@pytest.fixture
def plugged():
    registry.register(ENTRY)
    yield ENTRY
    registry.unregister(NAME)


def test_the_model_is_a_fitted_model(n50_recordings):
    fit = fit_traditional(n50_recordings, seed=1)
    assert isinstance(fit, FittedModel) and fit.has_volume and not fit.has_dvdp
    # P = p_u A and dV/dx = A: the traditional theory, draw by draw
    P = fit.force_draws(0.1, 5.0)
    assert np.allclose(P / (5.0 * BAR_PA), fit.volume_area_draws(0.1, 5.0))
    assert 12e3 < P.mean() < 17e3 and fit.on_draws(100).n_draws == 100
    assert set(fit.blocks()) == {"area_m2", "piston_reference_m"}


def test_a_model_plugged_in_runs_through_every_command(plugged, tmp_path, capsys):
    """uq surface (JSON, generic page, saved model), uq margin (fitted, saved, answered from the
    saved file: the same numbers) and uq design take the model by its registered name."""
    out = tmp_path / "surface"
    assert (
        run(
            [
                "surface",
                N50,
                "--model",
                NAME,
                "--no-compare",
                "--out",
                out,
                "--report",
                out,
                "--json",
                tmp_path / "surface.json",
            ]
        )
        == 0
    )
    doc = json.loads((tmp_path / "surface.json").read_text())
    assert doc["model"] == NAME and set(doc["coefficients"]) == {"area_m2", "piston_reference_m"}
    assert (out / f"{NAME}.html").is_file() and (out / f"{NAME}_force.png").is_file()
    query = ["--height-mm", "100", "--load-N", "15000", "--pressure-bar", "5"]
    fitted, from_saved = tmp_path / "fitted.json", tmp_path / "saved.json"
    assert (
        run(
            [
                "margin",
                N50,
                "--model",
                NAME,
                *query,
                "--save-fit",
                tmp_path / "fit.nc",
                "--json",
                fitted,
            ]
        )
        == 0
    )
    assert run(["margin", "--fit", tmp_path / "fit.nc", *query, "--json", from_saved]) == 0
    assert run(["margin", "--fit", out / f"{NAME}.nc", *query, "--json", "-"]) == 0
    a, b = json.loads(fitted.read_text()), json.loads(from_saved.read_text())
    assert a == b and a["model"]["name"] == NAME and 4.0 < a["pressure_bar_for_prob"] < 6.0
    design = tmp_path / "design.json"
    assert (
        run(
            [
                "design",
                N50,
                "--model",
                NAME,
                "--height-mm",
                "112",
                "--charge-bar",
                "5",
                "--volume-l",
                "5",
                "--json",
                design,
            ]
        )
        == 0
    )
    d = json.loads(design.read_text())
    assert d["model"].startswith("traditional test model") and d["natural_frequency_Hz"]["mean"] > 0
    # uq design ranks its model by default; one without pointwise likelihoods is said unranked
    assert d["comparison"]["better"] == "refused" and "no pointwise" in d["comparison"]["reason"]
    capsys.readouterr()


def test_a_package_registers_its_model_by_entry_point(monkeypatch):
    """The ``uq.models`` entry-point group: an entry point naming a ModelEntry is loaded once."""
    from importlib import metadata

    ep = metadata.EntryPoint(NAME, f"{__name__}:ENTRY", registry.ENTRY_POINT_GROUP)
    monkeypatch.setattr(registry, "_PLUGINS_LOADED", False)
    monkeypatch.setattr(
        registry.metadata,
        "entry_points",
        lambda group: [ep] if group == registry.ENTRY_POINT_GROUP else [],
    )
    try:
        assert NAME in registry.names(over_all_tests=True)
        assert registry.entry(NAME).model_class() is TraditionalFit
    finally:
        registry.unregister(NAME)


def test_unknown_model_names_the_known_ones():
    from uq._io.errors import InputError

    with pytest.raises(InputError, match="unknown model 'nope'; the registered models are cubics"):
        registry.entry("nope")


def test_the_default_model_is_the_discrepancy_surface_but_for_uq_surface():
    """Issue 29: margins, design, the report's model page, export and plan answer with the surface
    with a discrepancy in pressure; ``uq surface`` keeps fitting the smooth surface; the command
    lines offer the default and every other model by name."""
    from uq._cli.main import build_parser

    assert registry.DEFAULT_MODEL == registry.DISCREPANCY
    for command in ("margin", "design", "report", "export", "plan"):
        assert registry.default(command) == registry.DISCREPANCY, command
    assert registry.default("surface") == registry.SURFACE

    def model_option(command):
        (option,) = [
            a for a in build_parser([command])._uq_commands[command]._actions if a.dest == "model"
        ]
        return option

    for command, default in (("design", registry.DISCREPANCY), ("surface", registry.SURFACE)):
        option = model_option(command)
        assert option.default == default, command
        assert set(registry.names(over_all_tests=True)) <= set(option.choices), command
    option = model_option("report")  # with --surface; None: registry.default("report")
    assert option.default is None
    assert set(option.choices) == set(registry.names(over_all_tests=True))
    assert registry.DISCREPANCY in model_option("margin").choices


def test_a_saved_model_is_loaded_and_queried_without_jax(n50_surface, n50_fit, tmp_path):
    """The fitted objects are numpy: a saved surface and the saved cubics are loaded and answer a
    margin and the sealed spring in a fresh interpreter that imports no JAX, ArviZ or optimistix."""
    import subprocess
    import sys

    n50_surface.save(tmp_path / "surface.nc")
    n50_fit.save(tmp_path / "cubics.nc")
    code = (
        "import sys\n"
        "from uq._derived.design import SealedDesign, design_point\n"
        "from uq._derived.margin import margin\n"
        "from uq._models.saved import load\n"
        f"for name in ('surface', 'cubics'):\n"
        f"    m = load({str(tmp_path)!r} + '/' + name + '.nc')\n"
        "    assert margin(m, 0.112, 13020.0)['pressure_bar_needed']['mean'] > 4.0\n"
        "    design_point(m.on_draws(200), SealedDesign(0.112, 5.0, 3.4))\n"
        "print(sorted(k for k in ('jax', 'arviz', 'optimistix', 'emcee') if k in sys.modules))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "[]"


def test_a_file_of_a_model_no_longer_registered_is_refused_in_one_line(
    plugged, n50_recordings, tmp_path
):
    from uq._io.errors import InputError
    from uq._models.saved import load

    path = fit_traditional(n50_recordings, seed=2).save(tmp_path / "t.nc")
    assert load(path).name == NAME
    registry.unregister(NAME)
    with pytest.raises(InputError, match=f"holds the model '{NAME}', which no registered model is"):
        load(path)
