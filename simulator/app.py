"""The simulator process: the plant side of the SITL, in lockstep with the autopilot over UDP.

One thread, one loop. The simulator owns simulation time. Per control period it

1. reads the plant's truth at frame time ``t = k / control_hz`` and the sensors' readings,
2. sends ONE datagram (HIL_SENSOR, HIL_STATE_QUATERNION, ODOMETRY, and HIL_GPS when a fix is
   delivered: the sensor profile's rate and latency, see :mod:`simulator.sensors`,
   all stamped ``time_usec = round(k * 1e6 / control_hz)``) to the autopilot,
3. meanwhile (the autopilot is computing) appends the truth row to the zenoh batch and answers
   info queries,
4. waits for the ``HIL_ACTUATOR_CONTROLS`` with that ``time_usec`` (stale answers are ignored;
   after ``[lockstep] timeout_s`` of wall time without one the autopilot is LOST, see below),
5. applies the controls (zero, i.e. motors off, unless the armed bit is set) and steps the plant
   ``physics_hz / control_hz`` times, evaluating the disturbance schedule at every physics step,
   exactly as :mod:`sitl.inprocess` couples the same cores, so SITL and in-process runs agree,
6. paces on the wall clock: sleeps until ``wall_start + t / speed`` (no sleeping for ``max``);
   more than 0.2 s behind, it re-anchors instead of sprinting to catch up.

Autopilot lost: the simulator neither hangs nor leaves the vehicle in the air. It says so and
keeps stepping (paced as before) under its own emergency descent (:mod:`simulator.safety`: level,
descend at 0.5 m/s, motors off on touchdown; a vehicle already on the ground or disarmed keeps its
motors off), still sending every frame to the autopilot. Under ``--speed max`` the descent runs
as fast as it can (it is bounded: it ends on the ground) and, once down, time goes on at real
time (1x) so an idle simulator does not spin. The first answer from the autopilot (or a
restarted autopilot, at a new address) resumes lockstep from the current state.

The UDP link binds 127.0.0.1:(4560 + N) and learns the autopilot's address from its first
datagram (the autopilot sends HEARTBEAT to this port until frames flow). Ports in use, like bad
configuration, end the process with exit code 2 and a message naming the port and ``--instance``.
SIGINT/SIGTERM stop the loop cleanly (truth batch flushed, zenoh closed, socket closed; exit 0).
"""

from __future__ import annotations

import argparse
import errno
import math
import select
import signal
import socket
import sys
import time
from array import array
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from quadcommon import bus, wire
from quadcommon.config import apply_uncertainty, load_scenario, load_sitl, load_vehicle
from quadcommon.schema import ConfigError

from .dynamics.plant import make_plant
from .environment.gust_profile import DisturbanceSchedule, GustProfile, load_gust_profile
from .mavlink.hil import ActuatorAnswer, ActuatorDecoder, HilFrameEncoder
from .safety import MOTORS_OFF, emergency_descent, touched_down
from .sensors import SensorSuite, load_sensors
from .truth_bus import GustUploadServer, InfoServer, TruthStream, truth_row

POLL_S = 0.05  # longest blocking wait: bounds the reaction time to SIGTERM and info queries
RESYNC_BEHIND_S = 0.2  # further behind the wall-clock schedule than this: re-anchor, do not sprint
RATE_REPORT_WALL_S = 10.0  # at most one "cannot keep up" line per this many wall seconds
MAX_DATAGRAM = 65535
MAX_ROUND_TRIP_SAMPLES = 2_000_000  # 16 MB at most, ~1 h at 500 Hz
_MOTORS_OFF = (0.0, 0.0, 0.0, 0.0)
LOST = "lost"  # _await_answer's result when the autopilot does not answer within the timeout
MAX_DRAIN = 1000  # datagrams read per frame while the autopilot is lost (bounded)


class StartupError(RuntimeError):
    """The simulator cannot start (port in use, ...); the message says which and why."""


@dataclass(frozen=True)
class SimulatorOptions:
    instance: int = 0
    vehicle: str | None = None  # None: the scenario's vehicle
    scenario: str = "hover"
    speed: float | None = 1.0  # wall-clock pacing factor; None = as fast as lockstep allows
    duration_s: float | None = None  # stop after this much simulated time (None: until stopped)
    sitl_config: str | None = None
    sensors: str | None = None  # config/sensors/NAME.toml; None: the scenario's profile


