"""Position mode on the sticks (PX4's POSCTL): stick deflections -> a smooth reference.

What a pilot (or MAVSDK's ``manual_control`` plugin, QGroundControl's virtual joystick) sends as
MANUAL_CONTROL, already decoded into the paper's body axes by the MAVLink edge
(:func:`autopilot.mavlink.manual.decode_sticks`), each axis in [-1, 1]:

* ``forward`` / ``left``: a horizontal velocity in the vehicle's heading frame, full deflection
  ``MPC_VEL_MANUAL``;
* ``up`` (the throttle stick, centre = 0): a climb rate, full deflection ``MPC_Z_VEL_MAX_UP`` up and
  ``MPC_Z_VEL_MAX_DN`` down;
* ``yaw`` (counter-clockwise seen from above, as the paper's yaw): a yaw rate, full deflection
  ``MPC_MAN_Y_MAX``.

Deflections inside ``MPC_HOLD_DZ`` count as centred, and the rest is rescaled to start from zero
at the deadzone's edge (no jump). The commanded velocity moves towards the sticks' at most
``MPC_ACC_HOR`` (every axis), so a stick slammed to full never steps p_d'; the position reference
integrates it, and with the sticks centred the vehicle brakes and holds where it stopped, as
PX4's position mode does; the throttle stick held down brakes the descent to rest on the ground.
Sticks older than ``COM_RC_LOSS_T`` count as centred (the pilot's link
is lost: hold, and the commander says so once).

Pure: time comes in as arguments, limits as a record.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from quadcommon.trajectories import Reference

Vector3 = tuple[float, float, float]
GROUND_Z_M = 0.0


@dataclass(frozen=True)
class Sticks:
    """One MANUAL_CONTROL, in the paper's body axes, each in [-1, 1] (before the deadzone)."""

    time_s: float  # simulation time of arrival
    forward: float = 0.0
    left: float = 0.0
    up: float = 0.0
    yaw: float = 0.0  # counter-clockwise seen from above

    def deflected(self, deadzone: float) -> bool:
        return max(abs(self.forward), abs(self.left), abs(self.up), abs(self.yaw)) > deadzone


@dataclass(frozen=True)
class ManualLimits:
    speed_horizontal: float = 10.0  # MPC_VEL_MANUAL, m/s at full deflection
    speed_up: float = 1.5  # MPC_Z_VEL_MAX_UP
    speed_down: float = 1.0  # MPC_Z_VEL_MAX_DN
    acceleration: float = 2.0  # MPC_ACC_HOR, m/s^2 (every axis)
    yaw_rate: float = math.radians(150.0)  # MPC_MAN_Y_MAX, rad/s
    deadzone: float = 0.1  # MPC_HOLD_DZ, of full deflection
    loss_s: float = 0.5  # COM_RC_LOSS_T, s


def _beyond_deadzone(value: float, deadzone: float) -> float:
    """``value`` in [-1, 1] with the deadzone removed and the rest rescaled to [-1, 1]."""
    magnitude = abs(value) - deadzone
    if magnitude <= 0.0:
        return 0.0
    return math.copysign(min(magnitude / (1.0 - deadzone), 1.0), value)


class ManualGuidance:
    """The sticks' reference while in POSCTL: :meth:`reference` once per control step."""

    def __init__(self) -> None:
        self.sticks: Sticks | None = None
        self.engaged = False  # a deflection arrived since POSCTL was entered: the sticks fly
        self.lost = False  # engaged, and the sticks went stale

    def update(self, sticks: Sticks) -> None:
        self.sticks = sticks

    def reset(self) -> None:
        """Entering hold or POSCTL: the stop plan flies until the sticks are moved."""
        self.engaged = False
        self.lost = False

    def fresh(self, t: float, limits: ManualLimits) -> Sticks | None:
        sticks = self.sticks
        if sticks is None or t - sticks.time_s > limits.loss_s:
            return None
        return sticks

    def engage_if_moved(self, t: float, limits: ManualLimits) -> bool:
        """True once fresh sticks have been deflected beyond the deadzone (then they fly)."""
        if not self.engaged:
            sticks = self.fresh(t, limits)
            self.engaged = sticks is not None and sticks.deflected(limits.deadzone)
        return self.engaged

    def reference(self, t: float, dt: float, previous: Reference, limits: ManualLimits) -> Reference:
        """The reference at ``t``, continuing from ``previous`` (the last step's)."""
        sticks = self.fresh(t, limits)
        self.lost = sticks is None
        dz = limits.deadzone
        if sticks is None:
            forward = left = up = yaw_stick = 0.0
        else:
            forward = _beyond_deadzone(sticks.forward, dz)
            left = _beyond_deadzone(sticks.left, dz)
            up = _beyond_deadzone(sticks.up, dz)
            yaw_stick = _beyond_deadzone(sticks.yaw, dz)
        psi = previous.yaw_rad
        c, s = math.cos(psi), math.sin(psi)
        v_max = limits.speed_horizontal
        # Heading frame -> world: forward along (cos psi, sin psi), left along (-sin psi, cos psi).
        target = (
            v_max * (c * forward - s * left),
            v_max * (s * forward + c * left),
            up * (limits.speed_up if up > 0.0 else limits.speed_down),
        )
        p0, v0 = previous.position_m, previous.velocity_m_s
        step = limits.acceleration * dt
        # Down no faster than it can brake to rest at the ground within the acceleration limit.
        floor_speed = max(math.sqrt(2.0 * limits.acceleration * max(p0[2] - GROUND_Z_M, 0.0)) - step, 0.0)
        target = (target[0], target[1], max(target[2], -floor_speed))
        velocity = (
            v0[0] + min(max(target[0] - v0[0], -step), step),
            v0[1] + min(max(target[1] - v0[1], -step), step),
            v0[2] + min(max(target[2] - v0[2], -step), step),
        )
        acceleration = (
            (velocity[0] - v0[0]) / dt,
            (velocity[1] - v0[1]) / dt,
            (velocity[2] - v0[2]) / dt,
        )
        z = p0[2] + 0.5 * (v0[2] + velocity[2]) * dt
        if z < GROUND_Z_M:  # the throttle stick held down: the reference rests on the ground
            z, velocity, acceleration = GROUND_Z_M, (velocity[0], velocity[1], 0.0), (*acceleration[:2], 0.0)
        position = (p0[0] + 0.5 * (v0[0] + velocity[0]) * dt, p0[1] + 0.5 * (v0[1] + velocity[1]) * dt, z)
        yaw_rate = yaw_stick * limits.yaw_rate
        yaw = math.remainder(psi + yaw_rate * dt, 2.0 * math.pi)
        return Reference(position, velocity, acceleration, yaw, yaw_rate, 0.0)  # type: ignore[arg-type]
