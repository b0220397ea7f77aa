"""Offboard setpoints from the wire in the paper's frames (PX4 semantics).

SET_POSITION_TARGET_LOCAL_NED -> :class:`OffboardSetpoint` (:func:`decode_setpoint`);
SET_ATTITUDE_TARGET -> :class:`AttitudeSetpoint` (:func:`decode_attitude_target`).

SET_POSITION_TARGET_LOCAL_NED:

type_mask bits (POSITION_TARGET_TYPEMASK): 1/2/4 ignore x/y/z position, 8/16/32 velocity,
64/128/256 acceleration, 1024 yaw, 2048 yaw rate (512 force: refused). A group is used when any
of its axes is not ignored; ignored axes of a used position group keep the current reference,
of a velocity or acceleration group read as zero.

Frames: MAV_FRAME_LOCAL_NED (absolute), LOCAL_OFFSET_NED (position relative to the vehicle),
BODY_NED / BODY_FRD / BODY_OFFSET_NED (position offset, velocity and acceleration rotated by
the vehicle's yaw, as PX4 does). Other frames are refused with a reason.
"""

from __future__ import annotations

import math

from quadcommon import frames
from quadcommon.rigid_body import euler_from_quaternion

from ..guidance.offboard import AttitudeSetpoint, OffboardSetpoint
from .codec import mavlink

_POS, _VEL, _ACC = (1, 2, 4), (8, 16, 32), (64, 128, 256)
_FORCE, _YAW_IGNORE, _YAW_RATE_IGNORE = 512, 1024, 2048
_LOCAL = mavlink.MAV_FRAME_LOCAL_NED
_LOCAL_OFFSET = mavlink.MAV_FRAME_LOCAL_OFFSET_NED
_BODY = (mavlink.MAV_FRAME_BODY_NED, mavlink.MAV_FRAME_BODY_FRD, mavlink.MAV_FRAME_BODY_OFFSET_NED)

Vector3 = tuple[float, float, float]


def _group(mask: int, bits: tuple[int, int, int], values: Vector3, fill: Vector3) -> Vector3 | None:
    if all(mask & b for b in bits):
        return None
    return tuple(fill[i] if mask & bits[i] else values[i] for i in range(3))  # type: ignore[return-value]


def decode_setpoint(
    msg, t: float, position_now: Vector3, yaw_now: float, reference_position: Vector3
) -> tuple[OffboardSetpoint | None, str]:
    """(setpoint, "") or (None, reason). Positions etc. in the paper's frames, absolute; ``t`` is
    the simulation time of arrival (see :func:`sample_time` for the setpoint's own time)."""
    mask = msg.type_mask
    frame = msg.coordinate_frame
    if mask & _FORCE:
        return None, "force setpoints (type_mask bit 512) are not supported"
    if frame not in (_LOCAL, _LOCAL_OFFSET, *_BODY):
        return None, f"coordinate_frame {frame} not supported (use LOCAL_NED or BODY_NED)"
    values = [float(v) for v in (msg.x, msg.y, msg.z, msg.vx, msg.vy, msg.vz, msg.afx, msg.afy, msg.afz)]
    if any(not math.isfinite(v) for v in values):
        return None, "non-finite value in setpoint"
    pos_ned, vel_ned, acc_ned = tuple(values[0:3]), tuple(values[3:6]), tuple(values[6:9])

    # Rotate body-frame inputs by the vehicle's yaw (NED yaw = -psi).
    if frame in _BODY:
        yaw_ned = frames.yaw_to_ned(yaw_now)
        c, s = math.cos(yaw_ned), math.sin(yaw_ned)

        def rot(v):
            return (c * v[0] - s * v[1], s * v[0] + c * v[1], v[2])

        pos_ned, vel_ned, acc_ned = rot(pos_ned), rot(vel_ned), rot(acc_ned)

    position = None
    if not all(mask & b for b in _POS):
        if frame == _LOCAL:
            absolute = frames.vector_from_ned(pos_ned)
        else:
            offset = frames.vector_from_ned(pos_ned)
            absolute = tuple(p + o for p, o in zip(position_now, offset, strict=True))
        position = _group(mask, _POS, absolute, reference_position)  # type: ignore[arg-type]
    velocity = _group(mask, _VEL, frames.vector_from_ned(vel_ned), (0.0, 0.0, 0.0))
    acceleration = _group(mask, _ACC, frames.vector_from_ned(acc_ned), (0.0, 0.0, 0.0))
    yaw = None if mask & _YAW_IGNORE or not math.isfinite(msg.yaw) else frames.yaw_from_ned(msg.yaw)
    yaw_rate = (
        None
        if mask & _YAW_RATE_IGNORE or not math.isfinite(msg.yaw_rate)
        else frames.yaw_from_ned(msg.yaw_rate)
    )
    if position is None and velocity is None and acceleration is None and yaw is None and yaw_rate is None:
        return None, "type_mask ignores everything"
    return OffboardSetpoint(
        sample_time(msg.time_boot_ms, t), position, velocity, acceleration, yaw, yaw_rate
    ), ""


