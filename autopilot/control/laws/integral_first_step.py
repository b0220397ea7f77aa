"""Integral backstepping with the integral in the FIRST step: IntBS of Bouabdallah & Siegwart
(2007), the paper's ref. [2], translational loop (CONTROL.md "The two comparison structures").

Per axis: chi' = e1, e2 = e1' + c1 e1 + lambda chi and
``a = p_d'' + (c1^2 - 1 - lambda) e1 - (c1 + c2) e2 + c1 lambda chi``. Its integral pole is very
slow (about -0.09 with lambda = 1.5), which is why it converges slowly (the paper's Fig. 8).
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
class IntegralFirstStep(BacksteppingLaw):
    NAME = "integral_first_step"

    @classmethod
    def load_gains(cls, section):
        return load_backstepping_gains(section, cls.NAME, integral=True)

    @staticmethod
    def parameters(gains):
        return backstepping_parameters(gains, "lambda (integral of e1)")

    gains_from_params = staticmethod(backstepping_from_params)

    def integral_weights(self, gains: BacksteppingGains):
        # (c1^2 - 1 - lambda) e1 - (c1 + c2)(e1' + c1 e1 + lambda chi) + c1 lambda chi: the chi
        # terms add up to -(c1 + c2) lambda chi + c1 lambda chi = -c2 lambda chi.
        c2, lam = gains.c2, gains.k_integral
        return (c2[0] * lam[0], c2[1] * lam[1], c2[2] * lam[2])

    def accelerations(self, e1, e1_dot, ref_acc, dt: float, integrate: bool):
        integral, coef = self.integral, self._coef
        out = [0.0, 0.0, 0.0]
        for i in range(3):
            c1, _, k, _, c1_plus_c2 = coef[i]
            chi = integral[i]
            e2 = e1_dot[i] + c1 * e1[i] + k * chi
            out[i] = ref_acc[i] + (c1 * c1 - 1.0 - k) * e1[i] - c1_plus_c2 * e2 + c1 * k * chi
            if integrate:
                integral[i] += e1[i] * dt
        if integrate:
            self._clamp_integral()  # anti-windup (BacksteppingLaw.set_integral_limit)
        return out
