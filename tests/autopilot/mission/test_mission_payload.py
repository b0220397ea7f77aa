"""Payload items (camera, gimbal, ROI: stored, downloaded back, flown as no-ops) and DO_JUMP (pure)."""

import math

import pytest

from autopilot.commander.commander import Commander
from autopilot.mavlink.codec import mavlink
from autopilot.mission.executor import MissionExecutor, MissionState, check_mission
from autopilot.mission.items import ItemKind, WireItem, parse_item
from autopilot.mission.protocol import MissionProtocol
from autopilot.params.definitions import default_parameters
from tests.autopilot.mission.test_mission_commander import fly, reached_log, state, wire
from tests.autopilot.mission.test_protocol import GCS, SYS, acks, item, upload
from tests.autopilot.mission.test_protocol import wire as arrive

m = mavlink
HOME = (47.397742, 8.545594, 488.0)
NAN = math.nan
MISSION = m.MAV_FRAME_MISSION


def mavsdk_like_mission():
    """What MAVSDK 4's mission example uploads: waypoints with gimbal and camera items between."""
    lat, lon = 473977420, 85455940
    rel = m.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT
    return [
        item(0, m.MAV_CMD_NAV_WAYPOINT, rel, (0.0, 1.0, 0.0, NAN), lat, lon, 10.0, current=1),
        item(1, m.MAV_CMD_DO_CHANGE_SPEED, MISSION, (1.0, 2.0, -1.0, 0.0), 0, 0, NAN),
        item(2, m.MAV_CMD_DO_GIMBAL_MANAGER_CONFIGURE, MISSION, (-2.0, -2.0, -1.0, -1.0), 0, 0, 0.0),
        item(3, m.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW, MISSION, (-45.0, 0.0, NAN, NAN), 0, 0, 0.0),
        item(4, m.MAV_CMD_IMAGE_START_CAPTURE, MISSION, (0.0, 0.0, 1.0, 0.0), 0, 0, NAN),
        item(5, m.MAV_CMD_NAV_WAYPOINT, rel, (0.0, 1.0, 0.0, NAN), lat + 1000, lon, 10.0),
        item(6, m.MAV_CMD_VIDEO_START_CAPTURE, MISSION, (0.0, NAN, 0.0, 0.0), 0, 0, NAN),
        item(7, m.MAV_CMD_VIDEO_STOP_CAPTURE, MISSION, (0.0, 0.0, 0.0, 0.0), 0, 0, NAN),
        item(8, m.MAV_CMD_DO_SET_CAM_TRIGG_DIST, MISSION, (5.0, 0.0, 1.0, 0.0), 0, 0, 0.0),
        item(9, m.MAV_CMD_DO_SET_CAM_TRIGG_INTERVAL, MISSION, (2.0, 0.0, 0.0, 0.0), 0, 0, 0.0),
        item(10, m.MAV_CMD_DO_MOUNT_CONTROL, MISSION, (0.0, 0.0, 0.0, 0.0), 0, 0, 2.0),
        item(
            11, m.MAV_CMD_DO_SET_ROI_LOCATION, m.MAV_FRAME_GLOBAL_INT, (0.0, 0.0, 0.0, 0.0), lat, lon, 500.0
        ),
        item(12, m.MAV_CMD_DO_SET_ROI_NONE, MISSION, (0.0, 0.0, 0.0, 0.0), 0, 0, 0.0),
        item(13, m.MAV_CMD_IMAGE_STOP_CAPTURE, MISSION, (0.0, 0.0, 0.0, 0.0), 0, 0, NAN),
    ]


FIELDS = ("seq", "frame", "command", "autocontinue", "x", "y")
PARAMS = ("param1", "param2", "param3", "param4", "z")


def same(a, b) -> bool:
    floats = [getattr(a, f) for f in PARAMS], [getattr(b, f) for f in PARAMS]
    return [getattr(a, f) for f in FIELDS] == [getattr(b, f) for f in FIELDS] and all(
        (math.isnan(x) and math.isnan(y)) or x == y for x, y in zip(*floats, strict=True)
    )


def test_payload_items_are_accepted_and_downloaded_back_identical():
    proto = MissionProtocol(SYS, 1, HOME)
    sent = mavsdk_like_mission()
    outs = upload(proto, sent)
    assert acks(outs[-1]) == [m.MAV_MISSION_ACCEPTED]
    assert [it.kind for it in proto.mission.items].count(ItemKind.PAYLOAD) == 11
    out = proto.handle(arrive(m.MAVLink_mission_request_list_message(SYS, 1)), 1.0)
    assert out.replies[0].count == len(sent)
    for seq, a in enumerate(sent):
        b = proto.handle(arrive(m.MAVLink_mission_request_int_message(SYS, 1, seq)), 1.0).replies[0]
        assert b.target_system == GCS[0] and same(a, b), (a, b)


