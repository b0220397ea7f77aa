"""The batch engine's compiled kernels: one whole flight per call, in numba (``cache=True``).

Why numba and a loop per run (``benchmarks/engine_choice.py`` measures the alternatives): the
per-step work of this vehicle is a few hundred scalar operations on a 13-17 element state, too
little to fill a vector unit and too much branching (saturations, ground contact, law choice) to
vectorise well. A numpy batch axis pays ~1 µs of interpreter and temporary-array overhead per
operation whatever the batch size; compiled scalar code keeps the state in registers.

These functions are a *transcription* of the scalar reference, with every expression written in
the same order of floating-point operations so the two agree to rounding (the scalar code is
the specification; the tests in ``tests/campaign/`` prove the agreement run for run):

* plant: :class:`simulator.dynamics.plant.Plant` (``_make_derivative``, ``step``,
  ``_resolve_ground_contact``, ``kinematics``): the coupled rigid body about G with forces at O
  (CONTROL.md, "the more accurate plant"), RK4, quaternion renormalisation, ground contact; its
  compiled form lives with the plant (:mod:`simulator.dynamics.compiled`, which the simulator
  itself runs) and is imported here;
* disturbances: :class:`simulator.environment.gust_profile.DisturbanceSchedule.evaluate` (steps,
  ramps, 1-cos gusts, Dryden wind precomputed by the project's own generator);
* cascade: :class:`autopilot.control.cascade.Cascade.step`: translational laws (eqs. 24-29 and
  the IntBS / BS variants), the command filter, NLHinf (eqs. 43-44, M and C of eqs. 4-6) or the
  IntBS attitude law, ``W_eta^-T`` (eq. 3-4) and the wrench saturation or rotor allocation;
* the wire (switch ``S_WIRE``): ODOMETRY's float32 pose, velocity and rates, the autopilot's
  quaternion -> Euler and body rates -> Euler rates (``autopilot.mavlink.hil``), and the float32
  controls of HIL_ACTUATOR_CONTROLS;
* indices: :mod:`gcs_scripts.analysis.metrics` (final errors, ISE trapezoidal, IADU as total
  variation), accumulated while flying.

``min(max(x, lo), hi)`` is spelled with :func:`_max` / :func:`_min`, which have Python's exact
semantics (``max(a, b)`` is ``b if b > a else a``), NaN included. ``error_model="numpy"``: a
float division by zero gives inf/NaN instead of raising ZeroDivisionError as the scalar code
would, which spares a test on every division. The divisors are masses, time constants, clipped
thrusts, cosines kept >= 1e-6, and cos(theta) in W_eta^-1, zero only at theta = +-pi/2 exactly
(gimbal lock); a run there ends as "non-finite state" instead of an exception.

(~800 lines in one file on purpose: numba's cache is keyed on this file, and the whole closed
loop must be compiled together for the calls between kernels to inline.)
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from simulator.dynamics.compiled import (  # the plant, compiled (see the cache note below)
    P_GROUND,
    P_ROTOR_MODE,
    P_THRUST_MAX,
    P_TORQUE_MAX,
    P_WMAX,
    P_WMIN,
    U_FORCE,
    U_ROTOR,
    U_SIZE,
    U_TAU,
    U_THRUST,
    U_TORQUE,
    U_WIND,
    _max,
    _min,
    euler_from_rotation,
    ground_contact,
    rk4_step,
    rotation_from_quaternion,
    truth_of_O,
)  # fmt: skip


def _forget_kernels_compiled_against_another_plant() -> None:
    """numba keys a cached function on its own file only, but these kernels have the plant's
    functions and constants (:mod:`simulator.dynamics.compiled`) compiled into them: when that
    file changes, this file's cache entries are deleted before anything here compiles."""
    import hashlib
    import os
    from pathlib import Path

    import simulator.dynamics.compiled as plant_kernels

    stamp = hashlib.sha256(Path(plant_kernels.__file__).read_bytes()).hexdigest()
    here = Path(__file__).resolve()
    caches = [here.parent / "__pycache__"]
    if os.environ.get("NUMBA_CACHE_DIR"):
        caches.append(Path(os.environ["NUMBA_CACHE_DIR"]) / here.parent.relative_to(here.anchor))
    for cache in caches:
        marker = cache / f"{here.stem}.plant-sha256"
        try:
            if marker.exists() and marker.read_text() == stamp:
                continue
            for entry in [*cache.glob(f"{here.stem}.*.nbi"), *cache.glob(f"{here.stem}.*.nbc")]:
                entry.unlink(missing_ok=True)
            cache.mkdir(parents=True, exist_ok=True)
            marker.write_text(stamp)
        except OSError:
            pass  # a read-only install: numba does not cache there either


