"""The autopilot's edge of the HIL link: frames in, actuator controls out (NED <-> paper here).

A lockstep frame is one datagram with HIL_SENSOR, HIL_STATE_QUATERNION, ODOMETRY and sometimes
HIL_GPS, all stamped with the same ``time_usec`` (see :mod:`quadcommon.wire`). The state the
controllers see comes from ODOMETRY (float32 local NED, millimetre-exact) or, on request, from
HIL_STATE_QUATERNION (position quantised to 1e-7 deg ~ 1 cm, velocity to 1 cm/s).
"""

from __future__ import annotations

import struct
from typing import NamedTuple

from quadcommon import frames, wire
from quadcommon.mavlink_fast import DecodeError, FastDecoder, FastEncoder, split_frames
from quadcommon.rigid_body import (
    euler_from_quaternion,
    euler_rates_from_body_rates,
    rotation_from_quaternion,
)

from ..control.cascade import StateEstimate
from .codec import Encoder, mavlink

_ID_SENSOR = mavlink.MAVLINK_MSG_ID_HIL_SENSOR
_ID_STATE = mavlink.MAVLINK_MSG_ID_HIL_STATE_QUATERNION
_ID_ODOMETRY = mavlink.MAVLINK_MSG_ID_ODOMETRY
_ID_GPS = mavlink.MAVLINK_MSG_ID_HIL_GPS
_ARMED = mavlink.MAV_MODE_FLAG_SAFETY_ARMED
_CUSTOM = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED


class Frame(NamedTuple):
    time_usec: int
    state: StateEstimate  # paper frames
    sensor: object | None  # the HIL_SENSOR message, when decoded (not needed by the controllers yet)
    gps: object | None


_ODOMETRY = FastDecoder(mavlink.MAVLink_odometry_message)
# What the controllers need of ODOMETRY, in wire order: time_usec, x, y, z, q[4], vx, vy, vz, the
# three rates (the first 60 bytes), then child_frame_id after the two covariance arrays.
_ODOMETRY_STATE = struct.Struct("<Q13f")
_ODOMETRY_CHILD_FRAME = 8 + 4 * (13 + 21 + 21) + 1


class CorruptFrame(ValueError):
    """The state message of a lockstep frame failed its checksum or could not be decoded."""


def decode_frame(
    datagram: bytes, parser, home: tuple[float, float, float], use_odometry: bool = True
) -> Frame | None:
    """The lockstep frame in one datagram, or None if it holds no state (e.g. a heartbeat).

    Decodes (CRC checked) only the state message it needs: ODOMETRY (the fast decoder of
    :mod:`quadcommon.mavlink_fast`, it is on the lockstep critical path), or HIL_STATE_QUATERNION
    (pymavlink) when asked to or when there is no ODOMETRY. CorruptFrame if that message is bad.
    """
    try:
        return _decode_frame(datagram, parser, home, use_odometry)
    except (DecodeError, mavlink.MAVError, struct.error) as exc:
        raise CorruptFrame(str(exc)) from exc


def _decode_frame(datagram: bytes, parser, home, use_odometry: bool) -> Frame | None:
    parts = dict(split_frames(datagram))
    raw = parts.get(_ID_ODOMETRY)
    if raw is not None and (use_odometry or _ID_STATE not in parts):
        payload = _ODOMETRY.payload(raw)
        t, x, y, z, qw, qx, qy, qz, vx, vy, vz, p, q, r = _ODOMETRY_STATE.unpack_from(payload)
        state = state_from_odometry_fields(
            (qw, qx, qy, qz), (x, y, z), (vx, vy, vz), (p, q, r), payload[_ODOMETRY_CHILD_FRAME]
        )
        return Frame(t, state, None, None)
    raw = parts.get(_ID_STATE)
    if raw is None:
        return None
    msg = parser.decode(bytearray(raw))
    return Frame(msg.time_usec, state_from_hil_state(msg, home), None, None)


def _attitude(q_ned, rates_frd):
    q = frames.quaternion_from_ned(q_ned)
    euler = euler_from_quaternion(*q)
    omega = frames.vector_from_ned(rates_frd)
    return q, euler, euler_rates_from_body_rates(euler[0], euler[1], omega)


def state_from_odometry(msg) -> StateEstimate:
    """The state in an ODOMETRY message object (pymavlink)."""
    return state_from_odometry_fields(
        tuple(msg.q),
        (msg.x, msg.y, msg.z),
        (msg.vx, msg.vy, msg.vz),
        (msg.rollspeed, msg.pitchspeed, msg.yawspeed),
        msg.child_frame_id,
    )


def state_from_odometry_fields(
    q_ned, position_ned, velocity_child, rates_frd, child_frame_id
) -> StateEstimate:
    """ODOMETRY fields (NED pose, twist in ``child_frame_id``, FRD rates) -> paper frames."""
    q, euler, euler_rates = _attitude(tuple(q_ned), rates_frd)
    position = frames.vector_from_ned(position_ned)
    if child_frame_id in (mavlink.MAV_FRAME_BODY_FRD, mavlink.MAV_FRAME_BODY_NED):
        v_body = frames.vector_from_ned(velocity_child)
        R = rotation_from_quaternion(*q)
        velocity = tuple(R[i][0] * v_body[0] + R[i][1] * v_body[1] + R[i][2] * v_body[2] for i in range(3))
    else:
        velocity = frames.vector_from_ned(velocity_child)
    return StateEstimate(position, velocity, euler, euler_rates)  # type: ignore[arg-type]


def state_from_hil_state(msg, home: tuple[float, float, float]) -> StateEstimate:
    q, euler, euler_rates = _attitude(
        tuple(msg.attitude_quaternion), (msg.rollspeed, msg.pitchspeed, msg.yawspeed)
    )
    ned = frames.geodetic_to_ned(msg.lat * 1e-7, msg.lon * 1e-7, msg.alt * 1e-3, home)
    position = frames.vector_from_ned(ned)
    velocity = frames.vector_from_ned((msg.vx * 0.01, msg.vy * 0.01, msg.vz * 0.01))
    return StateEstimate(position, velocity, euler, euler_rates)


class ActuatorEncoder:
    """HIL_ACTUATOR_CONTROLS for one lockstep answer (a FastEncoder: on the critical path), with
    the sequence numbers of the autopilot's one encoder."""

    def __init__(self, encoder: Encoder, wrench: bool) -> None:
        mav = encoder.mav
        self.encoder = encoder
        message = mavlink.MAVLink_hil_actuator_controls_message
        self._fast = FastEncoder(message, mav.srcSystem, mav.srcComponent)
        slices = self._fast.slices
        self._time, self._controls, self._mode = slices["time_usec"], slices["controls"], slices["mode"]
        self._fast.values[slices["flags"]] = wire.HIL_FLAG_LOCKSTEP | (wire.HIL_FLAG_WRENCH if wrench else 0)
        self._zeros = [0.0] * 16

    def encode(self, time_usec: int, controls: tuple[float, ...], armed: bool) -> bytes:
        v = self._fast.values
        v[self._time] = time_usec
        v[self._mode] = _CUSTOM | (_ARMED if armed else 0)
        v[self._controls] = [*controls[:4], *self._zeros[4:]] if armed else self._zeros
        mav = self.encoder.mav
        data = self._fast.frame(mav.seq)
        mav.seq = (mav.seq + 1) % 256
        return data
