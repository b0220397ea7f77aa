"""The control cascade compiled with numba (``cache=True``): what :class:`~.cascade.Cascade` runs
per control step in the autopilot when numba is installed (the ``campaign`` extra), and what the
Monte Carlo batch engine (:mod:`sitl.campaign.kernels`) flies.

Why: the cascade was the largest single cost of a lockstep frame in Python (~35 µs of ~150 µs on
the paper's helix, measured with ``benchmarks/inprocess.py``'s run and timers around each call);
compiled, a step with its arguments in and out costs a few µs. These functions are a
*transcription* of the scalar laws (``translational.py``, ``laws/``, ``command_filter.py``,
``allocation.py``) with every expression in the same order of floating-point operations, so the two
agree bit for bit (``tests/autopilot/test_compiled_cascade.py`` step by step, with retunes and
resets; the campaign's agreement tests over whole flights). The Python laws stay the
specification, the fallback (no numba, ``QUADSITL_PURE_PYTHON=1``) and the only path for a law
added through the registry (README "Adding a control law") or for the rotor actuation.

``min(max(x, lo), hi)`` is spelled with :func:`_max` / :func:`_min`, which have Python's exact
semantics (``max(a, b)`` is ``b if b > a else a``), NaN included (the same two functions as the
plant's kernels: the autopilot and the simulator do not import each other). ``error_model="numpy"``:
see :mod:`sitl.campaign.kernels`.

Layout constants (where each number sits in the controller array ``C``) live here, next to the
functions: numba's cache is keyed on this file, so a changed index invalidates these kernels
(:mod:`sitl.campaign.kernels` clears its own cache when this file changes).
"""

from __future__ import annotations

import math
import os

import numpy as np
from numba import njit


@njit(cache=True, error_model="numpy")
def _max(a: float, b: float) -> float:
    """Python's ``max(a, b)``."""
    return b if b > a else a


@njit(cache=True, error_model="numpy")
def _min(a: float, b: float) -> float:
    """Python's ``min(a, b)``."""
    return b if b < a else a


# -- controller (read off an autopilot.control.cascade.Cascade instance) ---------------------------
C_TLAW = 0  # 0 integral_second_step, 1 integral_first_step, 2 backstepping
C_RLAW = 1  # 0 nlhinf, 1 integral_backstepping
C_MASS = 2  # nominal mass
C_GRAVITY = 3
C_THRUST_MAX = 4
C_THRUST_FLOOR = 5
C_SIN_TILT = 6
C_C1 = 7  # 3
C_C2 = 10  # 3
C_KI = 13  # 3
C_ONE_C1C2 = 16  # 3: 1 + c1 c2
C_C1_C2 = 19  # 3: c1 + c2
C_KD = 22  # NLHinf k_d
C_KP = 23  # NLHinf k_p
C_RINV = 24  # NLHinf 1 / omega_u^2
C_AC1 = 25  # 3: IntBS attitude c1
C_AC2 = 28  # 3
C_ALAM = 31  # 3
C_INERTIA = 34  # 3: nominal Ixx, Iyy, Izz
C_WN2 = 37  # command filter
C_2ZW = 38
C_PHI = 39  # 6: a00, a01, a02, a10, a11, a12
C_AB = 45  # allocator b, d, arm
C_AD = 46
C_AARM = 47
C_SQMIN = 48
C_SQMAX = 49
C_SPEED_MAX = 50
C_ATHRUST_MAX = 51
C_ATORQUE_MAX = 52  # 3
C_ROTOR_MODE = 55
C_DT = 56
C_TBOUND = 57  # 3: anti-windup bound of the translational integrals (law.integral_bound)
C_RBOUND = 60  # 3: anti-windup bound of the attitude integrals
C_SIZE = 63

TLAW_SECOND_STEP, TLAW_FIRST_STEP, TLAW_BACKSTEPPING = 0, 1, 2
RLAW_NLHINF, RLAW_INTBS = 0, 1

_PI = math.pi
_TWO_PI = 2.0 * math.pi


@njit(cache=True, error_model="numpy")
def _clip(x: float, lo: float, hi: float) -> float:
    return _min(_max(x, lo), hi)


