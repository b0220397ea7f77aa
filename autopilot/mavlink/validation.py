"""What the autopilot accepts from a ground station, decided in one place (docs/security.md has the
table).

* **Commands** (COMMAND_LONG / COMMAND_INT): :data:`COMMAND_RULES` is the table of the MAV_CMDs the
  autopilot handles (:class:`~.commands.CommandDispatcher` registers no handler for a command it
  does not list) and says what each parameter it reads may be (MAV_BOOL values, integers in an
  enum's range, finite numbers in a range, NaN where MAVLink lets it mean "unset"). Any parameter
  at +-inf is refused, whatever the command. A refusal is answered COMMAND_ACK ``DENIED`` with the
  reason (:func:`check_command`); an unknown command stays ``UNSUPPORTED``.
* **Parameter slots** (commands and mission items alike): a slot MAVLink's definition of the
  MAV_CMD leaves unused ("Empty", "Reserved", ...) must be unset, 0 or NaN (the int32 x/y of
  COMMAND_INT and MISSION_ITEM_INT: 0 or ``INT32_MAX``); :func:`slots` reads the definition from
  pymavlink's ``common.xml`` text, :data:`SLOT_OVERRIDES` lists where this vehicle reads it
  otherwise, and why. A command is refused ``DENIED``, an item ``MAV_MISSION_INVALID_PARAMn`` for
  its first such slot (:func:`autopilot.mission.items.parse_item`).
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

import functools
import math
import re
from collections import Counter
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import NamedTuple

from .codec import mavlink as m

Vector3 = tuple[float, float, float]
ANNOUNCE_EVERY_S = 1.0
MAX_MESSAGE_ID = (1 << 24) - 1  # MAVLink 2 message ids are 24 bits
MAX_INTERVAL_US = 60e6  # SET_MESSAGE_INTERVAL: at most one message a minute (longer: disable it)
FORCE_MAGIC = 21196.0  # ARM_DISARM param2: force (PX4, MAVLink)
MAX_REASONS = 200  # distinct refusal reasons counted (RefusalNotices.by_reason)
INT32_MAX = 2**31 - 1  # "unset" in the int32 x/y (param5/6) of COMMAND_INT and MISSION_ITEM_INT (MAVLink)
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
        """Why ``value`` is not allowed for this parameter (NaN where not allowed, not one of ``values``, not
        an integer, out of [lo, hi]), or None."""
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

# Every MAV_CMD the autopilot handles -> what the parameters it reads may be. The other slots MAVLink
# gives a meaning may be anything finite or NaN; the slots it leaves unused must be unset (slots()).
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
    m.MAV_CMD_GET_MESSAGE_INTERVAL: (Param(1, "message id", 0.0, MAX_MESSAGE_ID, integer=True),),
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
    m.MAV_CMD_DO_ORBIT: (  # the radius's limits are the commander's (MC_ORBIT_RAD_MAX); param4 is not read
        Param(1, "radius (m; > 0 clockwise; NaN keep)", nan_ok=True),
        Param(2, "tangential speed (m/s; NaN keep)", -100.0, 100.0, nan_ok=True),
        Param(3, "yaw behaviour (ORBIT_YAW_BEHAVIOUR)", values=(0.0, 1.0, 2.0, 3.0, 4.0, 5.0), nan_ok=True),
        Param(7, "centre altitude (m AMSL; NaN keep)", -1000.0, 10000.0, nan_ok=True),
    ),
    m.MAV_CMD_NAV_LAND: (),
    m.MAV_CMD_NAV_RETURN_TO_LAUNCH: (),
    m.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: (),
    m.MAV_CMD_GET_HOME_POSITION: (),
    m.MAV_CMD_INJECT_FAILURE: (
        Param(1, "failure unit (FAILURE_UNIT)", **_BYTE),
        Param(2, "failure type (FAILURE_TYPE)", **_BYTE),
        Param(3, "instance (0: all)", **_BYTE, nan_ok=True),
        Param(4, "motor effectiveness for wrong (0 or NaN: SIM_MOT_EFF)", 0.0, 1.0, nan_ok=True),
    ),
}


def check_command(command: int, params: tuple[float, ...], integer_xy: bool = False) -> str | None:
    """Why the command's parameters are refused, or None. ``params`` = param1..param7;
    ``integer_xy``: param5/6 are COMMAND_INT's int32 x/y."""
    for number, value in enumerate(params, 1):
        if math.isinf(value):
            return f"param{number} is infinite"
    unused = slots(command).problem(params, integer_xy)
    if unused:
        return unused[1]
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


# -- parameter slots -------------------------------------------------------------------------------
# How MAVLink's definitions (pymavlink's common.xml text) describe a slot they leave unused: "Empty",
# "Empty.", "Reserved", "Reserved (default:0)", "Reserved (default:NaN)", "Reserved (set to 0)",
# "Reserved (all remaining params)".
_UNUSED_DESCRIPTION = re.compile(r"(?:Empty|Reserved)\.?(?: \([^)]*\))?")
SLOT_NAMES = ("param1", "param2", "param3", "param4", "param5 (x)", "param6 (y)", "param7 (z)")
INTEGER_SLOTS = (5, 6)  # x, y: int32 in COMMAND_INT and MISSION_ITEM_INT


class SlotOverride(NamedTuple):
    """Slots of one MAV_CMD this vehicle reads otherwise than pymavlink's definition says."""

    command: int
    slots: tuple[int, ...]  # 1..7
    used: bool  # True: used although the definition says unused; False: the reverse
    why: str


