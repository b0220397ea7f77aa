"""Rotational kinematics and the Euler-Lagrange rotational model of Section II.

Frames are the paper's: world x-forward/y-left/z-up, body front-left-up, ZYX Euler angles
``eta = (phi, theta, psi)`` with ``R = Rz(psi) Ry(theta) Rx(phi)`` mapping body to world.

Everything here works on plain floats and tuples: these functions sit on the per-step path of
both the plant and the controllers, where small-array numpy costs ~10x more than float maths.
Matrices are row-major tuples of three row tuples.
"""

from __future__ import annotations

import math

Vector3 = tuple[float, float, float]
Matrix3 = tuple[Vector3, Vector3, Vector3]


# --------------------------------------------------------------------------------------------
# Kinematics
# --------------------------------------------------------------------------------------------
def rotation_matrix(phi: float, theta: float, psi: float) -> Matrix3:
    """Body-to-world rotation ``R = Rz(psi) Ry(theta) Rx(phi)`` (the matrix in eq. 2)."""
    sf, cf = math.sin(phi), math.cos(phi)
    st, ct = math.sin(theta), math.cos(theta)
    sp, cp = math.sin(psi), math.cos(psi)
    return (
        (cp * ct, cp * st * sf - sp * cf, cp * st * cf + sp * sf),
        (sp * ct, sp * st * sf + cp * cf, sp * st * cf - cp * sf),
        (-st, ct * sf, ct * cf),
    )


def euler_from_rotation(R: Matrix3) -> Vector3:
    """ZYX Euler angles of a rotation matrix; theta is kept in [-pi/2, pi/2]."""
    sin_theta = -R[2][0]
    sin_theta = 1.0 if sin_theta > 1.0 else (-1.0 if sin_theta < -1.0 else sin_theta)
    return (math.atan2(R[2][1], R[2][2]), math.asin(sin_theta), math.atan2(R[1][0], R[0][0]))


def quaternion_from_euler(phi: float, theta: float, psi: float) -> tuple[float, float, float, float]:
    """Unit quaternion ``(w, x, y, z)`` of the ZYX rotation, scalar first, w >= 0."""
    cf, sf = math.cos(0.5 * phi), math.sin(0.5 * phi)
    ct, st = math.cos(0.5 * theta), math.sin(0.5 * theta)
    cp, sp = math.cos(0.5 * psi), math.sin(0.5 * psi)
    w = cf * ct * cp + sf * st * sp
    x = sf * ct * cp - cf * st * sp
    y = cf * st * cp + sf * ct * sp
    z = cf * ct * sp - sf * st * cp
    if w < 0.0:
        w, x, y, z = -w, -x, -y, -z
    return (w, x, y, z)


def rotation_from_quaternion(w: float, x: float, y: float, z: float) -> Matrix3:
    """Body-to-world rotation matrix of a unit quaternion ``(w, x, y, z)``."""
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    return (
        (1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy)),
        (2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx)),
        (2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy)),
    )


def euler_from_quaternion(w: float, x: float, y: float, z: float) -> Vector3:
    """ZYX Euler angles ``(phi, theta, psi)`` of a unit quaternion: ``euler_from_rotation`` of
    ``rotation_from_quaternion``, the five entries it reads computed alone (the same operations,
    so the same bits; it runs at every frame)."""
    xx, yy, zz = x * x, y * y, z * z
    r00 = 1.0 - 2.0 * (yy + zz)
    r10 = 2.0 * (x * y + w * z)
    sin_theta = -(2.0 * (x * z - w * y))
    sin_theta = 1.0 if sin_theta > 1.0 else (-1.0 if sin_theta < -1.0 else sin_theta)
    r21 = 2.0 * (y * z + w * x)
    r22 = 1.0 - 2.0 * (xx + yy)
    return (math.atan2(r21, r22), math.asin(sin_theta), math.atan2(r10, r00))


def euler_rate_matrix(phi: float, theta: float) -> Matrix3:
    """``W_eta`` of eq. (3): body angular velocity ``omega = W_eta * eta_dot``."""
    sf, cf = math.sin(phi), math.cos(phi)
    st, ct = math.sin(theta), math.cos(theta)
    return ((1.0, 0.0, -st), (0.0, cf, sf * ct), (0.0, -sf, cf * ct))


