"""Parameter slots as the MAVLink definitions state them (autopilot.mavlink.validation.slots): a
value other than 0 or NaN (x/y: 0 or INT32_MAX) in a slot the definition leaves unused is refused,
COMMAND_ACK DENIED for a command, MAV_MISSION_INVALID_PARAMn for the first such slot of a mission,
fence or rally item. The tests are generated from the tables: every handled command
(COMMAND_RULES), every item command the protocol stores, every slot of each."""

from __future__ import annotations

import math

import pytest

from autopilot.mavlink.codec import mavlink as m
from autopilot.mavlink.commands import CommandDispatcher
from autopilot.mavlink.validation import (
    COMMAND_RULES,
    INT32_MAX,
    SLOT_OVERRIDES,
    check_command,
    defined_slots,
    slots,
)
from autopilot.mission import plans
from autopilot.mission.items import SLOT_RESULTS, SUPPORTED_COMMANDS, ItemRejected, WireItem, parse_item
from tests.stack import Gcs, make_stack

NAN = math.nan
HOME = (47.397742, 8.545594, 488.0)  # lat, lon deg, alt m: the items' origin
LAT, LON = round(HOME[0] * 1e7), round(HOME[1] * 1e7)
SLOTS = range(1, 8)


# -- the table ----------------------------------------------------------------------------------------
def test_the_definition_is_mavlinks_text():
    assert slots(m.MAV_CMD_COMPONENT_ARM_DISARM).unused == (3, 4, 5, 6, 7)  # "Reserved (default:0)"
    assert slots(m.MAV_CMD_NAV_RETURN_TO_LAUNCH).used == frozenset()  # "Empty" x 7
    assert slots(m.MAV_CMD_NAV_LAND).unused == (3,)  # "Empty."
    assert slots(m.MAV_CMD_NAV_WAYPOINT).unused == ()  # a fixed wing's pass radius is still a meaning
    assert slots(m.MAV_CMD_GET_HOME_POSITION).used == frozenset()  # "Reserved"


@pytest.mark.parametrize("override", SLOT_OVERRIDES, ids=lambda o: slots(o.command).name)
def test_every_override_changes_what_the_definition_says(override):
    """An override the definition already agrees with is dead (a newer pymavlink caught up)."""
    for slot in override.slots:
        assert (slot in defined_slots(override.command)) != override.used, (override, slot)
        assert (slot in slots(override.command).used) == override.used
    assert override.why


def test_every_rule_is_on_a_slot_the_command_uses():
    for command, rules in COMMAND_RULES.items():
        for rule in rules:
            assert rule.number in slots(command).used, (command, rule)


def test_the_vehicle_handles_exactly_the_commands_of_the_table():
    stack = make_stack()
    assert set(stack.autopilot.commands.handlers) == set(COMMAND_RULES)
    with pytest.raises(ValueError, match="COMMAND_RULES"):
        CommandDispatcher().register(m.MAV_CMD_DO_FLIGHTTERMINATION, lambda r: (m.MAV_RESULT_ACCEPTED, ""))


# -- commands, generated from the table ----------------------------------------------------------------
BASELINE = {m.MAV_CMD_DO_SET_MODE: {1: float(m.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED)}}  # else all 0


def baseline(command: int) -> list[float]:
    params = [0.0] * 7
    for slot, value in BASELINE.get(command, {}).items():
        params[slot - 1] = value
    assert check_command(command, tuple(params)) is None  # the command is valid as it starts
    return params


def with_slot(command: int, slot: int, value: float) -> tuple[float, ...]:
    params = baseline(command)
    params[slot - 1] = value
    return tuple(params)


COMMAND_SLOTS = [(command, slot) for command in sorted(COMMAND_RULES) for slot in SLOTS]


