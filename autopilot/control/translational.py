"""What the translational laws share: the thrust and tilt of eqs. 23-29, and the backstepping family's
gains, parameters and state.

Per axis i in {x, y, z}, with the error sign of CONTROL.md (e1 = p - p_d, e1' = v - v_d), a
backstepping law gives a commanded acceleration ``a_i``; then (eqs. 24-29, as CONTROL.md reads them):

* ``U1 = m (g + a_z) / (cos(phi) cos(theta))``, saturated to ``[0, U1_max]``;
* ``u_x = m a_x / U1``, ``u_y = m a_y / U1`` (the thrust directions of eq. 23);
* ``phi_r = asin(sin(psi) u_x - cos(psi) u_y)``,
  ``theta_r = asin((cos(psi) u_x + sin(psi) u_y) / cos(phi_r))``, arguments clipped to the tilt
  limit (eq. 29 solved for the angles; the paper prints the u_y line twice).

:func:`thrust_and_tilt` is that map, a kernel any translational law may end with. The family of
the paper (integral in the 2nd step, in the 1st step, none) shares its gains (c1, c2, k_integral
per axis), its parameters (``BS_C1_*``, ``BS_C2_*``, ``BS_KI_*``) and the layout of its gains array
(``G_*``): :func:`pack_backstepping` and the helpers below.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace

from quadcommon.kernel import kernel
from quadcommon.layout import Field, layout
from quadcommon.layout import values as layout_values
from quadcommon.numerics import clip
from quadcommon.schema import Section

from ..params.store import ParamSpec
from .registry import LawContext

Vector3 = tuple[float, float, float]
AXES = ("X", "Y", "Z")
GAIN_HI = 1000.0
INTEGRAL_LO = 0.001  # integral gains stay > 0: the retune keeps k * integral, which needs k != 0


@kernel
def thrust_and_tilt(
    mass: float, gravity: float, thrust_max: float, sin_tilt_max: float, ax: float, ay: float, az: float,
    euler: Vector3,
) -> tuple[float, float, float, float, float]:  # fmt: skip
    """Eqs. 23-29: ``(U1, phi_r, theta_r, thrust_limited, tilt_limited)`` for the commanded
    accelerations, the limits flagged 1.0 when they act. Below a tenth of the hover thrust the
    horizontal directions u_x, u_y are taken at that thrust (free fall has no direction)."""
    phi, theta, psi = euler
    tilt = math.cos(phi) * math.cos(theta)
    thrust = mass * (gravity + az) / (tilt if tilt > 0.1 else 0.1)
    thrust_limited = 1.0 if thrust < 0.0 or thrust > thrust_max else 0.0
    thrust = clip(thrust, 0.0, thrust_max)
    floor = 0.1 * mass * gravity
    divisor = thrust if thrust > floor else floor
    u_x = mass * ax / divisor
    u_y = mass * ay / divisor
    sp, cp = math.sin(psi), math.cos(psi)
    arg = sp * u_x - cp * u_y
    tilt_limited = 1.0 if arg < -sin_tilt_max or arg > sin_tilt_max else 0.0
    roll_ref = math.asin(clip(arg, -sin_tilt_max, sin_tilt_max))
    arg = (cp * u_x + sp * u_y) / math.cos(roll_ref)
    if arg < -sin_tilt_max or arg > sin_tilt_max:
        tilt_limited = 1.0
    pitch_ref = math.asin(clip(arg, -sin_tilt_max, sin_tilt_max))
    return thrust, roll_ref, pitch_ref, thrust_limited, tilt_limited


# -- the backstepping family ---------------------------------------------------------------------
# Gains array of the three backstepping laws: per axis (x, y, z) from each offset.
BACKSTEPPING_GAINS = layout("BacksteppingGains", (
    Field("c1", 3),
    Field("c2", 3),
    Field("k", 3),
    Field("one_c1c2", 3),
    Field("c1_c2", 3),
    Field("bound", 3),
    Field("mass"),
    Field("gravity"),
    Field("thrust_max"),
    Field("sin_tilt"),
))  # fmt: skip


@kernel
def backstepping_step(axis, g, x, position, velocity, euler, ref_position, ref_velocity, ref_acceleration, dt,
                      integrate):  # fmt: skip
    """A backstepping law's step: ``axis(g, x, i, e1, e1', p_d'', dt, integrate)`` (the law's own
    kernel) gives the commanded acceleration on each axis i, then :func:`thrust_and_tilt`."""
    ax = axis(g, x, 0, position[0] - ref_position[0], velocity[0] - ref_velocity[0], ref_acceleration[0], dt,
              integrate)  # fmt: skip
    ay = axis(g, x, 1, position[1] - ref_position[1], velocity[1] - ref_velocity[1], ref_acceleration[1], dt,
              integrate)  # fmt: skip
    az = axis(g, x, 2, position[2] - ref_position[2], velocity[2] - ref_velocity[2], ref_acceleration[2], dt,
              integrate)  # fmt: skip
    thrust, roll_ref, pitch_ref, thrust_limited, tilt_limited = thrust_and_tilt(
        g[BACKSTEPPING_GAINS.mass],
        g[BACKSTEPPING_GAINS.gravity],
        g[BACKSTEPPING_GAINS.thrust_max],
        g[BACKSTEPPING_GAINS.sin_tilt],
        ax,
        ay,
        az,
        euler,
    )
    return thrust, roll_ref, pitch_ref, ax, ay, az, thrust_limited, tilt_limited


@dataclass(frozen=True)
class BacksteppingGains:
    """Per-axis (x, y, z) gains of the translational backstepping laws (Section 3.1, eqs. 24-29).

    ``k_integral`` is k_xi for the integral in the second step (the paper's law) and lambda for
    the integral in the first step (IntBS); zero for plain backstepping.
    """

    law: str
    c1: Vector3
    c2: Vector3
    k_integral: Vector3 = (0.0, 0.0, 0.0)


_POSITIVE = {"lo": 0.0, "lo_open": True, "hi": 1e4}


def load_backstepping_gains(section: Section, law: str, integral: bool) -> BacksteppingGains:
    """c1, c2 (> 0) and, for an integral law, k_integral (> 0 on every axis)."""
    c1, c2 = section.vector("c1", **_POSITIVE), section.vector("c2", **_POSITIVE)
    if not integral:  # no integral: k_integral may be given, as zeros only
        zeros = section.vector("k_integral", 3, (0.0, 0.0, 0.0), lo=0.0, hi=0.0)
        return BacksteppingGains(law, c1, c2, zeros)
    k = section.vector("k_integral", 3, (0.0, 0.0, 0.0), lo=0.0, hi=1e4)
    if min(k) <= 0.0:
        raise section.error("k_integral", k, f"> 0 on every axis for law '{law}'")
    return BacksteppingGains(law, c1, c2, k)


def backstepping_parameters(gains: BacksteppingGains, integral_meaning: str | None) -> tuple[ParamSpec, ...]:
    """``BS_C1_*``, ``BS_C2_*`` and, with an integral, ``BS_KI_*`` (defaults: ``gains``)."""
    specs = []
    for name, values, what in (("C1", gains.c1, "c1"), ("C2", gains.c2, "c2")):
        for i, axis in enumerate(AXES):
            what_axis = f"translational backstepping {what}, {axis.lower()} axis"
            specs.append(
                ParamSpec(f"BS_{name}_{axis}", values[i], 0.01, GAIN_HI, unit="1/s", description=what_axis)
            )
    if integral_meaning is not None:
        for i, axis in enumerate(AXES):
            what_axis = f"translational {integral_meaning}, {axis.lower()} axis"
            specs.append(
                ParamSpec(f"BS_KI_{axis}", gains.k_integral[i], INTEGRAL_LO, GAIN_HI, description=what_axis)
            )
    return tuple(specs)


def backstepping_from_params(gains: BacksteppingGains, params: Mapping[str, float]) -> BacksteppingGains:
    """The gains with the parameters ``BS_C1_X`` ... ``BS_KI_Z`` of ``params`` applied; a vector keeps its
    configured value unless all three of its axes are given."""
    def vec(prefix: str, default: Vector3) -> Vector3:
        names = [f"{prefix}_{a}" for a in AXES]
        if not all(n in params for n in names):
            return default
        return (params[names[0]], params[names[1]], params[names[2]])

    return replace(gains, c1=vec("BS_C1", gains.c1), c2=vec("BS_C2", gains.c2),
                   k_integral=vec("BS_KI", gains.k_integral))  # fmt: skip


def acceleration_limits(context: LawContext) -> Vector3:
    """What the vehicle can give at all (m/s^2, per axis): horizontally what the tilt limit allows
    (g tan(tilt)), vertically what the thrust allows above hover (U1_max / m - g). An integral
    state is held where its term of the commanded acceleration reaches this (anti-windup)."""
    horizontal = context.gravity_m_s2 * math.tan(context.tilt_max_rad)
    vertical = max(context.thrust_max_n / context.mass_kg - context.gravity_m_s2, 0.0)
    return (horizontal, horizontal, vertical)


def pack_backstepping(gains: BacksteppingGains, context: LawContext, weights: Vector3) -> tuple[float, ...]:
    """The gains array (:data:`BACKSTEPPING_GAINS`); ``weights[i]``: the integral state's weight in ``a_i``
    (its term is ``-weights[i] * state[i]``), which sets its anti-windup bound."""
    a_max = acceleration_limits(context)
    bound = tuple(a_max[i] / w if w > 0.0 else math.inf for i, w in enumerate(weights))
    c1, c2, k = gains.c1, gains.c2, gains.k_integral
    return layout_values(
        BACKSTEPPING_GAINS, c1=c1, c2=c2, k=k, one_c1c2=[1.0 + c1[i] * c2[i] for i in range(3)],
        c1_c2=[c1[i] + c2[i] for i in range(3)], bound=bound, mass=context.mass_kg,
        gravity=context.gravity_m_s2, thrust_max=context.thrust_max_n,
        sin_tilt=math.sin(context.tilt_max_rad),
    )  # fmt: skip


def rescale_integrals(state: list[float], old: Vector3, new: Vector3) -> list[float]:
    """Integral states after a retune: ``weight * state`` (the integral's term of the commanded
    acceleration) unchanged at the moment of the change; a new weight of zero drops the state."""
    return [state[i] * old[i] / new[i] if new[i] != 0.0 else 0.0 for i in range(len(state))]
