"""What the vehicle knows of its own health: PX4's failsafe flags and sensor health (pure: the
frames' samples and the simulation time in, one typed record out).

PX4 learns of a failure only from its data, and so does this module: a sensor stream that stops,
a value that stops changing while the vehicle moves, a sample the estimator's innovation test
keeps rejecting, an estimate whose accuracy or aiding is gone. It never asks the simulator what
went wrong, so the same reaction follows whichever way the data went bad.

:class:`FailsafeFlags` holds PX4's ``failsafe_flags`` (``msg/FailsafeFlags.msg``: the per-mode
requirements as bit masks over PX4's navigation states, the ``*_invalid`` / ``*_lost`` flags with
PX4's names) and, beyond that topic, the heading and the health of each sensor (what SYS_STATUS
reports). :class:`HealthMonitor` computes it:

* validity (PX4's ``EstimatorChecks::setModeRequirementFlags``): on the EKF, the horizontal
  position is valid while the filter has horizontal aiding (``EKF2_NOAID_TOUT``, its
  ``ESTIMATOR_POS_HORIZ_REL`` flag) and its 1-sigma is below ``COM_POS_FS_EPH`` (2.5 times that
  while valid, and 1 s of good data before it is valid again: PX4's ``checkPosVelValidity``
  hysteresis); the velocity likewise with ``COM_VEL_FS_EVH``; the altitude while the filter has
  vertical aiding (``ESTIMATOR_POS_VERT_ABS``); the attitude and the angular velocity while IMU
  samples arrive (PX4: a topic older than 1 s is invalid). The global position is the local one
  here: the local frame's origin is always known (the configured home, as PX4's EKF origin).
  On the truth estimator (``EKF2_EN`` 0: the vehicle flies on the simulator's state) every
  estimate is valid while frames flow;
* sensor health (PX4's sensor checks and ``DataValidator``): a stream that stops (silent for
  ``max(1 s, 3 intervals)``, :class:`~autopilot.estimation.streams.StreamWatch`); a value that
  repeats exactly (the DataValidator's count, accumulated over the axes, above 100; compared
  every :data:`STUCK_CHECK_S` rather than every sample, see :class:`_StuckCheck`) *while the
  vehicle moves* enough that it must have changed (so a noise-free sensor, the ``ideal`` profile,
  at rest is not called stuck: PX4 would); the estimator rejecting the sensor's samples for
  :data:`REJECTING_S`; a GPS without a 3D fix.

The rates are PX4's commander's. :meth:`HealthMonitor.observe` takes every frame (500 Hz) but
only notes there which streams delivered, compares a value when its stuck check is due (the
samples are needed only then: :meth:`HealthMonitor.wants_samples`) and judges the streams'
silences at 100 Hz (:data:`STREAM_CHECK_S`, PX4's commander loop); :meth:`HealthMonitor.evaluate`
runs when the commander asks (at 10 Hz and when its state changes, as PX4's health and arming
checks) and returns the same record while nothing in it changed.
"""

from __future__ import annotations

import math
from typing import NamedTuple, Protocol

from ..estimation.status import (
    ESTIMATOR_POS_HORIZ_REL,
    ESTIMATOR_POS_VERT_ABS,
    ESTIMATOR_VELOCITY_HORIZ,
    EstimatorStatus,
)
from ..estimation.streams import StreamWatch
from ..params.store import ParameterStore
from ..records import STREAM_BARO, STREAM_GPS, STREAM_IMU, STREAM_MAG, STREAM_VISION, SensorSamples
from .modes import FlightMode

Vector3 = tuple[float, float, float]