@pytest.mark.parametrize("command, slot", COMMAND_SLOTS, ids=lambda v: str(v))
def test_a_command_slot(command, slot):
    integer = slot in (5, 6)
    if slot in slots(command).unused:
        for as_command_int in (False, True):
            problem = check_command(command, with_slot(command, slot, 1.0), as_command_int)
            assert problem is not None and f"param{slot}" in problem and "unused" in problem
        assert check_command(command, with_slot(command, slot, 0.0)) is None
        assert check_command(command, with_slot(command, slot, NAN)) is None  # COMMAND_LONG
        if integer:  # COMMAND_INT's int32 x/y: 0 or INT32_MAX
            assert check_command(command, with_slot(command, slot, 0.0), True) is None
            assert check_command(command, with_slot(command, slot, float(INT32_MAX)), True) is None
        else:
            assert check_command(command, with_slot(command, slot, NAN), True) is None
    else:  # a slot the command uses: its own rules may refuse 1, never for being unused
        for as_command_int in (False, True):
            problem = check_command(command, with_slot(command, slot, 1.0), as_command_int)
            assert problem is None or "unused" not in problem


def test_the_first_unused_slot_is_named():
    problem = check_command(m.MAV_CMD_COMPONENT_ARM_DISARM, (1.0, 0.0, 0.0, 2.0, 0.0, 5.0, 1.0))
    assert problem.startswith("param4 = 2: unused")


# -- mission, fence and rally items, generated from the table ---------------------------------------------
MISSION = m.MAV_FRAME_MISSION


def item_baseline(command: int) -> WireItem:
    """A valid item of ``command`` with every unused slot unset (seq 1)."""
    local, glob = m.MAV_FRAME_LOCAL_NED, m.MAV_FRAME_GLOBAL_INT
    at = {"x": 10_000, "y": 0, "z": -2.0, "frame": local}  # 1 m north, 2 m up
    here = {"x": LAT, "y": LON, "z": 500.0, "frame": glob}
    special = {
        m.MAV_CMD_NAV_TAKEOFF: at, m.MAV_CMD_NAV_WAYPOINT: at, m.MAV_CMD_NAV_LAND: at,
        m.MAV_CMD_NAV_LOITER_TIME: {**at, "param1": 1.0}, m.MAV_CMD_WAYPOINT_USER_1: {**at, "param1": 1.0},
        m.MAV_CMD_NAV_DELAY: {"param1": 1.0}, m.MAV_CMD_DO_CHANGE_SPEED: {"param1": 1.0, "param2": 2.0},
        m.MAV_CMD_DO_JUMP: {"param1": 0.0, "param2": 1.0}, m.MAV_CMD_DO_SET_ROI_LOCATION: here,
        plans.CMD_POLYGON_INCLUSION: {**here, "param1": 3.0, "z": 0.0},
        plans.CMD_POLYGON_EXCLUSION: {**here, "param1": 3.0, "z": 0.0},
        plans.CMD_CIRCLE_INCLUSION: {**here, "param1": 10.0, "z": 0.0},
        plans.CMD_CIRCLE_EXCLUSION: {**here, "param1": 10.0, "z": 0.0},
        plans.CMD_FENCE_RETURN_POINT: here, plans.CMD_RALLY_POINT: here,
    }  # fmt: skip
    fields = {"frame": MISSION, "param1": 0.0, "param2": 0.0, "param3": 0.0, "param4": 0.0, "x": 0, "y": 0,
              "z": 0.0, **special.get(command, {})}  # fmt: skip
    return WireItem(seq=1, command=command, current=0, autocontinue=1, **fields)


def parse(wire: WireItem):
    """The item as the protocol parses it for its plan type."""
    if wire.command in plans.FENCE_COMMANDS:
        return plans.parse_fence_item(wire, HOME)
    if wire.command in plans.RALLY_COMMANDS:
        return plans.parse_rally_item(wire, HOME)
    return parse_item(wire, HOME)


FIELD = ("param1", "param2", "param3", "param4", "x", "y", "z")
ITEM_COMMANDS = sorted(SUPPORTED_COMMANDS | plans.FENCE_COMMANDS | plans.RALLY_COMMANDS)
ITEM_SLOTS = [(command, slot) for command in ITEM_COMMANDS for slot in SLOTS]


def item_with(command: int, slot: int, value: float) -> WireItem:
    return item_baseline(command)._replace(**{FIELD[slot - 1]: value})


