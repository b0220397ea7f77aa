"""Message dispatch that no datagram can break: routed by message id, faults counted, never fatal.

pymavlink parses garbage into ``BAD_DATA`` objects and frames of messages outside the dialect into
``UNKNOWN_<id>`` objects; both report ``get_msgId() < 0`` but carry a field ``id == 0`` (the
HEARTBEAT id), and real messages may have a field named ``id`` too (LOG_REQUEST_DATA, HIL_GPS).
So the route is ``get_msgId()``, never ``msg.id``; bad and unknown frames are counted and dropped;
a handler that raises is caught here, logged once per kind with its traceback, counted, and
announced (rate-limited STATUSTEXT). The counters are part of the autopilot's info.
"""

from __future__ import annotations

import traceback
from collections import Counter
from collections.abc import Callable

Handler = Callable[[object, object, tuple[str, int]], None]
ANNOUNCE_EVERY_S = 10.0  # a recurring fault is announced again at most this often (wall time)


class FaultLog:
    """Counts exceptions caught at the core's boundary, by kind (where they happened)."""

    def __init__(self, log: Callable[[str], None], announce: Callable[[str], None]) -> None:
        self.log = log
        self.announce = announce
        self.counts: Counter[str] = Counter()
        self._announced_at: dict[str, float] = {}

    def record(self, kind: str, exc: BaseException, now: float) -> None:
        """Count ``exc`` caught in ``kind`` (where it happened) at ``now`` (the caller's clock, s):
        logged with its traceback the first time, announced at most every :data:`ANNOUNCE_EVERY_S`."""
        self.counts[kind] += 1
        count = self.counts[kind]
        if count == 1:
            detail = "".join(traceback.format_exception(type(exc), exc, exc.__traceback__)).rstrip()
            self.log(f"internal error in {kind} (caught, counted; the process goes on):\n{detail}")
        last = self._announced_at.get(kind)
        if last is None or now - last >= ANNOUNCE_EVERY_S:
            self._announced_at[kind] = now
            self.announce(f"internal error in {kind}: {type(exc).__name__}: {exc} ({count}x)"[:200])


class MessageDispatcher:
    """Handlers by message id; :meth:`dispatch` routes one parsed message."""

    def __init__(self, faults: FaultLog) -> None:
        self.handlers: dict[int, Handler] = {}
        self.faults = faults
        self.received: Counter[str] = Counter()  # "bad data", "unknown message", "unhandled"

    def __setitem__(self, msg_id: int, handler: Handler) -> None:
        self.handlers[msg_id] = handler

    def dispatch(self, msg, link, address: tuple[str, int], now: float) -> None:
        """Route ``msg`` (pymavlink, from ``address`` on ``link``) to its handler by
        ``get_msgId()``; bad data, unknown and unhandled messages counted and dropped, a handler's
        exception caught and recorded (:class:`FaultLog`, at ``now``)."""
        msg_id = msg.get_msgId()
        if msg_id < 0:  # BAD_DATA (-1) or a frame of a message outside the dialect (-2)
            self.received["bad data" if msg_id == -1 else "unknown message"] += 1
            return
        handler = self.handlers.get(msg_id)
        if handler is None:
            self.received["unhandled"] += 1
            return
        try:
            handler(msg, link, address)
        except Exception as exc:  # a handler's bug must never end the process
            self.faults.record(f"{msg.get_type()} handler", exc, now)
