"""Geofence and rally plans on the wire, in simulation time (the whole stack in-process): an
uploaded inclusion fence is enforced (breach -> GF_ACTION), DO_REPOSITION outside it is refused,
and RTL goes to the nearest rally point when it is closer than home, as PX4 does."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as m

from autopilot.commander.modes import FlightMode
from quadcommon import frames

from ..stack import Gcs
from .test_params_failsafes import INT32, param_set, take_off, texts, wait_sim
from .test_reposition import HOME, command_int, wait_at

FENCE, RALLY = m.MAV_MISSION_TYPE_FENCE, m.MAV_MISSION_TYPE_RALLY
RTL = FlightMode.AUTO_RTL.custom_mode
LOITER = FlightMode.AUTO_LOITER.custom_mode


def at(north: float, east: float) -> tuple[int, int]:
    lat, lon, _ = frames.ned_to_geodetic(north, east, 0.0, HOME)
    return round(lat * 1e7), round(lon * 1e7)


def plan_item(seq, command, p1, north, east, mission_type, z=0.0):
    x, y = at(north, east)
    return (seq, m.MAV_FRAME_GLOBAL_INT, command, 0, 1, p1, 0.0, 0.0, 0.0, x, y, z, mission_type)


def upload_plan(gcs: Gcs, items, mission_type) -> int:
    """The mission protocol from the ground station's side; returns the MISSION_ACK type."""
    gcs.conn.mav.mission_count_send(gcs.system_id, 1, len(items), mission_type)
    result = {}

    def step(g: Gcs) -> bool:
        msg = g.poll()
        if msg is None:
            return False
        if msg.get_type() == "MISSION_REQUEST_INT" and msg.mission_type == mission_type:
            g.conn.mav.mission_item_int_send(g.system_id, 1, *items[msg.seq])
        elif msg.get_type() == "MISSION_ACK" and msg.mission_type == mission_type:
            result["ack"] = msg.type
        return "ack" in result

    end = gcs.sim_time + 5.0
    while gcs.sim_time < end and not step(gcs):
        pass
    assert "ack" in result, "no MISSION_ACK"
    return result["ack"]


@pytest.mark.timeout(120)
def test_fence_breach_returns_to_the_nearest_rally_point(vehicle):
    stack, gcs = vehicle
    rally = [
        plan_item(k, m.MAV_CMD_NAV_RALLY_POINT, 0.0, n, e, RALLY, 10.0)
        for k, (n, e) in enumerate([(-30, 0), (9, 4)])
    ]
    assert upload_plan(gcs, rally, RALLY) == m.MAV_MISSION_ACCEPTED
    take_off(gcs, 2.0)
    x, y = at(8.0, 0.0)
    assert command_int(gcs, m.MAV_FRAME_GLOBAL_INT, (-1, 1, 0, math.nan), x, y, 490.0).result == 0
    wait_at(gcs, frames.vector_from_ned((8.0, 0.0, -2.0)), 0.1, sim_timeout=20.0)
    # An inclusion circle of 5 m about home, uploaded while the vehicle is 8 m out: breach at once.
    param_set(gcs, "GF_ACTION", 3, INT32)  # return
    fence = [plan_item(0, m.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, 5.0, 0.0, 0.0, FENCE)]
    assert upload_plan(gcs, fence, FENCE) == m.MAV_MISSION_ACCEPTED
    gcs.wait(lambda g: g.custom_mode == RTL, sim_timeout=2.0, what="RTL")
    wait_sim(gcs, 0.2)
    assert "m outside the fence's inclusion area: returning" in texts(gcs)
    assert "returning to rally point 1" in texts(gcs)
    # Lands at the rally point (9 m north, 4 m east), not at home.
    gcs.wait(lambda g: not g.armed, sim_timeout=40.0, what="landed and disarmed")
    north, east, _ = frames.vector_to_ned(gcs.position())
    assert math.hypot(north - 9.0, east - 4.0) < 0.3


