"""The one launcher: start processes, wait until they are linked, stop them, never leave an orphan.

``quadsitl up`` and ``quadsitl demo``, the benchmarks and the tests all start their processes
here. A :class:`Child` is one process with its output collected line by line (bounded) by a
reader thread, so :meth:`Child.wait_line` waits for a line with a timeout and never blocks on a
pipe; :meth:`Child.stop` sends SIGTERM, then SIGKILL after a grace period. Children get
``PR_SET_PDEATHSIG`` (Linux) and their own process group: a killed launcher takes them along,
and a terminal's Ctrl-C reaches only the launcher, which stops them in order.

A :class:`Launcher` owns its children (a context manager: leaving it stops them all) and knows
how to start vehicles (:class:`VehicleSpec`: simulator + autopilot per instance, ports checked
first, linked when the simulator says so).
"""

from __future__ import annotations

import ctypes
import errno
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from quadcommon import wire
from quadcommon.config import load_sitl

REPO = Path(__file__).resolve().parents[1]
MAX_LINES = 2000  # kept per child (older lines are dropped)
LINKED = "simulator: linked"


class LaunchError(RuntimeError):
    """A process could not be started or did not get where it should (the message says why)."""


def _die_with_parent() -> None:  # runs in the child between fork and exec (Linux)
    try:
        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except OSError:
        pass
    os.setpgrp()  # own process group: a terminal Ctrl-C reaches the launcher, which stops us


