"""PX4's multicopter attitude and rate controllers (``mc_att_control``'s AttitudeControl and
``lib/rate_control``'s RateControl), the rotational half of the ``px4_pid`` cascade, on this
vehicle's physical torque.

Attitude (quaternion P with yaw weight), from the attitude ``q`` and its setpoint ``q_d`` (the
ZYX quaternions of eta and eta_d):

1. the reduced setpoint ``q_red``: the shortest rotation turning the current body z axis onto the
   desired one (world frame), applied to ``q``: the thrust direction corrected first, no yaw;
2. the yaw left between ``q_red`` and ``q_d`` is scaled by MC_YAW_WEIGHT:
   ``q_d' = q_red (cos(w acos(q_mix,w)), 0, 0, sin(w asin(q_mix,z)))``, ``q_mix = q_red^-1 q_d``;
3. ``omega_sp = K (2 Im(q^-1 q_d'))`` with K = (MC_ROLL_P, MC_PITCH_P, MC_YAW_P / MC_YAW_WEIGHT)
   (the division gives small yaw errors the gain MC_YAW_P), plus the yaw-rate feed-forward
   ``R^T e3 psi_d'`` (the reference's yaw rate about the world z, in body axes), each axis then
   clipped to MC_ROLLRATE_MAX, MC_PITCHRATE_MAX, MC_YAWRATE_MAX.

Rate (PID, D on the rate's derivative), per body axis with ``e = omega_sp - omega``:
``u = K P e + i - K D omega' + FF omega_sp`` (MC_*RATE_P, _I, _D, _FF, _K). ``omega'`` is the
measured body rate differentiated over one step and low-passed at IMU_DGYRO_CUTOFF (PX4 derives
its angular acceleration the same way from the gyro). The integral ``i' = f K I e`` with PX4's
i-factor ``f = max(0, 1 - (e / 400 deg/s)^2)`` (less integration on large rate errors), clamped to
the integrator limits MC_RR_INT_LIM, MC_PR_INT_LIM, MC_YR_INT_LIM, and frozen in the direction of
a saturated output (PX4 learns that from its control allocator; this law does not see the
actuators, so it takes an output at or beyond the actuators' limit, ``|u| >= 1``, as saturated:
exact under ``actuation = "wrench"``, an approximation under "rotors").

Normalised to physical: PX4's torque ``u`` is normalised, 1 = the vehicle's largest torque on that
axis; here ``tau_i = u_i * tau_max_i`` with the actuators' ``torque_max_n_m`` (LawContext), so
MC_ROLLRATE_P = 0.15 is 0.15 * 1.5 = 0.225 N m per rad/s on the paper's vehicle. PX4's low pass
of the yaw torque (MC_YAW_TQ_CUTOFF) and its attitude reference model (MC_REF_*, off by default)
are not modelled. Rates from the command filter are not used (``px4_pid`` passes the roll/pitch
references through, as PX4 has no such filter); the reference's yaw rate is.

The autotune's input: three entries of the gains array (``GAINS.autotune_rate``, rad/s per body axis,
zero as packed) are added to the rate setpoint after its limits, as mc_att_control adds the rate
setpoint PX4's autotune publishes; ``quadsitl tune`` (:mod:`sitl.tune`) writes its excitation
there while it identifies an axis.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from quadcommon.kernel import kernel
from quadcommon.layout import Field, layout, values
from quadcommon.numerics import clip, clip_symmetric, derivative_names, filtered_derivative, low_pass_alpha
from quadcommon.rigid_body import (
    cross,
    quaternion_conjugate,
    quaternion_from_euler,
    quaternion_multiply,
    quaternion_normalised,
    rotation_from_quaternion,
)

from ..registry import ROTATIONAL, LawContext, register
from ..tunable import Tunable, TunableLaw

# Gains array, per body axis (roll, pitch, yaw) from each offset: attitude P (yaw divided by the
# yaw weight), rate limits (rad/s), rate P, I, D (times K), rate FF, integrator limits, the actuators'
# torque limits (N m); then the yaw weight, the rate derivative's low-pass weight and the autotune's
# rate setpoint (rad/s per body axis: zero except while sitl.autotune excites an axis).
GAINS = layout("Px4AttitudeGains", (
    Field("att_p", 3),
    Field("rate_max", 3),
    Field("rate_p", 3),
    Field("rate_i", 3),
    Field("rate_d", 3),
    Field("rate_ff", 3),
    Field("int_lim", 3),
    Field("torque_max", 3),
    Field("yaw_weight"),
    Field("alpha"),
    Field("autotune_rate", 3),
))  # fmt: skip
# State: the rate integrals (normalised torque), then the rate derivative's filter.
X_INT, X_DERIVATIVE = 0, 3
I_FACTOR_RATE = math.radians(400.0)  # rate error at which the i-factor reaches zero (rad/s)


@kernel
def shortest_arc(a, b):
    """The unit quaternion of the smallest rotation turning unit vector ``a`` onto ``b``; for
    opposite vectors a half turn about an axis normal to ``a``."""
    c = cross(a, b)
    w = 1.0 + a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
    if w < 1e-9 and c[0] * c[0] + c[1] * c[1] + c[2] * c[2] < 1e-18:
        # a half turn about the axis normal to a, off a's smallest component (as PX4 picks it)
        ax, ay, az = abs(a[0]), abs(a[1]), abs(a[2])
        if ax <= ay and ax <= az:
            c = cross(a, (1.0, 0.0, 0.0))
        elif ay <= az:
            c = cross(a, (0.0, 1.0, 0.0))
        else:
            c = cross(a, (0.0, 0.0, 1.0))
        w = 0.0
    return quaternion_normalised((w, c[0], c[1], c[2]))


@kernel
def canonical(q):
    """``q`` or ``-q``, the one with a non-negative scalar part (the same rotation)."""
    if q[0] < 0.0:
        return (-q[0], -q[1], -q[2], -q[3])
    return q


@kernel
def rate_setpoint(g, euler, eta_d, yaw_rate):
    """PX4's AttitudeControl::update: the body rate setpoint (rad/s) of the module's steps 1-3."""
    q = quaternion_from_euler(euler[0], euler[1], euler[2])
    qd = quaternion_from_euler(eta_d[0], eta_d[1], eta_d[2])
    R = rotation_from_quaternion(q[0], q[1], q[2], q[3])
    Rd = rotation_from_quaternion(qd[0], qd[1], qd[2], qd[3])
    q_red = shortest_arc((R[0][2], R[1][2], R[2][2]), (Rd[0][2], Rd[1][2], Rd[2][2]))
    if abs(q_red[1]) > 1.0 - 1e-5 or abs(q_red[2]) > 1.0 - 1e-5:
        q_red = qd  # body z axes opposite: the full setpoint decides (PX4's corner case)
    else:
        q_red = quaternion_multiply(q_red, q)
    q_mix = canonical(quaternion_multiply(quaternion_conjugate(q_red), qd))
    weight = g[GAINS.yaw_weight]
    w, z = clip(q_mix[0], -1.0, 1.0), clip(q_mix[3], -1.0, 1.0)
    q_yaw = (math.cos(weight * math.acos(w)), 0.0, 0.0, math.sin(weight * math.asin(z)))
    q_sp = quaternion_multiply(q_red, q_yaw)
    q_e = canonical(quaternion_multiply(quaternion_conjugate(q), q_sp))
    # world z in body axes (last row of R) times the reference's yaw rate: the yaw feed-forward
    r0 = 2.0 * q_e[1] * g[GAINS.att_p] + R[2][0] * yaw_rate
    r1 = 2.0 * q_e[2] * g[GAINS.att_p + 1] + R[2][1] * yaw_rate
    r2 = 2.0 * q_e[3] * g[GAINS.att_p + 2] + R[2][2] * yaw_rate
    # clipped to the rate limits, then the autotune's excitation added (as mc_att_control adds
    # autotune_attitude_control_status.rate_sp after AttitudeControl::update)
    return (clip_symmetric(r0, g[GAINS.rate_max]) + g[GAINS.autotune_rate],
            clip_symmetric(r1, g[GAINS.rate_max + 1]) + g[GAINS.autotune_rate + 1],
            clip_symmetric(r2, g[GAINS.rate_max + 2]) + g[GAINS.autotune_rate + 2])  # fmt: skip


@kernel
def rate_axis(g, x, i, rate_sp, rate, rate_dot, dt, integrate):
    """PX4's RateControl on body axis ``i``: the torque (N m); the integral advanced."""
    e = rate_sp - rate
    u = (
        g[GAINS.rate_p + i] * e
        + x[X_INT + i]
        - g[GAINS.rate_d + i] * rate_dot
        + g[GAINS.rate_ff + i] * rate_sp
    )
    if integrate:
        if u >= 1.0 and e > 0.0 or u <= -1.0 and e < 0.0:  # saturated: no integration further into the limit
            e = 0.0
        f = e / I_FACTOR_RATE
        f = 1.0 - f * f
        if f < 0.0:
            f = 0.0
        x[X_INT + i] = clip_symmetric(x[X_INT + i] + f * g[GAINS.rate_i + i] * e * dt, g[GAINS.int_lim + i])
    return u * g[GAINS.torque_max + i]


