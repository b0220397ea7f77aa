"""The stuck checks (commander/health.py): a sensor whose value repeats exactly is called stuck only
when the vehicle moved in a way that must have changed it. A noise-free sensor repeats its value
legitimately (at rest, at touchdown), so what counts as "moved" is per sensor: the accelerometer's
specific force turns with the tilt (not with the heading), and the speed the filter integrates
from it changes with it; the gyro's body rates change with a turn (a translation leaves them at
zero). The repeat is paired with the pose of the frame it was seen in (at touchdown: at rest)."""

from __future__ import annotations

import math
from typing import NamedTuple

import pytest

from autopilot.commander.health import EQUAL_COUNT_MAX, HealthMonitor, LinkState
from autopilot.params.definitions import default_parameters
from autopilot.records import STREAM_IMU, SensorSamples

pytestmark = pytest.mark.timeout(30)
IMU_DT = 0.002


class Pose(NamedTuple):
    position_m: tuple[float, float, float]
    velocity_m_s: tuple[float, float, float]
    euler_rad: tuple[float, float, float]


def health_after(poses, gyro=(0.0, 0.0, 0.0), accel=(0.0, 0.0, 9.81), airborne=True) -> dict[str, str]:
    """Feed IMU samples that never change while the vehicle goes through ``poses`` (one per frame);
    the accelerometer's and gyro's health at the end (problem, "" when healthy), judged with the
    vehicle ``airborne`` or on the ground."""
    monitor = HealthMonitor(default_parameters())
    samples = SensorSamples(gyro, accel, None, None, None, None)
    t = 0.0
    for pose in poses:
        monitor.observe(t, STREAM_IMU, samples, pose)
        t += IMU_DT
    flags = monitor.evaluate(t, None, False, True, LinkState(), airborne=airborne)
    return {"gyro": flags.gyro.problem, "accel": flags.accel.problem}


FRAMES = 4 * EQUAL_COUNT_MAX  # well past PX4's count of equal values


def ramp(f) -> list[Pose]:
    return [f(k / FRAMES) for k in range(FRAMES)]


def test_a_touchdown_is_no_evidence_a_change_of_speed_is_for_the_accelerometer_only():
    """On the ground (landed) a change of speed is the estimate's, not the vehicle's: the EKF's
    velocity settling from the landing speed to 0 while a noise-free IMU repeats its values is no
    evidence. In the air a change of speed of 3 m/s must have changed the accelerometer's value
    (the filter integrates it), not the gyro's."""
    settling = ramp(lambda s: Pose((0.0, 0.0, 0.0), (0.0, 0.0, -0.7 * (1.0 - s)), (0.0, 0.0, 0.0)))
    assert health_after(settling, airborne=False) == {"gyro": "", "accel": ""}
    assert health_after(settling) == {"gyro": "", "accel": "stuck"}  # (the same motion in the air)
    speeding = ramp(lambda s: Pose((0.0, 0.0, 2.0 + s), (0.0, 0.0, 3.0 * s), (0.0, 0.0, 0.0)))
    assert health_after(speeding) == {"gyro": "", "accel": "stuck"}


def test_a_turn_of_heading_leaves_the_accelerometer_but_not_the_gyro_unchanged():
    turning = ramp(lambda s: Pose((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, math.radians(30.0) * s)))
    assert health_after(turning) == {"gyro": "stuck", "accel": ""}


def test_a_tilt_must_change_both():
    tilting = ramp(lambda s: Pose((0.0, 0.0, 2.0), (0.0, 0.0, 0.0), (math.radians(10.0) * s, 0.0, 0.0)))
    assert health_after(tilting) == {"gyro": "stuck", "accel": "stuck"}
