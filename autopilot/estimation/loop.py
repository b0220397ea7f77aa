"""The estimator in the control loop: one lockstep frame's samples in, the state the controllers
fly on out (pure: the frame's time comes in with it).

:class:`EstimatorLoop` feeds an :class:`~.eskf.ErrorStateEkf` in PX4's order (predict on the
IMU sample, then the measurements that arrived with it: magnetometer, barometer, GNSS, vision)
and turns its :class:`~.status.Estimate` into the :class:`~autopilot.control.cascade.StateEstimate`
the commander and the cascade read. Until the filter has aligned (on the ground, at rest: about
a second) there is no estimate and the autopilot has no position (arming refused with the
filter's reason). A vehicle that starts in the air (the paper's experiments start at 1 m with the
motors off) cannot align; :meth:`EstimatorLoop.start_in_air` initialises the filter from a known
pose instead, as a vehicle already flying with a converged estimator would be: the simulator's
first frame (its truth) with the filter's initial uncertainties, used once, at frame 0.

The pre-arm verdict (:meth:`EstimatorLoop.problem`) is the filter's ``converged`` / ``reason``,
refreshed every :data:`STATUS_EVERY` frames (the full status costs ~40 us; the verdict changes
on the scale of seconds).
"""

from __future__ import annotations

from quadcommon.rigid_body import quaternion_from_euler

from ..control.cascade import StateEstimate
from ..mavlink.hil import SensorSamples
from .eskf import ErrorStateEkf
from .measurements import BaroSample, ImuSample, MagSample
from .parameters import EstimatorParams
from .status import EstimatorStatus

STATUS_EVERY = 25  # frames between two status() refreshes (50 ms at 500 Hz)


class EstimatorLoop:
    def __init__(self, params: EstimatorParams, dt_s: float, gravity_m_s2: float = 9.81) -> None:
        self.ekf = ErrorStateEkf(params, gravity_m_s2=gravity_m_s2)
        self.dt = dt_s
        self._last_t: float | None = None
        self._frames = 0
        self.last_status: EstimatorStatus | None = None
        self.last_imu: ImuSample | None = None

    def step(self, t: float, samples: SensorSamples) -> StateEstimate | None:
        """Predict with this frame's IMU sample, fuse what arrived; the estimate, or None while
        the filter is not initialised."""
        ekf = self.ekf
        dt = self.dt if self._last_t is None else t - self._last_t
        self._last_t = t
        imu = ImuSample(t, dt, samples.angular_rate_rad_s, samples.specific_force_m_s2)
        self.last_imu = imu
        ekf.predict(imu)
        if samples.mag_gauss is not None:
            ekf.fuse_mag(MagSample(t, samples.mag_gauss))
        if samples.baro_height_m is not None:
            ekf.fuse_baro(BaroSample(t, samples.baro_height_m))
        if samples.gps is not None:
            ekf.fuse_gps(samples.gps._replace(time_s=t))
        if samples.vision is not None:
            ekf.fuse_vision(samples.vision._replace(time_s=t))
        self._frames += 1
        if self.last_status is None or self._frames % STATUS_EVERY == 0:
            self.last_status = ekf.status()
        if not ekf.initialised:
            return None
        e = ekf.estimate()
        return StateEstimate(e.position_m, e.velocity_m_s, e.euler_rad, e.euler_rates_rad_s)

    def start_in_air(self, t: float, samples: SensorSamples, pose: StateEstimate) -> None:
        """Initialise from ``pose`` at this frame instead of :meth:`step` (an in-air start: no
        alignment possible); see the module."""
        imu = ImuSample(t, self.dt, samples.angular_rate_rad_s, samples.specific_force_m_s2)
        self.last_imu = imu
        self.ekf.reset_to(imu, pose.position_m, pose.velocity_m_s, quaternion_from_euler(*pose.euler_rad),
                          baro_height_m=samples.baro_height_m)  # fmt: skip
        self._last_t = t
        self.last_status = self.ekf.status()

    def problem(self) -> str | None:
        """Why the vehicle must not arm on this estimate (None: converged)."""
        status = self.last_status
        if status is None:
            return "estimator: no IMU sample yet"
        return None if status.converged else f"estimator not ready: {status.reason}"
