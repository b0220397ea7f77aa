"""Every row of the commander's transition table, driven (generated from the table itself).

For each (phase, event) pair the table defines, a fresh commander is flown into the phase along a
route of table rows (each step of the route is itself checked), the event is made to happen (a
command is fired; an internal event is provoked: a plan is let run out, setpoints stop, the
vehicle touches down, the geofence is breached or changed, the sticks move or raise the throttle,
the estimate loses its horizontal aiding or its attitude) and the phase and mode afterwards must
be the row's. The vehicle follows its reference exactly and
stops at the ground, as in the other commander tests.
"""

import math
from dataclasses import replace

import pytest

from autopilot.commander.commander import Commander, Motors, VehicleState
from autopilot.commander.modes import FlightMode
from autopilot.commander.transitions import (
    AFTER,
    ASKED,
    KEEP,
    REFUSALS,
    TABLE,
    TRANSITIONS,
    Event,
    Phase,
    describe,
    lookup,
)
from autopilot.estimation.status import (
    ESTIMATOR_ATTITUDE,
    ESTIMATOR_POS_HORIZ_REL,
    ESTIMATOR_POS_VERT_ABS,
    ESTIMATOR_VELOCITY_HORIZ,
    ESTIMATOR_VELOCITY_VERT,
    EstimatorStatus,
)
from autopilot.guidance.offboard import OffboardSetpoint
from autopilot.guidance.sticks import Sticks
from autopilot.mavlink.codec import mavlink as m
from autopilot.mission.executor import MissionExecutor
from autopilot.mission.items import WireItem, parse_item
from autopilot.mission.plans import Area, Geofence
from autopilot.params.definitions import GF_HOLD, GF_LAND, GF_RTL, default_parameters
from autopilot.records import SensorSamples
from quadcommon import frames
from quadcommon.trajectories import Hover

HOME = (47.397742, 8.545594, 488.0)
DT = 0.002
E, P = Event, Phase
SCENARIO_THEN = FlightMode.AUTO_LOITER  # the hold a scenario hands over to
MANUAL_ASKED = FlightMode.ALTCTL  # distinct from POSCTL, which the stick override sets itself

# How to reach each phase from a fresh (disarmed) commander: events, each a row of the table.
ROUTES: dict[Phase, list[Event]] = {
    P.DISARMED: [],
    P.IDLE: [E.ARM],
    P.TAKEOFF: [E.ARM, E.TAKEOFF],
    P.HOLD: [E.ARM, E.TAKEOFF, E.PLAN_DONE],
    P.OFFBOARD: [E.ARM, E.TAKEOFF, E.PLAN_DONE, E.OFFBOARD],
    P.MISSION: [E.ARM, E.TAKEOFF, E.PLAN_DONE, E.MISSION],
    P.TRAJECTORY: [E.SCENARIO],
    P.LAND: [E.ARM, E.TAKEOFF, E.PLAN_DONE, E.LAND],
    P.RTL: [E.ARM, E.TAKEOFF, E.PLAN_DONE, E.RTL],
    P.RTL_LAND: [E.ARM, E.TAKEOFF, E.PLAN_DONE, E.RTL, E.PLAN_DONE],
    P.LANDED: [E.ARM, E.TAKEOFF, E.PLAN_DONE, E.LAND, E.TOUCHDOWN],
    P.MANUAL: [E.ARM, E.TAKEOFF, E.PLAN_DONE, E.MANUAL],
    P.DESCEND: [E.ARM, E.TAKEOFF, E.PLAN_DONE, E.FAILSAFE_DESCEND],
    P.ORBIT: [E.ARM, E.TAKEOFF, E.PLAN_DONE, E.ORBIT],
    P.FOLLOW: [E.ARM, E.TAKEOFF, E.PLAN_DONE, E.FOLLOW],
}
# The estimate a fallback is provoked with (flying on the EKF): its ESTIMATOR_STATUS flags, or None
# for an estimator that has lost its alignment (no attitude).
GOOD = (ESTIMATOR_ATTITUDE | ESTIMATOR_VELOCITY_HORIZ | ESTIMATOR_VELOCITY_VERT | ESTIMATOR_POS_HORIZ_REL
        | ESTIMATOR_POS_VERT_ABS)  # fmt: skip
