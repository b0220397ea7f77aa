"""What the simulator process's frame loop measured, for the line it logs when it stops: frames
sent, the wall time per frame spent on its own work and waiting for the autopilot, the loop's
real-time factor and the HIL round trip's median and 99th percentile
(:class:`~simulator.latency.LatencyHistogram`: constant memory)."""

from __future__ import annotations

from dataclasses import dataclass, field

from .latency import LatencyHistogram


@dataclass
class LoopStats:
    """The frame loop's counters (wall seconds)."""

    frames_sent: int = 0
    work_s: float = 0.0  # own work: the frame built and sent, the plant stepped
    wait_s: float = 0.0  # waiting for the autopilot's answer
    loop_start: float = 0.0  # wall clock when the frame loop started (linked to the autopilot)
    loop_s: float = 0.0  # the frame loop's wall time (linked to the last frame)
    round_trips: LatencyHistogram = field(default_factory=LatencyHistogram)  # frame sent -> its answer

    def summary(self, t: float, overruns: int, resends: int) -> str:
        """The run in one line: the simulation time ``t`` reached (s), frames sent, the work and the
        wait per frame, the pacer's re-anchors (``overruns``), the frames resent, the real-time
        factor and the round trip's quantiles."""
        n = max(self.frames_sent - 1, 1)  # the final frame is not answered
        text = (
            f"stopped at t={t:.3f} s ({self.frames_sent} frames; per frame "
            f"{1e6 * self.work_s / n:.0f} us own work, {1e6 * self.wait_s / n:.0f} us waiting for the "
            f"autopilot; {overruns} re-anchors; {resends} frames resent)"
        )
        if self.loop_s > 0.0:
            text += f"; {t:.3f} s simulated in {self.loop_s:.3f} s of frame loop ({t / self.loop_s:.1f}x)"
        if self.round_trips:
            median, p99 = self.round_trips.quantile(0.5), self.round_trips.quantile(0.99)
            text += f"; HIL round trip median {1e6 * median:.0f} us, p99 {1e6 * p99:.0f} us"
        return text
