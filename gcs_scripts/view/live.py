"""One live vehicle as the view sees it: zenoh (truth, controller, info) and MAVLink, polled.

The view is a passive ground station. It never binds a ground-station port (14550 is
QGroundControl's, 14540+N MAVSDK's): its MAVLink socket is an ephemeral port on 127.0.0.1, from
which it sends a HEARTBEAT (``MAV_TYPE_GCS``, system id 254) once per wall second to the
autopilot's GCS link (``18570+N``). The autopilot answers every address that talks to it, so it
adds the view as a peer of that link and streams the link's telemetry to it as well; the
heartbeat is kept going because silent peers are (to be) dropped. The view never sends a
command, and never ``SET_MESSAGE_INTERVAL``: the rates belong to the link, which QGC shares.
Being a GCS heartbeat, it also counts for the GCS-link-loss failsafe (``NAV_DLL_ACT``): while the
view runs, a vehicle whose only other ground station went silent does not see the link as lost.

zenoh: a peer session towards the vehicle's hub (``tcp/127.0.0.1:7447+N``) with ring-buffer
subscribers on ``quadsitl/<N>/truth`` and ``quadsitl/<N>/controller``. A ring channel drops
the oldest batch when full rather than push back (the publisher drops for a slow subscriber
anyway), so a stalled view can never hold up the simulator's loop.

Everything is polled from the view's tick (:meth:`LiveVehicle.poll`); nothing blocks.
"""

from __future__ import annotations

import math
import os
import socket
import time
from typing import Any

from gcs_scripts.link import mavutil  # noqa: F401  (sets the MAVLink 2 / common dialect first)
from quadcommon import bus, wire
from quadcommon.bus_records import CONTROLLER_CODEC, TRUTH_CODEC
from quadcommon.config import SitlConfig

from .sampler import VehicleSampler
from .telemetry import VehicleTelemetry, wanted_frames

VIEW_SYSTEM_ID = 254  # not 255 (the scripts' and QGC's) nor a vehicle's 1+N
VIEW_COMPONENT_ID = 190  # MAV_COMP_ID_MISSIONPLANNER, a ground station
HEARTBEAT_PERIOD_WALL_S = 1.0
INFO_RETRY_WALL_S = 1.0
MAX_DATAGRAMS_PER_POLL = 20000  # bounded drain: ~10 wall seconds of telemetry at --speed max
MAX_SAMPLES_PER_POLL = 4096
RING_CAPACITY = 512  # zenoh batches kept between two ticks (~0.8 s at --speed max)