def sample_time(time_boot_ms: int, t: float) -> float:
    """When the setpoint was sampled: its ``time_boot_ms`` if that is our (simulation) clock.

    A trajectory streamed by a script that stamps each sample with the simulation time it belongs
    to is then extrapolated from the right instant, and the reference between samples is continuous
    (stamping on arrival instead puts a small step in p_d at every sample, which the high-gain
    cascade turns into torque chatter). Clients on another clock (MAVSDK stamps its own uptime)
    fall back to the arrival time ``t``.
    """
    stamped = time_boot_ms * 1e-3
    return stamped if t - 0.5 <= stamped <= t + 0.05 else t


# SET_ATTITUDE_TARGET type_mask (ATTITUDE_TARGET_TYPEMASK), as PX4's receiver reads it.
_ROLL_RATE_IGNORE, _PITCH_RATE_IGNORE, _YAW_RATE_IGNORE_ATT = 1, 2, 4
_THRUST_IGNORE, _ATTITUDE_IGNORE = 64, 128
QUATERNION_NORM_TOLERANCE = 0.1  # |q| within 1 +- this is normalised; beyond, refused


def decode_attitude_target(msg, t: float) -> tuple[AttitudeSetpoint | None, str]:
    """``SET_ATTITUDE_TARGET`` -> (setpoint, "") or (None, reason), as PX4's receiver reads it:
    the attitude ``q`` (NED/FRD, w x y z) unless ``type_mask`` bit 128 ignores it; otherwise the body
    rates when roll and pitch rates are both used (the yaw rate reads 0 when bit 4 ignores it);
    the collective thrust (0..1, clamped) unless bit 64 ignores it. Refused: a non-finite value in
    a used field, a quaternion whose norm is not within :data:`QUATERNION_NORM_TOLERANCE` of 1 (a
    near-unit one is normalised), a mask that leaves neither the attitude nor the body rates.
    (PX4 builds its setpoint from whatever arrives; refusing keeps a zero quaternion out of the
    attitude law.)"""
    mask = msg.type_mask
    thrust = None
    if not mask & _THRUST_IGNORE:
        value = float(msg.thrust)
        if not math.isfinite(value):
            return None, "non-finite thrust"
        thrust = min(max(value, 0.0), 1.0)
    if not mask & _ATTITUDE_IGNORE:
        q = tuple(float(v) for v in msg.q)
        if not all(math.isfinite(v) for v in q):
            return None, "non-finite attitude quaternion"
        norm = math.sqrt(sum(v * v for v in q))
        if abs(norm - 1.0) > QUATERNION_NORM_TOLERANCE:
            return None, f"attitude quaternion is not a unit quaternion (|q| = {norm:.3g})"
        w, x, y, z = frames.quaternion_from_ned(tuple(v / norm for v in q))  # type: ignore[arg-type]
        return AttitudeSetpoint(t, attitude=euler_from_quaternion(w, x, y, z), thrust=thrust), ""
    if mask & _ROLL_RATE_IGNORE or mask & _PITCH_RATE_IGNORE:
        return None, "type_mask ignores the attitude and the roll or pitch rate"
    yaw_rate = 0.0 if mask & _YAW_RATE_IGNORE_ATT else float(msg.body_yaw_rate)
    rates_frd = (float(msg.body_roll_rate), float(msg.body_pitch_rate), yaw_rate)
    if not all(math.isfinite(v) for v in rates_frd):
        return None, "non-finite body rate"
    return AttitudeSetpoint(t, body_rates=frames.vector_from_ned(rates_frd), thrust=thrust), ""
