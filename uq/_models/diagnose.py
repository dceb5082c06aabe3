"""The models of ``uq diagnose``: the traditional baseline and its augmentations (section 4).

All tests of a campaign are fitted jointly. With t = (x - x0) / H, H = 0.05 m, and the
effective area F_eff(u) = sum_j a_j t^j (one curve for every pressure, order K by data):

    force   P_ij = p_i F_eff(u_ij)                                   (eq. 1)
    piston  L_ij = r_i - (1/S) int_{x0}^{x_ij} F_eff dx                (eq. 2, 5)

one piston reference r_i per test. Each mechanism adds columns or rescales columns, so the
model stays linear in (a, r, mechanism coefficients) given at most three nonlinear
magnitudes (pressure_dependent_area m_A, hysteresis m_H, volume_excess m_V):

    pressure_dependent_area  force and integral scaled by (1 + m_A p_bar)
    casing_force             force + E(u), E a cubic in t (magnitude E(x0) = e_0)
    hysteresis               force x (1 + m_H) on compression, (1 - m_H) on rebound
    force_offset             force + m
    thermal_drift            piston + step * m * 1e-6 / S   (m in cm^3 per step)
    volume_excess            integral scaled by (1 + m_V): dV/dx = F_eff (1 + m_V), force unchanged

Noise (the stand's error budget, section 3.2 of the paper): the same pressure-holding
error dp raises the force by dp F_eff and leaves the piston *short* by V_gas dp / (p_abs S)
(Boyle: at p + dp the gas needs less room), so force and piston residuals are strongly
anti-correlated. We fit the decorrelated pair z = P + c L (c = F_eff p_abs S / V_gas, a
plug-in constant per point, so c dL = -dp F_eff cancels the force's dp F_eff; a
unit-triangular linear map of the data, so likelihoods are unchanged in meaning) and L, each
with the budget's sd times a learned scale factor k_z, k_L (log k ~ N(0, 2^2)). The budget
(load cell, pressure holding, displacement, calipers, gas volumes) is a StandDescription,
the paper's stand by default.

Every model shares the same jitted functions (MAP solver, Hessian, log posterior, coefficient
draws): inactive mechanisms have zero columns (which cancel exactly in the collapsed marginal
likelihood) and inactive magnitudes are held at zero, the switches being array arguments, so a
campaign compiles each once, whatever the candidate. Each log posterior is formed from the
moments of a fixed expanded design (``Data``), not from the (2n x k) design itself: the same
numbers (tests/models/test_diagnose_model.py), about 8 times faster per call.
"""

from __future__ import annotations

import itertools
from typing import NamedTuple

import numpy as np

from uq._data.recordings import Recordings
from uq._data.stand_description import PAPER_STAND, StandDescription
from uq._inference.collapsed import CollapsedModel
from uq._inference.float64 import jax, jnp
from uq._inference.linear import draw_exact, gaussian_loglik, posterior_from_moments
from uq._physics.mechanisms import MECHANISMS, DesignContext, LinearTerm, ScaleTerm
from uq._physics.quantities import BAR_PA, BASIS_SCALE_M

#: every mechanism, in the order of the table in uq._physics.mechanisms
MECHS = tuple(MECHANISMS)
N_MECH = len(MECHS)
#: the mechanisms that are a magnitude multiplying parts of the model, and those with coefficients
SCALES = tuple(n for n in MECHS if isinstance(MECHANISMS[n].term, ScaleTerm))
LINEARS = tuple(n for n in MECHS if isinstance(MECHANISMS[n].term, LinearTerm))
K_MAX = 5  # highest power of t in F_eff
#: Number of parameters each mechanism adds (parsimony order: fewer is simpler).
N_PARAMS = {n: MECHANISMS[n].n_params for n in MECHS}
THETA_NAMES = ("log_k_force", "log_k_piston", *(f"m_{n}" for n in SCALES))
#: Prior sds of the sampled parameters (the noise scale factors', then each magnitude's).
THETA_PRIOR_SD = np.array([2.0, 2.0, *(MECHANISMS[n].term.prior_sd for n in SCALES)])
N_THETA = len(THETA_NAMES)
#: theta index of each nonlinear magnitude.
NONLINEAR = {n: 2 + i for i, n in enumerate(SCALES)}
#: a magnitude with g = 1 multiplies its parts as a whole (1 + m); the others split into terms
WHOLE = np.array([MECHANISMS[n].term.variable == "one" for n in SCALES])
FEFF_PRIOR_SD = 1.0  # m^2
REF_PRIOR_SD = 1.0  # m
FLOOR_N = 1.0
DP_RESIDUAL_SHARE = 0.2  # share of the pressure term left in z if V_gas is off


