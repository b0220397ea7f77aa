"""Integral backstepping with the integral in the SECOND step: the paper's translational law
(Section 3.1, eqs. 24-28, with eq. 28's last term p_d'' as CONTROL.md reads it).

Per axis: integral state xi' = e2 = e1' + c1 e1 and
``a = p_d'' - k_xi xi - (1 + c1 c2) e1 - (c1 + c2) e1'``. Gains of Section IV: c1 = 17, c2 = 2.5,
k_xi = 1.5 on every axis.
"""

from __future__ import annotations

from ..registry import TRANSLATIONAL, register
from ..translational import (
    BacksteppingGains,
    BacksteppingLaw,
    backstepping_from_params,
    backstepping_parameters,
    load_backstepping_gains,
)


@register(TRANSLATIONAL)
class IntegralSecondStep(BacksteppingLaw):
    NAME = "integral_second_step"

    @classmethod
    def load_gains(cls, section):
        return load_backstepping_gains(section, cls.NAME, integral=True)

    @staticmethod
    def parameters(gains):
        return backstepping_parameters(gains, "k_xi (integral of e2)")

    gains_from_params = staticmethod(backstepping_from_params)

    def integral_weights(self, gains: BacksteppingGains):
        return gains.k_integral  # the integral term is -k_xi xi

    def accelerations(self, e1, e1_dot, ref_acc, dt: float, integrate: bool):
        integral, coef = self.integral, self._coef
        out = [0.0, 0.0, 0.0]
        for i in range(3):
            c1, _, k, one_plus_c1c2, c1_plus_c2 = coef[i]
            out[i] = ref_acc[i] - k * integral[i] - one_plus_c1c2 * e1[i] - c1_plus_c2 * e1_dot[i]
            if integrate:
                integral[i] += (e1_dot[i] + c1 * e1[i]) * dt
        if integrate:
            self._clamp_integral()  # anti-windup (BacksteppingLaw.set_integral_limit)
        return out
