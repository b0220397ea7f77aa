"""The control laws as the tests step them: bound to their gains and the paper's vehicle."""

from __future__ import annotations

from autopilot.control.cascade import law_context
from autopilot.control.config import load_controller
from autopilot.control.registry import ROTATIONAL, TRANSLATIONAL, BoundLaw
from quadcommon.config import load_vehicle

VEHICLE = load_vehicle("paper_quad")  # m 0.74 kg, inertia (0.004, 0.004, 0.0084), U1_max 28 N
DT = 0.002


def bind(controller: str, loop: str, gains=None, dt: float = DT) -> BoundLaw:
    """The ``loop`` law of controller ``controller`` (its gains, or ``gains``)."""
    config = load_controller(controller)
    if gains is None:
        gains = config.translational if loop == TRANSLATIONAL else config.rotational
    return BoundLaw(loop, gains, law_context(config, VEHICLE, dt))


def translational(controller: str, gains=None) -> BoundLaw:
    return bind(controller, TRANSLATIONAL, gains)


def rotational(controller: str, gains=None) -> BoundLaw:
    return bind(controller, ROTATIONAL, gains)


def state_term(law: BoundLaw, args: tuple):
    """What the law's state adds to its output at ``args`` (its output minus its output with a zero
    state; the paper's laws are linear in their state), as a numpy array."""
    import numpy as np

    with_state = np.array(law.step(*args))
    saved, law.state = law.state, [0.0] * len(law.state)
    without = np.array(law.step(*args))
    law.state = saved
    return with_state - without
