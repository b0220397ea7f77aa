"""UDP sockets of the process shells: bind on loopback, with a clear error when a port is taken."""

from __future__ import annotations

import errno
import socket

from .wire import LOOPBACK

RECEIVE_BUFFER_BYTES = 1 << 20


class PortInUse(RuntimeError):
    """A UDP port this process must bind is already bound; the message names it."""


def bind_udp(port: int, what: str, blocking: bool = False) -> socket.socket:
    """A UDP socket bound to ``127.0.0.1:port`` (0: any free port); PortInUse names ``what``."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.bind((LOOPBACK, port))
    except OSError as exc:
        sock.close()
        if exc.errno == errno.EADDRINUSE:
            raise PortInUse(f"UDP port {port} ({what}) is already in use") from None
        raise
    sock.setblocking(blocking)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER_BYTES)
    return sock
