"""Nonlinear H-infinity attitude law of Section 3.2, eqs. (30)-(44), as corrected in CONTROL.md.

With eta~ = eta - eta_d and the weights of eq. (44) (Q_i = w_i^2 1, R = w_u^2 1, S = 0):

    tau = M(eta) eta_d'' + C(eta, eta') eta' - M(eta) [K_D eta~' + K_P eta~ + K_I int(eta~) dt]
    G   = M^-1 (C + w_u^-2 1),  k_d = sqrt(w2^2 + 2 w1 w3) / w1,  k_p = w3 / w1
    K_D = k_d 1 + G,  K_P = k_p 1 + k_d G,  K_I = k_p G

(the paper's eq. 43 prints eta_a'' for eta_d'' and -K_I for +K_I under this error sign). Since
``M G = C + w_u^-2 1``, the law is evaluated without inverting M:

    tau = M (eta_d'' - k_d eta~' - k_p eta~) + C eta' - (C + w_u^-2 1) s,
    s   = eta~' + k_d eta~ + k_p int(eta~) dt.

tau is the generalised torque on the Euler coordinates (eq. 4); the actuators get the body torque
``W_eta^-T tau``. Linearised about hover each axis has the poles of
(s + 1/(w_u^2 I))(s^2 + k_d s + k_p). The gains do not depend on gamma. With omega3 = 0
(BS-NLHinf) K_I = 0 and there is no integral action. Anti-windup: the integral is held where its
torque near hover, ``w_u^-2 k_p int(eta~)``, reaches the actuators' limit.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, replace

from quadcommon.frames import wrap_pi
from quadcommon.kernel import kernel
from quadcommon.layout import Field, layout, values
from quadcommon.numerics import clip_symmetric
from quadcommon.rigid_body import (
    body_torque_from_euler_torque,
    coriolis_matrix,
    inertia_matrix,
    matrix_times,
    solve3,
)
from quadcommon.schema import Section

from ...params.store import ParamSpec
from ..registry import ROTATIONAL, register
from ..translational import GAIN_HI, INTEGRAL_LO

Vector3 = tuple[float, float, float]

# Gains array: k_d, k_p, 1 / omega_u^2, the nominal inertia, the integrals' bounds.
GAINS = layout("NlhinfGains", (
    Field("kd"),
    Field("kp"),
    Field("r_inv"),
    Field("inertia", 3),
    Field("bound", 3),
))  # fmt: skip


@kernel
def step(g, x, euler, euler_rates, body_rates, eta_d, eta_d_dot, eta_d_ddot, dt, integrate):
    """eq. (43) as the module docstring writes it; returns the body torque (N m)."""
    k_d, k_p, r_inv = g[GAINS.kd], g[GAINS.kp], g[GAINS.r_inv]
    inertia = (g[GAINS.inertia], g[GAINS.inertia + 1], g[GAINS.inertia + 2])
    e0, e1, e2 = euler[0] - eta_d[0], euler[1] - eta_d[1], wrap_pi(euler[2] - eta_d[2])
    ed0 = euler_rates[0] - eta_d_dot[0]
    ed1 = euler_rates[1] - eta_d_dot[1]
    ed2 = euler_rates[2] - eta_d_dot[2]
    s = (ed0 + k_d * e0 + k_p * x[0], ed1 + k_d * e1 + k_p * x[1], ed2 + k_d * e2 + k_p * x[2])
    v = (eta_d_ddot[0] - k_d * ed0 - k_p * e0, eta_d_ddot[1] - k_d * ed1 - k_p * e1,
         eta_d_ddot[2] - k_d * ed2 - k_p * e2)  # fmt: skip
    Mv = matrix_times(inertia_matrix(inertia, euler[0], euler[1]), v)
    C = coriolis_matrix(inertia, euler, euler_rates)
    Ce = matrix_times(C, euler_rates)
    Cs = matrix_times(C, s)
    if integrate and k_p != 0.0:  # omega3 = 0: no integral action, no state to grow
        x[0] = clip_symmetric(x[0] + e0 * dt, g[GAINS.bound])
        x[1] = clip_symmetric(x[1] + e1 * dt, g[GAINS.bound + 1])
        x[2] = clip_symmetric(x[2] + e2 * dt, g[GAINS.bound + 2])
    tau_eta = (Mv[0] + Ce[0] - Cs[0] - r_inv * s[0], Mv[1] + Ce[1] - Cs[1] - r_inv * s[1],
               Mv[2] + Ce[2] - Cs[2] - r_inv * s[2])  # fmt: skip
    return body_torque_from_euler_torque(euler[0], euler[1], tau_eta)


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
        """``k_d = sqrt(omega2^2 + 2 omega1 omega3) / omega1`` (1/s), eq. (44)'s derivative weight."""
        return math.sqrt(self.omega2**2 + 2.0 * self.omega1 * self.omega3) / self.omega1

    @property
    def k_p(self) -> float:
        """``k_p = omega3 / omega1`` (1/s^2), eq. (44)'s proportional weight."""
        return self.omega3 / self.omega1

    @property
    def r_inv(self) -> float:
        """``w_u^-2 = 1 / omega_u^2``, the inverse of the control weight R (eq. 44)."""
        return 1.0 / self.omega_u**2


