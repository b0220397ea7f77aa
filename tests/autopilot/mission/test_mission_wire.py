"""The mission protocol on the wire, in simulation time: the whole stack in-process (real MAVLink
bytes, no sockets) and the ground-station scripts' own client (gcs_scripts.upload_mission).
Upload/download round trip, broken uploads that must leave the old mission intact, clear, set
current, refused float messages. The autopilot's mission transfer timeouts run on its wall clock,
which is simulation time in-process, so the retry timing is checked exactly."""

from __future__ import annotations

import math
from collections.abc import Iterator

import pytest

from gcs_scripts.upload_mission import (
    CMD_TIMED,
    Item,
    MissionError,
    MissionLink,
    make_item,
    same_item,
)
from tests.stack import connect, make_stack

m = __import__("gcs_scripts.link", fromlist=["mavutil"]).mavutil.mavlink
LOCAL, GLOBAL_REL, MISSION = m.MAV_FRAME_LOCAL_NED, m.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, m.MAV_FRAME_MISSION
NAN4 = (0.0, 0.0, 0.0, math.nan)


def mixed_mission() -> list[Item]:
    """One of every supported item, in local and global frames."""
    return [
        make_item(LOCAL, m.MAV_CMD_NAV_TAKEOFF, NAN4, z=-2.5),
        make_item(LOCAL, m.MAV_CMD_NAV_WAYPOINT, (1.5, 0.3, 0.0, 45.0), 20_000, -10_000, -2.5),
        make_item(GLOBAL_REL, m.MAV_CMD_NAV_WAYPOINT, NAN4, 473977600, 85456100, 3.0),
        make_item(MISSION, m.MAV_CMD_DO_CHANGE_SPEED, (1.0, 0.75, -1.0, 0.0)),
        make_item(LOCAL, m.MAV_CMD_NAV_LOITER_TIME, (2.0, 0.0, 0.0, 0.0), 0, 10_000, -3.0),
        make_item(MISSION, m.MAV_CMD_NAV_DELAY, (1.0, -1.0, -1.0, -1.0)),
        *(make_item(LOCAL, CMD_TIMED, (10.0 + 0.1 * k, 0.0, 0.0, 0.0), 1000 * k, 0, -3.0) for k in range(8)),
        make_item(GLOBAL_REL, m.MAV_CMD_NAV_LAND),
        make_item(MISSION, m.MAV_CMD_NAV_RETURN_TO_LAUNCH, (0.0, 0.0, 0.0, 0.0)),
    ]


@pytest.fixture
def vehicle() -> Iterator[MissionLink]:
    stack = make_stack()
    link = connect(stack, MissionLink)
    link.stack = stack
    yield link
    link.close()


def wait_for(link: MissionLink, kind: str, sim_s: float, accept=lambda msg: True):
    """The first mission message of ``kind`` that ``accept`` takes within ``sim_s`` of simulation
    time (None after that)."""
    stack = link.stack
    end = stack.t + sim_s
    while stack.t <= end:
        link.poll()
        for msg in list(link.mission_inbox):
            if msg.get_type() == kind and accept(msg):
                link.mission_inbox.remove(msg)
                return msg
    return None


def download_equals(link: MissionLink, items: list[Item]) -> bool:
    got = link.download()
    return len(got) == len(items) and all(same_item(a, b) for a, b in zip(items, got, strict=True))


def test_upload_download_round_trip_is_identical(vehicle):
    items = mixed_mission()
    vehicle.upload(items)
    assert download_equals(vehicle, items)


def test_missing_items_time_out_and_the_old_mission_stays(vehicle):
    old = mixed_mission()
    vehicle.upload(old)
    new = [make_item(LOCAL, m.MAV_CMD_NAV_WAYPOINT, NAN4, 10_000 * k, 0, -2.0) for k in range(5)]
    vehicle.mission_inbox.clear()
    vehicle.mav.mission_count_send(*vehicle.target, 5, 0)  # count says 5 ...
    for seq in range(3):  # ... but only 3 are sent, then silence
        req = wait_for(vehicle, "MISSION_REQUEST_INT", 2.0, lambda x, s=seq: x.seq == s)
        assert req is not None
        vehicle.mav.send(new[seq].message(vehicle.target, seq))
    stack = vehicle.stack
    start = stack.t
    requests = []
    ack = None
    while ack is None and stack.t - start < 6.0:
        msg = wait_for(vehicle, "MISSION_REQUEST_INT", 0.01) or wait_for(vehicle, "MISSION_ACK", 0.0)
        if msg is not None and msg.get_type() == "MISSION_REQUEST_INT":
            assert msg.seq == 3
            requests.append(stack.t - start)
        elif msg is not None:
            ack = msg
    elapsed = stack.t - start
    assert ack is not None and ack.type == m.MAV_MISSION_OPERATION_CANCELLED
    # PX4's rule: the request, then a retry every 250 ms (polled every 50 ms: at most 0.3 s apart) until
    # 5 s without an item from the client
    gaps = [b - a for a, b in zip(requests, requests[1:], strict=False)]
    assert len(requests) >= 15 and all(0.24 < g < 0.31 for g in gaps), gaps
    assert 4.99 < elapsed < 5.4
    assert download_equals(vehicle, old)


