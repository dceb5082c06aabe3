"""A model is math, a fit is one driver: every model of ``uq`` is fitted by :func:`fit_collapsed`.

Every model here is linear in its coefficients beta given a few sampled parameters theta (noise
scales, nonlinear magnitudes), so its posterior factorises as p(theta | y) p(beta | theta, y) with
the second factor Gaussian (``uq._inference.linear``). A model is a bundle of pure functions
(:class:`CollapsedModel`, blackjax's ``SamplingAlgorithm`` style): the log posterior of theta with
the coefficients integrated out, an exact draw of beta given theta, the pointwise log-likelihood,
and a start for the optimiser. The driver does the rest, the same way for every model:

1. MAP of theta: optimistix BFGS on the collapsed negative log posterior from the model's
   start(s), the best optimum kept; a run that does not report success is restarted once from
   where it stopped and kept only if a Newton step from it would gain less than
   ``MAP_DECREMENT`` nats. The Laplace covariance is the inverse of the Hessian there, by
   central differences (Richardson-extrapolated) through the same compiled log posterior the
   sampler calls (:func:`laplace_curvature`): no Hessian program to trace and compile per model.
2. Sampling of theta: emcee (``uq._inference.sampler.run_many``) from starts overdispersed by
   the Laplace covariance, until the convergence rules pass (``uq._inference.convergence``); or,
   for quick screening (``method="laplace"``), independent draws from the Laplace approximation.
3. An exact draw of beta for every retained theta (``uq._inference.linear.map_rows``), the
   model's reported variables and the convergence verdict.
4. On demand (:class:`Posterior`: made when first asked for, the same draws whenever): the
   pointwise log-likelihood, posterior-predictive replicates, the integrated leave-one-out
   densities and an ArviZ ``InferenceData`` with ``posterior``, ``log_likelihood``,
   ``posterior_predictive``, ``observed_data`` and ``sample_stats`` groups, so that ``az.loo``
   and ``az.plot_ppc`` work on it. A command pays only for what it uses (``uq fit`` for none of
   them; the report's bands need none either).

Several problems of one model (the tests of a campaign) are fitted in one emcee run
(:func:`fit_collapsed` with a list of data): every problem keeps its own ensembles, burn-in and
verdict, while one jitted, vmapped log-probability evaluates all of them per move.

Some coordinates of theta can be held at zero (``active``): the diagnose engine fits many
candidate models that differ only in which magnitudes are free; they share one compiled program
because ``active`` is an array, not a shape.
"""

from __future__ import annotations

import contextlib
import dataclasses
import functools
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from uq._inference.convergence import Convergence, convergence, importance_convergence
from uq._inference.exported import persistent_jit
from uq._inference.float64 import jax, jnp
from uq._inference.linear import map_rows, row_keys, seed_row_keys
from uq._inference.sampler import INDEPENDENCE_MIX, Chains, Settings, run_many, thin
from uq._inference.summary import thin_rows, thin_step


class CollapsedModel(NamedTuple):
    """The pure functions of a model whose coefficients beta are linear-Gaussian given theta.

    All functions take the model's ``data`` (a pytree of arrays) last; those marked jittable are
    traced by JAX and must be module-level functions (they are static arguments of jitted code).

    log_prob(theta (D,), data) -> ()                 jittable: log p(theta | y), beta integrated out
    draw_linear(theta, key, data) -> beta (k,)       jittable: exact draw from p(beta | theta, y)
    pointwise(theta, beta, data) -> {name: (n,)}     jittable: log-likelihood of each reading
    start(data) -> (m, D)                            numpy: start(s) of the optimiser
    report(theta (N, D), beta (N, k), data) -> {name: (N, ...)}   numpy: the reported variables
    predict(theta, beta, key, data) -> {name: (n,)}  jittable, optional: a replicate of the readings
    observed(data) -> {name: (n,)}                   numpy, optional: the readings, for ArviZ
    pointwise_loo(theta, data) -> (n,)               jittable, optional: log p(reading_i | theta,
                                                     the other readings), beta integrated out exactly
    hold_out(data, held (n,) bool) -> data           numpy, optional: the data with the readings
                                                     ``held`` kept in the arrays but left out of the
                                                     fit (exact leave-one-out and K-fold refits)
    """

    name: str
    theta_names: tuple[str, ...]
    log_prob: Callable
    draw_linear: Callable
    pointwise: Callable
    start: Callable
    report: Callable
    predict: Callable | None = None
    observed: Callable | None = None
    pointwise_loo: Callable | None = None
    hold_out: Callable | None = None
    #: map the log posterior over walkers one at a time (XLA CPU can hang on large batched
    #: Cholesky factorisations); False: one vmapped call
    sequential: bool = False

    @classmethod
    def of(cls, namespace, name: str, theta_names, *, prefix: str = "", **fields) -> CollapsedModel:
        """The model whose functions are those of ``namespace`` (a module, or ``globals()`` of a
        module after its functions) under the fields' names (``log_prob``, ``draw_linear``, ...,
        ``hold_out``), each after ``prefix`` (``"ar1_"``: ``ar1_log_prob``, ...); ``fields`` set
        any field explicitly (an optional one absent from both is None)."""
        ns = namespace if isinstance(namespace, dict) else vars(namespace)
        found = {f: ns[prefix + f] for f in cls._fields[2:] if callable(ns.get(prefix + f))}
        return cls(name, theta_names, **(found | fields))