# PX4's navigation states (vehicle_status.msg NAVIGATION_STATE_*) of the modes flown here.
NAV_MANUAL, NAV_ALTCTL, NAV_POSCTL, NAV_AUTO_MISSION, NAV_AUTO_LOITER, NAV_AUTO_RTL = 0, 1, 2, 3, 4, 5
NAV_ACRO, NAV_DESCEND, NAV_TERMINATION, NAV_OFFBOARD, NAV_STAB = 10, 12, 13, 14, 15
NAV_AUTO_TAKEOFF, NAV_AUTO_LAND = 17, 18
NAV_AUTO_FOLLOW_TARGET, NAV_ORBIT = 19, 21
NAV_STATE_OF_MODE = {
    FlightMode.MANUAL: NAV_MANUAL, FlightMode.ALTCTL: NAV_ALTCTL, FlightMode.POSCTL: NAV_POSCTL,
    FlightMode.AUTO_MISSION: NAV_AUTO_MISSION, FlightMode.AUTO_LOITER: NAV_AUTO_LOITER,
    FlightMode.AUTO_RTL: NAV_AUTO_RTL, FlightMode.ACRO: NAV_ACRO, FlightMode.OFFBOARD: NAV_OFFBOARD,
    FlightMode.STABILIZED: NAV_STAB, FlightMode.AUTO_TAKEOFF: NAV_AUTO_TAKEOFF,
    FlightMode.AUTO_LAND: NAV_AUTO_LAND,
    FlightMode.ORBIT: NAV_ORBIT, FlightMode.AUTO_FOLLOW_TARGET: NAV_AUTO_FOLLOW_TARGET,
}  # fmt: skip
NAV_NAMES = {
    NAV_MANUAL: "Manual", NAV_ALTCTL: "Altitude", NAV_POSCTL: "Position", NAV_AUTO_MISSION: "Mission",
    NAV_AUTO_LOITER: "Hold", NAV_AUTO_RTL: "Return", NAV_ACRO: "Acro", NAV_DESCEND: "Descend",
    NAV_TERMINATION: "Termination", NAV_OFFBOARD: "Offboard", NAV_STAB: "Stabilized",
    NAV_AUTO_TAKEOFF: "Takeoff", NAV_AUTO_LAND: "Land",
    NAV_ORBIT: "Orbit", NAV_AUTO_FOLLOW_TARGET: "Follow Target",
}  # fmt: skip


def _mask(*states: int) -> int:
    out = 0
    for s in states:
        out |= 1 << s
    return out


# PX4's mode requirements of a multicopter (ModeUtil/mode_requirements.cpp), for the modes flown
# here. OFFBOARD: PX4 derives its position requirement from the setpoints; here every OFFBOARD
# setpoint is a position or a velocity, so it needs the local position.
_MOVING = (NAV_ALTCTL, NAV_POSCTL, NAV_AUTO_MISSION, NAV_AUTO_LOITER, NAV_AUTO_RTL, NAV_DESCEND, NAV_OFFBOARD,
           NAV_STAB, NAV_AUTO_TAKEOFF, NAV_AUTO_LAND, NAV_ORBIT, NAV_AUTO_FOLLOW_TARGET)  # fmt: skip
MODE_REQ_ANGULAR_VELOCITY = _mask(*_MOVING, NAV_ACRO)
MODE_REQ_ATTITUDE = _mask(*_MOVING)
MODE_REQ_LOCAL_ALT = _mask(NAV_ALTCTL, NAV_POSCTL, NAV_AUTO_MISSION, NAV_AUTO_LOITER, NAV_AUTO_RTL,
                           NAV_AUTO_TAKEOFF, NAV_AUTO_LAND, NAV_ORBIT, NAV_AUTO_FOLLOW_TARGET)  # fmt: skip
MODE_REQ_LOCAL_POSITION = _mask(NAV_AUTO_MISSION, NAV_AUTO_LOITER, NAV_AUTO_RTL, NAV_AUTO_TAKEOFF,
                                NAV_OFFBOARD, NAV_ORBIT, NAV_AUTO_FOLLOW_TARGET)  # fmt: skip
