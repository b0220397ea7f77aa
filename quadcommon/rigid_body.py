"""Rotational kinematics and the Euler-Lagrange rotational model of Section II.

Frames are the paper's: world x-forward/y-left/z-up, body front-left-up, ZYX Euler angles
``eta = (phi, theta, psi)`` with ``R = Rz(psi) Ry(theta) Rx(phi)`` mapping body to world.

Everything here works on plain floats and tuples, and every function is a kernel
(:mod:`quadcommon.kernel`): Python calls it as it is (small-array numpy would cost ~10x more on
the per-step paths of the plant, the controllers and the estimator), and the compiled plant,
cascade, filter and campaign engine compile these same functions. Matrices are row-major tuples
of three row tuples; quaternions ``(w, x, y, z)``, scalar first, Hamilton product.
"""

from __future__ import annotations

import math

from .kernel import kernel

Vector3 = tuple[float, float, float]
Matrix3 = tuple[Vector3, Vector3, Vector3]


# --------------------------------------------------------------------------------------------
# Kinematics
# --------------------------------------------------------------------------------------------
@kernel
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


@kernel
def euler_from_rotation(R: Matrix3) -> Vector3:
    """ZYX Euler angles of a rotation matrix; theta is kept in [-pi/2, pi/2]."""
    sin_theta = -R[2][0]
    sin_theta = 1.0 if sin_theta > 1.0 else (-1.0 if sin_theta < -1.0 else sin_theta)
    return (math.atan2(R[2][1], R[2][2]), math.asin(sin_theta), math.atan2(R[1][0], R[0][0]))


@kernel
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


@kernel
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


@kernel
def euler_from_quaternion(w: float, x: float, y: float, z: float) -> Vector3:
    """ZYX Euler angles ``(phi, theta, psi)`` of a unit quaternion."""
    return euler_from_rotation(rotation_from_quaternion(w, x, y, z))


@kernel
def euler_rate_matrix(phi: float, theta: float) -> Matrix3:
    """``W_eta`` of eq. (3): body angular velocity ``omega = W_eta * eta_dot``."""
    sf, cf = math.sin(phi), math.cos(phi)
    st, ct = math.sin(theta), math.cos(theta)
    return ((1.0, 0.0, -st), (0.0, cf, sf * ct), (0.0, -sf, cf * ct))


@kernel
def body_rates_from_euler_rates(phi: float, theta: float, eta_dot: Vector3) -> Vector3:
    """``omega = W_eta eta_dot`` (eq. 3) without forming the matrix."""
    sf, cf = math.sin(phi), math.cos(phi)
    st, ct = math.sin(theta), math.cos(theta)
    dphi, dtheta, dpsi = eta_dot
    return (dphi - st * dpsi, cf * dtheta + sf * ct * dpsi, -sf * dtheta + cf * ct * dpsi)


@kernel
def euler_rates_from_body_rates(phi: float, theta: float, omega: Vector3) -> Vector3:
    """``eta_dot = W_eta^-1 omega``; singular at theta = +-pi/2 (gimbal lock)."""
    sf, cf = math.sin(phi), math.cos(phi)
    ct, tt = math.cos(theta), math.tan(theta)
    p, q, r = omega
    return (p + sf * tt * q + cf * tt * r, cf * q - sf * r, (sf * q + cf * r) / ct)


@kernel
def body_torque_from_euler_torque(phi: float, theta: float, tau_eta: Vector3) -> Vector3:
    """Body torque equivalent to generalised torque ``tau_eta`` on the Euler coordinates.

    The Lagrangian generalised force is ``tau_eta = W_eta^T tau_body`` (eq. 4), so
    ``tau_body = W_eta^-T tau_eta``.
    """
    return body_torque_from_euler_torque_sincos(
        math.sin(phi), math.cos(phi), math.sin(theta), math.cos(theta), tau_eta
    )


