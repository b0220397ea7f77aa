"""Vehicles for the client-compatibility tests: real ``quadsitl up`` processes on their own ports.

The vehicles run on this pytest process's port block (tests/ports.py: a ``sitl.toml`` with the
shipped settings and the block's port bases, first in ``QUADSITL_CONFIG_DIR``), so they behave
exactly like a default ``quadsitl up``, on ports no other test run uses.

Only instances 0-9 are used: the API port of instance k + 10 is the GCS port of instance k
(PX4's scheme overlaps the same way), and two clients must never share a port.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from quadcommon import wire
from sitl.launcher import Launcher, VehicleSpec
from tests.ports import instance_ports

REPO = Path(__file__).resolve().parents[2]
FLOWS = Path(__file__).with_name("mavsdk_flows.py")


def ports(instance: int) -> wire.Ports:
    return instance_ports(instance)


@contextmanager
def vehicle(
    instance: int, sitl_config: Path, speed: str = "2", log_dir: Path | None = None,
    impair: tuple[str, ...] = (), estimator: str | None = None, sensors: str | None = None,
) -> Iterator[Launcher]:
    """One vehicle (simulator + autopilot) started by the ``quadsitl up`` launcher; always stopped.

    ``speed`` is the wall-clock pacing: MAVSDK and MAVProxy time out on the wall clock, so they run
    at a modest factor, never at ``max``. ``log_dir``: its flight logs (default: none).
    """
    assert 0 <= instance <= 9, "compat tests use instances 0-9"
    spec = VehicleSpec(instance=instance, speed=speed, sitl_config=str(sitl_config),
                       log_dir=str(log_dir) if log_dir is not None else None, impair=impair,
                       estimator=estimator, sensors=sensors)  # fmt: skip
    with Launcher() as sitl:
        sitl.start_vehicles([spec], 20.0)
        yield sitl


# Where flight_logs' files go on a vehicle: PX4's layout, distinct start times (MAVSDK's example
# names a download after its date).
LOG_NAMES = ("2024-05-01/10_00_00.ulg", "2024-05-01/10_05_30.ulg")


def vehicle_logs(directory: Path, logs: list[Path]) -> list[Path]:
    """Copies of ``logs`` in ``directory`` as a vehicle keeps them (LOG_NAMES), oldest first."""
    out = []
    for name, log in zip(LOG_NAMES, logs, strict=True):
        target = directory / name
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_bytes(log.read_bytes())
        out.append(target)
    return out


def sitl_output(sitl: Launcher, lines: int = 40) -> str:
    """The last lines each process printed (for failure messages)."""
    return "\n".join(f"--- {c.name}:\n" + c.tail(lines) for c in sitl.children)


class FlowResult:
    """What one MAVSDK flow subprocess printed: JSON events, the rest, exit code, wall time."""

    def __init__(self, flow: str, proc: subprocess.CompletedProcess | None, wall_s: float, timed_out: bool):
        self.flow = flow
        self.wall_s = wall_s
        self.timed_out = timed_out
        self.returncode = None if proc is None else proc.returncode
        self.stdout = "" if proc is None else proc.stdout
        self.stderr = "" if proc is None else proc.stderr
        self.events: list[dict] = []
        for line in self.stdout.splitlines():
            if line.startswith("{"):  # MAVSDK's own log lines also go to stdout
                self.events.append(json.loads(line))

    def event(self, name: str) -> dict:
        """The (last) event called ``name``."""
        found = [e for e in self.events if e["event"] == name]
        assert found, f"flow {self.flow}: no event {name!r}\n{self.transcript()}"
        return found[-1]

    def transcript(self, tail: int = 80) -> str:
        lines = self.stdout.splitlines()[-tail:] + self.stderr.splitlines()[-20:]
        state = "TIMED OUT" if self.timed_out else f"rc={self.returncode}"
        return f"[{self.flow}: {state}, {self.wall_s:.1f} s]\n" + "\n".join(lines)


def run_flow(flow: str, url: str, timeout_s: float, *args: str) -> FlowResult:
    """Run one flow of ``mavsdk_flows.py`` in a subprocess with a hard timeout.

    A subprocess because a MAVSDK call cut short can leave the C++ core's teardown waiting
    forever (see the MAVSDK notes): pytest must never share a process with it.
    """
    cmd = [sys.executable, str(FLOWS), flow, url, *args]
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    start = time.monotonic()
    try:
        proc = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s, cwd=REPO, env=env)
        return FlowResult(flow, proc, time.monotonic() - start, False)
    except subprocess.TimeoutExpired as exc:
        fake = subprocess.CompletedProcess(cmd, -9, _text(exc.stdout), _text(exc.stderr))
        return FlowResult(flow, fake, time.monotonic() - start, True)


def _text(data) -> str:
    if data is None:
        return ""
    return data.decode(errors="replace") if isinstance(data, bytes) else data


class TruthTap:
    """One vehicle's zenoh stream ``quadsitl/<N>/<leaf>``: the simulator's ground truth (``truth``,
    the default) or the autopilot's controller internals (``controller``: the reference flown).

    Tests check what a client's command did to the vehicle here, independently of what the client
    itself reports. Close it (or use it as a context manager): a zenoh session left open keeps
    threads alive.
    """

    def __init__(self, instance: int, leaf: str = "truth", key_instance: int | None = None) -> None:
        import zenoh

        from quadcommon import bus
        from quadcommon.bus_records import CONTROLLER_CODEC, TRUTH_CODEC

        self.codec = TRUTH_CODEC if leaf == "truth" else CONTROLLER_CODEC
        self.key = wire.zenoh_key(instance if key_instance is None else key_instance, leaf)
        self.session = bus.open_peer(ports(instance).zenoh)
        self._sub = self.session.declare_subscriber(self.key, zenoh.handlers.FifoChannel(100_000))
        self.rows: list = []

    def __enter__(self) -> TruthTap:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        try:
            self._sub.undeclare()
        finally:
            self.session.close()

    def drain(self):
        """Every row received so far, as one array (columns: the codec's fields)."""
        import numpy as np

        while True:
            sample = self._sub.try_recv()
            if sample is None:
                break
            self.rows.append(self.codec.decode(sample.payload.to_bytes()).copy())
        if not self.rows:
            return np.zeros((0, len(self.codec.fields)))
        self.rows = [np.concatenate(self.rows)]
        return self.rows[0]

    def latest(self) -> dict[str, float] | None:
        rows = self.drain()
        return dict(zip(self.codec.fields, rows[-1], strict=True)) if len(rows) else None

    def wait(self, what: str, predicate, timeout_s: float) -> dict[str, float]:
        """Poll until ``predicate(latest row)``; fails naming ``what`` after ``timeout_s`` (wall)."""
        deadline = time.monotonic() + timeout_s
        row = None
        while time.monotonic() < deadline:
            row = self.latest()
            if row is not None and predicate(row):
                return row
            time.sleep(0.05)
        raise AssertionError(f"{self.key}: no {what} within {timeout_s} s; last row {row}")