MODE_REQ_LOCAL_POSITION_RELAXED = _mask(NAV_POSCTL, NAV_AUTO_LAND)
MODE_REQ_GLOBAL_POSITION = _mask(NAV_AUTO_MISSION, NAV_AUTO_LOITER, NAV_AUTO_RTL)
MODE_REQ_MISSION = _mask(NAV_AUTO_MISSION)
MODE_REQ_OFFBOARD_SIGNAL = _mask(NAV_OFFBOARD)
MODE_REQ_HOME_POSITION = _mask(NAV_AUTO_RTL)
MODE_REQ_WIND_AND_FLIGHT_TIME = _mask(NAV_AUTO_MISSION, NAV_AUTO_LOITER, NAV_ORBIT, NAV_AUTO_FOLLOW_TARGET)
MODE_REQ_PREVENT_ARMING = _mask(NAV_AUTO_RTL, NAV_DESCEND, NAV_TERMINATION, NAV_AUTO_LAND, NAV_ORBIT,
                                NAV_AUTO_FOLLOW_TARGET)  # fmt: skip
MODE_REQ_MANUAL_CONTROL = _mask(NAV_MANUAL, NAV_ALTCTL, NAV_POSCTL, NAV_ACRO, NAV_STAB)

STALE_S = 1.0  # PX4: an estimate (attitude, rates, position) older than this is invalid
PROBATION_S = 1.0  # PX4's checkPosVelValidity: good this long before valid again
VALID_HYSTERESIS = 2.5  # ... and while valid, the accuracy may reach this times the threshold
EQUAL_COUNT_MAX = 100  # PX4's DataValidator VALUE_EQUAL_COUNT_DEFAULT (counted over the axes)
STUCK_CHECK_S = 0.02  # a sensor's value is compared at most this often (every 10th IMU sample at 500 Hz)
STREAM_CHECK_S = 0.01  # the streams' silences are judged this often (PX4's commander loop, 100 Hz)
FRAME_TIME_EPS_S = 1e-6  # the frames' times are whole microseconds: "due" is to within one
REJECTING_S = 1.0  # the estimator's gate rejecting a sensor this long: unhealthy
HEADING_SIGMA_MAX_RAD = math.radians(15.0)  # a yaw 1-sigma above this: no heading
# How far the vehicle must have moved since a sensor's value froze for the freeze to be a fault.
MOVED_HEIGHT_M = 0.5
MOVED_HORIZONTAL_M = 1.0
MOVED_SPEED_M_S = 0.5
MOVED_ANGLE_RAD = math.radians(5.0)

SENSORS = ("gyro", "accel", "mag", "baro", "gps", "vision")
SENSOR_NAMES = {"gyro": "gyroscope", "accel": "accelerometer", "mag": "magnetometer", "baro": "barometer",
                "gps": "GPS", "vision": "vision"}  # fmt: skip
_STREAM_OF = {"gyro": "imu", "accel": "imu", "mag": "mag", "baro": "baro", "gps": "gps", "vision": "vision"}
# The estimator's measurement kinds (EstimatorStatus.sources) that judge each sensor.
_SOURCES_OF = {"mag": ("mag", "heading"), "baro": ("baro",), "gps": ("gps_pos",), "vision": ("ev_pos",)}


class SensorHealth(NamedTuple):
    """One sensor as the autopilot sees it."""

    present: bool = False  # it delivered a sample at least once
    healthy: bool = True
    problem: str = ""  # why not healthy ('' when healthy): "stopped", "stuck", "rejected", "no 3D fix"


# The verdicts there are (shared records: an evaluation allocates none of them).
_ABSENT = SensorHealth()
_HEALTHY = SensorHealth(True, True, "")
_STOPPED = SensorHealth(True, False, "stopped")
_NO_FIX = SensorHealth(True, False, "no 3D fix")
_STUCK = SensorHealth(True, False, "stuck")
_REJECTED = SensorHealth(True, False, "rejected by the estimator")


