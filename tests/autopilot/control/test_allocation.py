"""Control allocation: round trip, saturation order, normalisation."""

import pytest

from autopilot.control.allocation import Allocator
from quadcommon.config import load_vehicle


@pytest.fixture
def allocator():
    return Allocator(load_vehicle())


def test_round_trip_inside_limits(allocator):
    for thrust, torque in [
        (7.26, (0.0, 0.0, 0.0)),
        (10.0, (0.2, -0.1, 0.05)),
        (5.0, (-0.3, 0.3, -0.02)),
    ]:
        out = allocator.to_rotors(thrust, torque)
        assert out.thrust_n == pytest.approx(thrust, rel=1e-12)
        assert out.torque_body_n_m == pytest.approx(torque, rel=1e-9, abs=1e-12)
        assert all(0.0 <= c <= 1.0 for c in out.normalised)


def test_saturation_keeps_thrust_and_drops_yaw_first(allocator):
    # a yaw demand far beyond what the rotors can give (drag torque ~0.3 N m at most)
    out = allocator.to_rotors(7.26, (0.1, 0.0, 1.0))
    assert out.thrust_n == pytest.approx(7.26, rel=1e-12)
    assert out.torque_body_n_m[0] == pytest.approx(0.1, rel=1e-9)
    assert 0.0 < out.torque_body_n_m[2] < 1.0
    assert max(out.speeds_rad_s) <= allocator.speed_max + 1e-9


def test_roll_pitch_scaled_when_infeasible(allocator):
    out = allocator.to_rotors(7.26, (5.0, 0.0, 0.0))
    assert out.thrust_n == pytest.approx(7.26, rel=1e-12)
    assert 0.0 < out.torque_body_n_m[0] < 5.0
    assert out.torque_body_n_m[2] == pytest.approx(0.0, abs=1e-12)


def test_wrench_normalisation(allocator):
    thrust, torque = allocator.saturate_wrench(40.0, (2.0, -0.75, 0.1))
    assert thrust == 28.0 and torque == (1.5, -0.75, 0.1)
    assert allocator.wrench_to_normalised(thrust, torque) == pytest.approx((1.0, 1.0, -0.5, 0.1 / 1.5))
