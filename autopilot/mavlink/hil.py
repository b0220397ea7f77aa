"""The autopilot's edge of the HIL link: frames in, actuator controls out (NED <-> paper here).

A lockstep frame is one datagram with HIL_SENSOR, HIL_STATE_QUATERNION, ODOMETRY and sometimes
HIL_GPS and BATTERY_STATUS, all stamped with the same ``time_usec`` (see :mod:`quadcommon.wire`).
The state the controllers see comes from ODOMETRY (float32 local NED, millimetre-exact) or, on
request, from HIL_STATE_QUATERNION (position quantised to 1e-7 deg ~ 1 cm, velocity to 1 cm/s).
"""

from __future__ import annotations

import math
import struct
from typing import NamedTuple

from quadcommon import frames, wire
from quadcommon.mavlink_fast import DecodeError, FastDecoder, FastEncoder, MessageParts
from quadcommon.rigid_body import (
    rotation_from_quaternion,
)
from quadcommon.wire_values import attitude_from_fields, entry, gps_fix, odometry_state, vision_pose

from ..records import (
    STREAM_BARO,
    STREAM_GPS,
    STREAM_IMU,
    STREAM_MAG,
    STREAM_VISION,
    GpsFix,
    SensorSamples,
    StateEstimate,
    VisionPose,
)
from .codec import Encoder, mavlink

Vector3 = tuple[float, float, float]
_ID_STATE = mavlink.MAVLINK_MSG_ID_HIL_STATE_QUATERNION
_ARMED = mavlink.MAV_MODE_FLAG_SAFETY_ARMED
_CUSTOM = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED


class Frame(NamedTuple):
    time_usec: int
    state: StateEstimate  # paper frames: the truth (ODOMETRY or HIL_STATE_QUATERNION)
    sensors: SensorSamples | None = None  # decoded when asked (frame_of(..., sensors=True))
    # The frame's messages by id, undecoded (a log decodes HIL_SENSOR / HIL_GPS from them at its
    # own rate: sensor_samples(), gps_fields()).
    parts: MessageParts | None = None
    # The sensor streams that delivered in this frame (STREAM_* bits), decoded or not: the same as
    # ``sensors.streams`` (frame_streams without the samples).
    streams: int = 0


_ODOMETRY = FastDecoder(mavlink.MAVLink_odometry_message)
# What the controllers need of ODOMETRY, in wire order: time_usec, x, y, z, q[4], vx, vy, vz, the
# three rates (the first 60 bytes), then child_frame_id after the two covariance arrays.
_ODOMETRY_STATE = struct.Struct("<Q13f")
_ODOMETRY_CHILD_FRAME = 8 + 4 * (13 + 21 + 21) + 1


class CorruptFrame(ValueError):
    """The state message of a lockstep frame failed its checksum or could not be decoded."""


def frame_of(
    parts: MessageParts,
    home: tuple[float, float, float],
    use_odometry: bool = True,
    sensors: bool = False,
) -> Frame | None:
    """The lockstep frame of a datagram's messages (``MessageParts.of_datagram``, or the
    in-process runner's ``MessageParts.of_payloads``), or None if it holds no state (e.g. a
    heartbeat).

    Decodes (CRC checked) only the state message it needs: ODOMETRY (the fast decoder of
    :mod:`quadcommon.mavlink_fast`, it is on the lockstep critical path), or HIL_STATE_QUATERNION
    when asked to or when there is no ODOMETRY; with ``sensors`` also what an estimator reads
    (:class:`SensorSamples`). CorruptFrame if one of those messages is bad.
    """
    try:
        return _decode_frame(parts, home, use_odometry, sensors)
    except (DecodeError, struct.error) as exc:
        raise CorruptFrame(str(exc)) from exc


