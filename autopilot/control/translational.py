"""Translational (outer-loop) laws: total thrust U1 and the roll/pitch references.

Per axis i in {x, y, z}, with the error sign of CONTROL.md (e1 = p - p_d, e1' = v - v_d), each
law gives a commanded acceleration ``a_i``; then (eqs. 24-29, as clarified in CONTROL.md)

* ``U1 = m (g + a_z) / (cos(phi) cos(theta))``, saturated to ``[0, U1_max]``;
* ``u_x = m a_x / U1``, ``u_y = m a_y / U1`` (the thrust directions of eq. 23);
* ``phi_r = asin(sin(psi) u_x - cos(psi) u_y)``,
  ``theta_r = asin((cos(psi) u_x + sin(psi) u_y) / cos(phi_r))``, arguments clipped to the tilt
  limit (eq. 29 solved for the angles; the paper prints the u_y line twice).

Laws (``translational.law``):

* ``integral_second_step`` (the paper's, Section 3.1): integral state xi' = e2 = e1' + c1 e1,
  ``a = p_d'' - k_xi xi - (1 + c1 c2) e1 - (c1 + c2) e1'`` (eq. 28 with its last term p_d'').
* ``integral_first_step`` (IntBS, ref. [2]): chi' = e1, e2 = e1' + c1 e1 + lambda chi,
  ``a = p_d'' + (c1^2 - 1 - lambda) e1 - (c1 + c2) e2 + c1 lambda chi``.
* ``backstepping`` (ref. [23]): ``a = p_d'' - (1 + c1 c2) e1 - (c1 + c2) e1'``.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from quadcommon.config import TranslationalGains

Vector3 = tuple[float, float, float]


class TranslationalOutput(NamedTuple):
    thrust_n: float  # U1, saturated
    roll_ref_rad: float  # phi_r
    pitch_ref_rad: float  # theta_r
    acceleration_cmd_m_s2: Vector3  # a_x, a_y, a_z of the law


class TranslationalController:
    """One of the three outer-loop laws; holds its integral states."""

    def __init__(
        self, gains: TranslationalGains, mass_kg: float, gravity_m_s2: float, thrust_max_n: float
    ) -> None:
        self.law = gains.law
        self.mass = mass_kg
        self.gravity = gravity_m_s2
        self.thrust_max = thrust_max_n
        # Below this thrust the horizontal directions u_x, u_y are meaningless (free fall).
        self.thrust_floor = 0.1 * mass_kg * gravity_m_s2
        self.integral = [0.0, 0.0, 0.0]
        self._set_gains(gains)

    def _set_gains(self, gains: TranslationalGains) -> None:
        self.gains = gains
        self.sin_tilt_max = math.sin(gains.tilt_max_rad)
        c1, c2, k = gains.c1, gains.c2, gains.k_integral
        # Precomputed per-axis coefficients of the laws.
        self._coef = [(c1[i], c2[i], k[i], 1.0 + c1[i] * c2[i], c1[i] + c2[i]) for i in range(3)]

    def reset(self) -> None:
        """Zero the integral states (on the ground, disarmed, or at a law switch)."""
        self.integral = [0.0, 0.0, 0.0]

    def _integral_weights(self, gains: TranslationalGains) -> Vector3:
        """w_i such that the integral term of ``a_i`` is ``-w_i * integral_i`` (1/s^2 units)."""
        if self.law == "integral_second_step":
            return gains.k_integral  # -k_xi xi
        if self.law == "integral_first_step":
            # (c1^2 - 1 - lambda) e1 - (c1 + c2)(e1' + c1 e1 + lambda chi) + c1 lambda chi: the chi
            # terms add up to -(c1 + c2) lambda chi + c1 lambda chi = -c2 lambda chi.
            c2, lam = gains.c2, gains.k_integral
            return (c2[0] * lam[0], c2[1] * lam[1], c2[2] * lam[2])
        return (0.0, 0.0, 0.0)

    def integral_acceleration(self) -> Vector3:
        """The integral states' contribution to the commanded acceleration now (m/s^2)."""
        w = self._integral_weights(self.gains)
        return (-w[0] * self.integral[0], -w[1] * self.integral[1], -w[2] * self.integral[2])

    def retune(self, gains: TranslationalGains) -> None:
        """New gains from the next step on, without a jump in the integral action.

        Each integral state is rescaled by ``w_old / w_new`` (w = k_xi for the integral in the 2nd
        step, c2 lambda for the integral in the 1st step), so ``w * integral`` and hence the
        commanded acceleration's integral term are unchanged at the moment of the change; the new
        gains then shape how it evolves. The proportional terms change with c1, c2 as they must.
        A new integral gain of zero drops the integral (its term cannot be kept).
        """
        if gains.law != self.law:
            raise ValueError(f"cannot switch translational law {self.law} -> {gains.law} by retuning")
        old, new = self._integral_weights(self.gains), self._integral_weights(gains)
        for i in range(3):
            self.integral[i] = self.integral[i] * old[i] / new[i] if new[i] != 0.0 else 0.0
        self._set_gains(gains)

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
        """One control step; integral states advance by ``dt`` (forward Euler) if ``integrate``."""
        accel = [0.0, 0.0, 0.0]
        integral = self.integral
        law = self.law
        for i in range(3):
            c1, c2, k, one_plus_c1c2, c1_plus_c2 = self._coef[i]
            e1 = position[i] - ref_position[i]
            e1_dot = velocity[i] - ref_velocity[i]
            if law == "integral_second_step":
                accel[i] = ref_acceleration[i] - k * integral[i] - one_plus_c1c2 * e1 - c1_plus_c2 * e1_dot
                if integrate:
                    integral[i] += (e1_dot + c1 * e1) * dt
            elif law == "integral_first_step":
                chi = integral[i]
                e2 = e1_dot + c1 * e1 + k * chi
                accel[i] = ref_acceleration[i] + (c1 * c1 - 1.0 - k) * e1 - c1_plus_c2 * e2 + c1 * k * chi
                if integrate:
                    integral[i] += e1 * dt
            else:
                accel[i] = ref_acceleration[i] - one_plus_c1c2 * e1 - c1_plus_c2 * e1_dot
        phi, theta, psi = euler
        m = self.mass
        tilt = math.cos(phi) * math.cos(theta)
        thrust = m * (self.gravity + accel[2]) / max(tilt, 0.1)
        thrust = min(max(thrust, 0.0), self.thrust_max)
        divisor = max(thrust, self.thrust_floor)
        u_x = m * accel[0] / divisor
        u_y = m * accel[1] / divisor
        sp, cp = math.sin(psi), math.cos(psi)
        limit = self.sin_tilt_max
        arg = sp * u_x - cp * u_y
        roll_ref = math.asin(min(max(arg, -limit), limit))
        arg = (cp * u_x + sp * u_y) / math.cos(roll_ref)
        pitch_ref = math.asin(min(max(arg, -limit), limit))
        return TranslationalOutput(thrust, roll_ref, pitch_ref, (accel[0], accel[1], accel[2]))
