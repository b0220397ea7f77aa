"""What the flight log holds: the topics, their fields and rates, and their samples built from a frame.

PX4's topics keep PX4's names, fields and units (NED world, FRD body, radians, metres; a subset
of each message's fields: every one that Flight Review and PlotJuggler users plot), so their
tools read a quadsitl log as a PX4 SITL log. Our own topics are in the paper's frames (world
x north / y west / z up, body front-left-up, ZYX Euler angles), SI units:

Our own topics' names and layouts are :mod:`quadcommon.ulog_topics` (the ground stations read
them too); their samples are built here:

* ``paper_tracking`` (every control step): what the paper's indices are computed from, the same
  quantities as the recorder's Parquet columns (``quadsitl analyze`` reads either): the truth the
  HIL frame carries (position, Euler angles), the reference, eta_d, the applied U1 and tau_eta,
  and the mode and armed state;
* ``cascade_status`` (every 50 ms: reading the laws' states costs ~5 µs): the rest of the
  cascade (reference velocity and acceleration, phi_r and theta_r before the command filter,
  eta_d', the acceleration command, the body torque, the normalised actuator controls, the
  commanded rotor speeds) and the laws' integral states
  (:meth:`~autopilot.control.cascade.Cascade.law_states`, one field per state);
* ``failsafe_flags`` (PX4's topic, every 500 ms): the commander's failsafe flags, PX4's fields
  (:data:`autopilot.commander.health.PX4_FIELDS`);
* ``sim_disturbance``: the disturbance the simulator applies (force at the CoM, world; torque on
  the Euler coordinates), as the lockstep frame reports it (``DISTURB``, :mod:`quadcommon.wire`);
* ``sim_rotors``: the rotors' health the simulator applies, from the same report, logged when
  the log starts and at every change: each rotor's effectiveness (1 healthy, 0 off) and its
  failure as ``FAILURE_TYPE`` (0 none, 1 off, 2 stuck, 4 wrong: a loss of effectiveness), rotors
  1-4 in the simulator's order (1 front, 2 right, 3 rear, 4 left, as ``actuator_motors``).

Rates are PX4's default logging profile (``logged_topics.cpp``: an interval in ms, at most one
sample per interval; its SITL ground-truth topics included, at 20 ms rather than PX4's 10 ms for
attitude and rates), sampled on the simulation clock of the frames, except four topics logged at
every control step, as PX4's high-rate profile logs them: ``sensor_combined`` (PX4 logs every
sample; here the IMU comes with each frame), ``vehicle_angular_velocity`` (PX4 SITL: every 10 ms,
100 Hz, the very edge of the 100 Hz Flight Review's spectra need, and folding the content of the
rate loop above 50 Hz into them) and ``vehicle_torque_setpoint`` / ``vehicle_thrust_setpoint``
(PX4: 20 ms, too slow for the Actuator Controls FFT). Every builder reads the frame's
:class:`Snapshot` and returns the sample's values, timestamp first, or None when the vehicle has
no such data now (no estimate yet, no GPS fix in this frame, not flying on the EKF, motors off).

Pure: no file, no clock; :mod:`.logger` decides when a log runs and packs these samples.

(One module: every builder reads the same :class:`Snapshot` and the one table of topics names each
builder beside its rate and layout; split by topic, each part would need both.)
"""

from __future__ import annotations

import functools
import math
import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import NamedTuple

from quadcommon import frames
from quadcommon.bus_records import CONTROLLER_FIELDS
from quadcommon.mavlink_fast import MessageParts
from quadcommon.rigid_body import body_rates_from_euler_rates, quaternion_from_euler
from quadcommon.ulog_topics import (
    CASCADE_FIELDS,
    DISTURBANCE,
    DISTURBANCE_FIELDS,
    ROTORS,
    ROTORS_FIELDS,
    TRACKING_FIELDS,
)

from ..commander.health import PX4_FIELDS
from ..commander.modes import FlightMode, LandedState
from ..commander.transitions import Phase
from ..mavlink.codec import mavlink
from ..mavlink.hil import GpsFields, gps_fields, imu_fields
from .ulog import Format, fields

NAN = math.nan
NAN3 = (NAN, NAN, NAN)

