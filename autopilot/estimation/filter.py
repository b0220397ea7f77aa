"""The filter's memory and its course between measurements, written once as kernels: the layouts
of its arrays, the start, the prediction with the delayed-state buffer, and the convergence verdict.

The filter's kernels are four modules along its seams: this one (what the filter holds and how
it moves from one IMU sample to the next), :mod:`.fusion` (the measurements in: their models,
noise, gates and the batch update of GNSS, barometer, magnetometer and vision), :mod:`.checks`
(the quality checks and resets the fusions call: a fix's quality, the magnetic field checks, the
bad-vertical-acceleration check and its innovation windows, the position reset after a run of
rejections) and :mod:`.kernels` (the arithmetic of the prediction and of the Joseph update).
:class:`~.eskf.ErrorStateEkf` is a thin shell around them (it keeps the alignment at rest, the
records it reports and the messages); a batch engine calls them from its own compiled loop
(:func:`sitl.campaign.kernels.simulate_estimated`), so both fly one filter. The equations are
those of :mod:`.eskf`'s docstring.

A filter's memory is six float arrays (:func:`new_memory`), each laid out by a layout below
(:mod:`quadcommon.layout`: fields declared once, offsets generated):

* ``F`` (``MEMORY.size``): the nominal state, the trapezoid's previous sample, the cumulative
  corrections the buffered states are brought forward with, the clocks of the last aiding, the
  fusion-rate limits, the step's process noise, counters;
* ``P`` (``N`` x ``N``): the error-state covariance (layout :data:`.kernels.ERROR_STATE`);
* ``ring`` (``RING`` x ``RING_ROW.size``): the delayed-state buffer, one row per IMU step;
* ``stats`` (``SOURCE.size`` x ``STATS.size``): per measurement kind (a row per field of
  :data:`.status.SOURCE`) the counters and last innovation :class:`~.status.SourceStats` reports;
* ``windows`` (``INNOVATION_WINDOWS.size`` x ``WINDOW_ROW.size``): the recent normalised vertical
  innovations (GNSS vertical velocity, vision height) the bad-vertical-acceleration check averages;
* ``scratch`` (``SCRATCH.size``): where a fusion forms its rows, gates and batch update
  (:mod:`.fusion` cuts its arrays from it), so that a running filter allocates nothing;

and the parameters are one more (``A``, :func:`parameter_array`, layout :data:`PARAMETERS`). Flags
and counts are floats in these arrays (``int(F[MEMORY.head])``): one array type for everything.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any, NamedTuple

import numpy as np

from quadcommon.kernel import kernel
from quadcommon.layout import Field, layout, quaternion_at, set_quaternion_at, set_vector_at, vector_at
from quadcommon.rigid_body import (
    Quaternion,
    Vector3,
    matrix_times,
    quaternion_conjugate,
    quaternion_multiply,
    rotation_from_quaternion,
)

from .kernels import IBA, IBG, IBH, IBM, IP, ITH, IV, ImuStep, N, NominalState, predict, update_work_size
from .parameters import EstimatorParams
from .status import SOURCE, SourceStats

# -- the parameters A (EstimatorParams' fields in its order, then the constants of the vehicle) ----
PARAMETERS = layout("FilterParameters", (
    *(Field(f.name) for f in dataclasses.fields(EstimatorParams)),  # in EstimatorParams' units
    Field("gravity", unit="m/s^2"),
    Field("field", 3, unit="gauss", doc="the earth field at home, world frame"),
    Field("field_strength", unit="gauss"),
    Field("field_inclination", unit="rad", doc="positive: pointing down"),
    Field("field_heading", unit="rad", doc="-declination in the paper's frame (z up)"),
))  # fmt: skip

# -- the state F ---------------------------------------------------------------------------------
MEMORY = layout("FilterMemory", (
    Field("p", 3, unit="m"), Field("v", 3, unit="m/s"), Field("q", 4, doc="attitude quaternion (w, x, y, z)"),
    Field("gyro_bias", 3, unit="rad/s"), Field("accel_bias", 3, unit="m/s^2"),
    Field("mag_bias", 3, unit="gauss"),
    Field("baro_bias", unit="m"),
    Field("prev_rate", 3, unit="rad/s", doc="raw gyro of the previous sample"),
    Field("prev_force", 3, unit="m/s^2", doc="raw accelerometer of the previous sample"),
    Field("prev_acc", 3, unit="m/s^2", doc="R (f - b_a) of the previous sample"),
    Field("rate", 3, unit="rad/s", doc="bias-corrected rate of the last sample (what the controllers get)"),
    Field("correction_p", 3, doc="cumulative corrections for the buffered states"),
    Field("correction_v", 3), Field("correction_q", 4),
    Field("time", unit="s"), Field("dt_avg", unit="s"),
    Field("head", doc="ring: index of the newest row"), Field("count_held", doc="ring: rows held"),
    Field("last_h_aid", unit="s", doc="time of the last fusion that constrains the horizontal drift"),
    Field("last_v_aid", unit="s", doc="... the vertical drift"),
    Field("last_gps_pos", unit="s"), Field("bad_accel_until", unit="s"), Field("bad_accel_detections"),
    Field("next_mag", unit="s", doc="fusion-rate limit (EKF2_MAG_RATE)"),
    Field("next_baro", unit="s", doc="fusion-rate limit (EKF2_BARO_RATE)"),
    Field("q_dt", unit="s", doc="the dt the process noise was derived for (-1: derive again)"),
    Field("imu_samples"), Field("imu_dt_rejected"),
    Field("qdiag", N, doc="the step's process noise variances"),
))  # fmt: skip

# -- the delayed-state buffer: per IMU step t, p, v, q, cp, cv, cq ---------------------------------
RING = 4096  # IMU steps (8 s at 500 Hz; the EKF2_*_DELAY parameters stop at 300 ms); a power of two
RING_MASK = RING - 1
RING_ROW = layout("RingRow", (
    Field("t", unit="s"), Field("p", 3, unit="m"), Field("v", 3, unit="m/s"), Field("q", 4),
    Field("correction_p", 3), Field("correction_v", 3), Field("correction_q", 4),
))  # fmt: skip

# -- per measurement kind (a row per field of SOURCE): SourceStats' fields, in its order ------------
STATS = layout("SourceStats", tuple(Field(f.name, unit="s" if f.name.endswith("_s") else "")
                                    for f in dataclasses.fields(SourceStats)))  # fmt: skip
STATS_INITIAL = tuple(float(f.default) for f in dataclasses.fields(SourceStats))

# -- the innovation windows of the bad-vertical-acceleration check (:mod:`.checks`) ------------------
WINDOW = 256  # samples held (then the oldest goes)
WINDOW_ROW = layout("InnovationWindow", (
    Field("times", WINDOW, unit="s"), Field("values", WINDOW), Field("start"), Field("count_held"),
    Field("total"), Field("appends"),
))  # fmt: skip
INNOVATION_WINDOWS = layout("InnovationWindows", (
    Field("gps_vvel", doc="GNSS vertical velocity, normalised innovations"),
    Field("ev_hgt", doc="vision height, normalised innovations"),
))  # fmt: skip

# -- a fusion's work arrays (:mod:`.fusion`), one buffer cut into views: nothing allocated per sample --
MAX_ROWS = 6  # the largest measurement: GNSS horizontal and vertical position and velocity
MAX_GROUPS = 4  # its groups, gated apart: horizontal and vertical position, horizontal and vertical velocity
SCRATCH = layout("FusionScratch", (
    Field("H", MAX_ROWS * N, doc="a measurement's rows, MAX_ROWS x N"),
    Field("r", MAX_ROWS, unit="variance"), Field("y", MAX_ROWS, doc="innovations"),
    Field("row_group", MAX_ROWS), Field("group_source", MAX_GROUPS), Field("group_gate", MAX_GROUPS),
    Field("accepted", MAX_GROUPS), Field("prior", MAX_ROWS, unit="variance"),
    Field("kept_H", MAX_ROWS * N, doc="the accepted rows, MAX_ROWS x N"), Field("kept_r", MAX_ROWS),
    Field("kept_y", MAX_ROWS), Field("dx", N, doc="the error K y"),
    Field("update", update_work_size(MAX_ROWS, N), doc="the batch update's products (kernels.joseph_update)"),
))  # fmt: skip

MAX_IMU_DT_S = 0.1  # a longer gap is a lost link, not an interval to integrate across
# While a bad vertical acceleration holds (:func:`.checks.check_vertical_accel`), the vertical
# velocity gets PX4's BADACC_BIAS_PNOISE (4.9 m/s^2 per 10 ms prediction, i.e. 0.49
# m/s^2/sqrt(Hz)) and the z accelerometer bias a fast random walk, so the aiding is accepted again
# and the new bias is learned instead of the filter diverging.
BAD_ACCEL_VEL_DENSITY = 0.49  # m/s^2/sqrt(Hz)
BAD_ACCEL_BIAS_RW = 0.1  # m/s^2/sqrt(s)

# The convergence verdict (not_converged): why the filter is not fit to fly on.
CONVERGED, DEAD_RECKONING, TILT, YAW, POSITION, HEIGHT = 0, 1, 2, 3, 4, 5


class DelayedState(NamedTuple):
    """The state at a measurement's time of validity ``t_m`` (:func:`state_at`), brought forward
    by the corrections applied since."""

    found: bool  # False: older than the buffer (the other fields are placeholders)
    position_m: Vector3
    velocity_m_s: Vector3
    attitude: Quaternion
    age_s: float  # D = now - t_m


class FilterArrays(NamedTuple):
    """A filter's memory (:func:`new_memory`; the module's docstring describes each array)."""

    state: np.ndarray  # F, layout MEMORY
    covariance: np.ndarray  # P, N x N
    ring: np.ndarray  # RING x RING_ROW.size
    stats: np.ndarray  # SOURCE.size x STATS.size
    windows: np.ndarray  # INNOVATION_WINDOWS.size x WINDOW_ROW.size
    scratch: np.ndarray  # SCRATCH.size: a fusion's work arrays


class Accuracies(NamedTuple):
    """1-sigma figures of the covariance (ESTIMATOR_STATUS' accuracies, :func:`accuracies`)."""

    horizontal_position_m: float  # sqrt(Pxx + Pyy)
    vertical_position_m: float  # sqrt(Pzz)
    velocity_m_s: float  # sqrt(Pvx + Pvy + Pvz)
    tilt_rad: float  # sqrt(P_theta_x + P_theta_y), world frame
    yaw_rad: float  # sqrt(P_theta_z)


# =================================================================================================
# Memory and parameters (Python)
# =================================================================================================
def parameter_array(params: EstimatorParams, gravity_m_s2: float, earth_field: Vector3) -> np.ndarray:
    """The parameters as the kernels read them (layout :data:`PARAMETERS`)."""
    A = np.zeros(PARAMETERS.size)
    for f in dataclasses.fields(params):
        A[getattr(PARAMETERS, f.name)] = float(getattr(params, f.name))
    mx, my, mz = (float(c) for c in earth_field)
    A[PARAMETERS.gravity] = gravity_m_s2
    A[PARAMETERS.field : PARAMETERS.field + 3] = (mx, my, mz)
    A[PARAMETERS.field_strength] = math.sqrt(mx * mx + my * my + mz * mz)
    A[PARAMETERS.field_inclination] = math.atan2(-mz, math.hypot(mx, my))
    A[PARAMETERS.field_heading] = math.atan2(my, mx)
    return A


def new_memory() -> FilterArrays:
    """The memory of a filter not yet started."""
    F = np.zeros(MEMORY.size)
    F[MEMORY.q] = F[MEMORY.correction_q] = 1.0
    F[MEMORY.dt_avg] = 0.002
    F[MEMORY.last_h_aid] = F[MEMORY.last_v_aid] = F[MEMORY.last_gps_pos] = -1.0
    F[MEMORY.bad_accel_until] = F[MEMORY.next_mag] = F[MEMORY.next_baro] = -math.inf
    F[MEMORY.q_dt] = -1.0
    stats = np.tile(np.array(STATS_INITIAL), (SOURCE.size, 1))
    windows = np.zeros((INNOVATION_WINDOWS.size, WINDOW_ROW.size))
    ring, scratch = np.zeros((RING, RING_ROW.size)), np.zeros(SCRATCH.size)
    return FilterArrays(F, np.zeros((N, N)), ring, stats, windows, scratch)


# =================================================================================================
# Reading and writing the memory
# =================================================================================================
@kernel
def world_force(F: Any, force: Vector3) -> Vector3:
    """``R (f - b_a)``: a body specific force in the world frame."""
    q = quaternion_at(F, MEMORY.q)
    R = rotation_from_quaternion(q[0], q[1], q[2], q[3])
    return matrix_times(
        R,
        (
            force[0] - F[MEMORY.accel_bias],
            force[1] - F[MEMORY.accel_bias + 1],
            force[2] - F[MEMORY.accel_bias + 2],
        ),
    )


@kernel
def restart_trapezoid(F: Any, rate: Vector3, force: Vector3) -> None:
    """The trapezoid starts again from this sample (after a gap, at the start, after a reset)."""
    set_vector_at(F, MEMORY.prev_rate, rate)
    set_vector_at(F, MEMORY.prev_force, force)
    set_vector_at(F, MEMORY.prev_acc, world_force(F, force))
    set_vector_at(
        F,
        MEMORY.rate,
        (rate[0] - F[MEMORY.gyro_bias], rate[1] - F[MEMORY.gyro_bias + 1], rate[2] - F[MEMORY.gyro_bias + 2]),
    )


@kernel
def store(F: Any, ring: Any, row: int) -> None:
    """The nominal state and the corrections so far into the buffer's ``row``."""
    r = ring[row]
    r[RING_ROW.t] = F[MEMORY.time]
    for i in range(3):
        r[RING_ROW.p + i] = F[MEMORY.p + i]
        r[RING_ROW.v + i] = F[MEMORY.v + i]
        r[RING_ROW.correction_p + i] = F[MEMORY.correction_p + i]
        r[RING_ROW.correction_v + i] = F[MEMORY.correction_v + i]
    for i in range(4):
        r[RING_ROW.q + i] = F[MEMORY.q + i]
        r[RING_ROW.correction_q + i] = F[MEMORY.correction_q + i]


# =================================================================================================
# Start and prediction
# =================================================================================================
@kernel
def start(F: Any, ring: Any, t: float, dt: float, rate: Vector3, force: Vector3) -> None:
    """The filter starts at this IMU sample with the state and covariance set (the alignment's or
    :func:`reset_state`'s): the trapezoid, the buffer and the aiding clocks start here."""
    if 0.0 < dt <= MAX_IMU_DT_S:
        F[MEMORY.dt_avg] = dt
    F[MEMORY.time] = t
    restart_trapezoid(F, rate, force)
    set_vector_at(F, MEMORY.correction_p, (0.0, 0.0, 0.0))
    set_vector_at(F, MEMORY.correction_v, (0.0, 0.0, 0.0))
    set_quaternion_at(F, MEMORY.correction_q, (1.0, 0.0, 0.0, 0.0))
    F[MEMORY.last_h_aid] = t
    F[MEMORY.last_v_aid] = t
    store(F, ring, 0)
    F[MEMORY.head] = 0.0
    F[MEMORY.count_held] = 1.0


@kernel
def reset_state(F: Any, P: Any, A: Any, position: Vector3, velocity: Vector3, q: Quaternion,
                position_std: float, velocity_std: float, baro_offset: float) -> None:  # fmt: skip
    """A known state (an in-air start, a test): attitude uncertainty from EKF2_ANGERR_INIT (tilt)
    and 5 deg of yaw, biases zero with their EKF2_*BIAS_INIT priors; ``baro_offset``: the baro
    height minus ``position``'s z (0 without a baro sample). Then :func:`start`."""
    set_vector_at(F, MEMORY.p, position)
    set_vector_at(F, MEMORY.v, velocity)
    n = 1.0 / math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    set_quaternion_at(F, MEMORY.q, (q[0] * n, q[1] * n, q[2] * n, q[3] * n))
    for i in range(9):
        F[MEMORY.gyro_bias + i] = 0.0
    F[MEMORY.baro_bias] = baro_offset
    for i in range(N):
        for j in range(N):
            P[i, j] = 0.0
    for i in range(3):
        P[IP + i, IP + i] = position_std * position_std
        P[IV + i, IV + i] = velocity_std * velocity_std
        P[IBG + i, IBG + i] = A[PARAMETERS.gyro_bias_init] ** 2
        P[IBA + i, IBA + i] = A[PARAMETERS.accel_bias_init] ** 2
        P[IBM + i, IBM + i] = A[PARAMETERS.mag_bias_init_gauss] ** 2
    P[ITH, ITH] = A[PARAMETERS.tilt_init] ** 2
    P[ITH + 1, ITH + 1] = A[PARAMETERS.tilt_init] ** 2
    P[ITH + 2, ITH + 2] = math.radians(5.0) ** 2
    P[IBH, IBH] = position_std * position_std + A[PARAMETERS.baro_noise_m] ** 2


@kernel
def process_noise(F: Any, A: Any, dt: float) -> None:
    """The step's process noise variances (``Q`` of :mod:`.eskf`'s docstring) into ``F``."""
    for i in range(N):
        F[MEMORY.qdiag + i] = 0.0
    for i in range(3):
        F[MEMORY.qdiag + IV + i] = A[PARAMETERS.accel_noise_density] ** 2 * dt
        F[MEMORY.qdiag + ITH + i] = A[PARAMETERS.gyro_noise_density] ** 2 * dt
        F[MEMORY.qdiag + IBG + i] = A[PARAMETERS.gyro_bias_rw] ** 2 * dt
        F[MEMORY.qdiag + IBA + i] = A[PARAMETERS.accel_bias_rw] ** 2 * dt
        F[MEMORY.qdiag + IBM + i] = A[PARAMETERS.mag_bias_rw] ** 2 * dt
    F[MEMORY.qdiag + IBH] = A[PARAMETERS.baro_bias_rw] ** 2 * dt
    F[MEMORY.q_dt] = dt


@kernel
def predict_step(
    F: Any, P: Any, ring: Any, A: Any, t: float, dt: float, rate: Vector3, force: Vector3
) -> None:
    """One IMU sample (raw gyro ``rate``, accelerometer ``force``) at ``t``, ``dt`` after the
    previous: the nominal state and P predicted (:func:`.kernels.predict`), then buffered."""
    F[MEMORY.imu_samples] += 1.0
    if not 0.0 < dt <= MAX_IMU_DT_S:
        # Not an interval to integrate across: restart the trapezoid from this sample.
        F[MEMORY.imu_dt_rejected] += 1.0
        F[MEMORY.time] = t
        restart_trapezoid(F, rate, force)
        return
    F[MEMORY.time] = t
    F[MEMORY.dt_avg] += 0.01 * (dt - F[MEMORY.dt_avg])
    if abs(dt - F[MEMORY.q_dt]) > 1e-9:  # time stamps jitter in the last bits: keep the noise
        process_noise(F, A, dt)
    bg = vector_at(F, MEMORY.gyro_bias)
    qdiag = F[MEMORY.qdiag : MEMORY.qdiag + N]
    imu = ImuStep(rate, force, vector_at(F, MEMORY.prev_rate), vector_at(F, MEMORY.prev_acc))
    nominal = NominalState(quaternion_at(F, MEMORY.q), vector_at(F, MEMORY.p), vector_at(F, MEMORY.v), bg,
                           vector_at(F, MEMORY.accel_bias))  # fmt: skip
    q, p, v, a1 = predict(P, qdiag, dt, A[PARAMETERS.gravity], imu, nominal)
    set_quaternion_at(F, MEMORY.q, q)
    set_vector_at(F, MEMORY.p, p)
    set_vector_at(F, MEMORY.v, v)
    set_vector_at(F, MEMORY.prev_acc, a1)
    set_vector_at(F, MEMORY.prev_rate, rate)
    set_vector_at(F, MEMORY.prev_force, force)
    set_vector_at(F, MEMORY.rate, (rate[0] - bg[0], rate[1] - bg[1], rate[2] - bg[2]))
    if t < F[MEMORY.bad_accel_until]:
        P[IV + 2, IV + 2] += BAD_ACCEL_VEL_DENSITY**2 * dt
        P[IBA + 2, IBA + 2] += BAD_ACCEL_BIAS_RW**2 * dt
    head = (int(F[MEMORY.head]) + 1) & RING_MASK
    store(F, ring, head)
    F[MEMORY.head] = head
    if F[MEMORY.count_held] < RING:
        F[MEMORY.count_held] += 1.0


# =================================================================================================
# The delayed-state buffer
# =================================================================================================
@kernel
def state_at(F: Any, ring: Any, t_m: float) -> DelayedState:
    """The state at ``t_m`` (corrected since), ``age_s = now - t_m``; not found when older than
    the buffer."""
    now = F[MEMORY.time]
    if t_m >= now - 1e-9:
        position, velocity = vector_at(F, MEMORY.p), vector_at(F, MEMORY.v)
        return DelayedState(True, position, velocity, quaternion_at(F, MEMORY.q), 0.0)
    dt_avg = F[MEMORY.dt_avg]
    count, head = int(F[MEMORY.count_held]), int(F[MEMORY.head])
    k = int((now - t_m) / dt_avg + 0.5)
    none = DelayedState(False, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), 0.0)
    if k >= count:
        return none
    row = (head - k) & RING_MASK
    # The step is nearly uniform; walk at most a few entries to the nearest time.
    while ring[row, RING_ROW.t] > t_m and k + 1 < count:
        nxt = (head - k - 1) & RING_MASK
        if abs(ring[nxt, RING_ROW.t] - t_m) >= abs(ring[row, RING_ROW.t] - t_m):
            break
        k += 1
        row = nxt
    while ring[row, RING_ROW.t] < t_m and k > 0:
        nxt = (head - k + 1) & RING_MASK
        if abs(ring[nxt, RING_ROW.t] - t_m) >= abs(ring[row, RING_ROW.t] - t_m):
            break
        k -= 1
        row = nxt
    r = ring[row]
    te = r[RING_ROW.t]
    if t_m < te - 2.0 * dt_avg:
        return none  # older than the buffer's oldest entry
    dtm = t_m - te
    pm = (
        r[RING_ROW.p] + F[MEMORY.correction_p] - r[RING_ROW.correction_p] + r[RING_ROW.v] * dtm,
        r[RING_ROW.p + 1]
        + F[MEMORY.correction_p + 1]
        - r[RING_ROW.correction_p + 1]
        + r[RING_ROW.v + 1] * dtm,
        r[RING_ROW.p + 2]
        + F[MEMORY.correction_p + 2]
        - r[RING_ROW.correction_p + 2]
        + r[RING_ROW.v + 2] * dtm,
    )
    vm = (
        r[RING_ROW.v] + F[MEMORY.correction_v] - r[RING_ROW.correction_v],
        r[RING_ROW.v + 1] + F[MEMORY.correction_v + 1] - r[RING_ROW.correction_v + 1],
        r[RING_ROW.v + 2] + F[MEMORY.correction_v + 2] - r[RING_ROW.correction_v + 2],
    )
    q = quaternion_at(r, RING_ROW.q)
    cq, cq_now = quaternion_at(r, RING_ROW.correction_q), quaternion_at(F, MEMORY.correction_q)
    if cq != cq_now:  # corrected since it was stored: the corrections since, cq_now (x) cq^-1
        q = quaternion_multiply(quaternion_multiply(cq_now, quaternion_conjugate(cq)), q)
    return DelayedState(True, pm, vm, q, now - t_m)


