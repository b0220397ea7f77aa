"""The socket edge of an impaired link, for the process shells: UDP sends and receives through
:class:`~quadcommon.impairment.ImpairedChannel` on the wall clock.

:class:`ImpairedSender` stands in for ``sock.sendto``: a datagram goes into the outgoing channel
and out on the socket when its time comes (:meth:`~ImpairedSender.flush`, called from the shell's
loop, whose waits end no later than :meth:`~ImpairedSender.next_due`). :class:`ImpairedReceiver`
does the same for what the socket received. Without an impairment neither holds anything: a send is
a plain ``sendto``.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any

from .impairment import ImpairConfig, ImpairedChannel, ImpairmentError, parse_link_spec

Address = tuple[str, int]


class ImpairedSender:
    """``sendto`` through an outgoing channel (None: straight to the socket)."""

    def __init__(
        self, sock: Any, channel: ImpairedChannel | None, clock: Callable[[], float] = time.monotonic
    ) -> None:
        self.sock = sock
        self.channel = channel
        self.clock = clock

    def sendto(self, data: bytes, address: Address) -> None:
        """Send (or queue) ``data``; a send that fails (nobody listening) is dropped silently."""
        channel = self.channel
        if channel is None:
            try:
                self.sock.sendto(data, address)
            except OSError:
                pass
            return
        now = self.clock()
        channel.send((data, address), now)
        self.flush(now)

    def flush(self, now: float | None = None) -> None:
        """Send every queued datagram whose time has come."""
        channel = self.channel
        if channel is None or channel.next_due() is None:
            return
        for data, address in channel.due(self.clock() if now is None else now):
            try:
                self.sock.sendto(data, address)
            except OSError:
                pass

    def next_due(self) -> float | None:
        """When the next held datagram is due (the clock's seconds), None when none is held."""
        return None if self.channel is None else self.channel.next_due()


class ImpairedReceiver:
    """What a socket received, through an incoming channel (None: handed on at once)."""

    def __init__(self, channel: ImpairedChannel | None) -> None:
        self.channel = channel

    def received(self, data: bytes, address: Address, now: float) -> list[tuple[bytes, Address]]:
        """``data`` just arrived from ``address``: what is to be handled now (it, nothing, or
        earlier datagrams whose time has come too)."""
        if self.channel is None:
            return [(data, address)]
        self.channel.send((data, address), now)
        return self.channel.due(now)

    def due(self, now: float) -> list[tuple[bytes, Address]]:
        """Held datagrams whose time has come."""
        if self.channel is None or self.channel.next_due() is None:
            return []
        return self.channel.due(now)

    def next_due(self) -> float | None:
        """When the next held datagram is due (the clock's seconds), None when none is held."""
        return None if self.channel is None else self.channel.next_due()


def wait_s(default_s: float, now: float, *due: float | None) -> float:
    """How long a shell may block: ``default_s``, or less if a held datagram is due sooner."""
    soonest = min((d for d in due if d is not None), default=None)
    return default_s if soonest is None else max(0.0, min(default_s, soonest - now))


class ImpairedLinks:
    """A process's impaired endpoints (senders and receivers) by (link, direction), and the live
    change of their impairment: ``quadsitl/<N>/impair`` (``quadsitl impair``) hands its payload to
    :meth:`change`. An endpoint whose link is not impaired has no channel until a change gives it
    one (seeded as at start)."""

    def __init__(self, config: ImpairConfig, process: str) -> None:
        self.config = config
        self.process = process  # named in the replies (both processes answer quadsitl/<N>/impair)
        self.endpoints: dict[tuple[str, str], ImpairedSender | ImpairedReceiver] = {}
        self._active = False  # any endpoint with a channel (endpoints_active)

    def sender(self, sock: Any, link: str, direction: str, clock: Callable[[], float] = time.monotonic):
        """An impaired sender on ``sock`` for ``link`` in ``direction``, kept to answer status requests."""
        endpoint = ImpairedSender(sock, self.config.channel(link, direction), clock)
        self.endpoints[(link, direction)] = endpoint
        self._endpoints_changed()
        return endpoint

    def receiver(self, link: str, direction: str) -> ImpairedReceiver:
        """An impaired receiver for ``link`` in ``direction``, kept to answer status requests."""
        endpoint = ImpairedReceiver(self.config.channel(link, direction))
        self.endpoints[(link, direction)] = endpoint
        self._endpoints_changed()
        return endpoint

    def change(self, payload: bytes) -> tuple[bool, bytes]:
        """``LINK:SPEC`` items separated by spaces or ``;`` (``api:loss=100%``, ``gcs:none``):
        applied to this process's endpoints of those links; the reply (JSON) says what each
        endpoint does now, or why nothing changed."""
        try:
            text = payload.decode("utf-8")
            specs = [item for item in text.replace(";", " ").split() if item]
            if not specs:
                raise ImpairmentError("give LINK:SPEC, e.g. api:loss=100% (or api:none)")
            changed = dict(parse_link_spec(item, "impair") for item in specs)
        except (UnicodeDecodeError, ImpairmentError) as exc:
            return False, json.dumps({"process": self.process, "accepted": False, "error": str(exc)}).encode()
        self.config = replace(self.config, **changed)
        for (link, direction), endpoint in self.endpoints.items():
            if link not in changed:
                continue
            if endpoint.channel is not None:
                endpoint.channel.set(changed[link])
            else:
                endpoint.channel = self.config.channel(link, direction)
        self._endpoints_changed()
        return True, json.dumps({"process": self.process, "accepted": True, "links": self.info()}).encode()

    @property
    def endpoints_active(self) -> bool:
        """True if any endpoint has a channel (the shell's loop then flushes them)."""
        return self._active  # (asked every frame: kept up to date by what gives channels)

    def _endpoints_changed(self) -> None:
        self._active = any(e.channel is not None for e in self.endpoints.values())

    def info(self) -> dict[str, Any]:
        """Per endpoint that has a channel: its impairment and counts (for ``info``)."""
        return {e.channel.name: e.channel.info() for e in self.endpoints.values() if e.channel is not None}
