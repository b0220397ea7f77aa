"""Offboard setpoints -> a smooth reference (p_d, p_d', p_d'', yaw) at every control step.

PX4's SET_POSITION_TARGET_LOCAL_NED semantics, already decoded into the paper's frames by the
MAVLink edge (:mod:`autopilot.mavlink.offboard`):

* position only: the setpoint is a target; a C2 transition (within the speed and acceleration
  limits) is planned from the current reference whenever the target moves, so a step in the
  setpoint never becomes a step in p_d;
* position + velocity (+ acceleration): a trajectory sample used as is, with the velocity and
  acceleration as feedforward; between samples it is extrapolated (p + v tau + a tau^2 / 2) so a
  50 Hz stream gives the 500 Hz cascade a continuous reference;
* velocity (+ acceleration) without position: the reference velocity moves to the setpoint's
  at most at ``MPC_ACC_HOR`` (a step in the setpoint becomes a ramp, never a step in p_d': that
  would be an impulse in p_d'' for the position law), and the position reference integrates it;
* yaw: absolute, or a yaw rate integrated; when neither is given the yaw reference is kept. Outside
  a planned transition an absolute yaw is reached the shorter way round at the planner's yaw rate
  limit, never in one step.

Attitude and body-rate targets (``SET_ATTITUDE_TARGET``, PX4's offboard attitude and rate
control) bypass the position law as ACRO does: :meth:`OffboardGuidance.attitude_step` gives the
cascade the whole attitude reference and the collective thrust (a :class:`~.manual.ManualSetpoint`),
the attitude as sent, or the one the body rates integrate (:func:`~.manual.integrate_body_rates`,
ACRO's own step); the translational law keeps running on the measured state, so its integrals
neither wind up nor jump when position setpoints come back.

Bounded whatever arrives (PX4 does the same in its position controller): feedforward velocities
are limited to ``MPC_XY_VEL_MAX`` / ``MPC_Z_VEL_MAX_UP`` / ``MPC_Z_VEL_MAX_DN`` and accelerations to
``MPC_ACC_HOR``; a trajectory sample more than :data:`JUMP_M` from the reference flown so far is
not followed at once but joined by a planned transition (within the same limits), and followed
again once the reference is within that distance of it. So no setpoint makes the reference move
faster than the limits allow. (Positions beyond ``NAV_REF_MAX_DIST`` never get here:
:mod:`autopilot.mavlink.validation`.)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from quadcommon.trajectories import Reference, Trajectory

from .manual import ManualLimits, ManualSetpoint, MeasuredState, integrate_body_rates
from .planner import Limits, transition

Vector3 = tuple[float, float, float]
ZERO3: Vector3 = (0.0, 0.0, 0.0)
_MAX_EXTRAPOLATION_S = 0.2
JUMP_M = 0.5  # a trajectory sample this far from the reference is joined by a planned transition


@dataclass(frozen=True)
class OffboardSetpoint:
    """One decoded setpoint, paper world frame, absolute (offsets already resolved)."""

    time_s: float  # simulation time of arrival
    position: Vector3 | None = None
    velocity: Vector3 | None = None
    acceleration: Vector3 | None = None
    yaw: float | None = None
    yaw_rate: float | None = None


@dataclass(frozen=True)
class AttitudeSetpoint:
    """One decoded attitude or body-rate target (``SET_ATTITUDE_TARGET``), paper frames.

    Exactly one of ``attitude`` (ZYX Euler angles, rad) and ``body_rates`` (rad/s, body FLU) is
    given (bounded when flown: :meth:`OffboardGuidance.attitude_step`); ``thrust`` is the
    collective thrust as a fraction of the maximum (0..1), None when the target leaves it out (the
    last one given is kept)."""

    time_s: float  # simulation time of arrival
    attitude: Vector3 | None = None
    body_rates: Vector3 | None = None
    thrust: float | None = None


class OffboardGuidance:
    """OFFBOARD's state between control steps: the last setpoint, a planned transition, the
    attitude that body rates integrate, the collective thrust last given."""

    def __init__(self, limits: Limits) -> None:
        self.limits = limits
        self.setpoint: OffboardSetpoint | AttitudeSetpoint | None = None
        self._rate_attitude: Vector3 | None = None
        self.thrust: float | None = None  # the last collective thrust given (fraction of the maximum)
        self._target: tuple[Vector3, float] | None = None
        self._plan: Trajectory | None = None
        self._plan_start = 0.0
        self._joining = False  # joining a trajectory stream that started too far away

    def update(self, setpoint: OffboardSetpoint | AttitudeSetpoint) -> None:
        """The latest setpoint received (it replaces the one before, of either kind)."""
        if isinstance(setpoint, AttitudeSetpoint):
            if setpoint.body_rates is None or not isinstance(self.setpoint, AttitudeSetpoint):
                self._rate_attitude = None  # rates integrate from the attitude flown when they start
            if setpoint.thrust is not None:
                self.thrust = setpoint.thrust
        self.setpoint = setpoint

    @property
    def flies_attitude(self) -> bool:
        """Whether the setpoint flown is an attitude or body-rate target."""
        return isinstance(self.setpoint, AttitudeSetpoint)

    def reset(self) -> None:
        """Forget the plan (entering offboard again starts from the current reference)."""
        self._target = None
        self._plan = None
        self._joining = False
        self._rate_attitude = None

    def attitude_step(self, dt: float, state: MeasuredState, limits: ManualLimits) -> ManualSetpoint:
        """One control step on an attitude or body-rate target: the attitude reference and the
        collective thrust (the last given; ``MPC_THR_HOVER`` until one is). Bounded as ACRO is:
        roll and pitch within ``ACRO_TILT_LIM`` (no flips: the Euler angles the attitude law tracks
        are singular at 90 degrees of pitch), body rates within ``MC_ACRO_R/P/Y_MAX``, integrated
        as ACRO integrates its sticks. The translational law gets the measured state as its
        reference (no position error to fight)."""
        sp = self.setpoint
        assert isinstance(sp, AttitudeSetpoint)
        thrust = self.thrust if self.thrust is not None else limits.thrust_hover
        tilt = limits.acro_tilt
        if sp.attitude is not None:
            phi, theta, psi = sp.attitude
            eta = (min(max(phi, -tilt), tilt), min(max(theta, -tilt), tilt), psi)
            rates = ZERO3
        else:
            assert sp.body_rates is not None
            omega = tuple(min(max(w, -w_max), w_max) for w, w_max in zip(sp.body_rates, limits.acro_rates,
                                                                          strict=True))  # fmt: skip
            start = self._rate_attitude if self._rate_attitude is not None else state.euler_rad
            eta, rates = integrate_body_rates(start, omega, dt, tilt)  # type: ignore[arg-type]
            self._rate_attitude = eta
        reference = Reference(state.position_m, state.velocity_m_s, ZERO3, eta[2], rates[2], 0.0)
        return ManualSetpoint(reference, attitude=(eta, rates, ZERO3), thrust=thrust)

    def reference(self, t: float, dt: float, previous: Reference) -> Reference:
        """The reference at time ``t``, continuing from ``previous`` (the last step's)."""
        sp = self.setpoint
        if sp is None or isinstance(sp, AttitudeSetpoint):
            return Reference(previous.position_m, ZERO3, ZERO3, previous.yaw_rad, 0.0, 0.0)
        yaw, yaw_rate = previous.yaw_rad, 0.0
        if sp.yaw is not None:  # (a planned transition turns to it; other references slew to it)
            yaw, yaw_rate = _toward_yaw(previous.yaw_rad, sp.yaw, self.limits.yaw_rate * dt, dt)
        elif sp.yaw_rate is not None:
            yaw_rate = sp.yaw_rate
            yaw = math.remainder(previous.yaw_rad + yaw_rate * dt, 2.0 * math.pi)
        planned_yaw = yaw if sp.yaw is None else sp.yaw  # where a planned transition ends

        if sp.position is not None and sp.velocity is None and sp.acceleration is None:
            target = (sp.position, planned_yaw)
            if self._plan is None or self._target is None or _moved(self._target, target):
                self._target = target
                self._plan = transition(previous, sp.position, self.limits, target[1])
                self._plan_start = t
            ref = self._plan.sample(t - self._plan_start)
            if sp.yaw is None and sp.yaw_rate is not None:
                return ref._replace(yaw_rad=yaw, yaw_rate_rad_s=yaw_rate, yaw_acceleration_rad_s2=0.0)
            return ref

        acc = _limit_acceleration(sp.acceleration or ZERO3, self.limits)
        if sp.position is not None:
            tau = min(max(t - sp.time_s, 0.0), _MAX_EXTRAPOLATION_S)
            vel = _limit_velocity(sp.velocity or ZERO3, self.limits)
            position = tuple(
                p + v * tau + 0.5 * a * tau * tau for p, v, a in zip(sp.position, vel, acc, strict=True)
            )
            velocity = tuple(v + a * tau for v, a in zip(vel, acc, strict=True))
            if self._joining or math.dist(position, previous.position_m) > JUMP_M:
                return self._join(t, previous, position, planned_yaw)  # type: ignore[arg-type]
        elif sp.velocity is not None:
            target_velocity = _limit_velocity(sp.velocity, self.limits)
            velocity, acc = _toward_velocity(previous.velocity_m_s, target_velocity, acc, self.limits, dt)
            position = tuple(p + v * dt for p, v in zip(previous.position_m, velocity, strict=True))
        else:  # acceleration only
            velocity = tuple(v + a * dt for v, a in zip(previous.velocity_m_s, acc, strict=True))
            position = tuple(p + v * dt for p, v in zip(previous.position_m, velocity, strict=True))
        self._plan = None
        self._target = None
        return Reference(position, velocity, acc, yaw, yaw_rate, 0.0)  # type: ignore[arg-type]

    def _join(self, t: float, previous: Reference, position: Vector3, yaw: float) -> Reference:
        """A planned transition from the reference flown so far towards a trajectory sample too
        far to follow at once. The plan is kept while the samples stay within ``JUMP_M`` of its
        target (replanned from the current reference when they move on); following resumes once
        the reference is within ``JUMP_M / 2`` of the sample."""
        target = (position, yaw)
        if not self._joining or self._plan is None or self._target is None or (
            math.dist(self._target[0], position) > JUMP_M
        ):
            self._target = target
            self._plan = transition(previous, position, self.limits, yaw)
            self._plan_start = t
        ref = self._plan.sample(t - self._plan_start)
        self._joining = math.dist(ref.position_m, position) > 0.5 * JUMP_M
        if not self._joining:
            self._plan = self._target = None
        return ref


def _limit_velocity(v: Vector3, limits: Limits) -> Vector3:
    """Horizontal speed at most ``speed_horizontal``; vertical within [-speed_down, speed_up]."""
    h = math.hypot(v[0], v[1])
    scale = limits.speed_horizontal / h if h > limits.speed_horizontal else 1.0
    return (v[0] * scale, v[1] * scale, min(max(v[2], -limits.speed_down), limits.speed_up))


def _toward_velocity(
    current: Vector3, target: Vector3, feedforward: Vector3, limits: Limits, dt: float
) -> tuple[Vector3, Vector3]:
    """The reference velocity one step closer to ``target`` (at most ``limits.acceleration``) and
    the reference acceleration that moves it: the ramp's while on the way, the setpoint's
    ``feedforward`` once there."""
    dv = tuple(b - a for a, b in zip(current, target, strict=True))
    gap = math.sqrt(dv[0] * dv[0] + dv[1] * dv[1] + dv[2] * dv[2])
    reach = limits.acceleration * dt
    if gap <= reach:
        return target, feedforward
    scale = limits.acceleration / gap
    acc = (dv[0] * scale, dv[1] * scale, dv[2] * scale)
    return tuple(v + a * dt for v, a in zip(current, acc, strict=True)), acc  # type: ignore[return-value]


def _toward_yaw(current: float, target: float, reach: float, dt: float) -> tuple[float, float]:
    """The yaw one step closer to ``target`` the shorter way round (at most ``reach`` rad) and
    its rate; ``target`` itself (wrapped) once within reach."""
    error = math.remainder(target - current, 2.0 * math.pi)
    if abs(error) <= reach:
        return math.remainder(target, 2.0 * math.pi), 0.0
    step = math.copysign(reach, error)
    return math.remainder(current + step, 2.0 * math.pi), step / dt


def _limit_acceleration(a: Vector3, limits: Limits) -> Vector3:
    norm = math.sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2])
    scale = limits.acceleration / norm if norm > limits.acceleration else 1.0
    return (a[0] * scale, a[1] * scale, a[2] * scale)


def _moved(old: tuple[Vector3, float], new: tuple[Vector3, float]) -> bool:
    return math.dist(old[0], new[0]) > 1e-3 or abs(math.remainder(old[1] - new[1], 2 * math.pi)) > 1e-3
