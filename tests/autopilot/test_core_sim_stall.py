"""A simulator that stalls (a loaded machine: no frame for longer than COM_SIM_LOSS_T of wall time)
and then resumes continues the same flight: in lockstep the plant did not move either, so the
cascade keeps its state. Found under load in the suite: the SITL drifted 4 cm from the in-process
run after a stall at the plant's first compiled step (now loaded before the first frame)."""

import numpy as np

from autopilot.control.config import load_controller
from quadcommon.config import load_scenario
from sitl.inprocess import RunOptions, paper_stack


def fly(frames: int, stall_at: int | None = None, stall_s: float = 1.6):
    stack = paper_stack(load_scenario("helix"), load_controller("intbs_nlhinf"), RunOptions())
    texts = []
    stack.autopilot.log = texts.append
    done = 0
    while done < frames:
        if done == stall_at:
            stack.frames_flow = False
            stack.run_for(stall_s)  # the autopilot's clock runs, no frame arrives
            stack.frames_flow = True
        stack.step()
        done += 1
    return np.asarray(stack.truth_rows), texts


def test_a_stall_longer_than_the_loss_timeout_then_frames_again_is_the_same_flight():
    steady, _ = fly(3000)
    stalled, texts = fly(3000, stall_at=1500)
    assert any("simulator lost" in t for t in texts) and any("recovered" in t for t in texts)
    assert np.array_equal(steady[:, 1:], stalled[:, 1:])
