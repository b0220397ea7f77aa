"""The sticks (MANUAL_CONTROL) as PX4 reads them: the stream, and the shapes that turn a deflection
into a tilt, a thrust or a body rate. Pure: time comes in as arguments.

A :class:`Sticks` is one MANUAL_CONTROL, already decoded into the paper's body axes by the MAVLink
edge (:func:`autopilot.mavlink.manual.decode_sticks`), each axis in [-1, 1]: ``forward`` (pitch
stick), ``left`` (roll stick, right = -1), ``up`` (the throttle stick, centre = 0, i.e. 50 %),
``yaw`` (counter-clockwise seen from above, as the paper's yaw).

:class:`StickStream` is the stream as the commander sees it, PX4's rules:

* **loss**: no MANUAL_CONTROL for ``COM_RC_LOSS_T`` (simulation time) after one arrived is a loss
  ("Manual control lost"); the next one ends it ("Manual control regained after 2.3s"). Until the
  timeout the last sticks count, as PX4 flies the last setpoint.
* **override**: a stick *moving* (not merely deflected) is PX4's override request: per axis the
  stick's speed, low-pass filtered with a 0.1 s time constant, above ``COM_RC_STICK_OV`` % of full
  travel per second (PX4's ``MovingDiff`` in its manual_control module). Sticks held still, however
  far deflected, never take over; after a loss the first sample starts the measure afresh.

The shapes (PX4's, mapped to this vehicle where PX4 is normalised):

* :func:`stick_tilt`: roll/pitch sticks -> roll and pitch angles, the stick vector scaled to
  ``MPC_MAN_TILT_MAX`` as an axis-angle tilt (its length clipped to the limit), then read as ZYX
  Euler angles (PX4's stabilized and altitude modes);
* :func:`throttle_curve`: throttle stick -> normalised thrust U1 / U1_max (PX4's ``MPC_THR_CURVE``:
  0 rescales so that the centre is ``MPC_THR_HOVER``, bottom ``MPC_MANTHR_MIN``, top ``MPC_THR_MAX``;
  1 is linear from ``MPC_MANTHR_MIN`` to ``MPC_THR_MAX``);
* :func:`acro_rate`: a stick -> a body rate with PX4's expo and super-expo
  (``MC_ACRO_*``): ``r (f x^3 + (1 - f) x) (1 - g) / (1 - g |x|)``;
* :func:`beyond_deadzone`: ``MPC_HOLD_DZ`` for the sticks that command speeds (POSCTL, the
  ALTCTL throttle), rescaled to start from zero at the deadzone's edge.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from quadcommon.rigid_body import euler_from_rotation

STICK_FILTER_TAU_S = 0.1  # PX4's MovingDiff: the stick speed's low-pass time constant
LOST, REGAINED = "lost", "regained"


@dataclass(frozen=True)
class Sticks:
    """One MANUAL_CONTROL, in the paper's body axes, each in [-1, 1] (before any deadzone)."""

    time_s: float  # simulation time of arrival
    forward: float = 0.0
    left: float = 0.0
    up: float = 0.0  # throttle stick, 0 = centred (50 %)
    yaw: float = 0.0  # counter-clockwise seen from above

    def deflected(self, deadzone: float) -> bool:
        """True when any stick is beyond ``deadzone`` (fraction of full travel): the pilot is moving the
        sticks."""
        return max(abs(self.forward), abs(self.left), abs(self.up), abs(self.yaw)) > deadzone

    def axes(self) -> tuple[float, float, float, float]:
        """``(forward, left, up, yaw)``, each in [-1, 1]."""
        return (self.forward, self.left, self.up, self.yaw)


class _MovingDiff:
    """A stick's speed (full travel per second), low-pass filtered (PX4's MovingDiff)."""

    def __init__(self) -> None:
        self.reset()

    def reset(self) -> None:
        self.speed = 0.0
        self._last = math.nan

    def update(self, value: float, dt: float) -> float:
        if dt <= 0.0:  # the first sample, or two at one instant (a flood): nothing to differentiate
            self._last = value
            return math.nan
        if not math.isnan(self._last):
            alpha = dt / (STICK_FILTER_TAU_S + dt)
            self.speed += alpha * ((value - self._last) / dt - self.speed)
        self._last = value
        return self.speed


