"""Where to measure next: the preposterior analysis behind ``uq plan`` (docs/plan.md).

Given its sampled parameters theta (noise scales, a travel factor), every model of ``uq`` is
linear-Gaussian in its coefficients beta: the posterior precision after a set of readings is

    A(theta) + sum_i Z_i(theta)' Z_i(theta),

with A(theta) what the file already says (prior plus its readings) and Z_i the whitened design
rows of reading i (two rows, force and piston, for the models of the (force, piston) pair: their
errors are correlated through the pressure holding, so a reading is a rank-2 update). It does not
depend on the readings' values. So the posterior variance a planned set of readings would give a
target g' beta is known in closed form for every draw of theta, and its expectation over the
current posterior of theta is an average of closed forms (a preposterior analysis, no simulation):

    E[var(target | new readings)] ~= mean over draws theta_s of  g_s' (A_s + sum Z' Z)^-1 g_s.

Nonlinear targets are linearised at the posterior mean given theta (``uq._derived.plan_targets``).
What this leaves out (docs/plan.md says when it matters, reports/plan-proof/ measures it): the
spread of the posterior mean over theta (reported now as ``sd_now_theta_spread``), and that the
new readings also teach theta (a noise scale poorly known from a small pilot moves).

The model is a :class:`Frame`: per draw of theta the precision and mean from what the file holds,
the whitened rows of a reading at any height of any candidate test, and the rows of the force and
the volume-derived area at any (height, pressure) in the coefficients. Frames are built from a
fitted model by ``uq._derived.plan_frames``; everything here is numpy.

The search (:func:`search`) is greedy by gain per cost: a reading at a test already planned costs
one reading; a new test (a set-pressure change) costs ``cost_per_pressure`` readings more and is
judged by its best batch of at least ``MIN_TEST_READINGS`` readings (an inner greedy looks ahead
within the test), so one reading's small gain does not hide a test's large one. A test visits each
height at most twice (once on compression, once on rebound, as the paper's procedure does). All
draws are updated by rank-r Sherman-Morrison-Woodbury steps, vectorised over draws and candidates;
the covariance is recomputed from the accumulated precision every ``REFRESH_EVERY`` readings, and
every number reported is recomputed exactly by Cholesky (:func:`evaluate`).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from uq._io.errors import InputError

MIN_TEST_READINGS = 8  # a new test: at least 4 heights down and up (the surface keeps its cubic)
MAX_PER_HEIGHT = 2  # once on compression, once on rebound
COST_PER_PRESSURE = 10.0  # readings a set-pressure change costs (charging and settling)
REFRESH_EVERY = 25
MAX_PLAN_READINGS = 2000  # the search's cap under --target-sd
SEARCH_DRAWS = 100  # draws of theta the search uses (every reported number uses all)


@dataclass(frozen=True, eq=False)
class Frame:
    """A model as the planner sees it (module docstring): S draws of theta, k coefficients.

    precision (S, k, k), mean (S, k): the coefficients' posterior given each draw, from the file's
    readings and the prior of every coefficient (those of tests not yet made included).
    tested_bar (T0,): the file's tests; new_bar (J,): the tests the frame can add, one per pressure.
    reading_rows(j, heights_m (n,)) -> (S, n, r, k): whitened rows of one reading at each height of
    new test j (r = 2: force and piston; 1 for a force-only model).
    force_rows(x (n,), p (n,), open (J,) bool) -> (n, k): the mean force at (x, p) is rows @ beta,
    with the new tests ``open`` made (an interpolating model's rows depend on which tests exist:
    ``rows_follow_tests``); area_rows the same for dV/dx (None: the model has no volume, and
    ``volume_why`` says why); extra_force_var(x, p, open) -> (n,) N^2 the force's variance no
    reading at other pressures reduces (an interpolation error), or None.
    """

    name: str
    label: str
    precision: np.ndarray
    mean: np.ndarray
    tested_bar: np.ndarray
    new_bar: np.ndarray
    x0_m: float
    reading_rows: Callable
    force_rows: Callable
    area_rows: Callable | None = None
    extra_force_var: Callable | None = None
    rows_follow_tests: bool = False
    volume_why: str = ""
    key: tuple = ()

    @property
    def n_draws(self) -> int:
        return self.precision.shape[0]

    def pressure_range(self, open_) -> tuple[float, float]:
        p = np.concatenate([self.tested_bar, self.new_bar[np.asarray(open_, bool)]])
        return float(p.min()), float(p.max())

    def thinned(self, n: int) -> Frame:
        """The frame on at most ``n`` of its draws (evenly spaced)."""
        S = self.n_draws
        if S <= n:
            return self
        idx = np.linspace(0, S - 1, n).round().astype(int)
        rows = self.reading_rows

        def reading_rows(j, heights_m):
            return rows(j, heights_m)[idx]

        return replace(
            self, precision=self.precision[idx], mean=self.mean[idx], reading_rows=reading_rows
        )


@dataclass(frozen=True)
class Reading:
    """One planned reading: new test ``test`` (index into ``Frame.new_bar``) at height ``height_m``."""

    test: int
    height_m: float


# ----------------------------------------------------------------------------- exact evaluation


def target_columns(frame: Frame, targets, open_) -> tuple[np.ndarray, np.ndarray]:
    """Gradients (S, k, T) and irreducible variances (S, T) of the targets, linearised at the
    frame's posterior mean given each draw."""
    G, E = [], []
    for t in targets:
        _, g, e = t.linearise(frame, frame.mean, open_)
        G.append(g)
        E.append(e)
    return np.stack(G, axis=-1), np.stack(E, axis=-1)