NO_HORIZONTAL = ESTIMATOR_ATTITUDE | ESTIMATOR_VELOCITY_VERT | ESTIMATOR_POS_VERT_ABS
FALLBACKS = {E.FAILSAFE_DESCEND: NO_HORIZONTAL, E.FAILSAFE_MANUAL: NO_HORIZONTAL, E.FAILSAFE_TERMINATE: None}


IMU_ONLY = SensorSamples((0.0, 0.0, 0.0), (0.0, 0.0, 9.81), None, None, None, None)


def _status(t: float, flags: int | None) -> EstimatorStatus:
    """An EKF status with ``flags`` (None: not initialised), accurate where it is aided."""
    return EstimatorStatus(t, flags is not None, flags == GOOD, "", flags or 0, 0.0, 0.0, 0.0, 0.0, 0.1, 0.1,
                           0.1, 0.01, 0.01, False, False, {}, 0, 0)  # fmt: skip
FAILSAFE_ACTION = {E.FAILSAFE_HOLD: GF_HOLD, E.FAILSAFE_RTL: GF_RTL, E.FAILSAFE_LAND: GF_LAND}


def _item(seq, command, xyz=(0.0, 0.0, 0.0)):
    n, e, d = frames.vector_to_ned(xyz)
    return WireItem(seq, m.MAV_FRAME_LOCAL_NED, command, 0, 1, 0.0, 0.0, 0.0, math.nan,
                    round(n * 1e4), round(e * 1e4), d)  # fmt: skip


def _mission(last_command: int) -> MissionExecutor:
    wires = [
        _item(0, m.MAV_CMD_NAV_TAKEOFF, (0.0, 0.0, 2.5)),
        _item(1, m.MAV_CMD_NAV_WAYPOINT, (1.0, 0.0, 2.5)),
        _item(2, last_command, (1.0, 0.0, 0.0) if last_command == m.MAV_CMD_NAV_LAND else (0.0, 0.0, 0.0)),
    ]
    items = []
    for w in wires:
        items.append(parse_item(w, HOME, items[-1] if items else None))
    return MissionExecutor(items, HOME)