def model_columns(n_tests: int) -> dict[str, np.ndarray]:
    """The model's coefficient columns by group: "feff" (K_MAX + 1 powers of t), "offsets" (one
    piston reference per test), then each mechanism with coefficients (``LINEARS``)."""
    out, start = {}, 0
    for group, width in (
        ("feff", K_MAX + 1),
        ("offsets", n_tests),
        *((n, MECHANISMS[n].term.n_params) for n in LINEARS),
    ):
        out[group] = np.arange(start, start + width)
        start += width
    return out


class Data(NamedTuple):
    """Campaign arrays, one entry per recorded point (n,), the expanded design and its moments.

    The model's stacked design (z rows, then L rows; ``k`` columns: F_eff powers, one piston
    reference per test, casing cubic, offset, drift) depends on the sampled magnitudes only
    through factors that multiply fixed columns: with g = 1 + m_A p and hy = 1 + m_H sgn,
    p g hy t^j = p t^j + m_A p^2 t^j + m_H p sgn t^j + m_A m_H p^2 sgn t^j, and so on. So the
    design is ``E diag(coef(theta)) O``: ``E`` (2n, ke) the fixed expanded columns, ``coef``
    one factor per expanded column (:func:`_coef`), ``O`` (ke, k) which model column each one
    belongs to. Its weighted Gram matrix and right-hand side are then those of ``E``, formed
    once per campaign (``moments_E``), scaled by coef: a (ke x ke) product per noise draw
    instead of a (2n x k) design's Gram, about 10 times fewer operations.
    """

    p_bar: jnp.ndarray
    t: jnp.ndarray
    sgn: jnp.ndarray  # +1 compression, -1 rebound
    step: jnp.ndarray
    R: jnp.ndarray  # (n, n_tests)
    c: jnp.ndarray  # decorrelation constant, N/m
    force: jnp.ndarray
    piston: jnp.ndarray
    sd_z: jnp.ndarray  # budget sd of z, N
    sd_L: jnp.ndarray  # budget sd of L, m
    area: jnp.ndarray  # piston area S, m^2 (scalar)
    #: (2n,) 1 = row informs the fit, 0 = held out (K-fold); stacked as (z rows, L rows).
    fit_w: jnp.ndarray
    #: (2n,) 1 = row was recorded (a force-only campaign has no L rows): never fitted nor scored
    observed: jnp.ndarray
    E_z: jnp.ndarray  # (n, ke) expanded columns of the z rows
    E_L: jnp.ndarray  # (n, ke) expanded columns of the L rows
    onehot: jnp.ndarray  # (ke, k) O: the model column of each expanded column
    mask_idx: jnp.ndarray  # (ke,) int: entry of [mask, 1] switching the column on
    uses: jnp.ndarray  # (ke, len(SCALES)) whether the column's factor holds each magnitude
    prior_sd: jnp.ndarray  # (k,)
    #: Moments of E over the fitted rows at unit noise scales: z-rows' and L-rows' Gram (ke, ke),
    #: right-hand sides (ke,), y^T W y, sum log sd^2 and row counts, each (z, L).
    moments_E: tuple
    #: the model switch (``mask_of``): mechanism flags, then flags of the F_eff powers
    mask: jnp.ndarray


def _scale_value(name: str, ctx: DesignContext) -> np.ndarray:
    """g of a magnitude's factor (1 + m g) at every point."""
    variable = MECHANISMS[name].term.variable
    return {"pressure": ctx.p_bar, "branch": ctx.sgn, "one": np.ones_like(ctx.t)}[variable]


def _parts(ctx: DesignContext, R: np.ndarray):
    """(group, kind, raw columns, mask entry) of every part of the model: the traditional area's
    force (p F_eff) and volume (its integral, the piston's travel) parts, the piston references,
    and each mechanism's force and piston columns."""
    pw = np.arange(K_MAX + 1)
    T = ctx.t[:, None] ** pw
    Tint = -(BASIS_SCALE_M / ctx.area_m2) * ctx.t[:, None] ** (pw + 1) / (pw + 1)
    parts = [
        ("feff", "force", (ctx.p_bar * BAR_PA)[:, None] * T, N_MECH + pw),
        ("feff", "volume", Tint, N_MECH + pw),
        ("offsets", "volume", R, np.full(R.shape[1], N_MECH + K_MAX + 1)),
    ]
    for name in LINEARS:
        force, piston = MECHANISMS[name].term.columns(ctx)
        switch = MECHS.index(name)
        for kind, cols in (("force", force), ("volume", piston)):
            if cols is not None:
                parts.append((name, kind, np.asarray(cols, float), np.full(cols.shape[1], switch)))
    return parts


