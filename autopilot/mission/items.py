"""Mission items: MISSION_ITEM_INT on the wire <-> typed, validated records (pure).

Every item keeps the exact wire fields it arrived with (:class:`WireItem`), so a download returns
what was uploaded, bit for bit; the typed :class:`MissionItem` is what the executor flies.

Supported items (anything else is refused at upload with ``MAV_MISSION_UNSUPPORTED``, never
skipped silently):

=======================  =====  ==========================================================
command                  id     meaning here (multicopter semantics, as PX4)
=======================  =====  ==========================================================
NAV_TAKEOFF              22     climb vertically where the vehicle is to altitude z (NaN:
                                ``MIS_TAKEOFF_ALT`` above home); p4 yaw (deg, NaN: keep)
NAV_WAYPOINT             16     fly to x, y, z and stop; p1 hold time (s), p2 acceptance
                                radius (m, 0/NaN: ``NAV_ACC_RAD``), p4 yaw (deg, NaN: keep)
NAV_LOITER_TIME          19     fly to x, y, z and hold there p1 seconds
NAV_DELAY                93     hold where the vehicle is for p1 seconds (MAVSDK's loiter time)
DO_CHANGE_SPEED          178    p1 speed type (0 air / 1 ground: horizontal, 2 climb,
                                3 descent), p2 speed m/s (-1 no change, -2 back to default);
                                applies to every later leg
NAV_LAND                 21     fly to x, y at the current altitude, then land and disarm
                                (global frame with lat = lon = 0: land where the vehicle is)
NAV_RETURN_TO_LAUNCH     20     return home and land (the vehicle switches to AUTO.RTL)
WAYPOINT_USER_1          31000  TIMED trajectory sample: be at x, y, z at p1 seconds after the
                                mission started; p4 yaw (deg, NaN: keep); consecutive timed
                                items form one curve, interpolated by a C4 spline in time
DO_JUMP                  177    p1 target item (seq), p2 repeat count (>= 0): jump back (or
                                forward) that many times, then go on with the next item (PX4)
payload items            below  stored and downloaded as uploaded, flown as no-ops (this
                                vehicle has no gimbal, camera, gripper or winch): one
                                STATUSTEXT per mission run says so
=======================  =====  ==========================================================

Payload items (the ones PX4's mission parser accepts without the payload being present):
DO_CONTROL_VIDEO 200, DO_DIGICAM_CONTROL 203, DO_MOUNT_CONFIGURE 204, DO_MOUNT_CONTROL 205,
DO_SET_CAM_TRIGG_DIST 206, DO_GRIPPER 211, DO_SET_CAM_TRIGG_INTERVAL 214, OBLIQUE_SURVEY 260,
SET_CAMERA_MODE 530, SET_CAMERA_FOCUS 532, SET_CAMERA_SOURCE 534, DO_GIMBAL_MANAGER_PITCHYAW 1000,
DO_GIMBAL_MANAGER_CONFIGURE 1001, IMAGE_START_CAPTURE 2000, IMAGE_STOP_CAPTURE 2001,
DO_TRIGGER_CONTROL 2003, VIDEO_START_CAPTURE 2500, VIDEO_STOP_CAPTURE 2501, DO_WINCH 42600, and the
region-of-interest items DO_SET_ROI_WPNEXT_OFFSET 196, DO_SET_ROI_NONE 197, DO_SET_ROI_LOCATION 195
and NAV_ROI 80 / DO_SET_ROI 201 (p1 = MAV_ROI_NONE, WPNEXT, WPINDEX or, in a global frame,
LOCATION; other ROI modes: ``INVALID_PARAM1``, as PX4). Their parameters must be finite or NaN
(infinite: ``INVALID_PARAMn``); ROI positions are checked as positions. PX4's parser refuses
SET_CAMERA_ZOOM (531) in a mission, and so does this one. PX4 items that are not payload
(DO_SET_HOME, DO_LAND_START, CONDITION_*, DO_SET_ACTUATOR, DO_VTOL_TRANSITION, ...) stay refused.

Frames for items with a position: ``MAV_FRAME_GLOBAL(_INT)`` (z above mean sea level),
``MAV_FRAME_GLOBAL_RELATIVE_ALT(_INT)`` (z above the vehicle's home) and ``MAV_FRAME_LOCAL_NED``
(x, y, z north-east-down metres from the local frame's origin, the configured geodetic home
``sitl.home``; x and y are int32 scaled by 1e4 as the MAVLink mission spec says). In
MISSION_ITEM_INT, x and y of every global frame are degrees * 1e7 (also for the non-``_INT``
variants: PX4, MAVSDK and QGC encode them that way). Items without a position accept any of
these frames and ``MAV_FRAME_MISSION``. Other frames: ``MAV_MISSION_UNSUPPORTED_FRAME``.

Parameter slots: a slot MAVLink's definition of the item's command leaves unused ("Empty",
"Reserved", ...) must be unset: 0 or NaN (x, y: 0 or ``INT32_MAX``), whatever the frame, or the
upload ends with ``MAV_MISSION_INVALID_PARAMn`` for the first such slot (checked right after the
command is known, before its frame and values: :func:`check_unused_slots`, the rule and its
exceptions in :mod:`autopilot.mavlink.validation`). The other slots are read as above or, where
this vehicle has no use for them (a fixed wing's pass radius, a camera's id), stored and ignored.

Positions are resolved to the paper frame only when the mission is flown
(:meth:`ItemPosition.to_paper`), because "relative to home" depends on where the vehicle armed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum
from typing import NamedTuple

from quadcommon import frames

from ..mavlink.codec import mavlink as m
from ..mavlink.validation import slots

Vector3 = tuple[float, float, float]

CMD_NAV_WAYPOINT = m.MAV_CMD_NAV_WAYPOINT  # 16
CMD_NAV_LOITER_TIME = m.MAV_CMD_NAV_LOITER_TIME  # 19
CMD_NAV_RETURN_TO_LAUNCH = m.MAV_CMD_NAV_RETURN_TO_LAUNCH  # 20
CMD_NAV_LAND = m.MAV_CMD_NAV_LAND  # 21
CMD_NAV_TAKEOFF = m.MAV_CMD_NAV_TAKEOFF  # 22
CMD_NAV_DELAY = m.MAV_CMD_NAV_DELAY  # 93
CMD_DO_CHANGE_SPEED = m.MAV_CMD_DO_CHANGE_SPEED  # 178
CMD_TIMED = m.MAV_CMD_WAYPOINT_USER_1  # 31000: the timed trajectory item
CMD_DO_JUMP = m.MAV_CMD_DO_JUMP  # 177
CMD_DO_SET_ROI_LOCATION = m.MAV_CMD_DO_SET_ROI_LOCATION  # 195
ROI_MODE_COMMANDS = frozenset((m.MAV_CMD_NAV_ROI, m.MAV_CMD_DO_SET_ROI))  # 80, 201: p1 = MAV_ROI
# Accepted, stored and flown as no-ops (no payload on this vehicle); see the module docstring.
PAYLOAD_COMMANDS = frozenset(
    (
        m.MAV_CMD_DO_CONTROL_VIDEO, m.MAV_CMD_DO_DIGICAM_CONTROL, m.MAV_CMD_DO_MOUNT_CONFIGURE,
        m.MAV_CMD_DO_MOUNT_CONTROL, m.MAV_CMD_DO_SET_CAM_TRIGG_DIST, m.MAV_CMD_DO_GRIPPER,
        m.MAV_CMD_DO_SET_CAM_TRIGG_INTERVAL, m.MAV_CMD_OBLIQUE_SURVEY, m.MAV_CMD_SET_CAMERA_MODE,
        m.MAV_CMD_SET_CAMERA_FOCUS, m.MAV_CMD_SET_CAMERA_SOURCE, m.MAV_CMD_DO_GIMBAL_MANAGER_PITCHYAW,
        m.MAV_CMD_DO_GIMBAL_MANAGER_CONFIGURE, m.MAV_CMD_IMAGE_START_CAPTURE, m.MAV_CMD_IMAGE_STOP_CAPTURE,
        m.MAV_CMD_DO_TRIGGER_CONTROL, m.MAV_CMD_VIDEO_START_CAPTURE, m.MAV_CMD_VIDEO_STOP_CAPTURE,
        m.MAV_CMD_DO_WINCH, m.MAV_CMD_DO_SET_ROI_WPNEXT_OFFSET, m.MAV_CMD_DO_SET_ROI_NONE,
        CMD_DO_SET_ROI_LOCATION, *ROI_MODE_COMMANDS,
    )
)  # fmt: skip
MAX_JUMP_REPEATS = 10_000

FRAME_GLOBAL = m.MAV_FRAME_GLOBAL  # 0
FRAME_LOCAL_NED = m.MAV_FRAME_LOCAL_NED  # 1
FRAME_MISSION = m.MAV_FRAME_MISSION  # 2
FRAME_GLOBAL_RELATIVE_ALT = m.MAV_FRAME_GLOBAL_RELATIVE_ALT  # 3
FRAME_GLOBAL_INT = m.MAV_FRAME_GLOBAL_INT  # 5
FRAME_GLOBAL_RELATIVE_ALT_INT = m.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT  # 6

LOCAL_XY_SCALE = 1e-4  # MISSION_ITEM_INT x, y in local frames: metres * 1e4
GLOBAL_XY_SCALE = 1e-7  # degrees * 1e7

MAX_DISTANCE_M = 10_000.0  # sanity bound at parsing; NAV_REF_MAX_DIST is the rule (check_mission)
MIN_TIMED_GAP_S = 1e-3  # consecutive timed items at least this far apart (a curve is fitted to them)
MAX_ALTITUDE_M = 10_000.0  # |z| above this is refused
MAX_TIME_S = 86_400.0  # hold times and timed-item times beyond a day are refused
MAX_SPEED_M_S = 100.0


class WireItem(NamedTuple):
    """The fields of one MISSION_ITEM_INT exactly as received (float32 params, int32 x/y)."""

    seq: int
    frame: int
    command: int
    current: int
    autocontinue: int
    param1: float
    param2: float
    param3: float
    param4: float
    x: int
    y: int
    z: float
    mission_type: int = m.MAV_MISSION_TYPE_MISSION

    @property
    def slots(self) -> tuple[float, float, float, float, int, int, float]:
        """param1..param7 as MAVLink numbers them (param5/6: the int32 x, y)."""
        return (self.param1, self.param2, self.param3, self.param4, self.x, self.y, self.z)

    @classmethod
    def from_message(cls, msg) -> WireItem:
        """From a pymavlink MISSION_ITEM_INT."""
        return cls(
            msg.seq, msg.frame, msg.command, msg.current, msg.autocontinue,
            msg.param1, msg.param2, msg.param3, msg.param4, msg.x, msg.y, msg.z,
            getattr(msg, "mission_type", m.MAV_MISSION_TYPE_MISSION),
        )  # fmt: skip

    def to_message(self, target_system: int, target_component: int, current: int | None = None):
        """As a pymavlink MISSION_ITEM_INT addressed to a ground station (``current`` overrides)."""
        return m.MAVLink_mission_item_int_message(
            target_system, target_component, self.seq, self.frame, self.command,
            self.current if current is None else current, self.autocontinue,
            self.param1, self.param2, self.param3, self.param4, self.x, self.y, self.z,
            self.mission_type,
        )  # fmt: skip


class ItemKind(Enum):
    TAKEOFF = "takeoff"
    WAYPOINT = "waypoint"
    LOITER_TIME = "loiter_time"
    DELAY = "delay"
    CHANGE_SPEED = "change_speed"
    LAND = "land"
    RETURN_TO_LAUNCH = "return_to_launch"
    TIMED = "timed"
    JUMP = "jump"
    PAYLOAD = "payload"  # camera, gimbal, ROI, gripper, winch: a no-op on this vehicle
    # geofence and rally plans (autopilot.mission.plans)
    FENCE_POLYGON = "fence_polygon"
    FENCE_CIRCLE = "fence_circle"
    FENCE_RETURN_POINT = "fence_return_point"
    RALLY_POINT = "rally_point"


class PositionKind(Enum):
    LOCAL_NED = "local_ned"  # a, b, c = north, east, down (m) from the configured origin
    GLOBAL_AMSL = "global_amsl"  # a, b = lat, lon (deg); c = altitude above mean sea level (m)
    GLOBAL_RELATIVE = "global_relative"  # c = altitude above the vehicle's home (m)


@dataclass(frozen=True)
class ItemPosition:
    """A position as the item gives it; resolved to the paper frame when flown."""

    kind: PositionKind
    a: float
    b: float
    c: float  # NaN when the item leaves the altitude to the vehicle (takeoff, land)

    @property
    def horizontal_given(self) -> bool:
        """False for a global position at lat = lon = 0 (PX4: "here")."""
        return self.kind == PositionKind.LOCAL_NED or not (self.a == 0.0 and self.b == 0.0)

    def to_paper(self, origin: tuple[float, float, float], home_local: Vector3) -> Vector3:
        """Paper-frame position (m). ``origin`` = configured geodetic home (lat, lon deg, alt m
        AMSL) = the local frame's origin; ``home_local`` = the vehicle's home (paper frame, m)."""
        if self.kind == PositionKind.LOCAL_NED:
            return frames.vector_from_ned((self.a, self.b, self.c))
        north, east, _ = frames.geodetic_to_ned(self.a, self.b, origin[2], origin)
        x, y, _ = frames.vector_from_ned((north, east, 0.0))
        return (x, y, self.altitude_paper(origin, home_local))

    def altitude_paper(self, origin: tuple[float, float, float], home_local: Vector3) -> float:
        """Paper-frame z (m, up from the local origin); NaN if the item gives no altitude."""
        if self.kind == PositionKind.LOCAL_NED:
            return -self.c
        if self.kind == PositionKind.GLOBAL_AMSL:
            return self.c - origin[2]
        return home_local[2] + self.c


@dataclass(frozen=True)
class MissionItem:
    """One validated item (units: s, m, m/s, rad in the paper frame)."""

    seq: int
    kind: ItemKind
    wire: WireItem
    position: ItemPosition | None = None
    hold_s: float = 0.0  # waypoint hold / loiter time / delay
    acceptance_radius_m: float | None = None  # None: NAV_ACC_RAD
    yaw_rad: float | None = None  # paper frame (counter-clockwise from x); None: keep heading
    time_s: float | None = None  # TIMED: when to be there, seconds after the mission started
    speed_channel: int = 0  # CHANGE_SPEED: 1 horizontal, 2 climb, 3 descent
    speed_m_s: float | None = None  # CHANGE_SPEED: new speed; None: back to the default
    speed_unchanged: bool = False  # CHANGE_SPEED with speed -1
    jump_target: int = 0  # JUMP: the item to jump to
    jump_repeats: int = 0  # JUMP: how many times

    @property
    def autocontinue(self) -> bool:
        """The item's ``autocontinue`` flag: go on to the next item once this one is reached."""
        return bool(self.wire.autocontinue)