class Flight:
    """A commander and a vehicle that follows its reference exactly (and stops at the ground)."""

    def __init__(self, mission_end: int) -> None:
        self.c = Commander(default_parameters())
        self.t = 0.0
        self.feed_setpoints = True
        self.sticks = Sticks(0.0)  # fed every step (a MANUAL_CONTROL stream), moved by happen()
        self.feed_sticks = True
        self.ekf_flags: int | None = GOOD  # the estimate, once flying on a (made-up) EKF status
        self.on_ekf = False
        self._state((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
        self.c.set_mission(0.0, _mission(mission_end))

    def _state(self, p, v, yaw=0.0) -> None:
        self.c.update_state(VehicleState(self.t, p, v, (0.0, 0.0, yaw), (0.0, 0.0, 0.0)))

    def step(self) -> None:
        if self.feed_setpoints:
            self.c.offboard_setpoint(OffboardSetpoint(self.t, position=(0.0, 0.0, 2.5)))
        if self.feed_sticks:
            self.c.manual_sticks(replace(self.sticks, time_s=self.t))
        if self.on_ekf:  # an IMU stream and the filter's status
            self.c.on_ekf = True
            self.c.estimator_status = _status(self.t, self.ekf_flags)
            self.c.observe_sensors(self.t, IMU_ONLY)
        out = self.c.step(self.t, DT)
        if out.motors == Motors.FLY:
            ref = out.reference
            z = max(ref.position_m[2], 0.0)
            v = ref.velocity_m_s if z > 0.0 else (0.0, 0.0, 0.0)
            self._state((ref.position_m[0], ref.position_m[1], z), v, ref.yaw_rad)
        self.t += DT

    def step_until(self, done, seconds: float = 120.0) -> None:
        for _ in range(int(seconds / DT)):
            self.step()
            if done():
                return
        raise AssertionError(f"still {self.c.phase.name} after {seconds} s")

    @property
    def height(self) -> float:
        return self.c.state.position_m[2]

    def prepare(self, event: Event) -> None:
        """What ``event`` needs besides the phase: a manual mode on the ground for the sticks to take
        off in, the override of OFFBOARD enabled, the throttle down to land on the sticks."""
        c = self.c
        if event == E.STICK_TAKEOFF:
            assert c.set_mode(self.t, MANUAL_ASKED).accepted
        elif event == E.RC_OVERRIDE and c.phase == P.OFFBOARD:
            c.params.set("COM_RC_OVERRIDE", 3)
        elif event == E.TOUCHDOWN and c.phase == P.MANUAL:
            self.sticks = replace(self.sticks, up=-1.0)
        elif event == E.FAILSAFE_MANUAL:  # POSCTL falls back to ALTCTL (MANUAL_ASKED)
            assert c.set_mode(self.t, FlightMode.POSCTL).accepted
        if event in FALLBACKS:
            self.on_ekf = True
            self.step()

    def happen(self, event: Event) -> None:
        """Make ``event`` happen in the current phase."""
        c, phase = self.c, self.c.phase
        if event == E.STICK_TAKEOFF:
            self.sticks = replace(self.sticks, up=0.5)
            self.step_until(lambda: c.phase != phase, seconds=1.0)
        elif event == E.RC_OVERRIDE:
            self.step()  # the stream as it was
            self.sticks = replace(self.sticks, forward=0.5)  # then a stick moves (held, it would not)
            self.step_until(lambda: c.phase != phase, seconds=1.0)
        elif event == E.MISSION_INVALID:  # a fence that excludes the mission's waypoint (1, 0)
            c.set_geofence(self.t, Geofence((Area(False, centre=(1.0, 0.0), radius_m=0.3),)))
        elif event == E.PLAN_DONE:
            self.step_until(lambda: c.phase != phase)
        elif event == E.TOUCHDOWN:
            self.step_until(lambda: c.phase == P.LANDED)
        elif event in (E.LANDED_TIMEOUT, E.PREFLIGHT_TIMEOUT):
            self.step_until(lambda: c.phase == P.DISARMED)
        elif event == E.OFFBOARD_LOST:
            self.feed_setpoints = False
            self.step_until(lambda: c.phase != phase)
        elif event in (E.MISSION_LAND, E.MISSION_RTL):
            self.step_until(lambda: c.phase != phase)
        elif event in FALLBACKS:  # the estimate degrades: the mode (or the next) cannot run
            if self.height < 0.5:  # just taken off: in the air
                self.step_until(lambda: self.height > 0.5, seconds=10.0)
            if phase == P.MANUAL and event == E.FAILSAFE_DESCEND:
                self.feed_sticks = False  # ALTCTL flies without a position: the sticks' loss acts
            self.ekf_flags = FALLBACKS[event]
            mode = c.mode
            if lookup(phase, event).action:
                self.step_until(lambda: (c.phase, c.mode) != (phase, mode), seconds=2.0)
            else:  # already descending: nothing to do
                self.step()
        elif event in FAILSAFE_ACTION:
            if self.height < 0.5:  # just taken off: high enough to put a fence below it
                self.step_until(lambda: self.height > 0.5, seconds=10.0)
            assert c.phase == phase
            c.params.set("GF_ACTION", FAILSAFE_ACTION[event])
            c.params.set("GF_MAX_VER_DIST", round(self.height / 2.0, 2))
            self.step()
        else:  # a command
            args = {
                E.DISARM: {"force": True, "why": "disarmed"},
                E.MANUAL: {"mode": MANUAL_ASKED},
                E.SCENARIO: {"trajectory": Hover((0.0, 0.0, 1.5), 0.0, 1.0), "then": SCENARIO_THEN},
                E.REPOSITION: {"target": (1.0, 0.0, 2.0), "speed_m_s": None, "yaw_rad": None},
            }.get(event, {})
            if self.feed_setpoints:  # a fresh setpoint: OFFBOARD needs a stream
                c.offboard_setpoint(OffboardSetpoint(self.t, position=(0.0, 0.0, 2.5)))
            c.manual_sticks(replace(self.sticks, time_s=self.t))  # the manual modes need the sticks
            assert c._fire(self.t, event, **args).accepted, c.events[-1:]


def _fly_to(phase: Phase, mission_end: int) -> Flight:
    flight = Flight(mission_end)
    for event in ROUTES[phase]:
        before = flight.c.phase
        row = lookup(before, event)
        assert row is not None, f"route to {phase.name}: no row {before.name} + {event.name}"
        if event in FALLBACKS:  # through the table alone: the estimate stays good on the route
            assert flight.c._fire(flight.t, event).accepted
        else:
            flight.happen(event)
        expected = before if not isinstance(row.to, Phase) else row.to
        assert flight.c.phase == expected, f"route to {phase.name}: {event.name} from {before.name}"
    assert flight.c.phase == phase
    return flight


@pytest.mark.timeout(60)
@pytest.mark.parametrize(
    "phase, event", sorted(TRANSITIONS, key=lambda k: (k[0].value, k[1].value)), ids=lambda x: x.name
)
def test_every_row_of_the_table(phase: Phase, event: Event) -> None:
    row = TRANSITIONS[(phase, event)]
    flight = _fly_to(phase, m.MAV_CMD_NAV_RETURN_TO_LAUNCH if event == E.MISSION_RTL else m.MAV_CMD_NAV_LAND)
    flight.prepare(event)
    mode_before = flight.c.mode
    flight.happen(event)
    c = flight.c
    assert c.phase == (phase if not isinstance(row.to, Phase) else row.to)
    expected_mode = {KEEP: mode_before, ASKED: MANUAL_ASKED, AFTER: SCENARIO_THEN}.get(row.mode, row.mode)
    assert c.mode == expected_mode
    assert c.armed == (c.phase != P.DISARMED)


@pytest.mark.timeout(60)
def test_commands_without_a_row_are_refused_with_a_reason() -> None:
    flight = Flight(m.MAV_CMD_NAV_LAND)
    outcome = flight.c.takeoff(0.0)
    assert not outcome.accepted and outcome.reason == REFUSALS[E.TAKEOFF]
    assert flight.c.phase == P.DISARMED


@pytest.mark.timeout(60)
def test_offboard_during_rtl_descent_is_offboard_not_landing() -> None:
    """Found reading the old implicit machine: switching to OFFBOARD in RTL's final descent kept
    a 'landing' flag, so the vehicle reported LANDING while flying offboard and failsafes treated it
    as busy. In the table it is the phase RTL_LAND, which OFFBOARD leaves."""
    flight = _fly_to(P.RTL_LAND, m.MAV_CMD_NAV_LAND)
    assert flight.c.landed_state.name == "LANDING"
    assert flight.c.set_mode(flight.t, FlightMode.OFFBOARD).accepted
    assert flight.c.phase == P.OFFBOARD
    flight.step_until(lambda: flight.height > 2.4, seconds=20.0)
    assert flight.c.landed_state.name == "IN_AIR"
    flight.happen(E.FAILSAFE_HOLD)  # not busy any more: the failsafe acts
    assert flight.c.phase == P.HOLD


def test_the_table_is_printable() -> None:
    lines = describe().splitlines()
    assert len(lines) == len(TABLE) + 2  # header, rule, one line per row
    assert "| DISARMED | ARM | IDLE | (keep) | arm |" in lines


@pytest.mark.timeout(60)
@pytest.mark.parametrize("event, name", [(E.ORBIT, "ORBIT"), (E.FOLLOW, "AUTO.FOLLOW_TARGET")])
def test_orbit_and_follow_need_the_local_position(event: Event, name: str) -> None:
    """Without a horizontal position (PX4's mode requirements) the switch is refused with the reason;
    the vehicle stays in the fallback it took (Descend)."""
    flight = _fly_to(P.HOLD, m.MAV_CMD_NAV_LAND)
    flight.on_ekf = True
    flight.step()
    flight.step_until(lambda: flight.height > 0.5, seconds=10.0)
    flight.ekf_flags = NO_HORIZONTAL
    flight.step_until(lambda: flight.c.phase == P.DESCEND, seconds=2.0)
    outcome = flight.c._fire(flight.t, event)
    assert not outcome.accepted
    assert outcome.reason.startswith(f"Switching to {name} is currently not possible: no ")
    assert flight.c.phase == P.DESCEND
