"""PX4's multicopter position controller (``mc_pos_control``, its PositionControl class), the
translational half of the ``px4_pid`` cascade, on this vehicle's physical thrust.

Per step, with the error sign of PX4 (setpoint - estimate) and world z up:

1. position P: ``v_sp = v_d + K_p (p_d - p)`` (MPC_XY_P, MPC_Z_P); horizontally the P part has
   priority over the feed-forward within ``velocity_max_xy_m_s`` (PX4's ``constrainXY``),
   vertically ``v_sp_z`` is clipped to ``[-velocity_max_down_m_s, velocity_max_up_m_s]``;
2. velocity PID with acceleration feed-forward, D on the measured acceleration:
   ``a_sp = a_d + K_vp (v_sp - v) + i - K_vd v'`` (MPC_*_VEL_P_ACC, _I_ACC, _D_ACC). The estimate
   carries no acceleration, so ``v'`` is the velocity differentiated over one step and low-passed
   at MPC_VELD_LP (PX4 differentiates its velocity estimate the same way);
3. thrust vector (PX4's accelerationControl): the body z axis along ``(a_x, a_y, g)`` (with
   MPC_ACC_DECOUPLE; ``(a_x, a_y, g + a_z)`` without), its tilt limited to the cascade's
   ``tilt_max_rad`` (PX4's MPC_TILTMAX_AIR; ControlMath::limitTilt); the collective thrust is the
   vertical thrust ``T_h (g + a_z) / g`` projected on that axis (divided by its cosine), at least
   ``thrust_min``;
4. saturation with vertical priority: the vertical thrust is limited to what ``thrust_max`` leaves
   after a horizontal margin ``thrust_xy_margin``, the horizontal thrust to what is left;
5. anti-windup: the vertical integral stops when the thrust is at a limit in the direction of the
   error and stays within +-g; horizontally a tracking anti-reset-windup feeds the acceleration
   the saturated thrust cannot give back into the integral (gain 2 / MPC_XY_VEL_P_ACC; Rundqwist
   1990), as PX4 does;
6. the attitude setpoint: roll and pitch of the attitude whose body z axis is the thrust vector and
   whose yaw is the reference's (PX4's bodyzToAttitude); U1 is the thrust vector's length.

Normalised to physical: PX4's thrust is normalised, 1 = the vehicle's maximum; here 1 is the
actuators' ``U1_max`` (LawContext.thrust_max_n) and the hover thrust ``T_h`` is ``m g / U1_max``,
exact for the nominal vehicle (PX4 estimates it, or reads MPC_THR_HOVER). So ``U1 = m (g + a_z) /
cos(tilt of the thrust axis)``: the collective thrust is projected on the *commanded* axis, not on
the current attitude as the paper's eq. 26 does. Velocity limits and thrust limits are config keys
of the law (``velocity_max_*``, ``thrust_min`` = MPC_THR_MIN, ``thrust_max`` = MPC_THR_MAX,
``thrust_xy_margin`` = MPC_THR_XY_MARG, normalised), not parameters.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from quadcommon.kernel import kernel
from quadcommon.layout import Field, layout, values
from quadcommon.numerics import clip, derivative_names, filtered_derivative, low_pass_alpha
from quadcommon.rigid_body import limit_tilt, roll_pitch_from_body_z
from quadcommon.schema import Section

from ..registry import TRANSLATIONAL, LawContext, register
from ..tunable import Tunable, TunableLaw

# Gains array: position P (x, y, z), velocity P, I, D (x, y, z), the velocity derivative's low-pass
# weight, MPC_ACC_DECOUPLE (1.0/0.0), the velocity limits (xy, up, down), the hover thrust, the
# thrust limits (min, max, horizontal margin; normalised), U1_max, g, the tilt limit.
GAINS = layout("Px4PositionGains", (
    Field("pos_p", 3),
    Field("vel_p", 3),
    Field("vel_i", 3),
    Field("vel_d", 3),
    Field("alpha"),
    Field("decouple"),
    Field("vel_max_xy"),
    Field("vel_max_up"),
    Field("vel_max_down"),
    Field("hover"),
    Field("thr_min"),
    Field("thr_max"),
    Field("thr_xy_margin"),
    Field("thrust_max"),
    Field("gravity"),
    Field("tilt_max"),
))  # fmt: skip
# State: the velocity integral (m/s^2, PX4's _vel_int), then the velocity derivative's filter.
X_INT, X_DERIVATIVE = 0, 3


@kernel
def constrain_xy(v0x, v0y, v1x, v1y, limit):
    """``v0 + v1`` with length at most ``limit``, ``v0`` first (PX4's ControlMath::constrainXY):
    the direction of ``v0`` is kept whole up to the limit, then as much of ``v1`` as fits."""
    sx, sy = v0x + v1x, v0y + v1y
    if sx * sx + sy * sy <= limit * limit:
        return sx, sy
    n0 = math.sqrt(v0x * v0x + v0y * v0y)
    if n0 >= limit:
        return v0x / n0 * limit, v0y / n0 * limit
    n1 = math.sqrt(v1x * v1x + v1y * v1y)
    if n0 < 0.001:
        return v1x / n1 * limit, v1y / n1 * limit
    # the s >= 0 with |v0 + s u1| = limit, u1 = v1 / |v1|
    ux, uy = v1x / n1, v1y / n1
    m = ux * v0x + uy * v0y
    s = -m + math.sqrt(m * m - (n0 * n0 - limit * limit))
    return v0x + ux * s, v0y + uy * s


@kernel
def thrust_setpoint(g, ax, ay, az):
    """PX4's accelerationControl: the normalised thrust vector for the commanded acceleration
    (world z up), 1.0 if the tilt limit acted, 1.0 if the minimum thrust did."""
    gravity = g[GAINS.gravity]
    vertical = gravity if g[GAINS.decouple] != 0.0 else gravity + az
    bx, by, bz, tilt_limited = limit_tilt(ax, ay, vertical, g[GAINS.tilt_max])
    hover = g[GAINS.hover]
    collective = hover * (gravity + az) / gravity / bz
    floored = 0.0
    if collective < g[GAINS.thr_min]:
        collective, floored = g[GAINS.thr_min], 1.0
    return bx * collective, by * collective, bz * collective, tilt_limited, floored


@kernel
def step(g, x, position, velocity, euler, ref_position, ref_velocity, ref_acceleration, ref_yaw, dt,
         integrate):  # fmt: skip
    """The translational step of the registry's contract, steps 1-6 of the module docstring; ``(U1, phi_r,
    theta_r, a_x, a_y, a_z, thrust_limited, tilt_limited)``."""
    # 1. position P -> velocity setpoint
    px = g[GAINS.pos_p] * (ref_position[0] - position[0])
    py = g[GAINS.pos_p + 1] * (ref_position[1] - position[1])
    pz = g[GAINS.pos_p + 2] * (ref_position[2] - position[2])
    vx, vy = constrain_xy(px, py, ref_velocity[0], ref_velocity[1], g[GAINS.vel_max_xy])
    vz = clip(ref_velocity[2] + pz, -g[GAINS.vel_max_down], g[GAINS.vel_max_up])
    # 2. velocity PID, D on the measured acceleration
    dvx, dvy, dvz = filtered_derivative(x, X_DERIVATIVE, velocity, g[GAINS.alpha], dt, integrate)
    ex, ey, ez = vx - velocity[0], vy - velocity[1], vz - velocity[2]
    ax = ref_acceleration[0] + g[GAINS.vel_p] * ex + x[X_INT] - g[GAINS.vel_d] * dvx
    ay = ref_acceleration[1] + g[GAINS.vel_p + 1] * ey + x[X_INT + 1] - g[GAINS.vel_d + 1] * dvy
    az = ref_acceleration[2] + g[GAINS.vel_p + 2] * ez + x[X_INT + 2] - g[GAINS.vel_d + 2] * dvz
    # 3. thrust vector
    tx, ty, tz, tilt_limited, thrust_limited = thrust_setpoint(g, ax, ay, az)
    thr_min, thr_max = g[GAINS.thr_min], g[GAINS.thr_max]
    # 5a. vertical anti-windup: no integration further into a thrust limit
    if (tz <= thr_min and ez <= 0.0) or (tz >= thr_max and ez >= 0.0):
        ez = 0.0
    # 4. saturation, vertical first with a horizontal margin
    horizontal = math.sqrt(tx * tx + ty * ty)
    allocated = horizontal if horizontal < g[GAINS.thr_xy_margin] else g[GAINS.thr_xy_margin]
    tz_max = math.sqrt(thr_max * thr_max - allocated * allocated)
    if tz > tz_max:
        tz, thrust_limited = tz_max, 1.0
    left = thr_max * thr_max - tz * tz
    horizontal_max = math.sqrt(left) if left > 0.0 else 0.0
    if horizontal > horizontal_max:
        tx, ty, thrust_limited = tx / horizontal * horizontal_max, ty / horizontal * horizontal_max, 1.0
    # 5b. horizontal tracking anti-reset-windup on what the saturated thrust gives
    to_acceleration = g[GAINS.gravity] / g[GAINS.hover]
    produced_x, produced_y = tx * to_acceleration, ty * to_acceleration
    if ax * ax + ay * ay > produced_x * produced_x + produced_y * produced_y:
        arw = 2.0 / g[GAINS.vel_p]
        ex -= arw * (ax - produced_x)
        ey -= arw * (ay - produced_y)
    if integrate:
        x[X_INT] += ex * g[GAINS.vel_i] * dt
        x[X_INT + 1] += ey * g[GAINS.vel_i + 1] * dt
        x[X_INT + 2] = clip(x[X_INT + 2] + ez * g[GAINS.vel_i + 2] * dt, -g[GAINS.gravity], g[GAINS.gravity])
    # 6. attitude setpoint and thrust
    collective = math.sqrt(tx * tx + ty * ty + tz * tz)
    roll_ref, pitch_ref = roll_pitch_from_body_z(tx / collective, ty / collective, tz / collective, ref_yaw)
    return collective * g[GAINS.thrust_max], roll_ref, pitch_ref, ax, ay, az, thrust_limited, tilt_limited


TUNABLE_GAINS = (
    Tunable("mpc_xy_p", "MPC_XY_P", 0.0, 2.0, "1/s", "horizontal position P gain"),
    Tunable("mpc_z_p", "MPC_Z_P", 0.1, 1.5, "1/s", "vertical position P gain"),
    Tunable("mpc_xy_vel_p_acc", "MPC_XY_VEL_P_ACC", 1.2, 5.0, "1/s", "horizontal velocity P gain"),
    Tunable("mpc_xy_vel_i_acc", "MPC_XY_VEL_I_ACC", 0.0, 60.0, "1/s^2", "horizontal velocity I gain"),
    Tunable("mpc_xy_vel_d_acc", "MPC_XY_VEL_D_ACC", 0.1, 2.0, "s", "horizontal velocity D gain (on v')"),
    Tunable("mpc_z_vel_p_acc", "MPC_Z_VEL_P_ACC", 2.0, 15.0, "1/s", "vertical velocity P gain"),
    Tunable("mpc_z_vel_i_acc", "MPC_Z_VEL_I_ACC", 0.2, 3.0, "1/s^2", "vertical velocity I gain"),
    Tunable("mpc_z_vel_d_acc", "MPC_Z_VEL_D_ACC", 0.0, 2.0, "s", "vertical velocity D gain (on v')"),
    Tunable("mpc_veld_lp", "MPC_VELD_LP", 0.0, 50.0, "Hz", "velocity derivative low-pass cutoff (0: none)"),
    Tunable("mpc_acc_decouple", "MPC_ACC_DECOUPLE", 0, 1, "", "tilt from the horizontal acceleration alone",
            switch=True),
)  # fmt: skip


@dataclass(frozen=True)
class Px4PositionGains:
    """PX4's position and velocity gains (field = lower-case parameter name, PX4's units) and the
    law's limits (config keys only)."""

    law: str
    mpc_xy_p: float
    mpc_z_p: float
    mpc_xy_vel_p_acc: float
    mpc_xy_vel_i_acc: float
    mpc_xy_vel_d_acc: float
    mpc_z_vel_p_acc: float
    mpc_z_vel_i_acc: float
    mpc_z_vel_d_acc: float
    mpc_veld_lp: float
    mpc_acc_decouple: bool
    velocity_max_xy_m_s: float
    velocity_max_up_m_s: float
    velocity_max_down_m_s: float
    thrust_min: float  # normalised (1 = U1_max): PX4's MPC_THR_MIN
    thrust_max: float  # MPC_THR_MAX
    thrust_xy_margin: float  # MPC_THR_XY_MARG


