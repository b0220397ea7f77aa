"""MANUAL_CONTROL -> :class:`~autopilot.guidance.manual.Sticks` in the paper's body axes (PX4's reading).

The message's axes are int16 in thousandths of full deflection: ``x`` pitch stick (forward +),
``y`` roll stick (right +), ``r`` yaw stick (clockwise +), each in [-1000, 1000]; ``z`` the thrust
stick, read as PX4 reads it, [0, 1000] with 500 centred (below 0: full down). ``INT16_MAX`` on an
axis means "this axis is not sent" (MAVLink): it reads as centred. Anything else outside
[-1000, 1000] is not a stick: the whole message is refused, with the axis and value named (a
value that is not an integer, which only an in-process caller could hand over, likewise).
Buttons and the extension axes are ignored (no camera, no gimbal).
"""

from __future__ import annotations

from quadcommon import frames

from ..guidance.sticks import Sticks

INT16_MAX = 32767
FULL = 1000.0


def decode_sticks(msg, t: float) -> tuple[Sticks | None, str]:
    """(sticks, "") or (None, reason); ``t`` is the simulation time of arrival."""
    values = {}
    for axis, centre in (("x", 0), ("y", 0), ("z", 500), ("r", 0)):
        raw = getattr(msg, axis)
        if not isinstance(raw, int):  # pymavlink decodes int16; NaN or a float is no stick
            return None, f"MANUAL_CONTROL {axis}={raw!r} is not an integer"
        if raw == INT16_MAX:
            raw = centre
        elif not -1000 <= raw <= 1000:
            return None, f"MANUAL_CONTROL {axis}={raw} outside [-1000, 1000]"
        values[axis] = raw
    throttle = (max(values["z"], 0) - 500) / 500.0  # PX4: z in [0, 1000] -> [-1, 1]
    forward, left, up, yaw = frames.sticks_from_frd(values["x"] / FULL, values["y"] / FULL, throttle,
                                                    values["r"] / FULL)  # fmt: skip
    return Sticks(t, forward, left, up, yaw), ""