@kernel
def body_torque_from_euler_torque_sincos(
    sf: float, cf: float, st: float, ct: float, tau_eta: Vector3
) -> Vector3:
    """:func:`body_torque_from_euler_torque` given ``sin``/``cos`` of phi and theta (a plant reads
    them off its rotation matrix, without Euler angles)."""
    a, b, c = tau_eta
    # Solve W^T x = tau_eta, W^T = [[1,0,0],[0,cf,-sf],[-st, sf ct, cf ct]].
    x0 = a
    # rows 2, 3: cf x1 - sf x2 = b ;  sf ct x1 + cf ct x2 = c + st x0
    rhs = (c + st * x0) / ct
    x1 = cf * b + sf * rhs
    x2 = -sf * b + cf * rhs
    return (x0, x1, x2)


@kernel
def euler_torque_from_body_torque(phi: float, theta: float, tau_body: Vector3) -> Vector3:
    """``tau_eta = W_eta^T tau_body`` (generalised torque of a body torque)."""
    sf, cf = math.sin(phi), math.cos(phi)
    st, ct = math.sin(theta), math.cos(theta)
    x, y, z = tau_body
    return (x, cf * y - sf * z, -st * x + sf * ct * y + cf * ct * z)


@kernel
def body_acceleration_from_euler(phi: float, theta: float, eta_dot: Vector3, eta_ddot: Vector3) -> Vector3:
    """``omega' = W_eta eta'' + W_eta' eta'``: the body angular acceleration of a motion of the
    Euler angles (eq. 3 differentiated in time)."""
    sf, cf = math.sin(phi), math.cos(phi)
    st, ct = math.sin(theta), math.cos(theta)
    dphi, dtheta, dpsi = eta_dot
    a0, a1, a2 = eta_ddot
    return (
        a0 - st * a2 - ct * dtheta * dpsi,
        cf * a1 + sf * ct * a2 - sf * dphi * dtheta + (cf * ct * dphi - sf * st * dtheta) * dpsi,
        -sf * a1 + cf * ct * a2 - cf * dphi * dtheta - (sf * ct * dphi + cf * st * dtheta) * dpsi,
    )


@kernel
def cross(a: Vector3, b: Vector3) -> Vector3:
    """``a x b`` (also ``hat(a) b``)."""
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


@kernel
def transpose_times(R: Matrix3, v: Vector3) -> Vector3:
    """``R^T v`` (world to body for a body-to-world rotation ``R``)."""
    return (
        R[0][0] * v[0] + R[1][0] * v[1] + R[2][0] * v[2],
        R[0][1] * v[0] + R[1][1] * v[1] + R[2][1] * v[2],
        R[0][2] * v[0] + R[1][2] * v[1] + R[2][2] * v[2],
    )


@kernel
def roll_pitch_from_body_z(bx: float, by: float, bz: float, psi: float) -> tuple[float, float]:
    """ZYX roll and pitch ``(phi, theta)`` of the attitude whose body z axis is the unit vector
    ``b`` (world frame) and whose yaw is ``psi``: the third column of ``R(phi, theta, psi)`` is
    ``b``. That attitude's body x axis lies in the vertical plane of heading ``psi`` (the attitude
    PX4's ``bodyzToAttitude`` builds from a thrust direction and a yaw)."""
    sp, cp = math.sin(psi), math.cos(psi)
    # Rz(-psi) b = (sin(theta) cos(phi), -sin(phi), cos(theta) cos(phi))
    forward = cp * bx + sp * by
    left = cp * by - sp * bx
    sin_phi = -left
    sin_phi = 1.0 if sin_phi > 1.0 else (-1.0 if sin_phi < -1.0 else sin_phi)
    return math.asin(sin_phi), math.atan2(forward, bz)


@kernel
def limit_tilt(bx: float, by: float, bz: float, tilt_max: float) -> tuple[float, float, float, float]:
    """The direction of the vector ``b`` (the world's z axis if ``b`` is zero) turned towards z, in
    the vertical plane that holds it, until its angle from z is at most ``tilt_max`` (rad): the unit
    vector and ``limited``, 1.0 when it had to turn. A vector along -z turns towards +x."""
    n = math.sqrt(bx * bx + by * by + bz * bz)
    if n < 1e-9:
        return 0.0, 0.0, 1.0, 0.0
    bx, by, bz = bx / n, by / n, bz / n
    if bz >= math.cos(tilt_max):
        return bx, by, bz, 0.0
    horizontal = math.sqrt(bx * bx + by * by)
    if horizontal > 1e-12:
        dx, dy = bx / horizontal, by / horizontal
    else:
        dx, dy = 1.0, 0.0
    s = math.sin(tilt_max)
    return s * dx, s * dy, math.cos(tilt_max), 1.0


