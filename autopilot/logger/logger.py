"""The flight logger: when a log runs (``SDLOG_MODE``, as PX4's logger) and the ULog bytes of it.

Pure: the core calls :meth:`FlightLogger.frame` once per control step, after the answer has
gone to the simulator (and, when periodic topics are due, :meth:`FlightLogger.sample_due`); the
shell takes
what it wrote with :meth:`FlightLogger.take` (:class:`LogOpen` / bytes / :class:`LogClose` in
file order) and writes it, in a thread off the lockstep's critical path (:mod:`.storage`).

``SDLOG_MODE`` (PX4's values): -1 no logging; 0 from arming until disarming (default); 1 from
boot until the first disarming, then from arming until disarming; 2 from boot until shutdown;
4 from the first arming until shutdown. Boot is the first frame. A simulator that restarts
(time going backwards) ends the log: a ULog's time cannot go back; a new one starts as the mode
says. A mode change takes effect at the next frame.

A log holds the definitions (formats, info, every parameter's value at the start), then samples
of :data:`~.topics.TOPICS` at their rates, every STATUSTEXT as a logged string with its
severity, every parameter change, and the simulator's disturbance and rotors' health as the frames
report them.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import NamedTuple

from quadcommon import ulog_topics
from quadcommon.build_info import flight_sw_version
from quadcommon.mavlink_fast import MessageParts

from ..params.store import INT32, ParameterStore
from . import topics, ulog
from .topics import TOPICS, Snapshot

SDLOG_OFF, SDLOG_WHILE_ARMED, SDLOG_BOOT_UNTIL_DISARM, SDLOG_BOOT_UNTIL_SHUTDOWN = -1, 0, 1, 2
SDLOG_FIRST_ARM_UNTIL_SHUTDOWN = 4
SYNC_EVERY_US = 1_000_000  # a sync marker per second of log (lets a reader resynchronise)
DISTURBANCE_INTERVAL_US = 10_000  # the simulator's disturbance reports while it changes


@dataclass(frozen=True)
class LogOptions:
    """Where an autopilot logs: ``directory`` (None: no flight log at all) and the wall clock
    (POSIX seconds) for UTC times in the log (None: none there); ``version``: the software's, for
    the log's ``ver_sw`` (the shell reads it from the installed package)."""

    directory: str | None = None
    utc_clock: Callable[[], float] | None = None
    version: str = ""

    @property
    def enabled(self) -> bool:
        """True when the autopilot writes a flight log (a directory is given)."""
        return self.directory is not None


def log_info(version: str, controller: str, vehicle: str, estimator: str, instance: int) -> dict:
    """The log's information messages: PX4's keys where they mean the same (Flight Review shows
    ``sys_name``, ``ver_hw``, ``ver_sw``; ``ver_data_format`` 2 says vehicle_gps_position has
    ``latitude_deg``...), and what the run is (controller, vehicle, estimator, instance)."""
    return {
        "sys_name": "quadsitl",
        "ver_hw": "SITL",
        "ver_sw": f"quadsitl {version}".strip(),
        "ver_sw_release": flight_sw_version(version),  # PX4's 0xMMmmppTT
        "ver_data_format": 2,
        "sys_os_name": "Linux",
        "sys_toolchain": "CPython",
        "quadsitl_controller": controller,
        "quadsitl_vehicle": vehicle,
        "quadsitl_estimator": estimator,
        "quadsitl_instance": instance,
    }


class LogOpen(NamedTuple):
    """A new log starts here: ``utc_s`` is the wall clock when it started (None: no clock given)."""

    start_us: int  # simulation time of its first sample
    utc_s: float | None


class LogClose(NamedTuple):
    end_us: int


class _Periodic(NamedTuple):
    """One periodic topic of the open log: its message, the builder of its values, and what is
    appended to them (the laws' states of ``cascade_status``), if anything."""

    topic: ulog.Topic
    build: Callable[[Snapshot], tuple | None]
    extra: Callable[[], Sequence[float]] | None = None


class _Group:
    """The periodic topics of one interval: due together (the frames' clock is checked once per
    interval, not once per topic)."""

    __slots__ = ("interval_us", "next_us", "topics")

    def __init__(self, interval_us: int, next_us: int) -> None:
        self.interval_us = interval_us
        self.next_us = next_us
        self.topics: list[_Periodic] = []


