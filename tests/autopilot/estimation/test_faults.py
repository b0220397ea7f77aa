"""Faults on the helix with the ``gps`` profile (see test_helix): each injected by the sensor
models 15 s into the helix, and handled as docs/estimation.md states."""

from __future__ import annotations

import math

import numpy as np
import pytest

from autopilot.estimation import load_estimator_params
from autopilot.estimation.kernels import IP
from autopilot.estimation.status import ESTIMATOR_ACCEL_ERROR, ESTIMATOR_GPS_GLITCH
from simulator.sensors import SensorFault, load_sensors

from .helpers import helix_truth, run_filter

pytestmark = pytest.mark.timeout(120)

PRE_S = 10.0
T_FAULT = PRE_S + 15.0


def fly(*faults: SensorFault, after_s: float = 15.0, status_every_s: float = 0.1):
    return run_filter(
        helix_truth(40.0, PRE_S), load_sensors("gps"), load_estimator_params("gps"), faults=faults,
        until_s=T_FAULT + after_s, status_every_s=status_every_s, nees_every=5,
    )  # fmt: skip


def window(r, t0: float, t1: float) -> slice:
    return slice(r.at(t0), r.at(t1))


def statuses(r, t0: float, t1: float):
    return [s for t, s in r.statuses if t0 <= t < t1]


def test_gps_glitch_of_10_m_for_2_s_is_rejected_by_the_gate():
    r = fly(SensorFault("gps_glitch", T_FAULT, 2.0, (10.0, 0.0, 0.0)))
    stats = r.ekf.status().sources["gps_pos"]
    assert 19 <= stats.rejected <= 21  # the 20 fixes of the glitch, and only those
    assert stats.resets == 0
    err = np.linalg.norm(r.pos_err, axis=1)
    assert err[window(r, T_FAULT, T_FAULT + 3.0)].max() < 0.4  # velocity fusion holds the position
    during = statuses(r, T_FAULT + 0.5, T_FAULT + 2.0)
    assert all(s.flags & ESTIMATOR_GPS_GLITCH and s.gps_glitch and s.converged for s in during)
    assert not any(s.gps_glitch for s in statuses(r, T_FAULT + 3.5, T_FAULT + 15.0))
    assert err[window(r, T_FAULT + 5.0, T_FAULT + 15.0)].max() < 0.3


def test_gps_outage_of_10_s_drifts_boundedly_and_recovers():
    r = fly(SensorFault("gps_outage", T_FAULT, 10.0), after_s=20.0)
    err = np.linalg.norm(r.pos_err, axis=1)
    out = window(r, T_FAULT, T_FAULT + 10.0)
    sigma = np.linalg.norm(r.sigma[:, IP : IP + 3], axis=1)
    end_sigma = sigma[r.at(T_FAULT + 9.99)]
    print(f"outage: largest error {err[out].max():.2f} m, 1-sigma at its end {end_sigma:.2f} m")
    assert err[out].max() < 2.0  # dead reckoning on IMU, baro and compass
    assert np.all(err[out] < 3.0 * sigma[out])  # ... and the filter knows how far it may be off
    assert sigma[r.at(T_FAULT + 9.99)] > 3.0 * sigma[r.at(T_FAULT - 0.01)]
    # EKF2_NOAID_TOUT (5 s) later it says so: not converged, no horizontal position.
    late = statuses(r, T_FAULT + 5.5, T_FAULT + 10.0)
    assert late and all(s.dead_reckoning and not s.converged and "dead reckoning" in s.reason for s in late)
    assert not any(s.flags & 8 for s in late)  # ESTIMATOR_POS_HORIZ_REL cleared
    # Recovery: the fixes are accepted again (no reset needed) and the error is back within seconds.
    stats = r.ekf.status().sources["gps_pos"]
    assert stats.resets == 0 and stats.rejected == 0 and stats.check_rejected == 100
    assert err[window(r, T_FAULT + 13.0, T_FAULT + 20.0)].max() < 0.3
    assert all(s.converged for s in statuses(r, T_FAULT + 13.0, T_FAULT + 20.0))


def test_magnetometer_disturbance_is_gated_out_and_the_heading_holds():
    r = fly(SensorFault("mag_disturbance", T_FAULT, 5.0, (0.0, 0.3, 0.0)))  # 0.3 G on the body y axis
    mag = r.ekf.status().sources["mag"]
    assert 245 <= mag.rejected <= 251  # the 50 Hz samples of the 5 s, gated out (3 sigma)
    yaw = np.degrees(np.abs(r.att_err[:, 2]))
    before = yaw[window(r, T_FAULT - 5.0, T_FAULT)].max()
    assert yaw[window(r, T_FAULT, T_FAULT + 15.0)].max() < max(1.0, 2.0 * before)
    assert mag.last_fused_s > T_FAULT + 5.0  # fused again afterwards


def test_imu_bias_step_is_learned():
    """A 20 mg vertical accelerometer step and 0.57 deg/s gyro steps (roll and yaw axes): the
    vertical innovations turn consistent, the bad-acceleration check (PX4's bad_acc_vertical)
    lets the bias state move, and the new biases are learned."""
    r = fly(
        SensorFault("accel_bias_step", T_FAULT, math.inf, (0.0, 0.0, 0.2)),
        SensorFault("gyro_bias_step", T_FAULT, math.inf, (0.01, 0.0, 0.01)),
    )
    assert r.ekf.bad_accel_detections >= 1
    assert any(s.flags & ESTIMATOR_ACCEL_ERROR for s in statuses(r, T_FAULT, T_FAULT + 6.0))
    assert not any(s.flags & ESTIMATOR_ACCEL_ERROR for s in statuses(r, T_FAULT - 10.0, T_FAULT))
    at = r.at(T_FAULT + 10.0)
    ba, bg = r.accel_bias_err[at], r.gyro_bias_err[at]
    print(
        f"10 s after the step: accel z bias error {ba[2]:.3f} m/s^2 (step 0.2),",
        f"gyro x, z {bg[0]:.4f}, {bg[2]:.4f} rad/s (step 0.01)",
    )
    assert abs(r.accel_bias_err[at, 2]) < 0.03
    assert abs(r.gyro_bias_err[at, 0]) < 1e-3 and abs(r.gyro_bias_err[at, 2]) < 2e-3
    err = np.linalg.norm(r.pos_err, axis=1)
    assert err[window(r, T_FAULT, T_FAULT + 15.0)].max() < 0.5
    assert np.degrees(np.linalg.norm(r.att_err[window(r, T_FAULT, T_FAULT + 15.0)], axis=1)).max() < 2.0
