"""What the estimator reports: the state estimate, and ESTIMATOR_STATUS-like health figures.

:class:`Estimate` is read every control step (cheap); :class:`EstimatorStatus` at telemetry rate
(it walks the per-sensor counters). The flag bits are MAVLink's ``ESTIMATOR_STATUS_FLAGS`` so the
autopilot can send them unchanged; the test ratios are PX4's: ``innovation^2 / (gate^2 * S)``
with ``S`` the innovation variance, so a sample passes its gate when the ratio is <= 1.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

from quadcommon.layout import Field, fields_of, layout

Vector3 = tuple[float, float, float]
Quaternion = tuple[float, float, float, float]

# MAVLink ESTIMATOR_STATUS_FLAGS (common.xml).
ESTIMATOR_ATTITUDE = 1
ESTIMATOR_VELOCITY_HORIZ = 2
ESTIMATOR_VELOCITY_VERT = 4
ESTIMATOR_POS_HORIZ_REL = 8
ESTIMATOR_POS_HORIZ_ABS = 16
ESTIMATOR_POS_VERT_ABS = 32
ESTIMATOR_POS_VERT_AGL = 64
ESTIMATOR_CONST_POS_MODE = 128
ESTIMATOR_PRED_POS_HORIZ_REL = 256
ESTIMATOR_PRED_POS_HORIZ_ABS = 512
ESTIMATOR_GPS_GLITCH = 1024
ESTIMATOR_ACCEL_ERROR = 2048

# The fused measurement kinds: the rows of the filter's per-source figures (``stats``), in this
# order, and the keys of EstimatorStatus.sources.
SOURCE = layout("MeasurementKinds", (
    Field("gps_pos", doc="GNSS horizontal position"),
    Field("gps_hgt", doc="GNSS height"),
    Field("gps_vel", doc="GNSS horizontal velocity"),
    Field("gps_vvel", doc="GNSS vertical velocity (gated apart from the horizontal)"),
    Field("baro", doc="barometric height"),
    Field("mag", doc="3-axis magnetometer field (EKF2_MAG_TYPE 0)"),
    Field("heading", doc="tilt-compensated magnetic heading (EKF2_MAG_TYPE 1)"),
    Field("ev_pos", doc="external vision horizontal position"),
    Field("ev_hgt", doc="external vision height"),
    Field("ev_yaw", doc="external vision yaw"),
    Field("ev_vel", doc="external vision velocity"),
))  # fmt: skip
SOURCE_NAMES = tuple(f.name for f in fields_of(SOURCE))


class Estimate(NamedTuple):
    """The filter's state at ``time_s`` (paper frames, SI); what the controllers are fed."""

    time_s: float
    position_m: Vector3  # world, of O
    velocity_m_s: Vector3  # world
    quaternion: Quaternion  # (w, x, y, z), body to world
    euler_rad: Vector3  # ZYX (phi, theta, psi)
    body_rates_rad_s: Vector3  # the last gyro sample minus the estimated bias
    euler_rates_rad_s: Vector3  # W_eta^-1 of the body rates (eq. 3)
    gyro_bias_rad_s: Vector3
    accel_bias_m_s2: Vector3
    mag_bias_gauss: Vector3
    baro_offset_m: float  # baro height minus the filter's z


@dataclass
class SourceStats:
    """Counters and the last innovation test of one measurement kind."""

    fused: int = 0
    rejected: int = 0  # by the innovation gate
    check_rejected: int = 0  # by a quality check (GPS fix quality, magnetic field checks)
    too_old: int = 0  # valid before the oldest buffered state
    skipped: int = 0  # not fused: above the kind's fusion rate (EKF2_MAG_RATE, EKF2_BARO_RATE)
    test_ratio: float = 0.0  # of the last sample tested
    innovation: float = 0.0  # of the last sample tested (its last axis): measured - predicted
    normalized_innovation: float = 0.0  # innovation / sqrt(S) of that axis
    last_tested_s: float = -1.0
    last_fused_s: float = -1.0
    last_rejected_s: float = -1.0
    rejecting_since_s: float = -1.0  # start of the current run of gate rejections (-1: none)
    resets: int = 0  # state resets to this source after a long run of rejections


class EstimatorStatus(NamedTuple):
    """ESTIMATOR_STATUS-like figures plus the pre-arm verdict (``converged`` and ``reason``)."""

    time_s: float
    initialised: bool  # alignment done: attitude, position and velocity are estimated
    converged: bool  # fit to fly on: uncertainties below the EST_CONV_* thresholds, aided
    reason: str  # why not converged ('' when converged)
    flags: int  # ESTIMATOR_STATUS_FLAGS bits
    vel_ratio: float  # ESTIMATOR_STATUS fields: largest recent test ratio per kind
    pos_horiz_ratio: float
    pos_vert_ratio: float
    mag_ratio: float
    pos_horiz_accuracy_m: float  # sqrt(Pxx + Pyy)
    pos_vert_accuracy_m: float  # sqrt(Pzz)
    vel_accuracy_m_s: float  # sqrt(Pvx + Pvy + Pvz)
    tilt_accuracy_rad: float  # sqrt(P_theta_x + P_theta_y), world frame
    yaw_accuracy_rad: float  # sqrt(P_theta_z)
    gps_glitch: bool  # GPS position rejected by its gate within the last second
    dead_reckoning: bool  # no horizontal position/velocity aiding for EKF2_NOAID_TOUT
    sources: dict[str, SourceStats]
    imu_samples: int
    imu_dt_rejected: int  # IMU samples not integrated (dt <= 0 or > 0.1 s)
