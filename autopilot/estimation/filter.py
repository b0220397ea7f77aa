"""The filter's steps, written once as kernels: prediction with the delayed-state buffer, the
fusions of GNSS, barometer, magnetometer and vision with their gates, checks and resets, and the
convergence verdict.

:class:`~.eskf.ErrorStateEkf` is a thin shell around these functions (it keeps the alignment at
rest, the records it reports and the messages); a batch engine calls them from its own compiled
loop (:func:`sitl.campaign.kernels.simulate_estimated`), so both fly one filter. The equations
are those of :mod:`.eskf`'s docstring; the arithmetic of the prediction and of the Joseph update
is in :mod:`.kernels`.

A filter's memory is five float arrays (:func:`new_memory`), each laid out by a layout below
(:mod:`quadcommon.layout`: fields declared once, offsets generated):

* ``F`` (``MEMORY.size``): the nominal state, the trapezoid's previous sample, the cumulative
  corrections the buffered states are brought forward with, the clocks of the last aiding, the
  fusion-rate limits, the step's process noise, counters;
* ``P`` (19 x 19): the error-state covariance (order :data:`.kernels.STATE_NAMES`);
* ``ring`` (``RING`` x ``RING_ROW.size``): the delayed-state buffer, one row per IMU step;
* ``stats`` (10 x ``STATS.size``): per measurement kind (:data:`.status.SOURCE_NAMES`' order)
  the counters and last innovation :class:`~.status.SourceStats` reports;
* ``windows`` (2 x ``WINDOW_ROW.size``): the recent normalised vertical innovations (GNSS vertical
  velocity, vision height) the bad-vertical-acceleration check averages;

and the parameters are one more (``A``, :func:`parameter_array`). Flags and counts are floats
in these arrays (``int(F[MEMORY.head])``): one array type for everything.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from quadcommon.frames import wrap_pi
from quadcommon.kernel import kernel
from quadcommon.layout import Field, layout
from quadcommon.rigid_body import (
    Quaternion,
    Vector3,
    euler_from_quaternion,
    matrix_times,
    quaternion_conjugate,
    quaternion_exp,
    quaternion_multiply,
    quaternion_normalised,
    rotation_from_quaternion,
)

from .kernels import IBA, IBG, IBH, IBM, IP, ITH, IV, N, joseph_update, predict, prior_variances
from .parameters import (  # the EKF2_* bit fields and values, defined with the parameters
    EV_CTRL_HPOS,
    EV_CTRL_VEL,
    EV_CTRL_VPOS,
    EV_CTRL_YAW,
    GPS_CTRL_HPOS,
    GPS_CTRL_VEL,
    GPS_CTRL_VPOS,
    MAG_CHECK_INCLINATION,
    MAG_CHECK_STRENGTH,
    MAG_TYPE_HEADING,
    MAG_TYPE_NONE,
    EstimatorParams,
)

# -- the parameters (EstimatorParams' fields in this order, then the constants of the vehicle) ----
PARAMETER_FIELDS = (
    "gyro_noise_density", "accel_noise_density", "gyro_bias_rw", "accel_bias_rw", "mag_bias_rw",
    "baro_bias_rw", "gyro_bias_init", "accel_bias_init", "tilt_init",
    "gps_ctrl", "gps_delay_s", "gps_pos_noise_m", "gps_vel_noise_m_s", "gps_pos_gate", "gps_vel_gate",
    "gps_req_eph_m", "gps_req_epv_m", "gps_req_nsats",
    "baro_enabled", "baro_period_s", "baro_delay_s", "baro_noise_m", "baro_gate",
    "mag_type", "mag_period_s", "mag_bias_init_gauss", "mag_delay_s", "mag_noise_gauss", "mag_gate",
    "heading_noise_rad", "heading_gate", "mag_check", "mag_strength_tol_gauss", "mag_inclination_tol_rad",
    "ev_ctrl", "ev_delay_s", "ev_noise_mode", "ev_pos_noise_m", "ev_yaw_noise_rad", "ev_pos_gate",
    "ev_vel_noise_m_s", "ev_vel_gate",
    "no_aid_timeout_s", "align_time_s", "pos_reset_timeout_s",
    "converged_tilt_rad", "converged_yaw_rad", "converged_pos_m", "converged_vpos_m",
)  # fmt: skip
PARAMETERS = layout("FilterParameters", (
    *(Field(name) for name in PARAMETER_FIELDS),
    Field("gravity", unit="m/s^2"),
    Field("field", 3, unit="gauss", doc="the earth field at home, world frame"),
    Field("field_strength", unit="gauss"),
    Field("field_inclination", unit="rad", doc="positive: pointing down"),
    Field("field_heading", unit="rad", doc="-declination in the paper's frame (z up)"),
))  # fmt: skip

GPS_FIX_3D = 3

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

# -- per measurement kind (rows in SOURCE_NAMES' order) ---------------------------------------------
SRC_GPS_POS, SRC_GPS_HGT, SRC_GPS_VEL, SRC_GPS_VVEL, SRC_BARO = 0, 1, 2, 3, 4
SRC_MAG, SRC_HEADING, SRC_EV_POS, SRC_EV_HGT, SRC_EV_YAW, SRC_EV_VEL = 5, 6, 7, 8, 9, 10
SOURCES = 11
STATS_FIELDS = (
    "fused", "rejected", "check_rejected", "too_old", "skipped", "test_ratio", "innovation",
    "normalized_innovation", "last_tested_s", "last_fused_s", "last_rejected_s", "rejecting_since_s",
    "resets",
)  # fmt: skip
STATS = layout("SourceStats", tuple(Field(name) for name in STATS_FIELDS))
STATS_INITIAL = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0, -1.0, -1.0, -1.0, 0.0)

# -- the innovation windows of the bad-vertical-acceleration check ---------------------------------
WINDOW = 256  # samples held (then the oldest goes)
WINDOW_ROW = layout("InnovationWindow", (
    Field("times", WINDOW, unit="s"), Field("values", WINDOW), Field("start"), Field("count_held"),
    Field("total"), Field("appends"),
))  # fmt: skip
W_GPS_VVEL, W_EV_HGT = 0, 1

MAX_IMU_DT_S = 0.1  # a longer gap is a lost link, not an interval to integrate across
MIN_VARIANCE = 1e-12  # floor of a scalar innovation variance (guards a degenerate P)
# Bad vertical acceleration (PX4's bad_acc_vertical): vertical velocity and height innovations
# both gated out with the same sign mean the accelerometer, not the aiding, is wrong. Then, for
# BAD_ACCEL_HOLD_S, the vertical velocity gets PX4's BADACC_BIAS_PNOISE (4.9 m/s^2 per 10 ms
# prediction, i.e. 0.49 m/s^2/sqrt(Hz)) and the z accelerometer bias a fast random walk, so the
# aiding is accepted again and the new bias is learned instead of the filter diverging.
BAD_ACCEL_VEL_DENSITY = 0.49  # m/s^2/sqrt(Hz)
BAD_ACCEL_BIAS_RW = 0.1  # m/s^2/sqrt(s)
BAD_ACCEL_HOLD_S = 1.0
BAD_ACCEL_WINDOW_S = 1.0  # the mean of the normalised vertical innovations over this window ...
BAD_ACCEL_MEAN = 1.5  # ... beyond this (4.7 sigma of the mean of 10 GPS fixes)
BAD_ACCEL_MIN_SAMPLES = 8

# The convergence verdict (not_converged): why the filter is not fit to fly on.
CONVERGED, DEAD_RECKONING, TILT, YAW, POSITION, HEIGHT = 0, 1, 2, 3, 4, 5


# =================================================================================================
# Memory and parameters (Python)
# =================================================================================================
def parameter_array(params: EstimatorParams, gravity_m_s2: float, earth_field: Vector3) -> np.ndarray:
    """The parameters as the kernels read them (layout :data:`PARAMETERS`)."""
    names = [f.name for f in dataclasses.fields(EstimatorParams)]
    if sorted(names) != sorted(PARAMETER_FIELDS):
        raise RuntimeError(f"EstimatorParams' fields {names} are not the kernels' {PARAMETER_FIELDS}")
    A = np.zeros(PARAMETERS.size)
    for i, name in enumerate(PARAMETER_FIELDS):
        A[i] = float(getattr(params, name))
    mx, my, mz = (float(c) for c in earth_field)
    A[PARAMETERS.gravity] = gravity_m_s2
    A[PARAMETERS.field : PARAMETERS.field + 3] = (mx, my, mz)
    A[PARAMETERS.field_strength] = math.sqrt(mx * mx + my * my + mz * mz)
    A[PARAMETERS.field_inclination] = math.atan2(-mz, math.hypot(mx, my))
    A[PARAMETERS.field_heading] = math.atan2(my, mx)
    return A


def new_memory() -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(F, P, ring, stats, windows)`` of a filter not yet started."""
    F = np.zeros(MEMORY.size)
    F[MEMORY.q] = F[MEMORY.correction_q] = 1.0
    F[MEMORY.dt_avg] = 0.002
    F[MEMORY.last_h_aid] = F[MEMORY.last_v_aid] = F[MEMORY.last_gps_pos] = -1.0
    F[MEMORY.bad_accel_until] = F[MEMORY.next_mag] = F[MEMORY.next_baro] = -math.inf
    F[MEMORY.q_dt] = -1.0
    stats = np.tile(np.array(STATS_INITIAL), (SOURCES, 1))
    return F, np.zeros((N, N)), np.zeros((RING, RING_ROW.size)), stats, np.zeros((2, WINDOW_ROW.size))


