"""The filter's covariance arithmetic compiled with numba (``cache=True``): what
:class:`~.eskf.ErrorStateEkf` runs per IMU sample and per fusion when numba is installed (the
``campaign`` extra) and ``QUADSITL_PURE_PYTHON`` is not ``1``; without it the filter does the same
products with numpy (the reference).

Why: with estimation in the loop the filter was the largest single cost of an autopilot frame
(~60 us of ~200 us on the paper's helix with ``mocap``, timers around each call of the in-process
run), and most of it was numpy's call overhead on 19x19 and 19xm operands: a prediction made ~8
numpy calls, a fusion ~20. Here each is one call, and the arithmetic uses the structure the
numpy products ignore:

* :func:`predict_step` is a whole prediction (the nominal state in the filter's order of
  operations, then the covariance): one call per IMU sample;
* :func:`predict_covariance` is eq. 269, ``P <- F P F^T + Q``, with ``F = I + E`` and ``E``'s 27
  non-zero entries (``F_pv``, ``F_v theta``, ``F_v ba``, ``F_theta bg``; see :mod:`.eskf`):
  ``A = P + E P`` row by row, then ``A + A E^T`` column by column, the upper triangle mirrored;
* :func:`joseph_update` is the batch update in Joseph form, factorised as the filter specifies it,
  ``P <- (I - K H) P (I - K H)^T + K R K^T``: ``(I - K H) P = P - K (H P)``, then
  ``X (I - K H)^T = X - (X H^T) K^T``, with ``K = P H^T S^-1`` through a Cholesky factor of ``S``
  (symmetric positive definite: ``R > 0``); the upper triangle is computed and mirrored, so the
  covariance stays exactly symmetric.

The same products in another order of floating-point operations: equal to the numpy path to
round-off (~1e-16 relative; ``tests/estimation/test_compiled_filter.py`` over whole flights). Block
offsets come in as arguments (the layout lives in :mod:`.eskf` alone).
"""

from __future__ import annotations

import functools
import math
import os

import numpy as np
from numba import njit


@njit(cache=True, error_model="numpy")
def _transition_rows(S, D, ip, iv, ith, ibg, iba, dt, mdx, mdy, mdz,
                     e00, e01, e02, e10, e11, e12, e20, e21, e22):  # fmt: skip
    """``D = F S`` for ``F = I + E`` (see :func:`predict_covariance`; ``e = -R dt``): only the
    position, velocity and attitude rows of ``S`` change."""
    rows, cols = S.shape
    for j in range(cols):
        for i in range(rows):
            D[i, j] = S[i, j]
        t0, t1, t2 = S[ith, j], S[ith + 1, j], S[ith + 2, j]
        a0, a1, a2 = S[iba, j], S[iba + 1, j], S[iba + 2, j]
        g0, g1, g2 = S[ibg, j], S[ibg + 1, j], S[ibg + 2, j]
        D[ip, j] = S[ip, j] + dt * S[iv, j]
        D[ip + 1, j] = S[ip + 1, j] + dt * S[iv + 1, j]
        D[ip + 2, j] = S[ip + 2, j] + dt * S[iv + 2, j]
        D[iv, j] = S[iv, j] + (mdz * t1 - mdy * t2) + (e00 * a0 + e01 * a1 + e02 * a2)
        D[iv + 1, j] = S[iv + 1, j] + (mdx * t2 - mdz * t0) + (e10 * a0 + e11 * a1 + e12 * a2)
        D[iv + 2, j] = S[iv + 2, j] + (mdy * t0 - mdx * t1) + (e20 * a0 + e21 * a1 + e22 * a2)
        D[ith, j] = t0 + (e00 * g0 + e01 * g1 + e02 * g2)
        D[ith + 1, j] = t1 + (e10 * g0 + e11 * g1 + e12 * g2)
        D[ith + 2, j] = t2 + (e20 * g0 + e21 * g1 + e22 * g2)