# ----------------------------------------------------------------------------- jitted kernels


@persistent_jit(static_argnums=(0,))
def _log_prob_problems(fn, thetas, data):
    """thetas (K, W, D), data with a leading K axis -> (K, W)."""
    return jax.vmap(lambda ths, d: jax.vmap(lambda th: _finite(fn(th, d)))(ths))(thetas, data)


def hold_out_by_weight(data, held):
    """``hold_out`` of a model whose data carry ``weight`` (n,): the readings ``held`` weigh 0."""
    return data._replace(weight=jnp.asarray(np.where(np.asarray(held, bool), 0.0, 1.0)))


def _finite(lp):
    return jnp.where(jnp.isfinite(lp), lp, -jnp.inf)


def _objective(fn):
    """The collapsed negative log posterior over the full theta, ``(x, (active, data)) -> ()``.
    Inactive coordinates are held at zero in the model and carry a unit quadratic, so every
    ``active`` pattern minimises a function of the same shape (one compilation)."""

    def objective(x, args):
        active, data = args
        return -fn(active * x, data) + 0.5 * jnp.sum((1.0 - active) * x**2)

    return objective


MAP_RTOL = 1e-10
MAP_ATOL = 1e-10
MAP_MAX_STEPS = 1000
MAP_DECREMENT = 1e-3


@persistent_jit(static_argnums=(0,))
def _bfgs(fn, x0, active, data):
    # reason: only traced when the program is not kept (uq._inference.exported): a warm `uq fit`
    # loads it and never imports optimistix, equinox and lineax (about 0.7 CPU s)
    import optimistix as optx

    solver = optx.BFGS(rtol=MAP_RTOL, atol=MAP_ATOL)
    objective = _objective(fn)
    args = (active, data)
    sol = optx.minimise(objective, solver, x0, args=args, max_steps=MAP_MAX_STEPS, throw=False)
    return sol.value, objective(sol.value, args), sol.result == optx.RESULTS.successful


@functools.partial(jax.jit, static_argnums=0)
def _gradient_hessian(fn, x, active, data):
    """JAX's exact gradient and Hessian of the objective: the fallback of the finite differences
    where they cannot be taken (an optimum on a wall of the support, where every step to one side
    leaves it); traced only then."""
    objective = _objective(fn)
    return jax.grad(objective)(x, (active, data)), jax.hessian(objective)(x, (active, data))


def replicates(model: CollapsedModel, posterior: Posterior, n_draws: int, seed: int = 0):
    """Posterior-predictive replicates of the readings ``posterior`` was fitted to (the model's
    ``predict``: the mean plus the reading noise of each draw) on at most ``n_draws`` of its draws,
    thinned evenly: {name: (S, n)} as numpy, or None when the model has no ``predict`` or the
    posterior keeps no data. Deterministic for ``seed``."""
    if model.predict is None or posterior.data is None:
        return None
    C, D, nt = posterior.theta.shape
    rows = posterior.theta.reshape(C * D, nt)
    beta = np.asarray(posterior.beta).reshape(C * D, -1)
    rows, beta = (thin_rows(a, max(int(n_draws), 1)) for a in (rows, beta))
    keys = row_keys(jax.random.PRNGKey(seed), rows.shape[0])
    out = map_rows(model.predict, (rows, beta, keys), (posterior.data,))
    return {k: np.asarray(v) for k, v in out.items()}


