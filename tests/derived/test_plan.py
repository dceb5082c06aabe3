"""uq plan's engine (uq._derived.plan, plan_frames, plan_targets): the closed-form preposterior
against the models' own likelihood and against a brute-force simulation, the greedy search on
cases whose best reading is known, layouts and targets.

No sampler runs here: the frames are built from their parts (the models' data and draws of the
noise parameters near the stand's budget), which is all the planner takes from a fit.
"""

from __future__ import annotations

import numpy as np
import pytest
from plan_helpers import cubic_builder as _cubic_builder
from plan_helpers import surface_builder as _surface_builder

import uq
from uq._data.stand_description import PAPER_STAND
from uq._derived import plan as P
from uq._derived import plan_search as E
from uq._derived.plan_targets import SealedInputs, parse_target
from uq._inference.float64 import jax, jnp
from uq._io.errors import InputError
from uq._models import cubic, pair, surface
from uq._physics.quantities import BAR_PA

HEIGHTS = np.round(np.arange(0.065, 0.1551, 0.015), 6)


@pytest.fixture(scope="module")
def pilot():
    """A small campaign of the smooth spring (three tests, 13 heights down and up)."""
    return uq.simulate(
        "n50-smooth", seed=3, layout=uq.Layout(pressures_bar=(2.0, 5.0, 8.0), step_m=0.015)
    )


# ----------------------------------------------------------------------------- the closed form


def _combined(builder, frame, new_bar, readings):
    """The surface model's PairData of the file and the planned readings, in the frame's basis
    (what fitting the combined campaign would give the likelihood), readings' values zero."""
    rec, d = builder.rec, builder.data
    o, g = builder.model(np.concatenate([builder.tested, new_bar]))
    T0, J = builder.tested.size, len(new_bar)
    xs = np.array([r.height_m for r in readings])
    ps = np.array([new_bar[r.test] for r in readings])
    idx = np.array([T0 + r.test for r in readings])
    x = np.concatenate([builder.x, xs])
    p = np.concatenate([builder.p, ps])
    Xf, Xl = surface.designs(o, g, x, p, np.concatenate([builder.test_index, idx]), T0 + J)
    force, lever = builder.reference(xs, ps)
    return pair.pair_data(
        Xf,
        Xl,
        np.concatenate([np.asarray(d.F), np.zeros(xs.size)]),
        np.concatenate([np.asarray(d.L), np.zeros(xs.size)]),
        np.concatenate([np.asarray(d.phat), force]),
        np.concatenate([np.asarray(d.feff_hat), lever]),
        p,
        rec.piston_area_m2,
        PAPER_STAND,
    )


def test_planned_precision_is_the_pair_likelihoods(pilot):
    """The frame's precision plus the planned readings' rank-2 blocks equals the precision of the
    (force, piston) pair likelihood (uq._models.pair.posterior) on the combined campaign, draw by
    draw: the whitening of a planned reading is the model's own."""
    builder, _ = _surface_builder(pilot, n_draws=4)
    new = np.array([3.5, 6.5])
    frame = builder.frame(new)
    readings = [E.Reading(0, 0.080), E.Reading(0, 0.110), E.Reading(1, 0.140), E.Reading(1, 0.140)]
    A = frame.precision + E.added_precision(frame, readings)
    d = _combined(builder, frame, new, readings)
    chol = jax.jit(jax.vmap(lambda th: pair.posterior(th, d).chol))(jnp.asarray(builder.theta))
    for s in range(frame.n_draws):
        L = np.asarray(chol[s])
        np.testing.assert_allclose(A[s], L @ L.T, rtol=1e-9, atol=1e-9 * np.abs(A[s]).max())


def test_now_frame_mean_is_the_models_posterior_mean(pilot):
    """With no planned reading the frame is the fitted model given theta: its mean is the pair
    likelihood's posterior mean (the readings as read), draw by draw."""
    builder, _ = _surface_builder(pilot, n_draws=4)
    frame = builder.frame()
    d = builder.data
    mean = jax.jit(jax.vmap(lambda th: pair.posterior(th, d).mean))(jnp.asarray(builder.theta))
    np.testing.assert_allclose(frame.mean, np.asarray(mean), rtol=1e-7, atol=1e-9)


def test_greedy_updates_match_the_exact_evaluation(pilot):
    """The search's rank-2 updates and the exact Cholesky evaluation of the same readings agree."""
    builder, _ = _surface_builder(pilot, n_draws=4)
    frame = builder.frame(np.array([3.5, 6.5]))
    targets = [parse_target("force@110mm,6.5bar"), parse_target("pressure_for@110mm,9000N")]
    path = E.search(frame, targets, HEIGHTS, max_readings=20, draws=4)
    exact = np.sqrt(E.evaluate(frame, targets, path.readings).mean(0))
    np.testing.assert_allclose(path.sd[-1], exact, rtol=1e-6)
    assert path.n_readings[-1] == len(path.readings) <= 20


