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
  sample (its rate below the frame rate), the accelerometer bits (0-2) and the gyro bits (3-5)
  in frames where an injected failure stops it (:mod:`quadcommon.failures`), ``id`` 0.
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
* ``DEBUG_FLOAT_ARRAY`` ``DISTURB`` (when the core reports the disturbance, see
  :mod:`quadcommon.wire`): force (N, world NED) and torque on the Euler coordinates (N m, NED's
  Euler convention) in ``data[0:6]``, the rotors' health in ``data[6:14]`` (each rotor's
  effectiveness, then its FAILURE_TYPE, rotors 1-4 in the plant's order).
* ``BATTERY_STATUS`` (at the battery monitor's rate, :mod:`simulator.battery`): the pack's voltage
  in ``voltages[0]`` (mV, MAVLink's split above 65 534 mV), current in cA (-1: not measured),
  every other field "unknown" (see :mod:`quadcommon.wire`); a reading that is not a finite number
  goes out as the unknowns.
* ``HIL_GPS`` (when a fix is delivered): the reading's fix type (3D, or 1 "no fix" in an
  outage), lat/lon/alt as above but from the (noisy) GPS
  reading, eph/epv in cm (PX4 reads them as cm), ground speed and NED velocity (cm/s), course
  over ground (cdeg, [0, 36000)), satellites, ``id`` 0, ``yaw`` 0 (no heading from GPS).

Integer fields are clamped to their wire range so that a wild state cannot crash the encoder.
"""

from __future__ import annotations

import functools
import math
from typing import Any, NamedTuple

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from quadcommon import frames, wire
from quadcommon.config import SIM_BATTERY_PARAMETERS
from quadcommon.kernel import kernel, warmed
from quadcommon.mavlink_fast import DecodeError, FastDecoder, FastEncoder, split_frames
from quadcommon.wire import LockstepAnswer, sat_i16, sat_u16
from quadcommon.wire_values import (
    HIL_SENSOR_RECORD,
    HIL_STATE_RECORD,
    ODOMETRY_RECORD,
    entry,
    frame_records,
    gps_values,
    vision_values,
)

from ..battery import BatteryReading
from ..dynamics.plant import TruthState
from ..sensors.frame import DELIVERY
from ..sensors.models import GpsReading, SensorReadings, VisionReading

Vector3 = tuple[float, float, float]

FIELDS_UPDATED_ALL = 0x1FFF  # HIL_SENSOR_UPDATED_{X,Y,Z}{ACC,GYRO,MAG}, ABS/DIFF_PRESSURE, PRESSURE_ALT, TEMP
FIELDS_MAG = 0x1C0  # bits 6-8
FIELDS_BARO = 0x1A00  # bits 9 (abs pressure), 11 (pressure altitude), 12 (temperature)
FIELDS_ACCEL = 0x7  # bits 0-2
FIELDS_GYRO = 0x38  # bits 3-5
GPS_FIX_3D = 3
_UNKNOWN_COVARIANCE = [math.nan] + [0.0] * 20  # MAVLink: NaN first element = unknown
_ARMED = mavlink.MAV_MODE_FLAG_SAFETY_ARMED
UINT16_UNKNOWN = 65535
CELL_VOLTAGE_MAX_MV = 65534  # BATTERY_STATUS voltages[0]: above it, the rest goes to voltages[1]
_ID_CONTROLS = mavlink.MAVLINK_MSG_ID_HIL_ACTUATOR_CONTROLS
_ID_SENSOR = mavlink.MAVLINK_MSG_ID_HIL_SENSOR
_ID_STATE = mavlink.MAVLINK_MSG_ID_HIL_STATE_QUATERNION
_ID_ODOMETRY = mavlink.MAVLINK_MSG_ID_ODOMETRY


@kernel
def fields_updated(mag_fresh: bool, baro_fresh: bool, accel_fresh: bool, gyro_fresh: bool) -> int:
    """HIL_SENSOR's ``fields_updated``: every field's bit but those of a sensor that holds its last
    sample (the magnetometer and the barometer between their samples) or that a failure stops
    (the accelerometer, the gyro)."""
    updated = FIELDS_UPDATED_ALL
    if not mag_fresh:
        updated &= ~FIELDS_MAG
    if not baro_fresh:
        updated &= ~FIELDS_BARO
    if not accel_fresh:
        updated &= ~FIELDS_ACCEL
    if not gyro_fresh:
        updated &= ~FIELDS_GYRO
    return updated


@kernel
def delivery_records(sensor, state, odometry, time_usec: int, delivery, position: Vector3, velocity: Vector3,
                     quaternion, body_rates: Vector3, specific_force_body: Vector3, wind: Vector3,
                     home) -> bool:  # fmt: skip
    """:func:`~quadcommon.wire_values.frame_records` of a frame's sensor delivery
    (:data:`~simulator.sensors.frame.DELIVERY`): the IMU sample, the held magnetometer and
    barometer readings, HIL_SENSOR's :func:`fields_updated` from the delivery's flags."""
    d, at = delivery, DELIVERY
    updated = fields_updated(d[at.mag_fresh] != 0.0, d[at.baro_fresh] != 0.0, d[at.accel_fresh] != 0.0,
                             d[at.gyro_fresh] != 0.0)  # fmt: skip
    f, r, m = at.force, at.rate, at.held_mag
    return frame_records(
        sensor, state, odometry, time_usec, updated, position, velocity, quaternion, body_rates,
        specific_force_body, wind, home, (d[f], d[f + 1], d[f + 2]), (d[r], d[r + 1], d[r + 2]),
        (d[m], d[m + 1], d[m + 2]), d[at.held_baro_pressure], d[at.held_baro_altitude],
        d[at.held_baro_temperature],
    )  # fmt: skip


@functools.cache
def delivery_records_entry() -> Any:
    """:func:`delivery_records` as the simulator calls it every frame, warmed on scratch buffers
    (:func:`~quadcommon.kernel.warmed`, as :func:`quadcommon.wire_values.entry` makes the frame's
    other entries)."""
    z3 = (0.0, 0.0, 0.0)
    buffers = (np.zeros(record.itemsize, np.uint8) for record in (HIL_SENSOR_RECORD, HIL_STATE_RECORD,
                                                                   ODOMETRY_RECORD))  # fmt: skip
    quaternion = (1.0, 0.0, 0.0, 0.0)
    return warmed(delivery_records, *buffers, 0, np.zeros(DELIVERY.size), z3, z3, quaternion, z3, z3, z3, z3)


class HilFrameEncoder:
    """Packs the lockstep datagram: one :class:`~quadcommon.mavlink_fast.FastEncoder` per message
    (its framing). The three messages of every frame are byte buffers filled in one compiled call
    (:func:`~quadcommon.wire_values.frame_records`), the others flat field lists refilled when they
    are sent; the constant fields stay as the templates set them."""

    def __init__(self, system_id: int, home: tuple[float, float, float]) -> None:
        self.home = (float(home[0]), float(home[1]), float(home[2]))  # (as the compiled entries take it)
        self._frame_records = entry(frame_records)
        self._delivery_records = delivery_records_entry()
        self._vision_values, self._gps_values = entry(vision_values), entry(gps_values)
        self.seq = 0
        ids = (system_id, wire.SIMULATOR_COMPONENT_ID)
        z3 = (0.0, 0.0, 0.0)
        sensor = mavlink.MAVLink_hil_sensor_message(
            0, *z3, *z3, *z3, 0.0, 0.0, 0.0, 0.0, FIELDS_UPDATED_ALL, 0
        )
        self._sensor = FastEncoder(mavlink.MAVLink_hil_sensor_message, *ids, sensor)
        state = mavlink.MAVLink_hil_state_quaternion_message(
            0, [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0
        )
        self._state = FastEncoder(mavlink.MAVLink_hil_state_quaternion_message, *ids, state)
        odometry = mavlink.MAVLink_odometry_message(
            0, mavlink.MAV_FRAME_LOCAL_NED, mavlink.MAV_FRAME_LOCAL_NED, 0.0, 0.0, 0.0,
            [1.0, 0.0, 0.0, 0.0], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
            list(_UNKNOWN_COVARIANCE), list(_UNKNOWN_COVARIANCE), 0, mavlink.MAV_ESTIMATOR_TYPE_MOCAP, 100,
        )  # fmt: skip
        self._odometry = FastEncoder(mavlink.MAVLink_odometry_message, *ids, odometry)
        gps = mavlink.MAVLink_hil_gps_message(0, GPS_FIX_3D, 0, 0, 0, 100, 100, 0, 0, 0, 0, 0, 10, 0, 0)
        self._gps = FastEncoder(mavlink.MAVLink_hil_gps_message, *ids, gps)
        vision = mavlink.MAVLink_vision_position_estimate_message(0, *(0.0,) * 6, [0.0] * 21, 0)
        self._vision = FastEncoder(mavlink.MAVLink_vision_position_estimate_message, *ids, vision)
        self._v = _slots(self._vision, "usec", "x", "y", "z", "yaw")
        self._v_cov = self._vision.slices["covariance"]
        # The three messages of every frame as payload buffers, filled in compiled code (the constant
        # fields as the templates set them), in frame_records' order.
        self._buffers = tuple(encoder.buffer() for encoder in (self._sensor, self._state, self._odometry))
        self._g = _slots(self._gps, "time_usec", "lat", "lon", "alt", "eph", "epv", "vel", "vn", "ve", "vd",
                         "cog", "satellites_visible")  # fmt: skip
        self._g_fix = _slots(self._gps, "fix_type")[0]
        disturbance = mavlink.MAVLink_debug_float_array_message(0, wire.DISTURBANCE_NAME, 0, [0.0] * 58)
        self._disturbance = FastEncoder(mavlink.MAVLink_debug_float_array_message, *ids, disturbance)
        self._disturbance.values[self._disturbance.slices["name"]] = wire.DISTURBANCE_NAME
        self._d_time = _slots(self._disturbance, "time_usec")[0]
        self._d_data = self._disturbance.slices["data"]
        battery = mavlink.MAVLink_battery_status_message(
            0, mavlink.MAV_BATTERY_FUNCTION_ALL, mavlink.MAV_BATTERY_TYPE_LIPO, 32767, [UINT16_UNKNOWN] * 10,
            -1, -1, -1, -1, 0, mavlink.MAV_BATTERY_CHARGE_STATE_UNDEFINED, [0, 0, 0, 0], 0, 0,
        )  # fmt: skip
        self._battery = FastEncoder(mavlink.MAVLink_battery_status_message, *ids, battery)
        self._b_cells = self._battery.slices["voltages"].start
        self._b_current = _slots(self._battery, "current_battery")[0]
        every = (self._sensor, self._state, self._odometry, self._gps, self._vision, self._disturbance,
                 self._battery)  # fmt: skip
        self._encoders = {encoder.msg_id: encoder for encoder in every}

    def encode(self, *args: Any, **kw: Any) -> bytes:
        """One datagram: :meth:`datagram` of :meth:`payloads` (the same arguments)."""
        return self.datagram(self.payloads(*args, **kw))

    def datagram(self, payloads: dict[int, bytes]) -> bytes:
        """The frames of :meth:`payloads`, one after the other on this encoder's sequence."""
        out = b""
        encoders = self._encoders
        for msg_id, payload in payloads.items():
            out += encoders[msg_id].frame_of(payload, self.seq)
            self.seq = (self.seq + 1) & 0xFF
        return out

    def payloads(
        self,
        time_usec: int,
        truth: TruthState,
        readings: SensorReadings,
        wind_world_m_s: Vector3 = (0.0, 0.0, 0.0),
        gps: GpsReading | None = None,
        vision: VisionReading | None = None,
        disturbance: tuple[int, tuple[Vector3, Vector3, tuple[float, ...]]] | None = None,
        battery: BatteryReading | None = None,
    ) -> dict[int, bytes]:
        """One frame's messages by id, as payloads (:meth:`FastEncoder.payload`; :meth:`datagram`
        frames them): HIL_SENSOR, HIL_STATE_QUATERNION, ODOMETRY (+ HIL_GPS when ``gps``,
        + VISION_POSITION_ESTIMATE when ``vision``, + the ``DISTURB`` array when ``disturbance``:
        its sample time (µs) and (force (world), torque (Euler coordinates), the rotors' health) in
        the paper's frames, + BATTERY_STATUS when ``battery``)."""
        updated = fields_updated(readings.mag_fresh, readings.baro_fresh, readings.accel_fresh,
                                 readings.gyro_fresh)  # fmt: skip
        baro, imu = readings.baro, readings.imu
        sensor, state, odometry = self._buffers
        fits = self._frame_records(
            sensor, state, odometry, time_usec, updated, truth.position_m, truth.velocity_m_s,
            truth.quaternion, truth.body_rates_rad_s, truth.specific_force_body_m_s2, wind_world_m_s,
            self.home, imu.specific_force_m_s2, imu.angular_rate_rad_s, readings.magnetic_field_gauss,
            baro.pressure_hpa, baro.pressure_altitude_m, baro.temperature_c,
        )  # fmt: skip
        return self._with_the_others(fits, time_usec, gps, vision, disturbance, battery)

    def frame_payloads(
        self,
        time_usec: int,
        truth: TruthState,
        delivery: Any,
        wind_world_m_s: Vector3,
        gps: GpsReading | None,
        vision: VisionReading | None,
        disturbance: tuple[int, tuple[Vector3, Vector3, tuple[float, ...]]] | None,
        battery: BatteryReading | None,
    ) -> dict[int, bytes]:
        """:meth:`payloads` of a frame's sensor delivery as the sensor suite left it
        (:meth:`~simulator.sensors.models.SensorSuite.deliver`, the
        :data:`~simulator.sensors.frame.DELIVERY` layout), read in the same compiled call that
        fills the messages: the simulator's every frame."""
        sensor, state, odometry = self._buffers
        fits = self._delivery_records(
            sensor, state, odometry, time_usec, delivery, truth.position_m, truth.velocity_m_s,
            truth.quaternion, truth.body_rates_rad_s, truth.specific_force_body_m_s2, wind_world_m_s,
            self.home,
        )  # fmt: skip
        return self._with_the_others(fits, time_usec, gps, vision, disturbance, battery)

    def _with_the_others(
        self, fits: bool, time_usec: int, gps, vision, disturbance, battery
    ) -> dict[int, bytes]:
        """The three every-frame payloads just filled (``fits``: else OverflowError), then the
        messages this frame also carries."""
        if not fits:
            raise OverflowError("the state is past the range of the frame's float32 fields")
        sensor, state, odometry = self._buffers
        payloads = {
            _ID_SENSOR: sensor.tobytes(), _ID_STATE: state.tobytes(), _ID_ODOMETRY: odometry.tobytes()
        }
        sent = []
        if gps is not None:
            self._fill_gps(time_usec, gps)
            sent.append(self._gps)
        if vision is not None:
            self._fill_vision(time_usec, vision)
            sent.append(self._vision)
        if disturbance is not None:
            stamp_usec, (force, torque, health) = disturbance
            v = self._disturbance.values
            v[self._d_time] = stamp_usec
            start = self._d_data.start
            v[start : start + wire.DISTURB_SIZE] = (
                *frames.vector_to_ned(force), *frames.euler_to_ned(torque), *health
            )
            sent.append(self._disturbance)
        if battery is not None:
            self._fill_battery(battery)
            sent.append(self._battery)
        for encoder in sent:
            payloads[encoder.msg_id] = encoder.payload()
        return payloads

    def _fill_battery(self, reading: BatteryReading) -> None:
        """The monitor's reading as BATTERY_STATUS: mV in voltages[0] (and [1] past 65 534 mV),
        cA; not a finite number: the field's unknown (65535 mV, -1 cA)."""
        v, cells = self._battery.values, self._b_cells
        volts, current = reading.voltage_v, reading.current_a
        if not math.isfinite(volts):
            v[cells], v[cells + 1] = UINT16_UNKNOWN, UINT16_UNKNOWN
        else:
            millivolts = sat_u16(volts * 1000.0, 2 * CELL_VOLTAGE_MAX_MV)
            split = millivolts > CELL_VOLTAGE_MAX_MV
            v[cells] = CELL_VOLTAGE_MAX_MV if split else millivolts
            v[cells + 1] = millivolts - CELL_VOLTAGE_MAX_MV if split else UINT16_UNKNOWN
        v[self._b_current] = sat_i16(current * 100.0) if math.isfinite(current) else -1

    def _fill_vision(self, time_usec: int, reading: VisionReading) -> None:
        """Position (NED) and yaw of the motion capture; its reported variances in the
        covariance's upper triangle (x, y, z, roll, pitch, yaw: entries 0, 6, 11, 15, 18, 20;
        roll and pitch are not measured: NaN, as MAVLink has it for unknown)."""
        v, i = self._vision.values, self._v
        (n, e, d), yaw, position_variance, yaw_variance = self._vision_values(
            reading.position_m, reading.yaw_rad, reading.position_std_m, reading.yaw_std_rad
        )
        v[i[0]], v[i[1]], v[i[2]], v[i[3]], v[i[4]] = time_usec, n, e, d, yaw
        cov = [0.0] * 21
        cov[0] = cov[6] = cov[11] = position_variance
        cov[15] = cov[18] = math.nan
        cov[20] = yaw_variance
        v[self._v_cov] = cov

    def _fill_gps(self, time_usec: int, reading: GpsReading) -> None:
        """The fix as HIL_GPS (:func:`quadcommon.wire_values.gps_values`), with its fix type and
        satellites."""
        v, i = self._gps.values, self._g
        v[self._g_fix] = reading.fix_type
        fields = self._gps_values(
            reading.position_m, reading.velocity_m_s, reading.eph_m, reading.epv_m, self.home
        )
        (v[i[1]], v[i[2]], v[i[3]], v[i[4]], v[i[5]], v[i[6]], v[i[7]], v[i[8]], v[i[9]], v[i[10]]) = fields
        v[i[0]], v[i[11]] = time_usec, reading.satellites_visible


def _slots(encoder: FastEncoder, *names: str) -> tuple[int, ...]:
    return tuple(encoder.slices[name] for name in names)  # type: ignore[misc]


class ActuatorAnswer(NamedTuple):
    """One decoded ``HIL_ACTUATOR_CONTROLS``."""

    time_usec: int
    controls: tuple[float, float, float, float]  # normalised, see quadcommon.wire
    armed: bool  # MAV_MODE_FLAG_SAFETY_ARMED in mode
    lockstep: bool  # flags bit 0
    wrench: bool  # flags bit 1: controls are a normalised wrench, else rotor speeds
    # The rest of the datagram, undecoded: ``(message id, frame)`` of every other MAVLink 2 frame,
    # and ``(NOT_MAVLINK, bytes)`` for bytes that are not frames (requests: RequestDecoder).
    others: tuple[tuple[int, bytes], ...] = ()


NOT_MAVLINK = -1  # ActuatorAnswer.others: bytes that are not a MAVLink 2 frame


class InjectFailure(NamedTuple):
    """The request ``MAV_CMD_INJECT_FAILURE`` (:mod:`quadcommon.failures`), as the ground station
    sent it to the autopilot; a motor's ``wrong`` with the effectiveness the autopilot resolved
    (param4)."""

    unit: int  # FAILURE_UNIT
    failure_type: int  # FAILURE_TYPE
    instance: int  # 0: all
    effectiveness: float = 1.0  # param4: what a motor at a loss of effectiveness keeps, in [0, 1]


class SetSimParameter(NamedTuple):
    """A ``PARAM_SET`` of one of the simulator's own parameters (PX4's ``SIM_BAT_*``:
    :data:`quadcommon.config.SIM_BATTERY_PARAMETERS`), forwarded by the autopilot that declares
    them."""

    name: str
    value: float


Request = InjectFailure | SetSimParameter  # the requests to the simulator (quadcommon.wire)


class RequestDecoder:
    """The requests to the simulator in an answer's other frames (:mod:`quadcommon.wire`): decoded
    with their checksum, from this vehicle's autopilot, addressed to the simulator, known, finite.
    Anything else is refused and counted by reason (:attr:`refused`); nothing here raises."""

    def __init__(self, system_id: int) -> None:
        self.sender = (system_id, wire.AUTOPILOT_COMPONENT_ID)
        self.target = (system_id, wire.SIMULATOR_COMPONENT_ID)
        self.refused: dict[str, int] = {}
        self._command = FastDecoder(mavlink.MAVLink_command_long_message)
        where = self._command.slices
        self._c = tuple(where[name] for name in ("target_system", "target_component", "command", "param1",
                                                 "param2", "param3", "param4"))  # fmt: skip
        self._param_set = FastDecoder(mavlink.MAVLink_param_set_message)
        where = self._param_set.slices
        self._p = tuple(where[name] for name in ("target_system", "target_component", "param_id",
                                                 "param_value"))  # fmt: skip
        # message id -> how its frame becomes a request (a new request: one entry and a method)
        self._decoders = {mavlink.MAVLINK_MSG_ID_COMMAND_LONG: self._command_long,
                          mavlink.MAVLINK_MSG_ID_PARAM_SET: self._parameter}  # fmt: skip

    def decode(self, others: tuple[tuple[int, bytes], ...]) -> list[Request]:
        """The requests carried by an answer's other frames (``COMMAND_LONG``, ``PARAM_SET``), at most
        ``wire.MAX_REQUESTS_PER_ANSWER``; anything else, or a request that does not decode, is refused
        and counted (:meth:`refuse`), never raised."""
        requests: list[Request] = []
        for i, (msg_id, frame) in enumerate(others):
            if i >= wire.MAX_REQUESTS_PER_ANSWER:
                self.refuse(f"more than {wire.MAX_REQUESTS_PER_ANSWER} requests in one answer")
                continue
            decoder = self._decoders.get(msg_id)
            if msg_id == NOT_MAVLINK:
                self.refuse("bytes that are not MAVLink 2 after the controls")
            elif decoder is None:
                self.refuse(f"message {msg_id}: not a request to the simulator")
            elif (frame[5], frame[6]) != self.sender:
                self.refuse(f"a request from system {frame[5]} component {frame[6]}, not the autopilot")
            else:
                try:
                    request = decoder(frame)
                except DecodeError:
                    self.refuse(f"message {msg_id}: bad checksum or length")
                    continue
                if isinstance(request, str):
                    self.refuse(request)
                else:
                    requests.append(request)
        return requests

    def _command_long(self, frame: bytes) -> Request | str:
        v = self._command.unpack(frame)
        system, component, command, unit, failure_type, instance, effectiveness = (v[i] for i in self._c)
        if (system, component) != self.target:
            return f"a command to system {system} component {component}, not the simulator"
        if command != mavlink.MAV_CMD_INJECT_FAILURE:
            return f"command {command}: not a request to the simulator"
        params = (unit, failure_type, instance)
        if not all(math.isfinite(x) and 0.0 <= x <= 255.0 and x == int(x) for x in params):
            return "MAV_CMD_INJECT_FAILURE with a parameter that is not an integer in [0, 255]"
        if not 0.0 <= effectiveness <= 1.0:  # (NaN fails it too)
            return "MAV_CMD_INJECT_FAILURE with an effectiveness (param4) outside [0, 1]"
        return InjectFailure(int(unit), int(failure_type), int(instance), float(effectiveness))

    def _parameter(self, frame: bytes) -> Request | str:
        v = self._param_set.unpack(frame)
        system, component, raw_id, value = (v[i] for i in self._p)
        if (system, component) != self.target:
            return f"a PARAM_SET to system {system} component {component}, not the simulator"
        name = bytes(raw_id).split(b"\0", 1)[0].decode("ascii", "replace")
        if name not in SIM_BATTERY_PARAMETERS:
            return f"PARAM_SET {name[:16]!r}: not a simulator parameter"
        if not math.isfinite(value):
            return f"PARAM_SET {name}: value not finite"
        return SetSimParameter(name, float(value))

    @property
    def refused_total(self) -> int:
        """How many requests were refused, all reasons together."""
        return sum(self.refused.values())

    def refuse(self, reason: str) -> None:
        """Count a refused request (by reason; at most 64 reasons kept, the rest together)."""
        if reason in self.refused or len(self.refused) < 64:  # bounded
            self.refused[reason] = self.refused.get(reason, 0) + 1
        else:
            self.refused["(other reasons)"] = self.refused.get("(other reasons)", 0) + 1


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
        """The last actuator message in ``datagram``, or None when it holds none; the datagram's
        other frames (and bytes that are not frames) ride along, undecoded, in ``others``."""
        answer = None
        others: list[tuple[int, bytes]] = []
        consumed = 0
        for msg_id, frame in split_frames(datagram):
            consumed += len(frame)
            if msg_id != _ID_CONTROLS:
                others.append((msg_id, frame))
                continue
            try:
                answer = self._answer(self.decoder.unpack(frame))
            except DecodeError:  # a malformed frame must never stop the simulator
                continue
        if consumed != len(datagram):
            others.append((NOT_MAVLINK, datagram[consumed:]))
        if answer is not None and others:
            answer = answer._replace(others=tuple(others))
        return answer

    def decode_unframed(self, answer: LockstepAnswer) -> ActuatorAnswer | None:
        """An answer handed over in the process: what :meth:`decode` reads of its datagram. Its
        controls' payload is read as the frame's would be; an answer carrying requests (rare: a
        failure injected, a parameter set) is decoded from its datagram."""
        if answer.requests:
            return self.decode(answer.datagram)
        return self._answer(self.decoder.unpacker.unpack_from(answer.controls))

    def _answer(self, v: tuple) -> ActuatorAnswer:
        """The answer in HIL_ACTUATOR_CONTROLS's flat field tuple ``v``."""
        c = v[self._controls]
        flags = v[self._flags]
        return ActuatorAnswer(
            v[self._time],
            (c[0], c[1], c[2], c[3]),
            bool(v[self._mode] & _ARMED),
            bool(flags & wire.HIL_FLAG_LOCKSTEP),
            bool(flags & wire.HIL_FLAG_WRENCH),
        )
