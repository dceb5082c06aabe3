"""Tables of a fit for the tools engineers use (issue 30): the coefficient table of ``uq fit --csv``.

Every table is written in the units asked for (:class:`uq._data.units.OutputUnits`): the
contract's, or the units the recordings came in (``--units input``).
"""

from __future__ import annotations

import numpy as np

from uq._data.reference import FORCE_NAMES, PISTON_NAMES
from uq._data.units import OutputUnits

#: The coefficients' units of ``uq fit --json`` (SI, u = x - x0 in metres): ``--units si``.
JSON_UNITS = OutputUnits(height="m", piston="m")
COEFFICIENT_STATS = ("mean", "sd", "q05", "q50", "q95", "r_hat", "ess_bulk")


def coefficient_table(cf, units: OutputUnits = JSON_UNITS) -> tuple[list[str], list[list]]:
    """(header, rows) of ``uq fit --csv``: one row per test and coefficient of the cubics (eqs. 8,
    9), its posterior mean, sd, 5/50/95 % quantiles, R-hat and bulk ESS, in ``units`` against
    u = x - x0 in ``units.height`` (x0 in the last column). A force-only test has no piston rows.

    ``cf``: a fit of the per-pressure cubics (``uq.fit_campaign``).
    """
    rec = cf.recordings
    x0 = float(units.value("height", rec.x0_m))
    header = [
        units.column("pressure"),
        "block",
        "coefficient",
        "unit",
        *COEFFICIENT_STATS,
        f"x0_{units.height}",
    ]
    rows = []
    for t in cf.tests:
        p = float(units.value("pressure", t.pressure_bar))
        variables = t.convergence.variables
        for block, names in (("force", FORCE_NAMES), ("piston", PISTON_NAMES)):
            if block == "piston" and not t.has_piston:
                continue
            draws = t.flat(block)  # (S, 4), SI
            for k, name in enumerate(names):
                scale, unit = units.coefficient(block, k)
                d = draws[:, k] * scale
                q05, q50, q95 = np.quantile(d, (0.05, 0.5, 0.95))
                v = variables.get(name, {})
                rows.append(
                    [
                        p,
                        block,
                        name,
                        unit,
                        float(d.mean()),
                        float(d.std(ddof=1)),
                        float(q05),
                        float(q50),
                        float(q95),
                        float(v.get("r_hat", np.nan)),
                        float(v.get("ess_bulk", np.nan)),
                        x0,
                    ]
                )
    return header, rows
