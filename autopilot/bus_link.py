"""The autopilot process's zenoh side (part of its shell, beside :mod:`autopilot.app`): the
controller's and the estimator's rows published in batches, the ``autopilot/info`` and ``impair``
queryables answered. Nothing here decides anything about the vehicle.

The first rows wait up to :data:`SUBSCRIBER_GRACE_S` of wall time for a subscriber declared before
this process started (a recorder) to be discovered, so that none of its rows is lost; then they
flow regardless.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from typing import Any

from quadcommon import bus, wire
from quadcommon.bus_records import CONTROLLER_CODEC, ESTIMATOR_CODEC
from quadcommon.impaired_udp import ImpairedLinks

from .core import AutopilotCore

CONTROLLER_BATCH = 10  # controller rows per zenoh sample
SUBSCRIBER_GRACE_S = 1.0


class AutopilotBus:
    """The zenoh session of one autopilot process and what it serves."""

    def __init__(self, core: AutopilotCore, impaired: ImpairedLinks, log: Callable[[str], None]) -> None:
        self.core, self.impaired, self.log = core, impaired, log
        self.session = self.controller_pub = self.estimator_pub = None
        self.info_queryable = self.impair_queryable = None
        self._hold_rows_until: float | None = None
        self._owns_session = True

    def open(self, port: int, session: Any = None) -> None:
        """Join the bus (peer on ``port``, or the configured router); BusError names what failed.
        ``session``: serve on this one instead (a fleet's vehicle, whose simulator shares it); it
        stays open at :meth:`close`."""
        import zenoh

        core = self.core
        n = core.setup.instance
        self._owns_session = session is None
        self.session = session if session is not None else bus.open_peer(port, core.setup.sitl.zenoh_router)
        self.controller_pub = self.session.declare_publisher(wire.zenoh_key(n, "controller"))
        self._hold_rows_until = time.monotonic() + SUBSCRIBER_GRACE_S
        self.estimator_pub = self.session.declare_publisher(wire.zenoh_key(n, "estimator"))
        self.info_queryable = self.session.declare_queryable(
            wire.zenoh_key(n, "autopilot/info"), zenoh.handlers.FifoChannel(16)
        )
        self.impair_queryable = self.session.declare_queryable(
            wire.zenoh_key(n, "impair"), zenoh.handlers.FifoChannel(16)
        )

    def close(self) -> None:
        """Leave the bus (a shared session stays open: its owner closes it)."""
        if self.session is not None and self._owns_session:
            self.session.close()

    def publish_rows(self, force: bool = False) -> None:
        """The controller's (and the estimator's) rows the core buffered, once a batch is full
        (``force``: whatever there is)."""
        core = self.core
        if len(core.controller_rows) < (1 if force else CONTROLLER_BATCH):
            return
        if self._hold_rows_until is not None and not force:
            if not bus.publisher_matched(self.controller_pub) and time.monotonic() < self._hold_rows_until:
                return  # keep them (the core buffers): a subscriber may still be being discovered
            self._hold_rows_until = None
        rows = core.take_controller_rows()
        estimates = core.take_estimator_rows()
        if self.controller_pub is not None:
            try:
                self.controller_pub.put(CONTROLLER_CODEC.encode(rows))
                if estimates:
                    self.estimator_pub.put(ESTIMATOR_CODEC.encode(estimates))
            except Exception:
                pass  # session closing under us at shutdown

    def info(self) -> dict:
        """The answer of ``quadsitl/<N>/autopilot/info``: the core's, and the links' impairment."""
        return {**self.core.info(), "impairment": self.impaired.info()}

    def poll(self) -> None:
        """Answer the queries waiting: the info, and a change of the links' impairment."""
        if self.info_queryable is None:
            return
        try:
            query = self.info_queryable.try_recv()
        except Exception:
            query = None
        if query is not None:
            with query:
                query.reply(query.key_expr, json.dumps(self.info()).encode())
        try:
            query = self.impair_queryable.try_recv()
        except Exception:
            return
        if query is not None:
            with query:
                payload = query.payload.to_bytes() if query.payload is not None else b""
                ok, reply = self.impaired.change(payload)
                if ok:
                    now_impaired = self.impaired.config.describe()
                    self.log(f"impairment changed at t={self.core.sim_time:.3f} s: {now_impaired}")
                    query.reply(query.key_expr, reply)
                else:
                    query.reply_err(reply)
