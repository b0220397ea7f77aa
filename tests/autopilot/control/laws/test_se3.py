"""Geometric control on SE(3) (se3): laws/se3_position.py and laws/se3_attitude.py against Lee,
Leok and McClamroch (2010), on the paper's vehicle."""

import math

import numpy as np
import pytest

from autopilot.control.laws import se3_attitude
from quadcommon.rigid_body import (
    body_acceleration_from_euler,
    body_rates_from_euler_rates,
    euler_from_rotation,
    euler_rates_from_body_rates,
    quaternion_exp,
    quaternion_from_euler,
    quaternion_multiply,
    rotation_from_quaternion,
    rotation_matrix,
)
from tests.autopilot.laws import DT, rotational, translational

M, G = 0.74, 9.81
J = np.array([0.004, 0.004, 0.0084])
Z3 = (0.0, 0.0, 0.0)


def test_hover_on_the_reference_asks_for_the_weight_and_a_level_attitude():
    law = translational("se3")
    out = law.step((1, 2, 3), (0.1, 0, 0), (0.0, 0.0, 0.4), (1, 2, 3), (0.1, 0, 0), Z3, 0.4, DT, True)
    assert out.thrust_n == pytest.approx(M * G, rel=1e-12)
    assert (out.roll_ref_rad, out.pitch_ref_rad) == pytest.approx((0.0, 0.0), abs=1e-15)


def test_thrust_is_the_desired_force_along_the_current_body_z_axis():
    """F_d = -k_x e_x - k_v e_v + m g e3 + m p_d''; U1 = F_d . R e3; b3_d = F_d / |F_d|."""
    law = translational("se3")
    k_x, k_v = law.gains.k_x, law.gains.k_v
    p, v, rp, rv, ra = (0.1, -0.2, 1.0), (0.3, 0.0, -0.1), (0.0, 0.0, 1.1), (0.2, 0.1, 0.0), (0.5, -0.3, 0.2)
    euler = (0.1, -0.05, 0.3)
    out = law.step(p, v, euler, rp, rv, ra, 0.3, DT, True)
    force = -k_x * (np.array(p) - rp) - k_v * (np.array(v) - rv) + M * (np.array(ra) + (0, 0, G))
    assert out.thrust_n == pytest.approx(force @ np.array(rotation_matrix(*euler))[:, 2], rel=1e-12)
    b3_d = np.array(rotation_matrix(out.roll_ref_rad, out.pitch_ref_rad, 0.3))[:, 2]
    assert b3_d == pytest.approx(force / np.linalg.norm(force), abs=1e-12)
    assert out[3:6] == pytest.approx(force / M - (0, 0, G), rel=1e-12)


def test_tilt_limit():
    out = translational("se3").step(Z3, Z3, Z3, (5.0, 0.0, 0.0), Z3, Z3, 0.0, DT, True)
    assert out.pitch_ref_rad == pytest.approx(0.7, abs=1e-12) and out.tilt_limited == 1.0


def test_without_integral_a_constant_force_leaves_the_offset_force_over_k_x():
    """The double integrator under F_d with a 1 N push settles at e = 1 N / k_x (no integral)."""
    law = translational("se3")
    p, v = np.zeros(3), np.zeros(3)
    for _ in range(int(10 / DT)):
        out = law.step(tuple(p), tuple(v), Z3, Z3, Z3, Z3, 0.0, DT, True)
        v = v + DT * (np.array(out[3:6]) + np.array([1.0, -1.0, 1.0]) / M)
        p = p + DT * v
    assert p == pytest.approx(np.array([1.0, -1.0, 1.0]) / law.gains.k_x, rel=1e-6)


# -- attitude -------------------------------------------------------------------------------------------
def random_reference(rng):
    eta_d = tuple(rng.uniform(-0.6, 0.6, size=3))
    return eta_d, tuple(rng.normal(size=3)), tuple(rng.normal(size=3))


def test_errors_vanish_on_the_reference_and_the_torque_is_the_reference_motions():
    """On the reference (R = R_d, W = W_d): e_R = e_W = 0 and M = J W_d' + W_d x J W_d, the torque
    the rigid body needs to follow it."""
    rng = np.random.default_rng(1)
    law = rotational("se3")
    for _ in range(20):
        eta_d, eta_d_dot, eta_d_ddot = random_reference(rng)
        w_d = body_rates_from_euler_rates(eta_d[0], eta_d[1], eta_d_dot)
        e_R, e_W, _, _ = se3_attitude.errors(eta_d, w_d, eta_d, eta_d_dot, eta_d_ddot)
        assert e_R == pytest.approx(Z3, abs=1e-15) and e_W == pytest.approx(Z3, abs=1e-15)
        tau = law.step(eta_d, eta_d_dot, w_d, eta_d, eta_d_dot, eta_d_ddot, DT, True)
        w_d_dot = np.array(body_acceleration_from_euler(eta_d[0], eta_d[1], eta_d_dot, eta_d_ddot))
        assert tau == pytest.approx(J * w_d_dot + np.cross(w_d, J * np.array(w_d)), abs=1e-12)


def test_attitude_error_is_the_small_rotation_in_body_axes():
    """R = R_d Exp(delta) (delta in body axes): e_R = delta to first order."""
    rng = np.random.default_rng(2)
    for _ in range(20):
        eta_d = tuple(rng.uniform(-0.6, 0.6, size=3))
        delta = rng.normal(scale=1e-4, size=3)
        q = quaternion_multiply(quaternion_from_euler(*eta_d), quaternion_exp(*delta))
        euler = euler_from_rotation(rotation_from_quaternion(*q))
        e_R, _, _, _ = se3_attitude.errors(euler, Z3, eta_d, Z3, Z3)
        assert e_R == pytest.approx(delta, abs=1e-8)