# Where the controller row (quadcommon.bus_records.CONTROLLER_FIELDS, one per frame) holds what the
# log reads of it: the recorder's Parquet columns are these same rows.
_C = {name: i for i, name in enumerate(CONTROLLER_FIELDS)}
ROW_POS_REF = slice(_C["x_ref_m"], _C["z_ref_m"] + 1)
ROW_VEL_REF = slice(_C["vx_ref_m_s"], _C["vz_ref_m_s"] + 1)
ROW_ACC_REF = slice(_C["ax_ref_m_s2"], _C["az_ref_m_s2"] + 1)
ROW_EULER_REF = slice(_C["phi_ref_rad"], _C["psi_ref_rad"] + 1)
ROW_RAW = slice(_C["phi_raw_rad"], _C["theta_raw_rad"] + 1)
ROW_U1 = _C["U1_n"]
ROW_TAU = slice(_C["tau_phi_n_m"], _C["tau_psi_n_m"] + 1)
ROW_ARMED = _C["armed"]
ROW_CUSTOM_MODE = _C["custom_mode"]

# PX4's vehicle_status.nav_state for the modes flown here (msg/VehicleStatus.msg).
NAV_STATE = {
    FlightMode.POSCTL: 2,
    FlightMode.AUTO_MISSION: 3,
    FlightMode.AUTO_LOITER: 4,
    FlightMode.AUTO_RTL: 5,
    FlightMode.OFFBOARD: 14,
    FlightMode.AUTO_TAKEOFF: 17,
    FlightMode.AUTO_LAND: 18,
    FlightMode.AUTO_FOLLOW_TARGET: 19,
    FlightMode.ORBIT: 21,
}
ARMING_STATE_DISARMED, ARMING_STATE_ARMED = 1, 2  # vehicle_status.arming_state
VEHICLE_TYPE_ROTARY_WING = 1
MAV_TYPE_QUADROTOR = 2
ACTUATOR_OUTPUTS = 16  # actuator_outputs.output[16]


GPS_ID = mavlink.MAVLINK_MSG_ID_HIL_GPS


def gps_of(parts: MessageParts) -> GpsFields | None:
    """The frame's HIL_GPS as sent, or None (none in the frame, or corrupt)."""
    try:
        return gps_fields(parts)
    except (ValueError, struct.error):  # DecodeError is a ValueError
        return None


def imu_of(parts: MessageParts) -> tuple | None:
    """The frame's HIL_SENSOR accelerometer and gyro as sent (FRD), or None (none, or corrupt)."""
    try:
        return imu_fields(parts)
    except (ValueError, struct.error):
        return None


@dataclass(slots=True)
class Snapshot:
    """One frame as the log reads it (refreshed in place: what every control step's topics read by
    the logger at each frame, the rest by the core when periodic topics are due)."""

    t_us: int = 0  # the frame's time_usec: simulation time since boot
    truth: object = None  # StateEstimate: the simulator's state in the HIL frame (paper frames)
    estimate: object = None  # StateEstimate | None: what the vehicle flies on
    row: tuple = ()  # the frame's controller row (CONTROLLER_FIELDS)
    reference: object = None  # quadcommon.trajectories.Reference | None
    output: object = None  # CascadeOutput | None (motors off: None)
    controls: tuple = (0.0, 0.0, 0.0, 0.0)  # normalised actuator controls sent to the simulator
    commander: object = None  # the Commander (its landed state is read when a sample needs it)
    estimator: object = None  # EstimatorStatus | None (flying on truth: None)
    battery: object = None  # autopilot.battery.estimator.BatteryStatus | None (no battery reported)
    parts: MessageParts | None = None  # the frame's undecoded messages (sensor_combined reads HIL_SENSOR's)
    gps: object = None  # hil.GpsFields of this frame's HIL_GPS, or None
    thrust_max_n: float = 1.0  # the actuators' U1_max: 1 of PX4's normalised thrust
    torque_max_n_m: tuple = (1.0, 1.0, 1.0)  # the actuators' tau_max per body axis: 1 of PX4's torque
    rotors: bool = False  # actuation "rotors": the controls are rotor speeds over Omega_max
    home_geodetic: tuple = (0.0, 0.0, 0.0)  # the local frame's origin (lat, lon, alt)
    system_id: int = 1
    utc_offset_us: int = 0  # UTC minus simulation time (µs) when the log started with a clock, else 0
    arming_time_us: int = 0
    mode_time_us: int = 0


class TopicSpec(NamedTuple):
    """One logged topic: PX4's message notation of its fields after the timestamp (a field's type
    may be one of the ``nested`` formats), and at most one sample per ``interval_ms`` of
    simulation time (0: every control step)."""

    name: str
    fields: str
    interval_ms: int
    build: Callable[[Snapshot], tuple | None]
    nested: tuple[Format, ...] = ()

    def format(self, extra: str = "") -> Format:
        """The topic's ULog format: ``uint64_t timestamp`` first, then its fields and ``extra`` (the law
        states' fields of ``cascade_status``)."""
        return Format(self.name, fields(f"uint64_t timestamp; {self.fields}; {extra}", self.nested))


