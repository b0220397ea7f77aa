"""The filter's equations against their definitions: transition and measurement Jacobians
against numerical derivatives, the Joseph update against the Kalman form, the noise conversion
against PX4's per-step formula, alignment, the delayed-state buffer and the gates."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from autopilot.estimation import (
    DEFAULT_PARAMS,
    ErrorStateEkf,
    GpsFix,
    ImuSample,
    MagSample,
    VisionPose,
    estimator_params,
)
from autopilot.estimation.fusion import mag_model, yaw_jacobian, yaw_of
from autopilot.estimation.kernels import IBA, IBG, IP, ITH, IV, N
from quadcommon.rigid_body import (
    quaternion_conjugate,
    quaternion_exp,
    quaternion_from_euler,
    quaternion_multiply,
    rotation_from_quaternion,
)

pytestmark = pytest.mark.timeout(60)

G = 9.81
Q0 = quaternion_multiply(quaternion_exp(0.2, -0.3, 0.8), (1.0, 0.0, 0.0, 0.0))


def rest_force(q) -> tuple[float, float, float]:
    R = rotation_from_quaternion(*q)
    return (R[2][0] * G, R[2][1] * G, R[2][2] * G)  # R^T (0, 0, g)


# The error state up to the accelerometer bias (what these tests perturb and differentiate).
MOVING = IBA + 3


def filter_at(dx=None, params=DEFAULT_PARAMS) -> tuple[ErrorStateEkf, ImuSample]:
    """A filter reset to a moving, rotating state; ``dx`` (``MOVING``) perturbs it as the true state."""
    ekf = ErrorStateEkf(params)
    imu = ImuSample(0.0, 0.002, (0.3, -0.5, 0.7), (1.0, -0.5, 9.0))
    ekf.reset_to(imu, (1.0, 2.0, 3.0), (0.5, -0.2, 0.1), Q0)
    ekf._bg, ekf._ba = (0.01, -0.02, 0.03), (0.1, -0.2, 0.05)
    if dx is not None:
        ekf._p = tuple(np.add(ekf._p, dx[IP : IP + 3]))
        ekf._v = tuple(np.add(ekf._v, dx[IV : IV + 3]))
        ekf._q = quaternion_multiply(quaternion_exp(*dx[ITH : ITH + 3]), ekf._q)  # q_true = Exp(dth) q
        ekf._bg = tuple(np.add(ekf._bg, dx[IBG : IBG + 3]))
        ekf._ba = tuple(np.add(ekf._ba, dx[IBA : IBA + 3]))
    ekf._restart_trapezoid(imu)
    return ekf, imu


def error_between(true: ErrorStateEkf, nominal: ErrorStateEkf) -> np.ndarray:
    w, x, y, z = quaternion_multiply(true._q, quaternion_conjugate(nominal._q))
    dth = np.array((x, y, z)) * 2.0 * math.copysign(1.0, w)
    return np.concatenate([
        np.subtract(true._p, nominal._p), np.subtract(true._v, nominal._v), dth,
        np.subtract(true._bg, nominal._bg), np.subtract(true._ba, nominal._ba),
    ])  # fmt: skip


def propagated_transition(step: ImuSample) -> np.ndarray:
    """The F the covariance prediction applies (compiled or numpy), read off ``F P F^T + Q``:
    with ``P = e_j e_j^T`` the result minus Q is ``f_j f_j^T``, whose column j is ``f_j``
    (F's diagonal is 1)."""
    quiet, _ = filter_at()
    quiet.P = np.zeros((N, N))
    quiet.predict(step)
    Q = quiet.P.copy()
    F = np.zeros((N, N))
    for j in range(N):
        ekf, _ = filter_at()
        ekf.P = np.zeros((N, N))
        ekf.P[j, j] = 1.0
        ekf.predict(step)
        F[:, j] = (ekf.P - Q)[:, j]
    return F


def test_transition_matrix_is_the_jacobian_of_the_nominal_propagation():
    """F of eq. 269 (first order, Solà §7.2.3), as the covariance prediction applies it, against
    central differences of one real step."""
    dt = 0.002
    step = ImuSample(dt, dt, (0.3, -0.5, 0.7), (1.0, -0.5, 9.0))
    nominal, _ = filter_at()
    nominal.predict(step)
    F = propagated_transition(step)[:MOVING, :MOVING]
    eps = 1e-6
    numeric = np.zeros((MOVING, MOVING))
    for j in range(MOVING):
        dx = np.zeros(MOVING)
        dx[j] = eps
        plus, _ = filter_at(dx)
        plus.predict(step)
        dx[j] = -eps
        minus, _ = filter_at(dx)
        minus.predict(step)
        numeric[:, j] = (error_between(plus, nominal) - error_between(minus, nominal)) / (2 * eps)
    # What first order leaves out is O(dt^2 |a|, dt^2 |w|): below 1e-4 here.
    assert np.abs(F - numeric).max() < 1e-4
    # ... and the first-order blocks themselves are right to 1 %.
    v, theta, bg, ba = (slice(i, i + 3) for i in (IV, ITH, IBG, IBA))
    for rows, cols in ((v, theta), (v, ba), (theta, bg)):
        assert F[rows, cols] == pytest.approx(numeric[rows, cols], rel=0.01, abs=1e-6)


def test_measurement_jacobians_are_the_derivatives_of_the_models():
    field, bias = (0.21, -0.016, -0.43), (0.01, -0.02, 0.005)
    pred, H = mag_model(Q0, field, bias)
    R = np.array(rotation_from_quaternion(*Q0))
    assert pred == pytest.approx(R.T @ np.array(field) + np.array(bias))
    eps = 1e-7
    for j in range(3):
        d = [0.0, 0.0, 0.0]
        d[j] = eps
        moved = mag_model(quaternion_multiply(quaternion_exp(*d), Q0), field, bias).field_gauss
        assert [(moved[i] - pred[i]) / eps for i in range(3)] == pytest.approx(
            [H[i][j] for i in range(3)], abs=1e-6
        )
        yaw_moved = yaw_of(quaternion_multiply(quaternion_exp(*d), Q0))
        assert (yaw_moved - yaw_of(Q0)) / eps == pytest.approx(yaw_jacobian(Q0)[j], abs=1e-5)


def test_joseph_update_is_the_kalman_update_and_stays_symmetric_positive():
    """One vision fusion (x, y, z, yaw rows) against P - K S K^T and x + K y computed here."""
    params = dataclasses.replace(DEFAULT_PARAMS, ev_delay_s=0.0)
    ekf, _ = filter_at(params=params)
    rng = np.random.default_rng(3)
    A = rng.normal(size=(N, N)) * 0.05
    P = A @ A.T + np.eye(N) * 1e-4
    ekf.P = P.copy()
    H = np.zeros((4, N))
    H[0, IP] = H[1, IP + 1] = H[2, IP + 2] = 1.0
    H[3, ITH : ITH + 3] = yaw_jacobian(ekf._q)
    r = np.array([0.1**2] * 3 + [0.1**2])  # EKF2_EVP_NOISE, EKF2_EVA_NOISE floors
    y = np.array([0.001, -0.0006, 0.0004, 4e-5])
    pose = VisionPose(ekf.time_s, tuple(np.add(ekf._p, y[:3])), yaw_of(ekf._q) + y[3], 0.001, 0.001)
    p_before = np.array(ekf._p)
    ekf.fuse_vision(pose)
    S = H @ P @ H.T + np.diag(r)
    K = P @ H.T @ np.linalg.inv(S)
    assert np.abs(K @ y)[ITH : ITH + 3].max() < 1e-3  # below the 1 mrad of the attitude reset: no G here
    expected = P - K @ S @ K.T
    assert np.allclose(ekf.P, expected, rtol=1e-9, atol=1e-14)
    assert np.array(ekf._p) - p_before == pytest.approx((K @ y)[IP : IP + 3], rel=1e-9, abs=1e-14)
    assert np.abs(ekf.P - ekf.P.T).max() < 1e-15
    assert np.linalg.eigvalsh(ekf.P).min() > 0.0
    assert {k: ekf.sources[k].fused for k in ("ev_pos", "ev_hgt", "ev_yaw")} == dict.fromkeys(
        ("ev_pos", "ev_hgt", "ev_yaw"), 1
    )


@pytest.mark.parametrize("predict_us", [10000, 20000])
def test_px4_noise_parameters_mean_the_same_variance_per_second(predict_us):
    """PX4 adds (dt * EKF2_GYR_NOISE)^2 per EKF2_PREDICT_US prediction; at 500 Hz this filter
    must add the same per second, and likewise for the accelerometer and the biases."""
    params = estimator_params({"EKF2_PREDICT_US": predict_us})
    ekf = ErrorStateEkf(params)
    imu = ImuSample(0.0, 0.002, (0.0, 0.0, 0.0), rest_force((1.0, 0.0, 0.0, 0.0)))
    ekf.reset_to(imu, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0))
    ekf.P[:] = 0.0  # what grows is then the process noise alone
    P0 = ekf.P.copy()
    for k in range(1, 501):  # 1 s at 500 Hz
        ekf.predict(ImuSample(k * 0.002, 0.002, imu.angular_rate_rad_s, imu.specific_force_m_s2))
    grew = np.diag(ekf.P) - np.diag(P0)
    px4_steps = 1e6 / predict_us
    px4_dt = predict_us * 1e-6
    gyro_rate = px4_steps * (px4_dt * 0.015) ** 2  # variance per second
    bias_rate = px4_steps * (px4_dt * 0.001) ** 2
    # Yaw: the gyro noise, plus the gyro bias random walk integrated twice (bias_rate t^3 / 3).
    assert grew[8] == pytest.approx(gyro_rate + bias_rate / 3.0, rel=1e-3)
    # Bias variances: PX4 adds (dt * EKF2_*_B_NOISE)^2 per prediction.
    assert grew[9] == pytest.approx(bias_rate, rel=1e-6)
    assert grew[14] == pytest.approx(px4_steps * (px4_dt * 0.003) ** 2, rel=1e-6)


