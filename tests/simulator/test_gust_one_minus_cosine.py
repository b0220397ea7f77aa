"""The discrete 1-cos wind gust: shape, continuity, direction, evaluation through the schedule."""

from __future__ import annotations

import math

import pytest

from simulator.environment.discrete_gust import OneMinusCosineGust
from simulator.environment.gust_profile import DisturbanceSchedule, GustProfile, gust_profile_from_mapping

GUST = OneMinusCosineGust(start_s=2.0, duration_s=4.0, amplitude_m_s=3.0, direction=(0.0, 3.0, 4.0))


def test_peak_is_the_amplitude_at_the_middle_and_zero_outside() -> None:
    assert GUST.speed(4.0) == pytest.approx(3.0, abs=1e-12)
    assert max(GUST.speed(2.0 + 4.0 * k / 1000) for k in range(1001)) == pytest.approx(3.0, abs=1e-12)
    for t in (0.0, 1.999, 2.0, 6.0, 6.001, 100.0):
        assert GUST.speed(t) == pytest.approx(0.0, abs=1e-12)
    # Symmetric about the peak; half amplitude at a quarter of the bump (x = d_m / 2).
    assert GUST.speed(3.0) == pytest.approx(1.5) and GUST.speed(5.0) == pytest.approx(1.5)


def test_formula_in_distance_matches_mil_f_8785c() -> None:
    """v = (V_m/2)(1 - cos(pi x / d_m)), x = V (t - start), duration = 2 d_m / V."""
    airspeed, d_m = 5.0, 10.0
    gust = gust_profile_from_mapping(
        {
            "one_minus_cosine": [
                {"start_s": 1.0, "length_m": d_m, "airspeed_m_s": airspeed, "amplitude_m_s": 2.0, "axis": "z"}
            ]
        }  # fmt: skip
    ).one_minus_cosine[0]
    for t in (1.0, 1.7, 2.5, 3.0, 4.2, 5.0):
        x = airspeed * (t - 1.0)
        assert gust.speed(t) == pytest.approx(1.0 * (1.0 - math.cos(math.pi * x / d_m)), abs=1e-12)


def test_c1_continuity_at_both_ends() -> None:
    h = 1e-6
    for edge in (GUST.start_s, GUST.end_s):
        left = (GUST.speed(edge) - GUST.speed(edge - h)) / h
        right = (GUST.speed(edge + h) - GUST.speed(edge)) / h
        assert abs(GUST.speed(edge + h) - GUST.speed(edge - h)) < 1e-9  # C0
        assert abs(left) < 1e-4 and abs(right) < 1e-4  # slope ~ pi^2 V_m h / D^2 -> 0: C1
    # Inside, the slope is continuous and peaks at pi V_m / D at the quarter points.
    slope = (GUST.speed(3.0 + h) - GUST.speed(3.0 - h)) / (2 * h)
    assert slope == pytest.approx(math.pi * 3.0 / 4.0, rel=1e-6)


def test_schedule_gives_a_wind_along_the_normalised_direction() -> None:
    schedule = DisturbanceSchedule(GustProfile(one_minus_cosine=(GUST,)), start_time_s=1.0)
    force, torque, wind = schedule.evaluate(5.0)  # profile time 4 s: the peak
    assert force == (0.0, 0.0, 0.0) and torque == (0.0, 0.0, 0.0)  # a wind, not a force
    assert wind == pytest.approx((0.0, 3.0 * 0.6, 3.0 * 0.8))
    assert schedule.evaluate(7.5)[2] == (0.0, 0.0, 0.0)
    assert schedule.evaluate(100.0)[2] == (0.0, 0.0, 0.0)
    samples = [schedule.evaluate(3.0 + k * 1e-3)[2][2] for k in range(4001)]
    assert max(samples) == pytest.approx(2.4, abs=1e-6) and min(samples) >= 0.0


def test_axis_key_gives_unit_directions() -> None:
    for axis, expected in (("x", (1.0, 0.0, 0.0)), ("y", (0.0, 1.0, 0.0)), ("z", (0.0, 0.0, 1.0))):
        profile = gust_profile_from_mapping(
            {"one_minus_cosine": [{"start_s": 0.0, "duration_s": 1.0, "amplitude_m_s": 2.0, "axis": axis}]}
        )
        assert profile.one_minus_cosine[0].unit() == expected
        wind = DisturbanceSchedule(profile).evaluate(0.5)[2]
        assert wind == pytest.approx(tuple(2.0 * c for c in expected))
