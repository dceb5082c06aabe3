"""The springs not smooth in pressure (uq/_stand/not_smooth.py): force and volume from one potential
(P = -dG/dx, V = -dG/dp_u, so the Maxwell relation holds), the stated non-smoothness, and the stand
runs them."""

from __future__ import annotations

import numpy as np
import pytest

from uq._physics.quantities import BAR_PA
from uq._stand.not_smooth import NOT_SMOOTH, KinkSpring
from uq._stand.simulator import SPRINGS, Layout, simulate_recordings

HEIGHTS = np.array([0.070, 0.100, 0.112, 0.140, 0.150])
#: pressures away from the kinks (finite differences across a kink are not derivatives)
PRESSURES = (1.3, 3.7, 5.2, 8.9)


@pytest.mark.parametrize("cls", NOT_SMOOTH)
def test_force_and_volume_derive_from_one_potential(cls):
    """P = -dG/dx and V(x) - V(x0) = -(dG/dp_u)(x) + (dG/dp_u)(x0), by central differences of the
    potential (relative 1e-6), hence the Maxwell relation dP/dp_u = dV/dx (checked directly too)."""
    s = cls()
    hx, hp = 1e-6, 1e-4  # m, bar
    for p in PRESSURES:
        G = lambda x, q: s.potential_J(x, q)  # noqa: E731
        force = -(G(HEIGHTS + hx, p) - G(HEIGHTS - hx, p)) / (2 * hx)
        np.testing.assert_allclose(force, s.force_N(HEIGHTS, p), rtol=1e-6, atol=1e-3)
        dGdp = (G(HEIGHTS, p + hp) - G(HEIGHTS, p - hp)) / (2 * hp * BAR_PA)
        x0 = np.array(s.x0_m)
        dGdp0 = (G(x0, p + hp) - G(x0, p - hp)) / (2 * hp * BAR_PA)
        np.testing.assert_allclose(
            -(dGdp - dGdp0), s.volume_m3(HEIGHTS, p) - s.volume_m3(x0, p), rtol=1e-5, atol=1e-9
        )
        dPdp = (s.force_N(HEIGHTS, p + hp) - s.force_N(HEIGHTS, p - hp)) / (2 * hp * BAR_PA)
        dVdx = (s.volume_m3(HEIGHTS + hx, p) - s.volume_m3(HEIGHTS - hx, p)) / (2 * hx)
        np.testing.assert_allclose(dPdp, dVdx, rtol=1e-5)
        np.testing.assert_allclose(dVdx, s.volume_area_m2(HEIGHTS, p), rtol=1e-5)


def test_the_kink_steps_the_force_slope_in_pressure():
    """n50-kink: dP/dp_u jumps by w(x) at 4.5 bar, the force itself is continuous there."""
    s = KinkSpring()
    p, e = KinkSpring.P_KINK_BAR, 1e-6
    below = s.volume_area_m2(HEIGHTS, p - e)
    above = s.volume_area_m2(HEIGHTS, p + e)
    np.testing.assert_allclose(above - below, s.extra_area_m2(HEIGHTS), rtol=1e-4)
    np.testing.assert_allclose(s.force_N(HEIGHTS, p - e), s.force_N(HEIGHTS, p + e), rtol=1e-6)


@pytest.mark.parametrize("name", [c.name for c in NOT_SMOOTH])
def test_the_stand_records_them(name):
    rec = simulate_recordings(name, seed=2, layout=Layout(pressures_bar=(2.0, 6.0), step_m=0.015))
    assert [t.pressure_bar for t in rec.tests] == [2.0, 6.0]
    assert SPRINGS[name].description in rec.comments[1]
