"""Real processes for the few smoke tests that need them: vehicles started by the project's one
launcher (:mod:`sitl.launcher`), zenoh taps on their truth and controller streams, and a minimal
pymavlink ground station over UDP. Every wait is bounded; everything started is stopped.

Instances 1-19 belong to the tests under tests/sitl.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np

os.environ.setdefault("MAVLINK20", "1")
os.environ.setdefault("MAVLINK_DIALECT", "common")
from pymavlink import mavutil  # noqa: E402

from quadcommon import bus, wire  # noqa: E402
from quadcommon.bus_records import CONTROLLER_CODEC, TRUTH_CODEC  # noqa: E402
from sitl.launcher import Launcher, VehicleSpec  # noqa: E402
from tests.ports import instance_ports  # noqa: E402


class ZenohTap:
    """One vehicle's zenoh stream ``quadsitl/<N>/<leaf>`` (``truth`` or ``controller``), collected.

    Declared before the vehicle starts streaming; :meth:`barrier` returns once the simulator's info
    queryable has answered over the same link, which proves our subscription is known to it.
    """

    def __init__(self, instance: int, leaf: str = "truth", ports: wire.Ports | None = None) -> None:
        import zenoh

        ports = ports or instance_ports(instance)
        self.instance, self.codec = instance, TRUTH_CODEC if leaf == "truth" else CONTROLLER_CODEC
        self.session = bus.open_peer(ports.zenoh)
        self._sub = self.session.declare_subscriber(
            wire.zenoh_key(instance, leaf), zenoh.handlers.FifoChannel(100_000)
        )
        self.batches: list[np.ndarray] = []

    def barrier(self, timeout_s: float = 10.0) -> None:
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            replies = list(self.session.get(wire.zenoh_key(self.instance, "info"), timeout=1.0))
            if any(r.ok is not None for r in replies):
                return
            time.sleep(0.05)
        raise AssertionError("the simulator's zenoh info queryable never answered")

    def rows(self) -> np.ndarray:
        while (sample := self._sub.try_recv()) is not None:
            self.batches.append(self.codec.decode(sample.payload.to_bytes()).copy())
        if not self.batches:
            return np.zeros((0, len(self.codec.fields)))
        self.batches = [np.concatenate(self.batches)]
        return self.batches[0]

    def close(self) -> None:
        try:
            self._sub.undeclare()
        finally:
            self.session.close()


@contextmanager
def running(
    spec: VehicleSpec, leaves: tuple[str, ...] = ()
) -> Iterator[tuple[Launcher, dict[str, ZenohTap]]]:
    """Start ``spec``'s simulator, tap ``leaves`` on zenoh, start its autopilot; stop them all."""
    taps: dict[str, ZenohTap] = {}
    with Launcher() as launcher:
        try:
            if leaves:  # the taps must exist before the first frame: start the simulator first
                sim = launcher.spawn(f"simulator[{spec.instance}]", spec.simulator_command())
                sim.wait_line("waiting for the autopilot", 20.0)
                taps = {leaf: ZenohTap(spec.instance, leaf, spec.ports()) for leaf in leaves}
                next(iter(taps.values())).barrier()
                launcher.spawn(f"autopilot[{spec.instance}]", spec.autopilot_command())
                launcher.wait_linked(sim, time.monotonic() + 20.0)
            else:
                launcher.start_vehicles([spec], 20.0)
            yield launcher, taps
        finally:
            for tap in taps.values():
                tap.close()


class UdpGcs:
    """A minimal pymavlink ground station on a UDP port, timed by simulation time."""

    def __init__(self, port: int, system_id: int) -> None:
        self.conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255,
                                               source_component=190)  # fmt: skip
        self.system_id = system_id
        self.sim_time = 0.0
        self.last: dict[str, object] = {}
        self.statustext: list[str] = []
        self.acks: list = []

    def close(self) -> None:
        self.conn.close()

    def poll(self, timeout: float = 0.05):
        msg = self.conn.recv_match(blocking=True, timeout=timeout)
        if msg is None or msg.get_srcSystem() != self.system_id:
            return msg
        kind = msg.get_type()
        self.last[kind] = msg
        if hasattr(msg, "time_boot_ms"):
            self.sim_time = max(self.sim_time, msg.time_boot_ms * 1e-3)
        if kind == "STATUSTEXT":
            self.statustext.append(msg.text)
        elif kind == "COMMAND_ACK":
            self.acks.append(msg)
        return msg

    def wait(self, predicate, sim_timeout: float = 30.0, wall_timeout: float = 60.0, what: str = ""):
        """Poll until ``predicate(self)``; fail after ``sim_timeout`` s of simulation time or
        ``wall_timeout`` s of wall time."""
        start_sim, deadline = self.sim_time, time.monotonic() + wall_timeout
        while time.monotonic() < deadline and self.sim_time - start_sim <= sim_timeout:
            self.poll()
            if predicate(self):
                return
        raise AssertionError(f"timed out waiting for {what or predicate} (sim t={self.sim_time:.2f} s)")

    def command(self, command: int, *params: float, timeout: float = 5.0):
        """COMMAND_LONG; returns the COMMAND_ACK (fails if none within ``timeout`` wall s)."""
        p = list(params) + [0.0] * (7 - len(params))
        self.acks.clear()
        self.conn.mav.command_long_send(self.system_id, 1, command, 0, *p)
        self.wait(lambda g: any(a.command == command for a in g.acks), 1e9, timeout, f"ACK {command}")
        return next(a for a in self.acks if a.command == command)

    def position(self) -> tuple[float, float, float]:
        """Last LOCAL_POSITION_NED in the paper frame (x, y left, z up)."""
        lp = self.last["LOCAL_POSITION_NED"]
        return (lp.x, -lp.y, -lp.z)

    def send_position_setpoint(self, x: float, y: float, z: float) -> None:
        """A position-only setpoint in the paper frame."""
        mask = 8 | 16 | 32 | 64 | 128 | 256 | 1024 | 2048
        self.conn.mav.set_position_target_local_ned_send(
            int(self.sim_time * 1000), self.system_id, 1, 1, mask, x, -y, -z, 0, 0, 0, 0, 0, 0, 0, 0
        )
