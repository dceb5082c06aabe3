"""Write table1_points.json: Table 1 of the paper in SI, the point estimates for ``uq check``.

Run from the repository root:  .venv/bin/python fits/n50/make_points.py [--out PATH]
The values come from uq._data.reference.table1() (the paper's table shipped in uq/_data,
converted to SI there); this script reshapes them (and rounds away the binary noise of
the conversion at 12 significant digits) into the point-estimate format of ``uq check``
(docs/formats.md), so rerunning it reproduces the JSON byte for byte (tests/test_scripts.py
checks that).

Each test also carries ``covariance`` (force, piston; SI, paper basis): the sampling
covariance of the paper's own estimator, because Table 1 is a least-squares fit to one
campaign and has its own error (uq._derived.check.lsq_covariance):
* force: ordinary least squares on the test's 37 readings (19 compression, 18 rebound,
  section 3.4) with the noise sd taken from Table 2: s_P^2 N/(N-4) (X^T X)^-1; s_P is the
  paper's rms residual (divisor N), N/(N-4) turns it into the unbiased residual variance.
  Table 2's s_P holds everything the paper's data scatter by (including the
  compression/rebound difference), so this is the paper's own measure of its noise.
* piston: the paper gives no residual measure, so the noise sd of each reading comes from
  the stand's error budget (uq._stand.simulator.noise_sd on the Table 1 curves: calipers, displacement,
  and the gas volume's response to the pressure holding), propagated through the same
  least-squares estimator (X^T X)^-1 X^T diag(sd^2) X (X^T X)^-1. This assumes the budget
  is the whole piston scatter; if the paper's piston readings scattered more, the
  covariance is too small and the check errs on the strict side.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from uq._data.reference import FORCE_NAMES, PAPER_X0_M, PISTON_NAMES, table1, table2
from uq._derived.check import lsq_covariance
from uq._io.files import dumps_json, write_text_atomic
from uq._stand.simulator import Layout, N50Spring, noise_sd

HERE = Path(__file__).resolve().parent


def _clean(v: float) -> float:
    """Drop the binary noise of the unit conversion (e.g. 130.89 * 1e3 = 130889.99999999999)."""
    return float(f"{v:.12g}")


COVARIANCE_SOURCE = (
    "sampling covariance of the paper's least-squares estimator on the 37 readings of section 3.4: "
    "force with Table 2's s_P (s_P^2 N/(N-4) (X^T X)^-1), piston with the stand's error budget "
    "(uq._stand.simulator.noise_sd); see fits/n50/make_points.py"
)


def covariances(p_bar: float) -> dict:
    """The force and piston covariance of the module docstring for the test at ``p_bar``."""
    heights, _ = Layout().heights()
    u = heights - PAPER_X0_M
    n = u.size
    s_p = table2()[float(p_bar)][0]
    # The budget differentiates along height, so it wants each height once, in order.
    unique, back = np.unique(heights, return_inverse=True)
    sd_piston = noise_sd(N50Spring(), unique, float(p_bar))[1][back]
    return {
        "force": lsq_covariance(u, s_p * np.sqrt(n / (n - 4))),
        "piston": lsq_covariance(u, sd_piston),
    }


def points() -> dict:
    t = table1()
    tests = []
    for i, p in enumerate(t.pressures_bar):
        cov = covariances(p)
        tests.append(
            {
                "pressure_bar": float(p),
                "force": {n: _clean(v) for n, v in zip(FORCE_NAMES, t.force[i], strict=True)},
                "piston": {n: _clean(v) for n, v in zip(PISTON_NAMES, t.piston[i], strict=True)},
                "covariance": {b: [[_clean(v) for v in row] for row in c] for b, c in cov.items()},
            }
        )
    return {
        "source": "Table 1 of the paper, converted to SI",
        "covariance_source": COVARIANCE_SOURCE,
        "tests": tests,
    }


def main(argv: list[str] | None = None) -> None:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default=str(HERE / "table1_points.json"), help="the file to write")
    target = ap.parse_args(argv).out
    write_text_atomic(target, dumps_json(points()))
    print(f"wrote {target}")


if __name__ == "__main__":
    main()