def nlhinf_gains(omega1: float, omega2: float, omega3: float, omega_u: float) -> NlHinfGains:
    """The gains record of the nonlinear H-infinity law from its four weights (eq. 44)."""
    return NlHinfGains(NonlinearHinfAttitude.NAME, omega1, omega2, omega3, omega_u)


def integral_matrix(gains: NlHinfGains, inertia: Vector3, euler: Vector3 | None, euler_rates: Vector3 | None):
    """``(C + w_u^-2 1) k_p``: tau's integral term is minus this times int(eta~) dt (C = 0 before
    any state is known: the small-rate form, exact at hover)."""
    if euler is None or euler_rates is None:
        C = ((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    else:
        C = coriolis_matrix(inertia, euler, euler_rates)
    k_p, r_inv = gains.k_p, gains.r_inv
    return tuple(tuple(k_p * (C[i][j] + (r_inv if i == j else 0.0)) for j in range(3)) for i in range(3))


@register(ROTATIONAL)
class NonlinearHinfAttitude:
    """eq. (43)-(44) on the nominal inertia; its state is the integral of the attitude error."""

    NAME = "nlhinf"
    STATE = ("int_roll", "int_pitch", "int_yaw")
    step = staticmethod(step)

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

    @staticmethod
    def pack(g: NlHinfGains, context) -> tuple[float, ...]:
        gain = g.r_inv * g.k_p
        bound = tuple(t / gain if gain > 0.0 else math.inf for t in context.torque_max_n_m)
        return values(GAINS, kd=g.k_d, kp=g.k_p, r_inv=g.r_inv, inertia=context.inertia_kg_m2, bound=bound)

    @staticmethod
    def retune(old: NlHinfGains, new: NlHinfGains, context, state, euler, euler_rates) -> list[float]:
        """The integral enters tau only through ``-(C + w_u^-2 1) k_p int(eta~)``; keeping it equal
        at the latest state means solving ``(C + w_u'^-2 1) k_p' I' = (C + w_u^-2 1) k_p I`` for
        the new integral I' (C at the (eta, eta') of the latest step, so the integral term is
        exactly continuous there; by the next step the state has moved one control period, an
        O(dt) difference). A singular system falls back to the small-rate scaling; k_p' = 0 removes
        the integral action and the integral.

        That continuity is kept only while it does not grow the integral's part of s, ``k_p I``:
        a larger w_u (a smaller w_u^-2) would need a proportionally larger s for the same torque,
        and s also enters tau through ``C s``, which grows with the rates (from w_u = 1.5 to 900,
        s would grow ~3.6e5 times and the vehicle tumble within 0.1 s). Then s is kept instead
        (``k_p' I' = k_p I``): tau steps by ``(w_u^-2 - w_u'^-2) k_p I``, which for a larger w_u
        is at most the integral's torque before the change."""
        if new.k_p == 0.0:
            return [0.0, 0.0, 0.0]
        kept_s = [v * old.k_p / new.k_p for v in state]
        inertia = context.inertia_kg_m2
        target = matrix_times(integral_matrix(old, inertia, euler, euler_rates), tuple(state))
        try:
            solved = solve3(integral_matrix(new, inertia, euler, euler_rates), target)
        except ZeroDivisionError:
            solved = None
        if solved is None or not all(math.isfinite(v) for v in solved):
            scale = (old.k_p * old.r_inv) / (new.k_p * new.r_inv)
            solved = tuple(v * scale for v in state)
        if max(abs(v) for v in solved) > max(abs(v) for v in kept_s):
            return kept_s
        return list(solved)