LOO_DRAWS = 2000  # draws of theta for the integrated leave-one-out densities


# ----------------------------------------------------------------------------- MAP


@dataclass(frozen=True)
class Optimum:
    """The MAP of theta and the Laplace approximation there (full theta; ``cov`` over ``active``)."""

    theta: np.ndarray  # (D,)
    log_prob: float
    cov: np.ndarray  # (d, d), d = number of active coordinates
    active: np.ndarray  # (D,) bool
    converged: bool


#: finite-difference steps of the Laplace curvature: a first pass at ``FD_STEP`` times max(1, |x|)
#: finds each coordinate's posterior sd, the second takes ``FD_SD_FRACTION`` of it and half that
FD_STEP = 1e-4
FD_SD_FRACTION = 0.1
FD_RETRIES = 4


def find_map(model: CollapsedModel, data, active=None, *, block: int = 64) -> Optimum:
    """MAP of the sampled parameters and the Laplace covariance over the active ones (step 1 of
    the module docstring). Raises FloatingPointError when no start gives a finite optimum.
    ``block``: the rows of one call of the compiled log posterior (``_campaign_log_prob``)."""
    act = _active(model, data, active)
    lp, _ = _campaign_log_prob(model, [data], act, block)
    return _optima(model, [data], act, lp)[0]


def _active(model: CollapsedModel, data, active) -> np.ndarray:
    D = np.atleast_2d(np.asarray(model.start(data), float)).shape[1]
    return np.ones(D, bool) if active is None else np.asarray(active, bool)


def _bfgs_best(model: CollapsedModel, data, act: np.ndarray):
    """BFGS from every start of the model, the best optimum kept; a run that does not report
    success restarted once from where it stopped: (x (D,), objective, success) or None."""
    flags = act.astype(float)  # numpy: jnp.asarray would compile a copy program per shape
    starts = np.atleast_2d(np.asarray(model.start(data), float)) * act

    def best_of(xs):
        best = None
        for x0 in xs:
            x, f, ok = _bfgs(model.log_prob, np.asarray(x0, float), flags, data)
            f = float(f)
            if np.isfinite(f) and (best is None or f < best[1]):
                best = (np.asarray(x), f, bool(ok))
        return best

    best = best_of(starts)
    if best is not None and not best[2]:  # restart once, with a fresh BFGS, from where it stopped
        again = best_of([best[0]])
        if again is not None and again[1] <= best[1]:
            best = again
    return best


