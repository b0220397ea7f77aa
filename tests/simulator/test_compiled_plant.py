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
        if k % 10 == 0:  # the compiled truth read-out too (its own kernel)
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