# =================================================================================================
# Small pieces
# =================================================================================================
@kernel
def vec3(a: Any, i: int) -> Vector3:
    return (a[i], a[i + 1], a[i + 2])


@kernel
def set3(a: Any, i: int, v: Vector3) -> None:
    a[i], a[i + 1], a[i + 2] = v[0], v[1], v[2]


@kernel
def quat(a: Any, i: int) -> Quaternion:
    return (a[i], a[i + 1], a[i + 2], a[i + 3])


@kernel
def set4(a: Any, i: int, q: Quaternion) -> None:
    a[i], a[i + 1], a[i + 2], a[i + 3] = q[0], q[1], q[2], q[3]


@kernel
def yaw_of(q: Quaternion) -> float:
    """The paper's psi of a body-to-world quaternion (ZYX Euler): ``atan2(R10, R00)`` with the two
    entries of :func:`~quadcommon.rigid_body.rotation_from_quaternion` it reads (per fusion)."""
    w, x, y, z = q
    return math.atan2(2.0 * (x * y + w * z), 1.0 - 2.0 * (y * y + z * z))


@kernel
def yaw_jacobian(q: Quaternion) -> Vector3:
    """d psi / d dtheta for the global angular error (``R <- (I + [dtheta]_x) R``).

    With ``psi = atan2(R10, R00)``: ``dR00 = -dth_z R10 + dth_y R20``, ``dR10 = dth_z R00 -
    dth_x R20``, so ``dpsi = dth_z - (R00 R20 dth_x + R10 R20 dth_y) / (R00^2 + R10^2)``.
    """
    R = rotation_from_quaternion(q[0], q[1], q[2], q[3])
    r00, r10, r20 = R[0][0], R[1][0], R[2][0]
    d = r00 * r00 + r10 * r10
    if d < 1e-9:  # pitch at +-90 deg: yaw undefined; fall back to the level-flight Jacobian
        return (0.0, 0.0, 1.0)
    return (-r00 * r20 / d, -r10 * r20 / d, 1.0)


