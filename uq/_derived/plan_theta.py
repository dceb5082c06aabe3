"""The preposterior that also updates theta (docs/plan.md, scenario D): the distribution of the
posterior sd a planned set of readings will achieve when the readings also teach the sampled
parameters theta (noise scales, the discrepancy's amplitudes and length scale).

``uq plan``'s prediction (``uq._derived.plan_search.evaluate``) averages over the pilot's draws of
theta the posterior variance given theta, which does not depend on the readings' values. When the new
readings rule out part of the pilot's theta (a short length scale the pilot's tests far apart cannot
exclude), the achieved posterior is that of the reweighted draws, and the prediction is too wide.
Here the planned readings are simulated and the pilot's draws reweighted, all in closed form given
theta (numpy only):

1. a simulated set: a draw s of the pilot's theta (uniform: the draws are the pilot's posterior),
   coefficients beta ~ N(m_s, A_s^-1) given theta_s and the pilot's readings (the frame's
   precision and mean), the readings y = X_s beta + noise with the noise at theta_s (y = C_s (Z_s beta
   + e), e ~ N(0, I); Z the frame's whitened rows, C their noise factor, ``Frame.reading_noise``);
2. the weight of each draw t of a pool of the pilot's theta draws, held out of those the sets are
   simulated from (``uq plan --theta-pool``): the new readings' predictive density given theta_t
   and the pilot's readings (the pilot's own likelihood is already in the draws),

       log p(y | theta_t, pilot) = -1/2 [ |r|^2 - |L^-1 Z' r|^2 + log det B_t - log det A_t ]
                                   - sum log diag C_t  + const,

   r = C_t^-1 y - Z_t m_t, B_t = A_t + Z_t' Z_t = L L' (Woodbury and the determinant lemma: the
   readings' covariance Z A^-1 Z' + I in whitened units; the Jacobian of the whitening C_t^-1, which
   depends on theta, is the last term);
3. the target's posterior given theta_t and all readings: mean_t = value_t + g_t' B_t^-1 Z_t' r (the
   target linearised at the pilot's posterior mean given theta_t, as the closed form is: value_t, g_t
   from ``plan_targets``), variance V_t = g_t' B_t^-1 g_t + its irreducible part (the closed form,
   which does not depend on y);
4. the mixture's variance sum_t w_t (V_t + (mean_t - mean_w)^2) is the target's posterior variance
   after that set; its sd over the simulated sets is the answer (median, 10-90 % range, mean).

The weights' Kish effective sample size 1 / sum w^2 says how many of the pilot's draws carry a set's
answer: when the new readings pin theta far inside the pilot's draws, few draws are left and the
answer is as coarse as they are (it is reported, and flagged below ``SMALL_ESS``).

Why the pool is held out: the true theta of a campaign is not one of the pilot's draws. Were the
draw a set is simulated from among those reweighted, readings that pin theta would put the weight
on that very draw, and the answer would be the posterior of a fit that knew theta exactly: too
narrow by the spread over theta the real fit keeps (scripts/plan_proof.py measured the uniform
grid's achieved sd at 1.5-1.7 times such a prediction for ``pressure_for`` between tested
pressures). With a held-out pool the reweighting is an importance-sampling estimate of the
posterior the fit will have, consistent as the pool grows.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from uq._derived.plan_search import Frame, opened

THETA_UPDATES = 200  # simulated sets of the planned readings (uq plan --theta-updates)
THETA_POOL = 400  # the pilot's draws of theta reweighted, held out of those the sets come from
SET_CHUNK = 20  # simulated sets per block (memory: sets x draws x readings)
SMALL_ESS = 10.0  # a set whose weights keep fewer effective draws is flagged
QUANTILES = (0.1, 0.5, 0.9)


def solve_lower(C: np.ndarray, y: np.ndarray) -> np.ndarray:
    """C^-1 y for lower-triangular r x r blocks C (..., r, r) and y (..., r) (forward substitution;
    r is 1 or 2 here)."""
    r = C.shape[-1]
    out = np.empty(np.broadcast_shapes(C.shape[:-1], y.shape))
    for i in range(r):
        acc = y[..., i] - np.sum(C[..., i, :i] * out[..., :i], axis=-1)
        out[..., i] = acc / C[..., i, i]
    return out


@dataclass(frozen=True)
class Parts:
    """What the reweighting needs of a frame and a planned set of readings, per draw of theta (S
    draws, k coefficients, n readings of r rows, T targets)."""

    Z: np.ndarray  # (S, n, r, k) whitened rows of the planned readings
    C: np.ndarray  # (S, n, r, r) their noise factor (Frame.reading_noise)
    mean: np.ndarray  # (S, k) coefficients' posterior mean given theta and the pilot
    chol_pilot: np.ndarray  # (S, k, k) Cholesky factor of the pilot's precision A
    inv_chol: np.ndarray  # (S, k, k) inverse of the Cholesky factor of B = A + Z'Z
    log_det: np.ndarray  # (S,) log det B - log det A + 2 sum log diag C
    value: np.ndarray  # (S, T) the targets at the pilot's mean given theta
    H: np.ndarray  # (S, k, T) L^-1 g: the targets' gradients in B's whitened coordinates
    var: np.ndarray  # (S, T) the closed-form posterior variance given theta (evaluate's)


def parts_of(Z, C, precision, mean, value, grad, extra) -> Parts:
    """:class:`Parts` from arrays: ``Z`` (S, n, r, k), ``C`` (S, n, r, r), the pilot's ``precision``
    (S, k, k) and ``mean`` (S, k), the targets' ``value`` (S, T), gradient ``grad`` (S, k, T) and
    irreducible variance ``extra`` (S, T)."""
    Z, C = np.asarray(Z, float), np.asarray(C, float)
    S, n, r, k = Z.shape
    Zf = Z.reshape(S, n * r, k)
    B = precision + np.einsum("sik,sil->skl", Zf, Zf)
    LB = np.linalg.cholesky(B)
    LA = np.linalg.cholesky(precision)
    inv = np.linalg.inv(LB)
    diag = np.log(np.abs(np.diagonal(C, axis1=-2, axis2=-1))).reshape(S, -1).sum(1)
    log_det = 2.0 * (
        np.log(np.diagonal(LB, axis1=1, axis2=2)).sum(1)
        - np.log(np.diagonal(LA, axis1=1, axis2=2)).sum(1)
        + diag
    )
    H = inv @ grad
    return Parts(Z, C, mean, LA, inv, log_det, value, H, np.sum(H**2, axis=1) + extra)


def frame_parts(frame: Frame, targets, readings) -> Parts:
    """:class:`Parts` of a frame (``uq._derived.plan_search.Frame``, with ``reading_noise``) and a
    planned set of readings, the targets linearised at the pilot's posterior mean given theta in the
    frame's tests the readings open (as ``evaluate`` does)."""
    if frame.reading_noise is None:
        raise ValueError(f"the frame of {frame.name} gives no reading_noise")
    readings = list(readings)
    by: dict[int, list[float]] = {}
    for rd in readings:
        by.setdefault(rd.test, []).append(rd.height_m)
    Z = np.concatenate([frame.reading_rows(j, np.asarray(h, float)) for j, h in by.items()], axis=1)
    C = np.concatenate(
        [frame.reading_noise(j, np.asarray(h, float)) for j, h in by.items()], axis=1
    )
    open_ = opened(frame, readings)
    lin = [t.linearise(frame, frame.mean, open_) for t in targets]  # as target_columns
    value, G, E = (np.stack([x[i] for x in lin], axis=-1) for i in range(3))
    return parts_of(Z, C, frame.precision, frame.mean, value, G, E)


