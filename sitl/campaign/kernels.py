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
* the plant's actuator faults (:func:`simulator.dynamics.equations.rotor_faults_due`: a run's
  drawn rotor faults, applied at the start of the first step at or after their onset, as the
  simulator applies a scenario's);
* the disturbance profile's steps, ramps and 1-cos gusts
  (:func:`simulator.environment.gust_profile.steps_and_ramps`, ``one_minus_cosine_wind``) and the
  Dryden wind drawn beforehand by the project's own generator;
* the cascade (:func:`autopilot.control.cascade.cascade_step`) with the run's two laws: what the
  autopilot flies per frame;
* on the estimate, the sensors' frame (:func:`simulator.sensors.frame.sensor_frame`), the
  filter's prediction and a frame's aiding fused in PX4's order
  (:func:`autopilot.estimation.aiding.fuse_frame`), as the autopilot's estimator loop calls them;
* the wire (switch ``SETTINGS.wire``): what ODOMETRY, HIL_SENSOR, HIL_GPS,
  VISION_POSITION_ESTIMATE and HIL_ACTUATOR_CONTROLS carry, by the simulator's encoders and the
  autopilot's decoders themselves (:mod:`quadcommon.wire_values`: the float32 fields, the scaled
  integers, the NED/FRD sign flips), applied in turn;

and accumulates the paper's indices while flying (final errors, ISE trapezoidal, IADU as total
variation, the definitions of :mod:`gcs_scripts.analysis.metrics`), and what a fault study reads:
the largest position error from the fault's onset on, the last time the error was above the
recovery bound, and the vertical speed at a ground contact after take-off. ``error_model="numpy"``: a
division by zero gives inf/NaN. A run whose plant state goes non-finite ends as the plant's failure
(``FAIL_NONFINITE``); one whose cascade applies a non-finite U1 or torque to a finite state ends as
the controller's (``FAIL_CONTROLLER``), by the check the autopilot makes
(:func:`~autopilot.control.cascade.output_finite`).

