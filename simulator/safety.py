"""The simulator's own emergency descent, flown when the autopilot stops answering (autopilot lost).

A real vehicle whose flight controller dies falls; a simulated one whose autopilot process dies
would otherwise hang in the air forever (lockstep never advances) or be left mid-air when the
simulator gives up. So after the lockstep timeout the simulator lands the vehicle by itself,
with a deliberately simple law that uses the TRUE plant (the simulator knows it exactly) and no
code of the autopilot:

* attitude: PD towards a small levelling attitude on body torques,
  ``tau = J (-w^2 (eta - eta_d) - 2 zeta w omega) + r_G x F`` (roll/pitch; yaw: rate damping only),
  the last term cancelling the moment of the thrust about the offset centre of mass;
* horizontal: damp the horizontal velocity through that attitude, ``a_xy = -k_h v_xy`` (the
  vehicle comes down near where it was lost, tilting at most ``tilt_max_rad``);
* vertical: descend at ``descent_speed_m_s``, ``U1 = m (g + k_z (-v_d - v_z)) / (cos phi cos theta)``;
* motors off once on the ground (:func:`touched_down`), and kept off.

The commands come out normalised exactly as ``HIL_ACTUATOR_CONTROLS`` carries them for the
vehicle's actuation (wrench: U1/U1_max, tau/tau_max; rotors: Omega_i/Omega_max from the + mixer),
so the plant takes them through the same :meth:`set_actuator_controls` path.

Pure: no clocks, no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

from quadcommon.config import VehicleConfig

from .dynamics.plant import TruthState

Vector3 = tuple[float, float, float]
Controls = tuple[float, float, float, float]
MOTORS_OFF: Controls = (0.0, 0.0, 0.0, 0.0)
TOUCHDOWN_HEIGHT_M = 0.02
TOUCHDOWN_SPEED_M_S = 0.2


@dataclass(frozen=True)
class DescentGains:
    descent_speed_m_s: float = 0.5  # v_d, downwards
    vertical_gain_1_s: float = 2.0  # k_z
    horizontal_damping_1_s: float = 1.0  # k_h
    tilt_max_rad: float = 0.2
    attitude_omega_rad_s: float = 15.0  # w of the attitude PD
    attitude_damping: float = 1.0  # zeta


class EmergencyCommand(NamedTuple):
    controls: Controls  # normalised, as HIL_ACTUATOR_CONTROLS for this vehicle's actuation
    thrust_n: float  # U1 asked for (before the actuator's saturation)
    torque_body_n_m: Vector3  # body torque asked for


def touched_down(truth: TruthState) -> bool:
    """On the ground: resting there, or within 2 cm of it and barely moving vertically."""
    return truth.on_ground or (
        truth.position_m[2] < TOUCHDOWN_HEIGHT_M and abs(truth.velocity_m_s[2]) < TOUCHDOWN_SPEED_M_S
    )


def emergency_descent(
    truth: TruthState, vehicle: VehicleConfig, gains: DescentGains = DescentGains()
) -> EmergencyCommand:
    """The descent command for the plant state ``truth`` (paper frames, SI units).

    ``vehicle`` is the plant as simulated (uncertainty applied): its true mass, inertia and CoM
    offset are used.
    """
    plant = vehicle.plant
    g = vehicle.nominal.gravity_m_s2
    mass = plant.mass_kg
    phi, theta, psi = truth.euler_rad
    vx, vy, vz = truth.velocity_m_s

    # Horizontal: damp the velocity by tilting; world -> heading frame, then small-angle attitude.
    ax, ay = -gains.horizontal_damping_1_s * vx, -gains.horizontal_damping_1_s * vy
    c, s = math.cos(psi), math.sin(psi)
    a_fwd, a_left = c * ax + s * ay, -s * ax + c * ay
    limit = gains.tilt_max_rad
    theta_d = min(max(a_fwd / g, -limit), limit)  # +pitch tilts thrust forward (+x body)
    phi_d = min(max(-a_left / g, -limit), limit)  # +roll tilts thrust to the right (-y body)

    # Vertical: track the descent speed.
    az = gains.vertical_gain_1_s * (-gains.descent_speed_m_s - vz)
    az = min(max(az, -0.8 * g), g)
    tilt = max(math.cos(phi) * math.cos(theta), 0.5)
    thrust = min(max(mass * (g + az) / tilt, 0.0), vehicle.actuation.thrust_max_n)

    # Attitude PD on body torques, plus the thrust moment about the offset CoM cancelled.
    w = gains.attitude_omega_rad_s
    kp, kd = w * w, 2.0 * gains.attitude_damping * w
    Jx, Jy, Jz = plant.inertia_kg_m2
    p, q, r = truth.body_rates_rad_s
    rx, ry, _ = plant.com_offset_m
    torque = (
        Jx * (-kp * (phi - phi_d) - kd * p) + ry * thrust,
        Jy * (-kp * (theta - theta_d) - kd * q) - rx * thrust,
        Jz * (-kd * r),
    )
    return EmergencyCommand(normalise(thrust, torque, vehicle), thrust, torque)


def normalise(thrust_n: float, torque_body_n_m: Vector3, vehicle: VehicleConfig) -> Controls:
    """``(U1, tau)`` as normalised actuator controls for ``vehicle``'s actuation."""
    act = vehicle.actuation
    tx, ty, tz = torque_body_n_m
    if act.mode == "wrench":
        tm = act.torque_max_n_m

        def unit(v: float, top: float) -> float:
            return min(max(v / top, -1.0), 1.0)

        return (
            min(max(thrust_n / act.thrust_max_n, 0.0), 1.0),
            unit(tx, tm[0]),
            unit(ty, tm[1]),
            unit(tz, tm[2]),
        )
    # "+" mixer (1 front, 2 right, 3 rear, 4 left): U1 = b sum(O^2), tau_x = l b (O4^2 - O2^2),
    # tau_y = l b (O3^2 - O1^2), tau_z = d (-O1^2 + O2^2 - O3^2 + O4^2), solved for O_i^2.
    rot = vehicle.rotors
    b, d, arm = rot.thrust_coefficient_n_s2, rot.drag_coefficient_n_m_s2, vehicle.nominal.arm_length_m
    T, X, Y, Z = thrust_n / b, tx / (arm * b), ty / (arm * b), tz / d
    s1 = 0.5 * (0.5 * (T - Z) - Y)
    s2 = 0.5 * (0.5 * (T + Z) - X)
    s3 = 0.5 * (0.5 * (T - Z) + Y)
    s4 = 0.5 * (0.5 * (T + Z) + X)
    lo, hi = rot.speed_min_rad_s**2, rot.speed_max_rad_s**2
    top = rot.speed_max_rad_s
    return tuple(math.sqrt(min(max(sq, lo), hi)) / top for sq in (s1, s2, s3, s4))  # type: ignore[return-value]
