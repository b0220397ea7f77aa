"""Braking to rest (guidance/planner.py stop_from), which every hold starts with: from any state the
reference comes to rest soon, near where braking would stop it, within the acceleration limit; also
when the start accelerates along its velocity (a mission leg speeding up when a hold is asked for),
which it then does without backing up."""

import math

import numpy as np
import pytest

from autopilot.guidance.planner import Limits, stop_from
from quadcommon.trajectories import Reference

LIMITS = Limits(speed_horizontal=2.0, speed_up=1.5, speed_down=1.0, acceleration=2.0, yaw_rate=1.0)


@pytest.mark.parametrize(
    "velocity, acceleration",
    [
        ((1.5, 0.0, 0.0), (0.0, 0.0, 0.0)),  # cruising
        ((1.577, 0.0, 0.0), (1.585, 0.0, 0.0)),  # speeding up (found as a 109 s overshooting quintic)
        ((0.5, -1.0, 0.3), (1.9, -1.0, 0.0)),
        ((0.0, 0.0, 0.0), (1.0, 0.0, 0.0)),  # at rest, pushed
        ((2.0, 0.0, 0.0), (-1.0, 0.0, 0.0)),  # already braking
    ],
)
def test_stop_from_any_state_comes_to_rest_without_reversing(velocity, acceleration):
    start = Reference((1.0, 2.0, 3.0), velocity, acceleration, 0.3, 0.0, 0.0)
    stop = stop_from(start, LIMITS)
    assert stop.duration_s < 5.0
    end = stop.sample(stop.duration_s)
    assert math.hypot(*end.velocity_m_s) < 1e-6 and math.hypot(*end.acceleration_m_s2) < 1e-6
    samples = [stop.sample(t) for t in np.linspace(0.0, stop.duration_s, 200)]
    ceiling = max(LIMITS.acceleration, math.hypot(*acceleration)) * 1.05
    assert max(math.hypot(*s.acceleration_m_s2) for s in samples) <= ceiling
    travelled = math.dist(end.position_m, start.position_m)
    speed = math.hypot(*velocity)
    assert travelled < speed * speed / LIMITS.acceleration + 0.5  # stops about where braking would
    if np.dot(velocity, acceleration) > 0.0:  # speeding up: it stops wherever it comes to rest
        along = [float(np.dot(s.velocity_m_s, velocity)) for s in samples]
        assert min(along) > -1e-6  # never backing up
