"""The commander flying a stored mission (pure): AUTO.MISSION, hold pauses, resume, land, RTL."""

import math

import pytest

from autopilot.commander.commander import ACCEPTED, DENIED, Commander, Motors, Phase, VehicleState
from autopilot.commander.modes import FlightMode
from autopilot.mavlink.codec import mavlink
from autopilot.mission.executor import MissionExecutor, MissionState
from autopilot.mission.items import WireItem, parse_item
from autopilot.params.definitions import default_parameters
from quadcommon import frames

m = mavlink
HOME = (47.397742, 8.545594, 488.0)
DT = 0.002


def wire(seq, command, p=(0.0, 0.0, 0.0, math.nan), xyz=(0.0, 0.0, 0.0), frame=m.MAV_FRAME_LOCAL_NED):
    n, e, d = frames.vector_to_ned(xyz)
    return WireItem(seq, frame, command, 0, 1, *p, round(n * 1e4), round(e * 1e4), d)


def executor(*wires):
    items = []
    for w in wires:
        items.append(parse_item(w, HOME, items[-1] if items else None))
    return MissionExecutor(items, HOME)


def state(t, p=(0.0, 0.0, 0.0), v=(0.0, 0.0, 0.0), yaw=0.0):
    return VehicleState(t, p, v, (0.0, 0.0, yaw), (0.0, 0.0, 0.0))


def fly(c: Commander, t: float, seconds: float, until=None):
    """The vehicle follows the reference exactly, but stops at the ground (as the plant)."""
    for _ in range(int(round(seconds / DT))):
        out = c.step(t, DT)
        if out.motors == Motors.FLY:
            ref = out.reference
            z = max(ref.position_m[2], 0.0)
            v = ref.velocity_m_s if z > 0.0 else (0.0, 0.0, 0.0)
            c.update_state(state(t, (ref.position_m[0], ref.position_m[1], z), v, ref.yaw_rad))
        t += DT
        if until is not None and until(c):
            break
    return t


def reached_log(c: Commander, log: list):
    log.extend(c.mission.drain_reached())
    return False


@pytest.fixture
def commander():
    c = Commander(default_parameters())
    c.update_state(state(0.0))
    return c


def square():
    return executor(
        wire(0, m.MAV_CMD_NAV_TAKEOFF, xyz=(0.0, 0.0, 2.0)),
        wire(1, m.MAV_CMD_NAV_WAYPOINT, p=(1.0, 0.0, 0.0, math.nan), xyz=(2.0, 0.0, 2.0)),
        wire(2, m.MAV_CMD_NAV_WAYPOINT, xyz=(2.0, 2.0, 2.0)),
        wire(3, m.MAV_CMD_NAV_WAYPOINT, xyz=(0.0, 2.0, 2.0)),
        wire(4, m.MAV_CMD_NAV_LAND, xyz=(0.0, 0.0, 0.0)),
    )


def test_auto_mission_needs_a_mission(commander):
    out = commander.set_mode(0.0, FlightMode.AUTO_MISSION)
    assert out.result == DENIED and "no mission" in out.reason


def test_mission_mode_on_the_ground_starts_at_arming_and_ends_landed_and_disarmed(commander):
    commander.set_mission(0.0, square())
    assert commander.set_mode(0.0, FlightMode.AUTO_MISSION).result == ACCEPTED  # disarmed: PX4 allows
    assert commander.phase == Phase.DISARMED and commander.mission.state == MissionState.NOT_STARTED
    assert commander.arm(0.0).accepted
    assert commander.phase == Phase.MISSION and commander.mode == FlightMode.AUTO_MISSION
    log: list[int] = []
    t = fly(commander, 0.0, 90.0, until=lambda c: reached_log(c, log) or not c.armed)
    log.extend(commander.mission.drain_reached())
    assert log == [0, 1, 2, 3, 4]
    assert not commander.armed and commander.mission.state == MissionState.COMPLETE
    assert commander.state.position_m == pytest.approx((0.0, 0.0, 0.0), abs=1e-3)
    assert commander.mode == FlightMode.AUTO_MISSION  # a mission LAND keeps the mode (PX4)
    assert t < 90.0


def test_the_destination_is_each_items_point_then_the_landing_point_on_the_ground(commander):
    """Commander.destination (the flight log's position_setpoint_triplet, PX4's navigator
    setpoint): nothing while disarmed, then where each leg of the mission leads, in order."""
    commander.set_mission(0.0, square())
    assert commander.destination is None
    commander.arm(0.0)
    commander.set_mode(0.0, FlightMode.AUTO_MISSION)
    seen: list[tuple] = []

    def note(c: Commander) -> bool:
        if c.destination is not None:
            point = tuple(round(v, 3) + 0.0 for v in c.destination.position_m)
            if not seen or seen[-1] != point:
                seen.append(point)
        return not c.armed

    fly(commander, 0.0, 90.0, until=note)
    # takeoff, the three waypoints, above the landing point, the landing point on the ground
    assert seen == [(0.0, 0.0, 2.0), (2.0, 0.0, 2.0), (2.0, 2.0, 2.0), (0.0, 2.0, 2.0), (0.0, 0.0, 2.0),
                    (0.0, 0.0, 0.0)]  # fmt: skip
    assert commander.destination is None  # landed, disarmed


