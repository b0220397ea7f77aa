"""Smooth, time-parameterised motion between points, within speed and acceleration limits.

Everything the commander and the missions fly is built here, so the cascade always gets
p_d, p_d', p_d'' (C2 or smoother), never steps:

* :class:`LineMove`: rest-to-rest along a straight line with an S-curve speed profile: the speed
  ramps up and down with a quintic smoothstep (so acceleration is continuous and starts and ends
  at zero) and cruises at the speed limit in between; the ramp time is chosen so the peak
  acceleration (1.875 v/T) meets the limit. Yaw turns with a quintic over the same time.
* :func:`transition`: from any (p, v, a) to rest at a point (a quintic), with a duration long
  enough that sampled speed and acceleration stay within the limits; used when a new target
  arrives while moving.
* :func:`stop_from`: brake to rest (hold, landing and RTL entry).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from quadcommon.trajectories import PiecewiseTrajectory, QuinticSegment, Reference, Trajectory

Vector3 = tuple[float, float, float]
ZERO3: Vector3 = (0.0, 0.0, 0.0)
_PEAK_ACCEL = 1.875  # max of d/dt smoothstep5 = 15/8


@dataclass(frozen=True)
class Limits:
    """Speed and acceleration limits (m/s, m/s^2) for planned motion."""

    speed_horizontal: float = 2.0
    speed_up: float = 1.5
    speed_down: float = 1.0
    acceleration: float = 2.0
    yaw_rate: float = 1.0  # rad/s

    def line_speed(self, direction: Vector3) -> float:
        """Largest speed along a unit ``direction`` within the horizontal and vertical limits."""
        h = math.hypot(direction[0], direction[1])
        vz = direction[2]
        limits = []
        if h > 1e-9:
            limits.append(self.speed_horizontal / h)
        if vz > 1e-9:
            limits.append(self.speed_up / vz)
        elif vz < -1e-9:
            limits.append(self.speed_down / -vz)
        return min(limits) if limits else self.speed_horizontal


def _smoothstep(u: float) -> tuple[float, float, float]:
    """s(u) = 10u^3 - 15u^4 + 6u^5 and its first two derivatives, u in [0, 1]."""
    u2 = u * u
    return (u2 * u * (10.0 - 15.0 * u + 6.0 * u2), 30.0 * u2 * (1.0 - u) ** 2,
            60.0 * u * (1.0 - u) * (1.0 - 2.0 * u))  # fmt: skip


class LineMove:
    """Rest-to-rest straight move from ``start`` to ``end`` with an S-curve speed profile."""

    def __init__(
        self,
        start: Vector3,
        end: Vector3,
        limits: Limits,
        yaw0: float = 0.0,
        yaw1: float = 0.0,
        speed: float | None = None,
    ) -> None:
        delta = tuple(e - s for s, e in zip(start, end, strict=True))
        distance = math.sqrt(sum(d * d for d in delta))
        self.start, self.end, self.distance = start, end, distance
        self.direction = tuple(d / distance for d in delta) if distance > 1e-9 else ZERO3
        cruise = limits.line_speed(self.direction)  # type: ignore[arg-type]
        if speed is not None and speed > 0.0:
            cruise = min(cruise, speed)
        ramp = _PEAK_ACCEL * cruise / limits.acceleration
        if distance < cruise * ramp:  # no room to reach cruise speed: lower it
            cruise = math.sqrt(distance * limits.acceleration / _PEAK_ACCEL)
            ramp = _PEAK_ACCEL * cruise / limits.acceleration
        self.cruise = cruise
        self.ramp = ramp
        self.cruise_time = (distance - cruise * ramp) / cruise if cruise > 0.0 else 0.0
        dyaw = (yaw1 - yaw0 + math.pi) % (2.0 * math.pi) - math.pi
        yaw_time = 1.875 * abs(dyaw) / limits.yaw_rate
        self.duration_s = max(2.0 * ramp + self.cruise_time, yaw_time, 1e-3)
        self.yaw = QuinticSegment(self.duration_s, ZERO3, ZERO3, yaw0=yaw0, yaw1=yaw1)

    def _progress(self, t: float) -> tuple[float, float, float]:
        """Distance along the line, speed and acceleration at time t."""
        v, T, tc = self.cruise, self.ramp, self.cruise_time
        if v <= 0.0:
            return 0.0, 0.0, 0.0
        if t <= 0.0:
            return 0.0, 0.0, 0.0
        if t < T:  # speed ramps up: v s(u); distance = v T * integral of s
            u = t / T
            s, ds, _ = _smoothstep(u)
            dist = v * T * u**4 * (2.5 - 3.0 * u + u * u)
            return dist, v * s, v * ds / T
        ramp_dist = 0.5 * v * T
        if t < T + tc:
            return ramp_dist + v * (t - T), v, 0.0
        t3 = t - T - tc
        if t3 < T:  # speed ramps down: v (1 - s(u))
            u = t3 / T
            s, ds, _ = _smoothstep(u)
            dist = ramp_dist + v * tc + v * T * (u - u**4 * (2.5 - 3.0 * u + u * u))
            return dist, v * (1.0 - s), -v * ds / T
        return self.distance, 0.0, 0.0

    def sample(self, t: float) -> Reference:
        """The reference at ``t`` s from the move's start: along the line at the S-curve's distance, speed and
        acceleration, the yaw on its quintic; at rest at ``end`` after :attr:`duration_s`."""
        dist, speed, accel = self._progress(t)
        d = self.direction
        yaw = self.yaw.sample(t)
        return Reference(
            (self.start[0] + d[0] * dist, self.start[1] + d[1] * dist, self.start[2] + d[2] * dist),
            (d[0] * speed, d[1] * speed, d[2] * speed),
            (d[0] * accel, d[1] * accel, d[2] * accel),
            yaw.yaw_rad, yaw.yaw_rate_rad_s, yaw.yaw_acceleration_rad_s2,
        )  # fmt: skip


def transition(
    start: Reference, target: Vector3, limits: Limits, yaw: float | None = None, brake_first: bool = True
) -> Trajectory:
    """From the state of ``start`` to rest at ``target`` (quintic), within the limits.

    At rest, a straight :class:`LineMove` is used (cruises where the quintic would not). Moving,
    a quintic within the limits is looked for; where none is (a far target: the quintic long
    enough for the distance carries the start's acceleration for most of its duration and
    overshoots), the vehicle brakes to rest first, then flies a LineMove.
    """
    yaw1 = start.yaw_rad if yaw is None else yaw
    moving = any(abs(v) > 1e-6 for v in start.velocity_m_s + start.acceleration_m_s2)
    if not moving:
        return LineMove(start.position_m, target, limits, start.yaw_rad, yaw1)
    seg = _quintic_within_limits(start, target, limits, yaw1)
    if seg is not None:
        return seg
    if not brake_first:
        return _free_stop(start, limits)
    brake = stop_from(start, limits)
    rest = brake.sample(brake.duration_s)
    return PiecewiseTrajectory([brake, LineMove(rest.position_m, target, limits, rest.yaw_rad, yaw1)])


def _quintic_within_limits(
    start: Reference, target: Vector3, limits: Limits, yaw1: float
) -> Trajectory | None:
    """A quintic from ``start`` to rest at ``target`` within the speed and acceleration limits, or
    None if none of 20 durations keeps within them."""
    distance = math.dist(start.position_m, target)
    speed = math.sqrt(sum(v * v for v in start.velocity_m_s))
    vmax = min(limits.speed_horizontal, limits.speed_up, limits.speed_down)
    amax = limits.acceleration
    T = max(1.875 * distance / vmax, math.sqrt(5.7735 * distance / amax), 2.0 * speed / amax, 0.5)
    for _ in range(20):
        seg = QuinticSegment(T, start.position_m, target, start.velocity_m_s, ZERO3,
                             start.acceleration_m_s2, ZERO3, start.yaw_rad, yaw1)  # fmt: skip
        peak_v, peak_a = _peaks(seg, T)
        if peak_v <= max(vmax, speed) * 1.05 and peak_a <= amax * 1.05:
            return seg
        T *= 1.25
    return None


def _free_stop(start: Reference, limits: Limits) -> Trajectory:
    """To rest wherever the vehicle comes to rest: each axis' velocity a cubic from (v0, a0) to
    (0, 0) (its integral fixes the end point), so it never reverses; the shortest such stop
    within the acceleration limit (or the start's own acceleration, if that is above it)."""
    p0, v0, a0 = start.position_m, start.velocity_m_s, start.acceleration_m_s2
    speed = math.sqrt(sum(v * v for v in v0))
    accel = math.sqrt(sum(a * a for a in a0))
    amax = max(limits.acceleration, accel)
    T = max(1.5 * speed / amax, 0.2)
    for _ in range(40):
        # The integral of the cubic Hermite velocity: v0 T / 2 + a0 T^2 / 12 per axis.
        target = tuple(p + v * T / 2.0 + a * T * T / 12.0 for p, v, a in zip(p0, v0, a0, strict=True))
        seg = QuinticSegment(T, p0, target, v0, ZERO3, a0, ZERO3, start.yaw_rad, start.yaw_rad)  # type: ignore[arg-type]
        if _peaks(seg, T)[1] <= amax * 1.05:
            break
        T *= 1.15
    return seg


def stop_from(start: Reference, limits: Limits) -> Trajectory:
    """Brake from ``start`` (p, v, a) to rest, about where a constant deceleration would stop;
    where that is not possible within the limits (an acceleration along the velocity at the
    start), to rest wherever the vehicle comes to rest without reversing."""
    speed = math.sqrt(sum(v * v for v in start.velocity_m_s))
    if speed < 1e-3 and not any(abs(a) > 1e-6 for a in start.acceleration_m_s2):
        p = start.position_m
        return QuinticSegment(0.01, p, p, yaw0=start.yaw_rad, yaw1=start.yaw_rad)
    stop_distance = speed * speed / (2.0 * limits.acceleration)
    target = tuple(
        p + (v / speed * stop_distance if speed > 0.0 else 0.0)
        for p, v in zip(start.position_m, start.velocity_m_s, strict=True)
    )
    return transition(start, target, limits, start.yaw_rad, brake_first=False)  # type: ignore[arg-type]


def _peaks(traj: Trajectory, duration: float, samples: int = 40) -> tuple[float, float]:
    peak_v = peak_a = 0.0
    for i in range(samples + 1):
        ref = traj.sample(duration * i / samples)
        peak_v = max(peak_v, math.sqrt(sum(v * v for v in ref.velocity_m_s)))
        peak_a = max(peak_a, math.sqrt(sum(a * a for a in ref.acceleration_m_s2)))
    return peak_v, peak_a