# =================================================================================================
# Health
# =================================================================================================
@kernel
def accuracies(P: Any) -> Accuracies:
    """1-sigma horizontal position, vertical position, velocity, tilt and yaw of ``P``."""
    return Accuracies(
        math.sqrt(max(P[IP, IP] + P[IP + 1, IP + 1], 0.0)),
        math.sqrt(max(P[IP + 2, IP + 2], 0.0)),
        math.sqrt(max(P[IV, IV] + P[IV + 1, IV + 1] + P[IV + 2, IV + 2], 0.0)),
        math.sqrt(max(P[ITH, ITH] + P[ITH + 1, ITH + 1], 0.0)),
        math.sqrt(max(P[ITH + 2, ITH + 2], 0.0)),
    )


@kernel
def not_converged(F: Any, P: Any, A: Any) -> int:
    """Why the estimate is not fit to fly on (``CONVERGED``: it is): no aiding for EKF2_NOAID_TOUT,
    else the first 1-sigma above its EST_CONV_* threshold (tilt, yaw, horizontal position, height:
    just after the alignment the height is one GNSS fix, 0.5-1 m 1-sigma)."""
    if F[MEMORY.time] - F[MEMORY.last_h_aid] > A[PARAMETERS.no_aid_timeout_s]:
        return DEAD_RECKONING
    sigma = accuracies(P)
    if sigma.tilt_rad > A[PARAMETERS.converged_tilt_rad]:
        return TILT
    if sigma.yaw_rad > A[PARAMETERS.converged_yaw_rad]:
        return YAW
    if sigma.horizontal_position_m > A[PARAMETERS.converged_pos_m]:
        return POSITION
    if sigma.vertical_position_m > A[PARAMETERS.converged_vpos_m]:
        return HEIGHT
    return CONVERGED
