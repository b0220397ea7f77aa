"""What the vehicle flies on: the simulator's truth (the paper's assumption) or the EKF's estimate
of the sensors (:mod:`autopilot.estimation`), as ``EKF2_EN`` says.

The switch happens only while disarmed, never in flight: ``EKF2_EN`` set in flight waits for the
disarm. On the EKF, each frame's IMU sample is predicted before the answer and the frame's aiding
(GNSS, barometer, magnetometer, a client's vision) fused after it (:meth:`EstimatorSwitch.fuse`,
:mod:`autopilot.estimation.loop`); the commander reads the filter's verdict (pre-arm, the height's
uncertainty) and telemetry its status. A frame whose samples are not finite is counted, and those
samples are never fed to the filter.
"""

from __future__ import annotations

from collections.abc import Callable

from .commander.commander import Commander
from .estimation.loop import EstimatorLoop
from .estimation.parameters import estimator_params
from .mavlink.hil import Frame
from .mavlink.telemetry import VehicleStatus
from .params.store import ParameterStore
from .records import StateEstimate

IN_AIR_START_M = 0.1  # a first frame above this height: the EKF starts from it (no alignment)


class EstimatorSwitch:
    """The EKF's loop while ``EKF2_EN`` is 1 (module docstring); ``loop`` None: on the truth.

    ``status``: the telemetry status whose estimator fields this keeps; ``drop``: counts a
    refused input by its reason (the core's ``on_foreign_datagram``)."""

    def __init__(
        self,
        params: ParameterStore,
        commander: Commander,
        status: VehicleStatus,
        dt_s: float,
        gravity_m_s2: float,
        log: Callable[[str], None],
        drop: Callable[[str], None],
    ) -> None:
        self.params, self.commander, self.status = params, commander, status
        self.dt_s, self.gravity_m_s2 = dt_s, gravity_m_s2
        self.log, self.drop = log, drop
        self.loop: EstimatorLoop | None = None  # flying on the EKF (EKF2_EN = 1), else on the truth
        self._done: tuple | None = None  # (t, estimate, loop) of the frame, fused after the answer
        self.switch()

    def switch(self) -> None:
        """Start or stop the EKF to follow EKF2_EN (only while disarmed: never in flight)."""
        want = self.params.values["EKF2_EN"] == 1.0
        if want == (self.loop is not None) or self.commander.armed:
            return
        if want:
            self.loop = EstimatorLoop(estimator_params(self.params), self.dt_s, self.gravity_m_s2)
        else:
            self.loop = None
            self.commander.estimator_problem = None
            self.commander.height_uncertainty_m = 0.0  # the truth
        self.status.estimator = None
        self.status.on_ekf = want
        self.log(f"flying on {'the EKF estimate' if want else 'the simulator truth'} (EKF2_EN {int(want)})")

    @property
    def wanted(self) -> bool:
        """On the EKF, or asked to be (EKF2_EN 1, waiting for the disarm): each frame goes through
        :meth:`estimate`."""
        return self.loop is not None or self.params.values["EKF2_EN"] == 1.0

    def estimate(self, t: float, frame: Frame, first_frame: bool) -> StateEstimate | None:
        """This frame's EKF estimate at ``t`` (None until it has aligned; the frame's state while
        the switch waits for the disarm); the commander's pre-arm verdict. ``first_frame``: the
        run's first, from which a vehicle above :data:`IN_AIR_START_M` starts in the air."""
        self.switch()
        loop = self.loop
        if loop is None:  # EKF2_EN = 1 set in flight: the switch waits for the disarm
            return frame.state
        samples = frame.sensors
        if samples is None:  # no HIL_SENSOR in this frame (a simulator without sensors)
            self.commander.estimator_problem = "estimator: no HIL_SENSOR in the frames"
            return None
        for name in samples.refused:  # never fed to the filter
            self.drop(f"HIL frame with a non-finite {name} sample")
        if "imu" in samples.refused or not samples.imu_fresh:  # no prediction, no fusion this frame:
            est = loop.estimate()  # fly on the filter as it is (the next sample integrates across the gap)
        elif first_frame and frame.state.position_m[2] > IN_AIR_START_M:
            loop.start_in_air(t, samples, frame.state)  # the paper's experiments start in the air
            est = frame.state
        else:
            est = loop.predict(t, samples)  # the frame's aiding is fused after the answer
        self.commander.estimator_problem = loop.problem()
        self.commander.height_uncertainty_m = loop.height_uncertainty_m()
        self.status.estimator = loop.last_status
        self._done = (t, est, loop)  # its row is written after the answer is out
        return est

    def fuse(self) -> tuple[float, StateEstimate | None, EstimatorLoop] | None:
        """After the answer: the frame's aiding fused (see :mod:`autopilot.estimation.loop`);
        (t, the estimate then, None until it has one, the loop) for the frame's estimator row, or
        None when the frame was not estimated."""
        if self._done is None:
            return None
        t, est, loop = self._done
        self._done = None
        loop.fuse()
        return t, loop.estimate() if est is not None else None, loop

    def parameter_changed(self, name: str) -> None:
        """An ``EKF2_*`` or ``EST_*`` parameter changed: the running filter takes the new values."""
        if name.startswith(("EKF2_", "EST_")) and self.loop is not None:
            self.loop.ekf.set_params(estimator_params(self.params))
