"""A fitted model known in closed form, and independent readers of the MATLAB and TeimOrbit files,
for the tests of ``uq export`` (tests/derived/test_export.py,
tests/cli/test_export_command.py): the FittedModel protocol (uq._models.fitted) implemented by a
force P = p_u A(x), A(x) = a + b (x - X_REF) per draw, and dV/dx = (1 + c) A(x), so dV/dp_u = 0."""

from __future__ import annotations

import re
import shlex

import numpy as np

from uq._io.errors import InputError

X_REF = 0.11


class LinearArea:
    """A fitted model known in closed form (the FittedModel protocol)."""

    name = "linear-area"
    label = "closed-form test model (area linear in height)"
    height_range_m = (0.065, 0.155)
    pressure_range_bar = (1.0, 10.0)
    tested_pressures_bar = np.array([1.0, 5.0, 10.0])
    has_volume = True
    has_dvdp = True  # V(x, p_u) = V0 + integral of (1 + c) A(x) dx: dV/dp_u = 0 exactly
    recordings = None
    convergence = None
    idata = None
    omitted_reason = None

    def __init__(self, n: int = 3000, seed: int = 0, volume: bool = True):
        rng = np.random.default_rng(seed)
        self.a = rng.normal(0.0150, 2e-4, n)
        self.b = rng.normal(-0.05, 0.004, n)
        self.c = rng.normal(0.05, 0.01, n)
        self.n_draws = n
        self.has_volume = volume
        self.omitted_reason = None if volume else "force-only test model: no volume"
        self.provenance = {"recordings_path": "closed form", "recordings_sha256": "0" * 64}

    def _draws(self, v, h, p):
        h, p = np.broadcast_arrays(np.asarray(h, float), np.asarray(p, float))
        e = (slice(None),) + (None,) * h.ndim
        return v[e], h, p

    def _area(self, h, p):
        a, h, p = self._draws(self.a, h, p)
        return a + self.b[(slice(None),) + (None,) * h.ndim] * (h - X_REF), h, p

    def check_range(self, height_m, p_bar, param=None):
        lo, hi = self.height_range_m
        if np.any(np.asarray(height_m) < lo) or np.any(np.asarray(height_m) > hi):
            raise InputError(f"{param or 'height_m'}: outside", param=param)

    def force_draws(self, height_m, p_bar, *, check=True):
        area, h, p = self._area(height_m, p_bar)
        return area * p * 1e5

    def feff_draws(self, height_m, p_bar, *, check=True):
        return self._area(height_m, p_bar)[0]

    def volume_area_draws(self, height_m, p_bar, *, check=True):
        area, h, _ = self._area(height_m, p_bar)
        return area * (1.0 + self.c[(slice(None),) + (None,) * h.ndim])

    def volume_pressure_draws(self, height_m, p_bar, *, check=True):
        return 0.0 * self._area(height_m, p_bar)[0]

    def on_draws(self, n):
        m = LinearArea.__new__(LinearArea)
        m.__dict__ = dict(self.__dict__)
        idx = np.linspace(0, self.n_draws - 1, n).round().astype(int)
        m.a, m.b, m.c, m.n_draws = self.a[idx], self.b[idx], self.c[idx], n
        return m

    def blocks(self):
        return {}

    def to_json(self, comparison=None, advice=None):
        return {}

    def save(self, path, **provenance):
        raise NotImplementedError


# ----------------------------------------------------------------------------- readers


def matlab_assignments(text: str) -> dict:
    """A reader of the assignments a MATLAB script makes (``s.a.b = [1; 2];``): numbers, column
    vectors, matrices (rows split by ';', columns by spaces), strings; comments (%) dropped."""
    out = {}
    for line in text.splitlines():
        line = line.split("%", 1)[0].strip() if not re.search(r"=\s*'", line) else line.strip()
        m = re.match(r"^([A-Za-z]\w*(?:\.\w+)*)\s*=\s*(.*);", line)
        if not m or m.group(2) == "struct()":
            continue
        name, value = m.group(1), m.group(2).strip()
        if value.startswith("'"):
            out[name] = value[1 : value.rindex("'")].replace("''", "'")
            continue
        rows = [r.split() for r in value.strip("[]").split(";")]
        a = np.array([[float(v) for v in r] for r in rows])
        out[name] = a
    return out


def parse_teimorbit(text: str) -> dict:
    """A TeimOrbit reader from the format's rules (Adams Tire "About the TeimOrbit format", Altair
    "About TeimOrbit Files"): [BLOCK], (SUB_BLOCK), NAME = value parameters, {labels} tables whose
    rows follow until the next table, sub-block, block, comment or blank line; comments start with
    '$' or '!'. Returns block -> {"params", sub-block -> {"params", "labels", "rows"}}."""
    blocks: dict = {}
    block = sub = table = None
    for raw in text.splitlines():
        line = raw.strip()
        if not line or line[0] in "$!":
            table = None
            continue
        if line.startswith("["):
            name = line[1 : line.index("]")].upper()
            block = blocks.setdefault(name, {"params": {}})
            sub, table = None, None
        elif line.startswith("("):
            sub = block.setdefault(line[1 : line.index(")")].upper(), {"params": {}})
            table = None
        elif line.startswith("{"):
            table = (sub if sub is not None else block).setdefault("table", {})
            table["labels"] = line[1 : line.index("}")].split()
            table["rows"] = []
        elif "=" in line and table is None:
            k, v = (x.strip() for x in line.split("=", 1))
            v = v.strip("'\"") if v[0] in "'\"" else float(v)
            (sub if sub is not None else block)["params"][k.upper()] = v
        elif table is not None:
            table["rows"].append([_token(c) for c in shlex.split(line)])
    return blocks


def _token(text: str):
    try:
        return float(text)
    except ValueError:
        return text
