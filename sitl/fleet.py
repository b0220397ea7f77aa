"""A fleet in one process: K vehicles, each the in-process stack (:class:`~sitl.inprocess.Lockstep`:
the simulator's and the autopilot's cores, the very cores the two processes of ``quadsitl up``
run), each with its own MAVLink endpoints on loopback, numbered as PX4 numbers its instances, all
stepped frame by frame on one loop paced to the wall clock.

A vehicle of the fleet is instance N (system id N + 1): its ground-station link sends from
``18570 + N`` to 14550 (one QGroundControl or MAVProxy there sees the whole fleet), its API link
from ``14580 + N`` to ``14540 + N`` (MAVSDK's port; PX4's 14549 past N = 9), as ``quadsitl up``
(:func:`quadcommon.wire.ports`); every port is bound at start and a taken one is refused naming
the port and the instance. A vehicle's frames never leave the process: the lockstep between its
simulator and its autopilot is a function call (no HIL port), which is what makes a vehicle cheap
(one process of ~200 MB for the fleet instead of two per vehicle).

Per frame: one poll of every vehicle's sockets; what waits on a vehicle's sockets goes in (at
most :data:`~autopilot.app.GCS_DATAGRAMS_PER_FRAME` per link, as the autopilot process takes
them, so a flood on one vehicle's port cannot starve the others), then each vehicle's frame is
flown; whatever the autopilot sends on a ground-station link goes out on that link's socket. A
vehicle flies exactly as it flies alone in the in-process stack (``tests/sitl/test_fleet.py``):
the vehicles share nothing but the loop.

``--zenoh``: each vehicle serves its zenoh keys ``quadsitl/<N>/...`` as its two processes do (the
truth, the controller's and estimator's rows, ``info``, ``autopilot/info``, ``sim/gusts``,
``impair``), on one session per vehicle listening on its zenoh port (the processes' own bus
classes, :mod:`simulator.bus_link` and :mod:`autopilot.bus_link`, on a shared session); its
queries are answered every 50 ms of simulation time. ``--processes P`` flies the fleet in P
processes, one core each, a lost one restarted (:mod:`sitl.fleet_processes`).

Run: ``quadsitl fleet --count K [--instance N] [--speed S] [--scenario NAME] [--controller NAME]
[--zenoh] [--processes P]``; launches on several hosts meet through a zenoh router
(``quadsitl router``, :mod:`sitl.router`). ``--params params-{instance}.toml`` gives each vehicle
its parameter file, saved on every change and loaded again when the vehicle is restarted;
``--spacing M`` puts instance N's home N x M metres north of the configured one.
"""

from __future__ import annotations

import argparse
import resource
import selectors
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

from autopilot.app import GCS_DATAGRAMS_PER_FRAME, MAX_DATAGRAM
from autopilot.control.config import load_controller
from autopilot.logger.logger import LogOptions
from autopilot.mavlink.links import API_LINK, GCS_LINK, Outgoing
from autopilot.setup import AutopilotSetup
from quadcommon import wire
from quadcommon.bus import BusError
from quadcommon.config import MAX_SPACING_M, load_scenario
from quadcommon.schema import ConfigError
from quadcommon.trajectories import trajectory_from_spec
from quadcommon.udp import PortInUse, bind_udp
from simulator.core import SimulatorSetup
from simulator.pacing import Pacer, parse_speed

from .cli import speed_text
from .inprocess import HOUSEKEEPING_S, Lockstep, estimator_profile_for
from .supervise import stop_on_signals

LINKS = ((GCS_LINK, "GCS link"), (API_LINK, "API link"))
# Open files a vehicle holds at most: its two sockets, its flight log, its zenoh session's (6
# measured with --zenoh and --log-dir); the fleet asks the system for room for all of them.
FILES_PER_VEHICLE = 8
FILES_BESIDE_VEHICLES = 64  # the interpreter's own, the selector, the kernel caches' files


@dataclass(frozen=True)
class FleetOptions:
    """What every vehicle of the fleet is (the same for all; each has its own instance)."""

    scenario: str = "hover"
    controller: str = "intbs_nlhinf"
    vehicle: str | None = None
    sensors: str | None = None
    estimator: str = "truth"
    log_directory: str | None = None  # each vehicle's flight logs (ULog) under DIR/<instance>; None: none
    autostart: str | None = None  # a scenario whose trajectory each vehicle flies, armed at t = 0
    # Each vehicle's parameter file ({instance} in the path: its number), loaded at its start (and
    # at a restart) and saved on every PARAM_SET, as ``quadsitl up --params``; None: none.
    params: str | None = None
    # Instance N's home this far north of the configured home, times N (PX4's multi-vehicle SITL
    # spawns its instances 3 m apart): the vehicles stand apart on a ground station's map, each
    # flying its own local frame about its own home. 0: every vehicle at the configured home.
    spacing_m: float = 0.0


