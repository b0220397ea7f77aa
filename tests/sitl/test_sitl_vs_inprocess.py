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
