"""Control allocation: (U1, body torque) -> rotor speeds and normalised actuator commands.

Rotors in + configuration, 1 front, 2 right, 3 rear, 4 left (CONTROL.md), with
``U1 = b sum(Omega_i^2)``, ``tau_x = l b (Omega4^2 - Omega2^2)``,
``tau_y = l b (Omega3^2 - Omega1^2)``,
``tau_z = d (-Omega1^2 + Omega2^2 - Omega3^2 + Omega4^2)``: the equation of
:mod:`quadcommon.rotor_geometry`, both ways, which the simulator's plant reads too.

Saturation preserves thrust first: the collective part is clipped to the feasible range, then
the roll/pitch part is scaled down until every rotor is within its limits, then the yaw part.
Normalised rotor commands are ``Omega_i / Omega_max`` in [0, 1] (``HIL_ACTUATOR_CONTROLS``).
Under ``actuation = "wrench"`` the normalised commands are ``U1 / U1_max`` and ``tau_i / tau_max``.

The two allocations are kernels over the actuators' numbers (layout ``A_*`` from an offset into
the cascade's array) writing the normalised commands, and the rotor speeds, into ``out``;
:class:`Allocator` runs them on one vehicle's numbers for Python callers.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from quadcommon.config import VehicleConfig
from quadcommon.kernel import kernel
from quadcommon.layout import Field, layout, values
from quadcommon.numerics import clip
from quadcommon.rotor_geometry import squared_speed_parts, wrench_from_squares

Vector3 = tuple[float, float, float]

# The actuators' numbers: U1_max, tau_max (3), rotor constants b, d, arm, the limits of Omega^2,
# Omega_max.
ACTUATORS = layout("ActuatorNumbers", (
    Field("thrust_max"),
    Field("torque_max", 3),
    Field("thrust_coefficient"),
    Field("torque_coefficient"),
    Field("arm"),
    Field("squared_speed_min"),
    Field("squared_speed_max"),
    Field("speed_max"),
))  # fmt: skip
# out: the four normalised commands, then the four rotor speeds (rad/s; zeros under "wrench").
OUT_SIZE = 8


def actuator_numbers(vehicle: VehicleConfig) -> tuple[float, ...]:
    """The actuators' numbers (:data:`ACTUATORS`) of ``vehicle``."""
    rotors, actuation = vehicle.rotors, vehicle.actuation
    return values(
        ACTUATORS, thrust_max=actuation.thrust_max_n, torque_max=actuation.torque_max_n_m,
        thrust_coefficient=rotors.thrust_coefficient_n_s2, torque_coefficient=rotors.drag_coefficient_n_m_s2,
        arm=vehicle.nominal.arm_length_m, squared_speed_min=rotors.speed_min_rad_s**2,
        squared_speed_max=rotors.speed_max_rad_s**2, speed_max=rotors.speed_max_rad_s,
    )


@kernel
def saturate_wrench(a, o, thrust, tx, ty, tz, out):
    """U1 clipped to [0, U1_max], each body torque to [-tau_max, tau_max]: ``(U1, tau, saturated)``;
    the normalised commands into ``out``."""
    thrust_max = a[o + ACTUATORS.thrust_max]
    m0, m1, m2 = a[o + ACTUATORS.torque_max], a[o + ACTUATORS.torque_max + 1], a[o + ACTUATORS.torque_max + 2]
    thrust_a = clip(thrust, 0.0, thrust_max)
    t0, t1, t2 = clip(tx, -m0, m0), clip(ty, -m1, m1), clip(tz, -m2, m2)
    saturated = 1.0 if (thrust_a != thrust or t0 != tx or t1 != ty or t2 != tz) else 0.0
    out[0], out[1], out[2], out[3] = thrust_a / thrust_max, t0 / m0, t1 / m1, t2 / m2
    out[4], out[5], out[6], out[7] = 0.0, 0.0, 0.0, 0.0
    return thrust_a, t0, t1, t2, saturated


