"""The Gaussian process in pressure of the discrepancy surface: kernel, priors, draws between tests.

Each coefficient k of a deviation block (the pressure-area deviation delta, the volume-area
deviation eps, the force's deviation phi; uq._models.discrepancy) is, over the tested pressures, a zero-mean Gaussian process
in the overpressure p_u (bar):

    Cov(delta_k(p), delta_k(p')) = a^2 s_k^2 R(|p - p'| / l),   R Matern 3/2:  (1 + r) exp(-r),
    r = sqrt(3) |p - p'| / l,

with one amplitude a per block, a shared length scale l (bar) and fixed coefficient scales s_k.

Why Matern 3/2. The springs this is for are not smooth in pressure (a cord layer that engages at
some pressure puts a kink into the force's pressure dependence; Table 1's per-pressure fits wiggle
from test to test): Matern 3/2 paths are once differentiable, not twice, so they follow a kink
(the squared-exponential kernel's analytic paths cannot, and its predictions between tests are
overconfident when the truth bends abruptly), while unlike Matern 1/2 (Brownian-like paths, no
slope) a draw is a curve whose value between two close pressures is almost fixed by its values at
them: a force at 801 pressures is a coherent function of p per draw, and a grid of pressures
(``GRID_STEP_BAR``) with the two-point conditional mean between its nodes carries the process
between tests with a neglected conditional sd of at most 5 % of the amplitude for l >= 0.5 bar
(``interpolation_sd``). 1/2 would leave 22 % at the same grid.

Priors (penalised complexity, Simpson et al. 2017; Fuglstad et al. 2019 for the Matern range):

* amplitude: exponential, P(a > U) = ``AMPLITUDE_TAIL`` with U = ``AMPLITUDE_UPPER_REL`` times the
  campaign's reference area (the median pressure area of a least-squares fit, m^2). The
  exponential puts its mode at a = 0, the base model (the smooth surface): without evidence of a
  deviation the amplitude shrinks towards zero and the model is the surface.
* length scale: the PC prior of a Matern range in one dimension, density
  (lam / 2) l^(-3/2) exp(-lam l^(-1/2)), with P(l < ``LENGTH_LOWER_BAR``) = ``LENGTH_TAIL``. It
  shrinks towards l = infinity (a deviation that is one smooth function over all tests: the
  surface absorbs it) and keeps l from being far below a bar, the spacing of the paper's tests,
  without forbidding it (P(l < 0.25 bar) = 0.06): median 4 bar.
"""

from __future__ import annotations

import numpy as np

SQRT3 = float(np.sqrt(3.0))
#: P(a > AMPLITUDE_UPPER_REL x reference area) = AMPLITUDE_TAIL
AMPLITUDE_UPPER_REL = 0.04
AMPLITUDE_TAIL = 0.05
#: P(l < LENGTH_LOWER_BAR) = LENGTH_TAIL
LENGTH_LOWER_BAR = 1.0
LENGTH_TAIL = 0.25
#: spacing of the virtual pressures that carry a draw between tested pressures (bar); campaigns
#: over more than 10 bar use GRID_MAX_NODES nodes
GRID_STEP_BAR = 0.1
GRID_MAX_NODES = 201
#: s_k: the prior sd of every deviation coefficient relative to its block's amplitude (t^k is of
#: order one over the stroke, |t| <= 0.94 on the paper's heights, so every k gets the same)
COEFFICIENT_SCALE = 1.0
#: relative jitter on the correlation matrices' diagonal (a long length scale makes them nearly
#: singular); 1e-9 of the amplitude's variance, far below anything the data resolve
JITTER = 1e-9


def matern32(d, length, xp=np):
    """Matern 3/2 correlation of pressures ``d`` apart (bar) at length scale ``length`` (bar)."""
    r = SQRT3 * xp.abs(d) / length
    return (1.0 + r) * xp.exp(-r)


def per_distance(d, length):
    """``matern32(d, l_s)`` for every draw's length scale ``length`` (S,): (S, *d.shape), the same
    numbers, each computed once per distinct |d| (a grid's distances repeat)."""
    u, inv = np.unique(np.abs(d), return_inverse=True)
    return matern32(u, np.asarray(length, float)[:, None])[:, inv.reshape(np.shape(d))]


def correlation(p_bar, length, xp=np):
    """R (T, T) of the tested pressures with the jitter on its diagonal."""
    p = xp.asarray(p_bar)
    return matern32(p[:, None] - p[None, :], length, xp) + JITTER * xp.eye(p.shape[0])


def amplitude_rate(reference_area_m2: float) -> float:
    """The exponential prior's rate (1/m^2) for a campaign of this reference area."""
    return -np.log(AMPLITUDE_TAIL) / (AMPLITUDE_UPPER_REL * reference_area_m2)


LENGTH_RATE = -np.log(LENGTH_TAIL) * np.sqrt(LENGTH_LOWER_BAR)


def log_prior_amplitude(log_a, rate, xp=np):
    """log density of log a for a ~ Exponential(rate) (the Jacobian a included)."""
    return xp.log(rate) - rate * xp.exp(log_a) + log_a


def log_prior_length(log_l, xp=np):
    """log density of log l for the PC prior of a Matern range in one dimension (Jacobian included)."""
    return np.log(LENGTH_RATE / 2.0) - 0.5 * log_l - LENGTH_RATE * xp.exp(-0.5 * log_l)


