"""IntBS attitude law (Bouabdallah & Siegwart 2007, the paper's ref. [2]), on eq. (4).

Integral in the FIRST backstepping step, per Euler axis (e1 = eta - eta_d):
chi' = e1, e2 = e1' + c1 e1 + lambda chi, and the commanded angular acceleration
``eta_cmd'' = eta_d'' + (c1^2 - 1 - lambda) e1 - (c1 + c2) e2 + c1 lambda chi``, applied through
the nominal model: ``tau = M(eta) eta_cmd'' + C(eta, eta') eta'``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace

from quadcommon.config import NominalModel
from quadcommon.frames import wrap_pi
from quadcommon.rigid_body import coriolis_matrix, inertia_matrix, matrix_times
from quadcommon.schema import Section

from ...params.store import ParamSpec
from ..registry import ROTATIONAL, register
from ..translational import GAIN_HI, INTEGRAL_LO

Vector3 = tuple[float, float, float]
EULER_AXES = ("R", "P", "Y")  # parameter suffixes: roll, pitch, yaw
_POSITIVE = {"lo": 0.0, "lo_open": True, "hi": 1e4}


@dataclass(frozen=True)
class IntBSAttitudeGains:
    """Per Euler axis (roll, pitch, yaw): c1, c2 and lambda (the integral gain)."""

    law: str
    c1: Vector3
    c2: Vector3
    k_integral: Vector3


@register(ROTATIONAL)
class IntegralBacksteppingAttitude:
    NAME = "integral_backstepping"

    @classmethod
    def load_gains(cls, section: Section) -> IntBSAttitudeGains:
        c1, c2 = section.vector("c1", **_POSITIVE), section.vector("c2", **_POSITIVE)
        return IntBSAttitudeGains(cls.NAME, c1, c2, section.vector("k_integral", lo=0.0, hi=1e4))

    @staticmethod
    def parameters(gains: IntBSAttitudeGains) -> tuple[ParamSpec, ...]:
        specs = []
        groups = (("C1", gains.c1, 0.01, "c1"), ("C2", gains.c2, 0.01, "c2"),
                  ("KI", gains.k_integral, INTEGRAL_LO, "lambda (integral)"))  # fmt: skip
        for name, values, lo, what in groups:
            for i, axis in enumerate(EULER_AXES):
                what_axis = f"IntBS attitude {what}, {('roll', 'pitch', 'yaw')[i]}"
                specs.append(ParamSpec(f"ATT_{name}_{axis}", values[i], lo, GAIN_HI, description=what_axis))
        return tuple(specs)

    @staticmethod
    def gains_from_params(gains: IntBSAttitudeGains, params: Mapping[str, float]) -> IntBSAttitudeGains:
        def vec(prefix: str, default: Vector3) -> Vector3:
            names = [f"{prefix}_{a}" for a in EULER_AXES]
            if not all(n in params for n in names):
                return default
            return (params[names[0]], params[names[1]], params[names[2]])

        return replace(gains, c1=vec("ATT_C1", gains.c1), c2=vec("ATT_C2", gains.c2),
                       k_integral=vec("ATT_KI", gains.k_integral))  # fmt: skip

    def __init__(self, gains: IntBSAttitudeGains, nominal: NominalModel) -> None:
        self.gains = gains
        self.c1, self.c2, self.lam = gains.c1, gains.c2, gains.k_integral
        self.inertia = nominal.inertia_kg_m2
        self.integral = [0.0, 0.0, 0.0]
        self._torque_max: Vector3 = (math.inf, math.inf, math.inf)
        self._bound_integral()

    def set_integral_limit(self, torque_max: Vector3) -> None:
        """Anti-windup: chi is held where its torque, ``I c2 lambda chi`` per axis near hover (the
        integral term of eta_cmd'' through M), is at most ``torque_max`` (N m)."""
        self._torque_max = torque_max
        self._bound_integral()

    def _bound_integral(self) -> None:
        gains = [self.inertia[i] * self.c2[i] * self.lam[i] for i in range(3)]
        tau = self._torque_max
        self.integral_bound = tuple(tau[i] / g if g > 0.0 else math.inf for i, g in enumerate(gains))

    def reset(self) -> None:
        self.integral = [0.0, 0.0, 0.0]

    def integral_acceleration(self) -> Vector3:
        """The integral's term of eta_cmd'' now: ``-c2 lambda chi`` per axis (rad/s^2).

        In eta_cmd'' the chi terms are ``-(c1 + c2) lambda chi`` (through e2) and ``+c1 lambda chi``,
        which add up to ``-c2 lambda chi``; tau = M eta_cmd'' + C eta' carries them through M.
        """
        return tuple(-self.c2[i] * self.lam[i] * self.integral[i] for i in range(3))  # type: ignore[return-value]

    def retune(self, gains: IntBSAttitudeGains) -> None:
        """New gains from the next step on, without a jump in the integral action.

        chi_i is rescaled by ``(c2 lambda)_old / (c2 lambda)_new`` so every component of the
        integral term of eta_cmd'' is unchanged, and so is its image ``M (.)`` in tau at any
        state. A new lambda of zero drops the integral.
        """
        c2, k_integral = gains.c2, gains.k_integral
        for i in range(3):
            old, new = self.c2[i] * self.lam[i], c2[i] * k_integral[i]
            self.integral[i] = self.integral[i] * old / new if new != 0.0 else 0.0
        self.gains = gains
        self.c1, self.c2, self.lam = tuple(gains.c1), tuple(c2), tuple(k_integral)
        self._bound_integral()

    def update(
        self,
        euler: Vector3,
        euler_rates: Vector3,
        ref: Vector3,
        ref_rate: Vector3,
        ref_accel: Vector3,
        dt: float,
        integrate: bool = True,
    ) -> Vector3:
        e = (euler[0] - ref[0], euler[1] - ref[1], wrap_pi(euler[2] - ref[2]))
        accel_cmd = []
        for i in range(3):
            c1, c2, lam = self.c1[i], self.c2[i], self.lam[i]
            chi = self.integral[i]
            e_dot = euler_rates[i] - ref_rate[i]
            e2 = e_dot + c1 * e[i] + lam * chi
            accel_cmd.append(ref_accel[i] + (c1 * c1 - 1.0 - lam) * e[i] - (c1 + c2) * e2 + c1 * lam * chi)
        if integrate:
            bound, integral = self.integral_bound, self.integral
            for i in range(3):
                value = integral[i] + e[i] * dt
                integral[i] = bound[i] if value > bound[i] else (-bound[i] if value < -bound[i] else value)
        M = inertia_matrix(self.inertia, euler[0], euler[1])
        Ma = matrix_times(M, tuple(accel_cmd))
        Ce = matrix_times(coriolis_matrix(self.inertia, euler, euler_rates), euler_rates)
        return (Ma[0] + Ce[0], Ma[1] + Ce[1], Ma[2] + Ce[2])