class FailsafeFlags(NamedTuple):
    """PX4's ``failsafe_flags`` (same names; false means no failure), then the heading and the
    sensors. The ``mode_req_*`` masks have bit ``1 << nav_state`` set for each navigation state
    needing that item."""

    timestamp_s: float = 0.0
    mode_req_angular_velocity: int = MODE_REQ_ANGULAR_VELOCITY
    mode_req_attitude: int = MODE_REQ_ATTITUDE
    mode_req_local_alt: int = MODE_REQ_LOCAL_ALT
    mode_req_local_position: int = MODE_REQ_LOCAL_POSITION
    mode_req_local_position_relaxed: int = MODE_REQ_LOCAL_POSITION_RELAXED
    mode_req_global_position: int = MODE_REQ_GLOBAL_POSITION
    mode_req_global_position_relaxed: int = 0
    mode_req_mission: int = MODE_REQ_MISSION
    mode_req_offboard_signal: int = MODE_REQ_OFFBOARD_SIGNAL
    mode_req_home_position: int = MODE_REQ_HOME_POSITION
    mode_req_wind_and_flight_time_compliance: int = MODE_REQ_WIND_AND_FLIGHT_TIME
    mode_req_prevent_arming: int = MODE_REQ_PREVENT_ARMING
    mode_req_manual_control: int = MODE_REQ_MANUAL_CONTROL
    mode_req_other: int = 0
    mode_req_not_possible: int = 0
    angular_velocity_invalid: bool = True
    attitude_invalid: bool = True
    local_altitude_invalid: bool = True
    local_position_invalid: bool = True
    local_position_invalid_relaxed: bool = True
    local_velocity_invalid: bool = True
    global_position_invalid: bool = True
    global_position_invalid_relaxed: bool = True
    auto_mission_missing: bool = True
    offboard_control_signal_lost: bool = True
    home_position_invalid: bool = True
    manual_control_signal_lost: bool = True
    gcs_connection_lost: bool = False
    battery_warning: int = 0
    battery_low_remaining_time: bool = False
    battery_unhealthy: bool = False
    fd_critical_failure: bool = False
    fd_esc_arming_failure: bool = False
    fd_imbalanced_prop: bool = False
    fd_motor_failure: bool = False
    fd_alt_loss: bool = False
    geofence_breached: bool = False
    mission_failure: bool = False
    vtol_fixed_wing_system_failure: bool = False
    wind_limit_exceeded: bool = False
    flight_time_limit_exceeded: bool = False
    position_accuracy_low: bool = False
    navigator_failure: bool = False
    parachute_unhealthy: bool = False
    traffic_avoidance_unhealthy: bool = False
    remote_id_unhealthy: bool = False
    gnss_lost: bool = False
    # -- beyond PX4's topic --------------------------------------------------------------------
    heading_invalid: bool = True
    gyro: SensorHealth = _ABSENT
    accel: SensorHealth = _ABSENT
    mag: SensorHealth = _ABSENT
    baro: SensorHealth = _ABSENT
    gps: SensorHealth = _ABSENT
    vision: SensorHealth = _ABSENT

    def sensor(self, name: str) -> SensorHealth:
        """The :class:`SensorHealth` of one sensor by its field name (one of :data:`SENSORS`: ``gyro``,
        ``accel``, ``mag``, ``baro``, ``gps``, ``vision``)."""
        return getattr(self, name)

    def unhealthy_sensors(self) -> list[str]:
        """'barometer (stuck)', ... for each present sensor that is not healthy."""
        out = []
        for name in SENSORS:
            s = getattr(self, name)
            if s.present and not s.healthy:
                out.append(f"{SENSOR_NAMES[name]} ({s.problem})")
        return out


# The fields of PX4's topic (the ULog ``failsafe_flags``): all but the ones beyond it.
PX4_FIELDS = FailsafeFlags._fields[1 : FailsafeFlags._fields.index("heading_invalid")]