def _decode_frame(parts: MessageParts, home, use_odometry: bool, sensors: bool) -> Frame | None:
    if sensors:
        samples = sensor_samples(parts, home)
        streams = samples.streams if samples is not None else 0
    else:
        samples, streams = None, frame_streams(parts)
    payload = parts.payload(_ODOMETRY) if use_odometry or _ID_STATE not in parts else None
    if payload is not None:
        t, x, y, z, qw, qx, qy, qz, vx, vy, vz, p, q, r = _ODOMETRY_STATE.unpack_from(payload)
        state = state_from_odometry_fields(
            (qw, qx, qy, qz), (x, y, z), (vx, vy, vz), (p, q, r), payload[_ODOMETRY_CHILD_FRAME]
        )
        return Frame(t, state, samples, parts, streams)
    msg = _state_message(parts)
    if msg is None:
        return None
    return Frame(msg.time_usec, state_from_hil_state(msg, home), samples, parts, streams)


_SENSOR = FastDecoder(mavlink.MAVLink_hil_sensor_message)
_GPS = FastDecoder(mavlink.MAVLink_hil_gps_message)
_VISION = FastDecoder(mavlink.MAVLink_vision_position_estimate_message)
_IMU_BITS = 0x3F  # HIL_SENSOR fields_updated: x/y/z accelerometer, x/y/z gyro
_MAG_BITS = 0x1C0  # HIL_SENSOR fields_updated: x/y/z magnetometer
_BARO_ALT_BIT = 0x800  # HIL_SENSOR fields_updated: pressure altitude


def _where(decoder: FastDecoder, *names: str) -> tuple:
    """Where ``names`` sit in the decoder's flat field tuple (looked up once, not per frame)."""
    return tuple(decoder.slices[name] for name in names)


def _fields(decoder: FastDecoder, payload: bytes, where: tuple) -> list:
    values = decoder.unpacker.unpack_from(payload)
    return [values[i] for i in where]


# What an estimator reads of HIL_SENSOR, in wire order: the accelerometer, gyro and magnetometer
# (after time_usec), pressure_alt (after abs_pressure and diff_pressure), fields_updated (after
# temperature); one unpack of the checked payload.
_SENSOR_VALUES = struct.Struct("<8x9f8xf4xI")
assert _SENSOR.unpacker.format == "<QfffffffffffffIB"
assert [_SENSOR.slices[name] for name in ("xacc", "zmag", "pressure_alt", "fields_updated")] == [1, 9, 12, 14]
_GPS_FIELDS = _where(_GPS, "fix_type", "lat", "lon", "alt", "eph", "epv", "vn", "ve", "vd",
                     "satellites_visible")  # fmt: skip
_VISION_FIELDS = _where(_VISION, "x", "y", "z", "yaw", "covariance")
_REFUSED_NAMES = ((STREAM_IMU, "imu"), (STREAM_MAG, "mag"), (STREAM_BARO, "baro"))  # SensorSamples.refused


def _hil_sensor(payload: bytes) -> tuple[tuple, int, int]:
    """HIL_SENSOR's values (``_SENSOR_VALUES``) and which of its streams are fresh and which
    refused (``STREAM_*`` bits): each stream when fields_updated says so (the IMU: its six
    accelerometer and gyro bits, which a failure clears); a stream with a non-finite value is
    refused."""
    values = _SENSOR_VALUES.unpack_from(payload)
    ax, ay, az, gx, gy, gz, mx, my, mz, alt, updated = values
    fresh, refused = 0, 0
    if updated & _IMU_BITS == _IMU_BITS:
        fresh |= STREAM_IMU
    if not math.isfinite(ax + ay + az + gx + gy + gz):
        refused |= STREAM_IMU
    if updated & _MAG_BITS == _MAG_BITS:
        fresh |= STREAM_MAG
        if not math.isfinite(mx + my + mz):
            refused |= STREAM_MAG
    if updated & _BARO_ALT_BIT:
        fresh |= STREAM_BARO
        if not math.isfinite(alt):
            refused |= STREAM_BARO
    return values, fresh, refused


