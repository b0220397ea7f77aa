"""A small ground-station client over pymavlink's ``mavutil``: what every flying script needs.

Only MAVLink on this path (no project internals besides the pure frame helpers). The vehicle
behaves like PX4 SITL: it sends to ``udpin:127.0.0.1:14540+N`` (API scripts, like MAVSDK; 14549
for every instance from 10 on, where a script for one of them talks to ``udpout:127.0.0.1:14580+N``
instead) and to ``14550`` (ground stations, every instance), answers whatever address talks to it,
and reads only its vehicle's system id (1 + N); it stamps telemetry with
``time_boot_ms`` = SIMULATION time. The simulation may run faster or slower than the wall clock,
so everything here waits on simulation time (tracked from the telemetry), with a wall-clock
safety timeout on top so that a stopped simulator can never hang a script.

Frames: the scripts' users give positions in the paper's frame (x forward/north, y left, z up,
metres; yaw counter-clockwise from x seen from above, radians); the conversion to MAVLink's
NED happens here, at the edge, with :mod:`quadcommon.frames` (the one module that flips signs).
Raw telemetry accessors say ``ned`` in their names.

Usage::

    link = connect("udpin:127.0.0.1:14540", instance=0)
    link.arm(); link.takeoff(2.5)
    link.wait_until(lambda l: l.position_paper[2] > 2.4, sim_timeout_s=20, what="climb")

(One module: every flying script imports just this client; its waits, commands and setpoint
encoding share the telemetry state.)
"""

from __future__ import annotations

import math
import struct
import sys
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from quadcommon import environment

environment.use_mavlink2()  # before pymavlink is imported (it reads them then)

from pymavlink import mavutil  # noqa: E402

from gcs_scripts.view.telemetry import StatusTextAssembler  # noqa: E402
from quadcommon import frames  # noqa: E402

Vector3 = tuple[float, float, float]

GCS_SYSTEM_ID = 255  # conventional ground-station system id
GCS_COMPONENT_ID = 190  # MAV_COMP_ID_MISSIONPLANNER

# PX4 main modes and AUTO sub modes: custom_mode = (main << 16) | (sub << 24).
PX4_MODES: dict[str, tuple[int, int]] = {
    "MANUAL": (1, 0),
    "ALTCTL": (2, 0),
    "POSCTL": (3, 0),
    "AUTO.READY": (4, 1),
    "AUTO.TAKEOFF": (4, 2),
    "AUTO.LOITER": (4, 3),
    "AUTO.MISSION": (4, 4),
    "AUTO.RTL": (4, 5),
    "AUTO.LAND": (4, 6),
    "AUTO.FOLLOW_TARGET": (4, 8),
    "ORBIT": (3, 1),  # POSCTL's sub mode 1
    "ACRO": (5, 0),
    "OFFBOARD": (6, 0),
    "STABILIZED": (7, 0),
}
MODE_ALIASES = {
    "HOLD": "AUTO.LOITER",
    "LOITER": "AUTO.LOITER",
    "LAND": "AUTO.LAND",
    "RTL": "AUTO.RTL",
    "MISSION": "AUTO.MISSION",
    "TAKEOFF": "AUTO.TAKEOFF",
    "POSITION": "POSCTL",
}

# SET_POSITION_TARGET_LOCAL_NED type_mask bits (POSITION_TARGET_TYPEMASK): set = ignore.
IGNORE_POSITION = 1 | 2 | 4
IGNORE_VELOCITY = 8 | 16 | 32
IGNORE_ACCELERATION = 64 | 128 | 256
IGNORE_YAW = 1024
IGNORE_YAW_RATE = 2048

MAV_LANDED_STATE_ON_GROUND = 1
MAV_LANDED_STATE_IN_AIR = 2
PREARM_CHECK = mavutil.mavlink.MAV_SYS_STATUS_PREARM_CHECK
# How long (simulation time) a script waits for the vehicle to be ready to arm: an EKF aligns and
# converges in a few seconds; one that cannot (no heading source, ...) fails with its reason.
READY_TIMEOUT_S = 30.0
# What the vehicle says about its readiness (autopilot/commander: PX4's "Preflight Fail: ..." while
# disarmed, "arming refused: ..." on a refused arm, "ready to arm" once ready again).
NOT_READY_PREFIXES = ("Preflight Fail: ", "arming refused: ")
READY_TO_ARM = "ready to arm"
CONFIRMING_READY = "the vehicle says it is ready to arm; its SYS_STATUS does not show it yet"
LANDED_STATE_NAMES = {0: "UNDEFINED", 1: "ON_GROUND", 2: "IN_AIR", 3: "TAKEOFF", 4: "LANDING"}
MAV_RESULT_NAMES = {
    0: "ACCEPTED",
    1: "TEMPORARILY_REJECTED",
    2: "DENIED",
    3: "UNSUPPORTED",
    4: "FAILED",
    5: "IN_PROGRESS",
    6: "CANCELLED",
}