def body_rates_from_euler_rates(phi: float, theta: float, eta_dot: Vector3) -> Vector3:
    """``omega = W_eta eta_dot`` (eq. 3) without forming the matrix."""
    sf, cf = math.sin(phi), math.cos(phi)
    st, ct = math.sin(theta), math.cos(theta)
    dphi, dtheta, dpsi = eta_dot
    return (dphi - st * dpsi, cf * dtheta + sf * ct * dpsi, -sf * dtheta + cf * ct * dpsi)


def euler_rates_from_body_rates(phi: float, theta: float, omega: Vector3) -> Vector3:
    """``eta_dot = W_eta^-1 omega``; singular at theta = +-pi/2 (gimbal lock)."""
    sf, cf = math.sin(phi), math.cos(phi)
    ct, tt = math.cos(theta), math.tan(theta)
    p, q, r = omega
    return (p + sf * tt * q + cf * tt * r, cf * q - sf * r, (sf * q + cf * r) / ct)


def body_torque_from_euler_torque(phi: float, theta: float, tau_eta: Vector3) -> Vector3:
    """Body torque equivalent to generalised torque ``tau_eta`` on the Euler coordinates.

    The Lagrangian generalised force is ``tau_eta = W_eta^T tau_body`` (eq. 4), so
    ``tau_body = W_eta^-T tau_eta``.
    """
    sf, cf = math.sin(phi), math.cos(phi)
    st, ct = math.sin(theta), math.cos(theta)
    a, b, c = tau_eta
    # Solve W^T x = tau_eta, W^T = [[1,0,0],[0,cf,-sf],[-st, sf ct, cf ct]].
    x0 = a
    # rows 2, 3: cf x1 - sf x2 = b ;  sf ct x1 + cf ct x2 = c + st x0
    rhs = (c + st * x0) / ct
    x1 = cf * b + sf * rhs
    x2 = -sf * b + cf * rhs
    return (x0, x1, x2)


def euler_torque_from_body_torque(phi: float, theta: float, tau_body: Vector3) -> Vector3:
    """``tau_eta = W_eta^T tau_body`` (generalised torque of a body torque)."""
    sf, cf = math.sin(phi), math.cos(phi)
    st, ct = math.sin(theta), math.cos(theta)
    x, y, z = tau_body
    return (x, cf * y - sf * z, -st * x + sf * ct * y + cf * ct * z)


# --------------------------------------------------------------------------------------------
# Euler-Lagrange rotational model, eqs. (4)-(6), diagonal inertia J = diag(Ixx, Iyy, Izz)
# --------------------------------------------------------------------------------------------
def inertia_matrix(inertia: Vector3, phi: float, theta: float) -> Matrix3:
    """``M(eta) = W_eta^T J W_eta`` of Section II (symmetric positive definite off gimbal lock)."""
    Ixx, Iyy, Izz = inertia
    sf, cf = math.sin(phi), math.cos(phi)
    st, ct = math.sin(theta), math.cos(theta)
    m13 = -Ixx * st
    m22 = Iyy * cf * cf + Izz * sf * sf
    m23 = (Iyy - Izz) * sf * cf * ct
    m33 = Ixx * st * st + Iyy * sf * sf * ct * ct + Izz * cf * cf * ct * ct
    return ((Ixx, 0.0, m13), (0.0, m22, m23), (m13, m23, m33))


def inertia_matrix_partials(inertia: Vector3, phi: float, theta: float) -> tuple[Matrix3, Matrix3]:
    """``(dM/dphi, dM/dtheta)``; ``dM/dpsi`` is zero since M does not depend on psi."""
    Ixx, Iyy, Izz = inertia
    sf, cf = math.sin(phi), math.cos(phi)
    st, ct = math.sin(theta), math.cos(theta)
    d = Iyy - Izz
    # d/dphi
    p22 = -2.0 * d * sf * cf
    p23 = d * (cf * cf - sf * sf) * ct
    p33 = 2.0 * d * sf * cf * ct * ct
    dphi = ((0.0, 0.0, 0.0), (0.0, p22, p23), (0.0, p23, p33))
    # d/dtheta
    t13 = -Ixx * ct
    t23 = -d * sf * cf * st
    t33 = 2.0 * st * ct * (Ixx - Iyy * sf * sf - Izz * cf * cf)
    dtheta = ((0.0, 0.0, t13), (0.0, 0.0, t23), (t13, t23, t33))
    return dphi, dtheta


