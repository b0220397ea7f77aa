"""The commander's state machine as one table: (phase, event) -> (next phase, mode, action).

A *phase* is what the vehicle is doing; the *mode* is what a ground station sees in HEARTBEAT.
Disarmed, a mode can still be selected (PX4 remembers it; arming then enters it), so the state is
the pair (phase, mode). Every change of either goes through :data:`TABLE`; the commander
(:mod:`.commander`) only decides *which* event happened (a command, a timeout, a plan that
finished, a failsafe) and carries out the row's action (plan a trajectory, check a guard).

Reading a row: "in any of these phases, this event leads to that phase with that mode, after the
named action succeeded". An action may refuse (a guard: no setpoint stream, no mission, in the
air without force); the state is then unchanged and the refusal is answered with its reason.
An event with no row for the current phase is refused (commands) or cannot happen (internal
events are only raised where a row exists).

Mode column: a :class:`~.modes.FlightMode`, or ``KEEP`` (unchanged), ``ASKED`` (the mode the
event asked for: one of the manual modes MANUAL, STABILIZED, ALTCTL, POSCTL, ACRO), ``AFTER`` (the
mode a scenario's trajectory hands over to when it ends). Phase column ``SAME`` keeps the phase.
"""

from __future__ import annotations

from enum import Enum
from typing import NamedTuple

from .modes import FlightMode


class Phase(Enum):
    DISARMED = "disarmed"
    IDLE = "idle"  # armed, on the ground, waiting
    TAKEOFF = "takeoff"
    HOLD = "hold"
    OFFBOARD = "offboard"
    MISSION = "mission"  # flying the stored mission (AUTO.MISSION)
    TRAJECTORY = "trajectory"  # a trajectory installed by a scenario (the paper's experiment)
    LAND = "land"  # descending to touchdown (AUTO.LAND, or a mission's LAND item in AUTO.MISSION)
    RTL = "rtl"  # climbing to RTL_RETURN_ALT and returning above home
    RTL_LAND = "rtl_land"  # RTL's final descent (mode stays AUTO.RTL)
    DESCEND = "descend"  # PX4's Descend: level, down at MPC_LAND_SPEED, no position (mode AUTO.LAND)
    LANDED = "landed"  # touched down, motors idle, waiting to disarm
    MANUAL = "manual"  # flying on the sticks (MANUAL, STABILIZED, ALTCTL, POSCTL, ACRO)
    ORBIT = "orbit"  # circling a centre (Orbit: MAV_CMD_DO_ORBIT)
    FOLLOW = "follow"  # following the target a ground station reports (AUTO.FOLLOW_TARGET)


class Event(Enum):
    # commands from a ground station (or the scenario runner)
    ARM = "arm"
    DISARM = "disarm"
    TAKEOFF = "takeoff"  # MAV_CMD_NAV_TAKEOFF
    SELECT_TAKEOFF = "select takeoff"  # DO_SET_MODE AUTO.TAKEOFF
    HOLD = "hold"  # AUTO.LOITER
    MANUAL = "manual"  # a manual mode (MANUAL, STABILIZED, ALTCTL, POSCTL, ACRO): needs the sticks
    LAND = "land"
    RTL = "rtl"
    OFFBOARD = "offboard"
    MISSION = "mission"  # enter AUTO.MISSION (continue if already flying it)
    MISSION_START = "mission start"  # MAV_CMD_MISSION_START: (re)start from the current item
    SET_CURRENT = "set current item"
    MISSION_REPLACED = "mission replaced"
    MISSION_INVALID = "mission invalid"  # a new geofence excludes the mission flown (PX4: loiter)
    SCENARIO = "scenario"  # armed and flying a scenario's trajectory from t = 0
    REPOSITION = "reposition"  # MAV_CMD_DO_REPOSITION: fly to a point, then hold there
    ORBIT = "orbit"  # MAV_CMD_DO_ORBIT, or DO_SET_MODE Orbit
    FOLLOW = "follow"  # DO_SET_MODE AUTO.FOLLOW_TARGET
    # raised by the commander itself
    PLAN_DONE = "plan done"  # the phase's trajectory reached its end
    TOUCHDOWN = "touchdown"
    LANDED_TIMEOUT = "landed timeout"  # COM_DISARM_LAND after touchdown
    PREFLIGHT_TIMEOUT = "preflight timeout"  # COM_DISARM_PRFLT after arming without takeoff
    OFFBOARD_LOST = "offboard lost"  # no setpoint for COM_OF_LOSS_T
    MISSION_LAND = "mission land"  # the mission reached a LAND item
    MISSION_RTL = "mission rtl"  # the mission reached a RETURN_TO_LAUNCH item
    FAILSAFE_HOLD = "failsafe hold"
    FAILSAFE_RTL = "failsafe rtl"
    FAILSAFE_LAND = "failsafe land"
    # PX4's mode fallback (failsafe.py mode_fallback): the chosen mode cannot run any more
    FAILSAFE_MANUAL = "failsafe manual"  # POSCTL -> ALTCTL -> STABILIZED without a position / altitude
    FAILSAFE_DESCEND = "failsafe descend"  # not even Land can run: Descend
    FAILSAFE_TERMINATE = "failsafe terminate"  # not even Descend can run: motors off
    STICK_TAKEOFF = "stick takeoff"  # on the ground in a manual mode: throttle above 62.5 %
    RC_OVERRIDE = "rc override"  # sticks moved in AUTO or OFFBOARD (COM_RC_OVERRIDE): to POSCTL


