"""Geofence and rally plans: transfers (upload, download, clear), validation, fence geometry (pure),
and on the wire in simulation time: a fence breach acts by GF_ACTION, RTL goes to the nearest rally
point."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as m

from autopilot.mission.items import WireItem
from autopilot.mission.plans import Geofence, check_fence, parse_fence_item
from autopilot.mission.protocol import MissionProtocol, TransferState
from quadcommon import frames
from tests.autopilot.mission.test_protocol import COMP, SYS, acks, kinds, waypoints
from tests.autopilot.mission.test_protocol import upload as upload_mission
from tests.autopilot.mission.test_protocol import wire as arrive

HOME = (47.397742, 8.545594, 488.0)
FENCE, RALLY = m.MAV_MISSION_TYPE_FENCE, m.MAV_MISSION_TYPE_RALLY
GLOBAL = m.MAV_FRAME_GLOBAL_INT
CIRCLE_IN = m.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION


def at(north: float, east: float) -> tuple[int, int]:
    lat, lon, _ = frames.ned_to_geodetic(north, east, 0.0, HOME)
    return round(lat * 1e7), round(lon * 1e7)


def fitem(seq, command, p1, north, east, mission_type=FENCE, frame=GLOBAL, z=0.0):
    x, y = at(north, east)
    return m.MAVLink_mission_item_int_message(
        SYS, COMP, seq, frame, command, 0, 1, p1, 0.0, 0.0, 0.0, x, y, z, mission_type
    )


def square_fence(
    half: float = 10.0, first_seq: int = 0, command=m.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION
):
    corners = [(-half, -half), (half, -half), (half, half), (-half, half)]
    return [fitem(first_seq + k, command, 4.0, n, e) for k, (n, e) in enumerate(corners)]


def upload(proto, items, now=0.0):
    """MISSION_COUNT of the items' mission_type, then the items; the Output of each message."""
    mission_type = items[0].mission_type
    outs = [proto.handle(arrive(m.MAVLink_mission_count_message(SYS, COMP, len(items), mission_type)), now)]
    outs += [proto.handle(arrive(it), now) for it in items]
    return outs


def download(proto, mission_type):
    out = proto.handle(arrive(m.MAVLink_mission_request_list_message(SYS, COMP, mission_type)), 1.0)
    assert kinds(out) == ["MISSION_COUNT"] and out.replies[0].mission_type == mission_type
    got = []
    for seq in range(out.replies[0].count):
        reply = proto.handle(arrive(m.MAVLink_mission_request_int_message(SYS, COMP, seq, mission_type)), 1.0)
        got.append(reply.replies[0])
    proto.handle(arrive(m.MAVLink_mission_ack_message(SYS, COMP, 0, mission_type)), 1.0)
    return got


FIELDS = ("seq", "frame", "command", "param1", "x", "y", "z", "mission_type")


@pytest.fixture
def proto():
    return MissionProtocol(SYS, COMP, HOME)


def test_fence_rally_and_mission_are_stored_apart_and_downloaded_back(proto):
    upload_mission(proto, waypoints(2))
    fence = [
        *square_fence(),
        fitem(4, m.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION, 2.0, 5.0, 5.0),
        fitem(5, m.MAV_CMD_NAV_FENCE_RETURN_POINT, 0.0, 0.0, 0.0),
    ]
    outs = upload(proto, fence)
    assert kinds(outs[0]) == ["MISSION_REQUEST_INT"] and outs[0].replies[0].mission_type == FENCE
    assert acks(outs[-1]) == [m.MAV_MISSION_ACCEPTED] and outs[-1].replies[0].mission_type == FENCE
    assert outs[-1].fence is not None and outs[-1].mission is None
    rally = [fitem(k, m.MAV_CMD_NAV_RALLY_POINT, 0.0, 20.0 * k, 3.0, RALLY, z=15.0) for k in range(2)]
    outs = upload(proto, rally)
    assert acks(outs[-1]) == [m.MAV_MISSION_ACCEPTED] and outs[-1].rally.count == 2
    for sent, mission_type in ((fence, FENCE), (rally, RALLY)):
        got = download(proto, mission_type)
        assert [[getattr(g, f) for f in FIELDS] for g in got] == [
            [getattr(s, f) for f in FIELDS] for s in sent
        ]
    assert proto.mission.count == 2 and len(download(proto, m.MAV_MISSION_TYPE_MISSION)) == 2
    # Clear one type: the others stay; ALL clears everything.
    out = proto.handle(arrive(m.MAVLink_mission_clear_all_message(SYS, COMP, RALLY)), 2.0)
    assert acks(out) == [m.MAV_MISSION_ACCEPTED] and out.rally.count == 0 and out.fence is None
    assert proto.plans[FENCE].count == 6 and proto.mission.count == 2
    out = proto.handle(arrive(m.MAVLink_mission_clear_all_message(SYS, COMP, m.MAV_MISSION_TYPE_ALL)), 2.0)
    assert out.fence.count == 0 and out.mission.count == 0 and out.rally.count == 0


