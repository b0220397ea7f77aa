"""Which sensor streams of the HIL frames have stopped (pure: simulation time and samples in,
announcements out).

A stream counts once it has delivered a sample; silent then for longer than
``max(STREAM_SILENT_S, 3 x its last interval)`` of simulation time it is announced stopped, once,
and announced again when it resumes. The estimator handles the gap (the EKF predicts on, dead
reckons without position aiding and says so, EKF2_NOAID_TOUT; without IMU samples there is
nothing to fly on and arming is refused); this makes the stop visible to a ground station, never
a silent hang.
"""

from __future__ import annotations

from ..mavlink.hil import SensorSamples

STREAM_SILENT_S = 1.0
STREAM_NAMES = {
    "imu": "IMU (HIL_SENSOR)", "mag": "magnetometer (HIL_SENSOR)", "baro": "barometer (HIL_SENSOR)",
    "gps": "GPS (HIL_GPS)", "vision": "vision (VISION_POSITION_ESTIMATE)",
}  # fmt: skip


def _present(samples: SensorSamples | None) -> dict[str, bool]:
    if samples is None:
        return dict.fromkeys(STREAM_NAMES, False)
    return {
        "imu": "imu" not in samples.refused, "mag": samples.mag_gauss is not None,
        "baro": samples.baro_height_m is not None, "gps": samples.gps is not None,
        "vision": samples.vision is not None,
    }  # fmt: skip


class StreamWatch:
    """Call :meth:`update` with every frame's samples; it returns the texts to announce."""

    def __init__(self, silent_s: float = STREAM_SILENT_S) -> None:
        self.silent_s = silent_s
        self.last: dict[str, float] = {}  # stream -> time of its latest sample
        self.interval: dict[str, float] = {}  # stream -> its latest interval between samples
        self.stopped: set[str] = set()

    def update(self, t: float, samples: SensorSamples | None) -> list[str]:
        out = []
        for name, present in _present(samples).items():
            last = self.last.get(name)
            if present:
                if name in self.stopped:
                    self.stopped.discard(name)
                    out.append(f"sensor stream resumed: {STREAM_NAMES[name]} after {t - last:.1f} s")
                if last is not None:
                    self.interval[name] = t - last
                self.last[name] = t
            elif last is not None and name not in self.stopped:
                limit = max(self.silent_s, 3.0 * self.interval.get(name, 0.0))
                if t - last > limit:
                    self.stopped.add(name)
                    out.append(f"sensor stream stopped: {STREAM_NAMES[name]} silent for {t - last:.1f} s")
        return out
