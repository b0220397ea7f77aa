"""Geometric tracking control on SE(3) of Lee, Leok and McClamroch (2010), attitude part: the
rotational half of the ``se3`` cascade, with the feed-forward of the reference's angular velocity
and angular acceleration.

With ``R = R(eta)``, ``R_d = R(eta_d)`` (ZYX, paper frames), ``W`` the body angular velocity and the
reference's body angular velocity and acceleration from the command filter's eta_d', eta_d''
(eq. 3 and its time derivative, :mod:`quadcommon.rigid_body`)::

    W_d  = W_eta(eta_d) eta_d'
    W_d' = W_eta(eta_d) eta_d'' + W_eta'(eta_d, eta_d') eta_d'
    e_R  = 1/2 (R_d^T R - R^T R_d)^vee
    e_W  = W - R^T R_d W_d
    M    = -k_R e_R - k_W e_W + W x J W - J (hat(W) R^T R_d W_d - R^T R_d W_d')

(Lee et al. 2010), with diagonal gains ``k_R``, ``k_W`` (per body axis) and the
nominal inertia J. The last term is the feed-forward that makes a reference attitude motion
tracked exactly (RotorPy's implementation leaves out W_d and W_d'; this one keeps them). M is the
body torque (N m). Linearised about hover each axis is ``J s^2 + k_W s + k_R``. No integral action.
"""

from __future__ import annotations

from dataclasses import dataclass

from quadcommon.kernel import kernel
from quadcommon.layout import Field, layout, values
from quadcommon.rigid_body import (
    body_acceleration_from_euler,
    body_rates_from_euler_rates,
    cross,
    matrix_times,
    rotation_matrix,
)

from ..registry import ROTATIONAL, LawContext, register
from ..tunable import Tunable, TunableLaw

# Gains array, per body axis from each offset: k_R (N m/rad), k_W (N m s/rad), the nominal inertia.
GAINS = layout("Se3AttitudeGains", (
    Field("kr", 3),
    Field("kw", 3),
    Field("inertia", 3),
))  # fmt: skip


@kernel
def transpose_times(A, B):
    """``A^T B`` for 3x3 tuple matrices."""
    return (
        (A[0][0] * B[0][0] + A[1][0] * B[1][0] + A[2][0] * B[2][0],
         A[0][0] * B[0][1] + A[1][0] * B[1][1] + A[2][0] * B[2][1],
         A[0][0] * B[0][2] + A[1][0] * B[1][2] + A[2][0] * B[2][2]),
        (A[0][1] * B[0][0] + A[1][1] * B[1][0] + A[2][1] * B[2][0],
         A[0][1] * B[0][1] + A[1][1] * B[1][1] + A[2][1] * B[2][1],
         A[0][1] * B[0][2] + A[1][1] * B[1][2] + A[2][1] * B[2][2]),
        (A[0][2] * B[0][0] + A[1][2] * B[1][0] + A[2][2] * B[2][0],
         A[0][2] * B[0][1] + A[1][2] * B[1][1] + A[2][2] * B[2][1],
         A[0][2] * B[0][2] + A[1][2] * B[1][2] + A[2][2] * B[2][2]),
    )  # fmt: skip


@kernel
def errors(euler, body_rates, eta_d, eta_d_dot, eta_d_ddot):
    """``(e_R, e_W, R^T R_d W_d, R^T R_d W_d')`` of the module's equations."""
    R = rotation_matrix(euler[0], euler[1], euler[2])
    Q = transpose_times(R, rotation_matrix(eta_d[0], eta_d[1], eta_d[2]))
    w_d = matrix_times(Q, body_rates_from_euler_rates(eta_d[0], eta_d[1], eta_d_dot))
    w_d_dot = matrix_times(Q, body_acceleration_from_euler(eta_d[0], eta_d[1], eta_d_dot, eta_d_ddot))
    # (R_d^T R - R^T R_d) = Q^T - Q; its vee is (S[2][1], S[0][2], S[1][0])
    e_R = (0.5 * (Q[1][2] - Q[2][1]), 0.5 * (Q[2][0] - Q[0][2]), 0.5 * (Q[0][1] - Q[1][0]))
    e_W = (body_rates[0] - w_d[0], body_rates[1] - w_d[1], body_rates[2] - w_d[2])
    return e_R, e_W, w_d, w_d_dot


@kernel
def step(g, x, euler, euler_rates, body_rates, eta_d, eta_d_dot, eta_d_ddot, dt, integrate):
    """The rotational step of the registry's contract: Lee et al.'s moment ``M`` (N m, body FLU), the module's
    last equation; no state."""
    e_R, e_W, w_d, w_d_dot = errors(euler, body_rates, eta_d, eta_d_dot, eta_d_ddot)
    J = (g[GAINS.inertia], g[GAINS.inertia + 1], g[GAINS.inertia + 2])
    gyro = cross(body_rates, (J[0] * body_rates[0], J[1] * body_rates[1], J[2] * body_rates[2]))
    h = cross(body_rates, w_d)
    return (
        -g[GAINS.kr] * e_R[0] - g[GAINS.kw] * e_W[0] + gyro[0] - J[0] * (h[0] - w_d_dot[0]),
        -g[GAINS.kr + 1] * e_R[1] - g[GAINS.kw + 1] * e_W[1] + gyro[1] - J[1] * (h[1] - w_d_dot[1]),
        -g[GAINS.kr + 2] * e_R[2] - g[GAINS.kw + 2] * e_W[2] + gyro[2] - J[2] * (h[2] - w_d_dot[2]),
    )


TUNABLE_GAINS = (
    Tunable("k_R", "SE3_KR", 0.0, 1000.0, "N m/rad", "SE(3) attitude gain k_R", per_axis=True),
    Tunable("k_W", "SE3_KW", 0.0, 100.0, "N m s/rad", "SE(3) angular velocity gain k_W", per_axis=True),
)


@dataclass(frozen=True)
class Se3AttitudeGains:
    """Lee's attitude gains, per body axis (roll, pitch, yaw)."""

    law: str
    k_R: tuple[float, float, float]  # noqa: N815 - Lee's names
    k_W: tuple[float, float, float]  # noqa: N815


@register(ROTATIONAL)
class Se3Attitude(TunableLaw):
    NAME = "se3_attitude"
    GAINS, TUNABLE = Se3AttitudeGains, TUNABLE_GAINS
    step = staticmethod(step)

    @staticmethod
    def pack(gains: Se3AttitudeGains, context: LawContext) -> tuple[float, ...]:
        return values(GAINS, kr=gains.k_R, kw=gains.k_W, inertia=context.inertia_kg_m2)