@njit(cache=True, error_model="numpy")
def wrap_pi(angle: float) -> float:
    """:func:`quadcommon.frames.wrap_pi`, ``(angle + pi) % 2 pi - pi``, bit for bit.

    For ``0 <= angle + pi < 2 pi`` Python's float ``%`` returns its left operand unchanged, so
    the (costly) ``fmod`` is skipped there; elsewhere Python's ``%`` (sign of the divisor).
    """
    shifted = angle + _PI
    if 0.0 <= shifted < _TWO_PI:
        return shifted - _PI
    return shifted % _TWO_PI - _PI

# -------------------------------------------------------------------------------------------------
# Rigid-body helpers (quadcommon.rigid_body)
# -------------------------------------------------------------------------------------------------
@njit(cache=True, error_model="numpy")
def euler_rates_from_body_rates(
    phi: float, theta: float, p: float, q: float, r: float
) -> tuple[float, float, float]:
    """``eta_dot = W_eta^-1 omega`` (eq. 3)."""
    sf, cf = math.sin(phi), math.cos(phi)
    ct, tt = math.cos(theta), math.tan(theta)
    return (p + sf * tt * q + cf * tt * r, cf * q - sf * r, (sf * q + cf * r) / ct)


@njit(cache=True, error_model="numpy")
def inertia_matrix(Ixx: float, Iyy: float, Izz: float, phi: float, theta: float) -> tuple[float, ...]:
    """``M(eta) = W^T J W`` of Section II: (m11, m13, m22, m23, m33); m12 = 0."""
    sf, cf = math.sin(phi), math.cos(phi)
    st, ct = math.sin(theta), math.cos(theta)
    m13 = -Ixx * st
    m22 = Iyy * cf * cf + Izz * sf * sf
    m23 = (Iyy - Izz) * sf * cf * ct
    m33 = Ixx * st * st + Iyy * sf * sf * ct * ct + Izz * cf * cf * ct * ct
    return (Ixx, m13, m22, m23, m33)


@njit(cache=True, error_model="numpy")
def coriolis_matrix(
    Ixx: float, Iyy: float, Izz: float, phi: float, theta: float, a0: float, a1: float, a2: float
) -> tuple[float, ...]:
    """``C(eta, eta_dot)`` of eqs. (5)-(6) as ``coriolis_matrix`` computes it (9 entries)."""
    sf, cf = math.sin(phi), math.cos(phi)
    st, ct = math.sin(theta), math.cos(theta)
    d = Iyy - Izz
    p22 = -2.0 * d * sf * cf
    p23 = d * (cf * cf - sf * sf) * ct
    p33 = 2.0 * d * sf * cf * ct * ct
    t13 = -Ixx * ct
    t23 = -d * sf * cf * st
    t33 = 2.0 * st * ct * (Ixx - Iyy * sf * sf - Izz * cf * cf)
    # The same expressions, in the same order, as quadcommon.rigid_body.coriolis_matrix.
    fa1, fa2 = p22 * a1 + p23 * a2, p23 * a1 + p33 * a2
    ta0, ta2 = t13 * a2, t13 * a0 + t23 * a1 + t33 * a2
    m12 = p23 * a0 + t23 * a1
    c00, c01, c02 = 0.0, 0.5 * (ta0 - fa1), 0.5 * (t13 * a1 - fa2)
    c10, c11, c12 = 0.5 * (fa1 - ta0), 0.5 * p22 * a0, 0.5 * (m12 - ta2)
    c20, c21, c22 = 0.5 * (t13 * a1 + fa2), 0.5 * (m12 + ta2), 0.5 * (p33 * a0 + t33 * a1)
    return (c00, c01, c02, c10, c11, c12, c20, c21, c22)


@njit(cache=True, error_model="numpy")
def _inertia_times(m11: float, m13: float, m22: float, m23: float, m33: float,
                   x0: float, x1: float, x2: float) -> tuple[float, float, float]:  # fmt: skip
    """``M(eta) x`` with :func:`inertia_matrix`'s entries (m12 = 0, written as the Python laws do)."""
    return (m11 * x0 + 0.0 * x1 + m13 * x2, 0.0 * x0 + m22 * x1 + m23 * x2, m13 * x0 + m23 * x1 + m33 * x2)


@njit(cache=True, error_model="numpy")
def _times3(c00: float, c01: float, c02: float, c10: float, c11: float, c12: float, c20: float, c21: float,
            c22: float, x0: float, x1: float, x2: float) -> tuple[float, float, float]:  # fmt: skip
    """A 3x3 matrix (row-major entries) times ``x``."""
    return (c00 * x0 + c01 * x1 + c02 * x2, c10 * x0 + c11 * x1 + c12 * x2, c20 * x0 + c21 * x1 + c22 * x2)


