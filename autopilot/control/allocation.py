"""Control allocation: (U1, body torque) -> rotor speeds and normalised actuator commands.

Rotors in + configuration, 1 front, 2 right, 3 rear, 4 left (CONTROL.md), with
``U1 = b sum(Omega_i^2)``, ``tau_x = l b (Omega4^2 - Omega2^2)``,
``tau_y = l b (Omega3^2 - Omega1^2)``,
``tau_z = d (-Omega1^2 + Omega2^2 - Omega3^2 + Omega4^2)``.

Saturation preserves thrust first: the collective part is clipped to the feasible range, then
the roll/pitch part is scaled down until every rotor is within its limits, then the yaw part.
Normalised rotor commands are ``Omega_i / Omega_max`` in [0, 1] (``HIL_ACTUATOR_CONTROLS``).
Under ``actuation = "wrench"`` the normalised commands are ``U1 / U1_max`` and ``tau_i / tau_max``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from quadcommon.config import VehicleConfig

Vector3 = tuple[float, float, float]


class RotorAllocation(NamedTuple):
    speeds_rad_s: tuple[float, float, float, float]
    normalised: tuple[float, float, float, float]
    thrust_n: float  # achieved after saturation
    torque_body_n_m: Vector3  # achieved after saturation


class Allocator:
    def __init__(self, vehicle: VehicleConfig) -> None:
        rot = vehicle.rotors
        self.b = rot.thrust_coefficient_n_s2
        self.d = rot.drag_coefficient_n_m_s2
        self.arm = vehicle.nominal.arm_length_m
        self.sq_min = rot.speed_min_rad_s**2
        self.sq_max = rot.speed_max_rad_s**2
        self.speed_max = rot.speed_max_rad_s
        self.thrust_max = vehicle.actuation.thrust_max_n
        self.torque_max = vehicle.actuation.torque_max_n_m

    # -- rotors ----------------------------------------------------------------------------------
    def to_rotors(self, thrust_n: float, torque_body_n_m: Vector3) -> RotorAllocation:
        b, d, arm = self.b, self.d, self.arm
        tx, ty, tz = torque_body_n_m
        lo, hi = self.sq_min, self.sq_max
        base = min(max(thrust_n / (4.0 * b), lo), hi)
        rp = (
            -ty / (2.0 * arm * b),
            -tx / (2.0 * arm * b),
            ty / (2.0 * arm * b),
            tx / (2.0 * arm * b),
        )
        yaw = (-tz / (4.0 * d), tz / (4.0 * d), -tz / (4.0 * d), tz / (4.0 * d))
        k_rp = _largest_scale((base,) * 4, rp, lo, hi)
        partial = tuple(base + k_rp * x for x in rp)
        k_yaw = _largest_scale(partial, yaw, lo, hi)
        squares = tuple(min(max(p + k_yaw * y, lo), hi) for p, y in zip(partial, yaw, strict=True))
        speeds = tuple(math.sqrt(s) for s in squares)
        s1, s2, s3, s4 = squares
        return RotorAllocation(
            speeds_rad_s=speeds,  # type: ignore[arg-type]
            normalised=tuple(s / self.speed_max for s in speeds),  # type: ignore[arg-type]
            thrust_n=b * (s1 + s2 + s3 + s4),
            torque_body_n_m=(arm * b * (s4 - s2), arm * b * (s3 - s1), d * (-s1 + s2 - s3 + s4)),
        )

    # -- wrench ----------------------------------------------------------------------------------
    def saturate_wrench(self, thrust_n: float, torque_body_n_m: Vector3) -> tuple[float, Vector3]:
        """U1 clipped to [0, U1_max], each body torque to [-tau_max, tau_max]."""
        m0, m1, m2 = self.torque_max
        t0, t1, t2 = torque_body_n_m
        return (
            min(max(thrust_n, 0.0), self.thrust_max),
            (min(max(t0, -m0), m0), min(max(t1, -m1), m1), min(max(t2, -m2), m2)),
        )

    def wrench_to_normalised(self, thrust_n: float, torque_body_n_m: Vector3) -> tuple[float, ...]:
        """Normalised ``HIL_ACTUATOR_CONTROLS`` of an already saturated wrench."""
        tm = self.torque_max
        t0, t1, t2 = torque_body_n_m
        return (thrust_n / self.thrust_max, t0 / tm[0], t1 / tm[1], t2 / tm[2])


def _largest_scale(base: tuple[float, ...], delta: tuple[float, ...], lo: float, hi: float) -> float:
    """Largest k in [0, 1] with lo <= base_i + k delta_i <= hi for every i."""
    k = 1.0
    for b0, dl in zip(base, delta, strict=True):
        if dl > 0.0 and b0 + dl > hi:
            k = min(k, max(hi - b0, 0.0) / dl)
        elif dl < 0.0 and b0 + dl < lo:
            k = min(k, max(b0 - lo, 0.0) / -dl)
    return k