@pytest.fixture(scope="module")
def wide_pilot():
    """Seven tests over 1..10 bar: the surface has its default orders already, so planned tests
    inside the range do not change the model (the preposterior is then the model's own)."""
    return uq.simulate(
        "n50-smooth",
        seed=4,
        layout=uq.Layout(pressures_bar=(1.0, 2.5, 4.0, 5.5, 7.0, 8.5, 10.0), step_m=0.015),
    )


def test_preposterior_against_brute_force_simulation(wide_pilot):
    """Simulate the planned readings from the prior predictive given theta (coefficients from the
    current posterior, readings with the pair's correlated noise), refit the linear part exactly with
    the model's own likelihood, and compare the mean squared error of the refitted targets with the
    predicted posterior variance: the linear force within Monte Carlo error (300 simulations per
    draw, about 8 % sd; pooled over 4 draws, tolerance 12 %), the linearised ones (the pressure that
    carries a load, the sealed natural frequency, the casing's magnitude) within 20 % (docs/plan.md:
    the delta method needs the current posterior to be narrow on the scale of the targets'
    curvature, as it is here)."""
    builder, _ = _surface_builder(wide_pilot, n_draws=4, seed=1)
    new = np.array([3.25, 6.25])
    frame = builder.frame(new)
    targets = [
        parse_target("force@110mm,6.5bar"),
        parse_target("pressure_for@110mm,9000N"),
        parse_target("natural_frequency@112mm,5bar", SealedInputs(volume_l=4.5)),
        parse_target("elastic_casing").with_range([1.0, 10.0]),
    ]
    readings = [E.Reading(0, h) for h in HEIGHTS] + [E.Reading(1, h) for h in HEIGHTS[::2]]
    predicted = E.evaluate(frame, targets, readings)  # (S, T)
    d = _combined(builder, frame, new, readings)
    n0 = builder.data.F.shape[0]
    xs = np.array([r.height_m for r in readings])
    ps = np.array([new[r.test] for r in readings])
    force, lever = builder.reference(xs, ps)
    dn = d._replace(
        phat=jnp.asarray(force),
        feff_hat=jnp.asarray(lever),
        dp_pa=d.dp_pa[n0:],
        p_abs_pa=d.p_abs_pa[n0:],
    )
    rng = np.random.default_rng(7)
    R = 300
    ratios = []
    for s in range(frame.n_draws):
        th = jnp.asarray(builder.theta[s])
        L11, L21, L22 = (np.asarray(a) for a in pair.cov_factors(th, dn))
        cov = np.linalg.inv(frame.precision[s])
        beta = rng.multivariate_normal(frame.mean[s], cov, size=R)  # (R, k)
        Xf, Xl = np.asarray(d.Xf)[n0:], np.asarray(d.Xl)[n0:]
        z1, z2 = rng.standard_normal((2, R, xs.size))
        Fn = beta @ Xf.T + L11 * z1
        Ln = beta @ Xl.T + L21 * z1 + L22 * z2
        F = np.concatenate([np.broadcast_to(np.asarray(d.F)[:n0], (R, n0)), Fn], axis=1)
        L = np.concatenate([np.broadcast_to(builder.data.L, (R, n0)), Ln], axis=1)
        mean = np.asarray(
            jax.jit(jax.vmap(lambda f, l, th=th: pair.posterior(th, d._replace(F=f, L=l)).mean))(
                jnp.asarray(F), jnp.asarray(L)
            )
        )
        truth = np.stack([t.linearise(frame, beta, np.ones(2, bool))[0] for t in targets], -1)
        fitted = np.stack([t.linearise(frame, mean, np.ones(2, bool))[0] for t in targets], -1)
        mse = np.mean((fitted - truth) ** 2, axis=0)
        ratios.append(mse / predicted[s])
    ratio = np.mean(ratios, axis=0)
    assert abs(ratio[0] - 1.0) < 0.12 and np.all(np.abs(ratio[1:] - 1.0) < 0.2), ratio


def test_cubic_frame_is_the_cubics_posterior(pilot):
    """The per-pressure cubics' frame: each file test's block is the cubic's conditional posterior
    given theta (uq._models.cubic), and a new test's block is its prior plus its readings with the
    noise of the nearest tested pressure at its own force level."""
    b = _cubic_builder(pilot)
    frame = b.frame(np.array([6.5]))
    for i, d in enumerate(b.datas):
        pf, pl = cubic.conditional_posteriors(jnp.asarray(b.theta[i][0]), d)
        Lf, Ll = np.asarray(pf.chol), np.asarray(pl.chol)
        np.testing.assert_allclose(
            frame.precision[0, 8 * i : 8 * i + 4, 8 * i : 8 * i + 4], Lf @ Lf.T, rtol=1e-9
        )
        np.testing.assert_allclose(
            frame.precision[0, 8 * i + 4 : 8 * i + 8, 8 * i + 4 : 8 * i + 8], Ll @ Ll.T, rtol=1e-9
        )
        np.testing.assert_allclose(frame.mean[0, 8 * i : 8 * i + 4], np.asarray(pf.mean), rtol=1e-8)
    hs = np.array([0.08, 0.11, 0.14])
    Z = frame.reading_rows(0, hs)[0]  # (n, 2, k)
    near = int(np.argmin(np.abs(b.tested - 6.5)))
    s0, rel, sL = (a[0] for a in b._noise[near])
    ref = np.abs(b.mean_force(hs, np.full(3, 6.5)))
    sd = np.sqrt(s0**2 + (rel * ref) ** 2)
    X = np.asarray(cubic.basis(hs - pilot.x0_m))
    np.testing.assert_allclose(Z[:, 0, 24:28], X / sd[:, None], rtol=1e-12)
    np.testing.assert_allclose(Z[:, 1, 28:32], X / sL, rtol=1e-12)


