"""Wall-clock pacing on top of lockstep (the simulator process's shell; the core has no clock).

Frame time ``t`` is due at ``anchor + t / speed`` on the wall clock: the loop sleeps until then
(no busy-wait), never for ``speed = None`` ("max"). More than :data:`RESYNC_BEHIND_S` behind, the
anchor moves instead of sprinting to catch up (each such re-anchor is counted), and after an
outage (the wait was not simulated time) the next frame re-anchors. Running well below the asked
speed is reported at most every :data:`RATE_REPORT_WALL_S`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable

RESYNC_BEHIND_S = 0.2
RATE_REPORT_WALL_S = 10.0
SLEEP_SLICE_S = 0.05  # sleeps in slices so that a stop request is seen


def parse_speed(text: str) -> float | None:
    """``--speed``: ``"max"`` -> None (as fast as it goes), else the factor of real time, a finite
    number above 0; ValueError naming the value otherwise."""
    if text == "max":
        return None
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (value > 0.0 and math.isfinite(value)):
        raise ValueError(f"--speed must be a positive number or 'max', got {text!r}")
    return value


class Pacer:
    """Paces the lockstep frames on the wall clock at ``speed`` times real time (None: as fast as the
    CPU allows), re-anchoring after an overrun or an outage rather than catching up, and reporting
    the rate achieved now and then through ``log``."""
    def __init__(self, speed: float | None, log: Callable[[str], None], running: Callable[[], bool]) -> None:
        self.speed = speed
        self.log = log
        self.running = running
        self.overruns = 0
        self._resync = False
        now = time.perf_counter()
        self._anchor, self._paced_at = now, speed
        self._report_at, self._report_sim, self._report_wall = now + RATE_REPORT_WALL_S, 0.0, now

    def resync(self) -> None:
        """The last wait was an outage, not simulated time: re-anchor at the next frame."""
        self._resync = True

    def pace(self, t_next: float, idle: bool = False) -> None:
        """Wait until frame time ``t_next`` is due; ``idle``: nothing to compute (a landed vehicle
        without autopilot), so even "max" goes at real time instead of spinning."""
        pace = self.speed if self.speed is not None else (1.0 if idle else None)
        if pace is None:
            return
        now = time.perf_counter()
        if self._resync or pace != self._paced_at:
            self._resync, self._paced_at = False, pace
            self._anchor = now - t_next / pace
        target = self._anchor + t_next / pace
        if target > now:
            self._sleep_until(target)
        elif now - target > RESYNC_BEHIND_S:
            self._anchor = now - t_next / pace
            self.overruns += 1
        if now >= self._report_at and self.speed is not None:
            achieved = (t_next - self._report_sim) / (now - self._report_wall)
            if achieved < 0.95 * self.speed:
                self.log(f"running at {achieved:.2f}x real time (asked {self.speed:g}x); "
                         f"{self.overruns} re-anchors so far")  # fmt: skip
            self._report_at, self._report_sim, self._report_wall = now + RATE_REPORT_WALL_S, t_next, now

    def _sleep_until(self, target: float) -> None:
        while self.running():
            remaining = target - time.perf_counter()
            if remaining <= 0.0:
                return
            time.sleep(min(remaining, SLEEP_SLICE_S))
