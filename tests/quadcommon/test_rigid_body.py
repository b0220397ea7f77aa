"""Invariants of the Section II rotational model (eqs. 3-6) and the kinematics helpers."""

import math
import random

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from quadcommon import rigid_body as rb

INERTIA = (0.004, 0.004, 0.0084)
ASYMMETRIC = (0.004, 0.0052, 0.0084)


def random_states(n=50, seed=1):
    rng = random.Random(seed)
    for _ in range(n):
        eta = (rng.uniform(-1.2, 1.2), rng.uniform(-1.2, 1.2), rng.uniform(-3, 3))
        eta_dot = tuple(rng.uniform(-3, 3) for _ in range(3))
        yield eta, eta_dot


def M(inertia, eta):
    return np.array(rb.inertia_matrix(inertia, eta[0], eta[1]))


def M_dot_fd(inertia, eta, eta_dot, h=1e-6):
    e_plus = np.array(eta) + h * np.array(eta_dot)
    e_minus = np.array(eta) - h * np.array(eta_dot)
    return (M(inertia, e_plus) - M(inertia, e_minus)) / (2 * h)


@pytest.mark.parametrize("inertia", [INERTIA, ASYMMETRIC])
def test_inertia_matrix_is_symmetric_positive_definite(inertia):
    for eta, _ in random_states():
        m = M(inertia, eta)
        assert np.allclose(m, m.T, atol=0)
        assert np.linalg.eigvalsh(m).min() > 0.0


def test_inertia_matrix_is_W_transpose_J_W():
    for eta, _ in random_states(10):
        W = np.array(rb.euler_rate_matrix(eta[0], eta[1]))
        assert np.allclose(M(INERTIA, eta), W.T @ np.diag(INERTIA) @ W, atol=1e-15)


@pytest.mark.parametrize("inertia", [INERTIA, ASYMMETRIC])
def test_M_dot_minus_2C_is_skew_symmetric(inertia):
    for eta, eta_dot in random_states():
        C = np.array(rb.coriolis_matrix(inertia, eta, eta_dot))
        N = M_dot_fd(inertia, eta, eta_dot) - 2.0 * C
        assert np.allclose(N, -N.T, atol=1e-9), N + N.T


@pytest.mark.parametrize("inertia", [INERTIA, ASYMMETRIC])
def test_C_eta_dot_equals_lagrangian_residual(inertia):
    """C eta_dot = d/dt(dL/d eta_dot) - dL/d eta - M eta_ddot
    = M_dot eta_dot - 1/2 grad(eta_dot' M eta_dot)."""
    h = 1e-6
    for eta, eta_dot in random_states():
        qd = np.array(eta_dot)
        grad = np.zeros(3)
        for k in range(3):
            dk = np.zeros(3)
            dk[k] = h
            grad[k] = (
                qd @ M(inertia, np.array(eta) + dk) @ qd - qd @ M(inertia, np.array(eta) - dk) @ qd
            ) / (2 * h)
        residual = M_dot_fd(inertia, eta, eta_dot) @ qd - 0.5 * grad
        C_eta_dot = np.array(rb.coriolis_times(inertia, eta, eta_dot, eta_dot))
        assert np.allclose(C_eta_dot, residual, atol=1e-9)


def test_rotation_matrix_matches_scipy_zyx():
    for eta, _ in random_states(20):
        ours = np.array(rb.rotation_matrix(*eta))
        ref = Rotation.from_euler("ZYX", [eta[2], eta[1], eta[0]]).as_matrix()
        assert np.allclose(ours, ref, atol=1e-14)


def test_quaternion_euler_round_trip_and_matrix():
    for eta, _ in random_states(30):
        q = rb.quaternion_from_euler(*eta)
        assert math.isclose(sum(c * c for c in q), 1.0, abs_tol=1e-14)
        assert np.allclose(rb.rotation_from_quaternion(*q), rb.rotation_matrix(*eta), atol=1e-14)
        back = rb.euler_from_quaternion(*q)
        assert np.allclose(back[:2], eta[:2], atol=1e-12)
        assert math.isclose(math.remainder(back[2] - eta[2], 2 * math.pi), 0.0, abs_tol=1e-12)


def test_body_rates_and_euler_rates_are_inverse_maps():
    for eta, eta_dot in random_states(30):
        omega = rb.body_rates_from_euler_rates(eta[0], eta[1], eta_dot)
        W = np.array(rb.euler_rate_matrix(eta[0], eta[1]))
        assert np.allclose(omega, W @ np.array(eta_dot), atol=1e-14)
        assert np.allclose(rb.euler_rates_from_body_rates(eta[0], eta[1], omega), eta_dot, atol=1e-12)


def test_body_rates_are_rotation_kinematics():
    """omega from W_eta eta_dot equals the body rate of R(eta(t)) by finite differences."""
    h = 1e-6
    for eta, eta_dot in random_states(20):
        e0, ed = np.array(eta), np.array(eta_dot)
        R0 = np.array(rb.rotation_matrix(*e0))
        Rdot = (
            np.array(rb.rotation_matrix(*(e0 + h * ed))) - np.array(rb.rotation_matrix(*(e0 - h * ed)))
        ) / (2 * h)
        skew = R0.T @ Rdot
        omega = (skew[2, 1], skew[0, 2], skew[1, 0])
        assert np.allclose(omega, rb.body_rates_from_euler_rates(eta[0], eta[1], eta_dot), atol=1e-8)