def _q_ned(euler) -> tuple[float, float, float, float]:
    return frames.quaternion_to_ned(quaternion_from_euler(*euler))


def _rates_frd(state) -> tuple[float, float, float]:
    phi, theta, _ = state.euler_rad
    return frames.vector_to_ned(body_rates_from_euler_rates(phi, theta, state.euler_rates_rad_s))


# -- PX4's topics --------------------------------------------------------------------------------------
LOCAL_POSITION = (
    "uint64_t timestamp_sample; uint64_t ref_timestamp; double ref_lat; double ref_lon; "
    "float x; float y; float z; float vx; float vy; float vz; float z_deriv; float ax; float ay; float az; "
    "float heading; float ref_alt; float eph; float epv; float evh; float evv; "
    "bool xy_valid; bool z_valid; bool v_xy_valid; bool v_z_valid; bool xy_global; bool z_global; "
    "bool heading_good_for_control; bool dead_reckoning"
)


def _local_position(s: Snapshot, state, estimator) -> tuple:
    x, y, z = frames.vector_to_ned(state.position_m)
    vx, vy, vz = frames.vector_to_ned(state.velocity_m_s)
    lat, lon, alt = s.home_geodetic
    if estimator is not None:
        eph, epv = estimator.pos_horiz_accuracy_m, estimator.pos_vert_accuracy_m
        evh, dead_reckoning = estimator.vel_accuracy_m_s, estimator.dead_reckoning
    else:
        eph = epv = evh = 0.0
        dead_reckoning = False
    return (s.t_us, s.t_us, 0, lat, lon, x, y, z, vx, vy, vz, vz, NAN, NAN, NAN,
            frames.yaw_to_ned(state.euler_rad[2]), alt, eph, epv, evh, evh,
            True, True, True, True, True, True, True, dead_reckoning)  # fmt: skip


def vehicle_local_position(s: Snapshot) -> tuple | None:
    """PX4's ``vehicle_local_position`` of the estimate the vehicle flies on (NED from the home origin, with
    the estimator's accuracies); None without an estimate."""
    return None if s.estimate is None else _local_position(s, s.estimate, s.estimator)


def vehicle_local_position_groundtruth(s: Snapshot) -> tuple:
    """PX4 SITL's ``vehicle_local_position_groundtruth``: the simulator's state from the frame, NED."""
    return _local_position(s, s.truth, None)


GLOBAL_POSITION = (
    "uint64_t timestamp_sample; double lat; double lon; float alt; float alt_ellipsoid; float delta_alt; "
    "float eph; float epv; float terrain_alt; bool lat_lon_valid; bool alt_valid; bool terrain_alt_valid; "
    "bool dead_reckoning"
)


def _global_position(s: Snapshot, state, estimator) -> tuple:
    lat, lon, alt = frames.ned_to_geodetic(*frames.vector_to_ned(state.position_m), s.home_geodetic)
    eph, epv = (estimator.pos_horiz_accuracy_m, estimator.pos_vert_accuracy_m) if estimator else (0.0, 0.0)
    reckoning = estimator.dead_reckoning if estimator else False
    return (s.t_us, s.t_us, lat, lon, alt, alt, 0.0, eph, epv, NAN, True, True, False, reckoning)


def vehicle_global_position(s: Snapshot) -> tuple | None:
    """PX4's ``vehicle_global_position`` of the estimate (WGS84 from the home origin, altitude AMSL); None
    without an estimate."""
    return None if s.estimate is None else _global_position(s, s.estimate, s.estimator)


def vehicle_global_position_groundtruth(s: Snapshot) -> tuple:
    """PX4 SITL's ``vehicle_global_position_groundtruth``: the simulator's position as latitude, longitude and
    altitude."""
    return _global_position(s, s.truth, None)


ATTITUDE = "uint64_t timestamp_sample; float[4] q; float[4] delta_q_reset; uint8_t quat_reset_counter"


def vehicle_attitude(s: Snapshot) -> tuple | None:
    """PX4's ``vehicle_attitude``: the estimate's attitude as the NED/FRD quaternion; None without an
    estimate."""
    if s.estimate is None:
        return None
    return (s.t_us, s.t_us, *_q_ned(s.estimate.euler_rad), 1.0, 0.0, 0.0, 0.0, 0)


def vehicle_attitude_groundtruth(s: Snapshot) -> tuple:
    """PX4 SITL's ``vehicle_attitude_groundtruth``: the simulator's attitude as the NED/FRD quaternion."""
    return (s.t_us, s.t_us, *_q_ned(s.truth.euler_rad), 1.0, 0.0, 0.0, 0.0, 0)


ANGULAR_VELOCITY = "uint64_t timestamp_sample; float[3] xyz"


