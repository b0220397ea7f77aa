"""Reference trajectories: analytic derivatives and the smooth segment."""

import math

import numpy as np
import pytest

from quadcommon.config import load_scenario
from quadcommon.trajectories import (
    PiecewiseTrajectory,
    QuinticSegment,
    circle,
    helix,
    trajectory_from_spec,
)


def finite_difference_check(traj, times, h=1e-5):
    for t in times:
        r, rp, rm = traj.sample(t), traj.sample(t + h), traj.sample(t - h)
        v_fd = (np.array(rp.position_m) - rm.position_m) / (2 * h)
        a_fd = (np.array(rp.velocity_m_s) - rm.velocity_m_s) / (2 * h)
        assert np.allclose(r.velocity_m_s, v_fd, atol=1e-7)
        assert np.allclose(r.acceleration_m_s2, a_fd, atol=1e-7)


def test_paper_circle_is_the_printed_curve():
    traj = trajectory_from_spec(load_scenario("circle").trajectory)
    for t in (0.0, 7.3, 20.0, 33.1):
        w = math.pi / 20
        expected = (0.5 * math.cos(w * t), 0.5 * math.sin(w * t), 2.5 - 2 * math.cos(w * t))
        assert traj.sample(t).position_m == pytest.approx(expected, abs=1e-12)
    finite_difference_check(traj, np.linspace(0, 40, 9))


def test_helix_passes_through_its_start_point():
    traj = trajectory_from_spec(load_scenario("helix").trajectory)
    assert traj.sample(0.0).position_m == pytest.approx((0.5, 0.0, 1.0))
    assert traj.sample(10.0).position_m[2] == pytest.approx(2.0)
    finite_difference_check(helix(0.5, 0.5, (0, 0, 1), 0.1), np.linspace(0, 40, 9))


def test_circle_factory_derivatives():
    finite_difference_check(circle(1.0, 0.7, (1, 2, 3), 0.5, 0.2), [0.1, 1.3, 5.0])


def test_quintic_segment_meets_boundary_conditions():
    seg = QuinticSegment(
        4.0,
        (0, 0, 1),
        (3, -2, 2),
        v0=(0.5, 0, 0),
        v1=(0, 0.2, 0),
        a0=(0, 0, 0.1),
        yaw0=3.0,
        yaw1=-3.0,
    )
    start, end = seg.sample(0.0), seg.sample(4.0)
    assert start.position_m == pytest.approx((0, 0, 1))
    assert start.velocity_m_s == pytest.approx((0.5, 0, 0))
    assert start.acceleration_m_s2 == pytest.approx((0, 0, 0.1))
    assert end.position_m == pytest.approx((3, -2, 2))
    assert end.velocity_m_s == pytest.approx((0, 0.2, 0))
    assert end.acceleration_m_s2 == pytest.approx((0, 0, 0), abs=1e-12)
    # yaw takes the short way across +-pi
    mid = seg.sample(2.0).yaw_rad
    assert abs(mid) == pytest.approx(math.pi, abs=1e-9)
    finite_difference_check(seg, [0.5, 1.7, 3.2])


def test_piecewise_trajectory_is_continuous_and_holds_at_the_end():
    a = QuinticSegment(2.0, (0, 0, 0), (1, 0, 0))
    b = QuinticSegment(3.0, (1, 0, 0), (1, 2, 0))
    traj = PiecewiseTrajectory([a, b])
    assert traj.duration_s == 5.0
    assert traj.sample(2.0 - 1e-9).position_m == pytest.approx(traj.sample(2.0).position_m, abs=1e-6)
    assert traj.sample(10.0).position_m == pytest.approx((1, 2, 0))
    assert traj.sample(10.0).velocity_m_s == (0.0, 0.0, 0.0)
    with pytest.raises(ValueError):
        QuinticSegment(0.0, (0, 0, 0), (1, 0, 0))