class Child:
    """One child process; its stdout and stderr merged and collected line by line."""

    def __init__(
        self,
        name: str,
        cmd: Sequence[str],
        cwd: Path | str | None = REPO,
        env: dict[str, str] | None = None,
        echo: Callable[[str, str], None] | None = None,
    ) -> None:
        self.name = name
        self.cmd = list(cmd)
        self.echo = echo
        self.lines: deque[str] = deque(maxlen=MAX_LINES)
        self._cond = threading.Condition()
        self.process = subprocess.Popen(
            self.cmd, cwd=cwd, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
            bufsize=1, preexec_fn=_die_with_parent,
        )  # fmt: skip
        self._reader = threading.Thread(target=self._read, name=f"{name} output", daemon=True)
        self._reader.start()

    def _read(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            line = line.rstrip("\n")
            with self._cond:
                self.lines.append(line)
                self._cond.notify_all()
            if self.echo is not None:
                self.echo(self.name, line)
        with self._cond:
            self._cond.notify_all()

    @property
    def output(self) -> str:
        with self._cond:
            return "\n".join(self.lines)

    def tail(self, n: int = 40) -> str:
        with self._cond:
            return "\n".join(list(self.lines)[-n:])

    @property
    def alive(self) -> bool:
        return self.process.poll() is None

    @property
    def returncode(self) -> int | None:
        return self.process.poll()

    def wait_line(self, needle: str, timeout: float = 10.0) -> str:
        """The first output line containing ``needle``; LaunchError (with the output) after
        ``timeout`` seconds or when the process ends without printing it."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while True:
                for line in self.lines:
                    if needle in line:
                        return line
                remaining = deadline - time.monotonic()
                finished = self.process.poll() is not None and not self._reader.is_alive()
                if remaining <= 0 or finished:
                    why = f"exited, code {self.process.returncode}" if finished else f"within {timeout:g} s"
                    raise LaunchError(f"{self.name}: no line with {needle!r} ({why}):\n{self.tail()}")
                self._cond.wait(min(remaining, 0.1))

    def wait(self, timeout: float) -> int:
        """The exit code; LaunchError if the process is still running after ``timeout`` s."""
        try:
            code = self.process.wait(timeout)
        except subprocess.TimeoutExpired:
            raise LaunchError(f"{self.name} still running after {timeout:g} s:\n{self.tail()}") from None
        self._reader.join(2.0)
        return code

    def signal(self, sig: int) -> None:
        if self.process.poll() is None:
            try:
                self.process.send_signal(sig)
            except ProcessLookupError:
                pass

    def stop(self, grace_s: float = 5.0) -> int:
        """SIGTERM, then SIGKILL after ``grace_s``; the exit code (idempotent)."""
        if self.process.poll() is None:
            self.signal(signal.SIGTERM)
            try:
                self.process.wait(grace_s)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(5.0)
        self._reader.join(2.0)
        return self.process.returncode


@dataclass(frozen=True)
class VehicleSpec:
    instance: int = 0
    controller: str = "intbs_nlhinf"
    vehicle: str = "paper_quad"
    scenario: str = "hover"
    speed: str = "1"
    autostart: bool = False  # the autopilot arms at t=0 and flies the scenario's trajectory
    duration_s: float | None = None  # simulator stops after this simulated time
    sitl_config: str | None = None
    params_file: str | None = None  # the autopilot's params.toml (--params): loaded, saved on change
    signing_key_file: str | None = None  # MAVLink 2 signing key (--signing-key): hex key or passphrase
    extra_simulator_args: tuple[str, ...] = ()
    extra_autopilot_args: tuple[str, ...] = ()

    def simulator_command(self) -> list[str]:
        cmd = [sys.executable, "-u", "-m", "simulator", *self._common(), "--scenario", self.scenario,
               "--speed", self.speed, *self.extra_simulator_args]  # fmt: skip
        if self.duration_s is not None:
            cmd += ["--duration", str(self.duration_s)]
        return cmd

    def autopilot_command(self) -> list[str]:
        cmd = [sys.executable, "-u", "-m", "autopilot", *self._common(), "--controller", self.controller,
               *self.extra_autopilot_args]  # fmt: skip
        if self.autostart:
            cmd += ["--autostart", self.scenario]
        if self.params_file:
            cmd += ["--params", self.params_file]
        if self.signing_key_file:
            cmd += ["--signing-key", self.signing_key_file]
        return cmd

    def _common(self) -> list[str]:
        common = ["--instance", str(self.instance), "--vehicle", self.vehicle]
        return common + (["--sitl-config", self.sitl_config] if self.sitl_config else [])

    def ports(self) -> wire.Ports:
        cfg = load_sitl(self.sitl_config)
        return wire.ports(self.instance, cfg.hil_port_base, cfg.gcs_port_base, cfg.api_port_base,
                          cfg.zenoh_port_base)  # fmt: skip


def check_port(port: int, kind: int, what: str, instance: int) -> None:
    """Bind ``port`` on loopback and let go: in use -> LaunchError naming it and ``--instance``."""
    sock = socket.socket(socket.AF_INET, kind)
    if kind == socket.SOCK_STREAM:
        # As zenoh's own listener does: connections of a vehicle just stopped linger in TIME_WAIT
        # for a minute and must not block starting it again; a live listener still makes bind fail.
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((wire.LOOPBACK, port))
    except OSError as exc:
        if exc.errno == errno.EADDRINUSE:
            proto = "TCP" if kind == socket.SOCK_STREAM else "UDP"
            raise LaunchError(
                f"{proto} port {port} ({what}) is already in use: another SITL with --instance "
                f"{instance} may be running; stop it or choose another --instance"
            ) from None
        raise
    finally:
        sock.close()


def check_ports(spec: VehicleSpec) -> wire.Ports:
    ports = spec.ports()
    udp, n = socket.SOCK_DGRAM, spec.instance
    check_port(ports.hil, udp, "simulator HIL link", n)
    check_port(ports.gcs_local, udp, "autopilot GCS link", n)
    check_port(ports.api_local, udp, "autopilot API link", n)
    if not load_sitl(spec.sitl_config).zenoh_router:
        check_port(ports.zenoh, socket.SOCK_STREAM, "simulator zenoh endpoint", n)
    return ports


class Launcher:
    """Children started together and stopped together; leaving the ``with`` block stops them."""

    def __init__(self, echo: Callable[[str, str], None] | None = None) -> None:
        self.echo = echo
        self.children: list[Child] = []
        self.ports: dict[int, wire.Ports] = {}

    def __enter__(self) -> Launcher:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def spawn(self, name: str, cmd: Sequence[str], **kw) -> Child:
        child = Child(name, cmd, echo=self.echo, **kw)
        self.children.append(child)
        return child

    def start_vehicles(self, specs: Sequence[VehicleSpec], link_timeout_s: float = 30.0) -> None:
        """Check every port, start simulator + autopilot per vehicle, wait until all are linked."""
        for spec in specs:
            self.ports[spec.instance] = check_ports(spec)
        try:
            simulators = []
            for spec in specs:
                n = spec.instance
                simulators.append(self.spawn(f"simulator[{n}]", spec.simulator_command()))
                self.spawn(f"autopilot[{n}]", spec.autopilot_command())
            deadline = time.monotonic() + link_timeout_s
            for simulator in simulators:
                self.wait_linked(simulator, deadline)
        except BaseException:
            self.stop()
            raise

    def wait_linked(self, simulator: Child, deadline: float) -> None:
        """Until ``simulator`` reports its autopilot linked; LaunchError naming a process that died."""
        while True:
            try:
                simulator.wait_line(LINKED, 0.1)
                return
            except LaunchError:
                pass
            dead = [c for c in self.children if not c.alive]
            if dead:
                raise LaunchError(f"{dead[0].name} exited with code {dead[0].returncode} before linking:\n"
                                  f"{dead[0].tail(15)}")  # fmt: skip
            if time.monotonic() > deadline:
                raise LaunchError(f"{simulator.name} did not link in time:\n{simulator.tail(15)}")

    def child(self, name: str) -> Child:
        return next(c for c in self.children if c.name == name)

    def first_exited(self) -> Child | None:
        return next((c for c in self.children if not c.alive), None)

    def stop(self, grace_s: float = 5.0) -> dict[str, int]:
        """Stop every child (SIGTERM to all, then SIGKILL to those left); their exit codes."""
        for child in self.children:
            child.signal(signal.SIGTERM)
        deadline = time.monotonic() + grace_s
        for child in self.children:
            child.stop(max(deadline - time.monotonic(), 0.05))
        return {c.name: c.returncode for c in self.children}


def python_script(path: str | Path, *args: str) -> list[str]:
    """The command that runs a script of this checkout with this interpreter (unbuffered)."""
    return [sys.executable, "-u", str(REPO / path), *args]