def vehicle_angular_velocity(s: Snapshot) -> tuple | None:
    """The body rates the vehicle flies on (FRD)."""
    if s.estimate is None:
        return None
    return (s.t_us, s.t_us, *_rates_frd(s.estimate))


def vehicle_angular_velocity_groundtruth(s: Snapshot) -> tuple:
    """PX4 SITL's ``vehicle_angular_velocity_groundtruth``: the simulator's body rates (FRD, rad/s)."""
    return (s.t_us, s.t_us, *_rates_frd(s.truth))


ATTITUDE_SETPOINT = (
    "float roll_body; float pitch_body; float yaw_body; float yaw_sp_move_rate; float[4] q_d; "
    "float[3] thrust_body; bool reset_integral; bool fw_control_yaw_wheel"
)


def vehicle_attitude_setpoint(s: Snapshot) -> tuple | None:
    """PX4's ``vehicle_attitude_setpoint``: eta_d (after the command filter) in NED, its quaternion, the
    reference's yaw rate and the thrust as PX4's normalised body z thrust; None with the motors off."""
    eta_d = s.row[ROW_EULER_REF]
    if s.output is None or not math.isfinite(eta_d[0]):
        return None
    roll, pitch, yaw = frames.euler_to_ned(eta_d)
    yaw_rate = frames.yaw_to_ned(s.reference.yaw_rate_rad_s) if s.reference is not None else 0.0
    thrust = s.row[ROW_U1] / s.thrust_max_n
    return (s.t_us, roll, pitch, yaw, yaw_rate, *_q_ned(eta_d), 0.0, 0.0, -thrust, False, False)


RATES_SETPOINT = "float roll; float pitch; float yaw; float[3] thrust_body; bool reset_integral"


def vehicle_rates_setpoint(s: Snapshot) -> tuple | None:
    """PX4's ``vehicle_rates_setpoint``: the body rates (FRD, rad/s) of the filtered eta_d', and the
    normalised thrust; None with the motors off."""
    out = s.output
    if out is None:
        return None
    phi, theta, _ = out.euler_ref_rad
    roll, pitch, yaw = frames.vector_to_ned(body_rates_from_euler_rates(phi, theta, out.euler_rate_ref_rad_s))
    return (s.t_us, roll, pitch, yaw, 0.0, 0.0, -out.thrust_n / s.thrust_max_n, False)


LOCAL_POSITION_SETPOINT = (
    "float x; float y; float z; float yaw; float yawspeed; float vx; float vy; float vz; "
    "float[3] acceleration; float[3] thrust"
)


def vehicle_local_position_setpoint(s: Snapshot) -> tuple | None:
    """PX4's ``vehicle_local_position_setpoint``: the reference (NED position, velocity, acceleration, yaw and
    yaw rate) and the normalised thrust (NaN with the motors off); None without a reference."""
    ref = s.reference
    if ref is None:
        return None
    x, y, z = frames.vector_to_ned(ref.position_m)
    vx, vy, vz = frames.vector_to_ned(ref.velocity_m_s)
    thrust = (0.0, 0.0, -s.row[ROW_U1] / s.thrust_max_n) if s.output is not None else NAN3
    return (s.t_us, x, y, z, frames.yaw_to_ned(ref.yaw_rad), frames.yaw_to_ned(ref.yaw_rate_rad_s),
            vx, vy, vz, *frames.vector_to_ned(ref.acceleration_m_s2), *thrust)  # fmt: skip


LAND_DETECTED = (
    "float alt_max; bool freefall; bool ground_contact; bool maybe_landed; bool landed; "
    "bool in_ground_effect; bool in_descend; bool at_rest"
)


def vehicle_land_detected(s: Snapshot) -> tuple:
    """PX4's land detector flags from MAV_LANDED_STATE: on the ground, landing (descending), or
    in the air (taking off included)."""
    state = s.commander.landed_state
    on_ground = state is LandedState.ON_GROUND
    landing = state is LandedState.LANDING
    return (s.t_us, NAN, False, on_ground, on_ground, on_ground, False, landing, on_ground)


OUTPUTS = "uint32_t noutputs; float[16] output"


def actuator_outputs(s: Snapshot) -> tuple:
    """PX4's ``actuator_outputs``: the normalised actuator controls sent to the simulator (rotor speeds over
    Omega_max, or under wrench actuation thrust and torques over their maxima); the other outputs zero."""
    c = s.controls
    return (s.t_us, len(c), *c, *(0.0,) * (ACTUATOR_OUTPUTS - len(c)))