class FleetVehicle:
    """One vehicle: its stack and, once :meth:`open`, its two ground-station sockets."""

    def __init__(self, stack: Lockstep, instance: int) -> None:
        self.stack = stack
        self.instance = instance
        self.ports = stack.autopilot.setup.sitl.ports(instance)
        self.socks: dict[int, object] = {}
        stack.record_rows = False  # (a fleet flies for hours: nothing kept per frame)
        stack.outbound = self.send
        self.session = self.sim_bus = self.ap_bus = None  # zenoh, once open_bus

    def open(self) -> None:
        """Bind its ports; PortInUse names the port, the link and the instance."""
        own = {GCS_LINK: self.ports.gcs_local, API_LINK: self.ports.api_local}
        try:
            for link, what in LINKS:
                self.socks[link] = bind_udp(own[link], f"{what} of instance {self.instance}")
        except PortInUse:
            self.close()
            raise

    def send(self, record: Outgoing) -> None:
        """A datagram the autopilot sends on a ground-station link, out on its socket (nobody
        listening is normal for a GCS port: the send is dropped)."""
        link, address, data = record
        sock = self.socks.get(link)
        if sock is not None and address is not None:
            try:
                sock.sendto(data, address)
            except OSError:
                pass

    def take_datagrams(self, link: int) -> None:
        """What waits on the link's socket, into the stack (at most GCS_DATAGRAMS_PER_FRAME)."""
        sock, stack = self.socks[link], self.stack
        for _ in range(GCS_DATAGRAMS_PER_FRAME):
            try:
                data, address = sock.recvfrom(MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                continue  # ICMP unreachable from an earlier send: ignore
            stack.deliver(link, address, data)

    def open_bus(self, speed: float | None, log: Callable[[str], None]) -> None:
        """Its zenoh keys ``quadsitl/<N>/...`` as its two processes serve them (truth, controller
        and estimator rows, ``info``, ``autopilot/info``, ``sim/gusts``, ``impair``), on one
        session listening on its zenoh port (or joining the configured router); BusError names
        the port."""
        from autopilot.bus_link import AutopilotBus
        from quadcommon import bus
        from simulator.bus_link import SimulatorBus

        stack, port = self.stack, self.ports.zenoh
        self.session = bus.open_hub(port, stack.sim.setup.sitl.zenoh_router)
        self.sim_bus = SimulatorBus(stack.sim, stack.impaired, speed, log)
        self.sim_bus.open(port, self.session)
        self.ap_bus = AutopilotBus(stack.autopilot, stack.impaired, log)
        self.ap_bus.open(port, self.session)
        stack.rows_taken_elsewhere = True  # the autopilot's rows wait in its core for the bus

    def after_frame(self) -> None:
        """The frame's truth row out on zenoh (batched), when on the bus."""
        if self.sim_bus is not None:
            self.sim_bus.truth.append(self.stack.sim.truth_row)

    def housekeeping(self) -> None:
        """On the bus: the autopilot's rows out, the queries answered."""
        if self.sim_bus is not None:
            self.sim_bus.poll()
            self.ap_bus.poll()
            self.ap_bus.publish_rows()

    def close(self) -> list:
        """The sockets and the bus closed, the flight log ended; the logs written."""
        for sock in self.socks.values():
            sock.close()
        self.socks = {}
        if self.sim_bus is not None:
            self.ap_bus.publish_rows(force=True)
            self.sim_bus.close()
            self.ap_bus.close()
            self.session.close()
            self.sim_bus = self.ap_bus = self.session = None
        return self.stack.close()


def make_vehicle(
    instance: int, options: FleetOptions, log: Callable[[int, str], None] = lambda instance, text: None
) -> FleetVehicle:
    """Vehicle ``instance`` as ``quadsitl up --instance N`` would make its two processes' setups
    (ConfigError names a bad name); what it says goes to ``log(instance, text)``."""
    sim = SimulatorSetup.load(instance=instance, scenario=options.scenario, vehicle=options.vehicle,
                              sensors=options.sensors)  # fmt: skip
    if options.spacing_m:  # (the autopilot's setup takes its configuration from here)
        sim = replace(sim, sitl=sim.sitl.spaced(instance, options.spacing_m))
    profile = estimator_profile_for(options.sensors or "default") if options.estimator == "ekf" else "default"
    log_dir = None if options.log_directory is None else f"{options.log_directory}/{instance}"
    trajectory = None
    if options.autostart is not None:
        trajectory = trajectory_from_spec(load_scenario(options.autostart).trajectory)
    params_file = None if options.params is None else options.params.replace("{instance}", str(instance))
    ap = AutopilotSetup(sim.sitl, sim.vehicle, load_controller(options.controller), instance=instance,
                        autostart=trajectory, estimator=options.estimator, estimator_profile=profile,
                        log=LogOptions(log_dir), params_file=params_file)  # fmt: skip
    return FleetVehicle(Lockstep(sim, ap, log=lambda text: log(instance, text)), instance)


class Fleet:
    """K vehicles stepped together: :meth:`step` flies one frame of each.

    A vehicle whose frame fails (its plant diverged, a law failed past the autopilot's own
    handling) must not end the others' flights: it is reported through ``log`` and, when the fleet
    has a ``restart`` (instance -> a new vehicle), replaced by a new one on the ground on the same
    ports, as a lost process is restarted; else it is left out."""

    def __init__(
        self,
        vehicles: Sequence[FleetVehicle],
        log: Callable[[str], None] = lambda text: None,
        restart: Callable[[int], FleetVehicle] | None = None,
        zenoh: bool = False,
        speed: float | None = 1.0,
    ) -> None:
        if not vehicles:
            raise ValueError("a fleet needs at least one vehicle")
        self.vehicles = list(vehicles)
        self.dt = vehicles[0].stack.sim.dt_control
        self.frames = 0
        self.log = log
        self.restart = restart
        self.restarts: dict[int, int] = {}  # instance -> vehicles replaced
        self.opened = False  # the vehicles' ports bound (open)
        self.zenoh = zenoh  # each vehicle's keys, as its processes serve them
        self.speed = speed  # the pacing factor a vehicle's info reports on zenoh (None: max)
        self._housekeeping_every = max(1, round(HOUSEKEEPING_S / self.dt))
        # Every vehicle's sockets in one poll a frame (one system call for the fleet, not two
        # receive attempts per vehicle).
        self.selector = selectors.DefaultSelector()

    @property
    def t(self) -> float:
        """The fleet's simulation time (s)."""
        return self.frames * self.dt

    def open(self) -> None:
        """Bind every vehicle's ports, or none (PortInUse names the first taken)."""
        opened: list[FleetVehicle] = []
        try:
            for vehicle in self.vehicles:
                vehicle.open()
                opened.append(vehicle)
        except PortInUse:
            for vehicle in opened:
                vehicle.close()
            raise
        for vehicle in self.vehicles:
            self._watch(vehicle)
        if self.zenoh:
            for vehicle in self.vehicles:
                vehicle.open_bus(self.speed, self.log)
        self.opened = True

    def _watch(self, vehicle: FleetVehicle) -> None:
        for link, sock in vehicle.socks.items():
            self.selector.register(sock, selectors.EVENT_READ, (vehicle, link))

    def step(self) -> None:
        """One frame of every vehicle: its datagrams in, its frame, its answer, its plant."""
        if self.selector.get_map():
            for key, _ in self.selector.select(0):
                vehicle, link = key.data
                vehicle.take_datagrams(link)
        failed = []
        for vehicle in self.vehicles:
            try:
                vehicle.stack.step()
            except Exception as exc:  # one vehicle's failure is not the fleet's
                failed.append((vehicle, exc))
        for vehicle, exc in failed:
            self._replace(vehicle, exc)
        self.frames += 1
        if self.zenoh and self.opened:
            for vehicle in self.vehicles:
                vehicle.after_frame()
            if self.frames % self._housekeeping_every == 0:
                for vehicle in self.vehicles:
                    vehicle.housekeeping()

    def _replace(self, vehicle: FleetVehicle, exc: Exception) -> None:
        """``vehicle`` lost: out of the fleet, and a new one in its place when there is a restart."""
        n, why = vehicle.instance, f"{type(exc).__name__}: {exc}"
        for sock in vehicle.socks.values():
            self.selector.unregister(sock)
        try:
            vehicle.close()  # (its flight log ended, as far as it goes)
        except Exception as closing:
            self.log(f"vehicle {n}: closing it failed: {closing}")
        index = self.vehicles.index(vehicle)
        new = None
        if self.restart is not None:
            try:
                new = self.restart(n)
                if self.opened:
                    new.open()
                    self._watch(new)
                    if self.zenoh:
                        new.open_bus(self.speed, self.log)
            except Exception as again:
                self.log(f"vehicle {n}: restarting it failed: {again}")
                new = None
        if new is None:
            del self.vehicles[index]
            self.log(f"vehicle {n} lost ({why}); left out")
            return
        self.vehicles[index] = new
        self.restarts[n] = self.restarts.get(n, 0) + 1
        self.log(f"vehicle {n} lost ({why}); restarted on the ground")

    def close(self) -> list:
        """Every vehicle's sockets closed and flight log ended; the logs written."""
        written: list = []
        self.selector.close()
        for vehicle in self.vehicles:
            written += vehicle.close()
        return written


class VehicleLines:
    """What the vehicles say, as ``[N] text`` lines; at start the K vehicles of a fleet say the same
    things (their signing state, "linked with simulator"): until :meth:`flush`, one line per text
    with the instances that said it (``[0..99] linked with simulator ...``), then each line as it
    comes."""

    def __init__(self, out: Callable[[str], None]) -> None:
        self.out = out
        self._held: dict[str, list[int]] | None = {}  # text -> instances, in the order first said

    def say(self, instance: int, text: str) -> None:
        """Vehicle ``instance`` said ``text``: held until :meth:`flush`, then out as it comes."""
        if self._held is None:
            self.out(f"[{instance}] {text}")
        else:
            self._held.setdefault(text, []).append(instance)

    def flush(self) -> None:
        """The lines held, grouped; from now on each line as it comes."""
        held, self._held = self._held or {}, None
        for text, instances in held.items():
            self.out(f"[{wire.instance_ranges(instances)}] {text}")


def room_for_files(count: int) -> int:
    """Raise this process's soft limit on open files to what ``count`` vehicles need, as far as the
    hard limit allows (a desktop's default soft limit, 1024, holds ~120 vehicles); the limit now."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    wanted = FILES_BESIDE_VEHICLES + FILES_PER_VEHICLE * count
    if soft != resource.RLIM_INFINITY and soft < wanted:
        soft = wanted if hard == resource.RLIM_INFINITY else min(wanted, hard)
        resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))
    return soft


def run(fleet: Fleet, speed: float | None, duration_s: float | None, log: Callable[[str], None],
        running: Callable[[], bool], started: Callable[[], None] = lambda: None) -> None:  # fmt: skip
    """Fly ``fleet`` at ``speed`` times real time (None: as fast as it goes) until ``running()`` is
    false or ``duration_s`` of simulation time has flown; ``started()`` after the first frame."""
    pacer = Pacer(speed, log, running)
    first = True
    while running() and (duration_s is None or fleet.t < duration_s):
        fleet.step()
        if first:
            started()
            first = False
        pacer.pace(fleet.t)


def main(argv: Sequence[str] | None = None) -> int:
    """``quadsitl fleet``: the fleet's vehicles until Ctrl-C (or ``--duration``)."""
    parser = argparse.ArgumentParser(prog="quadsitl fleet", description=__doc__.split("\n\n")[0],
                                     formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    parser.add_argument("--count", type=int, default=2, help="vehicles (default 2)")
    parser.add_argument("--instance", type=int, default=0, help="the first vehicle's instance N (default 0)")
    parser.add_argument("--speed", default="1", type=speed_text, help="times real time, or 'max' (default 1)")
    parser.add_argument("--duration", type=float, default=None, help="simulated seconds, then exit")
    parser.add_argument("--scenario", default="hover")
    parser.add_argument("--controller", default="intbs_nlhinf")
    parser.add_argument("--vehicle", default=None)
    parser.add_argument("--estimator", choices=("truth", "ekf"), default="truth")
    parser.add_argument("--sensors", default=None, help="sensor profile (the EKF's parameters follow it)")
    parser.add_argument("--autostart", default=None, metavar="SCENARIO",
                        help="every vehicle armed at t = 0, flying the scenario's trajectory")
    parser.add_argument("--log-dir", default=None, help="each vehicle's flight logs (ULog) under DIR/<N>")
    parser.add_argument("--params", default=None, metavar="FILE",
                        help="each vehicle's parameters: loaded at its start and restart, saved on every "
                        "change; with --count > 1 put {instance} in the path, e.g. params-{instance}.toml")
    parser.add_argument("--spacing", type=float, default=0.0, metavar="M",
                        help="instance N's home N x M metres north of the configured one (PX4's "
                        "multi-vehicle SITL: 3), so a ground station's map shows the vehicles apart; 0: all "
                        "at home")
    parser.add_argument("--processes", type=int, default=1,
                        help="fly the fleet in P processes (one core each), a lost one restarted")
    parser.add_argument("--zenoh", action="store_true",
                        help="each vehicle's zenoh keys (truth, rows, info, gusts, impair) on its zenoh port")
    parser.add_argument("--no-restart", action="store_true",
                        help="with --processes: a lost process stays down")
    args = parser.parse_args(argv)
    first, last = args.instance, args.instance + args.count - 1
    if args.count < 1 or not wire.INSTANCE_MIN <= first <= last <= wire.INSTANCE_MAX:
        parser.error(f"--instance {first} --count {args.count}: instances must be in "
                     f"[{wire.INSTANCE_MIN}, {wire.INSTANCE_MAX}] (got {first}..{last})")  # fmt: skip
    speed = parse_speed(args.speed)  # (checked by its type)

    if args.processes < 1:
        parser.error(f"--processes {args.processes}: at least 1")
    if not 0.0 <= args.spacing <= MAX_SPACING_M:
        parser.error(f"--spacing {args.spacing}: metres between homes, in [0, {MAX_SPACING_M:g}]")
    if args.params is not None and args.count > 1 and "{instance}" not in args.params:
        parser.error(f"--params {args.params}: with --count {args.count} the path must contain {{instance}} "
                     "(each vehicle saves its own parameters), e.g. params-{instance}.toml")  # fmt: skip
    options = FleetOptions(args.scenario, args.controller, args.vehicle, args.sensors, args.estimator,
                           args.log_dir, args.autostart, args.params, args.spacing)  # fmt: skip
    if args.processes > 1:
        try:  # a bad name fails here, naming file and key, before any process starts
            make_vehicle(first, options).close()
        except ConfigError as exc:
            print(f"quadsitl fleet: {exc}", file=sys.stderr)
            return 2
        from .fleet_processes import supervise
        from .supervise import RestartPolicy

        passed = ["--speed", args.speed, "--scenario", args.scenario, "--controller", args.controller,
                  "--estimator", args.estimator, *(["--zenoh"] if args.zenoh else [])]  # fmt: skip
        for flag, value in (("--duration", args.duration), ("--vehicle", args.vehicle),
                            ("--sensors", args.sensors), ("--log-dir", args.log_dir),
                            ("--params", args.params), ("--spacing", args.spacing or None)):  # fmt: skip
            if value is not None:
                passed += [flag, str(value)]
        autostart = ["--autostart", args.autostart] if args.autostart else []
        return supervise(first, args.count, args.processes, passed, autostart,
                         RestartPolicy(enabled=not args.no_restart))  # fmt: skip

    def log(text: str) -> None:
        print(f"fleet: {text}", flush=True)

    started = time.monotonic()
    lines = VehicleLines(log)
    files = room_for_files(args.count)
    try:
        on_ground = replace(options, autostart=None)  # a restarted vehicle does not take off by itself
        fleet = Fleet([make_vehicle(n, options, lines.say) for n in range(first, last + 1)], log,
                      restart=lambda n: make_vehicle(n, on_ground, lines.say),
                      zenoh=args.zenoh, speed=speed)  # fmt: skip
        fleet.open()
    except (ConfigError, PortInUse, BusError) as exc:
        lines.flush()
        print(f"quadsitl fleet: {exc}", file=sys.stderr)
        return 2
    except OSError as exc:  # out of open files (EMFILE), most likely: say what would help
        lines.flush()
        print(f"quadsitl fleet: {exc} (open files allowed: {files}; a vehicle needs up to "
              f"{FILES_PER_VEHICLE}: raise `ulimit -n`, or split the fleet with --processes)",
              file=sys.stderr)  # fmt: skip
        return 2
    stop = stop_on_signals()
    p0 = fleet.vehicles[0].ports
    log(f"{args.count} vehicles, instances {first}..{last} (system ids {first + 1}..{last + 1}), "
        f"ready in {time.monotonic() - started:.1f} s; GCS links udp {wire.LOOPBACK}:{p0.gcs_local}.. "
        f"-> {p0.gcs_remote}, API links {p0.api_local}.. -> {p0.api_remote}..")  # fmt: skip
    try:
        run(fleet, speed, args.duration, log, lambda: not stop.is_set(), started=lines.flush)
    finally:
        lines.flush()  # (stopped before the first frame)
        for path in fleet.close():
            log(f"flight log {path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

