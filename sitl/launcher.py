"""The one launcher: start processes, wait until they are linked, stop them, never leave an orphan.

``quadsitl up`` and ``quadsitl demo``, the benchmarks and the tests all start their processes
here. A :class:`Child` is one process with its output collected line by line (bounded) by a
reader thread, so :meth:`Child.wait_line` waits for a line with a timeout and never blocks on a
pipe; :meth:`Child.stop` sends SIGTERM, then SIGKILL after a grace period. Children get
``PR_SET_PDEATHSIG`` (Linux) and their own process group: a killed launcher takes them along,
and a terminal's Ctrl-C reaches only the launcher, which stops them in order.

A :class:`Launcher` owns its children (a context manager: leaving it stops them all) and knows
how to start vehicles (:class:`VehicleSpec`: simulator + autopilot per instance, ports checked
first, linked when the simulator says so) and how to start one again (:meth:`Launcher.respawn`,
used by ``quadsitl up``'s supervisor, :mod:`sitl.supervise`).

Ports (:func:`check_launch`, before anything starts): every port of an instance by role
(:func:`quadcommon.wire.port_roles`: *own* ports bound by our processes, *client* ports where
ground stations listen). Refused, naming the port, its link and the instances: an own port in
use; two instances of one launch sharing a port where one of them binds it
(:func:`quadcommon.wire.port_collisions`; never with the default bases); a client port that is another
instance's own port while that port is in use (that instance is running: our stream would reach
its autopilot); an own port that is the client port of another instance that is running (its
stream would reach ours). A ground station listening on a client port is normal, never an error.
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
from quadcommon.config import SPIN_ENV, estimator_profile_for, load_scenario, load_sitl

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
        cwd: Path | str | None = None,  # the launcher's: relative paths mean what the user meant
        env: dict[str, str] | None = None,
        echo: Callable[[str, str], None] | None = None,
    ) -> None:
        self.name = name
        self.cmd = list(cmd)
        self.env = env
        self.echo = echo
        self.lines: deque[str] = deque(maxlen=MAX_LINES)
        self.line_count = 0  # lines read so far (``lines`` keeps the last MAX_LINES of them)
        self._cond = threading.Condition()
        self.started = time.monotonic()
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
            if self.echo is not None:  # first: whatever a waiter prints because of it comes after
                self.echo(self.name, line)
            with self._cond:
                self.lines.append(line)
                self.line_count += 1
                self._cond.notify_all()
        with self._cond:
            self._cond.notify_all()

    @property
    def output(self) -> str:
        """Everything the child printed so far (the lines kept)."""
        with self._cond:
            return "\n".join(self.lines)

    def tail(self, n: int = 40) -> str:
        """The child's last ``n`` output lines."""
        with self._cond:
            return "\n".join(list(self.lines)[-n:])

    def lines_since(self, count: int) -> tuple[list[str], int]:
        """The lines read after the first ``count`` (those still kept) and the new count: a caller
        scanning the output as it comes keeps the count and passes it back."""
        with self._cond:
            new = min(self.line_count - count, len(self.lines))
            return (list(self.lines)[len(self.lines) - new :] if new > 0 else []), self.line_count

    @property
    def pid(self) -> int:
        """The child's process id."""
        return self.process.pid

    @property
    def alive(self) -> bool:
        """The child has not exited."""
        return self.process.poll() is None

    @property
    def returncode(self) -> int | None:
        """The exit status (negative: the signal that ended it), or None while running."""
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
        """Send ``sig`` to the child, if it still runs."""
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
    sensors: str | None = None  # sensor profile (config/sensors); None: the scenario's
    estimator: str | None = None  # "truth" or "ekf"; None: the scenario's
    log_dir: str | None = None  # the autopilot's flight logs (ULog); None: no flight log (--no-log)
    impair: tuple[str, ...] = ()  # --impair LINK:SPEC for both processes (docs/links.md)
    spacing_m: float = 0.0  # --spacing: its home instance x spacing_m north (SitlConfig.spaced)
    extra_simulator_args: tuple[str, ...] = ()
    extra_autopilot_args: tuple[str, ...] = ()

    def simulator_command(self) -> list[str]:
        """The command line of this vehicle's simulator process."""
        cmd = [sys.executable, "-u", "-m", "simulator", *self._common(), "--scenario", self.scenario,
               "--speed", self.speed, *self.extra_simulator_args]  # fmt: skip
        if self.duration_s is not None:
            cmd += ["--duration", str(self.duration_s)]
        if self.sensors:
            cmd += ["--sensors", self.sensors]
        return cmd

    def autopilot_command(self) -> list[str]:
        """The command line of this vehicle's autopilot process."""
        cmd = [sys.executable, "-u", "-m", "autopilot", *self._common(), "--controller", self.controller,
               *self.extra_autopilot_args]  # fmt: skip
        if self.autostart:
            cmd += ["--autostart", self.scenario]
        if self.params_file:
            cmd += ["--params", self.params_file]
        if self.signing_key_file:
            cmd += ["--signing-key", self.signing_key_file]
        cmd += ["--log-dir", self.log_dir] if self.log_dir is not None else ["--no-log"]
        estimator, profile = self.estimation()
        if estimator != "truth":
            cmd += ["--estimator", estimator, "--estimator-profile", profile]
        return cmd

    def estimation(self) -> tuple[str, str]:
        """(estimator, EKF profile): the spec's or its scenario's; the profile named after the
        sensor profile (config/estimator/NAME.toml), else ``default``."""
        scenario = load_scenario(self.scenario)
        sensors = self.sensors or scenario.sensors
        return self.estimator or scenario.estimator, estimator_profile_for(sensors)

    def _common(self) -> list[str]:
        common = ["--instance", str(self.instance), "--vehicle", self.vehicle]
        for spec in self.impair:
            common += ["--impair", spec]
        if self.spacing_m:
            common += ["--spacing", repr(self.spacing_m)]
        return common + (["--sitl-config", self.sitl_config] if self.sitl_config else [])

    def ports(self) -> wire.Ports:
        """The vehicle's UDP and zenoh ports (from the SITL configuration and its instance)."""
        return load_sitl(self.sitl_config).ports(self.instance)