def laplace_curvature(lp, centers: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Gradient (K, d) and Hessian (K, d, d) of K log posteriors at ``centers`` (K, d), by
    central differences through ``lp`` ((K, m, d) -> (K, m), the same compiled program the
    sampler calls): no second program to trace and compile for the curvature of every model.

    Two passes: the diagonal at steps ``FD_STEP`` max(1, |x|) gives each coordinate's posterior
    sd (1 / sqrt(-H_ii)); the full stencil (2 d^2 + 1 points) then steps ``FD_SD_FRACTION`` of it
    and half that, combined by Richardson's extrapolation (truncation error of order the step to
    the fourth power). Steps that large are needed: the collapsed log posterior is a difference of
    terms far larger than itself (y' W y - m' A m), so its rounding error is about 1e-8, not 1e-16,
    of its size. Agreement with JAX's exact Hessian: within 1e-5 relative on the models checked
    (tests/inference/test_collapsed.py). Where a step to one side leaves the support at every
    size tried (an optimum on a wall), the result is not finite and the caller takes JAX's
    Hessian instead."""
    x = np.atleast_2d(np.asarray(centers, float))
    K, d = x.shape
    eye = np.eye(d)
    h = FD_STEP * np.maximum(1.0, np.abs(x))
    f = np.asarray(
        lp(
            np.concatenate(
                [x[:, None], x[:, None] + h[:, None] * eye, x[:, None] - h[:, None] * eye], axis=1
            )
        ),
        float,
    )
    with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
        curv = -(f[:, 1 : 1 + d] - 2.0 * f[:, :1] + f[:, 1 + d :]) / h**2
        sd = 1.0 / np.sqrt(curv)
    h = np.where(np.isfinite(sd) & (sd > 0), FD_SD_FRACTION * sd, h)
    pairs = [(i, j) for i in range(d) for j in range(i + 1, d)]

    def stencil(h):
        steps = [np.zeros_like(h)]
        steps += [s * h * eye[i] for i in range(d) for s in (1.0, -1.0)]
        steps += [
            si * h * eye[i] + sj * h * eye[j]
            for i, j in pairs
            for si, sj in ((1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0))
        ]
        return np.stack(steps, axis=1)

    def differences(f, h):
        K = f.shape[0]
        f0, fp, fm = f[:, 0], f[:, 1 : 1 + 2 * d : 2], f[:, 2 : 2 + 2 * d : 2]
        grad = (fp - fm) / (2.0 * h)
        hess = np.zeros((K, d, d))
        idx = np.arange(d)
        hess[:, idx, idx] = (fp - 2.0 * f0[:, None] + fm) / h**2
        for n, (i, j) in enumerate(pairs):
            q = f[:, 1 + 2 * d + 4 * n : 5 + 2 * d + 4 * n]
            hess[:, i, j] = hess[:, j, i] = (q[:, 0] - q[:, 1] - q[:, 2] + q[:, 3]) / (
                4.0 * h[:, i] * h[:, j]
            )
        return grad, hess

    n = 1 + 2 * d + 2 * d * (d - 1)
    grad, hess = np.full((K, d), np.nan), np.full((K, d, d), np.nan)
    todo = np.arange(K)
    for _ in range(FD_RETRIES):  # a step that leaves the support (-inf): ten times smaller
        hk = h[todo]
        pts = x[todo, None] + np.concatenate([stencil(hk), stencil(hk / 2)], axis=1)
        f = np.full((K, pts.shape[1]), -np.inf)
        f[todo] = np.asarray(lp(_rows_of(pts, todo, K)), float)[todo]
        with np.errstate(invalid="ignore", over="ignore"):
            (g1, h1), (g2, h2) = differences(f[todo, :n], hk), differences(f[todo, n:], hk / 2)
            g, H = (4.0 * g2 - g1) / 3.0, (4.0 * h2 - h1) / 3.0
        ok = np.all(np.isfinite(g), axis=1) & np.all(np.isfinite(H), axis=(1, 2))
        grad[todo], hess[todo] = g, H
        todo = todo[~ok]
        if todo.size == 0:
            break
        h[todo] = h[todo] / 10.0
    return grad, hess


def _rows_of(pts: np.ndarray, todo: np.ndarray, K: int) -> np.ndarray:
    """``pts`` (len(todo), m, d) of the problems ``todo`` as the (K, m, d) ``lp`` takes (the
    other problems at the first problem's points: evaluated and discarded)."""
    out = np.repeat(pts[:1], K, axis=0)
    out[todo] = pts
    return out


def _optima(model: CollapsedModel, datas: list, act: np.ndarray, lp) -> list[Optimum]:
    """The MAP of every problem (BFGS, one after another) and their Laplace covariances (one
    batch of finite differences through ``lp`` for all of them)."""
    bests = [_bfgs_best(model, d, act) for d in datas]
    if any(b is None for b in bests):
        raise FloatingPointError(
            f"{model.name}: the log posterior is not finite at any start of the optimiser"
        )
    dims = np.flatnonzero(act)
    grads, hessians = laplace_curvature(lp, np.stack([b[0][dims] for b in bests]))
    out = []
    for (x, f, ok), g, H, d in zip(bests, grads, hessians, datas, strict=True):
        g, H = -g, -H  # of the objective, the negative log posterior
        if not (np.all(np.isfinite(g)) and np.all(np.isfinite(H))):  # on a wall: JAX's Hessian
            flags = jnp.asarray(act.astype(float))
            g, H = (
                np.asarray(a) for a in _gradient_hessian(model.log_prob, jnp.asarray(x), flags, d)
            )
            g, H = g[dims], H[np.ix_(dims, dims)]
        try:
            cov = np.linalg.inv(H)
            np.linalg.cholesky(cov)
        except np.linalg.LinAlgError:
            cov = None
        if cov is not None and not np.all(np.isfinite(cov)):
            cov = None
        if not np.all(np.isfinite(x)) or (
            not ok and (cov is None or 0.5 * g @ cov @ g > MAP_DECREMENT)
        ):
            raise FloatingPointError(
                f"{model.name}: the MAP did not converge (BFGS, {MAP_MAX_STEPS} steps, restarted once)"
            )
        if cov is None:
            cov = np.diag(1.0 / np.maximum(np.abs(np.diag(H)), 1e-12))
        out.append(Optimum(x * act, -f, cov, act, bool(ok)))
    return out


# ----------------------------------------------------------------------------- the posterior


class Posterior:
    """The fitted posterior of one problem of a :class:`CollapsedModel`.

    ``theta`` (C, D, n_theta) the sampled parameters (full vector; held coordinates zero),
    ``beta`` (C, D, k) the exact coefficient draws, ``reported`` {name: (C, D, ...)} the model's
    reported variables, ``convergence`` the verdict (None for Laplace draws, ``method ==
    "laplace"``, which are independent).

    Made when first asked for, not by every fit (a command uses some of them, never all; each
    is computed once and kept): ``loglik`` {name: (C, D, n)} the pointwise log-likelihood,
    ``loglik_loo`` (C, D', n) the integrated leave-one-out densities, ``predictive`` the
    posterior-predictive replicates, and ``idata``, the ArviZ view (posterior = the reported
    variables, with log_likelihood, posterior_predictive when the fit asked for it, observed_data
    and sample_stats). The draws behind them are fixed by the fit's seed, so they are the same
    whenever they are made.
    """

    def __init__(
        self,
        model: CollapsedModel,
        method: str,
        theta: np.ndarray,
        beta: np.ndarray,
        reported: dict,
        optimum: Optimum,
        convergence: Convergence | None = None,
        chains: Chains | None = None,
        seconds: float = 0.0,
        data: Any = None,
        *,
        seed: int = 0,
        predictive: bool = True,
        lp=None,
        attrs: dict | None = None,
    ):
        self._model = model
        self.model = model.name
        self.method = method
        self.theta = theta
        self.beta = beta
        self.reported = reported
        self.optimum = optimum
        self.convergence = convergence
        self.chains = chains
        self.seconds = seconds
        #: the model's data this posterior was fitted to (for refits without some readings)
        self.data = data
        self._seed = seed
        self._predictive = predictive
        self._lp = lp
        self._attrs = attrs or {}
        self._cache: dict = {}

    def _rows(self):
        C, D, nt = self.theta.shape
        return self.theta.reshape(C * D, nt), self.beta.reshape(C * D, -1)

    @property
    def loglik(self) -> dict:
        """Pointwise log-likelihood {observed variable: (C, D, n)} (computed on first use)."""
        if "loglik" not in self._cache:
            C, D = self.theta.shape[:2]
            rows, beta = self._rows()
            ll = map_rows(self._model.pointwise, (rows, beta), (self.data,))
            self._cache["loglik"] = {k: np.asarray(v).reshape(C, D, -1) for k, v in ll.items()}
        return self._cache["loglik"]

    @property
    def predictive(self) -> dict | None:
        """Posterior-predictive replicates {observed variable: (C, D, n)}: one replicate of the
        readings per draw (computed on first use; None when the model has no ``predict``)."""
        if self._model.predict is None:
            return None
        if "predictive" not in self._cache:
            C, D = self.theta.shape[:2]
            rows, beta = self._rows()
            pred = map_rows(
                self._model.predict, (rows, beta, seed_row_keys(self._seed, 1, C * D)), (self.data,)
            )
            self._cache["predictive"] = {
                k: np.asarray(v).reshape(C, D, -1) for k, v in pred.items()
            }
        return self._cache["predictive"]

    def predictive_thinned(self, max_draws: int | None) -> dict | None:
        """The rows of :attr:`predictive` (chains flattened, {name: (S, n)}) that thinning to at
        most ``max_draws`` keeps (:func:`uq._inference.summary.thin_rows`), the same numbers,
        computed on those draws only: memory of S, not N, replicates a reading (None when the model
        has no ``predict`` or the fit asked for no replicates)."""
        if self._model.predict is None or not self._predictive:
            return None
        C, D = self.theta.shape[:2]
        if "predictive" in self._cache:
            return {
                k: thin_rows(v.reshape(C * D, -1), max_draws)
                for k, v in self._cache["predictive"].items()
            }
        rows, beta = self._rows()
        keys = seed_row_keys(self._seed, 1, C * D)
        pred = map_rows(
            self._model.predict,
            tuple(thin_rows(a, max_draws) for a in (rows, beta, keys)),
            (self.data,),
        )
        return {k: np.asarray(v) for k, v in pred.items()}

    @property
    def loglik_loo(self) -> np.ndarray | None:
        """(C, D', n) log p(reading_i | theta, other readings) on at most ``LOO_DRAWS`` draws, for
        PSIS-LOO over theta alone (the model's ``pointwise_loo``); None when the model has none."""
        if self._model.pointwise_loo is None:
            return None
        if "loglik_loo" not in self._cache:
            C, D, nt = self.theta.shape
            sub = self.theta[:, :: thin_step(C * D, LOO_DRAWS)]
            self._cache["loglik_loo"] = np.asarray(
                map_rows(self._model.pointwise_loo, (sub.reshape(-1, nt),), (self.data,))
            ).reshape(sub.shape[0], sub.shape[1], -1)
        return self._cache["loglik_loo"]

    @property
    def idata(self):
        """The ArviZ ``InferenceData`` (made on first use: ArviZ and xarray are slow to build)."""
        if "idata" not in self._cache:
            self._cache["idata"] = self._idata(
                self.loglik, self.predictive if self._predictive else None
            )
        return self._cache["idata"]

    def draws_idata(self):
        """The InferenceData without the (draws x readings) groups: posterior, observed_data and
        sample_stats (not cached). The pointwise log-likelihood and the replicates are
        recomputable exactly from these draws (:attr:`loglik`, :attr:`predictive`)."""
        return self._idata(None, None)

    def _idata(self, loglik, predictive):
        import arviz as az

        groups = {"posterior": self.reported}
        if loglik is not None:
            groups["log_likelihood"] = loglik
        if predictive is not None:
            groups["posterior_predictive"] = predictive
        if self._model.observed is not None:
            groups["observed_data"] = self._model.observed(self.data)
        if self._lp is not None:
            groups["sample_stats"] = {"lp": self._lp}
        attrs = {"model": self.model, "method": self.method} | self._attrs
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message="More chains", category=UserWarning)
            return az.from_dict(**groups, attrs=attrs)

    @contextlib.contextmanager
    def transient(self):
        """A block whose parts made on demand (pointwise terms, replicates, InferenceData) are
        dropped at its end; parts made before it are kept. For a use of every draw's (draws x
        readings) arrays that need not outlive it, such as writing the posterior to a file."""
        held = set(self._cache)
        try:
            yield self
        finally:
            for name in set(self._cache) - held:
                del self._cache[name]

    @property
    def converged(self) -> bool:
        return self.convergence is None or self.convergence.converged

    def flat(self, name: str) -> np.ndarray:
        """Draws of a reported variable with chains flattened, (N, ...)."""
        a = np.asarray(self.reported[name])
        return a.reshape(-1, *a.shape[2:])

    def loglik_total(self) -> np.ndarray:
        """Pointwise log-likelihood summed over the observed variables of a reading, (C, D, n)."""
        return sum(np.asarray(v) for v in self.loglik.values())

    def summary(self, var_names=None):
        """One row per reported scalar (vector variables one row per element), ArviZ-style: mean,
        sd, q05, q95 and, for sampled posteriors, the convergence module's mcse_mean, ess_bulk,
        ess_tail and r_hat (ESS on the ensemble-mean chains, not ArviZ's walker-as-chain ESS).
        A pandas DataFrame."""
        import pandas as pd

        from uq._inference.summary import estimate

        names = list(self.reported) if var_names is None else list(var_names)
        variables = self.convergence.variables if self.convergence is not None else {}
        rows = {}
        for name in names:
            draws = self.flat(name).reshape(-1, int(np.prod(self.flat(name).shape[1:], dtype=int)))
            diag = variables.get(name, {})
            for j in range(draws.shape[1]):
                label = name if draws.shape[1] == 1 else f"{name}[{j}]"
                row = {k: float(v) for k, v in estimate(draws[:, j]).items()}
                for k, v in diag.items():
                    row[k] = float(v if np.ndim(v) == 0 else v[j])
                rows[label] = row
        return pd.DataFrame.from_dict(rows, orient="index")

    def __repr__(self) -> str:
        C, D = self.theta.shape[:2]
        state = (
            "independent Laplace draws"
            if self.convergence is None
            else ("converged" if self.converged else "NOT converged")
        )
        return f"Posterior({self.model}, {self.method}, {C} x {D} draws, {self.beta.shape[-1]} coefficients, {state})"