def _vertex(seq, count, north=0.0, east=0.0, command=m.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION):
    return fitem(seq, command, count, north, east)


@pytest.mark.parametrize(
    "items, result",
    [
        ([_vertex(0, 2.0), _vertex(1, 2.0, 5.0)], m.MAV_MISSION_INVALID_PARAM1),  # < 3 vertices
        ([_vertex(0, 4.0), _vertex(1, 4.0, 5.0), _vertex(2, 4.0, 5.0, 5.0)], m.MAV_MISSION_INVALID_PARAM1),
        ([_vertex(0, 3.0), _vertex(1, 4.0, 5.0), _vertex(2, 3.0, 5.0, 5.0)], m.MAV_MISSION_INVALID_PARAM1),
        (
            [_vertex(0, 3.0), _vertex(1, 3.0, 5.0, command=m.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION),
             _vertex(2, 3.0, 5.0, 5.0)],
            m.MAV_MISSION_INVALID_PARAM1,
        ),
        ([_vertex(0, 3.5), _vertex(1, 3.5, 5.0), _vertex(2, 3.5, 5.0, 5.0)], m.MAV_MISSION_INVALID_PARAM1),
        ([fitem(0, m.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, math.nan, 0.0, 0.0)], m.MAV_MISSION_INVALID_PARAM1),
        ([fitem(0, m.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, math.inf, 0.0, 0.0)], m.MAV_MISSION_INVALID_PARAM1),
        ([fitem(0, m.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, 5.0, 0.0, 0.0, frame=m.MAV_FRAME_LOCAL_NED)],
         m.MAV_MISSION_UNSUPPORTED_FRAME),
        ([fitem(0, m.MAV_CMD_NAV_WAYPOINT, 5.0, 0.0, 0.0)], m.MAV_MISSION_UNSUPPORTED),
        ([fitem(0, m.MAV_CMD_NAV_RALLY_POINT, 0.0, 0.0, 0.0)], m.MAV_MISSION_UNSUPPORTED),
        ([fitem(0, CIRCLE_IN, 5.0, 0.0, 0.0, z=math.inf)], m.MAV_MISSION_INVALID_PARAM7),
        ([fitem(0, CIRCLE_IN, 5.0, 20_000.0, 0.0)], m.MAV_MISSION_INVALID_PARAM5_X),
    ],
)  # fmt: skip
def test_bad_fence_plans_are_refused_and_the_old_one_kept(proto, items, result):
    upload(proto, square_fence())
    old = proto.plans[FENCE]
    outs = upload(proto, items)
    assert next(acks(o) for o in outs if acks(o)) == [result]
    assert proto.plans[FENCE] is old and proto.state == TransferState.IDLE