def test_cubic_force_rows_interpolate_feff_linearly_in_pressure(pilot):
    """The cubics' force at (x, p): a tested pressure's own cubic; between tests p times F_eff linear
    in p (uq._derived.margin.CubicInterpolation's rule), with the new tests made taking part."""
    b = _cubic_builder(pilot)
    frame = b.frame(np.array([6.5]))
    beta = frame.mean[:1]
    u = 0.11 - pilot.x0_m
    X = np.asarray(cubic.basis(np.array([u])))[0]
    at5 = frame.force_rows([0.11], [5.0], np.zeros(1, bool))[0]
    np.testing.assert_allclose(beta @ at5, beta[:, 8:12] @ X)
    mid = frame.force_rows([0.11], [6.5], np.zeros(1, bool))[0]
    f5, f8 = beta[:, 8:12] @ X / 5.0, beta[:, 16:20] @ X / 8.0
    np.testing.assert_allclose(beta @ mid, 6.5 * (0.5 * f5 + 0.5 * f8))
    opened = frame.force_rows([0.11], [6.5], np.ones(1, bool))[0]
    assert np.flatnonzero(opened).min() >= 24  # the new test's own cubic alone
    assert b.frame(np.array([6.5])).extra_force_var([0.11], [6.5], np.ones(1, bool))[0] == 0.0


# ----------------------------------------------------------------------------- the search


def _toy(rows, k=2):
    """A frame of k coefficients with unit prior, one draw, and new tests whose reading rows at
    heights h are rows[j](h) (r = 1); the force row is the first coefficient."""
    J = len(rows)
    return E.Frame(
        name="toy",
        label="toy",
        precision=np.eye(k)[None],
        mean=np.zeros((1, k)),
        tested_bar=np.array([1.0]),
        new_bar=np.arange(2.0, 2.0 + J),
        x0_m=0.1,
        reading_rows=lambda j, h: np.stack([rows[j](hh) for hh in np.atleast_1d(h)])[
            None, :, None, :
        ],
        force_rows=lambda x, p, o=None: np.tile(np.eye(k)[0], (np.size(x), 1)),
    )


def test_greedy_reads_the_most_informative_height_once_per_branch():
    """A reading at height h informs the target with weight h: the best reading is the highest
    height, read once on each branch, then the next; a test that informs only another coefficient
    is never made."""
    frame = _toy([lambda h: np.array([h, 0.0]), lambda h: np.array([0.0, 10 * h])])
    heights = np.array([0.5, 1.0, 2.0, 3.0])
    target = parse_target("force@100mm,1bar")
    path = E.search(frame, [target], heights, max_readings=10, cost_per_pressure=0.0, draws=1)
    assert {r.test for r in path.readings} == {0}
    assert [r.height_m for r in path.readings][:2] == [3.0, 3.0]
    assert sorted(r.height_m for r in path.readings) == [0.5, 0.5, 1.0, 1.0, 2.0, 2.0, 3.0, 3.0]
    # exact: 1 / (1 + sum h^2) after the eight readings of the informative test
    assert path.sd[-1][0] == pytest.approx((1.0 / (1.0 + 2 * (0.25 + 1 + 4 + 9))) ** 0.5)


def test_no_reading_helps_a_target_at_a_tested_pressure_of_the_cubics(pilot):
    """The per-pressure cubics answer at a tested pressure from that test alone, which the file
    holds whole: no reading of a new test changes it, so the search adds none, and a plan is refused
    with one line; a new test at the target's pressure with too few readings would do worse than
    interpolating between its neighbours (the frame says so)."""
    b = _cubic_builder(pilot)
    frame = b.frame(np.array([3.5, 6.5, 9.0]))
    at5 = parse_target("force@110mm,5bar")
    path = E.search(frame, [at5], HEIGHTS, max_readings=12, draws=8)
    assert path.readings == [] and path.stop.startswith("no reading")
    with pytest.raises(InputError, match="no planned reading reduces"):
        P.make_plan(b, [at5], HEIGHTS, np.array([3.5, 6.5]), max_readings=12, draws=8)
    at65 = parse_target("force@110mm,6.5bar")
    now = E.evaluate(frame, [at65]).mean()
    few = E.evaluate(frame, [at65], [E.Reading(1, h) for h in HEIGHTS]).mean()
    assert few > now


