"""A motor that is off (FAILURE_UNIT_SYSTEM_MOTOR): the rotor's effectiveness in the plant's
equations, PX4's motor numbers mapped to the rotors by position, the wrench vehicle refusing it."""

from __future__ import annotations

import pytest

from quadcommon.failures import PX4_MOTOR_POSITIONS, Type, Unit
from simulator.core import SimulatorCore, SimulatorSetup
from simulator.dynamics.plant import ROTOR_POSITIONS

pytestmark = pytest.mark.timeout(60)


def hovering_rotors() -> SimulatorCore:
    core = SimulatorCore(SimulatorSetup.load(vehicle="paper_quad_rotors"))
    plant = core.plant
    plant.reset((0.0, 0.0, 5.0), (0.0, 0.0, 0.0))
    speed = 0.6 * plant.speed_max
    plant.state[13:17] = [speed] * 4  # rotors spinning, equal speeds
    plant.set_rotor_commands((speed,) * 4)
    return core


def test_a_motor_off_gives_no_thrust_and_no_reaction_torque():
    core = hovering_rotors()
    plant = core.plant
    healthy = plant.truth()
    assert healthy.torque_body_n_m == pytest.approx((0.0, 0.0, 0.0), abs=1e-12)
    assert core.inject_failure(Unit.motor, Type.off, 1) is None  # PX4's motor 1: the right rotor
    right = ROTOR_POSITIONS.index("right")
    assert plant.rotor_effectiveness == [0.0 if i == right else 1.0 for i in range(4)]
    failed = plant.truth()
    assert failed.thrust_n == pytest.approx(0.75 * healthy.thrust_n)
    b, d, arm = plant.b, plant.d, plant.arm
    square = plant.state[13] ** 2
    # + configuration, rotor 2 right (tau_x = l b (Omega4^2 - Omega2^2), tau_z = d (-Omega1^2 +
    # Omega2^2 - Omega3^2 + Omega4^2)): the left rotor alone rolls the vehicle right (its right side
    # down), the reaction torques no longer cancel.
    assert failed.torque_body_n_m == pytest.approx((arm * b * square, 0.0, -d * square))
    before = plant.state[10]
    core.end_frame(None)  # (the emergency descent: still four rotors commanded alike)
    assert plant.state[10] > before  # it rolls


def test_px4_motor_numbers_and_all_of_them():
    core = hovering_rotors()
    for number, position in enumerate(PX4_MOTOR_POSITIONS, 1):
        assert core.inject_failure(Unit.motor, Type.off, number) is None
        rotor = ROTOR_POSITIONS.index(position)
        assert core.plant.rotor_effectiveness[rotor] == 0.0
        assert core.inject_failure(Unit.motor, Type.ok, number) is None
    assert core.inject_failure(Unit.motor, Type.off, 0) is None
    assert core.plant.rotor_effectiveness == [0.0] * 4 and core.plant.truth().thrust_n == 0.0
    assert core.failures == {f"motor {n}": "off" for n in (1, 2, 3, 4)}
    assert core.inject_failure(Unit.motor, Type.ok, 0) is None
    assert core.plant.rotor_effectiveness == [1.0] * 4 and core.failures == {}


def test_the_wrench_vehicle_has_no_rotor_to_lose():
    core = SimulatorCore(SimulatorSetup.load(vehicle="paper_quad"))
    assert "wrench actuation" in core.inject_failure(Unit.motor, Type.off, 1)
    with pytest.raises(ValueError, match="no rotors"):
        core.plant.set_rotor_effectiveness(1, 0.0)
