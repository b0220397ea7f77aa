"""Several vehicles at once: ``quadsitl up --instance N --count 2``, as PX4's multi-vehicle SITL.

Vehicle N gets its own ports (PX4's scheme, quadcommon/wire.py), sysid 1+N and its own zenoh key
prefix ``quadsitl/<N>/``. Both stream their GCS link to the one ground-station port (PX4's 14550):
one socket there hears both, told apart by system id. Two vehicles fly different offboard
setpoints at the same time, each driven by a pymavlink client on its own API port; neither obeys
what is addressed to the other.

What PX4 does with a command for another system (and what this autopilot does): it ignores it
without an ACK (PX4's ``MavlinkReceiver::handle_message_command_both``: "Ignore command ... to
<sys>/<comp>" unless MAVLink forwarding is on and that system was seen on another link); setpoints
are taken only when ``target_system`` is the vehicle's own sysid or 0. One difference: PX4 also
ignores most commands sent to target_system 0 (broadcast), where this autopilot accepts them.
The vehicles run at ``--speed 2``: a single-threaded test client streaming setpoints to two
vehicles that each run flat out (``max``) on a 2-core machine could fall behind in simulation time
and trip the offboard-loss failsafe; a fixed factor keeps the test about wall time.
"""

from __future__ import annotations

import math
import os
import re
import signal
import socket
import sys
import time

import pytest

os.environ.setdefault("MAVLINK20", "1")
os.environ.setdefault("MAVLINK_DIALECT", "common")
from pymavlink import mavutil  # noqa: E402
from pymavlink.dialects.v20 import common as m  # noqa: E402

from quadcommon import bus, frames, wire  # noqa: E402
from quadcommon.bus_records import TRUTH_CODEC  # noqa: E402
from quadcommon.config import load_sitl  # noqa: E402
from sitl.launcher import Child, LaunchError, VehicleSpec, check_ports  # noqa: E402

from .vehicles import ports  # noqa: E402

pytestmark = [pytest.mark.processes, pytest.mark.compat]  # (tests/conftest.py: the markers)

FIRST = 7  # instances 7 and 8: sysids 8, 9
TARGETS = {7: (2.0, 0.0, 2.5), 8: (0.0, -2.0, 3.5)}  # paper frame (x north, y west, z up), m
ALIEN = (-3.0, 3.0, 1.0)  # a setpoint addressed to the OTHER vehicle's sysid
OFFBOARD = (6 << 16) | 0
LOITER = (4 << 16) | (3 << 24)


class Client:
    """A pymavlink script on one vehicle's API port (udpin, as MAVSDK), non-blocking."""

    def __init__(self, instance: int) -> None:
        self.instance = instance
        self.sysid = wire.system_id(instance)
        self.conn = mavutil.mavlink_connection(
            f"udpin:127.0.0.1:{ports(instance).api_remote}", source_system=255, source_component=190
        )
        self.heartbeat = None
        self.position = None  # paper frame
        self.global_position = None  # GLOBAL_POSITION_INT
        self.acks: list = []
        self.foreign: set[int] = set()  # sysids seen on this port other than ours

    def poll(self) -> None:
        while True:
            msg = self.conn.recv_match(blocking=False)
            if msg is None:
                return
            if msg.get_type() == "BAD_DATA":
                continue
            if msg.get_srcSystem() != self.sysid:
                self.foreign.add(msg.get_srcSystem())
                continue
            kind = msg.get_type()
            if kind == "HEARTBEAT":
                self.heartbeat = msg
            elif kind == "LOCAL_POSITION_NED":
                self.position = (msg.x, -msg.y, -msg.z)
            elif kind == "GLOBAL_POSITION_INT":
                self.global_position = msg
            elif kind == "COMMAND_ACK":
                self.acks.append(msg)

    @property
    def armed(self) -> bool:
        return bool(self.heartbeat and self.heartbeat.base_mode & m.MAV_MODE_FLAG_SAFETY_ARMED)

    def command(self, command: int, *params: float, target: int | None = None) -> None:
        p = list(params) + [0.0] * (7 - len(params))
        self.conn.mav.command_long_send(self.sysid if target is None else target, 1, command, 0, *p)

    def setpoint(self, position, target: int | None = None) -> None:
        """A position-only SET_POSITION_TARGET_LOCAL_NED (paper frame in, NED on the wire)."""
        mask = 0b110111111000  # ignore velocity, acceleration, yaw, yaw rate
        x, y, z = position
        self.conn.mav.set_position_target_local_ned_send(
            0, self.sysid if target is None else target, 1, m.MAV_FRAME_LOCAL_NED, mask,
            x, -y, -z, 0, 0, 0, 0, 0, 0, 0, 0,
        )  # fmt: skip

    def close(self) -> None:
        self.conn.close()


class GroundStationPort:
    """A socket on the GCS client port, as QGroundControl on 14550: the system ids it hears."""

    def __init__(self, port: int) -> None:
        self.conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255)
        self.heartbeats: set[int] = set()  # system ids of the HEARTBEATs received

    def poll(self) -> None:
        while (msg := self.conn.recv_match(type="HEARTBEAT", blocking=False)) is not None:
            self.heartbeats.add(msg.get_srcSystem())

    def close(self) -> None:
        self.conn.close()


