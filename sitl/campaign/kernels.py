"""The batch engine: one whole flight per call, composed per law pair from the kernels the SITL
flies (:mod:`quadcommon.kernel`), compiled by numba with the pair's laws inlined.

Why numba and a loop per run (``benchmarks/engine_choice.py`` measures the alternatives): the
per-step work of this vehicle is a few hundred scalar operations on a 13-17 element state, too
little to fill a vector unit and too much branching (saturations, ground contact, law choice) to
vectorise well. A numpy batch axis pays ~1 us of interpreter and temporary-array overhead per
operation whatever the batch size; compiled scalar code keeps the state in registers.

Nothing here is a second copy of an equation: :func:`simulate` calls

* the plant's RK4 step, ground contact and read-out of O (:mod:`simulator.dynamics`), the same
  kernels :class:`~simulator.dynamics.plant.Plant` steps in the simulator;
* the disturbance profile's steps, ramps and 1-cos gusts
  (:func:`simulator.environment.gust_profile.steps_and_ramps`, ``one_minus_cosine_wind``) and the
  Dryden wind drawn beforehand by the project's own generator;
* the cascade (:func:`autopilot.control.cascade.cascade_step`) with the run's two laws: what the
  autopilot flies per frame;
* the wire (switch ``S_WIRE``): ODOMETRY's float32 pose, velocity and rates and the autopilot's
  conversions back (:mod:`quadcommon.rigid_body`), and the float32 controls of
  HIL_ACTUATOR_CONTROLS;

and accumulates the paper's indices while flying (final errors, ISE trapezoidal, IADU as total
variation, the definitions of :mod:`gcs_scripts.analysis.metrics`). ``error_model="numpy"``: a
division by zero gives inf/NaN, and a run that goes non-finite ends as "non-finite state".
"""

from __future__ import annotations

import math

import numpy as np

from autopilot.control.allocation import OUT_SIZE
from autopilot.control.cascade import cascade_step
from autopilot.control.command_filter import S_SIZE as FILTER_STATE_SIZE
from quadcommon.frames import wrap_pi
from quadcommon.kernel import borrowed, kernel
from quadcommon.numerics import clip
from quadcommon.rigid_body import euler_from_quaternion, euler_from_rotation, euler_rates_from_body_rates
from simulator.dynamics.equations import (  # the plant (what the simulator steps)
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
)
from simulator.environment.gust_profile import one_minus_cosine_wind, steps_and_ramps

# =================================================================================================
# Where each number sits in the flat float64 arrays simulate() takes and returns.
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


@kernel
def _f32(x: float) -> float:
    """Round to float32 and back, as a MAVLink float field does."""
    return np.float64(np.float32(x))


# -------------------------------------------------------------------------------------------------
# Disturbances
# -------------------------------------------------------------------------------------------------
@kernel
def disturbance(t, u, steps, ramps, gusts, dryden, S):
    """The disturbance profile at time ``t`` (start time 0) into the held inputs ``u``, as
    :class:`~simulator.environment.gust_profile.DisturbanceSchedule` evaluates it; ``dryden``: the
    wind at each step index of the turbulence (:class:`simulator.environment.dryden.DrydenWind`)."""
    f0, f1, f2, t0, t1, t2, _ = steps_and_ramps(t, steps, ramps)
    wx, wy, wz, _ = one_minus_cosine_wind(t, gusts)
    if S[S_DRYDEN_ON] != 0.0 and S[S_DRYDEN_FROM] <= t < S[S_DRYDEN_UNTIL]:
        n = int(math.floor((t - S[S_DRYDEN_T0]) / S[S_DRYDEN_STEP] + 0.5))
        n = min(max(n, 0), dryden.shape[0] - 1)  # the table is sized for the run: never clipped above
        wx += dryden[n, 0]
        wy += dryden[n, 1]
        wz += dryden[n, 2]
    u[U_FORCE], u[U_FORCE + 1], u[U_FORCE + 2] = f0, f1, f2
    u[U_TORQUE], u[U_TORQUE + 1], u[U_TORQUE + 2] = t0, t1, t2
    u[U_WIND], u[U_WIND + 1], u[U_WIND + 2] = wx, wy, wz