def _expanded(ctx: DesignContext, R, c):
    """The fixed expanded design (``Data``): z-row and L-row columns, the model column of each,
    the mask entry switching it and the magnitudes in its factor. Every part is expanded over the
    magnitudes that scale it (``ScaleTerm.scales``): (1 + m_1 g_1)(1 + m_2 g_2) B = B + m_1 g_1 B
    + ... term by term, except a magnitude with g = 1, which multiplies as a whole (1 + m)."""
    n = ctx.t.size
    cols = model_columns(R.shape[1])
    blocks = []
    for group, kind, raw, switch in _parts(ctx, R):
        applicable = [
            j for j, s in enumerate(SCALES) if f"{group}.{kind}" in MECHANISMS[s].term.scales
        ]
        split = [j for j in applicable if not WHOLE[j]]
        for subset in itertools.chain.from_iterable(
            itertools.combinations(split, r) for r in range(len(split) + 1)
        ):
            g = np.prod([_scale_value(SCALES[j], ctx) for j in subset], axis=0) if subset else 1.0
            block = raw * np.reshape(g, (-1, 1)) if subset else raw
            uses = np.zeros(len(SCALES))
            uses[list(subset) + [j for j in applicable if WHOLE[j]]] = 1.0
            if kind == "force":
                z, L = block, np.zeros_like(block)
            else:
                z, L = c[:, None] * block, block
            blocks.append((z, L, cols[group], switch, uses))
    E_z = np.concatenate([b[0] for b in blocks], axis=1)
    E_L = np.concatenate([b[1] for b in blocks], axis=1)
    width = sum(len(v) for v in cols.values())
    onehot = np.eye(width)[np.concatenate([b[2] for b in blocks])]
    mask_idx = np.concatenate([b[3] for b in blocks]).astype(np.int32)
    uses = np.concatenate([np.tile(b[4], (len(b[2]), 1)) for b in blocks])
    assert E_z.shape == (n, onehot.shape[0])
    return E_z, E_L, onehot, mask_idx, uses


def _moments(E_z, E_L, y_z, y_L, sd_z, sd_L, fit_w) -> tuple:
    """Weighted moments of the expanded design over the fitted rows at unit noise scales (numpy)."""
    n = y_z.size
    out = []
    for E, y, sd, w in ((E_z, y_z, sd_z, fit_w[:n]), (E_L, y_L, sd_L, fit_w[n:])):
        wt = w / sd**2
        out.append(
            (
                E.T @ (wt[:, None] * E),
                E.T @ (wt * y),
                float(wt @ y**2),
                float(w @ np.log(sd**2)),
                float(w.sum()),
            )
        )
    return tuple(
        jnp.asarray(np.stack([a, b]) if np.ndim(a) else np.array([a, b]))
        for a, b in zip(*out, strict=True)
    )


def hold_out(d: Data, held: np.ndarray) -> Data:
    """``d`` with rows held out of the fit: ``held`` bool, (n,) recorded points (their z and L
    rows both) or (2n,) single rows of the stacked (z, L) likelihood."""
    held = np.asarray(held, bool)
    if held.size == np.asarray(d.force).size:
        held = np.concatenate([held, held])
    fit_w = np.where(held, 0.0, np.asarray(d.observed))
    moments = _moments(
        *(np.asarray(a) for a in (d.E_z, d.E_L, decorrelated_force(d), d.piston, d.sd_z, d.sd_L)),
        fit_w,
    )
    return d._replace(fit_w=jnp.asarray(fit_w), moments_E=moments)


def scored_rows(d: Data) -> np.ndarray:
    """Indices of the stacked (z, L) rows that were recorded: every row, or the z rows of a
    force-only campaign. Pointwise log-likelihoods are scored (LOO, K-fold) on these only."""
    return np.flatnonzero(np.asarray(d.observed) > 0)


def decorrelated_force(d: Data):
    """z = P + c L: the pressure-holding error moves P by +dp F_eff and c L by -dp F_eff."""
    return d.force + d.c * d.piston