(One module: the flight composed per law pair is one compiled unit; its settings, metrics and
recorded rows are laid out beside the loop that reads and fills them.)
"""

from __future__ import annotations

import math
from typing import Any, NamedTuple

import numpy as np

from autopilot.control.allocation import OUT_SIZE
from autopilot.control.cascade import GIVEN, CascadeMemory, cascade_step, output_finite
from autopilot.control.command_filter import FILTER_STATE
from autopilot.estimation import filter as ekf
from autopilot.estimation.aiding import Aiding, fuse_frame
from autopilot.estimation.filter import FilterArrays
from autopilot.records import StateEstimate
from quadcommon.frames import wrap_pi
from quadcommon.kernel import borrowed, kernel
from quadcommon.layout import Field, column_names, layout, quaternion_at, vector_at
from quadcommon.numerics import clip
from quadcommon.rigid_body import (
    euler_from_quaternion,
    euler_from_rotation,
    euler_rates_from_body_rates,
    quaternion_from_euler,
)
from quadcommon.trajectories import Reference
from quadcommon.wire_values import (
    float_field,
    frame_time_s,
    frame_time_usec,
    gps_fix,
    gps_values,
    odometry_state,
    odometry_values,
    vector_field,
    vector_from_field,
    vision_pose,
    vision_values,
)
from simulator.dynamics.equations import (  # the plant (what the simulator steps)
    INPUTS,
    PLANT,
    STATE,
    ground_contact,
    motion_of_O,
    rk4_step,
    rotor_faults_due,
    truth,
)
from simulator.environment.gust_profile import one_minus_cosine_wind, steps_and_ramps
from simulator.sensors import frame as sensors
from simulator.sensors.frame import DELIVERY

# =================================================================================================
# The records simulate() takes and returns (flat float64 arrays; offsets generated from these).
# =================================================================================================
SETTINGS = layout("RunSettings", (
    Field("dt_control", unit="s", doc="control period"),
    Field("dt_physics", unit="s", doc="physics step"),
    Field("substeps", doc="physics steps per control step"),
    Field("steps", doc="control steps; samples k = 0..steps"),
    Field("wire", doc="1.0: float32 state and controls as on the MAVLink wire"),
    Field("usec_per_frame", unit="us", doc="informational: the reference table is sampled on this clock"),
    Field("max_position_error", unit="m", doc="a run whose position error exceeds it fails"),
    Field("max_tilt", unit="rad", doc="a run whose tilt exceeds it fails"),
    Field("airborne_height", unit="m", doc="height of O above which the vehicle counts as airborne"),
    Field("dryden_on", doc="1.0: Dryden turbulence is drawn"),
    Field("dryden_t0", unit="s", doc="start_time + dryden.start_s"),
    Field("dryden_from", unit="s", doc="profile time window of the turbulence"),
    Field("dryden_until", unit="s"),
    Field("dryden_step", unit="s", doc="time between two samples of the drawn wind"),
    Field("estimated", doc="1.0: the controllers fly on the EKF fed by the sensor models (the est arrays)"),
    Field("home", 3, unit="deg, deg, m", doc="the geodetic home the GNSS fixes cross the wire about"),
    Field("fault_onset", unit="s", doc="first fault's onset (inf: none): excursion, recovery count from it"),
    Field("recovery_bound", unit="m", doc="position error within which the vehicle has recovered"),
))  # fmt: skip

# The metrics row, one per run: the paper's indices (the results table's columns, named as here) ...
METRICS = layout("RunMetrics", (
    Field("final_error", elements=("x_m", "y_m", "z_m"), unit="m", doc="final position error"),
    Field("ise", elements=("x", "y", "z", "phi", "theta", "psi"), doc="integral of the squared errors"),
    Field("iadu", elements=("U1", "tau_phi", "tau_theta", "tau_psi"), doc="total variation of the controls"),
    Field("max_position_error_m", unit="m"),
    Field("max_tilt_rad", unit="rad"),
    Field("time_saturated_s", unit="s", doc="time with an actuator limit active"),
    Field("time_tilt_limited_s", unit="s", doc="time with the roll/pitch reference at the tilt limit"),
))  # fmt: skip
# ... how the run ended ...
RUN_END = layout("RunEnd", (
    Field("failure", doc="failure code (FAIL_*)"),
    Field("failure_time", unit="s", doc="time of the failure, NaN when none"),
    Field("end_time", unit="s", doc="last sample's time"),
), after=METRICS)  # fmt: skip
# ... on the estimate (SETTINGS.estimated; NaN otherwise) ...
ESTIMATION_METRICS = layout("EstimationMetrics", (
    Field("estimate_rms_error_m", unit="m", doc="RMS of |estimated - true position| over the samples flown"),
    Field("worst_test_ratio", doc="largest innovation test ratio of any fusion (gate at 1)"),
    Field("time_not_converged_s", unit="s", doc="time the filter's verdict was 'not converged'"),
    Field("rejected_samples", doc="samples rejected by the gates or the quality checks"),
), after=RUN_END)  # fmt: skip
# ... and what a fault study reads (from SETTINGS.fault_onset on).
FAULT_METRICS = layout("FaultMetrics", (
    Field("excursion", unit="m", doc="the largest position error from the onset on (NaN: onset not reached)"),
    Field("last_out", unit="s", doc="the last sample time from the onset on with the error above the bound"),
    Field("impact_speed", unit="m/s", doc="downward speed of the centre of mass at a contact after take-off"),
), after=ESTIMATION_METRICS)  # fmt: skip
METRICS_SIZE = FAULT_METRICS.size

FAIL_NONE, FAIL_NONFINITE, FAIL_POSITION, FAIL_TILT, FAIL_GROUND, FAIL_CONTROLLER = 0, 1, 2, 3, 4, 5

# The recorded time series (run_scenario's columns, one row per control step).
XYZ, EULER = ("x", "y", "z"), ("phi", "theta", "psi")
RECORD = layout("RecordRow", (
    Field("t", unit="s"),
    Field("position", elements=XYZ, unit="m", doc="true position of O"),
    Field("position_ref", elements=XYZ, unit="m"),
    Field("euler", elements=EULER, unit="rad", doc="true attitude"),
    Field("euler_ref", elements=EULER, unit="rad", doc="eta_d (filtered roll/pitch, yaw reference)"),
    Field("thrust", unit="N", doc="applied U1"),
    Field("torque_euler", elements=EULER, unit="N m", doc="applied tau_eta"),
    Field("disturbance_force", elements=XYZ, unit="N", doc="world"),
    Field("disturbance_torque", elements=EULER, unit="N m", doc="on the Euler coordinates"),
    Field("position_estimate", elements=XYZ, unit="m", doc="what the controllers flew on"),
))  # fmt: skip
RECORD_COLUMNS = column_names(RECORD)

# The reference the controllers get at each control step (engine.reference_table's rows).
REFERENCE_ROW = layout("ReferenceRow", (
    Field("position", 3, unit="m"), Field("velocity", 3, unit="m/s"), Field("acceleration", 3, unit="m/s^2"),
    Field("yaw", unit="rad"), Field("yaw_rate", unit="rad/s"), Field("yaw_acceleration", unit="rad/s^2"),
))  # fmt: skip


class FlightArrays(NamedTuple):
    """What :func:`simulate` reads of one run x controller
    (:meth:`sitl.campaign.engine.Flight.arrays`)."""

    state0: Any  # the plant's initial state
    plant: Any  # the plant's parameters (simulator.dynamics.equations.PLANT)
    numbers: Any  # the cascade's numbers (autopilot.control.cascade.CASCADE_NUMBERS)
    translational_gains: Any
    rotational_gains: Any
    translational_states: int  # entries of the translational law's state
    rotational_states: int
    reference: Any  # one REFERENCE_ROW per control step
    settings: Any  # SETTINGS
    steps: Any  # the disturbance profile's steps, ramps and 1-cos gusts (gust_profile.element_rows)
    ramps: Any
    gusts: Any
    dryden: Any  # the Dryden wind at each step of the turbulence
    faults: Any  # the run's rotor faults (ROTOR_FAULT rows, by onset; none: zero rows)


class PlantNow(NamedTuple):
    """The plant as a step's estimate reads it (its truth: what the sensors sample)."""

    state: Any  # the plant's state (simulator.dynamics.equations.STATE)
    parameters: Any  # PLANT
    inputs: Any  # the inputs held since the last step (INPUTS)
    work: Any  # scratch for truth(): its state and derivative


