"""Actuator faults in the plant (the motor unit of quadcommon/failures.py): a rotor at a loss of
effectiveness, stuck, off; PX4's motor numbers mapped to the rotors by position; on the ideal-wrench
vehicle through the allocation's equation; at a time from a scenario's [[actuator_faults]].

The invariants are checked against the autopilot's allocation (autopilot/control/allocation.py),
which the plant does not import: both read quadcommon/rotor_geometry.py."""

from __future__ import annotations

import dataclasses
import math

import pytest

from autopilot.control.allocation import Allocator
from quadcommon.bus_records import TRUTH_FIELDS
from quadcommon.config import config_path, load_scenario, load_vehicle
from quadcommon.failures import PX4_MOTOR_POSITIONS, ActuatorFault, Type, Unit
from quadcommon.rotor_geometry import wrench_from_squares
from quadcommon.schema import ConfigError
from simulator.core import SimulatorCore, SimulatorSetup
from simulator.dynamics.plant import HEALTHY, ROTOR_POSITIONS, RotorFault, rotor_of_motor

pytestmark = pytest.mark.timeout(60)

# A wrench inside the rotor set's limits: every rotor's squared speed within (0, Omega_max^2).
WRENCH = (9.0, (0.08, -0.05, 0.02))


def hovering_rotors(wrench=WRENCH) -> tuple[SimulatorCore, tuple[float, ...]]:
    """The rotors vehicle in the air, its rotors at the speeds the allocation gives ``wrench``."""
    core = SimulatorCore(SimulatorSetup.load(vehicle="paper_quad_rotors"))
    plant = core.plant
    plant.reset((0.0, 0.0, 5.0), (0.0, 0.0, 0.0))
    speeds = Allocator(core.setup.vehicle).to_rotors(wrench[0], wrench[1]).speeds_rad_s
    plant.state[13:17] = list(speeds)
    plant.set_rotor_commands(speeds)
    return core, speeds


def squares(speeds) -> list[float]:
    return [w * w for w in speeds]


@pytest.mark.parametrize("rotor", [1, 2, 3, 4])
@pytest.mark.parametrize("effectiveness", [0.0, 0.7])
def test_a_rotors_loss_of_effectiveness_takes_its_share_of_thrust_and_torque(rotor, effectiveness):
    """Rotor i at effectiveness e: the plant's wrench is the allocation's wrench at the same speeds
    with rotor i's squared speed scaled by e; at e = 0 exactly its thrust b Omega_i^2 and its
    torques (arm and reaction) are gone, the others' unchanged."""
    core, speeds = hovering_rotors()
    plant = core.plant
    healthy = plant.truth()
    assert healthy.thrust_n == pytest.approx(WRENCH[0], rel=1e-12)  # the allocation's own wrench
    assert healthy.torque_body_n_m == pytest.approx(WRENCH[1], rel=1e-9, abs=1e-12)
    plant.set_rotor_fault(rotor, RotorFault.of(Type.wrong, effectiveness))
    failed = plant.truth()
    s = squares(speeds)
    lost = s[rotor - 1]
    s[rotor - 1] *= effectiveness
    thrust, *torque = wrench_from_squares(plant.b, plant.d, plant.arm, *s)
    assert failed.thrust_n == pytest.approx(thrust, rel=1e-12)
    assert failed.torque_body_n_m == pytest.approx(tuple(torque), rel=1e-9, abs=1e-12)
    loss = (1.0 - effectiveness) * lost
    assert healthy.thrust_n - failed.thrust_n == pytest.approx(plant.b * loss, rel=1e-9)
    # the rotor's own torque contribution, by position: + configuration, 1 front, 2 right, 3 rear, 4 left
    lb, d = plant.arm * plant.b, plant.d
    lever = {1: (0.0, -lb, -d), 2: (-lb, 0.0, d), 3: (0.0, lb, -d), 4: (lb, 0.0, d)}[rotor]
    for axis in range(3):
        change = healthy.torque_body_n_m[axis] - failed.torque_body_n_m[axis]
        assert change == pytest.approx(loss * lever[axis], rel=1e-9, abs=1e-12)


