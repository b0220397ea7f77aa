"""The filter's arithmetic, written once: the prediction (nominal state and covariance), the
gates' prior innovation variances and the batch update in Joseph form.

These are kernels (:mod:`quadcommon.kernel`): plain functions over floats, tuples (vectors
``(x, y, z)``, quaternions ``(w, x, y, z)``, 3x3 matrices as three row tuples) and numpy arrays.
:class:`~.eskf.ErrorStateEkf` calls their compiled entries, or the same functions in Python
where nothing compiles (``QUADSITL_PURE_PYTHON=1``); a batch engine can call them from its own
compiled loop (the covariance is any 2-D float array, one vehicle's slice of a stack say). The
equations are those of :mod:`.eskf`'s docstring (Solà, arXiv:1711.02508, §5-7); this module
states how they are computed.

* :func:`predict`: the nominal state by the trapezoid of the previous and this IMU sample, then
  :func:`predict_covariance`, ``P <- F P F^T + Q`` (eq. 269) with ``F = I + E``, whose non-zero
  blocks are ``E_pv = I dt``, ``E_v theta = -[a dt]_x`` (``a`` the step's mean world specific
  force), ``E_v ba = E_theta bg = -R dt``. F changes only the position, velocity and attitude
  rows, so ``F P`` is computed in place on those nine rows, then ``(F P) F^T`` the same way on
  the nine columns (the transpose's rows): 2 x 9 x 19 updates instead of two 19x19 products.
* :func:`prior_variances`: ``H_k P H_k^T`` per row of ``H`` (the gates test the prior).
* :func:`joseph_update`: ``K = P H^T S^-1``, ``S = H P H^T + R``, through a Cholesky factor of S
  (symmetric positive definite: ``R > 0``), and ``P <- (I - K H) P (I - K H)^T + K R K^T``
  factorised as ``X = P - K (H P)``, ``P <- X - (X H^T) K^T + K R K^T``.

Both covariance updates leave P exactly symmetric (the upper triangle mirrored).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from quadcommon.kernel import kernel, matrix_view
from quadcommon.layout import Field, fields_of, layout
from quadcommon.rigid_body import (
    Matrix3,
    Quaternion,
    Vector3,
    matrix_times,
    quaternion_exp,
    quaternion_multiply,
    quaternion_normalised,
    rotation_from_quaternion,
)

# The error state dx = [dp, dv, dtheta, db_g, db_a, db_m, db_h]: the covariance's rows and columns,
# each element named as the logs and the tests print it (STATE_NAMES).
ERROR_STATE = layout("ErrorState", (
    Field("p", unit="m", elements=("px", "py", "pz")),
    Field("v", unit="m/s", elements=("vx", "vy", "vz")),
    Field("theta", unit="rad", doc="attitude error, world frame", elements=("thx", "thy", "thz")),
    Field("gyro_bias", unit="rad/s", elements=("bgx", "bgy", "bgz")),
    Field("accel_bias", unit="m/s^2", elements=("bax", "bay", "baz")),
    Field("mag_bias", unit="gauss", elements=("bmx", "bmy", "bmz")),
    Field("baro_bias", unit="m", elements=("bh",)),
))  # fmt: skip
N = ERROR_STATE.size
# The covariance algebra reads the blocks by these short names (the filter literature's), taken
# from the layout: I + the block's state.
E = ERROR_STATE
IP, IV, ITH, IBG, IBA, IBM, IBH = E.p, E.v, E.theta, E.gyro_bias, E.accel_bias, E.mag_bias, E.baro_bias
STATE_NAMES = tuple(name for field in fields_of(ERROR_STATE) for name in field.elements)


class NominalPrediction(NamedTuple):
    """What :func:`predict` returns: the nominal state after the step, and the sample's world
    specific force ``R (f - b_a)`` (the next step's trapezoid starts from it)."""

    attitude: Quaternion  # (w, x, y, z), body to world
    position_m: Vector3
    velocity_m_s: Vector3
    world_force_m_s2: Vector3


class ImuStep(NamedTuple):
    """The two IMU samples a prediction integrates across (raw, body frame)."""

    rate_rad_s: Vector3  # this sample's gyro
    specific_force_m_s2: Vector3  # this sample's accelerometer
    previous_rate_rad_s: Vector3  # the previous sample's gyro
    previous_world_force_m_s2: Vector3  # the previous sample's R (f - b_a), world


class NominalState(NamedTuple):
    """The part of the nominal state a prediction reads."""

    attitude: Quaternion  # (w, x, y, z), body to world
    position_m: Vector3
    velocity_m_s: Vector3
    gyro_bias_rad_s: Vector3
    accel_bias_m_s2: Vector3


@kernel
def predict(
    P: np.ndarray, process_noise: np.ndarray, dt: float, gravity: float, imu: ImuStep, nominal: NominalState
) -> NominalPrediction:
    """One prediction over ``dt`` (s): the nominal attitude, position and velocity from the raw
    gyro and accelerometer samples of ``imu`` (this one and the previous), then ``P`` in place
    with the diagonal ``process_noise`` (the step's variances). Returns the new attitude, position
    and velocity and this sample's world specific force ``R (f - b_a)``."""
    rate, force = imu.rate_rad_s, imu.specific_force_m_s2
    previous_rate, previous_world_force = imu.previous_rate_rad_s, imu.previous_world_force_m_s2
    gyro_bias, accel_bias = nominal.gyro_bias_rad_s, nominal.accel_bias_m_s2
    q, p, v = nominal.attitude, nominal.position_m, nominal.velocity_m_s
    # Attitude: the mean bias-corrected rate over the step (trapezoid), body-frame increment.
    h = 0.5 * dt
    rx = (rate[0] + previous_rate[0]) * h - gyro_bias[0] * dt
    ry = (rate[1] + previous_rate[1]) * h - gyro_bias[1] * dt
    rz = (rate[2] + previous_rate[2]) * h - gyro_bias[2] * dt
    q1 = quaternion_normalised(quaternion_multiply(q, quaternion_exp(rx, ry, rz)))
    R = rotation_from_quaternion(q1[0], q1[1], q1[2], q1[3])
    a1 = matrix_times(R, (force[0] - accel_bias[0], force[1] - accel_bias[1], force[2] - accel_bias[2]))
    a0 = previous_world_force
    # Position and velocity: exact for a specific force linear in time over the step.
    dt2 = dt * dt
    p1 = (
        p[0] + v[0] * dt + (a0[0] / 3.0 + a1[0] / 6.0) * dt2,
        p[1] + v[1] * dt + (a0[1] / 3.0 + a1[1] / 6.0) * dt2,
        p[2] + v[2] * dt + (a0[2] / 3.0 + a1[2] / 6.0 - 0.5 * gravity) * dt2,
    )
    mx, my, mz = 0.5 * (a0[0] + a1[0]), 0.5 * (a0[1] + a1[1]), 0.5 * (a0[2] + a1[2])
    v1 = (v[0] + mx * dt, v[1] + my * dt, v[2] + (mz - gravity) * dt)
    predict_covariance(P, process_noise, dt, (mx * dt, my * dt, mz * dt), R)
    return NominalPrediction(q1, p1, v1, a1)


@kernel
def predict_covariance(
    P: np.ndarray, process_noise: np.ndarray, dt: float, mean_force_dt: Vector3, R: Matrix3
) -> None:
    """``P <- F P F^T + diag(process_noise)`` in place (P symmetric), F as in the module's
    docstring from ``dt`` (s), the step's mean world specific force times ``dt`` (m/s) and the
    body-to-world rotation ``R`` of the new attitude."""
    e = (
        (-R[0][0] * dt, -R[0][1] * dt, -R[0][2] * dt),
        (-R[1][0] * dt, -R[1][1] * dt, -R[1][2] * dt),
        (-R[2][0] * dt, -R[2][1] * dt, -R[2][2] * dt),
    )
    transition_rows(P, dt, mean_force_dt, e)  # F P
    transition_rows(P.T, dt, mean_force_dt, e)  # (F (F P)^T)^T = F P F^T
    n = P.shape[0]
    for i in range(n):
        P[i, i] += process_noise[i]
        for j in range(i + 1, n):  # the 9x9 block of the moving rows differs from its mirror by round-off
            P[j, i] = P[i, j]


@kernel
def transition_rows(M: np.ndarray, dt: float, mean_force_dt: Vector3, e: Matrix3) -> None:
    """``M <- F M`` in place, ``F = I + E`` (``e = -R dt``): only the position, velocity and
    attitude rows change, each from rows not yet changed in its column (p from v, v from theta
    and b_a, theta from b_g)."""
    mdx, mdy, mdz = mean_force_dt
    (e00, e01, e02), (e10, e11, e12), (e20, e21, e22) = e
    for j in range(M.shape[1]):
        t0, t1, t2 = M[ITH, j], M[ITH + 1, j], M[ITH + 2, j]
        a0, a1, a2 = M[IBA, j], M[IBA + 1, j], M[IBA + 2, j]
        g0, g1, g2 = M[IBG, j], M[IBG + 1, j], M[IBG + 2, j]
        M[IP, j] += dt * M[IV, j]
        M[IP + 1, j] += dt * M[IV + 1, j]
        M[IP + 2, j] += dt * M[IV + 2, j]
        M[IV, j] += (mdz * t1 - mdy * t2) + (e00 * a0 + e01 * a1 + e02 * a2)
        M[IV + 1, j] += (mdx * t2 - mdz * t0) + (e10 * a0 + e11 * a1 + e12 * a2)
        M[IV + 2, j] += (mdy * t0 - mdx * t1) + (e20 * a0 + e21 * a1 + e22 * a2)
        M[ITH, j] = t0 + (e00 * g0 + e01 * g1 + e02 * g2)
        M[ITH + 1, j] = t1 + (e10 * g0 + e11 * g1 + e12 * g2)
        M[ITH + 2, j] = t2 + (e20 * g0 + e21 * g1 + e22 * g2)


@kernel
def prior_variances(P: np.ndarray, H: np.ndarray, out: np.ndarray) -> None:
    """``out[k] = H_k P H_k^T`` for each row ``H_k`` of ``H`` (m x N): the gates' variances."""
    m, n = H.shape
    for k in range(m):
        s = 0.0
        for i in range(n):
            hi = H[k, i]
            if hi != 0.0:
                row = 0.0
                for j in range(n):
                    row += P[i, j] * H[k, j]
                s += hi * row
        out[k] = s


def update_work_size(m: int, n: int) -> int:
    """Floats :func:`joseph_update` works in for ``m`` rows of an ``n``-state filter: P H^T, K and
    X H^T (n x m each), S and its factor L (m x m), a solve's vector (m), H P (m x n), X (n x n)."""
    return 3 * n * m + 2 * m * m + m + m * n + n * n


@kernel
def joseph_update(
    P: np.ndarray, H: np.ndarray, r: np.ndarray, y: np.ndarray, dx: np.ndarray, work: np.ndarray
) -> None:
    """One batch update of ``P`` (in place, Joseph form, see the module) for the rows ``H`` (m x N)
    with noise variances ``r`` and innovations ``y``; the error ``K y`` into ``dx`` (N). ``work``:
    at least :func:`update_work_size` floats, where the products are formed (a filter updating at
    sensor rate allocates nothing)."""
    m, n = H.shape
    at = 0
    PHt = matrix_view(work, at, n, m)
    at += n * m
    S = matrix_view(work, at, m, m)
    at += m * m
    L = matrix_view(work, at, m, m)
    at += m * m
    K = matrix_view(work, at, n, m)
    at += n * m
    z = work[at : at + m]
    at += m
    HP = matrix_view(work, at, m, n)
    at += m * n
    X = matrix_view(work, at, n, n)
    at += n * n
    XHt = matrix_view(work, at, n, m)
    matrix_product(P, H.T, PHt)
    # S = H P H^T + R and its Cholesky factor L (S = L L^T).
    matrix_product(H, PHt, S)
    for a in range(m):
        S[a, a] += r[a]
    L[:] = 0.0
    for a in range(m):
        for b in range(a + 1):
            s = S[a, b]
            for c in range(b):
                s -= L[a, c] * L[b, c]
            if a == b:
                L[a, a] = math.sqrt(s)
            else:
                L[a, b] = s / L[b, b]
    # K = P H^T S^-1: row i of K solves S k = (P H^T)_i (forward, then back substitution).
    for i in range(n):
        for a in range(m):
            s = PHt[i, a]
            for c in range(a):
                s -= L[a, c] * z[c]
            z[a] = s / L[a, a]
        for a in range(m - 1, -1, -1):
            s = z[a]
            for c in range(a + 1, m):
                s -= L[c, a] * K[i, c]
            K[i, a] = s / L[a, a]
    for i in range(n):
        s = 0.0
        for k in range(m):
            s += K[i, k] * y[k]
        dx[i] = s
    # X = (I - K H) P = P - K (H P); H P = (P H^T)^T only for an exactly symmetric P, so computed.
    matrix_product(H, P, HP)
    for i in range(n):
        for j in range(n):
            s = P[i, j]
            for k in range(m):
                s -= K[i, k] * HP[k, j]
            X[i, j] = s
    # P = X (I - K H)^T + K R K^T = X - (X H^T) K^T + K R K^T, upper triangle then mirrored.
    matrix_product(X, H.T, XHt)
    for i in range(n):
        for j in range(i, n):
            s = X[i, j]
            for k in range(m):
                s += K[j, k] * (K[i, k] * r[k] - XHt[i, k])
            P[i, j] = s
            P[j, i] = s


@kernel
def matrix_product(A: np.ndarray, B: np.ndarray, out: np.ndarray) -> None:
    """``out = A B`` (``B`` may be a transposed view: ``A H^T`` without a copy)."""
    rows, inner = A.shape
    columns = B.shape[1]
    for i in range(rows):
        for k in range(columns):
            s = 0.0
            for j in range(inner):
                s += A[i, j] * B[j, k]
            out[i, k] = s