def test_a_costly_pressure_change_is_made_only_when_it_pays():
    """Two tests inform the target equally; with set-pressure changes free the search spreads over
    both, with a change costing 1000 readings it fills one test first."""
    frame = _toy([lambda h: np.array([h, 0.0]), lambda h: np.array([h, 0.0])])
    heights = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    target = parse_target("force@100mm,1bar")
    dear = E.search(frame, [target], heights, max_readings=10, cost_per_pressure=1000.0, draws=1)
    assert len({r.test for r in dear.readings}) == 1


# ----------------------------------------------------------------------------- plans and layouts


@pytest.mark.slow  # the plan's document: tests/cli/test_plan_command.py::test_json_has_the_contracts_keys
def test_make_plan_surface_states_now_after_and_the_comparisons(pilot):
    builder, _ = _surface_builder(pilot, n_draws=6)
    targets = [
        parse_target("force@110mm,6.5bar"),
        parse_target("elastic_casing").with_range([2, 5, 8]),
    ]
    plan = P.make_plan(
        builder, targets, HEIGHTS, np.array([1.0, 3.5, 6.5, 10.0]), max_readings=24, draws=6
    )
    assert plan.n_readings <= 24 and plan.n_pressure_changes >= 1
    assert all(s is not None and s > 0 for s in plan.sd_now + plan.sd_predicted)
    assert plan.paper["n_readings"] == 37 * 8  # the paper's pressures but 2, 5 and 8 bar
    doc = P.plan_document(plan)
    for key in ("model", "n_readings", "n_pressure_changes", "tests", "targets"):
        assert key in doc
    for t in doc["tests"]:
        assert set(t) >= {"pressure_bar", "heights_mm", "branches"}
        down = [
            h for h, b in zip(t["heights_mm"], t["branches"], strict=True) if b == "compression"
        ]
        up = [h for h, b in zip(t["heights_mm"], t["branches"], strict=True) if b == "rebound"]
        assert down == sorted(down, reverse=True) and up == sorted(up)
    for row in doc["targets"]:
        assert set(row) >= {
            "spec",
            "sd_now",
            "sd_predicted",
            "sd_uniform_grid",
            "sd_paper_protocol",
        }


def test_required_test_beyond_the_tested_pressures():
    t = parse_target("force@110mm,12bar")
    need = P.required_tests([t], [2.0, 5.0, 8.0], [1.0, 10.0, 12.0, 14.0])
    assert need.tolist() == [False, False, True, False]
    with pytest.raises(InputError, match="no candidate pressure is at or above"):
        P.required_tests([t], [2.0, 5.0, 8.0], [1.0, 10.0])


def test_recording_order_and_uniform_layout():
    readings = [E.Reading(1, 0.08), E.Reading(0, 0.1), E.Reading(1, 0.12), E.Reading(1, 0.08)]
    order = P.recording_order(readings, np.array([7.0, 3.0]))
    assert [t["pressure_bar"] for t in order] == [3.0, 7.0]
    assert order[0]["heights_m"] == [0.12, 0.08, 0.08] and order[1]["heights_m"] == [0.1]
    assert order[0]["branches"] == ["compression", "compression", "rebound"]
    ps, tests = P.uniform_readings(20, 2, [0.1, 1, 3, 4, 6, 7, 9, 10], HEIGHTS)
    assert ps.tolist() == [3.0, 7.0]
    assert sum(len(h) for _, h in tests) == 20
    _, tests = P.uniform_readings(16, 2, [3, 7], HEIGHTS, min_heights=5)
    for _, h in tests:  # 8 readings a test, 5 of them down: 5 distinct heights, none twice a branch
        assert h.size == 8 and P.distinct_heights(h) >= 5
        assert np.all(np.diff(h[:5]) < 0) and np.all(np.diff(h[5:]) > 0)


@pytest.mark.parametrize(
    "spec, match",
    [
        ("force@110mm", "expected force@H mm,P bar"),
        ("force@110,6.5bar", "not a number with a unit"),
        ("forces@110mm,6bar", "unknown target"),
        ("pressure_for@110mm,6bar", "expected pressure_for@H mm,W N"),
        ("elastic_casing@5bar", "two different positive pressures"),
        ("natural_frequency@112mm,5bar", "internal volume"),
    ],
)
def test_target_syntax_is_refused_in_one_line(spec, match):
    with pytest.raises(InputError, match=match):
        parse_target(spec)


def test_targets_parse():
    t = parse_target("pressure_for@0.11m,9kN")
    assert (t.height_m, t.load_N, t.unit) == (pytest.approx(0.11), 9000.0, "Pa")
    t = parse_target(
        "natural_frequency@112mm,5bar", SealedInputs(volume_l=5.0, polytropic=(1.0, 1.4))
    )
    n, v, w = t.sealed.nodes()
    assert w.sum() == pytest.approx(1.0) and n.min() > 1.0 and n.max() < 1.4
    with pytest.raises(InputError, match="file holds one test"):
        parse_target("elastic_casing").with_range([5.0])