@kernel
def mag_model(
    q: Quaternion, earth_field: Vector3, bias: Vector3
) -> tuple[Vector3, tuple[Vector3, Vector3, Vector3]]:
    """Predicted body field ``R^T m_e + b_m`` and its Jacobian ``R^T [m_e]_x`` on the global
    attitude error (``R <- (I + [dtheta]_x) R`` gives ``R^T m_e <- R^T m_e + R^T [m_e]_x dtheta``);
    the Jacobian on ``b_m`` is the identity."""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = rotation_from_quaternion(q[0], q[1], q[2], q[3])
    ex, ey, ez = earth_field
    pred = (
        r00 * ex + r10 * ey + r20 * ez + bias[0],
        r01 * ex + r11 * ey + r21 * ez + bias[1],
        r02 * ex + r12 * ey + r22 * ez + bias[2],
    )
    # Row i of R^T [m_e]_x is (column i of R) x m_e.
    H = (
        (r10 * ez - r20 * ey, r20 * ex - r00 * ez, r00 * ey - r10 * ex),
        (r11 * ez - r21 * ey, r21 * ex - r01 * ez, r01 * ey - r11 * ex),
        (r12 * ez - r22 * ey, r22 * ex - r02 * ez, r02 * ey - r12 * ex),
    )
    return pred, H


@kernel
def mag_heading(A: Any, m: Vector3, phi: float, theta: float, bias: Vector3) -> float:
    """The yaw that turns the tilt-compensated body field onto the earth field's heading."""
    cx, cy, cz = m[0] - bias[0], m[1] - bias[1], m[2] - bias[2]
    sf, cf = math.sin(phi), math.cos(phi)
    st, ct = math.sin(theta), math.cos(theta)
    # Level-frame field: Ry(theta) Rx(phi) m (yaw left out).
    lx = ct * cx + st * sf * cy + st * cf * cz
    ly = cf * cy - sf * cz
    return wrap_pi(A[PARAMETERS.field_heading] - math.atan2(ly, lx))


@kernel
def gps_variances(A: Any, eph: float, epv: float, speed_accuracy: float) -> Vector3:
    """Horizontal, vertical position and velocity variances of a fix: the reported accuracies
    with the parameters as floors (PX4: the vertical floor 1.5x the horizontal)."""
    h = max(eph, A[PARAMETERS.gps_pos_noise_m])
    v = max(epv, 1.5 * A[PARAMETERS.gps_pos_noise_m])
    s = max(speed_accuracy, A[PARAMETERS.gps_vel_noise_m_s])
    return (h * h, v * v, s * s)


@kernel
def gps_usable(A: Any, fix_type: float, eph: float, epv: float, satellites: float) -> bool:
    return (
        fix_type >= GPS_FIX_3D
        and eph <= A[PARAMETERS.gps_req_eph_m]
        and epv <= A[PARAMETERS.gps_req_epv_m]
        and satellites >= A[PARAMETERS.gps_req_nsats]
    )


@kernel
def ev_pos_variance(A: Any, position_std: float) -> float:
    """EKF2_EV_NOISE_MD 0: the reported 1-sigma with EKF2_EVP_NOISE as its floor; 1: the parameter."""
    s = (
        A[PARAMETERS.ev_pos_noise_m]
        if A[PARAMETERS.ev_noise_mode] != 0.0
        else max(position_std, A[PARAMETERS.ev_pos_noise_m])
    )
    return s * s


@kernel
def ev_vel_variance(A: Any, velocity_std: float) -> float:
    """EKF2_EV_NOISE_MD 0: the reported 1-sigma with EKF2_EVV_NOISE as its floor; 1: the parameter."""
    s = (
        A[PARAMETERS.ev_vel_noise_m_s]
        if A[PARAMETERS.ev_noise_mode] != 0.0
        else max(velocity_std, A[PARAMETERS.ev_vel_noise_m_s])
    )
    return s * s


@kernel
def ev_yaw_variance(A: Any, yaw_std: float) -> float:
    s = (
        A[PARAMETERS.ev_yaw_noise_rad]
        if A[PARAMETERS.ev_noise_mode] != 0.0
        else max(yaw_std, A[PARAMETERS.ev_yaw_noise_rad])
    )
    return s * s


