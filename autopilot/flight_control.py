"""The cascade flying the commander's guidance, one control step at a time.

When the commander says ``Motors.FLY`` and there is a state to fly on, the cascade
(:mod:`autopilot.control.cascade`) steps towards the guidance's reference, starting from rest (its
integrators and filters reset) at the first step of each flight; a manual mode's overrides (the
sticks' tilt, an attitude, a thrust as a fraction of the vehicle's U1_max) go in through the
cascade's own override arguments. Otherwise the motors are off or idle: zero controls, and the
cascade held at rest. A law that fails raises :class:`~autopilot.control.registry.ControllerFailure`
to the caller, which terminates the flight and calls :meth:`FlightControl.stop`.
"""

from __future__ import annotations

from .commander.commander import GuidanceOutput, Motors
from .control.cascade import AttitudeReference, Cascade, CascadeOutput
from .records import StateEstimate

Controls = tuple[float, float, float, float]
MOTORS_OFF: Controls = (0.0, 0.0, 0.0, 0.0)


class FlightControl:
    """The cascade behind the commander (module docstring); ``thrust_max_n``: the vehicle's U1_max
    (N), the scale of a manual mode's thrust."""

    def __init__(self, cascade: Cascade, thrust_max_n: float) -> None:
        self.cascade = cascade
        self.thrust_max_n = thrust_max_n
        self.flying = False

    def step(
        self, est: StateEstimate | None, guidance: GuidanceOutput
    ) -> tuple[CascadeOutput | None, Controls]:
        """This step's cascade output (None: motors off or idle) and actuator controls;
        ControllerFailure if the law fails."""
        if guidance.motors == Motors.FLY and est is not None:
            if not self.flying:
                self.cascade.reset()
                self.flying = True
            output = self._cascade_step(est, guidance)
            return output, output.actuator_controls
        self.stop()
        return None, MOTORS_OFF

    def stop(self) -> None:
        """Motors off: the cascade at rest until the next flight."""
        self.flying = False
        self.cascade.reset()

    def _cascade_step(self, est: StateEstimate, guidance: GuidanceOutput) -> CascadeOutput:
        manual = guidance.manual
        if manual is None:
            return self.cascade.step(est, guidance.reference)
        attitude = AttitudeReference(*manual.attitude) if manual.attitude is not None else None
        thrust = manual.thrust * self.thrust_max_n if manual.thrust is not None else None
        return self.cascade.step(est, guidance.reference, roll_pitch=manual.roll_pitch, attitude=attitude,
                                 thrust_n=thrust)  # fmt: skip
