"""``uq check RESULT.json --against POINTS.json``: do stored point estimates agree with a posterior?

RESULT is the JSON of ``uq fit --json`` (docs/formats.md section 2), which carries per test the
posterior mean of each coefficient and the posterior covariance of each coefficient block
(``covariance: {force: 4x4, piston: 4x4}``, SI, paper basis). POINTS holds point estimates
in the same units (e.g. ``fits/n50/table1_points.json``, Table 1 of the paper), or is itself a
``uq fit --json`` result: a reference batch of the same part, whose posterior means are the
point estimates and whose posterior covariances their own covariance C (below).

The rule
--------
Every test in POINTS must be in RESULT (matched by ``pressure_bar``); tests only in RESULT
are not checked. For each checked test and each block b in (force, piston) that both files give
(a force-only result has no piston block; POINTS may give none: each block left out is listed
under ``not_checked`` with its reason and printed in one line), with posterior
mean m_b and posterior covariance S_b of the four coefficients, point estimate x_b and the
point estimate's own sampling covariance C_b (optional ``covariance`` of the POINTS test),

    d2_b = (x_b - m_b)^T (S_b + C_b)^{-1} (x_b - m_b)   (squared Mahalanobis distance)

Why S + C: a stored estimate such as Table 1 is itself a least-squares estimate from its own
campaign, x_b ~ N(theta_b, C_b) about the truth theta_b, independent of the data behind the
posterior; a calibrated posterior has m_b ~ N(theta_b, S_b) over repeated campaigns. So
x_b - m_b ~ N(0, S_b + C_b) and d2_b follows chi-square with 4 degrees of freedom when both
describe the same spring. Leaving C_b out (treating the stored estimates as exact) makes
the distance too large by up to a factor 2 when both campaigns are alike, and a correct fit
then fails far more often than alpha (tests/derived/test_check.py shows it by simulation). When a
POINTS block carries no covariance the check says so ("treated as exact") in its output and
JSON; fits/n50/table1_points.json carries the covariance of the paper's least-squares
estimator (``lsq_covariance``; derivation in fits/n50/make_points.py).

A block disagrees when

    d2_b > chi2_4^{-1}(1 - alpha / K),                  K = number of blocks checked,

the Bonferroni correction, so the chance that the whole check fails although every point
estimate is an honest estimate of the same spring is at most alpha (default 0.01), whatever
the number of tests. One distance per block (not one interval per coefficient) respects the
strong correlation of the cubic's coefficients. Exit status: 0 when every block agrees, 1
when any disagrees (each printed with its coefficients, their 90 % intervals, the distance
and the threshold), 2 on bad input (missing or invalid file, missing test/coefficient/
covariance, a non-numeric value, a covariance that is not symmetric positive definite).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
from scipy.stats import chi2

from uq._data.reference import FORCE_NAMES, PISTON_NAMES, Reference
from uq._io.errors import InputError
from uq._io.files import plain

BLOCKS = {"force": FORCE_NAMES, "piston": PISTON_NAMES}
DEFAULT_ALPHA = 0.01
PRESSURE_ATOL_BAR = 1e-6


# --------------------------------------------------------------------------- reading


def load_json(path: str | Path, what: str) -> dict:
    path = str(path)
    try:
        with open(path, encoding="utf-8") as fh:
            doc = json.load(fh)
    except FileNotFoundError:
        raise InputError(f"{path}: {what} file not found") from None
    except IsADirectoryError:
        raise InputError(f"{path}: {what} is a directory, expected a JSON file") from None
    except UnicodeDecodeError:
        raise InputError(f"{path}: {what} is not UTF-8 text (expected JSON)") from None
    except json.JSONDecodeError as exc:
        raise InputError(
            f"{path}: invalid JSON at line {exc.lineno}, column {exc.colno}: {exc.msg}"
        ) from None
    if not isinstance(doc, dict):
        raise InputError(
            f"{path}: expected a JSON object at the top level, got {type(doc).__name__}"
        )
    return doc


def _number(value, path: str, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        shown = "null" if value is None else json.dumps(value)[:40]
        raise InputError(f"{path}: {key}: expected a finite number, got {shown}")
    value = float(value)
    if not math.isfinite(value):
        raise InputError(f"{path}: {key}: expected a finite number, got {value}")
    return value


def _get(obj, name: str, path: str, key: str, kind=dict, hint: str = ""):
    if not isinstance(obj, dict) or name not in obj:
        raise InputError(f"{path}: {key}: missing{hint}")
    val = obj[name]
    if not isinstance(val, kind) or isinstance(val, bool):
        raise InputError(
            f"{path}: {key}: expected {'an object' if kind is dict else 'a list'}, got {type(val).__name__}"
        )
    return val


def _tests(doc: dict, path: str) -> list[tuple[float, dict, str]]:
    tests = _get(doc, "tests", path, "'tests'", list)
    out = []
    for i, t in enumerate(tests):
        if not isinstance(t, dict):
            raise InputError(f"{path}: tests[{i}]: expected an object, got {type(t).__name__}")
        if "pressure_bar" not in t:
            raise InputError(f"{path}: tests[{i}].pressure_bar: missing")
        p = _number(t["pressure_bar"], path, f"tests[{i}].pressure_bar")
        label = f"tests[{i}] ({p:g} bar)"
        for q, _, other in out:
            if abs(q - p) <= PRESSURE_ATOL_BAR:
                raise InputError(f"{path}: {label}: pressure {p:g} bar listed twice (also {other})")
        out.append((p, t, label))
    return out


def points_kind(doc: dict) -> str:
    """ "fit result" when POINTS is a ``uq fit --json`` document (its coefficients are estimate
    objects ``{"mean", "sd", ...}``), else "point estimates" (plain numbers)."""
    tests = doc.get("tests") if isinstance(doc, dict) else None
    for t in tests if isinstance(tests, list) else []:
        for block in BLOCKS:
            b = t.get(block) if isinstance(t, dict) else None
            if isinstance(b, dict) and any(isinstance(v, dict) for v in b.values()):
                return FIT_RESULT
    return POINT_ESTIMATES


POINT_ESTIMATES, FIT_RESULT = "point estimates", "fit result"


def read_points(doc: dict, path: str) -> list[dict]:
    """POINTS -> [{"pressure_bar", "label", "force": (4,), "piston": (4,), "cov": {block: (4, 4)}}].

    ``cov`` holds the blocks whose optional ``covariance`` the test carries (the stored
    estimate's own sampling covariance, SI, paper basis); a block without one is exact.

    POINTS may also be a ``uq fit --json`` result (another batch of the same part, the reference
    batch): each coefficient's posterior mean is its point estimate and the fit's posterior
    covariance of the block its own covariance (required, as in RESULT); a piston block made
    from a volume column keeps its ``"piston_from"``, so its arbitrary a_L is left out.
    """
    tests = _tests(doc, path)
    if not tests:
        raise InputError(f"{path}: 'tests' is empty: nothing to check")
    fit = points_kind(doc) == FIT_RESULT
    out = []
    for p, t, label in tests:
        row = {"pressure_bar": p, "label": label, "cov": {}}
        if fit and isinstance(t.get("piston_from"), str):
            row["piston_from"] = t["piston_from"]
        for block, names in BLOCKS.items():
            if block == "piston" and block not in t:  # a force-only stand's estimates
                continue
            b = _get(t, block, path, f"{label}.{block}")
            row[block] = np.array(
                [
                    _point(b[n], path, f"{label}.{block}.{n}", fit)
                    if n in b
                    else _missing(path, f"{label}.{block}.{n}")
                    for n in names
                ]
            )
        if fit or "covariance" in t:
            cov = _get(
                t,
                "covariance",
                path,
                f"{label}.covariance",
                hint=(
                    " (a fit result as the stored estimates needs its posterior covariance, which a "
                    "fit's JSON carries; fit again with this version)"
                    if fit
                    else ""
                ),
            )
            for block in BLOCKS:
                if block in cov and block in row:
                    row["cov"][block] = _matrix(cov, block, path, f"{label}.covariance.{block}")
                elif fit and block in row:
                    _missing(path, f"{label}.covariance.{block}")
        out.append(row)
    return out


def _point(value, path: str, key: str, fit: bool) -> float:
    """A point estimate: a number, or the posterior mean of a fit result's estimate object."""
    if not fit:
        return _number(value, path, key)
    if not isinstance(value, dict):
        raise InputError(
            f'{path}: {key}: expected an estimate object {{"mean", ...}} as in the rest of this '
            f"fit result, got {json.dumps(value)[:40]}"
        )
    if "mean" not in value:
        raise InputError(f"{path}: {key}.mean: missing")
    return _number(value["mean"], path, f"{key}.mean")


def reference_from_points(path: str | Path) -> Reference:
    """A point-estimates file (the format ``uq check`` reads: docs/formats.md) as the values a
    report compares with (``uq report --reference FILE``): the coefficients per test and, where a
    test gives them, its deviation measures ``s_P_N`` and ``eps_P_pct``."""
    doc = load_json(path, "reference file")
    points = read_points(doc, str(path))
    deviations = {}
    for p, t, label in _tests(doc, str(path)):
        if "s_P_N" in t and "eps_P_pct" in t:
            deviations[p] = (
                _number(t["s_P_N"], str(path), f"{label}.s_P_N"),
                _number(t["eps_P_pct"], str(path), f"{label}.eps_P_pct"),
            )
    source = doc.get("source") if isinstance(doc.get("source"), str) else None
    return Reference(
        name=Path(path).name,
        source=source or str(path),
        force={r["pressure_bar"]: r["force"] for r in points},
        piston={r["pressure_bar"]: r["piston"] for r in points if "piston" in r},
        deviations=deviations,
    )


def _matrix(cov: dict, block: str, path: str, key: str) -> np.ndarray:
    """A 4x4 symmetric positive definite matrix from ``cov[block]``, or InputError naming ``key``."""
    c = _get(cov, block, path, key, list)
    if len(c) != 4 or not all(isinstance(r, list) and len(r) == 4 for r in c):
        raise InputError(f"{path}: {key}: expected a 4x4 matrix (a list of 4 lists of 4 numbers)")
    m = np.array(
        [[_number(v, path, f"{key}[{i}][{j}]") for j, v in enumerate(r)] for i, r in enumerate(c)]
    )
    _check_cov(m, path, key)
    return m


def _missing(path: str, key: str):
    raise InputError(f"{path}: {key}: missing")


def read_result(doc: dict, path: str) -> dict[float, dict]:
    """RESULT -> {pressure: {"label", block: {"mean", "sd", "q05", "q95" (4,), "cov" (4, 4)}}}.

    A force-only test (``uq fit`` of a campaign without piston_* or volume_* column) has no
    "piston" block and says why under "omitted"; its row then has no "piston" and
    ``"omitted": {"piston": why}``. A test missing its piston block without saying why is refused.
    A test whose piston block comes from a volume column keeps its "piston_from" (its a_L is the
    arbitrary reference of L = -V/S, so :func:`check` leaves a_L out of that block).
    """
    out = {}
    for p, t, label in _tests(doc, path):
        row = {"label": label}
        omitted = t.get("omitted") if isinstance(t.get("omitted"), dict) else {}
        if "piston" not in t and isinstance(omitted.get("piston"), str):
            row["omitted"] = {"piston": omitted["piston"]}
        if isinstance(t.get("piston_from"), str):  # L = -V/S from a volume column: a_L arbitrary
            row["piston_from"] = t["piston_from"]
        cov = _get(
            t,
            "covariance",
            path,
            f"{label}.covariance",
            hint=(
                " (uq check needs the posterior covariance of each coefficient block, "
                "which `uq fit --json` writes; rerun the fit with this version)"
            ),
        )
        for block, names in BLOCKS.items():
            if block in row.get("omitted", {}):
                continue
            b = _get(t, block, path, f"{label}.{block}")
            est = {k: np.empty(4) for k in ("mean", "sd", "q05", "q95")}
            for j, n in enumerate(names):
                e = _get(b, n, path, f"{label}.{block}.{n}")
                for k in est:
                    if k not in e:
                        raise InputError(f"{path}: {label}.{block}.{n}.{k}: missing")
                    est[k][j] = _number(e[k], path, f"{label}.{block}.{n}.{k}")
            est["cov"] = _matrix(cov, block, path, f"{label}.covariance.{block}")
            row[block] = est
        out[p] = row
    return out


def _check_cov(cov: np.ndarray, path: str, key: str) -> None:
    scale = np.sqrt(np.abs(np.diag(cov)))
    if np.any(scale == 0):
        raise InputError(f"{path}: {key}: singular covariance (zero variance on the diagonal)")
    corr = cov / np.outer(scale, scale)
    if not np.allclose(corr, corr.T, atol=1e-8):
        raise InputError(f"{path}: {key}: covariance is not symmetric")
    w = np.linalg.eigvalsh(0.5 * (corr + corr.T))
    if np.any(np.diag(cov) < 0) or w[0] <= 1e-12 * max(w[-1], 1.0):
        raise InputError(
            f"{path}: {key}: singular covariance (not positive definite; smallest correlation eigenvalue {w[0]:.3g})"
        )


# --------------------------------------------------------------------------- the rule


def threshold(alpha: float, n_blocks: int, df: int = 4) -> float:
    """Bonferroni threshold on the squared Mahalanobis distance: chi2_df quantile at 1 - alpha/K."""
    return float(chi2.isf(alpha / n_blocks, df))


def mahalanobis2(x: np.ndarray, mean: np.ndarray, cov: np.ndarray) -> float:
    """Squared Mahalanobis distance, computed on the correlation scale (coefficients span ~1e10)."""
    s = np.sqrt(np.diag(cov))
    z = (x - mean) / s
    corr = cov / np.outer(s, s)
    L = np.linalg.cholesky(0.5 * (corr + corr.T))
    y = np.linalg.solve(L, z)
    return float(y @ y)


def check(
    result: dict[float, dict],
    points: list[dict],
    *,
    alpha: float = DEFAULT_ALPHA,
    result_path: str = "RESULT",
    points_path: str = "POINTS",
    kind: str = POINT_ESTIMATES,
) -> dict:
    """Apply the rule of the module docstring; returns the machine-readable verdict.

    ``kind``: what POINTS is (:func:`points_kind`), said in the verdict."""
    if not 0.0 < alpha < 1.0:
        raise InputError(f"alpha: expected a probability in (0, 1), got {alpha:g}", param="alpha")
    matched = []
    for pt in points:
        hit = [p for p in result if abs(p - pt["pressure_bar"]) <= PRESSURE_ATOL_BAR]
        if not hit:
            have = ", ".join(f"{p:g}" for p in sorted(result)) or "none"
            raise InputError(
                f"{points_path}: {pt['label']}: no test at {pt['pressure_bar']:g} bar in {result_path} (it has: {have} bar)"
            )
        matched.append((pt, result[hit[0]]))
    pairs, not_checked = [], []
    for pt, res in matched:
        for block in BLOCKS:
            if block in pt and block in res:
                pairs.append((pt, res, block))
            elif block in pt:
                why = res.get("omitted", {}).get(block, "no such block")
                not_checked.append(_not_checked(pt, block, f"{result_path} has none ({why})"))
            elif block in res:
                not_checked.append(_not_checked(pt, block, f"{points_path} gives none"))
    if not pairs:
        raise InputError(f"{points_path}: no block to check: {result_path} and it share none")
    n_blocks = len(pairs)
    thr = threshold(alpha, n_blocks)
    blocks = [
        _block(pt, res[block], block, alpha, n_blocks, _checked(res, block, pt))
        for pt, res, block in pairs
    ]
    exact = [f"{b['pressure_bar']:g} bar {b['block']}" for b in blocks if not b["point_covariance"]]
    return {
        "result": str(result_path),
        "against": str(points_path),
        "rule": "squared Mahalanobis distance of the point estimates from the posterior mean under the sum of "
        "the posterior covariance and the point estimates' own covariance (when POINTS gives one), "
        "per test and block, against the chi-square(4) quantile at 1 - alpha/K",
        "alpha": alpha,
        "n_blocks": n_blocks,
        "df": 4,
        "threshold2": thr,
        "threshold": math.sqrt(thr),
        "points_kind": kind,
        "point_uncertainty": _assumption(exact, n_blocks, kind),
        "blocks_treated_as_exact": exact,
        "agree": all(b["agree"] for b in blocks),
        "n_disagree": sum(not b["agree"] for b in blocks),
        "n_tests": len(matched),
        "blocks": blocks,
        "not_checked": not_checked,
    }


def _not_checked(pt: dict, block: str, why: str) -> dict:
    return {"pressure_bar": pt["pressure_bar"], "block": block, "reason": why}


def _assumption(exact: list[str], n_blocks: int, kind: str = POINT_ESTIMATES) -> str:
    if kind == FIT_RESULT:
        return (
            "included: the stored estimates are a `uq fit --json` result (another batch): its posterior "
            "means, with its posterior covariance added to this one's"
        )
    if not exact:
        return "included: every block's distance uses posterior covariance + the stored estimate's covariance"
    what = "all blocks" if len(exact) == n_blocks else ", ".join(exact)
    return (
        f"stored estimates treated as exact for {what} (POINTS gives no covariance): the false-failure "
        "rate is then larger than alpha when the stored estimates carry sampling error"
    )


VOLUME_REFERENCE = "the arbitrary reference of L = -V/S (a piston block made from a volume column)"


def _checked(res: dict, block: str, pt: dict | None = None) -> np.ndarray:
    """The coefficients of ``block`` the check compares: all four, but b_L..d_L of a piston block
    made from a volume column on either side (its a_L is the arbitrary reference of L = -V/S)."""
    from_volume = "piston_from" in res or "piston_from" in (pt or {})
    return np.arange(1, 4) if block == "piston" and from_volume else np.arange(4)


def _block(pt: dict, r: dict, block: str, alpha: float, n_blocks: int, idx: np.ndarray) -> dict:
    """One test's block: distance under S + C over the coefficients ``idx`` (chi-square with
    len(idx) degrees of freedom), per-coefficient z on the same combined scale."""
    c = pt.get("cov", {}).get(block)
    total = r["cov"] + (c if c is not None else 0.0)
    df = len(idx)
    thr = threshold(alpha, n_blocks, df)
    d2 = mahalanobis2(pt[block][idx], r["mean"][idx], total[np.ix_(idx, idx)])
    point_sd = np.sqrt(np.diag(c)) if c is not None else np.zeros(4)
    coefs = {
        n: {
            "point": float(pt[block][j]),
            "point_sd": float(point_sd[j]),
            "mean": float(r["mean"][j]),
            "sd": float(r["sd"][j]),
            "q05": float(r["q05"][j]),
            "q95": float(r["q95"][j]),
            "z": float((pt[block][j] - r["mean"][j]) / math.sqrt(total[j, j])),
        }
        for j, n in enumerate(BLOCKS[block])
    }
    return {
        "pressure_bar": pt["pressure_bar"],
        "block": block,
        "point_covariance": c is not None,
        "mahalanobis": math.sqrt(d2),
        "mahalanobis2": d2,
        "threshold2": thr,
        "threshold": math.sqrt(thr),
        "p_value": float(chi2.sf(d2, df)),
        "agree": bool(d2 <= thr),
        "df": df,
        "coefficients": coefs,
    } | ({"unchecked": {BLOCKS[block][0]: VOLUME_REFERENCE}} if df < 4 else {})


def lsq_covariance(u_m, sd) -> np.ndarray:
    """Sampling covariance of the ordinary least-squares cubic in u (paper basis, SI).

    ``sd``: the noise sd of each reading (array) or one sd for all. With X = [1, u, u^2, u^3]
    the estimator (X^T X)^-1 X^T y has covariance (X^T X)^-1 X^T diag(sd^2) X (X^T X)^-1,
    which is sd^2 (X^T X)^-1 for a constant sd. Solved on u scaled to O(1) (the raw X^T X
    spans 20 decades).
    """
    u = np.asarray(u_m, float)
    scale = float(np.max(np.abs(u)))
    X = np.vander(u / scale, 4, increasing=True)
    w = np.broadcast_to(np.asarray(sd, float) ** 2, u.shape)
    A = np.linalg.inv(X.T @ X)
    cov = A @ (X.T * w) @ X @ A
    D = np.diag(scale ** -np.arange(4.0))
    return D @ cov @ D


def check_documents(
    result,
    points,
    *,
    alpha: float = DEFAULT_ALPHA,
    result_name: str = "RESULT",
    points_name: str = "POINTS",
) -> dict:
    """``uq check`` in memory: the verdict of the module docstring's rule, as a dict.

    ``result``: a cubic fit (:func:`uq.fit_campaign`), its ``to_json()``, or that JSON read back;
    ``points``: point estimates in the POINTS format (docs/check.md), as a dict or the path of a
    file holding them (e.g. fits/n50/table1_points.json). The
    verdict is what ``uq check --json`` writes: ``agree``, ``n_disagree``, ``threshold2`` and one
    entry per test and block in ``blocks``. ``result_name``/``points_name`` name them in messages.

    >>> import uq
    >>> rec = uq.simulate("n50", seed=1, layout=uq.Layout(pressures_bar=(1.0, 5.0), step_m=0.01))
    >>> result = uq.fit_campaign(rec, seed=1, settings=uq.Settings(max_steps=200)).to_json()
    >>> means = {"tests": [{"pressure_bar": t["pressure_bar"],
    ...                     **{b: {n: e["mean"] for n, e in t[b].items()} for b in ("force", "piston")}}
    ...                    for t in result["tests"]]}
    >>> verdict = uq.check(result, means)  # the posterior means agree with their own posterior
    >>> verdict["agree"], verdict["n_blocks"]
    (True, 4)
    """
    if hasattr(result, "to_json"):
        result = result.to_json()
    if isinstance(points, str | Path):
        points_name = str(points)
        points = load_json(points, "POINTS")
    points = plain(points)  # the values a JSON file of the same documents would hold
    return check(
        read_result(plain(result), result_name),
        read_points(points, points_name),
        alpha=alpha,
        result_path=result_name,
        points_path=points_name,
        kind=points_kind(points),
    )


def check_files(result_path: str, points_path: str, alpha: float = DEFAULT_ALPHA) -> dict:
    result = read_result(load_json(result_path, "RESULT"), str(result_path))
    doc = load_json(points_path, "POINTS")
    points = read_points(doc, str(points_path))
    return check(
        result,
        points,
        alpha=alpha,
        result_path=str(result_path),
        points_path=str(points_path),
        kind=points_kind(doc),
    )


# --------------------------------------------------------------------------- output


def _fmt(v: float) -> str:
    return f"{v:.6g}"


def summary(verdict: dict) -> str:
    lines = []
    for b in verdict["blocks"]:
        if b["agree"]:
            continue
        lines.append(
            f"DISAGREE {b['pressure_bar']:g} bar {b['block']}: Mahalanobis distance {b['mahalanobis']:.2f} "
            f"> threshold {b['threshold']:.2f} (d^2 {b['mahalanobis2']:.1f} > {b['threshold2']:.1f}, p = {b['p_value']:.2g})"
        )
        for n, c in b["coefficients"].items():
            flag = "  <- outside" if not c["q05"] <= c["point"] <= c["q95"] else ""
            flag = "  (not checked)" if n in b.get("unchecked", {}) else flag
            own = f" +/- {c['point_sd']:.3g}" if b["point_covariance"] else " (exact)"
            lines.append(
                f"    {n}: point {_fmt(c['point'])}{own}, posterior {_fmt(c['mean'])} "
                f"[90% {_fmt(c['q05'])}, {_fmt(c['q95'])}], {c['z']:+.1f} sd{flag}"
            )
    worst = max(verdict["blocks"], key=lambda b: b["mahalanobis2"])
    n_tests = verdict.get("n_tests", verdict["n_blocks"] // len(BLOCKS))
    shape = (
        f"{n_tests} tests x 2 blocks"
        if verdict["n_blocks"] == n_tests * len(BLOCKS)
        else f"{n_tests} tests, {verdict['n_blocks']} blocks"
    )
    head = (
        f"uq check: {verdict['against']} against {verdict['result']}: {shape}, "
        f"alpha {verdict['alpha']:g}, threshold d^2 <= {verdict['threshold2']:.2f} "
        f"(chi2_4 at 1 - {verdict['alpha']:g}/{verdict['n_blocks']})"
    )
    state = (
        "OK: all agree"
        if verdict["agree"]
        else (f"FAIL: {verdict['n_disagree']} of {verdict['n_blocks']} blocks disagree")
    )
    tail = f"{state}; largest d^2 {worst['mahalanobis2']:.2f} ({worst['pressure_bar']:g} bar {worst['block']})"
    note = f"point-estimate uncertainty: {verdict['point_uncertainty']}"
    return "\n".join([head, note, *_not_checked_lines(verdict), *lines, tail])


def _not_checked_lines(verdict: dict) -> list[str]:
    """One line per block and reason left unchecked (e.g. the piston of a force-only result)."""
    by_reason: dict[tuple[str, str], list[float]] = {}
    for n in verdict.get("not_checked", []):
        by_reason.setdefault((n["block"], n["reason"]), []).append(n["pressure_bar"])
    for b in verdict["blocks"]:
        for name, why in b.get("unchecked", {}).items():
            by_reason.setdefault((name, why), []).append(b["pressure_bar"])
    return [
        f"NOT CHECKED {block} ({', '.join(f'{p:g}' for p in ps)} bar): {why}"
        for (block, why), ps in by_reason.items()
    ]