def port_in_use(proto: str, port: int) -> bool:
    """Whether binding ``port`` on loopback fails with EADDRINUSE (``proto`` "UDP" or "TCP").

    TCP binds with SO_REUSEADDR, as zenoh's own listener does: connections of a vehicle just
    stopped linger in TIME_WAIT for a minute and must not count; a live listener still does."""
    kind = socket.SOCK_STREAM if proto == "TCP" else socket.SOCK_DGRAM
    sock = socket.socket(socket.AF_INET, kind)
    if kind == socket.SOCK_STREAM:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind((wire.LOOPBACK, port))
    except OSError as exc:
        if exc.errno == errno.EADDRINUSE:
            return True
        raise
    finally:
        sock.close()
    return False


def check_port(port: int, kind: int, what: str, instance: int) -> None:
    """Bind ``port`` on loopback and let go: in use -> LaunchError naming it and ``--instance``."""
    proto = "TCP" if kind == socket.SOCK_STREAM else "UDP"
    if port_in_use(proto, port):
        raise LaunchError(_in_use_text(proto, port, what, instance))


def _in_use_text(proto: str, port: int, what: str, instance: int) -> str:
    return (f"{proto} port {port} ({what}) is already in use: another SITL with --instance "
            f"{instance} may be running; stop it or choose another --instance")  # fmt: skip


class _PortPlan:
    """The ports by role of every instance in [0, 249] under one sitl.toml (its bases), indexed by
    port; which instances run is probed once per plan."""

    def __init__(self, spec: VehicleSpec) -> None:
        cfg = load_sitl(spec.sitl_config)
        self.bases = (cfg.hil_port_base, cfg.gcs_port_base, cfg.api_port_base, cfg.zenoh_port_base)
        self.zenoh_listener = not cfg.zenoh_router
        everyone = range(wire.INSTANCE_MIN, wire.INSTANCE_MAX + 1)
        self._roles = {n: wire.port_roles(self.ports(n), self.zenoh_listener) for n in everyone}
        self._users: dict[tuple[str, int], list[tuple[int, wire.PortRole]]] = {}
        for n in everyone:
            for r in self._roles[n]:
                self._users.setdefault((r.proto, r.port), []).append((n, r))
        self._running: dict[int, wire.PortRole | None] = {}

    def ports(self, n: int) -> wire.Ports:
        return wire.ports(n, *self.bases)

    def roles(self, n: int) -> tuple[wire.PortRole, ...]:
        return self._roles[n]

    def sharing(self, role: wire.PortRole, n: int) -> list[tuple[int, wire.PortRole]]:
        """Every (other instance, its role) using the same protocol and port as ``role`` of ``n``."""
        return [(m, r) for m, r in self._users[(role.proto, role.port)] if m != n]

    def unique_own(self, m: int) -> list[wire.PortRole]:
        """``m``'s own ports that no other instance uses in any role: one of them in use means
        instance ``m`` is running."""
        return [r for r in self.roles(m) if r.own and len(self._users[(r.proto, r.port)]) == 1]

    def running(self, m: int) -> wire.PortRole | None:
        """The first of ``m``'s :meth:`unique_own` ports in use (instance ``m`` runs), else None."""
        if m not in self._running:
            self._running[m] = next((r for r in self.unique_own(m) if port_in_use(r.proto, r.port)), None)
        return self._running[m]

    def hint(self) -> str:
        clash = wire.port_collisions(self.roles, range(wire.INSTANCE_MIN, wire.INSTANCE_MAX + 1))
        text = f"--instance is {wire.INSTANCE_MIN}-{wire.INSTANCE_MAX}"
        if clash:
            c = clash[0]
            text += (f"; sitl.toml's [ports] bases make {len(clash)} ports meet across instances, e.g. "
                     f"{_both(c.first[1], c.first[0], c.second[1], c.second[0])}")  # fmt: skip
        return text