# Where this vehicle deliberately differs from pymavlink's common.xml, and why. Each entry must change
# what the definition says (tests/autopilot/mavlink/test_validation_slots.py), so a pymavlink that catches up
# shows which to remove.
SLOT_OVERRIDES: tuple[SlotOverride, ...] = (
    SlotOverride(
        m.MAV_CMD_NAV_LOITER_TIME, (2,), True,
        "newer common.xml: heading required (MAV_BOOL), which PX4 reads (force heading)",
    ),
    SlotOverride(
        m.MAV_CMD_DO_MOUNT_CONFIGURE, (5, 6, 7), True,
        "newer common.xml: roll, pitch and yaw input modes; MAVSDK's missions put 2 (absolute yaw) in param7",
    ),
    SlotOverride(
        m.MAV_CMD_SET_MESSAGE_INTERVAL, (3, 4, 5, 6), True,
        "newer common.xml: request parameters of the message (an index, ...), as in REQUEST_MESSAGE",
    ),
    SlotOverride(
        m.MAV_CMD_INJECT_FAILURE, (4,), True,
        "this vehicle's extension: the effectiveness a motor keeps under FAILURE_TYPE_WRONG (a loss of "
        "effectiveness), in [0, 1]; 0 or NaN (unset) takes SIM_MOT_EFF",
    ),
    SlotOverride(
        m.MAV_CMD_WAYPOINT_USER_1, (3,), False,
        "the timed trajectory item: MAVLink leaves param1-4 to the user, this vehicle reads param1 "
        "(time), param2 (acceptance radius) and param4 (yaw)",
    ),
)  # fmt: skip


def _unset(value: float, integer: bool) -> bool:
    """MAVLink's "unset": 0 or NaN in a float slot, 0 or INT32_MAX in an int32 one."""
    return value == 0.0 or (value == INT32_MAX if integer else math.isnan(value))


@dataclass(frozen=True)
class Slots:
    """Which of a MAV_CMD's seven parameter slots (1-7, as MAVLink numbers them) mean something."""

    command: int
    name: str  # MAV_CMD_..., without the prefix
    descriptions: tuple[str, ...]  # MAVLink's text for slots 1..7 ("" where it has none)
    used: frozenset[int]

    @property
    def unused(self) -> tuple[int, ...]:
        """The slots (1-7) the command does not use: each must hold 0 or NaN (0 or INT32_MAX in the int32
        x and y of COMMAND_INT and MISSION_ITEM_INT)."""
        return tuple(slot for slot in range(1, 8) if slot not in self.used)

    def problem(self, params: Sequence[float], integer_xy: bool) -> tuple[int, str] | None:
        """The first unused slot holding a value, with the reason, or None. ``params`` = the seven
        slots; ``integer_xy``: slots 5 and 6 are the int32 x/y (COMMAND_INT, MISSION_ITEM_INT)."""
        for slot in self.unused:
            value = params[slot - 1]
            integer = integer_xy and slot in INTEGER_SLOTS
            if not _unset(value, integer):
                unset = "0 or INT32_MAX" if integer else "0 or NaN"
                said = self.descriptions[slot - 1] or "not defined"
                return slot, f"{SLOT_NAMES[slot - 1]} = {value:.10g}: unused ({said}), must be {unset}"
        return None


def _descriptions(command: int) -> tuple[str, ...] | None:
    """MAVLink's text for the command's slots 1..7 ("" where it has none); None: not in the dialect."""
    entry = m.enums["MAV_CMD"].get(command)
    if entry is None:
        return None
    return tuple(entry.param.get(slot, "").strip() for slot in range(1, 8))


def defined_slots(command: int) -> frozenset[int]:
    """The slots MAVLink's definition gives a meaning (before :data:`SLOT_OVERRIDES`); all seven
    for a command the dialect does not define."""
    descriptions = _descriptions(command)
    if descriptions is None:
        return frozenset(range(1, 8))
    return frozenset(n for n, text in enumerate(descriptions, 1) if not _UNUSED_DESCRIPTION.fullmatch(text))


@functools.cache
def slots(command: int) -> Slots:
    """The slots ``command`` uses: MAVLink's definition (:func:`defined_slots`) with
    :data:`SLOT_OVERRIDES` applied."""
    used = set(defined_slots(command))
    for override in SLOT_OVERRIDES:
        if override.command == command:
            used = used | set(override.slots) if override.used else used - set(override.slots)
    entry = m.enums["MAV_CMD"].get(command)
    name = entry.name.removeprefix("MAV_CMD_") if entry is not None else str(command)
    return Slots(command, name, _descriptions(command) or ("",) * 7, frozenset(used))


def slots_table(commands: Iterable[int]) -> str:
    """The commands' slots as a Markdown table (the ones in docs/security.md and docs/missions.md)."""
    rows = ["| MAV_CMD | id | slots used | unused: must be unset |", "|---|---:|---|---|"]
    for command in sorted(commands):
        s = slots(command)
        used = ", ".join(str(slot) for slot in sorted(s.used)) or "none"
        unused = ", ".join(str(slot) for slot in s.unused) or "none"
        rows.append(f"| `{s.name}` | {command} | {used} | {unused} |")
    return "\n".join(rows)


def overrides_table() -> str:
    """:data:`SLOT_OVERRIDES` as a Markdown table (the one in docs/security.md)."""
    rows = ["| MAV_CMD | slots | here | why |", "|---|---|---|---|"]
    for o in SLOT_OVERRIDES:
        numbers = ", ".join(str(slot) for slot in o.slots)
        rows.append(f"| `{slots(o.command).name}` | {numbers} | {'used' if o.used else 'unused'} | {o.why} |")
    return "\n".join(rows)


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