# the identity's shared code path: test_planned_precision_is_the_pair_likelihoods
@pytest.mark.slow
@pytest.mark.parametrize("kind", ["thermodynamic", "force-only"])
def test_planned_precision_of_the_other_models(pilot, kind):
    """The same identity for the thermodynamic model (its travel factor scales the piston rows) and
    the force surface of a campaign without piston readings (one row per reading)."""
    from plan_helpers import model_precision, pair_builder

    from uq._data.recordings import recordings_from_text, write_recordings_csv
    from uq._models.thermo import ThermoFit
    from uq._stand.simulator import Layout, simulate

    if kind == "force-only":
        layout = Layout(pressures_bar=(2.0, 5.0, 8.0), step_m=0.015)
        text = write_recordings_csv(simulate("n50-smooth", seed=3, layout=layout), piston=False)
        rec = recordings_from_text(text, "force-only pilot")
        builder = pair_builder(rec, n_draws=3)
    else:
        builder = pair_builder(pilot, ThermoFit, n_draws=3)
    new = np.array([3.5, 6.5])
    frame = builder.frame(new)
    assert (frame.area_rows is None) == (kind == "force-only")
    readings = [E.Reading(0, 0.080), E.Reading(1, 0.110), E.Reading(1, 0.110)]
    A = frame.precision + E.added_precision(frame, readings)
    for s in range(frame.n_draws):
        want = model_precision(builder, new, readings, builder.theta[s])
        np.testing.assert_allclose(A[s], want, rtol=1e-9, atol=1e-9 * np.abs(want).max())


# ----------------------------------------------------------------------------- the targets' closed forms


def _element_frame(area_rows, force_rows):
    """A one-draw frame of two coefficients with the given force and area rows."""
    return E.Frame(
        name="toy",
        label="toy",
        precision=np.eye(2)[None],
        mean=np.zeros((1, 2)),
        tested_bar=np.array([1.0, 10.0]),
        new_bar=np.zeros(0),
        x0_m=0.112,
        reading_rows=None,
        force_rows=force_rows,
        area_rows=area_rows,
    )


def _inextensible():
    """P = p_u A(x), dV/dx = A(x), A = b0 + b1 t (t = (x - x0) / 0.05 m)."""

    def area(x, p, o=None):
        t = (np.asarray(x, float) - 0.112) / 0.05
        return np.stack([np.ones_like(t), t], axis=-1)

    def force(x, p, o=None):
        return area(x, p) * (np.asarray(p, float) * BAR_PA)[:, None]

    return _element_frame(area, force)


def test_natural_frequency_is_the_sealed_springs_and_its_gradient_exact():
    """For an inextensible element the sealed rate is n p_abs A^2 / V - p_u dA/dx
    (uq._physics.sealed.inextensible_rate): the target's value there, and its gradient against
    central differences in the coefficients."""
    from uq._physics.sealed import G_STANDARD, inextensible_rate

    frame = _inextensible()
    beta = np.array([[0.025, -0.002]])
    t = parse_target(
        "natural_frequency@120mm,5bar", SealedInputs(volume_l=4.0, polytropic=1.3, reservoir_l=1.0)
    )
    value, grad, extra = t.linearise(frame, beta, np.zeros(0, bool))
    tt = (0.120 - 0.112) / 0.05
    A, dA = beta[0, 0] + beta[0, 1] * tt, beta[0, 1] / 0.05
    k = inextensible_rate(5 * BAR_PA, A, dA, 4e-3, 1.3, 1e-3)
    want = np.sqrt(k * G_STANDARD / (5 * BAR_PA * A)) / (2 * np.pi)
    assert value[0] == pytest.approx(want, rel=1e-6)
    assert extra[0] == 0.0
    for j in range(2):
        h = 1e-7 * abs(beta[0, j])
        up, down = beta.copy(), beta.copy()
        up[0, j] += h
        down[0, j] -= h
        fd = (t.linearise(frame, up, None)[0] - t.linearise(frame, down, None)[0]) / (2 * h)
        assert grad[0, j] == pytest.approx(fd[0], rel=1e-5)


def test_natural_frequency_spread_of_a_polytropic_range_is_irreducible():
    frame = _inextensible()
    beta = np.array([[0.025, -0.002]])
    one = parse_target("natural_frequency@112mm,5bar", SealedInputs(volume_l=4.0, polytropic=1.2))
    rng = parse_target(
        "natural_frequency@112mm,5bar", SealedInputs(volume_l=4.0, polytropic=(1.0, 1.4))
    )
    assert one.linearise(frame, beta, None)[2][0] == 0.0
    spread = rng.linearise(frame, beta, None)[2][0]
    lo = parse_target("natural_frequency@112mm,5bar", SealedInputs(volume_l=4.0, polytropic=1.0))
    hi = parse_target("natural_frequency@112mm,5bar", SealedInputs(volume_l=4.0, polytropic=1.4))
    f_lo, f_hi = (x.linearise(frame, beta, None)[0][0] for x in (lo, hi))
    # a uniform n over the range: sd about (f_hi - f_lo) / sqrt(12) (f nearly linear in n)
    assert np.sqrt(spread) == pytest.approx(abs(f_hi - f_lo) / np.sqrt(12), rel=0.05)


