"""What the autopilot accepts from a ground station, decided in one place (docs/security.md has the
table).

* **Commands** (COMMAND_LONG / COMMAND_INT): :data:`COMMAND_RULES` says, per MAV_CMD the autopilot
  handles, what each parameter it reads may be (MAV_BOOL values, integers in an enum's range,
  finite numbers in a range, NaN where MAVLink lets it mean "unset"). Any parameter at +-inf is
  refused, whatever the command. A refusal is answered COMMAND_ACK ``DENIED`` with the reason
  (:func:`check_command`); an unknown command stays ``UNSUPPORTED``.
* **Setpoints and mission items**: one distance rule for both (:func:`reference_problem`): a
  position farther than ``NAV_REF_MAX_DIST`` from home is refused (an offboard setpoint with a
  STATUSTEXT, a mission item with ``MAV_MISSION_INVALID_PARAM5_X``); what else a setpoint may be
  (frames, type_mask, finite values) is decided by :mod:`.offboard`, and its velocity and
  acceleration are limited to ``MPC_*`` there (:mod:`autopilot.guidance.offboard`); items by
  :mod:`autopilot.mission.items`.
* **Parameters**: :meth:`autopilot.params.store.ParamSpec.check` (type, range, refused values,
  read-only), answered with PARAM_VALUE echoing the old value.

Refusals are announced by STATUSTEXT at most once per second per reason (:class:`RefusalNotices`):
a flood of bad commands cannot flood the ground stations in turn.
"""

from __future__ import annotations

import math
import re
from collections import Counter
from collections.abc import Callable, Mapping
from dataclasses import dataclass

from .codec import mavlink as m

Vector3 = tuple[float, float, float]
ANNOUNCE_EVERY_S = 1.0
MAX_MESSAGE_ID = (1 << 24) - 1  # MAVLink 2 message ids are 24 bits
MAX_INTERVAL_US = 60e6  # SET_MESSAGE_INTERVAL: at most one message a minute (longer: disable it)
FORCE_MAGIC = 21196.0  # ARM_DISARM param2: force (PX4, MAVLink)
MAX_REASONS = 200  # distinct refusal reasons counted (RefusalNotices.by_reason)
_NUMBER = re.compile(r"(?<![A-Za-z_\d])[-+]?(?:\d+\.?\d*(?:e[-+]?\d+)?|nan\b|inf\b)", re.IGNORECASE)


@dataclass(frozen=True)
class Param:
    """What one parameter (1-7, as MAVLink numbers them) of a command may be."""

    number: int
    what: str
    lo: float = -math.inf
    hi: float = math.inf
    integer: bool = False
    values: tuple[float, ...] = ()  # the only values allowed (an enum, MAV_BOOL)
    nan_ok: bool = False  # NaN allowed: "unset" (MAVSDK sends it for parameters it does not use)

    def problem(self, value: float) -> str | None:
        if math.isnan(value):
            return None if self.nan_ok else f"param{self.number} ({self.what}) is NaN"
        if self.values:
            if value in self.values:
                return None
            allowed = ", ".join(f"{v:g}" for v in self.values)
            return f"param{self.number} ({self.what}) = {value:g}; allowed: {allowed}"
        if self.integer and value != math.floor(value):
            return f"param{self.number} ({self.what}) = {value:g} is not an integer"
        if not self.lo <= value <= self.hi:
            return f"param{self.number} ({self.what}) = {value:g} out of range [{self.lo:g}, {self.hi:g}]"
        return None


_BYTE = {"lo": 0.0, "hi": 255.0, "integer": True}
_SEQ = {"lo": 0.0, "hi": 65535.0, "integer": True, "nan_ok": True}