def wait(clients, what: str, predicate, timeout_s: float, each=None) -> None:
    """Poll every client (calling ``each(client)`` every 50 ms) until ``predicate()``."""
    deadline = time.monotonic() + timeout_s
    next_tick = 0.0
    while time.monotonic() < deadline:
        for c in clients:
            c.poll()
        if predicate():
            return
        if each is not None and time.monotonic() >= next_tick:
            next_tick = time.monotonic() + 0.05
            for c in clients:
                each(c)
        time.sleep(0.005)
    raise AssertionError(f"timed out after {timeout_s} s waiting for {what}")


def start_up(config, params_dir) -> tuple[Child, Child]:
    """``quadsitl up --instance 7 --count 2 --spacing 3`` (each vehicle's home 3 m x its instance
    north of the configured one), the command a user types; returns it twice (as the
    process and as its collected output: one Child is both). Each vehicle's COM_OF_LOSS_T is 5 s
    of simulation time: the test is about addressing, and its one thread streams both vehicles'
    setpoints on the wall clock, which a loaded machine (two checkouts testing at once) can stall
    for longer than PX4's 1 s (0.5 s of wall time at --speed 2)."""
    for n in (FIRST, FIRST + 1):
        (params_dir / f"params-{n}.toml").write_text("COM_OF_LOSS_T = 5.0\n")
    cmd = [sys.executable, "-u", "-m", "sitl.cli", "up", "--instance", str(FIRST), "--count", "2",
           "--speed", "2", "--sitl-config", str(config), "--no-log", "--spacing", "3",
           "--params", str(params_dir / "params-{instance}.toml")]  # fmt: skip
    up = Child("quadsitl up", cmd)
    try:
        up.wait_line("Ctrl-C stops every process", 30.0)
    except LaunchError:
        up.stop()
        raise
    return up, up


def stop(up: Child) -> int:
    """Ctrl-C, as a user stops it; killed if it has not stopped within 10 s."""
    up.signal(signal.SIGINT)
    try:
        return up.wait(10.0)
    except LaunchError:
        return up.stop(grace_s=0.0)


class SharedBus:
    """One zenoh session joined to both vehicles' hubs, subscribed to every vehicle's truth."""

    def __init__(self, instances) -> None:
        import zenoh

        hubs = [bus.hub_endpoint(ports(n).zenoh) for n in instances]
        self.session = zenoh.open(bus.session_config(connect=hubs))
        self.sub = self.session.declare_subscriber("quadsitl/*/truth", zenoh.handlers.FifoChannel(100_000))
        self.latest: dict[str, tuple[float, ...]] = {}
        self.rows: dict[str, list] = {}

    def poll(self) -> None:
        while (sample := self.sub.try_recv()) is not None:
            rows = TRUTH_CODEC.decode(sample.payload.to_bytes())
            key = str(sample.key_expr)
            self.rows.setdefault(key, []).extend(tuple(r) for r in rows)
            self.latest[key] = tuple(rows[-1])

    def close(self) -> None:
        self.sub.undeclare()
        self.session.close()