def static_run(
    ekf: ErrorStateEkf, q, seconds: float, *, t0=0.0, gps=True, mag=True, vision=False, field=None
):
    """Feed a vehicle at rest (exact sensors) for ``seconds``; GPS at 10 Hz, mag at 50 Hz."""
    f = rest_force(q)
    field = field or ekf.earth_field
    R = np.array(rotation_from_quaternion(*q))
    m_body = tuple(R.T @ np.array(field))
    n = round(seconds * 500)
    for k in range(n):
        t = t0 + k * 0.002
        ekf.predict(ImuSample(t, 0.002, (0.0, 0.0, 0.0), f))
        if gps and k % 50 == 0:
            ekf.fuse_gps(GpsFix(t, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.5, 0.8, 0.1))
        if mag and k % 10 == 0:
            ekf.fuse_mag(MagSample(t, m_body))
        if vision and k % 5 == 0:
            ekf.fuse_vision(VisionPose(t, (0.0, 0.0, 0.0), yaw_of(q), 0.001, 0.001))
    return t0 + n * 0.002


def test_alignment_at_rest_gives_tilt_and_heading_then_converges():
    q = quaternion_from_euler(0.05, -0.08, 2.0)
    ekf = ErrorStateEkf()
    status = ekf.status()
    assert not status.initialised and not status.converged and status.reason.startswith("aligning")
    t = static_run(ekf, q, 0.5)
    assert not ekf.initialised and "at rest for 0.5 s of 1.0 s" in ekf.status().reason
    t = static_run(ekf, q, 0.6, t0=t)
    assert ekf.initialised
    est = ekf.estimate()
    assert est.euler_rad == pytest.approx((0.05, -0.08, 2.0), abs=1e-6)  # exact sensors
    # The height is one fix (epv 0.8 m) so far: not fit to arm on until a few more have come.
    assert not ekf.status().converged and "vertical position not converged" in ekf.status().reason
    static_run(ekf, q, 1.0, t0=t)
    assert ekf.status().pos_vert_accuracy_m <= ekf.params.converged_vpos_m
    assert ekf.status().converged and ekf.status().reason == ""