class ItemRejected(Exception):
    """An item the autopilot will not store: ``result`` is the MAV_MISSION_RESULT to answer."""

    def __init__(self, result: int, reason: str) -> None:
        super().__init__(reason)
        self.result = result
        self.reason = reason


_KINDS = {
    CMD_NAV_TAKEOFF: ItemKind.TAKEOFF,
    CMD_NAV_WAYPOINT: ItemKind.WAYPOINT,
    CMD_NAV_LOITER_TIME: ItemKind.LOITER_TIME,
    CMD_NAV_DELAY: ItemKind.DELAY,
    CMD_DO_CHANGE_SPEED: ItemKind.CHANGE_SPEED,
    CMD_NAV_LAND: ItemKind.LAND,
    CMD_NAV_RETURN_TO_LAUNCH: ItemKind.RETURN_TO_LAUNCH,
    CMD_TIMED: ItemKind.TIMED,
    CMD_DO_JUMP: ItemKind.JUMP,
    **{command: ItemKind.PAYLOAD for command in PAYLOAD_COMMANDS},
}
_POSITIONAL = {ItemKind.TAKEOFF, ItemKind.WAYPOINT, ItemKind.LOITER_TIME, ItemKind.LAND, ItemKind.TIMED}
_POSITION_FRAMES = {
    FRAME_LOCAL_NED: PositionKind.LOCAL_NED,
    FRAME_GLOBAL: PositionKind.GLOBAL_AMSL,
    FRAME_GLOBAL_INT: PositionKind.GLOBAL_AMSL,
    FRAME_GLOBAL_RELATIVE_ALT: PositionKind.GLOBAL_RELATIVE,
    FRAME_GLOBAL_RELATIVE_ALT_INT: PositionKind.GLOBAL_RELATIVE,
}
_ANY_FRAMES = {*_POSITION_FRAMES, FRAME_MISSION}