def _finish(
    model: CollapsedModel,
    data,
    theta: np.ndarray,
    optimum: Optimum,
    *,
    seed: int,
    method: str,
    chains: Chains | None,
    lp,
    predictive: bool,
    t0: float,
    importance=None,
) -> Posterior:
    """Step 3 of the module docstring for retained draws ``theta`` (C, D, n_theta), the reported
    variables and the verdict; step 4 (pointwise terms, replicates, InferenceData) is left to the
    :class:`Posterior`, which makes each when it is first asked for."""
    C, D, nt = theta.shape
    rows = theta.reshape(C * D, nt)
    keys = seed_row_keys(seed, 0, C * D)  # the first of the seed's two keys (Posterior._keys)
    beta = np.asarray(map_rows(model.draw_linear, (rows, keys), (data,)))
    reported = {
        k: np.asarray(v).reshape(C, D, *np.shape(v)[1:])
        for k, v in model.report(rows, beta, data).items()
    }
    attrs = {}
    if chains is not None:
        attrs |= {
            "n_ensembles": chains.n_ensembles,
            "n_walkers": chains.n_walkers,
            "draw_order": "each chain is one emcee ensemble; draw = step * n_walkers + walker",
            "sampler": "emcee (DE, DE-snooker and independence-t moves) on the sampled parameters; "
            "coefficients drawn exactly",
        }
    conv = convergence(reported, chains) if chains is not None else None
    if importance is not None:  # tried: its draws (passed) or its refusal beside emcee's verdict
        if importance.passed:
            conv = importance_convergence(reported, importance)
            attrs["sampler"] = (
                "importance sampling (PSIS-checked) on the sampled parameters, resampled; "
                "coefficients drawn exactly"
            )
        else:
            conv = dataclasses.replace(conv, importance=importance.to_json())
    return Posterior(
        model,
        method,
        theta,
        beta.reshape(C, D, -1),
        reported,
        optimum,
        conv,
        chains,
        time.perf_counter() - t0,
        data,
        seed=seed,
        predictive=predictive,
        lp=lp,
        attrs=attrs,
    )