class _Marker(Enum):
    SAME = "same"
    KEEP = "keep"
    ASKED = "asked"
    AFTER = "after"


SAME, KEEP, ASKED, AFTER = _Marker.SAME, _Marker.KEEP, _Marker.ASKED, _Marker.AFTER

P = Phase
E = Event
M = FlightMode
ON_GROUND = (P.IDLE, P.LANDED)
FLYING = (P.TAKEOFF, P.HOLD, P.OFFBOARD, P.MISSION, P.TRAJECTORY, P.LAND, P.RTL, P.RTL_LAND, P.MANUAL,
          P.DESCEND, P.ORBIT, P.FOLLOW)
ARMED = ON_GROUND + FLYING
DESCENDING = (P.LAND, P.RTL_LAND)
BUSY = (P.LAND, P.RTL, P.RTL_LAND, P.DESCEND)  # returning or landing: a hold/RTL failsafe lets it go on
NOT_BUSY = tuple(p for p in FLYING if p not in BUSY)
# AUTO modes, in the air (Orbit is POSCTL's: its sticks change the orbit, they do not take over)
AUTOMATIC = tuple(p for p in FLYING if p not in (P.OFFBOARD, P.MANUAL, P.ORBIT))


def _but(phases: tuple[Phase, ...], *excluded: Phase) -> tuple[Phase, ...]:
    return tuple(p for p in phases if p not in excluded)


