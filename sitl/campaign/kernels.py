"""The batch engine's compiled kernels: one whole flight per call, in numba (``cache=True``).

Why numba and a loop per run (``benchmarks/engine_choice.py`` measures the alternatives): the
per-step work of this vehicle is a few hundred scalar operations on a 13-17 element state, too
little to fill a vector unit and too much branching (saturations, ground contact, law choice) to
vectorise well. A numpy batch axis pays ~1 µs of interpreter and temporary-array overhead per
operation whatever the batch size; compiled scalar code keeps the state in registers.

These functions are a *transcription* of the scalar reference, with every expression written in
the same order of floating-point operations so the two agree to rounding (the scalar code is
the specification; the tests in ``tests/campaign/`` prove the agreement run for run):

* plant: the coupled rigid body about G with forces at O (CONTROL.md, "the more accurate
  plant"), RK4, quaternion renormalisation, ground contact: the plant's own equations
  (:mod:`simulator.dynamics.equations`, kernels the simulator itself runs), compiled in here;
* disturbances: :class:`simulator.environment.gust_profile.DisturbanceSchedule.evaluate` (steps,
  ramps, 1-cos gusts, Dryden wind precomputed by the project's own generator);
* cascade: :class:`autopilot.control.cascade.Cascade.step`: translational laws (eqs. 24-29 and
  the IntBS / BS variants), the command filter, NLHinf (eqs. 43-44, M and C of eqs. 4-6) or the
  IntBS attitude law, ``W_eta^-T`` (eq. 3-4) and the wrench saturation or rotor allocation; their
  compiled form lives with the cascade (:mod:`autopilot.control.compiled`, which the autopilot
  itself runs) and is imported here;
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

from autopilot.control.compiled import (  # the cascade, compiled (what the autopilot flies)
    C_DT,
    C_ROTOR_MODE,
    F_SIZE,
    _max,
    _min,
    allocate_rotors,
    attitude_torque,
    command_filter,
    euler_rates_from_body_rates,
    euler_torque_from_body_torque,
    saturate_wrench,
    translational,
    wrap_pi,
)
from quadcommon import kernel as _kernel
from quadcommon.rigid_body import euler_from_rotation, rotation_from_quaternion
from simulator.dynamics.equations import (  # the plant's equations (kernels; see the cache note below)
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
    ground_contact,
    motion_of_O,
    rk4_step,
)  # fmt: skip

# The plant's equations are kernels: numba compiles them into the functions here once they are
# registered with it, which this engine needs whatever QUADSITL_PURE_PYTHON says.
_kernel._load_numba()


def _forget_kernels_compiled_against_another_plant() -> None:
    """numba keys a cached function on its own file only, but these kernels have the plant's and
    the plant's and the cascade's functions and constants (:mod:`simulator.dynamics.equations`,
    :mod:`quadcommon.rigid_body`, :mod:`autopilot.control.compiled`) compiled into them: when any of
    these files changes, this file's cache entries are deleted before anything here compiles."""
    import hashlib
    import os
    from pathlib import Path

    import autopilot.control.compiled as cascade_kernels
    import quadcommon.rigid_body as rigid_body
    import simulator.dynamics.equations as plant_kernels

    digest = hashlib.sha256()
    for module in (plant_kernels, rigid_body, cascade_kernels):
        digest.update(Path(module.__file__).read_bytes())
    stamp = digest.hexdigest()
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


@njit(cache=True, error_model="numpy")
def _f32(x: float) -> float:
    """Round to float32 and back, as a MAVLink float field does."""
    return np.float64(np.float32(x))


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

    n = state0.shape[0]
    s = state0.copy()
    k1, k2, k3, k4, tmp = np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n)
    u = np.zeros(U_SIZE)
    controls = np.zeros(4)
    integ_t = np.zeros(3)
    integ_r = np.zeros(3)
    filt = np.zeros(F_SIZE)  # the command filter (layout F_*)
    dt_c = C[C_DT]
    plant_thrust_max = P[P_THRUST_MAX]
    ptm0, ptm1, ptm2 = P[P_TORQUE_MAX], P[P_TORQUE_MAX + 1], P[P_TORQUE_MAX + 2]
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
        R, pos, vel = motion_of_O(s, P)
        euler, cos_tilt = euler_from_rotation(R), R[2][2]
        p_w, q_w, r_w = s[10], s[11], s[12]
        if wire:
            # ODOMETRY: float32 NED pose, NED velocity, FRD rates; the autopilot converts back.
            qw, qx, qy, qz = _f32(s[6]), _f32(s[7]), -_f32(-s[8]), -_f32(-s[9])
            c_euler = euler_from_rotation(rotation_from_quaternion(qw, qx, qy, qz))
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
        thrust, roll_r, pitch_r, thrust_sat, tilt_lim, _, _, _ = translational(
            C, integ_t, c_pos, c_vel, c_euler, rp, rv, ra, dt_c
        )
        phi_d, theta_d, phi_dd, theta_dd, phi_ddd, theta_ddd = command_filter(C, filt, roll_r, pitch_r)
        eta_d, eta_d_dot = (phi_d, theta_d, yaw), (phi_dd, theta_dd, yaw_rate)
        eta_d_ddot = (phi_ddd, theta_ddd, yaw_acc)
        tb0, tb1, tb2 = attitude_torque(C, integ_r, c_euler, c_rates, eta_d, eta_d_dot, eta_d_ddot, dt_c)
        phi_c, theta_c = c_euler[0], c_euler[1]
        if rotor_ctrl:
            thrust_a, ta0, ta1, ta2, sat = allocate_rotors(C, thrust, tb0, tb1, tb2, controls)
        else:
            thrust_a, ta0, ta1, ta2, sat, c0, c1, c2, c3 = saturate_wrench(C, thrust, tb0, tb1, tb2)
            controls[0], controls[1], controls[2], controls[3] = c0, c1, c2, c3
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