class EstimatorArrays(NamedTuple):
    """The memory of a flight's sensors (:mod:`simulator.sensors.frame`) and filter
    (:mod:`autopilot.estimation.filter`) (:func:`sitl.campaign.engine.estimator_memory`)."""

    rng: Any
    sensor_state: Any  # frame.STATE
    sensor_figures: Any  # frame.FIGURES
    sensor_faults: Any
    delivered: Any  # frame.DELIVERY
    memory: Any  # filter.MEMORY
    covariance: Any
    ring: Any
    stats: Any
    windows: Any
    scratch: Any  # filter.SCRATCH
    parameters: Any  # filter.PARAMETERS


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
    if S[SETTINGS.dryden_on] != 0.0 and S[SETTINGS.dryden_from] <= t < S[SETTINGS.dryden_until]:
        n = int(math.floor((t - S[SETTINGS.dryden_t0]) / S[SETTINGS.dryden_step] + 0.5))
        n = min(max(n, 0), dryden.shape[0] - 1)  # the table is sized for the run: never clipped above
        wx += dryden[n, 0]
        wy += dryden[n, 1]
        wz += dryden[n, 2]
    f, tq, w = INPUTS.disturbance_force, INPUTS.disturbance_torque, INPUTS.wind
    u[f], u[f + 1], u[f + 2] = f0, f1, f2
    u[tq], u[tq + 1], u[tq + 2] = t0, t1, t2
    u[w], u[w + 1], u[w + 2] = wx, wy, wz


# -------------------------------------------------------------------------------------------------
# The sensors and the filter (on the estimate)
# -------------------------------------------------------------------------------------------------
@kernel
def _through_fields(wire: bool, v: tuple) -> tuple:
    """A vector as three float fields of the wire carry it (HIL_SENSOR, VISION_POSITION_ESTIMATE)."""
    if wire:
        return vector_from_field(vector_field(v))
    return (v[0], v[1], v[2])


@kernel
def _home(S) -> tuple:
    """The geodetic home the GNSS fixes cross the wire about."""
    return (S[SETTINGS.home], S[SETTINGS.home + 1], S[SETTINGS.home + 2])