class LinkError(RuntimeError):
    """Something the vehicle did or did not do; the message says what, for the user."""


class LinkTimeout(LinkError):
    """A wait ran out of simulation time (or of its wall-clock safety margin)."""


class CommandFailed(LinkError):
    """A COMMAND_LONG was answered with a result other than ACCEPTED (or not at all)."""

    def __init__(self, message: str, command: int, result: int | None) -> None:
        super().__init__(message)
        self.command = command
        self.result = result


def api_url(instance: int) -> str:
    """Where a flying script meets vehicle ``instance`` alone (:func:`quadcommon.wire.api_endpoint`
    under ``sitl.toml``'s ``[ports]``): ``udpin:127.0.0.1:14540+N`` for the first ten, else
    ``udpout:127.0.0.1:14580+N`` (the script's 1 Hz HEARTBEAT makes it a peer of that link)."""
    from quadcommon import wire
    from quadcommon.config import load_sitl

    kind, port = wire.api_endpoint(load_sitl().ports(instance), instance)
    return f"{kind}:127.0.0.1:{port}"


def gcs_url(instance: int) -> str:
    """Where a ground station (or the recorder) listens for vehicle ``instance``: the GCS client port
    of ``sitl.toml``'s ``[ports]``, QGroundControl's 14550 for every instance (the vehicles told
    apart by system id) unless configured otherwise."""
    from quadcommon.config import load_sitl

    return f"udpin:127.0.0.1:{load_sitl().ports(instance).gcs_remote}"


def custom_mode(name: str) -> tuple[int, int, int]:
    """(custom_mode, main, sub) of a PX4 mode name (``"OFFBOARD"``, ``"AUTO.LOITER"``, ``"HOLD"``...)."""
    key = name.strip().upper()
    key = MODE_ALIASES.get(key, key)
    if key not in PX4_MODES:
        known = ", ".join(list(PX4_MODES) + list(MODE_ALIASES))
        raise ValueError(f"unknown PX4 mode {name!r}; known: {known}")
    main, sub = PX4_MODES[key]
    return (main << 16) | (sub << 24), main, sub


def mode_name(custom: int) -> str:
    """PX4 name of a HEARTBEAT ``custom_mode`` (``"MODE(main,sub)"`` if unknown)."""
    main, sub = (custom >> 16) & 0xFF, (custom >> 24) & 0xFF
    if main == 0:
        return "NONE"  # no mode yet (e.g. heartbeats before the autopilot's first frame)
    for name, (m, s) in PX4_MODES.items():
        if m == main and (s == sub or (m != 4 and sub == 0)):
            return name
    return f"MODE({main},{sub})"


# --------------------------------------------------------------------------------------------
# Setpoints: the paper's frame for users, NED on the wire
# --------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class PositionTarget:
    """A setpoint in the paper's world frame (x north, y left/west, z up; SI units).

    ``velocity_m_s``/``acceleration_m_s2`` are feed-forward terms (None: not sent); ``yaw_rad``
    is the heading counter-clockwise from x seen from above (None: keep the current heading).
    """

    position_m: Vector3
    velocity_m_s: Vector3 | None = None
    acceleration_m_s2: Vector3 | None = None
    yaw_rad: float | None = None


@dataclass(frozen=True)
class NedTarget:
    """The fields of SET_POSITION_TARGET_LOCAL_NED (MAV_FRAME_LOCAL_NED) for one setpoint."""

    type_mask: int
    position: Vector3  # m, NED
    velocity: Vector3  # m/s, NED
    acceleration: Vector3  # m/s^2, NED
    yaw: float  # rad, NED (clockwise from north)
    yaw_rate: float  # rad/s (always ignored here)


def encode_target(target: PositionTarget) -> NedTarget:
    """Paper-frame setpoint -> NED fields and the PX4 type_mask (ignore-bits for what is unset).

    Position is always used; velocity and acceleration are feed-forward when given; yaw rate is
    always ignored (bit 2048) so the yaw, when given, is an absolute heading.
    """
    mask = IGNORE_YAW_RATE
    position = frames.vector_to_ned(target.position_m)
    velocity: Vector3 = (0.0, 0.0, 0.0)
    acceleration: Vector3 = (0.0, 0.0, 0.0)
    if target.velocity_m_s is None:
        mask |= IGNORE_VELOCITY
    else:
        velocity = frames.vector_to_ned(target.velocity_m_s)
    if target.acceleration_m_s2 is None:
        mask |= IGNORE_ACCELERATION
    else:
        acceleration = frames.vector_to_ned(target.acceleration_m_s2)
    yaw = 0.0
    if target.yaw_rad is None:
        mask |= IGNORE_YAW
    else:
        yaw = frames.wrap_pi(frames.yaw_to_ned(target.yaw_rad))
    return NedTarget(mask, position, velocity, acceleration, yaw, 0.0)


