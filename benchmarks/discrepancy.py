"""The discrepancy surface's log posterior, the call its sampler makes about half a million times on
data/n50: CPU (user and kernel), wall time and page faults per call with glibc's malloc at its
defaults (``UQ_MALLOC=default`` while uq is imported: the baseline, measured first) and with the
thresholds uq sets (``uq._inference.allocator``, which keep JAX's large temporaries in the heap),
both in one process; then, with uq's thresholds, the previous formula of the same density
(``previous_log_prob``: before its fixed products were made with the data, commit c8f9c5f)
against the current one, alternating in rounds so that a change of the machine's load falls on
both.

Not part of the installed package: run from the repository root with the project installed,

    .venv/bin/python benchmarks/discrepancy.py [--calls 100] [--json reports/bench/discrepancy.json]
"""

from __future__ import annotations

import argparse
import os
import resource
import sys
import time

os.environ["UQ_MALLOC"] = "default"  # the baseline: uq imports JAX with malloc's defaults

import jax  # noqa: E402
import numpy as np  # noqa: E402

from uq._data.recordings import read_recordings  # noqa: E402
from uq._inference import allocator  # noqa: E402
from uq._inference.float64 import jnp  # noqa: E402
from uq._inference.linear import LOG_2PI  # noqa: E402
from uq._io.files import emit_json  # noqa: E402
from uq._models import discrepancy as dev  # noqa: E402
from uq._models import discrepancy_gp as gp  # noqa: E402
from uq._models import pair, surface  # noqa: E402

RECORDINGS = "data/n50/recordings.csv"


def timed(fn, thetas, calls: int) -> dict:
    """Per call: user and kernel CPU, wall time (ms) and minor page faults, after a warm-up call."""
    np.asarray(fn(thetas))
    r0, w0 = resource.getrusage(resource.RUSAGE_SELF), time.perf_counter()
    for _ in range(calls):
        np.asarray(fn(thetas))
    r1, wall = resource.getrusage(resource.RUSAGE_SELF), time.perf_counter() - w0
    return {
        "user_ms": 1e3 * (r1.ru_utime - r0.ru_utime) / calls,
        "sys_ms": 1e3 * (r1.ru_stime - r0.ru_stime) / calls,
        "wall_ms": 1e3 * wall / calls,
        "page_faults": (r1.ru_minflt - r0.ru_minflt) / calls,
    }


def cpu(r: dict) -> float:
    return r["user_ms"] + r["sys_ms"]


def previous_log_marginal(theta, d):
    """log p(y | theta) of the discrepancy surface with piston readings as its sampler computed it
    until commit c8f9c5f: segment sums of the readings' moments, P (T, T, m, m) from the
    deviations' maps D, R P R^T by one einsum, Cholesky factors and triangular solves. The
    baseline of this benchmark, and the reference tests/models/test_discrepancy.py holds
    ``uq._models.discrepancy.log_marginal`` to."""
    noise, amps, length = dev._split(theta, d)
    T, m = d.A.shape[:2]
    nf = (m - 1) // 2
    L11, L21, L22 = pair.cov_factors(noise, d)
    F, L = pair.readings(noise, d)
    w, s = d.weight, L21 / (L11 * L22)
    yf = F / L11
    yl = (L - L21 * yf) / L22

    def seg(v):
        return jax.ops.segment_sum(v, d.test, num_segments=T)

    P = d.t[:, None] ** jnp.arange(2 * nf + 1)
    M1, M2, M3 = (seg(x[:, None] * P) for x in (w * (1 / L11**2 + s**2), w / L22**2, -w * s / L22))
    a, b, pp = np.arange(nf), np.arange(nf + 1), d.p_pa[:, None, None]
    Hff, Hll = M1[:, a[:, None] + a[None, :]] * pp**2, M2[:, b[:, None] + b[None, :]]
    Hfl = M3[:, a[:, None] + b[None, :]] * pp
    H = jnp.concatenate(
        [jnp.concatenate([Hff, Hfl], 2), jnp.concatenate([jnp.swapaxes(Hfl, 1, 2), Hll], 2)], 1
    )
    vf, vl = w * (yf / L11 - s * yl), w * yl / L22
    bvec = jnp.concatenate(
        [seg(vf[:, None] * P[:, :nf]) * d.p_pa[:, None], seg(vl[:, None] * P[:, : nf + 1])], 1
    )
    yy, log_det = jnp.sum(w * (yf**2 + yl**2)), 2 * jnp.sum(w * (jnp.log(L11) + jnp.log(L22)))
    Rt = jnp.linalg.cholesky(H)
    u = jax.scipy.linalg.solve_triangular(Rt, bvec[..., None], lower=True)[..., 0]
    R = gp.correlation(d.p_bar, length, jnp)
    g2 = dev.channel_scales(amps, d) ** 2
    Pc = jnp.einsum("iak,jbk->ijab", d.A, d.A) + jnp.einsum("ij,iac,c,jbc->ijab", R, d.D, g2, d.D)
    RPR = jnp.einsum("iba,ijbc,jcd->iajd", Rt, Pc, Rt).reshape(T * m, T * m)
    Lm = jnp.linalg.cholesky(jnp.eye(T * m) + RPR)
    v = jax.scipy.linalg.solve_triangular(Lm, u.reshape(-1), lower=True)
    quad = yy - (jnp.sum(u**2) - jnp.sum(v**2))
    logdet = 2.0 * jnp.sum(jnp.log(jnp.diag(Lm)))
    return -0.5 * (quad + log_det + logdet + 2 * jnp.sum(w) * LOG_2PI)


