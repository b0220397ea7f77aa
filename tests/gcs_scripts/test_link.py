"""The MAVLink client helper against a scripted vehicle (real pymavlink frames both ways)."""

from __future__ import annotations

import math
import time

import pytest
from pymavlink.dialects.v20 import common as mavlink2

from gcs_scripts.link import CommandFailed, Link, LinkTimeout, PositionTarget, SetpointStream, mavutil

from .helpers import Vehicle, parse


class ScriptedConnection:
    """Stands in for a mavutil connection: hands out queued messages, captures what is sent."""

    def __init__(self, on_send=None) -> None:
        self.inbox: list = []
        self.sent_bytes = bytearray()
        self.mav = mavlink2.MAVLink(self, srcSystem=255, srcComponent=190)
        self.on_send = on_send
        self.address = "scripted"

    def write(self, data: bytes) -> None:  # called by self.mav for every message sent
        self.sent_bytes += data
        if self.on_send is not None:
            for msg in parse([bytes(data)]):
                self.on_send(self, msg)

    def recv_msg(self):
        return self.inbox.pop(0) if self.inbox else None

    def deliver(self, frames: list[bytes]) -> None:
        self.inbox.extend(parse(frames))

    def sent(self, kind: str) -> list:
        return [m for m in parse([bytes(self.sent_bytes)]) if m.get_type() == kind]

    def close(self) -> None:
        pass


VEHICLE = Vehicle(instance=0)


def _ack(command: int, result: int) -> bytes:
    return VEHICLE.pack(mavlink2.MAVLink_command_ack_message(command, result, 0, 0, 255, 190))


def test_command_ack_retries_then_accepts() -> None:
    attempts = []

    def vehicle(conn, msg):
        if msg.get_type() == "COMMAND_LONG":
            attempts.append(msg.confirmation)
            if len(attempts) == 2:  # the first one is "lost"
                conn.deliver([_ack(msg.command, 0)])

    conn = ScriptedConnection(vehicle)
    link = Link(conn, instance=0)
    assert link.command_long(400, (1.0,), ack_timeout_s=0.05) == 0
    assert attempts == [0, 1]  # confirmation counts the retransmissions


def test_refusal_raises_with_the_vehicles_reason() -> None:
    def vehicle(conn, msg):
        if msg.get_type() == "COMMAND_LONG":
            conn.deliver([_ack(msg.command, 2), VEHICLE.statustext("OFFBOARD refused: no setpoint stream")])

    link = Link(ScriptedConnection(vehicle), instance=0)
    with pytest.raises(
        CommandFailed, match="MAV_CMD_DO_SET_MODE DENIED: OFFBOARD refused: no setpoint stream"
    ):
        link.set_mode("OFFBOARD")


def test_no_ack_at_all_is_reported() -> None:
    link = Link(ScriptedConnection(), instance=0)
    with pytest.raises(CommandFailed, match="no COMMAND_ACK after 2 attempts"):
        link.command_long(400, (1.0,), ack_timeout_s=0.02, attempts=2)


def test_wait_until_counts_simulation_time() -> None:
    conn = ScriptedConnection()
    conn.deliver([VEHICLE.local_position(10.0 + 0.1 * k, 0.0) for k in range(40)])  # 4 s of sim time
    link = Link(conn, instance=0)
    start = time.monotonic()
    with pytest.raises(LinkTimeout, match="after 2 s of simulation time waiting for nothing"):
        link.wait_until(lambda lk: False, sim_timeout_s=2.0, what="nothing")
    assert time.monotonic() - start < 1.0  # sim time, not wall time
    assert link.now() == pytest.approx(13.9)  # the burst arrived in one poll: counted from 10.0


def test_wait_until_detects_a_stopped_simulation() -> None:
    conn = ScriptedConnection()
    conn.deliver([VEHICLE.local_position(3.0, 0.0), VEHICLE.statustext("simulator lost: no frame for 1 s")])
    link = Link(conn, instance=0, stall_wall_s=0.2)
    with pytest.raises(LinkTimeout, match=r"simulation time stopped at t=3\.00 s .*simulator lost"):
        link.wait_until(lambda lk: False, sim_timeout_s=60.0, what="takeoff")


def test_reactive_stream_sends_one_ned_setpoint_per_sample() -> None:
    conn = ScriptedConnection()
    link = Link(conn, instance=0)
    stream = SetpointStream(link, lambda t: PositionTarget((1.0, 2.0, 3.0 + t), yaw_rad=math.pi / 2)).start()
    conn.deliver([VEHICLE.local_position(5.0 + 0.02 * k, 0.0) for k in range(5)])
    conn.deliver([VEHICLE.attitude(5.1, 0, 0, 0)])  # not a position sample: no setpoint
    link.poll()
    targets = conn.sent("SET_POSITION_TARGET_LOCAL_NED")
    assert stream.sent == len(targets) == 5
    last = targets[-1]
    assert last.time_boot_ms == 5080 and last.coordinate_frame == mavutil.mavlink.MAV_FRAME_LOCAL_NED
    assert (last.x, last.y) == (1.0, -2.0) and last.z == pytest.approx(-(3.0 + 5.08), abs=1e-5)
    assert last.yaw == pytest.approx(-math.pi / 2) and last.type_mask == 8 + 16 + 32 + 64 + 128 + 256 + 2048
    assert (last.target_system, last.target_component) == (1, 1)
    stream.stop()
    conn.deliver([VEHICLE.local_position(6.0, 0.0)])
    link.poll()
    assert len(conn.sent("SET_POSITION_TARGET_LOCAL_NED")) == 5


def test_telemetry_accessors_in_both_frames() -> None:
    conn = ScriptedConnection()
    loiter = 4 << 16 | 3 << 24
    conn.deliver(
        [
            VEHICLE.local_position(1.0, 1.0, 2.0, -3.0),
            VEHICLE.heartbeat(True, custom_mode=loiter),
            VEHICLE.extended_sys_state(2),
            VEHICLE.attitude(1.0, 0.1, 0.2, 0.3),
        ]
    )
    link = Link(conn, instance=0)
    link.poll()
    assert link.position_ned == (1.0, 2.0, -3.0)
    assert link.position_paper == (1.0, -2.0, 3.0)  # z up, y left
    assert link.yaw_paper == pytest.approx(-0.3)
    assert link.armed and link.mode == "AUTO.LOITER" and link.landed_state_name == "IN_AIR"
    assert conn.sent("HEARTBEAT")[0].type == mavutil.mavlink.MAV_TYPE_GCS  # a GCS announces itself


def test_a_refusal_longer_than_one_statustext_is_named_whole() -> None:
    """A reason of more than 50 bytes comes in chunks (MAVLink 2 ``id``/``chunk_seq``): the client
    joins them before naming the refusal."""
    reason = "arming refused: estimator not ready: vertical position not converged (1-sigma 0.75 m > 0.3 m)"
    raw = reason.encode()
    chunks = [raw[i : i + 50] for i in range(0, len(raw), 50)]

    def vehicle(conn, msg):
        if msg.get_type() == "COMMAND_LONG":
            texts = [VEHICLE.pack(mavlink2.MAVLink_statustext_message(4, chunk, 7, seq))
                     for seq, chunk in enumerate(chunks)]  # fmt: skip
            conn.deliver([_ack(msg.command, 2), *texts])

    link = Link(ScriptedConnection(vehicle), instance=0)
    with pytest.raises(CommandFailed, match=r"DENIED: arming refused: .*\(1-sigma 0\.75 m > 0\.3 m\)$"):
        link.arm()
    assert [text for _, _, text in link.statustext] == [reason]
