"""The kernels' building blocks equal the scalar code they transcribe (same values, bitwise)."""

import math

import numpy as np
import pytest

pytest.importorskip("numba")

from autopilot.control import compiled as cc  # noqa: E402
from autopilot.control.allocation import Allocator  # noqa: E402
from quadcommon import frames, rigid_body  # noqa: E402
from quadcommon.config import load_vehicle  # noqa: E402

RNG = np.random.default_rng(11)


@pytest.mark.timeout(120)
def test_rigid_body_helpers_equal_quadcommon():
    inertia = (0.004, 0.0045, 0.0084)
    for _ in range(200):
        phi, theta, psi = (float(v) for v in RNG.uniform(-1.2, 1.2, size=3))
        rates = tuple(float(v) for v in RNG.normal(size=3))
        M = rigid_body.inertia_matrix(inertia, phi, theta)
        assert cc.inertia_matrix(*inertia, phi, theta) == (M[0][0], M[0][2], M[1][1], M[1][2], M[2][2])
        C = rigid_body.coriolis_matrix(inertia, (phi, theta, psi), rates)
        assert cc.coriolis_matrix(*inertia, phi, theta, *rates) == tuple(v for row in C for v in row)
        tau = tuple(float(v) for v in RNG.normal(size=3))
        assert cc.body_torque_from_euler_torque(
            phi, theta, *tau
        ) == rigid_body.body_torque_from_euler_torque(phi, theta, tau)
        assert cc.euler_torque_from_body_torque(
            phi, theta, *tau
        ) == rigid_body.euler_torque_from_body_torque(phi, theta, tau)
        assert cc.euler_rates_from_body_rates(phi, theta, *rates) == rigid_body.euler_rates_from_body_rates(
            phi, theta, rates
        )
        angle = float(RNG.uniform(-20.0, 20.0))
        assert cc.wrap_pi(angle) == frames.wrap_pi(angle)
    for edge in (-math.pi, math.pi, 0.0, -0.0, 3 * math.pi, -3 * math.pi):
        assert cc.wrap_pi(edge) == frames.wrap_pi(edge)


@pytest.mark.timeout(120)
def test_rotor_allocation_equals_allocator():
    from dataclasses import replace

    vehicle = load_vehicle("paper_quad")
    vehicle = replace(vehicle, actuation=replace(vehicle.actuation, mode="rotors"))
    alloc = Allocator(vehicle)
    C = np.zeros(cc.C_SIZE)
    C[cc.C_AB], C[cc.C_AD], C[cc.C_AARM] = alloc.b, alloc.d, alloc.arm
    C[cc.C_SQMIN], C[cc.C_SQMAX], C[cc.C_SPEED_MAX] = alloc.sq_min, alloc.sq_max, alloc.speed_max
    saturated = 0
    for _ in range(300):
        thrust = float(RNG.uniform(-2.0, 32.0))
        tau = tuple(float(v) for v in RNG.normal(scale=0.3, size=3))
        ref = alloc.to_rotors(thrust, tau)
        out = np.zeros(4)
        U1, t0, t1, t2, sat = cc.allocate_rotors(C, thrust, *tau, out)
        assert (U1, (t0, t1, t2)) == (ref.thrust_n, ref.torque_body_n_m)
        assert tuple(out) == ref.normalised
        saturated += sat
    assert 0 < saturated < 300  # both branches were exercised