@njit(cache=True, error_model="numpy")
def predict_covariance(P, A, ip, iv, ith, ibg, iba, dt, mdx, mdy, mdz,
                       r00, r01, r02, r10, r11, r12, r20, r21, r22, q_diag):  # fmt: skip
    """``P <- F P F^T + diag(q_diag)`` in place (``A``: an N x N scratch array).

    ``F = I + E``: ``E[p_i, v_i] = dt``; ``E[v, theta] = -[m dt]_x`` with ``m dt = (mdx, mdy,
    mdz)`` the mean world specific force times dt; ``E[v, ba] = E[theta, bg] = -R dt``. Computed
    as ``A = F P``, then ``F A^T`` (= ``F P F^T`` for the symmetric P), its upper triangle
    mirrored."""
    n = P.shape[0]
    e = (-r00 * dt, -r01 * dt, -r02 * dt, -r10 * dt, -r11 * dt, -r12 * dt, -r20 * dt, -r21 * dt, -r22 * dt)
    _transition_rows(P, A, ip, iv, ith, ibg, iba, dt, mdx, mdy, mdz, *e)
    _transition_rows(A.T, P, ip, iv, ith, ibg, iba, dt, mdx, mdy, mdz, *e)
    for i in range(n):
        P[i, i] += q_diag[i]
        for j in range(i + 1, n):
            P[j, i] = P[i, j]


@njit(cache=True, error_model="numpy")
def predict_step(P, A, q_diag, ip, iv, ith, ibg, iba, dt, g,
                 gx, gy, gz, fx, fy, fz, pgx, pgy, pgz, bgx, bgy, bgz, bax, bay, baz,
                 qw, qx, qy, qz, a0x, a0y, a0z, px, py, pz, vx, vy, vz):  # fmt: skip
    """One prediction, :meth:`~.eskf.ErrorStateEkf.predict` transcribed in the same order of
    floating-point operations: the nominal state from the trapezoid of the previous and this IMU
    sample (``g*``, ``f*``: this sample; ``pg*``: the previous rate; ``a0*``: the previous world
    specific force), then :func:`predict_covariance`. Returns the new ``(q, p, v, a1)``, 13 floats
    (``a1``: this sample's world specific force)."""
    h = 0.5 * dt
    rx = (gx + pgx) * h - bgx * dt
    ry = (gy + pgy) * h - bgy * dt
    rz = (gz + pgz) * h - bgz * dt
    th2 = rx * rx + ry * ry + rz * rz
    if th2 > 1e-12:
        th = math.sqrt(th2)
        s = math.sin(0.5 * th) / th
        dw = math.cos(0.5 * th)
    else:
        s = 0.5 - th2 / 48.0
        dw = 1.0 - th2 / 8.0
    dx, dy, dz = rx * s, ry * s, rz * s
    w = qw * dw - qx * dx - qy * dy - qz * dz
    x = qw * dx + qx * dw + qy * dz - qz * dy
    y = qw * dy - qx * dz + qy * dw + qz * dx
    z = qw * dz + qx * dy - qy * dx + qz * dw
    n = 1.0 / math.sqrt(w * w + x * x + y * y + z * z)
    w, x, y, z = w * n, x * n, y * n, z * n
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    r00, r01, r02 = 1.0 - 2.0 * (yy + zz), 2.0 * (xy - wz), 2.0 * (xz + wy)
    r10, r11, r12 = 2.0 * (xy + wz), 1.0 - 2.0 * (xx + zz), 2.0 * (yz - wx)
    r20, r21, r22 = 2.0 * (xz - wy), 2.0 * (yz + wx), 1.0 - 2.0 * (xx + yy)
    ux, uy, uz = fx - bax, fy - bay, fz - baz
    a1x = r00 * ux + r01 * uy + r02 * uz
    a1y = r10 * ux + r11 * uy + r12 * uz
    a1z = r20 * ux + r21 * uy + r22 * uz
    dt2 = dt * dt
    npx = px + vx * dt + (a0x / 3.0 + a1x / 6.0) * dt2
    npy = py + vy * dt + (a0y / 3.0 + a1y / 6.0) * dt2
    npz = pz + vz * dt + (a0z / 3.0 + a1z / 6.0 - 0.5 * g) * dt2
    mx, my, mz = 0.5 * (a0x + a1x), 0.5 * (a0y + a1y), 0.5 * (a0z + a1z)
    nvx, nvy, nvz = vx + mx * dt, vy + my * dt, vz + (mz - g) * dt
    predict_covariance(P, A, ip, iv, ith, ibg, iba, dt, mx * dt, my * dt, mz * dt,
                       r00, r01, r02, r10, r11, r12, r20, r21, r22, q_diag)  # fmt: skip
    return (w, x, y, z, npx, npy, npz, nvx, nvy, nvz, a1x, a1y, a1z)