@kernel
def world_force(F: Any, force: Vector3) -> Vector3:
    """``R (f - b_a)``: a body specific force in the world frame."""
    q = quat(F, MEMORY.q)
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
    set3(F, MEMORY.prev_rate, rate)
    set3(F, MEMORY.prev_force, force)
    set3(F, MEMORY.prev_acc, world_force(F, force))
    set3(
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
    set3(F, MEMORY.correction_p, (0.0, 0.0, 0.0))
    set3(F, MEMORY.correction_v, (0.0, 0.0, 0.0))
    set4(F, MEMORY.correction_q, (1.0, 0.0, 0.0, 0.0))
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
    set3(F, MEMORY.p, position)
    set3(F, MEMORY.v, velocity)
    n = 1.0 / math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    set4(F, MEMORY.q, (q[0] * n, q[1] * n, q[2] * n, q[3] * n))
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
    bg = vec3(F, MEMORY.gyro_bias)
    qdiag = F[MEMORY.qdiag : MEMORY.qdiag + N]
    q, p, v, a1 = predict(P, qdiag, dt, A[PARAMETERS.gravity], rate, force, vec3(F, MEMORY.prev_rate),
                          vec3(F, MEMORY.prev_acc), bg, vec3(F, MEMORY.accel_bias), quat(F, MEMORY.q),
                          vec3(F, MEMORY.p), vec3(F, MEMORY.v))  # fmt: skip
    set4(F, MEMORY.q, q)
    set3(F, MEMORY.p, p)
    set3(F, MEMORY.v, v)
    set3(F, MEMORY.prev_acc, a1)
    set3(F, MEMORY.prev_rate, rate)
    set3(F, MEMORY.prev_force, force)
    set3(F, MEMORY.rate, (rate[0] - bg[0], rate[1] - bg[1], rate[2] - bg[2]))
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
def state_at(F: Any, ring: Any, t_m: float) -> tuple[bool, Vector3, Vector3, Quaternion, float]:
    """``(found, p, v, q, D)`` at ``t_m`` (corrected since), ``D = now - t_m``; not found when
    older than the buffer."""
    now = F[MEMORY.time]
    if t_m >= now - 1e-9:
        return True, vec3(F, MEMORY.p), vec3(F, MEMORY.v), quat(F, MEMORY.q), 0.0
    dt_avg = F[MEMORY.dt_avg]
    count, head = int(F[MEMORY.count_held]), int(F[MEMORY.head])
    k = int((now - t_m) / dt_avg + 0.5)
    none = (False, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0), 0.0)
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
    q = quat(r, RING_ROW.q)
    cq, cq_now = quat(r, RING_ROW.correction_q), quat(F, MEMORY.correction_q)
    if cq != cq_now:  # corrected since it was stored: the corrections since, cq_now (x) cq^-1
        q = quaternion_multiply(quaternion_multiply(cq_now, quaternion_conjugate(cq)), q)
    return True, pm, vm, q, now - t_m


# =================================================================================================
# Fusion
# =================================================================================================
@kernel
def window_append(W: Any, w: int, t: float, value: float) -> None:
    """``(t, value)`` into window ``w`` (the oldest goes when full); its running sum is summed
    again every ``WINDOW`` appends, so round-off cannot build up."""
    row = W[w]
    start, count = int(row[WINDOW_ROW.start]), int(row[WINDOW_ROW.count_held])
    if count >= WINDOW:
        row[WINDOW_ROW.total] -= row[WINDOW_ROW.values + start]
        start = (start + 1) % WINDOW
        count -= 1
    i = (start + count) % WINDOW
    row[WINDOW_ROW.times + i] = t
    row[WINDOW_ROW.values + i] = value
    count += 1
    row[WINDOW_ROW.total] += value
    row[WINDOW_ROW.start], row[WINDOW_ROW.count_held] = start, count
    row[WINDOW_ROW.appends] += 1.0
    if row[WINDOW_ROW.appends] >= WINDOW:
        row[WINDOW_ROW.appends] = 0.0
        total = 0.0
        for j in range(count):
            total += row[WINDOW_ROW.values + (start + j) % WINDOW]
        row[WINDOW_ROW.total] = total


@kernel
def window_mean_since(W: Any, w: int, t: float) -> tuple[int, float]:
    """Drop the samples of window ``w`` older than ``t``; ``(samples left, their mean)``."""
    row = W[w]
    start, count = int(row[WINDOW_ROW.start]), int(row[WINDOW_ROW.count_held])
    while count > 0 and row[WINDOW_ROW.times + start] < t:
        row[WINDOW_ROW.total] -= row[WINDOW_ROW.values + start]
        start = (start + 1) % WINDOW
        count -= 1
    row[WINDOW_ROW.start], row[WINDOW_ROW.count_held] = start, count
    return count, (row[WINDOW_ROW.total] / count if count > 0 else 0.0)


@kernel
def window_of(source: int) -> int:
    """The innovation window a kind feeds (-1: none)."""
    if source == SRC_GPS_VVEL:
        return W_GPS_VVEL
    if source == SRC_EV_HGT:
        return W_EV_HGT
    return -1


@kernel
def fuse(F: Any, P: Any, stats: Any, W: Any, H: Any, r: Any, y: Any, row_group: Any, group_source: Any,
         group_gate: Any, accepted: Any) -> None:  # fmt: skip
    """Gate, then fuse one measurement: rows ``H`` (m x N) with noise variances ``r``,
    innovations ``y``, each row in group ``row_group[k]`` (groups in order, rows of a group
    consecutive); a group is one kind's axes (``group_source``, gate ``group_gate``).

    Each group passes or fails its gate as a whole on the prior innovation variances, as PX4
    does (``accepted`` 1/0 per group); the accepted rows are then fused in one batch, in Joseph
    form (:func:`.kernels.joseph_update`, Solà §6.1), and the error ``K y`` injected
    (:func:`inject`). A batch equals the sequence of scalar updates for a linear ``h`` and costs
    one set of 19x19 products instead of one per axis.
    """
    m = H.shape[0]
    groups = group_source.shape[0]
    prior = np.empty(m)
    prior_variances(P, H, prior)
    now = F[MEMORY.time]
    kept = 0
    k = 0
    for g in range(groups):
        src = int(group_source[g])
        gate = group_gate[g]
        first = k
        while k < m and int(row_group[k]) == g:
            k += 1
        worst = 0.0
        for j in range(first, k):
            ratio = y[j] * y[j] / (gate * gate * max(prior[j] + r[j], MIN_VARIANCE))
            if ratio > worst:
                worst = ratio
        last = k - 1
        s = stats[src]
        s[STATS.test_ratio] = worst
        s[STATS.innovation] = y[last]
        s[STATS.normalized_innovation] = y[last] / math.sqrt(max(prior[last] + r[last], MIN_VARIANCE))
        s[STATS.last_tested_s] = now
        w = window_of(src)
        if w >= 0:
            window_append(W, w, now, s[STATS.normalized_innovation])
        if worst > 1.0:
            s[STATS.rejected] += 1.0
            s[STATS.last_rejected_s] = now
            if s[STATS.rejecting_since_s] < 0.0:
                s[STATS.rejecting_since_s] = now
            accepted[g] = 0.0
        else:
            s[STATS.rejecting_since_s] = -1.0
            s[STATS.fused] += 1.0
            s[STATS.last_fused_s] = now
            accepted[g] = 1.0
            kept += k - first
    if kept == 0:
        return
    Hk = np.empty((kept, N))
    rk = np.empty(kept)
    yk = np.empty(kept)
    i = 0
    for j in range(m):
        if accepted[int(row_group[j])] != 0.0:
            for c in range(N):
                Hk[i, c] = H[j, c]
            rk[i] = r[j]
            yk[i] = y[j]
            i += 1
    dx = np.empty(N)
    joseph_update(P, Hk, rk, yk, dx)
    inject(F, P, dx)


