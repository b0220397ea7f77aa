"""Geometric tracking control on SE(3) of Lee, Leok and McClamroch (2010), position part: the
translational half of the ``se3`` cascade.

With ``e_x = p - p_d``, ``e_v = v - v_d`` and world z up (Lee's paper has z down; the signs of g
follow):

* ``F_d = -k_x e_x - k_v e_v + m g e3 + m p_d''``, the force the thrust should give;
* ``U1 = F_d . R e3``: its component along the current body z axis (saturated to ``[0, U1_max]``);
* ``b3_d = F_d / |F_d|``, the desired body z axis, its angle from the vertical limited to the
  cascade's ``tilt_max_rad`` (not in the paper: the same limit every cascade here has).

The desired attitude is the one with body z axis ``b3_d`` and the reference's yaw psi_d in the ZYX
convention of this project: ``R_d = R(phi_d, theta_d, psi_d)`` whose third column is ``b3_d``
(:func:`quadcommon.rigid_body.roll_pitch_from_body_z`). Lee builds it from a desired heading
direction ``b1_d`` instead: ``b2_d = b3_d x b1_d / |.|``, ``b1 = b2_d x b3_d``, whose projection on
the horizontal plane need not point along ``b1_d``; with ``b1_d = (cos psi_d, sin psi_d, 0)`` the
two attitudes share ``b3_d`` and differ in heading by a term of second order in the tilt (zero
for a pure roll or a pure pitch). The law hands (phi_d, theta_d) to the command filter, whose
eta_d, eta_d', eta_d'' the attitude law (:mod:`.se3_attitude`) tracks with their feed-forward.

No integral action (the 2010 law has none): under a sustained disturbance it keeps an offset,
as BS-NLHinf does.
"""

from __future__ import annotations

from dataclasses import dataclass

from quadcommon.kernel import kernel
from quadcommon.layout import Field, layout, values
from quadcommon.numerics import clip
from quadcommon.rigid_body import limit_tilt, roll_pitch_from_body_z, rotation_matrix

from ..registry import TRANSLATIONAL, LawContext, register
from ..tunable import Tunable, TunableLaw

# Gains array: k_x (N/m), k_v (N s/m), the nominal mass, g, U1_max, the tilt limit.
GAINS = layout("Se3PositionGains", (
    Field("kx"),
    Field("kv"),
    Field("mass"),
    Field("gravity"),
    Field("thrust_max"),
    Field("tilt_max"),
))  # fmt: skip


@kernel
def force(g, e_x, e_v, acceleration):
    """One axis of ``F_d = -k_x e_x - k_v e_v + m (p_d'' + g e3)`` (``acceleration``: p_d'' + g e3)."""
    return g[GAINS.mass] * acceleration - g[GAINS.kx] * e_x - g[GAINS.kv] * e_v


@kernel
def step(g, x, position, velocity, euler, ref_position, ref_velocity, ref_acceleration, ref_yaw, dt,
         integrate):  # fmt: skip
    """The translational step of the registry's contract: ``F_d``, ``U1 = F_d . R e3`` and the tilt-limited
    ``b3_d`` as roll and pitch references; ``(U1, phi_r, theta_r, a_x, a_y, a_z, thrust_limited,
    tilt_limited)``."""
    m, gravity = g[GAINS.mass], g[GAINS.gravity]
    fx = force(g, position[0] - ref_position[0], velocity[0] - ref_velocity[0], ref_acceleration[0])
    fy = force(g, position[1] - ref_position[1], velocity[1] - ref_velocity[1], ref_acceleration[1])
    fz = force(g, position[2] - ref_position[2], velocity[2] - ref_velocity[2], ref_acceleration[2] + gravity)
    R = rotation_matrix(euler[0], euler[1], euler[2])
    thrust = fx * R[0][2] + fy * R[1][2] + fz * R[2][2]  # F_d . R e3
    thrust_max = g[GAINS.thrust_max]
    thrust_limited = 1.0 if thrust < 0.0 or thrust > thrust_max else 0.0
    bx, by, bz, tilt_limited = limit_tilt(fx, fy, fz, g[GAINS.tilt_max])  # b3_d
    roll_ref, pitch_ref = roll_pitch_from_body_z(bx, by, bz, ref_yaw)
    thrust = clip(thrust, 0.0, thrust_max)
    return thrust, roll_ref, pitch_ref, fx / m, fy / m, fz / m - gravity, thrust_limited, tilt_limited


TUNABLE_GAINS = (
    Tunable("k_x", "SE3_KX", 0.0, 1000.0, "N/m", "SE(3) position gain k_x"),
    Tunable("k_v", "SE3_KV", 0.0, 1000.0, "N s/m", "SE(3) velocity gain k_v"),
)


@dataclass(frozen=True)
class Se3PositionGains:
    """Lee's position and velocity gains (force per metre, per metre per second)."""

    law: str
    k_x: float
    k_v: float


@register(TRANSLATIONAL)
class Se3Position(TunableLaw):
    NAME = "se3_position"
    GAINS, TUNABLE = Se3PositionGains, TUNABLE_GAINS
    step = staticmethod(step)

    @staticmethod
    def pack(gains: Se3PositionGains, context: LawContext) -> tuple[float, ...]:
        return values(GAINS, kx=gains.k_x, kv=gains.k_v, mass=context.mass_kg, gravity=context.gravity_m_s2,
                      thrust_max=context.thrust_max_n, tilt_max=context.tilt_max_rad)  # fmt: skip
