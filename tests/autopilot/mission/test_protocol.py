"""The mission transfer state machine (pure): upload, download, clear, set current, timeouts."""

import math

import pytest

from autopilot.mavlink.codec import Encoder, mavlink, new_parser
from autopilot.mission.items import CMD_TIMED
from autopilot.mission.protocol import MissionProtocol, TransferState

m = mavlink
HOME = (47.397742, 8.545594, 488.0)
SYS, COMP = 1, 1
GCS = (255, 190)
OTHER_GCS = (246, 191)


def wire(msg, source=GCS):
    """``msg`` as it arrives: packed by a ground station and parsed (src ids set)."""
    return new_parser().parse_buffer(Encoder(*source).pack(msg))[0]


def item(seq, command=m.MAV_CMD_NAV_WAYPOINT, frame=m.MAV_FRAME_LOCAL_NED, p=(0.0, 0.0, 0.0, math.nan),
         x=10_000 * 1, y=0, z=-2.5, current=0, autocontinue=1, mission_type=0):  # fmt: skip
    return m.MAVLink_mission_item_int_message(
        SYS, COMP, seq, frame, command, current, autocontinue, *p, x, y, z, mission_type
    )


def waypoints(n):
    return [item(k, x=10_000 * k, y=5_000 * k, z=-2.0 - k, current=int(k == 0)) for k in range(n)]


def kinds(out):
    return [msg.get_type() for msg in out.replies]


def acks(out):
    return [msg.type for msg in out.replies if msg.get_type() == "MISSION_ACK"]


def upload(proto, items, now=0.0, source=GCS):
    out = proto.handle(wire(m.MAVLink_mission_count_message(SYS, COMP, len(items)), source), now)
    outs = [out]
    for it in items:
        outs.append(proto.handle(wire(it, source), now))
    return outs


@pytest.fixture
def proto():
    return MissionProtocol(SYS, COMP, HOME)


def test_upload_requests_each_item_and_acks(proto):
    outs = upload(proto, waypoints(3))
    assert kinds(outs[0]) == ["MISSION_REQUEST_INT"] and outs[0].replies[0].seq == 0
    assert outs[0].replies[0].target_system == GCS[0] and outs[0].replies[0].target_component == GCS[1]
    assert [o.replies[0].seq for o in outs[1:3]] == [1, 2]
    assert acks(outs[3]) == [m.MAV_MISSION_ACCEPTED]
    assert outs[3].mission is not None and outs[3].mission.count == 3
    assert proto.mission.count == 3 and proto.state == TransferState.IDLE


def test_download_returns_the_upload_exactly(proto):
    sent = waypoints(4)
    sent[2] = item(2, m.MAV_CMD_NAV_LOITER_TIME, m.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT,
                   (12.5, 0.0, 0.0, 0.0), 473977420, 85455940, 7.25)  # fmt: skip
    upload(proto, sent)
    out = proto.handle(wire(m.MAVLink_mission_request_list_message(SYS, COMP)), 1.0)
    assert kinds(out) == ["MISSION_COUNT"] and out.replies[0].count == 4
    got = []
    for seq in range(4):
        out = proto.handle(wire(m.MAVLink_mission_request_int_message(SYS, COMP, seq)), 1.0)
        got.append(out.replies[0])
    fields = (
        "seq",
        "frame",
        "command",
        "current",
        "autocontinue",
        "param1",
        "param2",
        "param3",
        "x",
        "y",
        "z",
    )
    for a, b in zip(sent, got, strict=True):
        assert [getattr(a, f) for f in fields] == [getattr(b, f) for f in fields]
        assert math.isnan(a.param4) == math.isnan(b.param4)
    proto.handle(wire(m.MAVLink_mission_ack_message(SYS, COMP, 0)), 1.0)
    assert proto.state == TransferState.IDLE