@kernel
def estimate(k, t, dt, S, plant, pose, t_previous, est):
    """Step ``k``'s sensor samples (:func:`simulator.sensors.frame.sensor_frame` on the truth at
    ``t``), then the state the controllers fly on: at step 0 the frame's state (``c_*``, from
    ODOMETRY through the wire), from whose pose the filter starts
    (:func:`~autopilot.estimation.filter.reset_state`); afterwards the filter's prediction on the
    IMU sample (none while an injected failure stops the IMU: the estimate as it is, the next
    prediction spans the gap, as the autopilot's). Returns ``(position, velocity, euler, euler
    rates, the autopilot's time of the last prediction)``: ``(StateEstimate, time)``; ``pose``: the
    frame's state, ``plant``: the :class:`PlantNow` whose truth the sensors read, ``est``: the
    :class:`EstimatorArrays`."""
    s, P, u, plant_work = plant
    rng, sensor, sensor_figures, faults, delivered = (est.rng, est.sensor_state, est.sensor_figures,
                                                      est.sensor_faults, est.delivered)  # fmt: skip
    F, Pf, ring, A = est.memory, est.covariance, est.ring, est.parameters
    wire = S[SETTINGS.wire] != 0.0
    for i in range(s.shape[0]):
        plant_work[0, i] = s[i]
    tr = truth(plant_work, P, u)  # what the simulator's frame reads: the inputs held since the last step
    sensors.sensor_frame(sensors.SensorMemory(rng, sensor, sensor_figures, faults), t, tr, delivered)
    t_autopilot = frame_time_s(frame_time_usec(k, S[SETTINGS.usec_per_frame])) if wire else t
    force = _through_fields(wire, vector_at(delivered, DELIVERY.force))
    rate = _through_fields(wire, vector_at(delivered, DELIVERY.rate))
    if k == 0:
        offset = 0.0
        if delivered[DELIVERY.baro_fresh] != 0.0:
            height = delivered[DELIVERY.baro_altitude]
            offset = (float_field(height) if wire else height) - pose.position_m[2]
        e = pose.euler_rad
        q = quaternion_from_euler(e[0], e[1], e[2])
        ekf.reset_state(F, Pf, A, pose.position_m, pose.velocity_m_s, q, 0.1, 0.1, offset)
        ekf.start(F, ring, t_autopilot, dt, rate, force)
        F[ekf.MEMORY.imu_samples] += 1.0
        return pose, t_autopilot  # the frame's pose flies this step
    if imu_fresh(delivered):
        ekf.predict_step(F, Pf, ring, A, t_autopilot, t_autopilot - t_previous, rate, force)
    else:
        t_autopilot = t_previous
    q = quaternion_at(F, ekf.MEMORY.q)
    euler = euler_from_quaternion(q[0], q[1], q[2], q[3])
    rates = euler_rates_from_body_rates(euler[0], euler[1], vector_at(F, ekf.MEMORY.rate))
    return StateEstimate(vector_at(F, ekf.MEMORY.p), vector_at(F, ekf.MEMORY.v), euler, rates), t_autopilot


@kernel
def imu_fresh(delivered) -> bool:
    """Both the accelerometer and the gyro sampled this step (HIL_SENSOR's bits 0-5)."""
    return delivered[DELIVERY.accel_fresh] != 0.0 and delivered[DELIVERY.gyro_fresh] != 0.0


@kernel
def fuse_aiding(t, S, est):
    """The step's magnetometer, barometer, GNSS and vision samples into the filter as the wire
    delivers them (:mod:`quadcommon.wire_values`), through the autopilot's own fusion of a frame's
    aiding (:func:`autopilot.estimation.aiding.fuse_frame`: PX4's order)."""
    d, D = est.delivered, DELIVERY
    if (d[D.mag_fresh] == 0.0 and d[D.baro_fresh] == 0.0 and d[D.gps_fresh] == 0.0
            and d[D.vision_fresh] == 0.0):  # fmt: skip
        return  # (most steps at 500 Hz bring no aiding: nothing to read, as the autopilot reads nothing)
    wire = S[SETTINGS.wire] != 0.0
    mag = _through_fields(wire, vector_at(d, D.mag_field))
    height = d[D.baro_altitude]
    if wire:  # HIL_SENSOR's pressure altitude
        height = float_field(height)
    position, velocity = vector_at(d, D.gps_position), vector_at(d, D.gps_velocity)
    eph, epv, speed_accuracy = d[D.gps_eph], d[D.gps_epv], d[D.gps_speed_accuracy]
    if wire and d[D.gps_fresh] != 0.0:  # through HIL_GPS's fields (it has no speed accuracy)
        home = _home(S)
        f = gps_values(position, velocity, eph, epv, home)
        position, velocity, eph, epv = gps_fix(f[0], f[1], f[2], f[6], f[7], f[8], f[3], f[4], home)
        speed_accuracy = 0.0
    vision_position = vector_at(d, D.vision_position)
    yaw, position_std, yaw_std = d[D.vision_yaw], d[D.vision_position_std], d[D.vision_yaw_std]
    if wire and d[D.vision_fresh] != 0.0:  # through VISION_POSITION_ESTIMATE's fields
        p_ned, yaw_ned, p_var, yaw_var = vision_values(vision_position, yaw, position_std, yaw_std)
        vision_position, yaw, position_std, yaw_std = vision_pose(p_ned, yaw_ned, p_var, yaw_var)
    memory = FilterArrays(est.memory, est.covariance, est.ring, est.stats, est.windows, est.scratch)
    fuse_frame(memory, est.parameters, t, Aiding(
        d[D.mag_fresh] != 0.0, mag, d[D.baro_fresh] != 0.0, height,
        d[D.gps_fresh] != 0.0, position, velocity, (eph, epv, speed_accuracy),
        (d[D.gps_fix_type], d[D.gps_satellites]),
        d[D.vision_fresh] != 0.0, vision_position, yaw, (position_std, yaw_std),
        False, (0.0, 0.0, 0.0), 0.0,  # (the sensors' vision is a pose)
    ))  # fmt: skip