def test_elastic_casing_reads_the_mechanisms_magnitude():
    """dV/dx = V0'(1 + m p_u) at x0 (docs/formats.md section 3): the target is m for any two
    pressures, and its gradient matches central differences."""

    def area(x, p, o=None):
        return np.stack([np.ones(np.size(p)), np.asarray(p, float)], axis=-1)

    frame = _element_frame(area, None)
    V0, m = 0.027, 0.013
    beta = np.array([[V0, V0 * m]])
    for pair_ in ((1.0, 10.0), (0.1, 4.0)):
        t = parse_target(f"elastic_casing@{pair_[0]}bar,{pair_[1]}bar")
        value, grad, _ = t.linearise(frame, beta, None)
        assert value[0] == pytest.approx(m, rel=1e-12)
        for j in range(2):
            h = 1e-6 * beta[0, j]
            up, down = beta.copy(), beta.copy()
            up[0, j] += h
            down[0, j] -= h
            fd = (t.linearise(frame, up, None)[0] - t.linearise(frame, down, None)[0]) / (2 * h)
            assert grad[0, j] == pytest.approx(fd[0], rel=1e-6)


def test_pressure_for_is_the_root_and_its_gradient_the_implicit_one():
    """P = p_u A with A = b0 + b1 t: the pressure carrying W at x is W / A(x) exactly."""
    frame = _inextensible()
    beta = np.array([[0.025, -0.002], [0.026, 0.001]])
    t = parse_target("pressure_for@100mm,12000N")
    value, grad, _ = t.linearise(frame, beta, np.zeros(0, bool))
    A = beta[:, 0] + beta[:, 1] * (0.100 - 0.112) / 0.05
    np.testing.assert_allclose(value, 12000.0 / A, rtol=1e-6)
    # d(W / A) / d b = -W / A^2 (1, t)
    want = -(12000.0 / A**2)[:, None] * np.array([1.0, (0.100 - 0.112) / 0.05])[None]
    np.testing.assert_allclose(grad, want, rtol=1e-4)


def test_target_sd_stops_where_the_sd_is_reached():
    """--target-sd: readings are added until the predicted sd is at most the target, no more. The
    toy's variance after readings at heights h is 1 / (1 + sum h^2): a new test's first batch is at
    least 8 readings (5, 5, 4, 4, 3, 3, 2, 2: 1 / 109), one more at 1 reaches 1 / 110."""
    frame = _toy([lambda h: np.array([h, 0.0])])
    heights = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    target = parse_target("force@100mm,1bar")
    tau = (1.0 / 110.0) ** 0.5
    path = E.search(frame, [target], heights, target_sd=[tau * 1.0001], draws=1)
    assert path.stop == "target sd reached"
    assert sorted(r.height_m for r in path.readings) == [1, 2, 2, 3, 3, 4, 4, 5, 5]
    assert path.n_readings == [0, 8, 9]
    assert path.sd[-1][0] == pytest.approx(tau) and path.sd[-2][0] > tau * 1.0001


# ----------------------------------------------------------------------------- the discrepancy's frames


@pytest.fixture(scope="module")
def table1_four():
    """A small campaign of Table 1's spring (not smooth in pressure): four tests every 15 mm."""
    return uq.simulate(
        "n50", seed=5, layout=uq.Layout(pressures_bar=(1.0, 4.0, 7.0, 10.0), step_m=0.015)
    )


def _first_tests(rec, n):
    """``rec`` with its first ``n`` tests (the file), the rest planned."""
    import dataclasses

    return dataclasses.replace(rec, tests=tuple(rec.tests[:n]))


def test_discrepancy_frame_is_the_models_posterior(table1_four):
    """The frame's precision and mean given theta, from the file alone, are the discrepancy model's
    own (uq._models.discrepancy.posterior: sum_i C_i' H_i C_i + I in the same coefficients)."""
    from plan_helpers import discrepancy_builder

    from uq._models import discrepancy as dev

    b = discrepancy_builder(table1_four, n_draws=3)
    frame = b.frame()
    posterior = jax.jit(dev.posterior)
    for s in range(frame.n_draws):
        post = posterior(jnp.asarray(b.theta[s]), b.data)
        L = np.asarray(post.chol)
        want = L @ L.T
        np.testing.assert_allclose(
            frame.precision[s], want, rtol=1e-8, atol=1e-8 * np.abs(want).max()
        )
        np.testing.assert_allclose(frame.mean[s], np.asarray(post.mean), rtol=1e-6, atol=1e-8)


