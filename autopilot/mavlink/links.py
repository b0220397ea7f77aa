"""UDP links of the autopilot: two GCS links (as PX4 SITL) and the HIL link.

A :class:`GcsLink` binds a local loopback port, sends to a default remote (the port ground
stations and API scripts listen on) and also answers every address that talks to it.
"""

from __future__ import annotations

import errno
import socket

from quadcommon.wire import LOOPBACK

from .codec import new_parser
from .telemetry import StreamTable

MAX_DATAGRAM = 65535


class PortInUse(RuntimeError):
    pass


def bind_udp(port: int, what: str) -> socket.socket:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.bind((LOOPBACK, port))
    except OSError as exc:
        sock.close()
        if exc.errno == errno.EADDRINUSE:
            raise PortInUse(f"UDP port {port} ({what}) is already in use") from None
        raise
    sock.setblocking(False)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
    return sock


class GcsLink:
    def __init__(self, name: str, local_port: int, remote_port: int) -> None:
        self.name = name
        self.sock = bind_udp(local_port, f"{name} link")
        self.local_port = local_port
        self.default_remote = (LOOPBACK, remote_port)
        self.peers: list[tuple[str, int]] = [self.default_remote]
        self.parser = new_parser()
        self.streams = StreamTable()
        self.last_heartbeat_s: float | None = None  # simulation time of the last GCS heartbeat

    def send(self, data: bytes) -> None:
        for address in self.peers:
            try:
                self.sock.sendto(data, address)
            except OSError:
                pass  # nobody listening (ECONNREFUSED on loopback) is normal for a GCS port

    def send_to(self, data: bytes, address: tuple[str, int]) -> None:
        try:
            self.sock.sendto(data, address)
        except OSError:
            pass

    def receive(self) -> list[tuple[object, tuple[str, int]]]:
        """Every message waiting on the socket, with the address it came from."""
        out = []
        while True:
            try:
                data, address = self.sock.recvfrom(MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                return out
            except OSError:
                continue  # ICMP port unreachable from an earlier send: ignore
            if address not in self.peers:
                self.peers.append(address)
            try:
                messages = self.parser.parse_buffer(data) or []
            except Exception:
                continue  # garbage on the link must not stop the autopilot
            out.extend((msg, address) for msg in messages)

    def close(self) -> None:
        self.sock.close()