def test_a_rotor_stuck_holds_its_speed_and_a_rotor_off_spins_down():
    core, speeds = hovering_rotors()
    plant = core.plant
    plant.set_rotor_fault(2, RotorFault.of(Type.stuck))
    plant.set_rotor_fault(4, RotorFault.of(Type.off))
    assert plant.truth().thrust_n == pytest.approx(plant.b * sum(squares(speeds)[:3]), rel=1e-12)
    plant.set_rotor_commands((0.5 * plant.speed_max,) * 4)  # every rotor asked to change speed
    tau = plant.rotor_tau
    steps = round(3.0 * tau / plant.dt)
    for _ in range(steps):
        plant.step()
    w = plant.state[13:17]
    assert w[1] == speeds[1]  # stuck: exactly where it was
    assert w[3] == pytest.approx(speeds[3] * math.exp(-3.0), rel=1e-3)  # unpowered: towards 0, the lag's
    assert w[0] == pytest.approx(0.5 * plant.speed_max + (speeds[0] - 0.5 * plant.speed_max) * math.exp(-3.0),
                                 rel=1e-3)  # healthy: towards its command  # fmt: skip
    assert plant.rotor_fault(4) == RotorFault(RotorFault.of(Type.off).mode, 0.0)
    plant.set_rotor_fault(2, HEALTHY)
    plant.step()
    assert plant.state[14] != speeds[1]  # follows its command again


@pytest.mark.parametrize("rotor", [1, 2, 3, 4])
def test_the_ideal_wrench_vehicles_rotor_fails_through_the_allocation(rotor):
    """The paper's vehicle (actuation "wrench"): the commanded wrench is split into the rotors'
    shares by the allocation's equation; a rotor off removes its share (what the allocation gives
    that rotor), a loss of effectiveness e of every rotor scales the wrench by e, and a stuck rotor
    keeps the share it had when a new command arrives."""
    core = SimulatorCore(SimulatorSetup.load(vehicle="paper_quad"))
    plant = core.plant
    plant.reset((0.0, 0.0, 5.0), (0.0, 0.0, 0.0))
    plant.set_wrench(*WRENCH)
    assert plant.truth().thrust_n == WRENCH[0] and plant.truth().torque_body_n_m == WRENCH[1]
    s = squares(Allocator(load_vehicle("paper_quad")).to_rotors(*WRENCH).speeds_rad_s)
    share = s[rotor - 1]
    s[rotor - 1] = 0.0
    plant.set_rotor_fault(rotor, RotorFault.of(Type.off))
    failed = plant.truth()
    thrust, *torque = wrench_from_squares(plant.b, plant.d, plant.arm, *s)
    assert failed.thrust_n == pytest.approx(thrust, rel=1e-12)
    assert failed.torque_body_n_m == pytest.approx(tuple(torque), rel=1e-9, abs=1e-12)
    assert WRENCH[0] - failed.thrust_n == pytest.approx(plant.b * share, rel=1e-9)
    # stuck: the share of the command in force, whatever is commanded next
    plant.set_rotor_fault(rotor, RotorFault.of(Type.stuck))
    plant.set_wrench(0.5 * WRENCH[0], (0.0, 0.0, 0.0))
    hover = 0.5 * WRENCH[0] / (4.0 * plant.b)  # each rotor's share of a pure thrust
    s = [hover] * 4
    s[rotor - 1] = share
    thrust, *torque = wrench_from_squares(plant.b, plant.d, plant.arm, *s)
    assert plant.truth().thrust_n == pytest.approx(thrust, rel=1e-12)
    assert plant.truth().torque_body_n_m == pytest.approx(tuple(torque), rel=1e-9, abs=1e-12)
    for r in (1, 2, 3, 4):  # every rotor at 60 %: the wrench at 60 % (the equation is linear)
        plant.set_rotor_fault(r, RotorFault.of(Type.wrong, 0.6))
    plant.set_wrench(*WRENCH)
    assert plant.truth().thrust_n == pytest.approx(0.6 * WRENCH[0], rel=1e-12)
    assert plant.truth().torque_body_n_m == pytest.approx(tuple(0.6 * t for t in WRENCH[1]), rel=1e-9)
    for r in (1, 2, 3, 4):
        plant.set_rotor_fault(r, HEALTHY)
    assert plant.truth().thrust_n == WRENCH[0]  # healthy again: the wrench untouched, bit for bit


def test_px4_motor_numbers_and_all_of_them():
    core, _ = hovering_rotors()
    for number, position in enumerate(PX4_MOTOR_POSITIONS, 1):
        rotor = ROTOR_POSITIONS.index(position)
        assert rotor_of_motor(number) == rotor + 1
        assert core.inject_failure(Unit.motor, Type.off, number) is None
        assert core.plant.rotor_effectiveness[rotor] == 0.0
        assert core.rotor_health[rotor] == 0.0 and core.rotor_health[4 + rotor] == Type.off
        assert core.inject_failure(Unit.motor, Type.ok, number) is None
    assert core.inject_failure(Unit.motor, Type.off, 0) is None
    assert core.plant.rotor_effectiveness == [0.0] * 4 and core.plant.truth().thrust_n == 0.0
    assert core.failures == {f"motor {n}": "off" for n in (1, 2, 3, 4)}
    assert core.inject_failure(Unit.motor, Type.ok, 0) is None
    assert core.plant.rotor_effectiveness == [1.0] * 4 and core.failures == {}
    assert core.rotor_health == (1.0,) * 4 + (0.0,) * 4
    assert "outside [0, 1]" in core.inject_failure(Unit.motor, Type.wrong, 1, 1.5)