def coriolis_matrix(inertia: Vector3, eta: Vector3, eta_dot: Vector3) -> Matrix3:
    """``C(eta, eta_dot)`` built from the Christoffel symbols of the first kind, eqs. (5)-(6).

    ``c_kj = sum_i 1/2 (dM_kj/deta_i + dM_ki/deta_j - dM_ij/deta_k) eta_dot_i``.
    """
    partials = (*inertia_matrix_partials(inertia, eta[0], eta[1]), ((0.0,) * 3,) * 3)
    return tuple(
        tuple(
            0.5
            * sum((partials[i][k][j] + partials[j][k][i] - partials[k][i][j]) * eta_dot[i] for i in range(3))
            for j in range(3)
        )
        for k in range(3)
    )  # type: ignore[return-value]


def coriolis_times(inertia: Vector3, eta: Vector3, eta_dot: Vector3, v: Vector3) -> Vector3:
    """``C(eta, eta_dot) v`` (the per-step form of eqs. 5-6)."""
    return matrix_times(coriolis_matrix_fast(inertia, eta, eta_dot), v)


def coriolis_matrix_fast(inertia: Vector3, eta: Vector3, eta_dot: Vector3) -> Matrix3:
    """``C(eta, eta_dot)`` of eq. (6), written out entry by entry for the per-step path.

    Only dM/dphi (entries p22, p23, p33) and dM/dtheta (t13, t23, t33) are non-zero (see
    :func:`inertia_matrix_partials`); with ``Mdot = Pf a0 + Pt a1``, ``fa = Pf a``, ``ta = Pt a``
    (a = eta_dot), eq. (6) reads ``c_kj = 1/2 [Mdot_kj + fa_k [j=0] + ta_k [j=1] - fa_j [k=0] -
    ta_j [k=1]]``, expanded below. :func:`coriolis_matrix` is the literal sum over Christoffel
    symbols it is tested against.
    """
    Ixx, Iyy, Izz = inertia
    phi, theta = eta[0], eta[1]
    sf, cf = math.sin(phi), math.cos(phi)
    st, ct = math.sin(theta), math.cos(theta)
    d = Iyy - Izz
    p22 = -2.0 * d * sf * cf
    p23 = d * (cf * cf - sf * sf) * ct
    p33 = 2.0 * d * sf * cf * ct * ct
    t13 = -Ixx * ct
    t23 = -d * sf * cf * st
    t33 = 2.0 * st * ct * (Ixx - Iyy * sf * sf - Izz * cf * cf)
    a0, a1, a2 = eta_dot
    fa1, fa2 = p22 * a1 + p23 * a2, p23 * a1 + p33 * a2
    ta0, ta2 = t13 * a2, t13 * a0 + t23 * a1 + t33 * a2
    m12 = p23 * a0 + t23 * a1  # Mdot_12 = Mdot_21
    return (
        (0.0, 0.5 * (ta0 - fa1), 0.5 * (t13 * a1 - fa2)),
        (0.5 * (fa1 - ta0), 0.5 * p22 * a0, 0.5 * (m12 - ta2)),
        (0.5 * (t13 * a1 + fa2), 0.5 * (m12 + ta2), 0.5 * (p33 * a0 + t33 * a1)),
    )


def matrix_times(A: Matrix3, v: Vector3) -> Vector3:
    """``A v`` for a 3x3 tuple matrix."""
    v0, v1, v2 = v
    return (
        A[0][0] * v0 + A[0][1] * v1 + A[0][2] * v2,
        A[1][0] * v0 + A[1][1] * v1 + A[1][2] * v2,
        A[2][0] * v0 + A[2][1] * v1 + A[2][2] * v2,
    )


def solve3(A: Matrix3, b: Vector3) -> Vector3:
    """Solve ``A x = b`` for a 3x3 matrix by Cramer's rule (A well conditioned here)."""
    (a, bb, c), (d, e, f), (g, h, i) = A
    co00 = e * i - f * h
    co01 = f * g - d * i
    co02 = d * h - e * g
    det = a * co00 + bb * co01 + c * co02
    x, y, z = b
    return (
        (x * co00 + y * (c * h - bb * i) + z * (bb * f - c * e)) / det,
        (x * co01 + y * (a * i - c * g) + z * (c * d - a * f)) / det,
        (x * co02 + y * (bb * g - a * h) + z * (a * e - bb * d)) / det,
    )
