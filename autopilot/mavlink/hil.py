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
    sensor: object | None  # the HIL_SENSOR message (pymavlink object) if present
    gps: object | None


def decode_frame(messages: list, home: tuple[float, float, float], use_odometry: bool = True) -> Frame | None:
    """The frame in ``messages`` (parsed from one datagram), or None if it holds no state."""
    odometry = hil_state = sensor = gps = None
    for msg in messages:
        mid = msg.id
        if mid == _ID_ODOMETRY:
            odometry = msg
        elif mid == _ID_STATE:
            hil_state = msg
        elif mid == _ID_SENSOR:
            sensor = msg
        elif mid == _ID_GPS:
            gps = msg
    if odometry is not None and (use_odometry or hil_state is None):
        return Frame(odometry.time_usec, state_from_odometry(odometry), sensor, gps)
    if hil_state is not None:
        return Frame(hil_state.time_usec, state_from_hil_state(hil_state, home), sensor, gps)
    return None


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