def test_out_of_sequence_item_is_rerequested_then_times_out(vehicle):
    old = mixed_mission()
    vehicle.upload(old)
    new = [make_item(LOCAL, m.MAV_CMD_NAV_WAYPOINT, NAN4, 10_000 * k, 0, -2.0) for k in range(3)]
    vehicle.mission_inbox.clear()
    vehicle.mav.mission_count_send(*vehicle.target, 3, 0)
    assert wait_for(vehicle, "MISSION_REQUEST_INT", 2.0, lambda x: x.seq == 0) is not None
    vehicle.mav.send(new[0].message(vehicle.target, 0))
    assert wait_for(vehicle, "MISSION_REQUEST_INT", 2.0, lambda x: x.seq == 1) is not None
    vehicle.mav.send(new[2].message(vehicle.target, 2))  # wrong seq: dropped, 1 asked for again at once
    again = wait_for(vehicle, "MISSION_REQUEST_INT", 0.3)
    assert again is not None and again.seq == 1
    ack = wait_for(vehicle, "MISSION_ACK", 6.0)
    assert ack is not None and ack.type == m.MAV_MISSION_OPERATION_CANCELLED
    assert download_equals(vehicle, old)


@pytest.mark.parametrize(
    "bad, result",
    [
        (make_item(MISSION, m.MAV_CMD_DO_SET_SERVO, (1.0, 1500.0, 0.0, 0.0)), m.MAV_MISSION_UNSUPPORTED),
        (
            make_item(
                m.MAV_FRAME_GLOBAL_TERRAIN_ALT_INT, m.MAV_CMD_NAV_WAYPOINT, NAN4, 473977420, 85455940, 5.0
            ),
            m.MAV_MISSION_UNSUPPORTED_FRAME,
        ),  # fmt: skip
        (
            make_item(LOCAL, m.MAV_CMD_NAV_WAYPOINT, (-2.0, 0.0, 0.0, 0.0), 0, 0, -2.0),
            m.MAV_MISSION_INVALID_PARAM1,
        ),
    ],
)
def test_refused_items_name_the_result_and_keep_the_old_mission(vehicle, bad, result):
    old = mixed_mission()
    vehicle.upload(old)
    new = [
        make_item(LOCAL, m.MAV_CMD_NAV_TAKEOFF, NAN4, z=-2.0),
        bad,
        make_item(GLOBAL_REL, m.MAV_CMD_NAV_LAND),
    ]
    with pytest.raises(MissionError) as info:
        vehicle.upload(new)
    assert info.value.result == result
    assert download_equals(vehicle, old)


def test_clear_all_empties_the_mission(vehicle):
    vehicle.upload(mixed_mission())
    vehicle.clear()
    assert vehicle.download() == []


def test_set_current_is_confirmed_by_mission_current(vehicle):
    items = mixed_mission()
    vehicle.upload(items)
    vehicle.set_current(4)
    current = vehicle.mission_current
    assert current.seq == 4 and current.total == len(items)
    assert current.mission_state == m.MISSION_STATE_NOT_STARTED
    got = vehicle.download()
    assert len(got) == len(items)  # the download flags item 4 as current (checked on the raw message):
    vehicle.mission_inbox.clear()
    vehicle.mav.mission_request_int_send(*vehicle.target, 4, 0)
    assert wait_for(vehicle, "MISSION_ITEM_INT", 2.0).current == 1


def test_float_mission_request_is_refused_as_unsupported(vehicle):
    vehicle.upload(mixed_mission())
    vehicle.mission_inbox.clear()
    vehicle.mav.mission_request_send(*vehicle.target, 0, 0)
    ack = wait_for(vehicle, "MISSION_ACK", 2.0)
    assert ack is not None and ack.type == m.MAV_MISSION_UNSUPPORTED


def test_mission_commands_set_current_and_start(vehicle):
    items = mixed_mission()
    vehicle.upload(items)
    result = vehicle.command_long(m.MAV_CMD_DO_SET_MISSION_CURRENT, (3, 0), check=False)
    assert result == m.MAV_RESULT_ACCEPTED
    vehicle.wait_until(lambda lk: lk.mission_current is not None and lk.mission_current.seq == 3, 1.0,
                       what="MISSION_CURRENT 3")  # fmt: skip
    assert vehicle.command_long(m.MAV_CMD_DO_SET_MISSION_CURRENT, (99, 0), check=False) == m.MAV_RESULT_DENIED
    # Disarmed: MISSION_START selects AUTO.MISSION (PX4: the mission then starts at arming) and its
    # param1 makes item 1 current.
    assert vehicle.command_long(m.MAV_CMD_MISSION_START, (1, 0), check=False) == m.MAV_RESULT_ACCEPTED
    vehicle.wait_until(lambda lk: lk.mission_current is not None and lk.mission_current.seq == 1, 1.0,
                       what="MISSION_CURRENT 1")  # fmt: skip
    vehicle.clear()
    assert vehicle.command_long(m.MAV_CMD_MISSION_START, (0, 0), check=False) == m.MAV_RESULT_DENIED