def test_generalised_and_body_torques_are_dual():
    for eta, tau in random_states(30):
        body = rb.body_torque_from_euler_torque(eta[0], eta[1], tau)
        W = np.array(rb.euler_rate_matrix(eta[0], eta[1]))
        assert np.allclose(W.T @ np.array(body), tau, atol=1e-12)
        assert np.allclose(rb.euler_torque_from_body_torque(eta[0], eta[1], body), tau, atol=1e-12)


def test_solve3():
    rng = np.random.default_rng(3)
    for _ in range(20):
        A = rng.normal(size=(3, 3)) + 3 * np.eye(3)
        b = rng.normal(size=3)
        x = rb.solve3(tuple(map(tuple, A)), tuple(b))
        assert np.allclose(A @ np.array(x), b)


def test_quaternion_algebra_matches_rotation_matrices():
    rng = np.random.default_rng(5)
    for _ in range(20):
        a = rb.quaternion_normalised(tuple(rng.normal(size=4)))
        b = rb.quaternion_normalised(tuple(rng.normal(size=4)))
        ab = rb.quaternion_multiply(a, b)
        Ra, Rb = np.array(rb.rotation_from_quaternion(*a)), np.array(rb.rotation_from_quaternion(*b))
        assert np.allclose(np.array(rb.rotation_from_quaternion(*ab)), Ra @ Rb)
        identity = rb.quaternion_multiply(a, rb.quaternion_conjugate(a))
        assert np.allclose(identity, (1.0, 0.0, 0.0, 0.0), atol=1e-15)
        r = rng.normal(size=3) * (1e-8 if _ % 2 else 1.0)  # the series branch and the closed form
        expected = Rotation.from_rotvec(r).as_matrix()
        ours = np.array(rb.rotation_from_quaternion(*rb.quaternion_exp(*r)))
        assert np.allclose(ours, expected, atol=1e-14)


def test_body_acceleration_is_the_time_derivative_of_the_body_rates():
    """omega' = W_eta eta'' + W_eta' eta' against d/dt of W_eta(eta(t)) eta'(t) by finite differences."""
    h = 1e-6
    rng = np.random.default_rng(9)
    for eta, eta_dot in random_states(20):
        e0, ed, edd = np.array(eta), np.array(eta_dot), rng.normal(size=3)
        omega = []
        for t in (h, -h):  # eta(t) = eta + t eta' + t^2/2 eta''
            e, e_dot = e0 + t * ed + 0.5 * t * t * edd, ed + t * edd
            omega.append(np.array(rb.body_rates_from_euler_rates(e[0], e[1], tuple(e_dot))))
        expected = (omega[0] - omega[1]) / (2 * h)
        got = rb.body_acceleration_from_euler(eta[0], eta[1], eta_dot, tuple(edd))
        assert np.allclose(got, expected, atol=1e-7)


def test_cross():
    rng = np.random.default_rng(4)
    for _ in range(10):
        a, b = rng.normal(size=3), rng.normal(size=3)
        assert np.allclose(rb.cross(tuple(a), tuple(b)), np.cross(a, b), atol=1e-15)


def test_roll_pitch_from_body_z_gives_that_body_z_and_yaw():
    """R(phi, theta, psi) e3 is the given unit vector, and the body x axis lies in the vertical plane
    of heading psi (PX4's bodyzToAttitude: x_b = y_C x z_b, y_C = (-sin psi, cos psi, 0))."""
    rng = np.random.default_rng(6)
    for _ in range(50):
        b = rng.normal(size=3)
        b[2] = abs(b[2]) + 0.2
        b /= np.linalg.norm(b)
        psi = rng.uniform(-3, 3)
        phi, theta = rb.roll_pitch_from_body_z(*b, psi)
        R = np.array(rb.rotation_matrix(phi, theta, psi))
        assert np.allclose(R[:, 2], b, atol=1e-12)
        x_c = np.cross([-math.sin(psi), math.cos(psi), 0.0], b)
        assert np.allclose(R[:, 0], x_c / np.linalg.norm(x_c), atol=1e-12)
    assert rb.roll_pitch_from_body_z(0.0, 0.0, 1.0, 1.2) == (0.0, 0.0)


def test_limit_tilt_turns_a_direction_to_the_limit_in_its_vertical_plane():
    tilt = 0.7
    b = np.array([3.0, -4.0, 1.0]) / math.sqrt(26.0)  # 1.37 rad from the vertical
    *limited, flag = rb.limit_tilt(*b, tilt)
    assert flag == 1.0
    assert math.acos(limited[2]) == pytest.approx(tilt, abs=1e-12)
    assert np.linalg.norm(limited) == pytest.approx(1.0, abs=1e-12)
    assert np.allclose(np.array(limited[:2]) / np.linalg.norm(limited[:2]), [0.6, -0.8], atol=1e-12)
    inside = (math.sin(0.5), 0.0, math.cos(0.5))
    assert rb.limit_tilt(*inside, tilt) == (*inside, 0.0)
    assert rb.limit_tilt(0.0, 0.0, -1.0, tilt) == pytest.approx((math.sin(tilt), 0.0, math.cos(tilt), 1.0))
    assert rb.limit_tilt(0.0, 0.0, 0.0, tilt) == (0.0, 0.0, 1.0, 0.0)  # no direction: up
    assert rb.limit_tilt(*(2.0 * v for v in inside), tilt) == pytest.approx((*inside, 0.0), abs=1e-15)
