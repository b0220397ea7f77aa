"""Follow-me (PX4's AUTO.FOLLOW_TARGET): follow a target a ground station reports in FOLLOW_TARGET.

Pure: no clock, no socket; reports and steps come with their simulation times. As PX4's
``TargetEstimator`` and ``FlightTaskAutoFollowTarget``, in the paper frame (x north, y west, z up):

* **The target's estimate** (:class:`TargetEstimator`): each report is blended into a constant-
  velocity estimate with the weight ``1 - FLW_TGT_RS`` (PX4's responsiveness: lower follows the
  reports faster and filters less); the velocity is the report's when it carries one, else the
  change of the reported positions. Between reports the estimate is carried forward at its
  velocity. No report for :data:`TARGET_STALE_S` (PX4's stale timeout): the target is lost.
* **Where to be**: ``FLW_TGT_DST`` from the target, at ``FLW_TGT_FA`` from its course (clockwise
  seen from above, 0 in front, 180 behind; the course is the direction the target moves in, kept
  while it stands still); the angle around the target changes at most at ``FLW_TGT_MAX_VEL`` of
  tangential speed. Altitude by ``FLW_TGT_ALT_M``: ``FLW_TGT_HT`` above home (0; 1 above the
  terrain, which here is the flat ground: the same) or above the target (2), never lower than
  :data:`MIN_HEIGHT_M` above the ground (PX4's emergency ascent height). More than
  :data:`ALTITUDE_FIRST_M` from that altitude, the vehicle first climbs or descends where it is
  (PX4: "achieve target altitude first").
* **How**: the reference moves towards that point with the target's velocity as feed forward,
  within ``MPC_XY_VEL_MAX``, ``MPC_Z_VEL_MAX_UP/DN`` and ``MPC_ACC_HOR``; the vehicle faces the
  target (turning at most at ``MPC_YAWRAUTO_MAX``) once more than :data:`YAW_MIN_DISTANCE_M` from it.
* **Target lost** (or none yet): the vehicle stops and holds where it is, still in
  AUTO.FOLLOW_TARGET (PX4: "stay in current position"), and follows again when reports resume.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from quadcommon.frames import wrap_pi
from quadcommon.trajectories import Reference, Trajectory

from .orbit import slew_yaw
from .planner import Limits, stop_from

Vector3 = tuple[float, float, float]

TARGET_STALE_S = 3.0  # PX4 TargetEstimator: GPS_MESSAGE_STALE_TIMEOUT_MS
MOVING_SPEED_M_S = 0.1  # PX4: a target slower than this keeps its last course
ALTITUDE_FIRST_M = 3.0  # PX4: ALT_ACCEPTANCE_THRESHOLD
MIN_HEIGHT_M = 1.0  # PX4: MINIMUM_SAFETY_ALTITUDE
YAW_MIN_DISTANCE_M = 1.0  # PX4: MINIMUM_DISTANCE_TO_TARGET_FOR_YAW_CONTROL
POSITION_GAIN_1_S = 1.0  # the reference's approach to the follow point: speed per metre of distance
WEIGHT_MIN = 0.02  # FLW_TGT_RS = 1 would ignore every report: the estimate still moves

FOLLOW_ALT_HOME, FOLLOW_ALT_TERRAIN, FOLLOW_ALT_TARGET = 0, 1, 2  # FLW_TGT_ALT_M


class TargetReport(NamedTuple):
    """One FOLLOW_TARGET, checked at the edge (:mod:`autopilot.mavlink.follow_target`)."""

    time_s: float  # simulation time of arrival
    position_m: Vector3  # paper frame
    velocity_m_s: Vector3 | None  # paper frame; None: not reported


class FollowSettings(NamedTuple):
    """The FLW_TGT_* parameters and the limits the reference keeps (from the parameter store)."""

    height_m: float  # FLW_TGT_HT
    distance_m: float  # FLW_TGT_DST
    angle_deg: float  # FLW_TGT_FA
    altitude_mode: int  # FLW_TGT_ALT_M
    tangential_speed_m_s: float  # FLW_TGT_MAX_VEL
    responsiveness: float  # FLW_TGT_RS
    travel: Limits


class TargetEstimate(NamedTuple):
    position_m: Vector3
    velocity_m_s: Vector3


class TargetEstimator:
    """The target's position and velocity from its reports (an alpha filter at constant velocity)."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        """Forget the target: the next report starts the estimate afresh."""
        self._position: Vector3 | None = None
        self._velocity: Vector3 = (0.0, 0.0, 0.0)
        self._last_measured: Vector3 = (0.0, 0.0, 0.0)
        self._time = 0.0
        self.last_report_s = -math.inf

    def report(self, r: TargetReport, responsiveness: float) -> None:
        """Fuse one FOLLOW_TARGET report with weight ``max(1 - FLW_TGT_RS, WEIGHT_MIN)`` on the prediction at
        constant velocity; its velocity from the report, else from the last two positions. The first
        report, or one after :data:`TARGET_STALE_S` of silence, restarts the estimate at the report."""
        weight = max(1.0 - responsiveness, WEIGHT_MIN)
        if self._position is None or r.time_s - self.last_report_s > TARGET_STALE_S:
            self._position = r.position_m
            self._velocity = r.velocity_m_s or (0.0, 0.0, 0.0)
        else:
            dt = r.time_s - self._time
            predicted = _along(self._position, self._velocity, dt)
            if r.velocity_m_s is not None:
                measured_velocity = r.velocity_m_s
            elif r.time_s - self.last_report_s > 1e-3:
                gap = r.time_s - self.last_report_s
                measured_velocity = tuple((p - q) / gap for p, q in zip(r.position_m, self._last_measured,
                                                                       strict=True))  # fmt: skip
            else:
                measured_velocity = self._velocity
            self._position = _blend(predicted, r.position_m, weight)
            self._velocity = _blend(self._velocity, measured_velocity, weight)
        self._last_measured = r.position_m
        self._time = self.last_report_s = r.time_s

    def estimate(self, t: float) -> TargetEstimate | None:
        """The target at ``t``, or None: no report yet, or none for :data:`TARGET_STALE_S`."""
        if self._position is None or t - self.last_report_s > TARGET_STALE_S:
            return None
        return TargetEstimate(_along(self._position, self._velocity, t - self._time), self._velocity)