# ----------------------------------------------------------------------------- drivers


def _signature(data) -> tuple:
    leaves, tree = jax.tree.flatten(data)
    return (tree, tuple(np.shape(x) for x in leaves))


def _campaign_log_prob(model: CollapsedModel, datas: list, active: np.ndarray, block: int = 64):
    """One log-probability over all problems, (K, W, d) -> (K, W): one jitted, vmapped call per
    group of problems with equal data shapes (the tests of a campaign usually form one group)
    and per ``block`` rows of each: the rows are padded to a multiple of ``block``, so the
    sampler's starts, its moves (half of the walkers) and its first step (all of them) and the
    Laplace curvature's stencils all run one compiled program instead of one per shape."""
    groups: dict[tuple, list[int]] = {}
    for i, d in enumerate(datas):
        groups.setdefault(_signature(d), []).append(i)
    stacked = [
        (
            np.array(idx),
            jax.tree.map(lambda *a: jax.device_put(np.stack(a)), *[datas[i] for i in idx]),
        )
        for idx in groups.values()
    ]
    dims = np.flatnonzero(active)
    D = active.size

    def expand(sub):
        full = np.zeros(sub.shape[:-1] + (D,))
        full[..., dims] = sub
        return full

    def lp(thetas):
        thetas = expand(np.asarray(thetas, float))
        m = thetas.shape[1]
        if not model.sequential and m % block:  # pad with copies of the last row
            thetas = np.concatenate(
                [thetas, np.repeat(thetas[:, -1:], block - m % block, axis=1)], axis=1
            )
        out = np.empty(thetas.shape[:2])
        for idx, d in stacked:
            if model.sequential:
                for i in idx:
                    out[i] = map_rows(
                        _sequential_lp,
                        (thetas[i],),
                        (datas[i],),
                        static=(model.log_prob,),
                        batch_size=1,
                        chunk=32,
                    )
            else:
                for j in range(0, thetas.shape[1], block):
                    out[idx, j : j + block] = np.asarray(
                        _log_prob_problems(model.log_prob, thetas[idx, j : j + block], d)
                    )
        return out[:, :m]

    return lp, expand