@pytest.mark.parametrize(
    "bad, result",
    [
        (item(1, command=m.MAV_CMD_DO_SET_HOME, frame=m.MAV_FRAME_MISSION), m.MAV_MISSION_UNSUPPORTED),
        (item(1, frame=m.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT), m.MAV_MISSION_UNSUPPORTED_FRAME),
        (item(1, frame=m.MAV_FRAME_BODY_FRD), m.MAV_MISSION_UNSUPPORTED_FRAME),
        (item(1, p=(-1.0, 0.0, 0.0, 0.0)), m.MAV_MISSION_INVALID_PARAM1),
        (item(1, p=(0.0, -3.0, 0.0, 0.0)), m.MAV_MISSION_INVALID_PARAM2),
        (item(1, p=(0.0, 0.0, 0.0, 400.0)), m.MAV_MISSION_INVALID_PARAM4),
        (item(1, frame=m.MAV_FRAME_GLOBAL_INT, x=0, y=0, z=10.0), m.MAV_MISSION_INVALID_PARAM5_X),
        (item(1, frame=m.MAV_FRAME_GLOBAL_INT, x=473977420, y=1900000000), m.MAV_MISSION_INVALID_PARAM6_Y),
        (item(1, z=math.nan), m.MAV_MISSION_INVALID_PARAM7),
        (
            item(1, command=m.MAV_CMD_DO_CHANGE_SPEED, frame=2, p=(1.0, 0.0, -1.0, 0.0), x=0, z=0.0),
            m.MAV_MISSION_INVALID_PARAM2,
        ),
    ],
)
def test_a_bad_item_rejects_the_upload_and_keeps_the_old_mission(proto, bad, result):
    upload(proto, waypoints(2))
    old = proto.mission
    outs = upload(proto, [item(0), bad, item(2)])
    assert acks(outs[2]) == [result]
    assert outs[2].notices and "previous mission kept" in outs[2].notices[0][1]
    assert proto.mission is old and proto.state == TransferState.IDLE
    assert acks(outs[3]) == [m.MAV_MISSION_ERROR]  # a stray item after the rejection


def test_retries_every_250_ms_then_5_s_of_silence_cancels_and_keeps_the_old_mission(proto):
    """PX4's rule (mavlink_mission: retry timeout 250 ms, protocol timeout 5 s)."""
    upload(proto, waypoints(2))
    old = proto.mission
    proto.handle(wire(m.MAVLink_mission_count_message(SYS, COMP, 5)), 10.0)
    for k in range(3):
        proto.handle(wire(waypoints(5)[k]), 10.0 + 0.01 * k)
    t, requests, cancelled = 10.02, [], None
    while t < 20.0 and cancelled is None:
        t += 0.05
        out = proto.poll(t)
        for msg in out.replies:
            if msg.get_type() == "MISSION_REQUEST_INT":
                requests.append((round(t, 2), msg.seq))
            else:
                cancelled = (round(t, 2), msg.type)
    assert {seq for _, seq in requests} == {3} and 18 <= len(requests) <= 20
    assert requests[0][0] == pytest.approx(10.27, abs=0.06)
    assert cancelled == (pytest.approx(15.02, abs=0.06), m.MAV_MISSION_OPERATION_CANCELLED)
    assert proto.mission is old and proto.state == TransferState.IDLE


def test_out_of_sequence_items_are_dropped_and_rerequested(proto):
    items = waypoints(3)
    proto.handle(wire(m.MAVLink_mission_count_message(SYS, COMP, 3)), 0.0)
    proto.handle(wire(items[0]), 0.0)
    out = proto.handle(wire(items[2]), 0.0)  # a gap: ask for 1 again
    assert kinds(out) == ["MISSION_REQUEST_INT"] and out.replies[0].seq == 1
    assert proto.handle(wire(items[0]), 0.0).replies == []  # a repeat: ignored
    proto.handle(wire(items[1]), 0.0)
    assert acks(proto.handle(wire(items[2]), 0.0)) == [m.MAV_MISSION_ACCEPTED]


def test_a_second_client_cannot_interfere_with_an_upload(proto):
    proto.handle(wire(m.MAVLink_mission_count_message(SYS, COMP, 2)), 0.0)
    out = proto.handle(wire(m.MAVLink_mission_count_message(SYS, COMP, 4), OTHER_GCS), 0.0)
    assert acks(out) == [m.MAV_MISSION_ERROR] and out.replies[0].target_system == OTHER_GCS[0]
    out = proto.handle(wire(m.MAVLink_mission_clear_all_message(SYS, COMP), OTHER_GCS), 0.0)
    assert acks(out) == [m.MAV_MISSION_DENIED]
    for it in waypoints(2):
        out = proto.handle(wire(it), 0.0)
    assert acks(out) == [m.MAV_MISSION_ACCEPTED]


def test_the_uploader_may_restart_with_a_new_count(proto):
    proto.handle(wire(m.MAVLink_mission_count_message(SYS, COMP, 5)), 0.0)
    proto.handle(wire(waypoints(5)[0]), 0.0)
    out = proto.handle(wire(m.MAVLink_mission_count_message(SYS, COMP, 2)), 0.0)
    assert out.replies[0].seq == 0
    outs = [proto.handle(wire(it), 0.0) for it in waypoints(2)]
    assert acks(outs[-1]) == [m.MAV_MISSION_ACCEPTED] and proto.mission.count == 2