def closed_loop_poles(law, size, inertia_or_mass, rotational_loop, h=1e-7):
    """Poles of the law's loop linearised about hover: [e, e'] per axis, e'' = output / inertia."""
    A = np.zeros((2 * size, 2 * size))
    for col in range(2 * size):
        x = np.zeros(2 * size)
        x[col] = h
        e, e_dot = tuple(x[:size]), tuple(x[size:])
        if rotational_loop:
            body_rates = body_rates_from_euler_rates(e[0], e[1], e_dot)
            acc = np.array(law.step(e, e_dot, body_rates, Z3, Z3, Z3, DT, False)) / inertia_or_mass
        else:
            acc = np.array(law.step(e, e_dot, Z3, Z3, Z3, Z3, 0.0, DT, False)[3:6])
        A[:size, col] = x[size:] / h
        A[size:, col] = acc / h
    return np.sort(np.linalg.eigvals(A).real)


def test_linearised_position_loop_is_the_backstepping_loops():
    """k_x / m = 1 + c1 c2 = 43.5 and k_v / m = c1 + c2 = 19.5: s^2 + 19.5 s + 43.5 per axis, as the
    backstepping outer loop of BS-NLHinf (c1 = 17, c2 = 2.5)."""
    se3 = closed_loop_poles(translational("se3"), 3, M, False)
    bs = closed_loop_poles(translational("bs_nlhinf"), 3, M, False)
    assert se3 == pytest.approx(bs, abs=1e-3)
    expected = sorted(np.roots([1.0, 19.5, 43.5]).real.tolist() * 3)  # -16.93, -2.57 per axis
    assert se3 == pytest.approx(expected, abs=1e-3)


def test_linearised_attitude_loop_is_bs_nlhinfs():
    """k_R = k_d / omega_u^2 and k_W = J k_d + 1 / omega_u^2 (k_d = omega2 / omega1 = 30): J s^2 +
    k_W s + k_R has the poles of the NLHinf loop without integral, -1 / (omega_u^2 J) and -k_d:
    -111.1 and -30 (roll, pitch), -52.9 and -30 (yaw)."""
    poles = closed_loop_poles(rotational("se3"), 3, J, True)
    expected = sorted([-1 / (2.25 * 0.004)] * 2 + [-1 / (2.25 * 0.0084)] + [-30.0] * 3)
    assert poles == pytest.approx(expected, abs=0.05)


def reference(t):
    """A smooth attitude motion and its first two derivatives."""
    a, w, ph = np.array([0.3, 0.2, 0.5]), np.array([2.0, 3.0, 1.0]), np.array([0.0, 0.5, 0.2])
    s, c = np.sin(w * t + ph), np.cos(w * t + ph)
    return tuple(a * s), tuple(a * w * c), tuple(-a * w * w * s)


def fly_attitude(law, seconds, feed_forward=True, dt=1e-3):
    """The nominal rigid body (J W' + W x J W = M, eta' = W_eta^-1 W) under the law by RK4, started
    on the reference: the largest attitude error seen (rad)."""

    def derivative(t, eta, w):
        eta_d, eta_d_dot, eta_d_ddot = reference(t)
        if not feed_forward:
            eta_d_dot, eta_d_ddot = Z3, Z3
        eta_dot = euler_rates_from_body_rates(eta[0], eta[1], tuple(w))
        tau = np.array(law.step(tuple(eta), eta_dot, tuple(w), eta_d, eta_d_dot, eta_d_ddot, dt, False))
        return np.array(eta_dot), (tau - np.cross(w, J * w)) / J

    eta_d, eta_d_dot, _ = reference(0.0)
    eta, w = np.array(eta_d), np.array(body_rates_from_euler_rates(eta_d[0], eta_d[1], eta_d_dot))
    worst, t = 0.0, 0.0
    for _ in range(round(seconds / dt)):
        k1 = derivative(t, eta, w)
        k2 = derivative(t + dt / 2, eta + dt / 2 * k1[0], w + dt / 2 * k1[1])
        k3 = derivative(t + dt / 2, eta + dt / 2 * k2[0], w + dt / 2 * k2[1])
        k4 = derivative(t + dt, eta + dt * k3[0], w + dt * k3[1])
        eta = eta + dt / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
        w = w + dt / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
        t += dt
        worst = max(worst, float(np.abs(eta - reference(t)[0]).max()))
    return worst


def test_feed_forward_tracks_a_reference_attitude_motion_with_zero_error():
    """Started on a reference swinging up to 0.5 rad at up to 3 rad/s: with W_d and W_d' fed
    forward the nominal closed loop stays on it (error at the integrator's accuracy); without them
    (RotorPy's form) it lags by about 0.03 rad."""
    law = rotational("se3")
    assert fly_attitude(law, 3.0) < 1e-9
    assert fly_attitude(law, 3.0, feed_forward=False) > 1e-2


def test_parameters_are_lees_gains():
    from autopilot.control.config import load_controller
    from autopilot.params.definitions import controller_params

    names = {p.name: p.default for p in controller_params(load_controller("se3"))}
    assert names["SE3_KX"] == 32.19 and names["SE3_KV"] == 14.43
    assert (names["SE3_KR_R"], names["SE3_KR_P"], names["SE3_KR_Y"]) == (13.3333,) * 3
    assert (names["SE3_KW_R"], names["SE3_KW_Y"]) == (0.56444, 0.69644)
    assert math.isclose(names["SE3_KX"] / M, 43.5, rel_tol=1e-3)