def _vision(payload: bytes) -> tuple[list, bool]:
    """VISION_POSITION_ESTIMATE's values (``_VISION_FIELDS``) and whether its pose is finite."""
    values = _fields(_VISION, payload, _VISION_FIELDS)
    n, e, d, yaw, _ = values
    return values, math.isfinite(n + e + d + yaw)


def frame_streams(parts: MessageParts) -> int:
    """The sensor streams that delivered in a frame (``STREAM_*`` bits): ``sensor_samples(parts,
    home).streams`` without building the samples (where nothing flies on them, the health checks
    read this every frame and the samples only when a check is due). DecodeError if a message is
    corrupt."""
    payload = parts.payload(_SENSOR)
    if payload is None:
        return 0
    _, fresh, refused = _hil_sensor(payload)
    streams = fresh & ~refused
    if parts.payload(_GPS) is not None:  # (its checksum, as sensor_samples checks it)
        streams |= STREAM_GPS
    payload = parts.payload(_VISION)
    if payload is not None and _vision(payload)[1]:
        streams |= STREAM_VISION
    return streams


def sensor_samples(parts: MessageParts, home) -> SensorSamples | None:
    """What an estimator reads of a frame's messages (``Frame.parts``); None without HIL_SENSOR.
    DecodeError (quadcommon.mavlink_fast) if a message is corrupt."""
    payload = parts.payload(_SENSOR)
    if payload is None:
        return None
    (ax, ay, az, gx, gy, gz, mx, my, mz, alt, _), fresh, refused_streams = _hil_sensor(payload)
    imu_fresh = bool(fresh & STREAM_IMU)
    to_paper = frames.vector_from_ned
    usable = fresh & ~refused_streams
    mag = to_paper((mx, my, mz)) if usable & STREAM_MAG else None
    baro = alt if usable & STREAM_BARO else None
    refused = [name for bit, name in _REFUSED_NAMES if refused_streams & bit] if refused_streams else []
    gps = vision = None
    payload = parts.payload(_GPS)
    if payload is not None:
        fix, lat, lon, alt_mm, eph, epv, vn, ve, vd, sats = _fields(_GPS, payload, _GPS_FIELDS)
        position, velocity, eph_m, epv_m = entry(gps_fix)(lat, lon, alt_mm, vn, ve, vd, eph, epv, home)
        gps = GpsFix(0.0, position, velocity, eph_m, epv_m, 0.0, fix, sats)  # (no speed accuracy field)
    payload = parts.payload(_VISION)
    if payload is not None:
        (n, e, d, yaw, cov), finite = _vision(payload)
        if finite:
            vision = VisionPose(0.0, *entry(vision_pose)((n, e, d), yaw, cov[0], cov[20]))
        else:
            refused.append("vision")
    return SensorSamples(to_paper((gx, gy, gz)), to_paper((ax, ay, az)), mag, baro, gps, vision,
                         tuple(refused), imu_fresh)  # fmt: skip


# HIL_SENSOR's accelerometer then gyro, right after time_usec in wire order (the log reads these
# six of its sixteen fields at every control step: one small unpack, not the whole message).
_IMU = struct.Struct("<8x6f")
assert _SENSOR.slices["xacc"] == 1 and _SENSOR.slices["zgyro"] == 6


def imu_fields(parts: MessageParts) -> tuple | None:
    """The frame's HIL_SENSOR accelerometer (m/s²) and gyro (rad/s) as sent, FRD body axes
    (``xacc, yacc, zacc, xgyro, ygyro, zgyro``), or None when the frame has none (a log's raw
    sensor topic: no conversion, no checks). DecodeError if it is corrupt."""
    payload = parts.payload(_SENSOR)
    return None if payload is None else _IMU.unpack_from(payload)


_HIGHRES_FIELDS = _where(_SENSOR, "xacc", "yacc", "zacc", "xgyro", "ygyro", "zgyro", "xmag", "ymag", "zmag",
                         "abs_pressure", "diff_pressure", "pressure_alt", "temperature")  # fmt: skip