@pytest.mark.timeout(120)
def test_reposition_outside_the_uploaded_fence_is_refused_and_an_exclusion_counts(vehicle):
    stack, gcs = vehicle
    square = [(-10, -10), (10, -10), (10, 10), (-10, 10)]
    fence = [
        *(
            plan_item(k, m.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION, 4.0, n, e, FENCE)
            for k, (n, e) in enumerate(square)
        ),
        plan_item(4, m.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION, 2.0, 6.0, 0.0, FENCE),
    ]
    assert upload_plan(gcs, fence, FENCE) == m.MAV_MISSION_ACCEPTED
    take_off(gcs, 2.0)
    for north, east in ((15.0, 0.0), (6.0, 0.5)):  # outside the square; inside the exclusion
        x, y = at(north, east)
        ack = command_int(gcs, m.MAV_FRAME_GLOBAL_INT, (-1, 1, 0, math.nan), x, y, 490.0)
        assert ack.result == m.MAV_RESULT_DENIED
    wait_sim(gcs, 0.1)
    assert "outside the fence's inclusion area" in texts(gcs) and "inside an exclusion area" in texts(gcs)
    x, y = at(3.0, 5.0)
    assert command_int(gcs, m.MAV_FRAME_GLOBAL_INT, (-1, 1, 0, math.nan), x, y, 490.0).result == 0
    wait_at(gcs, frames.vector_from_ned((3.0, 5.0, -2.0)), 0.1, sim_timeout=20.0)
    # Cleared: the same point is accepted.
    gcs.conn.mav.mission_clear_all_send(gcs.system_id, 1, FENCE)
    wait_sim(gcs, 0.2)
    x, y = at(15.0, 0.0)
    assert command_int(gcs, m.MAV_FRAME_GLOBAL_INT, (-1, 1, 0, math.nan), x, y, 490.0).result == 0


@pytest.mark.timeout(120)
def test_a_mission_is_checked_against_the_fence_at_upload(vehicle):
    stack, gcs = vehicle
    MISSION = m.MAV_MISSION_TYPE_MISSION
    fence = [plan_item(0, m.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, 10.0, 0.0, 0.0, FENCE)]
    assert upload_plan(gcs, fence, FENCE) == m.MAV_MISSION_ACCEPTED

    def mission(*points):  # relative altitude 3 m
        frame, waypoint = m.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, m.MAV_CMD_NAV_WAYPOINT
        return [(k, frame, waypoint, 0, 1, 0.0, 0.0, 0.0, math.nan, *at(n, e), 3.0, MISSION)
                for k, (n, e) in enumerate(points)]  # fmt: skip

    assert upload_plan(gcs, mission((3.0, 0.0), (12.0, 0.0)), MISSION) == m.MAV_MISSION_INVALID_PARAM5_X
    wait_sim(gcs, 0.2)
    assert "mission rejected: item 1: outside the geofence" in texts(gcs)
    assert upload_plan(gcs, mission((3.0, 0.0), (0.0, 6.0)), MISSION) == m.MAV_MISSION_ACCEPTED
    # and the vertical limit, relative to home
    param_set(gcs, "GF_MAX_VER_DIST", 2.0)
    assert upload_plan(gcs, mission((3.0, 0.0)), MISSION) == m.MAV_MISSION_INVALID_PARAM5_X


def waypoints(*points, altitude: float = 3.0):
    """Mission items: waypoints at (north, east) m from home, ``altitude`` m above home."""
    frame, waypoint = m.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, m.MAV_CMD_NAV_WAYPOINT
    mission = m.MAV_MISSION_TYPE_MISSION
    return [(k, frame, waypoint, 0, 1, 0.0, 0.0, 0.0, math.nan, *at(n, e), altitude, mission)
            for k, (n, e) in enumerate(points)]  # fmt: skip


@pytest.mark.timeout(120)
def test_a_fence_uploaded_after_the_mission_is_checked_against_it_warned_not_refused(vehicle):
    """PX4: the fence is accepted; the mission it excludes is reported ("Geofence violation for
    waypoint N") and AUTO.MISSION refuses it until the mission or the fence changes."""
    stack, gcs = vehicle
    MISSION = m.MAV_MISSION_TYPE_MISSION
    assert upload_plan(gcs, waypoints((3.0, 0.0), (12.0, 0.0)), MISSION) == m.MAV_MISSION_ACCEPTED
    small = [plan_item(0, m.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, 10.0, 0.0, 0.0, FENCE)]
    assert upload_plan(gcs, small, FENCE) == m.MAV_MISSION_ACCEPTED  # the fence is not refused
    wait_sim(gcs, 0.2)
    assert "Geofence violation for waypoint 2 (item 1: outside the geofence:" in texts(gcs)
    assert "the mission is not valid with this geofence" in texts(gcs)
    ack = gcs.command(m.MAV_CMD_DO_SET_MODE, 1, 4, 4)  # AUTO.MISSION
    assert ack.result == m.MAV_RESULT_DENIED
    wait_sim(gcs, 0.1)
    assert "AUTO.MISSION refused: Geofence violation for waypoint 2" in texts(gcs)
    wide = [plan_item(0, m.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, 20.0, 0.0, 0.0, FENCE)]
    assert upload_plan(gcs, wide, FENCE) == m.MAV_MISSION_ACCEPTED  # the mission fits again
    assert gcs.command(m.MAV_CMD_DO_SET_MODE, 1, 4, 4).result == m.MAV_RESULT_ACCEPTED