def target_values(frame: Frame, targets, open_) -> np.ndarray:
    """Each target at the posterior mean given each draw, (S, T)."""
    return np.stack([t.linearise(frame, frame.mean, open_)[0] for t in targets], axis=-1)


def added_precision(frame: Frame, readings) -> np.ndarray:
    """sum Z' Z of ``readings`` per draw, (S, k, k)."""
    k = frame.precision.shape[-1]
    out = np.zeros((frame.n_draws, k, k))
    by_test: dict[int, list[float]] = {}
    for r in readings:
        by_test.setdefault(r.test, []).append(r.height_m)
    for j, hs in by_test.items():
        Z = frame.reading_rows(j, np.asarray(hs, float))  # (S, n, r, k)
        Z = Z.reshape(Z.shape[0], -1, k)
        out += np.einsum("sik,sil->skl", Z, Z)
    return out


def opened(frame: Frame, readings) -> np.ndarray:
    o = np.zeros(frame.new_bar.size, bool)
    o[[r.test for r in readings]] = True
    return o


def evaluate(frame: Frame, targets, readings=()) -> np.ndarray:
    """The targets' posterior variance given each draw of theta after ``readings``, exactly
    (Cholesky of the summed precision), (S, T); NaN for a target the tests do not reach."""
    readings = list(readings)
    open_ = opened(frame, readings)
    G, E = target_columns(frame, targets, open_)
    A = frame.precision + added_precision(frame, readings)
    L = np.linalg.cholesky(A)
    W = np.linalg.solve(L, G)  # (S, k, T): L^-1 g
    return np.sum(W**2, axis=1) + E


# ----------------------------------------------------------------------------- the search


@dataclass
class PlanPath:
    """What the search did: the readings in the order chosen, and after each move the readings,
    set-pressure changes and each target's predicted sd (in the search's frame)."""

    readings: list = field(default_factory=list)
    n_readings: list = field(default_factory=list)
    n_changes: list = field(default_factory=list)
    sd: list = field(default_factory=list)
    stop: str = ""