def test_alignment_says_what_it_waits_for():
    q = quaternion_from_euler(0.0, 0.0, 0.3)
    no_position = ErrorStateEkf()
    static_run(no_position, q, 1.5, gps=False)
    assert not no_position.initialised and "waiting for a position source" in no_position.status().reason
    no_heading = ErrorStateEkf(estimator_params({"EKF2_MAG_TYPE": 5}))
    static_run(no_heading, q, 1.5)
    assert not no_heading.initialised and "waiting for a heading source" in no_heading.status().reason
    moving = ErrorStateEkf()
    for k in range(600):  # rotating at 0.5 rad/s: not at rest
        moving.predict(ImuSample(k * 0.002, 0.002, (0.0, 0.0, 0.5), rest_force(q)))
    assert not moving.initialised and "not at rest" in moving.status().reason
    # Vision yaw is a heading source too (the magnetometer off).
    vision = ErrorStateEkf(estimator_params({"EKF2_MAG_TYPE": 5}))
    static_run(vision, q, 1.5, gps=False, vision=True)
    assert vision.initialised and vision.estimate().euler_rad[2] == pytest.approx(0.3, abs=1e-9)
    # A source whose aiding is off is no position source: vision with EKF2_EV_CTRL 0, GNSS with
    # EKF2_GPS_CTRL 0 (the reason says none is enabled).
    off = ErrorStateEkf(estimator_params({"EKF2_EV_CTRL": 0, "EKF2_GPS_CTRL": 0}))
    static_run(off, q, 1.5, vision=True)
    assert not off.initialised
    assert off.status().reason.endswith("position source (none enabled (EKF2_GPS_CTRL, EKF2_EV_CTRL))")
    vision_off = ErrorStateEkf(estimator_params({"EKF2_EV_CTRL": 0}))
    static_run(vision_off, q, 1.5, gps=False, vision=True)
    assert not vision_off.initialised and "(a GPS 3D fix with eph <= 3 m" in vision_off.status().reason


