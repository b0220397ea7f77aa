"""Orbit (MAV_CMD_DO_ORBIT, PX4's Orbit mode): circle a centre at a radius and a tangential speed.

Pure: no clock, no socket; the commander passes the simulation time step and the vehicle's
measured position. Behaviour as PX4's ``FlightTaskOrbit`` (its main branch), in this project's
frames (paper: x north, y west, z up; positive radius = clockwise seen from above, as MAVLink says):

* **Entering** (the mode asked for, or a DO_ORBIT): the centre is where the vehicle is, the radius
  :data:`RADIUS_MIN_M`, the speed :data:`DEFAULT_SPEED_M_S` clockwise, the yaw behaviour
  ``MC_ORBIT_YAW_MOD``; a DO_ORBIT's finite parameters then replace them (NaN keeps them: the
  radius, the speed, the yaw behaviour, the centre, the centre's altitude).
* **Limits** (PX4's ``_sanitizeParams``): a radius outside [:data:`RADIUS_MIN_M`,
  ``MC_ORBIT_RAD_MAX``] is refused ("Orbit radius limit exceeded"); the speed is clipped to
  :data:`SPEED_MAX_M_S` (and here also to ``MPC_XY_VEL_MAX``, which PX4's position controller
  applies after the task) and then lowered until the centripetal acceleration ``v^2 / r`` stays
  below :data:`ACCELERATION_MAX_M_S2` (a small radius flown slowly is the safe combination).
* **Approach**: off the circle (more than :data:`ON_CIRCLE_M` from it horizontally or
  :data:`ON_CIRCLE_ALT_M` vertically: PX4's acceptance radius and ``NAV_MC_ALT_RAD``) the vehicle
  flies straight to the closest point of the circle at the centre's altitude, facing the centre,
  as a smooth rest-to-rest move (:class:`~.planner.LineMove` at ``MPC_XY_VEL_MAX``).
* **On the circle**: the reference runs around it at the commanded speed (reached at
  ``MPC_ACC_HOR`` from the speed it had), with the centripetal acceleration ``v^2 / r`` as feed
  forward; the yaw follows ``ORBIT_YAW_BEHAVIOUR`` (:data:`YAW_FRONT_TO_CENTRE` ...), turned at
  most at ``MPC_YAWRAUTO_MAX`` (PX4's yaw slew rate).

The orbit flies until another mode is asked for (param4, the number of turns, is not read: PX4
orbits forever too).
"""

from __future__ import annotations

import math
from typing import NamedTuple

from quadcommon.frames import wrap_pi
from quadcommon.trajectories import PiecewiseTrajectory, Reference, Trajectory

from .planner import Limits, LineMove, stop_from

Vector3 = tuple[float, float, float]

RADIUS_MIN_M = 1.0  # PX4 FlightTaskOrbit: _radius_min
SPEED_MAX_M_S = 10.0  # PX4: _velocity_max
ACCELERATION_MAX_M_S2 = 2.0  # PX4: _acceleration_max (centripetal)
DEFAULT_SPEED_M_S = 1.0  # PX4: the speed on entering the mode
ON_CIRCLE_M = 1.0  # PX4: _horizontal_acceptance_radius
ON_CIRCLE_ALT_M = 0.8  # PX4: NAV_MC_ALT_RAD's default
# A new radius within ON_CIRCLE_M of the circle flown is reached at this radial speed (PX4 closes the
# gap with its velocity feedback; a step of the reference would jolt the cascade).
RADIUS_RATE_M_S = 1.0

# MAVLink ORBIT_YAW_BEHAVIOUR
YAW_FRONT_TO_CENTRE, YAW_HOLD_INITIAL, YAW_UNCONTROLLED, YAW_FRONT_TANGENT, YAW_RC, YAW_UNCHANGED = range(6)
YAW_NAMES = {
    YAW_FRONT_TO_CENTRE: "front to the centre", YAW_HOLD_INITIAL: "initial heading",
    YAW_UNCONTROLLED: "uncontrolled", YAW_FRONT_TANGENT: "front tangent to the circle",
    YAW_RC: "yaw stick",
}  # fmt: skip


