"""The nonlinear H-infinity law (eqs. 43-44) and the IntBS attitude law."""

import numpy as np
import pytest

from autopilot.control.config import load_controller
from quadcommon.rigid_body import coriolis_matrix, euler_torque_from_body_torque, inertia_matrix
from tests.autopilot.laws import rotational

INERTIA = (0.004, 0.004, 0.0084)
Z3 = (0.0, 0.0, 0.0)


def tau_eta(law, eta, eta_dot, ref, ref_rate, ref_acc, dt=0.002, integrate=True):
    """The law's generalised torque on the Euler coordinates (eq. 4): its body torque mapped."""
    body = law.step(eta, eta_dot, Z3, ref, ref_rate, ref_acc, dt, integrate)
    return np.array(euler_torque_from_body_torque(eta[0], eta[1], body))


def explicit_law(gains, eta, eta_dot, ref, ref_rate, ref_acc, integral):
    """eq. (43) with the gain matrices of eq. (44) formed literally, M inverted."""
    M = np.array(inertia_matrix(INERTIA, eta[0], eta[1]))
    C = np.array(coriolis_matrix(INERTIA, eta, eta_dot))
    G = np.linalg.inv(M) @ (C + np.eye(3) / gains.omega_u**2)
    KD = gains.k_d * np.eye(3) + G
    KP = gains.k_p * np.eye(3) + gains.k_d * G
    KI = gains.k_p * G
    e = np.array(eta) - np.array(ref)
    e_dot = np.array(eta_dot) - np.array(ref_rate)
    return M @ np.array(ref_acc) + C @ np.array(eta_dot) - M @ (KD @ e_dot + KP @ e + KI @ np.array(integral))


def test_law_equals_the_literal_gain_matrix_form():
    gains = load_controller("intbs_nlhinf").rotational
    rng = np.random.default_rng(7)
    for _ in range(30):
        law = rotational("intbs_nlhinf")
        law.state = list(rng.normal(scale=0.1, size=3))
        eta = tuple(rng.uniform(-0.8, 0.8, size=3))
        eta_dot = tuple(rng.normal(size=3))
        ref, ref_rate, ref_acc = (tuple(rng.normal(scale=0.3, size=3)) for _ in range(3))
        integral = list(law.state)
        tau = tau_eta(law, eta, eta_dot, ref, ref_rate, ref_acc)
        expected = explicit_law(gains, eta, eta_dot, ref, ref_rate, ref_acc, integral)
        assert np.allclose(tau, expected, rtol=1e-10, atol=1e-12)


def closed_loop_matrix(name, inertia, dt=1e-6):
    """Numerical linearisation of [int e, e, e_dot] under M e'' = tau(e), about hover."""
    A = np.zeros((9, 9))
    for col in range(9):
        x = np.zeros(9)
        x[col] = dt
        law = rotational(name)
        law.state = list(x[0:3])
        tau = tau_eta(law, tuple(x[3:6]), tuple(x[6:9]), Z3, Z3, Z3, 0.0, integrate=False)
        acc = np.linalg.solve(np.array(inertia_matrix(inertia, 0.0, 0.0)), tau)
        A[0:3, col] = x[3:6] / dt
        A[3:6, col] = x[6:9] / dt
        A[6:9, col] = acc / dt
    return A


def test_linearised_poles_are_those_of_CONTROL_md():
    poles = np.sort(np.linalg.eigvals(closed_loop_matrix("intbs_nlhinf", INERTIA)).real)
    # roll/pitch: -1/(w_u^2 Ixx) = -111.1, yaw: -1/(w_u^2 Izz) = -52.9; all axes -29.8 and -3.02
    expected = sorted([-1 / (2.25 * 0.004)] * 2 + [-1 / (2.25 * 0.0084)] + [-29.8, -3.02] * 3)
    assert poles == pytest.approx(expected, abs=0.05)


def test_intbs_attitude_matches_the_nlhinf_poles():
    """Config intbs.toml is tuned to the NLHinf linearised loop (CONTROL.md)."""
    poles = np.sort(np.linalg.eigvals(closed_loop_matrix("intbs", INERTIA)).real)
    expected = sorted([-111.1, -111.1, -52.9] + [-29.8, -3.02] * 3)
    assert poles == pytest.approx(expected, abs=0.2)


def test_omega3_zero_removes_integral_action():
    law = rotational("bs_nlhinf")
    assert law.gains.k_p == 0.0
    law.state = [1.0, 1.0, 1.0]
    assert tau_eta(law, Z3, Z3, Z3, Z3, Z3) == pytest.approx((0.0, 0.0, 0.0))
    assert law.state == [1.0, 1.0, 1.0]  # and nothing integrates


def test_integral_rejects_a_constant_torque_disturbance():
    """Closed loop on the nominal model with 0.5 N m on yaw: the error goes to zero."""
    law = rotational("intbs_nlhinf")
    eta, eta_dot, dt = np.zeros(3), np.zeros(3), 0.001
    for _ in range(int(10 / dt)):
        tau = tau_eta(law, tuple(eta), tuple(eta_dot), Z3, Z3, Z3, dt)
        M = np.array(inertia_matrix(INERTIA, eta[0], eta[1]))
        C = np.array(coriolis_matrix(INERTIA, tuple(eta), tuple(eta_dot)))
        acc = np.linalg.solve(M, tau + np.array([0, 0, 0.5]) - C @ eta_dot)
        eta_dot = eta_dot + dt * acc
        eta = eta + dt * eta_dot
    assert np.abs(eta).max() < 1e-4