class Simulator:
    """The simulator process's state and loop; ``open`` -> ``run`` -> ``close`` (in ``finally``)."""

    def __init__(self, options: SimulatorOptions) -> None:
        self.options = options
        self.instance = options.instance
        self.sitl = sitl = load_sitl(options.sitl_config)
        self.scenario = scenario = load_scenario(options.scenario)
        self.vehicle = load_vehicle(options.vehicle or scenario.vehicle)
        self.ports = wire.ports(
            options.instance, sitl.hil_port_base, sitl.gcs_port_base, sitl.api_port_base, sitl.zenoh_port_base
        )
        rates = sitl.rates
        # Same time grid as sitl.inprocess.run_scenario (frame k at t = k * dt_control).
        self.control_hz = rates.control_hz
        self.physics_hz = rates.physics_hz
        self.substeps = rates.physics_steps_per_control
        self.dt_control = 1.0 / rates.control_hz
        self.dt_physics = self.dt_control / self.substeps
        self.plant_vehicle = apply_uncertainty(self.vehicle, scenario)  # what is flown (emergency law)
        self.plant = make_plant(self.plant_vehicle, self.dt_physics)
        self.plant.reset(scenario.initial_position_m, scenario.initial_euler_rad)
        self.schedule = self._new_schedule(load_gust_profile(scenario.gusts), 0.0)
        self._pending_schedule: DisturbanceSchedule | None = None
        self.sensors = SensorSuite(
            load_sensors(options.sensors or scenario.sensors), sitl.home[2], imu_rate_hz=rates.control_hz
        )
        self.encoder = HilFrameEncoder(wire.system_id(options.instance), sitl.home)
        self.decoder = ActuatorDecoder()
        self.wrench = self.vehicle.actuation.mode == "wrench"
        self.timeout_s = sitl.lockstep_timeout_s
        self.spin_s = sitl.lockstep_spin_s

        self.sock: socket.socket | None = None
        self.session: Any = None
        self.truth_stream: TruthStream | None = None
        self.info: InfoServer | None = None
        self.gusts: GustUploadServer | None = None
        self.peer: tuple[str, int] | None = None
        self._running = True
        self.sim_time_s = 0.0
        self.frames_sent = 0
        self.overruns = 0
        self._resync = False  # re-anchor the wall clock after an outage
        self._warned: set[str] = set()
        # Wall time per frame split into own work and waiting for the autopilot (for the report).
        self.work_s = 0.0
        self.wait_s = 0.0
        # HIL round trip per frame (send -> matching answer), wall seconds; bounded memory.
        self.round_trips = array("d")
        # Autopilot lost: emergency descent state.
        self.emergency = False
        self.emergency_landed = False  # motors off for the rest of the outage
        self._armed = False  # the armed bit of the last applied answer
        self._lost_usec = 0  # the frame that was not answered
        self._outage_wall = 0.0  # perf_counter() when the outage was declared

    # -- setup / teardown ---------------------------------------------------------------------
    def open(self) -> None:
        """Bind the HIL port and open the zenoh hub; raises :class:`StartupError` on a port in use."""
        n = self.instance
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.bind((wire.LOOPBACK, self.ports.hil))
        except OSError as exc:
            sock.close()
            if exc.errno == errno.EADDRINUSE:
                raise StartupError(
                    f"UDP port {self.ports.hil} (HIL link, udp {wire.LOOPBACK}:{self.ports.hil}) is already "
                    f"in use: is another simulator running with --instance {n}? (pick another --instance)"
                ) from None
            raise
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        sock.settimeout(POLL_S)
        self.sock = sock
        try:
            self.session = bus.open_hub(self.ports.zenoh, self.sitl.zenoh_router)
        except bus.BusError as exc:
            raise StartupError(
                f"{exc}: is another simulator running with --instance {n}? (pick another --instance)"
            ) from None
        self.truth_stream = TruthStream(self.session, wire.zenoh_key(n, "truth"))
        self.info = InfoServer(self.session, wire.zenoh_key(n, "info"), self.describe)
        self.gusts = GustUploadServer(
            self.session,
            wire.zenoh_key(n, "sim/gusts"),
            lambda: self.sim_time_s,
            self._install_uploaded_gusts,
            self.dt_physics,
            self._wind_warning,
        )

    def close(self) -> None:
        """Flush the truth batch, close zenoh and the socket (idempotent)."""
        if self.truth_stream is not None:
            self.truth_stream.close()
            self.truth_stream = None
        if self.gusts is not None:
            self.gusts.close()
            self.gusts = None
        if self.info is not None:
            self.info.close()
            self.info = None
        if self.session is not None:
            self.session.close()
            self.session = None
        if self.sock is not None:
            self.sock.close()
            self.sock = None

    def stop(self, *_args: object) -> None:
        """Ask the loop to stop (signal handler: SIGINT, SIGTERM)."""
        self._running = False

    def describe(self) -> dict[str, Any]:
        """The answer of the ``quadsitl/<N>/info`` queryable."""
        speed = self.options.speed
        return {
            "instance": self.instance,
            "vehicle": self.vehicle.name,
            "scenario": self.scenario.name,
            "actuation": self.vehicle.actuation.mode,
            "physics_hz": self.physics_hz,
            "control_hz": self.control_hz,
            "speed": "max" if speed is None else speed,
            "sim_time_s": self.sim_time_s,
        }

    # -- gust uploads (hook) ----------------------------------------------------------------------
    def schedule_gust_profile(self, profile: GustProfile, start_time_s: float) -> None:
        """Replace the active disturbance schedule by ``profile`` starting at ``start_time_s`` (s, sim).

        Takes effect at the next frame boundary, so a frame's truth row and its physics steps
        always see one schedule. (The upload queryable on ``quadsitl/<N>/sim/gusts`` is meant to
        call this from the main loop.)
        """
        self._pending_schedule = self._new_schedule(profile, start_time_s)

    def _poll_services(self) -> None:
        """Answer zenoh queries (info, gust uploads) without blocking."""
        self.info.poll()  # type: ignore[union-attr]
        self.gusts.poll()  # type: ignore[union-attr]

    def _install_uploaded_gusts(self, profile: GustProfile, start_time_s: float) -> None:
        self.schedule_gust_profile(profile, start_time_s)
        self.log(f"gust profile uploaded: applies from t={start_time_s:.3f} s")

    def _wind_warning(self, profile: GustProfile) -> str | None:
        """Wind acts through drag only: say so when this vehicle has none."""
        has_wind = bool(profile.one_minus_cosine) or profile.dryden is not None
        if has_wind and not any(self.vehicle.plant.drag_coefficient_n_s_m):
            return (
                f"vehicle '{self.vehicle.name}' has zero drag (plant.drag_coefficient_n_s_m), so wind "
                "gusts and turbulence have no effect; use a vehicle with drag, e.g. paper_quad_drag"
            )
        return None

    def _new_schedule(self, profile: GustProfile, start_time_s: float) -> DisturbanceSchedule:
        """The one place schedules are built: evaluated at every physics step, in non-decreasing
        time (the Dryden turbulence samples at ``step_s`` and only runs forward)."""
        return DisturbanceSchedule(profile, start_time_s, step_s=self.dt_physics)

    # -- messages -----------------------------------------------------------------------------------
    def log(self, text: str) -> None:
        print(f"simulator: {text}", flush=True)

    def _warn_once(self, key: str, text: str) -> None:
        if key not in self._warned:
            self._warned.add(key)
            print(f"simulator: {text}", file=sys.stderr, flush=True)

    # -- link ------------------------------------------------------------------------------------
    def _wait_for_link(self) -> bool:
        """Block until a MAVLink datagram arrives; remember its sender. False if stopped first."""
        assert self.sock is not None and self.info is not None
        self.log(f"waiting for the autopilot on udp {wire.LOOPBACK}:{self.ports.hil}")
        probe = mavlink.MAVLink(None)  # own parser: a stray datagram must not touch the lockstep one
        probe.robust_parsing = True
        while self._running:
            try:
                data, address = self.sock.recvfrom(MAX_DATAGRAM)
            except TimeoutError:
                self._poll_services()
                continue
            except OSError:
                continue
            try:
                messages = probe.parse_buffer(data) or []
            except Exception:
                messages = []
            if any(m.get_msgId() >= 0 for m in messages):
                self.peer = address
                self.log(f"linked with autopilot at {address[0]}:{address[1]}")
                return True
        return False

    def _await_answer(self, time_usec: int, datagram: bytes) -> ActuatorAnswer | str | None:
        """The autopilot's answer to the frame ``time_usec``; None if stopped while waiting;
        :data:`LOST` after ``timeout_s`` wall seconds without it (reported here, once).
        """
        sock, decode, info = self.sock, self.decoder.decode, self.info
        assert sock is not None and info is not None
        deadline = time.perf_counter() + self.timeout_s
        wire.spin_until_readable(sock, self.spin_s)  # the answer is due within ~100 µs
        while self._running:
            try:
                data, address = sock.recvfrom(MAX_DATAGRAM)
            except TimeoutError:
                data = None
            except OSError:
                data = None  # e.g. ICMP port unreachable surfaced by the kernel: the peer is gone
            if data is not None and address == self.peer:
                answer = decode(data)
                if answer is not None and answer.time_usec == time_usec:
                    return answer
                # else: a heartbeat, or a late answer to an earlier frame
            # Checked on every wake-up, so a peer chattering without answering is reported too.
            now = time.perf_counter()
            if now >= deadline:
                self.log(
                    f"no HIL_ACTUATOR_CONTROLS for frame t={time_usec * 1e-6:.3f} s within "
                    f"{self.timeout_s:.1f} s; is the autopilot running? "
                    f"(udp {wire.LOOPBACK}:{self.ports.hil})"
                )
                return LOST
            if data is None:
                self._poll_services()
        return None

    # -- autopilot lost ----------------------------------------------------------------------------
    def _enter_emergency(self, time_usec: int) -> None:
        """The autopilot did not answer frame ``time_usec``: fly the emergency descent from now."""
        self.emergency = True
        self._lost_usec = time_usec
        self._outage_wall = time.perf_counter()
        truth = self.plant.truth()
        if not self._armed or touched_down(truth):
            self.emergency_landed = True
            what = "disarmed" if not self._armed else "on the ground"
            self.log(f"autopilot lost: vehicle {what}, motors off; waiting for the autopilot to answer again")
        else:
            self.emergency_landed = False
            self.log(
                f"autopilot lost: emergency descent from z={truth.position_m[2]:.2f} m at 0.5 m/s "
                "(levelled; motors off on touchdown); waiting for the autopilot to answer again"
            )

    def _emergency_controls(self, t: float) -> tuple[float, float, float, float]:
        """This frame's controls under the emergency descent (motors off once down)."""
        if self.emergency_landed:
            return MOTORS_OFF
        truth = self.plant.truth()
        if touched_down(truth):
            self.emergency_landed = True
            self.log(f"emergency descent: touchdown at t={t:.3f} s, motors off")
            return MOTORS_OFF
        return emergency_descent(truth, self.plant_vehicle).controls

    def _autopilot_answered(self) -> bool:
        """Drain the socket without blocking; True once the autopilot answers a frame again.

        Any answer to a frame at or after the one it missed counts (it may be catching up on
        queued frames); a datagram from a new address is a restarted autopilot saying hello,
        which becomes the peer (the next frame goes to it).
        """
        sock, decode = self.sock, self.decoder.decode
        assert sock is not None
        for _ in range(MAX_DRAIN):
            # A socket with a timeout waits for it even with MSG_DONTWAIT: ask select first.
            if not select.select((sock,), (), (), 0.0)[0]:
                return False
            try:
                data, address = sock.recvfrom(MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError, TimeoutError):
                return False
            except OSError:
                continue  # ICMP unreachable from a send to the dead autopilot
            if address != self.peer:
                self.peer = address
                self.log(f"autopilot now at {address[0]}:{address[1]}")
                continue
            answer = decode(data)
            if answer is not None and answer.time_usec >= self._lost_usec:
                return True
        return False

    def _leave_emergency(self, t: float) -> None:
        self.emergency = False
        self.emergency_landed = False
        self._resync = True
        outage = time.perf_counter() - self._outage_wall
        self.log(
            f"link recovered: the autopilot answers again after {outage:.1f} s; "
            f"resuming lockstep at t={t:.3f} s"
        )

    def _send(self, datagram: bytes) -> None:
        assert self.sock is not None and self.peer is not None
        try:
            self.sock.sendto(datagram, self.peer)
        except OSError:
            pass  # the autopilot is gone; the lockstep timeout reports it

    def _apply(self, answer: ActuatorAnswer) -> None:
        """Controls into the plant: zero unless armed, consistent and finite."""
        self._armed = answer.armed
        controls = _MOTORS_OFF
        if answer.wrench != self.wrench:
            mode = "wrench" if answer.wrench else "rotors"
            self._warn_once(
                "actuation",
                f"refusing HIL_ACTUATOR_CONTROLS: their flags say actuation '{mode}' but vehicle "
                f"'{self.vehicle.name}' has actuation '{self.vehicle.actuation.mode}'; motors off. "
                "Start both processes with the same --vehicle.",
            )
        elif answer.armed:
            c = answer.controls
            if math.isfinite(c[0] + c[1] + c[2] + c[3]):
                controls = c
            else:
                self._warn_once("finite", f"non-finite actuator controls {c}; motors off for those frames")
        if not answer.lockstep:
            self._warn_once("lockstep", "HIL_ACTUATOR_CONTROLS without the lockstep flag (bit 0); accepted")
        self.plant.set_actuator_controls(controls)

    # -- loop --------------------------------------------------------------------------------------
    def run(self) -> int:
        """Until stopped or ``duration_s`` of simulated time; returns the exit code."""
        assert self.truth_stream is not None and self.info is not None
        if not self._wait_for_link():
            return 0
        plant, sensors, encoder = self.plant, self.sensors, self.encoder
        append_truth, poll_info = self.truth_stream.append, self._poll_services
        send = self._send
        perf_counter = time.perf_counter
        dt, dt_physics, substeps = self.dt_control, self.dt_physics, self.substeps
        usec_per_frame = 1e6 / self.control_hz
        speed = self.options.speed
        last_frame = (
            None if self.options.duration_s is None else round(self.options.duration_s / self.dt_control)
        )
        wall_anchor = perf_counter()
        report_at = wall_anchor + RATE_REPORT_WALL_S
        report_sim, report_wall = 0.0, wall_anchor
        paced_at = speed  # the pacing factor in use (changes only around an autopilot outage)
        k = 0
        while self._running:
            start = perf_counter()
            t = k * dt
            time_usec = round(k * usec_per_frame)
            if self._pending_schedule is not None:
                self.schedule, self._pending_schedule = self._pending_schedule, None
            schedule = self.schedule
            truth = plant.truth()
            p = truth.position_m
            if not math.isfinite(p[0] + p[1] + p[2]):
                print(f"simulator: the plant state is not finite at t={t:.3f} s; stopping", file=sys.stderr)
                return 1
            force, torque, wind = schedule.evaluate(t)
            frame = sensors.step(t, truth)
            datagram = encoder.encode(time_usec, truth, frame.readings, wind, frame.gps)
            sent_at = perf_counter()
            send(datagram)
            self.frames_sent += 1
            self.sim_time_s = t
            # Bookkeeping while the autopilot computes its answer.
            append_truth(truth_row(t, truth, force, torque, wind))
            poll_info()
            if last_frame is not None and k >= last_frame:
                break  # the final frame (t = duration) is sent and recorded, not stepped
            sent = perf_counter()
            if self.emergency:
                # Autopilot lost: our own descent this frame; lockstep again from the next one
                # once it answers.
                controls = self._emergency_controls(t)
                if self._autopilot_answered():
                    self._leave_emergency(t)
                plant.set_actuator_controls(controls)
                answered = perf_counter()
            else:
                answer = self._await_answer(time_usec, datagram)
                if answer is None:
                    break
                answered = perf_counter()
                if answer is LOST:
                    self._enter_emergency(time_usec)
                    self._resync = True  # the wait was an outage, not simulated time
                    plant.set_actuator_controls(self._emergency_controls(t))
                else:
                    if len(self.round_trips) < MAX_ROUND_TRIP_SAMPLES:
                        self.round_trips.append(answered - sent_at)
                    self._apply(answer)  # type: ignore[arg-type]
            for j in range(substeps):
                f, tq, w = schedule.evaluate(t + j * dt_physics)
                plant.set_disturbance(f, tq, w)
                plant.step()
            k += 1
            now = perf_counter()
            self.work_s += (sent - start) + (now - answered)
            self.wait_s += answered - sent
            pace = speed
            if pace is None:
                if not (self.emergency and self.emergency_landed):
                    continue
                pace = 1.0  # as fast as possible, but once landed without an autopilot: real time
            # Wall-clock pacing on top of lockstep.
            t_next = k * dt
            if self._resync or pace != paced_at:
                self._resync = False
                paced_at = pace
                wall_anchor = now - t_next / pace
            target = wall_anchor + t_next / pace
            if target > now:
                self._sleep_until(target)
            elif now - target > RESYNC_BEHIND_S:
                wall_anchor = now - t_next / pace
                self.overruns += 1
            if now >= report_at and speed is not None:
                achieved = (t_next - report_sim) / (now - report_wall)
                if achieved < 0.95 * speed:
                    self.log(
                        f"running at {achieved:.2f}x real time (asked {speed:g}x); "
                        f"{self.overruns} re-anchors so far"
                    )
                report_at = now + RATE_REPORT_WALL_S
                report_sim, report_wall = t_next, now
        return 0

    def _sleep_until(self, target: float) -> None:
        """Sleep (no busy-wait) until ``perf_counter() >= target``, in slices that see a stop."""
        while self._running:
            remaining = target - time.perf_counter()
            if remaining <= 0.0:
                return
            time.sleep(min(remaining, POLL_S))

    def summary(self) -> str:
        n = max(self.frames_sent - 1, 1)  # the final frame is not answered
        text = (
            f"stopped at t={self.sim_time_s:.3f} s ({self.frames_sent} frames; per frame "
            f"{1e6 * self.work_s / n:.0f} us own work, {1e6 * self.wait_s / n:.0f} us waiting for the "
            f"autopilot; {self.overruns} re-anchors)"
        )
        if self.round_trips:
            rtt = sorted(self.round_trips)
            median = rtt[len(rtt) // 2]
            p99 = rtt[min(int(0.99 * len(rtt)), len(rtt) - 1)]
            text += f"; HIL round trip median {1e6 * median:.0f} us, p99 {1e6 * p99:.0f} us"
        return text


# -- command line -----------------------------------------------------------------------------------
def _speed(text: str) -> float | None:
    if text == "max":
        return None
    message = f"--speed must be a positive number or 'max', got {text!r}"
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(message) from None
    if not (value > 0.0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(message)
    return value


def _duration(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"--duration must be a number of seconds, got {text!r}") from None
    if not (value > 0.0 and math.isfinite(value)):
        raise argparse.ArgumentTypeError(f"--duration must be > 0 s, got {text!r}")
    return value


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="python -m simulator",
        description="The quadsitl simulator process (plant side of the SITL, lockstep over MAVLink HIL).",
    )
    parser.add_argument("--instance", type=int, default=0, help="vehicle instance N (ports +N, sysid 1+N)")
    parser.add_argument("--vehicle", default=None, help="vehicle (config/vehicle); default: the scenario's")
    parser.add_argument("--scenario", default="hover", help="scenario (config/scenarios); default: hover")
    parser.add_argument(
        "--speed", type=_speed, default=1.0, help="wall-clock pacing: a factor (1 = real time) or 'max'"
    )
    parser.add_argument("--duration", type=_duration, default=None, help="stop after S simulated seconds")
    parser.add_argument("--config-dir", default=None, help="configuration directory (default: ./config)")
    parser.add_argument("--sitl-config", default=None, help="path of an alternative sitl.toml")
    parser.add_argument(
        "--sensors",
        default=None,
        help="sensor profile (config/sensors: ideal, mocap, gps); default: the scenario's",
    )
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if args.config_dir is not None:
        import quadcommon.config as qconfig

        config_dir = Path(args.config_dir)
        if not config_dir.is_dir():
            print(f"simulator: --config-dir {config_dir} is not a directory", file=sys.stderr)
            return 2
        qconfig.CONFIG_DIR = config_dir  # config_path() reads it at call time
    try:
        app = Simulator(
            SimulatorOptions(
                instance=args.instance,
                vehicle=args.vehicle,
                scenario=args.scenario,
                speed=args.speed,
                duration_s=args.duration,
                sitl_config=args.sitl_config,
                sensors=args.sensors,
            )
        )
    except (ConfigError, ValueError) as exc:
        print(f"simulator: {exc}", file=sys.stderr)
        return 2
    signal.signal(signal.SIGTERM, app.stop)
    signal.signal(signal.SIGINT, app.stop)
    code = 2
    opened = False
    try:
        app.open()
        opened = True
        speed = "max" if app.options.speed is None else f"{app.options.speed:g}x"
        app.log(
            f"instance {app.instance}, vehicle {app.vehicle.name} (actuation {app.vehicle.actuation.mode}, "
            f"plant {app.vehicle.plant.model}), scenario {app.scenario.name}, physics {app.physics_hz:g} Hz, "
            f"control {app.control_hz:g} Hz, speed {speed}; truth on zenoh "
            f"{wire.zenoh_key(app.instance, 'truth')} (tcp/{wire.LOOPBACK}:{app.ports.zenoh})"
        )
        code = app.run()
    except StartupError as exc:
        print(f"simulator: {exc}", file=sys.stderr)
        return 2
    finally:
        app.close()
        if opened:
            app.log(app.summary())
    return code