class FollowTarget:
    """The follow-me mode's reference, one control step at a time."""

    def __init__(self) -> None:
        self.target = TargetEstimator()
        self.lost = True  # no target to follow (none yet, or its reports stopped)
        self._offset_angle: float | None = None  # where around the target, world angle (paper frame)
        self._course = 0.0  # the target's direction of motion, kept while it stands still
        self._hold: Trajectory | None = None
        self._hold_start = 0.0
        self._ref: Reference | None = None

    def enter(self, yaw_rad: float) -> None:
        """Entering the mode: the vehicle's heading stands for the target's course until it moves
        (PX4: so that the vehicle at least faces the target)."""
        self._offset_angle = None
        self._course = yaw_rad
        self._hold = None
        self._ref = None
        self.lost = True

    def reference(self, t: float, dt: float, position_m: Vector3, previous: Reference, home_m: Vector3,
                  s: FollowSettings) -> Reference:  # fmt: skip
        """This step's reference; ``position_m`` is the measured position."""
        target = self.target.estimate(t)
        if target is None:
            self.lost = True
            if self._hold is None:
                self._hold, self._hold_start = stop_from(previous, s.travel), t
            self._ref = None
            return self._hold.sample(t - self._hold_start)
        self.lost = False
        self._hold = None
        ref = self._ref or previous
        tx, ty, tz = target.position_m
        vx, vy, vz = target.velocity_m_s
        if math.hypot(vx, vy) > MOVING_SPEED_M_S:
            self._course = math.atan2(vy, vx)
        wanted = self._course - math.radians(s.angle_deg)  # clockwise from the course (z up)
        if self._offset_angle is None:
            self._offset_angle = wanted
        rate = s.tangential_speed_m_s / s.distance_m
        turn = wrap_pi(wanted - self._offset_angle)
        self._offset_angle = wrap_pi(self._offset_angle + min(max(turn, -rate * dt), rate * dt))
        base = tz if s.altitude_mode == FOLLOW_ALT_TARGET else home_m[2]
        z = max(base + s.height_m, home_m[2] + MIN_HEIGHT_M)
        goal = (tx + s.distance_m * math.cos(self._offset_angle),
                ty + s.distance_m * math.sin(self._offset_angle), z)  # fmt: skip
        feed = (vx, vy, vz if s.altitude_mode == FOLLOW_ALT_TARGET else 0.0)
        if abs(z - position_m[2]) > ALTITUDE_FIRST_M:  # the altitude first, where it is
            goal = (ref.position_m[0], ref.position_m[1], z)
            feed = (0.0, 0.0, 0.0)
        new = _track(ref, goal, feed, s.travel, dt)
        to_x, to_y = tx - new.position_m[0], ty - new.position_m[1]
        far = math.hypot(to_x, to_y) > YAW_MIN_DISTANCE_M
        yaw_target = math.atan2(to_y, to_x) if far else previous.yaw_rad
        yaw, yaw_rate, yaw_acc = slew_yaw(previous.yaw_rad, yaw_target, 0.0, 0.0, s.travel.yaw_rate, dt)
        self._ref = new._replace(yaw_rad=yaw, yaw_rate_rad_s=yaw_rate, yaw_acceleration_rad_s2=yaw_acc)
        return self._ref


def _track(ref: Reference, goal: Vector3, feed: Vector3, limits: Limits, dt: float) -> Reference:
    """One step of the reference towards ``goal``: velocity = feed forward + gain x distance, within
    the speed limits, changed at most at the acceleration limit."""
    want = [f + POSITION_GAIN_1_S * (g - p) for f, g, p in zip(feed, goal, ref.position_m, strict=True)]
    horizontal = math.hypot(want[0], want[1])
    if horizontal > limits.speed_horizontal:
        want[0] *= limits.speed_horizontal / horizontal
        want[1] *= limits.speed_horizontal / horizontal
    want[2] = min(max(want[2], -limits.speed_down), limits.speed_up)
    dv = [w - v for w, v in zip(want, ref.velocity_m_s, strict=True)]
    norm = math.sqrt(sum(d * d for d in dv))
    reach = limits.acceleration * dt
    if norm > reach:
        dv = [d * reach / norm for d in dv]
    velocity = tuple(v + d for v, d in zip(ref.velocity_m_s, dv, strict=True))
    position = tuple(p + v * dt for p, v in zip(ref.position_m, velocity, strict=True))
    acceleration = tuple(d / dt for d in dv) if dt > 0.0 else (0.0, 0.0, 0.0)
    return Reference(position, velocity, acceleration, ref.yaw_rad, 0.0, 0.0)  # type: ignore[arg-type]


def _along(p: Vector3, v: Vector3, dt: float) -> Vector3:
    return (p[0] + v[0] * dt, p[1] + v[1] * dt, p[2] + v[2] * dt)


def _blend(old: Vector3, new: Vector3, weight: float) -> Vector3:
    return tuple(o + weight * (n - o) for o, n in zip(old, new, strict=True))  # type: ignore[return-value]
