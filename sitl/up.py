"""``quadsitl up``: start simulator + autopilot (per vehicle) as two OS processes, linked.

The launcher checks every port first (a port in use is an error naming the port and
``--instance``), starts the processes, waits until each simulator reports its autopilot linked,
prints the endpoints a ground station connects to, and on Ctrl-C or SIGTERM stops everything
(SIGTERM, then SIGKILL after a grace period). Children get PR_SET_PDEATHSIG so that even a
killed launcher leaves no orphans.
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
from collections.abc import Sequence
from dataclasses import dataclass, field

from quadcommon import wire
from quadcommon.config import load_sitl


class LaunchError(RuntimeError):
    pass


def _die_with_parent() -> None:  # runs in the child between fork and exec (Linux)
    try:
        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except OSError:
        pass
    os.setpgrp()  # own process group: a terminal Ctrl-C reaches the launcher, which stops us


def _check_port(port: int, kind: int, what: str, instance: int) -> None:
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


def check_ports(instance: int, sitl_config: str | None = None) -> wire.Ports:
    cfg = load_sitl(sitl_config)
    ports = wire.ports(instance, cfg.hil_port_base, cfg.gcs_port_base, cfg.api_port_base, cfg.zenoh_port_base)
    udp = socket.SOCK_DGRAM
    _check_port(ports.hil, udp, "simulator HIL link", instance)
    _check_port(ports.gcs_local, udp, "autopilot GCS link", instance)
    _check_port(ports.api_local, udp, "autopilot API link", instance)
    if not cfg.zenoh_router:
        _check_port(ports.zenoh, socket.SOCK_STREAM, "simulator zenoh endpoint", instance)
    return ports


@dataclass
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
    extra_simulator_args: Sequence[str] = ()
    extra_autopilot_args: Sequence[str] = ()


@dataclass
class _Child:
    name: str
    process: subprocess.Popen
    lines: list[str] = field(default_factory=list)
    linked: threading.Event = field(default_factory=threading.Event)


class Sitl:
    """Running vehicles; a context manager that always stops what it started."""

    def __init__(self, specs: Sequence[VehicleSpec], echo: bool = True) -> None:
        self.specs = list(specs)
        self.echo = echo
        self.children: list[_Child] = []
        self.ports: dict[int, wire.Ports] = {}

    def __enter__(self) -> Sitl:
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def start(self, link_timeout_s: float = 30.0) -> None:
        for spec in self.specs:
            self.ports[spec.instance] = check_ports(spec.instance, spec.sitl_config)
        try:
            for spec in self.specs:
                self._spawn(spec)
            deadline = time.monotonic() + link_timeout_s
            for child in self.children:
                if not child.name.startswith("simulator"):
                    continue
                while not child.linked.wait(0.1):
                    dead = [c for c in self.children if c.process.poll() is not None]
                    if dead:
                        raise LaunchError(
                            f"{dead[0].name} exited with code {dead[0].process.returncode} before linking:\n"
                            + "\n".join(dead[0].lines[-15:])
                        )
                    if time.monotonic() > deadline:
                        raise LaunchError(f"{child.name} did not link within {link_timeout_s:.0f} s")
        except BaseException:
            self.stop()
            raise

    def _spawn(self, spec: VehicleSpec) -> None:
        n = spec.instance
        common = ["--instance", str(n), "--vehicle", spec.vehicle]
        if spec.sitl_config:
            common += ["--sitl-config", spec.sitl_config]
        sim_cmd = [
            sys.executable,
            "-u",
            "-m",
            "simulator",
            *common,
            "--scenario",
            spec.scenario,
            "--speed",
            spec.speed,
            *spec.extra_simulator_args,
        ]
        if spec.duration_s is not None:
            sim_cmd += ["--duration", str(spec.duration_s)]
        ap_cmd = [
            sys.executable,
            "-u",
            "-m",
            "autopilot",
            *common,
            "--controller",
            spec.controller,
            *spec.extra_autopilot_args,
        ]
        if spec.autostart:
            ap_cmd += ["--autostart", spec.scenario]
        if spec.params_file:
            ap_cmd += ["--params", spec.params_file]
        for name, cmd in ((f"simulator[{n}]", sim_cmd), (f"autopilot[{n}]", ap_cmd)):
            process = subprocess.Popen(
                cmd,
                stdout=subprocess.PIPE,
                stderr=subprocess.STDOUT,
                text=True,
                bufsize=1,
                preexec_fn=_die_with_parent,
            )
            child = _Child(name, process)
            self.children.append(child)
            threading.Thread(target=self._pump, args=(child,), daemon=True).start()

    def _pump(self, child: _Child) -> None:
        assert child.process.stdout is not None
        for line in child.process.stdout:
            line = line.rstrip("\n")
            child.lines.append(line)
            if len(child.lines) > 2000:
                del child.lines[:1000]
            if line.startswith("simulator: linked"):
                child.linked.set()
            if self.echo:
                print(f"[{child.name}] {line}", flush=True)

    def alive(self) -> bool:
        return all(c.process.poll() is None for c in self.children)

    def wait_any_exit(self, timeout_s: float | None = None) -> _Child | None:
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        while deadline is None or time.monotonic() < deadline:
            for child in self.children:
                if child.process.poll() is not None:
                    return child
            time.sleep(0.1)
        return None

    def stop(self, grace_s: float = 5.0) -> None:
        for child in self.children:
            if child.process.poll() is None:
                try:
                    child.process.send_signal(signal.SIGTERM)
                except ProcessLookupError:
                    pass
        deadline = time.monotonic() + grace_s
        for child in self.children:
            remaining = max(deadline - time.monotonic(), 0.05)
            try:
                child.process.wait(remaining)
            except subprocess.TimeoutExpired:
                child.process.kill()
                child.process.wait(2.0)
        self.children_exit_codes = {c.name: c.process.returncode for c in self.children}


def endpoints_banner(spec: VehicleSpec, ports: wire.Ports) -> str:
    n = spec.instance
    return "\n".join(
        [
            f"quadsitl: vehicle {n} is up (MAVLink sysid {wire.system_id(n)}, controller {spec.controller}, "
            f"scenario {spec.scenario}, speed {spec.speed}{'x' if spec.speed != 'max' else ''})",
            f"  QGroundControl / MAVProxy : udp {ports.gcs_remote}   "
            f"(mavproxy.py --master=udpin:127.0.0.1:{ports.gcs_remote})",
            f"  MAVSDK / API scripts      : udpin://0.0.0.0:{ports.api_remote}   "
            f"(pymavlink: udpin:127.0.0.1:{ports.api_remote})",
            f"  zenoh (truth, internals)  : tcp/127.0.0.1:{ports.zenoh}   "
            f"keys quadsitl/{n}/truth, quadsitl/{n}/controller",
        ]
    )


def run_up(specs: Sequence[VehicleSpec], view_port: int | None = None) -> int:
    """Foreground ``quadsitl up``: until Ctrl-C / SIGTERM or a process exits.

    ``view_port``: also start the live view (``--view``) on 127.0.0.1:``view_port`` once the
    vehicles are linked (sitl/view_process.py), print its URL and stop it with the rest.
    """
    sitl = Sitl(specs)
    viewer = None
    stop = threading.Event()

    def on_signal(signum, frame):
        stop.set()

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    try:
        if view_port is not None:  # --view: its port is checked with the others, before any start
            from .view_process import check_view_port, start_view

            check_view_port(view_port)
        sitl.start()
        if view_port is not None:
            viewer = start_view([s.instance for s in specs], view_port, specs[0].sitl_config)
    except LaunchError as exc:
        print(f"quadsitl: {exc}", file=sys.stderr)
        sitl.stop()
        return 2
    for spec in specs:
        print(endpoints_banner(spec, sitl.ports[spec.instance]), flush=True)
    if viewer is not None:
        print(f"  live view (browser)       : {viewer.url}", flush=True)
    print("  Ctrl-C stops every process.", flush=True)
    code = 0
    try:
        while not stop.is_set():
            exited = sitl.wait_any_exit(0.2)
            if exited is not None:
                rc = exited.process.returncode
                finished = rc == 0 and exited.name.startswith("simulator")
                if not finished:
                    print(f"quadsitl: {exited.name} exited with code {rc}; stopping", file=sys.stderr)
                    code = 1
                break
    finally:
        print("quadsitl: stopping ...", flush=True)
        if viewer is not None:
            viewer.stop()
        sitl.stop()
        print("quadsitl: stopped", flush=True)
    return code
