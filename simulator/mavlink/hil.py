"""The simulator's edge of the HIL link: truth and sensor readings -> one lockstep datagram.

Frames and units: everything arrives in the paper's frames (z up, body front-left-up) and SI;
signs flip only through :mod:`quadcommon.frames` (NED world, FRD body on the wire) and the
scaling to MAVLink's integers (mm, cm/s, mG, 1e-7 deg) happens here and nowhere else.

One datagram per control period (see :mod:`quadcommon.wire`), all messages with the same
``time_usec`` (simulation time, µs):

* ``HIL_SENSOR``: specific force (m/s^2, FRD; -g on z at rest), body rates (rad/s, FRD),
  magnetic field (gauss, FRD), ``abs_pressure`` (hPa, ISA), ``diff_pressure`` 0 (no airspeed
  sensor), ``pressure_alt`` (m AMSL), ``temperature`` (deg C); ``fields_updated`` bits 0-12
  (accel, gyro, mag, abs/diff pressure, pressure altitude, temperature): all set (0x1FFF) when
  every sensor sampled this frame, as PX4's Gazebo bridge sends them; the magnetometer bits (6-8)
  and the barometer bits (9, 11, 12) are cleared in frames where that sensor holds its last
  sample (its rate below the frame rate), ``id`` 0.
* ``HIL_STATE_QUATERNION`` (ground truth): attitude quaternion NED/FRD, body rates FRD,
  lat/lon (1e-7 deg) and alt (mm AMSL) of O from the local NED position about the configured
  home (:func:`quadcommon.frames.ned_to_geodetic`), velocity (cm/s, NED), specific force (mG, FRD,
  as an accelerometer reads it), indicated = true airspeed = |v - wind| (cm/s).
* ``ODOMETRY`` (ground truth, float32, millimetre-exact near home): ``frame_id =
  MAV_FRAME_LOCAL_NED`` for the pose (x, y, z NED about home, q NED/FRD) and **``child_frame_id =
  MAV_FRAME_LOCAL_NED``** so that vx, vy, vz are the world NED velocity (MAVLink defines the twist
  in ``child_frame_id``; a world-frame twist is exact without a rotation on either side); the
  angular rates are body FRD (the only frame in which MAVLink carries rates). Covariances unknown
  (first element NaN), ``estimator_type = MAV_ESTIMATOR_TYPE_MOCAP``, ``quality = 100``.
* ``HIL_GPS`` (when a fix is delivered): the reading's fix type (3D, or 1 "no fix" in an
  outage), lat/lon/alt as above but from the (noisy) GPS
  reading, eph/epv in cm (PX4 reads them as cm), ground speed and NED velocity (cm/s), course
  over ground (cdeg, [0, 36000)), satellites, ``id`` 0, ``yaw`` 0 (no heading from GPS).

Integer fields are clamped to their wire range so that a wild state cannot crash the encoder.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from pymavlink.dialects.v20 import common as mavlink

from quadcommon import frames, wire
from quadcommon.mavlink_fast import DecodeError, FastDecoder, split_frames

from ..dynamics.plant import TruthState
from ..sensors.models import GpsReading, SensorReadings

Vector3 = tuple[float, float, float]

STANDARD_GRAVITY_M_S2 = 9.80665  # 1 G for the mG fields of HIL_STATE_QUATERNION
FIELDS_UPDATED_ALL = 0x1FFF  # HIL_SENSOR_UPDATED_{X,Y,Z}{ACC,GYRO,MAG}, ABS/DIFF_PRESSURE, PRESSURE_ALT, TEMP
FIELDS_MAG = 0x1C0  # bits 6-8
FIELDS_BARO = 0x1A00  # bits 9 (abs pressure), 11 (pressure altitude), 12 (temperature)
GPS_FIX_3D = 3
_UNKNOWN_COVARIANCE = [math.nan] + [0.0] * 20  # MAVLink: NaN first element = unknown
_ARMED = mavlink.MAV_MODE_FLAG_SAFETY_ARMED
_ID_CONTROLS = mavlink.MAVLINK_MSG_ID_HIL_ACTUATOR_CONTROLS


def _i16(x: float) -> int:
    return -32767 if x < -32767.0 else (32767 if x > 32767.0 else round(x))


def _u16(x: float) -> int:
    return 0 if x < 0.0 else (65534 if x > 65534.0 else round(x))


def _i32(x: float) -> int:
    return -2147483647 if x < -2147483647.0 else (2147483647 if x > 2147483647.0 else round(x))


class HilFrameEncoder:
    """Packs the lockstep datagram; the message objects are built once and refilled each frame."""

    def __init__(self, system_id: int, home: tuple[float, float, float]) -> None:
        self.home = home
        self.mav = mavlink.MAVLink(None, srcSystem=system_id, srcComponent=wire.SIMULATOR_COMPONENT_ID)
        z3 = (0.0, 0.0, 0.0)
        self._sensor = mavlink.MAVLink_hil_sensor_message(0, *z3, *z3, *z3, 0.0, 0.0, 0.0, 0.0, 0, 0)
        self._sensor.fields_updated = FIELDS_UPDATED_ALL
        self._state = mavlink.MAVLink_hil_state_quaternion_message(
            0, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0
        )
        self._odometry = mavlink.MAVLink_odometry_message(
            0,
            mavlink.MAV_FRAME_LOCAL_NED,
            mavlink.MAV_FRAME_LOCAL_NED,
            0.0, 0.0, 0.0,
            [1.0, 0.0, 0.0, 0.0],
            0.0, 0.0, 0.0,
            0.0, 0.0, 0.0,
            list(_UNKNOWN_COVARIANCE),
            list(_UNKNOWN_COVARIANCE),
            0,
            mavlink.MAV_ESTIMATOR_TYPE_MOCAP,
            100,
        )  # fmt: skip
        self._gps = mavlink.MAVLink_hil_gps_message(0, GPS_FIX_3D, 0, 0, 0, 100, 100, 0, 0, 0, 0, 0, 10, 0, 0)

    def _pack(self, message) -> bytes:
        mav = self.mav
        data = message.pack(mav)
        mav.seq = (mav.seq + 1) & 0xFF  # pack() does not advance it (only send() does)
        return data

    def encode(
        self,
        time_usec: int,
        truth: TruthState,
        readings: SensorReadings,
        wind_world_m_s: Vector3 = (0.0, 0.0, 0.0),
        gps: GpsReading | None = None,
    ) -> bytes:
        """One datagram: HIL_SENSOR, HIL_STATE_QUATERNION, ODOMETRY (+ HIL_GPS when ``gps``)."""
        to_ned = frames.vector_to_ned
        q_ned = list(frames.quaternion_to_ned(truth.quaternion))
        rates_frd = to_ned(truth.body_rates_rad_s)
        pos_ned = to_ned(truth.position_m)
        vel_ned = to_ned(truth.velocity_m_s)

        s = self._sensor
        s.time_usec = time_usec
        updated = FIELDS_UPDATED_ALL
        if not readings.mag_fresh:
            updated &= ~FIELDS_MAG
        if not readings.baro_fresh:
            updated &= ~FIELDS_BARO
        s.fields_updated = updated
        s.xacc, s.yacc, s.zacc = to_ned(readings.imu.specific_force_m_s2)
        s.xgyro, s.ygyro, s.zgyro = to_ned(readings.imu.angular_rate_rad_s)
        s.xmag, s.ymag, s.zmag = to_ned(readings.magnetic_field_gauss)
        baro = readings.baro
        s.abs_pressure = baro.pressure_hpa
        s.pressure_alt = baro.pressure_altitude_m
        s.temperature = baro.temperature_c

        lat, lon, alt = frames.ned_to_geodetic(pos_ned[0], pos_ned[1], pos_ned[2], self.home)
        f_frd = to_ned(truth.specific_force_body_m_s2)
        to_mg = 1000.0 / STANDARD_GRAVITY_M_S2
        wx, wy, wz = wind_world_m_s
        v = truth.velocity_m_s
        airspeed_cm_s = _u16(100.0 * math.sqrt((v[0] - wx) ** 2 + (v[1] - wy) ** 2 + (v[2] - wz) ** 2))
        h = self._state
        h.time_usec = time_usec
        h.attitude_quaternion = q_ned
        h.rollspeed, h.pitchspeed, h.yawspeed = rates_frd
        h.lat, h.lon, h.alt = _i32(lat * 1e7), _i32(lon * 1e7), _i32(alt * 1000.0)
        h.vx, h.vy, h.vz = _i16(vel_ned[0] * 100.0), _i16(vel_ned[1] * 100.0), _i16(vel_ned[2] * 100.0)
        h.ind_airspeed = h.true_airspeed = airspeed_cm_s
        h.xacc, h.yacc, h.zacc = _i16(f_frd[0] * to_mg), _i16(f_frd[1] * to_mg), _i16(f_frd[2] * to_mg)

        o = self._odometry
        o.time_usec = time_usec
        o.x, o.y, o.z = pos_ned
        o.q = q_ned
        o.vx, o.vy, o.vz = vel_ned
        o.rollspeed, o.pitchspeed, o.yawspeed = rates_frd

        datagram = self._pack(s) + self._pack(h) + self._pack(o)
        if gps is not None:
            datagram += self._pack(self._fill_gps(time_usec, gps))
        return datagram

    def _fill_gps(self, time_usec: int, reading: GpsReading):
        p_ned = frames.vector_to_ned(reading.position_m)
        v_ned = frames.vector_to_ned(reading.velocity_m_s)
        lat, lon, alt = frames.ned_to_geodetic(p_ned[0], p_ned[1], p_ned[2], self.home)
        g = self._gps
        g.time_usec = time_usec
        g.fix_type = reading.fix_type
        g.lat, g.lon, g.alt = _i32(lat * 1e7), _i32(lon * 1e7), _i32(alt * 1000.0)
        g.eph, g.epv = _u16(reading.eph_m * 100.0), _u16(reading.epv_m * 100.0)
        g.vel = _u16(100.0 * math.hypot(v_ned[0], v_ned[1]))
        g.vn, g.ve, g.vd = _i16(v_ned[0] * 100.0), _i16(v_ned[1] * 100.0), _i16(v_ned[2] * 100.0)
        # Course over ground, 0 = north, clockwise (NED), in [0, 36000) cdeg.
        g.cog = round(math.degrees(math.atan2(v_ned[1], v_ned[0])) * 100.0) % 36000
        g.satellites_visible = reading.satellites_visible
        return g


class ActuatorAnswer(NamedTuple):
    """One decoded ``HIL_ACTUATOR_CONTROLS``."""

    time_usec: int
    controls: tuple[float, float, float, float]  # normalised, see quadcommon.wire
    armed: bool  # MAV_MODE_FLAG_SAFETY_ARMED in mode
    lockstep: bool  # flags bit 0
    wrench: bool  # flags bit 1: controls are a normalised wrench, else rotor speeds


class ActuatorDecoder:
    """Finds the ``HIL_ACTUATOR_CONTROLS`` in a datagram (anything else is ignored).

    Decoded with :class:`quadcommon.mavlink_fast.FastDecoder` (CRC checked): it is on the lockstep
    critical path (2.9 µs against 11 µs through pymavlink's parser, measured).
    """

    def __init__(self) -> None:
        self.decoder = FastDecoder(mavlink.MAVLink_hil_actuator_controls_message)
        where = self.decoder.slices
        self._time, self._controls = where["time_usec"], where["controls"]
        self._mode, self._flags = where["mode"], where["flags"]

    def decode(self, datagram: bytes) -> ActuatorAnswer | None:
        """The last actuator message in ``datagram``, or None when it holds none."""
        answer = None
        for msg_id, frame in split_frames(datagram):
            if msg_id != _ID_CONTROLS:
                continue
            try:
                v = self.decoder.unpack(frame)
            except DecodeError:  # a malformed frame must never stop the simulator
                continue
            c = v[self._controls]
            flags = v[self._flags]
            answer = ActuatorAnswer(
                v[self._time],
                (c[0], c[1], c[2], c[3]),
                bool(v[self._mode] & _ARMED),
                bool(flags & wire.HIL_FLAG_LOCKSTEP),
                bool(flags & wire.HIL_FLAG_WRENCH),
            )
        return answer
