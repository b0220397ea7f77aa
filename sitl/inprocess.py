"""The whole flight stack in one process: the simulator's and the autopilot's cores in lockstep.

:class:`Lockstep` couples :class:`~simulator.core.SimulatorCore` and
:class:`~autopilot.core.AutopilotCore` through the messages they exchange over UDP in the SITL (real
MAVLink encoding and decoding, no sockets): per frame the simulator's messages go to the
autopilot, its answer back, the autopilot's output to the in-process ground stations, then the
plant steps. The messages cross unframed, as the payloads the other side reads of the datagram
(:class:`~quadcommon.mavlink_fast.MessageParts`, :class:`~quadcommon.wire.LockstepAnswer`): the
same bytes without the framing and the checksums, which only a link that can lose or damage them
needs (an impaired HIL link carries the datagrams). So the commander, missions, parameters,
failsafes and telemetry all run, in simulation time, deterministically; the SITL is the same two
cores with UDP in between, and their trajectories are identical.

The autopilot's wall clock (``now``: mission transfer timeouts, parameter list pacing, simulator
loss) is simulation time here: nothing waits on anything real.

With a log directory in the autopilot's setup (``AutopilotSetup.log``), the autopilot writes its
flight logs (ULog) there as the process does, without the writer thread, and serves them to the
ground stations' log download and MAVLink FTP (with the parameter file, as the process does:
:mod:`autopilot.vehicle_files`); :meth:`Lockstep.close` ends the open log.
The links can be impaired as the processes' are (``impair=``, ``RunOptions.impair``, the
simulator's ``[impair]``; :meth:`Lockstep.impair` while running): ground-station datagrams arrive
when their channel says, and over an impaired HIL link each frame is exchanged as the two processes
exchange it (resends after ``resend_after_s``, copies answered from the last answer, late ones
dropped), in stack time. A slow exchange holds the stack's clock up (as it holds up the SITL); the
flight itself is the same as without the impairment.

Ground stations act in simulation time: a :class:`GroundStation` receives what the autopilot
sends to it (parsed by pymavlink, as any client) and sends MAVLink messages, delivered before the
next frame. A ``script(gcs, t)`` callback runs once per frame; :meth:`Lockstep.run_until` stops on
a predicate or a time.

:func:`run_scenario` is the paper's experiment on it (armed at t = 0, flying the scenario's
trajectory: ``--autostart``), returning the time series as a FlightRecord. An experiment's stack
(:func:`paper_stack`, :func:`fly_mission_experiment`) ends where the autopilot terminates the flight
because a law failed (a non-finite output: the SITL's STATUSTEXT, flight termination):
:meth:`Lockstep.step` raises :class:`~autopilot.control.registry.ControllerFailure` with the
autopilot's reason, instead of flying on to indices of NaN.

(One module: the lockstep exchange, its impaired variant and the in-process ground stations are
one contract with the processes, the bytes they trade and the order of a frame's steps, read
together; the experiments on it are the few functions at the end.)
"""

from __future__ import annotations

import itertools
import json
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, replace

import numpy as np

from quadcommon import environment

environment.use_mavlink2()  # before pymavlink is imported (it reads them then)
from pymavlink.dialects.v20 import common as mavlink  # noqa: E402

from autopilot.commander.modes import FlightMode  # noqa: E402
from autopilot.control.config import ControllerConfig  # noqa: E402
from autopilot.control.registry import ControllerFailure  # noqa: E402
from autopilot.core import AutopilotCore, AutopilotSetup  # noqa: E402
from autopilot.logger.logger import LogOptions  # noqa: E402
from autopilot.logger.storage import LogDirectory, LogWriter  # noqa: E402
from autopilot.mavlink.links import API_LINK, GCS_LINK, HIL_LINK, Outgoing  # noqa: E402
from autopilot.vehicle_files import VehicleFiles  # noqa: E402
from gcs_scripts.analysis.record import FlightRecord  # noqa: E402
from quadcommon.bus_records import CONTROLLER_FIELDS, TRUTH_FIELDS  # noqa: E402
from quadcommon.config import (  # noqa: E402
    Rates,
    ScenarioConfig,
    VehicleConfig,
    estimator_profile_for,
    load_sitl,
    load_vehicle,
)
from quadcommon.impaired_udp import ImpairedLinks, ImpairedReceiver  # noqa: E402
from quadcommon.impairment import ImpairConfig, ImpairmentError  # noqa: E402
from quadcommon.trajectories import trajectory_from_spec  # noqa: E402
from quadcommon.wire import new_parser, parse_datagram  # noqa: E402
from simulator.core import SimulatorCore, SimulatorSetup, as_nominal  # noqa: E402
from simulator.environment.gust_profile import GustProfile, load_gust_profile  # noqa: E402
from simulator.sensors import SensorConfig, load_sensors  # noqa: E402