# -------------------------------------------------------------------------------------------------
# One flight
# -------------------------------------------------------------------------------------------------
# An entry per law pair: compiled(simulate, translational.step, rotational.step, nogil=True) (nogil:
# a Dask worker with several threads flies several runs at once; nothing here touches Python objects).
@kernel
def simulate(translational, rotational, state0, P, K, gt, gr, nxt, nxr, ref, S, steps_tab, ramps_tab,
             gusts_tab, dryden, record):  # noqa: C901  # fmt: skip
    """Fly one run from ``state0`` with the laws ``translational`` and ``rotational`` (their gains
    ``gt``, ``gr``; ``nxt``, ``nxr`` entries of state); return the metrics row (layout ``M_*``).

    As ``sitl.inprocess.run_scenario`` flies the whole stack: per control step k (t = k dt), read
    the state, take the reference (row k of ``ref``: p_d, p_d', p_d'', yaw, yaw', yaw'', sampled by
    the project's own trajectory at the time the controller sees), run the cascade, record the row
    (``record`` when it has rows), then hold the controls over ``substeps`` RK4 steps, evaluating
    the disturbance at every one.
    """
    dt = S[S_DT_CONTROL]
    dt_phys = S[S_DT_PHYSICS]
    substeps = int(S[S_SUBSTEPS])
    steps = int(S[S_STEPS])
    wire = S[S_WIRE] != 0.0
    max_pos_err, max_tilt, airborne_h = S[S_MAX_POS_ERR], S[S_MAX_TILT], S[S_AIRBORNE]
    do_record = record.shape[0] > 0
    rotor_plant = P[P_ROTOR_MODE] != 0.0

    # The arrays the loop passes to kernels, borrowed (quadcommon.kernel.borrowed: no reference
    # counting per call); ``work`` owns the loop's own arrays and is read after the loop.
    P, K, gt, gr, ref, S = borrowed(P), borrowed(K), borrowed(gt), borrowed(gr), borrowed(ref), borrowed(S)
    steps_tab, ramps_tab, gusts_tab = borrowed(steps_tab), borrowed(ramps_tab), borrowed(gusts_tab)
    dryden = borrowed(dryden)
    n = state0.shape[0]
    o_u, o_x, o_f, o_c = U_SIZE, U_SIZE + nxt + nxr, U_SIZE + nxt + nxr + FILTER_STATE_SIZE, 6 * n
    work = np.zeros(o_c + OUT_SIZE + o_f)
    whole = borrowed(work)
    s, k1, k2 = whole[0:n], whole[n : 2 * n], whole[2 * n : 3 * n]
    k3, k4, tmp = whole[3 * n : 4 * n], whole[4 * n : 5 * n], whole[5 * n : 6 * n]
    s[:] = state0
    u = whole[o_c : o_c + o_u]
    xt, xr = whole[o_c + o_u : o_c + o_u + nxt], whole[o_c + o_u + nxt : o_c + o_x]
    filt = whole[o_c + o_x : o_c + o_f]
    controls = whole[o_c + o_f : o_c + o_f + OUT_SIZE]
    no_tilt, no_attitude = (0.0, 0.0), (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
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
            c_euler = euler_from_quaternion(_f32(s[6]), _f32(s[7]), -_f32(-s[8]), -_f32(-s[9]))
            c_pos = (_f32(pos[0]), -_f32(-pos[1]), -_f32(-pos[2]))
            c_vel = (_f32(vel[0]), -_f32(-vel[1]), -_f32(-vel[2]))
            c_omega = (_f32(p_w), -_f32(-q_w), -_f32(-r_w))
            c_rates = euler_rates_from_body_rates(c_euler[0], c_euler[1], c_omega)
        else:
            c_pos, c_vel, c_euler = pos, vel, euler
            c_rates = euler_rates_from_body_rates(euler[0], euler[1], (p_w, q_w, r_w))
        rp = (ref[k, 0], ref[k, 1], ref[k, 2])
        rv = (ref[k, 3], ref[k, 4], ref[k, 5])
        ra = (ref[k, 6], ref[k, 7], ref[k, 8])
        yaw, yaw_rate, yaw_acc = ref[k, 9], ref[k, 10], ref[k, 11]

        # -- the cascade (what the autopilot flies) --
        o = cascade_step(translational, rotational, K, gt, xt, gr, xr, filt, c_pos, c_vel, c_euler, c_rates,
                         rp, rv, ra, yaw, yaw_rate, yaw_acc, True, 0, no_tilt, no_attitude, 0.0, controls)
        thrust_a, tq0, tq1, tq2, phi_d, theta_d = o[0], o[1], o[2], o[3], o[7], o[8]
        sat, tilt_lim = o[18] != 0.0, o[19] != 0.0

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
            u[U_ROTOR] = clip(c0 * wmax, wmin, wmax)
            u[U_ROTOR + 1] = clip(c1 * wmax, wmin, wmax)
            u[U_ROTOR + 2] = clip(c2 * wmax, wmin, wmax)
            u[U_ROTOR + 3] = clip(c3 * wmax, wmin, wmax)
        else:
            u[U_THRUST] = clip(c0 * plant_thrust_max, 0.0, plant_thrust_max)
            u[U_TAU] = clip(c1 * ptm0, -ptm0, ptm0)
            u[U_TAU + 1] = clip(c2 * ptm1, -ptm1, ptm1)
            u[U_TAU + 2] = clip(c3 * ptm2, -ptm2, ptm2)
        for j in range(substeps):
            disturbance(t + j * dt_phys, u, steps_tab, ramps_tab, gusts_tab, dryden, S)
            rk4_step(s, k1, k2, k3, k4, tmp, P, u, dt_phys)
            if P[P_GROUND] != 0.0 and ground_contact(s, P) and airborne:
                touched = True
    metrics[M_MAX_TILT] = math.acos(clip(min_cos_tilt, -1.0, 1.0))
    metrics[M_FAIL] = fail
    metrics[M_T_END] = t + 0.0 * work.shape[0]  # (a read of work: its arrays stay alive until here)
    return metrics
