"""The absolute volume (uq/_physics/volume.py): increments from the volume-derived area, V_c and the
assumption about dV/dp_u at the design height, against closed forms."""

from __future__ import annotations

import numpy as np
import pytest

from uq._io.errors import InputError
from uq._physics.volume import (
    absolute_volume_grid,
    charge_volume_draws,
    relative_volume_grid,
)

XS = np.linspace(0.065, 0.155, 19)
PS = np.linspace(1e5, 10e5, 10)
X_C, P_C = 0.112, 5e5


def _area(a0=0.027, a1=-0.22, a2=-1.5, g=6.5e-9):
    """dV/dx = a0 + a1 u + a2 u^2 + g p (a casing whose area grows with pressure), per draw (2 draws)."""
    u = (XS - X_C)[None, :, None]
    p = PS[None, None, :]
    scale = np.array([1.0, 1.1])[:, None, None]
    return scale * (a0 + a1 * u + a2 * u**2) + g * p + 0 * scale


def test_increments_integrate_the_area_exactly():
    """V(x, p) - V(x_c, p_c) = (x-integral of dV/dx from x_c) + dV/dp(x_c) (p - p_c): the spline
    integral is exact for areas cubic in x (1e-12)."""
    A = _area()
    u = (XS - X_C)[None, :, None]
    scale = np.array([1.0, 1.1])[:, None, None]
    exact_x = scale * (0.027 * u - 0.22 * u**2 / 2 - 1.5 * u**3 / 3) + 6.5e-9 * PS * u
    rel = relative_volume_grid(XS, PS, A, design_height_m=X_C, charge_pa=P_C)
    assert np.allclose(rel, exact_x, rtol=0, atol=1e-15)
    given = relative_volume_grid(
        XS, PS, A, design_height_m=X_C, charge_pa=P_C, dvdp_m3_per_pa=3e-10
    )
    assert np.allclose(given - rel, 3e-10 * (PS - P_C)[None, None, :], atol=1e-15)
    # a model's own dV/dp at x_c on the pressure grid (here linear in p): integrated in pressure
    d = np.stack([2e-10 + 1e-17 * PS, 4e-10 + 0 * PS])
    own = relative_volume_grid(XS, PS, A, design_height_m=X_C, charge_pa=P_C, dvdp_m3_per_pa=d)
    want = np.stack([2e-10 * (PS - P_C) + 0.5e-17 * (PS**2 - P_C**2), 4e-10 * (PS - P_C)])[
        :, None, :
    ]
    assert np.allclose(own - rel, want, atol=1e-15)


def test_absolute_volume_states_its_assumption():
    A = _area()
    v_c = np.array([3.3e-3, 3.4e-3])
    out = absolute_volume_grid(
        XS, PS, A, design_height_m=X_C, charge_pa=P_C, volume_m3=v_c, volume_sd_m3=1e-4
    )
    j, k = list(XS).index(0.11), 4
    assert out.volume_m3[:, j, k] == pytest.approx(
        v_c + relative_volume_grid(XS, PS, A, design_height_m=X_C, charge_pa=P_C)[:, j, k]
    )
    assert "ASSUMED" in out.statement and "112 mm" in out.statement and "+- 0.1 L" in out.statement
    given = absolute_volume_grid(
        XS, PS, A, design_height_m=X_C, charge_pa=P_C, volume_m3=3.3e-3, dvdp_m3_per_pa=2e-5 / 1e5
    )
    assert "GIVEN" in given.statement and "0.02 L per bar" in given.statement


def test_charge_volume_draws():
    rng = np.random.default_rng(5)
    d = charge_volume_draws(3.3e-3, 0.1e-3, 20000, rng)
    assert abs(d.mean() - 3.3e-3) < 4 * 0.1e-3 / np.sqrt(20000)
    assert d.std() == pytest.approx(0.1e-3, rel=0.03)
    assert np.all(charge_volume_draws(3.3e-3, 0.0, 5, rng) == 3.3e-3)
    for v, sd, opt in (
        (-1e-3, 0.0, "^volume_l:"),
        (3e-3, 1e-3, "^volume_sd_l:"),
        (3e-3, -1.0, "^volume_sd_l:"),
    ):
        with pytest.raises(InputError, match=opt):
            charge_volume_draws(v, sd, 10, rng)