HOUSEKEEPING_S = 0.05  # the autopilot's tick, as its process runs it (here in simulation time)
_T = {name: i for i, name in enumerate(TRUTH_FIELDS)}
_C = {name: i for i, name in enumerate(CONTROLLER_FIELDS)}
_ports = itertools.count(20000)


class GroundStation:
    """A scripted ground station on one of the autopilot's links (GCS or API), in-process.

    ``mav`` builds and packs messages as pymavlink does (``gcs.mav.command_long_send(...)`` works:
    what it writes is delivered to the autopilot before the next frame); everything the autopilot
    sends to this station lands in :attr:`messages` (parsed), newest last, and in :attr:`last` by
    type. Time is the simulation time of the stack.
    """

    def __init__(self, stack: Lockstep, link: int, system_id: int = 255, component_id: int = 190) -> None:
        self.stack = stack
        self.link = link
        self.address = ("in-process", next(_ports))
        self.mav = mavlink.MAVLink(self, srcSystem=system_id, srcComponent=component_id)
        self.mav.robust_parsing = True
        self._parser = new_parser()
        self.messages: list = []  # everything received (keep=False: only the last of each type)
        self.keep = True
        self.inbox: deque = deque()  # not yet taken by recv_msg()
        self.last: dict[str, object] = {}
        self.statustext: list[str] = []

    def write(self, data: bytes) -> None:
        """pymavlink's file interface: ``mav.*_send`` lands here."""
        self.stack.deliver(self.link, self.address, bytes(data))

    def send_bytes(self, data: bytes) -> None:
        """Raw bytes (hostile input, hand-made frames) to the autopilot."""
        self.stack.deliver(self.link, self.address, data)

    def receive(self, data: bytes) -> None:
        """Parse a datagram from the autopilot; keep its messages, the last of each type, the STATUSTEXTs."""
        for msg in parse_datagram(self._parser, data):
            if self.keep:
                self.messages.append(msg)
            self.inbox.append(msg)
            kind = msg.get_type()
            self.last[kind] = msg
            if kind == "STATUSTEXT":
                self.statustext.append(msg.text)

    def of_type(self, kind: str) -> list:
        """The messages of type ``kind`` received so far (with ``keep``)."""
        return [m for m in self.messages if m.get_type() == kind]

    def heartbeat(self) -> None:
        """A ground station's HEARTBEAT (MAV_TYPE_GCS)."""
        self.mav.heartbeat_send(mavlink.MAV_TYPE_GCS, mavlink.MAV_AUTOPILOT_INVALID, 0, 0, 0)

    def command(self, command: int, *params: float, target: int | None = None) -> None:
        """Send COMMAND_LONG ``command`` with ``params`` (padded with zeros to 7) to the autopilot, or
        to system ``target``."""
        p = list(params) + [0.0] * (7 - len(params))
        self.mav.command_long_send(self.stack.autopilot.system_id if target is None else target, 1,
                                   command, 0, *p)  # fmt: skip

    def acks(self, command: int) -> list:
        """The COMMAND_ACKs received for ``command``."""
        return [a for a in self.of_type("COMMAND_ACK") if a.command == command]


class StackConnection:
    """What ``pymavlink.mavutil`` connections offer to a client (``mav``, ``recv_msg()``,
    ``close()``), on a Lockstep: the ground-station scripts' :class:`gcs_scripts.link.Link` runs
    on it unchanged, in simulation time. ``recv_msg()`` returns the next message the vehicle sent
    this station; when there is none it steps the stack one frame (time passes only while the
    client waits, as a client's time passes in the SITL) and returns what that frame brought, or
    None."""

    steps_time = True  # gcs_scripts.link.Link: polling advances the simulation, never sleep

    def __init__(self, stack: Lockstep, link: int = API_LINK) -> None:
        self.stack = stack
        self.station = stack.ground_station(link)
        self.station.keep = False
        self.mav = self.station.mav

    def recv_msg(self):
        """The next message for this station, stepping the stack once if none waits; None if still none."""
        inbox = self.station.inbox
        if not inbox:
            self.stack.step()
        return inbox.popleft() if inbox else None

    def close(self) -> None:
        """Detach this station from the stack."""
        self.stack.stations.pop(self.station.address, None)


