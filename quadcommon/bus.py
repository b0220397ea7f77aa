"""Opening zenoh sessions the one safe way: peer mode, no multicast, loopback endpoints.

Topology: the simulator of vehicle N is the hub. Its session listens on
``tcp/127.0.0.1:7447+N``; every other session (autopilot, recorder, scripts) listens on an
ephemeral loopback port and connects to the hub, and gossip scouting lets those peers find each
other directly (a zenoh router does not forward between peers, so a plain peer mesh is used).
A ``router`` endpoint in ``config/sitl.toml`` (multi-host runs) makes sessions connect there
instead, in client mode.

Rules for using zenoh from Python here, each for a reason:

* always set ``listen/endpoints`` (the default listens on every interface) and switch multicast
  scouting off;
* always close the session in ``finally`` (a Python-callback subscriber or queryable otherwise
  keeps the process alive);
* receive with ``FifoChannel``/``RingChannel`` handlers polled by ``try_recv()`` in the process
  loop, not with Python callbacks (those wait for the GIL behind a busy loop);
* a fresh publisher may lose its first samples until ``matching_status.matching`` is true.
"""

from __future__ import annotations

import json
import time

import zenoh

from .wire import LOOPBACK


class BusError(RuntimeError):
    """A zenoh session could not be opened (e.g. its port is in use)."""


def session_config(
    listen: list[str] | None = None,
    connect: list[str] | None = None,
    router: str = "",
) -> zenoh.Config:
    """Config for a loopback peer (or a client of ``router`` when one is given)."""
    cfg = zenoh.Config()
    if router:
        cfg.insert_json5("mode", json.dumps("client"))
        cfg.insert_json5("connect/endpoints", json.dumps([router]))
        cfg.insert_json5("listen/endpoints", json.dumps([]))
    else:
        cfg.insert_json5("mode", json.dumps("peer"))
        cfg.insert_json5("listen/endpoints", json.dumps(listen or [f"tcp/{LOOPBACK}:0"]))
        cfg.insert_json5("connect/endpoints", json.dumps(connect or []))
        cfg.insert_json5("scouting/gossip/enabled", "true")
    cfg.insert_json5("scouting/multicast/enabled", "false")
    cfg.insert_json5("transport/shared_memory/enabled", "false")
    cfg.insert_json5(
        "connect/retry",
        json.dumps({"period_init_ms": 50, "period_max_ms": 500, "period_increase_factor": 1.5}),
    )
    return cfg


def hub_endpoint(port: int) -> str:
    """The zenoh endpoint of the hub on ``port`` (TCP, loopback)."""
    return f"tcp/{LOOPBACK}:{port}"


def open_hub(port: int, router: str = "") -> zenoh.Session:
    """The simulator's session: listens on ``tcp/127.0.0.1:port``."""
    try:
        if router:
            return zenoh.open(session_config(router=router))
        return zenoh.open(session_config(listen=[hub_endpoint(port)]))
    except zenoh.ZError as exc:
        if "Address already in use" in str(exc):
            raise BusError(f"zenoh port {port} (tcp/127.0.0.1) is already in use") from None
        raise BusError(f"cannot open the zenoh session on port {port}: {exc}") from None


def open_peer(hub_port: int, router: str = "") -> zenoh.Session:
    """Any other process's session: connects to the vehicle's hub (or to the router)."""
    try:
        if router:
            return zenoh.open(session_config(router=router))
        return zenoh.open(session_config(connect=[hub_endpoint(hub_port)]))
    except zenoh.ZError as exc:
        raise BusError(f"cannot open a zenoh session towards port {hub_port}: {exc}") from None


def open_router(endpoint: str) -> zenoh.Session:
    """A zenoh router listening on ``endpoint`` (``quadsitl router``): the sessions of launches
    whose ``[zenoh] router`` names it meet there."""
    cfg = session_config(listen=[endpoint])
    cfg.insert_json5("mode", json.dumps("router"))
    try:
        return zenoh.open(cfg)
    except zenoh.ZError as exc:
        raise BusError(f"cannot open a zenoh router on {endpoint}: {exc}") from None


def publisher_matched(publisher: zenoh.Publisher) -> bool:
    """True once ``publisher`` has a matching subscriber (its samples reach someone)."""
    try:
        return bool(publisher.matching_status.matching)
    except Exception:  # a session closing under us
        return False


def wait_matching(publisher: zenoh.Publisher, timeout_s: float) -> bool:
    """Wait until ``publisher`` has a matching subscriber (so the first samples are not lost)."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if publisher_matched(publisher):
            return True
        time.sleep(0.002)
    return False


class InfoQuery:
    """A zenoh ``get`` of an ``info`` queryable, polled without blocking and repeated every
    ``retry_wall_s`` until one answer (JSON) arrives; used by the recorder and the live view."""

    def __init__(self, key: str, retry_wall_s: float = 1.0) -> None:
        self.key = key
        self.retry_wall_s = retry_wall_s
        self.answer: dict | None = None
        self._handler = None
        self._next_try = 0.0

    def poll(self, session: zenoh.Session | None, wall: float) -> bool:
        """True when the answer has just arrived."""
        if self.answer is not None or session is None:
            return False
        if self._handler is None:
            if wall < self._next_try:
                return False
            self._next_try = wall + self.retry_wall_s
            self._handler = session.get(self.key, handler=zenoh.handlers.FifoChannel(4), timeout=1.0)
        try:
            reply = self._handler.try_recv()
        except zenoh.ZError:  # the get ended without an answer: nobody there yet
            self._handler = None
            return False
        if reply is None:
            return False
        self._handler = None
        if reply.ok is None:
            return False
        try:
            self.answer = json.loads(reply.ok.payload.to_bytes())
        except ValueError:
            return False
        return True
