"""The preposterior engine of ``uq plan`` (docs/plan.md): frames, exact evaluation, the search.

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
new readings also teach theta (a noise scale poorly known from a small pilot moves; the
discrepancy's length scale, docs/plan.md's scenario D).

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
    ``rows_follow_tests``), or (S, n, k) for rows that depend on the draw; area_rows the same for
    dV/dx (None: the model has no volume, and ``volume_why`` says why); extra_force_var(x, p, open)
    -> (n,) or (S, n), N^2: the force's variance no reading at other pressures reduces (an
    interpolation error), or None. min_test_heights: the distinct heights a new test needs for the
    model after the plan to be fitted (the discrepancy's per-test span; 0: any).
    reading_noise(j, heights_m (n,)) -> (S, n, r, r): per draw the lower-triangular factor C of each
    reading's noise covariance in the readings' own units (N, m), such that ``reading_rows`` are
    C^-1 times the reading's design rows and C^-1 y the whitened reading (what the preposterior
    that updates theta needs to compare one set of readings across draws: ``uq._derived.plan_theta``);
    None: not given.
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
    min_test_heights: int = 0
    reading_noise: Callable | None = None

    @property
    def n_draws(self) -> int:
        return self.precision.shape[0]

    def pressure_range(self, open_=None) -> tuple[float, float]:
        """The lowest and highest pressure of the tests that exist (the file's and ``open_``)."""
        o = np.zeros(self.new_bar.size, bool) if open_ is None else np.asarray(open_, bool)
        p = np.concatenate([self.tested_bar, self.new_bar[o]])
        return float(p.min()), float(p.max())

    def thinned(self, n: int) -> Frame:
        """The frame on at most ``n`` of its draws (evenly spaced)."""
        S = self.n_draws
        if S <= n:
            return self
        idx = np.linspace(0, S - 1, n).round().astype(int)

        def per_draw(fn, ndim):
            """``fn`` with its per-draw results (``ndim`` dimensions) on the kept draws."""
            if fn is None:
                return None

            def kept(*a):
                r = np.asarray(fn(*a))
                return r[idx] if r.ndim == ndim else r

            return kept

        return replace(
            self,
            precision=self.precision[idx],
            mean=self.mean[idx],
            reading_rows=per_draw(self.reading_rows, 4),
            reading_noise=per_draw(self.reading_noise, 4),
            force_rows=per_draw(self.force_rows, 3),
            area_rows=per_draw(self.area_rows, 3),
            extra_force_var=per_draw(self.extra_force_var, 2),
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
        need = self.f.min_test_heights
        if (
            js.size == 0
            or budget < max(MIN_TEST_READINGS, need)
            or self.open.sum() >= self.max_tests
        ):
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
            short = (counts > 0).sum(axis=1) < need  # a new height until the test has enough
            after = np.where(short[:, None] & (counts > 0), np.inf, after)
            h = np.argmin(after, axis=1)
            path[:, m], chosen[:, m] = after[lane, h], h
            counts[lane, h] += 1
            # rank-r update of each lane with its own reading
            cols = h[:, None] * r + np.arange(r)[None, :]  # (Ju, r)
            # (S, Ju, Hr, r)
            Y = CC.transpose(1, 3, 0, 2)[lane[:, None], cols].transpose(2, 0, 3, 1)
            Minv = np.linalg.inv(M[:, lane, h])  # (S, Ju, r, r)
            bh = b[:, lane, h]  # (S, Ju, r, T)
            CG -= Y @ (Minv @ bh)
            CC -= Y @ Minv @ np.swapaxes(Y, -1, -2)
            v -= delta[:, lane, h]
        m_all = np.arange(1, m_max + 1)
        ratio = (start - path) / (m_all[None, :] + self.cost)
        ratio[:, : max(MIN_TEST_READINGS, need) - 1] = -np.inf
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