class LiveVehicle:
    """Vehicle ``instance``: its zenoh streams and its MAVLink telemetry, sampled for the page."""

    def __init__(self, instance: int, sitl: SitlConfig) -> None:
        self.instance = instance
        self.sitl = sitl
        self.ports = sitl.ports(instance)
        self.system_id = wire.system_id(instance)
        self.autopilot_address = (wire.LOOPBACK, self.ports.gcs_local)
        self.sampler = VehicleSampler()
        self.telemetry = VehicleTelemetry()
        self.sim_info = bus.InfoQuery(wire.zenoh_key(instance, "info"), INFO_RETRY_WALL_S)
        self.autopilot_info = bus.InfoQuery(wire.zenoh_key(instance, "autopilot/info"), INFO_RETRY_WALL_S)
        self.session: Any = None
        self.truth_sub: Any = None
        self.controller_sub: Any = None
        self.sock: socket.socket | None = None
        self.mav = mavutil.mavlink.MAVLink(None, srcSystem=VIEW_SYSTEM_ID, srcComponent=VIEW_COMPONENT_ID)
        self.parser = mavutil.mavlink.MAVLink(None)
        self.parser.robust_parsing = True
        self._next_heartbeat = 0.0
        self.datagrams = 0
        self.decoded = 0
        self.decode_errors = 0
        self.heartbeats_sent = 0
        self.info_changed = False

    # -- lifecycle ---------------------------------------------------------------------------------
    def open(self) -> None:
        """Bind the ephemeral MAVLink socket; subscribe to the vehicle's zenoh truth and controller rows."""
        import zenoh

        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((wire.LOOPBACK, 0))  # ephemeral: never a port another client expects
        self.sock.setblocking(False)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 20)
        self.session = bus.open_peer(self.ports.zenoh, self.sitl.zenoh_router)
        self.truth_sub = self.session.declare_subscriber(
            wire.zenoh_key(self.instance, "truth"), zenoh.handlers.RingChannel(RING_CAPACITY)
        )
        self.controller_sub = self.session.declare_subscriber(
            wire.zenoh_key(self.instance, "controller"), zenoh.handlers.RingChannel(RING_CAPACITY)
        )

    def close(self) -> None:
        """Close the zenoh session and the socket; errors while closing are ignored."""
        for closer in (
            lambda: self.session.close() if self.session is not None else None,
            lambda: self.sock.close() if self.sock is not None else None,
        ):
            try:
                closer()
            except Exception:
                pass  # closing must go on
        self.session = self.sock = None

    @property
    def mavlink_port(self) -> int:
        """The view's own (ephemeral) MAVLink port."""
        return self.sock.getsockname()[1] if self.sock is not None else 0

    # -- the tick ----------------------------------------------------------------------------------
    def poll(self, wall: float | None = None) -> None:
        """Heartbeat if due, then everything waiting on zenoh and on the MAVLink socket."""
        wall = time.monotonic() if wall is None else wall
        if wall >= self._next_heartbeat:
            self._next_heartbeat = wall + HEARTBEAT_PERIOD_WALL_S
            self._send_heartbeat()
        self._drain(self.truth_sub, TRUTH_CODEC, self.sampler.add_truth)
        self._drain(self.controller_sub, CONTROLLER_CODEC, self.sampler.add_controller)
        self._drain_mavlink()
        for query in (self.sim_info, self.autopilot_info):
            if query.poll(self.session, wall):
                self.info_changed = True

    def _send_heartbeat(self) -> None:
        if self.sock is None:
            return
        m = mavutil.mavlink
        msg = self.mav.heartbeat_encode(m.MAV_TYPE_GCS, m.MAV_AUTOPILOT_INVALID, 0, 0, m.MAV_STATE_ACTIVE)
        try:
            self.sock.sendto(msg.pack(self.mav), self.autopilot_address)
            self.heartbeats_sent += 1
        except OSError:
            pass  # the autopilot is not up (yet): ICMP unreachable on loopback

    def _drain(self, sub: Any, codec: Any, add: Any) -> None:
        import zenoh

        if sub is None:
            return
        for _ in range(MAX_SAMPLES_PER_POLL):
            try:
                sample = sub.try_recv()
            except zenoh.ZError:
                return
            if sample is None:
                return
            try:
                rows = codec.decode(sample.payload.to_bytes())
            except ValueError:
                self.decode_errors += 1
                continue
            add(rows)

    def _drain_mavlink(self) -> None:
        if self.sock is None:
            return
        for _ in range(MAX_DATAGRAMS_PER_POLL):
            try:
                data, _address = self.sock.recvfrom(65535)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                continue  # ICMP port unreachable of an earlier heartbeat
            self.datagrams += 1
            for frame in wanted_frames(data, self.system_id):
                try:
                    messages = self.parser.parse_buffer(frame) or []
                except Exception:
                    self.decode_errors += 1
                    continue
                for msg in messages:
                    if msg.get_type() == "BAD_DATA":
                        continue
                    self.decoded += 1
                    self.telemetry.add(msg, self.sampler.latest_time_s or 0.0)

    # -- what the page gets ------------------------------------------------------------------------
    def describe(self) -> dict[str, Any]:
        """The track's description for the page: instance, system id, label, controller, scenario."""
        sim = self.sim_info.answer or {}
        ap = self.autopilot_info.answer or {}
        controller = ap.get("controller", "")
        scenario = sim.get("scenario", "")
        label = f"vehicle {self.instance}" + (f" · {controller}" if controller else "")
        return {
            "instance": self.instance,
            "system_id": self.system_id,
            "label": label,
            "controller": controller,
            "scenario": scenario,
            "vehicle": sim.get("vehicle", ap.get("vehicle", "")),
            "speed": sim.get("speed"),
        }

    def home(self) -> tuple[float, float, float] | None:
        """Its simulator's home (lat deg, lon deg, alt m) from its info, None until it answers."""
        home = (self.sim_info.answer or {}).get("home")
        try:
            lat, lon, alt = (float(value) for value in home)
        except (TypeError, ValueError):  # not there yet (or not three numbers)
            return None
        return (lat, lon, alt) if math.isfinite(lat + lon + alt) else None

    def status(self) -> dict[str, Any]:
        """Mode, armed, landed, active failsafe and whether heartbeats arrive, for the page."""
        tm = self.telemetry
        return {
            "mode": tm.mode,
            "armed": tm.armed,
            "landed": tm.landed,
            "failsafe": tm.failsafe_name,
            "linked": tm.heartbeats > 0,
        }