def mode_can_run(flags: FailsafeFlags, nav_state: int) -> bool:
    """PX4's ``FailsafeBase::modeCanRun``: every item the mode needs is valid (the manual control
    requirement is handled apart, as in PX4)."""
    bit = 1 << nav_state
    f = flags
    return not (
        (f.angular_velocity_invalid and f.mode_req_angular_velocity & bit)
        or (f.attitude_invalid and f.mode_req_attitude & bit)
        or (f.local_position_invalid and f.mode_req_local_position & bit)
        or (f.local_position_invalid_relaxed and f.mode_req_local_position_relaxed & bit)
        or (f.global_position_invalid and f.mode_req_global_position & bit)
        or (f.local_altitude_invalid and f.mode_req_local_alt & bit)
        or (f.auto_mission_missing and f.mode_req_mission & bit)
        or (f.offboard_control_signal_lost and f.mode_req_offboard_signal & bit)
        or (f.home_position_invalid and f.mode_req_home_position & bit)
        or f.mode_req_other & bit
    )


def missing_for(flags: FailsafeFlags, nav_state: int) -> str:
    """What ``nav_state`` lacks, in words ('' when it can run), for refusals and announcements."""
    bit = 1 << nav_state
    f = flags
    checks = (
        (f.angular_velocity_invalid, f.mode_req_angular_velocity, "no angular velocity"),
        (f.attitude_invalid, f.mode_req_attitude, "no attitude estimate"),
        (f.global_position_invalid, f.mode_req_global_position, "no global position"),
        (f.local_position_invalid, f.mode_req_local_position, "no local position"),
        (f.local_position_invalid_relaxed, f.mode_req_local_position_relaxed, "no local position"),
        (f.local_altitude_invalid, f.mode_req_local_alt, "no altitude estimate"),
        (f.auto_mission_missing, f.mode_req_mission, "no mission"),
        (f.offboard_control_signal_lost, f.mode_req_offboard_signal, "no offboard signal"),
        (f.home_position_invalid, f.mode_req_home_position, "no home position"),
    )
    for invalid, mask, text in checks:
        if invalid and mask & bit:
            return text
    return ""


class Pose(Protocol):
    """The state the vehicle flies on, as far as the stuck checks read it (the commander's
    VehicleState)."""

    position_m: Vector3
    velocity_m_s: Vector3
    euler_rad: Vector3


class _StuckCheck:
    """One sensor's stuck check (PX4's DataValidator equal-value count), with the vehicle's state
    when the value froze.

    PX4 compares every sample with the one before. Here a sample is compared at most every
    :data:`STUCK_CHECK_S` (every sample of a sensor slower than that, every 10th of the 500 Hz
    IMU) with the last one compared, and an axis found equal counts once for every sample since
    that one: a stuck sensor repeats its value exactly, so the samples in between were equal too,
    and the count passes :data:`EQUAL_COUNT_MAX` after as many samples as PX4's, give or take one
    comparison's span (4 comparisons, 80 ms, for the IMU at 500 Hz; 34 samples in PX4). A sensor
    whose value came back to exactly the same number at each comparison and changed in between
    would count as stuck here; measured noise never does that.
    """

    __slots__ = ("value", "equal", "frozen_state", "samples", "due_s")

    def __init__(self) -> None:
        self.value: tuple[float, ...] | None = None  # the last value compared
        self.equal = 0
        self.frozen_state: Pose | None = None
        self.samples = 0  # samples since the last comparison
        self.due_s = -math.inf

    def offer(self, t: float, value: tuple[float, ...], state: Pose | None) -> None:
        """A sample at ``t``, compared when :data:`STUCK_CHECK_S` has passed since the last
        comparison."""
        self.samples += 1
        if t >= self.due_s:
            span, self.samples = self.samples, 0
            self.compare(t, value, span, state)

    def compare(self, t: float, value: tuple[float, ...], span: int, state: Pose | None) -> None:
        """``value`` at ``t`` against the last one compared, ``span`` samples ago."""
        self.due_s = t + STUCK_CHECK_S - FRAME_TIME_EPS_S
        last, self.value = self.value, value
        if last is None:
            return
        if value == last:  # (the common case on a noise-free sensor at rest)
            if self.equal == 0 or self.frozen_state is None:
                self.frozen_state = state
            self.equal += span * len(value)
        elif len(last) == len(value):
            for a, b in zip(last, value, strict=True):
                if a == b:
                    if self.equal == 0 or self.frozen_state is None:
                        self.frozen_state = state
                    self.equal += span
                else:
                    self.equal = 0