def test_a_circle_of_radius_zero_or_less_is_no_circle_accepted_ignored_and_noted(proto):
    """MAVSDK's geofence example sends its polygon and Circle(Point(0, 0), 0): "no circle"."""
    no_circle = m.MAVLink_mission_item_int_message(  # at latitude 0, longitude 0: 5,000 km away
        SYS, COMP, 4, GLOBAL, CIRCLE_IN, 0, 1, 0.0, 0.0, 0.0, 0.0, 0, 0, 0.0, FENCE
    )
    negative = fitem(5, m.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION, -3.0, 0.0, 0.0)
    sent = [*square_fence(10.0), no_circle, negative]
    outs = upload(proto, sent)
    assert acks(outs[-1]) == [m.MAV_MISSION_ACCEPTED]
    assert (6, "geofence items 4, 5: a circle of radius <= 0 is no circle, ignored") in outs[-1].notices
    got = download(proto, FENCE)  # stored and downloaded back as uploaded
    assert [[getattr(g, f) for f in FIELDS] for g in got] == [[getattr(s, f) for f in FIELDS] for s in sent]
    fence = Geofence.from_items(outs[-1].fence.items, HOME)
    assert len(fence.areas) == 1  # the square only: neither circle encloses or excludes anything
    assert fence.excess((0.0, 0.0, 1.0))[0] < 0.0 < fence.excess((15.0, 0.0, 1.0))[0]
    alone = m.MAVLink_mission_item_int_message(
        SYS, COMP, 0, GLOBAL, CIRCLE_IN, 0, 1, 0.0, 0.0, 0.0, 0.0, 0, 0, 0.0, FENCE
    )
    only = upload(proto, [alone])
    assert acks(only[-1]) == [m.MAV_MISSION_ACCEPTED]
    assert Geofence.from_items(only[-1].fence.items, HOME).areas == ()  # no fence at all


def test_bad_rally_points_are_refused(proto):
    bad_lat = m.MAVLink_mission_item_int_message(
        SYS, COMP, 0, GLOBAL, m.MAV_CMD_NAV_RALLY_POINT, 0, 1, 0, 0, 0, 0, 950_000_000, 0, 10.0, RALLY
    )
    assert acks(upload(proto, [bad_lat])[-1]) == [m.MAV_MISSION_INVALID_PARAM5_X]
    fence_cmd = fitem(0, m.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, 5.0, 0.0, 0.0, RALLY)
    assert acks(upload(proto, [fence_cmd])[-1]) == [m.MAV_MISSION_UNSUPPORTED]
    mixed = [fitem(0, m.MAV_CMD_NAV_RALLY_POINT, 0.0, 0.0, 0.0, RALLY), *waypoints(2)[1:]]
    proto.handle(arrive(m.MAVLink_mission_count_message(SYS, COMP, 2, RALLY)), 0.0)
    proto.handle(arrive(mixed[0]), 0.0)
    out = proto.handle(arrive(mixed[1]), 0.0)  # a mission item inside a rally upload
    assert acks(out) == [m.MAV_MISSION_ERROR] and proto.plans[RALLY].count == 0


def _fence(items):
    parsed = [parse_fence_item(WireItem.from_message(arrive(it)), HOME) for it in items]
    assert check_fence(parsed) is None
    return Geofence.from_items(parsed, HOME)


def test_geofence_geometry_inclusion_union_and_exclusions():
    fence = _fence(
        [
            *square_fence(10.0),
            fitem(4, m.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION, 5.0, 20.0, 0.0),
            fitem(5, m.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION, 2.0, 5.0, 5.0),
        ]
    )

    def excess(north, east):
        x, y, _ = frames.vector_from_ned((north, east, 0.0))
        return fence.excess((x, y, 3.0))[0]

    assert excess(0.0, 0.0) == pytest.approx(-(math.hypot(5.0, 5.0) - 2.0), abs=0.01)  # nearest: exclusion
    assert excess(12.0, 0.0) == pytest.approx(2.0, abs=0.01)  # between the square and the circle
    assert excess(20.0, 1.0) == pytest.approx(-4.0, abs=0.01)  # inside the circle: inside the union
    assert excess(5.0, 5.0) == pytest.approx(2.0, abs=0.01)  # at the exclusion's centre
    assert excess(5.0, 8.0) == pytest.approx(-1.0, abs=0.01)  # 1 m outside the exclusion, in the square
    assert excess(0.0, 30.0) == pytest.approx(20.0, abs=0.01)
    only_exclusion = _fence([fitem(0, m.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION, 2.0, 0.0, 0.0)])
    assert only_exclusion.excess((10.0, 0.0, 1.0))[0] < 0.0 < only_exclusion.excess((0.5, 0.0, 1.0))[0]


def test_a_fence_of_too_many_items_gets_no_space(proto):
    out = proto.handle(arrive(m.MAVLink_mission_count_message(SYS, COMP, 257, FENCE)), 0.0)
    assert acks(out) == [m.MAV_MISSION_NO_SPACE] and out.replies[0].mission_type == FENCE
    assert proto.state == TransferState.IDLE