def test_hold_pauses_and_auto_mission_resumes_the_current_item(commander):
    commander.set_mission(0.0, square())
    commander.arm(0.0)
    assert commander.set_mode(0.0, FlightMode.AUTO_MISSION).accepted
    log: list[int] = []
    t = fly(commander, 0.0, 60.0, until=lambda c: reached_log(c, log) or 1 in log)
    t = fly(commander, t, 1.5)  # part of the way to item 2
    assert commander.mission.current_seq == 2
    assert commander.set_mode(t, FlightMode.AUTO_LOITER).accepted
    assert commander.mission.state == MissionState.PAUSED and commander.phase == Phase.HOLD
    t = fly(commander, t, 5.0)
    held = commander.state.position_m
    assert commander.mission.drain_reached() == []
    assert 2.0 < held[1] + 2.0 < 4.0  # stopped between items 1 and 2
    assert commander.set_mode(t, FlightMode.AUTO_MISSION).accepted
    assert commander.mission.state == MissionState.ACTIVE and commander.mission.current_seq == 2
    t = fly(commander, t, 60.0, until=lambda c: reached_log(c, log) or 3 in log)
    assert log == [0, 1, 2, 3]


def test_rtl_from_a_mission_returns_and_lands(commander):
    commander.set_mission(0.0, square())
    commander.arm(0.0)
    commander.set_mode(0.0, FlightMode.AUTO_MISSION)
    t = fly(commander, 0.0, 12.0)
    assert commander.set_mode(t, FlightMode.AUTO_RTL).accepted
    assert commander.mission.state == MissionState.PAUSED
    t = fly(commander, t, 60.0, until=lambda c: not c.armed)
    assert not commander.armed
    assert commander.state.position_m[:2] == pytest.approx((0.0, 0.0), abs=1e-3)


def test_rtl_item_switches_to_auto_rtl(commander):
    commander.set_mission(
        0.0,
        executor(
            wire(0, m.MAV_CMD_NAV_TAKEOFF, xyz=(0.0, 0.0, 2.0)),
            wire(1, m.MAV_CMD_NAV_WAYPOINT, xyz=(2.0, 0.0, 2.0)),
            wire(2, m.MAV_CMD_NAV_RETURN_TO_LAUNCH, frame=m.MAV_FRAME_MISSION),
        ),
    )
    commander.arm(0.0)
    commander.set_mode(0.0, FlightMode.AUTO_MISSION)
    t = fly(commander, 0.0, 20.0, until=lambda c: c.mode == FlightMode.AUTO_RTL)
    assert commander.mode == FlightMode.AUTO_RTL and commander.mission.drain_reached() == [0, 1, 2]
    fly(commander, t, 60.0, until=lambda c: not c.armed)
    assert not commander.armed


def test_set_current_in_flight_flies_there_next(commander):
    commander.set_mission(0.0, square())
    commander.arm(0.0)
    commander.set_mode(0.0, FlightMode.AUTO_MISSION)
    t = fly(commander, 0.0, 4.0)
    assert commander.mission_set_current(t, 3).accepted
    log: list[int] = []
    fly(commander, t, 30.0, until=lambda c: reached_log(c, log) or 3 in log)
    assert log[-1] == 3 and 1 not in log and 2 not in log
    assert commander.mission_set_current(t, 9).result == DENIED


def test_new_mission_in_flight_holds(commander):
    commander.set_mission(0.0, square())
    commander.arm(0.0)
    commander.set_mode(0.0, FlightMode.AUTO_MISSION)
    t = fly(commander, 0.0, 6.0)
    commander.set_mission(t, square())
    assert commander.mode == FlightMode.AUTO_LOITER and commander.phase == Phase.HOLD
    assert commander.mission.state == MissionState.NOT_STARTED


def test_a_completed_mission_does_not_restart_at_arming(commander):
    commander.set_mission(0.0, square())
    commander.set_mode(0.0, FlightMode.AUTO_MISSION)
    commander.arm(0.0)
    t = fly(commander, 0.0, 90.0, until=lambda c: not c.armed)
    assert commander.mission.state == MissionState.COMPLETE and commander.mode == FlightMode.AUTO_MISSION
    commander.drain_events()
    assert commander.arm(t).accepted
    assert commander.phase == Phase.IDLE  # no surprise takeoff
    assert any("mission complete" in text for _, text in commander.drain_events())
    assert commander.set_mode(t, FlightMode.AUTO_MISSION).accepted  # selecting it again flies it
    assert commander.phase == Phase.MISSION and commander.mission.current_seq == 0
    t = fly(commander, t, 10.0)
    assert commander.state.position_m[2] > 1.0
