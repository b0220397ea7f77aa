"""Translational backstepping laws (eqs. 24-29)."""

import math

import numpy as np
import pytest

from autopilot.control.config import load_controller
from autopilot.control.translational import TranslationalController
from quadcommon.config import load_vehicle

M, G, UMAX = 0.74, 9.81, 28.0
NOMINAL = load_vehicle("paper_quad").nominal  # m and g above


def law(name):
    config = load_controller(name)
    return TranslationalController.for_gains(config.translational, NOMINAL, UMAX, config.tilt_max_rad)


@pytest.mark.parametrize("name", ["intbs_nlhinf", "intbs", "bs_nlhinf"])
def test_hover_on_reference_needs_weight_and_no_tilt(name):
    out = law(name).update((1, 2, 3), (0, 0, 0), (0, 0, 0.4), (1, 2, 3), (0, 0, 0), (0, 0, 0), 0.002)
    assert out.thrust_n == pytest.approx(M * G)
    assert out.roll_ref_rad == pytest.approx(0.0, abs=1e-15)
    assert out.pitch_ref_rad == pytest.approx(0.0, abs=1e-15)


def test_reference_acceleration_maps_to_tilt_along_eq_23():
    """A desired forward acceleration with psi = 0 is a pitch-forward (positive theta)."""
    ctl = law("intbs_nlhinf")
    out = ctl.update((0, 0, 0), (0, 0, 0), (0, 0, 0), (0, 0, 0), (0, 0, 0), (1.0, 0, 0), 0.002)
    # U1 is computed with the current (level) attitude, so u_x = m a_x / (m g) (eqs. 26-29)
    assert out.pitch_ref_rad == pytest.approx(math.asin(1.0 / G), rel=1e-12)
    assert out.roll_ref_rad == pytest.approx(0.0, abs=1e-12)
    ctl = law("intbs_nlhinf")
    out = ctl.update((0, 0, 0), (0, 0, 0), (0, 0, 0), (0, 0, 0), (0, 0, 0), (0, 1.0, 0), 0.002)
    # acceleration to +y (left) needs a left roll, i.e. negative phi about x forward
    assert out.roll_ref_rad < 0.0
    # and the directions of eq. 23 reproduce the demanded acceleration
    phi, theta, psi = out.roll_ref_rad, out.pitch_ref_rad, 0.0
    u_y = math.sin(psi) * math.sin(theta) * math.cos(phi) - math.cos(psi) * math.sin(phi)
    assert out.thrust_n * u_y / M == pytest.approx(1.0, rel=1e-9)


def test_tilt_limit_is_respected():
    ctl = law("intbs_nlhinf")
    out = ctl.update((0, 0, 0), (0, 0, 0), (0, 0, 0), (50, 0, 0), (0, 0, 0), (0, 0, 0), 0.002)
    assert abs(out.pitch_ref_rad) <= 0.7 + 1e-12


def outer_poles(name):
    """Linearised per-axis closed loop of the double integrator under the law (dt -> small)."""
    c = load_controller(name).translational
    c1, c2, k = c.c1[0], c.c2[0], c.k_integral[0]
    if name == "intbs":
        # chi' = e1 ; e1'' = (c1^2-1-k) e1 - (c1+c2)(e1' + c1 e1 + k chi) + c1 k chi
        A = [
            [0, 1, 0],
            [0, 0, 1],
            [k * c1 - (c1 + c2) * k, c1 * c1 - 1 - k - (c1 + c2) * c1, -(c1 + c2)],
        ]
    else:
        # xi = int(e1' + c1 e1) ; state [int e1, e1, e1']
        A = [[0, 1, 0], [0, 0, 1], [-k * c1, -k - (1 + c1 * c2), -(c1 + c2)]]
    return np.sort(np.linalg.eigvals(np.array(A, dtype=float)).real)


def test_intbs_outer_loop_has_a_slow_integral_pole():
    """CONTROL.md: IntBS converges slowly (pole near -0.09); the paper's law does not."""
    assert outer_poles("intbs")[-1] == pytest.approx(-0.084, abs=0.01)
    assert outer_poles("intbs_nlhinf")[-1] < -0.5


def test_integral_states_reject_a_constant_force():
    """Double integrator with a constant 1 N push: the paper's law drives the error to zero."""
    ctl = law("intbs_nlhinf")
    dt = 0.002
    p, v = np.zeros(3), np.zeros(3)
    for _ in range(int(30 / dt)):
        out = ctl.update(tuple(p), tuple(v), (0, 0, 0), (0, 0, 0), (0, 0, 0), (0, 0, 0), dt)
        a = np.array(out.acceleration_cmd_m_s2) + np.array([1.0, -1.0, 1.0]) / M
        v = v + dt * a
        p = p + dt * v
    assert np.abs(p).max() < 1e-5