# --------------------------------------------------------------------------------------------
# Euler-Lagrange rotational model, eqs. (4)-(6), diagonal inertia J = diag(Ixx, Iyy, Izz)
# --------------------------------------------------------------------------------------------
@kernel
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


@kernel
def coriolis_times(inertia: Vector3, eta: Vector3, eta_dot: Vector3, v: Vector3) -> Vector3:
    """``C(eta, eta_dot) v`` (the per-step form of eqs. 5-6)."""
    return matrix_times(coriolis_matrix(inertia, eta, eta_dot), v)


@kernel
def coriolis_matrix(inertia: Vector3, eta: Vector3, eta_dot: Vector3) -> Matrix3:
    """``C(eta, eta_dot)`` of eqs. (5)-(6), from the Christoffel symbols of the first kind,
    ``c_kj = sum_i 1/2 (dM_kj/deta_i + dM_ki/deta_j - dM_ij/deta_k) eta_dot_i``, expanded.

    M depends on phi and theta only, and only dM/dphi (entries p22, p23, p33 below) and dM/dtheta
    (t13, t23, t33) are non-zero; with ``Mdot = Pf a0 + Pt a1``, ``fa = Pf a``, ``ta = Pt a``
    (a = eta_dot) the sum reads ``c_kj = 1/2 [Mdot_kj + fa_k [j=0] + ta_k [j=1] - fa_j [k=0] -
    ta_j [k=1]]``. Tested by its invariants: ``Mdot - 2 C`` skew-symmetric, ``C eta_dot`` the
    Lagrangian residual ``d/dt(dL/d eta_dot) - dL/d eta``.
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


@kernel
def matrix_times(A: Matrix3, v: Vector3) -> Vector3:
    """``A v`` for a 3x3 tuple matrix."""
    v0, v1, v2 = v
    return (
        A[0][0] * v0 + A[0][1] * v1 + A[0][2] * v2,
        A[1][0] * v0 + A[1][1] * v1 + A[1][2] * v2,
        A[2][0] * v0 + A[2][1] * v1 + A[2][2] * v2,
    )


@kernel
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


# --------------------------------------------------------------------------------------------
# Quaternion algebra (Hamilton product, (w, x, y, z))
# --------------------------------------------------------------------------------------------
Quaternion = tuple[float, float, float, float]


@kernel
def quaternion_multiply(a: Quaternion, b: Quaternion) -> Quaternion:
    """Hamilton product ``a (x) b``."""
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return (
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    )


@kernel
def quaternion_conjugate(q: Quaternion) -> Quaternion:
    """``q*`` of ``q = (w, x, y, z)``: the inverse rotation of a unit quaternion."""
    return (q[0], -q[1], -q[2], -q[3])


@kernel
def quaternion_exp(rx: float, ry: float, rz: float) -> Quaternion:
    """``Exp(r)``: the unit quaternion of the rotation vector ``r`` (rad), series below 1e-6 rad."""
    th2 = rx * rx + ry * ry + rz * rz
    if th2 > 1e-12:
        th = math.sqrt(th2)
        s = math.sin(0.5 * th) / th
        return (math.cos(0.5 * th), rx * s, ry * s, rz * s)
    s = 0.5 - th2 / 48.0
    return (1.0 - th2 / 8.0, rx * s, ry * s, rz * s)


@kernel
def quaternion_normalised(q: Quaternion) -> Quaternion:
    """``q / |q|``: ``q`` put back on the unit sphere."""
    n = 1.0 / math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return (q[0] * n, q[1] * n, q[2] * n, q[3] * n)
