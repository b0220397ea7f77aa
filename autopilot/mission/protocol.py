"""The MAVLink mission protocol, autopilot side (pure: messages and a monotonic clock in,
messages out; no sockets, no clock of its own).

Behaviour follows PX4's ``mavlink_mission.cpp`` and the MAVLink mission service, so pymavlink,
MAVProxy, MAVSDK and QGroundControl transfers work; the differences are deliberate and listed.

Upload (ground station -> vehicle)::

    MISSION_COUNT(n) -> MISSION_REQUEST_INT(0) -> MISSION_ITEM_INT(0) -> ... -> MISSION_ACK

* Each item is validated as it arrives (:func:`autopilot.mission.items.parse_item`); a bad one
  ends the upload with its MAV_MISSION_RESULT (``UNSUPPORTED`` for an unknown command,
  ``UNSUPPORTED_FRAME``, ``INVALID_PARAMn``); after the last item the whole mission is checked
  (``check``, e.g. a timed curve faster than the speed limits) before ``ACCEPTED``.
* The new mission replaces the stored one only when the upload is accepted: any failure, cancel
  or timeout leaves the previous mission intact (received items are kept aside until then).
* Out-of-sequence items are dropped (an item after a gap re-requests the expected one at once;
  a repeated earlier item is ignored, so duplicates cannot start a request storm).
* Timeouts, wall clock (``now``), PX4's rule (``mavlink_mission``: retry timeout 250 ms,
  protocol timeout 5 s): the expected item is re-requested every ``retry_s`` (0.25 s) for as long
  as the client keeps sending; ``protocol_timeout_s`` (5 s) without an item from it cancels the
  upload with ``MISSION_ACK(MAV_MISSION_OPERATION_CANCELLED)`` and a STATUSTEXT. PX4 only sends the
  STATUSTEXT ("Operation timeout"); the ACK is what the mission service prescribes for a
  cancelled operation, and tells a still-listening client at once.
* A repeated ``MISSION_COUNT`` from the uploading client restarts its upload (it evidently gave
  up and started again; PX4 answers ``ERROR`` once an item has arrived); a ``MISSION_COUNT`` from
  another client while busy gets ``MISSION_ACK(ERROR)`` (as PX4). ``MISSION_COUNT(0)`` clears.
* Only the INT path is offered: a float ``MISSION_ITEM`` is answered ``MAV_MISSION_UNSUPPORTED``
  (ending an upload from that client). PX4 would switch to float mode; we refuse because float
  latitude/longitude lose ~1 m and every current client uses the INT messages.

Download (vehicle -> ground station)::

    MISSION_REQUEST_LIST -> MISSION_COUNT(n) -> MISSION_REQUEST_INT(i) -> MISSION_ITEM_INT(i) ...
    -> MISSION_ACK

* Items go back exactly as uploaded (the stored wire fields), ``current`` = 1 on the current item.
  Requests may come in any order and repeat (MAVProxy bursts them); a ``seq`` out of range ends the
  download with ``MISSION_ACK(MAV_MISSION_INVALID_SEQUENCE)``. The client drives the retries; we
  forget the download after ``download_timeout_s`` (5 s, PX4's protocol timeout) of silence.
* A float ``MISSION_REQUEST`` is answered ``MISSION_ACK(MAV_MISSION_UNSUPPORTED)`` without ending
  the download: that is the signal PX4 itself reacts to by switching to the other message
  flavour (here: to MISSION_REQUEST_INT).

Other messages: ``MISSION_CLEAR_ALL`` (ACK ``ACCEPTED``; ``DENIED`` while another client uploads),
``MISSION_SET_CURRENT`` (no ACK by the spec: the shell broadcasts MISSION_CURRENT, or a
STATUSTEXT if ``seq`` is not in the mission). Messages addressed to another system are ignored.

Geofence and rally plans (``mission_type`` FENCE / RALLY, :mod:`.plans`) go through the same
transfers, each stored on its own: upload (validated item by item, then the fence's polygons as a
whole), download (exactly as uploaded), ``MISSION_CLEAR_ALL`` of that type (``ALL`` clears the
three); a new one replaces the old only when accepted. One transfer at a time, of any type.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from enum import Enum

from ..mavlink.codec import mavlink as m
from .items import ItemRejected, MissionItem, WireItem, parse_item
from .plans import check_fence, fence_notes, parse_fence_item, parse_rally_item

RETRY_S = 0.25  # PX4's MAVLINK_MISSION_RETRY_TIMEOUT_DEFAULT
PROTOCOL_TIMEOUT_S = 5.0  # PX4's MAVLINK_MISSION_PROTOCOL_TIMEOUT_DEFAULT: silence ends an upload
DOWNLOAD_TIMEOUT_S = 5.0
MAX_ITEMS = 10_000  # 1000 s of a timed curve sampled at 10 Hz
MAX_PLAN_ITEMS = 256  # fence and rally items (the fence is checked every control step)

MISSION = m.MAV_MISSION_TYPE_MISSION
FENCE = m.MAV_MISSION_TYPE_FENCE
RALLY = m.MAV_MISSION_TYPE_RALLY
PLAN_TYPES = (MISSION, FENCE, RALLY)
_PLAN_NAMES = {MISSION: "mission", FENCE: "geofence", RALLY: "rally points"}
_COMPONENTS = (0, m.MAV_COMP_ID_MISSIONPLANNER)  # besides our own component id (as PX4)

SEVERITY_CRITICAL, SEVERITY_WARNING, SEVERITY_INFO = (
    m.MAV_SEVERITY_CRITICAL,
    m.MAV_SEVERITY_WARNING,
    m.MAV_SEVERITY_INFO,
)

MissionCheck = Callable[[Sequence[MissionItem]], "tuple[int, str] | None"]


@dataclass(frozen=True)
class Mission:
    """A stored mission: validated items (with their wire form) and the item flagged current."""

    items: tuple[MissionItem, ...] = ()
    current_seq: int = 0  # the item uploaded with current = 1 (0 if none)

    @property
    def count(self) -> int:
        """The number of items in the plan."""
        return len(self.items)


class TransferState(Enum):
    IDLE = "idle"
    RECEIVING = "receiving"  # an upload is in progress
    SENDING = "sending"  # a download is in progress


@dataclass
class Output:
    """What handling one message (or one poll) produced."""

    replies: list = field(default_factory=list)  # pymavlink messages, to the sender / partner
    notices: list[tuple[int, str]] = field(default_factory=list)  # STATUSTEXT (severity, text)
    mission: Mission | None = None  # a new stored mission (upload accepted, or cleared)
    fence: Mission | None = None  # a new stored geofence plan (upload accepted, or cleared)
    rally: Mission | None = None  # new stored rally points (upload accepted, or cleared)
    set_current: int | None = None  # MISSION_SET_CURRENT asked for this (valid) item


class MissionProtocol:
    """The transfer state machine of one vehicle (all GCS links share it, as PX4's)."""

    def __init__(
        self,
        system_id: int,
        component_id: int,
        origin: tuple[float, float, float],
        check: MissionCheck | None = None,
        retry_s: float = RETRY_S,
        protocol_timeout_s: float = PROTOCOL_TIMEOUT_S,
        download_timeout_s: float = DOWNLOAD_TIMEOUT_S,
        max_items: int = MAX_ITEMS,
    ) -> None:
        """``origin`` = configured geodetic home (lat, lon deg, alt m) for item validation;
        ``check`` = whole-mission check run before an upload is accepted: None if fine, else
        (MAV_MISSION_RESULT, reason)."""
        self.system_id = system_id
        self.component_id = component_id
        self.origin = origin
        self.check = check
        self.retry_s = retry_s
        self.protocol_timeout_s = protocol_timeout_s
        self.download_timeout_s = download_timeout_s
        self.max_items = max_items
        self.plans: dict[int, Mission] = {t: Mission() for t in PLAN_TYPES}
        self.state = TransferState.IDLE
        self._type = MISSION  # the mission_type of the transfer under way (or the last one)
        self.partner: tuple[int, int] = (0, 0)  # (system, component) of the transfer's client
        self._count = 0
        self._expected = 0
        self._received: list[MissionItem] = []
        self._current_flag = -1
        self._retries = 0
        self._last_sent = 0.0
        self._last_received = 0.0
        self._all_sent = False
        self._completed_upload: tuple[tuple[int, int], int] | None = None  # (partner, last seq)

    # -- entry points ---------------------------------------------------------------------------
    def handle(self, msg, now: float, current_seq: int = 0) -> Output:
        """One mission message from a ground station; ``now`` = monotonic time (s);
        ``current_seq`` = the item the vehicle currently flies (for downloads)."""
        out = Output()
        target = (getattr(msg, "target_system", 0), getattr(msg, "target_component", 0))
        if target[0] not in (0, self.system_id) or target[1] not in (*_COMPONENTS, self.component_id):
            return out
        sender = (msg.get_srcSystem(), msg.get_srcComponent())
        mid = msg.get_msgId()
        if mid == m.MAVLINK_MSG_ID_MISSION_COUNT:
            self._on_count(msg, sender, now, out)
        elif mid == m.MAVLINK_MSG_ID_MISSION_ITEM_INT:
            self._on_item(msg, sender, now, out)
        elif mid == m.MAVLINK_MSG_ID_MISSION_ITEM:
            self._on_float_item(msg, sender, out)
        elif mid == m.MAVLINK_MSG_ID_MISSION_REQUEST_LIST:
            self._on_request_list(msg, sender, now, out)
        elif mid == m.MAVLINK_MSG_ID_MISSION_REQUEST_INT:
            self._on_request(msg, sender, now, current_seq, out)
        elif mid == m.MAVLINK_MSG_ID_MISSION_REQUEST:
            out.replies.append(
                self._ack(sender, m.MAV_MISSION_UNSUPPORTED, getattr(msg, "mission_type", MISSION))
            )
            out.notices.append((SEVERITY_WARNING, "MISSION_REQUEST not supported: use MISSION_REQUEST_INT"))
        elif mid == m.MAVLINK_MSG_ID_MISSION_ACK:
            self._on_ack(msg, sender, out)
        elif mid == m.MAVLINK_MSG_ID_MISSION_CLEAR_ALL:
            self._on_clear(msg, sender, out)
        elif mid == m.MAVLINK_MSG_ID_MISSION_SET_CURRENT:
            self._on_set_current(msg.seq, out)
        return out

    def poll(self, now: float) -> Output:
        """Timeouts and retries; call often (every <= 0.1 s). Replies go to :attr:`partner`."""
        out = Output()
        if self.state == TransferState.RECEIVING and now - self._last_sent >= self.retry_s:
            if now - self._last_received < self.protocol_timeout_s:
                self._retries += 1
                self._request(now, out)
            else:
                out.replies.append(self._ack(self.partner, m.MAV_MISSION_OPERATION_CANCELLED, self._type))
                out.notices.append(
                    (
                        SEVERITY_CRITICAL,
                        f"mission upload timed out waiting for item {self._expected} of {self._count}: "
                        "cancelled, previous mission kept",
                    )
                )
                self._idle()
        elif self.state == TransferState.SENDING and now - self._last_received >= self.download_timeout_s:
            if not self._all_sent:
                out.notices.append((SEVERITY_WARNING, "mission download timed out"))
            self._idle()
        return out

    def set_current_request(self, seq: int) -> Output:
        """MAV_CMD_DO_SET_MISSION_CURRENT: the same checks as MISSION_SET_CURRENT."""
        out = Output()
        self._on_set_current(seq, out)
        return out

    @property
    def mission(self) -> Mission:
        """The stored mission plan (MAV_MISSION_TYPE_MISSION)."""
        return self.plans[MISSION]

    @mission.setter
    def mission(self, value: Mission) -> None:
        self.plans[MISSION] = value

    def _store(self, mission_type: int, plan: Mission, out: Output) -> None:
        self.plans[mission_type] = plan
        if mission_type == MISSION:
            out.mission = plan
        elif mission_type == FENCE:
            out.fence = plan
        else:
            out.rally = plan

    @property
    def busy(self) -> bool:
        """True while an upload or a download is in progress."""
        return self.state != TransferState.IDLE

    # -- upload ---------------------------------------------------------------------------------
    def _on_count(self, msg, sender, now: float, out: Output) -> None:
        mission_type = getattr(msg, "mission_type", MISSION)
        if self.state == TransferState.SENDING and (self._all_sent or sender == self.partner):
            self._idle()  # the download is over (its ACK may have been lost) or abandoned
        if self.state == TransferState.RECEIVING and sender != self.partner:
            out.replies.append(self._ack(sender, m.MAV_MISSION_ERROR, mission_type))
            out.notices.append((SEVERITY_WARNING, "mission upload refused: another upload in progress"))
            return
        if self.state == TransferState.SENDING:
            out.replies.append(self._ack(sender, m.MAV_MISSION_ERROR, mission_type))
            out.notices.append((SEVERITY_WARNING, "mission upload refused: a download is in progress"))
            return
        if mission_type not in PLAN_TYPES:
            out.replies.append(self._ack(sender, m.MAV_MISSION_INVALID, mission_type))
            return
        self._idle()  # a repeated COUNT from the uploading client restarts its upload
        self._type = mission_type
        name = _PLAN_NAMES[mission_type]
        limit = self.max_items if mission_type == MISSION else min(self.max_items, MAX_PLAN_ITEMS)
        if msg.count > limit:
            out.replies.append(self._ack(sender, m.MAV_MISSION_NO_SPACE, mission_type))
            out.notices.append((SEVERITY_WARNING, f"{name} of {msg.count} items refused: at most {limit}"))
            return
        if msg.count == 0:
            self._store(mission_type, Mission(), out)
            out.replies.append(self._ack(sender, m.MAV_MISSION_ACCEPTED, mission_type))
            return
        self.state = TransferState.RECEIVING
        self.partner = sender
        self._count = msg.count
        self._expected = 0
        self._received = []
        self._current_flag = -1
        self._retries = 0
        self._last_received = now
        self._completed_upload = None
        self._request(now, out)

    def _on_item(self, msg, sender, now: float, out: Output) -> None:
        if self.state != TransferState.RECEIVING or sender != self.partner:
            done = self._completed_upload
            if self.state == TransferState.IDLE and done == (sender, msg.seq):
                # The last item again: our ACCEPTED was lost. Repeat it (as PX4).
                out.replies.append(self._ack(sender, m.MAV_MISSION_ACCEPTED, self._type))
            else:
                out.replies.append(
                    self._ack(sender, m.MAV_MISSION_ERROR, getattr(msg, "mission_type", MISSION))
                )
                out.notices.append(
                    (SEVERITY_WARNING, f"mission item {msg.seq} ignored: no upload in progress")
                )
            return
        if getattr(msg, "mission_type", MISSION) != self._type:
            self._fail(m.MAV_MISSION_ERROR, f"item {msg.seq} has mission type {msg.mission_type}", out)
            return
        self._last_received = now
        if msg.seq != self._expected:
            if msg.seq > self._expected:  # a gap: ask again for the one we need, now
                self._request(now, out)
            return  # a repeat of an earlier item: ignore it
        wire = WireItem.from_message(msg)
        previous = self._received[-1] if self._received else None
        try:
            if self._type == FENCE:
                item = parse_fence_item(wire, self.origin)
            elif self._type == RALLY:
                item = parse_rally_item(wire, self.origin)
            else:
                item = parse_item(wire, self.origin, previous)
        except ItemRejected as exc:
            self._fail(exc.result, exc.reason, out)
            return
        self._received.append(item)
        if wire.current:
            self._current_flag = wire.seq
        self._expected += 1
        self._retries = 0
        if self._expected < self._count:
            self._request(now, out)
            return
        items = tuple(self._received)
        if self._type == MISSION:
            problem = self.check(items) if self.check is not None else None
        elif self._type == FENCE:
            problem = check_fence(items)
        else:
            problem = None
        if problem is not None:
            self._fail(problem[0], problem[1], out)
            return
        current = max(self._current_flag, 0) if self._type == MISSION else 0
        self._store(self._type, Mission(items, current), out)
        out.replies.append(self._ack(self.partner, m.MAV_MISSION_ACCEPTED, self._type))
        out.notices.append((SEVERITY_INFO, f"{_PLAN_NAMES[self._type]} of {len(items)} items accepted"))
        if self._type == FENCE:
            out.notices.extend((SEVERITY_INFO, note) for note in fence_notes(items))
        self._completed_upload = (self.partner, self._count - 1)
        self._idle()

    def _on_float_item(self, msg, sender, out: Output) -> None:
        out.replies.append(
            self._ack(sender, m.MAV_MISSION_UNSUPPORTED, getattr(msg, "mission_type", MISSION))
        )
        out.notices.append((SEVERITY_WARNING, "MISSION_ITEM not supported: use MISSION_ITEM_INT"))
        if self.state == TransferState.RECEIVING and sender == self.partner:
            out.notices.append((SEVERITY_WARNING, "mission upload cancelled, previous mission kept"))
            self._idle()

    def _request(self, now: float, out: Output) -> None:
        out.replies.append(m.MAVLink_mission_request_int_message(*self.partner, self._expected, self._type))
        self._last_sent = now

    def _fail(self, result: int, reason: str, out: Output) -> None:
        name = _PLAN_NAMES[self._type]
        out.replies.append(self._ack(self.partner, result, self._type))
        out.notices.append((SEVERITY_CRITICAL, f"{name} rejected: {reason}; previous {name} kept"))
        self._idle()

    # -- download -------------------------------------------------------------------------------
    def _on_request_list(self, msg, sender, now: float, out: Output) -> None:
        mission_type = getattr(msg, "mission_type", MISSION)
        if mission_type not in PLAN_TYPES:
            out.replies.append(self._ack(sender, m.MAV_MISSION_INVALID, mission_type))
            return
        if self.state == TransferState.RECEIVING:
            out.notices.append((SEVERITY_WARNING, "mission download ignored: an upload is in progress"))
            return
        if self.state == TransferState.SENDING and not self._all_sent and sender != self.partner:
            out.notices.append((SEVERITY_WARNING, "mission download ignored: another download in progress"))
            return
        count = self.plans[mission_type].count
        out.replies.append(m.MAVLink_mission_count_message(*sender, count, mission_type))
        self._idle()
        self._type = mission_type
        if count:
            self.state = TransferState.SENDING
            self.partner = sender
            self._last_received = now

    def _on_request(self, msg, sender, now: float, current_seq: int, out: Output) -> None:
        mission_type = getattr(msg, "mission_type", MISSION)
        if mission_type not in PLAN_TYPES:
            return
        plan = self.plans[mission_type]
        seq = msg.seq
        if self.state == TransferState.RECEIVING:
            out.notices.append((SEVERITY_WARNING, "mission item request ignored: an upload is in progress"))
            return
        if self.state == TransferState.IDLE or sender != self.partner or mission_type != self._type:
            # Outside a download PX4 ignores requests; answering a valid one is harmless and
            # helps a client that re-requests after we timed it out.
            if 0 <= seq < plan.count:
                out.replies.append(self._item_message(plan, mission_type, seq, sender, current_seq))
            return
        self._last_received = now
        if not 0 <= seq < plan.count:
            out.replies.append(self._ack(sender, m.MAV_MISSION_INVALID_SEQUENCE, mission_type))
            out.notices.append(
                (SEVERITY_WARNING, f"{_PLAN_NAMES[mission_type]} item {seq} requested: not in the plan")
            )
            self._idle()
            return
        out.replies.append(self._item_message(plan, mission_type, seq, sender, current_seq))
        if seq == plan.count - 1:
            self._all_sent = True

    def _item_message(self, plan: Mission, mission_type: int, seq: int, to, current_seq: int):
        current = 1 if mission_type == MISSION and seq == current_seq else 0
        return plan.items[seq].wire.to_message(*to, current=current)

    def _on_ack(self, msg, sender, out: Output) -> None:
        if sender != self.partner:
            return
        if self.state == TransferState.SENDING:
            self._idle()  # download finished (or cancelled by the client)
        elif self.state == TransferState.RECEIVING and msg.type != m.MAV_MISSION_ACCEPTED:
            out.notices.append(
                (SEVERITY_WARNING, f"mission upload cancelled by the client (result {msg.type})")
            )
            self._idle()

    # -- clear, set current -----------------------------------------------------------------------
    def _on_clear(self, msg, sender, out: Output) -> None:
        mission_type = getattr(msg, "mission_type", MISSION)
        if self.state == TransferState.RECEIVING and sender != self.partner:
            out.replies.append(self._ack(sender, m.MAV_MISSION_DENIED, mission_type))
            out.notices.append((SEVERITY_WARNING, "mission clear refused: an upload is in progress"))
            return
        if mission_type not in (m.MAV_MISSION_TYPE_ALL, *PLAN_TYPES):
            out.replies.append(self._ack(sender, m.MAV_MISSION_INVALID, mission_type))
            return
        self._idle()
        for plan_type in PLAN_TYPES if mission_type == m.MAV_MISSION_TYPE_ALL else (mission_type,):
            self._store(plan_type, Mission(), out)
        self._completed_upload = None
        out.replies.append(self._ack(sender, m.MAV_MISSION_ACCEPTED, mission_type))

    def _on_set_current(self, seq: int, out: Output) -> None:
        if self.state == TransferState.RECEIVING:
            out.notices.append((SEVERITY_WARNING, "set current mission item ignored: upload in progress"))
        elif 0 <= seq < self.mission.count:
            out.set_current = seq
        else:
            out.notices.append(
                (
                    SEVERITY_WARNING,
                    f"set current mission item {seq}: not in the mission of {self.mission.count}",
                )
            )

    # -- helpers ----------------------------------------------------------------------------------
    def _ack(self, to, result: int, mission_type: int = MISSION):
        return m.MAVLink_mission_ack_message(to[0], to[1], result, mission_type)

    def _idle(self) -> None:
        self.state = TransferState.IDLE
        self._received = []
        self._all_sent = False