@kernel
def inject(F: Any, P: Any, dx: Any) -> None:
    """Nominal state <- nominal (+) dx (Solà §6.2, global attitude error), then the reset."""
    for i in range(3):
        F[MEMORY.p + i] += dx[i]
        F[MEMORY.v + i] += dx[3 + i]
        F[MEMORY.gyro_bias + i] += dx[9 + i]
        F[MEMORY.accel_bias + i] += dx[12 + i]
        F[MEMORY.mag_bias + i] += dx[15 + i]
        # Bookkeeping for the buffered past states.
        F[MEMORY.correction_p + i] += dx[i]
        F[MEMORY.correction_v + i] += dx[3 + i]
    F[MEMORY.baro_bias] += dx[18]
    dq = quaternion_exp(dx[6], dx[7], dx[8])
    set4(F, MEMORY.q, quaternion_normalised(quaternion_multiply(dq, quat(F, MEMORY.q))))
    set4(F, MEMORY.correction_q, quaternion_multiply(dq, quat(F, MEMORY.correction_q)))
    # The previous sample's world force and the reported rate follow the new q and biases.
    set3(F, MEMORY.prev_acc, world_force(F, vec3(F, MEMORY.prev_force)))
    for i in range(3):
        F[MEMORY.rate + i] = F[MEMORY.prev_rate + i] - F[MEMORY.gyro_bias + i]
    # Reset, Solà §7.3.3: P <- G P G^T with G_theta = I + [dtheta/2]_x. Below 1 mrad, G - I
    # changes P by less than 0.05 %: skipped there (it costs as much as a fusion).
    hx, hy, hz = 0.5 * dx[6], 0.5 * dx[7], 0.5 * dx[8]
    if hx * hx + hy * hy + hz * hz > 0.25e-6:
        for j in range(N):  # rows: G P
            a, b, c = P[ITH, j], P[ITH + 1, j], P[ITH + 2, j]
            P[ITH, j] = a - hz * b + hy * c
            P[ITH + 1, j] = hz * a + b - hx * c
            P[ITH + 2, j] = -hy * a + hx * b + c
        for i in range(N):  # columns: (G P) G^T
            a, b, c = P[i, ITH], P[i, ITH + 1], P[i, ITH + 2]
            P[i, ITH] = a - hz * b + hy * c
            P[i, ITH + 1] = hz * a + b - hx * c
            P[i, ITH + 2] = -hy * a + hx * b + c


@kernel
def maybe_reset_position(
    F: Any, P: Any, stats: Any, A: Any, source: int, target: Vector3, var: float
) -> None:
    """After EST_POS_RST_T of continuous rejections of a good source, the horizontal position
    jumps to it (PX4 does)."""
    s = stats[source]
    since = s[STATS.rejecting_since_s]
    if since < 0.0 or F[MEMORY.time] - since < A[PARAMETERS.pos_reset_timeout_s]:
        return
    for i in range(2):
        delta = target[i] - F[MEMORY.p + i]
        F[MEMORY.p + i] += delta
        F[MEMORY.correction_p + i] += delta
        for j in range(N):
            P[IP + i, j] = 0.0
            P[j, IP + i] = 0.0
        P[IP + i, IP + i] = var
    s[STATS.resets] += 1.0
    s[STATS.rejecting_since_s] = -1.0


@kernel
def check_vertical_accel(F: Any, stats: Any, W: Any) -> None:
    """Bad vertical acceleration (PX4's bad_acc_vertical, made statistical): the mean of the
    normalised vertical velocity innovations (GPS) over the last BAD_ACCEL_WINDOW_S is beyond
    BAD_ACCEL_MEAN and the height innovation agrees in sign; or, without a velocity source,
    the mean of the normalised vision height innovations is. For a consistent filter the
    mean of n samples has a standard deviation 1/sqrt(n) (0.32 at 10 GPS fixes): by chance
    the test fires about once in 10^5 windows; a vertical accelerometer fault (a bias step the
    random-walk model cannot follow) trips it within about a second."""
    now = F[MEMORY.time]
    bad = False
    if stats[SRC_GPS_VVEL, STATS.last_tested_s] == now:
        n, mean = window_mean_since(W, W_GPS_VVEL, now - BAD_ACCEL_WINDOW_S)
        if n >= BAD_ACCEL_MIN_SAMPLES and abs(mean) >= BAD_ACCEL_MEAN:
            # The height source tested last (GNSS height first on a tie) agrees in sign.
            hgt, baro = stats[SRC_GPS_HGT], stats[SRC_BARO]
            latest = -1
            if hgt[STATS.last_tested_s] >= 0.0:
                latest = SRC_GPS_HGT
            if baro[STATS.last_tested_s] >= 0.0 and (
                latest < 0 or baro[STATS.last_tested_s] > hgt[STATS.last_tested_s]
            ):
                latest = SRC_BARO
            bad = latest >= 0 and stats[latest, STATS.innovation] * mean > 0.0
    if stats[SRC_EV_HGT, STATS.last_tested_s] == now:
        n, mean = window_mean_since(W, W_EV_HGT, now - BAD_ACCEL_WINDOW_S)
        if n >= BAD_ACCEL_MIN_SAMPLES and abs(mean) >= BAD_ACCEL_MEAN:
            bad = True
    if bad:
        if now >= F[MEMORY.bad_accel_until]:
            F[MEMORY.bad_accel_detections] += 1.0
        F[MEMORY.bad_accel_until] = now + BAD_ACCEL_HOLD_S


