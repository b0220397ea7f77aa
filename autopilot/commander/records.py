"""The commander's records: what it knows of the vehicle (:class:`VehicleState`), what it answers
each control step (:class:`GuidanceOutput`) and each command (:class:`Outcome`), and the MAVLink
numbers it answers with (MAV_RESULT, MAV_SEVERITY), shared by the commander's parts
(:mod:`.commander` and the modules it is made of).
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum
from typing import NamedTuple

from quadcommon.trajectories import Reference

from ..guidance.manual import ManualSetpoint

Vector3 = tuple[float, float, float]
ZERO3: Vector3 = (0.0, 0.0, 0.0)

# MAV_RESULT
ACCEPTED, TEMPORARILY_REJECTED, DENIED, UNSUPPORTED, FAILED = 0, 1, 2, 3, 4
# MAV_SEVERITY
SEVERITY_EMERGENCY, SEVERITY_CRITICAL, SEVERITY_WARNING, SEVERITY_NOTICE, SEVERITY_INFO = 0, 2, 4, 5, 6
GROUND_Z_M = 0.0  # the local frame's origin (the configured home) is on flat ground


@dataclass(frozen=True)
class VehicleState:
    """What the commander knows of the vehicle (paper frames, SI)."""

    time_s: float
    position_m: Vector3
    velocity_m_s: Vector3
    euler_rad: Vector3
    euler_rates_rad_s: Vector3


class Motors(Enum):
    """What the motors do this control step."""

    OFF = 0  # disarmed
    IDLE = 1  # armed on the ground, no thrust, controller states held at zero
    FLY = 2  # the cascade tracks the reference


class GuidanceOutput(NamedTuple):
    """One control step's decision: the motors, the reference to fly (None: none), and a manual
    mode's overrides of the cascade."""

    motors: Motors
    reference: Reference | None
    manual: ManualSetpoint | None = None  # a manual mode's overrides of the cascade (None: none)


class Outcome(NamedTuple):
    """A command's answer: its MAV_RESULT and, when refused, why (the STATUSTEXT said)."""

    result: int  # MAV_RESULT
    reason: str = ""

    @property
    def accepted(self) -> bool:
        """MAV_RESULT_ACCEPTED."""
        return self.result == ACCEPTED


def at_rest(state: VehicleState) -> Reference:
    """A reference at the measured state, at rest in acceleration."""
    return Reference(state.position_m, state.velocity_m_s, ZERO3, state.euler_rad[2], 0.0, 0.0)
