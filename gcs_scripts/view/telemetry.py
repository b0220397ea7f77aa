"""What the view takes from the autopilot's MAVLink telemetry: mode, armed, landed, failsafe, texts.

Pure: datagrams and parsed messages in, state out; the sockets live in :mod:`.live`.

The autopilot streams every message of its GCS link to the view (it answers every address that
talks to it), ~150 messages/s at real time and ~12x that at ``--speed max``. The view needs four
of them, so :func:`wanted_frames` picks those out of a datagram by the MAVLink header alone and
only they are handed to pymavlink's parser: decoding everything would cost the view several
percent of a core at ``--speed max``, time taken from the simulator and autopilot on a 2-core
machine.

The active failsafe is not a MAVLink field (PX4 shows it in STATUSTEXT and in the mode it
forces); it is inferred from the autopilot's STATUSTEXT (:data:`FAILSAFE_RULES`, the texts of
``autopilot/commander``) and ends with its own "recovered" text, with a later mode change (the
pilot took over) or with the disarm.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any

MSG_HEARTBEAT = 0
MSG_SYS_STATUS = 1
MSG_EXTENDED_SYS_STATE = 245
MSG_STATUSTEXT = 253
WANTED_MESSAGE_IDS = frozenset({MSG_HEARTBEAT, MSG_SYS_STATUS, MSG_EXTENDED_SYS_STATE, MSG_STATUSTEXT})

MAV_MODE_FLAG_SAFETY_ARMED = 128
MAV_SYS_STATUS_GEOFENCE = 1 << 20
STATUSTEXT_CHUNK = 50  # bytes of text per STATUSTEXT; a shorter chunk ends a multi-chunk text
LANDED_STATE_NAMES = {0: "UNDEFINED", 1: "ON_GROUND", 2: "IN_AIR", 3: "TAKEOFF", 4: "LANDING"}
SEVERITY_NAMES = ("EMERGENCY", "ALERT", "CRITICAL", "ERROR", "WARNING", "NOTICE", "INFO", "DEBUG")


def wanted_frames(
    datagram: bytes, system_id: int, component_id: int = 1, wanted: frozenset[int] = WANTED_MESSAGE_IDS
) -> Iterator[bytes]:
    """The frames of ``datagram`` from (``system_id``, ``component_id``) whose id is in ``wanted``.

    Walks MAVLink 1 (0xFE) and 2 (0xFD, signed or not) frames by their length fields without
    decoding payloads or checking CRCs (the parser checks those on the frames kept). Stops at the
    first byte that does not start a frame.
    """
    n = len(datagram)
    i = 0
    while i + 8 <= n:
        magic = datagram[i]
        if magic == 0xFD:
            length = 12 + datagram[i + 1] + (13 if datagram[i + 2] & 1 else 0)  # 10 header + 2 CRC
            sysid, compid = datagram[i + 5], datagram[i + 6]
            msgid = datagram[i + 7] | (datagram[i + 8] << 8) | (datagram[i + 9] << 16) if i + 10 <= n else -1
        elif magic == 0xFE:
            length = 8 + datagram[i + 1]
            sysid, compid, msgid = datagram[i + 3], datagram[i + 4], datagram[i + 5]
        else:
            return
        if i + length > n:
            return
        if msgid in wanted and sysid == system_id and compid == component_id:
            yield datagram[i : i + length]
        i += length


class StatusTextAssembler:
    """Joins the chunks of a long STATUSTEXT (MAVLink 2 ``id`` and ``chunk_seq``) into one text.

    ``id == 0`` is a text of one chunk. Otherwise chunks of the same id are joined until one is
    shorter than 50 bytes (the last); at most ``max_pending`` ids are kept waiting, so a lost last
    chunk cannot grow memory: the oldest pending text is then given out as it is.
    """

    def __init__(self, max_pending: int = 8) -> None:
        self.max_pending = max_pending
        self._pending: dict[int, list[tuple[int, int, str]]] = {}

    def add(
        self, severity: int, raw: bytes | str, ident: int = 0, chunk_seq: int = 0
    ) -> list[tuple[int, str]]:
        """One STATUSTEXT; returns the texts completed by it as ``(severity, text)``."""
        if isinstance(raw, str):
            raw = raw.encode("utf-8", "replace")
        last = len(raw.rstrip(b"\x00")) < STATUSTEXT_CHUNK
        text = raw.rstrip(b"\x00").decode("utf-8", "replace")
        if ident == 0:
            return [(severity, text)]
        chunks = self._pending.setdefault(ident, [])
        chunks.append((chunk_seq, severity, text))
        out: list[tuple[int, str]] = []
        if last:
            del self._pending[ident]
            chunks.sort()
            out.append((chunks[0][1], "".join(c[2] for c in chunks)))
        while len(self._pending) > self.max_pending:
            oldest = next(iter(self._pending))
            stale = sorted(self._pending.pop(oldest))
            out.append((stale[0][1], "".join(c[2] for c in stale)))
        return out


@dataclass(frozen=True)
class FailsafeRule:
    name: str  # shown on the page
    starts_with: str  # STATUSTEXT that announces it (prefix)
    recovered_by: str = ""  # STATUSTEXT that ends it (prefix); "" = none
    ends_on_mode_change: bool = True  # a later mode change (pilot took over) ends it
    ends_on_disarm: bool = True


# The autopilot's own texts (autopilot/commander/commander.py, failsafe.py, autopilot/app.py).
FAILSAFE_RULES: tuple[FailsafeRule, ...] = (
    FailsafeRule(
        "GCS link lost", "GCS connection lost", "GCS connection regained", ends_on_mode_change=False
    ),
    FailsafeRule("geofence", "geofence breached"),
    FailsafeRule("offboard loss", "offboard setpoints lost"),
    FailsafeRule(
        "simulator lost", "simulator lost", "simulator link recovered", ends_on_mode_change=False,
        ends_on_disarm=False,
    ),
)  # fmt: skip


class FailsafeTracker:
    """The active failsafe (or None) from the STATUSTEXT feed and the heartbeat."""

    def __init__(self, rules: tuple[FailsafeRule, ...] = FAILSAFE_RULES) -> None:
        self.rules = rules
        self.active: FailsafeRule | None = None
        self.text = ""
        self._mode_after: str | None = None  # the mode the failsafe put the vehicle in

    @property
    def name(self) -> str | None:
        """The active failsafe's name, or None."""
        return None if self.active is None else self.active.name

    def statustext(self, text: str) -> None:
        """Start a failsafe whose STATUSTEXT this is, or end the active one this text recovers."""
        for rule in self.rules:
            if text.startswith(rule.starts_with):
                self.active, self.text, self._mode_after = rule, text, None
                return
            if rule.recovered_by and text.startswith(rule.recovered_by) and self.active is rule:
                self.active, self.text = None, ""
                return

    def heartbeat(self, mode: str, armed: bool) -> None:
        """End the active failsafe on a disarm, or on a mode change after the failsafe's own mode
        (where its rule says so)."""
        rule = self.active
        if rule is None:
            return
        if rule.ends_on_disarm and not armed:
            self.active, self.text = None, ""
            return
        if self._mode_after is None:
            self._mode_after = mode  # the first heartbeat after the text shows the failsafe's mode
        elif rule.ends_on_mode_change and mode != self._mode_after:
            self.active, self.text = None, ""