@kernel
def estimator_after_step(k, t_estimator, dt, S, est, metrics):
    """After the controllers' answer: the step's aiding into the filter (as the autopilot fuses it),
    then the step's share of the estimation metrics (time not converged, worst test ratio)."""
    if k > 0 and imu_fresh(est.delivered):  # (no IMU sample: no prediction, no fusion, as the autopilot)
        fuse_aiding(t_estimator, S, est)
    if ekf.not_converged(est.memory, est.covariance, est.parameters) != ekf.CONVERGED:
        metrics[ESTIMATION_METRICS.time_not_converged_s] += dt
    stats = est.stats
    for j in range(stats.shape[0]):
        if stats[j, ekf.STATS.test_ratio] > metrics[ESTIMATION_METRICS.worst_test_ratio]:
            metrics[ESTIMATION_METRICS.worst_test_ratio] = stats[j, ekf.STATS.test_ratio]


@kernel
def estimator_rejected(stats):
    """Samples the gates and the quality checks rejected over the flight."""
    rejected = 0.0
    for j in range(stats.shape[0]):
        rejected += stats[j, ekf.STATS.rejected] + stats[j, ekf.STATS.check_rejected]
    return rejected


# A flight on the truth binds these in their place (:func:`sitl.campaign.engine.entry`): the flight
# numba compiles then holds no sensor model and no filter, and compiles in a fraction of the time.
@kernel
def truth_estimate(k, t, dt, S, plant, pose, t_previous, est):
    """On the truth: the frame's state as it is."""
    return pose, t_previous


@kernel
def truth_after_step(k, t_estimator, dt, S, est, metrics):
    """On the truth: nothing to fuse."""
    return


@kernel
def truth_rejected(stats):
    """On the truth: nothing rejected."""
    return 0.0


ON_ESTIMATE = (estimate, estimator_after_step, estimator_rejected)
ON_TRUTH = (truth_estimate, truth_after_step, truth_rejected)