class Lockstep:
    """The simulator core and the autopilot core in lockstep, with in-process ground stations."""

    def __init__(
        self,
        simulator: SimulatorSetup,
        autopilot: AutopilotSetup,
        log=lambda text: None,
        impair: ImpairConfig | None = None,
    ) -> None:
        self.sim = SimulatorCore(simulator, log)
        self.log_directory = LogDirectory(autopilot.log.directory) if autopilot.log.enabled else None
        self.log_writer = LogWriter(self.log_directory, threaded=False) if self.log_directory else None
        files = VehicleFiles.for_vehicle(self.log_directory, autopilot.params_file)  # MAVLink FTP's root
        self.autopilot = AutopilotCore(autopilot, log, log_store=self.log_directory, files=files)
        # The links' impairment (default: the simulator's sitl.toml [impair]), in stack time: one
        # channel per link and direction, as the two processes have at their sockets.
        impair = simulator.sitl.impair if impair is None else impair
        self.impaired = ImpairedLinks(impair, "in-process")
        self.channels: dict[tuple[int, str], ImpairedReceiver] = {
            (HIL_LINK, "sim->ap"): self.impaired.receiver("hil", "sim->ap"),
            (HIL_LINK, "ap->sim"): self.impaired.receiver("hil", "ap->sim"),
            (GCS_LINK, "in"): self.impaired.receiver("gcs", "in"),
            (GCS_LINK, "out"): self.impaired.receiver("gcs", "out"),
            (API_LINK, "in"): self.impaired.receiver("api", "in"),
            (API_LINK, "out"): self.impaired.receiver("api", "out"),
        }
        self.stations: dict[tuple[str, int], GroundStation] = {}
        self.observers: list[Callable[[Outgoing], None]] = []  # see every datagram the vehicle sends
        # Where a datagram for no in-process station goes (a fleet's sockets: sitl.fleet); None: nowhere.
        self.outbound: Callable[[Outgoing], None] | None = None
        self.truth_rows: list[tuple[float, ...]] = []
        self.controller_rows: list[tuple[float, ...]] = []
        self.estimator_rows: list[tuple[float, ...]] = []  # on the EKF: one per frame (ESTIMATOR_FIELDS)
        self.record_rows = True
        # With record_rows False: True leaves the autopilot's rows in its core for a bus to take (a
        # fleet's vehicle on zenoh), False drops them each frame.
        self.rows_taken_elsewhere = False
        self.answer_frames = True  # False: the autopilot sees no frame (it is gone: the simulator
        # flies its emergency descent)
        self.frames_flow = True  # False: the simulator is gone (no frames; the autopilot's clock runs)
        self.clock = 0.0  # the autopilot's wall clock: simulation time, unless the simulator pauses
        self._inbox: list[tuple[int, tuple[str, int], bytes]] = []
        self._hil_direct: dict[str, list[bytes]] = {"sim->ap": [], "ap->sim": []}  # unimpaired way
        self._next_tick = 0.0
        self.frames = 0
        # True: a flight the autopilot terminates because a law failed ends the run (step() raises
        # ControllerFailure); False: the autopilot flies on, as its process does.
        self.stop_on_controller_failure = False

    @property
    def t(self) -> float:
        """The stack's clock (s): the simulation time while frames flow."""
        return self.clock

    def ground_station(self, link: int = API_LINK, listen: bool = True, **ids) -> GroundStation:
        """A station on ``link``; ``listen``: it is where the link sends by default (as MAVSDK on
        14540 + N, QGC on 14550), so it receives telemetry before it has sent anything."""
        gcs = GroundStation(self, link, **ids)
        self.stations[gcs.address] = gcs
        if listen:
            self.autopilot.links[link].listen(gcs.address)
        return gcs

    def deliver(self, link: int, address: tuple[str, int], data: bytes) -> None:
        """Hand ``data`` from ``address`` to the autopilot's ``link``: now, or through the link's
        impairment channel when it has one (delayed, or lost)."""
        channel = self.channels[(link, "in")].channel
        if channel is None:
            self._inbox.append((link, address, data))
        else:  # arrives when the link says (or never)
            channel.send((link, address, data), self.clock)

    def impair(self, spec: str) -> None:
        """Change the links' impairment from now on: ``"api:loss=100%"``, ``"gcs:none"`` ... (as
        ``quadsitl impair``); ImpairmentError names a bad value."""
        ok, reply = self.impaired.change(spec.encode())
        if not ok:
            raise ImpairmentError(json.loads(reply)["error"])

    def _dispatch(self, out: list[Outgoing], now: float | None = None) -> None:
        for watch in self.observers:
            for record in out:
                watch(record)
        now = self.clock if now is None else now
        channels = self.channels
        for record in out:
            if record[0] == HIL_LINK:
                continue  # hellos to the simulator: it is linked already
            channel = channels[(record[0], "out")].channel
            if channel is None:
                self._to_station(record)
            else:
                channel.send(record, now)
                for held in channel.due(now):
                    self._to_station(held)

    def _to_station(self, record: Outgoing) -> None:
        address = record[1]
        station = self.stations.get(address) if address is not None else None
        if station is not None:
            station.receive(record[2])
        elif self.outbound is not None:
            self.outbound(record)

    def _ground_links_due(self, now: float) -> None:
        """Datagrams held by impaired ground-station links whose time has come, both ways."""
        channels, ap = self.channels, self.autopilot
        for link in (GCS_LINK, API_LINK):
            channel = channels[(link, "out")].channel
            if channel is not None:
                for held in channel.due(now):
                    self._to_station(held)
            channel = channels[(link, "in")].channel
            if channel is not None:
                for held_link, address, data in channel.due(now):
                    self._dispatch(ap.on_gcs_datagram(held_link, address, data, now))

    def step(self) -> None:
        """One frame: ground-station datagrams in, the frame, its answer, the plant steps."""
        sim, ap, t = self.sim, self.autopilot, self.clock
        if self._inbox:
            inbox, self._inbox = self._inbox, []
            for link, address, data in inbox:
                self._dispatch(ap.on_gcs_datagram(link, address, data, t))
        impaired = self.impaired.endpoints_active  # (the cores never change the stack's links)
        if impaired:
            self._ground_links_due(t)
        if t >= self._next_tick:
            self._next_tick = t + HOUSEKEEPING_S
            self._dispatch(ap.tick(t))
            if self.log_writer is not None:
                self.log_writer.handle(ap.take_log())
        self.clock = t + sim.dt_control
        if not self.frames_flow:
            return
        # The frame's messages cross unframed (the bytes the autopilot would read of the datagram,
        # without the framing and the checksums); framed when an impaired link carries them.
        parts = sim.begin_frame_parts()
        answer = None
        if not self.answer_frames:  # the link is cut: the simulator flies its emergency descent
            if not sim.emergency:
                sim.autopilot_lost()
        elif impaired and (self.channels[(HIL_LINK, "sim->ap")].channel
                           or self.channels[(HIL_LINK, "ap->sim")].channel):  # fmt: skip
            answer, done = self._impaired_exchange(sim.frame_datagram, t)
            self.clock = max(self.clock, done)  # a slow exchange holds the stack up, as in the SITL
        else:
            data = ap.on_hil_frame(parts, t)
            self._dispatch(ap.after_frame())
            if sim.emergency:
                if data is not None:
                    sim.answers_again(data.datagram)
            elif data is None or (answer := sim.answer_to_frame(data)) is None:
                raise RuntimeError(f"the autopilot did not answer frame t={t:.3f} s")
        if self.record_rows:
            self.truth_rows.append(sim.truth_row)
            self.controller_rows.extend(ap.take_controller_rows())
            self.estimator_rows.extend(ap.take_estimator_rows())
        elif not self.rows_taken_elsewhere:
            ap.controller_rows.clear()
            ap.estimator_rows.clear()
        sim.end_frame(answer)
        self.frames += 1
        if self.stop_on_controller_failure and ap.controller_failure is not None:
            self._controller_failed()

    def _controller_failed(self) -> None:
        t_failed, failure = self.autopilot.controller_failure
        raise ControllerFailure(f"flight terminated at t={t_failed:.3f} s: {failure}") from failure

    def _impaired_exchange(self, datagram: bytes, t: float):
        """The frame and its answer over the impaired HIL link, as the two processes exchange them
        (simulator/app.py), in stack time: the frame goes out, copies arrive when the channel says,
        the autopilot answers each (a copy of a frame answered already from that answer, a late
        one not at all), an unanswered frame is resent after ``sim.resend_after_s``, and after
        ``[lockstep] timeout_s`` without the answer the simulator flies its emergency descent.
        Returns (the answer or None, the time the exchange ended)."""
        sim, ap = self.sim, self.autopilot
        send, answer_back = self._hil_send, self._hil_answer
        now = t
        send("sim->ap", datagram, now)
        resend_at = now + sim.resend_after_s
        lost_at = now + sim.setup.sitl.lockstep_timeout_s
        while True:
            for data in self._hil_due("sim->ap", now):
                reply = ap.on_hil_datagram(data, now)
                self._dispatch(ap.after_frame(), now)
                if reply is not None:
                    send("ap->sim", reply, now)
            for data in self._hil_due("ap->sim", now):
                if sim.emergency:
                    if sim.answers_again(data):
                        return None, now
                elif (answer := answer_back(data)) is not None:
                    return answer, now
            if sim.emergency:
                return None, now  # one send per frame while lost (as the process does)
            if now >= lost_at:
                sim.autopilot_lost()
                return None, now
            if now >= resend_at:
                send("sim->ap", sim.resend_frame(), now)
                resend_at = now + sim.resend_after_s
            due = [c.channel.next_due() for c in self.channels.values() if c.channel is not None]
            now = min([d for d in due if d is not None] + [resend_at, lost_at])

    def _hil_send(self, direction: str, data: bytes, now: float) -> None:
        channel = self.channels[(HIL_LINK, direction)].channel
        if channel is None:
            self._hil_direct[direction].append(data)
        else:
            channel.send(data, now)

    def _hil_due(self, direction: str, now: float) -> list[bytes]:
        direct = self._hil_direct[direction]
        out = direct[:]
        direct.clear()
        return out + self.channels[(HIL_LINK, direction)].due(now)

    def _hil_answer(self, data: bytes):
        return self.sim.answer_to_frame(data)

    def final_frame(self) -> None:
        """The last frame of a run: sent, answered and recorded, not stepped (as the SITL's
        ``--duration``)."""
        sim, ap, t = self.sim, self.autopilot, self.clock
        ap.on_hil_frame(sim.begin_frame_parts(), t)
        self._dispatch(ap.after_frame())
        if self.record_rows:
            self.truth_rows.append(sim.truth_row)
            self.controller_rows.extend(ap.take_controller_rows())
            self.estimator_rows.extend(ap.take_estimator_rows())
        if self.stop_on_controller_failure and ap.controller_failure is not None:
            self._controller_failed()

    def close(self) -> list:
        """End the flight log that is open and write what is left; the logs written (paths)."""
        if self.log_writer is None:
            return []
        self.autopilot.flight_log.stop()
        self.log_writer.handle(self.autopilot.take_log())
        self.log_writer.close()
        self.log_directory.close()
        return list(self.log_writer.written)

    def run_until(
        self,
        t_end: float,
        until: Callable[[Lockstep], bool] | None = None,
        script: Callable[[Lockstep, float], None] | None = None,
    ) -> bool:
        """Step until simulation time ``t_end`` (True) or ``until(self)`` (False returned only if
        ``until`` never held); ``script(self, t)`` runs before every frame."""
        frames = round((t_end - self.clock) / self.sim.dt_control)
        for _ in range(max(frames, 0)):
            if script is not None:
                script(self, self.clock)
            self.step()
            if until is not None and until(self):
                return True
        return until is None

    def run_for(self, seconds: float, **kw) -> bool:
        """Run ``seconds`` of simulation time (:meth:`run_until`; same options and result)."""
        return self.run_until(self.clock + seconds, **kw)