@pytest.mark.parametrize(
    "bad, result",
    [
        (
            item(1, m.MAV_CMD_SET_CAMERA_ZOOM, MISSION, (0.0, 1.0, 0.0, 0.0), 0, 0, 0.0),
            m.MAV_MISSION_UNSUPPORTED,
        ),
        (item(1, m.MAV_CMD_DO_SET_HOME, MISSION, (1.0, 0.0, 0.0, 0.0), 0, 0, 0.0), m.MAV_MISSION_UNSUPPORTED),
        (
            item(1, m.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW, MISSION, (math.inf, 0.0, 0.0, 0.0), 0, 0, 0.0),
            m.MAV_MISSION_INVALID_PARAM1,
        ),
        (
            item(1, m.MAV_CMD_IMAGE_START_CAPTURE, MISSION, (0.0, 0.0, -math.inf, 0.0), 0, 0, 0.0),
            m.MAV_MISSION_INVALID_PARAM3,
        ),
        (
            item(1, m.MAV_CMD_DO_SET_ROI, MISSION, (4.0, 0.0, 0.0, 0.0), 0, 0, 0.0),
            m.MAV_MISSION_INVALID_PARAM1,
        ),
        (
            item(1, m.MAV_CMD_DO_SET_ROI_LOCATION, MISSION, (0.0, 0.0, 0.0, 0.0), 0, 0, 0.0),
            m.MAV_MISSION_UNSUPPORTED_FRAME,
        ),
        (
            item(
                1,
                m.MAV_CMD_DO_SET_ROI_LOCATION,
                m.MAV_FRAME_GLOBAL_INT,
                (0.0, 0.0, 0.0, 0.0),
                950000000,
                0,
                1.0,
            ),
            m.MAV_MISSION_INVALID_PARAM5_X,
        ),
        (
            item(1, m.MAV_CMD_IMAGE_START_CAPTURE, m.MAV_FRAME_BODY_FRD, (0.0, 0.0, 1.0, 0.0), 0, 0, 0.0),
            m.MAV_MISSION_UNSUPPORTED_FRAME,
        ),
        (item(1, m.MAV_CMD_DO_JUMP, MISSION, (1.0, 2.0, 0.0, 0.0), 0, 0, 0.0), m.MAV_MISSION_INVALID_PARAM1),
        (item(1, m.MAV_CMD_DO_JUMP, MISSION, (0.0, -1.0, 0.0, 0.0), 0, 0, 0.0), m.MAV_MISSION_INVALID_PARAM2),
        (item(1, m.MAV_CMD_DO_JUMP, MISSION, (0.5, 1.0, 0.0, 0.0), 0, 0, 0.0), m.MAV_MISSION_INVALID_PARAM1),
        (item(1, m.MAV_CMD_DO_JUMP, MISSION, (NAN, 1.0, 0.0, 0.0), 0, 0, 0.0), m.MAV_MISSION_INVALID_PARAM1),
        (
            item(1, m.MAV_CMD_DO_JUMP, MISSION, (0.0, math.inf, 0.0, 0.0), 0, 0, 0.0),
            m.MAV_MISSION_INVALID_PARAM2,
        ),
    ],
)
def test_items_px4_refuses_or_invalid_payload_items_are_refused(bad, result):
    proto = MissionProtocol(SYS, 1, HOME)
    outs = upload(proto, [item(0), bad, item(2)])
    assert acks(outs[2]) == [result]
    assert proto.mission.count == 0


def _check(items):
    return check_mission(items, HOME, Commander(default_parameters()).limits())


def test_jump_target_outside_the_mission_or_a_loop_that_never_moves_is_refused():
    proto = MissionProtocol(SYS, 1, HOME, check=_check)
    outs = upload(proto, [item(0), item(1, m.MAV_CMD_DO_JUMP, MISSION, (5.0, 1.0, 0.0, 0.0), 0, 0, 0.0)])
    assert acks(outs[-1]) == [m.MAV_MISSION_INVALID_PARAM1] and "not in the mission" in outs[-1].notices[0][1]
    loop = [
        item(0),
        item(1, m.MAV_CMD_IMAGE_START_CAPTURE, MISSION, (0.0, 0.0, 1.0, 0.0), 0, 0, 0.0),
        item(2, m.MAV_CMD_DO_JUMP, MISSION, (1.0, 3.0, 0.0, 0.0), 0, 0, 0.0),
    ]
    outs = upload(proto, loop)
    assert acks(outs[-1]) == [m.MAV_MISSION_INVALID_PARAM1] and "no item that moves" in outs[-1].notices[0][1]


