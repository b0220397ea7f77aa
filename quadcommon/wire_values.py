"""What the lockstep frame's messages carry, as kernels: each quantity from the paper's frames to
its message fields (the simulator's encoder, :mod:`simulator.mavlink.hil`) and back from them (the
autopilot's decoder, :mod:`autopilot.mavlink.hil`), written once.

The encoders here give exactly the values the message carries: integer fields scaled, rounded and
saturated to their type (1e-7 deg, mm, cm, cm/s), float fields rounded to float32 (MAVLink's
``float``), signs flipped to NED/FRD by :mod:`quadcommon.frames`. Packing them is then lossless, and
a flight that does not pack bytes (the campaign engine, :mod:`sitl.campaign.kernels`) crosses the
wire by calling the decoder on the encoder's values: the same rounding, the same sign flips, the
same order, nowhere written a second time.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from typing import Any

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from . import frames
from .kernel import kernel, warmed
from .mavlink_fast import record_dtype
from .rigid_body import euler_from_quaternion, euler_rates_from_body_rates

Vector3 = tuple[float, float, float]

FLOAT32_MAX = 3.4028234663852886e38  # the largest finite float32
# The messages every lockstep frame carries, in :func:`frame_records`' order, and their payloads as
# records (compile-time constants of the kernels that fill them).
FRAME_RECORD_MESSAGES = (mavlink.MAVLink_hil_sensor_message, mavlink.MAVLink_hil_state_quaternion_message,
                         mavlink.MAVLink_odometry_message)  # fmt: skip
HIL_SENSOR_RECORD, HIL_STATE_RECORD, ODOMETRY_RECORD = (record_dtype(c) for c in FRAME_RECORD_MESSAGES)
GPS_UNKNOWN_ACCURACY = 65535  # HIL_GPS eph/epv: "unknown"
GPS_ACCURACY_UNKNOWN_M = 99.0  # what the autopilot reads an unknown eph/epv as
STANDARD_GRAVITY_M_S2 = 9.80665  # 1 G, for HIL_STATE_QUATERNION's mG fields


# -------------------------------------------------------------------------------------------------
# Field types
# -------------------------------------------------------------------------------------------------
@kernel
def float_field(x: float) -> float:
    """A MAVLink ``float`` field: ``x`` rounded to float32, as a float64 (``float()`` of a float32
    stays a float32 in compiled code, and the arithmetic after it would too)."""
    return np.float64(np.float32(x))


@kernel
def float_fields3(v: Vector3) -> Vector3:
    """Three ``float`` fields."""
    return (float_field(v[0]), float_field(v[1]), float_field(v[2]))


# (The in-range test first: a NaN fails it, and it is the one comparison of nearly every call.)
@kernel
def sat_i16(x: float) -> int:
    """An int16 field: saturated at +-32767, NaN as 0."""
    if -32767.0 <= x <= 32767.0:
        return round(x)
    if x != x:
        return 0
    return -32767 if x < 0.0 else 32767


@kernel
def sat_u16(x: float, top: int = 65534) -> int:
    """A uint16 field: saturated at [0, ``top``] (65535 is MAVLink's "unknown"), NaN as 65535."""
    if 0.0 <= x <= top:
        return round(x)
    if x != x:
        return 65535
    return 0 if x < 0.0 else top


@kernel
def sat_i32(x: float) -> int:
    """An int32 field: saturated at +-2147483647, NaN as 0."""
    if -2147483647.0 <= x <= 2147483647.0:
        return round(x)
    if x != x:
        return 0
    return -2147483647 if x < 0.0 else 2147483647


# -------------------------------------------------------------------------------------------------
# The frame's clock
# -------------------------------------------------------------------------------------------------
@kernel
def frame_time_usec(k: int, usec_per_frame: float) -> int:
    """The ``time_usec`` every message of lockstep frame ``k`` carries (µs since the simulator
    started; ``usec_per_frame``: 1e6 / the control rate)."""
    return round(k * usec_per_frame)


@kernel
def frame_time_s(time_usec: int) -> float:
    """A frame's ``time_usec`` as the autopilot's time (s)."""
    return time_usec * 1e-6


# -------------------------------------------------------------------------------------------------
# HIL_SENSOR, VISION_POSITION_ESTIMATE and ODOMETRY: float fields
# -------------------------------------------------------------------------------------------------
@kernel
def vector_field(v: Vector3) -> Vector3:
    """A world (body) vector of the paper's frames as three float fields, NED (FRD): HIL_SENSOR's
    specific force, rates and field, ODOMETRY's position, velocity and rates."""
    return float_fields3(frames.vector_to_ned(v))


@kernel
def vector_from_field(v_ned: Vector3) -> Vector3:
    """Three NED (FRD) float fields as a vector of the paper's frames."""
    return frames.vector_from_ned(v_ned)


@kernel
def odometry_values(position: Vector3, velocity: Vector3, quaternion, body_rates: Vector3):
    """ODOMETRY's pose and twist fields of the truth (``frame_id`` and ``child_frame_id``
    LOCAL_NED: world velocity; rates FRD): ``(position NED, velocity NED, q NED/FRD, rates FRD)``."""
    q = frames.quaternion_to_ned(quaternion)
    q_field = (float_field(q[0]), float_field(q[1]), float_field(q[2]), float_field(q[3]))
    return vector_field(position), vector_field(velocity), q_field, vector_field(body_rates)


@kernel
def hil_state_values(position: Vector3, velocity: Vector3, specific_force_body: Vector3, wind: Vector3, home):
    """HIL_STATE_QUATERNION's scaled integer fields of the truth about ``home`` (lat deg, lon deg,
    alt m): ``(lat 1e-7 deg, lon 1e-7 deg, alt mm, vx, vy, vz cm/s NED, airspeed cm/s (the speed
    through the air ``wind``), xacc, yacc, zacc mG FRD)``."""
    p = frames.vector_to_ned(position)
    v = frames.vector_to_ned(velocity)
    lat, lon, alt = frames.ned_to_geodetic(p[0], p[1], p[2], home)
    f = frames.vector_to_ned(specific_force_body)
    to_mg = 1000.0 / STANDARD_GRAVITY_M_S2
    air = (velocity[0] - wind[0], velocity[1] - wind[1], velocity[2] - wind[2])
    airspeed = sat_u16(100.0 * math.sqrt(air[0] * air[0] + air[1] * air[1] + air[2] * air[2]))
    return (sat_i32(lat * 1e7), sat_i32(lon * 1e7), sat_i32(alt * 1000.0),
            sat_i16(v[0] * 100.0), sat_i16(v[1] * 100.0), sat_i16(v[2] * 100.0), airspeed,
            sat_i16(f[0] * to_mg), sat_i16(f[1] * to_mg), sat_i16(f[2] * to_mg))  # fmt: skip


@kernel
def frame_fields(position: Vector3, velocity: Vector3, quaternion, body_rates: Vector3,
                 specific_force_body: Vector3, wind: Vector3, home, imu_specific_force: Vector3,
                 imu_angular_rate: Vector3, magnetic_field: Vector3, pressure_altitude: float):  # fmt: skip
    """The fields a lockstep frame carries every frame, in one call (the simulator's encoder calls
    it compiled, instead of some forty roundings, scalings and sign flips in Python): HIL_SENSOR's
    ``(specific force, rates, field, pressure altitude)`` (FRD floats) of the sensors' readings,
    then of the truth (``position`` ... ``specific_force_body``, with the ``wind`` and the
    ``home``) ODOMETRY's :func:`odometry_values` (whose attitude and rates HIL_STATE_QUATERNION
    carries too) and HIL_STATE_QUATERNION's :func:`hil_state_values`."""
    return (vector_field(imu_specific_force), vector_field(imu_angular_rate), vector_field(magnetic_field),
            float_field(pressure_altitude), odometry_values(position, velocity, quaternion, body_rates),
            hil_state_values(position, velocity, specific_force_body, wind, home))  # fmt: skip


@kernel
def frame_records(sensor, state, odometry, time_usec: int, fields_updated: int, position: Vector3,
                  velocity: Vector3, quaternion, body_rates: Vector3, specific_force_body: Vector3,
                  wind: Vector3, home, imu_specific_force: Vector3, imu_angular_rate: Vector3,
                  magnetic_field: Vector3, pressure_hpa: float, pressure_altitude: float,
                  temperature: float) -> bool:  # fmt: skip
    """:func:`frame_fields` written into the payloads of the three messages every frame carries
    (byte buffers, each viewed as its message's record: :data:`HIL_SENSOR_RECORD`,
    :data:`HIL_STATE_RECORD`, :data:`ODOMETRY_RECORD`), with the frame's ``time_usec``, HIL_SENSOR's
    ``fields_updated`` and its barometer's pressure (hPa) and temperature (deg C); the fields not
    named here keep their values. False, and nothing written, when a float field would not fit a
    float32: ODOMETRY's position, velocity or rates not finite once rounded, or the pressure or the
    temperature finite and past float32's range (``struct`` refuses to pack those)."""
    force, rate, field, altitude, odometry_fields, hil = frame_fields(
        position, velocity, quaternion, body_rates, specific_force_body, wind, home, imu_specific_force,
        imu_angular_rate, magnetic_field, pressure_altitude,
    )  # fmt: skip
    p, v, q, w = odometry_fields
    if not math.isfinite(p[0] + p[1] + p[2] + v[0] + v[1] + v[2] + w[0] + w[1] + w[2]):
        return False
    for raw in (pressure_hpa, temperature):
        if math.isfinite(raw) and abs(raw) > FLOAT32_MAX:
            return False
    s = sensor.view(HIL_SENSOR_RECORD)[0]
    s["time_usec"] = time_usec
    s["xacc"], s["yacc"], s["zacc"] = force[0], force[1], force[2]
    s["xgyro"], s["ygyro"], s["zgyro"] = rate[0], rate[1], rate[2]
    s["xmag"], s["ymag"], s["zmag"] = field[0], field[1], field[2]
    s["abs_pressure"] = pressure_hpa
    s["pressure_alt"] = altitude
    s["temperature"] = temperature
    s["fields_updated"] = fields_updated
    # HIL_STATE_QUATERNION's attitude and rates are float fields too: ODOMETRY's, the same bits.
    h = state.view(HIL_STATE_RECORD)[0]
    h["time_usec"] = time_usec
    hq = h["attitude_quaternion"]
    hq[0], hq[1], hq[2], hq[3] = q[0], q[1], q[2], q[3]
    h["rollspeed"], h["pitchspeed"], h["yawspeed"] = w[0], w[1], w[2]
    lat, lon, alt, vn, ve, vd, airspeed, xacc, yacc, zacc = hil
    h["lat"], h["lon"], h["alt"] = lat, lon, alt
    h["vx"], h["vy"], h["vz"] = vn, ve, vd
    h["ind_airspeed"], h["true_airspeed"] = airspeed, airspeed
    h["xacc"], h["yacc"], h["zacc"] = xacc, yacc, zacc
    o = odometry.view(ODOMETRY_RECORD)[0]
    o["time_usec"] = time_usec
    o["x"], o["y"], o["z"] = p[0], p[1], p[2]
    oq = o["q"]
    oq[0], oq[1], oq[2], oq[3] = q[0], q[1], q[2], q[3]
    o["vx"], o["vy"], o["vz"] = v[0], v[1], v[2]
    o["rollspeed"], o["pitchspeed"], o["yawspeed"] = w[0], w[1], w[2]
    return True


@kernel
def attitude_from_fields(q_ned, rates_frd: Vector3):
    """A NED/FRD quaternion and FRD body rates (ODOMETRY, HIL_STATE_QUATERNION) as the autopilot
    reads them: ``(quaternion, ZYX Euler angles, Euler rates)`` in the paper's frames."""
    q = frames.quaternion_from_ned(q_ned)
    euler = euler_from_quaternion(q[0], q[1], q[2], q[3])
    return q, euler, euler_rates_from_body_rates(euler[0], euler[1], frames.vector_from_ned(rates_frd))


@kernel
def odometry_state(position_ned: Vector3, velocity_ned: Vector3, q_ned, rates_frd: Vector3):
    """ODOMETRY's fields with a world twist (``child_frame_id`` LOCAL_NED or LOCAL_FRD) as the
    state the controllers fly on: ``(position, velocity, Euler angles, Euler rates)``."""
    _, euler, euler_rates = attitude_from_fields(q_ned, rates_frd)
    return frames.vector_from_ned(position_ned), frames.vector_from_ned(velocity_ned), euler, euler_rates


@kernel
def vision_values(position: Vector3, yaw: float, position_std: float, yaw_std: float):
    """VISION_POSITION_ESTIMATE's fields of a motion-capture reading: ``(position NED, yaw NED,
    position variance, yaw variance)`` (the variances in the covariance's upper triangle)."""
    return (vector_field(position), float_field(frames.yaw_to_ned(yaw)),
            float_field(position_std * position_std), float_field(yaw_std * yaw_std))  # fmt: skip


@kernel
def vision_pose(position_ned: Vector3, yaw_ned: float, position_variance: float, yaw_variance: float):
    """VISION_POSITION_ESTIMATE's fields as the autopilot reads them: ``(position, yaw, position
    std, yaw std)`` in the paper's frames (a variance that is not positive reads as 0)."""
    return (frames.vector_from_ned(position_ned), frames.yaw_from_ned(yaw_ned),
            math.sqrt(position_variance) if position_variance > 0.0 else 0.0,
            math.sqrt(yaw_variance) if yaw_variance > 0.0 else 0.0)  # fmt: skip


# -------------------------------------------------------------------------------------------------
# HIL_GPS: scaled integers
# -------------------------------------------------------------------------------------------------
@kernel
def gps_values(position: Vector3, velocity: Vector3, eph: float, epv: float, home):
    """HIL_GPS's fields of a fix (paper frames, m, m/s) about ``home`` (lat deg, lon deg, alt m):
    ``(lat 1e-7 deg, lon 1e-7 deg, alt mm, eph cm, epv cm, ground speed cm/s, vn, ve, vd cm/s,
    course over ground cdeg in [0, 36000))``."""
    p = frames.vector_to_ned(position)
    v = frames.vector_to_ned(velocity)
    lat, lon, alt = frames.ned_to_geodetic(p[0], p[1], p[2], home)
    cog = round(math.degrees(math.atan2(v[1], v[0])) * 100.0) % 36000  # 0 = north, clockwise
    return (sat_i32(lat * 1e7), sat_i32(lon * 1e7), sat_i32(alt * 1000.0), sat_u16(eph * 100.0, 65534),
            sat_u16(epv * 100.0, 65534), sat_u16(100.0 * math.hypot(v[0], v[1]), 65534),
            sat_i16(v[0] * 100.0), sat_i16(v[1] * 100.0), sat_i16(v[2] * 100.0), cog)  # fmt: skip


@kernel
def gps_fix(lat: int, lon: int, alt: int, vn: int, ve: int, vd: int, eph: int, epv: int, home):
    """HIL_GPS's fields as the autopilot reads them: ``(position, velocity, eph m, epv m)`` in the
    paper's frames about ``home`` (an unknown accuracy reads as :data:`GPS_ACCURACY_UNKNOWN_M`)."""
    ned = frames.geodetic_to_ned(lat * 1e-7, lon * 1e-7, alt * 1e-3, home)
    return (frames.vector_from_ned(ned), frames.vector_from_ned((vn * 0.01, ve * 0.01, vd * 0.01)),
            eph * 0.01 if eph != GPS_UNKNOWN_ACCURACY else GPS_ACCURACY_UNKNOWN_M,
            epv * 0.01 if epv != GPS_UNKNOWN_ACCURACY else GPS_ACCURACY_UNKNOWN_M)  # fmt: skip


# -------------------------------------------------------------------------------------------------
# The entries Python calls every frame
# -------------------------------------------------------------------------------------------------
_Z3 = (0.0, 0.0, 0.0)
_HOME = (0.0, 0.0, 0.0)

# The kernels the processes' encoder and decoder call from Python, each with the argument types it
# is called with (tuples of floats; HIL_GPS's integers as Python ints): warmed once, then frozen.
FRAME_ENTRIES = {
    frame_records: (*(np.zeros(r.itemsize, np.uint8) for r in (HIL_SENSOR_RECORD, HIL_STATE_RECORD,
                                                                ODOMETRY_RECORD)), 0, 0, _Z3, _Z3,
                    (1.0, 0.0, 0.0, 0.0), _Z3, _Z3, _Z3, _HOME, _Z3, _Z3, _Z3, 0.0, 0.0, 0.0),  # fmt: skip
    odometry_state: (_Z3, _Z3, (1.0, 0.0, 0.0, 0.0), _Z3),
    vision_values: (_Z3, 0.0, 0.0, 0.0),
    vision_pose: (_Z3, 0.0, 0.0, 0.0),
    gps_values: (_Z3, _Z3, 0.0, 0.0, _HOME),
    gps_fix: (0, 0, 0, 0, 0, 0, 0, 0, _HOME),
}


@functools.cache
def entry(fn: Callable[..., Any]) -> Callable[..., Any]:
    """``fn`` (one of :data:`FRAME_ENTRIES`) as the processes call it every frame: compiled (or
    loaded from numba's cache) and run once on its warm-up arguments, then frozen, so a flight
    never waits for a compilation (the Python kernel itself where nothing compiles). A compiled
    call is a fraction of a microsecond where the kernel run by Python takes two."""
    return warmed(fn, *FRAME_ENTRIES[fn])
