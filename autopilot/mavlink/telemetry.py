"""Telemetry to ground stations: what each message says, and how often (simulation time).

Messages are built from :class:`VehicleStatus` (paper frames inside, NED/FRD and MAVLink units
only here). :data:`STREAMS` is the one table of the messages the vehicle streams and sends on
request: each one's builder, its default rate and what it is built from, which decides whether a
request for it is granted (:func:`stream_refusal`). Each GCS link has its own :class:`StreamTable`:
PX4-like default rates, changed by ``MAV_CMD_SET_MESSAGE_INTERVAL``; intervals count simulation
time (lockstep), so at ``--speed 4`` a 1 Hz HEARTBEAT arrives 4 times per wall second, as in PX4
SITL, and no stream runs faster than the control frames (one message per frame at most).

(One module: each row of :data:`STREAMS` names its message's builder, rate and what it is built
from, beside the builder; split, what one message says and when it is sent would be read in two
places.)
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NamedTuple

from quadcommon import frames
from quadcommon.mavlink_fast import MessageParts
from quadcommon.rigid_body import quaternion_from_euler
from quadcommon.trajectories import Reference
from quadcommon.wire import sat_i16, sat_i32, sat_u16

from ..battery.estimator import (
    CURRENT_UNKNOWN,
    WARNING_CRITICAL,
    WARNING_EMERGENCY,
    WARNING_LOW,
    BatteryStatus,
)
from ..commander.health import FailsafeFlags
from ..estimation.status import EstimatorStatus
from ..guidance.orbit import OrbitStatus
from ..records import GpsFix, StateEstimate
from .codec import mavlink
from .hil import ground_truth, sensor_fields

m = mavlink
Vector3 = tuple[float, float, float]

# onboard_control_sensors bits reported in SYS_STATUS
SENSORS_PRESENT = (
    m.MAV_SYS_STATUS_SENSOR_3D_GYRO
    | m.MAV_SYS_STATUS_SENSOR_3D_ACCEL
    | m.MAV_SYS_STATUS_SENSOR_3D_MAG
    | m.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
    | m.MAV_SYS_STATUS_SENSOR_GPS
    | m.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL
    | m.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION
    | m.MAV_SYS_STATUS_SENSOR_YAW_POSITION
    | m.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL
    | m.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
    | m.MAV_SYS_STATUS_SENSOR_MOTOR_OUTPUTS
    | m.MAV_SYS_STATUS_AHRS
    | m.MAV_SYS_STATUS_PREARM_CHECK
)

# The sensors' bits, by the health record's names (commander/health.py): present once a sensor has
# delivered a sample, healthy while it is (PX4 sets them from its sensor and estimator checks).
SENSOR_BITS = {
    "gyro": m.MAV_SYS_STATUS_SENSOR_3D_GYRO, "accel": m.MAV_SYS_STATUS_SENSOR_3D_ACCEL,
    "mag": m.MAV_SYS_STATUS_SENSOR_3D_MAG, "baro": m.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE,
    "gps": m.MAV_SYS_STATUS_SENSOR_GPS, "vision": m.MAV_SYS_STATUS_SENSOR_VISION_POSITION,
}  # fmt: skip
ALL_SENSOR_BITS = sum(SENSOR_BITS.values())
# The control bits and what their health needs (a flag of the record that must be False).
CONTROL_NEEDS = {
    m.MAV_SYS_STATUS_SENSOR_ANGULAR_RATE_CONTROL: "angular_velocity_invalid",
    m.MAV_SYS_STATUS_SENSOR_ATTITUDE_STABILIZATION: "attitude_invalid",
    m.MAV_SYS_STATUS_SENSOR_YAW_POSITION: "heading_invalid",
    m.MAV_SYS_STATUS_SENSOR_Z_ALTITUDE_CONTROL: "local_altitude_invalid",
    m.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL: "local_position_invalid",
    m.MAV_SYS_STATUS_AHRS: "attitude_invalid",
}

@dataclass
class VehicleStatus:
    """Everything telemetry reports, refreshed by the autopilot shell every control frame."""

    system_id: int
    time_usec: int = 0
    state: StateEstimate | None = None
    armed: bool = False
    custom_mode: int = 0
    landed_state: int = m.MAV_LANDED_STATE_ON_GROUND
    home_local: Vector3 = (0.0, 0.0, 0.0)  # paper frame
    home_geodetic: tuple[float, float, float] = (0.0, 0.0, 0.0)  # the configured origin
    reference: Reference | None = None
    euler_ref: Vector3 = (0.0, 0.0, 0.0)
    thrust_normalised: float = 0.0
    controls: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    wrench: bool = True
    armable: bool = False
    geofence_enabled: bool = False
    geofence_breached: bool = False
    flight_sw_version: int = 0x01000000
    on_ekf: bool = False  # flying on the EKF (EKF2_EN 1), else on the simulator's truth
    estimator: EstimatorStatus | None = None  # flying on the EKF: its last status (else None)
    # The latest lockstep frame's messages by id, undecoded (autopilot.mavlink.hil.Frame.parts):
    # HIGHRES_IMU and the ground truth are decoded from them when one is sent.
    parts: MessageParts | None = None
    battery: BatteryStatus | None = None  # the battery's estimate (None: no battery has reported)
    battery_unhealthy: bool = False  # its reports stopped
    flags: FailsafeFlags | None = None  # the commander's failsafe flags and sensor health (None: none yet)
    failsafe: bool = False  # a failsafe action is in force (HEARTBEAT: MAV_STATE_CRITICAL)
    terminated: bool = False  # the flight was terminated (HEARTBEAT: MAV_STATE_FLIGHT_TERMINATION)
    gps: GpsFix | None = None  # the receiver's last sample (GPS_RAW_INT)
    orbit: OrbitStatus | None = None  # the orbit flown (None: not in Orbit)
    extra: dict = field(default_factory=dict)

    @property
    def time_boot_ms(self) -> int:
        """The frame's time since boot in ms, as a uint32 (wraps after 49.7 days, as on PX4)."""
        return (self.time_usec // 1000) & 0xFFFFFFFF  # uint32: wraps after 49.7 days, as on PX4


# -- message builders --------------------------------------------------------------------------------
def heartbeat(s: VehicleStatus):
    """HEARTBEAT as PX4 sends it: quadrotor, MAV_AUTOPILOT_PX4, the custom mode, armed flag; MAV_STATE_STANDBY
    or ACTIVE, CRITICAL in a failsafe, FLIGHT_TERMINATION once terminated."""
    base = m.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (m.MAV_MODE_FLAG_SAFETY_ARMED if s.armed else 0)
    state = m.MAV_STATE_ACTIVE if s.armed else m.MAV_STATE_STANDBY
    if s.armed and s.failsafe:  # PX4: vehicle_status.failsafe
        state = m.MAV_STATE_CRITICAL
    if s.terminated:  # PX4: NAVIGATION_STATE_TERMINATION
        state = m.MAV_STATE_FLIGHT_TERMINATION
    return m.MAVLink_heartbeat_message(
        m.MAV_TYPE_QUADROTOR, m.MAV_AUTOPILOT_PX4, base, s.custom_mode, state, 3
    )


def sys_status(s: VehicleStatus):
    """SYS_STATUS: the sensors and controls present, enabled and healthy (from the failsafe flags and the
    estimator, PX4's rules), the pre-arm bit, geofence and battery (MAVLink's unknown without one)."""
    health = SENSORS_PRESENT if s.armable or s.armed else SENSORS_PRESENT & ~m.MAV_SYS_STATUS_PREARM_CHECK
    if s.state is None:
        health &= ~(m.MAV_SYS_STATUS_SENSOR_GPS | m.MAV_SYS_STATUS_AHRS)
    est = s.estimator
    if est is not None and not est.converged:  # PX4: the AHRS bit follows the estimator's health
        health &= ~(m.MAV_SYS_STATUS_AHRS | m.MAV_SYS_STATUS_PREARM_CHECK)
        if est.dead_reckoning or est.gps_glitch:
            health &= ~m.MAV_SYS_STATUS_SENSOR_GPS
    present = enabled = SENSORS_PRESENT
    flags = s.flags
    if flags is not None:  # each sensor as the autopilot sees it; each control as its estimate allows
        present = enabled = (SENSORS_PRESENT & ~ALL_SENSOR_BITS) | _sensor_bits(flags, present=True)
        health = (health & ~ALL_SENSOR_BITS) | _sensor_bits(flags, present=False)
        for bit, needs in CONTROL_NEEDS.items():
            if getattr(flags, needs):
                health &= ~bit
        if est is not None and (est.dead_reckoning or est.gps_glitch):
            health &= ~m.MAV_SYS_STATUS_SENSOR_GPS
    if s.geofence_enabled:
        present |= m.MAV_SYS_STATUS_GEOFENCE
        enabled |= m.MAV_SYS_STATUS_GEOFENCE
    # The geofence bit reads healthy unless breached (also when no fence is set: MAVProxy's fence
    # module otherwise announces "fence breach" on connecting).
    if not s.geofence_breached:
        health |= m.MAV_SYS_STATUS_GEOFENCE
    b = s.battery
    millivolts, centiamps, percent = 65535, -1, -1  # MAVLink's "unknown": no battery
    if b is not None:
        present |= m.MAV_SYS_STATUS_SENSOR_BATTERY
        enabled |= m.MAV_SYS_STATUS_SENSOR_BATTERY
        if battery_healthy(s):
            health |= m.MAV_SYS_STATUS_SENSOR_BATTERY
        millivolts, centiamps, percent = _battery_numbers(b)
    return m.MAVLink_sys_status_message(
        present, enabled, health, 250, millivolts, centiamps, percent, 0, 0, 0, 0, 0, 0
    )


def battery_healthy(s: VehicleStatus) -> bool:
    """The battery's health bit (PX4's health report): reporting, connected, no fault, above the
    critical level."""
    b = s.battery
    return (b is not None and b.connected and not s.battery_unhealthy and not b.faults
            and b.warning < WARNING_CRITICAL)  # fmt: skip


def _battery_numbers(b: BatteryStatus) -> tuple[int, int, int]:
    """SYS_STATUS's voltage (mV), current (cA, -1 unknown) and remaining charge (%, -1 unknown)."""
    millivolts = sat_u16(b.voltage_v * 1000.0)
    centiamps = sat_i16(b.current_a * 100.0) if b.current_a != CURRENT_UNKNOWN else -1
    percent = min(round(100.0 * b.remaining), 100) if b.remaining >= 0.0 and b.connected else -1
    return millivolts, centiamps, percent


_CHARGE_STATES = {
    WARNING_LOW: m.MAV_BATTERY_CHARGE_STATE_LOW,
    WARNING_CRITICAL: m.MAV_BATTERY_CHARGE_STATE_CRITICAL,
    WARNING_EMERGENCY: m.MAV_BATTERY_CHARGE_STATE_EMERGENCY,
}
_CELL_MAX_MV = 65534  # BATTERY_STATUS voltages[0]: above it, the rest goes to voltages[1]


def battery_status(s: VehicleStatus):
    """BATTERY_STATUS of the battery's estimate (PX4's fields): the pack's voltage in voltages[0]
    (MAVLink's split above 65 534 mV), current, consumed mAh, remaining %, time remaining, the
    charge state of the warning level (unhealthy: stale reports or a fault) and the fault bits;
    None until a battery has reported."""
    b = s.battery
    if b is None:
        return None
    millivolts, centiamps, percent = _battery_numbers(b)
    total_mv = sat_u16(b.voltage_v * 1000.0, 2 * _CELL_MAX_MV)
    cells = [65535] * 10
    if total_mv > _CELL_MAX_MV:
        cells[0], cells[1] = _CELL_MAX_MV, total_mv - _CELL_MAX_MV
    else:
        cells[0] = total_mv
    consumed = round(b.discharged_mah) if b.current_a != CURRENT_UNKNOWN else -1
    remaining_s = sat_i32(b.time_remaining_s) if math.isfinite(b.time_remaining_s) else 0
    if s.battery_unhealthy or b.faults:
        state = m.MAV_BATTERY_CHARGE_STATE_UNHEALTHY
    else:
        state = _CHARGE_STATES.get(b.warning, m.MAV_BATTERY_CHARGE_STATE_OK)
    return m.MAVLink_battery_status_message(
        0, m.MAV_BATTERY_FUNCTION_ALL, m.MAV_BATTERY_TYPE_LIPO, 32767, cells, centiamps, consumed, -1,
        percent, max(remaining_s, 0), state, [0, 0, 0, 0], 0, b.faults,
    )  # fmt: skip


def _sensor_bits(flags: FailsafeFlags, present: bool) -> int:
    """The bits of the sensors present (``present``) or present and healthy."""
    out = 0
    for name, bit in SENSOR_BITS.items():
        sensor = flags.sensor(name)
        if sensor.present and (present or sensor.healthy):
            out |= bit
    return out


def extended_sys_state(s: VehicleStatus):
    """EXTENDED_SYS_STATE: no VTOL state, the commander's MAV_LANDED_STATE."""
    return m.MAVLink_extended_sys_state_message(m.MAV_VTOL_STATE_UNDEFINED, s.landed_state)


def _ned_state(s: VehicleStatus):
    st = s.state
    return (
        frames.vector_to_ned(st.position_m),
        frames.vector_to_ned(st.velocity_m_s),
        frames.euler_to_ned(st.euler_rad),
    )


def _body_rates_frd(st: StateEstimate) -> Vector3:
    from quadcommon.rigid_body import body_rates_from_euler_rates

    omega = body_rates_from_euler_rates(st.euler_rad[0], st.euler_rad[1], st.euler_rates_rad_s)
    return frames.vector_to_ned(omega)


def attitude(s: VehicleStatus):
    """ATTITUDE: roll, pitch, yaw (rad, NED) and the body rates (rad/s, FRD) of the state flown on."""
    _, _, eta = _ned_state(s)
    p, q, r = _body_rates_frd(s.state)
    return m.MAVLink_attitude_message(s.time_boot_ms, eta[0], eta[1], eta[2], p, q, r)


def attitude_quaternion(s: VehicleStatus):
    """ATTITUDE_QUATERNION: the NED/FRD attitude quaternion and the body rates (rad/s, FRD)."""
    q = frames.quaternion_to_ned(quaternion_from_euler(*s.state.euler_rad))
    p, qq, r = _body_rates_frd(s.state)
    return m.MAVLink_attitude_quaternion_message(s.time_boot_ms, *q, p, qq, r, [0.0, 0.0, 0.0, 0.0])


def local_position_ned(s: VehicleStatus):
    """LOCAL_POSITION_NED: position (m) and velocity (m/s) in NED from the local origin."""
    pos, vel, _ = _ned_state(s)
    return m.MAVLink_local_position_ned_message(s.time_boot_ms, *pos, *vel)


def _geodetic(s: VehicleStatus, position_paper: Vector3):
    n, e, d = frames.vector_to_ned(position_paper)
    return frames.ned_to_geodetic(n, e, d, s.home_geodetic)


def _heading_cdeg(psi: float) -> int:
    return sat_i32(math.degrees(frames.yaw_to_ned(psi)) * 100.0) % 36000


def global_position_int(s: VehicleStatus):
    """GLOBAL_POSITION_INT: latitude, longitude (degE7), altitude AMSL and above home (mm), NED velocity
    (cm/s) and heading (cdeg)."""
    pos, vel, _ = _ned_state(s)
    lat, lon, alt = _geodetic(s, s.state.position_m)
    home_alt = _geodetic(s, s.home_local)[2]
    return m.MAVLink_global_position_int_message(
        s.time_boot_ms,
        sat_i32(lat * 1e7),
        sat_i32(lon * 1e7),
        sat_i32(alt * 1000),
        sat_i32((alt - home_alt) * 1000),
        *(sat_i16(v * 100) for v in vel),
        _heading_cdeg(s.state.euler_rad[2]),
    )


def gps_raw_int(s: VehicleStatus):
    """The receiver's last sample, as PX4 reports its GPS: fix type, position, eph/epv, velocity and
    satellites of the fix; no receiver (never a sample): GPS_FIX_TYPE_NO_GPS; a receiver gone
    silent: its last position with GPS_FIX_TYPE_NO_FIX and no satellites."""
    fix = s.gps
    if fix is None:
        return m.MAVLink_gps_raw_int_message(s.time_usec, m.GPS_FIX_TYPE_NO_GPS, 0, 0, 0, 65535, 65535,
                                             65535, 65535, 255)  # fmt: skip
    stopped = s.flags is not None and s.flags.gps.problem == "stopped"
    vel = frames.vector_to_ned(fix.velocity_m_s)
    lat, lon, alt = _geodetic(s, fix.position_m)
    speed = math.hypot(vel[0], vel[1])
    cog = sat_i32(math.degrees(math.atan2(vel[1], vel[0])) * 100) % 36000 if speed > 0.2 else 65535
    return m.MAVLink_gps_raw_int_message(
        s.time_usec,
        m.GPS_FIX_TYPE_NO_FIX if stopped else fix.fix_type,
        sat_i32(lat * 1e7),
        sat_i32(lon * 1e7),
        sat_i32(alt * 1000),
        sat_u16(fix.eph_m * 100.0),
        sat_u16(fix.epv_m * 100.0),
        sat_u16(speed * 100),
        cog,
        0 if stopped else fix.satellites_visible,
    )


def home_position(s: VehicleStatus):
    """HOME_POSITION: home geodetic (degE7, mm) and in the local NED frame (m), identity approach
    quaternion."""
    lat, lon, alt = _geodetic(s, s.home_local)
    x, y, z = frames.vector_to_ned(s.home_local)
    return m.MAVLink_home_position_message(
        sat_i32(lat * 1e7),
        sat_i32(lon * 1e7),
        sat_i32(alt * 1000),
        x,
        y,
        z,
        [1.0, 0.0, 0.0, 0.0],
        0.0,
        0.0,
        0.0,
        s.time_usec,
    )


def attitude_target(s: VehicleStatus):
    """ATTITUDE_TARGET: eta_d as the NED/FRD quaternion (body rates ignored) and the normalised thrust."""
    q = frames.quaternion_to_ned(quaternion_from_euler(*s.euler_ref))
    ignore_rates = 7  # body roll/pitch/yaw rates not set: the target is an attitude
    return m.MAVLink_attitude_target_message(
        s.time_boot_ms, ignore_rates, list(q), 0.0, 0.0, 0.0, s.thrust_normalised
    )


def position_target_local_ned(s: VehicleStatus):
    """POSITION_TARGET_LOCAL_NED: the reference (position, velocity, acceleration, yaw, yaw rate) in NED; None
    without a reference."""
    ref = s.reference
    if ref is None:
        return None
    pos = frames.vector_to_ned(ref.position_m)
    vel = frames.vector_to_ned(ref.velocity_m_s)
    acc = frames.vector_to_ned(ref.acceleration_m_s2)
    return m.MAVLink_position_target_local_ned_message(
        s.time_boot_ms,
        m.MAV_FRAME_LOCAL_NED,
        0,
        *pos,
        *vel,
        *acc,
        frames.yaw_to_ned(ref.yaw_rad),
        frames.yaw_to_ned(ref.yaw_rate_rad_s),
    )


def _pwm(s: VehicleStatus) -> list[int]:
    """Outputs as PWM microseconds: rotors (or U1) 1000-2000; wrench torques 1500 +- 500."""
    c = s.controls if s.armed else (0.0, 0.0, 0.0, 0.0)
    if s.wrench:
        values = [1000 + 1000 * c[0], *(1500 + 500 * v for v in c[1:4])]
        if not s.armed:
            values = [900, 1500, 1500, 1500]
    else:
        values = [1000 + 1000 * v for v in c] if s.armed else [900] * 4
    return [sat_u16(v) for v in values] + [0] * 4


def servo_output_raw(s: VehicleStatus):
    """SERVO_OUTPUT_RAW: the actuator controls as PWM microseconds (rotors 1000-2000, wrench torques
    1500 +- 500; disarmed: 900 and 1500)."""
    return m.MAVLink_servo_output_raw_message(s.time_usec & 0xFFFFFFFF, 0, *_pwm(s))


def actuator_output_status(s: VehicleStatus):
    """ACTUATOR_OUTPUT_STATUS: the four normalised actuator controls (zero while disarmed)."""
    values = list(s.controls if s.armed else (0.0, 0.0, 0.0, 0.0)) + [0.0] * 28
    return m.MAVLink_actuator_output_status_message(s.time_usec, 4, values)


def vfr_hud(s: VehicleStatus):
    """VFR_HUD: ground speed as airspeed (no wind model), heading (deg), throttle (%), altitude above the
    origin and climb rate (m/s, up)."""
    _, vel, _ = _ned_state(s)
    speed = math.hypot(vel[0], vel[1])
    heading = _heading_cdeg(s.state.euler_rad[2]) // 100
    throttle = sat_u16(100 * s.thrust_normalised) if s.armed else 0
    climb = s.state.velocity_m_s[2]  # z up: the paper's frame is already VFR_HUD's sign
    return m.MAVLink_vfr_hud_message(speed, speed, heading, throttle, s.state.position_m[2], climb)


def estimator_status(s: VehicleStatus):
    """ESTIMATOR_STATUS of the EKF (PX4's fields: flags, test ratios, accuracies); None on truth."""
    e = s.estimator
    if e is None:
        return None
    f = _finite_or
    return m.MAVLink_estimator_status_message(
        s.time_usec, e.flags, f(e.vel_ratio), f(e.pos_horiz_ratio), f(e.pos_vert_ratio), f(e.mag_ratio),
        0.0, 0.0, f(e.pos_horiz_accuracy_m, 1e3), f(e.pos_vert_accuracy_m, 1e3),
    )  # fmt: skip


def _finite_or(value: float, fallback: float = 0.0) -> float:
    return value if math.isfinite(value) else fallback


def odometry(s: VehicleStatus):
    """The estimate as ODOMETRY (local NED, world-frame twist, FRD rates), on request."""
    pos, vel, _ = _ned_state(s)
    q = frames.quaternion_to_ned(quaternion_from_euler(*s.state.euler_rad))
    p, qq, r = _body_rates_frd(s.state)
    unknown = [math.nan] + [0.0] * 20
    estimator = m.MAV_ESTIMATOR_TYPE_NAIVE if s.estimator is None else m.MAV_ESTIMATOR_TYPE_AUTOPILOT
    return m.MAVLink_odometry_message(
        s.time_usec, m.MAV_FRAME_LOCAL_NED, m.MAV_FRAME_LOCAL_NED, *pos, list(q), *vel, p, qq, r,
        unknown, unknown, 0, estimator, 100,
    )  # fmt: skip


_HIGHRES_BITS = (  # HIGHRES_IMU_UPDATED_FLAGS of each group of fields, as HIL_SENSOR's fields_updated
    (0, 6, 0b111111),  # x/y/z acc, x/y/z gyro
    (6, 9, 0b111 << 6),  # x/y/z mag
    (9, 10, 1 << 9),  # abs_pressure
    (11, 12, 1 << 11),  # pressure_alt
    (12, 13, 1 << 12),  # temperature
)


def highres_imu(s: VehicleStatus):
    """The sensors as PX4 reports them (MAVSDK's Telemetry.imu), whatever the vehicle flies on:
    the latest lockstep frame's HIL_SENSOR (the IMU sample of that frame, the magnetometer's and
    the barometer's latest samples, which HIL_SENSOR carries in every frame), FRD body axes. A group
    of fields that is not finite goes out as 0 with its ``fields_updated`` bits clear; there is no
    airspeed sensor (``diff_pressure`` 0, its bit clear). None without a HIL_SENSOR in the frame."""
    values = sensor_fields(s.parts) if s.parts is not None else None
    if values is None:
        return None
    updated = 0
    for first, end, bits in _HIGHRES_BITS:
        if all(math.isfinite(v) for v in values[first:end]):
            updated |= bits
        else:
            values[first:end] = [0.0] * (end - first)
    values[10] = 0.0  # diff_pressure: no airspeed sensor
    return m.MAVLink_highres_imu_message(s.time_usec, *values, updated, 0)


def orbit_execution_status(s: VehicleStatus):
    """The orbit flown, as PX4 reports it: signed radius (> 0 clockwise), MAV_FRAME_GLOBAL, the
    centre's latitude/longitude (1e-7 deg) and altitude (m AMSL); None while not in Orbit."""
    o = s.orbit
    if o is None:
        return None
    lat, lon, alt = _geodetic(s, o.centre_m)
    return m.MAVLink_orbit_execution_status_message(s.time_usec, o.radius_m, m.MAV_FRAME_GLOBAL,
                                                    sat_i32(lat * 1e7), sat_i32(lon * 1e7), alt)  # fmt: skip


def hil_state_quaternion(s: VehicleStatus):
    """The ground truth on request, as PX4 SITL serves it (its HIL_STATE_QUATERNION stream, from
    the simulator's groundtruth): the simulator's own HIL_STATE_QUATERNION of the latest lockstep
    frame (lat/lon 1e-7 deg and alt mm AMSL of the vehicle, attitude, body rates, NED velocity,
    specific force), whatever the vehicle flies on. MAVSDK's Telemetry.ground_truth reads its
    lat, lon and alt."""
    return ground_truth(s.parts) if s.parts is not None else None


# What a stream is built from; while it is not there the stream sends nothing. A request for a
# stream whose source this vehicle cannot have is refused (stream_refusal).
ALWAYS, STATE, REFERENCE, BATTERY, EKF, SENSORS, TRUTH = (
    "always", "state", "reference", "battery", "ekf", "sensors", "truth"
)  # fmt: skip
ORBITING = "orbiting"
SENT_WHILE = {  # (the docs' table)
    ALWAYS: "always",
    STATE: "the vehicle has a state (its first frame; on the EKF: aligned)",
    REFERENCE: "it flies to a target (armed, in a flying mode)",
    BATTERY: "a battery has reported",
    EKF: "it flies on the EKF (`EKF2_EN` 1); refused on the truth",
    SENSORS: "the frames carry `HIL_SENSOR` (whatever the vehicle flies on); refused otherwise",
    TRUTH: "the frames carry `HIL_STATE_QUATERNION` (whatever the vehicle flies on); refused otherwise",
    ORBITING: "it flies the Orbit mode",
}
_NEEDS_PART = {SENSORS: mavlink.MAVLINK_MSG_ID_HIL_SENSOR, TRUTH: mavlink.MAVLINK_MSG_ID_HIL_STATE_QUATERNION}


class Stream(NamedTuple):
    """One message the vehicle streams and sends on request."""

    build: Callable[[VehicleStatus], object]  # the message now, or None while it cannot be built
    default_hz: float  # on every GCS link from the start (0: off until requested)
    needs: str  # what it is built from (ALWAYS, STATE, ...: SENT_WHILE says when it is sent)


STREAMS: dict[int, Stream] = {  # PX4's "normal" stream set, roughly, and what it sends on request
    m.MAVLINK_MSG_ID_HEARTBEAT: Stream(heartbeat, 1.0, ALWAYS),
    m.MAVLINK_MSG_ID_SYS_STATUS: Stream(sys_status, 1.0, ALWAYS),
    m.MAVLINK_MSG_ID_EXTENDED_SYS_STATE: Stream(extended_sys_state, 1.0, ALWAYS),
    m.MAVLINK_MSG_ID_ATTITUDE: Stream(attitude, 20.0, STATE),
    m.MAVLINK_MSG_ID_ATTITUDE_QUATERNION: Stream(attitude_quaternion, 10.0, STATE),
    m.MAVLINK_MSG_ID_LOCAL_POSITION_NED: Stream(local_position_ned, 30.0, STATE),
    m.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: Stream(global_position_int, 10.0, STATE),
    m.MAVLINK_MSG_ID_GPS_RAW_INT: Stream(gps_raw_int, 5.0, STATE),
    m.MAVLINK_MSG_ID_HOME_POSITION: Stream(home_position, 0.5, ALWAYS),
    m.MAVLINK_MSG_ID_ATTITUDE_TARGET: Stream(attitude_target, 10.0, STATE),
    m.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED: Stream(position_target_local_ned, 10.0, REFERENCE),
    m.MAVLINK_MSG_ID_SERVO_OUTPUT_RAW: Stream(servo_output_raw, 10.0, ALWAYS),
    m.MAVLINK_MSG_ID_ACTUATOR_OUTPUT_STATUS: Stream(actuator_output_status, 0.0, ALWAYS),
    m.MAVLINK_MSG_ID_VFR_HUD: Stream(vfr_hud, 4.0, STATE),
    m.MAVLINK_MSG_ID_BATTERY_STATUS: Stream(battery_status, 0.5, BATTERY),  # PX4's rate
    m.MAVLINK_MSG_ID_ESTIMATOR_STATUS: Stream(estimator_status, 1.0, EKF),
    m.MAVLINK_MSG_ID_ODOMETRY: Stream(odometry, 0.0, STATE),
    m.MAVLINK_MSG_ID_HIGHRES_IMU: Stream(highres_imu, 0.0, SENSORS),
    m.MAVLINK_MSG_ID_HIL_STATE_QUATERNION: Stream(hil_state_quaternion, 0.0, TRUTH),
    m.MAVLINK_MSG_ID_ORBIT_EXECUTION_STATUS: Stream(orbit_execution_status, 2.0, ORBITING),  # PX4's rate
}
BUILDERS = {msg_id: stream.build for msg_id, stream in STREAMS.items()}  # (a test replaces one)
DEFAULT_RATES_HZ = {msg_id: stream.default_hz for msg_id, stream in STREAMS.items()}


def stream_refusal(msg_id: int, status: VehicleStatus) -> str | None:
    """Why a request for ``msg_id`` (SET_MESSAGE_INTERVAL, REQUEST_MESSAGE) is refused, or None:
    a message the vehicle does not send, ESTIMATOR_STATUS while it flies on the truth, a message
    built from a part the simulator's frames do not carry. A granted stream is sent at its rate
    while what it is built from is there (:attr:`Stream.needs`: a state, a reference, a battery
    report)."""
    stream = STREAMS.get(msg_id)
    if stream is None:
        entry = m.mavlink_map.get(msg_id)
        name = entry.msgname if entry is not None else f"message {msg_id}"
        return f"{name}: not sent by this vehicle"
    name = m.mavlink_map[msg_id].msgname
    if stream.needs == EKF and not status.on_ekf:
        return f"{name}: no estimator, the vehicle flies on the simulator's truth (EKF2_EN 0)"
    part = _NEEDS_PART.get(stream.needs)
    if part is not None and status.parts is not None and part not in status.parts:
        return f"{name}: the simulator's frames carry no {m.mavlink_map[part].msgname}"
    return None


def streams_table() -> str:
    """:data:`STREAMS` as a Markdown table (the one in docs/compatibility.md)."""
    rows = ["| message | id | default rate | sent while |", "|---|---:|---|---|"]
    for msg_id, stream in sorted(STREAMS.items()):
        rate = f"{stream.default_hz:g} Hz" if stream.default_hz > 0.0 else "on request"
        rows.append(f"| `{m.mavlink_map[msg_id].msgname}` | {msg_id} | {rate} | {SENT_WHILE[stream.needs]} |")
    return "\n".join(rows)


STATUSTEXT_CHUNK = 50  # bytes of text per STATUSTEXT
STATUSTEXT_MAX = 200  # longer texts are cut (4 chunks)


def statustext_messages(severity: int, text: str, ident: int) -> list:
    """STATUSTEXT for ``text``: one message, or 50-byte chunks sharing ``ident`` (MAVLink 2's rule:
    ``id`` 0 for a single message, ``chunk_seq`` 0, 1, ...)."""
    raw = text.encode("utf-8")[:STATUSTEXT_MAX]
    chunks = [raw[i : i + STATUSTEXT_CHUNK] for i in range(0, len(raw), STATUSTEXT_CHUNK)] or [b""]
    if len(chunks) > 1 and len(chunks[-1]) == STATUSTEXT_CHUNK:
        chunks.append(b"")  # a last chunk shorter than 50 bytes ends the text (its NUL)
    ident = ident if len(chunks) > 1 else 0
    return [m.MAVLink_statustext_message(severity, chunk, ident, seq) for seq, chunk in enumerate(chunks)]


def build(msg_id: int, status: VehicleStatus):
    """The message ``msg_id`` describing ``status`` now, or None if it cannot be built yet."""
    builder = BUILDERS.get(msg_id)
    if builder is None or (STREAMS[msg_id].needs == STATE and status.state is None):
        return None
    return builder(status)


class StreamTable:
    """Per-link stream intervals (simulation time) and when each message is next due.
    ``frame_period_s``: the control frames' period, the shortest interval a stream can have (one
    message per frame); a shorter one asked for is granted at it."""

    def __init__(self, frame_period_s: float = 0.0) -> None:
        self.frame_period_s = frame_period_s
        self.interval_s: dict[int, float] = {}
        self.next_due: dict[int, float] = {}
        self._earliest = 0.0  # min(next_due): most frames nothing is due and due() returns at once
        for msg_id, hz in DEFAULT_RATES_HZ.items():
            self.set_rate(msg_id, hz)

    def set_rate(self, msg_id: int, hz: float, now: float = 0.0) -> None:
        """Stream ``msg_id`` at ``hz`` from ``now`` (first due at once), no faster than one per frame; 0 or
        less stops it."""
        if hz <= 0.0:
            self.interval_s.pop(msg_id, None)
            self.next_due.pop(msg_id, None)
        else:
            self.interval_s[msg_id] = max(1.0 / hz, self.frame_period_s)
            self.next_due[msg_id] = now
            self._earliest = min(self._earliest, now)

    def set_interval_us(self, msg_id: int, interval_us: float, now: float) -> bool:
        """MAV_CMD_SET_MESSAGE_INTERVAL semantics: -1 off, 0 default, >0 interval (µs); False for a
        message that is not one of :data:`STREAMS`."""
        if msg_id not in STREAMS:
            return False
        if interval_us == 0:
            self.set_rate(msg_id, DEFAULT_RATES_HZ[msg_id], now)
        elif interval_us < 0:
            self.set_rate(msg_id, 0.0, now)
        else:
            self.set_rate(msg_id, 1e6 / interval_us, now)
        return True

    def interval_us(self, msg_id: int) -> int:
        """MESSAGE_INTERVAL's ``interval_us`` for ``msg_id``: the interval granted (µs), -1 for a
        stream that is off, 0 for a message that is not one of :data:`STREAMS`."""
        if msg_id not in STREAMS:
            return 0
        interval = self.interval_s.get(msg_id)
        return -1 if interval is None else round(interval * 1e6)

    def restart(self) -> None:
        """Every stream due now: the simulation clock started again (a restarted simulator)."""
        for msg_id in self.next_due:
            self.next_due[msg_id] = 0.0
        self._earliest = 0.0

    def due(self, now: float) -> list[int]:
        """Message ids due at ``now``; their next due times advance by one interval."""
        if now + 1e-9 < self._earliest:
            return []
        ready = []
        next_due = self.next_due
        for msg_id, due in next_due.items():
            if now + 1e-9 >= due:
                ready.append(msg_id)
                interval = self.interval_s[msg_id]
                nxt = due + interval
                next_due[msg_id] = nxt if nxt > now else now + interval
        self._earliest = min(next_due.values(), default=math.inf)
        return ready