def executor(*wires):
    items = []
    for w in wires:
        items.append(parse_item(w, HOME, items[-1] if items else None))
    assert _check(items) is None
    return MissionExecutor(items, HOME)


def payload_wire(seq, command):
    """param3 = 1 (one picture, pitch rate) where the command has a param3; NaN where it is reserved."""
    p3 = 1.0 if command != m.MAV_CMD_IMAGE_STOP_CAPTURE else NAN
    return WireItem(seq, MISSION, command, 0, 1, 0.0, 0.0, p3, NAN, 0, 0, 0.0)


@pytest.fixture
def commander():
    c = Commander(default_parameters())
    c.update_state(state(0.0))
    return c


def test_payload_items_fly_as_no_ops_with_one_statustext_per_run(commander):
    mission = executor(
        wire(0, m.MAV_CMD_NAV_TAKEOFF, xyz=(0.0, 0.0, 2.0)),
        payload_wire(1, m.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW),
        payload_wire(2, m.MAV_CMD_IMAGE_START_CAPTURE),
        wire(3, m.MAV_CMD_NAV_WAYPOINT, xyz=(2.0, 0.0, 2.0)),
        payload_wire(4, m.MAV_CMD_IMAGE_STOP_CAPTURE),
        wire(5, m.MAV_CMD_NAV_LAND, xyz=(2.0, 0.0, 0.0)),
    )
    commander.set_mission(0.0, mission)
    commander.set_mode(0.0, commander.mode.AUTO_MISSION)
    assert commander.arm(0.0).accepted
    log: list[int] = []
    fly(commander, 0.0, 60.0, until=lambda c: reached_log(c, log) or not c.armed)
    log.extend(mission.drain_reached())
    assert log == [0, 1, 2, 3, 4, 5] and mission.state == MissionState.COMPLETE
    assert commander.state.position_m == pytest.approx((2.0, 0.0, 0.0), abs=1e-3)
    texts = [text for _, text in commander.drain_events() if "gimbal/camera" in text]
    assert texts == ["mission: no gimbal/camera on this vehicle, payload items skipped"]


def test_do_jump_repeats_its_loop_then_goes_on(commander):
    mission = executor(
        wire(0, m.MAV_CMD_NAV_TAKEOFF, xyz=(0.0, 0.0, 2.0)),
        wire(1, m.MAV_CMD_NAV_WAYPOINT, xyz=(1.0, 0.0, 2.0)),
        wire(2, m.MAV_CMD_NAV_WAYPOINT, xyz=(1.0, 1.0, 2.0)),
        WireItem(3, MISSION, m.MAV_CMD_DO_JUMP, 0, 1, 1.0, 2.0, 0.0, 0.0, 0, 0, 0.0),
        wire(4, m.MAV_CMD_NAV_LAND, xyz=(0.0, 0.0, 0.0)),
    )
    commander.set_mission(0.0, mission)
    commander.set_mode(0.0, commander.mode.AUTO_MISSION)
    assert commander.arm(0.0).accepted
    log: list[int] = []
    fly(commander, 0.0, 120.0, until=lambda c: reached_log(c, log) or not c.armed)
    log.extend(mission.drain_reached())
    assert log == [0, 1, 2, 3, 1, 2, 3, 1, 2, 3, 4]
    assert not commander.armed and mission.state == MissionState.COMPLETE
    # Flown again from the start, the jump counts start again.
    assert mission.set_current(0)
    assert mission._jumps == {3: 2}  # noqa: SLF001  (kept until the mission restarts)


def test_do_jump_with_zero_repeats_is_passed(commander):
    mission = executor(
        wire(0, m.MAV_CMD_NAV_TAKEOFF, xyz=(0.0, 0.0, 2.0)),
        WireItem(1, MISSION, m.MAV_CMD_DO_JUMP, 0, 1, 0.0, 0.0, 0.0, 0.0, 0, 0, 0.0),
        wire(2, m.MAV_CMD_NAV_LAND, xyz=(0.0, 0.0, 0.0)),
    )
    commander.set_mission(0.0, mission)
    commander.set_mode(0.0, commander.mode.AUTO_MISSION)
    commander.arm(0.0)
    log: list[int] = []
    fly(commander, 0.0, 60.0, until=lambda c: reached_log(c, log) or not c.armed)
    log.extend(mission.drain_reached())
    assert log == [0, 1, 2]