@njit(cache=True, error_model="numpy")
def body_torque_from_euler_torque(
    phi: float, theta: float, a: float, b: float, c: float
) -> tuple[float, float, float]:
    """``tau_body = W_eta^-T tau_eta`` (eq. 4)."""
    sf, cf = math.sin(phi), math.cos(phi)
    st, ct = math.sin(theta), math.cos(theta)
    x0 = a
    rhs = (c + st * x0) / ct
    x1 = cf * b + sf * rhs
    x2 = -sf * b + cf * rhs
    return (x0, x1, x2)


@njit(cache=True, error_model="numpy")
def euler_torque_from_body_torque(
    phi: float, theta: float, x: float, y: float, z: float
) -> tuple[float, float, float]:
    """``tau_eta = W_eta^T tau_body``."""
    sf, cf = math.sin(phi), math.cos(phi)
    st, ct = math.sin(theta), math.cos(theta)
    return (x, cf * y - sf * z, -st * x + sf * ct * y + cf * ct * z)


@njit(cache=True, error_model="numpy")
def translational(
    C: np.ndarray,
    integ: np.ndarray,
    pos: tuple,
    vel: tuple,
    euler: tuple,
    rp: tuple,
    rv: tuple,
    ra: tuple,
    dt: float,
) -> tuple:
    """Outer loop (eqs. 24-29 and the IntBS / BS variants): U1, phi_r, theta_r, flags.

    Returns ``(thrust, roll_ref, pitch_ref, thrust_saturated, tilt_limited, a_x, a_y, a_z)``;
    advances ``integ``.
    """
    law = int(C[C_TLAW])
    a_0 = a_1 = a_2 = 0.0
    for i in range(3):
        c1, k = C[C_C1 + i], C[C_KI + i]
        one_plus_c1c2, c1_plus_c2 = C[C_ONE_C1C2 + i], C[C_C1_C2 + i]
        e1 = pos[i] - rp[i]
        e1_dot = vel[i] - rv[i]
        if law == TLAW_SECOND_STEP:
            acc = ra[i] - k * integ[i] - one_plus_c1c2 * e1 - c1_plus_c2 * e1_dot
            integ[i] += (e1_dot + c1 * e1) * dt
        elif law == TLAW_BACKSTEPPING:
            acc = ra[i] - one_plus_c1c2 * e1 - c1_plus_c2 * e1_dot
        else:
            chi = integ[i]
            e2 = e1_dot + c1 * e1 + k * chi
            acc = ra[i] + (c1 * c1 - 1.0 - k) * e1 - c1_plus_c2 * e2 + c1 * k * chi
            integ[i] += e1 * dt
        if i == 0:
            a_0 = acc
        elif i == 1:
            a_1 = acc
        else:
            a_2 = acc
    if law != TLAW_BACKSTEPPING:  # anti-windup, as BacksteppingLaw._clamp_integral
        for i in range(3):
            bound = C[C_TBOUND + i]
            if integ[i] > bound:
                integ[i] = bound
            elif integ[i] < -bound:
                integ[i] = -bound
    phi, theta, psi = euler[0], euler[1], euler[2]
    m = C[C_MASS]
    thrust_max = C[C_THRUST_MAX]
    tilt = math.cos(phi) * math.cos(theta)
    thrust = m * (C[C_GRAVITY] + a_2) / _max(tilt, 0.1)
    thrust_sat = thrust < 0.0 or thrust > thrust_max
    thrust = _min(_max(thrust, 0.0), thrust_max)
    divisor = _max(thrust, C[C_THRUST_FLOOR])
    u_x = m * a_0 / divisor
    u_y = m * a_1 / divisor
    sp, cp = math.sin(psi), math.cos(psi)
    limit = C[C_SIN_TILT]
    arg = sp * u_x - cp * u_y
    tilt_lim = arg < -limit or arg > limit
    roll_ref = math.asin(_min(_max(arg, -limit), limit))
    arg = (cp * u_x + sp * u_y) / math.cos(roll_ref)
    tilt_lim = tilt_lim or arg < -limit or arg > limit
    pitch_ref = math.asin(_min(_max(arg, -limit), limit))
    return thrust, roll_ref, pitch_ref, thrust_sat, tilt_lim, a_0, a_1, a_2


