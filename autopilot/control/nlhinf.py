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

from quadcommon.config import NlHinfGains
from quadcommon.frames import wrap_pi
from quadcommon.rigid_body import coriolis_matrix_fast, inertia_matrix, matrix_times

Vector3 = tuple[float, float, float]


class NonlinearHinfAttitude:
    """eq. (43)-(44) on the nominal inertia; holds the integral of the attitude error."""

    def __init__(self, gains: NlHinfGains, inertia_kg_m2: Vector3) -> None:
        self.gains = gains
        self.inertia = inertia_kg_m2
        self.k_d = gains.k_d
        self.k_p = gains.k_p
        self.r_inv = 1.0 / gains.omega_u**2
        self.integral = [0.0, 0.0, 0.0]

    def reset(self) -> None:
        self.integral = [0.0, 0.0, 0.0]

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
        C = coriolis_matrix_fast(self.inertia, euler, euler_rates)
        C_eta_dot = matrix_times(C, euler_rates)
        C_s = matrix_times(C, s)
        r_inv = self.r_inv
        if integrate:
            for i in range(3):
                integral[i] += e[i] * dt
        return (
            Mv[0] + C_eta_dot[0] - C_s[0] - r_inv * s[0],
            Mv[1] + C_eta_dot[1] - C_s[1] - r_inv * s[1],
            Mv[2] + C_eta_dot[2] - C_s[2] - r_inv * s[2],
        )
