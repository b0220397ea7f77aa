"""Log download over MAVLink, as PX4's ``mavlink_log_handler`` answers it (QGC, MAVSDK, MAVProxy).

* ``LOG_REQUEST_LIST(start, end)``: the logs on the vehicle (a snapshot of the directory, oldest
  first, ids 0..n-1) as ``LOG_ENTRY`` (``id``, ``num_logs``, ``last_log_num`` = n-1, ``size``
  in bytes at that moment, ``time_utc`` of its start), for ids ``start..min(end, n-1)``; a range
  outside the logs gets the one entry it clamps to, and no logs at all one entry with
  ``num_logs = 0`` (MAVLink's rule; MAVSDK and MAVProxy read it as "no logs").
* ``LOG_REQUEST_DATA(id, ofs, count)``: ``LOG_DATA`` of 90 bytes each from ``ofs`` for
  ``min(count, size - ofs)`` bytes (the last one shorter), to the station that asked. An offset
  at or past the end, or a count of 0, gets one ``LOG_DATA`` with ``count = 0`` at ``ofs``: the
  end of the file (MAVProxy finishes on it); an id not in the listing is ignored, as PX4 does.
  A request replaces the station's transfer in progress. Without a listing first, the
  directory is listed then (PX4 ignores such a request).
* ``LOG_REQUEST_END``: the station's transfer stops.
* ``LOG_ERASE``: refused while armed (STATUSTEXT; the message has no acknowledgement), else every
  log but the one being written is deleted and every listing is dropped.

A log being written is listed with its size at listing time and served up to it: a ULog cut at
a flush is a readable ULog. Streaming is bounded: at most ``budget`` messages per :meth:`pump`,
which the core calls once per control frame (after the answer to the simulator) and from its
wall-clock housekeeping only while no frames flow, so a download never holds back lockstep; and
at most :data:`MESSAGES_PER_S` a second of the wall clock, so a fast simulation does not flood a
ground station. Each
station (an address on a link) has its own listing and transfer, served in turn; PX4 keeps one
per MAVLink instance, where a second station's request ends the first's stream. Every field of
every request is checked here: no request raises, whatever its values.

Pure: the log directory comes in as a :class:`LogStore` (the shell's, on disk:
:class:`autopilot.logger.storage.LogDirectory`).
"""

from __future__ import annotations

import struct
from collections import OrderedDict
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NamedTuple, Protocol

from quadcommon import wire
from quadcommon.mavlink_fast import frame_payload

from .codec import Encoder
from .codec import mavlink as m
from .links import Address, GcsLink

CHUNK = 90  # LOG_DATA.data
# What one link streams at most, per second of the caller's clock (the process's wall clock; the
# in-process runner's is simulation time): 180 kB/s of log, what the per-frame budget gives at
# --speed 1. Faster, a Python ground station (MAVProxy) drops datagrams and asks for them again.
MESSAGES_PER_S = 2000
BURST = 100  # messages a link may send at once after a pause
MAX_STATIONS_PER_LINK = 4  # stations with a listing or a transfer on one link; the oldest makes room
REFUSE_REPEAT_S = 1.0  # the same refusal text is not repeated within this (wall clock)
_LOG_DATA_HEAD = struct.Struct("<IHB")  # LOG_DATA in wire order: ofs, id, count, then data[90]


class LogEntry(NamedTuple):
    """One log as listed: ``key`` names it for :meth:`LogStore.read`."""

    key: str
    size: int  # bytes
    time_utc: int  # POSIX seconds of its start (0: unknown)


class LogStore(Protocol):
    """The logs on the vehicle (oldest first), their bytes, erasing them."""

    def entries(self) -> list[LogEntry]:
        """The logs now, oldest first, each with its key, size (bytes) and start time."""

    def read(self, key: str, offset: int, count: int) -> bytes:
        """Up to ``count`` bytes of log ``key`` from ``offset`` (fewer at its end; ``b""`` if gone)."""

    def erase(self) -> int:
        """Delete every log but the one being written; how many were deleted."""


