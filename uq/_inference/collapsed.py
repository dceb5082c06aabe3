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
   ``MAP_DECREMENT`` nats. The Laplace covariance is the inverse of JAX's Hessian there.
2. Sampling of theta: emcee (``uq._inference.sampler.run_many``) from starts overdispersed by
   the Laplace covariance, until the convergence rules pass (``uq._inference.convergence``); or,
   for quick screening (``method="laplace"``), independent draws from the Laplace approximation.
3. An exact draw of beta for every retained theta (``uq._inference.linear.map_rows``).
4. Pointwise log-likelihood, optional posterior-predictive replicates, and an ArviZ
   ``InferenceData`` with ``posterior``, ``log_likelihood``, ``posterior_predictive``,
   ``observed_data`` and ``sample_stats`` groups, so that ``az.loo`` and ``az.plot_ppc`` work on it.

Several problems of one model (the tests of a campaign) are fitted in one emcee run
(:func:`fit_collapsed` with a list of data): every problem keeps its own ensembles, burn-in and
verdict, while one jitted, vmapped log-probability evaluates all of them per move.

Some coordinates of theta can be held at zero (``active``): the diagnose engine fits many
candidate models that differ only in which magnitudes are free; they share one compiled program
because ``active`` is an array, not a shape.
"""

from __future__ import annotations

import functools
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
import optimistix as optx

from uq._inference.convergence import Convergence, convergence
from uq._inference.float64 import jax, jnp
from uq._inference.linear import map_rows, row_keys
from uq._inference.sampler import INDEPENDENCE_MIX, Chains, Settings, run_many, thin


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


# ----------------------------------------------------------------------------- jitted kernels


@functools.partial(jax.jit, static_argnums=0)
def _log_prob_rows(fn, thetas, data):
    return jax.vmap(lambda th: _finite(fn(th, data)))(thetas)


@functools.partial(jax.jit, static_argnums=0)
def _log_prob_problems(fn, thetas, data):
    """thetas (K, W, D), data with a leading K axis -> (K, W)."""
    return jax.vmap(lambda ths, d: jax.vmap(lambda th: _finite(fn(th, d)))(ths))(thetas, data)


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


@functools.partial(jax.jit, static_argnums=0)
def _bfgs(fn, x0, active, data):
    solver = optx.BFGS(rtol=MAP_RTOL, atol=MAP_ATOL)
    objective = _objective(fn)
    args = (active, data)
    sol = optx.minimise(objective, solver, x0, args=args, max_steps=MAP_MAX_STEPS, throw=False)
    return sol.value, objective(sol.value, args), sol.result == optx.RESULTS.successful


@functools.partial(jax.jit, static_argnums=0)
def _gradient_hessian(fn, x, active, data):
    objective = _objective(fn)
    return jax.grad(objective)(x, (active, data)), jax.hessian(objective)(x, (active, data))


def _draw_row(theta, key, fn, data):
    return fn(theta, key, data)


def _pointwise_row(theta, beta, fn, data):
    return fn(theta, beta, data)


def _predict_row(theta, beta, key, fn, data):
    return fn(theta, beta, key, data)


def _loo_row(theta, fn, data):
    return fn(theta, data)


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
    step = max(1, int(np.ceil(C * D / max(int(n_draws), 1))))
    rows, beta = rows[::step], beta[::step]
    keys = row_keys(jax.random.PRNGKey(seed), rows.shape[0])
    out = map_rows(_predict_row, (rows, beta, keys), (posterior.data,), static=(model.predict,))
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


def find_map(model: CollapsedModel, data, active=None) -> Optimum:
    """MAP of the sampled parameters and the Laplace covariance over the active ones (step 1 of
    the module docstring). Raises FloatingPointError when no start gives a finite optimum."""
    starts = np.atleast_2d(np.asarray(model.start(data), float))
    D = starts.shape[1]
    act = np.ones(D, bool) if active is None else np.asarray(active, bool)
    flags = jnp.asarray(act.astype(float))
    starts = starts * act

    def best_of(xs):
        best = None
        for x0 in xs:
            x, f, ok = _bfgs(model.log_prob, jnp.asarray(x0), flags, data)
            f = float(f)
            if np.isfinite(f) and (best is None or f < best[1]):
                best = (np.asarray(x), f, bool(ok))
        return best

    best = best_of(starts)
    if best is not None and not best[2]:  # restart once, with a fresh BFGS, from where it stopped
        again = best_of([best[0]])
        if again is not None and again[1] <= best[1]:
            best = again
    if best is None:
        raise FloatingPointError(
            f"{model.name}: the log posterior is not finite at any start of the optimiser"
        )
    x, f, ok = best
    dims = np.flatnonzero(act)
    g, H = (np.asarray(a) for a in _gradient_hessian(model.log_prob, jnp.asarray(x), flags, data))
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
    return Optimum(x * act, -f, cov, act, bool(ok))


# ----------------------------------------------------------------------------- the posterior


@dataclass(frozen=True, eq=False, repr=False)
class Posterior:
    """The fitted posterior of one problem of a :class:`CollapsedModel`.

    ``theta`` (C, D, n_theta) the sampled parameters (full vector; held coordinates zero),
    ``beta`` (C, D, k) the exact coefficient draws, ``loglik`` {name: (C, D, n)} the pointwise
    log-likelihood, ``idata`` the ArviZ view (posterior = the model's reported variables).
    ``convergence`` is None for Laplace draws (``method == "laplace"``), which are independent.
    """

    model: str
    method: str
    theta: np.ndarray
    beta: np.ndarray
    loglik: dict
    idata: Any
    optimum: Optimum
    convergence: Convergence | None = None
    chains: Chains | None = field(default=None)
    seconds: float = 0.0
    #: (C, D', n) log p(reading_i | theta, other readings) on at most ``LOO_DRAWS`` draws, for
    #: PSIS-LOO over theta alone (the model's ``pointwise_loo``); None when the model has none
    loglik_loo: np.ndarray | None = None
    #: the model's data this posterior was fitted to (for refits without some readings)
    data: Any = None

    @property
    def converged(self) -> bool:
        return self.convergence is None or self.convergence.converged

    def flat(self, name: str) -> np.ndarray:
        """Draws of a reported variable with chains flattened, (N, ...)."""
        a = np.asarray(self.idata.posterior[name])
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

        names = list(self.idata.posterior.data_vars) if var_names is None else list(var_names)
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


def _idata(model: CollapsedModel, reported, loglik, predictive, data, lp, attrs):
    import arviz as az

    groups = {"posterior": reported, "log_likelihood": loglik}
    if predictive is not None:
        groups["posterior_predictive"] = predictive
    if model.observed is not None:
        groups["observed_data"] = model.observed(data)
    if lp is not None:
        groups["sample_stats"] = {"lp": lp}
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message="More chains", category=UserWarning)
        return az.from_dict(**groups, attrs=attrs)


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
) -> Posterior:
    """Steps 3 and 4 of the module docstring for retained draws ``theta`` (C, D, n_theta)."""
    C, D, nt = theta.shape
    rows = theta.reshape(C * D, nt)
    key_draw, key_pred = jax.random.split(jax.random.PRNGKey(seed))
    beta = np.asarray(
        map_rows(_draw_row, (rows, row_keys(key_draw, C * D)), (data,), static=(model.draw_linear,))
    )
    ll = map_rows(_pointwise_row, (rows, beta), (data,), static=(model.pointwise,))
    ll = {k: np.asarray(v).reshape(C, D, -1) for k, v in ll.items()}
    pred = None
    if predictive and model.predict is not None:
        pred = map_rows(
            _predict_row, (rows, beta, row_keys(key_pred, C * D)), (data,), static=(model.predict,)
        )
        pred = {k: np.asarray(v).reshape(C, D, -1) for k, v in pred.items()}
    reported = {
        k: np.asarray(v).reshape(C, D, *np.shape(v)[1:])
        for k, v in model.report(rows, beta, data).items()
    }
    attrs = {"model": model.name, "method": method}
    if chains is not None:
        attrs |= {
            "n_ensembles": chains.n_ensembles,
            "n_walkers": chains.n_walkers,
            "draw_order": "each chain is one emcee ensemble; draw = step * n_walkers + walker",
            "sampler": "emcee (DE, DE-snooker and independence-t moves) on the sampled parameters; "
            "coefficients drawn exactly",
        }
    idata = _idata(model, reported, ll, pred, data, lp, attrs)
    conv = convergence(reported, chains) if chains is not None else None
    ll_loo = None
    if model.pointwise_loo is not None:
        step = max(1, int(np.ceil(C * D / LOO_DRAWS)))
        sub = theta[:, ::step]
        ll_loo = np.asarray(
            map_rows(_loo_row, (sub.reshape(-1, nt),), (data,), static=(model.pointwise_loo,))
        ).reshape(sub.shape[0], sub.shape[1], -1)
    return Posterior(
        model.name,
        method,
        theta,
        beta.reshape(C, D, -1),
        ll,
        idata,
        optimum,
        conv,
        chains,
        time.perf_counter() - t0,
        ll_loo,
        data,
    )


# ----------------------------------------------------------------------------- drivers


def _signature(data) -> tuple:
    leaves, tree = jax.tree.flatten(data)
    return (tree, tuple(np.shape(x) for x in leaves))


def _campaign_log_prob(model: CollapsedModel, datas: list, active: np.ndarray):
    """One log-probability over all problems, (K, W, d) -> (K, W): one jitted, vmapped call per
    group of problems with equal data shapes (the tests of a campaign usually form one group)."""
    groups: dict[tuple, list[int]] = {}
    for i, d in enumerate(datas):
        groups.setdefault(_signature(d), []).append(i)
    stacked = [
        (np.array(idx), jax.tree.map(lambda *a: jnp.asarray(np.stack(a)), *[datas[i] for i in idx]))
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
                out[idx] = np.asarray(_log_prob_problems(model.log_prob, thetas[idx], d))
        return out

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
):
    """Fit ``model`` to ``data`` (one problem) or to a list of data (several problems, one emcee run).

    ``method``: "emcee" (sampling until the convergence rules pass, thinned to at most
    ``max_draws`` retained draws per problem) or "laplace" (``n_laplace`` independent draws from
    the Laplace approximation: quick screening, no convergence verdict). ``active`` (n_theta,)
    bool: the coordinates of theta that are free (the others are held at zero). ``seeds``: the
    seed of each problem's exact draws (default: derived from ``seed``). Returns a
    :class:`Posterior` (or a list of them for a list of data).
    """
    many = isinstance(data, list)
    datas = data if many else [data]
    t0 = time.perf_counter()
    optima = [find_map(model, d, active) for d in datas]
    act = optima[0].active
    dims = np.flatnonzero(act)
    if seeds is None:
        seeds = [seed + 1 + i for i in range(len(datas))] if many else [seed + 1]
    if method == "laplace":
        posts = []
        for d, opt, s in zip(datas, optima, seeds, strict=True):
            rng = np.random.default_rng(s)
            sub = rng.multivariate_normal(
                opt.theta[dims], opt.cov, size=n_laplace, method="cholesky"
            )
            theta = np.zeros((1, n_laplace, act.size))
            theta[0][:, dims] = sub
            posts.append(
                _finish(
                    model,
                    d,
                    theta,
                    opt,
                    seed=s,
                    method="laplace",
                    chains=None,
                    lp=None,
                    predictive=predictive,
                    t0=t0,
                )
            )
        return posts if many else posts[0]
    if method != "emcee":
        raise ValueError(f"method must be 'emcee' or 'laplace', got {method!r}")
    lp, expand = _campaign_log_prob(model, datas, act)
    names = [model.theta_names[i] for i in dims]
    runs = run_many(
        lp,
        np.stack([o.theta[dims] for o in optima]),
        np.stack([o.cov for o in optima]),
        names,
        seed=seed,
        settings=settings,
        desc=desc,
        mix=mix,
    )
    posts = []
    for d, opt, ch, s in zip(datas, optima, runs, seeds, strict=True):
        ch = thin(ch, max_draws)
        theta = expand(ch.samples)
        posts.append(
            _finish(
                model,
                d,
                theta,
                opt,
                seed=s,
                method="emcee",
                chains=ch,
                lp=ch.log_prob,
                predictive=predictive,
                t0=t0,
            )
        )
    return posts if many else posts[0]