def sensor_fields(parts: MessageParts) -> list | None:
    """The frame's HIL_SENSOR readings as sent, in HIGHRES_IMU's field order and units (FRD body
    axes: specific force m/s², rates rad/s, field gauss; pressures hPa, pressure altitude m AMSL,
    temperature deg C), or None when the frame has none or it is corrupt. Decoded when asked (a
    requested HIGHRES_IMU), not every frame."""
    try:
        payload = parts.payload(_SENSOR)
    except DecodeError:
        return None
    return None if payload is None else _fields(_SENSOR, payload, _HIGHRES_FIELDS)


_STATE = FastDecoder(mavlink.MAVLink_hil_state_quaternion_message)
_STATE_FLOATS = tuple(
    name for name, kind in zip(_STATE.message_class.fieldnames, _STATE.message_class.fieldtypes, strict=True)
    if kind == "float"
)  # fmt: skip


def _state_message(parts: MessageParts):
    """The frame's HIL_STATE_QUATERNION as a message (pymavlink's class), or None when it has
    none; DecodeError if it is corrupt."""
    payload = parts.payload(_STATE)
    if payload is None:
        return None
    values = _STATE.unpacker.unpack_from(payload)
    slices = _STATE.slices
    fields = {name: values[slices[name]] for name in _STATE.message_class.fieldnames}
    fields["attitude_quaternion"] = list(fields["attitude_quaternion"])
    return _STATE.message_class(**fields)


def ground_truth(parts: MessageParts):
    """The simulator's HIL_STATE_QUATERNION of this frame (its ground truth: attitude, rates,
    lat/lon/alt, NED velocity, specific force) as a message to send on (pymavlink), or None when
    the frame has none, or one that is corrupt or not finite. Decoded when asked."""
    try:
        msg = _state_message(parts)
    except DecodeError:
        return None
    if msg is None:
        return None
    for name in _STATE_FLOATS:
        value = getattr(msg, name)
        if not all(math.isfinite(v) for v in (value if isinstance(value, list) else (value,))):
            return None
    return msg


class GpsFields(NamedTuple):
    """HIL_GPS as sent: scaled integers (degE7, mm, cm/s, cm), ``cog`` in cdeg (65535: unknown)."""

    fix_type: int
    lat: int
    lon: int
    alt: int
    eph: int
    epv: int
    vel: int
    vn: int
    ve: int
    vd: int
    cog: int
    satellites_visible: int


_GPS_RAW_FIELDS = _where(_GPS, *GpsFields._fields)


def gps_fields(parts: MessageParts) -> GpsFields | None:
    """The frame's HIL_GPS fields as sent (``Frame.parts``), or None when the frame has no fix;
    DecodeError if it is corrupt."""
    payload = parts.payload(_GPS)
    if payload is None:
        return None
    return GpsFields(*_fields(_GPS, payload, _GPS_RAW_FIELDS))


_DISTURBANCE = FastDecoder(mavlink.MAVLink_debug_float_array_message)
_DISTURBANCE_NAME = _where(_DISTURBANCE, "name")[0]
_DISTURBANCE_DATA = _DISTURBANCE.slices["data"].start


DISTURBANCE_ID = mavlink.MAVLINK_MSG_ID_DEBUG_FLOAT_ARRAY
BATTERY_ID = mavlink.MAVLINK_MSG_ID_BATTERY_STATUS
_BATTERY = FastDecoder(mavlink.MAVLink_battery_status_message)
_BATTERY_NUMBER, _BATTERY_CURRENT = _where(_BATTERY, "id", "current_battery")
_BATTERY_CELLS = _BATTERY.slices["voltages"].start
_MV_UNKNOWN = 65535
_MV_SPLIT = 65534  # voltages[0] at this value: the rest of the voltage is in voltages[1]