_forget_kernels_compiled_against_another_plant()

# =================================================================================================
# Where each number sits in the flat float64 arrays the kernels take (numba wants arrays). Kept in
# this file on purpose: numba's cache is keyed on this file only, so a changed index here also
# invalidates the compiled kernels (constants imported from another module would not).
# =================================================================================================
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

# -- simulation ----------------------------------------------------------------------------------
S_DT_CONTROL = 0
S_DT_PHYSICS = 1
S_SUBSTEPS = 2
S_STEPS = 3  # control steps; samples k = 0..steps
S_WIRE = 4  # 1.0: float32 state and controls as on the MAVLink wire
S_USEC_PER_FRAME = 5  # informational: the reference table is sampled on this clock
S_MAX_POS_ERR = 6
S_MAX_TILT = 7
S_AIRBORNE = 8  # height of O above which the vehicle counts as airborne
S_DRYDEN_ON = 9
S_DRYDEN_T0 = 10  # start_time + dryden.start_s (s)
S_DRYDEN_FROM = 11  # profile time window of the turbulence
S_DRYDEN_UNTIL = 12
S_DRYDEN_STEP = 13
S_SIZE = 14

# -- metrics (one row per run, see engine.METRIC_NAMES) -------------------------------------------
M_FINAL = 0  # 3: final position error x, y, z
M_ISE = 3  # 6: x, y, z, phi, theta, psi
M_IADU = 9  # 4: U1, tau_phi, tau_theta, tau_psi
M_MAX_POS_ERR = 13
M_MAX_TILT = 14
M_T_SAT = 15  # time with an actuator limit active (s)
M_T_TILT = 16  # time with the roll/pitch reference at the tilt limit (s)
M_FAIL = 17  # failure code (FAIL_*)
M_T_FAIL = 18  # time of the failure (s), NaN when none
M_T_END = 19  # last sample's time (s)
M_SIZE = 20

FAIL_NONE, FAIL_NONFINITE, FAIL_POSITION, FAIL_TILT, FAIL_GROUND = 0, 1, 2, 3, 4

# -- recorded time series (run_scenario's columns, one row per control step) ----------------------
RECORD_COLUMNS = (
    "t", "x", "y", "z", "xd", "yd", "zd", "phi", "theta", "psi", "phid", "thetad", "psid",
    "U1", "tau_phi", "tau_theta", "tau_psi", "Ax", "Ay", "Az", "Ap", "Aq", "Ar",
)  # fmt: skip
R_SIZE = len(RECORD_COLUMNS)

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


