"""The compiled cascade (autopilot.control.compiled) is the Python cascade, bit for bit: step by
step over the paper's helix for the three cascades, through a retune in flight, resets, a
non-integrating step, and on the way back out (the Python laws' state after compiled steps)."""

from dataclasses import replace

import pytest

pytest.importorskip("numba")

from autopilot.control.cascade import Cascade, StateEstimate  # noqa: E402
from autopilot.control.config import CONTROLLER_NAMES, load_controller  # noqa: E402
from quadcommon.config import load_scenario, load_vehicle  # noqa: E402
from sitl.inprocess import paper_stack  # noqa: E402


def states_and_references(controller: str, frames: int = 1500):
    """A real flight's inputs: what the autopilot's cascade saw on the helix."""
    stack = paper_stack(load_scenario("helix"), load_controller(controller))
    seen = []
    real = stack.autopilot.cascade
    original = real.step

    def spy(state, ref, integrate=True):
        seen.append((state, ref))
        return original(state, ref, integrate)

    real.step = spy
    for _ in range(frames):
        stack.step()
    return seen


@pytest.mark.parametrize("name", CONTROLLER_NAMES)
def test_compiled_steps_equal_the_python_laws_through_retune_and_reset(name):
    inputs = states_and_references(name)
    controller, vehicle = load_controller(name), load_vehicle("paper_quad")
    python = Cascade(controller, vehicle, 0.002)
    compiled = Cascade(controller, vehicle, 0.002, compiled=True)
    assert compiled._kernel is not None and python._kernel is None
    faster = replace(controller, tilt_max_rad=controller.tilt_max_rad * 0.9)
    for k, (state, ref) in enumerate(inputs):
        if k == 600:
            python.retune(faster)
            compiled.retune(faster)
        if k == 900:
            python.reset()
            compiled.reset()
        integrate = k != 1000
        a, b = python.step(state, ref, integrate), compiled.step(state, ref, integrate)
        assert a == b, f"step {k}: {a} != {b}"
    compiled._kernel.pull(compiled)
    assert compiled.translational.law.integral == python.translational.law.integral
    assert compiled.rotational.integral == python.rotational.integral
    assert (compiled.filter.value, compiled.filter.rate) == (python.filter.value, python.filter.rate)


def test_an_int_among_the_floats_compiles_nothing_in_flight_and_flies_the_same():
    controller, vehicle = load_controller("intbs_nlhinf"), load_vehicle("paper_quad")
    python = Cascade(controller, vehicle, 0.002)
    compiled = Cascade(controller, vehicle, 0.002, compiled=True)
    state = StateEstimate((0, 0, 1), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    from autopilot.control import compiled as kernels
    from quadcommon.trajectories import Reference

    ref = Reference((0.0, 0.0, 1.5), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), 0.0, 0, 0.0)
    signatures = len(kernels.cascade_step.signatures)
    for _ in range(3):  # numba converts the ints to the compiled float signature
        assert python.step(state, ref) == compiled.step(state, ref)
    assert len(kernels.cascade_step.signatures) == signatures  # nothing compiled in flight