class _Search:
    """State of the greedy search, per draw of theta (module docstring)."""

    def __init__(self, frame, targets, heights_m, scale2, target_var, cost, required, max_tests):
        self.f, self.targets = frame, list(targets)
        self.max_tests = max_tests
        self.h = np.asarray(heights_m, float)
        self.cost = float(cost)
        self.scale2 = np.asarray(scale2, float)  # objective: sum var / scale^2
        self.tau2 = None if target_var is None else np.asarray(target_var, float)
        J, H = frame.new_bar.size, self.h.size
        self.open = np.zeros(J, bool)
        self.counts = np.zeros((J, H), int)
        self.required = np.asarray(required, bool)
        Z = np.stack([frame.reading_rows(j, self.h) for j in range(J)], axis=1)
        self.Z = Z  # (S, J, H, r, k)
        self.S, _, _, self.r, self.k = Z.shape
        self.prec = frame.precision.copy()
        self.since_refresh = 0
        self._refresh()

    # ---- exact recomputation from the accumulated precision
    def _refresh(self):
        L = np.linalg.cholesky(self.prec)
        Li = np.linalg.inv(L)
        self.cov = np.einsum("sji,sjk->sik", Li, Li)
        self._targets()
        S, J, H, r, k = self.Z.shape
        Zf = self.Z.reshape(S, J, H * r, k)
        self.CC = np.einsum("sjak,skl,sjbl->sjab", Zf, self.cov, Zf, optimize=True)
        self.since_refresh = 0

    def _targets(self, open_=None):
        open_ = self.open if open_ is None else open_
        self.G, self.E = target_columns(self.f, self.targets, open_)
        self.SG = self.cov @ self.G  # (S, k, T)
        self.v = np.sum(self.G * self.SG, axis=1) + self.E  # (S, T)
        self.CG = np.einsum("sjhrk,skt->sjhrt", self.Z, self.SG, optimize=True)

    # ---- the objective of mean variances (..., T)
    def objective(self, vbar):
        if self.tau2 is None:
            return np.sum(vbar / self.scale2, axis=-1)
        return np.sum(np.maximum(vbar, self.tau2) / self.tau2, axis=-1)

    def met(self) -> bool:
        return self.tau2 is not None and bool(np.all(self.v.mean(0) <= self.tau2 * (1 + 1e-9)))

    # ---- moves
    def _blocks(self, CC):
        """The r x r diagonal blocks of CC (..., H r, H r) -> (..., H, r, r)."""
        H, r = self.h.size, self.r
        idx = np.arange(H)[:, None] * r + np.arange(r)[None, :]
        return CC[..., idx[:, :, None], idx[:, None, :]]

    def singles(self):
        """Best single reading at a test already opened: (gain per cost, j, h) or None."""
        js = np.flatnonzero(self.open)
        if js.size == 0:
            return None
        M = self._blocks(self.CC[:, js]) + np.eye(self.r)  # (S, Jo, H, r, r)
        b = self.CG[:, js]  # (S, Jo, H, r, T)
        delta = np.einsum("sjhrt,sjhrt->sjht", b, np.linalg.solve(M, b))
        after = self.objective((self.v[:, None, None, :] - delta).mean(0))  # (Jo, H)
        after = np.where(self.counts[js] >= MAX_PER_HEIGHT, np.inf, after)
        i = np.unravel_index(np.argmin(after), after.shape)
        gain = self.objective(self.v.mean(0)) - after[i]
        return gain, int(js[i[0]]), int(i[1])

    def openings(self, budget: int):
        """Best new test: (gain per cost, j, heights chosen) by an inner greedy within each
        unopened test, vectorised over tests, looked ahead to ``budget`` readings."""
        js = np.flatnonzero(~self.open)
        if js.size == 0 or budget < MIN_TEST_READINGS or self.open.sum() >= self.max_tests:
            return None
        if self.required.any():  # tests the targets need come first
            js = js[self.required[js]]
        H, r = self.h.size, self.r
        m_max = min(budget, MAX_PER_HEIGHT * H)
        S = self.S
        if self.f.rows_follow_tests:  # the targets' rows change when a test is added
            per = [self._with_test(j) for j in js]
            v = np.stack([p[0] for p in per], axis=1)  # (S, Ju, T)
            CG = np.stack([p[1] for p in per], axis=1)  # (S, Ju, H, r, T)
        else:
            v = np.repeat(self.v[:, None], js.size, axis=1)
            CG = self.CG[:, js]
        CG = CG.reshape(S, js.size, H * r, -1).copy()
        CC = self.CC[:, js].copy()
        counts = np.zeros((js.size, H), int)
        start = self.objective(self.v.mean(0))
        path = np.empty((js.size, m_max))
        chosen = np.empty((js.size, m_max), int)
        lane = np.arange(js.size)
        for m in range(m_max):
            M = self._blocks(CC) + np.eye(r)  # (S, Ju, H, r, r)
            b = CG.reshape(S, js.size, H, r, -1)
            sol = np.linalg.solve(M, b)
            delta = np.einsum("sjhrt,sjhrt->sjht", b, sol)
            after = self.objective((v[:, :, None, :] - delta).mean(0))  # (Ju, H)
            after = np.where(counts >= MAX_PER_HEIGHT, np.inf, after)
            h = np.argmin(after, axis=1)
            path[:, m], chosen[:, m] = after[lane, h], h
            counts[lane, h] += 1
            # rank-r update of each lane with its own reading
            cols = h[:, None] * r + np.arange(r)[None, :]  # (Ju, r)
            Y = CC.transpose(1, 3, 0, 2)[lane[:, None], cols].transpose(
                2, 0, 3, 1
            )  # (S, Ju, Hr, r)
            Minv = np.linalg.inv(M[:, lane, h])  # (S, Ju, r, r)
            bh = b[:, lane, h]  # (S, Ju, r, T)
            CG -= Y @ (Minv @ bh)
            CC -= Y @ Minv @ np.swapaxes(Y, -1, -2)
            v -= delta[:, lane, h]
        m_all = np.arange(1, m_max + 1)
        ratio = (start - path) / (m_all[None, :] + self.cost)
        ratio[:, : MIN_TEST_READINGS - 1] = -np.inf
        i = np.unravel_index(np.argmax(ratio), ratio.shape)
        m = i[1] + 1
        return ratio[i], int(js[i[0]]), [int(c) for c in chosen[i[0], :m]]

    def _with_test(self, j):
        open_ = self.open.copy()
        open_[j] = True
        G, E = target_columns(self.f, self.targets, open_)
        SG = self.cov @ G
        v = np.sum(G * SG, axis=1) + E
        CG = np.einsum("shrk,skt->shrt", self.Z[:, j], SG, optimize=True)
        return v, CG

    def add(self, j: int, h: int):
        """Add one reading (rank-r update of every draw's state)."""
        Z = self.Z[:, j, h]  # (S, r, k)
        U = self.cov @ np.swapaxes(Z, -1, -2)  # (S, k, r)
        M = np.eye(self.r) + Z @ U
        Minv = np.linalg.inv(M)
        bjh = self.CG[:, j, h]  # (S, r, T)
        S, J, H, r, k = self.Z.shape
        Y = np.einsum("sjhrk,skq->sjhrq", self.Z, U, optimize=True)  # (S, J, H, r, r)
        self.cov -= U @ Minv @ np.swapaxes(U, -1, -2)
        self.SG -= U @ (Minv @ bjh)
        self.v -= np.einsum("srt,srq,sqt->st", bjh, Minv, bjh)
        self.CG -= np.einsum("sjhrq,sqp,spt->sjhrt", Y, Minv, bjh, optimize=True)
        Yf = Y.reshape(S, J, H * r, r)
        self.CC -= np.einsum("sjaq,sqp,sjbp->sjab", Yf, Minv, Yf, optimize=True)
        self.prec += np.swapaxes(Z, -1, -2) @ Z
        self.counts[j, h] += 1
        self.since_refresh += 1

    def open_test(self, j: int):
        self.open[j] = True
        self.required[j] = False
        if self.f.rows_follow_tests:
            self._targets()

    def sd(self) -> list[float]:
        return [float(x) for x in np.sqrt(np.maximum(self.v.mean(0), 0.0))]