# -------------------------------------------------------------------------------------------------
# One flight
# -------------------------------------------------------------------------------------------------
# An entry per law pair: compiled(simulate, translational.step, rotational.step, nogil=True) (nogil:
# a Dask worker with several threads flies several runs at once; nothing here touches Python objects).
@kernel
def simulate(translational, rotational, estimate_step, after_step, rejected, flight, est, record):  # noqa: C901
    """Fly one run (``flight``: a :class:`FlightArrays`) with the laws ``translational`` and
    ``rotational``; return the metrics row (:data:`METRICS` and
    the layouts after it, ``METRICS_SIZE`` long). ``estimate_step``, ``after_step``, ``rejected``:
    :data:`ON_ESTIMATE` for a flight on the estimate, :data:`ON_TRUTH` (no sensors, no filter) for
    one on the truth.
    ``faults_tab``: the run's rotor faults (rows of :data:`simulator.dynamics.equations.ROTOR_FAULT`,
    by onset; none: zero rows), set into the flight's own copy of ``P`` at the start of the first
    step at or after their onset.

    As ``sitl.inprocess.run_scenario`` flies the whole stack: per control step k (t = k dt), read
    the state, take the reference (row k of ``ref``: p_d, p_d', p_d'', yaw, yaw', yaw'', sampled by
    the project's own trajectory at the time the controller sees), run the cascade, record the row
    (``record`` when it has rows), then hold the controls over ``substeps`` RK4 steps, evaluating
    the disturbance at every one.

    On the estimate (``S[SETTINGS.estimated]``), ``est`` is the memory of the run's sensors and filter:
    ``(rng, sensor state, sensor figures, faults, sensor delivery, F, P, ring, stats, windows,
    filter parameters)`` (:mod:`simulator.sensors.frame`, :mod:`autopilot.estimation.filter`);
    per step the sensors sample the truth the simulator's frame reads (the plant with the inputs
    held since the last physics step: :func:`~simulator.dynamics.equations.truth`), and the
    controllers fly on the filter as the autopilot runs it (:class:`~autopilot.estimation.loop.
    EstimatorLoop`): at step 0 started from the frame's pose (the in-air start), then per step a
    prediction on the IMU sample, the controllers, and the fusions of the step's magnetometer,
    barometer, GNSS and vision samples. Through the wire (``SETTINGS.wire``) the samples are what
    HIL_SENSOR, HIL_GPS and VISION_POSITION_ESTIMATE carry: float32, velocities in cm/s, eph/epv
    in cm, no speed accuracy, the GNSS position in 1e-7 deg and mm about the home ``SETTINGS.home``.
    Otherwise ``est`` holds placeholder arrays and is not read.
    """
    state0, P, K = flight.state0, flight.plant, flight.numbers
    gt, gr, nxt, nxr = (flight.translational_gains, flight.rotational_gains, flight.translational_states,
                        flight.rotational_states)  # fmt: skip
    ref, S, steps_tab, ramps_tab = flight.reference, flight.settings, flight.steps, flight.ramps
    gusts_tab, dryden, faults_tab = flight.gusts, flight.dryden, flight.faults
    dt = S[SETTINGS.dt_control]
    dt_phys = S[SETTINGS.dt_physics]
    substeps = int(S[SETTINGS.substeps])
    steps = int(S[SETTINGS.steps])
    wire = S[SETTINGS.wire] != 0.0
    max_pos_err, max_tilt = S[SETTINGS.max_position_error], S[SETTINGS.max_tilt]
    airborne_h = S[SETTINGS.airborne_height]
    do_record = record.shape[0] > 0
    rotor_plant = P[PLANT.rotor_mode] != 0.0
    flight_P = P.copy()  # the flight's own: its faults set into it (P is shared by a run's flights)

    # The arrays the loop passes to kernels, borrowed (quadcommon.kernel.borrowed: no reference
    # counting per call); ``work`` owns the loop's own arrays and is read after the loop.
    P, K, gt, gr = borrowed(flight_P), borrowed(K), borrowed(gt), borrowed(gr)
    ref, S = borrowed(ref), borrowed(S)
    steps_tab, ramps_tab, gusts_tab = borrowed(steps_tab), borrowed(ramps_tab), borrowed(gusts_tab)
    dryden, faults_tab = borrowed(dryden), borrowed(faults_tab)
    next_fault = 0
    fault_onset, recovery_bound = S[SETTINGS.fault_onset], S[SETTINGS.recovery_bound]
    ground_reach = P[PLANT.ground_reach]
    n = state0.shape[0]
    o_u = INPUTS.size
    o_x, o_f, o_c = o_u + nxt + nxr, o_u + nxt + nxr + FILTER_STATE.size, 6 * n
    work = np.zeros(o_c + OUT_SIZE + o_f + GIVEN.size)
    whole = borrowed(work)
    s, k1, k2 = whole[0:n], whole[n : 2 * n], whole[2 * n : 3 * n]
    k3, k4, tmp = whole[3 * n : 4 * n], whole[4 * n : 5 * n], whole[5 * n : 6 * n]
    s[:] = state0
    u = whole[o_c : o_c + o_u]
    xt, xr = whole[o_c + o_u : o_c + o_u + nxt], whole[o_c + o_u + nxt : o_c + o_x]
    filt = whole[o_c + o_x : o_c + o_f]
    controls = whole[o_c + o_f : o_c + o_f + OUT_SIZE]
    nothing_given = whole[o_c + o_f + OUT_SIZE :]  # (GIVEN: zeros, the cascade computes every part)
    memory = CascadeMemory(K, gt, xt, gr, xr, filt, nothing_given)
    plant_thrust_max = P[PLANT.thrust_max]
    ptm0, ptm1, ptm2 = P[PLANT.torque_max], P[PLANT.torque_max + 1], P[PLANT.torque_max + 2]
    wmin, wmax = P[PLANT.rotor_speed_min], P[PLANT.rotor_speed_max]

    estimated = S[SETTINGS.estimated] != 0.0
    owned = est  # (read after the loop: its arrays stay alive until then)
    est = EstimatorArrays(
        borrowed(est.rng), borrowed(est.sensor_state), borrowed(est.sensor_figures),
        borrowed(est.sensor_faults),
        borrowed(est.delivered), borrowed(est.memory), borrowed(est.covariance), borrowed(est.ring),
        borrowed(est.stats), borrowed(est.windows), borrowed(est.scratch), borrowed(est.parameters),
    )
    owned_plant_work = np.zeros((2, n))  # truth()'s state and derivative
    plant_work = borrowed(owned_plant_work)  # (in PlantNow every step: no counting)
    t_estimator = 0.0
    squared_error = 0.0

    metrics = np.zeros(METRICS_SIZE)
    metrics[RUN_END.failure_time] = np.nan
    for j in range(FAULT_METRICS.excursion, FAULT_METRICS.size):  # NaN until they happen
        metrics[j] = np.nan
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
        if next_fault < faults_tab.shape[0]:  # the rotor faults whose onset has come (held inputs: u)
            next_fault = rotor_faults_due(P, faults_tab, next_fault, t, u)
        R, pos, vel = motion_of_O(s, P)
        euler, cos_tilt = euler_from_rotation(R), R[2][2]
        p_w, q_w, r_w = vector_at(s, STATE.body_rates)
        if wire:  # through ODOMETRY's fields, read as the autopilot reads them
            c_pos, c_vel, c_euler, c_rates = odometry_state(
                *odometry_values(pos, vel, quaternion_at(s, STATE.attitude), (p_w, q_w, r_w))
            )
        else:
            c_pos, c_vel, c_euler = pos, vel, euler
            c_rates = euler_rates_from_body_rates(euler[0], euler[1], (p_w, q_w, r_w))
        if estimated:
            pose = StateEstimate(c_pos, c_vel, c_euler, c_rates)
            plant = PlantNow(s, P, u, plant_work)
            flown, t_estimator = estimate_step(k, t, dt, S, plant, pose, t_estimator, est)
            c_pos, c_vel, c_euler, c_rates = flown
            ex, ey, ez = c_pos[0] - pos[0], c_pos[1] - pos[1], c_pos[2] - pos[2]
            squared_error += ex * ex + ey * ey + ez * ez
        R = REFERENCE_ROW  # (scalar loads: a row view per step would count references)
        rp = (ref[k, R.position], ref[k, R.position + 1], ref[k, R.position + 2])
        rv = (ref[k, R.velocity], ref[k, R.velocity + 1], ref[k, R.velocity + 2])
        ra = (ref[k, R.acceleration], ref[k, R.acceleration + 1], ref[k, R.acceleration + 2])
        yaw = ref[k, R.yaw]

        # -- the cascade (what the autopilot flies) --
        o = cascade_step(translational, rotational, memory, StateEstimate(c_pos, c_vel, c_euler, c_rates),
                         Reference(rp, rv, ra, yaw, ref[k, R.yaw_rate], ref[k, R.yaw_acceleration]), True,
                         controls)  # fmt: skip
        thrust_a, (tq0, tq1, tq2), (phi_d, theta_d, _) = o.thrust, o.torque_euler, o.euler_ref
        sat, tilt_lim = o.saturated != 0.0, o.tilt_limited != 0.0

        # -- disturbance at the control instant (recorded) and this sample's indices --
        disturbance(t, u, steps_tab, ramps_tab, gusts_tab, dryden, S)
        if do_record:
            row = record[k]
            row[RECORD.t] = t
            for j in range(3):
                row[RECORD.position + j] = pos[j]
                row[RECORD.position_ref + j] = rp[j]
                row[RECORD.euler + j] = euler[j]
                row[RECORD.position_estimate + j] = c_pos[j]
                row[RECORD.disturbance_force + j] = u[INPUTS.disturbance_force + j]
                row[RECORD.disturbance_torque + j] = u[INPUTS.disturbance_torque + j]
            e_ref, torque = RECORD.euler_ref, RECORD.torque_euler
            row[e_ref], row[e_ref + 1], row[e_ref + 2] = phi_d, theta_d, yaw
            row[RECORD.thrust] = thrust_a
            row[torque], row[torque + 1], row[torque + 2] = tq0, tq1, tq2
        ex, ey, ez = pos[0] - rp[0], pos[1] - rp[1], pos[2] - rp[2]
        ephi = wrap_pi(euler[0] - phi_d)
        etheta = wrap_pi(euler[1] - theta_d)
        epsi = wrap_pi(euler[2] - yaw)
        sq0, sq1, sq2 = ex * ex, ey * ey, ez * ez
        sq3, sq4, sq5 = ephi * ephi, etheta * etheta, epsi * epsi
        if k > 0:
            half = 0.5 * dt
            metrics[METRICS.ise] += half * (sq0 + prev_sq[0])
            metrics[METRICS.ise + 1] += half * (sq1 + prev_sq[1])
            metrics[METRICS.ise + 2] += half * (sq2 + prev_sq[2])
            metrics[METRICS.ise + 3] += half * (sq3 + prev_sq[3])
            metrics[METRICS.ise + 4] += half * (sq4 + prev_sq[4])
            metrics[METRICS.ise + 5] += half * (sq5 + prev_sq[5])
            metrics[METRICS.iadu] += abs(thrust_a - prev_u[0])
            metrics[METRICS.iadu + 1] += abs(tq0 - prev_u[1])
            metrics[METRICS.iadu + 2] += abs(tq1 - prev_u[2])
            metrics[METRICS.iadu + 3] += abs(tq2 - prev_u[3])
        prev_sq[0], prev_sq[1], prev_sq[2] = sq0, sq1, sq2
        prev_sq[3], prev_sq[4], prev_sq[5] = sq3, sq4, sq5
        prev_u[0], prev_u[1], prev_u[2], prev_u[3] = thrust_a, tq0, tq1, tq2
        final = METRICS.final_error
        metrics[final], metrics[final + 1], metrics[final + 2] = ex, ey, ez
        err = math.sqrt(sq0 + sq1 + sq2)
        if err > metrics[METRICS.max_position_error_m]:
            metrics[METRICS.max_position_error_m] = err
        if t >= fault_onset:  # from the fault on: how far it strays, and until when
            if not err <= metrics[FAULT_METRICS.excursion]:  # (NaN until the first sample)
                metrics[FAULT_METRICS.excursion] = err
            if err > recovery_bound:
                metrics[FAULT_METRICS.last_out] = t
        if cos_tilt < min_cos_tilt:
            min_cos_tilt = cos_tilt
        if pos[2] > airborne_h:
            airborne = True
        # -- failures end the run at this sample --
        if not (math.isfinite(pos[0]) and math.isfinite(pos[1]) and math.isfinite(pos[2])):
            fail = FAIL_NONFINITE
        elif not output_finite(o.thrust, o.torque_body):  # finite state in, non-finite wrench out: the law's
            fail = FAIL_CONTROLLER
        elif err > max_pos_err:
            fail = FAIL_POSITION
        elif cos_tilt < cos_max_tilt:
            fail = FAIL_TILT
        elif touched:
            fail = FAIL_GROUND
        if fail != FAIL_NONE:
            metrics[RUN_END.failure_time] = t
            break
        if k == steps:
            break
        if sat:
            metrics[METRICS.time_saturated_s] += dt
        if tilt_lim:
            metrics[METRICS.time_tilt_limited_s] += dt
        if estimated:  # the step's aiding, fused after the controllers' answer (as the autopilot does)
            after_step(k, t_estimator, dt, S, est, metrics)

        # -- actuator controls into the plant (Plant.set_actuator_controls), float32 on the wire --
        c0, c1, c2, c3 = controls[0], controls[1], controls[2], controls[3]
        if wire:
            c0, c1, c2, c3 = float_field(c0), float_field(c1), float_field(c2), float_field(c3)
        if rotor_plant:
            u[INPUTS.rotor_commands] = clip(c0 * wmax, wmin, wmax)
            u[INPUTS.rotor_commands + 1] = clip(c1 * wmax, wmin, wmax)
            u[INPUTS.rotor_commands + 2] = clip(c2 * wmax, wmin, wmax)
            u[INPUTS.rotor_commands + 3] = clip(c3 * wmax, wmin, wmax)
        else:
            u[INPUTS.thrust] = clip(c0 * plant_thrust_max, 0.0, plant_thrust_max)
            u[INPUTS.torque] = clip(c1 * ptm0, -ptm0, ptm0)
            u[INPUTS.torque + 1] = clip(c2 * ptm1, -ptm1, ptm1)
            u[INPUTS.torque + 2] = clip(c3 * ptm2, -ptm2, ptm2)
        for j in range(substeps):
            disturbance(t + j * dt_phys, u, steps_tab, ramps_tab, gusts_tab, dryden, S)
            rk4_step(s, k1, k2, k3, k4, tmp, P, u, dt_phys)
            # O may be at the ground only when G is this low
            if P[PLANT.ground] != 0.0 and s[STATE.position + 2] < ground_reach:
                falling = -s[STATE.velocity + 2]
                if ground_contact(s, P) and airborne:
                    if not touched:
                        metrics[FAULT_METRICS.impact_speed] = falling
                    touched = True
    metrics[METRICS.max_tilt_rad] = math.acos(clip(min_cos_tilt, -1.0, 1.0))
    if estimated:
        samples = int(round(t / dt)) + 1
        metrics[ESTIMATION_METRICS.estimate_rms_error_m] = math.sqrt(squared_error / samples)
        metrics[ESTIMATION_METRICS.rejected_samples] = rejected(est.stats)
    else:
        for j in range(RUN_END.size, ESTIMATION_METRICS.size):  # no estimate: NaN
            metrics[j] = np.nan
    metrics[RUN_END.failure] = fail
    # (reads of work, plant_work and est: their arrays stay alive until here)
    metrics[RUN_END.end_time] = t + 0.0 * (work.shape[0] + owned_plant_work.shape[0] + owned.rng.shape[0]
                                           + owned.covariance.shape[0] + flight_P.shape[0])  # fmt: skip
    return metrics
