"""Campaigns that draw faults: a motor's loss of effectiveness, stuck or off per run
([[actuator_faults]]), sensor failures on the estimate ([[sensor_faults]] with a drawn kind); the
results' fault columns (survived, excursion, recovery, impact, the fault drawn); the ranking; and
the runs are the ones the scalar in-process stack flies with the same seeds and faults."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pyarrow as pa
import pytest

from quadcommon.failures import ActuatorFault
from quadcommon.schema import ConfigError
from sitl.campaign import batch
from sitl.campaign import engine as eng
from sitl.campaign.sampling import sample_run
from sitl.campaign.spec import load_campaign
from sitl.campaign.summary import fault_ranking, summary_markdown

pytestmark = pytest.mark.timeout(300)

ROTORS = """
name = "test_faults"
scenario = "helix"
vehicle = "{vehicle}"
controllers = ["intbs_nlhinf", "px4_pid"]
runs = 8
seed = 11
duration_s = {duration}

[plant]
mass_scale = {{ uniform = [0.8, 1.2] }}

[disturbances]
base = "none"

[[disturbances.step]]
channel = "force_x"
start_s = 0.5
value = 0.5

[[actuator_faults]]
motor = {{ choice = [1, 2, 3, 4] }}
type = {types}
effectiveness = {{ uniform = [0.4, 0.9] }}
start_s = {{ uniform = [1.0, 2.5] }}

[survival]
envelope_m = 0.5
recovery_bound_m = 0.05