# the frame's rows of a test: test_discrepancy_frame_is_the_models_posterior (the same code path)
@pytest.mark.slow
def test_discrepancy_planned_precision_is_the_models_on_the_combined_campaign(table1_four):
    """A planned test's readings add to the frame's precision exactly what the model's posterior
    of the combined campaign has (the planned readings' noise references the frame's)."""
    from plan_helpers import discrepancy_builder

    from uq._models import discrepancy as dev
    from uq._models.discrepancy_fit import p_ref_pa

    file = _first_tests(table1_four, 3)
    b = discrepancy_builder(file, n_draws=3)
    new = np.array([table1_four.tests[3].pressure_bar])
    frame = b.frame(new)
    hs = table1_four.tests[3].height_m
    readings = [E.Reading(0, float(h)) for h in hs]
    A = frame.precision + E.added_precision(frame, readings)
    o, _ = b.model(np.concatenate([b.tested, new]))
    d = dev.dev_data(table1_four, o, PAPER_STAND)
    force, lever = b.reference(hs, np.full(hs.shape, new[0]))
    n0 = file.n_points
    # phi's p_ref is the file's (the frame's theta draws are the file's fit's), not the combined
    # campaign's highest pressure: its columns scaled back (they are linear in p_ref)
    n_k = d.s.size
    D = np.asarray(d.D).copy()
    D[:, :, 2 * n_k :] *= p_ref_pa(b.tested) / p_ref_pa(np.concatenate([b.tested, new]))
    d = d._replace(  # the file's references are the file's fit's, the planned ones the frame's
        phat=jnp.concatenate([b.data.phat, jnp.asarray(force)]),
        feff_hat=jnp.concatenate([b.data.feff_hat, jnp.asarray(lever)]),
        D=jnp.asarray(D),
    )
    assert d.phat.shape[0] == n0 + hs.size
    for s in range(frame.n_draws):
        L = np.asarray(dev.posterior(jnp.asarray(b.theta[s]), d).chol)
        want = L @ L.T
        np.testing.assert_allclose(A[s], want, rtol=1e-8, atol=1e-8 * np.abs(want).max())


def test_discrepancy_between_tests_is_the_process_given_its_nodes(table1_four):
    """At an untested pressure the frame's force variance (kriging rows plus the conditional
    variance) equals that of a frame holding a test there without readings: a node the data do not
    touch changes nothing. And the conditional variance vanishes at a tested pressure."""
    from plan_helpers import discrepancy_builder

    b = discrepancy_builder(table1_four, n_draws=3, length_bar=1.0)
    target = [parse_target("force@110mm,5.5bar")]
    now = b.frame()
    with_node = b.frame([5.5], after_bar=b.tested)  # built after: each frame keeps its own nodes
    v_between = E.evaluate(now, target)
    v_node = E.evaluate(with_node, target)
    np.testing.assert_allclose(v_between, v_node, rtol=1e-6)
    frame = b.frame()
    extra = frame.extra_force_var(np.array([0.110, 0.110]), np.array([4.0, 5.5]))
    assert np.all(extra[:, 0] < 1e-6 * extra[:, 1]) and np.all(extra[:, 1] > 0)


# the frames' identities: test_discrepancy_frame_is_the_models_posterior and
# test_discrepancy_between_tests_is_the_process_given_its_nodes (a frame keeps its own nodes)
@pytest.mark.slow
def test_discrepancy_plan_tests_between_the_pilots_pressures(table1_four):
    """make_plan with the discrepancy's frames: a force target between the pilot's pressures gets a
    new test at its pressure (only there does the deviation's conditional variance go), with the
    distinct heights the model's per-test span needs, and its predicted sd below now's."""
    from plan_helpers import discrepancy_builder

    b = discrepancy_builder(table1_four, n_draws=4, length_bar=1.0)
    target = [parse_target("force@110mm,5.5bar")]
    plan = P.make_plan(b, target, HEIGHTS, [2.5, 5.5, 8.5], max_readings=16, draws=4)
    assert [t["pressure_bar"] for t in plan.tests] == [5.5]
    need = b.min_test_heights(b.model(np.append(b.tested, 5.5))[0])
    assert len(set(np.round(plan.tests[0]["heights_m"], 9))) >= need == 5
    assert plan.sd_predicted[0] < plan.sd_now[0]