def _sequential_lp(theta, fn, data):
    return _finite(fn(theta, data))


def fit_collapsed(
    model: CollapsedModel,
    data,
    *,
    seed: int,
    settings: Settings = Settings(),
    max_draws: int = 4000,
    active=None,
    method: str = "emcee",
    n_laplace: int = 1000,
    predictive: bool = True,
    desc: str | None = None,
    seeds: list[int] | None = None,
    mix: tuple[float, float, float] = INDEPENDENCE_MIX,
    proposal: str = "half",
    importance: bool = False,
):
    """Fit ``model`` to ``data`` (one problem) or to a list of data (several problems, one emcee run).

    ``method``: "emcee" (sampling until the convergence rules pass, thinned to at most
    ``max_draws`` retained draws per problem) or "laplace" (``n_laplace`` independent draws from
    the Laplace approximation: quick screening, no convergence verdict). ``active`` (n_theta,)
    bool: the coordinates of theta that are free (the others are held at zero). ``seeds``: the
    seed of each problem's exact draws (default: derived from ``seed``). ``predictive``: whether
    the posterior's InferenceData carries posterior-predictive replicates (made, as every part
    beyond the draws, only when first asked for). ``mix``, ``proposal``: the sampler's moves
    (``uq._inference.sampler.run_many``). ``importance`` (one problem, method "emcee"): first
    importance sampling from the MAP (``uq._inference.importance``), kept when its Pareto k-hat
    and effective sample sizes pass, emcee otherwise (the convergence verdict says which, and
    why). Returns a :class:`Posterior` (or a list of them for a list of data).
    """
    many = isinstance(data, list)
    datas = data if many else [data]
    t0 = time.perf_counter()
    act = _active(model, datas[0], active)
    dims = np.flatnonzero(act)
    # one block of the compiled log posterior: half of the walkers (one emcee move)
    block = max(settings.n_ensembles * settings.n_walkers // 2, 1)
    lp, expand = _campaign_log_prob(model, datas, act, block)
    optima = _optima(model, datas, act, lp)
    if seeds is None:
        seeds = [seed + 1 + i for i in range(len(datas))] if many else [seed + 1]
    names = [model.theta_names[i] for i in dims]
    tried = None  # importance sampling's result, when it was tried; emcee below if refused
    if method == "emcee" and importance and not many:
        from uq._inference.importance import sample

        o = optima[0]
        tried = sample(
            lambda x: lp(x[None])[0], o.theta[dims], o.cov, names, seed=seed, n_keep=max_draws
        )
    if method == "laplace":  # one chain of draws from each optimum's normal approximation
        runs = [None] * len(seeds)
        thetas = [
            expand(
                np.random.default_rng(s).multivariate_normal(
                    opt.theta[dims], opt.cov, size=n_laplace, method="cholesky"
                )[None]
            )
            for opt, s in zip(optima, seeds, strict=True)
        ]
    elif tried is not None and tried.passed:
        runs, thetas = [None], [expand(tried.samples[None])]
    elif method == "emcee":
        starts = np.stack([o.theta[dims] for o in optima]), np.stack([o.cov for o in optima])
        runs = run_many(
            lp, *starts, names, seed=seed, settings=settings, desc=desc, mix=mix, proposal=proposal
        )
        runs = [thin(ch, max_draws) for ch in runs]
        thetas = [expand(ch.samples) for ch in runs]
    else:
        raise ValueError(f"method must be 'emcee' or 'laplace', got {method!r}")
    posts = [
        _finish(
            model,
            d,
            theta,
            opt,
            seed=s,
            method="importance" if tried is not None and tried.passed else method,
            chains=ch,
            lp=None if ch is None else ch.log_prob,
            predictive=predictive,
            t0=t0,
            importance=tried,
        )
        for d, opt, theta, ch, s in zip(datas, optima, thetas, runs, seeds, strict=True)
    ]
    return posts if many else posts[0]
