"""Timed samples -> a smooth curve (pure): accuracy on wire-quantised samples, short curves, yaw."""

import math

import numpy as np
import pytest

from autopilot.mission.curve import GLOBAL_TOLERANCE_M, TimedCurve
from quadcommon import frames
from quadcommon.trajectories import circle, helix

HOME = (47.397742, 8.545594, 488.0)
CIRCLE = circle(0.5, math.pi / 20, (0.0, 0.0, 2.5), -2.0)
HELIX = helix(0.5, 0.5, (0.0, 0.0, 1.0), 0.1)


def local_samples(traj, rate_hz=10.0, duration_s=40.0):
    """Positions as MISSION_ITEM_INT in MAV_FRAME_LOCAL_NED carries them (x, y in 0.1 mm, z float32)."""
    ts = np.arange(0.0, duration_s + 1e-9, 1.0 / rate_hz)
    out = []
    for t in ts:
        x, y, z = traj.sample(float(t)).position_m
        out.append((round(x * 1e4) * 1e-4, round(y * 1e4) * 1e-4, float(np.float32(z))))
    return ts, out


def global_samples(traj, rate_hz=10.0, duration_s=40.0):
    """Positions as a global frame carries them (1e-7 deg)."""
    ts = np.arange(0.0, duration_s + 1e-9, 1.0 / rate_hz)
    out = []
    for t in ts:
        n, e, d = frames.vector_to_ned(traj.sample(float(t)).position_m)
        lat, lon, alt = frames.ned_to_geodetic(n, e, d, HOME)
        n2, e2, _ = frames.geodetic_to_ned(round(lat * 1e7) * 1e-7, round(lon * 1e7) * 1e-7, alt, HOME)
        out.append(frames.vector_from_ned((n2, e2, d)))
    return ts, out


def worst(curve, traj, duration_s=40.0):
    errors = np.zeros(3)
    for t in np.linspace(0.0, duration_s, 2001):
        got, want = curve.sample(float(t)), traj.sample(float(t))
        errors = np.maximum(errors, [math.dist(got.position_m, want.position_m),
                                     math.dist(got.velocity_m_s, want.velocity_m_s),
                                     math.dist(got.acceleration_m_s2, want.acceleration_m_s2)])  # fmt: skip
    return errors


@pytest.mark.parametrize("traj", [CIRCLE, HELIX], ids=["circle", "helix"])
@pytest.mark.parametrize("rate_hz", [50.0, 10.0, 2.0])
def test_local_frame_samples_give_the_analytic_curve_and_its_derivatives(traj, rate_hz):
    ts, positions = local_samples(traj, rate_hz)
    p, v, a = worst(TimedCurve(ts, positions, [None] * len(ts)), traj)
    # An interpolating spline would turn the 0.1 mm quantisation into ~0.2 m/s^2 here.
    assert p < 1e-4 and v < 1e-3 and a < 5e-3


def test_global_frame_samples_are_fitted_within_their_centimetre_resolution():
    ts, positions = global_samples(CIRCLE)
    p, v, a = worst(TimedCurve(ts, positions, [None] * len(ts), tolerance_m=GLOBAL_TOLERANCE_M), CIRCLE)
    assert p < 5e-3 and a < 0.02
    _, _, a_strict = worst(TimedCurve(ts, positions, [None] * len(ts)), CIRCLE)
    assert a_strict > 1.0  # what forcing the fit through 1 cm noise would do


def test_short_and_single_sample_curves():
    three = TimedCurve([0.0, 1.0, 2.0], [(0.0, 0.0, 1.0), (1.0, 0.0, 1.0), (2.0, 1.0, 1.0)], [None] * 3)
    assert three.sample(1.0).position_m == pytest.approx((1.0, 0.0, 1.0))
    assert three.sample(0.0).acceleration_m_s2 == pytest.approx((0.0, 0.0, 0.0), abs=1e-12)  # natural ends
    one = TimedCurve([5.0], [(1.0, 2.0, 3.0)], [0.3])
    ref = one.sample(2.0)
    assert one.duration_s == 0.0 and ref.position_m == (1.0, 2.0, 3.0) and ref.yaw_rad == pytest.approx(0.3)
    with pytest.raises(ValueError, match="increasing"):
        TimedCurve([0.0, 0.0], [(0.0, 0.0, 0.0)] * 2, [None] * 2)


def test_yaw_is_filled_forward_and_interpolated_across_the_wrap():
    ts = np.arange(0.0, 4.01, 0.5)
    yaws = [None, None, 3.0, 3.1, -3.1, -3.0, None, -2.9, -2.8]  # crosses +-pi between 3.1 and -3.1
    curve = TimedCurve(ts, [(0.1 * t, 0.0, 1.0) for t in ts], yaws, default_yaw=1.0)
    assert curve.sample(0.0).yaw_rad == pytest.approx(1.0, abs=1e-3)
    mid = curve.sample(1.75)  # between 3.1 and -3.1 the short way, through pi
    assert abs(abs(mid.yaw_rad) - math.pi) < 0.1 and mid.yaw_rate_rad_s > 0.0


@pytest.mark.parametrize("count", [4, 12, 400])  # natural cubic; quintic interpolant; least squares
def test_the_per_piece_polynomials_are_the_spline_to_rounding(count):
    times = np.linspace(0.0, 20.0, count)
    positions = [(math.sin(0.3 * t), math.cos(0.2 * t), 1.0 + 0.05 * t) for t in times]
    curve = TimedCurve(times, positions, [0.01 * t for t in times])
    for tau in list(np.linspace(0.0, 20.0, 997)) + list(np.linspace(20.0, 0.0, 13)):  # forth and back
        ref = curve.sample(float(tau))
        p, v, a = curve._p(tau), curve._v(tau), curve._a(tau)
        assert np.allclose(ref.position_m, p[:3], rtol=0.0, atol=1e-12)
        assert np.allclose(ref.velocity_m_s, v[:3], rtol=0.0, atol=1e-11)
        assert np.allclose(ref.acceleration_m_s2, a[:3], rtol=0.0, atol=1e-10)
        assert ref.yaw_rate_rad_s == pytest.approx(float(v[3]), abs=1e-11)
