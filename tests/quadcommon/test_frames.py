"""The paper <-> NED/FRD map: a rotation by pi about x on both sides."""

import math

import numpy as np
import pytest

from quadcommon import frames
from quadcommon.rigid_body import quaternion_from_euler, rotation_from_quaternion, rotation_matrix

F = np.diag([1.0, -1.0, -1.0])


@pytest.mark.parametrize("eta", [(0.1, -0.2, 0.3), (0.5, 0.4, -2.5), (-1.0, 1.2, 3.0)])
def test_euler_map_is_the_frame_rotation(eta):
    R_paper = np.array(rotation_matrix(*eta))
    R_ned_expected = F @ R_paper @ F
    R_ned = np.array(rotation_matrix(*frames.euler_to_ned(eta)))
    assert np.allclose(R_ned, R_ned_expected, atol=1e-14)
    assert np.allclose(frames.euler_from_ned(frames.euler_to_ned(eta)), eta)


@pytest.mark.parametrize("eta", [(0.1, -0.2, 0.3), (0.5, 0.4, -2.5)])
def test_quaternion_map_agrees_with_euler_map(eta):
    q_ned = frames.quaternion_to_ned(quaternion_from_euler(*eta))
    expected = quaternion_from_euler(*frames.euler_to_ned(eta))
    assert np.allclose(rotation_from_quaternion(*q_ned), rotation_from_quaternion(*expected), atol=1e-14)
    assert np.allclose(frames.quaternion_from_ned(q_ned), quaternion_from_euler(*eta))


def test_vector_map_flips_y_and_z():
    assert frames.vector_to_ned((1.0, 2.0, 3.0)) == (1.0, -2.0, -3.0)
    assert frames.vector_from_ned((1.0, -2.0, -3.0)) == (1.0, 2.0, 3.0)


def test_body_vector_map_is_consistent_with_attitude_map():
    """A body vector rotated to the world must agree in both conventions."""
    eta = (0.3, -0.4, 1.1)
    v_body = np.array([0.2, -0.7, 1.5])
    world_paper = np.array(rotation_matrix(*eta)) @ v_body
    world_ned = np.array(rotation_matrix(*frames.euler_to_ned(eta))) @ np.array(
        frames.vector_to_ned(tuple(v_body))
    )
    assert np.allclose(world_ned, frames.vector_to_ned(tuple(world_paper)), atol=1e-14)


def test_geodetic_round_trip_and_scale():
    home = (47.397742, 8.545594, 488.0)
    lat, lon, alt = frames.ned_to_geodetic(100.0, -50.0, -10.0, home)
    assert alt == pytest.approx(498.0)
    assert lat > home[0] and lon < home[1]
    # 100 m north is about 0.000899 degrees of latitude
    assert (lat - home[0]) * math.pi / 180 * frames.EARTH_RADIUS_M == pytest.approx(100.0, rel=1e-5)
    n, e, d = frames.geodetic_to_ned(lat, lon, alt, home)
    assert (n, e, d) == pytest.approx((100.0, -50.0, -10.0), abs=1e-6)


def test_wrap_pi():
    assert frames.wrap_pi(3 * math.pi / 2) == pytest.approx(-math.pi / 2)
    assert frames.wrap_pi(-3 * math.pi / 2) == pytest.approx(math.pi / 2)
