"""A fitted model known in closed form, for the tests of ``uq export`` (tests/derived/test_export.py,
tests/cli/test_export_command.py): the FittedModel protocol (uq._models.fitted) implemented by a
force P = p_u A(x), A(x) = a + b (x - X_REF) per draw, and dV/dx = (1 + c) A(x), so dV/dp_u = 0."""

from __future__ import annotations

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
