"""Physics invariants of the plant core (coupled and nominal)."""

import json
import math
import os
import random
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from quadcommon.config import load_vehicle
from quadcommon.kernel import compiling
from quadcommon.layout import values
from quadcommon.rigid_body import rotation_from_quaternion
from simulator.dynamics.equations import INPUTS
from simulator.dynamics.nominal_plant import NominalPlant, nominal_derivative
from simulator.dynamics.plant import Plant, TruthState

DT = 0.001


def vehicle(**plant_changes):
    v = load_vehicle("paper_quad")
    return replace(v, plant=replace(v.plant, **plant_changes))


def rigid_body_invariants(plant: Plant):
    s = plant.state
    J = np.array(plant.inertia)
    w = np.array(s[10:13])
    R = np.array(rotation_from_quaternion(*s[6:10]))
    return 0.5 * w @ J @ w, R @ J @ w


def test_torque_free_body_conserves_energy_and_angular_momentum():
    """Full inertia tensor, CoM offset, tumbling, no thrust, 10 s: drift below 1e-9 relative."""
    plant = Plant(vehicle(ground_contact=False), DT)
    plant.reset((0.0, 0.0, 100.0), (0.2, -0.3, 0.5), body_rates_rad_s=(3.0, -2.0, 5.0))
    plant.set_wrench(0.0, (0.0, 0.0, 0.0))
    energy0, momentum0 = rigid_body_invariants(plant)
    vz0 = plant.state[5]
    for _ in range(10_000):
        plant.step()
    energy, momentum = rigid_body_invariants(plant)
    assert abs(energy - energy0) / energy0 < 1e-9
    assert np.linalg.norm(momentum - momentum0) / np.linalg.norm(momentum0) < 1e-9
    # and the CoM falls freely: v_G(10 s) = v_G(0) - g t
    assert plant.state[5] - vz0 == pytest.approx(-9.81 * 10.0, rel=1e-12)


def test_hover_is_an_equilibrium_of_the_nominal_model_with_nominal_thrust():
    v = load_vehicle()
    plant = NominalPlant(replace(v, plant=replace(v.plant, model="nominal")), DT)
    plant.reset((1.0, -2.0, 3.0), (0.0, 0.0, 0.7))
    plant.set_wrench(v.nominal.mass_kg * v.nominal.gravity_m_s2, (0.0, 0.0, 0.0))
    for _ in range(2000):
        plant.step()
    assert np.allclose(plant.state, [1.0, -2.0, 3.0, 0, 0, 0, 0, 0, 0.7, 0, 0, 0], atol=1e-12)


def test_hover_equilibrium_of_the_coupled_plant_balances_the_com_moment():
    """With the CoM offset, hover needs the torque that cancels the thrust moment about G."""
    v = vehicle(ground_contact=False)
    plant = Plant(v, DT)
    plant.reset((0.0, 0.0, 2.0), (0.0, 0.0, 0.0))
    weight = v.plant.mass_kg * v.nominal.gravity_m_s2
    rx, ry, _ = v.plant.com_offset_m
    plant.set_wrench(weight, (ry * weight, -rx * weight, 0.0))
    for _ in range(2000):
        plant.step()
    truth = plant.truth()
    assert np.allclose(truth.position_m, (0.0, 0.0, 2.0), atol=1e-12)
    assert np.allclose(truth.euler_rad, 0.0, atol=1e-12)
    assert np.allclose(truth.specific_force_body_m_s2, (0.0, 0.0, 9.81), atol=1e-9)


