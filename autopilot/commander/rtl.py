"""Where RTL returns to and at what altitude: PX4's ``RTL_TYPE`` with rally points (pure).

* ``RTL_TYPE`` 0 (PX4's default) and 3: the closest, horizontally, of home and the rally points
  (3 would also weigh a mission landing pattern, which missions here do not have);
* 1: the closest rally point, home if there is none;
* 5: the closest rally point; with none, the vehicle lands where it is.

The return altitude is counted from the destination, as PX4's: ``max(current altitude,
destination altitude + RTL_RETURN_ALT)``, the destination's altitude being home's or the rally
point's (its item's altitude; a relative one above home). The vehicle climbs to it, flies there
and lands (a rally point's altitude only raises the return: the ground is flat here, so the
landing goes on down to it).
"""

from __future__ import annotations

import math
from typing import NamedTuple

from ..mission.plans import RallyPoint
from ..params.definitions import RTL_RALLY_ONLY, RTL_RALLY_OR_HOME

Vector3 = tuple[float, float, float]


class Destination(NamedTuple):
    position_m: Vector3  # x, y of the destination; z its altitude (paper frame)
    name: str  # "launch", "rally point K", or "here" (RTL_TYPE 5 without rally points)


def return_destination(
    rtl_type: int, position: Vector3, home: Vector3, rally_points: list[RallyPoint]
) -> Destination:
    """Where RTL goes from ``position`` (paper frame, m)."""
    best: Destination | None = None
    best_distance = math.inf
    for k, rally in enumerate(rally_points):
        d = math.hypot(position[0] - rally.x, position[1] - rally.y)
        if d < best_distance:
            best, best_distance = Destination((rally.x, rally.y, rally.z(home)), f"rally point {k}"), d
    if rtl_type in (RTL_RALLY_OR_HOME, RTL_RALLY_ONLY) and best is not None:
        return best
    if rtl_type == RTL_RALLY_ONLY:
        return Destination((position[0], position[1], home[2]), "here")
    if best is not None and best_distance < math.hypot(position[0] - home[0], position[1] - home[1]):
        return best
    return Destination(home, "launch")


def return_altitude(current_z: float, destination: Destination, return_alt: float) -> float:
    """PX4: at least RTL_RETURN_ALT above the destination, and never below the current altitude."""
    return max(current_z, destination.position_m[2] + return_alt)
