"""MAVLink log download (LOG_REQUEST_LIST / LOG_ENTRY / LOG_REQUEST_DATA / LOG_DATA /
LOG_REQUEST_END / LOG_ERASE) on the in-process stack, in simulation time, with pymavlink.

The real clients (MAVSDK 4 and 3, MAVProxy, pymavlink over UDP) are in tests/compat and
tests/sitl/test_flight_log_process.py; here every request a client could send, bad ones too.
"""

from __future__ import annotations

import random
import struct
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import common as m

from autopilot.core import LOG_MESSAGES_PER_FRAME
from autopilot.mavlink.codec import Encoder
from autopilot.mavlink.log_transfer import CHUNK, LogTransfer, NoLogs
from sitl.inprocess import GCS_LINK, StackConnection
from tests.stack import make_stack
from tests.ulog_check import check_ulog

ALL = 0xFFFFFFFF


class LogClient:
    """A ground station that keeps every LOG_ENTRY / LOG_DATA / STATUSTEXT the vehicle sends it."""

    def __init__(self, stack, link: int = GCS_LINK) -> None:
        self.stack = stack
        self.conn = StackConnection(stack, link)
        self.mav = self.conn.mav
        self.sysid = stack.autopilot.system_id
        self.entries: list = []
        self.data: list = []
        self.texts: list[str] = []
        self.data_per_frame: list[int] = []

    def pump(self, seconds: float, until=None) -> None:
        """Run the stack for ``seconds`` of simulation time (or until ``until(self)``)."""
        end = self.stack.t + seconds
        while self.stack.t < end and not (until and until(self)):
            frames = self.stack.frames
            before = len(self.data)
            while self.stack.frames == frames:
                msg = self.conn.recv_msg()
                if msg is None:
                    continue
                kind = msg.get_type()
                if kind == "LOG_ENTRY":
                    self.entries.append(msg)
                elif kind == "LOG_DATA":
                    self.data.append(msg)
                elif kind == "STATUSTEXT":
                    self.texts.append(msg.text)
            self.data_per_frame.append(len(self.data) - before)

    def list(self, start: int = 0, end: int = 0xFFFF, target: int | None = None) -> list:
        self.entries.clear()
        self.mav.log_request_list_send(self.sysid if target is None else target, 1, start, end)
        self.pump(0.2)
        return list(self.entries)

    def download(self, log_id: int, size: int, seconds: float = 20.0) -> bytes:
        """The whole log as a client reassembles it (chunks placed at their offsets)."""
        self.data.clear()
        self.mav.log_request_data_send(self.sysid, 1, log_id, 0, ALL)
        self.pump(seconds, until=lambda c: sum(d.count for d in c.data) >= size)
        return assemble(self.data, size)


def assemble(chunks, size: int) -> bytes:
    out = bytearray(size)
    got = 0
    for d in chunks:
        out[d.ofs : d.ofs + d.count] = bytes(d.data[: d.count])
        got += d.count
    assert got == size, f"{got} of {size} bytes"
    return bytes(out)


def short_flights(stack, count: int, seconds: float = 0.4) -> None:
    """``count`` logs: armed for ``seconds`` on the ground, then disarmed."""
    gcs = LogClient(stack, GCS_LINK)
    gcs.pump(0.1)
    for _ in range(count):
        for value in (1.0, 0.0):
            gcs.mav.command_long_send(
                gcs.sysid, 1, m.MAV_CMD_COMPONENT_ARM_DISARM, 0, value, 0, 0, 0, 0, 0, 0
            )
            gcs.pump(seconds)
    stack.run_for(0.1)


@pytest.fixture
def two_logs(tmp_path):
    stack = make_stack(log_dir=str(tmp_path))
    short_flights(stack, 2)
    stack.run_for(0.1)  # the writer has every byte (each housekeeping tick hands them over)
    paths = sorted(tmp_path.glob("*/*.ulg"))
    assert len(paths) == 2
    return stack, paths


def test_no_logs_is_one_entry_with_num_logs_0(tmp_path):
    for stack in (make_stack(), make_stack(log_dir=str(tmp_path))):  # no flight log / none yet
        client = LogClient(stack)
        (entry,) = client.list()
        assert (entry.id, entry.num_logs, entry.last_log_num, entry.size) == (0, 0, 0, 0)