def test_tilt_error_of_the_alignment_is_correlated_with_the_accelerometer_bias():
    """At rest a bias b reads as a tilt: g dth_y = (R b)_x, g dth_x = -(R b)_y. The alignment's
    covariance must say so, or the filter would believe a tilt it cannot observe."""
    q = quaternion_from_euler(0.0, 0.0, 0.5)
    bias = np.array((0.1, 0.05, 0.0))
    ekf = ErrorStateEkf()
    f = tuple(np.add(rest_force(q), bias))
    m_body = tuple(np.array(rotation_from_quaternion(*q)).T @ np.array(ekf.earth_field))
    k = 0
    while not ekf.initialised:  # stop at the alignment itself
        t = k * 0.002
        ekf.predict(ImuSample(t, 0.002, (0.0, 0.0, 0.0), f))
        if k % 50 == 0:
            ekf.fuse_gps(GpsFix(t, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.5, 0.8, 0.1))
        if k % 10 == 0:
            ekf.fuse_mag(MagSample(t, m_body))
        k += 1
    w, x, y, z = quaternion_multiply(q, quaternion_conjugate(ekf.estimate().quaternion))
    tilt_error = np.array((x, y)) * 2.0
    P = ekf.P
    tilt, ba = slice(ITH, ITH + 2), slice(IBA, IBA + 3)
    regression = P[tilt, ba] @ np.linalg.inv(P[ba, ba])  # E[dth | db] = C db
    # To 5 %: the heading taken from the tilted field carries a yaw error that rotates it slightly.
    assert tilt_error == pytest.approx(regression @ bias, abs=5e-4)
    assert np.linalg.norm(tilt_error) == pytest.approx(np.linalg.norm(bias[:2]) / G, rel=0.05)