def _angle_moved(a: Vector3, b: Vector3) -> float:
    tau = 2.0 * math.pi
    return max(abs(math.remainder(a[0] - b[0], tau)), abs(math.remainder(a[1] - b[1], tau)),
               abs(math.remainder(a[2] - b[2], tau)))  # fmt: skip


def _moved(sensor: str, then: Pose, now: Pose, airborne: bool) -> bool:
    """Has the vehicle moved since ``then`` enough that ``sensor`` must read differently?

    A change of speed counts only while ``airborne``: on the ground the vehicle cannot change its
    speed without its sensors changing, and what changes there is the estimate, not the vehicle
    (at a touchdown the plant stops in a frame, a noise-free IMU reads exactly g and 0 from then
    on, and the EKF's velocity settles from the landing speed to 0 over a second or two)."""
    p0, v0, e0 = then.position_m, then.velocity_m_s, then.euler_rad
    p1, v1, e1 = now.position_m, now.velocity_m_s, now.euler_rad
    dv = math.dist(v0, v1) if airborne else 0.0
    angle = _angle_moved(e0, e1)
    if sensor == "baro":
        return abs(p1[2] - p0[2]) > MOVED_HEIGHT_M
    if sensor == "mag":
        return angle > MOVED_ANGLE_RAD
    if sensor == "accel":  # the specific force turns with the tilt, not with the heading
        tilt = max(abs(math.remainder(e0[0] - e1[0], 2.0 * math.pi)),
                   abs(math.remainder(e0[1] - e1[1], 2.0 * math.pi)))  # fmt: skip
        return tilt > MOVED_ANGLE_RAD or dv > MOVED_SPEED_M_S
    if sensor == "gyro":  # (a translation leaves the body rates at zero)
        return angle > MOVED_ANGLE_RAD
    if sensor == "gps":
        return math.hypot(p1[0] - p0[0], p1[1] - p0[1]) > MOVED_HORIZONTAL_M or dv > MOVED_SPEED_M_S
    return math.dist(p0, p1) > MOVED_HEIGHT_M or angle > MOVED_ANGLE_RAD  # vision


class _Validity:
    """PX4's ``checkPosVelValidity``: hysteresis in level (``VALID_HYSTERESIS``) and time
    (``PROBATION_S``)."""

    __slots__ = ("valid", "last_fail_s")

    def __init__(self) -> None:
        self.valid = False
        self.last_fail_s = -math.inf

    def update(self, t: float, data_valid: bool, accuracy: float, required: float) -> bool:
        limit = required * VALID_HYSTERESIS if self.valid else required
        if data_valid and accuracy < limit:
            if not self.valid and t > self.last_fail_s + PROBATION_S:
                self.valid = True
        else:
            self.valid = False
            self.last_fail_s = t
        return self.valid


class LinkState(NamedTuple):
    """What the commander knows besides the estimate and the sensors (the links, the plans)."""

    mission_missing: bool = True
    offboard_lost: bool = True
    home_invalid: bool = True
    manual_control_lost: bool = True
    gcs_connection_lost: bool = False
    geofence_breached: bool = False