VEHICLE_STATUS = (
    "uint64_t armed_time; uint64_t takeoff_time; uint64_t nav_state_timestamp; "
    "uint32_t valid_nav_states_mask; uint32_t can_set_nav_states_mask; "
    "uint8_t arming_state; uint8_t nav_state; uint8_t nav_state_user_intention; uint8_t hil_state; "
    "uint8_t vehicle_type; bool failsafe; bool failsafe_and_user_took_over; bool gcs_connection_lost; "
    "bool is_vtol; bool is_vtol_tailsitter; "
    "bool in_transition_mode; bool in_transition_to_fw; uint8_t system_type; uint8_t system_id; "
    "uint8_t component_id; bool pre_flight_checks_pass"
)
NAV_STATES_MASK = sum(1 << n for n in NAV_STATE.values())


@functools.lru_cache(maxsize=64)
def nav_state(custom_mode: int) -> int:
    """PX4's nav_state of a custom_mode (unknown: AUTO_LOITER, hold); cached: looking a mode up
    walks the FlightMode enum."""
    mode = FlightMode.from_custom_mode(int(custom_mode))
    return NAV_STATE.get(mode, 4) if mode is not None else 4


def vehicle_status(s: Snapshot) -> tuple:
    """PX4's ``vehicle_status``: arming state and time, nav_state from the frame's custom mode, the vehicle
    type (rotary wing, MAV_TYPE_QUADROTOR) and system id."""
    armed = s.row[ROW_ARMED] > 0.5
    state = nav_state(int(s.row[ROW_CUSTOM_MODE]))
    return (s.t_us, s.arming_time_us if armed else 0, 0, s.mode_time_us,
            NAV_STATES_MASK, NAV_STATES_MASK, ARMING_STATE_ARMED if armed else ARMING_STATE_DISARMED,
            state, state, 1, VEHICLE_TYPE_ROTARY_WING, False, False, False, False, False, False, False,
            MAV_TYPE_QUADROTOR, s.system_id, 1, True)  # fmt: skip


SENSOR_COMBINED = (
    "float[3] gyro_rad; uint32_t gyro_integral_dt; int32_t accelerometer_timestamp_relative; "
    "float[3] accelerometer_m_s2; uint32_t accelerometer_integral_dt; uint8_t accelerometer_clipping; "
    "uint8_t gyro_clipping; uint8_t accel_calibration_count; uint8_t gyro_calibration_count"
)


def sensor_combined(s: Snapshot) -> tuple | None:
    """HIL_SENSOR's IMU as the simulator sent it (FRD already), non-finite samples left out."""
    imu = imu_of(s.parts) if s.parts is not None else None
    if imu is None:
        return None
    ax, ay, az, gx, gy, gz = imu
    if not math.isfinite(ax + ay + az + gx + gy + gz):
        return None
    return (s.t_us, gx, gy, gz, 0, 0, ax, ay, az, 0, 0, 0, 0, 0)


TORQUE_SETPOINT = THRUST_SETPOINT = "uint64_t timestamp_sample; float[3] xyz"


def vehicle_torque_setpoint(s: Snapshot) -> tuple | None:
    """PX4's normalised torque (FRD, each axis over the actuators' tau_max: 1 is the most the
    vehicle can give, docs/controllers.md), of the body torque applied after the actuators'
    saturation; while the motors fly."""
    out = s.output
    if out is None:
        return None
    tx, ty, tz = frames.vector_to_ned(out.torque_body_n_m)
    mx, my, mz = s.torque_max_n_m
    return (s.t_us, s.t_us, tx / mx, ty / my, tz / mz)


def vehicle_thrust_setpoint(s: Snapshot) -> tuple | None:
    """PX4's normalised thrust (FRD: -z is up; the applied U1 over the actuators' U1_max); while
    the motors fly."""
    out = s.output
    if out is None:
        return None
    return (s.t_us, s.t_us, 0.0, 0.0, -out.thrust_n / s.thrust_max_n)


MOTORS = "uint64_t timestamp_sample; uint16_t reversible_flags; float[12] control"
ACTUATOR_MOTORS = 12  # actuator_motors.control[12]
_NO_MOTOR = (NAN,) * ACTUATOR_MOTORS  # PX4: NaN stops a motor (disarmed, or no motor there)


def actuator_motors(s: Snapshot) -> tuple:
    """Each rotor's commanded thrust over its largest, ``(Omega_i / Omega_max)^2`` (PX4's motor
    control: thrust, 0..1), in the simulator's rotor order (1 front, 2 right, 3 rear, 4 left); NaN
    for the outputs without a rotor, while disarmed, and under ``actuation = "wrench"`` (no
    rotors: the wrench itself is vehicle_torque_setpoint / vehicle_thrust_setpoint)."""
    if not s.rotors or s.row[ROW_ARMED] <= 0.5:
        return (s.t_us, s.t_us, 0, *_NO_MOTOR)
    c0, c1, c2, c3 = s.controls
    return (s.t_us, s.t_us, 0, c0 * c0, c1 * c1, c2 * c2, c3 * c3, *_NO_MOTOR[4:])