@kernel
def largest_scale(base, delta, lo, hi):
    """Largest k in [0, 1] with lo <= base_i + k delta_i <= hi for each of the four rotors."""
    k = 1.0
    for i in range(4):
        b0, dl = base[i], delta[i]
        if dl > 0.0 and b0 + dl > hi:
            k = min(k, max(hi - b0, 0.0) / dl)
        elif dl < 0.0 and b0 + dl < lo:
            k = min(k, max(b0 - lo, 0.0) / -dl)
    return k


@kernel
def allocate_rotors(a, o, thrust, tx, ty, tz, out):
    """Rotor speeds for (U1, tau) with the saturation order of the module: ``(U1, tau, saturated)``
    achieved; normalised commands and speeds into ``out``."""
    b, d, arm = a[o + ACTUATORS.thrust_coefficient], a[o + ACTUATORS.torque_coefficient], a[o + ACTUATORS.arm]
    lo, hi = a[o + ACTUATORS.squared_speed_min], a[o + ACTUATORS.squared_speed_max]
    raw, rp, yaw = squared_speed_parts(b, d, arm, thrust, tx, ty, tz)
    base = clip(raw, lo, hi)
    k_rp = largest_scale((base, base, base, base), rp, lo, hi)
    partial = (base + k_rp * rp[0], base + k_rp * rp[1], base + k_rp * rp[2], base + k_rp * rp[3])
    k_yaw = largest_scale(partial, yaw, lo, hi)
    s1 = clip(partial[0] + k_yaw * yaw[0], lo, hi)
    s2 = clip(partial[1] + k_yaw * yaw[1], lo, hi)
    s3 = clip(partial[2] + k_yaw * yaw[2], lo, hi)
    s4 = clip(partial[3] + k_yaw * yaw[3], lo, hi)
    top = a[o + ACTUATORS.speed_max]
    out[4], out[5], out[6], out[7] = math.sqrt(s1), math.sqrt(s2), math.sqrt(s3), math.sqrt(s4)
    out[0], out[1], out[2], out[3] = out[4] / top, out[5] / top, out[6] / top, out[7] / top
    saturated = 1.0 if (raw != base or k_rp < 1.0 or k_yaw < 1.0) else 0.0
    thrust_a, tx_a, ty_a, tz_a = wrench_from_squares(b, d, arm, s1, s2, s3, s4)
    return thrust_a, tx_a, ty_a, tz_a, saturated


class RotorAllocation(NamedTuple):
    speeds_rad_s: tuple[float, float, float, float]
    normalised: tuple[float, float, float, float]
    thrust_n: float  # achieved after saturation
    torque_body_n_m: Vector3  # achieved after saturation


class Allocator:
    """The allocation kernels on one vehicle's actuators, for Python callers."""

    def __init__(self, vehicle: VehicleConfig) -> None:
        self.numbers = actuator_numbers(vehicle)
        self.speed_max = vehicle.rotors.speed_max_rad_s

    def to_rotors(self, thrust_n: float, torque_body_n_m: Vector3) -> RotorAllocation:
        """The rotor speeds (rad/s) and normalised commands of a wrench (U1 in N, body FLU torque in N m),
        saturated with thrust first (module docstring), with the thrust and torque they actually give."""
        out = [0.0] * OUT_SIZE
        thrust, tx, ty, tz, _ = allocate_rotors(self.numbers, 0, thrust_n, *torque_body_n_m, out)
        return RotorAllocation(tuple(out[4:]), tuple(out[:4]), thrust, (tx, ty, tz))  # type: ignore[arg-type]

    def saturate_wrench(self, thrust_n: float, torque_body_n_m: Vector3) -> tuple[float, Vector3]:
        """U1 clipped to [0, U1_max], each body torque to [-tau_max, tau_max]."""
        thrust, tx, ty, tz, _ = saturate_wrench(self.numbers, 0, thrust_n, *torque_body_n_m, [0.0] * OUT_SIZE)
        return thrust, (tx, ty, tz)

    def wrench_to_normalised(self, thrust_n: float, torque_body_n_m: Vector3) -> tuple[float, ...]:
        """Normalised ``HIL_ACTUATOR_CONTROLS`` of a wrench (saturated first)."""
        out = [0.0] * OUT_SIZE
        saturate_wrench(self.numbers, 0, thrust_n, *torque_body_n_m, out)
        return tuple(out[:4])
