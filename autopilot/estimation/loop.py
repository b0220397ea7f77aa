"""The estimator in the control loop: one lockstep frame's samples in, the state the controllers
fly on out (pure: the frame's time comes in with it).

:class:`EstimatorLoop` feeds an :class:`~.eskf.ErrorStateEkf` in PX4's order (predict on the
IMU sample, then the measurements that arrived with it: magnetometer, barometer, GNSS, vision)
and turns its :class:`~.status.Estimate` into the :class:`~autopilot.records.StateEstimate`
the commander and the cascade read. Until the filter has aligned (on the ground, at rest: about
a second) there is no estimate and the autopilot has no position (arming refused with the
filter's reason). A vehicle that starts in the air (the paper's experiments start at 1 m with the
motors off) cannot align; :meth:`EstimatorLoop.start_in_air` initialises the filter from a known
pose instead, as a vehicle already flying with a converged estimator would be: the simulator's
first frame (its truth) with the filter's initial uncertainties, used once, at frame 0.

The pre-arm verdict (:meth:`EstimatorLoop.problem`) is the filter's ``converged`` / ``reason``,
refreshed every :data:`STATUS_EVERY` frames (the full status costs ~40 us; the verdict changes
on the scale of seconds), and ``converged`` held for :data:`CONVERGED_HOLD_S`: the filter's
uncertainties pass their thresholds before its tilt and accelerometer biases, which a vehicle at
rest cannot tell apart, have settled. Armed and taking off at the first instant of "converged"
(on ``gps``, 0.65 s after the alignment), the filter gated out the GNSS velocity and its estimate
strayed more than 1 m from the truth within 10 s (up to 34 m) in 4 of 12 seeded runs; 0.35 s
later in 3 of 12, 1 s later in 1 of 44, 2 and 3 s later in none of 60; armed at the first instant
this hold allows, in 1 of 60 (1.5 m, back within 0.3 m 3 s later): ``quadsitl up --estimator ekf
--sensors gps``'s vehicle, in-process. The hold narrows the window; the filter's takeoff right
after a static alignment stays its weak point.

In the autopilot a frame is split in two around its answer: :meth:`EstimatorLoop.predict` (the
IMU sample: the state the controllers fly on this frame) before the actuator controls go out,
:meth:`EstimatorLoop.fuse` (the aiding that came with the frame) after, so the fusions (~60 us
for a vision sample) are off the lockstep's critical path and their correction reaches the
controllers one frame (2 ms at 500 Hz) later. The filter itself runs exactly as in :meth:`step`
(predict, then that frame's measurements); only the controllers read it before the fusions.
PX4's controllers see a correction later still: through EKF2's output predictor, over
EKF2_TAU_POS / EKF2_TAU_VEL (0.25 s), from a filter running on a delayed time horizon.
"""

from __future__ import annotations

from quadcommon.rigid_body import quaternion_from_euler

from ..records import BaroSample, ImuSample, MagSample, SensorSamples, StateEstimate, VisionPose
from .aiding import aiding_of
from .eskf import ErrorStateEkf
from .parameters import EstimatorParams
from .status import EstimatorStatus

STATUS_EVERY = 25  # frames between two status() refreshes (50 ms at 500 Hz)
CONVERGED_HOLD_S = 2.0  # "converged" held this long (filter time) before the vehicle may arm


def _brings_aiding(samples: SensorSamples) -> bool:
    """Whether a frame delivered a magnetometer, barometer, GNSS or vision sample."""
    return not (samples.mag_gauss is None and samples.baro_height_m is None and samples.gps is None
                and samples.vision is None)  # fmt: skip


