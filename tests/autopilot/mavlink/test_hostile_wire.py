"""One regression test per way the wire may be hostile (anything on it may be), against the
whole stack in-process (simulator core + autopilot core, real MAVLink bytes, simulation time).

Findings 9 (process loss under the launcher) and 11 (instance ports) are about processes and
ports: tests/sitl/test_launcher_failsafes.py and tests/sitl/test_up_cli.py.
"""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as m

from autopilot.mavlink.links import MAX_PEERS, PEER_EXPIRY_S
from gcs_scripts.upload_mission import CMD_TIMED, MissionError, MissionLink, make_item
from simulator.core import SimulatorCore
from sitl.inprocess import API_LINK
from tests.stack import Gcs, connect, make_stack

LOCAL = m.MAV_FRAME_LOCAL_NED
POSITION_ONLY = 8 | 16 | 32 | 64 | 128 | 256 | 1024 | 2048
POSITION_VELOCITY = 64 | 128 | 256 | 1024 | 2048
NAN4 = (0.0, 0.0, 0.0, math.nan)


@pytest.fixture
def flight():
    stack = make_stack()
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    yield stack, gcs
    gcs.close()


def next_heartbeat(gcs: Gcs) -> None:
    """Step a frame (what was sent is handled then), drop what was queued, wait for a HEARTBEAT."""
    gcs.stack.step()
    while gcs.conn.station.inbox:
        gcs.poll()
    gcs.last.pop("HEARTBEAT", None)
    gcs.wait_heartbeat()


def faults(stack) -> dict:
    return dict(stack.autopilot.faults.counts)


def take_off(gcs: Gcs, altitude: float = 2.0) -> None:
    assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == m.MAV_RESULT_ACCEPTED
    nan = math.nan
    assert gcs.command(m.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, nan, nan, nan, 488.0 + altitude).result == 0
    gcs.wait(lambda g: "LOCAL_POSITION_NED" in g.last and g.position()[2] > altitude - 0.05,
             sim_timeout=15, what="takeoff")  # fmt: skip


def setpoint(gcs: Gcs, mask: int, position_ned, velocity_ned=(0.0, 0.0, 0.0)) -> None:
    gcs.conn.mav.set_position_target_local_ned_send(
        int(gcs.sim_time * 1000), gcs.system_id, 1, LOCAL, mask, *position_ned, *velocity_ned, 0, 0, 0, 0, 0
    )


def land_here(gcs: Gcs, sim_timeout: float = 40.0) -> tuple[float, float, float]:
    """NAV_LAND, then wait until landed and disarmed; the position it landed at (paper frame)."""
    assert gcs.command(m.MAV_CMD_NAV_LAND).result == m.MAV_RESULT_ACCEPTED
    gcs.wait(lambda g: "EXTENDED_SYS_STATE" in g.last and not g.armed
             and g.last["EXTENDED_SYS_STATE"].landed_state == m.MAV_LANDED_STATE_ON_GROUND,
             sim_timeout=sim_timeout, what="landed and disarmed")  # fmt: skip
    return gcs.position()


# 1 -------------------------------------------------------------------------------------------------
def test_1_a_stray_datagram_and_an_unknown_message_are_counted_and_dropped(flight):
    stack, gcs = flight
    station = gcs.conn.station
    station.send_bytes(b"hello")
    # A well-formed MAVLink 2 frame of a message outside the dialect (id 0x123456).
    station.send_bytes(bytes([0xFD, 3, 0, 0, 7, 255, 190, 0x56, 0x34, 0x12]) + b"abc\x00\x00")
    next_heartbeat(gcs)
    received = stack.autopilot.dispatcher.received
    assert received["bad data"] >= 1 and received["unknown message"] == 1
    assert faults(stack) == {}
    take_off(gcs)  # and the vehicle still flies


