"""The autopilot process: the thin shell around the commander and the control cascade.

One thread, one loop. ``select`` waits on the HIL socket and the two GCS sockets; each lockstep
frame from the simulator runs exactly one control step, answered at once with
HIL_ACTUATOR_CONTROLS; telemetry, controller internals (zenoh) and STATUSTEXT follow. Ground
station messages are handled between frames, stamped with the simulation time of the latest
frame. Without frames (simulator not started or lost) HEARTBEAT and SYS_STATUS still go out on
the wall clock so ground stations see the vehicle.

Run: ``python -m autopilot --instance N --controller NAME --vehicle NAME``.
"""

from __future__ import annotations

import json
import math
import selectors
import signal
import socket
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from quadcommon import bus, wire
from quadcommon.bus_records import CONTROLLER_CODEC
from quadcommon.config import (
    ControllerConfig,
    SitlConfig,
    VehicleConfig,
    load_controller,
    load_scenario,
    load_sitl,
    load_vehicle,
)

from .commander.commander import Commander, Motors, VehicleState
from .commander.modes import FlightMode
from .control.cascade import Cascade
from .guidance.trajectories import trajectory_from_spec
from .mavlink import telemetry
from .mavlink.codec import Encoder, mavlink, new_parser
from .mavlink.commands import CommandDispatcher, CommandRequest, command_ack, request_from_message
from .mavlink.hil import ActuatorEncoder, decode_frame
from .mavlink.links import GcsLink, PortInUse
from .mavlink.offboard import decode_setpoint
from .mavlink.params import ParamService
from .mission.service import MissionService
from .params.definitions import (
    consistency_problems,
    controller_config_from_params,
    default_parameters,
    is_controller_param,
)
from .params.storage import load_params_file

m = mavlink
FORCE_MAGIC = 21196  # param2 of ARM_DISARM that forces arming/disarming (as PX4)
CONTROLLER_BATCH = 10
SPIN_BELOW_GAP_S = 0.001  # frames closer than this (wall): spin-wait for the next one


@dataclass(frozen=True)
class AutopilotOptions:
    instance: int = 0
    controller: str = "intbs_nlhinf"
    vehicle: str = "paper_quad"
    sitl_config: str | None = None
    autostart: str | None = None  # scenario name: arm and fly its trajectory from t = 0
    state_source: str = "odometry"  # or "hil_state_quaternion"
    zenoh: bool = True
    quiet: bool = False
    params_file: str | None = None  # params.toml: loaded at start, saved on every change