SUPPORTED_COMMANDS = frozenset(_KINDS)


def _invalid(result: int, reason: str) -> ItemRejected:
    return ItemRejected(result, reason)


# Slot n (1-7) -> the MAV_MISSION_RESULT naming it.
SLOT_RESULTS = (
    m.MAV_MISSION_INVALID_PARAM1, m.MAV_MISSION_INVALID_PARAM2, m.MAV_MISSION_INVALID_PARAM3,
    m.MAV_MISSION_INVALID_PARAM4, m.MAV_MISSION_INVALID_PARAM5_X, m.MAV_MISSION_INVALID_PARAM6_Y,
    m.MAV_MISSION_INVALID_PARAM7,
)  # fmt: skip


def check_unused_slots(wire: WireItem) -> None:
    """Raise ``INVALID_PARAMn`` for the first slot MAVLink leaves unused that holds a value."""
    problem = slots(wire.command).problem(wire.slots, integer_xy=True)
    if problem is not None:
        slot, reason = problem
        raise _invalid(SLOT_RESULTS[slot - 1], f"item {wire.seq}: {reason}")


def _optional_yaw(value: float, seq: int) -> float | None:
    """param4 yaw (deg, NED, clockwise) -> paper yaw (rad); NaN -> None (keep heading)."""
    if math.isnan(value):
        return None
    if not math.isfinite(value) or abs(value) > 360.0:
        raise _invalid(m.MAV_MISSION_INVALID_PARAM4, f"item {seq}: yaw {value} deg not in [-360, 360]")
    return frames.wrap_pi(frames.yaw_from_ned(math.radians(value)))