class NoLogs:
    """A vehicle that keeps no logs (logging off): every listing is empty."""

    def entries(self) -> list[LogEntry]:
        """No logs: an empty list."""
        return []

    def read(self, key: str, offset: int, count: int) -> bytes:
        """Nothing: there are no logs."""
        return b""

    def erase(self) -> int:
        """Nothing erased: 0."""
        return 0


@dataclass
class _Station:
    """One ground station's state: its last listing, the entries still to list, its transfer."""

    address: Address
    listing: list[LogEntry] | None = None
    to_list: list[int] = field(default_factory=list)  # ids of LOG_ENTRY still to send
    empty_listing: bool = False  # one LOG_ENTRY with num_logs = 0 still to send
    log_id: int = -1  # the transfer: which log, the next offset, where it ends
    offset: int = 0
    end: int = 0
    send_eof: bool = False  # one LOG_DATA with count 0 still to send

    @property
    def busy(self) -> bool:
        return bool(self.to_list) or self.empty_listing or self.send_eof or self.offset < self.end


class LogTransfer:
    """PX4's ``mavlink_log_handler`` over ``store`` (module docstring): a listing and a transfer per station
    on each link, streamed within the links' budgets by :meth:`pump`."""

    def __init__(
        self,
        store: LogStore,
        encoder: Encoder,
        links: list[GcsLink],
        statustext: Callable[[int, str], None],
        armed: Callable[[], bool],
        system_id: int,
        clock: Callable[[], float],
    ) -> None:
        self.store = store
        self.encoder = encoder
        self.links = links
        self.statustext = statustext
        self.armed = armed
        self.system_id = system_id
        self.clock = clock
        self.stations: list[OrderedDict[Address, _Station]] = [OrderedDict() for _ in links]
        self.ignored = 0  # requests answered with nothing (unknown log id), as PX4
        self._allowance = [BURST] * len(links)  # messages each link may still send now
        self._pumped_at = clock()
        self._requested = False  # a request came in that pump() has not finished serving
        self._refused_at: dict[str, float] = {}

    def register(self, dispatcher) -> None:
        """Put its handlers in the dispatcher's table: LOG_REQUEST_LIST, LOG_REQUEST_DATA, LOG_REQUEST_END,
        LOG_ERASE."""
        dispatcher[m.MAVLINK_MSG_ID_LOG_REQUEST_LIST] = self._on_request_list
        dispatcher[m.MAVLINK_MSG_ID_LOG_REQUEST_DATA] = self._on_request_data
        dispatcher[m.MAVLINK_MSG_ID_LOG_REQUEST_END] = self._on_request_end
        dispatcher[m.MAVLINK_MSG_ID_LOG_ERASE] = self._on_erase

    @property
    def active(self) -> bool:
        """Whether anything is still to be sent."""
        return any(st.busy for stations in self.stations for st in stations.values())

    # -- requests -------------------------------------------------------------------------------
    def _for_us(self, msg) -> bool:
        return msg.target_system in (0, self.system_id) and msg.target_component in (
            0, wire.AUTOPILOT_COMPONENT_ID)  # fmt: skip

    def _station(self, link: GcsLink, address: Address) -> _Station:
        self._requested = True
        stations = self.stations[link.index]
        station = stations.get(address)
        if station is None:
            if len(stations) >= MAX_STATIONS_PER_LINK:
                stations.popitem(last=False)
            station = stations[address] = _Station(address)
        else:
            stations.move_to_end(address)
        return station

    def _list(self, station: _Station) -> list[LogEntry]:
        station.listing = list(self.store.entries())
        return station.listing

    def _on_request_list(self, msg, link: GcsLink, address: Address) -> None:
        if not self._for_us(msg):
            return
        station = self._station(link, address)
        entries = self._list(station)
        station.to_list, station.empty_listing = [], False
        n = len(entries)
        if n == 0:
            station.empty_listing = True
            return
        first = min(msg.start, n - 1)
        last = max(min(msg.end, n - 1), first)
        station.to_list = list(range(first, last + 1))

    def _on_request_data(self, msg, link: GcsLink, address: Address) -> None:
        if not self._for_us(msg):
            return
        station = self._station(link, address)
        entries = station.listing if station.listing is not None else self._list(station)
        if msg.id >= len(entries):
            self.ignored += 1
            return
        size = entries[msg.id].size
        station.log_id = msg.id
        station.offset = msg.ofs
        station.end = msg.ofs + min(msg.count, max(size - msg.ofs, 0))
        station.send_eof = station.end == station.offset  # past the end, or count 0

    def _on_request_end(self, msg, link: GcsLink, address: Address) -> None:
        if not self._for_us(msg):
            return
        station = self.stations[link.index].get(address)
        if station is not None:
            station.offset = station.end = 0
            station.send_eof = False

    def _on_erase(self, msg, link: GcsLink, address: Address) -> None:
        if not self._for_us(msg):
            return
        if self.armed():
            self._refuse("log erase refused: the vehicle is armed")
            return
        self.store.erase()
        for stations in self.stations:
            stations.clear()

    def _refuse(self, text: str) -> None:
        now = self.clock()
        last = self._refused_at.get(text)
        if last is None or now - last >= REFUSE_REPEAT_S:
            self._refused_at[text] = now
            self.statustext(m.MAV_SEVERITY_WARNING, text)

    # -- streaming ------------------------------------------------------------------------------
    def pump(self, budget: int) -> None:
        """Send at most ``budget`` messages on each link, its stations taking turns, and no more
        than MESSAGES_PER_S of the caller's clock allows (what a Python ground station reads)."""
        if not self._requested:  # nothing asked since the last pump found nothing to send
            return
        now = self.clock()
        elapsed = min(max(now - self._pumped_at, 0.0), 1.0)
        self._pumped_at = now
        busy = False
        for index, (link, stations) in enumerate(zip(self.links, self.stations, strict=True)):
            if not stations:
                self._allowance[index] = BURST
                continue
            allowance = min(self._allowance[index] + elapsed * MESSAGES_PER_S, BURST)
            left = min(budget, int(allowance))
            self._allowance[index] = allowance - left
            while left > 0:
                sent = 0
                for station in list(stations.values()):
                    if left > 0 and station.busy:
                        self._send_one(link, station)
                        left -= 1
                        sent += 1
                if sent == 0:
                    break
            self._allowance[index] += left  # not spent: nothing was left to send
            busy = busy or any(station.busy for station in stations.values())
        self._requested = busy
    def _send_one(self, link: GcsLink, station: _Station) -> None:
        entries = station.listing or []
        n = len(entries)
        if station.empty_listing:
            station.empty_listing = False
            data = self.encoder.pack(m.MAVLink_log_entry_message(0, 0, 0, 0, 0))
        elif station.to_list:
            i = station.to_list.pop(0)
            entry = entries[i]
            time_utc = min(max(entry.time_utc, 0), 0xFFFFFFFF)
            msg = m.MAVLink_log_entry_message(i, n, n - 1, time_utc, min(entry.size, 0xFFFFFFFF))
            data = self.encoder.pack(msg)
        elif station.send_eof:
            station.send_eof = False
            data = self.log_data(station.log_id, station.offset, b"")
        else:
            entry = entries[station.log_id] if station.log_id < n else None
            count = min(CHUNK, station.end - station.offset)
            chunk = self.store.read(entry.key, station.offset, count) if entry is not None else b""
            data = self.log_data(station.log_id, station.offset, chunk)
            station.offset += len(chunk)
            if len(chunk) < count:  # the file is shorter than listed (erased, replaced): it ends here
                station.end = station.offset
        link.send_to(data, station.address)

    def log_data(self, log_id: int, offset: int, chunk: bytes) -> bytes:
        """One LOG_DATA frame, packed from the bytes (pymavlink's packing of its 90 bytes one by
        one costs ~40 µs a message); signed through pymavlink when signing is on."""
        offset = min(offset, 0xFFFFFFFF)
        padded = chunk.ljust(CHUNK, b"\0")
        mav = self.encoder.mav
        if mav.signing.sign_outgoing:
            return self.encoder.pack(m.MAVLink_log_data_message(log_id, offset, len(chunk), padded))
        payload = _LOG_DATA_HEAD.pack(offset, log_id, len(chunk)) + padded
        frame = frame_payload(m.MAVLink_log_data_message, payload, mav.seq, mav.srcSystem, mav.srcComponent)
        mav.seq = (mav.seq + 1) % 256
        return frame