class StickStream:
    """The latest sticks, whether the stream is alive, and the pilot's override requests."""

    def __init__(self) -> None:
        self.sticks: Sticks | None = None
        self.lost = False  # announced lost, nothing since
        self.override_requested = False  # a stick moved beyond the threshold since the last take
        self._lost_since = 0.0  # arrival of the last sample before the loss
        self._diffs = [_MovingDiff() for _ in range(4)]

    def receive(self, sticks: Sticks, loss_s: float, override_speed: float) -> None:
        """One MANUAL_CONTROL. ``override_speed``: COM_RC_STICK_OV / 100 (travel per second)."""
        previous = self.sticks
        if previous is None or sticks.time_s - previous.time_s > loss_s:
            for diff in self._diffs:  # a new stream: its first sample is no movement
                diff.reset()
        dt = 0.0 if previous is None else sticks.time_s - previous.time_s
        moving = False
        for diff, value in zip(self._diffs, sticks.axes(), strict=True):
            speed = diff.update(value, dt)
            moving = moving or abs(speed) > override_speed  # (NaN compares False)
        self.override_requested = self.override_requested or moving
        self.sticks = sticks

    def fresh(self, t: float, loss_s: float) -> Sticks | None:
        """The latest sticks if they arrived within ``loss_s`` before ``t``, else None (also for
        sticks stamped after ``t``: from before a simulator restart, when time went back)."""
        sticks = self.sticks
        if sticks is None or not 0.0 <= t - sticks.time_s <= loss_s:
            return None
        return sticks

    def poll(self, t: float, loss_s: float) -> tuple[str, float] | None:
        """``(LOST, 0)`` when the stream has just timed out, ``(REGAINED, gap s)`` when a sample
        came after a loss, else None. Call once per control step."""
        sticks = self.sticks
        if sticks is None:
            return None
        stale = self.fresh(t, loss_s) is None
        if stale and not self.lost:
            self.lost = True
            self._lost_since = sticks.time_s
            return (LOST, 0.0)
        if self.lost and not stale:
            self.lost = False
            return (REGAINED, sticks.time_s - self._lost_since)
        return None

    def take_override(self) -> bool:
        """Whether a stick moved since the last call (the request is consumed)."""
        requested, self.override_requested = self.override_requested, False
        return requested


def beyond_deadzone(value: float, deadzone: float) -> float:
    """``value`` in [-1, 1] with the deadzone removed and the rest rescaled to [-1, 1]."""
    magnitude = abs(value) - deadzone
    if magnitude <= 0.0:
        return 0.0
    return math.copysign(min(magnitude / (1.0 - deadzone), 1.0), value)


def stick_tilt(forward: float, left: float, tilt_max_rad: float) -> tuple[float, float]:
    """Roll and pitch (rad, ZYX Euler, paper frame) of the sticks' tilt.

    The stick vector, scaled by the limit, is an axis-angle rotation about a horizontal axis:
    forward pitches the nose down (+theta here), left rolls left (-phi here), full deflection on
    both tilts by the limit, not more (PX4's stabilized mode).
    """
    ax, ay = -left * tilt_max_rad, forward * tilt_max_rad
    angle = math.hypot(ax, ay)
    if angle < 1e-12:
        return (0.0, 0.0)
    if angle > tilt_max_rad:
        ax, ay, angle = ax * tilt_max_rad / angle, ay * tilt_max_rad / angle, tilt_max_rad
    ux, uy = ax / angle, ay / angle
    s, c = math.sin(angle), math.cos(angle)
    v = 1.0 - c
    # Rodrigues' formula for a rotation about (ux, uy, 0).
    rotation = (
        (c + ux * ux * v, ux * uy * v, uy * s),
        (ux * uy * v, c + uy * uy * v, -ux * s),
        (-uy * s, ux * s, c),
    )
    phi, theta, _ = euler_from_rotation(rotation)
    return (phi, theta)


def throttle_curve(up: float, hover: float, minimum: float, maximum: float, rescale: bool) -> float:
    """Normalised thrust (U1 / U1_max) of the throttle stick ``up`` in [-1, 1] (centre 0)."""
    up = min(max(up, -1.0), 1.0)
    if not rescale:  # MPC_THR_CURVE 1: linear over the stick's travel
        return minimum + 0.5 * (up + 1.0) * (maximum - minimum)
    if up <= 0.0:
        return hover + up * (hover - minimum)
    return hover + up * (maximum - hover)


def acro_rate(stick: float, rate_max: float, expo: float, super_expo: float) -> float:
    """Body rate (rate_max's unit) of one ACRO stick in [-1, 1]: PX4's expo and super-expo."""
    x = min(max(stick, -1.0), 1.0)
    shaped = expo * x * x * x + (1.0 - expo) * x
    return rate_max * shaped * (1.0 - super_expo) / (1.0 - super_expo * abs(x))
