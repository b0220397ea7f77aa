"""Hostile traffic on a real socket: a vehicle flown over UDP by one ground station while another
client (``python -m sitl.spray hostile``, its own process, 1,000 datagrams a second from 300
source ports) sprays datagrams at the same GCS port that must each be refused or ignored. The
flight goes as commanded (takeoff, offboard to a point, land there), telemetry keeps flowing
(heartbeat gaps in simulation time), both processes survive, and the autopilot's info counts what
it refused and dropped with no handler fault. Instance 93. The real-time factor under such
traffic, and under a flood: benchmarks/hostile_load.py.
"""

from __future__ import annotations

import json
import math
import re
import sys
import time

import pytest
from pymavlink.dialects.v20 import common as m

from autopilot.commander.modes import FlightMode
from quadcommon import bus, wire
from sitl.launcher import Child, VehicleSpec

from .harness import UdpGcs, running

pytestmark = pytest.mark.processes  # (tests/conftest.py: the markers)

INSTANCE = 93
OFFBOARD = FlightMode.OFFBOARD.custom_mode
TARGET = (1.0, 1.0, 2.0)  # paper frame: x forward, y left, z up (m)


class WatchedGcs(UdpGcs):
    """UdpGcs that also keeps the simulation time of every HEARTBEAT."""

    def __init__(self, *args) -> None:
        super().__init__(*args)
        self.heartbeat_times: list[float] = []

    def poll(self, timeout: float = 0.05):
        msg = super().poll(timeout)
        if msg is not None and msg.get_type() == "HEARTBEAT" and msg.get_srcSystem() == self.system_id:
            self.heartbeat_times.append(self.sim_time)
        return msg

    def command(self, command: int, *params: float, timeout: float = 2.0, attempts: int = 5):
        """COMMAND_LONG resent with ``confirmation`` + 1 until ACKed, as ground stations do: under a
        flood the kernel drops datagrams from the full socket buffer, the pilot's among them."""
        p = list(params) + [0.0] * (7 - len(params))
        for confirmation in range(attempts):
            self.acks.clear()
            self.conn.mav.command_long_send(self.system_id, 1, command, confirmation, *p)
            try:
                self.wait(lambda g: any(a.command == command for a in g.acks), 1e9, timeout, f"ACK {command}")
            except AssertionError:
                continue
            return next(a for a in self.acks if a.command == command)
        raise AssertionError(f"no COMMAND_ACK for command {command} after {attempts} attempts")

    def start_offboard(self, attempts: int = 5):
        """OFFBOARD as MAVSDK's offboard.start() does it: setpoints streamed first (0.3 s of
        simulation), then the mode; again if refused (the flood can cost the stream datagrams)."""
        for _ in range(attempts):
            start = self.sim_time
            self.stream_setpoint_until(lambda g, t0=start: g.sim_time - t0 > 0.3, "0.3 s of setpoints")
            ack = self.command(m.MAV_CMD_DO_SET_MODE, 1, 6, 0)
            if ack.result == m.MAV_RESULT_ACCEPTED:
                return ack
        return ack

    def stream_setpoint_until(self, predicate, what: str, sim_timeout: float = 25.0) -> None:
        start = self.sim_time
        while self.sim_time - start < sim_timeout:
            msg = self.poll()
            if msg is not None and msg.get_type() == "LOCAL_POSITION_NED":
                self.send_position_setpoint(*TARGET)
                if predicate(self):
                    return
        raise AssertionError(f"timed out: {what} (position {self.position()})")


def autopilot_info(session) -> dict:
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline:
        for reply in session.get(wire.zenoh_key(INSTANCE, "autopilot/info"), timeout=1.0):
            if reply.ok is not None:
                return json.loads(reply.ok.payload.to_bytes())
        time.sleep(0.1)
    raise AssertionError("the autopilot's info queryable never answered")


@pytest.mark.timeout(180)
def test_a_flight_under_a_hostile_spray_goes_as_commanded():
    spec = VehicleSpec(instance=INSTANCE, scenario="hover", speed="2")
    ports = spec.ports()
    with running(spec) as (launcher, _):
        gcs = WatchedGcs(ports.gcs_remote, wire.system_id(INSTANCE))
        session = bus.open_peer(ports.zenoh)
        spray = Child("spray", [sys.executable, "-u", "-m", "sitl.spray", "hostile", "--instance",
                                str(INSTANCE), "--datagrams", "12000", "--sources", "300", "--rate", "1000",
                                "--seconds", "12"])  # fmt: skip
        try:
            gcs.wait(lambda g: "LOCAL_POSITION_NED" in g.last, what="telemetry")
            assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == m.MAV_RESULT_ACCEPTED
            ack = gcs.command(m.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, 488.0 + 2.0)
            assert ack.result == m.MAV_RESULT_ACCEPTED
            gcs.wait(lambda g: g.position()[2] > 1.95, sim_timeout=15, what="takeoff")
            assert gcs.start_offboard().result == m.MAV_RESULT_ACCEPTED
            gcs.stream_setpoint_until(lambda g: math.dist(g.position(), TARGET) < 0.05, "reach the target")
            ack = gcs.command(m.MAV_CMD_NAV_LAND, 0, 0, 0, math.nan, math.nan, math.nan, math.nan)
            assert ack.result == m.MAV_RESULT_ACCEPTED
            gcs.wait(lambda g: g.last["HEARTBEAT"].base_mode & m.MAV_MODE_FLAG_SAFETY_ARMED == 0,
                     sim_timeout=20, what="landed and disarmed")  # fmt: skip
            assert spray.wait(30.0) == 0, spray.tail()
            sent = re.search(r"sent (\d+) hostile datagrams", spray.output)
            assert sent and int(sent.group(1)) >= 5000, spray.tail()
            x, y, z = gcs.position()
            assert math.dist((x, y), TARGET[:2]) < 0.1 and abs(z) < 0.05, (x, y, z)
            gaps = [b - a for a, b in zip(gcs.heartbeat_times, gcs.heartbeat_times[1:], strict=False)]
            assert len(gaps) >= 8 and max(gaps) <= 1.5, gaps
            info = autopilot_info(session)
            assert info["faults"] == {}
            assert sum(info["refused"].values()) > 1000 and any("ARM_DISARM" in k for k in info["refused"])
            assert info["received"].get("bad data", 0) > 100
            assert all(len(peers) <= 16 for peers in info["peers"].values())
            assert all(child.alive for child in launcher.children)
        finally:
            spray.stop()
            gcs.close()
            session.close()