# 2 -------------------------------------------------------------------------------------------------
def test_2_messages_with_a_field_named_id_do_not_reach_the_heartbeat_handler(flight):
    stack, gcs = flight
    mav = gcs.conn.mav
    mav.log_request_data_send(gcs.system_id, 1, 0, 0, 90)
    mav.log_data_send(0, 0, 3, [1, 2, 3] + [0] * 87)
    mav.hil_gps_send(0, 3, 473977418, 85455939, 488000, 80, 120, 0, 0, 0, 0, 0, 10)
    next_heartbeat(gcs)
    assert faults(stack) == {}
    assert stack.autopilot.dispatcher.received["unhandled"] >= 2  # LOG_DATA, HIL_GPS on a GCS link
    assert stack.autopilot.log_transfer.ignored == 1  # LOG_REQUEST_DATA: the log download's (no log 0)
    take_off(gcs)


# 3 -------------------------------------------------------------------------------------------------
def test_3_a_timesync_request_is_answered_with_our_clock(flight):
    stack, gcs = flight
    gcs.conn.mav.timesync_send(0, 123456789)
    gcs.wait(lambda g: "TIMESYNC" in g.last, sim_timeout=0.5, what="TIMESYNC answer")
    answer = gcs.last["TIMESYNC"]
    assert answer.ts1 == 123456789
    assert answer.tc1 == pytest.approx(stack.t * 1e9, abs=0.1e9)
    assert faults(stack) == {}


# 4 -------------------------------------------------------------------------------------------------
def test_4_near_coincident_timed_items_are_refused_with_a_reason():
    stack = make_stack()
    link = connect(stack, MissionLink)
    times = [0.0, 1e-30, 2e-30, 1.0, 2.0, 3.0]
    items = [make_item(LOCAL, CMD_TIMED, (t, 0, 0, 0), 1000 * k, 0, -2.0) for k, t in enumerate(times)]
    with pytest.raises(MissionError) as refused:
        link.upload(items)
    assert refused.value.result == m.MAV_MISSION_INVALID_PARAM1
    assert any("1 ms after" in text for _, _, text in link.statustext)
    assert faults(stack) == {}
    good = [make_item(LOCAL, CMD_TIMED, (t, 0, 0, 0), 1000 * k, 0, -2.0) for k, t in enumerate([0, 1, 2])]
    link.upload(good)  # the protocol is not stuck
    link.close()


# 5 -------------------------------------------------------------------------------------------------
@pytest.mark.parametrize("param1", [2.0, math.inf, 1e30, -1.0, 0.5, math.nan])
def test_5_arm_accepts_mav_bool_only(flight, param1):
    stack, gcs = flight
    ack = gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, param1)
    assert ack.result == m.MAV_RESULT_DENIED
    next_heartbeat(gcs)
    assert not gcs.armed and not stack.autopilot.commander.armed
    assert any("refused" in text and "param1" in text for text in gcs.statustext)
    assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1.0).result == m.MAV_RESULT_ACCEPTED


# 6 -------------------------------------------------------------------------------------------------
def test_6_a_nan_message_interval_is_refused_and_the_heartbeat_goes_on(flight):
    stack, gcs = flight
    ack = gcs.command(m.MAV_CMD_SET_MESSAGE_INTERVAL, m.MAVLINK_MSG_ID_HEARTBEAT, math.nan)
    assert ack.result == m.MAV_RESULT_DENIED
    beats = []
    end = stack.t + 3.0
    while stack.t < end:
        msg = gcs.poll()
        if msg is not None and msg.get_type() == "HEARTBEAT":
            beats.append(stack.t)
    assert len(beats) >= 2  # 1 Hz


# 7 -------------------------------------------------------------------------------------------------
def test_7_peers_are_bounded_only_valid_senders_count_and_silent_ones_expire(flight):
    stack, gcs = flight
    ap = stack.autopilot
    link = ap.links[API_LINK]
    heartbeat = m.MAVLink_heartbeat_message(m.MAV_TYPE_GCS, m.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3)
    frame = heartbeat.pack(m.MAVLink(None, srcSystem=200, srcComponent=190))
    for port in range(20000, 22000):  # 2,000 senders of one valid frame each
        stack.deliver(API_LINK, ("127.0.0.1", port), frame)
    for port in range(30000, 32000):  # 2,000 senders of garbage
        stack.deliver(API_LINK, ("127.0.0.1", port), b"\xfd\x09garbage")
    stack.step()
    assert len(link.peers) <= MAX_PEERS
    assert gcs.conn.station.address in link.peers  # a registered listener is never evicted
    assert not any(port >= 30000 for _, port in link.peers if isinstance(port, int))
    assert ap.info()["dropped"]["API peers evicted"] >= 2000 - MAX_PEERS
    next_heartbeat(gcs)  # the real station still hears the vehicle
    stack.run_for(PEER_EXPIRY_S + 1.0)
    assert list(link.peers) == [gcs.conn.station.address]
    assert faults(stack) == {}


