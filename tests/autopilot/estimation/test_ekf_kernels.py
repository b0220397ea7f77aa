"""The filter's steps as kernels (autopilot/estimation/filter.py, fusion.py, checks.py): the class is
their shell, and the compiled entries run the same function as Python does."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from autopilot.estimation import filter as fk
from autopilot.estimation.aiding import NO_AIDING
from autopilot.estimation.eskf import (
    DEFAULT_EARTH_FIELD_WORLD_GAUSS,
    ErrorStateEkf,
    filter_entries,
    filter_kernels,
)
from autopilot.estimation.parameters import DEFAULT_PARAMS, estimator_params
from autopilot.records import BaroSample, GpsFix, ImuSample, MagSample, VisionPose
from quadcommon.kernel import compiling
from quadcommon.rigid_body import quaternion_from_euler, rotation_from_quaternion

pytestmark = pytest.mark.timeout(120)

DT = 0.002
G = 9.81


def flight(steps: int = 1500):
    """A made-up flight: a slow turn with a climb; per step the IMU sample and what else arrives
    (GNSS every 50 steps, baro and magnetometer every 10, vision every 5), noisy."""
    rng = np.random.default_rng(7)
    out = []
    for k in range(steps):
        t = k * DT
        yaw = 0.2 * t
        q = quaternion_from_euler(0.02, -0.01, yaw)
        R = np.array(rotation_from_quaternion(*q))
        position = (math.cos(0.2 * t), math.sin(0.2 * t), 1.0 + 0.1 * t)
        velocity = (-0.2 * math.sin(0.2 * t), 0.2 * math.cos(0.2 * t), 0.1)
        accel = np.array((-0.04 * math.cos(0.2 * t), -0.04 * math.sin(0.2 * t), G))
        force = tuple(R.T @ accel + rng.normal(0.0, 0.02, 3))
        rate = tuple(np.array((0.0, 0.0, 0.2)) + rng.normal(0.0, 0.003, 3))
        field = tuple(R.T @ np.array(DEFAULT_EARTH_FIELD_WORLD_GAUSS) + rng.normal(0.0, 0.003, 3))
        frame = {"imu": ImuSample(t, DT, rate, force)}
        if k % 10 == 0:
            frame["mag"] = MagSample(t, field)
            frame["baro"] = BaroSample(t, position[2] + 2.0 + rng.normal(0.0, 0.1))
        if k % 50 == 25:
            noisy = tuple(np.add(position, rng.normal(0.0, 0.3, 3)))
            frame["gps"] = GpsFix(t, noisy, tuple(np.add(velocity, rng.normal(0.0, 0.05, 3))), 0.3, 0.5, 0.05)
        if k % 5 == 0:
            pose = tuple(np.add(position, rng.normal(0.0, 0.01, 3)))
            frame["vision"] = VisionPose(t, pose, yaw + rng.normal(0.0, 0.01), 0.01, 0.01)
        if k == 700:  # a GPS glitch the gate refuses
            frame["gps"] = GpsFix(t, tuple(np.add(position, (20.0, 0.0, 0.0))), velocity, 0.3, 0.5, 0.05)
        out.append(frame)
    return out


def fly_kernels(entries, params, frames):
    """The filter's memory after ``frames``, driven by calling ``entries`` directly."""
    memory = fk.new_memory()
    F, P, ring = memory.state, memory.covariance, memory.ring
    A = fk.parameter_array(params, G, DEFAULT_EARTH_FIELD_WORLD_GAUSS)
    first = frames[0]["imu"]
    q0 = quaternion_from_euler(0.02, -0.01, 0.0)
    entries.reset_state(F, P, A, (1.0, 0.0, 1.0), (0.0, 0.2, 0.1), q0, 0.1, 0.1, 0.0)
    entries.start(F, ring, first.time_s, first.dt_s, first.angular_rate_rad_s, first.specific_force_m_s2)
    F[fk.MEMORY.imu_samples] += 1.0  # the class counts the sample it starts at
    for frame in frames[1:]:
        imu = frame["imu"]
        entries.predict_step(
            F, P, ring, A, imu.time_s, imu.dt_s, imu.angular_rate_rad_s, imu.specific_force_m_s2
        )
        aiding = NO_AIDING  # the frame's samples in one call, in PX4's order (.aiding.fuse_frame)
        if "mag" in frame:
            aiding = aiding._replace(mag_fresh=True, mag_gauss=tuple(frame["mag"].field_gauss))
        if "baro" in frame:
            aiding = aiding._replace(baro_fresh=True, baro_height_m=frame["baro"].height_m)
        if "gps" in frame:
            g = frame["gps"]
            aiding = aiding._replace(gps_fresh=True, gps_position_m=tuple(g.position_m),
                                     gps_velocity_m_s=tuple(g.velocity_m_s),
                                     gps_accuracy=(g.eph_m, g.epv_m, g.speed_accuracy_m_s),
                                     gps_fix=(3.0, 10.0))  # fmt: skip
        if "vision" in frame:
            v = frame["vision"]
            aiding = aiding._replace(vision_fresh=True, vision_position_m=tuple(v.position_m),
                                     vision_yaw_rad=v.yaw_rad,
                                     vision_std=(v.position_std_m, v.yaw_std_rad))  # fmt: skip
        if aiding is not NO_AIDING:
            entries.fuse_frame(tuple(memory), A, imu.time_s, tuple(aiding))
    return F, P, memory.stats, int(entries.not_converged(F, P, A))