@kernel
def step(g, x, euler, euler_rates, body_rates, eta_d, eta_d_dot, eta_d_ddot, dt, integrate):
    """The rotational step of the registry's contract: the attitude P's rate setpoint, then the rate PID per
    body axis on the filtered rate derivative; the body torque (N m)."""
    s0, s1, s2 = rate_setpoint(g, euler, eta_d, eta_d_dot[2])
    d0, d1, d2 = filtered_derivative(x, X_DERIVATIVE, body_rates, g[GAINS.alpha], dt, integrate)
    return (rate_axis(g, x, 0, s0, body_rates[0], d0, dt, integrate),
            rate_axis(g, x, 1, s1, body_rates[1], d1, dt, integrate),
            rate_axis(g, x, 2, s2, body_rates[2], d2, dt, integrate))  # fmt: skip


# PX4's parameters, ranges as PX4 declares them; where PX4 gives no upper bound (the I and FF gains)
# the bound here is ours, and integrator limits stop at 1 (the largest normalised torque).
TUNABLE_GAINS = (
    Tunable("mc_roll_p", "MC_ROLL_P", 0.0, 12.0, "1/s", "roll attitude P gain (rad/s per rad)"),
    Tunable("mc_pitch_p", "MC_PITCH_P", 0.0, 12.0, "1/s", "pitch attitude P gain (rad/s per rad)"),
    Tunable("mc_yaw_p", "MC_YAW_P", 0.0, 5.0, "1/s", "yaw attitude P gain (rad/s per rad)"),
    Tunable("mc_yaw_weight", "MC_YAW_WEIGHT", 0.0, 1.0, "", "yaw weight against roll and pitch"),
    Tunable("mc_rollrate_max", "MC_ROLLRATE_MAX", 0.0, 1800.0, "deg/s", "roll rate limit"),
    Tunable("mc_pitchrate_max", "MC_PITCHRATE_MAX", 0.0, 1800.0, "deg/s", "pitch rate limit"),
    Tunable("mc_yawrate_max", "MC_YAWRATE_MAX", 0.0, 1800.0, "deg/s", "yaw rate limit"),
    Tunable("mc_rollrate_p", "MC_ROLLRATE_P", 0.01, 0.5, "", "roll rate P (normalised torque per rad/s)"),
    Tunable("mc_rollrate_i", "MC_ROLLRATE_I", 0.0, 10.0, "", "roll rate I gain"),
    Tunable("mc_rollrate_d", "MC_ROLLRATE_D", 0.0, 0.01, "", "roll rate D (on the angular acceleration)"),
    Tunable("mc_rollrate_ff", "MC_ROLLRATE_FF", 0.0, 1.0, "", "roll rate feed-forward"),
    Tunable("mc_rollrate_k", "MC_ROLLRATE_K", 0.01, 5.0, "", "roll rate controller gain (scales P, I, D)"),
    Tunable("mc_rr_int_lim", "MC_RR_INT_LIM", 0.0, 1.0, "", "roll rate integral limit (normalised torque)"),
    Tunable("mc_pitchrate_p", "MC_PITCHRATE_P", 0.01, 0.6, "", "pitch rate P (normalised torque per rad/s)"),
    Tunable("mc_pitchrate_i", "MC_PITCHRATE_I", 0.0, 10.0, "", "pitch rate I gain"),
    Tunable("mc_pitchrate_d", "MC_PITCHRATE_D", 0.0, 0.01, "", "pitch rate D (on the angular acceleration)"),
    Tunable("mc_pitchrate_ff", "MC_PITCHRATE_FF", 0.0, 1.0, "", "pitch rate feed-forward"),
    Tunable("mc_pitchrate_k", "MC_PITCHRATE_K", 0.01, 5.0, "", "pitch rate controller gain (scales P, I, D)"),
    Tunable("mc_pr_int_lim", "MC_PR_INT_LIM", 0.0, 1.0, "", "pitch rate integral limit (normalised torque)"),
    Tunable("mc_yawrate_p", "MC_YAWRATE_P", 0.0, 0.6, "", "yaw rate P (normalised torque per rad/s)"),
    Tunable("mc_yawrate_i", "MC_YAWRATE_I", 0.0, 10.0, "", "yaw rate I gain"),
    Tunable("mc_yawrate_d", "MC_YAWRATE_D", 0.0, 0.01, "", "yaw rate D (on the angular acceleration)"),
    Tunable("mc_yawrate_ff", "MC_YAWRATE_FF", 0.0, 1.0, "", "yaw rate feed-forward"),
    Tunable("mc_yawrate_k", "MC_YAWRATE_K", 0.01, 5.0, "", "yaw rate controller gain (scales P, I, D)"),
    Tunable("mc_yr_int_lim", "MC_YR_INT_LIM", 0.0, 1.0, "", "yaw rate integral limit (normalised torque)"),
    Tunable("imu_dgyro_cutoff", "IMU_DGYRO_CUTOFF", 0.0, 1000.0, "Hz",
            "low-pass cutoff of the rate derivative (D term input; 0: none)"),
)  # fmt: skip