class EstimatorLoop:
    """The EKF as the autopilot runs it each frame: predict with the IMU sample before the
    answer, fuse the frame's aiding (and a client's vision) after it, PX4's order
    (:mod:`.aiding`); its status every :data:`STATUS_EVERY` frames and the pre-arm verdict
    (converged for :data:`CONVERGED_HOLD_S`)."""

    def __init__(self, params: EstimatorParams, dt_s: float, gravity_m_s2: float = 9.81) -> None:
        self.ekf = ErrorStateEkf(params, gravity_m_s2=gravity_m_s2)
        self.dt = dt_s
        self._last_t: float | None = None
        self._frames = 0
        self.last_status: EstimatorStatus | None = None
        self._pending: SensorSamples | None = None  # the aiding of the last predict(), not yet fused
        self._external: VisionPose | None = None  # a client's vision pose, fused with the next frame's aiding
        self._converged_since: float | None = None  # filter time of the first "converged" in a row
        # The estimate as last read, until this loop changes the filter again (a prediction, a
        # fusion, a reset): a frame that brings no aiding reads it twice, before and after its
        # answer, and the second read costs nothing.
        self._estimate: StateEstimate | None = None

    def step(self, t: float, samples: SensorSamples) -> StateEstimate | None:
        """Predict with this frame's IMU sample, fuse what arrived; the estimate, or None while
        the filter is not initialised."""
        self.predict(t, samples)
        self.fuse()
        return self.estimate()

    def predict(self, t: float, samples: SensorSamples) -> StateEstimate | None:
        """Predict with this frame's IMU sample (after fusing a previous frame's aiding if
        :meth:`fuse` was not called for it); the estimate now, before this frame's aiding, or
        None while the filter is not initialised. The aiding waits for :meth:`fuse`."""
        if self._pending is not None:
            self.fuse()
        dt = self.dt if self._last_t is None else t - self._last_t
        self._last_t = t
        imu = ImuSample(t, dt, samples.angular_rate_rad_s, samples.specific_force_m_s2)
        self._estimate = None
        self.ekf.predict(imu)
        self._pending = samples
        if self.last_status is None:  # the first sample: a verdict from the start (aligning)
            self.last_status = self.ekf.status()
        return self.estimate()

    def fuse(self) -> None:
        """Fuse the aiding that came with the frame of the last :meth:`predict`, in PX4's order."""
        samples, self._pending = self._pending, None
        if samples is None:
            return
        ekf, t = self.ekf, self._last_t
        if ekf.initialised:  # the frame's aiding in PX4's order, one compiled call (.aiding)
            if _brings_aiding(samples):  # (most frames at 500 Hz bring none: no call)
                self._estimate = None
                ekf.fuse_frame(t, aiding_of(samples))
        else:  # each sensor's own method holds what the alignment waits for
            self._estimate = None
            self._hold_for_alignment(samples, t)
        if self._external is not None:
            self._estimate = None
            ekf.fuse_vision(self._external)
            self._external = None
        self._frames += 1
        if self.last_status is None or self._frames % STATUS_EVERY == 0:
            self.last_status = ekf.status()

    def _hold_for_alignment(self, samples: SensorSamples, t: float) -> None:
        """Before the filter is initialised: the samples the alignment and the first fusions wait
        for (the filter may initialise within the frame: the later samples are then fused)."""
        ekf = self.ekf
        if samples.mag_gauss is not None:
            ekf.fuse_mag(MagSample(t, samples.mag_gauss))
        if samples.baro_height_m is not None:
            ekf.fuse_baro(BaroSample(t, samples.baro_height_m))
        if samples.gps is not None:
            ekf.fuse_gps(samples.gps._replace(time_s=t))
        if samples.vision is not None:
            ekf.fuse_vision(samples.vision._replace(time_s=t))

    def external_vision(self, pose: VisionPose) -> None:
        """A client's vision pose (:mod:`autopilot.mavlink.vision_in`: checked, valid at its
        ``time_s``), fused after the next frame's own aiding, through the same vision fusion
        (EKF2_EV_*); one a frame (the edge refuses more), a newer one replaces it."""
        self._external = pose

    def estimate(self) -> StateEstimate | None:
        """The filter's estimate now, or None while it is not initialised."""
        ekf = self.ekf
        if not ekf.initialised:
            return None
        if self._estimate is None:
            e = ekf.estimate()
            self._estimate = StateEstimate(e.position_m, e.velocity_m_s, e.euler_rad, e.euler_rates_rad_s)
        return self._estimate

    def start_in_air(self, t: float, samples: SensorSamples, pose: StateEstimate) -> None:
        """Initialise from ``pose`` at this frame instead of :meth:`step` (an in-air start: no
        alignment possible); see the module."""
        imu = ImuSample(t, self.dt, samples.angular_rate_rad_s, samples.specific_force_m_s2)
        self._pending = None
        self._estimate = None
        self.ekf.reset_to(imu, pose.position_m, pose.velocity_m_s, quaternion_from_euler(*pose.euler_rad),
                          baro_height_m=samples.baro_height_m)  # fmt: skip
        self._last_t = t
        self.last_status = self.ekf.status()

    def height_uncertainty_m(self) -> float:
        """The 1-sigma of the estimate's height (m; inf while the filter is not initialised), as
        of the last status."""
        status = self.last_status
        return status.pos_vert_accuracy_m if status is not None else float("inf")

    def problem(self) -> str | None:
        """Why the vehicle must not arm on this estimate (None: converged for
        :data:`CONVERGED_HOLD_S`)."""
        status = self.last_status
        if status is None:
            return "estimator: no IMU sample yet"
        if not status.converged:
            self._converged_since = None
            return f"estimator not ready: {status.reason}"
        if self._converged_since is None:
            self._converged_since = status.time_s
        held = status.time_s - self._converged_since
        if held < CONVERGED_HOLD_S:
            return f"estimator not ready: settling (converged for {held:.1f} s of {CONVERGED_HOLD_S:g} s)"
        return None