@kernel
def position_rows(H: Any, r: Any, y: Any, row_group: Any, k: int, g: int, axis: int, D: float,
                  innovation: float, var: float) -> int:  # fmt: skip
    """Row ``k``: a position axis measured ``D`` s ago (``dp(t_m) = dp - D dv``); the next row."""
    H[k, IP + axis] = 1.0
    H[k, IV + axis] = -D
    r[k], y[k], row_group[k] = var, innovation, g
    return k + 1


@kernel
def velocity_row(H: Any, r: Any, y: Any, row_group: Any, k: int, g: int, axis: int, innovation: float,
                 var: float) -> int:  # fmt: skip
    H[k, IV + axis] = 1.0
    r[k], y[k], row_group[k] = var, innovation, g
    return k + 1


@kernel
def yaw_row(H: Any, r: Any, y: Any, row_group: Any, k: int, g: int, q: Quaternion, innovation: float,
            var: float) -> int:  # fmt: skip
    J = yaw_jacobian(q)
    H[k, ITH], H[k, ITH + 1], H[k, ITH + 2] = J[0], J[1], J[2]
    r[k], y[k], row_group[k] = var, innovation, g
    return k + 1


@kernel
def fuse_gps(F: Any, P: Any, ring: Any, stats: Any, W: Any, A: Any, t: float, position: Vector3,
             velocity: Vector3, eph: float, epv: float, speed_accuracy: float, fix_type: float,
             satellites: float) -> None:  # fmt: skip
    """GNSS position (horizontal, height) and velocity arrived at ``t``, valid EKF2_GPS_DELAY before."""
    if not gps_usable(A, fix_type, eph, epv, satellites):
        stats[SRC_GPS_POS, STATS.check_rejected] += 1.0
        return
    found, pm, vm, _, D = state_at(F, ring, t - A[PARAMETERS.gps_delay_s])
    if not found:
        stats[SRC_GPS_POS, STATS.too_old] += 1.0
        return
    hv, vv, sv = gps_variances(A, eph, epv, speed_accuracy)
    ctrl = int(A[PARAMETERS.gps_ctrl])
    H, r, y, row_group = np.zeros((6, N)), np.empty(6), np.empty(6), np.empty(6)
    group_source, group_gate = np.empty(4), np.empty(4)
    k = g = 0
    if ctrl & GPS_CTRL_HPOS:
        k = position_rows(H, r, y, row_group, k, g, 0, D, position[0] - pm[0], hv)
        k = position_rows(H, r, y, row_group, k, g, 1, D, position[1] - pm[1], hv)
        group_source[g], group_gate[g] = SRC_GPS_POS, A[PARAMETERS.gps_pos_gate]
        g += 1
    if ctrl & GPS_CTRL_VPOS:
        k = position_rows(H, r, y, row_group, k, g, 2, D, position[2] - pm[2], vv)
        group_source[g], group_gate[g] = SRC_GPS_HGT, A[PARAMETERS.baro_gate]
        g += 1
    if ctrl & GPS_CTRL_VEL:
        # Horizontal and vertical velocity gated apart (as PX4 does), so that a vertical
        # accelerometer fault does not also cut the horizontal aiding.
        k = velocity_row(H, r, y, row_group, k, g, 0, velocity[0] - vm[0], sv)
        k = velocity_row(H, r, y, row_group, k, g, 1, velocity[1] - vm[1], sv)
        group_source[g], group_gate[g] = SRC_GPS_VEL, A[PARAMETERS.gps_vel_gate]
        g += 1
        k = velocity_row(H, r, y, row_group, k, g, 2, velocity[2] - vm[2], sv * 2.25)  # PX4: 1.5x
        group_source[g], group_gate[g] = SRC_GPS_VVEL, A[PARAMETERS.gps_vel_gate]
        g += 1
    if g == 0:
        return
    accepted = np.zeros(g)
    fuse(F, P, stats, W, H[:k], r[:k], y[:k], row_group[:k], group_source[:g], group_gate[:g], accepted)
    now = F[MEMORY.time]
    for j in range(g):
        src, ok = int(group_source[j]), accepted[j] != 0.0
        if src == SRC_GPS_POS:
            if ok:
                F[MEMORY.last_h_aid] = now
                F[MEMORY.last_gps_pos] = now
            else:
                target = (position[0] + F[MEMORY.p] - pm[0], position[1] + F[MEMORY.p + 1] - pm[1], 0.0)
                maybe_reset_position(F, P, stats, A, SRC_GPS_POS, target, hv)
        elif ok and (src in (SRC_GPS_HGT, SRC_GPS_VVEL)):
            F[MEMORY.last_v_aid] = now
        elif ok and src == SRC_GPS_VEL:
            F[MEMORY.last_h_aid] = now
    check_vertical_accel(F, stats, W)