@dataclass(frozen=True)
class RunOptions:
    nominal_plant: bool = False  # fly the Section II model instead of the coupled plant
    duration_s: float | None = None  # default: the scenario's
    rates: Rates | None = None  # default: config/sitl.toml
    gusts: GustProfile | None = None  # default: the scenario's profile
    sensors: str | None = None  # config/sensors/NAME.toml; None: the scenario's profile
    sensor_config: SensorConfig | None = None  # the sensors as given (a campaign run's), else ``sensors``
    estimator: str | None = None  # "truth" or "ekf" (the autopilot flies on its EKF); None: the scenario's
    true_plant: VehicleConfig | None = None  # a campaign's drawn plant (else the scenario's uncertainty)
    initial_velocity_m_s: tuple[float, float, float] = (0.0, 0.0, 0.0)
    log_dir: str | None = None  # the autopilot's flight logs (ULog) go there; None: no flight log
    impair: ImpairConfig | None = None  # the links' faults (default: sitl.toml's [impair])


def paper_stack(
    scenario: ScenarioConfig,
    controller: ControllerConfig,
    options: RunOptions = RunOptions(),
    vehicle: VehicleConfig | None = None,
) -> Lockstep:
    """The paper's experiment as a Lockstep: armed at t = 0, flying the scenario's trajectory."""
    vehicle = vehicle or load_vehicle(scenario.vehicle)
    sitl = load_sitl()
    if options.rates is not None:
        sitl = replace(sitl, rates=options.rates)
    if options.nominal_plant:
        vehicle = as_nominal(vehicle)
    gusts = options.gusts if options.gusts is not None else load_gust_profile(scenario.gusts)
    sensor_config = options.sensor_config or load_sensors(options.sensors or scenario.sensors)
    sim = SimulatorSetup(sitl, scenario, vehicle, sensor_config, gusts, nominal_plant=options.nominal_plant,
                         true_plant=options.true_plant,
                         initial_velocity_m_s=options.initial_velocity_m_s)  # fmt: skip
    sensors = options.sensors or scenario.sensors
    ap = AutopilotSetup(sitl, vehicle, controller, autostart=trajectory_from_spec(scenario.trajectory),
                        default_remotes=False, estimator=options.estimator or scenario.estimator,
                        estimator_profile=estimator_profile_for(sensors),
                        log=LogOptions(options.log_dir))  # fmt: skip
    stack = Lockstep(sim, ap, impair=options.impair)
    stack.stop_on_controller_failure = True
    return stack