@njit(cache=True, error_model="numpy")
def _clamped(value: float, bound: float) -> float:
    return bound if value > bound else (-bound if value < -bound else value)


@njit(cache=True, error_model="numpy")
def _integrate_clamped(
    integ: np.ndarray, e0: float, e1: float, e2: float, dt: float, b0: float, b1: float, b2: float
) -> None:
    """The attitude laws' integral step with their anti-windup bound (value, then clamp)."""
    integ[0] = _clamped(integ[0] + e0 * dt, b0)
    integ[1] = _clamped(integ[1] + e1 * dt, b1)
    integ[2] = _clamped(integ[2] + e2 * dt, b2)


@njit(cache=True, error_model="numpy")
def nlhinf(
    C: np.ndarray,
    integ: np.ndarray,
    euler: tuple,
    rates: tuple,
    ref: tuple,
    ref_rate: tuple,
    ref_acc: tuple,
    dt: float,
) -> tuple[float, float, float]:
    """Nonlinear H-infinity attitude law, eqs. (43)-(44) as ``NonlinearHinfAttitude.update``."""
    k_d, k_p = C[C_KD], C[C_KP]
    Ixx, Iyy, Izz = C[C_INERTIA], C[C_INERTIA + 1], C[C_INERTIA + 2]
    e0 = euler[0] - ref[0]
    e1 = euler[1] - ref[1]
    e2 = wrap_pi(euler[2] - ref[2])
    ed0 = rates[0] - ref_rate[0]
    ed1 = rates[1] - ref_rate[1]
    ed2 = rates[2] - ref_rate[2]
    s0 = ed0 + k_d * e0 + k_p * integ[0]
    s1 = ed1 + k_d * e1 + k_p * integ[1]
    s2 = ed2 + k_d * e2 + k_p * integ[2]
    M = inertia_matrix(Ixx, Iyy, Izz, euler[0], euler[1])
    v0 = ref_acc[0] - k_d * ed0 - k_p * e0
    v1 = ref_acc[1] - k_d * ed1 - k_p * e1
    v2 = ref_acc[2] - k_d * ed2 - k_p * e2
    Mv0, Mv1, Mv2 = _inertia_times(*M, v0, v1, v2)
    Cm = coriolis_matrix(Ixx, Iyy, Izz, euler[0], euler[1], rates[0], rates[1], rates[2])
    Ce0, Ce1, Ce2 = _times3(*Cm, rates[0], rates[1], rates[2])
    Cs0, Cs1, Cs2 = _times3(*Cm, s0, s1, s2)
    r_inv = C[C_RINV]
    _integrate_clamped(integ, e0, e1, e2, dt, C[C_RBOUND], C[C_RBOUND + 1], C[C_RBOUND + 2])
    return (
        Mv0 + Ce0 - Cs0 - r_inv * s0,
        Mv1 + Ce1 - Cs1 - r_inv * s1,
        Mv2 + Ce2 - Cs2 - r_inv * s2,
    )


@njit(cache=True, error_model="numpy")
def intbs_attitude(
    C: np.ndarray,
    integ: np.ndarray,
    euler: tuple,
    rates: tuple,
    ref: tuple,
    ref_rate: tuple,
    ref_acc: tuple,
    dt: float,
) -> tuple[float, float, float]:
    """IntBS attitude law (integral in the first step) on eq. (4), ``IntegralBacksteppingAttitude``."""
    e0 = euler[0] - ref[0]
    e1 = euler[1] - ref[1]
    e2 = wrap_pi(euler[2] - ref[2])
    acc0 = acc1 = acc2 = 0.0
    for i in range(3):
        c1, c2, lam = C[C_AC1 + i], C[C_AC2 + i], C[C_ALAM + i]
        chi = integ[i]
        e = e0 if i == 0 else (e1 if i == 1 else e2)
        e_dot = rates[i] - ref_rate[i]
        e2_ = e_dot + c1 * e + lam * chi
        acc = ref_acc[i] + (c1 * c1 - 1.0 - lam) * e - (c1 + c2) * e2_ + c1 * lam * chi
        if i == 0:
            acc0 = acc
        elif i == 1:
            acc1 = acc
        else:
            acc2 = acc
    _integrate_clamped(integ, e0, e1, e2, dt, C[C_RBOUND], C[C_RBOUND + 1], C[C_RBOUND + 2])
    Ixx, Iyy, Izz = C[C_INERTIA], C[C_INERTIA + 1], C[C_INERTIA + 2]
    Ma0, Ma1, Ma2 = _inertia_times(*inertia_matrix(Ixx, Iyy, Izz, euler[0], euler[1]), acc0, acc1, acc2)
    Cm = coriolis_matrix(Ixx, Iyy, Izz, euler[0], euler[1], rates[0], rates[1], rates[2])
    Ce0, Ce1, Ce2 = _times3(*Cm, rates[0], rates[1], rates[2])
    return (Ma0 + Ce0, Ma1 + Ce1, Ma2 + Ce2)