class BatteryReport(NamedTuple):
    """The battery monitor's reading in a frame (``BATTERY_STATUS``, :mod:`quadcommon.wire`)."""

    voltage_v: float  # the pack's
    current_a: float  # drawn; NaN: not measured


class RefusedReport(ValueError):
    """A BATTERY_STATUS in a frame that is not a reading to use; the message says why (a few
    fixed words: the refusals are counted by them)."""


def battery_report(parts: MessageParts) -> BatteryReport | None:
    """The reading in a frame's BATTERY_STATUS (``Frame.parts``), None when it carries none.
    RefusedReport, saying why, when it is corrupt, not from the simulator's component, of another
    battery than battery 0, without a voltage (``voltages[0]`` unknown) or with a current below -1 cA
    (-1: not measured; a flying pack does not charge)."""
    try:
        payload = parts.payload(_BATTERY)
    except DecodeError:
        raise RefusedReport("corrupt") from None
    if payload is None:
        return None
    values = _BATTERY.unpacker.unpack_from(payload)
    if parts.component_id(BATTERY_ID) != wire.SIMULATOR_COMPONENT_ID:
        raise RefusedReport("not from the simulator's component")
    if values[_BATTERY_NUMBER] != 0:
        raise RefusedReport("not battery 0")
    millivolts, rest = values[_BATTERY_CELLS], values[_BATTERY_CELLS + 1]
    if millivolts == _MV_UNKNOWN:
        raise RefusedReport("no voltage")
    if millivolts == _MV_SPLIT and rest != _MV_UNKNOWN:
        millivolts += rest
    centiamps = values[_BATTERY_CURRENT]
    if centiamps < -1:
        raise RefusedReport("negative current")
    return BatteryReport(millivolts * 1e-3, centiamps * 1e-2 if centiamps != -1 else math.nan)


class DisturbanceReport(NamedTuple):
    """What the simulator reports it applies beyond the controls (``DISTURB``, :mod:`quadcommon.wire`)."""

    time_usec: int  # the sample's time
    force_n: Vector3  # at the centre of mass, world (paper frames)
    torque_n_m: Vector3  # on the Euler coordinates
    rotor_effectiveness: tuple[float, float, float, float]  # rotors 1-4, the plant's order
    rotor_failure: tuple[int, int, int, int]  # their FAILURE_TYPE (0 none)


def disturbance_of(parts: MessageParts) -> DisturbanceReport | None:
    """The disturbance and the rotors' health the simulator reports in this frame (``DISTURB``,
    see :mod:`quadcommon.wire`), in the paper's frames; None when the frame carries none, or one
    that is corrupt, named otherwise, not finite, or with a failure type that is not a byte
    (never logged)."""
    try:
        payload = parts.payload(_DISTURBANCE)
    except DecodeError:
        return None
    if payload is None:
        return None
    values = _DISTURBANCE.unpacker.unpack_from(payload)
    if values[_DISTURBANCE_NAME].rstrip(b"\0") != wire.DISTURBANCE_NAME:
        return None
    data = values[_DISTURBANCE_DATA : _DISTURBANCE_DATA + wire.DISTURB_SIZE]
    if not math.isfinite(sum(data)):
        return None
    failure = data[10:14]
    if not all(0.0 <= f <= 255.0 and f == int(f) for f in failure):
        return None
    return DisturbanceReport(values[0], frames.vector_from_ned(data[0:3]), frames.euler_from_ned(data[3:6]),
                             tuple(data[6:10]), tuple(int(f) for f in failure))  # fmt: skip


_BODY_FRAMES = (mavlink.MAV_FRAME_BODY_FRD, mavlink.MAV_FRAME_BODY_NED)


