"""The paper's Tables 1 and 2 (shipped in ``uq/_data/tables``), in SI units.

Table 1 gives, per overpressure, the cubic coefficients of force P(x) (eq. 8) and piston
coordinate L(x) (eq. 9) against u = x - x0 in metres, x0 = 0.112 m. Converted here:
a_P kN -> N (x1e3), b_P kN/m -> N/m (x1e3), c_P kN/m^2 -> N/m^2 (x1e3),
d_P 10^3 kN/m^3 -> N/m^3 (x1e6); a_L m, b_L 1, c_L 1/m, d_L 1/m^2 unchanged.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from functools import cache
from importlib import resources

import numpy as np

from uq._physics.cubic import cubic, cubic_slope  # noqa: F401  (the paper's cubic, one home)

FORCE_NAMES = ("a_P", "b_P", "c_P", "d_P")
PISTON_NAMES = ("a_L", "b_L", "c_L", "d_L")
PAPER_X0_M = 0.112
PAPER_PISTON_AREA_M2 = 54.82e-4
PAPER_X_MIN_M = 0.065
PAPER_X_MAX_M = 0.155
PAPER_PRESSURES_BAR = (0.1, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10)
_FORCE_SCALE = np.array([1e3, 1e3, 1e3, 1e6])


def _rows(name: str) -> list[dict[str, str]]:
    text = (
        resources.files("uq")
        .joinpath("_data")
        .joinpath("tables")
        .joinpath(name)
        .read_text(encoding="utf-8")
    )
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.startswith("#")]
    return list(csv.DictReader(lines))


@dataclass(frozen=True, eq=False)
class Table1:
    """Table 1 in SI: ``force[i]`` = (a_P, b_P, c_P, d_P), ``piston[i]`` = (a_L, ..., d_L)."""

    pressures_bar: np.ndarray  # (11,)
    force: np.ndarray  # (11, 4) N, N/m, N/m^2, N/m^3
    piston: np.ndarray  # (11, 4) m, 1, 1/m, 1/m^2

    def index(self, pressure_bar: float) -> int:
        hit = np.flatnonzero(np.isclose(self.pressures_bar, pressure_bar, atol=1e-9))
        if hit.size == 0:
            raise KeyError(f"no Table 1 row at {pressure_bar:g} bar")
        return int(hit[0])


@cache
def table1() -> Table1:
    """The paper's Table 1 in SI units (module docstring): the cubics of force and piston per pressure.

    >>> import uq
    >>> t = uq.table1()
    >>> t.pressures_bar.size, float(t.force[t.index(5.0)][0])   # 11 tests; a_P at 5 bar, N
    (11, 13020.0)
    """
    rows = _rows("table1_regression_coefficients.csv")
    p = np.array([float(r["pressure_bar"]) for r in rows])
    force = (
        np.array(
            [
                [
                    float(r[k])
                    for k in ("a_P_kN", "b_P_kN_per_m", "c_P_kN_per_m2", "d_P_1e3kN_per_m3")
                ]
                for r in rows
            ]
        )
        * _FORCE_SCALE
    )
    piston = np.array(
        [[float(r[k]) for k in ("a_L_m", "b_L", "c_L_per_m", "d_L_per_m2")] for r in rows]
    )
    return Table1(p, force, piston)


@cache
def table2() -> dict[float, tuple[float, float]]:
    """Table 2: pressure_bar -> (s_P in N, eps_P in %)."""
    return {
        float(r["pressure_bar"]): (float(r["s_P_N"]), float(r["eps_P_pct"]))
        for r in _rows("table2_force_deviations.csv")
    }


@dataclass(frozen=True, eq=False)
class Reference:
    """Values a report compares its posteriors with: per tested pressure, the cubic coefficients
    of force and piston (SI, the paper's basis) and optionally the deviation measures (s_P in N,
    eps_P in %). ``name`` says in a few words what they are (a column heading)."""

    name: str
    source: str
    force: dict[float, np.ndarray]  # pressure_bar -> (a_P, b_P, c_P, d_P)
    piston: dict[float, np.ndarray]  # pressure_bar -> (a_L, b_L, c_L, d_L)
    deviations: dict[float, tuple[float, float]]  # pressure_bar -> (s_P N, eps_P %)
    is_paper: bool = False

    def at(self, table: dict, pressure_bar: float):
        """The entry of ``table`` at a tested pressure (within 1e-6 bar), or None."""
        for p, v in table.items():
            if abs(p - pressure_bar) <= 1e-6:
                return v
        return None


@cache
def paper_reference() -> Reference:
    """The paper's Tables 1 and 2 as a :class:`Reference`."""
    t1 = table1()
    return Reference(
        name="paper",
        source="Tables 1 and 2 of the paper",
        force={float(p): t1.force[i] for i, p in enumerate(t1.pressures_bar)},
        piston={float(p): t1.piston[i] for i, p in enumerate(t1.pressures_bar)},
        deviations=table2(),
        is_paper=True,
    )


#: the comment line uq simulate writes for the N-50 spring of Table 1 (uq._stand.simulator)
N50_SPRING_WORDS = "N-50 balloon spring, true curves from Table 1 of the paper"


def is_n50_reconstruction(comments) -> bool:
    """The recordings are the virtual stand's reconstruction of the paper's N-50 spring (its
    header says so): the one campaign the paper's own tables describe."""
    text = "\n".join(comments)
    return "RECONSTRUCTED" in text.upper() and N50_SPRING_WORDS in text
