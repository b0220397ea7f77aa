"""The records the autopilot's rooms pass each other, low in the house so that every room may
import them: what the controllers see (:class:`StateEstimate`), what an estimator reads of one
lockstep frame (:class:`SensorSamples`), and what the estimator is fed, one record per sample, in
the paper's frames and SI units.

World frame x north / y west / z up, body front-left-up (the autopilot's MAVLink edge turns
HIL_SENSOR / HIL_GPS / vision messages into these). ``time_s`` is when the sample *arrived*
(simulation seconds, the frame's ``time_usec``), exactly what the autopilot knows; the filter
takes a delayed sensor's sample as valid at ``time_s`` minus that sensor's delay parameter
(EKF2_GPS_DELAY, EKF2_EV_DELAY, EKF2_BARO_DELAY, EKF2_MAG_DELAY), as PX4 does, and fuses it
against the state it buffered for that time. Plain named tuples: cheap to build per step.
"""

from __future__ import annotations

from typing import NamedTuple

Vector3 = tuple[float, float, float]

GPS_FIX_3D = 3  # MAVLink GPS_FIX_TYPE_3D_FIX; lower values are not fused


class ImuSample(NamedTuple):
    """One IMU sample: the control step's angular rate and specific force (instantaneous)."""

    time_s: float
    dt_s: float  # time since the previous sample (the integration interval)
    angular_rate_rad_s: Vector3  # body, front-left-up
    specific_force_m_s2: Vector3  # body, front-left-up; +g upward at rest


class GpsFix(NamedTuple):
    """A GNSS fix of the vehicle's origin O, local frame about home."""

    time_s: float
    position_m: Vector3  # world (x north, y west, z up), relative to home
    velocity_m_s: Vector3  # world
    eph_m: float  # reported 1-sigma horizontal position accuracy (per axis)
    epv_m: float  # reported 1-sigma vertical position accuracy
    speed_accuracy_m_s: float = 0.0  # reported 1-sigma speed accuracy (0: unknown)
    fix_type: int = GPS_FIX_3D
    satellites_visible: int = 10


class BaroSample(NamedTuple):
    """Barometric (pressure) altitude; any datum: the filter estimates the offset to its z."""

    time_s: float
    height_m: float


class MagSample(NamedTuple):
    """Magnetometer field, body frame (front-left-up), gauss."""

    time_s: float
    field_gauss: Vector3


class VisionPose(NamedTuple):
    """Motion capture / vision: position of O and yaw, with the source's reported accuracy; and
    the velocity, when the source gives one (a client's ODOMETRY)."""

    time_s: float
    position_m: Vector3  # world
    yaw_rad: float  # the paper's psi (ZYX Euler, z up, counter-clockwise from north)
    position_std_m: float = 0.0  # reported 1-sigma per axis (0: unknown)
    yaw_std_rad: float = 0.0
    velocity_m_s: Vector3 | None = None  # world, of O; None: not given
    velocity_std_m_s: float = 0.0  # reported 1-sigma per axis (0: unknown)


class StateEstimate(NamedTuple):
    """What the controllers see (paper frames): position/velocity of O, Euler angles and rates."""

    position_m: Vector3
    velocity_m_s: Vector3
    euler_rad: Vector3
    euler_rates_rad_s: Vector3


# The sensor streams a frame can deliver, one bit each (SensorSamples.streams, frame_streams).
STREAM_IMU, STREAM_MAG, STREAM_BARO, STREAM_GPS, STREAM_VISION = 1, 2, 4, 8, 16


class SensorSamples(NamedTuple):
    """What an estimator reads of one lockstep frame, in the paper's frames and SI units; None
    where the frame holds no new sample (the simulator's rates and latencies decide)."""

    angular_rate_rad_s: Vector3  # body front-left-up
    specific_force_m_s2: Vector3  # body front-left-up, +g upward at rest
    mag_gauss: Vector3 | None  # body front-left-up; None unless fields_updated has the mag bits
    baro_height_m: float | None  # pressure altitude (m AMSL); None unless fields_updated says fresh
    gps: GpsFix | None  # HIL_GPS, relative to home
    vision: VisionPose | None  # VISION_POSITION_ESTIMATE
    # What the edge refused of this frame (a non-finite value: never fed to the filter), by name:
    # "imu" (then the two IMU vectors are not to be used), "mag", "baro", "vision".
    refused: tuple[str, ...] = ()
    # HIL_SENSOR's accelerometer and gyro bits (fields_updated 0-5) all set: the IMU sampled this
    # frame; else it holds an old sample (a failure stopped it) and the two vectors are not new.
    imu_fresh: bool = True

    @property
    def streams(self) -> int:
        """The streams that delivered a sample (``STREAM_*`` bits; a refused sample is none)."""
        refused = self.refused
        bits = STREAM_IMU if self.imu_fresh and "imu" not in refused else 0
        if self.mag_gauss is not None:
            bits |= STREAM_MAG
        if self.baro_height_m is not None:
            bits |= STREAM_BARO
        if self.gps is not None:
            bits |= STREAM_GPS
        if self.vision is not None:
            bits |= STREAM_VISION
        return bits