@pytest.mark.parametrize("command, slot", ITEM_SLOTS, ids=lambda v: str(v))
def test_an_item_slot(command, slot):
    parse(item_baseline(command))  # valid as it starts
    integer = slot in (5, 6)
    if slot in slots(command).unused:
        with pytest.raises(ItemRejected) as refused:
            parse(item_with(command, slot, 1))
        assert refused.value.result == SLOT_RESULTS[slot - 1] and "unused" in refused.value.reason
        parse(item_with(command, slot, 0))
        parse(item_with(command, slot, INT32_MAX if integer else NAN))
    else:  # a slot the item uses: its own rules may refuse 1, never for being unused
        try:
            parse(item_with(command, slot, 1))
        except ItemRejected as exc:
            assert "unused" not in exc.reason


def test_an_item_names_its_first_unused_slot_whatever_else_is_wrong():
    rtl = item_baseline(m.MAV_CMD_NAV_RETURN_TO_LAUNCH)._replace(param3=math.inf, x=7, z=1.0)
    with pytest.raises(ItemRejected) as refused:
        parse(rtl)
    assert refused.value.result == m.MAV_MISSION_INVALID_PARAM3


# -- what real clients put in the slots is accepted --------------------------------------------------------
@pytest.mark.parametrize(
    "command, params, as_command_int",
    [
        (m.MAV_CMD_COMPONENT_ARM_DISARM, (1.0, NAN, NAN, NAN, NAN, NAN, NAN), False),  # MAVSDK arm
        (m.MAV_CMD_COMPONENT_ARM_DISARM, (1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0), False),  # MAVProxy, QGC
        (m.MAV_CMD_NAV_TAKEOFF, (NAN, NAN, NAN, NAN, NAN, NAN, 500.0), False),  # MAVSDK takeoff
        (m.MAV_CMD_NAV_TAKEOFF, (-1.0, 0.0, 0.0, NAN, NAN, NAN, 500.0), False),  # QGroundControl
        (m.MAV_CMD_NAV_TAKEOFF, (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 3.0), False),  # MAVProxy "takeoff 3"
        (m.MAV_CMD_NAV_RETURN_TO_LAUNCH, (NAN,) * 7, False),  # MAVSDK return_to_launch
        (m.MAV_CMD_NAV_LAND, (NAN,) * 7, False),  # MAVSDK land
        (m.MAV_CMD_DO_SET_MODE, (1.0, 4.0, 3.0, NAN, NAN, NAN, NAN), False),  # MAVSDK hold
        (m.MAV_CMD_DO_SET_MODE, (1.0, 4.0, 3.0, NAN, 0.0, 0.0, NAN), True),  # as COMMAND_INT
        (m.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, (1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0), False),  # QGC
        (m.MAV_CMD_SET_MESSAGE_INTERVAL, (33.0, 1e5, NAN, NAN, NAN, NAN, 0.0), False),  # MAVSDK set_rate
        (m.MAV_CMD_PREFLIGHT_STORAGE, (2.0, -1.0, 0.0, 0.0, 0.0, 0.0, 0.0), False),  # QGC parameter reset
        (m.MAV_CMD_MISSION_START, (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0), False),  # QGC start mission
    ],
)
def test_client_commands_are_accepted(command, params, as_command_int):
    assert check_command(command, params, as_command_int) is None


def item(command, frame, p, x=0, y=0, z=0.0):
    return WireItem(1, frame, command, 0, 1, *p, x, y, z)