# fmt: off
# (from phases,              event,               to,            mode,            action)
TABLE: tuple[tuple[tuple[Phase, ...], Event, Phase | _Marker, FlightMode | _Marker, str | None], ...] = (
    # -- arming and disarming -------------------------------------------------------------------
    ((P.DISARMED,),           E.ARM,               P.IDLE,        KEEP,            "arm"),
    (ARMED,                   E.ARM,               SAME,          KEEP,            None),
    ((P.DISARMED,),           E.DISARM,            SAME,          KEEP,            None),
    (ARMED,                   E.DISARM,            P.DISARMED,    KEEP,            "disarm"),
    ((P.IDLE,),               E.PREFLIGHT_TIMEOUT, P.DISARMED,    KEEP,            "disarm"),
    ((P.LANDED,),             E.LANDED_TIMEOUT,    P.DISARMED,    KEEP,            "disarm"),
    ((P.DISARMED,),           E.SCENARIO,          P.TRAJECTORY,  M.AUTO_MISSION,  "start_scenario"),
    # -- disarmed: a selected mode is remembered (arming enters OFFBOARD or AUTO.MISSION) -------
    ((P.DISARMED,),           E.SELECT_TAKEOFF,    SAME,          M.AUTO_TAKEOFF,  None),
    ((P.DISARMED,),           E.HOLD,              SAME,          M.AUTO_LOITER,   None),
    ((P.DISARMED,),           E.LAND,              SAME,          M.AUTO_LAND,     None),
    ((P.DISARMED,),           E.RTL,               SAME,          M.AUTO_RTL,      None),
    ((P.DISARMED,),           E.OFFBOARD,          SAME,          M.OFFBOARD,      "enter_offboard"),
    ((P.DISARMED,),           E.MISSION,           SAME,          M.AUTO_MISSION,  "check_mission"),
    ((P.DISARMED,),           E.MISSION_START,     SAME,          M.AUTO_MISSION,  "check_mission"),
    ((P.DISARMED,),           E.MANUAL,            SAME,          ASKED,           "enter_manual"),
    # -- armed on the ground: hold/land/RTL only change the mode --------------------------------
    (ON_GROUND,               E.HOLD,              SAME,          M.AUTO_LOITER,   None),
    (ON_GROUND,               E.LAND,              SAME,          M.AUTO_LAND,     None),
    (ON_GROUND,               E.RTL,               SAME,          M.AUTO_RTL,      None),
    (ON_GROUND,               E.MANUAL,            SAME,          ASKED,           "enter_manual"),
    # -- the sticks: a manual mode flies them; they take off, land, and take over --------------------
    (ON_GROUND,               E.STICK_TAKEOFF,     P.MANUAL,      KEEP,            "stick_takeoff"),
    (FLYING,                  E.MANUAL,            P.MANUAL,      ASKED,           "enter_manual"),
    (AUTOMATIC + (P.OFFBOARD,), E.RC_OVERRIDE,     P.MANUAL,      M.POSCTL,        "enter_manual"),
    ((P.MANUAL,),             E.TOUCHDOWN,         P.LANDED,      KEEP,            "touchdown"),
    # -- armed: going somewhere ------------------------------------------------------------------
    (ARMED,                   E.TAKEOFF,           P.TAKEOFF,     M.AUTO_TAKEOFF,  "plan_takeoff"),
    (ARMED,                   E.SELECT_TAKEOFF,    P.TAKEOFF,     M.AUTO_TAKEOFF,  "plan_takeoff"),
    (FLYING,                  E.HOLD,              P.HOLD,        M.AUTO_LOITER,   "plan_hold"),
    (FLYING,                  E.REPOSITION,        P.HOLD,        M.AUTO_LOITER,   "plan_reposition"),
    (ON_GROUND,               E.REPOSITION,        P.TAKEOFF,     M.AUTO_LOITER,   "plan_climb_reposition"),
    (_but(FLYING, *DESCENDING), E.LAND,            P.LAND,        M.AUTO_LAND,     "plan_landing"),
    (DESCENDING,              E.LAND,              P.LAND,        M.AUTO_LAND,     None),
    (_but(FLYING, P.RTL, P.RTL_LAND), E.RTL,       P.RTL,         M.AUTO_RTL,      "plan_return"),
    ((P.RTL, P.RTL_LAND),     E.RTL,               SAME,          KEEP,            None),
    (ARMED,                   E.OFFBOARD,          P.OFFBOARD,    M.OFFBOARD,      "enter_offboard"),
    (_but(ARMED, P.MISSION),  E.MISSION,           P.MISSION,     M.AUTO_MISSION,  "start_mission"),
    ((P.MISSION,),            E.MISSION,           SAME,          KEEP,            None),
    (ARMED,                   E.MISSION_START,     P.MISSION,     M.AUTO_MISSION,  "start_mission"),
    ((P.MISSION,),            E.SET_CURRENT,       SAME,          KEEP,            "start_mission"),
    ((P.MISSION,),            E.MISSION_REPLACED,  P.HOLD,        M.AUTO_LOITER,   "plan_hold"),
    ((P.MISSION,),            E.MISSION_INVALID,   P.HOLD,        M.AUTO_LOITER,   "plan_hold"),
    # -- Orbit and follow-me: flying only (both prevent arming in PX4); disarmed, only selected -----
    (FLYING,                  E.ORBIT,             P.ORBIT,       M.ORBIT,         "start_orbit"),
    (FLYING,                  E.FOLLOW,            P.FOLLOW,      M.AUTO_FOLLOW_TARGET, "start_follow"),
    ((P.DISARMED,),           E.FOLLOW,            SAME,          M.AUTO_FOLLOW_TARGET, None),
    ((P.DISARMED,),           E.ORBIT,             SAME,          M.ORBIT,         None),
    # -- plans that end, touchdown, timeouts -----------------------------------------------------
    ((P.TAKEOFF,),            E.PLAN_DONE,         P.HOLD,        M.AUTO_LOITER,   None),
    ((P.RTL,),                E.PLAN_DONE,         P.RTL_LAND,    M.AUTO_RTL,      "plan_landing"),
    ((P.TRAJECTORY,),         E.PLAN_DONE,         P.HOLD,        AFTER,           "plan_hold"),
    (DESCENDING + (P.DESCEND,), E.TOUCHDOWN,       P.LANDED,      KEEP,            "touchdown"),
    ((P.OFFBOARD,),           E.OFFBOARD_LOST,     P.HOLD,        M.AUTO_LOITER,   "plan_hold"),
    ((P.MISSION,),            E.MISSION_LAND,      P.LAND,        KEEP,            "plan_landing"),
    ((P.MISSION,),            E.MISSION_RTL,       P.RTL,         M.AUTO_RTL,      "plan_return"),
    # -- failsafes (only checked while flying); a return or landing under way goes on ------------
    (NOT_BUSY,                E.FAILSAFE_HOLD,     P.HOLD,        M.AUTO_LOITER,   "plan_hold"),
    (BUSY,                    E.FAILSAFE_HOLD,     SAME,          KEEP,            None),
    (NOT_BUSY,                E.FAILSAFE_RTL,      P.RTL,         M.AUTO_RTL,      "plan_return"),
    (BUSY,                    E.FAILSAFE_RTL,      SAME,          KEEP,            None),
    (_but(FLYING, *DESCENDING), E.FAILSAFE_LAND,   P.LAND,        M.AUTO_LAND,     "plan_landing"),
    (DESCENDING,              E.FAILSAFE_LAND,     SAME,          KEEP,            None),
    # -- the mode cannot run (an estimate or a sensor is gone): PX4's fallback chain --------------
    ((P.MANUAL,),             E.FAILSAFE_MANUAL,   SAME,          ASKED,           "enter_manual"),
    (_but(FLYING, P.DESCEND), E.FAILSAFE_DESCEND,  P.DESCEND,     M.AUTO_LAND,     "descend"),
    ((P.DESCEND,),            E.FAILSAFE_DESCEND,  SAME,          KEEP,            None),
    (FLYING,                  E.FAILSAFE_TERMINATE, P.DISARMED,   KEEP,            "terminate"),
)
# fmt: on

