"""Flight modes and their PX4 custom-mode encoding (HEARTBEAT.custom_mode, DO_SET_MODE).

PX4 packs ``custom_mode = (main_mode << 16) | (sub_mode << 24)`` (px4_custom_mode union: two
reserved bytes, main, sub). Ground stations (QGC, MAVSDK, MAVProxy/pymavlink ``px4_map``) decode
mode names from these numbers when ``HEARTBEAT.autopilot = MAV_AUTOPILOT_PX4``.
"""

from __future__ import annotations

from enum import Enum

# PX4 main modes
MAIN_MANUAL, MAIN_ALTCTL, MAIN_POSCTL, MAIN_AUTO, MAIN_ACRO, MAIN_OFFBOARD, MAIN_STABILIZED = (
    1,
    2,
    3,
    4,
    5,
    6,
    7,
)
_MANUAL_MAINS = (MAIN_MANUAL, MAIN_STABILIZED, MAIN_ALTCTL, MAIN_POSCTL, MAIN_ACRO)
# PX4 AUTO sub modes
SUB_READY, SUB_TAKEOFF, SUB_LOITER, SUB_MISSION, SUB_RTL, SUB_LAND = 1, 2, 3, 4, 5, 6
SUB_FOLLOW_TARGET = 8
# PX4 POSCTL sub modes: Orbit is POSCTL's sub mode 1 (PX4_CUSTOM_SUB_MODE_POSCTL_ORBIT)
SUB_POSCTL_ORBIT = 1


class FlightMode(Enum):
    """The modes this autopilot flies, with their PX4 (main, sub) numbers."""

    MANUAL = (MAIN_MANUAL, 0)  # a multicopter's MANUAL flies as STABILIZED (PX4)
    STABILIZED = (MAIN_STABILIZED, 0)
    ALTCTL = (MAIN_ALTCTL, 0)
    POSCTL = (MAIN_POSCTL, 0)
    ACRO = (MAIN_ACRO, 0)
    AUTO_TAKEOFF = (MAIN_AUTO, SUB_TAKEOFF)
    AUTO_LOITER = (MAIN_AUTO, SUB_LOITER)
    AUTO_MISSION = (MAIN_AUTO, SUB_MISSION)
    AUTO_RTL = (MAIN_AUTO, SUB_RTL)
    AUTO_LAND = (MAIN_AUTO, SUB_LAND)
    OFFBOARD = (MAIN_OFFBOARD, 0)
    ORBIT = (MAIN_POSCTL, SUB_POSCTL_ORBIT)  # MAV_CMD_DO_ORBIT (autopilot/guidance/orbit.py)
    AUTO_FOLLOW_TARGET = (MAIN_AUTO, SUB_FOLLOW_TARGET)  # follow-me (autopilot/guidance/follow.py)

    def __init__(self, main: int, sub: int) -> None:
        # A plain attribute, computed once: telemetry and the controller rows read it every frame
        # (an Enum property costs ~0.2 us a read).
        self.custom_mode: int = (main << 16) | (sub << 24)
        # Flown from the sticks (MANUAL_CONTROL): MANUAL, STABILIZED, ALTCTL, POSCTL, ACRO (not
        # POSCTL's sub mode Orbit, which flies by itself).
        self.is_manual: bool = main in _MANUAL_MAINS and sub == 0

    @property
    def px4_name(self) -> str:
        """The mode's name as PX4 spells it in its shell and pymavlink's ``px4_map``: ``AUTO.LOITER``,
        ``AUTO.RTL``, ...; the other modes by their own name (``POSCTL``, ``OFFBOARD``)."""
        return self.name.replace("_", ".", 1) if self.name.startswith("AUTO_") else self.name

    @classmethod
    def from_px4(cls, main: int, sub: int) -> FlightMode | None:
        """The mode DO_SET_MODE asks for, or None if this autopilot does not fly it."""
        for mode in cls:
            m, s = mode.value
            if m == main and (s == sub or (m != MAIN_AUTO and sub == 0)):
                return mode
        if main == MAIN_AUTO and sub == SUB_READY:
            return cls.AUTO_LOITER  # AUTO.READY behaves as hold here
        return None

    @classmethod
    def from_custom_mode(cls, custom_mode: int) -> FlightMode | None:
        return cls.from_px4((custom_mode >> 16) & 0xFF, (custom_mode >> 24) & 0xFF)


class LandedState(Enum):
    """MAV_LANDED_STATE values (EXTENDED_SYS_STATE)."""

    ON_GROUND = 1
    IN_AIR = 2
    TAKEOFF = 3
    LANDING = 4
