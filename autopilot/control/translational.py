"""The translational (outer) loop: a law's commanded accelerations -> U1 and the roll/pitch references.

Per axis i in {x, y, z}, with the error sign of CONTROL.md (e1 = p - p_d, e1' = v - v_d), the
law (``translational.law``, see :mod:`.registry` and ``laws/``) gives a commanded acceleration
``a_i``; then, the same for every law (eqs. 24-29, as clarified in CONTROL.md):

* ``U1 = m (g + a_z) / (cos(phi) cos(theta))``, saturated to ``[0, U1_max]``;
* ``u_x = m a_x / U1``, ``u_y = m a_y / U1`` (the thrust directions of eq. 23);
* ``phi_r = asin(sin(psi) u_x - cos(psi) u_y)``,
  ``theta_r = asin((cos(psi) u_x + sin(psi) u_y) / cos(phi_r))``, arguments clipped to the tilt
  limit (eq. 29 solved for the angles; the paper prints the u_y line twice).

The backstepping family of the paper (integral in the 2nd step, in the 1st step, none) shares its
gains (c1, c2, k_integral per axis) and their parameters (``BS_C1_*``, ``BS_C2_*``, ``BS_KI_*``):
:class:`BacksteppingGains` and the helpers below.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import NamedTuple

from quadcommon.config import NominalModel
from quadcommon.schema import Section

from ..params.store import ParamSpec

Vector3 = tuple[float, float, float]
AXES = ("X", "Y", "Z")
GAIN_HI = 1000.0
INTEGRAL_LO = 0.001  # integral gains stay > 0: the retune keeps k * integral, which needs k != 0


class TranslationalOutput(NamedTuple):
    thrust_n: float  # U1, saturated
    roll_ref_rad: float  # phi_r
    pitch_ref_rad: float  # theta_r
    acceleration_cmd_m_s2: Vector3  # a_x, a_y, a_z of the law


class TranslationalController:
    """The loop around one translational law: thrust and roll/pitch references (eqs. 23-29)."""

    def __init__(self, law, nominal: NominalModel, thrust_max_n: float, tilt_max_rad: float) -> None:
        self.law = law
        self.mass = nominal.mass_kg
        self.gravity = nominal.gravity_m_s2
        self.thrust_max = thrust_max_n
        # Below this thrust the horizontal directions u_x, u_y are meaningless (free fall).
        self.thrust_floor = 0.1 * nominal.mass_kg * nominal.gravity_m_s2
        self.set_tilt_max(tilt_max_rad)

    def _limit_integrals(self) -> None:
        """The law's anti-windup bound: horizontally what the tilt limit allows (g tan(tilt)),
        vertically what the thrust allows above hover (U1_max / m - g)."""
        if hasattr(self.law, "set_integral_limit"):
            horizontal = self.gravity * math.tan(self.tilt_max_rad)
            vertical = max(self.thrust_max / self.mass - self.gravity, 0.0)
            self.law.set_integral_limit((horizontal, horizontal, vertical))

    @classmethod
    def for_gains(cls, gains, nominal: NominalModel, thrust_max_n: float, tilt_max_rad: float = 0.7):
        """The loop around the law that ``gains`` belong to (looked up by ``gains.law``)."""
        from . import registry

        return cls(registry.law(registry.TRANSLATIONAL, gains.law)(gains, nominal), nominal, thrust_max_n,
                   tilt_max_rad)  # fmt: skip

    # The loop's integral state is its law's.
    @property
    def gains(self):
        return self.law.gains

    @property
    def integral(self) -> list[float]:
        return self.law.integral

    @integral.setter
    def integral(self, values) -> None:
        self.law.integral = list(values)

    def integral_acceleration(self) -> Vector3:
        return self.law.integral_acceleration()

    def retune(self, gains) -> None:
        self.law.retune(gains)
        self._limit_integrals()

    def set_tilt_max(self, tilt_max_rad: float) -> None:
        self.tilt_max_rad = tilt_max_rad
        self.sin_tilt_max = math.sin(tilt_max_rad)
        self._limit_integrals()

    def reset(self) -> None:
        """Zero the law's integral states (on the ground, disarmed)."""
        self.law.reset()

    def update(
        self,
        position: Vector3,
        velocity: Vector3,
        euler: Vector3,
        ref_position: Vector3,
        ref_velocity: Vector3,
        ref_acceleration: Vector3,
        dt: float,
        integrate: bool = True,
    ) -> TranslationalOutput:
        """One control step; the law's integral states advance by ``dt`` if ``integrate``."""
        e1 = (position[0] - ref_position[0], position[1] - ref_position[1], position[2] - ref_position[2])
        e1_dot = (velocity[0] - ref_velocity[0], velocity[1] - ref_velocity[1], velocity[2] - ref_velocity[2])
        ax, ay, az = self.law.accelerations(e1, e1_dot, ref_acceleration, dt, integrate)
        phi, theta, psi = euler
        m = self.mass
        tilt = math.cos(phi) * math.cos(theta)
        thrust = m * (self.gravity + az) / max(tilt, 0.1)
        thrust = min(max(thrust, 0.0), self.thrust_max)
        divisor = max(thrust, self.thrust_floor)
        u_x = m * ax / divisor
        u_y = m * ay / divisor
        sp, cp = math.sin(psi), math.cos(psi)
        limit = self.sin_tilt_max
        arg = sp * u_x - cp * u_y
        roll_ref = math.asin(min(max(arg, -limit), limit))
        arg = (cp * u_x + sp * u_y) / math.cos(roll_ref)
        pitch_ref = math.asin(min(max(arg, -limit), limit))
        return TranslationalOutput(thrust, roll_ref, pitch_ref, (ax, ay, az))


