"""A frame's aiding into the filter, in PX4's order, written once: what the autopilot's estimator
loop (:meth:`~.eskf.ErrorStateEkf.fuse_frame`) and the campaign engine
(:func:`sitl.campaign.kernels.fuse_aiding`) both call.

PX4's EKF2 fuses, per IMU step, the magnetometer, then the barometer, then the GNSS, then external
vision; each fusion's own rate limits and gates live in :mod:`.fusion`, its quality checks in
:mod:`.checks`. A frame's samples come as one :class:`Aiding` record: every field a float or a
tuple of floats, a flag per sensor saying whether it delivered (compiled code has no ``None``).
"""

from __future__ import annotations

from typing import Any, NamedTuple

from quadcommon.kernel import kernel

from ..records import SensorSamples
from .filter import FilterArrays
from .fusion import (
    GnssMeasurement,
    VisionMeasurement,
    fuse_baro,
    fuse_gps,
    fuse_mag,
    fuse_vision,
    fuse_vision_velocity,
)

Vector3 = tuple[float, float, float]
Z3 = (0.0, 0.0, 0.0)


class Aiding(NamedTuple):
    """The aiding one frame delivered (paper frames, SI units), or one sample of it; a sensor's
    values are read only when its ``*_fresh`` flag is set. (A frame's vision is
    VISION_POSITION_ESTIMATE: a pose, no velocity; a client's ODOMETRY brings a velocity too.)"""

    mag_fresh: bool
    mag_gauss: Vector3  # body front-left-up
    baro_fresh: bool
    baro_height_m: float  # pressure altitude (any datum: the filter estimates the offset)
    gps_fresh: bool
    gps_position_m: Vector3  # world, about home
    gps_velocity_m_s: Vector3  # world
    gps_accuracy: Vector3  # eph (m), epv (m), speed accuracy (m/s; 0: unknown)
    gps_fix: tuple[float, float]  # fix type (GPS_FIX_TYPE), satellites visible
    vision_fresh: bool
    vision_position_m: Vector3  # world
    vision_yaw_rad: float
    vision_std: tuple[float, float]  # position (m), yaw (rad); 0: unknown
    vision_velocity_fresh: bool
    vision_velocity_m_s: Vector3  # world
    vision_velocity_std_m_s: float  # 0: unknown


NO_AIDING = Aiding(False, Z3, False, 0.0, False, Z3, Z3, Z3, (0.0, 0.0), False, Z3, 0.0, (0.0, 0.0),
                   False, Z3, 0.0)  # fmt: skip


def _floats(v: Any) -> Vector3:
    return (float(v[0]), float(v[1]), float(v[2]))


def aiding_of(samples: SensorSamples) -> Aiding:
    """A decoded frame's aiding (:class:`~autopilot.records.SensorSamples`) as the record the
    kernel takes, every number a float (one compiled signature)."""
    mag, baro, gps, vision = samples.mag_gauss, samples.baro_height_m, samples.gps, samples.vision
    return Aiding(
        mag is not None, _floats(mag) if mag is not None else Z3,
        baro is not None, float(baro) if baro is not None else 0.0,
        gps is not None,
        _floats(gps.position_m) if gps is not None else Z3,
        _floats(gps.velocity_m_s) if gps is not None else Z3,
        (float(gps.eph_m), float(gps.epv_m), float(gps.speed_accuracy_m_s)) if gps is not None else Z3,
        (float(gps.fix_type), float(gps.satellites_visible)) if gps is not None else (0.0, 0.0),
        vision is not None,
        _floats(vision.position_m) if vision is not None else Z3,
        float(vision.yaw_rad) if vision is not None else 0.0,
        (float(vision.position_std_m), float(vision.yaw_std_rad)) if vision is not None else (0.0, 0.0),
        False, Z3, 0.0,  # (a frame's vision is a pose)
    )  # fmt: skip


@kernel
def fuse_frame(memory: FilterArrays, A: Any, t: float, aiding: Aiding) -> None:
    """Fuse ``aiding`` at the time ``t`` of its IMU sample, in PX4's order: magnetometer,
    barometer, GNSS, vision (pose, then velocity), into the filter's ``memory`` with its
    parameters ``A`` (:mod:`.filter`'s layouts)."""
    if aiding.mag_fresh:
        fuse_mag(memory, A, t, aiding.mag_gauss)
    if aiding.baro_fresh:
        fuse_baro(memory, A, t, aiding.baro_height_m)
    if aiding.gps_fresh:
        eph, epv, speed_accuracy = aiding.gps_accuracy
        fix_type, satellites = aiding.gps_fix
        fuse_gps(memory, A, t, GnssMeasurement(aiding.gps_position_m, aiding.gps_velocity_m_s, eph, epv,
                                               speed_accuracy, fix_type, satellites))  # fmt: skip
    if aiding.vision_fresh:
        position_std, yaw_std = aiding.vision_std
        vision = VisionMeasurement(aiding.vision_position_m, aiding.vision_yaw_rad, position_std, yaw_std)
        fuse_vision(memory, A, t, vision)
    if aiding.vision_velocity_fresh:
        fuse_vision_velocity(memory, A, t, aiding.vision_velocity_m_s, aiding.vision_velocity_std_m_s)


@kernel
def fuse_frame_fields(memory: tuple, A: Any, t: float, fields: tuple) -> None:
    """:func:`fuse_frame` as the entry Python calls, for a frame's aiding and for each sample the
    filter is given on its own: the memory's arrays (a :class:`~.filter.FilterArrays`) and the
    :class:`Aiding` as plain tuples (a compiled call types a plain tuple in C, a named tuple through
    Python: microseconds a call)."""
    fuse_frame(FilterArrays(*memory), A, t, Aiding(*fields))