# Commands refused where the table has no row, and why (anything else: "not possible now").
REFUSALS: dict[Event, str] = {
    E.TAKEOFF: "takeoff refused: arm first",
    E.REPOSITION: "reposition refused: disarmed (arm first)",
    E.ORBIT: "orbit refused: not flying (take off first)",
    E.FOLLOW: "follow-me refused: not flying (take off first)",
    E.SET_CURRENT: "",  # not flying the mission: the current item is just stored
    E.MISSION_REPLACED: "",  # not flying the mission: the new one is just stored
    E.MISSION_INVALID: "",  # not flying the mission: AUTO.MISSION refuses it until it is valid
}


class Transition(NamedTuple):
    to: Phase | _Marker
    mode: FlightMode | _Marker
    action: str | None


def _build() -> dict[tuple[Phase, Event], Transition]:
    table: dict[tuple[Phase, Event], Transition] = {}
    for phases, event, to, mode, action in TABLE:
        for phase in phases:
            key = (phase, event)
            if key in table:
                raise ValueError(f"the commander's table has two rows for {phase.name} + {event.name}")
            table[key] = Transition(to, mode, action)
    return table


TRANSITIONS: dict[tuple[Phase, Event], Transition] = _build()


def lookup(phase: Phase, event: Event) -> Transition | None:
    """The row for ``event`` in ``phase``, or None (refused / cannot happen there)."""
    return TRANSITIONS.get((phase, event))


def describe() -> str:
    """The table as Markdown, one line per row (``python -c "from autopilot.commander.transitions import
    describe; print(describe())"``)."""
    groups = {ARMED: "armed (any)", FLYING: "flying (any)", NOT_BUSY: "flying, not returning or landing",
              AUTOMATIC + (P.OFFBOARD,): "flying an AUTO mode or OFFBOARD"}
    lines = ["| from | event | to | mode | action |", "|---|---|---|---|---|"]
    for phases, event, to, mode, action in TABLE:
        names = groups.get(phases) or ", ".join(p.name for p in phases)
        to_text = to.name if isinstance(to, Phase) else "(same)"
        mode_text = mode.px4_name if isinstance(mode, FlightMode) else f"({mode.value})"
        lines.append(f"| {names} | {event.name} | {to_text} | {mode_text} | {action or ''} |")
    return "\n".join(lines)