RATE_CTRL = "rate_ctrl_status"
RATE_CTRL_FIELDS = "float rollspeed_integ; float pitchspeed_integ; float yawspeed_integ"
# The rotational law's state entries that are PX4's rate integrals (normalised torque, body
# front-left-up): px4_attitude's. Laws without them log zeros, as PX4 does with no rate
# integrator (MC_*RATE_I = 0); their integral action is in cascade_status's law states.
RATE_INTEGRAL_STATES = ("rotational.rate_int_x", "rotational.rate_int_y", "rotational.rate_int_z")
_NO_RATE_INTEGRAL = (0.0, 0.0, 0.0)


def rate_ctrl_status(s: Snapshot) -> tuple:
    """Without the integrals (the logger appends them: :func:`rate_integrals`)."""
    return (s.t_us,)


def rate_integrals(
    names: Sequence[str], law_states: Callable[[], tuple[tuple[str, ...], tuple[float, ...]]]
) -> Callable[[], tuple[float, float, float]]:
    """The reader of ``rate_ctrl_status``'s integrals (FRD) for the laws whose states are
    ``names`` (:meth:`~autopilot.control.cascade.Cascade.law_states`): the entries
    :data:`RATE_INTEGRAL_STATES`, or zeros when the law has none."""
    if not all(name in names for name in RATE_INTEGRAL_STATES):
        return lambda: _NO_RATE_INTEGRAL
    i, j, k = (names.index(name) for name in RATE_INTEGRAL_STATES)

    def read() -> tuple[float, float, float]:
        values = law_states()[1]
        return frames.vector_to_ned((values[i], values[j], values[k]))

    return read


POSITION_SETPOINT = Format(
    "position_setpoint",
    fields("uint64_t timestamp; bool valid; uint8_t type; float vx; float vy; float vz; double lat; "
           "double lon; float alt; float yaw"),
)  # fmt: skip
TRIPLET = "position_setpoint previous; position_setpoint current; position_setpoint next"
# PositionSetpoint.type of the phases with a destination (Commander.destination)
SETPOINT_TYPE = {Phase.TAKEOFF: 3, Phase.HOLD: 2, Phase.LAND: 4, Phase.RTL_LAND: 4}  # else 0: position
_NO_SETPOINT = (0, False, 0, NAN, NAN, NAN, NAN, NAN, NAN, NAN)


def position_setpoint_triplet(s: Snapshot) -> tuple | None:
    """``current``: where the flown plan leads (:attr:`Commander.destination
    <autopilot.commander.commander.Commander.destination>`: takeoff, hold, landing or return
    point, the mission leg's target) as latitude, longitude, altitude AMSL and yaw; ``previous``
    and ``next`` not valid. None (no sample, as PX4's navigator publishes none) where no plan
    leads anywhere: offboard, manual, a scenario's trajectory, on the ground."""
    commander = s.commander
    target = commander.destination
    if target is None:
        return None
    lat, lon, alt = frames.ned_to_geodetic(*frames.vector_to_ned(target.position_m), s.home_geodetic)
    kind = SETPOINT_TYPE.get(commander.phase, 0)
    current = (s.t_us, True, kind, NAN, NAN, NAN, lat, lon, alt, frames.yaw_to_ned(target.yaw_rad))
    return (s.t_us, *_NO_SETPOINT, *current, *_NO_SETPOINT)


GPS_POSITION = (
    "uint64_t timestamp_sample; uint64_t time_utc_usec; uint32_t device_id; double latitude_deg; "
    "double longitude_deg; double altitude_msl_m; double altitude_ellipsoid_m; float s_variance_m_s; "
    "float c_variance_rad; float eph; float epv; float hdop; float vdop; int32_t noise_per_ms; "
    "int32_t jamming_indicator; float vel_m_s; float vel_n_m_s; float vel_e_m_s; float vel_d_m_s; "
    "float cog_rad; uint8_t fix_type; bool vel_ned_valid; uint8_t satellites_used"
)
_UNKNOWN_U16 = 65535