class Autopilot:
    def __init__(self, options: AutopilotOptions) -> None:
        self.options = options
        self.instance = options.instance
        self.sitl: SitlConfig = load_sitl(options.sitl_config)
        self.vehicle: VehicleConfig = load_vehicle(options.vehicle)
        self.controller_config: ControllerConfig = load_controller(options.controller)
        self.ports = wire.ports(
            options.instance,
            self.sitl.hil_port_base,
            self.sitl.gcs_port_base,
            self.sitl.api_port_base,
            self.sitl.zenoh_port_base,
        )
        self.system_id = wire.system_id(options.instance)
        self.dt = 1.0 / self.sitl.rates.control_hz
        self.wrench = self.vehicle.actuation.mode == "wrench"
        self.params = default_parameters(self.controller_config, self.sitl.rates)
        self.params.values["MAV_SYS_ID"] = float(self.system_id)
        if options.params_file and Path(options.params_file).exists():
            loaded = load_params_file(options.params_file, self.params)  # ConfigError names file, key
            self.log(f"{len(loaded)} parameters loaded from {options.params_file}")
        for problem in consistency_problems(self.params):
            self.log(f"warning: parameters inconsistent (arming refused until fixed): {problem}")
        self.commander = Commander(self.params)
        self.cascade = Cascade(
            controller_config_from_params(self.controller_config, self.params), self.vehicle, self.dt
        )
        self.params.on_change(self._on_param_change)
        self.encoder = Encoder(self.system_id, wire.AUTOPILOT_COMPONENT_ID)
        self.actuators = ActuatorEncoder(self.encoder, self.wrench)
        self.status = telemetry.VehicleStatus(
            self.system_id, home_geodetic=self.sitl.home, wrench=self.wrench
        )
        self.commands = CommandDispatcher()
        self.message_handlers: dict[int, Callable] = {}
        self._register_handlers()
        self.missions = MissionService(
            self.commander,
            self.encoder,
            lambda: self.links,
            self._statustext,
            self.sitl.home,
            self.system_id,
            wire.AUTOPILOT_COMPONENT_ID,
        )
        self.missions.register(self.message_handlers, self.commands, lambda: self.sim_time)
        self.param_service = ParamService(
            self.params,
            self.encoder,
            lambda: self.links,
            self._statustext,
            self.system_id,
            wire.AUTOPILOT_COMPONENT_ID,
            options.params_file,
            header=f"controller {self.controller_config.name}, vehicle {self.vehicle.name}",
        )
        self.param_service.register(self.message_handlers, self.commands)
        self.autostart_trajectory = None
        if options.autostart:
            self.autostart_trajectory = trajectory_from_spec(load_scenario(options.autostart).trajectory)

        # sockets
        self.links: list[GcsLink] = []
        self.hil_sock: socket.socket | None = None
        self.selector = selectors.DefaultSelector()
        self.hil_parser = new_parser()
        self.hil_address = (wire.LOOPBACK, self.ports.hil)
        self.linked = False
        self.sim_lost = False
        self.last_frame_wall = 0.0
        self._frame_gap_s = 1.0  # wall time between the last two frames
        self._next_wall_heartbeat = 0.0
        self._next_hil_hello = 0.0
        # A message a command asked for, sent right after its COMMAND_ACK (as PX4 does).
        self._pending_after_ack: tuple | None = None
        self.sim_time = 0.0
        self.last_time_usec = -1
        self.frames = 0
        self._flying = False
        self._controls = (0.0, 0.0, 0.0, 0.0)
        self._controller_rows: list[tuple[float, ...]] = []
        self._running = True
        self.session = None
        self.controller_pub = None
        self.info_queryable = None
        self._statustext_id = 0

    # -- setup -----------------------------------------------------------------------------------
    def open(self) -> None:
        ports = self.ports
        self.links = [
            GcsLink("GCS", ports.gcs_local, ports.gcs_remote),
            GcsLink("API", ports.api_local, ports.api_remote),
        ]
        self.hil_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.hil_sock.bind((wire.LOOPBACK, 0))
        self.hil_sock.setblocking(False)
        self.selector.register(self.hil_sock, selectors.EVENT_READ, "hil")
        for link in self.links:
            self.selector.register(link.sock, selectors.EVENT_READ, link)
        if self.options.zenoh:
            self.session = bus.open_peer(ports.zenoh, self.sitl.zenoh_router)
            self.controller_pub = self.session.declare_publisher(wire.zenoh_key(self.instance, "controller"))
            import zenoh

            self.info_queryable = self.session.declare_queryable(
                wire.zenoh_key(self.instance, "autopilot/info"), zenoh.handlers.FifoChannel(16)
            )

    def close(self) -> None:
        self._flush_controller_rows()
        for link in self.links:
            link.close()
        if self.hil_sock is not None:
            self.hil_sock.close()
        if self.session is not None:
            self.session.close()

    def log(self, text: str) -> None:
        if not self.options.quiet:
            print(f"autopilot: {text}", flush=True)

    # -- handlers ----------------------------------------------------------------------------------
    def _register_handlers(self) -> None:
        c = self.commands
        c.register(m.MAV_CMD_COMPONENT_ARM_DISARM, self._cmd_arm_disarm)
        c.register(m.MAV_CMD_NAV_TAKEOFF, self._cmd_takeoff)
        c.register(m.MAV_CMD_NAV_LAND, lambda r: self.commander.land(self.sim_time))
        c.register(m.MAV_CMD_NAV_RETURN_TO_LAUNCH, lambda r: self.commander.return_to_launch(self.sim_time))
        c.register(m.MAV_CMD_DO_SET_MODE, self._cmd_set_mode)
        c.register(m.MAV_CMD_SET_MESSAGE_INTERVAL, self._cmd_message_interval)
        c.register(m.MAV_CMD_REQUEST_MESSAGE, self._cmd_request_message)
        c.register(m.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, self._cmd_capabilities)
        c.register(
            m.MAV_CMD_GET_HOME_POSITION, lambda r: self._send_requested(r, m.MAVLINK_MSG_ID_HOME_POSITION)
        )
        h = self.message_handlers
        h[m.MAVLINK_MSG_ID_COMMAND_LONG] = self._on_command
        h[m.MAVLINK_MSG_ID_COMMAND_INT] = self._on_command
        h[m.MAVLINK_MSG_ID_SET_POSITION_TARGET_LOCAL_NED] = self._on_setpoint
        h[m.MAVLINK_MSG_ID_SET_MODE] = self._on_set_mode_message
        h[m.MAVLINK_MSG_ID_HEARTBEAT] = self._on_gcs_heartbeat
        h[m.MAVLINK_MSG_ID_TIMESYNC] = self._on_timesync

    def _cmd_arm_disarm(self, r: CommandRequest) -> tuple[int, str]:
        # MAVSDK sends param2 = NaN ("unset") with a plain arm; only 21196 means force.
        force = r.params[1] == FORCE_MAGIC
        if r.params[0] >= 0.5:
            return self.commander.arm(self.sim_time, force)
        return self.commander.disarm(self.sim_time, force)

    def _cmd_takeoff(self, r: CommandRequest) -> tuple[int, str]:
        """param7 is the altitude AMSL (PX4); NaN means MIS_TAKEOFF_ALT above home.

        A value that would lie underground as AMSL (below the home altitude minus 10 m) is read as
        a height above home instead: that is what ArduPilot-style clients (MAVProxy's ``takeoff
        5``) send.
        """
        altitude = r.params[6]
        if not math.isfinite(altitude) or altitude == 0.0:
            return self.commander.takeoff(self.sim_time, None)
        home_z = self.commander.home[2] if self.commander.home else 0.0
        home_amsl = self.sitl.home[2] + home_z
        if altitude >= home_amsl - 10.0:
            return self.commander.takeoff(self.sim_time, altitude - home_amsl)
        return self.commander.takeoff(self.sim_time, altitude)

    def _cmd_set_mode(self, r: CommandRequest) -> tuple[int, str]:
        base_mode = int(r.params[0])
        if not base_mode & m.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return (
                m.MAV_RESULT_DENIED,
                "DO_SET_MODE needs MAV_MODE_FLAG_CUSTOM_MODE_ENABLED (PX4 modes)",
            )
        mode = FlightMode.from_px4(int(r.params[1]), int(r.params[2]))
        if mode is None:
            return (
                m.MAV_RESULT_DENIED,
                f"mode main={int(r.params[1])} sub={int(r.params[2])} not available",
            )
        return self.commander.set_mode(self.sim_time, mode)

    def _cmd_message_interval(self, r: CommandRequest) -> tuple[int, str]:
        ok = r.link.streams.set_interval_us(int(r.params[0]), r.params[1], self.sim_time)
        return (
            (m.MAV_RESULT_ACCEPTED, "")
            if ok
            else (m.MAV_RESULT_DENIED, f"no stream for message {int(r.params[0])}")
        )

    def _cmd_request_message(self, r: CommandRequest) -> tuple[int, str]:
        return self._send_requested(r, int(r.params[0]))

    def _cmd_capabilities(self, r: CommandRequest) -> tuple[int, str]:
        return self._send_requested(r, m.MAVLINK_MSG_ID_AUTOPILOT_VERSION)

    def _send_requested(self, r: CommandRequest, msg_id: int) -> tuple[int, str]:
        if msg_id == m.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            msg = self._autopilot_version()
        else:
            msg = telemetry.build(msg_id, self.status)
        if msg is None:
            return m.MAV_RESULT_UNSUPPORTED, f"message {msg_id} cannot be sent"
        # Answer after the ACK (PX4 does the same): queued on the link now, sent next.
        self._pending_after_ack = (r.link, r.address, self.encoder.pack(msg))
        return m.MAV_RESULT_ACCEPTED, ""

    def _autopilot_version(self):
        caps = (
            m.MAV_PROTOCOL_CAPABILITY_MISSION_FLOAT
            | m.MAV_PROTOCOL_CAPABILITY_PARAM_FLOAT
            | m.MAV_PROTOCOL_CAPABILITY_MISSION_INT
            | m.MAV_PROTOCOL_CAPABILITY_COMMAND_INT
            | m.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
            | m.MAV_PROTOCOL_CAPABILITY_SET_POSITION_TARGET_LOCAL_NED
            | m.MAV_PROTOCOL_CAPABILITY_MAVLINK2
        )
        version = 0x01000000 | 0xFF  # 1.0.0 release
        uid = 0x5153000000000000 | self.system_id
        return m.MAVLink_autopilot_version_message(
            caps, version, version, 0, 0, [0] * 8, [0] * 8, [0] * 8, 0, 0, uid, [0] * 18
        )

    def _on_command(self, msg, link: GcsLink, address) -> None:
        if msg.target_system not in (0, self.system_id) or msg.target_component not in (
            0,
            wire.AUTOPILOT_COMPONENT_ID,
        ):
            return
        request = request_from_message(msg, link, address)
        self._pending_after_ack = None
        result, reason = self.commands.dispatch(request)
        if reason and result != m.MAV_RESULT_ACCEPTED:
            self.log(f"command {request.command} -> result {result}: {reason}")
        link.send_to(self.encoder.pack(command_ack(request, result)), address)
        if self._pending_after_ack is not None:
            plink, paddress, data = self._pending_after_ack
            plink.send_to(data, paddress)
            self._pending_after_ack = None
        self._send_events()

    def _on_set_mode_message(self, msg, link, address) -> None:
        if msg.target_system not in (0, self.system_id):
            return
        mode = FlightMode.from_custom_mode(msg.custom_mode)
        if mode is not None:
            self.commander.set_mode(self.sim_time, mode)
            self._send_events()

    def _on_setpoint(self, msg, link, address) -> None:
        if msg.target_system not in (0, self.system_id):
            return
        state = self.commander.state
        if state is None:
            return
        ref = self.commander.last_reference
        ref_pos = ref.position_m if ref is not None else state.position_m
        setpoint, reason = decode_setpoint(msg, self.sim_time, state.position_m, state.euler_rad[2], ref_pos)
        if setpoint is None:
            self._statustext(m.MAV_SEVERITY_WARNING, f"setpoint refused: {reason}")
            return
        self.commander.offboard_setpoint(setpoint)

    def _on_gcs_heartbeat(self, msg, link: GcsLink, address) -> None:
        if msg.type != m.MAV_TYPE_GCS:
            return  # another vehicle or an onboard component: only ground stations count (link loss)
        link.last_heartbeat_s = self.sim_time
        self.commander.gcs_heartbeat(self.sim_time)
        self._send_events()

    def _on_param_change(self, name: str, value: float) -> None:
        """Gains take effect between two control steps (this runs between frames), no jump in
        the integral action (Cascade.retune)."""
        if is_controller_param(name):
            try:
                self.cascade.retune(controller_config_from_params(self.controller_config, self.params))
            except ValueError as exc:  # not reachable with the declared parameters; never crash
                self._statustext(m.MAV_SEVERITY_CRITICAL, f"retune failed: {exc}")
        if name.startswith(("GF_", "MIS_TAKEOFF_ALT", "RTL_RETURN_ALT", "MPC_")):
            for problem in consistency_problems(self.params):
                self._statustext(
                    m.MAV_SEVERITY_WARNING, f"parameters inconsistent (arming refused): {problem}"
                )

    def _on_timesync(self, msg, link: GcsLink, address) -> None:
        if msg.tc1 == 0:  # a request: answer with our (simulation) clock in ns
            reply = m.MAVLink_timesync_message(
                int(self.sim_time * 1e9), msg.ts1, msg.get_srcSystem(), msg.get_srcComponent()
            )
            link.send_to(self.encoder.pack(reply), address)

    # -- frames --------------------------------------------------------------------------------------
    def _on_hil_datagram(self, data: bytes) -> None:
        try:
            frame = decode_frame(
                data, self.hil_parser, self.sitl.home, self.options.state_source == "odometry"
            )
        except Exception as exc:  # a corrupt datagram: report, do not die (the simulator resends)
            self.log(f"bad HIL datagram ignored: {exc}")
            return
        if frame is None:
            return
        if frame.time_usec <= self.last_time_usec:
            if frame.time_usec < self.last_time_usec:
                self._simulator_restarted()
            else:  # the simulator resent a frame it did not get an answer to: answer again
                self.hil_sock.sendto(
                    self.actuators.encode(frame.time_usec, self._controls, self.commander.armed),
                    self.hil_address,
                )
                return
        now = time.monotonic()
        self._frame_gap_s = now - self.last_frame_wall
        self.last_frame_wall = now
        if not self.linked or self.sim_lost:
            self.log(f"linked with simulator (frames at t={frame.time_usec * 1e-6:.3f} s)")
            if self.sim_lost:
                self._statustext(m.MAV_SEVERITY_INFO, "simulator link recovered")
            self.linked, self.sim_lost = True, False
        self._control_step(frame)

    def _simulator_restarted(self) -> None:
        self.log("simulator time went backwards: simulator restarted; resetting")
        self.commander.disarm(self.sim_time, force=True)
        self.commander.home = None
        self.last_time_usec = -1

    def _control_step(self, frame) -> None:
        t = frame.time_usec * 1e-6
        self.sim_time = t
        self.last_time_usec = frame.time_usec
        est = frame.state
        commander = self.commander
        commander.update_state(
            VehicleState(t, est.position_m, est.velocity_m_s, est.euler_rad, est.euler_rates_rad_s)
        )
        if self.frames == 0 and self.autostart_trajectory is not None:
            commander.start_scenario(t, self.autostart_trajectory)
        self.frames += 1
        guidance = commander.step(t, self.dt)
        output = None
        if guidance.motors == Motors.FLY:
            if not self._flying:
                self.cascade.reset()
                self._flying = True
            output = self.cascade.step(est, guidance.reference)
            controls = output.actuator_controls
        else:
            if self._flying:
                self._flying = False
            self.cascade.reset()
            controls = (0.0, 0.0, 0.0, 0.0)
        self._controls = controls
        # Answer the frame first: the simulator is waiting (lockstep).
        self.hil_sock.sendto(
            self.actuators.encode(frame.time_usec, controls, commander.armed), self.hil_address
        )
        # Then the bookkeeping.
        self._update_status(frame, guidance, output)
        self._record_controller(t, guidance, output)
        self._send_telemetry(t)
        self.missions.update(t)  # MISSION_CURRENT, MISSION_ITEM_REACHED
        if commander.events:
            self._send_events()

    def _update_status(self, frame, guidance, output) -> None:
        s = self.status
        c = self.commander
        s.time_usec = frame.time_usec
        s.state = frame.state
        s.armed = c.armed
        s.custom_mode = c.mode.custom_mode
        s.landed_state = c.landed_state.value
        if c.home is not None:
            s.home_local = c.home
        s.reference = guidance.reference
        s.controls = self._controls
        s.armable = not c.armed and not c.in_air()
        s.geofence_enabled = self.params["GF_MAX_HOR_DIST"] > 0.0 or self.params["GF_MAX_VER_DIST"] > 0.0
        s.geofence_breached = c.failsafes.fence_breached
        if output is not None:
            s.euler_ref = output.euler_ref_rad
            s.thrust_normalised = output.thrust_n / self.vehicle.actuation.thrust_max_n
        else:
            s.euler_ref = (0.0, 0.0, frame.state.euler_rad[2])
            s.thrust_normalised = 0.0

    def _record_controller(self, t: float, guidance, output) -> None:
        if self.controller_pub is None:
            return
        ref = guidance.reference
        nan3 = (math.nan, math.nan, math.nan)
        if ref is not None:
            p, v, a = ref.position_m, ref.velocity_m_s, ref.acceleration_m_s2
        else:
            p = v = a = nan3
        if output is not None:
            eta_d, raw = output.euler_ref_rad, output.roll_pitch_raw_rad
            u1, tau = output.thrust_n, output.torque_euler_n_m
        else:
            eta_d, raw, u1, tau = nan3, (math.nan, math.nan), 0.0, (0.0, 0.0, 0.0)
        self._controller_rows.append(
            (
                t,
                *p,
                *v,
                *a,
                *eta_d,
                *raw,
                u1,
                *tau,
                float(self.commander.armed),
                float(self.commander.mode.custom_mode),
            )
        )
        if len(self._controller_rows) >= CONTROLLER_BATCH:
            self._flush_controller_rows()

    def _flush_controller_rows(self) -> None:
        if self.controller_pub is not None and self._controller_rows:
            try:
                self.controller_pub.put(CONTROLLER_CODEC.encode(self._controller_rows))
            except Exception:
                pass
            self._controller_rows = []

    # -- telemetry ----------------------------------------------------------------------------------
    def _send_telemetry(self, t: float) -> None:
        cache: dict[int, bytes | None] = {}
        for link in self.links:
            for msg_id in link.streams.due(t):
                if msg_id not in cache:
                    msg = telemetry.build(msg_id, self.status)
                    cache[msg_id] = self.encoder.pack(msg) if msg is not None else None
                data = cache[msg_id]
                if data is not None:
                    link.send(data)

    def _send_events(self) -> None:
        for severity, text in self.commander.drain_events():
            self._statustext(severity, text)

    def _statustext(self, severity: int, text: str) -> None:
        self.log(f"[t={self.sim_time:8.3f}] {text}")
        raw = text.encode("utf-8")[:200]
        chunks = [raw[i : i + 50] for i in range(0, len(raw), 50)] or [b""]
        self._statustext_id = (self._statustext_id % 65535) + 1
        ident = self._statustext_id if len(chunks) > 1 else 0
        for seq, chunk in enumerate(chunks):
            msg = m.MAVLink_statustext_message(severity, chunk, ident, seq)
            data = self.encoder.pack(msg)
            for link in self.links:
                link.send(data)

    def _wall_housekeeping(self, now: float) -> None:
        """Without frames: heartbeat on the wall clock, and tell the simulator we are here."""
        self.missions.poll()  # mission transfer retries and timeouts run on the wall clock
        self.param_service.poll()  # paced PARAM_REQUEST_LIST streams
        if self._controller_rows and now - self.last_frame_wall > 0.05:
            self._flush_controller_rows()  # frames paused: do not hold back the last rows
        sim_loss_s = self.params["COM_SIM_LOSS_T"]
        if not self.linked or now - self.last_frame_wall > sim_loss_s:
            if self.linked and not self.sim_lost:
                self.sim_lost = True
                self._flying = False
                self.commander.simulator_lost()  # no position: arming refused until frames resume
                self._statustext(
                    m.MAV_SEVERITY_CRITICAL,
                    f"simulator lost: no sensor frame for {sim_loss_s:g} s (COM_SIM_LOSS_T); motors off",
                )
            if now >= self._next_wall_heartbeat:
                self._next_wall_heartbeat = now + 1.0
                hb = self.encoder.pack(telemetry.heartbeat(self.status))
                for link in self.links:
                    link.send(hb)
                    link.send(self.encoder.pack(telemetry.sys_status(self.status)))
                self.missions.update(self.sim_time, force=True)
            if (not self.linked or self.sim_lost) and now >= self._next_hil_hello:
                # Say hello until frames flow: a restarted simulator learns our address from it.
                self._next_hil_hello = now + 0.2
                self.hil_sock.sendto(self.encoder.pack(telemetry.heartbeat(self.status)), self.hil_address)
        self._poll_info(now)

    def _poll_info(self, now: float) -> None:
        if self.info_queryable is None:
            return
        try:
            query = self.info_queryable.try_recv()
        except Exception:
            return
        if query is None:
            return
        info = {
            "instance": self.instance,
            "controller": self.controller_config.name,
            "vehicle": self.vehicle.name,
            "control_hz": self.sitl.rates.control_hz,
            "sim_time_s": self.sim_time,
            "armed": self.commander.armed,
            "mode": self.commander.mode.px4_name,
        }
        with query:
            query.reply(query.key_expr, json.dumps(info).encode())

    # -- loop ----------------------------------------------------------------------------------------
    def stop(self, *_args) -> None:
        self._running = False

    def run(self, max_wall_s: float | None = None) -> int:
        deadline = None if max_wall_s is None else time.monotonic() + max_wall_s
        hil = self.hil_sock
        select = self.selector.select
        self.log(
            f"instance {self.instance}, sysid {self.system_id}, controller {self.controller_config.name}, "
            f"GCS link udp {wire.LOOPBACK}:{self.ports.gcs_local}->{self.ports.gcs_remote}, "
            f"API link {self.ports.api_local}->{self.ports.api_remote}, simulator at udp {self.ports.hil}"
        )
        next_housekeeping = 0.0
        while self._running:
            now = time.monotonic()
            if deadline is not None and now > deadline:
                break
            if now >= next_housekeeping:
                self._wall_housekeeping(now)
                next_housekeeping = now + 0.05
            # Frames in quick succession (faster than real time): wait for the next one awake
            # (see quadcommon.wire.spin_until_readable); paced at real time, just block.
            gap = self._frame_gap_s
            if gap < SPIN_BELOW_GAP_S:
                wire.spin_until_readable(hil, min(self.sitl.lockstep_spin_s, 3.0 * gap))
            for key, _ in select(0.05):
                if key.data == "hil":
                    while True:
                        try:
                            data = hil.recv(65535)
                        except (BlockingIOError, InterruptedError):
                            break
                        except OSError:
                            break  # ICMP unreachable while the simulator is not up yet
                        self._on_hil_datagram(data)
                else:
                    link: GcsLink = key.data
                    for msg, address in link.receive():
                        handler = self.message_handlers.get(msg.id)
                        if handler is not None:
                            handler(msg, link, address)
        return 0


