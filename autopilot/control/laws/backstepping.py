"""Plain backstepping, no integral action: the translational loop of BS-NLHinf (the paper's
ref. [23]). Per axis ``a = p_d'' - (1 + c1 c2) e1 - (c1 + c2) e1'``; it keeps an offset under a
sustained disturbance (nothing integrates it away).
"""

from __future__ import annotations

from ..registry import TRANSLATIONAL, register
from ..translational import (
    BacksteppingLaw,
    backstepping_from_params,
    backstepping_parameters,
    load_backstepping_gains,
)


@register(TRANSLATIONAL)
class Backstepping(BacksteppingLaw):
    NAME = "backstepping"

    @classmethod
    def load_gains(cls, section):
        return load_backstepping_gains(section, cls.NAME, integral=False)

    @staticmethod
    def parameters(gains):
        return backstepping_parameters(gains, None)

    gains_from_params = staticmethod(backstepping_from_params)

    def accelerations(self, e1, e1_dot, ref_acc, dt: float, integrate: bool):
        coef = self.coef_pd
        return [ref_acc[i] - coef[i][0] * e1[i] - coef[i][1] * e1_dot[i] for i in range(3)]

    def _set_gains(self, gains) -> None:
        super()._set_gains(gains)
        self.coef_pd = [(c[3], c[4]) for c in self._coef]
