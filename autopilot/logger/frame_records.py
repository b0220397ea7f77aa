"""What the autopilot records of each control frame, after its answer is out: the controller's row
and (on the EKF) the estimator's row for zenoh (``quadsitl/<N>/controller``, ``/estimator``:
:data:`~quadcommon.bus_records.CONTROLLER_FIELDS`, :data:`~quadcommon.bus_records.ESTIMATOR_FIELDS`,
drained by the process shell or the in-process runner), the frame into the flight log
(:class:`~.logger.FlightLogger`), and the latest frame kept for the console's ``listener``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

from quadcommon.bus_records import ESTIMATOR_FIELDS

from ..battery.estimator import BatteryEstimator
from ..commander.commander import Commander, GuidanceOutput
from ..control.cascade import CascadeOutput
from ..estimation.loop import EstimatorLoop
from ..mavlink.hil import DISTURBANCE_ID, Frame, disturbance_of
from ..records import StateEstimate
from . import topics
from .logger import FlightLogger

_NAN3 = (math.nan, math.nan, math.nan)
Controls = tuple[float, float, float, float]


@dataclass(frozen=True)
class RecordContext:
    """What the records read besides the frame: the rooms, not the core."""

    flight_log: FlightLogger
    commander: Commander
    battery: BatteryEstimator
    estimator: Callable[[], EstimatorLoop | None]  # the EKF's loop, None on the truth


class FrameRecords:
    """The rows and the flight log of each frame (module docstring), on a :class:`RecordContext`."""

    def __init__(self, context: RecordContext) -> None:
        self.context = context
        self.controller_rows: list[tuple[float, ...]] = []  # one per frame, drained by the caller
        self.estimator_rows: list[tuple[float, ...]] = []  # ESTIMATOR_FIELDS, one per frame on the EKF
        # The latest frame, for the console's listener: (frame, truth, guidance, output, controls, row)
        self._latest: tuple | None = None

    def frame(
        self,
        t: float,
        frame: Frame,
        truth: StateEstimate | None,
        guidance: GuidanceOutput,
        output: CascadeOutput | None,
        controls: Controls,
    ) -> None:
        """Frame ``frame`` at simulation time ``t`` (s): its state as flown, the simulator's
        ``truth``, the commander's guidance, the cascade's output (None: motors off) and the
        actuator controls answered; its controller row, then the flight log."""
        row = self.controller_row(t, guidance, output)
        self.controller_rows.append(row)
        self._latest = (frame, truth, guidance, output, controls, row)
        self.log_frame(frame, truth, row, guidance, output, controls)

    def controller_row(self, t: float, guidance: GuidanceOutput, output: CascadeOutput | None) -> tuple:
        """One :data:`~quadcommon.bus_records.CONTROLLER_FIELDS` row: the reference, the cascade's
        attitude reference, thrust and torques (NaN and zero while the motors are off), armed, mode."""
        ref = guidance.reference
        if ref is not None:
            p, v, a = ref.position_m, ref.velocity_m_s, ref.acceleration_m_s2
        else:
            p = v = a = _NAN3
        if output is not None:
            eta_d, raw = output.euler_ref_rad, output.roll_pitch_raw_rad
            u1, tau = output.thrust_n, output.torque_euler_n_m
        else:
            eta_d, raw, u1, tau = _NAN3, (math.nan, math.nan), 0.0, (0.0, 0.0, 0.0)
        c = self.context.commander
        return (t, *p, *v, *a, *eta_d, *raw, u1, *tau, float(c.armed), float(c.mode.custom_mode))

    def estimator_row(self, t: float, est: StateEstimate | None, loop: EstimatorLoop) -> None:
        """One ESTIMATOR_FIELDS row for the frame at ``t`` (NaN until the filter has an estimate)."""
        e, st, src = loop.ekf, loop.last_status, loop.ekf.sources
        if st is None or est is None:
            self.estimator_rows.append((t, *(math.nan,) * (len(ESTIMATOR_FIELDS) - 1)))
            return
        bg, ba = e.estimate_biases()
        self.estimator_rows.append(
            (t, *est.position_m, *est.velocity_m_s, *est.euler_rad, *bg, *ba,
             st.pos_horiz_accuracy_m, st.pos_vert_accuracy_m, st.vel_accuracy_m_s, st.tilt_accuracy_rad,
             st.yaw_accuracy_rad, st.vel_ratio, st.pos_horiz_ratio, st.pos_vert_ratio, st.mag_ratio,
             src["gps_pos"].normalized_innovation, src["gps_vel"].normalized_innovation,
             src["baro"].normalized_innovation, src["mag"].normalized_innovation,
             src["ev_pos"].normalized_innovation, src["ev_yaw"].normalized_innovation,
             float(st.flags), float(st.converged))
        )  # fmt: skip

    def take_controller_rows(self) -> list[tuple[float, ...]]:
        """The controller rows of every frame since the last call (CONTROLLER_FIELDS order)."""
        rows, self.controller_rows = self.controller_rows, []
        return rows

    def take_estimator_rows(self) -> list[tuple[float, ...]]:
        """The estimator rows of every frame since the last call (ESTIMATOR_FIELDS order)."""
        rows, self.estimator_rows = self.estimator_rows, []
        return rows

    def log_frame(
        self,
        frame: Frame,
        truth: StateEstimate | None,
        row: tuple,
        guidance: GuidanceOutput,
        output: CascadeOutput | None,
        controls: Controls,
    ) -> None:
        """The frame into the flight log, when one is open; the simulator's disturbance and rotors'
        health when the frame reports them (kept while no log is open: a log starts with them)."""
        context = self.context
        log = context.flight_log
        parts = frame.parts
        due = log.frame(frame.time_usec, context.commander.armed, truth, row, parts, frame.state, output)
        if parts is not None and DISTURBANCE_ID in parts:  # a change, or a reminder (quadcommon.wire)
            report = disturbance_of(parts)
            if report is not None:
                log.disturbance(report.time_usec, report.force_n, report.torque_n_m)
                log.rotor_health(report.time_usec, report.rotor_effectiveness, report.rotor_failure)
        if due:  # the periodic topics (one frame in ten, at most)
            s = log.snapshot
            s.reference = guidance.reference
            s.controls = controls
            estimator = context.estimator()
            s.estimator = estimator.last_status if estimator is not None else None
            s.battery = context.battery.status
            log.sample_due()

    def topic_now(self, name: str) -> tuple[list[str], tuple] | None:
        """Flight-log topic ``name`` at the latest frame (the console's ``listener``), built by the
        log's own builders from a copy of its snapshot refreshed with that frame; None before the
        first frame."""
        if self._latest is None:
            return None
        frame, truth, guidance, output, controls, row = self._latest
        context = self.context
        log = context.flight_log
        parts = frame.parts
        gps = topics.gps_of(parts) if parts is not None and topics.GPS_ID in parts else None
        estimator = context.estimator()
        snapshot = dataclasses.replace(
            log.snapshot, t_us=frame.time_usec, truth=truth, estimate=frame.state, row=row, parts=parts,
            output=output, reference=guidance.reference, controls=controls,
            estimator=estimator.last_status if estimator is not None else None,
            battery=context.battery.status, gps=gps or log.snapshot.gps,
        )  # fmt: skip
        return log.sample_now(name, snapshot)