@njit(cache=True, error_model="numpy")
def prior_variances(P, H, out):
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


@njit(cache=True, error_model="numpy")
def joseph_update(P, H, r, y, dx):
    """One batch update of ``P`` (in place, Joseph form, see the module) for the rows ``H`` (m x N)
    with noise variances ``r`` and innovations ``y``; the error ``K y`` into ``dx`` (N)."""
    m, n = H.shape
    PHt = np.empty((n, m))
    for i in range(n):
        for k in range(m):
            s = 0.0
            for j in range(n):
                s += P[i, j] * H[k, j]
            PHt[i, k] = s
    # S = H P H^T + R and its Cholesky factor L (S = L L^T).
    S = np.empty((m, m))
    for a in range(m):
        for b in range(m):
            s = 0.0
            for j in range(n):
                s += H[a, j] * PHt[j, b]
            S[a, b] = s
        S[a, a] += r[a]
    L = np.zeros((m, m))
    for a in range(m):
        for b in range(a + 1):
            s = S[a, b]
            for c in range(b):
                s -= L[a, c] * L[b, c]
            if a == b:
                L[a, a] = np.sqrt(s)
            else:
                L[a, b] = s / L[b, b]
    # K = P H^T S^-1: row i of K solves S k = (P H^T)_i.
    K = np.empty((n, m))
    z = np.empty(m)
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
    HP = np.empty((m, n))
    for k in range(m):
        for j in range(n):
            s = 0.0
            for i in range(n):
                s += H[k, i] * P[i, j]
            HP[k, j] = s
    X = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            s = P[i, j]
            for k in range(m):
                s -= K[i, k] * HP[k, j]
            X[i, j] = s
    # P = X (I - K H)^T + K R K^T = X - (X H^T) K^T + K R K^T, upper triangle then mirrored.
    XHt = np.empty((n, m))
    for i in range(n):
        for k in range(m):
            s = 0.0
            for j in range(n):
                s += X[i, j] * H[k, j]
            XHt[i, k] = s
    for i in range(n):
        for j in range(i, n):
            s = X[i, j]
            for k in range(m):
                s += K[j, k] * (K[i, k] * r[k] - XHt[i, k])
            P[i, j] = s
            P[j, i] = s


def enabled() -> bool:
    """The compiled path is on unless ``QUADSITL_PURE_PYTHON=1`` (the numpy reference)."""
    return os.environ.get("QUADSITL_PURE_PYTHON", "") != "1"


@functools.cache
def warm_up() -> None:
    """Load (or compile) the kernels now, on scratch arrays, not at the first sample in flight
    (once per process)."""
    n, m = 19, 2
    P, A = np.eye(n), np.empty((n, n))
    H = np.zeros((m, n))
    H[0, 0] = H[1, 1] = 1.0
    predict_covariance(P, A, 0, 3, 6, 9, 12, 0.002, 0.0, 0.0, 0.0,
                       1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, np.zeros(n))  # fmt: skip
    predict_step(P, A, np.zeros(n), 0, 3, 6, 9, 12, 0.002, 9.81, *(0.0,) * 15,
                 1.0, 0.0, 0.0, 0.0, *(0.0,) * 9)  # fmt: skip
    prior_variances(P, H, np.empty(m))
    joseph_update(P, H, np.ones(m), np.zeros(m), np.empty(n))