@njit(cache=True, error_model="numpy")
def _largest_scale(
    b0: float,
    b1: float,
    b2: float,
    b3: float,
    d0: float,
    d1: float,
    d2: float,
    d3: float,
    lo: float,
    hi: float,
) -> float:
    """``allocation._largest_scale``: largest k in [0, 1] keeping every base + k delta in [lo, hi]."""
    k = 1.0
    for i in range(4):
        b = b0 if i == 0 else (b1 if i == 1 else (b2 if i == 2 else b3))
        dl = d0 if i == 0 else (d1 if i == 1 else (d2 if i == 2 else d3))
        if dl > 0.0 and b + dl > hi:
            k = _min(k, _max(hi - b, 0.0) / dl)
        elif dl < 0.0 and b + dl < lo:
            k = _min(k, _max(b - lo, 0.0) / -dl)
    return k


@njit(cache=True, error_model="numpy")
def allocate_rotors(
    C: np.ndarray, thrust_n: float, tx: float, ty: float, tz: float, out4: np.ndarray
) -> tuple:
    """``Allocator.to_rotors``: normalised commands into ``out4``; returns (U1, tau, saturated)."""
    b, d, arm = C[C_AB], C[C_AD], C[C_AARM]
    lo, hi = C[C_SQMIN], C[C_SQMAX]
    raw = thrust_n / (4.0 * b)
    base = _min(_max(raw, lo), hi)
    sat = raw < lo or raw > hi
    r0, r1, r2, r3 = -ty / (2.0 * arm * b), -tx / (2.0 * arm * b), ty / (2.0 * arm * b), tx / (2.0 * arm * b)
    y0, y1, y2, y3 = -tz / (4.0 * d), tz / (4.0 * d), -tz / (4.0 * d), tz / (4.0 * d)
    k_rp = _largest_scale(base, base, base, base, r0, r1, r2, r3, lo, hi)
    p0, p1, p2, p3 = base + k_rp * r0, base + k_rp * r1, base + k_rp * r2, base + k_rp * r3
    k_yaw = _largest_scale(p0, p1, p2, p3, y0, y1, y2, y3, lo, hi)
    s1 = _min(_max(p0 + k_yaw * y0, lo), hi)
    s2 = _min(_max(p1 + k_yaw * y1, lo), hi)
    s3 = _min(_max(p2 + k_yaw * y2, lo), hi)
    s4 = _min(_max(p3 + k_yaw * y3, lo), hi)
    sat = sat or k_rp < 1.0 or k_yaw < 1.0
    top = C[C_SPEED_MAX]
    out4[0], out4[1] = math.sqrt(s1) / top, math.sqrt(s2) / top
    out4[2], out4[3] = math.sqrt(s3) / top, math.sqrt(s4) / top
    thrust = b * (s1 + s2 + s3 + s4)
    return thrust, arm * b * (s4 - s2), arm * b * (s3 - s1), d * (-s1 + s2 - s3 + s4), sat



# -------------------------------------------------------------------------------------------------
# One step of Cascade.step (wrench actuation)
# -------------------------------------------------------------------------------------------------
F_Y, F_YD, F_READY, F_SIZE = 0, 2, 4, 5  # filter state: y (2: roll, pitch), y' (2), initialised