def _test_columns(
    test, i: int, rec: Recordings, stand: StandDescription
) -> tuple[dict, dict | None]:
    """One test's columns for ``prepare`` (the noise budget of z = P + cL and of L at every point,
    from a quartic least-squares plug-in) and its area check at x0 (None without a volume).

    The L rows are the piston coordinates; a test with a volume column instead (a catalogue's
    volume at its stated pressure) has L = -V/S, its own reference absorbing V's origin, and no
    pressure-holding coupling (c = 0: the volume was not read off the stand's piston); a test
    with neither has no L rows (``obs`` 0: neither fitted nor scored)."""
    S = rec.piston_area_m2
    if test.piston_m is not None:
        piston, source = test.piston_m, "piston"
    elif test.volume_m3 is not None:
        piston, source = -test.volume_m3 / S, "volume"
    else:
        piston, source = np.zeros(test.n_points), None
    u = test.height_m - rec.x0_m
    t = u / BASIS_SCALE_M
    deg = min(4, test.n_points - 2)
    V = np.vander(t, deg + 1, increasing=True)
    cf = np.linalg.lstsq(V, test.force_N, rcond=None)[0]
    cl = np.linalg.lstsq(V, piston, rcond=None)[0]
    dV = np.vander(t, deg, increasing=True) * np.arange(1, deg + 1) / BASIS_SCALE_M
    P_hat, dPdx, slope = V @ cf, dV @ cf[1:], dV @ cl[1:]
    p_pa = test.pressure_bar * BAR_PA
    feff = np.abs(P_hat) / p_pa
    # The gas a pressure error compresses (Boyle): element, receiver and pipe, whose volume keeps
    # its value in isobaric-isothermal conditions (eq. 4: the gas/water boundary moves inside the
    # receiver as the element is compressed).
    v_gas = stand.gas_volume_at_xmax_m3
    p_abs_bar = test.pressure_bar + stand.p_atm_bar
    sdp_bar = float(stand.pressure_sd_bar(test.pressure_bar))
    n = test.n_points
    # z = P + cL cancels the pressure-holding error but for DP_RESIDUAL_SHARE (c is a plug-in);
    # with no piston read on the stand (a catalogue's volume, or force only) c = 0 and z = P keeps
    # the whole pressure term
    dp_share = DP_RESIDUAL_SHARE if source == "piston" else 1.0
    # unknown order (a catalogue table): no branch sign, the rows' order as steps; neither
    # hysteresis nor a drift is then offered (their ``needs``)
    order_known = test.compression is not None and test.step is not None
    cols = {
        "p": np.full(n, test.pressure_bar),
        "t": t,
        "sgn": np.where(test.compression, 1.0, -1.0) if order_known else np.zeros(n),
        "step": test.step.astype(float) if order_known else np.arange(n, dtype=float),
        "ti": np.full(n, i),
        # only a piston read during the pressure-holding error moves against the force
        "c": feff * p_abs_bar * BAR_PA * S / v_gas if source == "piston" else np.zeros_like(feff),
        "obs": np.full(n, 0.0 if source is None else 1.0),
        "F": test.force_N,
        "L": piston,
        "sdz": np.sqrt(
            (stand.load_cell_rel_sd * P_hat) ** 2
            + (dp_share * sdp_bar * BAR_PA * feff) ** 2
            + (dPdx * stand.displacement_sd_m) ** 2
            + FLOOR_N**2
        ),
        "sdL": np.sqrt(
            (v_gas * sdp_bar / p_abs_bar / S) ** 2
            + (slope * stand.displacement_sd_m) ** 2
            + stand.caliper_sd_m**2
        ),
        "x": test.height_m,
        "comp": test.compression if order_known else np.ones(n, bool),
    }
    if source is None:
        return cols, None
    i0 = np.argmin(np.abs(u))
    check = {
        "pressure_bar": test.pressure_bar,
        "from_force_m2": float(P_hat[i0] / p_pa),
        "from_volume_m2": float(-S * slope[i0]),
        "volume_over_force": float(-S * slope[i0] / (P_hat[i0] / p_pa)),
    }
    return cols, check


