"""The autopilot's ground-station links as the core sees them: peers, parser, streams; no socket.

PX4 SITL has two: GCS (QGC, MAVProxy) and API (MAVSDK, scripts). Each sends to a default remote
(the port those clients listen on) and also answers every address that talks to it. What a link
sends is appended to the core's outbox as :class:`Outgoing` records; the process shell turns
them into ``sendto`` calls on the link's socket, the in-process runner hands them to a scripted
ground station.
"""

from __future__ import annotations

from typing import NamedTuple

from .codec import new_parser
from .telemetry import StreamTable

Address = tuple[str, int]
GCS_LINK, API_LINK, HIL_LINK = 0, 1, 2  # link numbers in Outgoing records
LINK_NAMES = ("GCS", "API", "HIL")


class Outgoing(NamedTuple):
    """One datagram to send: on ``link``, to ``address`` (None: the HIL link's simulator)."""

    link: int
    address: Address | None
    data: bytes


class GcsLink:
    def __init__(self, index: int, default_remote: Address | None, outbox: list[Outgoing]) -> None:
        self.index = index
        self.name = LINK_NAMES[index]
        self.default_remote = default_remote
        self.peers: list[Address] = [default_remote] if default_remote is not None else []
        self.parser = new_parser()
        self.streams = StreamTable()
        self.last_heartbeat_s: float | None = None  # simulation time of the last GCS heartbeat
        self._outbox = outbox

    def send(self, data: bytes) -> None:
        """To every peer of the link."""
        index, append = self.index, self._outbox.append
        for address in self.peers:
            append(Outgoing(index, address, data))

    def send_to(self, data: bytes, address: Address) -> None:
        self._outbox.append(Outgoing(self.index, address, data))

    def receive(self, data: bytes, address: Address) -> list:
        """The messages in one datagram from ``address`` (who becomes a peer); garbage parses to
        BAD_DATA objects, which the dispatcher counts and drops."""
        if address not in self.peers:
            self.peers.append(address)
        return self.parser.parse_buffer(data) or []