def simulate(parts: Parts, n_sets: int, rng: np.random.Generator):
    """``n_sets`` sets of the planned readings from the pilot's posterior predictive: (readings in
    their units (M, n, r), the draw of theta behind each (M,), its coefficients (M, k)): a draw of
    theta, the coefficients given it and the pilot's readings, the readings' noise at it."""
    S, n, r, k = parts.Z.shape
    s = rng.integers(S, size=n_sets)
    z = rng.standard_normal((n_sets, k))
    e = rng.standard_normal((n_sets, n, r))
    # beta = m + L_A^-T z: covariance A^-1
    LA = parts.chol_pilot[s]
    beta = parts.mean[s] + np.linalg.solve(np.swapaxes(LA, -1, -2), z[..., None])[..., 0]
    yw = (parts.Z[s].reshape(n_sets, n * r, k) @ beta[..., None])[..., 0].reshape(n_sets, n, r) + e
    return np.einsum("mnrq,mnq->mnr", parts.C[s], yw), s, beta


def mixture(parts: Parts, y: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The targets' posterior after each set of readings ``y`` (M, n, r), the pilot's draws
    reweighted by the readings' predictive density given each (module docstring): (variance (M, T),
    posterior mean (M, T), Kish effective sample size of the weights (M,))."""
    y = np.asarray(y, float)
    M = y.shape[0]
    S, n, r, k = parts.Z.shape
    T = parts.value.shape[1]
    var, mean, ess = np.empty((M, T)), np.empty((M, T)), np.empty(M)
    Zf = parts.Z.reshape(S, n * r, k)
    fitted = (Zf @ parts.mean[..., None])[..., 0].reshape(S, n, r)
    for lo in range(0, M, SET_CHUNK):
        yc = y[lo : lo + SET_CHUNK]
        res = (solve_lower(parts.C[None], yc[:, None]) - fitted[None]).reshape(-1, S, n * r)
        u = (res[..., None, :] @ Zf[None])[..., 0, :]  # (c, S, k): Z' r
        w = (parts.inv_chol[None] @ u[..., None])[..., 0]  # L^-1 Z' r
        quad = np.sum(res**2, axis=2) - np.sum(w**2, axis=2)
        logp = -0.5 * (quad + parts.log_det[None])
        logp -= logp.max(axis=1, keepdims=True)
        wt = np.exp(logp)
        wt /= wt.sum(axis=1, keepdims=True)  # (c, S)
        mu = parts.value[None] + (w[..., None, :] @ parts.H[None])[..., 0, :]  # (c, S, T)
        mbar = np.einsum("cs,cst->ct", wt, mu)
        v = np.einsum("cs,cst->ct", wt, parts.var[None] + (mu - mbar[:, None]) ** 2)
        var[lo : lo + SET_CHUNK], mean[lo : lo + SET_CHUNK] = v, mbar
        ess[lo : lo + SET_CHUNK] = 1.0 / np.sum(wt**2, axis=1)
    return var, mean, ess


def summary(sd: np.ndarray, ess: np.ndarray, draws: int, held_out: bool) -> dict | None:
    """One target's answer over the simulated sets (None where it is not finite), with the number
    of theta draws reweighted and whether they are held out of those the sets come from."""
    if not np.all(np.isfinite(sd)):
        return None
    p10, p50, p90 = np.quantile(sd, QUANTILES)
    return {
        "median": float(p50),
        "p10": float(p10),
        "p90": float(p90),
        "mean": float(np.mean(sd)),
        "ess_min": float(np.min(ess)),
        "ess_median": float(np.median(ess)),
        "small_ess_share": float(np.mean(ess < SMALL_ESS)),
        "draws": int(draws),
        "held_out": bool(held_out),
    }


def theta_updated(
    frame: Frame, targets, readings, n_sets: int = THETA_UPDATES, seed: int = 0, pool=None
):
    """Each target's posterior sd after the planned ``readings`` with theta updated by them, over
    ``n_sets`` simulated sets (module docstring): a list of :func:`summary` dicts (None for a
    target the model cannot answer), deterministic for ``seed``. The sets are simulated from
    ``frame``'s draws of theta and reweighted over ``pool``'s: the same frame on other draws of
    the pilot's posterior (``uq._derived.plan_frames``' ``pool``); None reweights ``frame``'s
    own draws, the simulating draw among them."""
    parts = frame_parts(frame, targets, readings)
    rng = np.random.default_rng(seed)
    y, _, _ = simulate(parts, n_sets, rng)
    weighed = parts if pool is None else frame_parts(pool, targets, readings)
    var, _, ess = mixture(weighed, y)
    sd = np.sqrt(np.maximum(var, 0.0))
    S = weighed.Z.shape[0]
    return [summary(sd[:, i], ess, S, pool is not None) for i in range(sd.shape[1])]
