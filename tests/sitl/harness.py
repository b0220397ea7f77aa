"""Full-SITL test harness: the real simulator and autopilot processes, real UDP, real zenoh.

Instances 1-19 belong to the tests under tests/sitl. Every wait is bounded; every process is
stopped (SIGTERM, then SIGKILL) even when a test fails.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

os.environ.setdefault("MAVLINK20", "1")
os.environ.setdefault("MAVLINK_DIALECT", "common")
from pymavlink import mavutil  # noqa: E402

from quadcommon import bus, wire  # noqa: E402
from quadcommon.bus_records import CONTROLLER_CODEC, TRUTH_CODEC  # noqa: E402

REPO = Path(__file__).resolve().parents[2]


class Proc:
    """A child process with its output collected (and shown on failure)."""

    def __init__(self, name: str, cmd: list[str]) -> None:
        self.name = name
        self.proc = subprocess.Popen(
            cmd, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, bufsize=1
        )
        self.lines: list[str] = []
        self._thread = threading.Thread(target=self._pump, daemon=True)
        self._thread.start()

    def _pump(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            self.lines.append(line.rstrip("\n"))

    def wait_line(self, needle: str, timeout: float) -> str:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for line in list(self.lines):
                if needle in line:
                    return line
            if self.proc.poll() is not None:
                break
            time.sleep(0.02)
        raise AssertionError(f"{self.name}: no line with {needle!r} within {timeout} s:\n" + self.output)

    @property
    def output(self) -> str:
        return "\n".join(self.lines[-60:])

    def stop(self, grace: float = 5.0) -> int:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(grace)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(2.0)
        self._thread.join(1.0)
        return self.proc.returncode


class Sitl:
    """Simulator + autopilot for one instance; zenoh truth/controller collected if asked."""

    def __init__(
        self,
        instance: int,
        scenario: str = "hover",
        controller: str = "intbs_nlhinf",
        speed: str = "max",
        autostart: bool = False,
        duration: float | None = None,
        collect: bool = False,
        sim_args: tuple[str, ...] = (),
        ap_args: tuple[str, ...] = (),
    ) -> None:
        self.instance = instance
        self.ports = wire.ports(instance)
        self.scenario, self.controller, self.speed = scenario, controller, speed
        self.autostart, self.duration, self.collect = autostart, duration, collect
        self.sim_args, self.ap_args = sim_args, ap_args
        self.sim: Proc | None = None
        self.ap: Proc | None = None
        self.session = None
        self._subs: list = []
        self.truth_batches: list[np.ndarray] = []
        self.controller_batches: list[np.ndarray] = []

    def __enter__(self) -> Sitl:
        try:
            self.start()
        except BaseException:
            self.stop()
            raise
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def start(self) -> None:
        py = [sys.executable, "-u", "-m"]
        cmd = [*py, "simulator", "--instance", str(self.instance), "--scenario", self.scenario,
               "--speed", self.speed, *self.sim_args]  # fmt: skip
        if self.duration is not None:
            cmd += ["--duration", str(self.duration)]
        self.sim = Proc("simulator", cmd)
        self.sim.wait_line("waiting for the autopilot", 20.0)
        if self.collect:
            self._subscribe()
        cmd = [*py, "autopilot", "--instance", str(self.instance), "--controller", self.controller,
               *self.ap_args]  # fmt: skip
        if self.autostart:
            cmd += ["--autostart", self.scenario]
        self.ap = Proc("autopilot", cmd)
        self.sim.wait_line("simulator: linked", 20.0)

    def _subscribe(self) -> None:
        import zenoh

        self.session = bus.open_peer(self.ports.zenoh)
        for key in ("truth", "controller"):
            self._subs.append(
                self.session.declare_subscriber(
                    wire.zenoh_key(self.instance, key), zenoh.handlers.FifoChannel(100000)
                )
            )
        # A reply from the simulator proves the link is up and our subscriptions are known to it
        # (declarations travel before the query on the same link).
        deadline = time.monotonic() + 10.0
        while time.monotonic() < deadline:
            replies = list(self.session.get(wire.zenoh_key(self.instance, "info"), timeout=1.0))
            if any(r.ok is not None for r in replies):
                return
            time.sleep(0.05)
        raise AssertionError("the simulator's zenoh info queryable never answered")

    def drain(self) -> None:
        for sub, sink, codec in zip(
            self._subs, (self.truth_batches, self.controller_batches), (TRUTH_CODEC, CONTROLLER_CODEC),
            strict=False,
        ):  # fmt: skip
            while True:
                sample = sub.try_recv()
                if sample is None:
                    break
                sink.append(codec.decode(sample.payload.to_bytes()).copy())

    def truth(self) -> np.ndarray:
        self.drain()
        return (
            np.concatenate(self.truth_batches)
            if self.truth_batches
            else np.zeros((0, len(TRUTH_CODEC.fields)))
        )

    def controller_rows(self) -> np.ndarray:
        self.drain()
        if not self.controller_batches:
            return np.zeros((0, len(CONTROLLER_CODEC.fields)))
        return np.concatenate(self.controller_batches)

    def wait_simulator_exit(self, timeout: float) -> int:
        assert self.sim is not None
        deadline = time.monotonic() + timeout
        while self.sim.proc.poll() is None and time.monotonic() < deadline:
            if self.collect:
                self.drain()
            time.sleep(0.05)
        if self.sim.proc.poll() is None:
            raise AssertionError(f"simulator still running after {timeout} s:\n{self.sim.output}")
        time.sleep(0.3)  # let the last batches arrive
        if self.collect:
            self.drain()
        return self.sim.proc.returncode

    def stop(self) -> None:
        for proc in (self.ap, self.sim):
            if proc is not None:
                proc.stop()
        for sub in self._subs:
            try:
                sub.undeclare()
            except Exception:
                pass
        if self.session is not None:
            self.session.close()
            self.session = None

    def gcs(self, api: bool = True) -> Gcs:
        port = self.ports.api_remote if api else self.ports.gcs_remote
        return Gcs(port, wire.system_id(self.instance))


class Gcs:
    """A minimal pymavlink ground station on the API (or GCS) port, timed by simulation time."""

    def __init__(self, port: int, system_id: int) -> None:
        self.conn = mavutil.mavlink_connection(
            f"udpin:127.0.0.1:{port}", source_system=255, source_component=190
        )
        self.system_id = system_id
        self.sim_time = 0.0
        self.last: dict[str, object] = {}
        self.statustext: list[str] = []
        self.acks: list = []

    def close(self) -> None:
        self.conn.close()

    def poll(self, timeout: float = 0.05):
        msg = self.conn.recv_match(blocking=True, timeout=timeout)
        if msg is None:
            return None
        if msg.get_srcSystem() != self.system_id:
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
        """Poll until ``predicate(self)`` is true; fail after ``sim_timeout`` s of sim time."""
        start_sim = self.sim_time
        deadline = time.monotonic() + wall_timeout
        while time.monotonic() < deadline:
            self.poll()
            if predicate(self):
                return
            if self.sim_time - start_sim > sim_timeout:
                break
        raise AssertionError(f"timed out waiting for {what or predicate} (sim t={self.sim_time:.2f} s)")

    def wait_heartbeat(self) -> None:
        self.wait(lambda g: "HEARTBEAT" in g.last, what="heartbeat", sim_timeout=1e9, wall_timeout=20)

    def command(self, command: int, *params: float, timeout: float = 5.0):
        """COMMAND_LONG; returns the COMMAND_ACK (fails if none within ``timeout`` wall s)."""
        p = list(params) + [0.0] * (7 - len(params))
        self.acks.clear()
        self.conn.mav.command_long_send(self.system_id, 1, command, 0, *p)
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self.poll()
            for ack in self.acks:
                if ack.command == command:
                    return ack
        raise AssertionError(f"no COMMAND_ACK for command {command} within {timeout} s")

    @property
    def armed(self) -> bool:
        hb = self.last.get("HEARTBEAT")
        return bool(hb and hb.base_mode & 128)

    @property
    def custom_mode(self) -> int:
        hb = self.last.get("HEARTBEAT")
        return hb.custom_mode if hb else -1

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


def info(session, instance: int) -> dict:
    for reply in session.get(wire.zenoh_key(instance, "info"), timeout=2.0):
        if reply.ok is not None:
            return json.loads(reply.ok.payload.to_bytes())
    return {}