@kernel
def fuse_baro(F: Any, P: Any, ring: Any, stats: Any, W: Any, A: Any, t: float, height: float) -> None:
    """Barometric height arrived at ``t``: ``h = z + b_h`` (the offset is a state), at most EKF2_BARO_RATE."""
    if A[PARAMETERS.baro_enabled] == 0.0:
        return
    s = stats[SRC_BARO]
    if t < F[MEMORY.next_baro]:
        s[STATS.skipped] += 1.0
        return
    F[MEMORY.next_baro] = t + A[PARAMETERS.baro_period_s] - 1e-9
    found, pm, _, _, D = state_at(F, ring, t - A[PARAMETERS.baro_delay_s])
    if not found:
        s[STATS.too_old] += 1.0
        return
    H, r, y, row_group = np.zeros((1, N)), np.empty(1), np.empty(1), np.zeros(1)
    H[0, IP + 2], H[0, IV + 2], H[0, IBH] = 1.0, -D, 1.0
    r[0], y[0] = A[PARAMETERS.baro_noise_m] ** 2, height - pm[2] - F[MEMORY.baro_bias]
    accepted = np.zeros(1)
    fuse(
        F,
        P,
        stats,
        W,
        H,
        r,
        y,
        row_group,
        np.full(1, float(SRC_BARO)),
        np.full(1, A[PARAMETERS.baro_gate]),
        accepted,
    )
    if accepted[0] != 0.0:
        F[MEMORY.last_v_aid] = F[MEMORY.time]
    check_vertical_accel(F, stats, W)


@kernel
def mag_checks(F: Any, stats: Any, A: Any, source: int, m: Vector3, q: Quaternion) -> bool:
    """PX4's EKF2_MAG_CHECK: the corrected field's strength and inclination against the model."""
    c = (m[0] - F[MEMORY.mag_bias], m[1] - F[MEMORY.mag_bias + 1], m[2] - F[MEMORY.mag_bias + 2])
    strength = math.sqrt(c[0] * c[0] + c[1] * c[1] + c[2] * c[2])
    check = int(A[PARAMETERS.mag_check])
    ok = True
    if (
        check & MAG_CHECK_STRENGTH
        and abs(strength - A[PARAMETERS.field_strength]) > A[PARAMETERS.mag_strength_tol_gauss]
    ):
        ok = False
    if ok and check & MAG_CHECK_INCLINATION and strength > 0.0:
        R = rotation_from_quaternion(q[0], q[1], q[2], q[3])
        wz = R[2][0] * c[0] + R[2][1] * c[1] + R[2][2] * c[2]
        inclination = math.asin(max(-1.0, min(1.0, -wz / strength)))
        ok = abs(inclination - A[PARAMETERS.field_inclination]) <= A[PARAMETERS.mag_inclination_tol_rad]
    if not ok:
        stats[source, STATS.check_rejected] += 1.0
        stats[source, STATS.last_rejected_s] = F[MEMORY.time]
    return ok


@kernel
def fuse_mag(F: Any, P: Any, ring: Any, stats: Any, W: Any, A: Any, t: float, m: Vector3) -> None:
    """Magnetometer arrived at ``t``, at most EKF2_MAG_RATE: the 3-axis field ``m = R^T m_earth +
    b_m`` (EKF2_MAG_TYPE 0) or the tilt-compensated heading (1)."""
    mag_type = int(A[PARAMETERS.mag_type])
    if mag_type == MAG_TYPE_NONE:
        return
    src = SRC_HEADING if mag_type == MAG_TYPE_HEADING else SRC_MAG
    if t < F[MEMORY.next_mag]:
        stats[src, STATS.skipped] += 1.0
        return
    F[MEMORY.next_mag] = t + A[PARAMETERS.mag_period_s] - 1e-9
    found, _, _, q, _ = state_at(F, ring, t - A[PARAMETERS.mag_delay_s])
    if not found:
        stats[src, STATS.too_old] += 1.0
        return
    if not mag_checks(F, stats, A, src, m, q):
        return
    if mag_type == MAG_TYPE_HEADING:
        H, r, y, row_group = np.zeros((1, N)), np.empty(1), np.empty(1), np.zeros(1)
        phi, theta, _ = euler_from_quaternion(q[0], q[1], q[2], q[3])
        measured = mag_heading(A, m, phi, theta, vec3(F, MEMORY.mag_bias))
        yaw_row(
            H, r, y, row_group, 0, 0, q, wrap_pi(measured - yaw_of(q)), A[PARAMETERS.heading_noise_rad] ** 2
        )
        source, gate = np.full(1, float(SRC_HEADING)), np.full(1, A[PARAMETERS.heading_gate])
        fuse(F, P, stats, W, H, r, y, row_group, source, gate, np.zeros(1))
        return
    pred, J = mag_model(q, vec3(A, PARAMETERS.field), vec3(F, MEMORY.mag_bias))
    H, r, y, row_group = np.zeros((3, N)), np.empty(3), np.empty(3), np.zeros(3)
    var = A[PARAMETERS.mag_noise_gauss] ** 2
    for i in range(3):
        H[i, ITH], H[i, ITH + 1], H[i, ITH + 2] = J[i][0], J[i][1], J[i][2]
        H[i, IBM + i] = 1.0
        r[i], y[i] = var, m[i] - pred[i]
    fuse(
        F,
        P,
        stats,
        W,
        H,
        r,
        y,
        row_group,
        np.full(1, float(SRC_MAG)),
        np.full(1, A[PARAMETERS.mag_gate]),
        np.zeros(1),
    )