def test_lost_final_ack_is_repeated(proto):
    items = waypoints(2)
    upload(proto, items)
    out = proto.handle(wire(items[1]), 0.1)
    assert acks(out) == [m.MAV_MISSION_ACCEPTED]


def test_float_messages_are_not_offered(proto):
    upload(proto, waypoints(2))
    out = proto.handle(wire(m.MAVLink_mission_request_message(SYS, COMP, 0)), 0.0)
    assert acks(out) == [m.MAV_MISSION_UNSUPPORTED]
    proto.handle(wire(m.MAVLink_mission_count_message(SYS, COMP, 1)), 0.0)
    flt = m.MAVLink_mission_item_message(SYS, COMP, 0, 1, 16, 0, 1, 0, 0, 0, 0, 1.0, 0.0, -2.0)
    out = proto.handle(wire(flt), 0.0)
    assert acks(out) == [m.MAV_MISSION_UNSUPPORTED]
    assert proto.state == TransferState.IDLE and proto.mission.count == 2


def test_clear_all_and_empty_upload_clear(proto):
    upload(proto, waypoints(2))
    out = proto.handle(wire(m.MAVLink_mission_clear_all_message(SYS, COMP)), 0.0)
    assert acks(out) == [m.MAV_MISSION_ACCEPTED] and out.mission.count == 0
    upload(proto, waypoints(2))
    out = proto.handle(wire(m.MAVLink_mission_count_message(SYS, COMP, 0)), 0.0)
    assert acks(out) == [m.MAV_MISSION_ACCEPTED] and proto.mission.count == 0


def test_fence_and_rally_plans_start_empty(proto):
    out = proto.handle(wire(m.MAVLink_mission_request_list_message(SYS, COMP, m.MAV_MISSION_TYPE_FENCE)), 0.0)
    assert kinds(out) == ["MISSION_COUNT"] and out.replies[0].count == 0
    assert out.replies[0].mission_type == m.MAV_MISSION_TYPE_FENCE
    out = proto.handle(wire(m.MAVLink_mission_count_message(SYS, COMP, 0, m.MAV_MISSION_TYPE_RALLY)), 0.0)
    assert acks(out) == [m.MAV_MISSION_ACCEPTED] and out.replies[0].mission_type == m.MAV_MISSION_TYPE_RALLY
    # (uploads, downloads and clears of both: test_plans.py)


def test_set_current_in_and_out_of_range(proto):
    upload(proto, waypoints(3))
    assert proto.handle(wire(m.MAVLink_mission_set_current_message(SYS, COMP, 2)), 0.0).set_current == 2
    out = proto.handle(wire(m.MAVLink_mission_set_current_message(SYS, COMP, 7)), 0.0)
    assert out.set_current is None and "not in the mission" in out.notices[0][1]


def test_download_out_of_range_request_ends_with_invalid_sequence(proto):
    upload(proto, waypoints(2))
    proto.handle(wire(m.MAVLink_mission_request_list_message(SYS, COMP)), 0.0)
    out = proto.handle(wire(m.MAVLink_mission_request_int_message(SYS, COMP, 5)), 0.0)
    assert acks(out) == [m.MAV_MISSION_INVALID_SEQUENCE] and proto.state == TransferState.IDLE


def test_download_forgotten_after_silence(proto):
    upload(proto, waypoints(2))
    proto.handle(wire(m.MAVLink_mission_request_list_message(SYS, COMP)), 0.0)
    assert proto.state == TransferState.SENDING
    proto.poll(4.9)
    assert proto.state == TransferState.SENDING
    proto.poll(5.1)
    assert proto.state == TransferState.IDLE


def test_timed_items_must_increase_in_time(proto):
    timed = [item(k, CMD_TIMED, p=(t, 0.0, 0.0, math.nan), x=1000 * k) for k, t in enumerate((0.0, 0.5, 0.5))]
    outs = upload(proto, timed)
    assert acks(outs[3]) == [m.MAV_MISSION_INVALID_PARAM1]


def test_whole_mission_check_can_refuse(proto):
    proto.check = lambda items: (m.MAV_MISSION_INVALID_PARAM1, "too fast")
    outs = upload(proto, waypoints(2))
    assert acks(outs[2]) == [m.MAV_MISSION_INVALID_PARAM1] and proto.mission.count == 0


def test_messages_for_another_system_are_ignored(proto):
    out = proto.handle(wire(m.MAVLink_mission_count_message(7, COMP, 2)), 0.0)
    assert out.replies == [] and proto.state == TransferState.IDLE
