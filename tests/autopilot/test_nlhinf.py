"""The nonlinear H-infinity law (eqs. 43-44) and the IntBS attitude law."""

import numpy as np
import pytest

from autopilot.control.config import load_controller
from autopilot.control.laws.integral_backstepping_attitude import IntegralBacksteppingAttitude
from autopilot.control.laws.nlhinf import NonlinearHinfAttitude
from quadcommon.config import load_vehicle
from quadcommon.rigid_body import coriolis_matrix, inertia_matrix

INERTIA = (0.004, 0.004, 0.0084)
NOMINAL = load_vehicle("paper_quad").nominal  # m 0.74 kg, the inertia above


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
        law = NonlinearHinfAttitude(gains, NOMINAL)
        law.integral = list(rng.normal(scale=0.1, size=3))
        eta = tuple(rng.uniform(-0.8, 0.8, size=3))
        eta_dot = tuple(rng.normal(size=3))
        ref, ref_rate, ref_acc = (tuple(rng.normal(scale=0.3, size=3)) for _ in range(3))
        integral = list(law.integral)
        tau = law.update(eta, eta_dot, ref, ref_rate, ref_acc, dt=0.002)
        expected = explicit_law(gains, eta, eta_dot, ref, ref_rate, ref_acc, integral)
        assert np.allclose(tau, expected, rtol=1e-10, atol=1e-12)


def closed_loop_matrix(law_factory, inertia, dt=1e-6):
    """Numerical linearisation of [int e, e, e_dot] under M e'' = tau(e), about hover."""
    A = np.zeros((9, 9))
    for col in range(9):
        x = np.zeros(9)
        x[col] = dt
        law = law_factory()
        law.integral = list(x[0:3])
        eta, eta_dot = tuple(x[3:6]), tuple(x[6:9])
        tau = np.array(law.update(eta, eta_dot, (0, 0, 0), (0, 0, 0), (0, 0, 0), 0.0, integrate=False))
        M = np.array(inertia_matrix(inertia, 0.0, 0.0))
        acc = np.linalg.solve(M, tau)
        A[0:3, col] = x[3:6] / dt
        A[3:6, col] = x[6:9] / dt
        A[6:9, col] = acc / dt
    return A


def test_linearised_poles_are_those_of_CONTROL_md():
    gains = load_controller("intbs_nlhinf").rotational
    A = closed_loop_matrix(lambda: NonlinearHinfAttitude(gains, NOMINAL), INERTIA)
    poles = np.sort(np.linalg.eigvals(A).real)
    # roll/pitch: -1/(w_u^2 Ixx) = -111.1, yaw: -1/(w_u^2 Izz) = -52.9; all axes -29.8 and -3.02
    expected = sorted([-1 / (2.25 * 0.004)] * 2 + [-1 / (2.25 * 0.0084)] + [-29.8, -3.02] * 3)
    assert poles == pytest.approx(expected, abs=0.05)


def test_intbs_attitude_matches_the_nlhinf_poles():
    """Config intbs.toml is tuned to the NLHinf linearised loop (CONTROL.md)."""
    cfg = load_controller("intbs").rotational
    A = closed_loop_matrix(
        lambda: IntegralBacksteppingAttitude(cfg, NOMINAL), INERTIA
    )
    poles = np.sort(np.linalg.eigvals(A).real)
    expected = sorted([-111.1, -111.1, -52.9] + [-29.8, -3.02] * 3)
    assert poles == pytest.approx(expected, abs=0.2)


def test_omega3_zero_removes_integral_action():
    gains = load_controller("bs_nlhinf").rotational
    assert gains.k_p == 0.0
    law = NonlinearHinfAttitude(gains, NOMINAL)
    law.integral = [1.0, 1.0, 1.0]
    tau = law.update((0, 0, 0), (0, 0, 0), (0, 0, 0), (0, 0, 0), (0, 0, 0), 0.002)
    assert tau == pytest.approx((0.0, 0.0, 0.0))


def test_integral_rejects_a_constant_torque_disturbance():
    """Closed loop on the nominal model with 0.5 N m on yaw: the error goes to zero."""
    gains = load_controller("intbs_nlhinf").rotational
    law = NonlinearHinfAttitude(gains, NOMINAL)
    eta, eta_dot, dt = np.zeros(3), np.zeros(3), 0.001
    for _ in range(int(10 / dt)):
        tau = np.array(law.update(tuple(eta), tuple(eta_dot), (0, 0, 0), (0, 0, 0), (0, 0, 0), dt))
        M = np.array(inertia_matrix(INERTIA, eta[0], eta[1]))
        C = np.array(coriolis_matrix(INERTIA, tuple(eta), tuple(eta_dot)))
        acc = np.linalg.solve(M, tau + np.array([0, 0, 0.5]) - C @ eta_dot)
        eta_dot = eta_dot + dt * acc
        eta = eta + dt * eta_dot
    assert np.abs(eta).max() < 1e-4
