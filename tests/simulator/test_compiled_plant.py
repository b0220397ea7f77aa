"""The compiled plant step (simulator/dynamics/compiled.py, numba) is the Python reference
(Plant.step with QUADSITL_PURE_PYTHON=1) bit for bit: every vehicle model, random inputs and
disturbances each step, wind with drag, rotors with their lag, landing on the ground."""

from __future__ import annotations

import random

import pytest

from quadcommon.config import load_vehicle
from simulator.dynamics.plant import Plant

pytest.importorskip("numba")


def pair(monkeypatch, vehicle: str):
    compiled = Plant(load_vehicle(vehicle), 0.001)
    monkeypatch.setenv("QUADSITL_PURE_PYTHON", "1")
    reference = Plant(load_vehicle(vehicle), 0.001)
    monkeypatch.delenv("QUADSITL_PURE_PYTHON")
    assert compiled._compiled is not None and reference._compiled is None
    return compiled, reference


@pytest.mark.parametrize("vehicle", ["paper_quad", "paper_quad_drag", "paper_quad_rotors"])
def test_compiled_steps_equal_the_python_reference_bit_for_bit(monkeypatch, vehicle):
    compiled, reference = pair(monkeypatch, vehicle)
    rng = random.Random(7)
    for plant in (compiled, reference):
        plant.reset((0.0, 0.0, 0.3), (0.05, -0.03, 0.5), (0.2, -0.1, 0.0), (0.1, 0.0, -0.2))
    for k in range(3000):  # 3 s: climbs, tumbles a little, comes down onto the ground
        controls = (rng.uniform(0.0, 0.9 if k < 1500 else 0.2), *(rng.uniform(-0.3, 0.3) for _ in range(3)))
        force = tuple(rng.gauss(0.0, 0.5) for _ in range(3))
        torque = tuple(rng.gauss(0.0, 0.02) for _ in range(3))
        wind = tuple(rng.gauss(0.0, 2.0) for _ in range(3))
        for plant in (compiled, reference):
            plant.set_actuator_controls(controls)
            plant.set_disturbance(force, torque, wind)
            plant.step()
        assert compiled.state == reference.state, f"step {k}"
        if k % 10 == 0:
            assert compiled.truth() == reference.truth(), f"truth at step {k}"
    assert compiled.truth() == reference.truth()


def test_vehicle_at_rest_on_the_ground_stays_there(monkeypatch):
    compiled, reference = pair(monkeypatch, "paper_quad")
    for plant in (compiled, reference):
        plant.reset((0.0, 0.0, 0.0), (0.0, 0.0, 1.0))
        for _ in range(500):
            plant.step()
    assert compiled.state == reference.state
    assert compiled.truth() == reference.truth()
    assert compiled.truth().on_ground and abs(compiled.truth().position_m[2]) < 1e-9


@pytest.mark.parametrize("vehicle", ["paper_quad", "paper_quad_drag", "paper_quad_rotors"])
def test_a_frame_advanced_in_one_call_equals_its_steps_and_its_truth_bit_for_bit(monkeypatch, vehicle):
    """Plant.advance (the lockstep frame: two steps, each its own disturbance, then the truth read-out,
    one compiled call) against set_disturbance + step per step and the Python truth."""
    compiled, reference = pair(monkeypatch, vehicle)
    rng = random.Random(11)
    for plant in (compiled, reference):
        plant.reset((0.0, 0.0, 0.3), (0.05, -0.03, 0.5), (0.2, -0.1, 0.0), (0.1, 0.0, -0.2))
    for k in range(1500):  # 3 s at 500 Hz frames: climbs, tumbles a little, lands
        controls = (rng.uniform(0.0, 0.9 if k < 750 else 0.2), *(rng.uniform(-0.3, 0.3) for _ in range(3)))
        disturbances = [tuple(tuple(rng.gauss(0.0, sd) for _ in range(3)) for sd in (0.5, 0.02, 2.0))
                        for _ in range(2)]  # fmt: skip
        for plant in (compiled, reference):
            plant.set_actuator_controls(controls)
        compiled.advance(disturbances)
        for force, torque, wind in disturbances:
            reference.set_disturbance(force, torque, wind)
            reference.step()
        assert compiled.state == reference.state, f"frame {k}"
        assert compiled.truth() == reference.truth(), f"truth of frame {k}"
    assert compiled.truth().on_ground


def test_the_truth_of_an_advance_is_not_served_once_the_state_or_an_input_changed(monkeypatch):
    compiled, reference = pair(monkeypatch, "paper_quad")
    for plant in (compiled, reference):
        plant.reset((0.0, 0.0, 1.0), (0.0, 0.0, 0.0))
        plant.set_actuator_controls((0.5, 0.0, 0.0, 0.0))
        plant.advance([((0.0, 0.0, 0.0),) * 3] * 2)
    for plant in (compiled, reference):
        plant.set_actuator_controls((0.6, 0.1, 0.0, 0.0))  # a new answer: thrust and torque in the truth
    assert compiled.truth() == reference.truth()
    assert compiled.truth().thrust_n == pytest.approx(0.6 * load_vehicle("paper_quad").actuation.thrust_max_n)
    for plant in (compiled, reference):
        plant.advance([((0.0, 0.0, 0.0),) * 3] * 2)
        plant.state[2] = 5.0  # changed in place
    assert compiled.truth() == reference.truth()
    assert compiled.truth().position_m[2] == pytest.approx(5.0, abs=0.05)  # O, 2 cm below G