class OrbitLimits(NamedTuple):
    """What limits an orbit (from the parameters)."""

    radius_max_m: float  # MC_ORBIT_RAD_MAX
    speed_max_m_s: float  # min(SPEED_MAX_M_S, MPC_XY_VEL_MAX)
    travel: Limits  # the approach's and the speed ramp's limits (MPC_*)
    default_yaw_behaviour: int  # MC_ORBIT_YAW_MOD


class OrbitRequest(NamedTuple):
    """One DO_ORBIT in the paper frame; None: keep (MAVLink's NaN)."""

    radius_m: float | None = None  # signed: > 0 clockwise seen from above
    speed_m_s: float | None = None  # tangential speed (its sign multiplies the radius's direction)
    yaw_behaviour: int | None = None  # ORBIT_YAW_BEHAVIOUR (YAW_UNCHANGED: keep)
    centre_xy_m: tuple[float, float] | None = None
    centre_z_m: float | None = None


class OrbitStatus(NamedTuple):
    """What ORBIT_EXECUTION_STATUS reports (paper frame)."""

    radius_m: float  # signed: > 0 clockwise
    centre_m: Vector3
    yaw_behaviour: int


def sanitize(radius_m: float, velocity_m_s: float, limits: OrbitLimits) -> tuple[float, float]:
    """PX4's ``_sanitizeParams``: the radius clipped to its range, the signed velocity to the speed
    limit, then lowered so that ``v^2 / r`` stays below :data:`ACCELERATION_MAX_M_S2`."""
    radius = min(max(radius_m, RADIUS_MIN_M), limits.radius_max_m)
    speed_max = limits.speed_max_m_s
    velocity = min(max(velocity_m_s, -speed_max), speed_max)
    if velocity * velocity >= ACCELERATION_MAX_M_S2 * radius:
        velocity = math.copysign(math.sqrt(ACCELERATION_MAX_M_S2 * radius), velocity)
    return radius, velocity


def radius_refusal(request: OrbitRequest, limits: OrbitLimits) -> str | None:
    """Why PX4 refuses the request's radius (outside [RADIUS_MIN_M, MC_ORBIT_RAD_MAX]), or None."""
    if request.radius_m is None or RADIUS_MIN_M <= abs(request.radius_m) <= limits.radius_max_m:
        return None
    return (f"Orbit radius limit exceeded: {abs(request.radius_m):g} m outside [{RADIUS_MIN_M:g}, "
            f"{limits.radius_max_m:g}] m (MC_ORBIT_RAD_MAX)")  # fmt: skip