@njit(cache=True, error_model="numpy")
def _f32(x: float) -> float:
    """Round to float32 and back, as a MAVLink float field does."""
    return np.float64(np.float32(x))


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
    """``C(eta, eta_dot)`` of eqs. (5)-(6) as ``coriolis_matrix_fast`` computes it (9 entries)."""
    sf, cf = math.sin(phi), math.cos(phi)
    st, ct = math.sin(theta), math.cos(theta)
    d = Iyy - Izz
    p22 = -2.0 * d * sf * cf
    p23 = d * (cf * cf - sf * sf) * ct
    p33 = 2.0 * d * sf * cf * ct * ct
    t13 = -Ixx * ct
    t23 = -d * sf * cf * st
    t33 = 2.0 * st * ct * (Ixx - Iyy * sf * sf - Izz * cf * cf)
    # The same expressions, in the same order, as quadcommon.rigid_body.coriolis_matrix_fast.
    fa1, fa2 = p22 * a1 + p23 * a2, p23 * a1 + p33 * a2
    ta0, ta2 = t13 * a2, t13 * a0 + t23 * a1 + t33 * a2
    m12 = p23 * a0 + t23 * a1
    c00, c01, c02 = 0.0, 0.5 * (ta0 - fa1), 0.5 * (t13 * a1 - fa2)
    c10, c11, c12 = 0.5 * (fa1 - ta0), 0.5 * p22 * a0, 0.5 * (m12 - ta2)
    c20, c21, c22 = 0.5 * (t13 * a1 + fa2), 0.5 * (m12 + ta2), 0.5 * (p33 * a0 + t33 * a1)
    return (c00, c01, c02, c10, c11, c12, c20, c21, c22)


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


# -------------------------------------------------------------------------------------------------
# Plant (simulator.dynamics.plant.Plant)
# -------------------------------------------------------------------------------------------------
# -------------------------------------------------------------------------------------------------
# Disturbances
# -------------------------------------------------------------------------------------------------
@njit(cache=True, error_model="numpy")
def disturbance(
    t: float,
    u: np.ndarray,
    steps: np.ndarray,
    ramps: np.ndarray,
    gusts: np.ndarray,
    dryden: np.ndarray,
    S: np.ndarray,
) -> None:
    """``DisturbanceSchedule.evaluate(t)`` (start time 0) into the held inputs ``u``.

    ``steps`` rows: channel, start, end, value; ``ramps``: channel, start, end, hold, value;
    ``gusts``: start, end, V_m / 2, 2 pi / duration, unit direction; ``dryden``: the wind at each
    step index of the turbulence (from :class:`simulator.environment.dryden.DrydenWind`).
    """
    tau = t - 0.0
    v0 = v1 = v2 = v3 = v4 = v5 = 0.0
    for i in range(steps.shape[0]):
        if steps[i, 1] <= tau < steps[i, 2]:
            ch = int(steps[i, 0])
            value = steps[i, 3]
            if ch == 0:
                v0 += value
            elif ch == 1:
                v1 += value
            elif ch == 2:
                v2 += value
            elif ch == 3:
                v3 += value
            elif ch == 4:
                v4 += value
            else:
                v5 += value
    for i in range(ramps.shape[0]):
        start, end, hold = ramps[i, 1], ramps[i, 2], ramps[i, 3]
        if start <= tau < hold:
            ch = int(ramps[i, 0])
            value = ramps[i, 4] * _min((tau - start) / (end - start), 1.0)
            if ch == 0:
                v0 += value
            elif ch == 1:
                v1 += value
            elif ch == 2:
                v2 += value
            elif ch == 3:
                v3 += value
            elif ch == 4:
                v4 += value
            else:
                v5 += value
    wx = wy = wz = 0.0
    for i in range(gusts.shape[0]):
        start = gusts[i, 0]
        if start <= tau < gusts[i, 1]:
            speed = gusts[i, 2] * (1.0 - math.cos(gusts[i, 3] * (tau - start)))
            wx += speed * gusts[i, 4]
            wy += speed * gusts[i, 5]
            wz += speed * gusts[i, 6]
    if S[S_DRYDEN_ON] != 0.0 and S[S_DRYDEN_FROM] <= tau < S[S_DRYDEN_UNTIL]:
        n = int(math.floor((t - S[S_DRYDEN_T0]) / S[S_DRYDEN_STEP] + 0.5))
        n = n if n > 0 else 0
        n = n if n < dryden.shape[0] else dryden.shape[0] - 1  # never reached: sized for the run
        wx += dryden[n, 0]
        wy += dryden[n, 1]
        wz += dryden[n, 2]
    u[U_FORCE], u[U_FORCE + 1], u[U_FORCE + 2] = v0, v1, v2
    u[U_TORQUE], u[U_TORQUE + 1], u[U_TORQUE + 2] = v3, v4, v5
    u[U_WIND], u[U_WIND + 1], u[U_WIND + 2] = wx, wy, wz


