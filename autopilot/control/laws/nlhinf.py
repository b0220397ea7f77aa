"""Nonlinear H-infinity attitude law of Section 3.2, eqs. (30)-(44), as corrected in CONTROL.md.

With eta~ = eta - eta_d and the weights of eq. (44) (Q_i = w_i^2 1, R = w_u^2 1, S = 0):

    tau = M(eta) eta_d'' + C(eta, eta') eta' - M(eta) [K_D eta~' + K_P eta~ + K_I int(eta~) dt]
    G   = M^-1 (C + w_u^-2 1),  k_d = sqrt(w2^2 + 2 w1 w3) / w1,  k_p = w3 / w1
    K_D = k_d 1 + G,  K_P = k_p 1 + k_d G,  K_I = k_p G

(the paper's eq. 43 prints eta_a'' for eta_d'' and -K_I for +K_I under this error sign). Since
``M G = C + w_u^-2 1``, the law is evaluated without inverting M:

    tau = M (eta_d'' - k_d eta~' - k_p eta~) + C eta' - (C + w_u^-2 1) s,
    s   = eta~' + k_d eta~ + k_p int(eta~) dt.

Linearised about hover each axis has the poles of (s + 1/(w_u^2 I))(s^2 + k_d s + k_p). The gains
do not depend on gamma. With omega3 = 0 (BS-NLHinf) K_I = 0 and there is no integral action.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace

from quadcommon.config import NominalModel
from quadcommon.frames import wrap_pi
from quadcommon.rigid_body import coriolis_matrix, inertia_matrix, matrix_times, solve3
from quadcommon.schema import Section

from ...params.store import ParamSpec
from ..registry import ROTATIONAL, register
from ..translational import GAIN_HI, INTEGRAL_LO

Vector3 = tuple[float, float, float]


@dataclass(frozen=True)
class NlHinfGains:
    """Weights of the nonlinear H-infinity law, eq. (44): omega1, omega2, omega3, omega_u."""

    law: str
    omega1: float
    omega2: float
    omega3: float
    omega_u: float

    @property
    def k_d(self) -> float:
        return math.sqrt(self.omega2**2 + 2.0 * self.omega1 * self.omega3) / self.omega1

    @property
    def k_p(self) -> float:
        return self.omega3 / self.omega1


def nlhinf_gains(omega1: float, omega2: float, omega3: float, omega_u: float) -> NlHinfGains:
    return NlHinfGains(NonlinearHinfAttitude.NAME, omega1, omega2, omega3, omega_u)


@register(ROTATIONAL)
class NonlinearHinfAttitude:
    """eq. (43)-(44) on the nominal inertia; holds the integral of the attitude error."""

    NAME = "nlhinf"

    @classmethod
    def load_gains(cls, section: Section) -> NlHinfGains:
        return NlHinfGains(
            cls.NAME,
            omega1=section.number("omega1", lo=0.0, lo_open=True, hi=1e3),
            omega2=section.number("omega2", lo=0.0, lo_open=True, hi=1e3),
            omega3=section.number("omega3", lo=0.0, hi=1e3),
            omega_u=section.number("omega_u", lo=0.0, lo_open=True, hi=1e3),
        )

    @staticmethod
    def parameters(g: NlHinfGains) -> tuple[ParamSpec, ...]:
        return (
            ParamSpec("NLH_W1", g.omega1, 0.001, GAIN_HI, description="NLHinf weight omega1 (eq. 44)"),
            ParamSpec("NLH_W2", g.omega2, 0.001, GAIN_HI, description="NLHinf weight omega2 (eq. 44)"),
            ParamSpec(
                "NLH_W3", g.omega3, INTEGRAL_LO, GAIN_HI,
                description="NLHinf weight omega3 (eq. 44; integral action K_I = k_p G)",
                read_only="" if g.omega3 > 0.0 else "this cascade has no attitude integral (omega3 = 0)",
            ),  # fmt: skip
            ParamSpec("NLH_WU", g.omega_u, 0.01, GAIN_HI, description="NLHinf weight omega_u (eq. 44)"),
        )

    @staticmethod
    def gains_from_params(g: NlHinfGains, params: Mapping[str, float]) -> NlHinfGains:
        if "NLH_W1" not in params:
            return g
        return replace(g, omega1=params["NLH_W1"], omega2=params["NLH_W2"], omega3=params["NLH_W3"],
                       omega_u=params["NLH_WU"])  # fmt: skip

    def __init__(self, gains: NlHinfGains, nominal: NominalModel) -> None:
        self.inertia = nominal.inertia_kg_m2
        self.integral = [0.0, 0.0, 0.0]
        self._set_gains(gains)
        # (eta, eta') of the latest update: where retune() evaluates C
        self._last_state: tuple[Vector3, Vector3] | None = None

    def _set_gains(self, gains: NlHinfGains) -> None:
        self.gains = gains
        self.k_d = gains.k_d
        self.k_p = gains.k_p
        self.r_inv = 1.0 / gains.omega_u**2
        self._bound_integral()

    def set_integral_limit(self, torque_max: Vector3) -> None:
        """Anti-windup: the integral of the attitude error is held where its torque,
        ``w_u^-2 k_p int(eta~)`` per axis (the s term of the module docstring near hover), is at
        most ``torque_max`` (N m): more than the actuators can give is never asked for."""
        self._torque_max = torque_max
        self._bound_integral()

    def _bound_integral(self) -> None:
        gain = self.r_inv * self.k_p
        tau = getattr(self, "_torque_max", (math.inf, math.inf, math.inf))
        self.integral_bound = tuple(tau[i] / gain if gain > 0.0 else math.inf for i in range(3))

    def reset(self) -> None:
        self.integral = [0.0, 0.0, 0.0]

    def _integral_matrix(self, k_p: float, r_inv: float, state: tuple[Vector3, Vector3] | None):
        """``(C + r_inv 1) k_p``: tau's integral term is minus this times int(eta~) dt."""
        if state is None:
            C = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
        else:
            C = coriolis_matrix(self.inertia, state[0], state[1])
        return tuple(tuple(k_p * (C[i][j] + (r_inv if i == j else 0.0)) for j in range(3)) for i in range(3))

    def integral_torque(self, euler: Vector3, euler_rates: Vector3) -> Vector3:
        """The integral's contribution to tau_eta at the state (eta, eta') now (N m)."""
        A = self._integral_matrix(self.k_p, self.r_inv, (euler, euler_rates))
        v = matrix_times(A, tuple(self.integral))
        return (-v[0], -v[1], -v[2])

    def retune(self, gains: NlHinfGains) -> None:
        """New weights from the next step on, without a jump in the integral action.

        The integral enters tau only through ``-(C + w_u^-2 1) k_p int(eta~)`` (the s term of
        the module docstring). Keeping it equal at the latest state means solving
        ``(C + w_u'^-2 1) k_p' I' = (C + w_u^-2 1) k_p I`` for the new integral I'. C is
        evaluated at the (eta, eta') of the latest update, so the integral term is exactly
        continuous there; by the next step the state has moved by one control period, an O(dt)
        difference. Before any update (or if the system is singular) C is taken as 0, which is
        the small-rate approximation ``I' = I (k_p / k_p') (w_u'^2 / w_u^2)``, exact at hover.
        k_p' = w3' / w1' = 0 removes the integral action, and the integral is zeroed.
        """
        k_p_new, r_inv_new = gains.omega3 / gains.omega1, 1.0 / gains.omega_u**2
        if k_p_new == 0.0:
            self.integral = [0.0, 0.0, 0.0]
        else:
            state = self._last_state
            old = matrix_times(self._integral_matrix(self.k_p, self.r_inv, state), tuple(self.integral))
            new = self._integral_matrix(k_p_new, r_inv_new, state)
            try:
                solved = solve3(new, old)
                if not all(math.isfinite(v) for v in solved):
                    raise ZeroDivisionError
                self.integral = list(solved)
            except ZeroDivisionError:
                scale = (self.k_p * self.r_inv) / (k_p_new * r_inv_new)
                self.integral = [v * scale for v in self.integral]
        self._set_gains(gains)

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
        """Generalised torque tau_eta (N m) on the Euler coordinates."""
        k_d, k_p = self.k_d, self.k_p
        self._last_state = (euler, euler_rates)
        e = (euler[0] - ref[0], euler[1] - ref[1], wrap_pi(euler[2] - ref[2]))
        e_dot = (
            euler_rates[0] - ref_rate[0],
            euler_rates[1] - ref_rate[1],
            euler_rates[2] - ref_rate[2],
        )
        integral = self.integral
        s = tuple(e_dot[i] + k_d * e[i] + k_p * integral[i] for i in range(3))
        M = inertia_matrix(self.inertia, euler[0], euler[1])
        v = tuple(ref_accel[i] - k_d * e_dot[i] - k_p * e[i] for i in range(3))
        Mv = matrix_times(M, v)
        C = coriolis_matrix(self.inertia, euler, euler_rates)
        C_eta_dot = matrix_times(C, euler_rates)
        C_s = matrix_times(C, s)
        r_inv = self.r_inv
        if integrate and k_p != 0.0:  # omega3 = 0: no integral action, no state to grow
            bound = self.integral_bound
            for i in range(3):
                value = integral[i] + e[i] * dt
                integral[i] = bound[i] if value > bound[i] else (-bound[i] if value < -bound[i] else value)
        return (
            Mv[0] + C_eta_dot[0] - C_s[0] - r_inv * s[0],
            Mv[1] + C_eta_dot[1] - C_s[1] - r_inv * s[1],
            Mv[2] + C_eta_dot[2] - C_s[2] - r_inv * s[2],
        )