def main(argv: list[str] | None = None) -> int:
    import argparse

    parser = argparse.ArgumentParser(
        prog="python -m autopilot", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--instance", type=int, default=0, help="vehicle instance N (ports +N, sysid 1+N)")
    parser.add_argument("--controller", default="intbs_nlhinf", help="cascade (config/controllers)")
    parser.add_argument("--vehicle", default="paper_quad", help="vehicle (config/vehicle)")
    parser.add_argument("--sitl-config", default=None, help="path of an alternative sitl.toml")
    parser.add_argument(
        "--autostart",
        metavar="SCENARIO",
        default=None,
        help="arm at t=0 and fly the scenario's trajectory (the paper's experiment)",
    )
    parser.add_argument("--state-source", choices=("odometry", "hil_state_quaternion"), default="odometry")
    parser.add_argument("--no-zenoh", action="store_true", help="do not publish controller internals")
    parser.add_argument("--quiet", action="store_true")
    parser.add_argument(
        "--params",
        metavar="FILE",
        default=None,
        help="parameter file (params.toml, NAME = value): loaded at start if it exists, saved on "
        "every change and on MAV_CMD_PREFLIGHT_STORAGE",
    )
    args = parser.parse_args(argv)
    from quadcommon.schema import ConfigError

    try:
        app = Autopilot(
            AutopilotOptions(
                args.instance,
                args.controller,
                args.vehicle,
                args.sitl_config,
                args.autostart,
                args.state_source,
                not args.no_zenoh,
                args.quiet,
                args.params,
            )
        )
        app.open()
    except (ConfigError, ValueError) as exc:
        print(f"autopilot: {exc}", file=sys.stderr)
        return 2
    except (PortInUse, bus.BusError) as exc:
        print(
            f"autopilot: {exc}; is another vehicle running with --instance {args.instance}? "
            "(pick another --instance)",
            file=sys.stderr,
        )
        return 2
    signal.signal(signal.SIGTERM, app.stop)
    signal.signal(signal.SIGINT, app.stop)
    try:
        return app.run()
    finally:
        app.close()
        print("autopilot: stopped", flush=True)
