"""Plain backstepping, no integral action: the translational loop of BS-NLHinf (the paper's
ref. [23]). Per axis ``a = p_d'' - (1 + c1 c2) e1 - (c1 + c2) e1'``; it keeps an offset under a
sustained disturbance (nothing integrates it away).
"""

from __future__ import annotations

from quadcommon.kernel import kernel

from ..registry import TRANSLATIONAL, register
from ..translational import (
    BACKSTEPPING_GAINS,
    backstepping_from_params,
    backstepping_parameters,
    backstepping_step,
    load_backstepping_gains,
    pack_backstepping,
)


@kernel
def axis(g, x, i, e1, e1_dot, ref_acc, dt, integrate):
    """The commanded acceleration on axis ``i`` (m/s^2): ``p_d'' - (1 + c1 c2) e1 - (c1 + c2) e1'``; no
    state."""
    return ref_acc - g[BACKSTEPPING_GAINS.one_c1c2 + i] * e1 - g[BACKSTEPPING_GAINS.c1_c2 + i] * e1_dot


@kernel
def step(g, x, position, velocity, euler, ref_position, ref_velocity, ref_acceleration, ref_yaw, dt,
         integrate):
    """The translational step of the registry's contract: :func:`axis` per world axis, then thrust and tilt;
    ``(U1, phi_r, theta_r, a_x, a_y, a_z, thrust_limited, tilt_limited)``."""
    return backstepping_step(axis, g, x, position, velocity, euler, ref_position, ref_velocity,
                             ref_acceleration, dt, integrate)


@register(TRANSLATIONAL)
class Backstepping:
    """Plain backstepping, the translational loop of BS-NLHinf (``law = "backstepping"``): the backstepping
    gains c1, c2 per axis, no integral and no state."""

    NAME = "backstepping"
    STATE = ()
    step = staticmethod(step)
    parameters = staticmethod(lambda gains: backstepping_parameters(gains, None))
    gains_from_params = staticmethod(backstepping_from_params)

    @classmethod
    def load_gains(cls, section):
        return load_backstepping_gains(section, cls.NAME, integral=False)

    @staticmethod
    def pack(gains, context):
        return pack_backstepping(gains, context, (0.0, 0.0, 0.0))
