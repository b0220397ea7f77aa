"""The autopilot's edge of the HIL link: frames in, actuator controls out (NED <-> paper here).

A lockstep frame is one datagram with HIL_SENSOR, HIL_STATE_QUATERNION, ODOMETRY and sometimes
HIL_GPS, all stamped with the same ``time_usec`` (see :mod:`quadcommon.wire`). The state the
controllers see comes from ODOMETRY (float32 local NED, millimetre-exact) or, on request, from
HIL_STATE_QUATERNION (position quantised to 1e-7 deg ~ 1 cm, velocity to 1 cm/s).
"""

from __future__ import annotations

from typing import NamedTuple

from quadcommon import frames, wire
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


def split_frames(datagram: bytes) -> list[tuple[int, bytes]]:
    """``(msgid, frame bytes)`` of each MAVLink 2 frame in a datagram, without decoding.

    MAVLink 2 header: STX 0xFD, payload length, incompat flags (bit 0: signed, +13 bytes),
    compat flags, seq, sysid, compid, 24-bit message id; then payload and a 2-byte CRC. Splitting
    first lets the autopilot decode only the messages it uses (decoding is most of a frame's cost
    here: ~10 us per message); anything that is not MAVLink 2 ends the split.
    """
    out = []
    i, n = 0, len(datagram)
    while i + 12 <= n and datagram[i] == 0xFD:
        total = 12 + datagram[i + 1] + (13 if datagram[i + 2] & 1 else 0)
        out.append((datagram[i + 7] | datagram[i + 8] << 8 | datagram[i + 9] << 16, datagram[i : i + total]))
        i += total
    return out


def decode_frame(
    datagram: bytes, parser, home: tuple[float, float, float], use_odometry: bool = True
) -> Frame | None:
    """The lockstep frame in one datagram, or None if it holds no state (e.g. a heartbeat).

    Decodes (with pymavlink, CRC checked) only the state message it needs: ODOMETRY, or
    HIL_STATE_QUATERNION when asked to or when there is no ODOMETRY.
    """
    parts = dict(split_frames(datagram))
    raw = parts.get(_ID_ODOMETRY) if use_odometry else None
    if raw is not None:
        msg = parser.decode(bytearray(raw))
        return Frame(msg.time_usec, state_from_odometry(msg), None, None)
    raw = parts.get(_ID_STATE) or parts.get(_ID_ODOMETRY)
    if raw is None:
        return None
    msg = parser.decode(bytearray(raw))
    if msg.id == _ID_ODOMETRY:
        return Frame(msg.time_usec, state_from_odometry(msg), None, None)
    return Frame(msg.time_usec, state_from_hil_state(msg, home), None, None)


def _attitude(q_ned, rates_frd):
    q = frames.quaternion_from_ned(q_ned)
    euler = euler_from_quaternion(*q)
    omega = frames.vector_from_ned(rates_frd)
    return q, euler, euler_rates_from_body_rates(euler[0], euler[1], omega)


def state_from_odometry(msg) -> StateEstimate:
    q, euler, euler_rates = _attitude(tuple(msg.q), (msg.rollspeed, msg.pitchspeed, msg.yawspeed))
    position = frames.vector_from_ned((msg.x, msg.y, msg.z))
    velocity_child = (msg.vx, msg.vy, msg.vz)
    if msg.child_frame_id in (mavlink.MAV_FRAME_BODY_FRD, mavlink.MAV_FRAME_BODY_NED):
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
    """HIL_ACTUATOR_CONTROLS for one lockstep answer."""

    def __init__(self, encoder: Encoder, wrench: bool) -> None:
        self.encoder = encoder
        self.flags = wire.HIL_FLAG_LOCKSTEP | (wire.HIL_FLAG_WRENCH if wrench else 0)
        self._zeros = [0.0] * 12

    def encode(self, time_usec: int, controls: tuple[float, ...], armed: bool) -> bytes:
        mode = _CUSTOM | (_ARMED if armed else 0)
        values = [*controls[:4], *self._zeros] if armed else [0.0] * 16
        msg = mavlink.MAVLink_hil_actuator_controls_message(time_usec, values, mode, self.flags)
        return self.encoder.pack(msg)
