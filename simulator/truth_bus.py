"""The simulator on zenoh: ground-truth rows out (``quadsitl/<N>/truth``) and an info queryable.

Truth rows follow :data:`quadcommon.bus_records.TRUTH_FIELDS` (paper frames, SI units), one row
per lockstep frame (the state sent in that frame, ``time_s`` = the frame's time), batched
``rows_per_batch`` to a sample (10 rows = 20 ms at 500 Hz: fifty 3 kB puts a second instead of
five hundred small ones) and flushed on exit. The publisher keeps zenoh's default congestion
control (drop): a slow subscriber must never stall the lockstep loop.

The info queryable (``quadsitl/<N>/info``) answers a JSON object describing the running
simulator. It uses a FIFO channel polled from the main loop, never a Python callback (a callback
thread would wait for the GIL behind the busy loop, and would keep the process alive at exit).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import Any

import zenoh

from quadcommon.bus_records import TRUTH_CODEC

from .dynamics.plant import TruthState

Vector3 = tuple[float, float, float]


def truth_row(
    time_s: float,
    truth: TruthState,
    force_n: Vector3,
    torque_n_m: Vector3,
    wind_m_s: Vector3,
    rotor_health: tuple[float, ...],
) -> tuple[float, ...]:
    """One row in :data:`~quadcommon.bus_records.TRUTH_FIELDS` order.

    ``force_n`` (world, at the CoM), ``torque_n_m`` (on the Euler coordinates) and ``wind_m_s``
    (world) are the disturbance applied at ``time_s``; ``rotor_health`` the rotors' effectiveness
    and failure types (:attr:`simulator.core.SimulatorCore.rotor_health`).
    """
    return (
        time_s,
        *truth.position_m,
        *truth.velocity_m_s,
        *truth.acceleration_m_s2,
        *truth.quaternion,
        *truth.euler_rad,
        *truth.body_rates_rad_s,
        *force_n,
        *torque_n_m,
        *wind_m_s,
        truth.thrust_n,
        *truth.torque_body_n_m,
        *truth.rotor_speeds_rad_s,
        *rotor_health,
        1.0 if truth.on_ground else 0.0,
    )


class TruthStream:
    """Batches truth rows and puts them on ``key`` through one declared publisher."""

    def __init__(self, session: zenoh.Session, key: str, rows_per_batch: int = 10) -> None:
        self.key = key
        self.publisher = session.declare_publisher(key)
        self.rows_per_batch = rows_per_batch
        self._rows: list[tuple[float, ...]] = []
        self.batches_sent = 0

    def append(self, row: tuple[float, ...]) -> None:
        """Add one row; a full batch goes out at once."""
        rows = self._rows
        rows.append(row)
        if len(rows) >= self.rows_per_batch:
            self.flush()

    def flush(self) -> None:
        """Put the rows collected so far (if any)."""
        if not self._rows:
            return
        payload = TRUTH_CODEC.encode(self._rows)
        self._rows.clear()
        try:
            self.publisher.put(payload)
            self.batches_sent += 1
        except zenoh.ZError:
            pass  # session closing under us at shutdown: nothing left to tell anyone

    def close(self) -> None:
        """Put the rows still batched, then undeclare the publisher (a closed session is ignored)."""
        self.flush()
        try:
            self.publisher.undeclare()
        except zenoh.ZError:
            pass


class _PolledQueryable:
    """A queryable on a FIFO channel, drained from the simulator's loop (never a Python callback:
    those wait for the GIL behind the busy loop, and keep the process alive at exit)."""

    def __init__(self, session: zenoh.Session, key: str) -> None:
        self.key = key
        self.queryable = session.declare_queryable(key, zenoh.handlers.FifoChannel(16))

    def poll(self) -> int:
        """Answer every waiting query (non-blocking); returns how many were answered."""
        answered = 0
        for _ in range(16):  # bounded: at most the channel's capacity per call
            try:
                query = self.queryable.try_recv()
            except zenoh.ZError:
                return answered  # channel closed (session closing)
            if query is None:
                return answered
            with query:  # finalises the query: the getter's iteration ends after our reply
                self.answer(query)
            answered += 1
        return answered

    def answer(self, query: zenoh.Query) -> None:
        raise NotImplementedError

    def close(self) -> None:
        try:
            self.queryable.undeclare()
        except zenoh.ZError:
            pass


class InfoServer(_PolledQueryable):
    """Answers queries on ``key`` with ``describe()`` as JSON; call :meth:`poll` from the loop."""

    def __init__(self, session: zenoh.Session, key: str, describe: Callable[[], dict[str, Any]]) -> None:
        super().__init__(session, key)
        self.describe = describe

    def answer(self, query: zenoh.Query) -> None:
        """Reply to ``query`` with ``describe()`` as JSON."""
        query.reply(self.key, json.dumps(self.describe()).encode())


class RequestServer(_PolledQueryable):
    """Each query's payload on ``key`` goes to ``handle(payload) -> (accepted, reply)`` and the
    reply goes back (an error reply if not accepted). Call :meth:`poll` from the main loop."""

    def __init__(
        self, session: zenoh.Session, key: str, handle: Callable[[bytes], tuple[bool, bytes]]
    ) -> None:
        super().__init__(session, key)
        self.handle = handle

    def answer(self, query: zenoh.Query) -> None:
        """Hand the query's payload to ``handle``; reply with its reply if accepted, else an error reply
        carrying it."""
        payload = query.payload.to_bytes() if query.payload is not None else b""
        ok, reply = self.handle(payload)
        if ok:
            query.reply(self.key, reply)
        else:
            query.reply_err(reply)


class GustUploadServer(RequestServer):
    """The simulator's side of ``quadsitl/<N>/sim/gusts``: ``handle`` is
    :meth:`simulator.core.SimulatorCore.upload_gusts` (the protocol of environment/gust_upload.py)."""