def _both(port: wire.PortRole, n: int, other: wire.PortRole, m: int) -> str:
    return f"{port.proto} {port.port}: instance {n}'s {port.role} is instance {m}'s {other.role}"


def launch_conflicts(specs: Sequence[VehicleSpec]) -> list[str]:
    """Ports two instances of one launch cannot share (pure: no socket; :func:`wire.port_collisions`:
    an own port of both, or one's own port the other's client port), one sentence each naming the
    port, both instances and their roles; empty when they can run together."""
    if not specs:
        return []
    plan = _PortPlan(specs[0])
    instances = [spec.instance for spec in specs]
    problems = [f"instance {n} is given twice" for n in sorted(set(instances)) if instances.count(n) > 1]
    for c in wire.port_collisions(plan.roles, sorted(set(instances))):
        (n, mine), (m, theirs) = sorted([c.first, c.second], key=lambda u: -u[0])
        problems.append(_both(mine, n, theirs, m))
    return problems


def _running_sharers(plan: _PortPlan, n: int, together: set[int], clients_too: bool = False):
    """(our role, other instance, its role, the port showing it runs) for every other instance
    outside ``together`` that shares a port with ``n`` and is running now; a client port shared
    with another's client port only with ``clients_too`` (allowed: a ground station hears both)."""
    for mine in plan.roles(n):
        for m, theirs in plan.sharing(mine, n):
            if m in together or (not clients_too and not mine.own and not theirs.own):
                continue
            running = plan.running(m)
            if running is not None:
                yield mine, m, theirs, running


def check_ports(
    spec: VehicleSpec, launch: Sequence[VehicleSpec] = (), plan: _PortPlan | None = None
) -> wire.Ports:
    """Every port of ``spec``'s instance against what is running now (sockets bound and let go):
    its own ports must be free, and no other instance it shares a port with may be running (one
    of that instance's ports no one else uses is in use). ``launch``: the instances started with
    it (:func:`launch_conflicts` checks those). LaunchError naming the port, the link, the instance
    and the other instance. A client port in use with no such instance running is a ground station
    listening there: normal."""
    plan = plan or _PortPlan(spec)
    n, together = spec.instance, {s.instance for s in launch} | {spec.instance}
    roles = plan.roles(n)
    for mine in roles:  # own ports in use
        if mine.own and port_in_use(mine.proto, mine.port):
            text = _in_use_text(mine.proto, mine.port, mine.role, n)
            for m, theirs in plan.sharing(mine, n):
                guess = f"is instance {m} running?" if theirs.own else f"a ground station of instance {m}?"
                text += f"; it is also instance {m}'s {theirs.role} ({guess})"
            raise LaunchError(text)
    for mine, m, theirs, running in _running_sharers(plan, n, together):
        if theirs.own:  # our client port: our stream to it would reach instance m's process
            effect = f"instance {n}'s traffic for its {mine.role} would reach instance {m}'s {theirs.role}"
        else:  # instance m's client port: its stream would reach our process
            effect = f"instance {m}'s traffic for its {theirs.role} would reach instance {n}'s {mine.role}"
        raise LaunchError(
            f"{_both(mine, n, theirs, m)}, and instance {m} looks running ({running.proto} "
            f"{running.port}, its {running.role}, is in use): {effect}; stop instance {m} or choose "
            f"another --instance ({plan.hint()})"
        )
    return plan.ports(n)


def port_notes(specs: Sequence[VehicleSpec]) -> list[str]:
    """Client ports shared with other instances that are running (not of ``specs``): allowed (a
    ground station tells the vehicles apart by system id, as with PX4's one GCS port 14550 for
    every instance), but a ground station there hears them all; one note per port."""
    if not specs:
        return []
    plan, together = _PortPlan(specs[0]), {s.instance for s in specs}
    heard: dict[tuple[str, int, str], set[int]] = {}
    for spec in specs:
        for mine, m, theirs, _ in _running_sharers(plan, spec.instance, together, clients_too=True):
            if not mine.own and not theirs.own:
                heard.setdefault((mine.proto, mine.port, mine.role), set()).add(m)
    notes = []
    for (proto, port, role), others in sorted(heard.items()):
        ours = sorted(s.instance for s in specs
                      if any(r.port == port and not r.own for r in plan.roles(s.instance)))  # fmt: skip
        shown = ", ".join(str(m) for m in sorted(others)[:8]) + (" ..." if len(others) > 8 else "")
        notes.append(
            f"note: {proto} {port} is the {role} of instance(s) {_span(ours)} and of running instance(s) "
            f"{shown}: a ground station there hears them all (system id 1 + N)"
        )
    return notes