def previous_log_prob(theta, d):
    return dev.log_prior(theta, d) + previous_log_marginal(theta, d)


def alternating(fns: dict, thetas, calls: int, rounds: int = 4) -> dict:
    """``timed`` of each function in ``rounds`` alternating turns of calls / rounds calls each,
    summed: the per-call figures of each over the same stretch of the machine's load."""
    per = max(1, calls // rounds)
    parts: dict[str, list] = {k: [] for k in fns}
    for _ in range(rounds):
        for k, f in fns.items():
            parts[k].append(timed(f, thetas, per))
    return {k: {q: float(np.mean([p[q] for p in v])) for q in v[0]} for k, v in parts.items()}


def measure(calls: int, walkers: int, seed: int) -> dict:
    rec = read_recordings(RECORDINGS)
    d = dev.dev_data(rec, surface.orders_for(rec))
    start = dev.start(d)[0]
    rng = np.random.default_rng(seed)
    thetas = jnp.asarray(start + 0.05 * rng.standard_normal((walkers, start.size)))
    log_prob = jax.jit(jax.vmap(lambda t: dev.log_prob(t, d)))
    previous = jax.jit(jax.vmap(lambda t: previous_log_prob(t, d)))
    runs = {"malloc_defaults": timed(log_prob, thetas, calls)}
    os.environ.pop("UQ_MALLOC")
    tuned = allocator.tune()
    runs["tuned"] = timed(log_prob, thetas, calls)
    formulas = alternating({"previous": previous, "current": log_prob}, thetas, calls)
    a, b = (np.asarray(f(thetas)) for f in (log_prob, previous))
    return {
        "workload": f"log posterior of the discrepancy surface on {RECORDINGS} ({rec.n_points} "
        f"readings, {len(rec.tests)} tests), {walkers} walkers a call (the sampler's half of four "
        f"ensembles of 92), {calls} calls after a warm-up",
        "load_average_1min": os.getloadavg()[0],
        "cores": os.cpu_count(),
        "allocator_tuned": tuned,
        "threshold_bytes": allocator.THRESHOLD_BYTES,
        "runs": runs,
        "cpu_ratio": cpu(runs["malloc_defaults"]) / cpu(runs["tuned"]),
        "wall_ratio": runs["malloc_defaults"]["wall_ms"] / runs["tuned"]["wall_ms"],
        "formulas": formulas,
        "formula_cpu_ratio": cpu(formulas["previous"]) / cpu(formulas["current"]),
        "formula_wall_ratio": formulas["previous"]["wall_ms"] / formulas["current"]["wall_ms"],
        "formula_max_rel_diff": float(np.max(np.abs(a - b) / np.abs(b))),
    }


def summary(r: dict) -> str:
    lines = [f"bench discrepancy: {r['workload']}; load average {r['load_average_1min']:.1f}"]
    for name, x in r["runs"].items():
        lines.append(
            f"  {name:18s} user {x['user_ms']:6.1f} ms  sys {x['sys_ms']:6.1f} ms  wall "
            f"{x['wall_ms']:6.1f} ms  page faults {x['page_faults']:8.0f} a call"
        )
    lines.append(
        f"  a call with malloc's defaults over one with uq's thresholds: CPU {r['cpu_ratio']:.2f}x, "
        f"wall {r['wall_ratio']:.2f}x"
    )
    for name, x in r["formulas"].items():
        lines.append(
            f"  {name + ' formula':18s} user {x['user_ms']:6.1f} ms  sys {x['sys_ms']:6.1f} ms  wall "
            f"{x['wall_ms']:6.1f} ms (uq's thresholds, alternating)"
        )
    lines.append(
        f"  a call of the previous formula over one of the current: CPU "
        f"{r['formula_cpu_ratio']:.2f}x, wall {r['formula_wall_ratio']:.2f}x; the same log "
        f"posterior to {r['formula_max_rel_diff']:.1e} relative"
    )
    return "\n".join(lines)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(
        prog="benchmarks/discrepancy.py", description=__doc__.splitlines()[0]
    )
    p.add_argument("--calls", type=int, default=100)
    p.add_argument("--walkers", type=int, default=184)
    p.add_argument("--seed", type=int, default=20201)
    p.add_argument("--json", metavar="PATH")
    args = p.parse_args(argv)
    r = measure(args.calls, args.walkers, args.seed)
    print(summary(r), file=sys.stderr if args.json == "-" else sys.stdout)
    if args.json:
        emit_json(r, args.json)
    return 0


if __name__ == "__main__":
    sys.exit(main())
