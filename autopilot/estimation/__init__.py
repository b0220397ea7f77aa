"""State estimation (pure: no sockets, no clocks; time comes in with every sample).

An error-state EKF (:class:`ErrorStateEkf`, Solà 2017) over the IMU, GNSS, barometer,
magnetometer and motion capture / vision, with PX4 EKF2 parameter names (:mod:`.parameters`).
"""

from ..records import BaroSample, GpsFix, ImuSample, MagSample, VisionPose
from .eskf import ErrorStateEkf
from .kernels import STATE_NAMES
from .parameters import (
    DEFAULT_PARAMS,
    ESTIMATOR_PARAMS,
    EstimatorParams,
    estimator_params,
    estimator_store,
    load_estimator_params,
)
from .status import Estimate, EstimatorStatus, SourceStats

__all__ = [
    "DEFAULT_PARAMS",
    "ESTIMATOR_PARAMS",
    "STATE_NAMES",
    "BaroSample",
    "Estimate",
    "EstimatorParams",
    "EstimatorStatus",
    "ErrorStateEkf",
    "GpsFix",
    "ImuSample",
    "MagSample",
    "SourceStats",
    "VisionPose",
    "estimator_params",
    "estimator_store",
    "load_estimator_params",
]