def mode_name(custom_mode: int) -> str:
    """PX4 name of a HEARTBEAT ``custom_mode`` (the table of :mod:`gcs_scripts.link`)."""
    from gcs_scripts.link import mode_name as px4_mode_name

    return px4_mode_name(int(custom_mode))


class VehicleTelemetry:
    """Mode, armed and landed state, geofence health, STATUSTEXT and the failsafe of one vehicle."""

    def __init__(self, max_texts: int = 200) -> None:
        self.mode = ""
        self.armed: bool | None = None
        self.landed = ""
        self.geofence_breached = False
        self.heartbeats = 0
        self.failsafe = FailsafeTracker()
        self.texts: deque[tuple[float, int, str]] = deque(maxlen=max_texts)
        self.new_texts: list[tuple[float, int, str]] = []  # since the last take_texts()
        self._assembler = StatusTextAssembler()

    def add(self, msg: Any, sim_time_s: float) -> None:
        """One parsed pymavlink message of the vehicle; ``sim_time_s`` stamps its texts."""
        msg_id = msg.get_msgId()
        if msg_id == MSG_HEARTBEAT:
            self.heartbeats += 1
            self.mode = mode_name(msg.custom_mode)
            self.armed = bool(msg.base_mode & MAV_MODE_FLAG_SAFETY_ARMED)
            self.failsafe.heartbeat(self.mode, self.armed)
        elif msg_id == MSG_EXTENDED_SYS_STATE:
            self.landed = LANDED_STATE_NAMES.get(int(msg.landed_state), str(msg.landed_state))
        elif msg_id == MSG_SYS_STATUS:
            present = msg.onboard_control_sensors_present & MAV_SYS_STATUS_GEOFENCE
            healthy = msg.onboard_control_sensors_health & MAV_SYS_STATUS_GEOFENCE
            self.geofence_breached = bool(present and not healthy)
        elif msg_id == MSG_STATUSTEXT:
            raw = msg.text.encode("utf-8", "replace") if isinstance(msg.text, str) else bytes(msg.text)
            ident = int(getattr(msg, "id", 0) or 0)
            seq = int(getattr(msg, "chunk_seq", 0) or 0)
            for severity, text in self._assembler.add(int(msg.severity), raw, ident, seq):
                entry = (sim_time_s, severity, text)
                self.texts.append(entry)
                self.new_texts.append(entry)
                self.failsafe.statustext(text)

    def take_texts(self) -> list[tuple[float, int, str]]:
        """The STATUSTEXTs (time s, severity, text) received since the last call."""
        out, self.new_texts = self.new_texts, []
        return out

    @property
    def failsafe_name(self) -> str | None:
        """The active failsafe's name, ``geofence`` on a breach, or None."""
        if self.failsafe.name is not None:
            return self.failsafe.name
        return "geofence" if self.geofence_breached else None
