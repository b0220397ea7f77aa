"""The autopilot's ground-station links as the core sees them: peers, parser, streams; no socket.

PX4 SITL has two: GCS (QGC, MAVProxy) and API (MAVSDK, scripts). Each sends to a default remote
(the port those clients listen on) and also answers every address that talks to it. What a link
sends is appended to the core's outbox as :class:`Outgoing` records; the process shell turns
them into ``sendto`` calls on the link's socket, the in-process runner hands them to a scripted
ground station.

Anyone on the machine can send to a link, so what a datagram can cost is bounded here:

* a datagram is parsed on its own (a UDP datagram carries whole frames): a truncated frame at
  its end is dropped with it and cannot swallow the next sender's frames;
* at most :data:`MAX_DATAGRAM_BYTES` of it are parsed (MAVLink senders put one frame of at most
  280 bytes in a datagram; PX4 reads 1600); the rest is counted as oversize and dropped;
* an address becomes a peer (is sent telemetry) only once it has sent one valid MAVLink message,
  so garbage from a thousand ports costs no sends; a link keeps at most :data:`MAX_PEERS`, the
  one heard from longest ago making room; a peer silent for :data:`PEER_EXPIRY_S` is dropped.
  The default remote and the stations the in-process runner registers are never dropped.
"""

from __future__ import annotations

import math
from typing import NamedTuple

from quadcommon.mavlink_fast import with_sequence

from .codec import new_parser, restart_parser
from .telemetry import StreamTable

Address = tuple[str, int]
GCS_LINK, API_LINK, HIL_LINK = 0, 1, 2  # link numbers in Outgoing records
LINK_NAMES = ("GCS", "API", "HIL")
MAX_PEERS = 16  # addresses one link answers at once (QGC + MAVProxy + MAVSDK + scripts fit)
PEER_EXPIRY_S = 30.0  # a peer silent this long (wall clock) is no longer sent telemetry
MAX_DATAGRAM_BYTES = 2048  # parsed of one datagram; a longer one is cut (and counted)
BAD_DATA = -1  # msg id of pymavlink's MAVLink_bad_data


class Outgoing(NamedTuple):
    """One datagram to send: on ``link``, to ``address`` (None: the HIL link's simulator)."""

    link: int
    address: Address | None
    data: bytes


class SendAllowance:
    """How many messages a paced stream may send on one link now: refilled at ``per_s`` a second
    of ``clock`` (the caller's: wall time in the process, simulation time in-process), never more
    than ``at_once`` saved up."""

    def __init__(self, per_s: float, at_once: int, clock) -> None:
        self.per_s = per_s
        self.at_once = at_once
        self.clock = clock
        self._left = float(at_once)
        self._at = clock()

    def take(self, wanted: int) -> int:
        """Up to ``wanted`` messages, as many as the allowance has now (spent)."""
        now = self.clock()
        elapsed = min(max(now - self._at, 0.0), 1.0)
        self._at = now
        self._left = min(self._left + elapsed * self.per_s, float(self.at_once))
        granted = max(min(wanted, int(self._left)), 0)
        self._left -= granted
        return granted

    def give_back(self, unused: int) -> None:
        """Messages taken but not sent (nothing was left to send)."""
        self._left = min(self._left + unused, float(self.at_once))


class GcsLink:
    """One ground-station link (UDP): its peers (who last spoke, and the default remote), its MAVLink parser,
    its stream table, the messages queued for it in the shared outbox."""

    def __init__(
        self, index: int, default_remote: Address | None, outbox: list[Outgoing], frame_period_s: float = 0.0,
        signing=None,
    ) -> None:
        """``frame_period_s``: the control frames' period, the shortest stream interval;
        ``signing``: the encoder's signing state (pymavlink's ``MAVLinkSigning``), whose key signs a
        signed frame again once the link has numbered it (None: frames go out as packed)."""
        self.index = index
        self.name = LINK_NAMES[index]
        self.default_remote = default_remote
        # address -> last time heard (s, the caller's clock); math.inf: never expires
        self.peers: dict[Address, float] = {}
        if default_remote is not None:
            self.peers[default_remote] = math.inf
        self.parser = new_parser()
        self.streams = StreamTable(frame_period_s)
        self.last_heartbeat_s: float | None = None  # simulation time of the last GCS heartbeat
        self.oversize = 0  # datagrams cut at MAX_DATAGRAM_BYTES
        self.evicted = 0  # peers dropped to make room for a new one
        self.seq = 0  # the sequence number of the link's next frame
        self._signing = signing
        self._outbox = outbox

    def send(self, data: bytes) -> None:
        """``data`` (one packed MAVLink frame) to every peer of the link, numbered on the link."""
        if not self.peers:
            return
        data = self._numbered(data)
        index, append = self.index, self._outbox.append
        for address in self.peers:
            append(Outgoing(index, address, data))

    def send_to(self, data: bytes, address: Address) -> None:
        """Queue ``data`` (one packed MAVLink frame) for one address of the link only, numbered on
        the link."""
        self._outbox.append(Outgoing(self.index, address, self._numbered(data)))

    def _numbered(self, data: bytes) -> bytes:
        """The frame with the link's next sequence number. The core packs a message once for every
        link that sends it; each link numbers what it sends on its own, as PX4 numbers each MAVLink
        channel, so a ground station sees no gap on a loss-free link (MAVProxy, QGroundControl and
        pymavlink count gaps as lost packets)."""
        signing = self._signing
        data = with_sequence(data, self.seq, signing.secret_key if signing is not None else None)
        self.seq = (self.seq + 1) & 0xFF
        return data

    def listen(self, address: Address) -> None:
        """Send to ``address`` from now on, whether it talks or not (a default remote)."""
        self.peers[address] = math.inf

    def receive(self, data: bytes, address: Address, now: float) -> list:
        """The messages in one datagram from ``address``; garbage parses to BAD_DATA objects,
        which the dispatcher counts and drops. A sender of one valid message becomes a peer."""
        if len(data) > MAX_DATAGRAM_BYTES:
            self.oversize += 1
            data = data[:MAX_DATAGRAM_BYTES]
        parser = self.parser
        restart_parser(parser)  # a frame left incomplete by the last datagram ended with it
        messages = parser.parse_buffer(data) or []
        if any(msg.get_msgId() != BAD_DATA for msg in messages):
            self._heard(address, now)
        return messages

    def expire(self, now: float) -> None:
        """Drop peers silent for longer than PEER_EXPIRY_S."""
        stale = [address for address, heard in self.peers.items() if now - heard > PEER_EXPIRY_S]
        for address in stale:
            del self.peers[address]

    def _heard(self, address: Address, now: float) -> None:
        peers = self.peers
        heard = peers.get(address)
        if heard is not None:
            if heard != math.inf:
                peers[address] = now
            return
        if len(peers) >= MAX_PEERS:
            expiring = [(when, a) for a, when in peers.items() if when != math.inf]
            if not expiring:
                return  # all kept for good: the newcomer is answered directly, not streamed to
            del peers[min(expiring)[1]]
            self.evicted += 1
        peers[address] = now