@kernel
def fuse_vision(F: Any, P: Any, ring: Any, stats: Any, W: Any, A: Any, t: float, position: Vector3,
                yaw: float, position_std: float, yaw_std: float) -> None:  # fmt: skip
    """Motion capture / vision position and yaw arrived at ``t``, valid EKF2_EV_DELAY before."""
    found, pm, _, qm, D = state_at(F, ring, t - A[PARAMETERS.ev_delay_s])
    if not found:
        stats[SRC_EV_POS, STATS.too_old] += 1.0
        return
    var = ev_pos_variance(A, position_std)
    ctrl = int(A[PARAMETERS.ev_ctrl])
    H, r, y, row_group = np.zeros((4, N)), np.empty(4), np.empty(4), np.empty(4)
    group_source, group_gate = np.empty(3), np.empty(3)
    k = g = 0
    if ctrl & EV_CTRL_HPOS:
        k = position_rows(H, r, y, row_group, k, g, 0, D, position[0] - pm[0], var)
        k = position_rows(H, r, y, row_group, k, g, 1, D, position[1] - pm[1], var)
        group_source[g], group_gate[g] = SRC_EV_POS, A[PARAMETERS.ev_pos_gate]
        g += 1
    if ctrl & EV_CTRL_VPOS:
        k = position_rows(H, r, y, row_group, k, g, 2, D, position[2] - pm[2], var)
        group_source[g], group_gate[g] = SRC_EV_HGT, A[PARAMETERS.ev_pos_gate]
        g += 1
    if ctrl & EV_CTRL_YAW:
        k = yaw_row(H, r, y, row_group, k, g, qm, wrap_pi(yaw - yaw_of(qm)), ev_yaw_variance(A, yaw_std))
        group_source[g], group_gate[g] = SRC_EV_YAW, A[PARAMETERS.heading_gate]
        g += 1
    if g == 0:
        return
    accepted = np.zeros(g)
    fuse(F, P, stats, W, H[:k], r[:k], y[:k], row_group[:k], group_source[:g], group_gate[:g], accepted)
    now = F[MEMORY.time]
    for j in range(g):
        src, ok = int(group_source[j]), accepted[j] != 0.0
        if src == SRC_EV_POS:
            if ok:
                F[MEMORY.last_h_aid] = now
            else:
                target = (position[0] + F[MEMORY.p] - pm[0], position[1] + F[MEMORY.p + 1] - pm[1], 0.0)
                maybe_reset_position(F, P, stats, A, SRC_EV_POS, target, var)
        elif ok and src == SRC_EV_HGT:
            F[MEMORY.last_v_aid] = now
    check_vertical_accel(F, stats, W)


@kernel
def fuse_vision_velocity(F: Any, P: Any, ring: Any, stats: Any, W: Any, A: Any, t: float, velocity: Vector3,
                         velocity_std: float) -> None:  # fmt: skip
    """External vision velocity (world, paper frame) arrived at ``t``, valid EKF2_EV_DELAY before:
    the three axes gated together (EKF2_EVV_GATE), as PX4's EKF2 fuses ``ev_vel`` when
    EKF2_EV_CTRL bit 2 is set. Accepted, it is horizontal aiding (no dead reckoning)."""
    if not int(A[PARAMETERS.ev_ctrl]) & EV_CTRL_VEL:
        return
    found, _, vm, _, _ = state_at(F, ring, t - A[PARAMETERS.ev_delay_s])
    if not found:
        stats[SRC_EV_VEL, STATS.too_old] += 1.0
        return
    var = ev_vel_variance(A, velocity_std)
    H, r, y, row_group = np.zeros((3, N)), np.empty(3), np.empty(3), np.zeros(3)
    k = 0
    for axis in range(3):
        k = velocity_row(H, r, y, row_group, k, 0, axis, velocity[axis] - vm[axis], var)
    accepted = np.zeros(1)
    source, gate = np.full(1, float(SRC_EV_VEL)), np.full(1, A[PARAMETERS.ev_vel_gate])
    fuse(F, P, stats, W, H, r, y, row_group, source, gate, accepted)
    if accepted[0] != 0.0:
        F[MEMORY.last_h_aid] = F[MEMORY.time]
    check_vertical_accel(F, stats, W)


# =================================================================================================
# Health
# =================================================================================================
@kernel
def accuracies(P: Any) -> tuple[float, float, float, float, float]:
    """1-sigma horizontal position, vertical position, velocity, tilt and yaw of ``P``."""
    return (
        math.sqrt(max(P[0, 0] + P[1, 1], 0.0)),
        math.sqrt(max(P[2, 2], 0.0)),
        math.sqrt(max(P[3, 3] + P[4, 4] + P[5, 5], 0.0)),
        math.sqrt(max(P[6, 6] + P[7, 7], 0.0)),
        math.sqrt(max(P[8, 8], 0.0)),
    )


@kernel
def not_converged(F: Any, P: Any, A: Any) -> int:
    """Why the estimate is not fit to fly on (``CONVERGED``: it is): no aiding for EKF2_NOAID_TOUT,
    else the first 1-sigma above its EST_CONV_* threshold (tilt, yaw, horizontal position, height:
    just after the alignment the height is one GNSS fix, 0.5-1 m 1-sigma)."""
    if F[MEMORY.time] - F[MEMORY.last_h_aid] > A[PARAMETERS.no_aid_timeout_s]:
        return DEAD_RECKONING
    pos_h, pos_v, _, tilt, yaw = accuracies(P)
    if tilt > A[PARAMETERS.converged_tilt_rad]:
        return TILT
    if yaw > A[PARAMETERS.converged_yaw_rad]:
        return YAW
    if pos_h > A[PARAMETERS.converged_pos_m]:
        return POSITION
    if pos_v > A[PARAMETERS.converged_vpos_m]:
        return HEIGHT
    return CONVERGED
