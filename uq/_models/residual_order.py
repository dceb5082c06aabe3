"""Are a test's residuals independent in recording order? The check behind a model warning.

Every model here assumes independent reading errors. A stand can break that: a pressure
controller that corrects slowly leaves the pressure errors of successive readings correlated,
and through Boyle's law (1.9 mm of piston per 0.01 bar at 5 bar) the piston readings with them;
a drift does the same. Then the posterior intervals are too narrow, by up to
sqrt((1 + rho) / (1 - rho)) for a lag-one correlation rho (2.4 at rho = 0.7), and the
calibration suite shows it (docs/validation.md: the 90 % intervals of a_L covered about half
on such a stand). Nothing in the fit itself signals this, so each block (force, piston) of
each test is checked:

    z_i = (y_i - mean curve) / noise sd at reading i, in recording order,
    r1  = sum z_i z_(i+1) / sum z_i^2                       (lag-one autocorrelation),

against its null distribution for independent Gaussian errors *after* a weighted cubic fit
(the fit's residuals are not independent even when the errors are: r1 is biased below 0),
taken from ``N_NULL`` simulated error vectors projected like the data (fixed seed, so the
p-value is reproducible). One-sided: a positive correlation is what makes intervals too narrow.
A block with p < ``ALPHA`` gets a warning that says what it means. A cubic that misses the
curve's shape (a branch difference, a kink) also correlates neighbouring residuals, and the
warning is then just as true: the intervals rest on a model the readings do not follow.
"""

from __future__ import annotations

import functools

import numpy as np

#: Why a test in unknown order (a catalogue table: no branch and step) gets no check.
ORDER_UNKNOWN = (
    "not checked: the recording order is unknown (no branch and step columns), so the residuals "
    "have no order to be correlated in"
)
ALPHA = 1e-3  # per block: 22 blocks in a campaign like data/n50 give a false warning about once in 45 campaigns
N_NULL = 10000
#: floats of one block of null vectors (16 MB): the check's memory does not grow with the readings
NULL_BLOCK_VALUES = 1 << 21


def lag_one_check(
    residuals: np.ndarray,
    sd: np.ndarray,
    design: np.ndarray,
    *,
    n_null: int = N_NULL,
    seed: int = 0,
) -> dict:
    """Lag-one autocorrelation of standardised residuals in the given (recording) order and its
    one-sided p-value under independent errors after a weighted least-squares fit of ``design``.

    ``residuals``, ``sd``: (n,) in recording order; ``design``: (n, k) the fitted columns (e.g. the
    cubic's basis). Returns ``{"lag1", "p"}``.
    """
    z = np.asarray(residuals, float) / np.asarray(sd, float)
    W = np.asarray(design, float) / np.asarray(sd, float)[:, None]
    q, _ = np.linalg.qr(W)
    r1 = _lag_one(z[None])[0]
    # the null vectors in blocks of rows (the generator's stream is the same as in one array): memory
    # of about NULL_BLOCK_VALUES floats whatever the number of readings, not n_null of them a reading
    rows = max(1, min(n_null, NULL_BLOCK_VALUES // max(z.size, 1)))
    if rows >= n_null:  # one block: the same normals for every block of this length and seed
        blocks = [_null_normals(seed, n_null, z.size)]
    else:
        rng = np.random.default_rng(seed)
        blocks = (
            rng.standard_normal((min(rows, n_null - i), z.size)) for i in range(0, n_null, rows)
        )
    above = 0
    for normals in blocks:
        null = normals - (normals @ q) @ q.T  # the residuals of a weighted fit to pure noise
        above += np.count_nonzero(_lag_one(null) >= r1)
    p = (1.0 + above) / (n_null + 1.0)
    return {"lag1": float(r1), "p": float(p)}


@functools.lru_cache(maxsize=2)
def _null_normals(seed: int, n_null: int, n: int) -> np.ndarray:
    """The null check's normals when they fit in one block (read-only, kept: every test of a
    campaign with this many readings draws the very same ones, 22 times on data/n50)."""
    normals = np.random.default_rng(seed).standard_normal((n_null, n))
    normals.flags.writeable = False
    return normals


def _lag_one(z: np.ndarray) -> np.ndarray:
    return np.sum(z[:, 1:] * z[:, :-1], axis=1) / np.sum(z * z, axis=1)


def order_warnings(check: dict) -> list[str]:
    """The warning lines of one test's check (``{"force": {...}, "piston": {...}, "alpha"}``;
    none when every block passes, and none for a test in unknown order, ``{"skipped": why}``)."""
    return [
        f"{block} residuals are correlated in recording order (lag-one r = {c['lag1']:.2f}, p = {c['p']:.1g} "
        f"< {check['alpha']:g}): the intervals assume independent readings and are likely too narrow "
        "(a slowly corrected pressure, a drift, or a shape the cubic misses)"
        for block, c in check.items()
        if block not in ("alpha", "skipped") and c["p"] < check["alpha"]
    ]