def state_from_odometry_fields(
    q_ned: tuple, position_ned: tuple, velocity_child: tuple, rates_frd: tuple, child_frame_id: int
) -> StateEstimate:
    """ODOMETRY fields (NED pose, twist in ``child_frame_id``, FRD rates; tuples of floats, as the
    wire's struct gives them) -> paper frames (:func:`quadcommon.wire_values.odometry_state`,
    compiled; a body twist rotated by the attitude)."""
    if child_frame_id in _BODY_FRAMES:
        q, euler, euler_rates = attitude_from_fields(q_ned, rates_frd)
        v_body = frames.vector_from_ned(velocity_child)
        R = rotation_from_quaternion(*q)
        velocity = tuple(R[i][0] * v_body[0] + R[i][1] * v_body[1] + R[i][2] * v_body[2] for i in range(3))
        return StateEstimate(frames.vector_from_ned(position_ned), velocity, euler, euler_rates)  # type: ignore[arg-type]
    return StateEstimate(*entry(odometry_state)(position_ned, velocity_child, q_ned, rates_frd))


def state_from_hil_state(msg, home: tuple[float, float, float]) -> StateEstimate:
    """The truth in a HIL_STATE_QUATERNION, in the paper's frames: its geodetic position made local against
    ``home`` (lat, lon in degrees, alt in m), velocity and attitude from NED/FRD."""
    q, euler, euler_rates = attitude_from_fields(
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
        """The HIL_ACTUATOR_CONTROLS frame of one lockstep answer (:meth:`frame` of :meth:`payload`)."""
        return self.frame(self.payload(time_usec, controls, armed))

    def payload(self, time_usec: int, controls: tuple[float, ...], armed: bool) -> bytes:
        """The HIL_ACTUATOR_CONTROLS payload of one lockstep answer: ``controls`` (the first four,
        zero while disarmed), the armed flag in ``mode`` and the lockstep (and wrench) flags."""
        v = self._fast.values
        v[self._time] = time_usec
        v[self._mode] = _CUSTOM | (_ARMED if armed else 0)
        v[self._controls] = [*controls[:4], *self._zeros[4:]] if armed else self._zeros
        return self._fast.payload()

    def frame(self, payload: bytes) -> bytes:
        """A :meth:`payload` framed, on the encoder's sequence."""
        mav = self.encoder.mav
        data = self._fast.frame_of(payload, mav.seq)
        mav.seq = (mav.seq + 1) % 256
        return data


class SimulatorRequests:
    """Requests to the simulator, carried in the lockstep answer after its HIL_ACTUATOR_CONTROLS
    (:mod:`quadcommon.wire`): MAVLink 2 frames from the autopilot, addressed to the simulator's
    component, never signed; at most ``MAX_REQUESTS_PER_ANSWER`` per answer, the rest in the next;
    at most :data:`MAX_PENDING` waiting (a flood of commands cannot grow the queue)."""

    MAX_PENDING = 64

    def __init__(self, encoder: Encoder, system_id: int) -> None:
        self.encoder = encoder
        self.system_id = system_id
        self.pending: list[bytes] = []

    @property
    def full(self) -> bool:
        """True when :data:`MAX_PENDING` requests wait: the caller refuses a new one (a failure injection
        is answered TEMPORARILY_REJECTED)."""
        return len(self.pending) >= self.MAX_PENDING

    def command(self, command: int, *params: float) -> None:
        """A COMMAND_LONG for the simulator (param1.. as given, the rest 0)."""
        p = [float(x) for x in params] + [0.0] * (7 - len(params))
        target = (self.system_id, wire.SIMULATOR_COMPONENT_ID)
        self.send(mavlink.MAVLink_command_long_message(*target, command, 0, *p))

    def send(self, message) -> None:
        """Any message for the simulator (pymavlink, its target the simulator's component: a
        ``PARAM_SET`` of a ``SIM_*`` parameter, say), packed now, sent in the next answer."""
        self.pending.append(self.encoder.pack_unsigned(message))

    def take(self) -> bytes:
        """The frames for this answer (removed from the queue)."""
        taken = self.pending[: wire.MAX_REQUESTS_PER_ANSWER]
        del self.pending[: wire.MAX_REQUESTS_PER_ANSWER]
        return b"".join(taken)
