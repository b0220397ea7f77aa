"""The one lockstep loop: the SITL (two processes, MAVLink over UDP) and the whole stack in-process
fly the same cores through the same bytes, so their trajectories are identical.

The autopilot is started with --autostart (armed at t = 0, flying the scenario's trajectory), as
the in-process paper runner does (sitl.inprocess.run_scenario). Both see the state through float32
ODOMETRY and send float32 controls; nothing else differs. Asserted: the ground truth of every frame
agrees to 1e-9 m (in practice bit for bit) and the controller's rows match.
"""

import numpy as np
import pytest

from autopilot.control.config import load_controller
from quadcommon.bus_records import CONTROLLER_FIELDS, TRUTH_FIELDS
from quadcommon.config import load_scenario
from sitl.inprocess import RunOptions, paper_stack
from sitl.launcher import VehicleSpec

from .harness import running

pytestmark = pytest.mark.processes  # (tests/conftest.py: the markers)

T = {name: i for i, name in enumerate(TRUTH_FIELDS)}
C = {name: i for i, name in enumerate(CONTROLLER_FIELDS)}
DURATION = 12.0  # covers the take-off transient and the disturbances at 5 and 10 s


@pytest.mark.timeout(180)
def test_sitl_and_the_in_process_stack_agree_frame_by_frame():
    stack = paper_stack(load_scenario("helix"), load_controller("intbs_nlhinf"), RunOptions())
    steps = round(DURATION / stack.sim.dt_control)
    for _ in range(steps):
        stack.step()
    stack.final_frame()
    inproc_truth, inproc_ctrl = np.asarray(stack.truth_rows), np.asarray(stack.controller_rows)

    spec = VehicleSpec(instance=1, scenario="helix", speed="max", autostart=True, duration_s=DURATION)
    with running(spec, leaves=("truth", "controller")) as (launcher, taps):
        assert launcher.child("simulator[1]").wait(120.0) == 0
        launcher.child("autopilot[1]").stop()  # flushes its last controller rows
        truth, ctrl = taps["truth"].rows(), taps["controller"].rows()
    assert len(truth) == len(inproc_truth) == steps + 1
    assert np.array_equal(truth[:, T["time_s"]], inproc_truth[:, T["time_s"]])
    gap = np.abs(truth[:, 1:] - inproc_truth[:, 1:]).max()
    assert gap <= 1e-9, f"largest difference in the truth rows: {gap:.2e}"
    assert len(ctrl) == len(inproc_ctrl)
    assert np.allclose(ctrl, inproc_ctrl, atol=1e-9, rtol=0.0, equal_nan=True)


@pytest.mark.timeout(180)
def test_under_hil_loss_the_sitl_flies_the_same_flight_as_without_it():
    """1 % of the frames and of the answers lost on the HIL link (both processes impair what they
    send): each loss costs one resend after [lockstep] resend_s, and the flight is still the clean
    in-process one, frame for frame."""
    duration = 6.0
    stack = paper_stack(load_scenario("helix"), load_controller("intbs_nlhinf"), RunOptions())
    steps = round(duration / stack.sim.dt_control)
    for _ in range(steps):
        stack.step()
    stack.final_frame()
    inproc_truth = np.asarray(stack.truth_rows)

    spec = VehicleSpec(instance=2, scenario="helix", speed="max", autostart=True, duration_s=duration,
                       impair=("hil:loss=1%",))  # fmt: skip
    with running(spec, leaves=("truth",)) as (launcher, taps):
        simulator = launcher.child("simulator[2]")
        assert simulator.wait(120.0) == 0
        truth = taps["truth"].rows()
    # zenoh drops truth batches rather than stall the lockstep when the machine is loaded (a test
    # suite beside it): compare every frame that arrived, the final one among them. A flight that
    # differed anywhere would differ at its end.
    frame = np.round(truth[:, T["time_s"]] * stack.sim.control_hz).astype(int)
    assert len(truth) >= 0.5 * (steps + 1) and frame[-1] == steps and len(set(frame)) == len(frame)
    gap = np.abs(truth[:, 1:] - inproc_truth[frame, 1:]).max()
    assert gap <= 1e-9, f"largest difference in the truth rows: {gap:.2e}"
    resent = int(simulator.output.split(" frames resent")[0].rsplit(" ", 1)[1])
    assert 0.005 * steps < resent < 0.2 * steps, simulator.tail()  # ~2 %: either way lost (+ a slow answer)