def _duration(value: float, seq: int, what: str, nan_ok: bool) -> float:
    if math.isnan(value) and nan_ok:
        return 0.0
    if not math.isfinite(value) or not 0.0 <= value <= MAX_TIME_S:
        raise _invalid(
            m.MAV_MISSION_INVALID_PARAM1, f"item {seq}: {what} {value} s not in [0, {MAX_TIME_S:g}]"
        )
    return float(value)


def _position(wire: WireItem, kind: ItemKind, origin: tuple[float, float, float]) -> ItemPosition:
    pkind = _POSITION_FRAMES[wire.frame]
    seq = wire.seq
    if pkind == PositionKind.LOCAL_NED:
        a, b = wire.x * LOCAL_XY_SCALE, wire.y * LOCAL_XY_SCALE
        if abs(a) > MAX_DISTANCE_M:
            raise _invalid(m.MAV_MISSION_INVALID_PARAM5_X, f"item {seq}: x {a:g} m farther than 10 km")
        if abs(b) > MAX_DISTANCE_M:
            raise _invalid(m.MAV_MISSION_INVALID_PARAM6_Y, f"item {seq}: y {b:g} m farther than 10 km")
    else:
        a, b = wire.x * GLOBAL_XY_SCALE, wire.y * GLOBAL_XY_SCALE
        if not -90.0 <= a <= 90.0:
            raise _invalid(m.MAV_MISSION_INVALID_PARAM5_X, f"item {seq}: latitude {a:g} deg")
        if not -180.0 <= b <= 180.0:
            raise _invalid(m.MAV_MISSION_INVALID_PARAM6_Y, f"item {seq}: longitude {b:g} deg")
    position = ItemPosition(pkind, a, b, float(wire.z))
    # Takeoff, and land at global lat = lon = 0, take their horizontal position from the vehicle:
    # only check the distance of positions that will be flown to.
    if kind != ItemKind.TAKEOFF and (kind != ItemKind.LAND or position.horizontal_given):
        x, y, _ = position.to_paper(origin, (0.0, 0.0, 0.0))
        distance_km = math.hypot(x, y) / 1000.0
        if distance_km > MAX_DISTANCE_M / 1000.0:
            raise _invalid(
                m.MAV_MISSION_INVALID_PARAM5_X,
                f"item {seq}: {distance_km:.1f} km from home (limit {MAX_DISTANCE_M / 1000:g} km)",
            )
    z = wire.z
    altitude_optional = kind in (ItemKind.TAKEOFF, ItemKind.LAND)
    if (math.isnan(z) and not altitude_optional) or (not math.isnan(z) and not abs(z) <= MAX_ALTITUDE_M):
        raise _invalid(m.MAV_MISSION_INVALID_PARAM7, f"item {seq}: altitude/z {z} m")
    return position