def vehicle_gps_position(s: Snapshot) -> tuple | None:
    """PX4's ``sensor_gps`` as ``vehicle_gps_position``: the frame's HIL_GPS in SI units (degrees, metres,
    m/s, course in rad; MAVLink's unknown 65535 as NaN); None when the frame has none."""
    g = s.gps
    if g is None:
        return None
    alt = g.alt * 1e-3
    eph = g.eph * 0.01 if g.eph != _UNKNOWN_U16 else NAN
    epv = g.epv * 0.01 if g.epv != _UNKNOWN_U16 else NAN
    cog = math.radians(g.cog * 0.01) if g.cog != _UNKNOWN_U16 else NAN
    utc = s.t_us + s.utc_offset_us if s.utc_offset_us else 0
    return (s.t_us, s.t_us, utc, 0, g.lat * 1e-7, g.lon * 1e-7, alt, alt, NAN, NAN, eph, epv, eph, epv, 0, 0,
            g.vel * 0.01 if g.vel != _UNKNOWN_U16 else NAN, g.vn * 0.01, g.ve * 0.01, g.vd * 0.01, cog,
            g.fix_type, True, g.satellites_visible)  # fmt: skip


BATTERY = (
    "float voltage_v; float voltage_filtered_v; float current_a; float current_filtered_a; "
    "float current_average_a; float discharged_mah; float remaining; float scale; float time_remaining_s; "
    "float temperature; uint8_t cell_count; bool connected; uint8_t source; uint8_t priority; "
    "uint16_t capacity; uint8_t id; uint8_t warning; uint16_t faults; float internal_resistance_estimate; "
    "float ocv_estimate; float ocv_estimate_filtered; float volt_based_soc_estimate"
)
SOURCE_POWER_MODULE = 0  # battery_status.source


def battery_status(s: Snapshot) -> tuple | None:
    """The battery's estimate (autopilot.battery.estimator: the one SYS_STATUS and BATTERY_STATUS
    report), PX4's fields; None until a battery has reported. ``timestamp`` is the frame's, the
    estimate is of the last report (20 Hz)."""
    b = s.battery
    if b is None:
        return None
    capacity = min(max(round(b.capacity_mah), 0), 65535)
    return (s.t_us, b.voltage_v, b.voltage_filtered_v, b.current_a, b.current_filtered_a, b.current_average_a,
            b.discharged_mah, b.remaining, b.scale, b.time_remaining_s, NAN, b.cell_count, b.connected,
            SOURCE_POWER_MODULE, 0, capacity, 1, b.warning, b.faults, b.internal_resistance_estimate,
            b.ocv_estimate, b.ocv_estimate_filtered, b.volt_based_soc_estimate)  # fmt: skip


ESTIMATOR_STATUS = (
    "uint64_t timestamp_sample; uint64_t control_mode_flags; float[3] output_tracking_error; "
    "uint32_t filter_fault_flags; float pos_horiz_accuracy; float pos_vert_accuracy; float hdg_test_ratio; "
    "float vel_test_ratio; float pos_test_ratio; float hgt_test_ratio; float tas_test_ratio; "
    "float hagl_test_ratio; float beta_test_ratio; uint16_t gps_check_fail_flags; "
    "uint16_t innovation_check_flags; uint16_t solution_status_flags; uint8_t health_flags; "
    "uint8_t timeout_flags"
)


def estimator_status(s: Snapshot) -> tuple | None:
    """PX4's ``estimator_status``: the EKF's accuracies, test ratios and ESTIMATOR_STATUS_FLAGS, with the
    older health and timeout flags Flight Review plots; None when flying on the truth."""
    e = s.estimator
    if e is None:
        return None
    # solution_status_flags are MAVLink's ESTIMATOR_STATUS_FLAGS bits, as PX4 fills them;
    # health_flags (velocity, position, height: bit set = its test failing) and timeout_flags (no
    # aiding: dead reckoning) as PX4's older estimator_status, which Flight Review plots.
    health = (e.vel_ratio > 1.0) | (e.pos_horiz_ratio > 1.0) << 1 | (e.pos_vert_ratio > 1.0) << 2
    timeout = 0b011 if e.dead_reckoning else 0
    return (s.t_us, s.t_us, 0, 0.0, 0.0, 0.0, 0, e.pos_horiz_accuracy_m, e.pos_vert_accuracy_m,
            e.mag_ratio, e.vel_ratio, e.pos_horiz_ratio, e.pos_vert_ratio, 0.0, 0.0, 0.0, 0, 0,
            e.flags, health, timeout)  # fmt: skip


# -- our own topics (paper frames) ---------------------------------------------------------------------
def paper_tracking(s: Snapshot) -> tuple:
    """The frame's truth and its controller row."""
    truth, row = s.truth, s.row
    return (s.t_us, *truth.position_m, *row[ROW_POS_REF], *truth.euler_rad, *row[ROW_EULER_REF],
            row[ROW_U1], *row[ROW_TAU], int(row[ROW_CUSTOM_MODE]), row[ROW_ARMED] > 0.5)  # fmt: skip


