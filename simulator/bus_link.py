"""The simulator process's zenoh side (part of its shell, beside :mod:`simulator.app`): the hub
session, the truth rows out (``quadsitl/<N>/truth``) and the queryables answered from the loop:
``info`` (the core's description, the pacing, the links' impairment), ``sim/gusts`` (uploads to the
core's disturbance schedule) and ``impair`` (a live change of the links' impairment);
:mod:`simulator.truth_bus` has the publisher and the queryables. Nothing here decides anything
about the plant.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from quadcommon import bus, wire
from quadcommon.impaired_udp import ImpairedLinks

from .core import SimulatorCore
from .truth_bus import GustUploadServer, InfoServer, RequestServer, TruthStream


class SimulatorBus:
    """The zenoh session of one simulator process and what it serves (module docstring); ``speed``:
    the pacing factor the info reports (None: as fast as lockstep allows)."""

    def __init__(
        self, core: SimulatorCore, impaired: ImpairedLinks, speed: float | None, log: Callable[[str], None]
    ) -> None:
        self.core, self.impaired, self.speed, self.log = core, impaired, speed, log
        self.session: Any = None
        self.truth: TruthStream | None = None
        self.services: list = []  # zenoh queryables polled from the loop
        self._owns_session = True

    def open(self, port: int, session: Any = None) -> None:
        """Open the hub on ``port`` (or join the configured router); bus.BusError names what failed.
        ``session``: serve on this one instead (a fleet's vehicle, whose autopilot shares it); it
        stays open at :meth:`close`."""
        core = self.core
        n = core.setup.instance
        self._owns_session = session is None
        self.session = session if session is not None else bus.open_hub(port, core.setup.sitl.zenoh_router)
        self.truth = TruthStream(self.session, wire.zenoh_key(n, "truth"))
        self.services = [
            InfoServer(self.session, wire.zenoh_key(n, "info"), self.describe),
            GustUploadServer(self.session, wire.zenoh_key(n, "sim/gusts"), core.upload_gusts),
            RequestServer(self.session, wire.zenoh_key(n, "impair"), self.change_impairment),
        ]  # fmt: skip

    def describe(self) -> dict[str, Any]:
        """The answer of the ``quadsitl/<N>/info`` queryable."""
        info = {**self.core.info(), "speed": "max" if self.speed is None else self.speed}
        info["impairment"] = self.impaired.info()
        return info

    def change_impairment(self, payload: bytes) -> tuple[bool, bytes]:
        """A request on ``quadsitl/<N>/impair``: the links' impairment changed (logged) or refused."""
        ok, reply = self.impaired.change(payload)
        if ok:
            self.log(f"impairment changed at t={self.core.t:.3f} s: {self.impaired.config.describe()}")
        return ok, reply

    def poll(self) -> None:
        """Answer the queries waiting (non-blocking)."""
        for service in self.services:
            service.poll()

    def close(self) -> None:
        """Flush the truth batch, undeclare the queryables, close the session (idempotent)."""
        if self.truth is not None:
            self.truth.close()
            self.truth = None
        for service in self.services:
            service.close()
        self.services = []
        if self.session is not None and self._owns_session:
            self.session.close()
        self.session = None