def search(
    frame: Frame,
    targets,
    heights_m,
    *,
    max_readings: int | None = None,
    target_sd=None,
    cost_per_pressure: float = COST_PER_PRESSURE,
    required=None,
    draws: int = SEARCH_DRAWS,
    max_tests: int | None = None,
    scale2=None,
) -> PlanPath:
    """The greedy search (module docstring) over readings at ``heights_m`` of the frame's new tests.

    Stops at ``max_readings`` readings, or when every target's predicted sd is at most its entry of
    ``target_sd`` (target units; ``MAX_PLAN_READINGS`` at most), or when no reading helps.
    ``required`` (J,) bool: new tests the plan must make (the targets lie beyond the tested
    pressures, and the models do not extrapolate): they are opened first. ``max_tests``: at most
    this many new tests. ``scale2`` (T,): the objective sum var / scale2 (default: each target's
    variance in the frame before any reading)."""
    if (max_readings is None) == (target_sd is None):
        raise ValueError("give max_readings or target_sd")
    f = frame.thinned(draws)
    J = frame.new_bar.size
    required = np.zeros(J, bool) if required is None else np.asarray(required, bool)
    if scale2 is None:
        v0 = evaluate(f, targets).mean(0)
        scale2 = np.where(np.isfinite(v0) & (v0 > 0), v0, 1.0)
    tau2 = None if target_sd is None else np.asarray(target_sd, float) ** 2
    max_tests = J if max_tests is None else int(max_tests)
    st = _Search(f, targets, heights_m, scale2, tau2, cost_per_pressure, required, max_tests)
    cap = MAX_PLAN_READINGS if max_readings is None else int(max_readings)
    path = PlanPath()
    n = 0

    def record():
        path.n_readings.append(n)
        path.n_changes.append(int(st.open.sum()))
        path.sd.append(st.sd())

    record()
    while True:
        if st.met():
            path.stop = "target sd reached"
            break
        left = cap - n
        if left <= 0:
            path.stop = "max readings" if max_readings is not None else "cap"
            break
        one = st.singles() if not st.required.any() else None
        new = st.openings(left)
        best_one = -np.inf if one is None else one[0]
        best_new = -np.inf if new is None else new[0]
        current = st.objective(st.v.mean(0))
        if max(best_one, best_new) <= 1e-12 * max(current, 1e-300):
            path.stop = "no reading reduces the targets' variance further"
            break
        if best_new > best_one:
            _, j, hs = new
            st.open_test(j)
            for h in hs:
                st.add(j, h)
                path.readings.append(Reading(j, float(st.h[h])))
            n += len(hs)
        else:
            _, j, h = one
            st.add(j, h)
            path.readings.append(Reading(j, float(st.h[h])))
            n += 1
        if st.since_refresh >= REFRESH_EVERY:
            st._refresh()
        record()
    return path