def cascade_status(s: Snapshot) -> tuple | None:
    """Without the laws' states (the logger appends them: their names depend on the laws)."""
    out, row = s.output, s.row
    if out is None:
        return (s.t_us, *row[ROW_VEL_REF], *row[ROW_ACC_REF], *row[ROW_RAW], *NAN3, *NAN3, 0.0, 0.0, 0.0,
                *s.controls, 0.0, 0.0, 0.0, 0.0)  # fmt: skip
    return (s.t_us, *row[ROW_VEL_REF], *row[ROW_ACC_REF], *row[ROW_RAW], *out.euler_rate_ref_rad_s,
            *out.acceleration_cmd_m_s2, *out.torque_body_n_m, *s.controls,
            *out.rotor_speeds_rad_s)  # fmt: skip


def law_state_field(name: str) -> str:
    """A law state's field name: ``translational.xi_x`` -> ``translational_xi_x``."""
    return "".join(c if c.isalnum() or c == "_" else "_" for c in name)


def _failsafe_type(name: str) -> str:
    if name.startswith("mode_req_"):
        return "uint32_t"
    return "uint8_t" if name == "battery_warning" else "bool"


# PX4's msg/FailsafeFlags.msg, its fields and types in its order (commander/health.py holds them).
FAILSAFE_FLAGS = "; ".join(f"{_failsafe_type(name)} {name}" for name in PX4_FIELDS)


def failsafe_flags(s: Snapshot) -> tuple | None:
    """The commander's failsafe flags (PX4 publishes them at 2 Hz and on a change)."""
    commander = s.commander
    if commander is None:
        return None
    flags = commander.flags
    return (s.t_us, *(getattr(flags, name) for name in PX4_FIELDS))


def sim_disturbance(s: Snapshot) -> None:
    """Not sampled from frames: FlightLogger.disturbance() logs what it is given."""
    return None


def sim_rotors(s: Snapshot) -> None:
    """Not sampled from frames: FlightLogger.rotor_health() logs what it is given."""
    return None


# The topics sampled from frames, in message-id order. Interval 0: every control step, but
# vehicle_gps_position is sampled from every frame that carries HIL_GPS; vehicle_status also
# whenever the mode or arming changes; sim_disturbance and sim_rotors as they are given
# (FlightLogger.disturbance, FlightLogger.rotor_health).
TOPICS: tuple[TopicSpec, ...] = tuple(
    TopicSpec(build.__name__, layout, interval_ms, build, tuple(nested))
    for build, layout, interval_ms, *nested in (
        (paper_tracking, TRACKING_FIELDS, 0),
        (cascade_status, CASCADE_FIELDS, 50),
        (vehicle_status, VEHICLE_STATUS, 500),
        (vehicle_land_detected, LAND_DETECTED, 100),
        (vehicle_attitude, ATTITUDE, 50),
        (vehicle_attitude_setpoint, ATTITUDE_SETPOINT, 50),
        (vehicle_angular_velocity, ANGULAR_VELOCITY, 0),
        (vehicle_rates_setpoint, RATES_SETPOINT, 20),
        (vehicle_torque_setpoint, TORQUE_SETPOINT, 0),
        (vehicle_thrust_setpoint, THRUST_SETPOINT, 0),
        (rate_ctrl_status, RATE_CTRL_FIELDS, 200),
        (vehicle_local_position, LOCAL_POSITION, 100),
        (vehicle_local_position_setpoint, LOCAL_POSITION_SETPOINT, 100),
        (position_setpoint_triplet, TRIPLET, 200, POSITION_SETPOINT),
        (vehicle_global_position, GLOBAL_POSITION, 200),
        (vehicle_gps_position, GPS_POSITION, 0),
        (sensor_combined, SENSOR_COMBINED, 0),
        (actuator_outputs, OUTPUTS, 100),
        (actuator_motors, MOTORS, 100),
        (battery_status, BATTERY, 200),
        (estimator_status, ESTIMATOR_STATUS, 200),
        (vehicle_angular_velocity_groundtruth, ANGULAR_VELOCITY, 20),
        (vehicle_attitude_groundtruth, ATTITUDE, 20),
        (vehicle_global_position_groundtruth, GLOBAL_POSITION, 100),
        (vehicle_local_position_groundtruth, LOCAL_POSITION, 20),
        (sim_disturbance, DISTURBANCE_FIELDS, 10),
        (sim_rotors, ROTORS_FIELDS, 10),
        (failsafe_flags, FAILSAFE_FLAGS, 500),
    )
)
# Sampled by the logger's own rules rather than by their interval alone (see TOPICS above).
EVENT_TOPICS = ("vehicle_gps_position", DISTURBANCE, ROTORS)
