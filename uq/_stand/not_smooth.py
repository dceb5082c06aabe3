"""Springs whose effective area is not smooth in pressure, force and volume still from one potential.

Each is the thermodynamic spring ``n50-thermo`` (uq._stand.simulator.ThermoSpring: G = -p_u V0(x)
- p_u^2 C(x)/2 + E(x), fitted to Table 1, the Maxwell relation exact) with one more term of the
potential,

    G(x, p_u) = G_thermo(x, p_u) - W(x) h(p_u),      W'(x) = w(x) = w0 (1 + slope t),

t = (x - x0) / 0.05 m, so that

    P     = -dG/dx   = P_thermo + w(x) h(p_u)
    V     = -dG/dp_u = V_thermo + W(x) h'(p_u)
    dV/dx            = dV_thermo/dx + w(x) h'(p_u)   = dP/dp_u   (the Maxwell relation holds)

with h a function of the overpressure that is not smooth, or not polynomial, in it:

* ``n50-kink``: h = (p_u - p_k)_+, p_k = 4.5 bar, w0 = 1.2e-3 m^2 (about 5 % of F_eff), slope
  0.5: a kink of the force in pressure; the force's slope dP/dp_u, and with it the volume-derived
  area, steps up by w at p_k (a casing whose folds take a new shape above p_k).
* ``n50-knee``: h = s log(1 + exp((p_u - p_k) / s)), p_k = 7.75 bar, s = 0.2 bar, w0 = -2.0e-3
  m^2 (about 8 % of F_eff), slope -0.5: the same step downwards, spread over a few tenths of a bar (a cord layer that
  yields above p_k).
* ``n50-ripple``: h = p_s sin(2 pi p_u / 3 bar), p_s = 1 bar, w0 = 4e-4 m^2, slope 0.5: smooth, but
  a wave in pressure that no low polynomial follows, like Table 1's coefficients from one test to
  the next.

The sizes are Table 1's own: its Maxwell check (docs/thermo.md) fits a step of about 4 % in
the volume-derived area between 5 and 6 bar, and its F_eff departs from a smooth surface by
0.5-3 % between tested pressures. The departure is largest towards x_max (slope 0.5), where
Table 1's F_eff varies most with pressure. Nothing is unphysical: the force and the volume derive
from one potential at every pressure (tests/stand/test_not_smooth.py checks dP/dp_u = dV/dx by
finite differences).

These springs register themselves in ``uq._stand.simulator.SPRINGS`` (``uq/_stand/__init__.py``
imports this module).
"""

from __future__ import annotations

import numpy as np

from uq._physics.quantities import BAR_PA, BASIS_SCALE_M
from uq._stand.simulator import SPRINGS, ThermoSpring


class NotSmoothSpring(ThermoSpring):
    """``n50-thermo`` plus -W(x) h(p_u) in its potential (module docstring); a subclass gives h and
    h' (``extra_h_pa``, ``extra_dh``: h in Pa, h' dimensionless, of p_u in bar) and w0, slope."""

    name = "not-smooth"
    description = ""
    W0_M2 = 0.0
    SLOPE = 0.5

    # ---- the extra term
    def extra_h_pa(self, p_bar):
        raise NotImplementedError

    def extra_dh(self, p_bar):
        raise NotImplementedError

    def extra_area_m2(self, height_m):
        """w(x) = W'(x), m^2."""
        return self.W0_M2 * (1.0 + self.SLOPE * self._t(height_m))

    def extra_volume_m3(self, height_m):
        """W(x) = int_x0^x w, m^3 (W(x0) = 0: the volume at x0 is the thermodynamic spring's)."""
        t = self._t(height_m)
        return self.W0_M2 * BASIS_SCALE_M * (t + self.SLOPE * t**2 / 2.0)

    # ---- the thermodynamic spring's quantities with it
    def force_N(self, height_m, p_bar):
        return super().force_N(height_m, p_bar) + self.extra_area_m2(height_m) * self.extra_h_pa(
            p_bar
        )

    def volume_m3(self, height_m, p_bar):
        return super().volume_m3(height_m, p_bar) + self.extra_volume_m3(height_m) * self.extra_dh(
            p_bar
        )

    def volume_area_m2(self, height_m, p_bar):
        """dV/dx = dP/dp_u (the Maxwell relation), m^2."""
        return super().volume_area_m2(height_m, p_bar) + self.extra_area_m2(
            height_m
        ) * self.extra_dh(p_bar)

    def potential_J(self, height_m, p_bar):
        """G = G_thermo - W(x) h(p_u), J (the thermodynamic part takes V0 = V(x, 0), which here
        holds W(x) h'(0): taken back out)."""
        w_vol = self.extra_volume_m3(height_m)
        pa = np.asarray(p_bar, float) * BAR_PA
        thermo = super().potential_J(height_m, p_bar) + pa * w_vol * self.extra_dh(0.0)
        return thermo - w_vol * self.extra_h_pa(p_bar)


class KinkSpring(NotSmoothSpring):
    name = "n50-kink"
    description = (
        "n50-thermo with a kink in pressure: the force's slope in p_u steps up at 4.5 bar "
        "(one potential, Maxwell relation exact)"
    )
    P_KINK_BAR = 4.5
    W0_M2 = 1.2e-3

    def extra_h_pa(self, p_bar):
        return np.maximum(np.asarray(p_bar, float) - self.P_KINK_BAR, 0.0) * BAR_PA

    def extra_dh(self, p_bar):
        return (np.asarray(p_bar, float) > self.P_KINK_BAR).astype(float)


class KneeSpring(NotSmoothSpring):
    name = "n50-knee"
    description = (
        "n50-thermo whose force's slope in p_u drops by 8 % of F_eff within 0.2 bar of 7.75 bar "
        "(a cord layer that yields; one potential, Maxwell relation exact)"
    )
    P_KNEE_BAR = 7.75
    WIDTH_BAR = 0.2
    W0_M2 = -2.0e-3
    SLOPE = -0.5

    def extra_h_pa(self, p_bar):
        d = (np.asarray(p_bar, float) - self.P_KNEE_BAR) / self.WIDTH_BAR
        return self.WIDTH_BAR * np.logaddexp(0.0, d) * BAR_PA

    def extra_dh(self, p_bar):
        d = (np.asarray(p_bar, float) - self.P_KNEE_BAR) / self.WIDTH_BAR
        return 0.5 * (1.0 + np.tanh(d / 2.0))


class RippleSpring(NotSmoothSpring):
    name = "n50-ripple"
    description = (
        "n50-thermo with a wave in pressure (period 3 bar) that no low polynomial follows "
        "(one potential, Maxwell relation exact)"
    )
    PERIOD_BAR = 3.0
    P_SCALE_BAR = 1.0
    W0_M2 = 4.0e-4

    def extra_h_pa(self, p_bar):
        k = 2.0 * np.pi / self.PERIOD_BAR
        return self.P_SCALE_BAR * np.sin(k * np.asarray(p_bar, float)) * BAR_PA

    def extra_dh(self, p_bar):
        k = 2.0 * np.pi / self.PERIOD_BAR
        return self.P_SCALE_BAR * k * np.cos(k * np.asarray(p_bar, float))


NOT_SMOOTH = (KinkSpring, KneeSpring, RippleSpring)
for _spring in NOT_SMOOTH:
    SPRINGS[_spring.name] = _spring