def _span(instances: list[int]) -> str:
    if len(instances) > 2 and instances == list(range(instances[0], instances[-1] + 1)):
        return f"{instances[0]}-{instances[-1]}"
    return ", ".join(str(n) for n in instances)


def check_launch(specs: Sequence[VehicleSpec], running: Sequence[VehicleSpec] = ()) -> dict[int, wire.Ports]:
    """Every port of every instance of one launch, before anything starts: :func:`launch_conflicts`
    over ``specs`` and the vehicles ``running`` from this launcher, then :func:`check_ports` for
    each of ``specs``. The ports per instance; LaunchError (all the conflicts) otherwise."""
    problems = launch_conflicts([*running, *specs])
    if problems:
        names = ", ".join(str(s.instance) for s in [*running, *specs])
        shown = problems[:6] + ([f"... and {len(problems) - 6} more"] if len(problems) > 6 else [])
        raise LaunchError(
            f"instances {names} cannot run together: their ports overlap:\n  "
            + "\n  ".join(shown)
            + f"\n({_PortPlan(specs[0]).hint()})"
        )
    everyone = [*running, *specs]
    plan = _PortPlan(specs[0])
    return {spec.instance: check_ports(spec, everyone, plan) for spec in specs}


def spin_environment(vehicles: int, environ: dict[str, str] | None = None, cores: int | None = None):
    """The children's environment with the lockstep spin off when the vehicles' processes (two each)
    outnumber the cores: a busy-waiting process would take the core its peer needs (docs/running.md,
    "Several vehicles"); None (inherit) otherwise, or when the user set the spin already."""
    environ = dict(os.environ) if environ is None else environ
    cores = cores if cores is not None else (os.cpu_count() or 1)
    if SPIN_ENV in environ or 2 * vehicles <= cores:
        return None
    return {**environ, SPIN_ENV: "0"}


class Launcher:
    """Children started together and stopped together; leaving the ``with`` block stops them."""

    def __init__(self, echo: Callable[[str, str], None] | None = None) -> None:
        self.echo = echo
        self.children: list[Child] = []
        self.ports: dict[int, wire.Ports] = {}
        self.specs: dict[int, VehicleSpec] = {}

    def __enter__(self) -> Launcher:
        return self

    def __exit__(self, *exc) -> None:
        self.stop()

    def spawn(self, name: str, cmd: Sequence[str], **kw) -> Child:
        """Start ``cmd`` as child ``name`` and keep it to stop with the others."""
        child = Child(name, cmd, echo=self.echo, **kw)
        self.children.append(child)
        return child

    def start_vehicles(self, specs: Sequence[VehicleSpec], link_timeout_s: float = 30.0) -> None:
        """Check every port, start simulator + autopilot per vehicle, wait until all are linked."""
        self.ports.update(check_launch(specs, list(self.specs.values())))
        self.specs.update({spec.instance: spec for spec in specs})
        env = spin_environment(len(self.specs))
        if env is not None and self.echo is not None:
            self.echo("quadsitl", f"{2 * len(self.specs)} lockstep processes on {os.cpu_count()} cores: "
                      f"they block instead of busy-waiting for each other ({SPIN_ENV}=0)")  # fmt: skip
        try:
            simulators = []
            for spec in specs:
                n = spec.instance
                simulators.append(self.spawn(f"simulator[{n}]", spec.simulator_command(), env=env))
                self.spawn(f"autopilot[{n}]", spec.autopilot_command(), env=env)
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

    def respawn(self, old: Child, cmd: Sequence[str] | None = None) -> Child:
        """Start ``old``'s command (or ``cmd``) again under the same name, in ``old``'s place (it
        must have exited). Call from the thread that started the others: PR_SET_PDEATHSIG is
        tied to the thread that forks."""
        assert not old.alive, f"{old.name} is still running"
        child = Child(old.name, old.cmd if cmd is None else cmd, env=old.env, echo=self.echo)
        self.children[self.children.index(old)] = child
        return child

    def child(self, name: str) -> Child:
        """The child called ``name`` (StopIteration if none)."""
        return next(c for c in self.children if c.name == name)

    def first_exited(self) -> Child | None:
        """The first child that has exited, or None while all run."""
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