@dataclass(frozen=True)
class Px4AttitudeGains:
    """PX4's attitude and rate gains (field = lower-case parameter name, PX4's units)."""

    law: str
    mc_roll_p: float
    mc_pitch_p: float
    mc_yaw_p: float
    mc_yaw_weight: float
    mc_rollrate_max: float
    mc_pitchrate_max: float
    mc_yawrate_max: float
    mc_rollrate_p: float
    mc_rollrate_i: float
    mc_rollrate_d: float
    mc_rollrate_ff: float
    mc_rollrate_k: float
    mc_rr_int_lim: float
    mc_pitchrate_p: float
    mc_pitchrate_i: float
    mc_pitchrate_d: float
    mc_pitchrate_ff: float
    mc_pitchrate_k: float
    mc_pr_int_lim: float
    mc_yawrate_p: float
    mc_yawrate_i: float
    mc_yawrate_d: float
    mc_yawrate_ff: float
    mc_yawrate_k: float
    mc_yr_int_lim: float
    imu_dgyro_cutoff: float


@register(ROTATIONAL)
class Px4Attitude(TunableLaw):
    NAME = "px4_attitude"
    STATE = ("rate_int_x", "rate_int_y", "rate_int_z", *derivative_names("rate"))
    GAINS, TUNABLE = Px4AttitudeGains, TUNABLE_GAINS
    step = staticmethod(step)

    @staticmethod
    def pack(gains: Px4AttitudeGains, context: LawContext) -> tuple[float, ...]:
        k = gains
        weight = k.mc_yaw_weight
        yaw_p = k.mc_yaw_p / weight if weight > 1e-4 else k.mc_yaw_p  # PX4's compensation of the weight
        rate_k = (k.mc_rollrate_k, k.mc_pitchrate_k, k.mc_yawrate_k)
        return values(
            GAINS, att_p=(k.mc_roll_p, k.mc_pitch_p, yaw_p),
            rate_max=[math.radians(v) for v in (k.mc_rollrate_max, k.mc_pitchrate_max, k.mc_yawrate_max)],
            rate_p=[rate_k[i] * v for i, v in enumerate((k.mc_rollrate_p, k.mc_pitchrate_p, k.mc_yawrate_p))],
            rate_i=[rate_k[i] * v for i, v in enumerate((k.mc_rollrate_i, k.mc_pitchrate_i, k.mc_yawrate_i))],
            rate_d=[rate_k[i] * v for i, v in enumerate((k.mc_rollrate_d, k.mc_pitchrate_d, k.mc_yawrate_d))],
            rate_ff=(k.mc_rollrate_ff, k.mc_pitchrate_ff, k.mc_yawrate_ff),
            int_lim=(k.mc_rr_int_lim, k.mc_pr_int_lim, k.mc_yr_int_lim),
            torque_max=context.torque_max_n_m, yaw_weight=weight,
            alpha=low_pass_alpha(k.imu_dgyro_cutoff, context.dt_s),
            autotune_rate=(0.0, 0.0, 0.0),  # the autotune's rate setpoint: none
        )  # fmt: skip