class HealthMonitor:
    """Feed :meth:`observe` every frame's samples; :meth:`evaluate` gives the flags. The streams
    that stopped or resumed are announced (:attr:`announcements`, :meth:`take_announcements`)."""

    def __init__(self, params: ParameterStore) -> None:
        self.params = params
        self.streams = StreamWatch()
        self._stuck = {name: _StuckCheck() for name in SENSORS}
        self._imu_samples = 0  # (the gyro and the accelerometer sample together: counted once)
        self._streams_due = -math.inf
        self._state: Pose | None = None  # the state the vehicle flies on
        self.last_imu_s: float | None = None  # the last IMU (gyro and accelerometer) sample
        self.last_gps_fix_type = 0
        self._position = _Validity()
        self._velocity = _Validity()
        self._verdict: tuple | None = None  # what the last record was made of (evaluate)
        self.announcements: list[str] = []  # the sensor streams that stopped or resumed, as texts
        self._flags: FailsafeFlags | None = None

    def wants_samples(self, t: float, streams: int) -> bool:
        """Whether :meth:`observe` reads the values of a frame at ``t`` that delivered ``streams``
        (``STREAM_*`` bits): a stuck check due, or a GPS or vision sample. Where nothing else reads
        the sensors (on the simulator's state) the samples are decoded only then."""
        stuck = self._stuck
        return bool(
            streams & (STREAM_GPS | STREAM_VISION)
            or (streams & STREAM_IMU and t >= stuck["gyro"].due_s)
            or (streams & STREAM_MAG and t >= stuck["mag"].due_s)
            or (streams & STREAM_BARO and t >= stuck["baro"].due_s)
        )

    def observe(self, t: float, streams: int, samples: SensorSamples | None, state: Pose | None) -> None:
        """A frame at ``t``: the sensor streams that delivered (``STREAM_*`` bits), their samples
        (None: none, or not decoded: :meth:`wants_samples` said no) and the state the vehicle
        flies on (None before the first)."""
        self._state = state
        if streams:
            self.streams.note(t, streams)
        if t >= self._streams_due:
            self._check_streams(t)
        if not streams:
            return
        stuck = self._stuck
        if streams & STREAM_IMU:
            self.last_imu_s = t
            self._imu_samples += 1
        if samples is None:  # not decoded (no check due): the samples only counted
            if streams & STREAM_MAG:
                stuck["mag"].samples += 1
            if streams & STREAM_BARO:
                stuck["baro"].samples += 1
            return
        if streams & STREAM_IMU and t >= stuck["gyro"].due_s:
            span, self._imu_samples = self._imu_samples, 0
            stuck["gyro"].compare(t, samples.angular_rate_rad_s, span, state)
            stuck["accel"].compare(t, samples.specific_force_m_s2, span, state)
        if samples.mag_gauss is not None:
            stuck["mag"].offer(t, samples.mag_gauss, state)
        if samples.baro_height_m is not None:
            stuck["baro"].offer(t, (samples.baro_height_m,), state)
        gps = samples.gps
        if gps is not None:
            self.last_gps_fix_type = gps.fix_type
            if gps.fix_type >= 3:
                stuck["gps"].offer(t, gps.position_m, state)
        if samples.vision is not None:
            v = samples.vision
            stuck["vision"].offer(t, (*v.position_m, v.yaw_rad), state)

    def restart_clock(self) -> None:
        """The simulation time went back (the simulator restarted): every check is due."""
        self._streams_due = -math.inf
        for check in self._stuck.values():
            check.due_s = -math.inf

    def _check_streams(self, t: float) -> None:
        """The streams' silences (:meth:`StreamWatch.check`), every :data:`STREAM_CHECK_S` and
        before each evaluation."""
        self._streams_due = t + STREAM_CHECK_S - FRAME_TIME_EPS_S
        texts = self.streams.check(t)
        if texts:
            self.announcements += texts

    def take_announcements(self) -> list[str]:
        """The sensor streams that stopped or resumed since the last call, as texts."""
        texts, self.announcements = self.announcements, []
        return texts

    def _sensor(self, name: str, estimator: EstimatorStatus | None, airborne: bool) -> SensorHealth:
        stream = _STREAM_OF[name]
        if stream not in self.streams.last:
            return _ABSENT
        if stream in self.streams.stopped:
            return _STOPPED
        if name == "gps" and self.last_gps_fix_type < 3:
            return _NO_FIX
        check = self._stuck[name]
        frozen, now = check.frozen_state, self._state
        frozen_long = check.equal > EQUAL_COUNT_MAX and frozen is not None and now is not None
        if frozen_long and _moved(name, frozen, now, airborne):
            return _STUCK
        if estimator is not None and estimator.initialised:
            for kind in _SOURCES_OF.get(name, ()):
                since = estimator.sources[kind].rejecting_since_s
                if since >= 0.0 and estimator.time_s - since > REJECTING_S:
                    return _REJECTED
        return _HEALTHY

    def evaluate(
        self,
        t: float,
        estimator: EstimatorStatus | None,
        on_ekf: bool,
        has_state: bool,
        links: LinkState,
        airborne: bool,
    ) -> FailsafeFlags:
        """The flags at ``t``: ``estimator`` is the EKF's last status (None before its first or on
        the truth), ``on_ekf`` whether the vehicle flies on the EKF, ``has_state`` whether it has
        a state at all (frames flowing), ``airborne`` whether it is off the ground (the stuck
        checks count a change of speed only then). The record of the last call when nothing in it changed
        (its ``timestamp_s`` is then the time of that call)."""
        p = self.params
        self._check_streams(t)  # (the streams' state as of now: the record is consistent)
        judged_by = estimator if on_ekf else None
        sensors = tuple([self._sensor(name, judged_by, airborne) for name in SENSORS])
        if not on_ekf:  # the simulator's state: valid while frames flow
            bad = not has_state
            rates = attitude = local = velocity = altitude = heading = bad
            low = False
        else:
            imu_fresh = self.last_imu_s is not None and t - self.last_imu_s <= STALE_S
            ready = estimator is not None and estimator.initialised and imu_fresh and has_state
            rates = not imu_fresh
            attitude = not ready
            eph = estimator.pos_horiz_accuracy_m if ready else math.inf
            flags = estimator.flags if ready else 0
            fs_eph = p["COM_POS_FS_EPH"]
            required = math.inf if fs_eph < 0.0 else fs_eph
            local = not self._position.update(t, bool(flags & ESTIMATOR_POS_HORIZ_REL), eph, required)
            evh = estimator.vel_accuracy_m_s if ready else math.inf
            velocity = not self._velocity.update(t, bool(flags & ESTIMATOR_VELOCITY_HORIZ), evh,
                                                 p["COM_VEL_FS_EVH"])  # fmt: skip
            altitude = not (flags & ESTIMATOR_POS_VERT_ABS)
            heading = not ready or estimator.yaw_accuracy_rad > HEADING_SIGMA_MAX_RAD
            low_eph = p["COM_POS_LOW_EPH"]
            low = not local and low_eph > 0.0 and eph > low_eph
        # The local position with the relaxed (no) accuracy requirement: aiding alone.
        relaxed = local if not on_ekf else not (ready and estimator.flags & ESTIMATOR_POS_HORIZ_REL)
        verdict = (rates, attitude, altitude, local, relaxed, velocity, low, heading, links, sensors)
        if verdict == self._verdict and self._flags is not None:
            return self._flags
        self._verdict = verdict
        self._flags = FailsafeFlags(
            timestamp_s=t,
            angular_velocity_invalid=rates,
            attitude_invalid=attitude,
            local_altitude_invalid=altitude,
            local_position_invalid=local,
            local_position_invalid_relaxed=relaxed,
            local_velocity_invalid=velocity,
            global_position_invalid=local,
            global_position_invalid_relaxed=relaxed,
            auto_mission_missing=links.mission_missing,
            offboard_control_signal_lost=links.offboard_lost,
            home_position_invalid=links.home_invalid,
            manual_control_signal_lost=links.manual_control_lost,
            gcs_connection_lost=links.gcs_connection_lost,
            geofence_breached=links.geofence_breached,
            position_accuracy_low=low,
            heading_invalid=heading,
            **dict(zip(SENSORS, sensors, strict=True)),
        )
        return self._flags