# -------------------------------------------------------------------------------------------------
# Cascade (autopilot.control)
# -------------------------------------------------------------------------------------------------
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

    Returns ``(thrust, roll_ref, pitch_ref, thrust_saturated, tilt_limited)``; advances ``integ``.
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
    return thrust, roll_ref, pitch_ref, thrust_sat, tilt_lim


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
    m11, m13, m22, m23, m33 = inertia_matrix(Ixx, Iyy, Izz, euler[0], euler[1])
    v0 = ref_acc[0] - k_d * ed0 - k_p * e0
    v1 = ref_acc[1] - k_d * ed1 - k_p * e1
    v2 = ref_acc[2] - k_d * ed2 - k_p * e2
    Mv0 = m11 * v0 + 0.0 * v1 + m13 * v2
    Mv1 = 0.0 * v0 + m22 * v1 + m23 * v2
    Mv2 = m13 * v0 + m23 * v1 + m33 * v2
    c00, c01, c02, c10, c11, c12, c20, c21, c22 = coriolis_matrix(
        Ixx, Iyy, Izz, euler[0], euler[1], rates[0], rates[1], rates[2]
    )
    w0, w1, w2 = rates[0], rates[1], rates[2]
    Ce0 = c00 * w0 + c01 * w1 + c02 * w2
    Ce1 = c10 * w0 + c11 * w1 + c12 * w2
    Ce2 = c20 * w0 + c21 * w1 + c22 * w2
    Cs0 = c00 * s0 + c01 * s1 + c02 * s2
    Cs1 = c10 * s0 + c11 * s1 + c12 * s2
    Cs2 = c20 * s0 + c21 * s1 + c22 * s2
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
    m11, m13, m22, m23, m33 = inertia_matrix(Ixx, Iyy, Izz, euler[0], euler[1])
    Ma0 = m11 * acc0 + 0.0 * acc1 + m13 * acc2
    Ma1 = 0.0 * acc0 + m22 * acc1 + m23 * acc2
    Ma2 = m13 * acc0 + m23 * acc1 + m33 * acc2
    c00, c01, c02, c10, c11, c12, c20, c21, c22 = coriolis_matrix(
        Ixx, Iyy, Izz, euler[0], euler[1], rates[0], rates[1], rates[2]
    )
    w0, w1, w2 = rates[0], rates[1], rates[2]
    Ce0 = c00 * w0 + c01 * w1 + c02 * w2
    Ce1 = c10 * w0 + c11 * w1 + c12 * w2
    Ce2 = c20 * w0 + c21 * w1 + c22 * w2
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
# One flight
# -------------------------------------------------------------------------------------------------
# nogil: a Dask worker with several threads flies several runs at once (nothing here touches
# Python objects).
@njit(cache=True, error_model="numpy", nogil=True)
def simulate(  # noqa: C901
    state0: np.ndarray,
    P: np.ndarray,
    C: np.ndarray,
    ref: np.ndarray,
    S: np.ndarray,
    steps_tab: np.ndarray,
    ramps_tab: np.ndarray,
    gusts_tab: np.ndarray,
    dryden: np.ndarray,
    record: np.ndarray,
) -> np.ndarray:
    """Fly one run from ``state0``; return the metrics row (layout ``M_*``).

    Mirrors ``sitl.inprocess.run_scenario``: per control step k (t = k dt), read the state,
    take the reference (row k of ``ref``: p_d, p_d', p_d'', yaw, yaw', yaw'', sampled by the
    project's own trajectory at the time the controller sees), run the cascade, record the row
    (``record`` when it has rows), then hold the controls over ``substeps`` RK4 steps,
    evaluating the disturbance at every one.
    """
    dt = S[S_DT_CONTROL]
    dt_phys = S[S_DT_PHYSICS]
    substeps = int(S[S_SUBSTEPS])
    steps = int(S[S_STEPS])
    wire = S[S_WIRE] != 0.0
    max_pos_err, max_tilt, airborne_h = S[S_MAX_POS_ERR], S[S_MAX_TILT], S[S_AIRBORNE]
    do_record = record.shape[0] > 0
    rotor_plant = P[P_ROTOR_MODE] != 0.0
    rotor_ctrl = C[C_ROTOR_MODE] != 0.0
    nlh = int(C[C_RLAW]) == RLAW_NLHINF

    n = state0.shape[0]
    s = state0.copy()
    k1, k2, k3, k4, tmp = np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    u = np.zeros(U_SIZE)
    controls = np.zeros(4)
    integ_t = np.zeros(3)
    integ_r = np.zeros(3)
    filt_y = np.zeros(2)
    filt_yd = np.zeros(2)
    filt_ready = False
    a00, a01, a02 = C[C_PHI], C[C_PHI + 1], C[C_PHI + 2]
    a10, a11, a12 = C[C_PHI + 3], C[C_PHI + 4], C[C_PHI + 5]
    wn2, two_zeta_wn = C[C_WN2], C[C_2ZW]
    dt_c = C[C_DT]
    plant_thrust_max = P[P_THRUST_MAX]
    ptm0, ptm1, ptm2 = P[P_TORQUE_MAX], P[P_TORQUE_MAX + 1], P[P_TORQUE_MAX + 2]
    atm0, atm1, atm2 = C[C_ATORQUE_MAX], C[C_ATORQUE_MAX + 1], C[C_ATORQUE_MAX + 2]
    athrust_max = C[C_ATHRUST_MAX]
    wmin, wmax = P[P_WMIN], P[P_WMAX]

    metrics = np.zeros(M_SIZE)
    metrics[M_T_FAIL] = np.nan
    # tilt = acos(R22) (the body z axis against the vertical): tracked as the smallest R22.
    min_cos_tilt = 1.0
    cos_max_tilt = math.cos(max_tilt)
    prev_sq = np.zeros(6)
    prev_u = np.zeros(4)
    airborne = False
    touched = False
    fail = FAIL_NONE
    t = 0.0
    for k in range(steps + 1):
        t = k * dt
        pos, vel, euler, cos_tilt = truth_of_O(s, P)
        p_w, q_w, r_w = s[10], s[11], s[12]
        if wire:
            # ODOMETRY: float32 NED pose, NED velocity, FRD rates; the autopilot converts back.
            qw, qx, qy, qz = _f32(s[6]), _f32(s[7]), -_f32(-s[8]), -_f32(-s[9])
            Rw = rotation_from_quaternion(qw, qx, qy, qz)
            c_euler = euler_from_rotation(Rw[0], Rw[3], Rw[6], Rw[7], Rw[8])
            c_pos = (_f32(pos[0]), -_f32(-pos[1]), -_f32(-pos[2]))
            c_vel = (_f32(vel[0]), -_f32(-vel[1]), -_f32(-vel[2]))
            c_rates = euler_rates_from_body_rates(c_euler[0], c_euler[1], _f32(p_w), -_f32(-q_w), -_f32(-r_w))
        else:
            c_pos, c_vel, c_euler = pos, vel, euler
            c_rates = euler_rates_from_body_rates(euler[0], euler[1], p_w, q_w, r_w)
        rp = (ref[k, 0], ref[k, 1], ref[k, 2])
        rv = (ref[k, 3], ref[k, 4], ref[k, 5])
        ra = (ref[k, 6], ref[k, 7], ref[k, 8])
        yaw, yaw_rate, yaw_acc = ref[k, 9], ref[k, 10], ref[k, 11]

        # -- cascade step (Cascade.step) --
        thrust, roll_r, pitch_r, thrust_sat, tilt_lim = translational(
            C, integ_t, c_pos, c_vel, c_euler, rp, rv, ra, dt_c
        )
        if not filt_ready:
            filt_y[0], filt_y[1] = roll_r, pitch_r
            filt_yd[0], filt_yd[1] = 0.0, 0.0
            filt_ready = True
        phi_d, theta_d = filt_y[0], filt_y[1]
        phi_dd, theta_dd = filt_yd[0], filt_yd[1]
        phi_ddd = wn2 * (roll_r - phi_d) - two_zeta_wn * phi_dd
        theta_ddd = wn2 * (pitch_r - theta_d) - two_zeta_wn * theta_dd
        filt_y[0] = a00 * phi_d + a01 * phi_dd + a02 * roll_r
        filt_yd[0] = a10 * phi_d + a11 * phi_dd + a12 * roll_r
        filt_y[1] = a00 * theta_d + a01 * theta_dd + a02 * pitch_r
        filt_yd[1] = a10 * theta_d + a11 * theta_dd + a12 * pitch_r
        eta_d = (phi_d, theta_d, yaw)
        eta_d_dot = (phi_dd, theta_dd, yaw_rate)
        eta_d_ddot = (phi_ddd, theta_ddd, yaw_acc)
        if nlh:
            te0, te1, te2 = nlhinf(C, integ_r, c_euler, c_rates, eta_d, eta_d_dot, eta_d_ddot, dt_c)
        else:
            te0, te1, te2 = intbs_attitude(C, integ_r, c_euler, c_rates, eta_d, eta_d_dot, eta_d_ddot, dt_c)
        phi_c, theta_c = c_euler[0], c_euler[1]
        tb0, tb1, tb2 = body_torque_from_euler_torque(phi_c, theta_c, te0, te1, te2)
        if rotor_ctrl:
            thrust_a, ta0, ta1, ta2, sat = allocate_rotors(C, thrust, tb0, tb1, tb2, controls)
        else:
            thrust_a = _min(_max(thrust, 0.0), athrust_max)
            ta0 = _min(_max(tb0, -atm0), atm0)
            ta1 = _min(_max(tb1, -atm1), atm1)
            ta2 = _min(_max(tb2, -atm2), atm2)
            sat = tb0 < -atm0 or tb0 > atm0 or tb1 < -atm1 or tb1 > atm1 or tb2 < -atm2 or tb2 > atm2
            controls[0] = thrust_a / athrust_max
            controls[1], controls[2], controls[3] = ta0 / atm0, ta1 / atm1, ta2 / atm2
        sat = sat or thrust_sat
        tq0, tq1, tq2 = euler_torque_from_body_torque(phi_c, theta_c, ta0, ta1, ta2)

        # -- disturbance at the control instant (recorded) and this sample's indices --
        disturbance(t, u, steps_tab, ramps_tab, gusts_tab, dryden, S)
        if do_record:
            row = record[k]
            row[0] = t
            row[1], row[2], row[3] = pos[0], pos[1], pos[2]
            row[4], row[5], row[6] = rp[0], rp[1], rp[2]
            row[7], row[8], row[9] = euler[0], euler[1], euler[2]
            row[10], row[11], row[12] = phi_d, theta_d, yaw
            row[13], row[14], row[15], row[16] = thrust_a, tq0, tq1, tq2
            for j in range(6):
                row[17 + j] = u[U_FORCE + j]
        ex, ey, ez = pos[0] - rp[0], pos[1] - rp[1], pos[2] - rp[2]
        ephi = wrap_pi(euler[0] - phi_d)
        etheta = wrap_pi(euler[1] - theta_d)
        epsi = wrap_pi(euler[2] - yaw)
        sq0, sq1, sq2 = ex * ex, ey * ey, ez * ez
        sq3, sq4, sq5 = ephi * ephi, etheta * etheta, epsi * epsi
        if k > 0:
            half = 0.5 * dt
            metrics[M_ISE] += half * (sq0 + prev_sq[0])
            metrics[M_ISE + 1] += half * (sq1 + prev_sq[1])
            metrics[M_ISE + 2] += half * (sq2 + prev_sq[2])
            metrics[M_ISE + 3] += half * (sq3 + prev_sq[3])
            metrics[M_ISE + 4] += half * (sq4 + prev_sq[4])
            metrics[M_ISE + 5] += half * (sq5 + prev_sq[5])
            metrics[M_IADU] += abs(thrust_a - prev_u[0])
            metrics[M_IADU + 1] += abs(tq0 - prev_u[1])
            metrics[M_IADU + 2] += abs(tq1 - prev_u[2])
            metrics[M_IADU + 3] += abs(tq2 - prev_u[3])
        prev_sq[0], prev_sq[1], prev_sq[2] = sq0, sq1, sq2
        prev_sq[3], prev_sq[4], prev_sq[5] = sq3, sq4, sq5
        prev_u[0], prev_u[1], prev_u[2], prev_u[3] = thrust_a, tq0, tq1, tq2
        metrics[M_FINAL], metrics[M_FINAL + 1], metrics[M_FINAL + 2] = ex, ey, ez
        err = math.sqrt(sq0 + sq1 + sq2)
        if err > metrics[M_MAX_POS_ERR]:
            metrics[M_MAX_POS_ERR] = err
        if cos_tilt < min_cos_tilt:
            min_cos_tilt = cos_tilt
        if pos[2] > airborne_h:
            airborne = True
        # -- failures end the run at this sample --
        if not (math.isfinite(pos[0]) and math.isfinite(pos[1]) and math.isfinite(pos[2])):
            fail = FAIL_NONFINITE
        elif err > max_pos_err:
            fail = FAIL_POSITION
        elif cos_tilt < cos_max_tilt:
            fail = FAIL_TILT
        elif touched:
            fail = FAIL_GROUND
        if fail != FAIL_NONE:
            metrics[M_T_FAIL] = t
            break
        if k == steps:
            break
        if sat:
            metrics[M_T_SAT] += dt
        if tilt_lim:
            metrics[M_T_TILT] += dt

        # -- actuator controls into the plant (Plant.set_actuator_controls), float32 on the wire --
        c0, c1, c2, c3 = controls[0], controls[1], controls[2], controls[3]
        if wire:
            c0, c1, c2, c3 = _f32(c0), _f32(c1), _f32(c2), _f32(c3)
        if rotor_plant:
            u[U_ROTOR] = _min(_max(c0 * wmax, wmin), wmax)
            u[U_ROTOR + 1] = _min(_max(c1 * wmax, wmin), wmax)
            u[U_ROTOR + 2] = _min(_max(c2 * wmax, wmin), wmax)
            u[U_ROTOR + 3] = _min(_max(c3 * wmax, wmin), wmax)
        else:
            u[U_THRUST] = _min(_max(c0 * plant_thrust_max, 0.0), plant_thrust_max)
            u[U_TAU] = _min(_max(c1 * ptm0, -ptm0), ptm0)
            u[U_TAU + 1] = _min(_max(c2 * ptm1, -ptm1), ptm1)
            u[U_TAU + 2] = _min(_max(c3 * ptm2, -ptm2), ptm2)
        for j in range(substeps):
            disturbance(t + j * dt_phys, u, steps_tab, ramps_tab, gusts_tab, dryden, S)
            rk4_step(s, k1, k2, k3, k4, tmp, P, u, dt_phys)
            if P[P_GROUND] != 0.0 and ground_contact(s, P) and airborne:
                touched = True
    metrics[M_MAX_TILT] = math.acos(_min(_max(min_cos_tilt, -1.0), 1.0))
    metrics[M_FAIL] = fail
    metrics[M_T_END] = t
    return metrics