# 8 -------------------------------------------------------------------------------------------------
def test_8_far_setpoints_are_refused_fast_ones_limited_and_the_vehicle_still_lands(flight):
    stack, gcs = flight
    take_off(gcs)
    params = stack.autopilot.params
    start = gcs.position()
    for _ in range(10):
        setpoint(gcs, POSITION_VELOCITY, (1e9, 1e9, -2.0), (1e9, 1e9, 0.0))
        gcs.poll()
    assert any("NAV_REF_MAX_DIST" in text for text in gcs.statustext)
    # Within the distance rule but with an absurd velocity: followed at MPC_XY_VEL_MAX at most.
    target_ned = (start[0] + 500.0, -start[1], -2.0)
    top_speed = 0.0
    for k in range(300):  # 6 s at 50 Hz
        setpoint(gcs, POSITION_VELOCITY, target_ned, (1e9, 0.0, 0.0))
        for _ in range(10):
            gcs.poll()
        if k == 10:
            assert gcs.command(m.MAV_CMD_DO_SET_MODE, 1, 6, 0).result == m.MAV_RESULT_ACCEPTED
        if "LOCAL_POSITION_NED" in gcs.last:
            lp = gcs.last["LOCAL_POSITION_NED"]
            top_speed = max(top_speed, math.hypot(lp.vx, lp.vy))
    assert 0.5 < top_speed <= 1.1 * params["MPC_XY_VEL_MAX"]
    before_land = gcs.position()
    landed = land_here(gcs)
    braking = params["MPC_XY_VEL_MAX"] ** 2 / (2 * params["MPC_ACC_HOR"])
    assert math.dist(landed[:2], before_land[:2]) < braking + 1.0
    assert faults(stack) == {}


# 10 ------------------------------------------------------------------------------------------------
def test_10_after_a_simulator_restart_telemetry_resumes_at_once(flight):
    stack, gcs = flight
    stack.run_for(20.0)
    stack.sim = SimulatorCore(stack.sim.setup)  # a new simulator: its time starts at 0 again
    restarted = stack.t
    gcs.last.clear()
    gcs.wait(lambda g: {"HEARTBEAT", "LOCAL_POSITION_NED", "ATTITUDE"} <= g.last.keys(),
             sim_timeout=1.5, what="telemetry after the restart")  # fmt: skip
    assert stack.t - restarted < 1.5
    assert faults(stack) == {}


# Resource bounds ---------------------------------------------------------------------------------------
def test_missions_beyond_mis_items_max_get_no_space_and_far_items_invalid_param5():
    stack = make_stack()
    stack.autopilot.params.values["MIS_ITEMS_MAX"] = 5.0
    link = connect(stack, MissionLink)
    wp = [make_item(LOCAL, m.MAV_CMD_NAV_WAYPOINT, NAN4, 10_000 * k, 0, -2.0) for k in range(6)]
    with pytest.raises(MissionError) as refused:
        link.upload(wp)
    assert refused.value.result == m.MAV_MISSION_NO_SPACE
    link.upload(wp[:5])
    far = make_item(LOCAL, m.MAV_CMD_NAV_WAYPOINT, NAN4, 2000 * 10_000, 0, -2.0)  # 2 km
    with pytest.raises(MissionError) as refused:
        link.upload([wp[0], far])
    assert refused.value.result == m.MAV_MISSION_INVALID_PARAM5_X
    assert any("NAV_REF_MAX_DIST" in text for _, _, text in link.statustext)
    assert faults(stack) == {}
    link.close()