def prepare(rec: Recordings, stand: StandDescription = PAPER_STAND) -> tuple[Data, dict]:
    """Arrays for the models and per-point metadata (numpy) for the residual analysis.

    Noise formulas from ``stand`` (its error budget and gas volumes)."""
    S = rec.piston_area_m2
    parts = [_test_columns(test, i, rec, stand) for i, test in enumerate(rec.tests)]
    area_check = [check for _, check in parts if check is not None]
    cols = {k: [c[k] for c, _ in parts] for k in parts[0][0]}
    cat = {k: np.concatenate(v) for k, v in cols.items()}
    R = np.eye(len(rec.tests))[cat["ti"].astype(int)]
    ctx = DesignContext(cat["t"], cat["p"], cat["sgn"], cat["step"], S)
    E_z, E_L, onehot, mask_idx, uses = _expanded(ctx, R, cat["c"])
    n_points = cat["F"].size
    # tests without piston or volume have no L rows; they are neither fitted nor scored
    observed = np.concatenate([np.ones(n_points), cat["obs"]])
    prior_sd = np.concatenate(
        [np.full(K_MAX + 1, FEFF_PRIOR_SD), np.full(R.shape[1], REF_PRIOR_SD)]
        + [np.full(MECHANISMS[n].term.n_params, MECHANISMS[n].term.prior_sd) for n in LINEARS]
    )
    moments = _moments(
        E_z, E_L, cat["F"] + cat["c"] * cat["L"], cat["L"], cat["sdz"], cat["sdL"], observed
    )
    data = Data(
        *(
            jnp.asarray(a, dtype=float)
            for a in (
                cat["p"],
                cat["t"],
                cat["sgn"],
                cat["step"],
                R,
                cat["c"],
                cat["F"],
                cat["L"],
                cat["sdz"],
                cat["sdL"],
                S,
                observed,
                observed,
                E_z,
                E_L,
                onehot,
            )
        ),
        jnp.asarray(mask_idx),
        jnp.asarray(uses),
        jnp.asarray(prior_sd),
        moments,
        mask_of((), 3),
    )
    meta = {
        "pressure_bar": cat["p"],
        "height_m": cat["x"],
        "compression": cat["comp"].astype(bool),
        "step": cat["step"].astype(int),
        "test": cat["ti"].astype(int),
        "force_N": cat["F"],
        "piston_m": cat["L"],
        "has_volume": bool(cat["obs"].any()),
        "volume_observed": cat["obs"] > 0,
        "order_known": all(t.compression is not None and t.step is not None for t in rec.tests),
        "context": ctx,
        "area": S,
        "area_check": area_check,
    }
    return data, meta


def mask_of(names, order: int) -> jnp.ndarray:
    """Dynamic model switch: N_MECH mechanism flags (order of MECHS), then flags for powers 0..K_MAX of F_eff."""
    mech = [1.0 if m in names else 0.0 for m in MECHS]
    powers = [1.0 if j <= order else 0.0 for j in range(K_MAX + 1)]
    return jnp.asarray(mech + powers)


_SCALE_SWITCH = np.array([MECHS.index(n) for n in SCALES])


def _coef(theta, mask, d: Data):
    """The factor of every expanded column (ke,): its switch times the magnitudes it holds (m for
    a split term, 1 + m for a magnitude that multiplies as a whole)."""
    m = mask[_SCALE_SWITCH] * theta[2:]
    f = jnp.where(WHOLE, 1.0 + m, m)
    switch = jnp.concatenate([mask, jnp.ones(1)])[d.mask_idx]
    return switch * jnp.prod(jnp.where(d.uses > 0, f, 1.0), axis=1)


def _posterior(theta, mask, d: Data):
    """Collapsed posterior of the coefficients given theta, from the moments (``Data``).

    Returns the posterior in column-scaled coordinates, the column scales s and the expanded-
    design factors. Column scaling (s = root mean square of the whitened column, from the
    Gram diagonal) is an exact reparametrisation (the marginal likelihood is invariant), for
    numerics. Held-out rows (fit_w = 0) are left out of the moments."""
    G, b, yy, ld, cnt = d.moments_E
    k_z2, k_L2 = jnp.exp(2.0 * theta[0]), jnp.exp(2.0 * theta[1])
    coef = _coef(theta, mask, d)
    GE = G[0] / k_z2 + G[1] / k_L2
    bE = b[0] / k_z2 + b[1] / k_L2
    O = d.onehot * coef[:, None]
    gram = O.T @ GE @ O
    rhs = O.T @ bE
    n_rows = 2 * d.force.size
    s = jnp.sqrt(jnp.diagonal(gram) / n_rows)
    s = jax.lax.stop_gradient(jnp.where(s > 0, s, 1.0))
    log_noise_det = ld[0] + ld[1] + 2.0 * (cnt[0] * theta[0] + cnt[1] * theta[1])
    post = posterior_from_moments(
        gram / jnp.outer(s, s),
        rhs / s,
        yy[0] / k_z2 + yy[1] / k_L2,
        n_rows,
        log_noise_det,
        d.prior_sd * s,
    )
    return post, s, coef


