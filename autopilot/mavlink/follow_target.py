"""FOLLOW_TARGET from a ground station (follow-me), checked at the edge: wire -> commander.

PX4's receiver takes the target's latitude/longitude (1e-7 deg), altitude (m AMSL) and, when
``est_capabilities`` bit 1 says so, its velocity (m/s, NED). Here a message is refused (counted,
said by a rate-limited STATUSTEXT, never fatal) when a coordinate is out of range, a value it uses
is not finite, or the target is farther from home than ``NAV_REF_MAX_DIST`` (the one distance
rule of setpoints and mission items: :func:`~.validation.reference_problem`). The position becomes
the local paper frame through :mod:`quadcommon.frames`, as a mission item's does.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from quadcommon import frames

from ..guidance.follow import TargetReport
from .validation import reference_problem

Vector3 = tuple[float, float, float]
EST_VELOCITY = 1 << 1  # FOLLOW_TARGET.est_capabilities: the velocity is valid (MAVLink)
ALTITUDE_RANGE_M = (-1000.0, 10000.0)  # AMSL, as the commands' altitudes


def decode_follow_target(msg, t: float, origin: tuple[float, float, float], home: Vector3,
                         params: Mapping[str, float]) -> tuple[TargetReport | None, str]:  # fmt: skip
    """(report, "") or (None, reason). ``origin``: the local frame's geodetic origin; ``home``: the
    vehicle's home (paper frame, m); ``t``: simulation time of arrival."""
    lat, lon, alt = msg.lat * 1e-7, msg.lon * 1e-7, msg.alt
    if not (-90.0 <= lat <= 90.0 and -180.0 <= lon <= 180.0):
        return None, f"latitude {lat:g}, longitude {lon:g} invalid"
    if not (isinstance(alt, float | int) and ALTITUDE_RANGE_M[0] <= alt <= ALTITUDE_RANGE_M[1]):
        return None, f"altitude {alt!r} not in [{ALTITUDE_RANGE_M[0]:g}, {ALTITUDE_RANGE_M[1]:g}] m"
    velocity = None
    if msg.est_capabilities & EST_VELOCITY:
        vel = tuple(msg.vel)
        if len(vel) != 3 or not all(math.isfinite(v) and abs(v) <= 100.0 for v in vel):
            return None, f"velocity {vel!r} not finite or beyond 100 m/s"
        velocity = frames.vector_from_ned(vel)  # type: ignore[arg-type]
    position = frames.vector_from_ned(frames.geodetic_to_ned(lat, lon, alt, origin))
    problem = reference_problem(position, home, params)
    if problem:
        return None, f"target {problem}"
    return TargetReport(t, position, velocity), ""
