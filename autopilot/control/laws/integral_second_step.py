"""Integral backstepping with the integral in the SECOND step: the paper's translational law
(Section 3.1, eqs. 24-28, with eq. 28's last term p_d'' as CONTROL.md reads it).

Per axis: integral state xi' = e2 = e1' + c1 e1 and
``a = p_d'' - k_xi xi - (1 + c1 c2) e1 - (c1 + c2) e1'``, then U1 and the roll/pitch references of
eqs. 23-29 (:func:`~..translational.thrust_and_tilt`). Gains of Section IV: c1 = 17, c2 = 2.5,
k_xi = 1.5 on every axis. Anti-windup: xi is held where ``k_xi xi`` reaches what the vehicle can
give (:func:`~..translational.acceleration_limits`).
"""

from __future__ import annotations

from quadcommon.kernel import kernel
from quadcommon.numerics import clip_symmetric

from ..registry import TRANSLATIONAL, register
from ..translational import (
    BACKSTEPPING_GAINS,
    backstepping_from_params,
    backstepping_parameters,
    backstepping_step,
    load_backstepping_gains,
    pack_backstepping,
    rescale_integrals,
)


@kernel
def axis(g, x, i, e1, e1_dot, ref_acc, dt, integrate):
    """eq. 28 on axis i, and the integral of e2 = e1' + c1 e1 (eq. 24)."""
    a = (
        ref_acc
        - g[BACKSTEPPING_GAINS.k + i] * x[i]
        - g[BACKSTEPPING_GAINS.one_c1c2 + i] * e1
        - g[BACKSTEPPING_GAINS.c1_c2 + i] * e1_dot
    )
    if integrate:
        x[i] = clip_symmetric(
            x[i] + (e1_dot + g[BACKSTEPPING_GAINS.c1 + i] * e1) * dt, g[BACKSTEPPING_GAINS.bound + i]
        )
    return a


@kernel
def step(
    g, x, position, velocity, euler, ref_position, ref_velocity, ref_acceleration, ref_yaw, dt, integrate
):
    """The translational step of the registry's contract: :func:`axis` per world axis, then thrust and tilt
    (eqs. 23-29); ``(U1, phi_r, theta_r, a_x, a_y, a_z, thrust_limited, tilt_limited)``."""
    return backstepping_step(
        axis, g, x, position, velocity, euler, ref_position, ref_velocity, ref_acceleration, dt, integrate
    )


@register(TRANSLATIONAL)
class IntegralSecondStep:
    """The paper's translational law (``law = "integral_second_step"``): c1, c2 and k_xi per axis, tunable in
    flight as ``BS_C1_*``, ``BS_C2_*``, ``BS_KI_*``; its state the integrals xi of e2 (m)."""

    NAME = "integral_second_step"
    STATE = ("xi_x", "xi_y", "xi_z")
    step = staticmethod(step)
    parameters = staticmethod(lambda gains: backstepping_parameters(gains, "k_xi (integral of e2)"))
    gains_from_params = staticmethod(backstepping_from_params)

    @classmethod
    def load_gains(cls, section):
        return load_backstepping_gains(section, cls.NAME, integral=True)

    @staticmethod
    def pack(gains, context):
        return pack_backstepping(gains, context, gains.k_integral)  # the integral term is -k_xi xi

    @staticmethod
    def retune(old, new, context, state, euler, euler_rates):
        return rescale_integrals(state, old.k_integral, new.k_integral)