def parse_item(
    wire: WireItem, origin: tuple[float, float, float], previous: MissionItem | None = None
) -> MissionItem:
    """Validate one item and type it; raises :class:`ItemRejected` with the MAV_MISSION_RESULT.

    ``origin`` is the configured geodetic home (lat, lon deg, alt m); ``previous`` the item
    before it in the same upload (timed items must come in increasing time).
    """
    seq = wire.seq
    kind = _KINDS.get(wire.command)
    if kind is None:
        raise _invalid(m.MAV_MISSION_UNSUPPORTED, f"item {seq}: command {wire.command} not supported")
    check_unused_slots(wire)
    if kind == ItemKind.PAYLOAD:
        return _payload(wire, origin)
    frames_ok = _POSITION_FRAMES if kind in _POSITIONAL else _ANY_FRAMES
    if wire.frame not in frames_ok:
        raise _invalid(
            m.MAV_MISSION_UNSUPPORTED_FRAME, f"item {seq}: frame {wire.frame} not supported for {kind.value}"
        )
    p1, p2, p4 = wire.param1, wire.param2, wire.param4
    position = _position(wire, kind, origin) if kind in _POSITIONAL else None

    if kind == ItemKind.WAYPOINT or kind == ItemKind.TIMED:
        if math.isnan(p2) or p2 == 0.0:
            radius = None
        elif math.isfinite(p2) and 0.0 < p2 <= 1000.0:
            radius = float(p2)
        else:
            raise _invalid(m.MAV_MISSION_INVALID_PARAM2, f"item {seq}: acceptance radius {p2} m")
        yaw = _optional_yaw(p4, seq)
        if kind == ItemKind.WAYPOINT:
            hold = _duration(p1, seq, "hold time", nan_ok=True)
            return MissionItem(seq, kind, wire, position, hold, radius, yaw)
        time_s = _duration(p1, seq, "time", nan_ok=False)
        after_timed = previous is not None and previous.kind == ItemKind.TIMED
        if after_timed and time_s < previous.time_s + MIN_TIMED_GAP_S:
            raise _invalid(
                m.MAV_MISSION_INVALID_PARAM1,
                f"item {seq}: time {time_s:g} s not at least {MIN_TIMED_GAP_S * 1e3:g} ms after the "
                f"previous timed item's {previous.time_s:g} s",
            )
        return MissionItem(seq, kind, wire, position, 0.0, radius, yaw, time_s)
    if kind == ItemKind.LOITER_TIME:
        hold = _duration(p1, seq, "loiter time", nan_ok=False)
        return MissionItem(seq, kind, wire, position, hold)
    if kind == ItemKind.DELAY:
        # p1 = -1 means "until the time of day in p2..p4" (PX4): not offered here.
        hold = _duration(p1, seq, "delay", nan_ok=False)
        return MissionItem(seq, kind, wire, None, hold)
    if kind == ItemKind.TAKEOFF or kind == ItemKind.LAND:
        return MissionItem(seq, kind, wire, position, yaw_rad=_optional_yaw(p4, seq))
    if kind == ItemKind.CHANGE_SPEED:
        speed_type = int(p1) if math.isfinite(p1) and p1 == int(p1) else -1
        if speed_type not in (0, 1, 2, 3):
            raise _invalid(m.MAV_MISSION_INVALID_PARAM1, f"item {seq}: speed type {p1} not in 0..3")
        channel = 1 if speed_type in (0, 1) else speed_type  # airspeed = ground speed for a multicopter
        if p2 == -1.0:
            return MissionItem(seq, kind, wire, speed_channel=channel, speed_unchanged=True)
        if p2 == -2.0:
            return MissionItem(seq, kind, wire, speed_channel=channel, speed_m_s=None)
        if not (math.isfinite(p2) and 0.0 < p2 <= MAX_SPEED_M_S):
            raise _invalid(m.MAV_MISSION_INVALID_PARAM2, f"item {seq}: speed {p2} m/s")
        return MissionItem(seq, kind, wire, speed_channel=channel, speed_m_s=float(p2))
    if kind == ItemKind.JUMP:
        target, repeats = wire.param1, wire.param2
        if not (math.isfinite(target) and target == int(target) and 0 <= target < MAX_ITEMS_SEQ):
            raise _invalid(m.MAV_MISSION_INVALID_PARAM1, f"item {seq}: jump target {target} not an item")
        if int(target) == seq:
            raise _invalid(m.MAV_MISSION_INVALID_PARAM1, f"item {seq}: jump to itself")
        if not (math.isfinite(repeats) and repeats == int(repeats) and 0 <= repeats <= MAX_JUMP_REPEATS):
            raise _invalid(
                m.MAV_MISSION_INVALID_PARAM2,
                f"item {seq}: jump repeat count {repeats} not an integer in [0, {MAX_JUMP_REPEATS}]",
            )
        return MissionItem(seq, kind, wire, jump_target=int(target), jump_repeats=int(repeats))
    return MissionItem(seq, kind, wire)  # RETURN_TO_LAUNCH: no parameters