class FlightLogger:
    """``info``: the log's information messages (``sys_name``, ``ver_sw``, ...); ``law_states``:
    the cascade's :meth:`~autopilot.control.cascade.Cascade.law_states` (read at the rate of
    ``cascade_status``); ``utc_clock``: the wall clock (POSIX seconds) the shell gives, for the
    GPS topic's UTC time and the file name, or None (in-process runs: no wall time in the log)."""

    def __init__(
        self,
        params: ParameterStore,
        info: dict[str, str | int],
        law_states: Callable[[], tuple[tuple[str, ...], tuple[float, ...]]],
        snapshot: Snapshot,
        utc_clock: Callable[[], float] | None = None,
        enabled: bool = True,
    ) -> None:
        self.params = params
        self.info = info
        self.law_states = law_states
        self.snapshot = snapshot
        self.utc_clock = utc_clock
        self.enabled = enabled
        self.logging = False
        self.logs_started = 0
        self._out: list = []  # LogOpen / bytes / LogClose, in file order, until take()
        self._buffer = bytearray()  # the open log's bytes since the last take()
        self._was_armed = False
        self._decide = True  # the next update() decides whether a log runs (first frame, SDLOG_MODE)
        self._ever_armed = False
        self._disarmed_since_boot = False
        self._last_t_us = -1
        self._every_step: list[tuple[ulog.Topic, Callable[[Snapshot], tuple | None]]] = []
        self._groups: list[_Group] = []
        self._gps: ulog.Topic | None = None
        self._status: ulog.Topic | None = None
        self._status_mode: float | None = None  # the row's custom_mode and armed at the last status
        self._status_armed: float | None = None
        self._disturbance: ulog.Topic | None = None
        self._disturbance_held: tuple | None = None  # the simulator's last report (held between)
        self._disturbance_logged_us = 0
        self._rotors: ulog.Topic | None = None
        self._rotors_held: tuple | None = None  # the rotors' health last reported
        self._next_due_us = 0
        self._next_sync_us = 0
        self._start_us = 0

    # -- inputs ---------------------------------------------------------------------------------
    def update(self, t_us: int, armed: bool) -> bool:
        """Start or stop the log as ``SDLOG_MODE`` says for this frame; True while a log is open
        (:meth:`frame` calls it; the rest of a frame is sampled there)."""
        if t_us > self._last_t_us and armed == self._was_armed and not self._decide:
            self._last_t_us = t_us  # most frames: nothing that could start or stop a log changed
            return self.logging
        if not self.enabled:
            return False
        if t_us < self._last_t_us:  # the simulator restarted: this log's time cannot go back
            self.stop()
            self._disarmed_since_boot = False
        self._last_t_us = t_us
        if armed and not self._was_armed:
            self._ever_armed = True
        elif self._was_armed and not armed:
            self._disarmed_since_boot = True
        self._was_armed = armed
        self._decide = False
        want = self._wanted(armed)
        if want != self.logging:
            if want:
                self._start(t_us)
            else:
                self.stop()
        return self.logging

    def frame(
        self, t_us: int, armed: bool, truth, row: tuple, parts: MessageParts | None, estimate, output
    ) -> bool:
        """One control step: :meth:`update`, then, while a log is open, the topics of every step
        (interval 0: ``paper_tracking``, the IMU, the body rates, the torque and thrust setpoints)
        from the frame's ``truth``, controller ``row``, undecoded messages ``parts``, the
        ``estimate`` flown on and the cascade's ``output`` (None: motors off); the GPS fix when the
        frame carries one, ``vehicle_status`` when the mode or arming changed. True when periodic
        topics are due: the caller then fills the rest of the snapshot and calls
        :meth:`sample_due` (most frames need neither)."""
        if t_us <= self._last_t_us or armed != self._was_armed or self._decide:
            if not self.update(t_us, armed):
                return False
        else:  # (update's common case, inline: this runs every control step)
            self._last_t_us = t_us
            if not self.logging:
                return False
        s = self.snapshot
        s.t_us = t_us
        s.truth = truth
        s.row = row
        s.parts = parts
        s.estimate = estimate
        s.output = output
        buf = self._buffer
        for topic, build in self._every_step:
            values = build(s)
            if values is not None:
                buf += topic.prefix
                buf += topic.pack(*values)
        if parts is not None and topics.GPS_ID in parts:
            s.gps = topics.gps_of(parts)
            values = topics.vehicle_gps_position(s)
            if values is not None:
                buf += self._gps.sample(values)
        if row[topics.ROW_CUSTOM_MODE] != self._status_mode or row[topics.ROW_ARMED] != self._status_armed:
            self._on_status_change(row[topics.ROW_CUSTOM_MODE], row[topics.ROW_ARMED], t_us)
        return t_us >= self._next_due_us

    def sample_due(self) -> None:
        """The periodic topics due at this frame."""
        s = self.snapshot
        t_us = s.t_us
        buf = self._buffer
        next_due = t_us + 3_600_000_000
        for group in self._groups:
            if t_us >= group.next_us:
                for topic, build, extra in group.topics:
                    values = build(s)
                    if values is not None:
                        if extra is not None:
                            values = (*values, *extra())
                        buf += topic.prefix
                        buf += topic.pack(*values)
                group.next_us += group.interval_us
                if group.next_us <= t_us:
                    group.next_us = t_us + group.interval_us
            if group.next_us < next_due:
                next_due = group.next_us
        self._next_due_us = next_due
        if t_us >= self._next_sync_us:
            buf += ulog.sync()
            self._next_sync_us = t_us + SYNC_EVERY_US

    def statustext(self, severity: int, text: str, t_s: float) -> None:
        """A STATUSTEXT as a logged string (its severity is the log level)."""
        if self.logging:
            self._buffer += ulog.logged_string(severity, self._clamp(t_s), text)

    def parameter(self, name: str, value: float) -> None:
        """A parameter change, logged where it happened."""
        if name == "SDLOG_MODE":
            self._decide = True
        if self.logging:
            spec = self.params.specs.get(name)
            self._buffer += ulog.parameter(name, value, spec is not None and spec.kind == INT32)

    def disturbance(self, t_us: int, force: Sequence[float], torque: Sequence[float]) -> None:
        """A report of the simulator's applied disturbance (force, world; torque on the Euler
        coordinates; the paper's frames) sampled at ``t_us``. The simulator reports changes (at
        an onset, every 10 ms while it changes, where it settles) and a steady value now and then
        (``DISTURB``, :mod:`quadcommon.wire`); between reports it holds. Each report is logged;
        before an onset, the value held until just before it (when it was last logged longer ago
        than the reports' 10 ms), so that a step is drawn as a step by plotting tools that join
        samples with lines. The last report is kept while no log is open: a log starts with it."""
        values = (*force, *torque)
        held, self._disturbance_held = self._disturbance_held, values
        if not self.logging:
            return
        # Not before what this log has (a ULog topic's time only goes forward): a value that
        # settled in the frame before the log started is logged as of the start.
        t_us = max(t_us, self._disturbance_logged_us)
        topic = self._disturbance
        if (
            held is not None
            and values != held
            and t_us - self._disturbance_logged_us > DISTURBANCE_INTERVAL_US
        ):
            self._buffer += topic.sample((t_us - 1, *held))
        self._buffer += topic.sample((t_us, *values))
        self._disturbance_logged_us = t_us

    def rotor_health(self, t_us: int, effectiveness: Sequence[float], failure: Sequence[int]) -> None:
        """The rotors' health the simulator reports (``sim_rotors``): logged when it changes (and,
        the last one kept while no log is open, when a log starts)."""
        values = (*effectiveness, *failure)
        if values == self._rotors_held:
            return
        self._rotors_held = values
        if self.logging:
            self._buffer += self._rotors.sample((max(t_us, self._start_us), *values))

    def stop(self) -> None:
        """End the open log (disarm, shutdown, a simulator restart); nothing if none is open."""
        if not self.logging:
            return
        self.logging = False
        self._flush_buffer()
        self._out.append(LogClose(self._last_t_us))

    def take(self) -> list:
        """What was written since the last call: LogOpen / bytes / LogClose, in file order."""
        self._flush_buffer()
        out, self._out = self._out, []
        return out

    # -- internals ------------------------------------------------------------------------------
    def _wanted(self, armed: bool) -> bool:
        mode = int(self.params.values.get("SDLOG_MODE", SDLOG_WHILE_ARMED))
        if mode == SDLOG_WHILE_ARMED:
            return armed
        if mode == SDLOG_BOOT_UNTIL_DISARM:
            return armed or not self._disarmed_since_boot
        if mode == SDLOG_BOOT_UNTIL_SHUTDOWN:
            return True
        if mode == SDLOG_FIRST_ARM_UNTIL_SHUTDOWN:
            return self._ever_armed
        return False  # SDLOG_OFF

    def _clamp(self, t_s: float) -> int:
        t_us = round(t_s * 1e6) if math.isfinite(t_s) else self._last_t_us
        return max(min(t_us, self._last_t_us), self._start_us)

    def _flush_buffer(self) -> None:
        if self._buffer:
            self._out.append(bytes(self._buffer))
            self._buffer.clear()

    def _start(self, t_us: int) -> None:
        utc = self.utc_clock() if self.utc_clock is not None else None
        names, _ = self.law_states()
        law_fields, extras = self._law_fields(names), self._extras(names)
        buf = bytearray(ulog.file_header(t_us))
        buf += ulog.flag_bits()
        formats = [spec.format(law_fields if spec.name == ulog_topics.CASCADE else "") for spec in TOPICS]
        nested: list[ulog.Format] = []
        for fmt in formats:
            nested.extend(n for n in fmt.nested if n not in nested)
        for fmt in (*nested, *formats):
            buf += ulog.format_message(fmt)
        for key, value in self.info.items():
            buf += ulog.info(key, value, "uint32_t" if key in _UINT32_INFO else None)
        if utc is not None:
            buf += ulog.info("time_ref_utc", 0)
        for name, value in self.params.values.items():
            buf += ulog.parameter(name, value, self.params.specs[name].kind == INT32)
        groups: dict[int, _Group] = {}
        self._every_step = []
        for msg_id, (spec, fmt) in enumerate(zip(TOPICS, formats, strict=True)):
            buf += ulog.add_logged(msg_id, spec.name)
            topic = ulog.Topic(fmt, msg_id)
            if spec.name == "vehicle_gps_position":
                self._gps = topic
            elif spec.name == ulog_topics.DISTURBANCE:
                self._disturbance = topic
            elif spec.name == ulog_topics.ROTORS:
                self._rotors = topic
            elif spec.interval_ms == 0:
                self._every_step.append((topic, spec.build))
            else:
                if spec.name == "vehicle_status":
                    self._status = topic
                group = groups.setdefault(spec.interval_ms, _Group(spec.interval_ms * 1000, t_us))
                group.topics.append(_Periodic(topic, spec.build, extras.get(spec.name)))
        self._groups = sorted(groups.values(), key=lambda g: g.interval_us)
        self._flush_buffer()
        self._out.append(LogOpen(t_us, utc))
        self._buffer += buf
        self.logging = True
        self.logs_started += 1
        self._start_us = t_us
        self.snapshot.utc_offset_us = round(utc * 1e6) - t_us if utc is not None else 0
        self._next_due_us = t_us
        self._next_sync_us = t_us
        self._status_mode = self._status_armed = None
        self._disturbance_logged_us = t_us
        if self._disturbance_held is not None:  # what applies as the log starts
            self._buffer += self._disturbance.sample((t_us, *self._disturbance_held))
        if self._rotors_held is not None:
            self._buffer += self._rotors.sample((t_us, *self._rotors_held))

    def _law_fields(self, names: Sequence[str]) -> str:
        """``cascade_status``'s fields after PX4's: one per state of the laws."""
        return "".join(f"float {topics.law_state_field(n)};" for n in names)

    def _extras(self, names: Sequence[str]) -> dict[str, Callable[[], Sequence[float]]]:
        """What is appended to a topic's built values: the laws' states (``cascade_status``), the
        rate integrals PX4 logs (``rate_ctrl_status``)."""
        return {ulog_topics.CASCADE: self._law_state_values,
                topics.RATE_CTRL: topics.rate_integrals(names, self.law_states)}  # fmt: skip

    def sample_now(self, name: str, snapshot: Snapshot) -> tuple[list[str], tuple] | None:
        """Topic ``name`` as a log would hold it for ``snapshot`` (the console's ``listener``): its
        fields' names (pyulog's) and values; None for no such topic, or no data for it now."""
        spec = next((s for s in TOPICS if s.name == name), None)
        values = spec.build(snapshot) if spec is not None else None
        if values is None:
            return None
        names, _ = self.law_states()
        extra = self._extras(names).get(name)
        if extra is not None:
            values = (*values, *extra())
        fields = spec.format(self._law_fields(names) if name == ulog_topics.CASCADE else "").field_names()
        return fields, values

    def _law_state_values(self) -> tuple[float, ...]:
        return self.law_states()[1]

    def _on_status_change(self, mode: float, armed: float, t_us: int) -> None:
        """vehicle_status at once when the mode or arming changes (PX4's commander publishes it
        then), besides its periodic sample; the times of the last arming and mode change."""
        s = self.snapshot
        if self._status_mode is not None and mode != self._status_mode:
            s.mode_time_us = t_us
        if armed > 0.5 and not (self._status_armed is not None and self._status_armed > 0.5):
            s.arming_time_us = t_us
        self._status_mode, self._status_armed = mode, armed
        self._buffer += self._status.sample(topics.vehicle_status(s))  # reads the row only


_UINT32_INFO = ("ver_sw_release", "ver_data_format")