def test_a_delayed_fix_is_fused_against_the_state_it_was_valid_for():
    """Flying at 2 m/s with fixes 0.2 s late: with EKF2_GPS_DELAY = 200 ms the estimate stays on
    the truth; declared as 0 ms, the filter is pulled about v * 0.2 s = 0.4 m behind."""

    def fly(delay_ms: float) -> float:
        params = estimator_params({"EKF2_GPS_DELAY": delay_ms, "EKF2_MAG_TYPE": 5, "EKF2_BARO_CTRL": 0})
        ekf = ErrorStateEkf(params)
        v = (2.0, 0.0, 0.0)
        f = rest_force((1.0, 0.0, 0.0, 0.0))
        ekf.reset_to(ImuSample(0.0, 0.002, (0.0, 0.0, 0.0), f), (0.0, 0.0, 0.0), v, (1.0, 0.0, 0.0, 0.0))
        for k in range(1, 5001):  # 10 s
            t = k * 0.002
            ekf.predict(ImuSample(t, 0.002, (0.0, 0.0, 0.0), f))
            if k % 50 == 0 and t >= 0.2:
                valid = t - 0.2
                ekf.fuse_gps(GpsFix(t, (2.0 * valid, 0.0, 0.0), v, 0.5, 0.8, 0.1))
        return ekf.estimate().position_m[0] - 2.0 * 10.0

    assert abs(fly(200.0)) < 0.01
    assert fly(0.0) < -0.25


def test_gates_reject_and_count_an_outlier_and_leave_the_state_alone():
    q = quaternion_from_euler(0.0, 0.0, 0.3)
    ekf = ErrorStateEkf(estimator_params({"EKF2_EV_DELAY": 0.0}))
    t = static_run(ekf, q, 3.0, gps=False, vision=True)
    before = ekf.estimate().position_m
    ekf.fuse_vision(VisionPose(t, (1.0, 0.0, 0.0), yaw_of(q), 0.001, 0.001))  # 1 m off in x
    stats = ekf.sources["ev_pos"]
    assert stats.rejected == 1 and stats.test_ratio > 1.0
    assert ekf.sources["ev_hgt"].rejected == 0  # the height and yaw of the same pose are fine
    assert ekf.estimate().position_m[0] == pytest.approx(before[0], abs=1e-4)
    # A sample just inside the gate (4 sigma of a 5 sigma gate) is fused.
    sigma = math.sqrt(ekf.P[IP, IP] + 0.1**2)
    ekf.fuse_vision(VisionPose(t, (before[0] + 4.0 * sigma, before[1], before[2]), yaw_of(q), 0.001, 0.001))
    assert stats.fused > 0 and stats.rejected == 1 and 0.5 < stats.test_ratio < 1.0


def test_a_long_run_of_rejections_resets_to_the_source():
    """PX4's behaviour: a good source rejected for EST_POS_RST_T means the filter is wrong."""
    q = quaternion_from_euler(0.0, 0.0, 0.3)
    ekf = ErrorStateEkf(estimator_params({"EKF2_EV_DELAY": 0.0, "EST_POS_RST_T": 2.0}))
    t = static_run(ekf, q, 2.0, gps=False, vision=True)
    f = rest_force(q)
    for k in range(1, 1501):  # the vehicle was moved 3 m east (-y) by hand: 3 s of new poses
        tt = t + k * 0.002
        ekf.predict(ImuSample(tt, 0.002, (0.0, 0.0, 0.0), f))
        if k % 5 == 0:
            ekf.fuse_vision(VisionPose(tt, (0.0, -3.0, 0.0), yaw_of(q), 0.001, 0.001))
    stats = ekf.sources["ev_pos"]
    assert stats.resets == 1 and 195 <= stats.rejected <= 205  # 2 s of rejections at 100 Hz first
    assert ekf.estimate().position_m[1] == pytest.approx(-3.0, abs=0.01)