def prior_start(rate) -> tuple[float, float]:
    """(log a, log l) where the optimiser starts: the amplitude's prior mean, the length's median."""
    return float(np.log(1.0 / rate)), float(np.log((LENGTH_RATE / np.log(2.0)) ** 2))


def grid_nodes(tested_bar) -> np.ndarray:
    """The virtual pressures between the tested ones (bar): an even grid over the tested range,
    nodes that coincide with a tested pressure (within a quarter step) left out."""
    p = np.sort(np.asarray(tested_bar, float))
    lo, hi = float(p[0]), float(p[-1])
    n = int(min(GRID_MAX_NODES, np.ceil((hi - lo) / GRID_STEP_BAR) + 1))
    if hi - lo <= 0 or n < 2:
        return np.zeros(0)
    g = np.linspace(lo, hi, n)
    step = (hi - lo) / (n - 1)
    keep = np.min(np.abs(g[:, None] - p[None, :]), axis=1) > step / 4
    return g[keep]


def tested_values(z, scales, length, tested_bar):
    """The deviations at the tested pressures from standard normals: a s_k chol(R(l)) z, draw by
    draw. ``z`` (S, c, T), ``scales`` (S, c) = a s_k, ``length`` (S,); returns (S, T, c)."""
    p = np.asarray(tested_bar, float)
    R = matern32(
        p[:, None] - p[None, :], np.asarray(length, float)[:, None, None]
    ) + JITTER * np.eye(p.size)
    return np.einsum("sij,scj->sic", np.linalg.cholesky(R), z) * np.asarray(scales)[:, None, :]


def draw_on_grid(values_T, scales, length, tested_bar, grid_bar, xi):
    """Draws of the process at ``grid_bar`` given its values at ``tested_bar``, draw by draw.

    ``values_T`` (S, T, c): the values of c series at the tested pressures, ``scales`` (S, c) their
    prior sd (a s_k), ``length`` (S,), ``xi`` (S, G, c) standard normals. Returns (S, G, c):
    R_GT R_TT^-1 v + scale chol(R_GG - R_GT R_TT^-1 R_TG) xi, exact (the grid's values carry no
    data: given the values at the tested pressures they are independent of the readings)."""
    T, G = len(tested_bar), len(grid_bar)
    if G == 0:
        return np.zeros((values_T.shape[0], 0, values_T.shape[2]))
    allp = np.concatenate([np.asarray(tested_bar, float), np.asarray(grid_bar, float)])
    R = per_distance(allp[:, None] - allp[None, :], length) + JITTER * np.eye(T + G)
    Rtt, Rgt, Rgg = R[:, :T, :T], R[:, T:, :T], R[:, T:, T:]
    W = np.linalg.solve(Rtt, np.swapaxes(Rgt, 1, 2))  # (S, T, G) = R_TT^-1 R_TG
    mean = np.swapaxes(W, 1, 2) @ values_T  # (S, G, c); matrix products, not einsum: BLAS
    cov = Rgg - Rgt @ W
    cov = 0.5 * (cov + np.swapaxes(cov, 1, 2)) + JITTER * np.eye(G)
    return mean + (np.linalg.cholesky(cov) @ xi) * scales[:, None, :]


def two_point_weights(p_bar, nodes_bar, length):
    """Index of the left bracketing node and the two weights of the conditional mean from the two
    bracketing nodes, per draw: ``p_bar`` (n,), ``nodes_bar`` (N,) ascending, ``length`` (S,);
    returns i (n,), w (S, n, 2)."""
    p = np.asarray(p_bar, float)
    nodes = np.asarray(nodes_bar, float)
    i = np.clip(np.searchsorted(nodes, p, side="right") - 1, 0, nodes.size - 2)
    pa, pb = nodes[i], nodes[i + 1]
    ka, kb, r = (per_distance(x, length) for x in (p - pa, pb - p, pb - pa))
    den = 1.0 - r**2
    with np.errstate(invalid="ignore", divide="ignore"):
        w = np.stack([(ka - r * kb) / den, (kb - r * ka) / den], axis=-1)
    # a length scale so long that 1 - r^2 cancels (l > 1e4 node steps): the two-point mean's limit,
    # linear interpolation
    far = (den < 1e-9)[..., None]
    if far.any():
        lin = np.stack(np.broadcast_arrays((pb - p) / (pb - pa), (p - pa) / (pb - pa)), axis=-1)
        w = np.where(far, np.broadcast_to(lin, w.shape), w)
    return i, w


def interpolation_sd(step_over_length: float) -> float:
    """The conditional sd (relative to the amplitude) the two-point mean neglects half-way between
    two nodes ``step_over_length`` length scales apart: the error of carrying a draw between nodes.
    Below ``1e-4`` (a length scale ten thousand steps long, which the weakly identified tail of a
    campaign of few pressures reaches) the two nodes' correlation is 1 to rounding and the
    neglected sd below 1e-6: 0."""
    if step_over_length < 1e-4:
        return 0.0
    x = np.array([0.0, step_over_length])
    K = matern32(x[:, None] - x[None, :], 1.0, np)
    k = matern32(step_over_length / 2 - x, 1.0, np)
    return float(np.sqrt(max(1.0 - k @ np.linalg.solve(K, k), 0.0)))