# --------------------------------------------------------------------------------------------
# The link
# --------------------------------------------------------------------------------------------
@dataclass
class VehicleView:
    """The latest telemetry, as received (NED/FRD, SI units). None until first received."""

    heartbeat: Any = None
    local_position: Any = None  # LOCAL_POSITION_NED
    attitude: Any = None  # ATTITUDE
    extended_sys_state: Any = None
    home_position: Any = None
    sys_status: Any = None  # SYS_STATUS: the pre-arm (armable) bit


class Link:
    """A connection to one vehicle: telemetry tracking, commands with ACK, waits in sim time.

    Everything advances through :meth:`poll` (non-blocking); the waits call it in a loop. Per
    received LOCAL_POSITION_NED, ``on_local_position`` (if set) is called: the hook reactive
    setpoint streams use, so a stream is paced by simulation time at any simulation speed.
    """

    def __init__(
        self,
        conn: Any,
        instance: int = 0,
        wall_factor: float = 3.0,
        wall_margin_s: float = 10.0,
        stall_wall_s: float = 5.0,
        log: Callable[[str], None] | None = None,
    ) -> None:
        self.conn = conn
        self.mav = conn.mav
        # An in-process connection (sitl.inprocess.StackConnection) advances the simulation when
        # polled: waiting must not sleep then.
        self._steps_time = bool(getattr(conn, "steps_time", False))
        self.instance = instance
        self.target_system = 1 + instance
        self.target_component = 1
        self.wall_factor = wall_factor  # wall safety = factor * sim timeout + margin (s)
        self.wall_margin_s = wall_margin_s
        self.stall_wall_s = stall_wall_s  # no new telemetry time stamp this long: simulation stopped
        self.view = VehicleView()
        self.sim_time_s: float | None = None  # latest time_boot_ms seen, s
        self.statustext: deque[tuple[float, int, str]] = deque(maxlen=200)
        self.on_local_position: Callable[[Any], None] | None = None
        self.log = log or (lambda text: None)
        self._acks: deque[tuple[Any, int]] = deque(maxlen=64)  # (COMMAND_ACK, texts so far)
        self._param_values: deque[Any] = deque(maxlen=64)  # PARAM_VALUE, newest last
        self._texts_seen = 0  # STATUSTEXT count, to find the ones that follow an ACK
        self._texts = StatusTextAssembler()  # a long STATUSTEXT comes in chunks
        self._next_gcs_heartbeat = 0.0
        self.messages_received = 0
        self._poll_first_time: float | None = None  # first telemetry time of the latest poll()

    # -- receiving -------------------------------------------------------------------------------
    def poll(self, max_messages: int = 1000) -> int:
        """Handle every message waiting (at most ``max_messages``); returns how many."""
        now = time.monotonic()
        if now >= self._next_gcs_heartbeat:
            # Ground stations announce themselves at 1 Hz (MAVSDK/QGC do); PX4 uses it for
            # GCS-loss detection, so a script behaves like any other GCS.
            self._next_gcs_heartbeat = now + 1.0
            self.mav.heartbeat_send(
                mavutil.mavlink.MAV_TYPE_GCS, mavutil.mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0
            )
        count = 0
        self._poll_first_time = None
        for _ in range(max_messages):
            msg = self.conn.recv_msg()
            if msg is None:
                break
            count += 1
            self._handle(msg)
        return count

    def _handle(self, msg: Any) -> None:
        if msg.get_srcSystem() != self.target_system:
            return
        kind = msg.get_type()
        if kind == "BAD_DATA":
            return
        self.messages_received += 1
        time_boot_ms = getattr(msg, "time_boot_ms", None)
        if time_boot_ms is not None:
            self._saw_time(time_boot_ms * 1e-3)
        elif kind == "ESTIMATOR_STATUS" and msg.time_usec * 1e-6 > (self.sim_time_s or -1.0):
            # The one clock of a vehicle whose EKF has no estimate yet (no time_boot_ms streams
            # before it has a state): a wait for it to become armable counts simulation time.
            self._saw_time(msg.time_usec * 1e-6)
        if kind == "HEARTBEAT":
            if msg.get_srcComponent() == self.target_component:
                self.view.heartbeat = msg
        elif kind == "LOCAL_POSITION_NED":
            self.view.local_position = msg
            if self.on_local_position is not None:
                self.on_local_position(msg)
        elif kind == "ATTITUDE":
            self.view.attitude = msg
        elif kind == "EXTENDED_SYS_STATE":
            self.view.extended_sys_state = msg
        elif kind == "HOME_POSITION":
            self.view.home_position = msg
        elif kind == "SYS_STATUS":
            self.view.sys_status = msg
        elif kind == "COMMAND_ACK":
            self._acks.append((msg, self._texts_seen))
        elif kind == "PARAM_VALUE":
            self._param_values.append(msg)
        elif kind == "STATUSTEXT":
            self._statustext(msg)

    def _saw_time(self, sim_time_s: float) -> None:
        self.sim_time_s = sim_time_s
        if self._poll_first_time is None:
            self._poll_first_time = sim_time_s

    def _statustext(self, msg: Any) -> None:
        """A STATUSTEXT, or a chunk of a longer one (joined by :class:`StatusTextAssembler`): a
        text is recorded once whole."""
        raw = msg.text.encode("utf-8", "replace") if isinstance(msg.text, str) else bytes(msg.text)
        ident, seq = int(getattr(msg, "id", 0) or 0), int(getattr(msg, "chunk_seq", 0) or 0)
        for severity, text in self._texts.add(int(msg.severity), raw, ident, seq):
            self.statustext.append((self.sim_time_s or 0.0, severity, text))
            self._texts_seen += 1
            self.log(f"t={self.sim_time_s or 0.0:.2f} s vehicle: {text}")

    # -- accessors -------------------------------------------------------------------------------
    @property
    def position_ned(self) -> Vector3 | None:
        """Latest LOCAL_POSITION_NED position (m, NED), or None."""
        lp = self.view.local_position
        return None if lp is None else (lp.x, lp.y, lp.z)

    @property
    def velocity_ned(self) -> Vector3 | None:
        """Latest LOCAL_POSITION_NED velocity (m/s, NED), or None."""
        lp = self.view.local_position
        return None if lp is None else (lp.vx, lp.vy, lp.vz)

    @property
    def position_paper(self) -> Vector3 | None:
        """Latest position in the paper's frame (x north, y left, z up; m), or None."""
        p = self.position_ned
        return None if p is None else frames.vector_from_ned(p)

    @property
    def velocity_paper(self) -> Vector3 | None:
        """Latest velocity in the paper's frame (x north, y left, z up; m/s), or None."""
        v = self.velocity_ned
        return None if v is None else frames.vector_from_ned(v)

    @property
    def yaw_paper(self) -> float | None:
        """Heading in the paper's frame (rad, counter-clockwise from x), or None."""
        att = self.view.attitude
        return None if att is None else frames.yaw_from_ned(att.yaw)

    @property
    def armed(self) -> bool:
        """The last HEARTBEAT has MAV_MODE_FLAG_SAFETY_ARMED set."""
        hb = self.view.heartbeat
        return hb is not None and bool(hb.base_mode & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED)

    @property
    def mode(self) -> str:
        """PX4 mode name from the latest HEARTBEAT (``""`` before the first)."""
        hb = self.view.heartbeat
        return "" if hb is None else mode_name(hb.custom_mode)

    @property
    def landed_state(self) -> int:
        """MAV_LANDED_STATE (0 undefined until EXTENDED_SYS_STATE arrives)."""
        ess = self.view.extended_sys_state
        return 0 if ess is None else int(ess.landed_state)

    @property
    def landed_state_name(self) -> str:
        """The EXTENDED_SYS_STATE landed state by name (e.g. ``ON_GROUND``, ``IN_AIR``)."""
        return LANDED_STATE_NAMES.get(self.landed_state, str(self.landed_state))

    @property
    def armable(self) -> bool:
        """The vehicle's pre-arm checks pass: SYS_STATUS ``onboard_control_sensors_health`` has
        ``MAV_SYS_STATUS_PREARM_CHECK`` (what MAVSDK's ``health.is_armable`` reads)."""
        status = self.view.sys_status
        return status is not None and bool(status.onboard_control_sensors_health & PREARM_CHECK)

    @property
    def ready_to_arm(self) -> bool:
        """Armable, and EXTENDED_SYS_STATE reports it on the ground (what PX4 clients wait for)."""
        return self.armable and self.landed_state == MAV_LANDED_STATE_ON_GROUND

    def not_ready_reason(self) -> str:
        """Why the vehicle is not ready to arm, as well as is known: the vehicle's own words (its
        latest ``Preflight Fail: ...`` or ``arming refused: ...`` STATUSTEXT not followed by
        ``ready to arm``), else what its telemetry shows."""
        said_ready = False
        for _, _, text in reversed(self.statustext):
            if text == READY_TO_ARM:
                said_ready = True
                break
            for prefix in NOT_READY_PREFIXES:
                if text.startswith(prefix):
                    return text[len(prefix):]
        status = self.view.sys_status
        if status is None:
            return "no SYS_STATUS from the vehicle yet"
        if not status.onboard_control_sensors_health & PREARM_CHECK:
            if said_ready:
                return CONFIRMING_READY
            if not status.onboard_control_sensors_health & mavutil.mavlink.MAV_SYS_STATUS_AHRS:
                return "SYS_STATUS: pre-arm checks failing, attitude/position estimate (AHRS) not healthy"
            return "SYS_STATUS: pre-arm checks failing"
        if self.landed_state != MAV_LANDED_STATE_ON_GROUND:
            return f"EXTENDED_SYS_STATE: landed state {self.landed_state_name}"
        return "unknown"

    @property
    def home_altitude_amsl_m(self) -> float | None:
        """The HOME_POSITION altitude above mean sea level (m), or None before one arrives."""
        hp = self.view.home_position
        return None if hp is None else hp.altitude * 1e-3

    def now(self) -> float:
        """Latest simulation time (s); 0 before any time-stamped telemetry."""
        return self.sim_time_s or 0.0

    # -- waiting ---------------------------------------------------------------------------------
    def wall_timeout(self, sim_timeout_s: float) -> float:
        """The wall-clock bound (s) for a wait of ``sim_timeout_s`` of simulation time."""
        return self.wall_factor * sim_timeout_s + self.wall_margin_s

    def wait_until(
        self,
        predicate: Callable[[Link], Any],
        sim_timeout_s: float,
        wall_timeout_s: float | None = None,
        what: str = "condition",
    ) -> Any:
        """Poll until ``predicate(self)`` is truthy; return its value.

        Raises :class:`LinkTimeout` after ``sim_timeout_s`` of simulation time (counted from the
        first time-stamped telemetry seen in this wait); when simulation time stops advancing for
        ``stall_wall_s`` of wall time (simulator stopped or lost: the autopilot then only sends
        wall-clock heartbeats); or after ``wall_timeout_s`` of wall time (default
        ``wall_factor * sim_timeout_s + wall_margin_s``: a simulation far slower than real time).
        """
        wall_limit = self.wall_timeout(sim_timeout_s) if wall_timeout_s is None else wall_timeout_s
        now = time.monotonic()
        wall_deadline = now + wall_limit
        sim_start = self.sim_time_s
        last_sim, last_advance = self.sim_time_s, now
        while True:
            got = self.poll()
            value = predicate(self)
            if value:
                return value
            now = time.monotonic()
            if self.sim_time_s != last_sim:
                last_sim, last_advance = self.sim_time_s, now
            if sim_start is None:
                # One poll may drain a burst: count from its first stamp, not its last.
                sim_start = self._poll_first_time
            if (
                sim_start is not None
                and self.sim_time_s is not None
                and self.sim_time_s - sim_start > sim_timeout_s
            ):
                raise LinkTimeout(
                    f"timed out after {sim_timeout_s:g} s of simulation time waiting for {what} "
                    f"(t={self.now():.2f} s, mode {self.mode or '?'}, {self.landed_state_name})"
                )
            if now - last_advance > self.stall_wall_s:
                last = f"; last STATUSTEXT: {self.statustext[-1][2]}" if self.statustext else ""
                raise LinkTimeout(
                    f"simulation time stopped at t={self.now():.2f} s ({self.stall_wall_s:g} s of wall "
                    f"time without telemetry time stamps) while waiting for {what}: is the simulator "
                    f"running?{last}"
                )
            if now > wall_deadline:
                raise LinkTimeout(
                    f"timed out after {wall_limit:g} s of wall time waiting for {what} "
                    f"(simulation too slow; t={self.now():.2f} s)"
                )
            if got == 0 and not self._steps_time:
                time.sleep(0.0005)  # nothing waiting: yield the CPU (the SITL shares it)

    def sleep_sim(self, seconds: float, what: str = "") -> None:
        """Keep polling (and streaming) for ``seconds`` of simulation time."""
        start: list[float | None] = [self.sim_time_s]

        def elapsed(link: Link) -> bool:
            if start[0] is None:
                start[0] = link.sim_time_s
                return False
            return link.sim_time_s is not None and link.sim_time_s - start[0] >= seconds

        self.wait_until(elapsed, sim_timeout_s=seconds + 1.0, what=what or f"{seconds:g} s to pass")

    def wait_heartbeat(self, timeout_s: float = 10.0) -> Any:
        """First HEARTBEAT of the vehicle's autopilot (wall-clock ``timeout_s``: nothing else to go on)."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            if self.poll() == 0:
                time.sleep(0.005)
            if self.view.heartbeat is not None:
                return self.view.heartbeat
        raise LinkTimeout(
            f"no HEARTBEAT from system {self.target_system} within {timeout_s:g} s on "
            f"{self.conn.address}: is the vehicle (--instance {self.instance}) running?"
        )

    # -- commands --------------------------------------------------------------------------------
    def command_long(
        self,
        command: int,
        params: Sequence[float] = (),
        ack_timeout_s: float = 1.0,
        attempts: int = 3,
        check: bool = True,
    ) -> int:
        """Send COMMAND_LONG, wait for its COMMAND_ACK (resending up to ``attempts`` times).

        The autopilot answers from its socket loop, independent of simulation time, so the ACK
        wait is on the wall clock (``ack_timeout_s`` per attempt). Returns the MAV_RESULT; with
        ``check`` a result other than ACCEPTED raises :class:`CommandFailed` naming the reason
        the vehicle gave in STATUSTEXT, if any.
        """
        p = [float(v) for v in params] + [0.0] * (7 - len(params))
        name = mavutil.mavlink.enums["MAV_CMD"].get(command)
        cmd_name = name.name if name is not None else str(command)
        for attempt in range(attempts):
            self._acks.clear()
            texts_before = self._texts_seen  # a refusal's reason may come just before the ACK
            self.mav.command_long_send(self.target_system, self.target_component, command, attempt, *p[:7])
            deadline = time.monotonic() + ack_timeout_s
            while time.monotonic() < deadline:
                if self.poll() == 0:
                    time.sleep(0.0005)
                for ack, _ in list(self._acks):
                    if ack.command != command:
                        continue
                    if ack.result == mavutil.mavlink.MAV_RESULT_IN_PROGRESS:
                        deadline = time.monotonic() + ack_timeout_s
                        continue
                    if ack.result != mavutil.mavlink.MAV_RESULT_ACCEPTED and check:
                        reasons = self.texts_since(texts_before)
                        why = f": {reasons[-1]}" if reasons else ""
                        result = MAV_RESULT_NAMES.get(ack.result, str(ack.result))
                        raise CommandFailed(f"{cmd_name} {result}{why}", command, ack.result)
                    return int(ack.result)
        if check:
            raise CommandFailed(
                f"{cmd_name}: no COMMAND_ACK after {attempts} attempts of {ack_timeout_s:g} s", command, None
            )
        return -1

    @property
    def texts_seen(self) -> int:
        """How many STATUSTEXT have arrived so far (a mark for :meth:`texts_since`)."""
        return self._texts_seen

    def texts_since(self, texts_before: int, wall_s: float = 0.05) -> list[str]:
        """The STATUSTEXT that arrived since the mark ``texts_before`` (:attr:`texts_seen`), waiting
        up to ``wall_s`` for one: PX4-like autopilots explain a command's result there, just before
        or after its ACK (the text may still be in the socket)."""
        deadline = time.monotonic() + wall_s
        while time.monotonic() < deadline and self._texts_seen == texts_before:
            if self.poll() == 0 and not self._steps_time:
                time.sleep(0.001)
        self.poll()  # a long text's further chunks, just behind its first
        new = min(self._texts_seen - texts_before, len(self.statustext))
        return [text for _, _, text in list(self.statustext)[len(self.statustext) - new :]]

    def set_parameter(self, name: str, value: float, integer: bool = False, timeout_s: float = 1.0,
                      attempts: int = 3) -> float:  # fmt: skip
        """PARAM_SET (an ``integer`` parameter as PX4 sends it: MAV_PARAM_TYPE_INT32, its bytes in
        the float field), waiting on the wall clock for the vehicle's PARAM_VALUE echo; returns the
        value the vehicle reports (the old one when it refused: the reason is in STATUSTEXT).
        :class:`LinkError` when no echo comes."""
        mavlink = mavutil.mavlink
        if integer:
            sent = struct.unpack("<f", struct.pack("<i", int(value)))[0]
            param_type = mavlink.MAV_PARAM_TYPE_INT32
        else:
            sent, param_type = float(value), mavlink.MAV_PARAM_TYPE_REAL32
        for _ in range(attempts):
            self._param_values.clear()
            self.mav.param_set_send(self.target_system, self.target_component, name.encode(), sent,
                                    param_type)  # fmt: skip
            deadline = time.monotonic() + timeout_s
            while time.monotonic() < deadline:
                if self.poll() == 0 and not self._steps_time:
                    time.sleep(0.0005)
                for echo in self._param_values:
                    echo_name = echo.param_id if isinstance(echo.param_id, str) else echo.param_id.decode()
                    if echo_name.rstrip("\x00") != name:
                        continue
                    if echo.param_type == mavlink.MAV_PARAM_TYPE_INT32:
                        return float(struct.unpack("<i", struct.pack("<f", echo.param_value))[0])
                    return float(echo.param_value)
        raise LinkError(f"PARAM_SET {name}: no PARAM_VALUE after {attempts} attempts of {timeout_s:g} s")

    def set_message_interval(self, msg_id: int, rate_hz: float) -> None:
        """MAV_CMD_SET_MESSAGE_INTERVAL on this link (rate in Hz of simulation time)."""
        interval_us = 1e6 / rate_hz if rate_hz > 0 else -1.0
        self.command_long(mavutil.mavlink.MAV_CMD_SET_MESSAGE_INTERVAL, (msg_id, interval_us))

    def request_message(self, msg_id: int) -> None:
        """Ask the vehicle for one message ``msg_id`` (MAV_CMD_REQUEST_MESSAGE; the ACK is not awaited)."""
        self.command_long(mavutil.mavlink.MAV_CMD_REQUEST_MESSAGE, (msg_id,))

    def set_mode(self, name: str) -> None:
        """DO_SET_MODE with a PX4 mode name (custom mode enabled, main mode, sub mode)."""
        _, main, sub = custom_mode(name)
        self.command_long(
            mavutil.mavlink.MAV_CMD_DO_SET_MODE,
            (mavutil.mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, main, sub),
        )

    def wait_mode(self, name: str, sim_timeout_s: float = 3.0) -> None:
        """Until the HEARTBEAT reports mode ``name``."""
        want = mode_name(custom_mode(name)[0])
        self.wait_until(lambda link: link.mode == want, sim_timeout_s, what=f"mode {want}")

    def arm(self, force: bool = False) -> None:
        """Send MAV_CMD_COMPONENT_ARM_DISARM to arm (``force``: PX4's magic 21196 skips the checks)."""
        self.command_long(mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM, (1.0, 21196.0 if force else 0.0))

    def wait_ready_to_arm(self, sim_timeout_s: float = READY_TIMEOUT_S) -> None:
        """Until the vehicle is ready to arm (:attr:`ready_to_arm`), as PX4 clients wait (QGC's
        "Ready To Fly", MAVSDK's ``health.is_armable``): an estimator still aligning or
        converging after ``quadsitl up`` is waited for, not refused. Says what it waits for (and
        again when the reason changes); :class:`LinkTimeout` with the reason after
        ``sim_timeout_s`` of simulation time."""
        if self.ready_to_arm or self.armed:
            return
        said = [""]

        def ready(link: Link) -> bool:
            if link.ready_to_arm or link.armed:
                return True
            reason = link.not_ready_reason()
            if reason != CONFIRMING_READY and _figures_aside(reason) != _figures_aside(said[0]):
                said[0] = reason
                report(link, f"waiting for the vehicle to be ready to arm: {reason}")
            return False

        try:
            self.wait_until(ready, sim_timeout_s, what="the vehicle to be ready to arm")
        except LinkTimeout as exc:
            raise LinkTimeout(f"{exc}: {self.not_ready_reason()}") from None

    def arm_when_ready(self, sim_timeout_s: float = READY_TIMEOUT_S) -> None:
        """:meth:`wait_ready_to_arm`, then arm (nothing if armed already)."""
        self.wait_ready_to_arm(sim_timeout_s)
        if not self.armed:
            self.arm()

    def disarm(self, force: bool = False) -> None:
        """Send MAV_CMD_COMPONENT_ARM_DISARM to disarm (``force``: 21196, even in flight)."""
        self.command_long(mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM, (0.0, 21196.0 if force else 0.0))

    def takeoff(self, altitude_above_home_m: float | None = None) -> None:
        """NAV_TAKEOFF to ``altitude_above_home_m`` (None: the vehicle's MIS_TAKEOFF_ALT).

        param7 is an altitude above mean sea level, so the home altitude from HOME_POSITION is
        asked for first (home is set where the vehicle armed).
        """
        altitude_amsl = math.nan
        if altitude_above_home_m is not None:
            altitude_amsl = self.fresh_home_altitude_amsl_m() + altitude_above_home_m
        self.command_long(
            mavutil.mavlink.MAV_CMD_NAV_TAKEOFF, (0, 0, 0, math.nan, math.nan, math.nan, altitude_amsl)
        )

    def fresh_home_altitude_amsl_m(self, sim_timeout_s: float = 5.0) -> float:
        """Home altitude (m AMSL) from a HOME_POSITION stamped no earlier than now.

        Asked for with MAV_CMD_REQUEST_MESSAGE; if the vehicle refuses that, the HOME_POSITION
        stream is sped up to 2 Hz instead (home moves when the vehicle arms, so an older
        HOME_POSITION may be stale).
        """
        since_us = int(self.now() * 1e6)
        ok = self.command_long(
            mavutil.mavlink.MAV_CMD_REQUEST_MESSAGE,
            (mavutil.mavlink.MAVLINK_MSG_ID_HOME_POSITION,),
            check=False,
        )
        if ok != mavutil.mavlink.MAV_RESULT_ACCEPTED:
            self.set_message_interval(mavutil.mavlink.MAVLINK_MSG_ID_HOME_POSITION, 2.0)

        def fresh(link: Link) -> bool:
            hp = link.view.home_position
            return hp is not None and hp.time_usec >= since_us

        self.wait_until(fresh, sim_timeout_s, what="a fresh HOME_POSITION")
        return self.home_altitude_amsl_m  # type: ignore[return-value]

    def land(self) -> None:
        """Send MAV_CMD_NAV_LAND: land here (NaN: the current position and heading)."""
        self.command_long(mavutil.mavlink.MAV_CMD_NAV_LAND, (0, 0, 0, math.nan, math.nan, math.nan, math.nan))

    def send_target(self, target: PositionTarget, time_boot_ms: int | None = None) -> None:
        """One SET_POSITION_TARGET_LOCAL_NED (MAV_FRAME_LOCAL_NED) for a paper-frame setpoint.

        ``time_boot_ms`` stamps the instant the setpoint is meant for (default: the latest
        telemetry time); PX4 itself ignores the field.
        """
        ned = encode_target(target)
        stamp = int(round(self.now() * 1e3)) if time_boot_ms is None else int(time_boot_ms)
        self.mav.set_position_target_local_ned_send(
            stamp & 0xFFFFFFFF,
            self.target_system,
            self.target_component,
            mavutil.mavlink.MAV_FRAME_LOCAL_NED,
            ned.type_mask,
            *ned.position,
            *ned.velocity,
            *ned.acceleration,
            ned.yaw,
            ned.yaw_rate,
        )

    def close(self) -> None:
        """Close the MAVLink connection."""
        self.conn.close()


class SetpointStream:
    """Reactive offboard stream: one setpoint per LOCAL_POSITION_NED sample received.

    ``provider(sample_time_s)`` returns the :class:`PositionTarget` for the simulation time of
    the sample (or None to skip). Because the stream is driven by telemetry stamped in
    simulation time, it keeps its rate (the telemetry rate) at any simulation speed.
    """

    def __init__(self, link: Link, provider: Callable[[float], PositionTarget | None]) -> None:
        self.link = link
        self.provider = provider
        self.sent = 0
        self.last_sample_s: float | None = None

    def _on_sample(self, msg: Any) -> None:
        t = msg.time_boot_ms * 1e-3
        self.last_sample_s = t
        target = self.provider(t)
        if target is not None:
            self.link.send_target(target, msg.time_boot_ms)
            self.sent += 1

    def start(self) -> SetpointStream:
        """Send a setpoint with every LOCAL_POSITION_NED received from now on; returns the stream."""
        self.link.on_local_position = self._on_sample
        return self

    def stop(self) -> None:
        """Stop sending setpoints (if this stream is the one attached to the link)."""
        if self.link.on_local_position == self._on_sample:
            self.link.on_local_position = None


def _figures_aside(text: str) -> str:
    """A reason without its figures (an alignment's elapsed time, a 1-sigma): the same reason."""
    return "".join("#" if c.isdigit() else c for c in text)


def report(link: Link | None, text: str) -> None:
    """One progress line on stdout, prefixed with the simulation time."""
    t = link.now() if link is not None else 0.0
    print(f"t={t:.2f} s {text}", flush=True)


def land_and_disarm(link: Link, sim_timeout_s: float, stream: SetpointStream | None = None) -> None:
    """NAV_LAND, wait for touchdown, then for the automatic disarm (or disarm after 5 s)."""
    link.land()
    if stream is not None:
        stream.stop()  # after the mode change, so no gap trips the offboard-loss failsafe first
    report(link, "landing")
    link.wait_until(
        lambda lk: lk.landed_state == MAV_LANDED_STATE_ON_GROUND and abs(lk.velocity_ned[2]) < 0.1,
        sim_timeout_s,
        what="landing",
    )
    report(link, "landed at ({:.2f}, {:.2f}, {:.2f})".format(*link.position_paper))
    try:
        link.wait_until(lambda lk: not lk.armed, 5.0, what="automatic disarm")
    except LinkTimeout:
        link.disarm()
        link.wait_until(lambda lk: not lk.armed, 3.0, what="disarm")
    report(link, "disarmed")


def emergency_land(link: Link, who: str) -> None:
    """Best effort after a failure: land if armed and flying, disarm if armed on the ground."""
    try:
        if link.armed and link.landed_state != MAV_LANDED_STATE_ON_GROUND:
            link.land()
            print(f"{who}: asked the vehicle to land (AUTO.LAND)", file=sys.stderr)
        elif link.armed:
            link.disarm()
            print(f"{who}: disarmed the vehicle", file=sys.stderr)
    except LinkError as exc:
        print(f"{who}: could not command a landing: {exc}", file=sys.stderr)


def connect(
    url: str | None = None,
    instance: int = 0,
    heartbeat_timeout_s: float = 10.0,
    log: Callable[[str], None] | None = None,
) -> Link:
    """Open ``url`` (default: the API port of ``instance``) and wait for the vehicle's HEARTBEAT.

    Only loopback ``udpin:``/``udpout:`` URLs are expected; a non-loopback host is refused.
    """
    url = url or api_url(instance)
    _check_loopback(url)
    conn = mavutil.mavlink_connection(
        url, source_system=GCS_SYSTEM_ID, source_component=GCS_COMPONENT_ID, dialect="common"
    )
    link = Link(conn, instance, log=log)
    try:
        link.wait_heartbeat(heartbeat_timeout_s)
    except BaseException:
        link.close()
        raise
    return link


def _check_loopback(url: str) -> None:
    kind, _, rest = url.partition(":")
    if kind not in ("udpin", "udpout", "udp"):
        raise ValueError(f"only udpin:/udpout: URLs are supported, got {url!r}")
    host = rest.rsplit(":", 1)[0]
    if host not in ("127.0.0.1", "localhost"):
        raise ValueError(f"only loopback addresses are allowed (127.0.0.1), got {url!r}")