def run_scenario(
    scenario: ScenarioConfig,
    controller: ControllerConfig,
    options: RunOptions = RunOptions(),
    vehicle: VehicleConfig | None = None,
    progress: Callable[[float], None] | None = None,
) -> FlightRecord:
    """Fly ``scenario`` with ``controller`` through the whole stack; the time series per frame.
    A flight terminated because a law failed raises ControllerFailure naming the scenario, the
    time and the controller."""
    stack = paper_stack(scenario, controller, options, vehicle)
    duration = options.duration_s if options.duration_s is not None else scenario.duration_s
    steps = int(round(duration / stack.sim.dt_control))
    report_every = max(steps // 20, 1)
    try:
        for k in range(steps):
            stack.step()
            if progress is not None and k % report_every == 0:
                progress(k / steps)
        stack.final_frame()
    except ControllerFailure as failure:
        raise ControllerFailure(f"{scenario.name}: {failure}") from failure
    if progress is not None:
        progress(1.0)
    return flight_record(stack, scenario.name, controller.name, nominal=options.nominal_plant)


def fly_mission_experiment(
    scenario: ScenarioConfig,
    controller: ControllerConfig,
    options: RunOptions = RunOptions(),
    start_time_s: float = 12.0,
    rate_hz: float = 20.0,
    margin_s: float = 1.0,
) -> tuple[FlightRecord, float, Lockstep]:
    """The paper's experiment as ``gcs_scripts/fly_paper.py`` flies it through the SITL, here on the
    in-process stack (commander, mission protocol, timed curve, MAVLink encoding and all): the
    scenario's trajectory uploaded as a timed mission by the upload script's own client (takeoff to
    p_d(0), the curve from ``start_time_s`` after the mission start, land), the scenario's gust
    profile anchored at the curve's t0, flown until disarmed. Returns the record over the curve
    (time 0 = t0, the scenario's duration), t0 and the stack."""
    import json

    from gcs_scripts import upload_mission

    sitl = load_sitl() if options.rates is None else replace(load_sitl(), rates=options.rates)
    vehicle = load_vehicle(scenario.vehicle)
    gusts = options.gusts if options.gusts is not None else load_gust_profile(scenario.gusts)
    sensor_profile = options.sensors or scenario.sensors
    sim = SimulatorSetup(sitl, scenario, vehicle, load_sensors(sensor_profile), GustProfile())
    ap = AutopilotSetup(sitl, vehicle, controller, default_remotes=False,
                        estimator=options.estimator or scenario.estimator,
                        estimator_profile=estimator_profile_for(sensor_profile))  # fmt: skip
    stack = Lockstep(sim, ap)
    stack.stop_on_controller_failure = True
    link = upload_mission.MissionLink(StackConnection(stack), 0)
    link.wait_heartbeat(5.0)
    trajectory = trajectory_from_spec(scenario.trajectory)
    duration = options.duration_s if options.duration_s is not None else scenario.duration_s
    height = trajectory.sample(0.0).position_m[2]
    items = upload_mission.curve_items(trajectory, duration + margin_s, rate_hz, start_time_s,
                                       takeoff_altitude_m=height, end="land")  # fmt: skip
    link.upload(items)
    link.arm()
    link.set_mode("AUTO.MISSION")
    auto_mission = float(FlightMode.AUTO_MISSION.custom_mode)
    rows = stack.controller_rows
    started = next(i for i, row in enumerate(rows) if row[-1] == auto_mission)
    t0 = rows[started - 1][0] + start_time_s  # the executor started on the clock of the frame before
    request = {"profile": _mapping(gusts), "start": {"at_s": t0}}
    ok, reply = stack.sim.upload_gusts(json.dumps(request).encode())
    if not ok:
        raise RuntimeError(f"gust profile refused: {reply.decode()}")
    upload_mission.fly(link, items, start_time_s + duration + 120.0)
    record = flight_record(stack, scenario.name, controller.name).window(t0, t0 + duration, shift=True)
    return record, t0, stack


def _mapping(profile: GustProfile) -> dict:
    from simulator.environment.gust_profile import profile_to_mapping

    return profile_to_mapping(profile)


def flight_record(stack: Lockstep, scenario: str, controller: str, nominal: bool = False) -> FlightRecord:
    """The rows a Lockstep recorded as a FlightRecord (truth joined with the controller's rows)."""
    truth = np.asarray(stack.truth_rows, dtype=float)
    ctrl = np.asarray(stack.controller_rows, dtype=float)
    if len(ctrl) != len(truth):
        raise RuntimeError(f"{len(truth)} truth rows but {len(ctrl)} controller rows")

    def cols(table, index, *names):
        return table[:, [index[n] for n in names]]

    return FlightRecord(
        label=controller,
        scenario=scenario,
        controller=controller,
        time_s=truth[:, _T["time_s"]],
        position_m=cols(truth, _T, "x_m", "y_m", "z_m"),
        position_ref_m=cols(ctrl, _C, "x_ref_m", "y_ref_m", "z_ref_m"),
        euler_rad=cols(truth, _T, "phi_rad", "theta_rad", "psi_rad"),
        euler_ref_rad=cols(ctrl, _C, "phi_ref_rad", "theta_ref_rad", "psi_ref_rad"),
        thrust_n=ctrl[:, _C["U1_n"]],
        torque_euler_n_m=cols(ctrl, _C, "tau_phi_n_m", "tau_theta_n_m", "tau_psi_n_m"),
        disturbance_force_n=cols(truth, _T, "Ax_n", "Ay_n", "Az_n"),
        disturbance_torque_n_m=cols(truth, _T, "Ap_n_m", "Aq_n_m", "Ar_n_m"),
        event_times_s=[stack.sim.schedule.start_time_s + e for e in stack.sim.schedule.profile.event_times()],
        source="in-process (nominal plant)" if nominal else "in-process",
        estimator=_estimator_table(stack.estimator_rows, len(truth)),
    )


def _estimator_table(rows: list[tuple[float, ...]], frames: int) -> np.ndarray | None:
    """The EKF's rows (ESTIMATOR_FIELDS columns), one per frame; None when flown on truth."""
    if not rows:
        return None
    table = np.asarray(rows, dtype=float)
    if len(table) != frames:
        raise RuntimeError(f"{frames} truth rows but {len(table)} estimator rows")
    return table


__all__ = [
    "GCS_LINK", "API_LINK", "GroundStation", "Lockstep", "RunOptions", "StackConnection", "paper_stack",
    "run_scenario",
]  # fmt: skip