@njit(cache=True, error_model="numpy")
def command_filter(C: np.ndarray, filt: np.ndarray, roll_r: float, pitch_r: float) -> tuple:
    """``SecondOrderFilter.outputs`` then ``advance`` for (phi_r, theta_r): returns phi_d, theta_d,
    their rates and their accelerations; advances ``filt`` (layout ``F_*``)."""
    if filt[F_READY] == 0.0:  # SecondOrderFilter.outputs: start at the reference, at rest
        filt[F_Y], filt[F_Y + 1] = roll_r, pitch_r
        filt[F_YD], filt[F_YD + 1] = 0.0, 0.0
        filt[F_READY] = 1.0
    phi_d, theta_d = filt[F_Y], filt[F_Y + 1]
    phi_dd, theta_dd = filt[F_YD], filt[F_YD + 1]
    wn2, two_zeta_wn = C[C_WN2], C[C_2ZW]
    phi_ddd = wn2 * (roll_r - phi_d) - two_zeta_wn * phi_dd
    theta_ddd = wn2 * (pitch_r - theta_d) - two_zeta_wn * theta_dd
    a00, a01, a02 = C[C_PHI], C[C_PHI + 1], C[C_PHI + 2]
    a10, a11, a12 = C[C_PHI + 3], C[C_PHI + 4], C[C_PHI + 5]
    filt[F_Y] = a00 * phi_d + a01 * phi_dd + a02 * roll_r
    filt[F_YD] = a10 * phi_d + a11 * phi_dd + a12 * roll_r
    filt[F_Y + 1] = a00 * theta_d + a01 * theta_dd + a02 * pitch_r
    filt[F_YD + 1] = a10 * theta_d + a11 * theta_dd + a12 * pitch_r
    return phi_d, theta_d, phi_dd, theta_dd, phi_ddd, theta_ddd


@njit(cache=True, error_model="numpy")
def attitude_torque(
    C: np.ndarray, integ_r: np.ndarray, euler: tuple, rates: tuple, eta_d: tuple, eta_d_dot: tuple,
    eta_d_ddot: tuple, dt: float,
) -> tuple[float, float, float]:
    """The attitude law's tau_eta (NLHinf or IntBS, advancing ``integ_r``) as a body torque."""
    if int(C[C_RLAW]) == RLAW_NLHINF:
        te0, te1, te2 = nlhinf(C, integ_r, euler, rates, eta_d, eta_d_dot, eta_d_ddot, dt)
    else:
        te0, te1, te2 = intbs_attitude(C, integ_r, euler, rates, eta_d, eta_d_dot, eta_d_ddot, dt)
    return body_torque_from_euler_torque(euler[0], euler[1], te0, te1, te2)


@njit(cache=True, error_model="numpy")
def saturate_wrench(C: np.ndarray, thrust: float, tb0: float, tb1: float, tb2: float) -> tuple:
    """``Allocator.saturate_wrench`` + ``wrench_to_normalised``: (U1, tau_body, saturated, the four
    normalised controls)."""
    athrust_max = C[C_ATHRUST_MAX]
    atm0, atm1, atm2 = C[C_ATORQUE_MAX], C[C_ATORQUE_MAX + 1], C[C_ATORQUE_MAX + 2]
    thrust_a = _min(_max(thrust, 0.0), athrust_max)
    ta0 = _min(_max(tb0, -atm0), atm0)
    ta1 = _min(_max(tb1, -atm1), atm1)
    ta2 = _min(_max(tb2, -atm2), atm2)
    sat = tb0 < -atm0 or tb0 > atm0 or tb1 < -atm1 or tb1 > atm1 or tb2 < -atm2 or tb2 > atm2
    return thrust_a, ta0, ta1, ta2, sat, thrust_a / athrust_max, ta0 / atm0, ta1 / atm1, ta2 / atm2


@njit(cache=True, error_model="numpy")
def cascade_step(
    C: np.ndarray,
    integ_t: np.ndarray,
    integ_r: np.ndarray,
    filt: np.ndarray,
    pos: tuple,
    vel: tuple,
    euler: tuple,
    rates: tuple,
    rp: tuple,
    rv: tuple,
    ra: tuple,
    yaw: float,
    yaw_rate: float,
    yaw_acc: float,
) -> tuple:
    """``Cascade.step(state, ref)`` for the wrench actuation, integrating: advances ``integ_t``,
    ``integ_r`` and ``filt``; returns the 20 numbers of its CascadeOutput (U1, tau_eta, tau_body,
    4 controls, eta_d roll/pitch, their rates, phi_r, theta_r, the commanded accelerations)."""
    dt = C[C_DT]
    thrust, roll_r, pitch_r, _, _, a_0, a_1, a_2 = translational(C, integ_t, pos, vel, euler, rp, rv, ra, dt)
    phi_d, theta_d, phi_dd, theta_dd, phi_ddd, theta_ddd = command_filter(C, filt, roll_r, pitch_r)
    eta_d, eta_d_dot = (phi_d, theta_d, yaw), (phi_dd, theta_dd, yaw_rate)
    eta_d_ddot = (phi_ddd, theta_ddd, yaw_acc)
    tb0, tb1, tb2 = attitude_torque(C, integ_r, euler, rates, eta_d, eta_d_dot, eta_d_ddot, dt)
    thrust_a, ta0, ta1, ta2, _, c0, c1, c2, c3 = saturate_wrench(C, thrust, tb0, tb1, tb2)
    tq0, tq1, tq2 = euler_torque_from_body_torque(euler[0], euler[1], ta0, ta1, ta2)
    return (thrust_a, tq0, tq1, tq2, ta0, ta1, ta2, c0, c1, c2, c3,
            phi_d, theta_d, phi_dd, theta_dd, roll_r, pitch_r, a_0, a_1, a_2)  # fmt: skip