# MAV_CMD -> what its parameters may be (the parameters the autopilot reads; the others may be
# anything finite or NaN).
COMMAND_RULES: dict[int, tuple[Param, ...]] = {
    m.MAV_CMD_COMPONENT_ARM_DISARM: (
        Param(1, "arm", values=(0.0, 1.0)),  # MAV_BOOL
        Param(2, "force", values=(0.0, FORCE_MAGIC), nan_ok=True),
    ),
    m.MAV_CMD_NAV_TAKEOFF: (Param(7, "altitude", -1000.0, 10000.0, nan_ok=True),),
    m.MAV_CMD_DO_SET_MODE: (
        Param(1, "base mode", **_BYTE),
        Param(2, "custom main mode", **_BYTE),
        Param(3, "custom sub mode", **_BYTE, nan_ok=True),
    ),
    m.MAV_CMD_SET_MESSAGE_INTERVAL: (
        Param(1, "message id", 0.0, MAX_MESSAGE_ID, integer=True),
        Param(2, "interval (us; -1 off, 0 default)", -1.0, MAX_INTERVAL_US),
    ),
    m.MAV_CMD_REQUEST_MESSAGE: (Param(1, "message id", 0.0, MAX_MESSAGE_ID, integer=True),),
    m.MAV_CMD_MISSION_START: (Param(1, "first item", **_SEQ), Param(2, "last item", **_SEQ)),
    m.MAV_CMD_DO_SET_MISSION_CURRENT: (Param(1, "item", -1.0, 65535.0, integer=True, nan_ok=True),),
    m.MAV_CMD_DO_REPOSITION: (
        Param(1, "ground speed (m/s; -1 default)", -1.0, 100.0, nan_ok=True),
        Param(2, "flags (bit 0: change mode)", **_BYTE, nan_ok=True),
        Param(4, "yaw (deg; NaN keep)", -360.0, 360.0, nan_ok=True),
        Param(7, "altitude (m; NaN keep)", -1000.0, 10000.0, nan_ok=True),
    ),
    m.MAV_CMD_PREFLIGHT_STORAGE: (Param(1, "parameter storage action", values=(0.0, 1.0, 2.0, 4.0)),),
    m.MAV_CMD_INJECT_FAILURE: (
        Param(1, "failure unit (FAILURE_UNIT)", **_BYTE),
        Param(2, "failure type (FAILURE_TYPE)", **_BYTE),
        Param(3, "instance (0: all)", **_BYTE, nan_ok=True),
    ),
}


def check_command(command: int, params: tuple[float, ...]) -> str | None:
    """Why the command's parameters are refused, or None. ``params`` = param1..param7."""
    for number, value in enumerate(params, 1):
        if math.isinf(value):
            return f"param{number} is infinite"
    rules = COMMAND_RULES.get(command, ())
    for rule in rules:
        problem = rule.problem(params[rule.number - 1])
        if problem:
            return problem
    if command == m.MAV_CMD_SET_MESSAGE_INTERVAL and -1.0 < params[1] < 0.0:
        return f"param2 (interval) = {params[1]:g}: -1 (off), 0 (default) or > 0 us"
    if command == m.MAV_CMD_DO_SET_MODE and not int(params[0]) & m.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
        return "DO_SET_MODE needs MAV_MODE_FLAG_CUSTOM_MODE_ENABLED (PX4 modes)"
    return None


def reference_problem(position: Vector3, home: Vector3, params: Mapping[str, float]) -> str | None:
    """The one distance rule for offboard setpoints and mission items (paper frame, m): farther
    than ``NAV_REF_MAX_DIST`` from home is refused."""
    limit = params["NAV_REF_MAX_DIST"]
    distance = math.dist(position, home)
    if not distance <= limit:  # (NaN is refused too)
        return f"{distance:.0f} m from home, farther than NAV_REF_MAX_DIST {limit:g} m"
    return None


class RefusalNotices:
    """STATUSTEXT for refusals, at most once per ``ANNOUNCE_EVERY_S`` (caller's wall clock) for the
    same text: the reason is always in the answer (ACK, MISSION_ACK, PARAM_VALUE); the STATUSTEXT
    is the human-readable echo and must not turn a flood of bad input into a flood of text."""

    def __init__(self, send: Callable[[int, str], None], clock: Callable[[], float]) -> None:
        self.send = send
        self.clock = clock
        self._last: dict[str, float] = {}
        self.refused = 0
        self.by_reason: Counter[str] = Counter()  # the text with its numbers as '#' (bounded)

    def __call__(self, text: str, severity: int = m.MAV_SEVERITY_WARNING) -> None:
        self.refused += 1
        reason = _NUMBER.sub("#", text)
        if reason in self.by_reason or len(self.by_reason) < MAX_REASONS:
            self.by_reason[reason] += 1
        else:
            self.by_reason["(other reasons)"] += 1
        now = self.clock()
        last = self._last.get(text)
        if last is not None and now - last < ANNOUNCE_EVERY_S:
            return
        if len(self._last) > 256:  # bounded: forget the old texts
            self._last.clear()
        self._last[text] = now
        self.send(severity, text)