def test_status_before_and_after_initialisation():
    ekf = ErrorStateEkf()
    status = ekf.status()
    assert status.flags == 0 and math.isinf(status.pos_horiz_accuracy_m)
    static_run(ekf, quaternion_from_euler(0.0, 0.0, 0.3), 1.5)
    status = ekf.status()
    assert status.initialised and status.flags & 1  # ESTIMATOR_ATTITUDE
    assert status.flags & 16 and status.flags & 32  # absolute horizontal (GPS) and vertical position
    assert 0.0 < status.pos_horiz_accuracy_m < 1.0 and status.sources["gps_pos"].fused >= 1


@pytest.mark.parametrize("ctrl", [15, 11])
def test_vision_velocity_is_fused_only_with_ekf2_ev_ctrl_bit_2_and_gated(ctrl):
    """A client's vision velocity (ODOMETRY's twist) with the pose: fused as ``ev_vel`` when
    EKF2_EV_CTRL has bit 2 (PX4's), within EKF2_EVV_GATE; with the bit cleared, never."""
    q = quaternion_from_euler(0.0, 0.0, 0.3)
    ekf = ErrorStateEkf(estimator_params({"EKF2_EV_DELAY": 0.0, "EKF2_EV_CTRL": ctrl}))
    t = static_run(ekf, q, 3.0, gps=False, vision=True)
    f = rest_force(q)
    for k in range(1, 501):  # 1 s at rest, the pose and a zero velocity at 100 Hz
        tt = t + k * 0.002
        ekf.predict(ImuSample(tt, 0.002, (0.0, 0.0, 0.0), f))
        if k % 5 == 0:
            ekf.fuse_vision(VisionPose(tt, (0.0, 0.0, 0.0), yaw_of(q), 0.001, 0.001, (0.0, 0.0, 0.0), 0.02))
    stats = ekf.sources["ev_vel"]
    if not ctrl & 4:
        assert stats.fused == 0 and stats.rejected == 0
        return
    assert stats.fused == 100 and stats.rejected == 0
    before = ekf.estimate().velocity_m_s
    # 2 m/s off: far outside 3 sigma of the velocity's uncertainty and the 0.1 m/s noise floor
    ekf.fuse_vision(VisionPose(tt, (0.0, 0.0, 0.0), yaw_of(q), 0.001, 0.001, (2.0, 0.0, 0.0), 0.02))
    assert stats.rejected == 1 and stats.test_ratio > 1.0
    assert ekf.estimate().velocity_m_s == pytest.approx(before, abs=1e-3)
    status = ekf.status()
    assert status.vel_ratio == pytest.approx(stats.test_ratio)  # ESTIMATOR_STATUS's velocity ratio


def test_the_estimate_follows_the_filter():
    """After a prediction, or a state written directly, the estimate is read anew (the filter's
    floats decide, nothing cached)."""
    ekf, imu = filter_at()
    first = ekf.estimate()
    ekf.predict(ImuSample(0.002, 0.002, imu.angular_rate_rad_s, imu.specific_force_m_s2))
    moved = ekf.estimate()
    assert moved.time_s == pytest.approx(0.002)
    assert moved.position_m != first.position_m
    ekf._p = (9.0, 9.0, 9.0)
    assert ekf.estimate().position_m == (9.0, 9.0, 9.0)
