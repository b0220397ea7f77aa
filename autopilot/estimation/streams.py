"""Which sensor streams of the HIL frames have stopped (pure: simulation time and samples in,
announcements out).

A stream counts once it has delivered a sample; silent then for longer than
``max(STREAM_SILENT_S, 3 x its last interval)`` of simulation time it is announced stopped, once,
and announced again when it resumes. The estimator handles the gap (the EKF predicts on, dead
reckons without position aiding and says so, EKF2_NOAID_TOUT; without IMU samples there is
nothing to fly on and arming is refused); this makes the stop visible to a ground station, never
a silent hang.

:meth:`StreamWatch.note` takes every frame's samples and only notes which streams delivered (it
runs at the control rate); :meth:`StreamWatch.check` judges the silences, as often as its caller
looks (the commander's health, at 100 Hz as PX4's commander checks its sensors' timestamps). A
stream's interval is measured between the checks that saw new samples: exact for a stream slower
than the checks, the only ones whose interval can exceed ``STREAM_SILENT_S / 3``.
"""

from __future__ import annotations

from ..records import STREAM_BARO, STREAM_GPS, STREAM_IMU, STREAM_MAG, STREAM_VISION

STREAM_SILENT_S = 1.0
STREAM_NAMES = {
    "imu": "IMU (HIL_SENSOR)", "mag": "magnetometer (HIL_SENSOR)", "baro": "barometer (HIL_SENSOR)",
    "gps": "GPS (HIL_GPS)", "vision": "vision (VISION_POSITION_ESTIMATE)",
}  # fmt: skip


class StreamWatch:
    """:meth:`note` every frame's samples; :meth:`check` returns the texts to announce."""

    def __init__(self, silent_s: float = STREAM_SILENT_S) -> None:
        self.silent_s = silent_s
        self.last: dict[str, float] = {}  # stream -> time of its latest sample
        self.interval: dict[str, float] = {}  # stream -> its latest interval between samples
        self.stopped: set[str] = set()
        self._checked: dict[str, float] = {}  # stream -> its latest sample at the last check

    def note(self, t: float, streams: int) -> None:
        """The streams that delivered in a frame at ``t`` (``STREAM_*`` bits: SensorSamples.streams,
        frame_streams)."""
        if not streams:
            return
        last = self.last
        if streams & STREAM_IMU:
            last["imu"] = t
        if streams & STREAM_MAG:
            last["mag"] = t
        if streams & STREAM_BARO:
            last["baro"] = t
        if streams & STREAM_GPS:
            last["gps"] = t
        if streams & STREAM_VISION:
            last["vision"] = t

    def check(self, t: float) -> list[str]:
        """The streams that stopped or resumed since the last check, as texts."""
        out = []
        checked = self._checked
        for name, latest in self.last.items():
            before = checked.get(name)
            if latest != before:  # samples since the last check
                checked[name] = latest
                if before is not None:
                    self.interval[name] = latest - before
                if name in self.stopped:
                    self.stopped.discard(name)
                    out.append(f"sensor stream resumed: {STREAM_NAMES[name]} after {latest - before:.1f} s")
                continue
            limit = max(self.silent_s, 3.0 * self.interval.get(name, 0.0))
            if name not in self.stopped and t - latest > limit:
                self.stopped.add(name)
                out.append(f"sensor stream stopped: {STREAM_NAMES[name]} silent for {t - latest:.1f} s")
        return out