@pytest.mark.timeout(180)
def test_with_a_failure_injected_in_flight_the_two_agree_from_the_frame_it_applies():
    """A rotor loses 40 % of its effectiveness in flight and recovers (MAV_CMD_INJECT_FAILURE from
    a ground station, as MAVSDK sends it, the effectiveness in param4): the request rides in a
    lockstep answer to the simulator, which applies it from the next frame and says at which; the
    truth rows carry the rotor's health from that frame. The in-process stack given the same
    command before the same frame's answer flies the same flight, frame for frame (1e-9 m)."""
    import re

    from pymavlink.dialects.v20 import common as m

    from gcs_scripts.link import connect
    from quadcommon.config import load_vehicle
    from quadcommon.failures import Type, Unit
    from simulator.dynamics.plant import ROTOR_POSITIONS

    duration, vehicle, effectiveness = 5.0, "paper_quad_rotors", 0.6
    spec = VehicleSpec(instance=3, scenario="helix", vehicle=vehicle, speed="1", autostart=True,
                       duration_s=duration)  # fmt: skip
    commands = ((Type.wrong, effectiveness), (Type.ok, 0.0))  # PX4's motor 1 (the right rotor), 0.4 s
    with running(spec, leaves=("truth",)) as (launcher, taps):
        link = connect(instance=spec.instance)
        try:
            assert link.set_parameter("SYS_FAILURE_EN", 1, integer=True) == 1.0
            link.wait_until(lambda v: v.sim_time_s is not None and v.sim_time_s > 2.0, sim_timeout_s=10.0)
            for failure_type, param4 in commands:
                assert link.command_long(m.MAV_CMD_INJECT_FAILURE, (Unit.motor, failure_type, 1, param4)) == 0
                link.sleep_sim(0.4)
        finally:
            link.close()
        simulator = launcher.child("simulator[3]")
        assert simulator.wait(60.0) == 0
        truth = taps["truth"].rows()
        log = simulator.output
    applied = [float(t) for t in re.findall(r"t=([\d.]+) s: (?:Injected|Cleared): motor", log)]
    assert len(applied) == 2, log
    frames = [round(t * 500.0) for t in applied]  # [rates] control_hz
    right = T[f"rotor{ROTOR_POSITIONS.index('right') + 1}_effectiveness"]
    health = truth[:, right]  # the plant's, from the frame the simulator applied it at
    assert (health[: frames[0]] == 1.0).all() and (health[frames[1] :] == 1.0).all()
    assert (health[frames[0] : frames[1]] == np.float32(effectiveness)).all()  # as param4 carries it

    stack = paper_stack(load_scenario("helix"), load_controller("intbs_nlhinf"), RunOptions(),
                        vehicle=load_vehicle(vehicle))  # fmt: skip
    stack.autopilot.params.set("SYS_FAILURE_EN", 1.0)
    gcs = stack.ground_station()
    steps = round(duration / stack.sim.dt_control)
    for k in range(steps):
        for frame, (failure_type, param4) in zip(frames, commands, strict=True):
            if k == frame - 1:  # handled before frame k's answer, which carries it
                gcs.command(m.MAV_CMD_INJECT_FAILURE, Unit.motor, failure_type, 1, param4)
        stack.step()
    stack.final_frame()
    inproc_truth = np.asarray(stack.truth_rows)
    assert stack.sim.requests_applied == 2
    assert len(truth) == len(inproc_truth) == steps + 1
    gap = np.abs(truth[:, 1:] - inproc_truth[:, 1:]).max()
    assert gap <= 1e-9, f"largest difference in the truth rows: {gap:.2e}"
    roll_rate = np.abs(truth[:, T["p_rad_s"]])
    calm = roll_rate[round(1.0 * stack.sim.control_hz) : frames[0]].max()  # settled on the helix
    assert roll_rate[frames[0] : frames[1] + 1].max() > 5 * calm  # the rotor weakened: it rolled