MAX_ITEMS_SEQ = 65_535  # a seq is uint16; the whole-mission check asks for a target in the mission
_ROI_MODES_MISSION_FRAME = (m.MAV_ROI_NONE, m.MAV_ROI_WPNEXT, m.MAV_ROI_WPINDEX)


def _payload(wire: WireItem, origin: tuple[float, float, float]) -> MissionItem:
    """A payload item: stored as received, flown as a no-op; refused as PX4 refuses it."""
    seq = wire.seq
    for i, value in enumerate((wire.param1, wire.param2, wire.param3, wire.param4)):
        if math.isinf(value):
            raise _invalid(SLOT_RESULTS[i], f"item {seq}: param{i + 1} is {value}")
    global_frame = wire.frame in _POSITION_FRAMES and wire.frame != FRAME_LOCAL_NED
    if wire.command == CMD_DO_SET_ROI_LOCATION or (
        wire.command in ROI_MODE_COMMANDS and global_frame and wire.param1 == m.MAV_ROI_LOCATION
    ):
        if not global_frame:
            raise _invalid(
                m.MAV_MISSION_UNSUPPORTED_FRAME, f"item {seq}: a region of interest needs a global frame"
            )
        _position(wire, ItemKind.WAYPOINT, origin)  # validated; not kept: nothing flies to it
        return MissionItem(seq, ItemKind.PAYLOAD, wire)
    if wire.command in ROI_MODE_COMMANDS and wire.param1 not in _ROI_MODES_MISSION_FRAME:
        raise _invalid(m.MAV_MISSION_INVALID_PARAM1, f"item {seq}: ROI mode {wire.param1} not supported")
    if wire.frame not in _ANY_FRAMES:
        raise _invalid(m.MAV_MISSION_UNSUPPORTED_FRAME, f"item {seq}: frame {wire.frame} not supported")
    if math.isinf(wire.z):
        raise _invalid(m.MAV_MISSION_INVALID_PARAM7, f"item {seq}: param7 is {wire.z}")
    return MissionItem(seq, ItemKind.PAYLOAD, wire)