# -------------------------------------------------------------------------------------------------
# The controller array, read off a Cascade (the one place its layout is filled)
# -------------------------------------------------------------------------------------------------
_TLAWS = {"integral_second_step": TLAW_SECOND_STEP, "integral_first_step": TLAW_FIRST_STEP,
          "backstepping": TLAW_BACKSTEPPING}  # fmt: skip
_RLAWS = {"nlhinf": RLAW_NLHINF, "integral_backstepping": RLAW_INTBS}


def supports(cascade) -> bool:
    """True if these kernels fly ``cascade``'s laws (the built-in ones)."""
    return cascade.config.translational.law in _TLAWS and cascade.config.rotational.law in _RLAWS


def controller_array(cascade) -> np.ndarray:
    """The cascade's gains as the kernels read them (layout ``C_*``), off a real Cascade."""
    controller = cascade.config
    tr, rot, flt, alloc = cascade.translational, cascade.rotational, cascade.filter, cascade.allocator
    C = np.zeros(C_SIZE)
    C[C_TLAW] = _TLAWS[controller.translational.law]
    C[C_RLAW] = _RLAWS[controller.rotational.law]
    C[C_MASS], C[C_GRAVITY] = tr.mass, tr.gravity
    C[C_THRUST_MAX], C[C_THRUST_FLOOR], C[C_SIN_TILT] = tr.thrust_max, tr.thrust_floor, tr.sin_tilt_max
    g = tr.gains
    for i in range(3):
        c1, c2 = g.c1[i], g.c2[i]
        C[C_C1 + i], C[C_C2 + i], C[C_KI + i] = c1, c2, g.k_integral[i]
        # TranslationalController._set_gains: (1 + c1 c2, c1 + c2)
        C[C_ONE_C1C2 + i], C[C_C1_C2 + i] = 1.0 + c1 * c2, c1 + c2
    if C[C_RLAW] == RLAW_NLHINF:
        C[C_KD], C[C_KP], C[C_RINV] = rot.k_d, rot.k_p, rot.r_inv
    else:
        C[C_AC1 : C_AC1 + 3] = rot.c1
        C[C_AC2 : C_AC2 + 3] = rot.c2
        C[C_ALAM : C_ALAM + 3] = rot.lam
    C[C_INERTIA : C_INERTIA + 3] = rot.inertia
    C[C_WN2], C[C_2ZW] = flt.wn2, flt.two_zeta_wn
    # The exact ZOH discretisation SecondOrderFilter computed (scipy expm); one source for it.
    C[C_PHI : C_PHI + 6] = np.array(flt._phi, dtype=float).ravel()
    C[C_AB], C[C_AD], C[C_AARM] = alloc.b, alloc.d, alloc.arm
    C[C_SQMIN], C[C_SQMAX], C[C_SPEED_MAX] = alloc.sq_min, alloc.sq_max, alloc.speed_max
    C[C_ATHRUST_MAX] = alloc.thrust_max
    C[C_ATORQUE_MAX : C_ATORQUE_MAX + 3] = alloc.torque_max
    C[C_ROTOR_MODE] = 1.0 if cascade.rotor_mode else 0.0
    C[C_DT] = cascade.dt
    C[C_TBOUND : C_TBOUND + 3] = tr.law.integral_bound
    C[C_RBOUND : C_RBOUND + 3] = rot.integral_bound
    return C


def enabled() -> bool:
    """The compiled path is on unless ``QUADSITL_PURE_PYTHON=1`` (the Python reference)."""
    return os.environ.get("QUADSITL_PURE_PYTHON", "") != "1"