def test_coupled_plant_without_offsets_agrees_with_the_nominal_model():
    """Two formulations (Newton-Euler in quaternions; Euler-Lagrange in eta, eqs 1-6) agree."""
    v = vehicle(
        com_offset_m=(0.0, 0.0, 0.0),
        products_of_inertia_kg_m2=(0.0, 0.0, 0.0),
        ground_contact=False,
    )
    coupled = Plant(v, DT)
    nominal = NominalPlant(replace(v, plant=replace(v.plant, model="nominal")), DT)
    for p in (coupled, nominal):
        p.reset((0.0, 0.0, 5.0), (0.1, -0.2, 0.5), body_rates_rad_s=(0.3, -0.2, 0.4))
    for k in range(3000):
        t = k * DT
        thrust = 7.3 + 0.5 * math.sin(3 * t)
        torque = (0.01 * math.sin(2 * t), -0.008 * math.cos(t), 0.004)
        for p in (coupled, nominal):
            p.set_wrench(thrust, torque)
            p.set_disturbance((0.2, -0.1, 0.3), (0.01, 0.02, -0.01))
            p.step()
    a, b = coupled.truth(), nominal.truth()
    # RK4 in two different coordinate sets: agreement to the integration error, ~1e-7 here
    assert np.allclose(a.position_m, b.position_m, atol=1e-6)
    assert np.allclose(a.velocity_m_s, b.velocity_m_s, atol=1e-6)
    angle_gap = (np.array(a.euler_rad) - np.array(b.euler_rad) + np.pi) % (2 * np.pi) - np.pi
    assert np.allclose(angle_gap, 0.0, atol=1e-7)
    assert np.allclose(a.body_rates_rad_s, b.body_rates_rad_s, atol=1e-7)


