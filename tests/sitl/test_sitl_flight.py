"""Flying on the wire, in simulation time: linking, commands and ACKs, offboard flight, offboard
loss. The whole stack in-process (simulator core + autopilot core, real MAVLink bytes); the test
acts as a pymavlink ground station. Over real UDP: test_sitl_smoke.py.
"""

import math

import pytest
from pymavlink.dialects.v20 import common as m

from autopilot.commander.modes import FlightMode

from ..stack import Gcs, make_stack

OFFBOARD = FlightMode.OFFBOARD.custom_mode
LOITER = FlightMode.AUTO_LOITER.custom_mode


@pytest.fixture
def sitl():
    stack = make_stack()
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    yield stack, gcs
    gcs.close()


def take_off(gcs, altitude=2.0):
    assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == m.MAV_RESULT_ACCEPTED
    assert (
        gcs.command(m.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, 488.0 + altitude).result
        == 0
    )
    gcs.wait(lambda g: "LOCAL_POSITION_NED" in g.last and g.position()[2] > altitude - 0.03
             and g.custom_mode == LOITER, sim_timeout=15, what="takeoff")  # fmt: skip


def start_offboard(gcs, target):
    for _ in range(10):
        gcs.send_position_setpoint(*target)
        gcs.poll()
    ack = gcs.command(m.MAV_CMD_DO_SET_MODE, 1, 6, 0)
    assert ack.result == m.MAV_RESULT_ACCEPTED


def fly_to(gcs, target, settle_s=3.0, sim_timeout=20.0):
    """Stream the setpoint (one per LOCAL_POSITION_NED: paced in sim time); return the error."""
    start = gcs.sim_time
    arrived_at = None
    while gcs.sim_time - start < sim_timeout:
        msg = gcs.poll()
        if msg is None or msg.get_type() != "LOCAL_POSITION_NED":
            continue
        gcs.send_position_setpoint(*target)
        error = math.dist(gcs.position(), target)
        if arrived_at is None and error < 0.05:
            arrived_at = gcs.sim_time
        if arrived_at is not None and gcs.sim_time - arrived_at > settle_s:
            return error
    raise AssertionError(f"did not reach {target} (position {gcs.position()})")


def test_link_and_vehicle_at_rest_on_the_ground(sitl):
    _, gcs = sitl
    gcs.wait(lambda g: "EXTENDED_SYS_STATE" in g.last and "LOCAL_POSITION_NED" in g.last, what="telemetry")
    hb = gcs.last["HEARTBEAT"]
    assert hb.autopilot == m.MAV_AUTOPILOT_PX4 and hb.type == m.MAV_TYPE_QUADROTOR
    assert gcs.last["EXTENDED_SYS_STATE"].landed_state == m.MAV_LANDED_STATE_ON_GROUND
    assert abs(gcs.position()[2]) < 1e-6
    t0 = gcs.sim_time
    gcs.wait(lambda g: g.sim_time > t0 + 2.0, what="2 s of simulation")
    assert abs(gcs.position()[2]) < 1e-6  # resting, not falling through the ground


def test_every_command_gets_an_ack(sitl):
    _, gcs = sitl
    nan = math.nan
    expected = {
        m.MAV_CMD_SET_MESSAGE_INTERVAL: ((m.MAVLINK_MSG_ID_ATTITUDE, 50_000), m.MAV_RESULT_ACCEPTED),
        m.MAV_CMD_REQUEST_MESSAGE: ((m.MAVLINK_MSG_ID_AUTOPILOT_VERSION,), m.MAV_RESULT_ACCEPTED),
        m.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: ((1,), m.MAV_RESULT_ACCEPTED),
        m.MAV_CMD_GET_HOME_POSITION: ((), m.MAV_RESULT_ACCEPTED),
        m.MAV_CMD_NAV_TAKEOFF: ((0, 0, 0, nan, nan, nan, nan), m.MAV_RESULT_DENIED),  # not armed
        m.MAV_CMD_DO_SET_MODE: ((1, 6, 0), m.MAV_RESULT_DENIED),  # OFFBOARD without a stream
        m.MAV_CMD_COMPONENT_ARM_DISARM: ((1,), m.MAV_RESULT_ACCEPTED),
        m.MAV_CMD_NAV_LAND: ((), m.MAV_RESULT_ACCEPTED),
        m.MAV_CMD_NAV_RETURN_TO_LAUNCH: ((), m.MAV_RESULT_ACCEPTED),
        m.MAV_CMD_DO_FLIGHTTERMINATION: ((1,), m.MAV_RESULT_UNSUPPORTED),
        31000: ((), m.MAV_RESULT_UNSUPPORTED),  # MAV_CMD_USER_1
    }
    for command, (params, result) in expected.items():
        ack = gcs.command(command, *params)
        assert ack.result == result, (command, ack.result, gcs.statustext[-3:])
        assert ack.target_system == 255 and ack.target_component == 190
    assert "AUTOPILOT_VERSION" in gcs.last and "HOME_POSITION" in gcs.last
    caps = gcs.last["AUTOPILOT_VERSION"].capabilities
    assert caps & m.MAV_PROTOCOL_CAPABILITY_MISSION_INT
    # COMMAND_INT takes the same path
    gcs.acks.clear()
    gcs.conn.mav.command_int_send(gcs.system_id, 1, 0, 31000, 0, 0, 0, 0, 0, 0, 0, 0, 0)
    gcs.wait(lambda g: any(a.command == 31000 for a in g.acks), sim_timeout=0.5, what="ack")
    assert gcs.acks[-1].result == m.MAV_RESULT_UNSUPPORTED


def test_offboard_square_and_land(sitl):
    _, gcs = sitl
    take_off(gcs, 2.0)
    start_offboard(gcs, (0.0, 0.0, 2.0))
    # (no waiting for the 1 Hz HEARTBEAT to show OFFBOARD here: without setpoints meanwhile the
    # vehicle would rightly fall back to hold after COM_OF_LOSS_T)
    for corner in [(2.0, 0.0, 2.0), (2.0, 2.0, 2.0), (0.0, 2.0, 2.0), (0.0, 0.0, 2.0)]:
        error = fly_to(gcs, corner)
        assert error < 0.05, f"corner {corner}: error {error:.3f} m"
        assert gcs.custom_mode == OFFBOARD
    assert gcs.command(m.MAV_CMD_NAV_LAND).result == m.MAV_RESULT_ACCEPTED
    gcs.wait(lambda g: not g.armed, sim_timeout=20, what="landed and disarmed")
    assert abs(gcs.position()[2]) < 0.01
    assert any("landing detected" in text for text in gcs.statustext)


def test_offboard_loss_switches_to_hold(sitl):
    _, gcs = sitl
    take_off(gcs, 2.0)
    start_offboard(gcs, (1.0, 0.0, 2.0))
    fly_to(gcs, (1.0, 0.0, 2.0), settle_s=1.0)
    stopped_at = gcs.sim_time
    held = gcs.position()
    gcs.wait(lambda g: g.custom_mode == LOITER, sim_timeout=3, what="hold after offboard loss")
    assert 0.9 < gcs.sim_time - stopped_at < 1.5  # COM_OF_LOSS_T = 1 s of simulation time
    assert any("offboard setpoints lost" in text for text in gcs.statustext)
    t0 = gcs.sim_time
    gcs.wait(lambda g: g.sim_time > t0 + 3.0, what="3 s of hold")
    assert math.dist(gcs.position(), held) < 0.05
