"""The HIL link's lockstep rules, the autopilot's side: which frame is new, resent, a late copy or
a restarted simulator's; when the simulator counts as lost and found again; the hello that tells a
(re)started simulator where the autopilot is; and the requests that ride in the next answer
(failure injection, the ``SIM_*`` parameters).

Pure: the times come in as arguments (``now``: the caller's clock, the wall clock of the process
shell or the in-process runner's). The core (:class:`~autopilot.core.AutopilotCore`) asks and
carries out what follows (a control step, a reset of the rooms after a restart, the STATUSTEXT);
the simulator's side of the same rules is in :mod:`simulator.core` (:mod:`quadcommon.wire` has the
contract).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from enum import Enum

from quadcommon import wire
from quadcommon.config import SIM_BATTERY_PARAMETERS
from quadcommon.mavlink_fast import MessageParts

from ..params.store import ParameterStore
from .codec import Encoder, mavlink
from .hil import Frame, SimulatorRequests, frame_of

HIL_HELLO_S = 0.2  # heartbeat to the simulator until frames flow: it learns our address from it
# A frame for t = 0 this long (s of ``now``) after the run's first one is a restarted simulator's,
# not a late copy of the first frame (a link delays a copy by at most a few 100 ms).
LATE_COPY_S = 1.0


class FrameOrder(Enum):
    """Where a frame stands against the last one answered."""

    NEW = "new"  # later than the last answered one: a control step
    AGAIN = "again"  # the last answered one, resent (or duplicated by the link): the same answer again
    LATE = "late"  # older: a late copy of a frame answered already, which nobody waits for
    RESTARTED = "restarted"  # older: a restarted simulator's (time starts again at 0)


class SimulatorLink:
    """The lockstep state of the HIL link (module docstring). ``home``: the geodetic origin of the
    local frame (lat deg, lon deg, alt m AMSL); ``use_odometry``: the state from ODOMETRY (float32)
    rather than HIL_STATE_QUATERNION (1 cm)."""

    def __init__(self, encoder: Encoder, system_id: int, home: tuple[float, float, float],
                 use_odometry: bool = True) -> None:  # fmt: skip
        self.home = home
        self.use_odometry = use_odometry
        self.system_id = system_id
        self.requests = SimulatorRequests(encoder, system_id)  # ride in the next answer
        self.last_time_usec = -1  # the frame answered last (-1: none in this run)
        self.last_answer: wire.LockstepAnswer | None = None  # sent again for a resent or duplicated frame
        self.linked = False  # frames have flowed
        self.lost = False  # no frame for COM_SIM_LOSS_T (reported once, until frames resume)
        self.last_frame_wall = 0.0  # ``now`` at the latest frame
        self.frame_gap_s = 1.0  # ``now`` between the last two frames (the shell spins below 1 ms)
        self._first_frame_wall = 0.0  # ``now`` at this run's first frame (see order)
        self._next_hello = 0.0

    def decode(self, parts: MessageParts, sensors: bool) -> Frame | None:
        """The lockstep frame of a datagram's messages (None: no state in them, e.g. the
        simulator's heartbeat); with ``sensors`` the samples an estimator reads too. CorruptFrame if
        a checksum fails."""
        return frame_of(parts, self.home, self.use_odometry, sensors=sensors)

    def order(self, time_usec: int, now: float) -> FrameOrder:
        """Where the frame stamped ``time_usec`` stands. An older frame than the last answered one
        is a restarted simulator's when it starts again at t = 0 after this autopilot reported it
        lost, or more than :data:`LATE_COPY_S` after this run's first frame; else a late copy (a
        duplicated or reordered datagram)."""
        if time_usec > self.last_time_usec:
            return FrameOrder.NEW
        if time_usec == self.last_time_usec:
            return FrameOrder.AGAIN
        if self.lost or (time_usec == 0 and now - self._first_frame_wall > LATE_COPY_S):
            return FrameOrder.RESTARTED
        return FrameOrder.LATE

    def restart(self) -> None:
        """A restarted simulator: its frames start a new run (from t = 0)."""
        self.last_time_usec = -1

    def arrived(self, time_usec: int, now: float) -> str | None:
        """A frame to step, stamped ``time_usec``, at ``now``: what the link became, ``"linked"``
        (the first frames), ``"recovered"`` (frames again after the simulator was reported lost),
        or None."""
        if self.last_time_usec < 0:
            self._first_frame_wall = now
        self.frame_gap_s = now - self.last_frame_wall
        self.last_frame_wall = now
        self.last_time_usec = time_usec
        if self.linked and not self.lost:
            return None
        became = "recovered" if self.lost else "linked"
        self.linked, self.lost = True, False
        return became

    def answer(self, controls: bytes, frame: Callable[[bytes], bytes]) -> wire.LockstepAnswer:
        """The answer to the frame just stepped: its HIL_ACTUATOR_CONTROLS payload (framed by
        ``frame`` when sent) then the requests that wait (as many as one answer carries); kept to be
        sent again for a resent frame."""
        requests = self.requests.take() if self.requests.pending else b""
        self.last_answer = wire.LockstepAnswer(controls, requests, frame)
        return self.last_answer

    def silent(self, now: float, loss_s: float) -> bool:
        """No frame within ``loss_s`` (COM_SIM_LOSS_T) of ``now``, or none yet."""
        return not (self.linked and now - self.last_frame_wall <= loss_s)

    def lose(self) -> bool:
        """Report the simulator lost (after :meth:`silent`); True the first time, until frames resume."""
        if not self.linked or self.lost:
            return False
        self.lost = True
        return True

    def hello_due(self, now: float) -> bool:
        """Whether to say hello now (every :data:`HIL_HELLO_S` while no frames flow)."""
        if now < self._next_hello:
            return False
        self._next_hello = now + HIL_HELLO_S
        return True

    def request_failure(self, unit: int, failure_type: int, instance: int, effectiveness: float) -> bool:
        """MAV_CMD_INJECT_FAILURE for the simulator, in the next answer (param4: a motor's
        effectiveness); False when too many wait."""
        if self.requests.full:
            return False
        self.requests.command(mavlink.MAV_CMD_INJECT_FAILURE, unit, failure_type, instance, effectiveness)
        return True

    def forward_parameter(self, name: str, value: float) -> None:
        """A ``SIM_*`` parameter to the simulator, as a PARAM_SET in the next answer, its value a
        plain float whatever its type (the channel is ours: :mod:`quadcommon.wire`); the simulator
        validates it again and counts a refusal."""
        target = (self.system_id, wire.SIMULATOR_COMPONENT_ID)
        self.requests.send(
            mavlink.MAVLink_param_set_message(*target, name.encode(), value, mavlink.MAV_PARAM_TYPE_REAL32)
        )

    def forward_parameters(
        self, params: ParameterStore, names: Iterable[str] = SIM_BATTERY_PARAMETERS
    ) -> None:
        """At the first frame of a simulator: the ``SIM_*`` parameters that differ from the vehicle
        file's (a parameters file or a PARAM_SET before it started), which the simulator starts from."""
        for name in names:
            if params[name] != params.specs[name].default:
                self.forward_parameter(name, params[name])