[failure]
max_position_error_m = 2.0
max_tilt_rad = 1.2
"""


def write(tmp_path, vehicle="paper_quad_rotors", duration=4.0, types='"wrong"', extra="") -> str:
    path = tmp_path / "faults.toml"
    path.write_text(ROTORS.format(vehicle=vehicle, duration=duration, types=types) + extra)
    return str(path)


def fly_both(spec, run: int, controller):
    """Run ``run`` through the batch engine (recorded) and through the in-process stack (simulator
    core with the run's scenario and its drawn faults, MAVLink frames, autopilot core); the batch's
    rows and the stack's truth rows over the frames both flew (a failed batch run stops there)."""
    from sitl.inprocess import RunOptions, paper_stack

    sample = sample_run(spec, run)
    _, rows = eng.fly(batch.flights(spec, sample)[controller.name], record=True)
    est = spec.estimation
    options = RunOptions(duration_s=spec.duration_s, rates=spec.rates, gusts=sample.gusts,
                         estimator=spec.estimator, sensors=est.sensors_name if est else None,
                         sensor_config=sample.sensors, true_plant=sample.plant_vehicle,
                         initial_velocity_m_s=sample.initial_velocity_m_s)  # fmt: skip
    stack = paper_stack(sample.scenario, controller, options, sample.vehicle)
    for _ in range(len(rows) - 1):
        stack.step()
    stack.final_frame()
    return sample, rows, np.asarray(stack.truth_rows)


@pytest.mark.parametrize(
    ("vehicle", "types", "runs"),
    [
        ("paper_quad_rotors", '{ choice = ["wrong", "stuck", "off"] }', (0, 1, 2, 3)),
        ("paper_quad", '{ choice = ["wrong", "stuck", "off"] }', (0, 2, 3)),
    ],
)
def test_fault_campaign_runs_agree_with_the_in_process_stack(tmp_path, vehicle, types, runs):
    """Tolerance: the position and attitude at every frame agree to 1e-9 (m, rad), round-off: the
    batch engine sets the drawn faults into the plant through the same kernel and table the
    simulator core applies a scenario's with (simulator.dynamics.equations.rotor_faults_due), at
    the start of the first frame at or after their onset. Measured: identical bits. Each run as
    far as the batch engine flew it (a rotor off tumbles the vehicle: the run fails there)."""
    spec = load_campaign(write(tmp_path, vehicle=vehicle, types=types))
    kinds = set()
    for controller in spec.controllers:
        for run in runs:
            sample, rows, truth = fly_both(spec, run, controller)
            (fault,) = sample.scenario.actuator_faults
            kinds.add(fault.type)
            assert len(truth) == len(rows)
            position = np.abs(truth[:, 1:4] - rows[:, 1:4]).max()
            attitude = np.abs(truth[:, 14:17] - rows[:, 7:10]).max()
            assert position <= 1e-9 and attitude <= 1e-9, (run, controller.name, fault, position, attitude)
            if rows[-1, 0] > fault.start_s + 0.1:  # the fault acted: the flight is not the healthy one
                healthy = replace(sample.scenario, actuator_faults=())
                flight = batch.flights(spec, replace(sample, scenario=healthy))[controller.name]
                _, clean = eng.fly(flight, record=True)
                n = min(len(clean), len(rows))
                assert np.abs(clean[:n, 1:4] - rows[:n, 1:4]).max() > 1e-4
    assert kinds == {"wrong", "stuck", "off"}, kinds  # the runs cover the three


def test_a_sensor_failure_drawn_per_run_agrees_with_the_in_process_stack(tmp_path):
    """[[sensor_faults]] with a drawn kind, on the EKF: the same 1e-9 tolerance (the sensor kernel's
    failure rows, in both paths)."""
    path = tmp_path / "sensors.toml"
    path.write_text("""
name = "test_sensor_failures"
scenario = "helix"
controllers = ["intbs_nlhinf"]
runs = 4
seed = 3
duration_s = 4.0
estimator = "ekf"
sensors = "gps"

[[sensor_faults]]
kind = { choice = ["gps_off", "baro_stuck", "mag_garbage"] }
start_s = { uniform = [1.0, 2.0] }
""")
    spec = load_campaign(str(path))
    kinds = set()
    for run in (0, 1, 2, 3):
        sample, rows, truth = fly_both(spec, run, spec.controllers[0])
        kinds.add(sample.sensors.faults[-1].kind)
        assert sample.fault.startswith(sample.sensors.faults[-1].kind)
        position = np.abs(truth[:, 1:4] - rows[:, 1:4]).max()
        attitude = np.abs(truth[:, 14:17] - rows[:, 7:10]).max()
        assert position <= 1e-9 and attitude <= 1e-9, (run, position, attitude)
    assert len(kinds) >= 2, kinds
    row = batch.run_chunk(spec, [1])[0]
    assert row["fault"] == sample_run(spec, 1).fault and "fault0_kind_index" in row
    assert set(eng.FAULT_COLUMNS) <= row.keys()


def test_the_fault_columns_say_what_each_run_survived(tmp_path):
    spec = load_campaign(write(tmp_path, duration=6.0, types='{ choice = ["wrong", "off"] }'))
    rows = batch.run_chunk(spec, range(spec.runs))
    for row in rows:
        sample = sample_run(spec, row["run"])
        (fault,) = sample.scenario.actuator_faults
        assert row["fault"] == fault.describe() == sample.fault
        assert row["actuator_fault0_start_s"] == fault.start_s
        assert row["actuator_fault0_motor"] in (1.0, 2.0, 3.0, 4.0)
        if fault.type == "off":  # no law here flies three rotors: it tumbles, or crashes
            assert row["failed"] and not row["survived"] and math.isnan(row["time_to_recover_s"])
        else:
            assert 0.4 <= fault.effectiveness <= 0.9
        assert row["max_excursion_m"] <= row["max_position_error_m"]
        if row["survived"]:
            assert not row["failed"] and row["max_position_error_m"] <= spec.survival.envelope_m
            assert row["time_to_recover_s"] >= 0.0 or math.isnan(row["time_to_recover_s"])
        if row["failure"].startswith("crashed"):
            assert row["impact_speed_m_s"] > 0.0
        else:
            assert math.isnan(row["impact_speed_m_s"])
    assert {r["fault"].split()[2] for r in rows} == {"wrong", "off"}
    assert any(r["survived"] for r in rows) and not all(r["survived"] for r in rows)
    table = pa.Table.from_pylist(rows)
    ranking = fault_ranking(table, spec.controller_names)
    assert [share for _, share, _ in ranking] == sorted((share for _, share, _ in ranking), reverse=True)
    text = summary_markdown(table, spec)
    assert "## Faults: what each controller survives" in text
    assert text.index("## Faults") < text.index("## Headline")


def test_a_healthy_fault_changes_nothing(tmp_path):
    """A drawn "wrong" that keeps all its effectiveness (1.0) flies the healthy run bit for bit:
    the healthy plant skips the fault terms (PLANT.faulted), the paired baseline of a fault study."""
    spec = load_campaign(write(tmp_path))
    sample = sample_run(spec, 0)
    healthy = replace(sample, scenario=replace(sample.scenario, actuator_faults=()))
    whole = replace(sample, scenario=replace(sample.scenario, actuator_faults=(
        ActuatorFault(2, "wrong", 1.0, 1.0),)))  # fmt: skip
    c = spec.controller_names[0]
    a = eng.fly(batch.flights(spec, healthy)[c], record=True)[1]
    b = eng.fly(batch.flights(spec, whole)[c], record=True)[1]
    assert np.array_equal(a, b)


@pytest.mark.parametrize(
    ("edit", "key", "allowed"),
    [
        (("{ choice = [1, 2, 3, 4] }", "{ choice = [1, 5] }"), "actuator_faults[0].motor", "[0, 4]"),
        (("{ choice = [1, 2, 3, 4] }", "{ uniform = [1, 4] }"), "actuator_faults[0].motor", "motor number"),
        (('type = "wrong"', 'type = "garbage"'), "actuator_faults[0].type", "stuck"),
        (('"wrong"', '{ choice = ["off", "slow"] }'), "actuator_faults[0].type.choice[1]", "wrong"),
        (('type = "wrong"', 'type = "off"'), "actuator_faults[0].effectiveness", 'type "wrong"'),
        (("effectiveness = { uniform = [0.4, 0.9] }", "effectiveness = { uniform = [0.4, 1.2] }"),
         "actuator_faults[0].effectiveness.uniform[1]", "[0, 1]"),
        (("start_s = { uniform = [1.0, 2.5] }", "start_s = 9.0"), "actuator_faults[0].start_s", "[0, 4]"),
        (("envelope_m = 0.5", "envelope_m = -1.0"), "survival.envelope_m", "[0.001, 10000]"),
        (("recovery_bound_m = 0.05", "recovery_bound_m = 0.05\nsettle_s = 1.0"), "survival.settle_s",
         "unknown"),
    ],
)
def test_fault_specs_are_validated_with_the_key(tmp_path, edit, key, allowed):
    old, new = edit
    text = ROTORS.format(vehicle="paper_quad_rotors", duration=4.0, types='"wrong"')
    assert old in text
    path = tmp_path / "bad.toml"
    path.write_text(text.replace(old, new))
    with pytest.raises(ConfigError) as error:
        load_campaign(str(path))
    message = str(error.value)
    assert str(path) in message and key in message and allowed in message, message


def test_survival_limits_need_faults_to_judge(tmp_path):
    text = ROTORS.format(vehicle="paper_quad_rotors", duration=4.0, types='"wrong"')
    start = text.index("[[actuator_faults]]")
    path = tmp_path / "nofaults.toml"
    path.write_text(text[:start] + text[text.index("[survival]") :])
    with pytest.raises(ConfigError, match="survival.*only in a spec that draws faults"):
        load_campaign(str(path))


def test_paper_box_faults_is_the_paper_box_on_rotors_with_a_rotor_losing_effectiveness():
    """The shipped fault study: paper_box's plant box, seed, cascades and limits, on the rotors
    vehicle, one motor of four at 50-100 % effectiveness from a time in 10-30 s."""
    box, faults = load_campaign("paper_box"), load_campaign("paper_box_faults")
    assert faults.vehicle.name == "paper_quad_rotors" and faults.draws_faults
    assert faults.controller_names == box.controller_names and faults.runs == box.runs == 1000
    for key in ("seed", "failure", "duration_s", "wire_float32", "plant"):
        assert getattr(faults, key) == getattr(box, key), key
    (fault,) = faults.actuator_faults
    assert fault.types == ("wrong",) and fault.effectiveness.support() == (0.5, 1.0)
    assert fault.start_s.support() == (10.0, 30.0) and fault.motor.params == (1.0, 2.0, 3.0, 4.0)
    for run in (0, 17):
        a, b = sample_run(box, run), sample_run(faults, run)
        assert a.parameters["mass_scale"] == b.parameters["mass_scale"]
        (drawn,) = b.scenario.actuator_faults
        assert drawn.type == "wrong" and 0.5 <= drawn.effectiveness <= 1.0 and 10.0 <= drawn.start_s <= 30.0


def test_a_drawn_fault_reaches_the_controllers_run_by_run(tmp_path):
    """Every controller of a run flies the same fault (a paired comparison), and each its own copy
    of the plant's parameters (the fault set in one flight does not leak into the next)."""
    spec = load_campaign(write(tmp_path))
    sample = sample_run(spec, 0)
    flight = batch.flights(spec, sample)["intbs_nlhinf"]
    before = flight.plant.copy()
    first, _ = eng.fly(flight)
    second, _ = eng.fly(flight)
    assert np.array_equal(flight.plant, before)
    assert np.array_equal(first, second, equal_nan=True)
