"""The manual modes (PX4's, for a multicopter): sticks -> what the cascade's own loops fly.

Every mode flies the cascade in use (whichever laws it has), through the cascade's overrides
(:meth:`autopilot.control.cascade.Cascade.step`); this module only says what to give it, one
:class:`ManualSetpoint` per control step:

=================  =========================================  ==================================
mode               sticks                                     what the cascade gets
=================  =========================================  ==================================
POSCTL             pitch/roll: horizontal velocity in the     a reference (p_d, p_d', p_d'',
                   heading frame (``MPC_VEL_MANUAL``);        yaw): the position law flies it
                   throttle: climb rate (``MPC_Z_VEL_MAX_UP``
                   / ``_DN``); yaw: yaw rate (``MPC_MAN_Y_MAX``)
ALTCTL             pitch/roll: tilt (``MPC_MAN_TILT_MAX``);   roll/pitch before the command
                   throttle: climb rate, altitude held at     filter; the position law's thrust
                   centre; yaw: yaw rate                      with the vertical reference from the
                                                              throttle and the horizontal one at
                                                              the measured state (no horizontal
                                                              error)
STABILIZED         pitch/roll: tilt; throttle: thrust         roll/pitch before the command
(and MANUAL)       (``MPC_THR_HOVER`` at centre); yaw: yaw    filter, U1 from the throttle
                   rate
ACRO               pitch/roll/yaw: body rates                 the whole attitude reference (the
                   (``MC_ACRO_*_MAX``, expo); throttle:       attitude the rates integrate, the
                   thrust                                     rates as feed-forward), U1 from the
                                                              throttle
=================  =========================================  ==================================

In every mode the translational law keeps running on its reference (the measured state where the
mode gives no position), so its integrals neither wind up nor jump when the mode changes.

POSCTL's reference: the commanded velocity moves towards the sticks' at most ``MPC_ACC_HOR``
(every axis), so a stick slammed to full never steps p_d'; the position reference integrates it,
and with the sticks centred the vehicle brakes and holds where it stopped; the throttle held down
brakes the descent to rest on the ground. ALTCTL's vertical channel is the same.

ACRO integrates ZYX Euler angles, which the paper's attitude law tracks; they are singular at 90
degrees of pitch, so ACRO here cannot flip: the attitude it integrates stays within
``ACRO_TILT_LIM`` of roll and pitch (the rate on that axis stops at the limit).

Pure: time comes in as arguments, limits as a record.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple, Protocol

from quadcommon.rigid_body import euler_rates_from_body_rates
from quadcommon.trajectories import Reference

from .sticks import Sticks, acro_rate, beyond_deadzone, stick_tilt, throttle_curve

Vector3 = tuple[float, float, float]
GROUND_Z_M = 0.0
DESCEND_ACCEL_M_S2 = 0.3  # PX4 FlightTaskDescend without a vertical velocity: 0.3 m/s^2 down
STANDARD_GRAVITY_M_S2 = 9.81
ZERO3: Vector3 = (0.0, 0.0, 0.0)
CENTRED = Sticks(0.0)


@dataclass(frozen=True)
class ManualLimits:
    """The manual modes' parameters (PX4's names), in SI units."""

    speed_horizontal: float = 10.0  # MPC_VEL_MANUAL, m/s at full deflection
    speed_up: float = 1.5  # MPC_Z_VEL_MAX_UP
    speed_down: float = 1.0  # MPC_Z_VEL_MAX_DN
    acceleration: float = 2.0  # MPC_ACC_HOR, m/s^2 (every axis)
    yaw_rate: float = math.radians(150.0)  # MPC_MAN_Y_MAX, rad/s
    deadzone: float = 0.1  # MPC_HOLD_DZ, of full deflection
    loss_s: float = 0.5  # COM_RC_LOSS_T, s
    tilt_max: float = math.radians(35.0)  # MPC_MAN_TILT_MAX, rad
    thrust_hover: float = 0.5  # MPC_THR_HOVER, of U1_max
    thrust_min: float = 0.08  # MPC_MANTHR_MIN
    thrust_max: float = 1.0  # MPC_THR_MAX
    thrust_rescale: bool = True  # MPC_THR_CURVE 0 (rescale to the hover thrust)
    acro_rates: Vector3 = (math.radians(100.0),) * 3  # MC_ACRO_R_MAX, _P_MAX, _Y_MAX, rad/s
    acro_expo: float = 0.0  # MC_ACRO_EXPO (roll, pitch)
    acro_expo_yaw: float = 0.0  # MC_ACRO_EXPO_Y
    acro_super_expo: float = 0.0  # MC_ACRO_SUPEXPO
    acro_super_expo_yaw: float = 0.0  # MC_ACRO_SUPEXPOY
    acro_tilt: float = math.radians(60.0)  # ACRO_TILT_LIM, rad
    override_speed: float = 0.3  # COM_RC_STICK_OV / 100: full travel per second


class MeasuredState(Protocol):
    """What the guidance reads of the vehicle (paper frames, SI)."""

    position_m: Vector3
    velocity_m_s: Vector3
    euler_rad: Vector3


class ManualSetpoint(NamedTuple):
    """What one control step of a manual mode gives the cascade."""

    reference: Reference  # the translational law's (and the yaw, unless ``attitude``)
    roll_pitch: tuple[float, float] | None = None  # (phi, theta) rad, before the command filter
    attitude: tuple[Vector3, Vector3, Vector3] | None = None  # eta_d, eta_d', eta_d'' (ACRO)
    thrust: float | None = None  # U1 / U1_max

    @property
    def overrides(self) -> bool:
        """Whether the cascade is given more than a reference."""
        return self.roll_pitch is not None or self.attitude is not None or self.thrust is not None


def integrate_body_rates(
    eta: Vector3, omega: Vector3, dt: float, tilt_limit: float
) -> tuple[Vector3, Vector3]:
    """One step of an attitude reference flown by body rates (ACRO's sticks, an offboard client's
    ``SET_ATTITUDE_TARGET`` rates): the ZYX Euler angles ``eta`` (rad) moved by the body rates
    ``omega`` (rad/s, FLU) over ``dt``, and the Euler rates that move them (the feed-forward).
    Roll and pitch stay within ``tilt_limit`` (rad): the rate on that axis stops at the limit, so
    the reference never reaches the Euler singularity at 90 degrees of pitch (no flips)."""
    phi, theta, psi = eta
    rates = list(euler_rates_from_body_rates(phi, theta, omega))
    angles = [phi + rates[0] * dt, theta + rates[1] * dt]
    for i in range(2):
        if abs(angles[i]) > tilt_limit:
            angles[i] = math.copysign(tilt_limit, angles[i])
            rates[i] = 0.0
    psi = math.remainder(psi + rates[2] * dt, 2.0 * math.pi)
    return (angles[0], angles[1], psi), (rates[0], rates[1], rates[2])


def _thrust(up: float, limits: ManualLimits) -> float:
    lim = limits
    return throttle_curve(up, lim.thrust_hover, lim.thrust_min, lim.thrust_max, lim.thrust_rescale)


def _vertical(up: float, z0: float, vz0: float, dt: float, limits: ManualLimits) -> Vector3:
    """(z, vz, az) after ``dt``: the climb rate ``up`` (deadzone removed) asks for, reached within
    the acceleration limit; down no faster than it can brake to rest at the ground, and resting
    there when the stick is held down."""
    target = up * (limits.speed_up if up > 0.0 else limits.speed_down)
    step = limits.acceleration * dt
    floor_speed = max(math.sqrt(2.0 * limits.acceleration * max(z0 - GROUND_Z_M, 0.0)) - step, 0.0)
    target = max(target, -floor_speed)
    vz = vz0 + min(max(target - vz0, -step), step)
    az = (vz - vz0) / dt
    z = z0 + 0.5 * (vz0 + vz) * dt
    if z < GROUND_Z_M:
        return GROUND_Z_M, 0.0, 0.0
    return z, vz, az


class ManualGuidance:
    """The manual modes' state between control steps: POSCTL's engagement, ACRO's attitude."""

    def __init__(self) -> None:
        self.engaged = False  # POSCTL: a deflection arrived since it was entered, the sticks fly
        self._acro_attitude: Vector3 | None = None

    def enter(self, state: MeasuredState) -> None:
        """A manual mode is entered: POSCTL holds until the sticks move, ACRO starts from the
        measured attitude."""
        self.engaged = False
        self._acro_attitude = state.euler_rad

    def engage_if_moved(self, sticks: Sticks | None, limits: ManualLimits) -> bool:
        """POSCTL: True once fresh sticks were deflected beyond the deadzone (then they fly)."""
        if not self.engaged:
            self.engaged = sticks is not None and sticks.deflected(limits.deadzone)
        return self.engaged

    # -- the modes: one control step each, continuing from ``previous`` (the last step's reference) --
    def position(
        self,
        dt: float,
        previous: Reference,
        state: MeasuredState,
        sticks: Sticks | None,
        limits: ManualLimits,
    ) -> ManualSetpoint:
        """POSCTL: velocity in the heading frame, climb rate and yaw rate from the sticks."""
        s = sticks or CENTRED
        dz = limits.deadzone
        forward, left = beyond_deadzone(s.forward, dz), beyond_deadzone(s.left, dz)
        up, yaw_stick = beyond_deadzone(s.up, dz), beyond_deadzone(s.yaw, dz)
        psi = previous.yaw_rad
        c, sn = math.cos(psi), math.sin(psi)
        v_max = limits.speed_horizontal
        # Heading frame -> world: forward along (cos psi, sin psi), left along (-sin psi, cos psi).
        target = (v_max * (c * forward - sn * left), v_max * (sn * forward + c * left))
        p0, v0 = previous.position_m, previous.velocity_m_s
        step = limits.acceleration * dt
        vx = v0[0] + min(max(target[0] - v0[0], -step), step)
        vy = v0[1] + min(max(target[1] - v0[1], -step), step)
        z, vz, az = _vertical(up, p0[2], v0[2], dt, limits)
        position = (p0[0] + 0.5 * (v0[0] + vx) * dt, p0[1] + 0.5 * (v0[1] + vy) * dt, z)
        acceleration = ((vx - v0[0]) / dt, (vy - v0[1]) / dt, az)
        yaw_rate = yaw_stick * limits.yaw_rate
        yaw = math.remainder(psi + yaw_rate * dt, 2.0 * math.pi)
        return ManualSetpoint(Reference(position, (vx, vy, vz), acceleration, yaw, yaw_rate, 0.0))

    def altitude(
        self,
        dt: float,
        previous: Reference,
        state: MeasuredState,
        sticks: Sticks | None,
        limits: ManualLimits,
    ) -> ManualSetpoint:
        """ALTCTL: tilt from the roll/pitch sticks, climb rate (altitude held at centre), yaw rate."""
        s = sticks or CENTRED
        dz = limits.deadzone
        z, vz, az = _vertical(beyond_deadzone(s.up, dz), previous.position_m[2], previous.velocity_m_s[2],
                              dt, limits)  # fmt: skip
        p, v = state.position_m, state.velocity_m_s
        yaw_rate = beyond_deadzone(s.yaw, dz) * limits.yaw_rate
        yaw = math.remainder(previous.yaw_rad + yaw_rate * dt, 2.0 * math.pi)
        reference = Reference((p[0], p[1], z), (v[0], v[1], vz), (0.0, 0.0, az), yaw, yaw_rate, 0.0)
        return ManualSetpoint(reference, roll_pitch=stick_tilt(s.forward, s.left, limits.tilt_max))

    def stabilized(
        self,
        dt: float,
        previous: Reference,
        state: MeasuredState,
        sticks: Sticks | None,
        limits: ManualLimits,
    ) -> ManualSetpoint:
        """STABILIZED (and MANUAL): tilt from the roll/pitch sticks, thrust from the throttle, yaw
        rate from the yaw stick."""
        s = sticks or CENTRED
        yaw_rate = s.yaw * limits.yaw_rate
        yaw = math.remainder(previous.yaw_rad + yaw_rate * dt, 2.0 * math.pi)
        reference = Reference(state.position_m, state.velocity_m_s, ZERO3, yaw, yaw_rate, 0.0)
        return ManualSetpoint(reference, roll_pitch=stick_tilt(s.forward, s.left, limits.tilt_max),
                              thrust=_thrust(s.up, limits))  # fmt: skip

    def descend(
        self,
        dt: float,
        previous: Reference,
        state: MeasuredState,
        land_speed: float,
        altitude_valid: bool,
        limits: ManualLimits,
    ) -> ManualSetpoint:
        """PX4's Descend (FlightTaskDescend), the last failsafe before termination: level attitude
        and the heading kept, no horizontal position control; down at ``land_speed``
        (MPC_LAND_SPEED) on the altitude estimate, or without one a thrust for DESCEND_ACCEL_M_S2
        downwards (PX4's crash landing)."""
        p, v = state.position_m, state.velocity_m_s
        yaw = previous.yaw_rad
        if altitude_valid:
            z = previous.position_m[2] - land_speed * dt
            reference = Reference((p[0], p[1], z), (v[0], v[1], -land_speed), ZERO3, yaw, 0.0, 0.0)
            return ManualSetpoint(reference, roll_pitch=(0.0, 0.0))
        reference = Reference(p, v, ZERO3, yaw, 0.0, 0.0)
        thrust = limits.thrust_hover * (1.0 - DESCEND_ACCEL_M_S2 / STANDARD_GRAVITY_M_S2)
        return ManualSetpoint(reference, roll_pitch=(0.0, 0.0), thrust=thrust)

    def acro(
        self,
        dt: float,
        previous: Reference,
        state: MeasuredState,
        sticks: Sticks | None,
        limits: ManualLimits,
    ) -> ManualSetpoint:
        """ACRO: body rates from the roll/pitch/yaw sticks, integrated into the attitude reference;
        thrust from the throttle."""
        s = sticks or CENTRED
        roll_max, pitch_max, yaw_max = limits.acro_rates
        omega = (
            acro_rate(-s.left, roll_max, limits.acro_expo, limits.acro_super_expo),
            acro_rate(s.forward, pitch_max, limits.acro_expo, limits.acro_super_expo),
            acro_rate(s.yaw, yaw_max, limits.acro_expo_yaw, limits.acro_super_expo_yaw),
        )
        start = self._acro_attitude if self._acro_attitude is not None else state.euler_rad
        eta, rates = integrate_body_rates(start, omega, dt, limits.acro_tilt)
        self._acro_attitude = eta
        psi = eta[2]
        reference = Reference(state.position_m, state.velocity_m_s, ZERO3, psi, rates[2], 0.0)
        return ManualSetpoint(reference, attitude=(eta, rates, ZERO3), thrust=_thrust(s.up, limits))