@register(TRANSLATIONAL)
class Px4Position(TunableLaw):
    NAME = "px4_position"
    STATE = ("vel_int_x", "vel_int_y", "vel_int_z", *derivative_names("vel"))
    GAINS, TUNABLE = Px4PositionGains, TUNABLE_GAINS
    step = staticmethod(step)

    @classmethod
    def settings(cls, section: Section) -> dict[str, float]:
        """The limits (config keys, not parameters)."""
        limits = {
            "velocity_max_xy_m_s": section.number("velocity_max_xy_m_s", lo=0.1, hi=20.0, unit="m/s"),
            "velocity_max_up_m_s": section.number("velocity_max_up_m_s", lo=0.1, hi=8.0, unit="m/s"),
            "velocity_max_down_m_s": section.number("velocity_max_down_m_s", lo=0.1, hi=4.0, unit="m/s"),
            "thrust_min": section.number("thrust_min", lo=0.001, hi=0.5),
            "thrust_max": section.number("thrust_max", lo=0.05, hi=1.0),
            "thrust_xy_margin": section.number("thrust_xy_margin", lo=0.0, hi=0.5),
        }
        if limits["thrust_max"] <= limits["thrust_min"]:
            allowed = f"> thrust_min ({limits['thrust_min']:g})"
            raise section.error("thrust_max", limits["thrust_max"], allowed)
        return limits

    @staticmethod
    def pack(gains: Px4PositionGains, context: LawContext) -> tuple[float, ...]:
        """The gains array; the hover thrust is ``m g / U1_max`` (must lie below ``thrust_max``)."""
        hover = context.mass_kg * context.gravity_m_s2 / context.thrust_max_n
        if hover >= gains.thrust_max:
            raise ValueError(f"thrust_max {gains.thrust_max:g} is not above the hover thrust m g / U1_max = "
                             f"{hover:.3g}")  # fmt: skip
        k = gains
        return values(
            GAINS, pos_p=(k.mpc_xy_p, k.mpc_xy_p, k.mpc_z_p),
            vel_p=(k.mpc_xy_vel_p_acc, k.mpc_xy_vel_p_acc, k.mpc_z_vel_p_acc),
            vel_i=(k.mpc_xy_vel_i_acc, k.mpc_xy_vel_i_acc, k.mpc_z_vel_i_acc),
            vel_d=(k.mpc_xy_vel_d_acc, k.mpc_xy_vel_d_acc, k.mpc_z_vel_d_acc),
            alpha=low_pass_alpha(k.mpc_veld_lp, context.dt_s), decouple=1.0 if k.mpc_acc_decouple else 0.0,
            vel_max_xy=k.velocity_max_xy_m_s, vel_max_up=k.velocity_max_up_m_s,
            vel_max_down=k.velocity_max_down_m_s, hover=hover, thr_min=k.thrust_min, thr_max=k.thrust_max,
            thr_xy_margin=k.thrust_xy_margin, thrust_max=context.thrust_max_n, gravity=context.gravity_m_s2,
            tilt_max=context.tilt_max_rad,
        )  # fmt: skip

