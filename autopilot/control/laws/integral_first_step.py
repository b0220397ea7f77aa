"""Integral backstepping with the integral in the FIRST step: IntBS of Bouabdallah & Siegwart
(2007), the paper's ref. [2], translational loop (CONTROL.md "The two comparison structures").

Per axis: chi' = e1, e2 = e1' + c1 e1 + lambda chi and
``a = p_d'' + (c1^2 - 1 - lambda) e1 - (c1 + c2) e2 + c1 lambda chi``. Its integral pole is very
slow (about -0.09 with lambda = 1.5), which is why it converges slowly (the paper's Fig. 8). The chi
terms of ``a`` add up to ``-c2 lambda chi``: that weight sets the anti-windup bound and the retune.
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
    """The commanded acceleration on axis ``i`` (m/s^2), the module's formula, and chi advanced by e1 dt
    within its anti-windup bound when ``integrate``."""
    c1, k = g[BACKSTEPPING_GAINS.c1 + i], g[BACKSTEPPING_GAINS.k + i]
    chi = x[i]
    e2 = e1_dot + c1 * e1 + k * chi
    a = ref_acc + (c1 * c1 - 1.0 - k) * e1 - g[BACKSTEPPING_GAINS.c1_c2 + i] * e2 + c1 * k * chi
    if integrate:
        x[i] = clip_symmetric(chi + e1 * dt, g[BACKSTEPPING_GAINS.bound + i])
    return a


@kernel
def step(g, x, position, velocity, euler, ref_position, ref_velocity, ref_acceleration, ref_yaw, dt,
         integrate):
    """The translational step of the registry's contract: :func:`axis` per world axis, then thrust and tilt;
    ``(U1, phi_r, theta_r, a_x, a_y, a_z, thrust_limited, tilt_limited)``."""
    return backstepping_step(axis, g, x, position, velocity, euler, ref_position, ref_velocity,
                             ref_acceleration, dt, integrate)


def integral_weights(gains):
    """The weight ``c2 lambda`` of chi in each axis's commanded acceleration (1/s^3): it sets the anti-windup
    bound and how a retune rescales chi."""
    c2, k = gains.c2, gains.k_integral
    return (c2[0] * k[0], c2[1] * k[1], c2[2] * k[2])


@register(TRANSLATIONAL)
class IntegralFirstStep:
    """IntBS translational law (``law = "integral_first_step"``): c1, c2 and lambda per axis, tunable in
    flight as ``BS_C1_*``, ``BS_C2_*``, ``BS_KI_*``; its state the integrals chi of the position errors (m
    s)."""

    NAME = "integral_first_step"
    STATE = ("chi_x", "chi_y", "chi_z")
    step = staticmethod(step)
    parameters = staticmethod(lambda gains: backstepping_parameters(gains, "lambda (integral of e1)"))
    gains_from_params = staticmethod(backstepping_from_params)

    @classmethod
    def load_gains(cls, section):
        return load_backstepping_gains(section, cls.NAME, integral=True)

    @staticmethod
    def pack(gains, context):
        return pack_backstepping(gains, context, integral_weights(gains))

    @staticmethod
    def retune(old, new, context, state, euler, euler_rates):
        return rescale_integrals(state, integral_weights(old), integral_weights(new))