def fly_class(params, frames) -> ErrorStateEkf:
    ekf = ErrorStateEkf(params, gravity_m_s2=G)
    first = frames[0]["imu"]
    ekf.reset_to(first, (1.0, 0.0, 1.0), (0.0, 0.2, 0.1), quaternion_from_euler(0.02, -0.01, 0.0))
    for frame in frames[1:]:
        ekf.predict(frame["imu"])
        if "mag" in frame:
            ekf.fuse_mag(frame["mag"])
        if "baro" in frame:
            ekf.fuse_baro(frame["baro"])
        if "gps" in frame:
            ekf.fuse_gps(frame["gps"])
        if "vision" in frame:
            ekf.fuse_vision(frame["vision"])
    return ekf


# EKF2_EV_CTRL 15 fuses vision position, height and yaw beside the GNSS; EKF2_MAG_TYPE 1 the heading.
PROFILES = {
    "gps+baro+mag": DEFAULT_PARAMS,
    "with vision": estimator_params({"EKF2_EV_CTRL": 11}),
    "heading": estimator_params({"EKF2_MAG_TYPE": 1, "EKF2_EV_CTRL": 11}),
}


@pytest.mark.parametrize("profile", sorted(PROFILES))
def test_the_class_is_a_shell_around_the_kernels(profile):
    """ErrorStateEkf's state, covariance and counters are those of the kernels called directly
    (bit for bit: the same entries on the same arrays), and every kind of fusion ran."""
    params, frames = PROFILES[profile], flight()
    F, P, stats, verdict = fly_kernels(filter_entries(), params, frames)
    ekf = fly_class(params, frames)
    assert np.array_equal(ekf._F, F)
    assert np.array_equal(ekf.P, P)
    assert np.array_equal(ekf._stats, stats)
    assert ekf.status().converged == (verdict == fk.CONVERGED)
    fused = {name: row.fused for name, row in ekf.sources.items()}
    assert fused["gps_pos"] > 20 and fused["baro"] > 40
    assert fused["mag" if params.mag_type == 0 else "heading"] > 30
    if params.ev_ctrl:
        assert fused["ev_pos"] > 200 and fused["ev_yaw"] > 200
    assert ekf.sources["gps_pos"].rejected >= 1  # the glitch
    truth = (math.cos(0.2 * 2.998), math.sin(0.2 * 2.998), 1.0 + 0.1 * 2.998)
    assert np.linalg.norm(np.subtract(ekf.estimate().position_m, truth)) < 0.3


@pytest.mark.skipif(not compiling(), reason="numba is not available: nothing compiles")
def test_compiled_and_python_run_one_source():
    """The compiled entries and the plain functions (what QUADSITL_PURE_PYTHON=1 runs) give the
    same filter to round-off (the same source; numba may contract a multiply-add)."""
    params, frames = PROFILES["with vision"], flight(600)
    Fc, Pc, sc, vc = fly_kernels(filter_entries(), params, frames)
    Fp, Pp, sp, vp = fly_kernels(filter_kernels(), params, frames)
    assert vc == vp
    assert np.array_equal(sc[:, fk.STATS.fused], sp[:, fk.STATS.fused])
    assert np.array_equal(sc[:, fk.STATS.rejected], sp[:, fk.STATS.rejected])
    finite = np.isfinite(Fp)
    assert np.array_equal(finite, np.isfinite(Fc))
    assert np.allclose(Fc[finite], Fp[finite], rtol=1e-9, atol=1e-12)
    assert np.allclose(Pc, Pp, rtol=1e-8, atol=1e-15)


def test_the_parameter_array_covers_every_parameter():
    """Each EstimatorParams field has its slot (a parameter the kernels did not read would be a
    parameter the batch engine silently ignores)."""
    params = estimator_params({"EKF2_GPS_DELAY": 123.0, "EKF2_EVP_GATE": 4.5, "EST_CONV_VPOS": 0.7})
    A = fk.parameter_array(params, G, DEFAULT_EARTH_FIELD_WORLD_GAUSS)
    assert A[fk.PARAMETERS.gps_delay_s] == pytest.approx(0.123)
    assert A[fk.PARAMETERS.ev_pos_gate] == 4.5 and A[fk.PARAMETERS.converged_vpos_m] == 0.7
    for field in dataclasses.fields(params):
        assert A[getattr(fk.PARAMETERS, field.name)] == float(getattr(params, field.name)), field.name
