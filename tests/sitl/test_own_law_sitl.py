"""A researcher's law, written into a configuration directory, and the two baselines (PX4-style PID,
geometric SE(3)) fly the SITL (two processes, MAVLink over UDP, lockstep) exactly as they fly the
whole stack in-process: the ground truth of every frame agrees to 1e-9 m. (The paper's cascade
flies the whole helix through the processes in test_paper_through_sitl.py.)"""

import os

import numpy as np
import pytest

from autopilot.control.config import load_controller
from quadcommon import environment
from quadcommon.bus_records import TRUTH_FIELDS
from quadcommon.config import load_scenario
from sitl.inprocess import RunOptions, paper_stack
from sitl.launcher import VehicleSpec
from tests.own_law import write_overlay

from .harness import running

pytestmark = pytest.mark.processes  # (tests/conftest.py: the markers)

DURATION = 6.0


@pytest.mark.timeout(240)
@pytest.mark.parametrize("law", ["a law from a configuration directory", "se3", "px4_pid"])
def test_the_law_flies_the_sitl_as_in_process(tmp_path, monkeypatch, law):
    if law in ("se3", "px4_pid"):
        name = law
    else:
        # The processes inherit it; the test process's port block (tests/ports.py) stays behind it.
        dirs = [str(tmp_path), *environment.config_dir_list()]
        monkeypatch.setenv("QUADSITL_CONFIG_DIR", os.pathsep.join(dirs))
        name = write_overlay(tmp_path, "toy_pd_sitl")
    stack = paper_stack(load_scenario("helix"), load_controller(name), RunOptions())
    steps = round(DURATION / stack.sim.dt_control)
    for _ in range(steps):
        stack.step()
    stack.final_frame()
    inproc = np.asarray(stack.truth_rows)
    assert np.abs(inproc[-1, 1:4] - inproc[0, 1:4]).max() > 0.1  # it flew the helix, not a hover

    spec = VehicleSpec(instance=11, controller=name, scenario="helix", speed="max", autostart=True,
                       duration_s=DURATION)  # fmt: skip
    with running(spec, leaves=("truth",)) as (launcher, taps):
        assert launcher.child("simulator[11]").wait(120.0) == 0
        truth = taps["truth"].rows()
    assert len(truth) == len(inproc) == steps + 1
    time = TRUTH_FIELDS.index("time_s")
    assert np.array_equal(truth[:, time], inproc[:, time])
    assert np.abs(truth[:, 1:] - inproc[:, 1:]).max() <= 1e-9
