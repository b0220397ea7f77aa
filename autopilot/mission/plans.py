"""Geofence and rally plans (MAV_MISSION_TYPE_FENCE, MAV_MISSION_TYPE_RALLY): items and geometry (pure).

They travel through the same mission protocol as the mission (:mod:`.protocol`), each type stored
on its own, and go back on download exactly as uploaded (the stored wire fields).

Fence items (PX4's set), in ``MAV_FRAME_GLOBAL(_INT)`` or ``MAV_FRAME_GLOBAL_RELATIVE_ALT(_INT)``
(the fence is horizontal, ``GF_MAX_VER_DIST`` limits the height; MAVLink reserves the polygons' and
circles' z, which must be 0 or NaN like every slot MAVLink leaves unused, see
:mod:`autopilot.mission.items`):

=====================================  =====  ===================================================
NAV_FENCE_POLYGON_VERTEX_INCLUSION     5001   p1 = vertex count n (>= 3); n consecutive items of
NAV_FENCE_POLYGON_VERTEX_EXCLUSION     5002   the same command and count form one polygon
NAV_FENCE_CIRCLE_INCLUSION             5003   p1 = radius (m) about x, y; a radius <= 0 is no
NAV_FENCE_CIRCLE_EXCLUSION             5004   circle: accepted, stored, ignored (MAVSDK sends
                                              ``Circle(Point(0, 0), 0)`` for "no circle")
NAV_FENCE_RETURN_POINT                 5000   stored (PX4 accepts it); not used: a breach acts by
                                              ``GF_ACTION``
=====================================  =====  ===================================================

Rally items: NAV_RALLY_POINT (5100), global frames, x, y, z = latitude, longitude, altitude: RTL's
destinations (``RTL_TYPE``), the altitude being the destination's, which the return altitude is
counted from (:class:`RallyPoint`).

Enforcement, as PX4's ``Geofence``: with inclusion areas the vehicle must be inside at least one of
them, and inside none of the exclusion areas. :meth:`Geofence.excess` gives how far outside the
vehicle is (m, <= 0 inside), so the failsafe monitor treats it like the ``GF_MAX_*`` limits (the
worst of all counts, breach -> ``GF_ACTION``, re-armed once back inside by a margin).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from quadcommon import frames

from ..mavlink.codec import mavlink as m
from .items import (
    _POSITION_FRAMES,
    FRAME_LOCAL_NED,
    GLOBAL_XY_SCALE,
    MAX_ALTITUDE_M,
    MAX_DISTANCE_M,
    ItemKind,
    ItemPosition,
    ItemRejected,
    MissionItem,
    PositionKind,
    WireItem,
    check_unused_slots,
)

Vector2 = tuple[float, float]
Vector3 = tuple[float, float, float]

CMD_FENCE_RETURN_POINT = m.MAV_CMD_NAV_FENCE_RETURN_POINT  # 5000
CMD_POLYGON_INCLUSION = m.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_INCLUSION  # 5001
CMD_POLYGON_EXCLUSION = m.MAV_CMD_NAV_FENCE_POLYGON_VERTEX_EXCLUSION  # 5002
CMD_CIRCLE_INCLUSION = m.MAV_CMD_NAV_FENCE_CIRCLE_INCLUSION  # 5003
CMD_CIRCLE_EXCLUSION = m.MAV_CMD_NAV_FENCE_CIRCLE_EXCLUSION  # 5004
CMD_RALLY_POINT = m.MAV_CMD_NAV_RALLY_POINT  # 5100

MAX_VERTICES = 1000
MAX_RADIUS_M = MAX_DISTANCE_M

_FENCE_KINDS = {
    CMD_FENCE_RETURN_POINT: ItemKind.FENCE_RETURN_POINT,
    CMD_POLYGON_INCLUSION: ItemKind.FENCE_POLYGON,
    CMD_POLYGON_EXCLUSION: ItemKind.FENCE_POLYGON,
    CMD_CIRCLE_INCLUSION: ItemKind.FENCE_CIRCLE,
    CMD_CIRCLE_EXCLUSION: ItemKind.FENCE_CIRCLE,
}
FENCE_COMMANDS = frozenset(_FENCE_KINDS)
RALLY_COMMANDS = frozenset((CMD_RALLY_POINT,))
_GLOBAL_FRAMES = {f for f in _POSITION_FRAMES if f != FRAME_LOCAL_NED}


def _global_position(wire: WireItem) -> ItemPosition:
    seq = wire.seq
    if wire.frame not in _GLOBAL_FRAMES:
        raise ItemRejected(m.MAV_MISSION_UNSUPPORTED_FRAME, f"item {seq}: frame {wire.frame}, not global")
    lat, lon = wire.x * GLOBAL_XY_SCALE, wire.y * GLOBAL_XY_SCALE
    if not -90.0 <= lat <= 90.0:
        raise ItemRejected(m.MAV_MISSION_INVALID_PARAM5_X, f"item {seq}: latitude {lat:g} deg")
    if not -180.0 <= lon <= 180.0:
        raise ItemRejected(m.MAV_MISSION_INVALID_PARAM6_Y, f"item {seq}: longitude {lon:g} deg")
    if not (math.isnan(wire.z) or abs(wire.z) <= MAX_ALTITUDE_M):
        raise ItemRejected(m.MAV_MISSION_INVALID_PARAM7, f"item {seq}: altitude {wire.z} m")
    return ItemPosition(_POSITION_FRAMES[wire.frame], lat, lon, float(wire.z))


def _far(position: ItemPosition, origin: tuple[float, float, float], seq: int) -> None:
    x, y, _ = position.to_paper(origin, (0.0, 0.0, 0.0))
    if math.hypot(x, y) > MAX_DISTANCE_M:
        raise ItemRejected(
            m.MAV_MISSION_INVALID_PARAM5_X, f"item {seq}: farther than {MAX_DISTANCE_M / 1000:g} km from home"
        )


def parse_fence_item(wire: WireItem, origin: tuple[float, float, float]) -> MissionItem:
    """One fence item, validated (the polygons' vertex counts are checked by :func:`check_fence`)."""
    seq = wire.seq
    kind = _FENCE_KINDS.get(wire.command)
    if kind is None:
        raise ItemRejected(m.MAV_MISSION_UNSUPPORTED, f"fence item {seq}: command {wire.command} unsupported")
    check_unused_slots(wire)
    position = _global_position(wire)
    p1 = wire.param1
    if kind == ItemKind.FENCE_POLYGON:
        if not (math.isfinite(p1) and p1 == int(p1) and 3 <= p1 <= MAX_VERTICES):
            raise ItemRejected(
                m.MAV_MISSION_INVALID_PARAM1, f"fence item {seq}: vertex count {p1} not in 3..{MAX_VERTICES}"
            )
    elif kind == ItemKind.FENCE_CIRCLE and not (math.isfinite(p1) and p1 <= MAX_RADIUS_M):
        why = f"fence item {seq}: radius {p1} m not finite or > 10 km"
        raise ItemRejected(m.MAV_MISSION_INVALID_PARAM1, why)
    if not _no_circle(kind, p1):  # "no circle" may sit anywhere (MAVSDK puts it at 0, 0)
        _far(position, origin, seq)
    return MissionItem(seq, kind, wire, position)


def _no_circle(kind: ItemKind, radius: float) -> bool:
    return kind == ItemKind.FENCE_CIRCLE and radius <= 0.0


def fence_notes(items: Sequence[MissionItem]) -> list[str]:
    """What an accepted fence upload holds that is not enforced: circles of radius <= 0."""
    ignored = [str(it.seq) for it in items if _no_circle(it.kind, it.wire.param1)]
    if not ignored:
        return []
    which = "item " + ignored[0] if len(ignored) == 1 else "items " + ", ".join(ignored)
    return [f"geofence {which}: a circle of radius <= 0 is no circle, ignored"]


def parse_rally_item(wire: WireItem, origin: tuple[float, float, float]) -> MissionItem:
    """A rally plan's item decoded and checked (NAV_RALLY_POINT, global frame, within range of home);
    ItemRejected with its MAV_MISSION_RESULT otherwise."""
    seq = wire.seq
    if wire.command != CMD_RALLY_POINT:
        raise ItemRejected(m.MAV_MISSION_UNSUPPORTED, f"rally item {seq}: command {wire.command} unsupported")
    check_unused_slots(wire)
    position = _global_position(wire)
    _far(position, origin, seq)
    return MissionItem(seq, ItemKind.RALLY_POINT, wire, position)


def check_fence(items: Sequence[MissionItem]) -> tuple[int, str] | None:
    """Polygons: each vertex count n followed by exactly n vertices of the same kind and count."""
    seq = 0
    while seq < len(items):
        it = items[seq]
        if it.kind != ItemKind.FENCE_POLYGON:
            seq += 1
            continue
        n = int(it.wire.param1)
        block = items[seq : seq + n]
        same = all(
            b.kind == ItemKind.FENCE_POLYGON and b.wire.command == it.wire.command and int(b.wire.param1) == n
            for b in block
        )
        if len(block) < n or not same:
            return (
                m.MAV_MISSION_INVALID_PARAM1,
                f"fence items {seq}-{seq + n - 1}: a polygon of {n} vertices needs {n} such items in a row",
            )
        seq += n
    return None


@dataclass(frozen=True)
class Area:
    inclusion: bool
    polygon: tuple[Vector2, ...] = ()  # paper frame x, y (m); empty for a circle
    centre: Vector2 = (0.0, 0.0)
    radius_m: float = 0.0

    def signed_distance(self, p: Vector2) -> float:
        """Distance to the boundary (m): > 0 outside, <= 0 inside."""
        if not self.polygon:
            return math.dist(p, self.centre) - self.radius_m
        edges = zip(self.polygon, self.polygon[1:] + self.polygon[:1], strict=True)
        edge = min(_segment_distance(p, a, b) for a, b in edges)
        return -edge if _inside(p, self.polygon) else edge


def _segment_distance(p: Vector2, a: Vector2, b: Vector2) -> float:
    ax, ay = b[0] - a[0], b[1] - a[1]
    length2 = ax * ax + ay * ay
    u = 0.0 if length2 == 0.0 else max(0.0, min(1.0, ((p[0] - a[0]) * ax + (p[1] - a[1]) * ay) / length2))
    return math.dist(p, (a[0] + u * ax, a[1] + u * ay))


def _inside(p: Vector2, polygon: Sequence[Vector2]) -> bool:
    """Even-odd rule (ray casting)."""
    x, y = p
    inside = False
    for (x1, y1), (x2, y2) in zip(polygon, [*polygon[1:], polygon[0]], strict=True):
        if (y1 > y) != (y2 > y) and x < x1 + (y - y1) * (x2 - x1) / (y2 - y1):
            inside = not inside
    return inside


@dataclass(frozen=True)
class Geofence:
    """Inclusion and exclusion areas in the paper frame (resolved against the configured origin)."""

    areas: tuple[Area, ...] = ()

    @classmethod
    def from_items(cls, items: Sequence[MissionItem], origin: tuple[float, float, float]) -> Geofence:
        areas: list[Area] = []
        seq = 0
        while seq < len(items):
            it = items[seq]
            if it.kind == ItemKind.FENCE_POLYGON:
                n = int(it.wire.param1)
                vertices = tuple(_xy(b, origin) for b in items[seq : seq + n])
                areas.append(Area(it.wire.command == CMD_POLYGON_INCLUSION, vertices))
                seq += n
                continue
            if it.kind == ItemKind.FENCE_CIRCLE and not _no_circle(it.kind, it.wire.param1):
                inclusion = it.wire.command == CMD_CIRCLE_INCLUSION
                areas.append(Area(inclusion, centre=_xy(it, origin), radius_m=float(it.wire.param1)))
            seq += 1
        return cls(tuple(areas))

    def excess(self, position: Vector3) -> tuple[float, str]:
        """How far outside the fence ``position`` is (m, <= 0 inside; -inf without areas) and why."""
        p = (position[0], position[1])
        worst, what = -math.inf, ""
        inclusions = [a.signed_distance(p) for a in self.areas if a.inclusion]
        if inclusions:
            d = min(inclusions)
            worst, what = d, f"{d:.1f} m outside the fence's inclusion area"
        for a in self.areas:
            if not a.inclusion:
                d = -a.signed_distance(p)
                if d > worst:
                    worst, what = d, f"{d:.1f} m inside an exclusion area of the fence"
        return worst, what


def _xy(item: MissionItem, origin: tuple[float, float, float]) -> Vector2:
    assert item.position is not None
    north, east, _ = frames.geodetic_to_ned(item.position.a, item.position.b, origin[2], origin)
    x, y, _ = frames.vector_from_ned((north, east, 0.0))
    return (x, y)


@dataclass(frozen=True)
class RallyPoint:
    """A rally point in the paper frame: x, y (m) and its altitude as the item gives it, resolved
    against the home of the moment (a relative altitude follows home, as PX4 reads it at RTL)."""

    x: float
    y: float
    altitude_m: float  # above home if ``relative``, else the paper frame's z (up from the origin)
    relative: bool

    def z(self, home: Vector3) -> float:
        """The point's height in the paper frame (m, up), a relative altitude taken above ``home``."""
        return home[2] + self.altitude_m if self.relative else self.altitude_m


def rally_points(items: Sequence[MissionItem], origin: tuple[float, float, float]) -> list[RallyPoint]:
    """The rally plan's points (global frames; an altitude not given is home's)."""
    points = []
    for it in items:
        position = it.position
        if position is None:
            continue
        x, y, _ = position.to_paper(origin, (0.0, 0.0, 0.0))
        if math.isnan(position.c):
            points.append(RallyPoint(x, y, 0.0, True))
        elif position.kind == PositionKind.GLOBAL_AMSL:
            points.append(RallyPoint(x, y, position.c - origin[2], False))
        else:
            points.append(RallyPoint(x, y, position.c, True))
    return points