class Orbit:
    """The Orbit mode's state and its reference, one control step at a time."""

    def __init__(self) -> None:
        self.centre: Vector3 = (0.0, 0.0, 0.0)
        self.radius_m = RADIUS_MIN_M
        self.velocity_m_s = DEFAULT_SPEED_M_S  # signed: > 0 clockwise
        self.yaw_behaviour = YAW_FRONT_TO_CENTRE
        self.initial_heading = 0.0
        self._approach: Trajectory | None = None  # flying to the circle (None: on it)
        self._approach_start = 0.0
        self._angle = 0.0  # the reference's angle around the centre (paper frame, from +x)
        self._speed = 0.0  # the reference's signed tangential speed now (ramps to velocity_m_s)
        self._radius = RADIUS_MIN_M  # the reference's radius now (moves to radius_m)

    @property
    def status(self) -> OrbitStatus:
        """What ORBIT_EXECUTION_STATUS reports now: the radius signed by the direction (> 0 clockwise), the
        centre and the yaw behaviour."""
        return OrbitStatus(math.copysign(self.radius_m, self.velocity_m_s), self.centre, self.yaw_behaviour)

    @property
    def approaching(self) -> bool:
        """True while the vehicle flies to the circle, False once it flies on it."""
        return self._approach is not None

    def enter(self, position_m: Vector3, yaw_rad: float, limits: OrbitLimits) -> None:
        """Entering the mode (PX4's ``activate``): centre here, the smallest radius, 1 m/s."""
        self.centre = position_m
        self.radius_m, self.velocity_m_s = sanitize(RADIUS_MIN_M, DEFAULT_SPEED_M_S, limits)
        self.yaw_behaviour = limits.default_yaw_behaviour
        self.initial_heading = yaw_rad
        self._approach = None
        self._speed = 0.0

    def apply(self, request: OrbitRequest, yaw_rad: float, limits: OrbitLimits) -> str | None:
        """A DO_ORBIT's parameters (PX4's ``applyCommandParameters``); the reason a radius is
        refused, or None. The rest of the command applies either way, as in PX4."""
        refused = radius_refusal(request, limits)
        clockwise = self.velocity_m_s > 0.0
        radius = self.radius_m
        speed = abs(self.velocity_m_s)
        if request.radius_m is not None:
            clockwise = request.radius_m > 0.0
            radius = abs(request.radius_m)
        if request.speed_m_s is not None:
            speed = request.speed_m_s
        if refused is None:
            self.radius_m, self.velocity_m_s = sanitize(radius, speed if clockwise else -speed, limits)
        if request.yaw_behaviour is not None and request.yaw_behaviour != YAW_UNCHANGED:
            self.yaw_behaviour = request.yaw_behaviour
        self.initial_heading = yaw_rad
        cx, cy, cz = self.centre
        if request.centre_xy_m is not None:
            cx, cy = request.centre_xy_m
        if request.centre_z_m is not None:
            cz = request.centre_z_m
        self.centre = (cx, cy, cz)
        return refused

    def on_circle(self, position_m: Vector3) -> bool:
        """Within PX4's acceptance of the circle (horizontally and in altitude)."""
        cx, cy, cz = self.centre
        off = abs(math.hypot(position_m[0] - cx, position_m[1] - cy) - self.radius_m)
        return off < ON_CIRCLE_M and abs(position_m[2] - cz) < ON_CIRCLE_ALT_M

    def reference(
        self, t: float, dt: float, position_m: Vector3, previous: Reference, limits: OrbitLimits,
        yaw_stick_rate_rad_s: float = 0.0,
    ) -> Reference:
        """This step's reference: approaching the circle, or on it. ``position_m`` is the measured
        position (it decides on or off the circle, as PX4), ``previous`` the reference flown the
        step before (the new one continues it); ``yaw_stick_rate_rad_s`` turns the vehicle in the
        yaw-stick behaviour."""
        if self._approach is None and not self.on_circle(position_m):
            self._plan_approach(t, previous, limits.travel)
        if self._approach is not None:
            local = t - self._approach_start
            if local < self._approach.duration_s:
                return self._approach.sample(local)
            end = self._approach.sample(self._approach.duration_s)
            self._approach = None
            self._start_circling(end)
            previous = end
        return self._circle(dt, previous, limits, yaw_stick_rate_rad_s)

    def _plan_approach(self, t: float, start: Reference, travel: Limits) -> None:
        """Brake, then a straight move to the closest point of the circle, facing the centre."""
        brake = stop_from(start, travel)
        p = brake.sample(brake.duration_s).position_m
        cx, cy, cz = self.centre
        dx, dy = p[0] - cx, p[1] - cy
        distance = math.hypot(dx, dy)
        if distance < 1e-6:  # at the centre: out along the current heading
            dx, dy, distance = math.cos(start.yaw_rad), math.sin(start.yaw_rad), 1.0
        target = (cx + dx / distance * self.radius_m, cy + dy / distance * self.radius_m, cz)
        facing = math.atan2(cy - target[1], cx - target[0])
        yaw1 = start.yaw_rad + wrap_pi(facing - start.yaw_rad)
        self._approach = PiecewiseTrajectory([brake, LineMove(p, target, travel, start.yaw_rad, yaw1)])
        self._approach_start = t

    def _start_circling(self, at: Reference) -> None:
        cx, cy, _ = self.centre
        self._angle = math.atan2(at.position_m[1] - cy, at.position_m[0] - cx)
        self._radius = math.hypot(at.position_m[1] - cy, at.position_m[0] - cx)
        # the tangential speed the reference has (clockwise positive: -d(angle)/dt r)
        tangent = (-math.sin(self._angle), math.cos(self._angle))
        self._speed = -(at.velocity_m_s[0] * tangent[0] + at.velocity_m_s[1] * tangent[1])

    def _circle(self, dt: float, previous: Reference, limits: OrbitLimits, yaw_stick: float) -> Reference:
        reach = RADIUS_RATE_M_S * dt
        grow = min(max(self.radius_m - self._radius, -reach), reach)
        self._radius += grow
        r = self._radius
        radial = grow / dt if dt > 0.0 else 0.0
        step = limits.travel.acceleration * dt
        change = min(max(self.velocity_m_s - self._speed, -step), step)
        self._speed += change
        tangential = change / dt if dt > 0.0 else 0.0
        omega = -self._speed / r  # about z up: clockwise seen from above is negative
        alpha = -tangential / r
        self._angle = wrap_pi(self._angle + omega * dt)
        c, s = math.cos(self._angle), math.sin(self._angle)
        cx, cy, cz = self.centre
        position = (cx + r * c, cy + r * s, cz)
        velocity = (-r * omega * s + radial * c, r * omega * c + radial * s, 0.0)
        acceleration = (-r * omega * omega * c - r * alpha * s, -r * omega * omega * s + r * alpha * c, 0.0)
        yaw, yaw_rate, yaw_acc = self._yaw_target(previous, omega, alpha, yaw_stick, dt)
        yaw_max = limits.travel.yaw_rate
        yaw, yaw_rate, yaw_acc = slew_yaw(previous.yaw_rad, yaw, yaw_rate, yaw_acc, yaw_max, dt)
        return Reference(position, velocity, acceleration, yaw, yaw_rate, yaw_acc)

    def _yaw_target(
        self, previous: Reference, omega: float, alpha: float, yaw_stick: float, dt: float
    ) -> tuple[float, float, float]:
        """The yaw ORBIT_YAW_BEHAVIOUR asks for, its rate and acceleration."""
        behaviour = self.yaw_behaviour
        if behaviour == YAW_HOLD_INITIAL:
            return self.initial_heading, 0.0, 0.0
        if behaviour == YAW_UNCONTROLLED:  # no yaw setpoint: the heading stays as it is
            return previous.yaw_rad, 0.0, 0.0
        if behaviour == YAW_RC:
            return wrap_pi(previous.yaw_rad + yaw_stick * dt), yaw_stick, 0.0
        if behaviour == YAW_FRONT_TANGENT:  # along the velocity
            return wrap_pi(self._angle + math.copysign(math.pi / 2.0, omega or 1.0)), omega, alpha
        return wrap_pi(self._angle + math.pi), omega, alpha  # front to the centre (PX4's default)


def slew_yaw(previous: float, target: float, rate: float, acceleration: float, rate_max: float, dt: float
          ) -> tuple[float, float, float]:  # fmt: skip
    """PX4's yaw slew rate: the yaw turns towards ``target`` at most at ``rate_max``."""
    error = wrap_pi(target - previous)
    reach = rate_max * dt
    if abs(error) <= reach:
        return target, rate, acceleration
    return wrap_pi(previous + math.copysign(reach, error)), math.copysign(rate_max, error), 0.0