# -- the backstepping family's gains and parameters ----------------------------------------------
@dataclass(frozen=True)
class BacksteppingGains:
    """Per-axis (x, y, z) gains of the translational backstepping laws (Section 3.1, eqs. 24-29).

    ``k_integral`` is k_xi for the integral in the second step (the paper's law) and lambda for
    the integral in the first step (IntBS); zero for plain backstepping.
    """

    law: str
    c1: Vector3
    c2: Vector3
    k_integral: Vector3 = (0.0, 0.0, 0.0)


_POSITIVE = {"lo": 0.0, "lo_open": True, "hi": 1e4}


def load_backstepping_gains(section: Section, law: str, integral: bool) -> BacksteppingGains:
    """c1, c2 (> 0) and, for an integral law, k_integral (> 0 on every axis)."""
    c1, c2 = section.vector("c1", **_POSITIVE), section.vector("c2", **_POSITIVE)
    if not integral:  # no integral: k_integral may be given, as zeros only
        zeros = section.vector("k_integral", 3, (0.0, 0.0, 0.0), lo=0.0, hi=0.0)
        return BacksteppingGains(law, c1, c2, zeros)
    k = section.vector("k_integral", 3, (0.0, 0.0, 0.0), lo=0.0, hi=1e4)
    if min(k) <= 0.0:
        raise section.error("k_integral", k, f"> 0 on every axis for law '{law}'")
    return BacksteppingGains(law, c1, c2, k)


def backstepping_parameters(gains: BacksteppingGains, integral_meaning: str | None) -> tuple[ParamSpec, ...]:
    """``BS_C1_*``, ``BS_C2_*`` and, with an integral, ``BS_KI_*`` (defaults: ``gains``)."""
    specs = []
    for name, values, what in (("C1", gains.c1, "c1"), ("C2", gains.c2, "c2")):
        for i, axis in enumerate(AXES):
            what_axis = f"translational backstepping {what}, {axis.lower()} axis"
            specs.append(
                ParamSpec(f"BS_{name}_{axis}", values[i], 0.01, GAIN_HI, unit="1/s", description=what_axis)
            )
    if integral_meaning is not None:
        for i, axis in enumerate(AXES):
            what_axis = f"translational {integral_meaning}, {axis.lower()} axis"
            specs.append(
                ParamSpec(f"BS_KI_{axis}", gains.k_integral[i], INTEGRAL_LO, GAIN_HI, description=what_axis)
            )
    return tuple(specs)


def backstepping_from_params(gains: BacksteppingGains, params: Mapping[str, float]) -> BacksteppingGains:
    def vec(prefix: str, default: Vector3) -> Vector3:
        names = [f"{prefix}_{a}" for a in AXES]
        if not all(n in params for n in names):
            return default
        return (params[names[0]], params[names[1]], params[names[2]])

    return replace(gains, c1=vec("BS_C1", gains.c1), c2=vec("BS_C2", gains.c2),
                   k_integral=vec("BS_KI", gains.k_integral))  # fmt: skip


class BacksteppingLaw:
    """Shared state and retune of the family: integral states, and per-axis coefficients."""

    NAME = ""

    def __init__(self, gains: BacksteppingGains, nominal: NominalModel | None = None) -> None:
        self.integral = [0.0, 0.0, 0.0]
        self._a_max: Vector3 = (math.inf, math.inf, math.inf)
        self._set_gains(gains)

    def _set_gains(self, gains: BacksteppingGains) -> None:
        self.gains = gains
        c1, c2, k = gains.c1, gains.c2, gains.k_integral
        self._coef = [(c1[i], c2[i], k[i], 1.0 + c1[i] * c2[i], c1[i] + c2[i]) for i in range(3)]
        w = self.integral_weights(gains)
        self.integral_bound = tuple(self._a_max[i] / w[i] if w[i] > 0.0 else math.inf for i in range(3))

    def set_integral_limit(self, acceleration_max: Vector3) -> None:
        """Anti-windup: each integral state is held where its term of the commanded acceleration
        is at most ``acceleration_max`` (m/s^2, per axis): what the vehicle can give at all."""
        self._a_max = acceleration_max
        self._set_gains(self.gains)

    def _clamp_integral(self) -> None:
        integral, bound = self.integral, self.integral_bound
        for i in range(3):
            if integral[i] > bound[i]:
                integral[i] = bound[i]
            elif integral[i] < -bound[i]:
                integral[i] = -bound[i]

    def reset(self) -> None:
        self.integral = [0.0, 0.0, 0.0]

    def integral_weights(self, gains: BacksteppingGains) -> Vector3:
        """w_i such that the integral term of ``a_i`` is ``-w_i * integral_i`` (1/s^2 units)."""
        return (0.0, 0.0, 0.0)

    def integral_acceleration(self) -> Vector3:
        """The integral states' contribution to the commanded acceleration now (m/s^2)."""
        w = self.integral_weights(self.gains)
        return (-w[0] * self.integral[0], -w[1] * self.integral[1], -w[2] * self.integral[2])

    def retune(self, gains: BacksteppingGains) -> None:
        """New gains from the next step on, without a jump in the integral action.

        Each integral state is rescaled by ``w_old / w_new`` (:meth:`integral_weights`), so
        ``w * integral`` and hence the commanded acceleration's integral term are unchanged at the
        moment of the change; the new gains then shape how it evolves. The proportional terms
        change with c1, c2 as they must. A new integral gain of zero drops the integral.
        """
        if gains.law != self.NAME:
            raise ValueError(f"cannot switch translational law {self.NAME} -> {gains.law} by retuning")
        old, new = self.integral_weights(self.gains), self.integral_weights(gains)
        for i in range(3):
            self.integral[i] = self.integral[i] * old[i] / new[i] if new[i] != 0.0 else 0.0
        self._set_gains(gains)
