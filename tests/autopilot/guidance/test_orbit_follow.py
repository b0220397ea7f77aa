"""The Orbit and follow-me references' rules (pure: no stack), as PX4's flight tasks have them."""

import math

import pytest

from autopilot.guidance.follow import TARGET_STALE_S, TargetEstimator, TargetReport
from autopilot.guidance.orbit import (
    YAW_HOLD_INITIAL,
    YAW_UNCHANGED,
    Orbit,
    OrbitLimits,
    OrbitRequest,
    sanitize,
)
from autopilot.guidance.planner import Limits

LIMITS = OrbitLimits(1000.0, 10.0, Limits(10.0, 1.5, 1.0, 2.0, 1.0), 0)


@pytest.mark.parametrize(
    "radius, velocity, expected",
    [
        (0.5, 0.5, (1.0, 0.5)),  # radius up to 1 m
        (5000.0, 3.0, (1000.0, 3.0)),  # down to MC_ORBIT_RAD_MAX
        (100.0, 25.0, (100.0, 10.0)),  # speed to 10 m/s
        (2.0, -5.0, (2.0, -2.0)),  # v^2 / r within 2 m/s^2: sqrt(2 x 2), direction kept
        (4.0, 3.0, (4.0, math.sqrt(8.0))),  # 9 > 2 x 4: lowered to sqrt(8)
        (5.0, 3.0, (5.0, 3.0)),  # 9 < 2 x 5: kept
    ],
)
def test_sanitize_clips_as_px4(radius, velocity, expected):
    assert sanitize(radius, velocity, LIMITS) == pytest.approx(expected)


def test_a_do_orbit_keeps_what_it_leaves_unset_and_refuses_a_radius_out_of_range():
    orbit = Orbit()
    orbit.enter((1.0, 2.0, 3.0), 0.5, LIMITS)
    assert (orbit.radius_m, orbit.velocity_m_s, orbit.centre) == (1.0, 1.0, (1.0, 2.0, 3.0))
    assert orbit.apply(OrbitRequest(-6.0, 2.0, YAW_HOLD_INITIAL), 0.7, LIMITS) is None
    assert (orbit.radius_m, orbit.velocity_m_s, orbit.yaw_behaviour) == (6.0, -2.0, YAW_HOLD_INITIAL)
    assert orbit.status.radius_m == -6.0 and orbit.initial_heading == 0.7
    # NaN radius and speed (None) keep them; YAW_UNCHANGED keeps the behaviour; the centre moves.
    assert orbit.apply(OrbitRequest(None, None, YAW_UNCHANGED, (4.0, 5.0), None), 0.7, LIMITS) is None
    assert (orbit.radius_m, orbit.velocity_m_s, orbit.yaw_behaviour) == (6.0, -2.0, YAW_HOLD_INITIAL)
    assert orbit.centre == (4.0, 5.0, 3.0)
    # A negative speed turns the other way (PX4 multiplies the radius's sign by it).
    orbit.apply(OrbitRequest(None, -1.5), 0.0, LIMITS)
    assert orbit.velocity_m_s == 1.5
    reason = orbit.apply(OrbitRequest(1500.0, 1.0), 0.0, LIMITS)
    assert "Orbit radius limit exceeded" in reason and orbit.radius_m == 6.0


def test_the_target_estimate_runs_on_between_reports_and_is_lost_after_the_stale_time():
    target = TargetEstimator()
    assert target.estimate(0.0) is None
    for k in range(5):  # 2 m/s north, positions only: the velocity from their change
        target.report(TargetReport(k * 0.5, (k * 1.0, 0.0, 0.0), None), responsiveness=0.0)
    now = target.estimate(2.5)
    assert now.velocity_m_s == pytest.approx((2.0, 0.0, 0.0))
    assert now.position_m == pytest.approx((5.0, 0.0, 0.0))
    assert target.estimate(2.0 + TARGET_STALE_S - 1e-6) is not None
    assert target.estimate(2.0 + TARGET_STALE_S + 1e-3) is None


def test_the_yaw_stick_behaviour_turns_at_the_stick_rate_while_circling():
    """ORBIT_YAW_BEHAVIOUR 4 (PX4: the altitude task's yaw, from the stick); the vehicle here follows
    its reference exactly."""
    from quadcommon.frames import wrap_pi
    from quadcommon.trajectories import Reference

    orbit = Orbit()
    orbit.enter((0.0, 0.0, 5.0), 0.0, LIMITS)
    orbit.apply(OrbitRequest(3.0, 1.0, 4), 0.0, LIMITS)
    ref = Reference((0.0, 0.0, 5.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0)
    t, dt = 0.0, 0.002
    while orbit.approaching or t < 0.1:  # fly the approach, perfectly tracked
        ref = orbit.reference(t, dt, ref.position_m, ref, LIMITS, 0.0)
        t += dt
    yaw0 = ref.yaw_rad
    for _ in range(250):  # 0.5 s at 0.4 rad/s
        ref = orbit.reference(t, dt, ref.position_m, ref, LIMITS, 0.4)
        t += dt
    assert wrap_pi(ref.yaw_rad - yaw0) == pytest.approx(0.2, abs=1e-6) and ref.yaw_rate_rad_s == 0.4
    assert math.hypot(*ref.position_m[:2]) == pytest.approx(3.0, abs=1e-6)