def test_two_vehicles_fly_their_own_setpoints(compat_sitl_config, tmp_path):
    started = time.monotonic()
    proc, output = start_up(compat_sitl_config, tmp_path)
    clients: list[Client] = []
    shared = gcs = None
    try:
        # The banner names each vehicle's endpoints: ports +N, sysid 1+N, its own zenoh keys.
        text = output.output
        for n in (FIRST, FIRST + 1):
            p = ports(n)
            assert f"vehicle {n} is up (MAVLink sysid {n + 1}," in text
            assert f"udpin://0.0.0.0:{p.api_remote}" in text and f"udp {p.gcs_remote}" in text
            assert f"tcp/127.0.0.1:{p.zenoh}   keys quadsitl/{n}/truth" in text
            assert f"1 parameters loaded from {tmp_path / f'params-{n}.toml'}" in text  # COM_OF_LOSS_T
        assert ports(FIRST).gcs_remote == ports(FIRST + 1).gcs_remote  # one GCS port for the fleet

        gcs = GroundStationPort(ports(FIRST).gcs_remote)
        clients = [Client(FIRST), Client(FIRST + 1)]
        one, two = clients
        shared = SharedBus((FIRST, FIRST + 1))

        def both_heard() -> bool:
            gcs.poll()
            return len(gcs.heartbeats) >= 2 and all(c.heartbeat and c.position for c in clients)

        wait(clients, "both heartbeats, on the API ports and the one GCS port", both_heard, 15)
        assert gcs.heartbeats == {one.sysid, two.sysid}
        for c in clients:
            assert c.heartbeat.autopilot == m.MAV_AUTOPILOT_PX4 and c.foreign == set()

        # A command for vehicle 8 (sysid 9) sent to vehicle 7's port: ignored, no ACK from anyone.
        one.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1, target=two.sysid)
        t_end = time.monotonic() + 1.5
        wait(clients, "1.5 s", lambda: time.monotonic() > t_end, 3)
        assert one.acks == [] and not one.armed and not two.armed

        # Both take off, each on its own sysid; the ACKs come from the addressed system only.
        for c in clients:
            c.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1)
        wait(clients, "both armed", lambda: all(c.armed for c in clients), 5)
        for c in clients:
            c.command(m.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, math.nan)
        wait(clients, "both hovering", lambda: all(
            c.heartbeat.custom_mode == LOITER and c.position[2] > 2.4 for c in clients), 20)  # fmt: skip
        for c in clients:
            assert [a.get_srcSystem() for a in c.acks] == [c.sysid] * 2
            assert all(a.result == m.MAV_RESULT_ACCEPTED and a.target_system == 255 for a in c.acks)

        # Offboard at the same time, different setpoints; each also gets a stream of setpoints
        # addressed to the other vehicle, which it must ignore.
        def stream(c: Client) -> None:
            c.setpoint(TARGETS[c.instance])
            c.setpoint(ALIEN, target=clients[1 - clients.index(c)].sysid)

        streaming = time.monotonic() + 0.3
        wait(clients, "setpoint streams", lambda: time.monotonic() > streaming, 2, stream)
        for c in clients:
            c.command(m.MAV_CMD_DO_SET_MODE, 1, 6, 0)
        wait(clients, "both OFFBOARD", lambda: all(c.heartbeat.custom_mode == OFFBOARD for c in clients),
             5, stream)  # fmt: skip

        def arrived() -> bool:
            shared.poll()
            return all(
                c.position and math.dist(c.position, TARGETS[c.instance]) < 0.03
                and math.dist(shared.latest.get(f"quadsitl/{c.instance}/truth", (0,) * 4)[1:4],
                              TARGETS[c.instance]) < 0.03
                for c in clients
            )  # fmt: skip

        wait(clients, "both at their own setpoints", arrived, 25, stream)
        settle_end = time.monotonic() + 1.0
        wait(clients, "1 s at the setpoints", lambda: time.monotonic() > settle_end, 3, stream)
        shared.poll()

        # On the map each vehicle stands at its own home (3 m x its instance north of the configured
        # one, --spacing 3) plus where it flew in its local frame.
        home = load_sitl(str(compat_sitl_config)).home
        metres_per_degree = frames.EARTH_RADIUS_M * math.pi / 180.0
        for c in clients:
            g, (x, y, _) = c.global_position, TARGETS[c.instance]
            north = (g.lat * 1e-7 - home[0]) * metres_per_degree
            east = (g.lon * 1e-7 - home[1]) * metres_per_degree * math.cos(math.radians(home[0]))
            assert north == pytest.approx(3.0 * c.instance + x, abs=0.05)
            assert east == pytest.approx(-y, abs=0.05)  # (paper y: west)

        # Each vehicle's truth went only to its own setpoint, never towards the other's ALIEN one.
        assert set(shared.rows) == {f"quadsitl/{FIRST}/truth", f"quadsitl/{FIRST + 1}/truth"}
        for c in clients:
            track = shared.rows[f"quadsitl/{c.instance}/truth"]
            assert math.dist(track[-1][1:4], TARGETS[c.instance]) < 0.03
            assert min(math.dist(r[1:4], ALIEN) for r in track) > 2.5
            assert c.foreign == set()  # nothing from the other vehicle on this port

        for c in clients:
            c.command(m.MAV_CMD_NAV_LAND)
        wait(clients, "both landed and disarmed", lambda: not any(c.armed for c in clients), 25)
    except AssertionError as exc:
        raise AssertionError(f"{exc}\n--- quadsitl up:\n" + output.tail(40)) from None
    finally:
        for c in clients:
            c.close()
        if shared is not None:
            shared.close()
        if gcs is not None:
            gcs.close()
        rc = stop(proc)
    assert rc == 0, output.tail(20)
    assert any(line.startswith("quadsitl: stopped") for line in output.lines)
    assert time.monotonic() - started < 60


def test_a_vehicle_restarts_at_once_on_its_ports(compat_sitl_config):
    """Connections of a vehicle just stopped linger in TIME_WAIT on its zenoh port; the launcher's
    port check must not mistake that for a vehicle still running (zenoh itself binds fine)."""
    zenoh_port = ports(9).zenoh
    server = socket.socket()
    server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    server.bind((wire.LOOPBACK, zenoh_port))
    server.listen()
    peer = socket.create_connection((wire.LOOPBACK, zenoh_port))
    accepted, _ = server.accept()
    accepted.close()  # the server side closes first: its end goes to TIME_WAIT
    server.close()
    peer.close()
    check_ports(VehicleSpec(instance=9, sitl_config=str(compat_sitl_config)))  # no LaunchError
    live = socket.socket()  # a vehicle really running: its listener (zenoh sets SO_REUSEADDR too)
    live.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    live.bind((wire.LOOPBACK, zenoh_port))
    live.listen()
    try:
        with pytest.raises(LaunchError, match=re.escape(f"TCP port {zenoh_port}")):
            check_ports(VehicleSpec(instance=9, sitl_config=str(compat_sitl_config)))
    finally:
        live.close()