#: Support of the sampled parameters: noise scale factors within e^+-8 of the stand's budget and
#: magnitudes below 1 in size (a 100 % branch difference or volume excess; 1/bar of area growth).
#: Beyond them the collapsed marginal likelihood is not computable in float64: with noise
#: e^-45 times the budget the quadratic form y^T W y - m^T A m cancels to garbage and an
#: optimiser can run away along it.
LOG_K_BOUND = 8.0
MAGNITUDE_BOUND = 1.0


def log_prob(theta, d: Data):
    """Log posterior of the sampled parameters (N_THETA,), coefficients integrated out, for the
    model switched on by ``d.mask``."""
    lp = _posterior(theta, d.mask, d)[0].log_marginal
    active = jnp.concatenate([jnp.ones(2), d.mask[_SCALE_SWITCH]])
    lp = lp - 0.5 * jnp.sum(active * (theta / THETA_PRIOR_SD) ** 2)
    inside = jnp.all(jnp.abs(theta[:2]) < LOG_K_BOUND) & jnp.all(
        jnp.abs(theta[2:]) < MAGNITUDE_BOUND
    )
    return jnp.where(inside, lp, -jnp.inf)


def draw_linear(theta, key, d: Data):
    """An exact coefficient draw given theta (model columns: F_eff powers, piston references,
    casing cubic, offset, drift)."""
    post, s, _ = _posterior(theta, d.mask, d)
    return draw_exact(post, key) / s


def means(theta, beta, d: Data):
    """Force and piston means of every recorded point at one draw, and the noise sd of every
    row of the stacked (z, L) likelihood: (muF (n,), muL (n,), sigma (2n,))."""
    coef = _coef(theta, d.mask, d)
    beta_E = coef * (d.onehot @ beta)
    muL = d.E_L @ beta_E
    mu_z = d.E_z @ beta_E
    sigma = jnp.concatenate([jnp.exp(theta[0]) * d.sd_z, jnp.exp(theta[1]) * d.sd_L])
    return mu_z - d.c * muL, muL, sigma


def pointwise(theta, beta, d: Data):
    """Log-likelihood of every row of the stacked likelihood, held out or not: the decorrelated
    force z = P + cL and the piston L, (n,) each."""
    muF, muL, sigma = means(theta, beta, d)
    n = d.force.shape[0]
    mu_z = muF + d.c * muL
    return {
        "z": gaussian_loglik(decorrelated_force(d), mu_z, sigma[:n]),
        "L": gaussian_loglik(d.piston, muL, sigma[n:]),
    }


_MECH_OF = {i: name for name, i in NONLINEAR.items()}

#: starts of the optimiser: zero, and the nonlinear magnitudes at +-MAP_START
MAP_START = 0.01


def start(d: Data) -> np.ndarray:
    mask = np.asarray(d.mask)
    nonlin = np.zeros(N_THETA)
    for name, i in NONLINEAR.items():
        nonlin[i] = mask[MECHS.index(name)]
    zero = np.zeros(N_THETA)
    return np.stack([zero, MAP_START * nonlin, -MAP_START * nonlin]) if nonlin.any() else zero[None]


def report(theta, beta, d: Data) -> dict:
    """The sampled parameters of the model switched on by ``d.mask`` (the held ones are zeros)."""
    mask = np.asarray(d.mask)
    on = [i for i in range(N_THETA) if i < 2 or mask[MECHS.index(_MECH_OF[i])] > 0]
    return {THETA_NAMES[i]: np.asarray(theta)[:, i] for i in on}


MODEL = CollapsedModel.of(
    globals(), "traditional model with mechanisms (uq diagnose)", THETA_NAMES, sequential=True
)


def with_model(d: Data, names, order: int) -> Data:
    """The data with the model switched to ``names`` and F_eff polynomial order ``order``."""
    return d._replace(mask=mask_of(names, order))


def active_of(names) -> np.ndarray:
    """The free coordinates of theta for a model with mechanisms ``names`` (bool, (N_THETA,))."""
    act = np.zeros(N_THETA, bool)
    act[[0, 1, *(NONLINEAR[m] for m in names if m in NONLINEAR)]] = True
    return act