def test_logs_are_listed_and_downloaded_byte_identical(two_logs):
    stack, paths = two_logs
    client = LogClient(stack)
    entries = client.list()
    assert [(e.id, e.num_logs, e.last_log_num) for e in entries] == [(0, 2, 1), (1, 2, 1)]
    assert [e.size for e in entries] == [p.stat().st_size for p in paths]
    assert all(e.time_utc > 1_600_000_000 for e in entries)  # no clock in-process: the file's time
    for entry, path in zip(entries, paths, strict=True):
        assert client.download(entry.id, entry.size) == path.read_bytes()
        assert all(d.id == entry.id and d.count <= CHUNK and d.ofs % CHUNK == 0 for d in client.data)
        check_ulog(path, flight_review=False)
    # a range: entries start..end only (MAVSDK asks for all, QGC for ranges when it re-lists)
    assert [e.id for e in client.list(1, 1)] == [1]
    assert [e.id for e in client.list(5, 9)] == [1]  # beyond the logs: the one it clamps to
    assert [e.id for e in client.list(1, 0)] == [1]  # an end before the start: the start's entry
    assert [e.id for e in client.list(0, 7)] == [0, 1]  # an end past the last log stops there
    assert stack.autopilot.faults.counts == {}


def test_bad_requests_get_px4s_answers_and_never_an_exception(two_logs):
    stack, paths = two_logs
    client = LogClient(stack)
    entries = client.list()
    size = entries[0].size
    send = client.mav.log_request_data_send

    def answers(log_id, ofs, count, target=None):
        client.data.clear()
        send(client.sysid if target is None else target, 1, log_id, ofs, count)
        client.pump(0.3)
        return [(d.id, d.ofs, d.count) for d in client.data]

    assert answers(7, 0, ALL) == []  # an id not in the listing: ignored, as PX4
    assert answers(0, size, ALL) == [(0, size, 0)]  # at the end: one LOG_DATA with count 0 (EOF)
    assert answers(0, size + 12345, 100) == [(0, size + 12345, 0)]  # past the end
    assert answers(0, 90, 0) == [(0, 90, 0)]  # count 0
    tail = answers(0, size - 100, ALL)  # a huge count: up to the end, no further
    assert [c for _, _, c in tail] == [90, 10] and tail[-1][1] == size - 10
    assert answers(1, 0, ALL, target=42) == []  # another vehicle's request
    assert answers(0, 45, 20) == [(0, 45, 20)]  # an unaligned offset and a short count
    assert client.data[0].data[:20] == list(paths[0].read_bytes()[45:65])
    # LOG_REQUEST_END stops a transfer in the middle
    client.data.clear()
    send(client.sysid, 1, 1, 0, ALL)
    client.pump(0.01)
    client.mav.log_request_end_send(client.sysid, 1)
    client.pump(0.01)
    stopped = len(client.data)
    client.pump(0.2)
    assert 0 < stopped < entries[1].size // CHUNK and len(client.data) == stopped
    # hostile values in every field of every log message
    rng = random.Random(23)
    for _ in range(300):
        kind = rng.randrange(4)
        u16, u32 = rng.randrange(0x10000), rng.choice((0, 1, 89, 90, 91, ALL, rng.randrange(ALL)))
        if kind == 0:
            client.mav.log_request_list_send(client.sysid, rng.choice((0, 1)), u16, rng.randrange(0x10000))
        elif kind == 1:
            send(client.sysid, rng.choice((0, 1)), rng.choice((0, 1, u16)), u32, rng.choice((0, 1, u32)))
        elif kind == 2:
            client.mav.log_request_end_send(client.sysid, 1)
        else:
            client.mav.log_request_data_send(0, 0, 0xFFFF, ALL, ALL)
        client.pump(0.004)
    client.pump(0.5)
    assert stack.autopilot.faults.counts == {} and all(p.exists() for p in paths)
    assert max(client.data_per_frame) <= LOG_MESSAGES_PER_FRAME


