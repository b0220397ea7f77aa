"""The whole autopilot as a step machine: bytes and times in, bytes out; no socket, no clock.

:class:`AutopilotCore` wires the rooms of the flight controller (the commander, guidance,
missions, parameters, failsafes, the estimator, telemetry, the flight log and the control cascade)
to the links, and runs them behind four entry points, each given the time by its caller:

* :meth:`~AutopilotCore.on_hil_datagram` ``(data, now) -> answer``: one lockstep frame from the
  simulator; runs exactly one control step and returns the ``HIL_ACTUATOR_CONTROLS`` datagram to
  send back at once (the simulator is waiting); :meth:`~AutopilotCore.on_hil_frame` the same for
  a frame's messages handed over unframed (the in-process runner);
* :meth:`~AutopilotCore.after_frame` ``() -> [Outgoing]``: that frame's bookkeeping (telemetry
  due on the simulation clock, STATUSTEXT, mission progress), deliberately after the answer;
* :meth:`~AutopilotCore.on_gcs_datagram` ``(link, address, data, now) -> [Outgoing]``: one datagram
  from a ground station on the GCS or API link;
* :meth:`~AutopilotCore.tick` ``(now) -> [Outgoing]``: wall-clock housekeeping (mission transfer
  retries, paced parameter lists, simulator loss, heartbeat and hello while no frames flow).

``now`` is the wall clock (monotonic seconds) of the process shell, or any clock the caller
chooses (the in-process runner passes simulation time): only rules that are about wall time use
it (COM_SIM_LOSS_T, mission transfer timeouts, parameter list pacing); everything a ground
station sees as time is the simulation time of the frames.

No exception raised while handling an input leaves the core: it is logged once per kind with
its traceback, counted (:meth:`~AutopilotCore.info`), announced by a rate-limited STATUSTEXT, and
the core goes on (:mod:`.mavlink.dispatch`).

The process shell (:mod:`autopilot.app`) owns the sockets, the selector and the pacing; the
in-process runner (:mod:`sitl.inprocess`) couples this core with the simulator's through the same
messages, unframed.

The rules live in the rooms, each given a narrow context (the commander, the parameters, the
clocks, the refusal and STATUSTEXT sinks it needs), never the core: the ground station's messages
in :mod:`.mavlink.handlers` and :mod:`.mavlink.vehicle_commands`, the lockstep link's rules in
:mod:`.mavlink.simulator_link`, what the vehicle flies on in :mod:`.estimator_switch`, the cascade
behind the commander in :mod:`.flight_control`, telemetry's status in :mod:`.mavlink.telemetry_feed`,
the frame's rows and flight log in :mod:`.logger.frame_records`. The core decides the order of a
frame's steps, what a simulator restart resets and what a parameter change reaches.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from quadcommon import wire
from quadcommon.config import SIM_BATTERY_PARAMETERS
from quadcommon.mavlink_fast import DecodeError, MessageParts
from quadcommon.wire_values import frame_time_s

from .battery.estimator import BatteryEstimator
from .commander.commander import Commander, VehicleState
from .control.cascade import Cascade
from .control.registry import ControllerFailure
from .estimation.loop import EstimatorLoop
from .estimator_switch import EstimatorSwitch
from .flight_control import MOTORS_OFF, FlightControl
from .logger import topics
from .logger.frame_records import FrameRecords, RecordContext
from .logger.logger import FlightLogger, log_info
from .logger.topics import Snapshot
from .mavlink import telemetry
from .mavlink.codec import Encoder, mavlink
from .mavlink.commands import CommandDispatcher, CommandRequest
from .mavlink.console import Console, ConsoleContext
from .mavlink.dispatch import FaultLog, MessageDispatcher
from .mavlink.failure_injection import FailureInjection
from .mavlink.ftp import FileSystem, FtpServer, NoFiles
from .mavlink.handlers import HandlerContext, MessageHandlers
from .mavlink.hil import (
    ActuatorEncoder,
    CorruptFrame,
    RefusedReport,
    battery_report,
    sensor_samples,
)
from .mavlink.links import API_LINK, GCS_LINK, HIL_LINK, Address, GcsLink, Outgoing
from .mavlink.log_transfer import LogStore, LogTransfer, NoLogs
from .mavlink.params import ParamService
from .mavlink.shell import MavlinkShell
from .mavlink.signing import Signing
from .mavlink.simulator_link import FrameOrder, SimulatorLink
from .mavlink.telemetry_feed import FeedContext, TelemetryFeed
from .mavlink.validation import RefusalNotices
from .mavlink.vehicle_commands import CommandContext, VehicleCommands
from .mavlink.vision_in import ExternalVision
from .mission.service import MissionService
from .params.definitions import (
    consistency_problems,
    controller_config_from_params,
    controller_params,
)
from .records import SensorSamples, StateEstimate
from .setup import AutopilotSetup, starting_parameters

m = mavlink
WALL_HEARTBEAT_S = 1.0  # HEARTBEAT + SYS_STATUS while no frames flow (wall)
# Log download (LOG_DATA / LOG_ENTRY) messages per ground station link: per control frame (4 at
# 500 Hz: 180 kB/s of simulation time, ~10 us of a frame's bookkeeping), and per housekeeping
# tick (wall) while no frames flow.
LOG_MESSAGES_PER_FRAME = 4
LOG_MESSAGES_PER_TICK = 100
# MAVLink FTP burst chunks (239 bytes each) per link, likewise: 1000 a second of simulation time.
FTP_MESSAGES_PER_FRAME = 2
FTP_MESSAGES_PER_TICK = 50
SHELL_MESSAGES_PER_FRAME = 1  # the console's output (SERIAL_CONTROL, 70 bytes each), likewise
SHELL_MESSAGES_PER_TICK = 25
NO_FRAMES_S = 0.1  # wall time without frames after which the housekeeping streams the download


class AutopilotCore:
    """One autopilot (module docstring): the rooms of ``setup`` wired to the GCS, API and HIL links."""

    def __init__(
        self,
        setup: AutopilotSetup,
        log: Callable[[str], None] = lambda text: None,
        log_store: LogStore | None = None,
        files: FileSystem | None = None,
    ) -> None:
        """``log``: where the process's text goes; ``log_store``: the flight logs on disk, for the
        MAVLink log download (the shell's :class:`~autopilot.logger.storage.LogDirectory`);
        ``files``: what MAVLink FTP serves (the shell's :class:`~autopilot.vehicle_files.VehicleFiles`;
        None: an empty root)."""
        self.setup = setup
        self.log = log
        sitl = setup.sitl
        self.system_id = wire.system_id(setup.instance)
        self.dt = 1.0 / sitl.rates.control_hz
        self.wrench = setup.vehicle.actuation.mode == "wrench"
        self.wall_now = 0.0  # the caller's clock at the latest entry point
        self.sim_time = 0.0
        self.frames = 0
        self._out: list[Outgoing] = []
        self._next_wall_heartbeat = 0.0
        self._controls = (0.0, 0.0, 0.0, 0.0)
        self._frame_done = None  # (frame, guidance, output) awaiting after_frame()
        self._statustext_id = 0
        self._frame_truth: StateEstimate | None = None  # the frame's truth (before the EKF's estimate)
        # The latest flight terminated because a law failed: (simulation time s, the failure). The
        # process flies on; an in-process experiment ends there (sitl.inprocess).
        self.controller_failure: tuple[float, ControllerFailure] | None = None

        self.params = starting_parameters(setup, log)  # ConfigError names the file and key
        self.commander = Commander(self.params)
        self.battery = BatteryEstimator(self.params)  # the one estimate of the flight battery
        gains = controller_config_from_params(setup.controller, self.params)
        self.cascade = Cascade(gains, setup.vehicle, self.dt)
        self.flight = FlightControl(self.cascade, setup.vehicle.actuation.thrust_max_n)
        self._gain_names = {spec.name for spec in controller_params(setup.controller)}
        self.flight_log = FlightLogger(
            self.params,
            log_info(setup.log.version, setup.controller.name, setup.vehicle.name, setup.estimator,
                     setup.instance),
            self.cascade.law_states,
            Snapshot(thrust_max_n=setup.vehicle.actuation.thrust_max_n,
                     torque_max_n_m=setup.vehicle.actuation.torque_max_n_m,
                     rotors=setup.vehicle.actuation.mode == "rotors", home_geodetic=sitl.home,
                     system_id=self.system_id, commander=self.commander),
            utc_clock=setup.log.utc_clock,
            enabled=setup.log.enabled,
        )  # fmt: skip
        self.params.on_change(self._on_param_change)
        self.records = FrameRecords(RecordContext(self.flight_log, self.commander, self.battery,
                                                  self._estimator_loop))  # fmt: skip
        self.encoder = Encoder(self.system_id, wire.AUTOPILOT_COMPONENT_ID)
        self.actuators = ActuatorEncoder(self.encoder, self.wrench)
        self._status = telemetry.VehicleStatus(self.system_id, home_geodetic=sitl.home, wrench=self.wrench)
        self.telemetry = TelemetryFeed(self._status, FeedContext(
            self.commander, self.params, self.battery, setup.vehicle.actuation.thrust_max_n,
            self._sim_time, self._on_ekf, self._latest_controls,
        ))  # fmt: skip
        self.simulator = SimulatorLink(self.encoder, self.system_id, sitl.home, setup.use_odometry)
        self.estimators = EstimatorSwitch(self.params, self.commander, self._status, self.dt,
                                          setup.vehicle.nominal.gravity_m_s2, log, self.on_foreign_datagram)

        ports = sitl.ports(setup.instance)
        remotes = (((wire.LOOPBACK, ports.gcs_remote), (wire.LOOPBACK, ports.api_remote))
                   if setup.default_remotes else (None, None))  # fmt: skip
        self.links = [GcsLink(link, remote, self._out, self.dt, self.encoder.mav.signing)
                      for link, remote in zip((GCS_LINK, API_LINK), remotes, strict=True)]  # fmt: skip
        self.faults = FaultLog(log, self._error_text)
        self.refusals = RefusalNotices(self.statustext, self._wall_time)
        self.dispatcher = MessageDispatcher(self.faults)
        self.dropped: dict[str, int] = {}  # datagrams the shell dropped before parsing, by reason
        self.commands = CommandDispatcher()
        clock = self._wall_time  # the services' wall clock is the caller's
        self.missions = MissionService(
            self.commander, self.encoder, self.links, self.statustext, sitl.home, self.system_id,
            wire.AUTOPILOT_COMPONENT_ID, clock,
        )  # fmt: skip
        self.missions.register(self.dispatcher, self.commands, self._sim_time)
        self.param_service = ParamService(
            self.params, self.encoder, self.links, self.statustext, self.system_id,
            wire.AUTOPILOT_COMPONENT_ID, setup.params_file,
            header=f"controller {setup.controller.name}, vehicle {setup.vehicle.name}", clock=clock,
            refusals=self.refusals,
        )  # fmt: skip
        self.param_service.register(self.dispatcher, self.commands)
        self.simulator_requests = self.simulator.requests  # in the next answer
        self.failure_injection = FailureInjection(
            self.params, self.simulator.request_failure, self._on_ekf, self.refusals,
            self.statustext,
        )  # fmt: skip
        self.vehicle_commands = VehicleCommands(CommandContext(
            self.commander, self._sim_time, self._read_status, self.params, self.refusals,
            self.failure_injection, setup.sitl.home, setup.build, self.system_id,
        ))  # fmt: skip
        self.vehicle_commands.register(self.commands)
        self.signing = Signing(setup.signing, self.encoder, self.links, self.statustext,
                               self._armed, self.system_id, log, setup.params_file,
                               setup.instance)  # fmt: skip
        self.signing.register(self.dispatcher)  # SETUP_SIGNING
        self.log_transfer = LogTransfer(log_store or NoLogs(), self.encoder, self.links, self.statustext,
                                        self._armed, self.system_id, clock)  # fmt: skip
        self.log_transfer.register(self.dispatcher)  # LOG_REQUEST_LIST, _DATA, _END, LOG_ERASE
        self.ftp = FtpServer(files or NoFiles(), self.encoder, self.links, self.system_id, clock)
        self.ftp.register(self.dispatcher)  # FILE_TRANSFER_PROTOCOL
        console = Console(ConsoleContext(
            self.params, self.param_service.set_value, self._console_command, self.records.topic_now,
            tuple(spec.name for spec in topics.TOPICS), self.info, self.commander, self._sim_time,
            setup.build,
        ))  # fmt: skip
        greeting = f"\nquadsitl {setup.build.version or '(version unknown)'}: 'help' lists the commands\n"
        self.shell = MavlinkShell(console, self.encoder, self.links, self.system_id, clock, greeting)
        self.shell.register(self.dispatcher)  # SERIAL_CONTROL (device SHELL)
        self.external_vision = ExternalVision()  # a client's vision (mocap bridge, VIO) for the EKF
        self.handlers = MessageHandlers(HandlerContext(
            self.system_id, self.commander, self._sim_time, self._wall_time, self.params,
            self.refusals, self.statustext, self.send_events, self.encoder.pack, self.log, setup.sitl.home,
            self._estimator_loop, self.commands, self.vehicle_commands, self.external_vision,
        ))  # fmt: skip
        self.handlers.register(self.dispatcher)

    # -- the rooms' views of the core: bound methods, never lambdas (a deep copy of the core rebinds
    # a bound method to the copy; a lambda's closure would go on reading the original).
    def _sim_time(self) -> float:
        return self.sim_time

    def _wall_time(self) -> float:
        return self.wall_now

    def _on_ekf(self) -> bool:
        return self.estimators.loop is not None

    def _estimator_loop(self) -> EstimatorLoop | None:
        return self.estimators.loop

    def _latest_controls(self) -> tuple[float, float, float, float]:
        return self._controls

    def _read_status(self) -> telemetry.VehicleStatus:
        return self.telemetry.status

    def _armed(self) -> bool:
        return self.commander.armed

    def _error_text(self, text: str) -> None:
        self.statustext(m.MAV_SEVERITY_ERROR, text)

    # -- entry points ---------------------------------------------------------------------------
    def on_hil_datagram(self, data: bytes, now: float) -> bytes | None:
        """One datagram on the HIL link: a lockstep frame is answered (its datagram), else None."""
        answer = self.on_hil_frame(MessageParts.of_datagram(data), now)
        return answer.datagram if answer is not None else None

    def on_hil_frame(self, parts: MessageParts, now: float) -> wire.LockstepAnswer | None:
        """The messages of one datagram on the HIL link (:meth:`on_hil_datagram`), or of a frame
        the in-process runner hands over unframed (``MessageParts.of_payloads``): a lockstep frame
        is answered (controls, and the requests to the simulator), else None."""
        self.wall_now = now
        try:
            return self._frame(parts, now)
        except Exception as exc:
            self.faults.record("HIL frame", exc, now)
            return None

    def after_frame(self) -> list[Outgoing]:
        """Telemetry, STATUSTEXT and mission progress of the frame just answered."""
        if self._frame_done is not None:
            try:
                self._bookkeeping(*self._frame_done)
            except Exception as exc:
                self.faults.record("frame bookkeeping", exc, self.wall_now)
            self._frame_done = None
        return self._take()

    def on_gcs_datagram(self, link: int, address: Address, data: bytes, now: float) -> list[Outgoing]:
        """One datagram from a ground station on link ``link`` (GCS_LINK or API_LINK)."""
        self.wall_now = now
        gcs = self.links[link]
        try:
            messages = gcs.receive(data, address, now)
        except Exception as exc:
            self.faults.record(f"{gcs.name} parser", exc, now)
            messages = []
        drops = self.failure_injection.drops
        for msg in messages:
            if not drops(msg):  # a link's injected failure (rc_signal, mavlink_signal)
                self.dispatcher.dispatch(msg, gcs, address, now)
        return self._take()

    def tick(self, now: float) -> list[Outgoing]:
        """Wall-clock housekeeping; call every ~50 ms of ``now``."""
        self.wall_now = now
        try:
            self._housekeeping(now)
        except Exception as exc:
            self.faults.record("housekeeping", exc, now)
        return self._take()

    def take_log(self) -> list:
        """The flight log written since the last call (FlightLogger.take): for the shell to write."""
        return self.flight_log.take()

    def take_controller_rows(self) -> list[tuple[float, ...]]:
        """The controller internals of every frame since the last call (CONTROLLER_FIELDS order)."""
        return self.records.take_controller_rows()

    def take_estimator_rows(self) -> list[tuple[float, ...]]:
        """The estimator rows of every frame since the last call (ESTIMATOR_FIELDS order)."""
        return self.records.take_estimator_rows()

    @property
    def controller_rows(self) -> list[tuple[float, ...]]:
        """The controller rows not taken yet (:mod:`.logger.frame_records`)."""
        return self.records.controller_rows

    @property
    def estimator_rows(self) -> list[tuple[float, ...]]:
        """The estimator rows not taken yet (on the EKF)."""
        return self.records.estimator_rows

    def info(self) -> dict:
        """What ``quadsitl/<N>/autopilot/info`` answers."""
        setup = self.setup
        return {
            "instance": setup.instance,
            "controller": setup.controller.name,
            "vehicle": setup.vehicle.name,
            "control_hz": setup.sitl.rates.control_hz,
            "sim_time_s": self.sim_time,
            "armed": self.commander.armed,
            "mode": self.commander.mode.px4_name,
            "faults": dict(self.faults.counts),
            "received": dict(self.dispatcher.received),
            "refused": dict(self.refusals.by_reason),
            "dropped": {
                **self.dropped,
                **{f"{link.name} oversize": link.oversize for link in self.links if link.oversize},
                **{f"{link.name} peers evicted": link.evicted for link in self.links if link.evicted},
            },
            "peers": {link.name: [f"{host}:{port}" for host, port in link.peers] for link in self.links},
            "signing": self.signing.info(),
            "vision": self.external_vision.info(),
            "flight_log": {"logging": self.flight_log.logging, "logs_started": self.flight_log.logs_started},
            "failures": self.failure_injection.info(),
            "ftp": self.ftp.info(),
        }

    def on_foreign_datagram(self, what: str) -> None:
        """Count a datagram the shell dropped before the core (``what`` names why)."""
        self.dropped[what] = self.dropped.get(what, 0) + 1

    def _take(self) -> list[Outgoing]:
        taken = self._out[:]
        self._out.clear()
        return taken

    # -- frames ---------------------------------------------------------------------------------
    def _frame(self, parts: MessageParts, now: float) -> wire.LockstepAnswer | None:
        link = self.simulator
        try:
            frame = link.decode(parts, sensors=self.estimators.loop is not None)
        except CorruptFrame:
            self.on_foreign_datagram("HIL frame with a bad checksum")
            return None  # the simulator resends a frame it gets no answer to
        if frame is None:
            return None  # a heartbeat from the simulator, or no state in it
        order = link.order(frame.time_usec, now)
        if order is FrameOrder.AGAIN:
            # The simulator resent a frame it got no answer to (or the link duplicated it): the same
            # answer again, byte for byte, without stepping twice.
            return link.last_answer
        if order is FrameOrder.LATE:
            self.on_foreign_datagram("HIL frame already answered (a late copy)")
            return None  # the simulator has moved on: nobody waits for this answer
        if order is FrameOrder.RESTARTED:
            self._simulator_restarted()
        p, v, e, w = frame.state
        total = p[0] + p[1] + p[2] + v[0] + v[1] + v[2] + e[0] + e[1] + e[2] + w[0] + w[1] + w[2]
        if not math.isfinite(total):
            # A broken simulator (or a forged frame): fly on the last good state for this frame.
            self.on_foreign_datagram("HIL frame with a non-finite state")
            if self.commander.state is None:
                controls = self.actuators.payload(frame.time_usec, (0.0, 0.0, 0.0, 0.0), False)
                return wire.LockstepAnswer(controls, b"", self.actuators.frame)
            c = self.commander.state
            frame = frame._replace(
                state=StateEstimate(c.position_m, c.velocity_m_s, c.euler_rad, c.euler_rates_rad_s)
            )
        became = link.arrived(frame.time_usec, now)
        if became is not None:
            self.log(f"linked with simulator (frames at t={frame.time_usec * 1e-6:.3f} s)")
            if became == "recovered":
                self.statustext(m.MAV_SEVERITY_INFO, "simulator link recovered")
        return self._control_step(frame)

    def _simulator_restarted(self) -> None:
        self.log("simulator time went backwards: simulator restarted; resetting")
        self.commander.disarm(self.sim_time, force=True)
        self.commander.home = None
        self.battery.reset()
        self.failure_injection.simulator_restarted()
        self.simulator.forward_parameters(self.params)  # a restarted simulator starts from its vehicle file
        self.simulator.restart()
        for link in self.links:  # stream deadlines were on the old run's clock
            link.streams.restart()
        self.external_vision.restart()  # so were the vision senders' stamps
        self.missions.restart_clock()
        self.commander.health.restart_clock()

    def _control_step(self, frame) -> wire.LockstepAnswer:
        self._frame_truth = frame.state
        t = frame_time_s(frame.time_usec)
        self.sim_time = t
        commander = self.commander
        # What the vehicle knows of its sensors (commander/health.py): every frame, on either
        # estimator. On the truth nothing else reads the samples: the frame says which streams
        # delivered, and the samples are decoded only when a health check wants their values.
        samples = frame.sensors
        if samples is None and frame.streams and commander.health.wants_samples(t, frame.streams):
            samples = self._sensor_samples(frame.parts)
        if samples is not None and samples.gps is not None:
            self._status.gps = samples.gps  # GPS_RAW_INT reports the receiver's last sample
        if self.estimators.wanted:
            est = self.estimators.estimate(t, frame, first_frame=self.frames == 0)
            frame = frame._replace(state=est)  # telemetry reports what the vehicle flies on
        else:
            est = frame.state
        loop = self.estimators.loop
        commander.on_ekf = loop is not None
        commander.estimator_status = loop.last_status if loop is not None else None
        if est is not None:
            commander.update_state(
                VehicleState(t, est.position_m, est.velocity_m_s, est.euler_rad, est.euler_rates_rad_s)
            )
        # After the state: a sensor's value that starts repeating is paired with this frame's pose.
        commander.observe_sensors(t, samples, frame.streams)
        self._battery_step(t, frame.parts)
        if self.frames == 0:
            self.simulator.forward_parameters(self.params)
            if self.setup.autostart is not None:
                commander.start_scenario(t, self.setup.autostart)
        self.frames += 1
        guidance = commander.step(t, self.dt)
        try:
            output, controls = self.flight.step(est, guidance)
        except ControllerFailure as failure:
            output, controls = None, self._controller_failed(t, failure)
        self._controls = controls
        self._frame_done = (frame, guidance, output)
        # The requests to the simulator ride in the answer.
        actuators = self.actuators
        controls_payload = actuators.payload(frame.time_usec, controls, commander.armed)
        return self.simulator.answer(controls_payload, actuators.frame)

    def _battery_step(self, t: float, parts: MessageParts | None) -> None:
        """The frame's battery report (if any) into the estimate, refused at the edge when it is no
        reading (counted); the estimate to the commander."""
        try:
            report = battery_report(parts) if parts is not None else None
        except RefusedReport as refused:
            self.on_foreign_datagram(f"HIL BATTERY_STATUS refused: {refused}")
        else:
            if report is not None:
                self.battery.update(t, report.voltage_v, report.current_a, self.commander.armed)
        self.commander.update_battery(self.battery.status, self.battery.unhealthy(t))

    def _sensor_samples(self, parts: MessageParts) -> SensorSamples | None:
        try:
            return sensor_samples(parts, self.setup.sitl.home)
        except DecodeError:  # (frame_of checked the messages already: not expected)
            return None

    def _controller_failed(self, t: float, failure: ControllerFailure) -> tuple[float, float, float, float]:
        """A law gave a non-finite output or raised: flight termination (motors off, disarmed), as
        PX4's failure detector terminates; the process flies on, the reason on every link."""
        self.statustext(m.MAV_SEVERITY_EMERGENCY, f"flight terminated: {failure}"[:200])
        self.log(f"flight terminated: {failure}")
        self.controller_failure = (t, failure)
        self.commander.disarm(t, force=True)
        self.flight.stop()
        return MOTORS_OFF

    def _bookkeeping(self, frame, guidance, output) -> None:
        t = self.sim_time
        fused = self.estimators.fuse()  # this frame's aiding, now that the answer is out
        if fused is not None:
            self.records.estimator_row(*fused)
        self.telemetry.frame_done(frame, guidance, output)  # brought into the status when it is read
        self.records.frame(t, frame, self._frame_truth, guidance, output, self._controls)
        self.telemetry.send_due(t, self.links, self.encoder.pack)
        self.missions.update(t)  # MISSION_CURRENT, MISSION_ITEM_REACHED
        self.send_events()
        self.log_transfer.pump(LOG_MESSAGES_PER_FRAME)
        self.ftp.pump(FTP_MESSAGES_PER_FRAME)
        self.shell.pump(SHELL_MESSAGES_PER_FRAME)

    @property
    def estimator(self) -> EstimatorLoop | None:
        """The EKF's loop while the vehicle flies on it (EKF2_EN 1), else None (the truth)."""
        return self.estimators.loop

    @property
    def status(self) -> telemetry.VehicleStatus:
        """What telemetry reports: the latest frame and the commander now (:mod:`.mavlink.telemetry_feed`)."""
        return self.telemetry.status

    # -- ground stations ------------------------------------------------------------------------
    def send_events(self) -> None:
        """The commander's queued events as STATUSTEXT."""
        if not self.commander.events:  # (every frame asks)
            return
        for severity, text in self.commander.drain_events():
            self.statustext(severity, text)

    def statustext(self, severity: int, text: str) -> None:
        """STATUSTEXT on every link (long texts in 50-byte chunks with one id, as MAVLink 2)."""
        self.log(f"[t={self.sim_time:8.3f}] {text}")
        self.flight_log.statustext(severity, text, self.sim_time)
        self._statustext_id = (self._statustext_id % 65535) + 1
        for msg in telemetry.statustext_messages(severity, text, self._statustext_id):
            data = self.encoder.pack(msg)
            for link in self.links:
                link.send(data)

    def run_command(self, request: CommandRequest) -> tuple[int, str]:
        """A MAV_CMD through the vehicle's one command path
        (:meth:`.mavlink.handlers.MessageHandlers.run_command`): (MAV_RESULT, reason)."""
        return self.handlers.run_command(request)

    def _console_command(self, command: int, params: tuple[float, ...]) -> tuple[int, str]:
        """The console's command (``commander arm``, ``failure gps off``...), as a COMMAND_LONG
        from the vehicle itself."""
        request = CommandRequest(command, params, None, self.system_id, wire.AUTOPILOT_COMPONENT_ID,
                                 None, None)  # fmt: skip
        outcome = self.run_command(request)
        self.send_events()
        return outcome

    def _on_param_change(self, name: str, value: float) -> None:
        """Gains take effect between two control steps (this runs between frames), no jump in
        the integral action (Cascade.retune)."""
        self.flight_log.parameter(name, value)
        if name in self._gain_names:
            try:
                self.cascade.retune(controller_config_from_params(self.setup.controller, self.params))
            except ValueError as exc:  # not reachable with the declared parameters; never crash
                self.statustext(m.MAV_SEVERITY_CRITICAL, f"retune failed: {exc}")
        self.estimators.parameter_changed(name)
        if name in SIM_BATTERY_PARAMETERS:  # PX4's battery simulator's: the simulator's own
            self.simulator.forward_parameter(name, value)
        if name.startswith(("GF_", "MIS_TAKEOFF_ALT", "RTL_RETURN_ALT", "MPC_", "BAT")):
            for problem in consistency_problems(self.params):
                text = f"parameters inconsistent (arming refused): {problem}"
                self.statustext(m.MAV_SEVERITY_WARNING, text)

    # -- wall-clock housekeeping ----------------------------------------------------------------
    def _housekeeping(self, now: float) -> None:
        for link in self.links:
            link.expire(now)
        self.missions.poll()  # mission transfer retries and timeouts run on the wall clock
        self.param_service.poll()  # paced PARAM_REQUEST_LIST streams
        self.signing.poll(now)  # wall clock -> timestamps, refusals announced, state saved
        sim = self.simulator
        if now - sim.last_frame_wall > NO_FRAMES_S:  # else each frame streams the downloads
            self.log_transfer.pump(LOG_MESSAGES_PER_TICK)
            self.ftp.pump(FTP_MESSAGES_PER_TICK)
            self.shell.pump(SHELL_MESSAGES_PER_TICK)
        sim_loss_s = self.params["COM_SIM_LOSS_T"]
        if not sim.silent(now, sim_loss_s):
            return
        if sim.lose():
            # The cascade keeps its state: in lockstep the plant has not moved either, so frames that
            # resume after a stall (a loaded machine) continue the same flight, as in-process. A
            # restarted simulator shows as time going backwards (_simulator_restarted: disarm).
            self.commander.simulator_lost()  # no position: arming refused until frames resume
            lost = f"simulator lost: no sensor frame for {sim_loss_s:g} s (COM_SIM_LOSS_T); motors off"
            self.statustext(m.MAV_SEVERITY_CRITICAL, lost)
        if now >= self._next_wall_heartbeat:  # no frames: ground stations still see the vehicle
            self._next_wall_heartbeat = now + WALL_HEARTBEAT_S
            heartbeat = self.encoder.pack(telemetry.heartbeat(self.status))
            sys_status = self.encoder.pack(telemetry.sys_status(self.status))
            for link in self.links:
                link.send(heartbeat)
                link.send(sys_status)
            self.missions.update(self.sim_time, force=True)
        if sim.hello_due(now):  # until frames flow: a (re)started simulator learns our address from it
            hello = self.encoder.pack_unsigned(telemetry.heartbeat(self.status))  # HIL: never signed
            self._out.append(Outgoing(HIL_LINK, None, hello))