# ----------------------------------------------------------------------------- layouts


def recording_order(readings, new_bar, heights_only: bool = False):
    """The planned tests in recording order (ascending pressure; in each, compression from the
    highest height down, then rebound up: a height read twice is read once on each branch):
    [{"test": j, "pressure_bar", "heights_m", "branches"}]."""
    by: dict[int, list[float]] = {}
    for r in readings:
        by.setdefault(r.test, []).append(r.height_m)
    out = []
    for j in sorted(by, key=lambda j: new_bar[j]):
        hs = np.asarray(by[j])
        uniq, count = np.unique(np.round(hs, 9), return_counts=True)
        down = uniq[::-1]
        up = uniq[count >= 2]
        heights = np.concatenate([down, up])
        branches = ["compression"] * down.size + ["rebound"] * up.size
        out.append(
            {
                "test": j,
                "pressure_bar": float(new_bar[j]),
                "heights_m": heights.tolist(),
                "branches": branches,
            }
        )
    return out


def spread(n: int, values) -> np.ndarray:
    """``n`` of ``values`` (sorted) spread evenly, ends included."""
    values = np.sort(np.asarray(values, float))
    if n >= values.size:
        return values
    if n == 1:
        return values[[values.size // 2]]
    return values[np.round(np.linspace(0, values.size - 1, n)).astype(int)]


def uniform_pressures(n: int, pressures_bar) -> np.ndarray:
    """``n`` of ``pressures_bar`` spread evenly: the candidates nearest the midpoints of ``n`` equal
    parts of their range (distinct)."""
    values = np.sort(np.asarray(pressures_bar, float))
    if n >= values.size:
        return values
    lo, hi = values[0], values[-1]
    want = lo + (hi - lo) * (np.arange(n) + 0.5) / n
    left = list(values)
    out = []
    for w in want:
        i = int(np.argmin(np.abs(np.asarray(left) - w)))
        out.append(left.pop(i))
    return np.sort(np.asarray(out))


def uniform_readings(n_readings: int, n_tests: int, pressures_bar, heights_m):
    """A uniform grid of ``n_readings`` readings over ``n_tests`` new tests: the tests' pressures
    spread evenly over ``pressures_bar`` (:func:`uniform_pressures`); in each test its share of the
    readings at heights spread evenly, down then up (each height at most once per branch).
    Returns (pressures, [(p, heights)])."""
    ps = uniform_pressures(n_tests, pressures_bar)
    share = np.full(ps.size, n_readings // ps.size)
    share[: n_readings % ps.size] += 1
    tests = []
    for p, m in zip(ps, share, strict=True):
        m = int(min(m, MAX_PER_HEIGHT * len(heights_m)))
        down = spread((m + 1) // 2, heights_m)
        up = spread(m // 2, heights_m)
        tests.append((float(p), np.concatenate([down[::-1], up])))
    return ps, tests


def readings_at(frame: Frame, tests) -> list[Reading]:
    """Readings of ``tests`` [(pressure_bar, heights_m)] as :class:`Reading` of the frame's new tests."""
    out = []
    for p, hs in tests:
        j = int(np.argmin(np.abs(frame.new_bar - p)))
        if abs(frame.new_bar[j] - p) > 1e-9:
            raise ValueError(f"the frame has no new test at {p:g} bar")
        out += [Reading(j, float(h)) for h in hs]
    return out


def required_tests(targets, tested_bar, candidates_bar) -> np.ndarray:
    """(J,) bool: the candidate tests the targets need because they lie beyond the tested pressures
    (for each target pressure outside them, the nearest candidate at or beyond it); InputError when
    no candidate reaches one."""
    tested = np.asarray(tested_bar, float)
    cand = np.asarray(candidates_bar, float)
    need = np.zeros(cand.size, bool)
    for t in targets:
        for p in t.fixed_pressures():
            if tested.min() - 1e-9 <= p <= tested.max() + 1e-9:
                continue
            above = p > tested.max()
            ok = cand >= p - 1e-9 if above else cand <= p + 1e-9
            if not ok.any() and not need.any():
                pass
            covered = need & ok
            if covered.any():
                continue
            if not ok.any():
                side = "at or above" if above else "at or below"
                raise InputError(
                    f"candidates_bar: target {t.spec}: {p:g} bar lies outside the tested pressures "
                    f"{tested.min():g}..{tested.max():g} bar and no candidate pressure is {side} it "
                    "(the models do not extrapolate): add one",
                    param="candidates_bar",
                )
            idx = np.flatnonzero(ok)
            need[idx[np.argmin(np.abs(cand[idx] - p))]] = True
    return need


# ----------------------------------------------------------------------------- the plan


@dataclass
class Plan:
    """What ``uq plan`` answers (docs/plan.md, docs/formats.md): the readings to add in recording
    order, what they cost, each target's predicted sd now and after them, and the same for a uniform
    grid of the same size and for the paper's full protocol. sd values are per target, in its unit
    (None where the model cannot answer: a target outside the tested pressures now)."""

    model: str
    label: str
    label_now: str
    targets: list
    readings: list
    tests: list
    n_readings: int
    n_pressure_changes: int
    cost_per_pressure: float
    value_now: list
    sd_now: list
    sd_now_theta_spread: list
    sd_predicted: list
    uniform: dict
    paper: dict
    path: PlanPath
    curves: dict
    target_sd: list | None = None
    n_draws: int = 0
    tried: list = field(default_factory=list)

    @property
    def cost(self) -> float:
        return self.n_readings + self.cost_per_pressure * self.n_pressure_changes

    @property
    def reached(self) -> list | None:
        if self.target_sd is None:
            return None
        return [
            bool(s <= t * (1 + 1e-9))
            for s, t in zip(self.sd_predicted, self.target_sd, strict=True)
        ]


def _sd(v) -> list:
    """Mean variance over draws -> sd per target (None where undefined)."""
    m = np.mean(v, axis=0)
    return [float(np.sqrt(x)) if np.isfinite(x) and x >= 0 else None for x in m]


def _now(builder, targets):
    """The targets as the fitted model answers now: value, theta-averaged sd, spread over theta."""
    frame = builder.frame()
    lo, hi = frame.pressure_range(np.zeros(0, bool))
    v = evaluate(frame, targets)
    vals = target_values(frame, targets, np.zeros(0, bool))
    out = {"value": [], "sd": [], "spread": []}
    for i, t in enumerate(targets):
        inside = all(lo - 1e-9 <= p <= hi + 1e-9 for p in t.fixed_pressures())
        ok = inside and np.all(np.isfinite(vals[:, i])) and np.isfinite(v[:, i]).all()
        out["value"].append(float(np.mean(vals[:, i])) if ok else None)
        out["sd"].append(float(np.sqrt(np.mean(v[:, i]))) if ok else None)
        out["spread"].append(float(np.std(vals[:, i])) if ok else None)
    return frame, out


def _layout(builder, targets, tests) -> tuple[list, np.ndarray, Frame]:
    """Readings of ``tests`` [(pressure_bar, heights)] in their own frame, and the variances."""
    ps = np.array([p for p, _ in tests], float)
    frame = builder.frame(ps)
    readings = readings_at(frame, tests)
    return readings, evaluate(frame, targets, readings), frame


def paper_tests(tested_bar, heights_m=None):
    """The paper's protocol (section 3.4) at its pressures not yet tested: 155 -> 65 -> 155 mm in
    5 mm steps (37 readings a test)."""
    from uq._data.reference import PAPER_PRESSURES_BAR, PAPER_X_MAX_M, PAPER_X_MIN_M

    down = np.round(np.arange(PAPER_X_MAX_M, PAPER_X_MIN_M - 1e-9, -0.005), 6)
    hs = np.concatenate([down, down[::-1][1:]])
    tested = np.asarray(tested_bar, float)
    return [(float(p), hs) for p in PAPER_PRESSURES_BAR if not np.any(np.abs(tested - p) < 1e-9)]


def make_plan(
    builder,
    targets,
    heights_m,
    candidates_bar,
    *,
    max_readings: int | None = None,
    target_sd=None,
    cost_per_pressure: float = COST_PER_PRESSURE,
    draws: int = SEARCH_DRAWS,
) -> Plan:
    """Plan with a model's frames (``uq._derived.plan_frames``): the readings at ``heights_m`` of new
    tests at ``candidates_bar`` that make the targets' predicted sd smallest for the readings and
    set-pressure changes spent (module docstring).

    A model over all tests is refitted with orders and a pressure scaling that depend on how many
    tests the campaign has and which pressures they span (``uq._models.surface.default_orders``):
    adding tests can widen the model and with it the bands. So the search is run for each number of
    new tests, in the frame of that campaign (twice when the chosen pressures change the scaling),
    and every plan is evaluated exactly in its own frame; the best is kept (least objective at the
    budget, or least stand time reaching ``target_sd``)."""
    targets = list(targets)
    cand = np.sort(np.asarray(candidates_bar, float))
    heights = np.asarray(heights_m, float)
    tested = builder.tested
    required = required_tests(targets, tested, cand)
    frame_now, now = _now(builder, targets)
    paper = paper_tests(tested)
    v_paper = None
    if paper:
        _, v_paper, _ = _layout(builder, targets, paper)
    ref = np.array(
        [(np.mean(v_paper[:, i]) if v_paper is not None else np.nan) for i in range(len(targets))]
    )
    ref_now = evaluate(frame_now, targets).mean(0)
    scale2 = np.where(np.isfinite(ref) & (ref > 0), ref, ref_now)
    scale2 = np.where(np.isfinite(scale2) & (scale2 > 0), scale2, 1.0)
    tau2 = None if target_sd is None else np.asarray(target_sd, float) ** 2

    def objective(vbar):
        if tau2 is None:
            return float(np.sum(vbar / scale2))
        return float(np.sum(np.maximum(vbar, tau2) / tau2))

    counts = (
        [cand.size]
        if getattr(builder, "fixed_frame", False)  # a model whose frame is the same for any plan
        else list(range(max(1, int(required.sum())), cand.size + 1))
    )
    best, tried, stale = None, [], 0
    for n_new in counts:
        after = np.concatenate([tested, spread(n_new, cand), cand[required]])
        for _ in range(2):
            frame = builder.frame(cand, after_bar=after)
            path = search(
                frame,
                targets,
                heights,
                max_readings=max_readings,
                target_sd=target_sd,
                cost_per_pressure=cost_per_pressure,
                required=required,
                draws=draws,
                max_tests=n_new,
                scale2=scale2,
            )
            chosen = cand[sorted({r.test for r in path.readings})]
            new_after = np.concatenate([tested, chosen])
            if not path.readings or builder.key(new_after) == frame.key:
                break
            after = new_after
        if not path.readings:
            break
        tests = [
            (t["pressure_bar"], np.asarray(t["heights_m"]))
            for t in recording_order(path.readings, frame.new_bar)
        ]
        readings, v, own = _layout(builder, targets, tests)
        sd = _sd(v)
        vbar = np.array([np.nan if s is None else s**2 for s in sd])
        cost = len(readings) + cost_per_pressure * len(tests)
        met = tau2 is not None and bool(np.all(vbar <= tau2 * (1 + 1e-9)))
        score = (0 if met else 1, cost if met else objective(vbar))
        tried.append(
            {
                "new_tests": len(tests),
                "label": own.label,
                "n_readings": len(readings),
                "sd": sd,
                "objective": objective(vbar),
            }
        )
        if best is None or score < best[0]:
            best, stale = (score, path, tests, readings, v, own), 0
        else:
            stale += 1
        if stale >= 2 or len(tests) < n_new:
            break
    if best is None:
        raise InputError(
            "no planned reading reduces the targets' variance: the candidate pressures and heights "
            "do not inform them (`candidates_bar`, `heights_m`)"
        )
    _, path, tests, readings, v, own = best
    order = recording_order(readings, own.new_bar)
    n_tests = len(tests)
    # the uniform grid of the same size and the paper's protocol, each in its own frame
    uni_p, uni_tests = uniform_readings(len(readings), n_tests, cand, heights)
    _, v_uni, _ = _layout(builder, targets, uni_tests)
    curves = {"uniform": []}
    for f in (0.5, 1.0, 2.0, 4.0):
        n = int(round(f * len(readings)))
        if n < MIN_TEST_READINGS * n_tests or n > MAX_PER_HEIGHT * heights.size * n_tests:
            continue
        _, tl = uniform_readings(n, n_tests, cand, heights)
        curves["uniform"].append(
            {
                "n_readings": n,
                "n_pressure_changes": n_tests,
                "sd": _sd(_layout(builder, targets, tl)[1]),
            }
        )
    return Plan(
        model=builder.name,
        label=own.label,
        label_now=frame_now.label,
        targets=targets,
        readings=readings,
        tests=order,
        n_readings=len(readings),
        n_pressure_changes=n_tests,
        cost_per_pressure=float(cost_per_pressure),
        value_now=now["value"],
        sd_now=now["sd"],
        sd_now_theta_spread=now["spread"],
        sd_predicted=_sd(v),
        uniform={
            "n_readings": int(sum(len(h) for _, h in uni_tests)),
            "n_pressure_changes": len(uni_tests),
            "pressures_bar": [float(p) for p in uni_p],
            "sd": _sd(v_uni),
        },
        paper={
            "n_readings": int(sum(len(h) for _, h in paper)),
            "n_pressure_changes": len(paper),
            "pressures_bar": [p for p, _ in paper],
            "sd": _sd(v_paper) if v_paper is not None else [None] * len(targets),
        },
        path=path,
        curves=curves,
        target_sd=None if target_sd is None else [float(t) for t in target_sd],
        n_draws=int(v.shape[0]),
        tried=tried,
    )


APPROXIMATIONS = (
    "predicted sd: the posterior variance given the sampled parameters theta (noise scales, "
    "travel factor) averaged over their current posterior draws; it does not depend on the "
    "readings' values (a preposterior closed form, no simulation)",
    "left out: the spread of the posterior mean over theta (reported now as "
    "sd_now_theta_spread), and that the new readings also move theta (a noise scale poorly known "
    "from a small pilot changes the band)",
    "pressure_for, natural_frequency and elastic_casing are linearised in the coefficients at the "
    "posterior mean given each theta (the delta method)",
    "the model after the plan is the one the default fit of the combined campaign takes (its orders "
    "and pressure scaling follow the tests); a different model choice after the new data is not "
    "foreseen",
)


def plan_document(plan: Plan, model_info: dict | None = None) -> dict:
    """The JSON document of ``uq plan`` (docs/formats.md): the contract's keys and more."""
    targets = []
    for i, t in enumerate(plan.targets):
        row = {
            "spec": t.spec,
            "unit": t.unit,
            "value_now": plan.value_now[i],
            "sd_now": plan.sd_now[i],
            "sd_now_theta_spread": plan.sd_now_theta_spread[i],
            "sd_predicted": plan.sd_predicted[i],
            "sd_uniform_grid": plan.uniform["sd"][i],
            "sd_paper_protocol": plan.paper["sd"][i],
        }
        if plan.target_sd is not None:
            row["target_sd"] = plan.target_sd[i]
            row["reached"] = plan.reached[i]
        targets.append(row)
    tests = [
        {
            "pressure_bar": t["pressure_bar"],
            "heights_mm": [round(h * 1e3, 6) for h in t["heights_m"]],
            "branches": t["branches"],
        }
        for t in plan.tests
    ]
    return {
        "model": plan.model,
        "model_label": plan.label,
        "model_now": plan.label_now,
        **({"model_choice": model_info} if model_info else {}),
        "n_readings": plan.n_readings,
        "n_pressure_changes": plan.n_pressure_changes,
        "cost_per_pressure_readings": plan.cost_per_pressure,
        "stand_time_readings": plan.cost,
        "tests": tests,
        "targets": targets,
        "uniform_grid": plan.uniform
        | {
            "stand_time_readings": plan.uniform["n_readings"]
            + plan.cost_per_pressure * plan.uniform["n_pressure_changes"]
        },
        "paper_protocol": plan.paper
        | {
            "stand_time_readings": plan.paper["n_readings"]
            + plan.cost_per_pressure * plan.paper["n_pressure_changes"]
        },
        "search": {
            "stop": plan.path.stop,
            "plans_tried": plan.tried,
            "path": [
                {"n_readings": n, "n_pressure_changes": c, "sd": sd}
                for n, c, sd in zip(
                    plan.path.n_readings, plan.path.n_changes, plan.path.sd, strict=True
                )
            ],
        },
        "theta_draws": plan.n_draws,
        "approximations": list(APPROXIMATIONS),
    }
