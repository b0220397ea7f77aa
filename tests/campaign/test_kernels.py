"""The kernels' building blocks equal the scalar code they transcribe (same values, bitwise)."""

import math

import numpy as np
import pytest

pytest.importorskip("numba")

from autopilot.control import compiled as cc  # noqa: E402
from autopilot.control.allocation import Allocator  # noqa: E402
from quadcommon import frames, rigid_body  # noqa: E402
from quadcommon.config import load_vehicle  # noqa: E402
from simulator.dynamics import compiled as cp  # noqa: E402
from simulator.dynamics.plant import Plant  # noqa: E402
from sitl.campaign import engine as eng  # noqa: E402
from sitl.campaign import kernels as ker  # noqa: E402

RNG = np.random.default_rng(11)


def _random_state(rotors: bool) -> list[float]:
    q = RNG.normal(size=4)
    q /= np.linalg.norm(q)
    s = [*RNG.normal(size=3), *RNG.normal(size=3), *q, *RNG.normal(scale=2.0, size=3)]
    if rotors:
        s += list(RNG.uniform(200.0, 450.0, size=4))
    return [float(v) for v in s]


@pytest.mark.timeout(120)
@pytest.mark.parametrize("mode", ["wrench", "rotors"])
def test_derivative_and_rk4_step_equal_the_plant(mode, monkeypatch):
    monkeypatch.setenv("QUADSITL_PURE_PYTHON", "1")  # the reference: Plant's own Python step
    from dataclasses import replace

    vehicle = load_vehicle("paper_quad_drag")
    vehicle = replace(vehicle, actuation=replace(vehicle.actuation, mode=mode))
    plant = Plant(vehicle, 1e-3)
    P = eng.plant_array(plant)
    for _ in range(50):
        s = _random_state(mode == "rotors")
        s[2] += 10.0  # in the air: plant.step() resolves ground contact, tested separately
        thrust, torque = float(RNG.uniform(0, 20)), tuple(float(v) for v in RNG.normal(scale=0.5, size=3))
        force, tq_eta, wind = (tuple(float(v) for v in RNG.normal(size=3)) for _ in range(3))
        rotor = tuple(float(v) for v in RNG.uniform(0, 491, size=4))
        plant.state = list(s)
        plant.set_wrench(thrust, torque)
        plant.set_rotor_commands(rotor)
        plant.set_disturbance(force, tq_eta, wind)
        u = np.zeros(ker.U_SIZE)
        u[ker.U_THRUST], u[ker.U_TAU : ker.U_TAU + 3] = plant.thrust_cmd, plant.torque_cmd
        u[ker.U_ROTOR : ker.U_ROTOR + 4] = plant.rotor_cmd
        u[ker.U_FORCE : ker.U_FORCE + 3], u[ker.U_TORQUE : ker.U_TORQUE + 3] = force, tq_eta
        u[ker.U_WIND : ker.U_WIND + 3] = wind
        out = np.zeros(len(s))
        cp.derivative(np.array(s), out, P, u)
        assert out.tolist() == plant._derivative(s)
        arr = np.array(s)
        n = len(s)
        cp.rk4_step(arr, *(np.empty(n) for _ in range(5)), P, u, 1e-3)
        plant.step()
        assert arr.tolist() == plant.state


@pytest.mark.timeout(120)
def test_ground_contact_and_readout_equal_the_plant(monkeypatch):
    monkeypatch.setenv("QUADSITL_PURE_PYTHON", "1")
    plant = Plant(load_vehicle("paper_quad"), 1e-3)
    P = eng.plant_array(plant)
    for _ in range(50):
        s = _random_state(False)
        s[2] = float(RNG.uniform(-0.05, 0.01))
        s[5] = float(RNG.uniform(-1.0, 0.2))
        plant.state = list(s)
        pos, vel, euler, _ = plant.kinematics()
        kpos, kvel, keuler, cos_tilt = cp.truth_of_O(np.array(s), P)
        assert (kpos, kvel, keuler) == (pos, vel, euler)
        assert cos_tilt == pytest.approx(math.cos(euler[0]) * math.cos(euler[1]), abs=1e-12)
        arr = np.array(s)
        acted = cp.ground_contact(arr, P)
        plant._resolve_ground_contact()
        assert arr.tolist() == plant.state
        assert acted == (plant.state != s)


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
        assert cp.quaternion_from_euler(phi, theta, psi) == rigid_body.quaternion_from_euler(phi, theta, psi)
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