class CpuPriority:
    """The view's CPU policy: ``nice 10`` (set at start), and ``SCHED_IDLE`` on every thread of the
    process while the vehicles run much faster than real time.

    On a 2-core machine at ``--speed max`` the simulator and the autopilot each keep a core busy
    and hand every frame to each other (lockstep, spin-waiting); a third process that wakes 30
    times a second and takes a core for a millisecond stalls that chain every time (measured: the
    view at nice 10 cost ~10 % of the real-time factor, at SCHED_IDLE ~5 %). A batch run is
    watched, if at all, at a lower update rate; an interactive one (``--speed 1``, 2) keeps the
    view at nice 10, where it gets its few percent of a core and its 30 Hz.
    """

    FAST_RTF = 4.0  # simulation seconds per wall second above which the view yields all
    SLOW_RTF = 3.0  # ... and below which it takes its share again (hysteresis)
    WINDOW_WALL_S = 2.0

    def __init__(self, enabled: bool = True) -> None:
        self.enabled = enabled and hasattr(os, "SCHED_IDLE")
        self.idle = False
        self.switches = 0
        self._anchor: tuple[float, float] | None = None  # (wall, simulation time)
        self.rtf: float | None = None

    def update(self, wall: float, sim_time_s: float | None) -> None:
        """Called each tick with the fastest vehicle's newest simulation time."""
        if sim_time_s is None:
            return
        if self._anchor is None or sim_time_s < self._anchor[1]:
            self._anchor = (wall, sim_time_s)
            return
        if wall - self._anchor[0] < self.WINDOW_WALL_S:
            return
        self.rtf = (sim_time_s - self._anchor[1]) / (wall - self._anchor[0])
        self._anchor = (wall, sim_time_s)
        if not self.enabled:
            return
        if not self.idle and self.rtf > self.FAST_RTF:
            self._set(os.SCHED_IDLE)
        elif self.idle and self.rtf < self.SLOW_RTF:
            self._set(os.SCHED_OTHER)

    def _set(self, policy: int) -> None:
        try:
            for tid in os.listdir("/proc/self/task"):  # zenoh's runtime threads too
                os.sched_setscheduler(int(tid), policy, os.sched_param(0))
        except (OSError, ValueError):
            return  # not allowed here: keep what we have
        self.idle = policy == os.SCHED_IDLE
        self.switches += 1


def nice_self(increment: int = 10) -> None:
    """Lower this process's CPU priority: the view is best effort, the lockstep loop is not.

    Called before any zenoh session is opened, so its runtime threads inherit it.
    """
    try:
        os.nice(increment)
    except OSError:
        pass