@pytest.mark.timeout(120)
def test_a_fence_that_excludes_the_mission_in_flight_makes_the_vehicle_hold(vehicle):
    stack, gcs = vehicle
    MISSION = m.MAV_MISSION_TYPE_MISSION
    assert upload_plan(gcs, waypoints((2.0, 0.0), (14.0, 0.0)), MISSION) == m.MAV_MISSION_ACCEPTED
    take_off(gcs, 3.0)
    assert gcs.command(m.MAV_CMD_MISSION_START, 0, 0).result == m.MAV_RESULT_ACCEPTED
    wait_sim(gcs, 5.0)
    assert stack.autopilot.commander.mode == FlightMode.AUTO_MISSION
    # An exclusion around the second waypoint; the vehicle is not in it (no breach).
    fence = [plan_item(0, m.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION, 3.0, 14.0, 0.0, FENCE)]
    assert upload_plan(gcs, fence, FENCE) == m.MAV_MISSION_ACCEPTED
    gcs.wait(lambda g: g.custom_mode == LOITER, sim_timeout=2.0, what="hold")
    wait_sim(gcs, 0.2)
    assert "No valid mission available, loitering" in texts(gcs)
    assert "geofence breached" not in texts(gcs)
    wait_sim(gcs, 6.0)
    north, _, _ = frames.vector_to_ned(gcs.position())
    assert north < 11.0  # held short of the exclusion


@pytest.mark.timeout(120)
@pytest.mark.parametrize("rtl_type, lands_at, height", [(0, (0.0, 0.0), 5.0), (1, (6.0, 2.0), 17.0)])
def test_rtl_goes_where_rtl_type_says_at_the_rally_points_altitude(vehicle, rtl_type, lands_at, height):
    """A rally point 6 m north, 2 m east at 12 m above home; the vehicle 1 m from home: RTL_TYPE 0
    returns home (closer) at RTL_RETURN_ALT; 1 returns to the rally point at 12 + 5 m."""
    stack, gcs = vehicle
    rally = [(0, m.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, m.MAV_CMD_NAV_RALLY_POINT, 0, 1, 0.0, 0.0, 0.0, 0.0,
              *at(6.0, 2.0), 12.0, RALLY)]  # fmt: skip
    assert upload_plan(gcs, rally, RALLY) == m.MAV_MISSION_ACCEPTED
    param_set(gcs, "RTL_TYPE", rtl_type, INT32)
    take_off(gcs, 2.0)
    x, y = at(1.0, 0.0)
    assert command_int(gcs, m.MAV_FRAME_GLOBAL_INT, (-1, 1, 0, math.nan), x, y, 490.0).result == 0
    wait_at(gcs, frames.vector_from_ned((1.0, 0.0, -2.0)), 0.1, sim_timeout=20.0)
    assert gcs.command(m.MAV_CMD_NAV_RETURN_TO_LAUNCH).result == m.MAV_RESULT_ACCEPTED
    top = {"z": 0.0}

    def landed(g) -> bool:
        if "LOCAL_POSITION_NED" in g.last:
            top["z"] = max(top["z"], g.position()[2])
        return not g.armed

    gcs.wait(landed, sim_timeout=90.0, what="landed and disarmed")
    assert top["z"] == pytest.approx(height, abs=0.1)
    north, east, _ = frames.vector_to_ned(gcs.position())
    assert math.hypot(north - lands_at[0], east - lands_at[1]) < 0.3
    where = "launch" if rtl_type == 0 else "rally point 0"
    assert f"returning to {where} at {height:.1f} m" in texts(gcs)


@pytest.mark.timeout(60)
def test_rtl_type_5_without_rally_points_lands_where_it_is(vehicle):
    stack, gcs = vehicle
    param_set(gcs, "RTL_TYPE", 5, INT32)
    take_off(gcs, 2.0)
    x, y = at(3.0, 0.0)
    assert command_int(gcs, m.MAV_FRAME_GLOBAL_INT, (-1, 1, 0, math.nan), x, y, 490.0).result == 0
    wait_at(gcs, frames.vector_from_ned((3.0, 0.0, -2.0)), 0.1, sim_timeout=20.0)
    assert gcs.command(m.MAV_CMD_NAV_RETURN_TO_LAUNCH).result == m.MAV_RESULT_ACCEPTED
    gcs.wait(lambda g: not g.armed, sim_timeout=30.0, what="landed and disarmed")
    north, _, _ = frames.vector_to_ned(gcs.position())
    assert north == pytest.approx(3.0, abs=0.3)
    assert "no rally point to return to (RTL_TYPE 5): landing here" in texts(gcs)