def test_two_ground_stations_download_at_once(two_logs):
    stack, paths = two_logs
    sent_in_frame: dict[int, int] = {}  # every LOG_DATA the vehicle sends, by frame

    def watch(record) -> None:
        if record.data[7:10] == bytes((m.MAVLINK_MSG_ID_LOG_DATA, 0, 0)):
            sent_in_frame[stack.frames] = sent_in_frame.get(stack.frames, 0) + 1

    stack.observers.append(watch)
    first, second = LogClient(stack, GCS_LINK), LogClient(stack, GCS_LINK)
    entries = first.list()
    second.list()
    for client, log_id in ((first, 0), (second, 1)):
        client.data.clear()
        client.mav.log_request_data_send(client.sysid, 1, log_id, 0, ALL)
    sizes = [e.size for e in entries]
    while sum(d.count for d in first.data) < sizes[0] or sum(d.count for d in second.data) < sizes[1]:
        first.pump(0.002)  # both stations' messages are delivered as the stack steps
        second.pump(0.002)
        assert stack.t < 60.0
    assert assemble(first.data, sizes[0]) == paths[0].read_bytes()
    assert assemble(second.data, sizes[1]) == paths[1].read_bytes()
    # the stations took turns: the link's budget per frame is shared, not doubled
    assert max(sent_in_frame.values()) == LOG_MESSAGES_PER_FRAME


def test_the_log_being_written_is_served_up_to_its_listed_size(tmp_path):
    stack = make_stack(log_dir=str(tmp_path))
    stack.autopilot.params.set("SDLOG_MODE", 2)
    stack.run_for(1.0)
    client = LogClient(stack)
    (entry,) = client.list()
    got = client.download(0, entry.size)
    (path,) = tmp_path.glob("*/*.ulg")
    assert path.stat().st_size > entry.size  # it went on growing
    assert got == path.read_bytes()[: entry.size]
    part = tmp_path / "downloaded.ulg"
    part.write_bytes(got)
    check_ulog(part, flight_review=False)  # cut at a hand-over: whole messages, a readable ULog


def test_erase_is_refused_while_armed_and_keeps_the_log_being_written(two_logs):
    stack, paths = two_logs
    client = LogClient(stack)
    client.mav.command_long_send(client.sysid, 1, m.MAV_CMD_COMPONENT_ARM_DISARM, 0, 1, 0, 0, 0, 0, 0, 0)
    client.pump(0.1)
    client.mav.log_erase_send(client.sysid, 1)
    client.pump(0.1)
    assert "log erase refused: the vehicle is armed" in client.texts
    assert all(p.exists() for p in paths)
    assert len(client.list()) == 3  # the two, and the one being written
    client.mav.command_long_send(client.sysid, 1, m.MAV_CMD_COMPONENT_ARM_DISARM, 0, 0, 0, 0, 0, 0, 0, 0)
    stack.autopilot.params.set("SDLOG_MODE", 2)  # logging again at once: a log open during the erase
    client.pump(0.2)
    client.mav.log_erase_send(client.sysid, 1)
    client.pump(0.1)
    assert not any(p.exists() for p in paths)
    (entry,) = client.list()
    assert entry.num_logs == 1 and Path(stack.log_directory.writing).exists()


def test_log_data_is_framed_as_pymavlink_frames_it_signed_or_not():
    encoder = Encoder(1, 1)
    transfer = LogTransfer(NoLogs(), encoder, [], lambda *a: None, lambda: False, 1, lambda: 0.0)
    for chunk, offset in ((bytes(range(90)), 900), (b"abc", 12), (b"", 2**32 - 1), (bytes(90), 0)):
        seq = encoder.mav.seq
        fast = transfer.log_data(3, offset, chunk)
        encoder.mav.seq = seq
        expected = encoder.pack(m.MAVLink_log_data_message(3, offset, len(chunk), chunk.ljust(90, b"\0")))
        assert fast == expected
    encoder.mav.signing.secret_key = bytes(32)
    encoder.mav.signing.sign_outgoing = True
    encoder.mav.signing.link_id = 0
    encoder.mav.signing.timestamp = 1
    signed = transfer.log_data(3, 0, b"x")
    assert signed[2] & 1 and len(signed) == 12 + struct.unpack_from("<B", signed, 1)[0] + 13
