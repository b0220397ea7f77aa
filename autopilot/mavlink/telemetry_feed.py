"""What the vehicle's telemetry reports, and the streams that are due: the
:class:`~.telemetry.VehicleStatus` brought up to date with the latest control frame and the
commander when it is read (a stream due, a requested message, a heartbeat), not at every frame:
most frames send nothing. Each due message is built once per frame for every link that wants it
(:mod:`.telemetry` builds it; the links' :class:`~.telemetry.StreamTable` say when).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

from ..battery.estimator import BatteryEstimator
from ..commander.commander import Commander, GuidanceOutput
from ..control.cascade import CascadeOutput
from ..params.store import ParameterStore
from . import telemetry
from .hil import Frame
from .links import GcsLink


@dataclass(frozen=True)
class FeedContext:
    """What the status is made of besides the frame: the rooms it reads, not the core."""

    commander: Commander
    params: ParameterStore
    battery: BatteryEstimator
    thrust_max_n: float  # U1_max (N): the reported thrust is a fraction of it
    now: Callable[[], float]  # simulation time (s)
    on_ekf: Callable[[], bool]  # flying on the EKF (EKF2_EN 1), else on the simulator's truth
    controls: Callable[[], tuple[float, float, float, float]]  # the latest frame's actuator controls


class TelemetryFeed:
    """The vehicle's status for telemetry (module docstring), on a :class:`FeedContext`."""

    def __init__(self, status: telemetry.VehicleStatus, context: FeedContext) -> None:
        self.context = context
        self._status = status
        self._pending: tuple[Frame, GuidanceOutput, CascadeOutput | None] | None = None

    def frame_done(self, frame: Frame, guidance: GuidanceOutput, output: CascadeOutput | None) -> None:
        """The control frame just answered (its state as flown, the guidance and the cascade's
        output, None when the motors were off); brought into the status when it is read."""
        self._pending = (frame, guidance, output)

    @property
    def status(self) -> telemetry.VehicleStatus:
        """What telemetry reports: the latest frame and the commander now."""
        if self._pending is not None:
            self._update(*self._pending)
            self._pending = None
        return self._status

    def send_due(self, t: float, links: Iterable[GcsLink], pack: Callable[[Any], bytes]) -> None:
        """The messages due at simulation time ``t`` on each link with peers, each one built and
        packed once for all the links that want it."""
        cache: dict[int, bytes | None] = {}
        for link in links:
            if not link.peers:
                continue
            due = link.streams.due(t)
            if not due:  # most frames
                continue
            for msg_id in due:
                if msg_id not in cache:
                    msg = telemetry.build(msg_id, self.status)  # (refreshes the status)
                    cache[msg_id] = pack(msg) if msg is not None else None
                data = cache[msg_id]
                if data is not None:
                    link.send(data)

    def _update(self, frame: Frame, guidance: GuidanceOutput, output: CascadeOutput | None) -> None:
        context = self.context
        s, c, now = self._status, context.commander, context.now()
        s.time_usec = frame.time_usec
        s.state = frame.state
        s.parts = frame.parts
        s.on_ekf = context.on_ekf()
        s.armed = c.armed
        s.custom_mode = c.mode.custom_mode
        s.landed_state = c.landed_state.value
        if c.home is not None:
            s.home_local = c.home
        s.reference = guidance.reference
        s.controls = context.controls()
        s.armable = not c.armed and c.arm_problem(now) is None
        values = context.params.values
        s.geofence_enabled = values["GF_MAX_HOR_DIST"] > 0.0 or values["GF_MAX_VER_DIST"] > 0.0
        s.geofence_breached = c.failsafes.fence_breached
        s.battery = context.battery.status
        s.battery_unhealthy = c.battery.unhealthy
        s.flags = c.health_flags(now)
        s.failsafe = c.in_failsafe
        s.terminated = c.terminated
        s.orbit = c.orbit_status
        if output is not None:
            s.euler_ref = output.euler_ref_rad
            s.thrust_normalised = output.thrust_n / context.thrust_max_n
        else:
            s.euler_ref = (0.0, 0.0, frame.state.euler_rad[2] if frame.state is not None else 0.0)
            s.thrust_normalised = 0.0
