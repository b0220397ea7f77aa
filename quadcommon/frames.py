"""The one place where signs flip: the paper's frames <-> MAVLink's NED/FRD.

Inside both processes: world x-forward(north)/y-left(west)/z-up, body front-left-up, ZYX Euler.
On the wire: world north-east-down, body front-right-down. The map between them is a rotation
by pi about x, ``F = diag(1, -1, -1)``, applied on both the world and the body side:

* vectors (position, velocity, acceleration, force, body rates, body torque): ``(x, -y, -z)``;
* Euler angles ``(phi, theta, psi)`` -> ``(phi, -theta, -psi)``;
* quaternion ``(w, x, y, z)`` -> ``(w, x, -y, -z)`` (``R_ned = F R F``).

Each map is its own inverse; the two names exist so call sites read in the right direction.
Scaled integers (mm, cdeg, 1e7 deg) are the concern of the MAVLink modules, not of this one.
"""

from __future__ import annotations

import math

from .kernel import kernel

Vector3 = tuple[float, float, float]
Quaternion = tuple[float, float, float, float]

# WGS-84 equatorial radius, as PX4's local projection uses.
EARTH_RADIUS_M = 6_378_137.0


@kernel
def vector_to_ned(v: Vector3) -> Vector3:
    """World (or body) vector from the paper's z-up frame to NED (or FRD)."""
    return (v[0], -v[1], -v[2])


@kernel
def vector_from_ned(v: Vector3) -> Vector3:
    """World (or body) vector from NED (or FRD) to the paper's z-up frame."""
    return (v[0], -v[1], -v[2])


@kernel
def euler_to_ned(eta: Vector3) -> Vector3:
    """ZYX Euler angles (roll, pitch, yaw) in the paper's frames to MAVLink's."""
    return (eta[0], -eta[1], -eta[2])


@kernel
def euler_from_ned(eta_ned: Vector3) -> Vector3:
    """MAVLink ZYX Euler angles (roll, pitch, yaw in NED/FRD) to the paper's."""
    return (eta_ned[0], -eta_ned[1], -eta_ned[2])


@kernel
def yaw_to_ned(psi: float) -> float:
    """Heading (yaw) from the paper's z-up frame to NED (same as the third Euler angle)."""
    return -psi


@kernel
def yaw_from_ned(yaw_ned: float) -> float:
    """Heading (yaw) from NED to the paper's z-up frame."""
    return -yaw_ned


def sticks_from_frd(
    forward: float, right: float, throttle: float, yaw_clockwise: float
) -> tuple[float, float, float, float]:
    """MANUAL_CONTROL's stick axes (x forward, y right, z thrust up, r yaw clockwise seen from
    above: the FRD body axes) to the paper's body axes (forward, left, up, yaw counter-clockwise)."""
    return (forward, -right, throttle, -yaw_clockwise)


@kernel
def quaternion_to_ned(q: Quaternion) -> Quaternion:
    """Attitude quaternion (w, x, y, z) from the paper's frames to NED/FRD."""
    return (q[0], q[1], -q[2], -q[3])


@kernel
def quaternion_from_ned(q_ned: Quaternion) -> Quaternion:
    """Attitude quaternion (w, x, y, z) from NED/FRD to the paper's frames."""
    return (q_ned[0], q_ned[1], -q_ned[2], -q_ned[3])


@kernel
def wrap_pi(angle: float) -> float:
    """Angle wrapped into [-pi, pi) (a kernel: the attitude laws and the campaign engine use it)."""
    return (angle + math.pi) % (2.0 * math.pi) - math.pi


@kernel
def home_terms(lat0_deg: float, lon0_deg: float) -> tuple[float, float, float]:
    """``(lon0 rad, sin lat0, cos lat0)`` of a home: the last three arguments of
    :func:`ned_to_geodetic_about` (a caller converting every frame computes them once)."""
    lat0_r = math.radians(lat0_deg)
    return math.radians(lon0_deg), math.sin(lat0_r), math.cos(lat0_r)


@kernel
def ned_to_geodetic(
    north_m: float, east_m: float, down_m: float, home: tuple[float, float, float]
) -> tuple[float, float, float]:
    """Local NED offset from ``home = (lat_deg, lon_deg, alt_m)`` to (lat_deg, lon_deg, alt_m).

    Azimuthal equidistant projection about home, as PX4's ``map_projection`` does; accurate to
    millimetres over the few kilometres a SITL flies.
    """
    lat0, lon0, alt0 = home[0], home[1], home[2]
    lon0_r, sin_lat0, cos_lat0 = home_terms(lat0, lon0)
    return ned_to_geodetic_about(north_m, east_m, down_m, lat0, lon0, alt0, lon0_r, sin_lat0, cos_lat0)


@kernel
def ned_to_geodetic_about(north_m: float, east_m: float, down_m: float, lat0: float, lon0: float,
                          alt0: float, lon0_r: float, sin_lat0: float,
                          cos_lat0: float) -> tuple[float, float, float]:  # fmt: skip
    """:func:`ned_to_geodetic` with the home's terms (:func:`home_terms`) computed beforehand."""
    x_rad = north_m / EARTH_RADIUS_M
    y_rad = east_m / EARTH_RADIUS_M
    c = math.hypot(x_rad, y_rad)
    if c == 0.0:
        return (lat0, lon0, alt0 - down_m)
    sin_c, cos_c = math.sin(c), math.cos(c)
    lat = math.asin(cos_c * sin_lat0 + (x_rad * sin_c * cos_lat0) / c)
    lon = lon0_r + math.atan2(y_rad * sin_c, c * cos_lat0 * cos_c - x_rad * sin_lat0 * sin_c)
    return (math.degrees(lat), math.degrees(lon), alt0 - down_m)


@kernel
def geodetic_to_ned(
    lat_deg: float, lon_deg: float, alt_m: float, home: tuple[float, float, float]
) -> tuple[float, float, float]:
    """(lat_deg, lon_deg, alt_m) to the local NED offset from ``home`` (inverse of the above)."""
    return geodetic_to_ned_about(lat_deg, lon_deg, alt_m, home[0], home[1], home[2])


@kernel
def geodetic_to_ned_about(lat_deg: float, lon_deg: float, alt_m: float, lat0: float, lon0: float,
                          alt0: float) -> tuple[float, float, float]:  # fmt: skip
    """:func:`geodetic_to_ned` (a kernel: the campaign engine carries GNSS fixes across the wire)."""
    lat0_r, lon0_r = math.radians(lat0), math.radians(lon0)
    lat_r, lon_r = math.radians(lat_deg), math.radians(lon_deg)
    sin_lat0, cos_lat0 = math.sin(lat0_r), math.cos(lat0_r)
    sin_lat, cos_lat = math.sin(lat_r), math.cos(lat_r)
    cos_dlon = math.cos(lon_r - lon0_r)
    arg = max(-1.0, min(1.0, sin_lat0 * sin_lat + cos_lat0 * cos_lat * cos_dlon))
    c = math.acos(arg)
    k = c / math.sin(c) if abs(c) > 1e-12 else 1.0
    north = k * (cos_lat0 * sin_lat - sin_lat0 * cos_lat * cos_dlon) * EARTH_RADIUS_M
    east = k * cos_lat * math.sin(lon_r - lon0_r) * EARTH_RADIUS_M
    return (north, east, alt0 - alt_m)