def test_force_disturbance_accelerates_the_com():
    v = vehicle(ground_contact=False)
    plant = Plant(v, DT)
    plant.reset((0.0, 0.0, 2.0), (0.0, 0.0, 0.0))
    plant.set_wrench(0.0, (0.0, 0.0, 0.0))
    plant.set_disturbance((1.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    plant.step()
    assert plant.truth().acceleration_m_s2[0] == pytest.approx(1.0 / v.plant.mass_kg, rel=1e-9)


def test_euler_torque_disturbance_is_the_generalised_force_of_eq_4():
    """A pure yaw generalised torque at a tilted attitude gives M eta_ddot = tau (at rest)."""
    v = vehicle(
        com_offset_m=(0.0, 0.0, 0.0),
        products_of_inertia_kg_m2=(0.0, 0.0, 0.0),
        ground_contact=False,
    )
    nominal = NominalPlant(replace(v, plant=replace(v.plant, model="nominal")), DT)
    nominal.reset((0.0, 0.0, 3.0), (0.3, 0.2, 0.0))
    from quadcommon.rigid_body import inertia_matrix, solve3

    expected = solve3(inertia_matrix(v.plant.inertia_kg_m2, 0.3, 0.2), (0.0, 0.0, 1.0))
    held = values(INPUTS, thrust=0.0, torque=(0.0, 0.0, 0.0), rotor_commands=(0.0, 0.0, 0.0, 0.0),
                  disturbance_force=(0.0, 0.0, 0.0), disturbance_torque=(0.0, 0.0, 1.0), wind=(0.0, 0.0, 0.0))
    derivative = [0.0] * 12
    nominal_derivative(nominal.state, derivative, nominal.parameters(), held)
    assert derivative[9:12] == pytest.approx(expected, rel=1e-12)
    coupled = Plant(v, DT)
    coupled.reset((0.0, 0.0, 3.0), (0.3, 0.2, 0.0))
    coupled.set_disturbance((0.0, 0.0, 0.0), (0.0, 0.0, 1.0))
    h = 1e-4
    coupled.dt = h
    coupled.step()
    rates = coupled.truth().euler_rates_rad_s
    assert np.array(rates) / h == pytest.approx(expected, rel=1e-3)


def test_resting_on_the_ground_disarmed():
    plant = Plant(vehicle(), DT)
    plant.reset((0.0, 0.0, 0.0), (0.0, 0.0, 0.3))
    plant.set_wrench(0.0, (0.0, 0.0, 0.0))
    for _ in range(1000):
        plant.step()
    truth = plant.truth()
    assert truth.position_m[2] == pytest.approx(0.0, abs=1e-12)
    assert truth.on_ground
    assert truth.euler_rad[2] == pytest.approx(0.3)
    assert truth.specific_force_body_m_s2 == pytest.approx((0.0, 0.0, 9.81))


def test_dropped_vehicle_stops_at_the_ground():
    plant = Plant(vehicle(), DT)
    plant.reset((0.0, 0.0, 1.0), (0.1, 0.0, 0.0))
    plant.set_wrench(0.0, (0.0, 0.0, 0.0))
    for _ in range(1000):
        plant.step()
    assert plant.truth().position_m[2] == pytest.approx(0.0, abs=1e-9)
    assert plant.truth().on_ground


def test_rotor_mode_hover_and_yaw_sign():
    v = vehicle(
        ground_contact=False,
        com_offset_m=(0.0, 0.0, 0.0),
        products_of_inertia_kg_m2=(0.0, 0.0, 0.0),
    )
    v = replace(v, actuation=replace(v.actuation, mode="rotors"))
    plant = Plant(v, DT)
    plant.reset((0.0, 0.0, 2.0), (0.0, 0.0, 0.0))
    hover_speed = math.sqrt(v.plant.mass_kg * 9.81 / (4 * v.rotors.thrust_coefficient_n_s2))
    plant.state[13:17] = [hover_speed] * 4
    plant.set_rotor_commands((hover_speed,) * 4)
    for _ in range(1000):
        plant.step()
    assert plant.truth().position_m == pytest.approx((0.0, 0.0, 2.0), abs=1e-9)
    assert plant.truth().thrust_n == pytest.approx(v.plant.mass_kg * 9.81)
    # rotors 2 and 4 faster (clockwise from above): reaction torque turns the body to +yaw
    plant.set_rotor_commands((hover_speed - 10, hover_speed + 10, hover_speed - 10, hover_speed + 10))
    for _ in range(200):
        plant.step()
    assert plant.truth().body_rates_rad_s[2] > 0.0
    # rotor 4 (left) faster than 2 (right): positive roll
    plant.reset((0.0, 0.0, 2.0), (0.0, 0.0, 0.0))
    plant.state[13:17] = [hover_speed] * 4
    plant.set_rotor_commands((hover_speed, hover_speed - 5, hover_speed, hover_speed + 5))
    for _ in range(100):
        plant.step()
    assert plant.truth().body_rates_rad_s[0] > 0.0


def test_rotor_speed_limits_and_first_order_lag():
    v = vehicle(ground_contact=False)
    v = replace(v, actuation=replace(v.actuation, mode="rotors"))
    plant = Plant(v, DT)
    plant.reset((0.0, 0.0, 2.0), (0.0, 0.0, 0.0))
    plant.set_rotor_commands((1e6, 1e6, 1e6, 1e6))
    assert plant.rotor_cmd == (v.rotors.speed_max_rad_s,) * 4
    steps = round(v.rotors.time_constant_s / DT)
    for _ in range(steps):
        plant.step()
    # one time constant: 1 - 1/e of the command
    assert plant.state[13] == pytest.approx(v.rotors.speed_max_rad_s * (1 - math.exp(-1)), rel=1e-6)


def test_wrench_saturation():
    v = vehicle()
    plant = Plant(v, DT)
    plant.set_wrench(100.0, (5.0, -5.0, 0.5))
    assert plant.thrust_cmd == v.actuation.thrust_max_n
    assert plant.torque_cmd == (1.5, -1.5, 0.5)
    plant.set_actuator_controls((0.5, 1.0, -0.5, 0.0))
    assert plant.thrust_cmd == pytest.approx(14.0)
    assert plant.torque_cmd == pytest.approx((1.5, -0.75, 0.0))


def random_controls(rng: random.Random, top: float) -> tuple[float, ...]:
    return (rng.uniform(0.0, top), *(rng.uniform(-0.3, 0.3) for _ in range(3)))


def random_frame(rng: random.Random) -> list[tuple[tuple[float, ...], ...]]:
    """Two physics steps' (force, torque on eta, wind)."""
    return [tuple(tuple(rng.gauss(0.0, sd) for _ in range(3)) for sd in (0.5, 0.02, 2.0)) for _ in range(2)]


def flattened(truth: TruthState) -> list:
    return [x for field in truth for x in (field if isinstance(field, tuple) else (field,))]


def random_flight(frames: int = 1500) -> dict[str, list]:
    """Each vehicle model flown from a tumbling start under random controls and disturbances
    (wind with drag, rotors with their lag, torques on the Euler coordinates), frames of two
    physics steps flown by ``advance`` and by ``step`` in turn, down onto the ground: the final
    state and the truth every 50 frames, flattened; and the nominal Section II model."""
    flown = {}
    for name in ("paper_quad", "paper_quad_drag", "paper_quad_rotors", "nominal"):
        if name == "nominal":
            v = load_vehicle("paper_quad")
            plant = NominalPlant(replace(v, plant=replace(v.plant, model="nominal")), DT)
        else:
            plant = Plant(load_vehicle(name), DT)
        rng = random.Random(7)
        plant.reset((0.0, 0.0, 0.3), (0.05, -0.03, 0.5), (0.2, -0.1, 0.0), (0.1, 0.0, -0.2))
        numbers: list = []
        for k in range(frames):
            plant.set_actuator_controls(random_controls(rng, 0.9 if k < frames // 2 else 0.2))
            frame = random_frame(rng)
            if k % 2:
                plant.advance(frame)
            else:
                for force, torque, wind in frame:
                    plant.set_disturbance(force, torque, wind)
                    plant.step()
            if k % 50 == 0:
                numbers += flattened(plant.truth())
        flown[name] = [*numbers, *plant.state, plant.on_ground(), *plant.kinematics()[0]]
    return flown


@pytest.mark.timeout(300)
def test_python_and_compiled_plants_fly_the_same_flight():
    """The equations are one source (simulator/dynamics/equations.py) that numba compiles and
    Python runs: the same random flight, here compiled and in a subprocess with
    QUADSITL_PURE_PYTHON=1, agrees to rounding (measured: bit for bit), landing included."""
    if not compiling():
        pytest.skip("the plant runs in Python here (numba missing or QUADSITL_PURE_PYTHON=1)")
    script = "import json; from tests.simulator.test_plant import random_flight as f; print(json.dumps(f()))"
    env = {**os.environ, "QUADSITL_PURE_PYTHON": "1"}
    root = Path(__file__).resolve().parents[2]
    python = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=240, env=env, cwd=root
    )
    assert python.returncode == 0, python.stderr
    in_python = json.loads(python.stdout)
    here = random_flight()
    for name, numbers in here.items():
        assert len(numbers) == len(in_python[name])
        assert numbers == pytest.approx(in_python[name], rel=1e-12, abs=1e-12), name
        assert numbers[-4] is True and in_python[name][-4] is True  # landed: on the ground at the end


@pytest.mark.parametrize("name", ["paper_quad_drag", "paper_quad_rotors"])
def test_a_frame_advanced_in_one_call_is_its_steps_and_its_truth(name):
    """advance(frame) flies what set_disturbance + step per physics step flies, and its truth is
    the one truth() reads off the state afterwards."""
    one_call, step_by_step = Plant(load_vehicle(name), DT), Plant(load_vehicle(name), DT)
    rng = random.Random(3)
    for plant in (one_call, step_by_step):
        plant.reset((0.0, 0.0, 5.0), (0.1, -0.2, 0.3), (1.0, 0.0, -0.5), (0.3, -0.2, 0.1))
    for _ in range(300):
        controls = random_controls(rng, 0.8)
        frame = random_frame(rng)
        for plant in (one_call, step_by_step):
            plant.set_actuator_controls(controls)
        one_call.advance(frame)
        for force, torque, wind in frame:
            step_by_step.set_disturbance(force, torque, wind)
            step_by_step.step()
        assert one_call.state == step_by_step.state
        assert one_call.truth() == step_by_step.truth()