@pytest.mark.parametrize(
    "wire",
    [  # MAVSDK's mission plugin
        item(m.MAV_CMD_DO_CHANGE_SPEED, MISSION, (1.0, 5.0, -1.0, 0.0), z=NAN),
        item(m.MAV_CMD_NAV_DELAY, MISSION, (2.0, -1.0, -1.0, -1.0)),
        item(m.MAV_CMD_NAV_RETURN_TO_LAUNCH, MISSION, (NAN, NAN, NAN, NAN)),
        item(m.MAV_CMD_DO_MOUNT_CONFIGURE, MISSION, (2.0, 0.0, 0.0, 1.0), z=2.0),  # absolute gimbal yaw
        item(m.MAV_CMD_DO_MOUNT_CONTROL, MISSION, (-30.0, 0.0, 10.0, NAN), z=2.0),
        item(m.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW, MISSION, (-30.0, 10.0, NAN, NAN), x=12, z=0.0),
        item(m.MAV_CMD_DO_GIMBAL_MANAGER_CONFIGURE, MISSION, (-2.0, -2.0, -1.0, -1.0)),
        item(m.MAV_CMD_IMAGE_STOP_CAPTURE, MISSION, (0.0, NAN, NAN, NAN), z=NAN),
        item(m.MAV_CMD_VIDEO_START_CAPTURE, MISSION, (0.0, NAN, NAN, NAN), z=NAN),
        # a loiter leaving only once headed for the next waypoint (newer common.xml; PX4 reads param2)
        item(m.MAV_CMD_NAV_LOITER_TIME, m.MAV_FRAME_GLOBAL_INT, (5.0, 1.0, 0.0, NAN), LAT, LON, 500.0),
        item(m.MAV_CMD_DO_JUMP, MISSION, (0.0, 2.0, 0.0, 0.0)),
        # MAVSDK's geofence
        item(plans.CMD_POLYGON_INCLUSION, m.MAV_FRAME_GLOBAL_INT, (3.0, 0.0, 0.0, 0.0), LAT, LON),
    ],
    ids=lambda w: str(w.command),
)
def test_client_items_are_accepted(wire):
    parse(wire)


# -- end to end, in simulation time ---------------------------------------------------------------
def test_a_command_with_a_value_in_an_unused_slot_is_denied_with_its_reason():
    stack = make_stack()
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    ack = gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1.0, 0.0, 1.0)
    assert ack.result == m.MAV_RESULT_DENIED and not gcs.armed
    reason = "COMPONENT_ARM_DISARM refused: param3 = 1: unused (Reserved (default:0)), must be 0 or NaN"
    gcs.wait(lambda g: reason in "".join(g.statustext), 1.0, "the reason")  # (in 50-byte chunks)
    assert stack.autopilot.refusals.by_reason  # counted with the other refusals
    rtl = m.MAV_CMD_NAV_RETURN_TO_LAUNCH  # COMMAND_INT with x = 1
    int_x = m.MAVLink_command_int_message(gcs.system_id, 1, m.MAV_FRAME_GLOBAL_RELATIVE_ALT, rtl, 0, 0,
                                          0, 0, 0, 0, 1, 0, 0)  # fmt: skip
    gcs.acks.clear()
    gcs.conn.mav.send(int_x)
    gcs.wait(lambda g: g.acks, 0.5, "COMMAND_ACK")
    assert gcs.acks[-1].result == m.MAV_RESULT_DENIED
    ack = gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1.0, NAN, NAN, NAN, NAN, NAN, NAN)
    assert ack.result == m.MAV_RESULT_ACCEPTED


def test_a_mission_item_with_a_value_in_an_unused_slot_is_refused_by_its_slot():
    stack = make_stack()
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    mav, sys = gcs.conn.mav, gcs.system_id
    items = [
        m.MAVLink_mission_item_int_message(sys, 1, 0, m.MAV_FRAME_LOCAL_NED, m.MAV_CMD_NAV_TAKEOFF, 1, 1,
                                           0, 0, 0, NAN, 0, 0, -2.0),
        m.MAVLink_mission_item_int_message(sys, 1, 1, MISSION, m.MAV_CMD_NAV_RETURN_TO_LAUNCH, 0, 1,
                                           1.0, 0, 0, 0, 0, 0, 0),
    ]  # fmt: skip

    def upload() -> int:
        gcs.last.pop("MISSION_ACK", None)
        mav.mission_count_send(sys, 1, len(items))
        for it in items:
            gcs.wait(lambda g, s=it.seq: getattr(g.last.get("MISSION_REQUEST_INT"), "seq", -1) == s, 1.0)
            mav.send(it)
        gcs.wait(lambda g: "MISSION_ACK" in g.last, 1.0, "MISSION_ACK")
        return gcs.last["MISSION_ACK"].type

    assert upload() == m.MAV_MISSION_INVALID_PARAM1
    reason = "item 1: param1 = 1: unused (Empty), must be 0 or NaN"
    gcs.wait(lambda g: reason in "".join(g.statustext), 1.0, "the reason")  # (in 50-byte chunks)
    items[1].param1 = NAN
    assert upload() == m.MAV_MISSION_ACCEPTED