def test_discrepancy_builder_on_other_theta_is_the_builder_of_those_draws(table1_four):
    """``with_theta`` (what scripts/plan_proof.py uses to measure what the new readings teach about
    theta): the pilot's builder on other draws predicts exactly what a builder made with those
    draws does, and leaves the original alone. And why it matters for this model: next to a
    planned test (0.037 bar from it, as the proof's pressure for 12000 N at 120 mm is from its
    5-bar test) the deviation's conditional variance, which only theta sets, is many times larger
    at a short length scale than at a long one."""
    from plan_helpers import discrepancy_builder

    b = discrepancy_builder(table1_four, n_draws=3, length_bar=1.0)
    other = discrepancy_builder(table1_four, n_draws=2, seed=1, length_bar=0.3)
    moved = b.with_theta(other.theta)
    target = [parse_target("force@110mm,5.5bar"), parse_target("force@120mm,4.963bar")]
    readings = [E.Reading(0, float(h)) for h in HEIGHTS]
    np.testing.assert_allclose(
        E.evaluate(moved.frame([5.0]), target, readings),
        E.evaluate(other.frame([5.0]), target, readings),
        rtol=1e-9,
    )
    np.testing.assert_allclose(moved.length, other.length)
    assert b.theta.shape[0] == 3 and b.length.shape == (3,)
    with pytest.raises(ValueError, match="theta must be"):
        b.with_theta(other.theta[:, :-1])
    theta = np.repeat(b.theta[:1], 2, axis=0)
    theta[:, -1] = np.log([0.25, 5.0])  # the length scale, bar
    extra = (
        b.with_theta(theta)
        .frame([5.0])
        .extra_force_var(np.array([0.120]), np.array([4.963]), np.array([True]))[:, 0]
    )
    assert extra[0] > 30 * extra[1]


def test_every_planned_test_has_the_heights_the_combined_campaigns_orders_need():
    """Issue 31: the model fitted after the plan takes the orders of the combined campaign (the
    pilot's three tests and the planned ones: F_p 3x1 becomes F_p 3x3), and the discrepancy refuses
    a test with fewer distinct heights than those orders need (5 with piston readings). Every test
    of the plan, and of the uniform grid it is compared with (the same 16 readings over two tests:
    8 a test, laid out 4 down and 4 up before the fix), holds them, and each is evaluated in the
    frame of those orders."""
    from plan_helpers import discrepancy_builder

    from uq._data.recordings import recordings_from_text, write_recordings_csv
    from uq._models import discrepancy as dev
    from uq._stand import simulator

    layout = uq.Layout(pressures_bar=(1.0, 4.0, 7.0), step_m=0.015)
    pilot_tests = simulator.simulate("n50", seed=5, layout=layout)
    pilot = recordings_from_text(write_recordings_csv(pilot_tests, "pilot"), "pilot")
    b = discrepancy_builder(pilot, n_draws=3, length_bar=1.0)
    targets = [parse_target("force@110mm,0.5bar"), parse_target("force@110mm,9bar")]
    plan = P.make_plan(b, targets, HEIGHTS, [0.5, 5.5, 9.0], max_readings=16, draws=3)
    assert plan.n_pressure_changes == 2 and plan.heights_added == []
    layouts = {
        "plan": [(t["pressure_bar"], np.asarray(t["heights_m"]) * 1e3) for t in plan.tests],
        "uniform grid": list(
            zip(plan.uniform["pressures_bar"], plan.uniform["heights_mm"], strict=True)
        ),
    }
    assert plan.uniform["n_readings"] == plan.n_readings == 16
    for name, tests in layouts.items():
        planned = [
            {
                "pressure_bar": p,
                "heights_mm": list(h),
                "branches": ["compression"] * P._n_down(h) + ["rebound"] * (len(h) - P._n_down(h)),
            }
            for p, h in tests
        ]
        new = simulator.simulate_planned("n50", planned, seed=1)
        combined = recordings_from_text(write_recordings_csv(pilot_tests + new, name), name)
        orders = surface.orders_for(combined)
        assert orders != surface.orders_for(pilot)  # the orders change with the new tests
        need = dev.min_heights_needed(orders, combined.has_piston)
        assert need == plan.min_heights_per_test == 5
        for t in combined.tests:
            have = np.unique(np.round(t.height_m, 9)).size
            assert have >= need, f"{name}: the {t.pressure_bar:g}-bar test has {have} heights"
    frame = b.frame([0.5, 9.0], new_heights=[h * 1e-3 for _, h in layouts["plan"]])
    assert frame.label == plan.label


def test_a_test_short_of_heights_is_completed_and_said():
    """A layout whose test visits fewer distinct heights than the combined campaign's orders need
    (a hand-made one: the search never makes it) gets compression readings at the heights it
    misses, spread evenly, and a note saying so."""
    from plan_helpers import discrepancy_builder

    b = discrepancy_builder(_first_tests(_table1_small(), 3), n_draws=2)
    short = [(9.0, np.array([0.155, 0.110, 0.065, 0.110]))]
    tests, need, notes = P.complete_tests(b, short, HEIGHTS)
    assert need == 5
    h = tests[0][1]
    assert P.distinct_heights(h) == 5 and h.size == 6
    assert np.all(np.diff(h[:5]) < 0) and h[-1] == 0.110  # the rebound reading stays last
    assert (
        len(notes) == 1
        and "9-bar test: 2 reading(s) on compression added at 125, 95 mm" in notes[0]
    )
    with pytest.raises(InputError, match="needs 5 distinct heights"):
        P.complete_tests(b, short, [0.155, 0.110, 0.065, 0.08])


def _table1_small():
    return uq.simulate("n50", seed=5, layout=uq.Layout(pressures_bar=(1.0, 4.0, 7.0), step_m=0.015))