def test_a_scenarios_actuator_faults_apply_from_the_first_frame_at_or_after_their_time():
    """[[actuator_faults]] in a scenario: applied at the start of the first frame at or after
    start_s (as the campaign engine applies them), announced, in the truth row's rotor health."""
    scenario = dataclasses.replace(load_scenario("hover"), actuator_faults=(
        ActuatorFault(2, "wrong", 0.6, 0.0105), ActuatorFault(3, "stuck", 1.0, 0.005)))  # fmt: skip
    setup = dataclasses.replace(SimulatorSetup.load(vehicle="paper_quad_rotors"), scenario=scenario)
    logged: list[str] = []
    core = SimulatorCore(setup, logged.append)
    left, front = ROTOR_POSITIONS.index("left"), ROTOR_POSITIONS.index("front")
    effectiveness = []
    for _ in range(8):
        core.begin_frame()
        effectiveness.append(core.truth_row)
        core.end_frame(None)
    k_stuck, k_wrong = math.ceil(0.005 * core.control_hz), math.ceil(0.0105 * core.control_hz)  # frames 3, 6
    col = {name: i for i, name in enumerate(TRUTH_FIELDS)}
    wrong = [row[col[f"rotor{left + 1}_effectiveness"]] for row in effectiveness]
    stuck = [row[col[f"rotor{front + 1}_failure"]] for row in effectiveness]
    assert wrong == [1.0] * k_wrong + [0.6] * (8 - k_wrong)
    assert stuck == [0.0] * k_stuck + [float(Type.stuck)] * (8 - k_stuck)
    assert core.failures == {"motor 2": "wrong", "motor 3": "stuck"}
    assert [text.split(": ", 1)[1] for text in logged if "Injected" in text] == [
        "Injected: motor stuck, instances 3 (scenario, from 0.005 s)",
        "Injected: motor wrong, instances 2 (scenario, from 0.0105 s)",
    ]


FAULT = '[[actuator_faults]]\nmotor = {motor}\ntype = "{type}"\n'


@pytest.mark.parametrize(
    "table, key, allowed",
    [
        (FAULT.format(motor=5, type="off") + "start_s = 1.0\n", "actuator_faults[0].motor", "[0, 4]"),
        (FAULT.format(motor=1, type="garbage") + "start_s = 1.0\n", "actuator_faults[0].type", "stuck"),
        (FAULT.format(motor=1, type="wrong") + "effectiveness = 1.2\nstart_s = 1.0\n",
         "actuator_faults[0].effectiveness", "[0, 1]"),
        (FAULT.format(motor=1, type="off") + "effectiveness = 0.5\nstart_s = 1.0\n",
         "actuator_faults[0].effectiveness", 'type = "wrong"'),
        (FAULT.format(motor=1, type="off") + "start_s = 99.0\n", "actuator_faults[0].start_s", "20"),
        (FAULT.format(motor=1, type="off"), "actuator_faults[0].start_s", "missing"),
        (FAULT.format(motor=1, type="off") + "start_s = 1.0\nrotor = 2\n", "rotor", "unknown"),
    ],
)
def test_a_scenarios_actuator_faults_are_validated_with_the_key(tmp_path, table, key, allowed):
    text = (load_scenario_text() + "\n" + table).replace('name = "hover"', 'name = "hover_faults"')
    path = tmp_path / "hover_faults.toml"
    path.write_text(text)
    with pytest.raises(ConfigError) as error:
        load_scenario(str(path))
    assert str(path) in str(error.value) and key in str(error.value) and allowed in str(error.value)


def load_scenario_text() -> str:
    return config_path("scenarios", "hover").read_text()


def test_a_scenarios_actuator_faults_as_read(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text(load_scenario_text() + "\n" + FAULT.format(motor=0, type="wrong") + "start_s = 2.5\n")
    faults = load_scenario(str(path)).actuator_faults
    assert faults == (ActuatorFault(0, "wrong", 0.5, 2.5),)  # SIM_MOT_EFF's default figure
    assert faults[0].describe() == "all motors wrong (0.5 effectiveness) from 2.5 s"
