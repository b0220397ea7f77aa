"""MAVLink FTP on the in-process stack, in simulation time: the file system PX4 serves (the flight
logs under /log, the parameter file), read as QGC and MAVSDK read it (listings, plain reads,
bursts, CRC), written where it may be, and every hostile request refused at its edge.

The real client (MAVSDK-Python 4's Ftp plugin against ``quadsitl up``) is in tests/compat/test_mavsdk.py.
"""

from __future__ import annotations

import errno
import os
import random
import struct
from pathlib import Path

import pytest
from pymavlink.dialects.v20 import common as m

from autopilot.core import FTP_MESSAGES_PER_FRAME
from autopilot.mavlink import ftp
from autopilot.mavlink.ftp import BURST_BYTES, DATA_MAX, HEADER, PAYLOAD_LEN, SESSION_IDLE_S
from sitl.inprocess import API_LINK, GCS_LINK
from tests.stack import Gcs, make_stack

LIST, OPEN_RO, READ, CREATE, WRITE, REMOVE = 3, 4, 5, 6, 7, 8
MKDIR, RMDIR, OPEN_WO, TRUNCATE, RENAME, CRC, BURST = 9, 10, 11, 12, 13, 14, 15
TERMINATE, RESET = 1, 2
ACK, NAK = 128, 129
E_FAIL, E_ERRNO, E_SIZE, E_SESSION, E_NO_SESSIONS, E_EOF, E_UNKNOWN = 1, 2, 3, 4, 5, 6, 7
E_EXISTS, E_PROTECTED, E_NOT_FOUND = 8, 9, 10


class Answer:
    def __init__(self, msg) -> None:
        raw = bytes(msg.payload)
        (self.seq, self.session, self.opcode, self.size, self.req_opcode, self.burst_complete, _,
         self.offset) = HEADER.unpack_from(raw)  # fmt: skip
        self.data = raw[HEADER.size : HEADER.size + self.size]
        self.target = (msg.target_system, msg.target_component)

    @property
    def error(self) -> int | None:
        return self.data[0] if self.opcode == NAK else None

    @property
    def u32(self) -> int:
        return struct.unpack("<I", self.data[:4])[0]


class FtpClient:
    """A ground station speaking MAVLink FTP as MAVSDK and QGC do, one request at a time."""

    def __init__(self, stack, link: int = API_LINK, system_id: int = 255) -> None:
        self.stack = stack
        self.station = stack.ground_station(link, listen=False, system_id=system_id)
        self.seq = 0
        self.answers: list[Answer] = []  # every FTP answer, in order

    def send(self, payload: bytes, target: int = 1) -> None:
        self.station.mav.file_transfer_protocol_send(0, target, 1, list(payload.ljust(PAYLOAD_LEN, b"\0")))

    def pump(self, frames: int = 1) -> None:
        for _ in range(frames):
            self.stack.step()
            inbox = self.station.inbox
            while inbox:
                msg = inbox.popleft()
                if msg.get_type() == "FILE_TRANSFER_PROTOCOL":
                    self.answers.append(Answer(msg))

    def request(self, opcode: int, data: bytes = b"", offset: int = 0, session: int = 0,
                size: int | None = None, seq: int | None = None) -> Answer:  # fmt: skip
        """Send one request; its answer (AssertionError if none within 0.5 s of simulation)."""
        if seq is None:
            seq, self.seq = self.seq, (self.seq + 1) & 0xFFFF
        payload = HEADER.pack(seq, session, opcode, len(data) if size is None else size, 0, 0, 0, offset)
        self.last_payload = payload + data
        self.send(self.last_payload)
        return self.wait_for((seq + 1) & 0xFFFF)

    def wait_for(self, seq: int, frames: int = 250) -> Answer:
        for _ in range(frames):
            for answer in self.answers:
                if answer.seq == seq:
                    self.answers.remove(answer)
                    return answer
            self.pump()
        raise AssertionError(f"no FTP answer numbered {seq}")

    def listing(self, path: str) -> list[str]:
        """Every entry of ``path`` (MAVSDK's loop: the next offset until EOF or an empty answer)."""
        entries: list[str] = []
        while True:
            answer = self.request(LIST, path.encode() + b"\0", offset=len(entries))
            if answer.opcode == NAK:
                assert answer.error == E_EOF, answer.error
                return entries
            if answer.size == 0:
                return entries
            entries += [e.decode() for e in answer.data.split(b"\0") if e]

    def open(self, path: str) -> int:
        answer = self.request(OPEN_RO, path.encode() + b"\0")
        assert answer.opcode == ACK, answer.error
        assert answer.size == 4 and answer.session == 0
        return answer.u32

    def read_all(self, path: str) -> bytes:
        size = self.open(path)
        out = bytearray()
        while len(out) < size:
            answer = self.request(READ, offset=len(out), size=min(DATA_MAX, size - len(out)))
            assert answer.opcode == ACK and answer.offset == len(out), answer.error
            out += answer.data
        assert self.request(TERMINATE).opcode == ACK
        return bytes(out)

    def burst_all(self, path: str, chunks_per_frame: list[int] | None = None) -> bytes:
        """A burst download as MAVSDK's: a new burst where one completes, until the end."""
        size = self.open(path)
        out = bytearray()
        while len(out) < size:
            start_seq = self.seq
            self.request_burst(len(out))
            expected = (start_seq + 1) & 0xFFFF
            while True:
                before = len(self.answers)
                self.pump()
                if chunks_per_frame is not None:
                    chunks_per_frame.append(len(self.answers) - before)
                done = False
                for answer in list(self.answers):
                    self.answers.remove(answer)
                    assert answer.seq == expected, (answer.seq, expected)  # numbered request + 1, + 2...
                    expected = (expected + 1) & 0xFFFF
                    assert answer.req_opcode == BURST
                    if answer.opcode == NAK:
                        assert answer.error == E_EOF and answer.offset == size
                        done = True
                        break
                    assert answer.offset == len(out)
                    out += answer.data
                    if answer.burst_complete:
                        done = True
                        break
                if done:
                    break
        assert self.request(TERMINATE).opcode == ACK
        return bytes(out)

    def request_burst(self, offset: int) -> None:
        seq, self.seq = self.seq, (self.seq + 1) & 0xFFFF
        self.send(HEADER.pack(seq, 0, BURST, 0, 0, 0, 0, offset))


def reference_crc32(data: bytes) -> int:
    """MAVLink FTP's CRC-32, bit by bit: reflected polynomial 0xEDB88320, starting from 0, no final
    inversion (PX4's crc32part; MAVSDK's Crc32)."""
    crc = 0
    for byte in data:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ (0xEDB88320 if crc & 1 else 0)
    return crc


def flights(stack, count: int) -> None:
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    for _ in range(count):
        for value in (1.0, 0.0):
            assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, value).result == m.MAV_RESULT_ACCEPTED
            stack.run_for(0.4)
    gcs.close()
    stack.run_for(0.1)  # the writer has every byte


@pytest.fixture
def vehicle(tmp_path):
    """A vehicle with two flight logs under tmp/log, a parameter file, and a file beside its log
    directory that nothing may reach."""
    params = tmp_path / "params.toml"
    params.write_text("MIS_TAKEOFF_ALT = 3.0\n")
    (tmp_path / "secret.txt").write_text("not for the ground station\n")
    stack = make_stack(log_dir=str(tmp_path / "log"), params_file=str(params))
    flights(stack, 2)
    logs = sorted((tmp_path / "log").glob("*/*.ulg"))
    assert len(logs) == 2
    return stack, tmp_path, logs


def test_the_root_lists_the_logs_and_the_parameter_file(vehicle):
    stack, tmp, logs = vehicle
    client = FtpClient(stack)
    assert client.listing("/") == ["Dlog", f"Fparams.toml\t{(tmp / 'params.toml').stat().st_size}"]
    assert client.listing("") == client.listing("/") == client.listing("//./")
    session = logs[0].parent.name  # sess001: no wall clock in-process (PX4's numbering)
    assert client.listing("/log") == [f"D{session}"]
    assert client.listing(f"/log/{session}") == [f"F{p.name}\t{p.stat().st_size}" for p in logs]
    assert client.listing(f"log/{session}/") == client.listing(f"/log/{session}")  # relative, as PX4 SITL


def test_a_log_reads_byte_identical_by_plain_reads_by_bursts_and_by_crc(vehicle):
    stack, tmp, logs = vehicle
    client = FtpClient(stack)
    path = f"/log/{logs[1].parent.name}/{logs[1].name}"
    original = logs[1].read_bytes()
    assert len(original) > BURST_BYTES  # more than one burst
    assert client.read_all(path) == original
    per_frame: list[int] = []
    assert client.burst_all(path, per_frame) == original
    assert max(per_frame) <= FTP_MESSAGES_PER_FRAME  # paced: a download never floods the link
    crc = client.request(CRC, path.encode() + b"\0")
    assert crc.opcode == ACK and crc.size == 4 and crc.u32 == ftp.crc32(original)
    small = b"123456789" * 7
    assert ftp.crc32(small) == reference_crc32(small)  # the server's CRC is MAVLink's, bit for bit
    assert ftp.crc32(small[20:], ftp.crc32(small[:20])) == ftp.crc32(small)  # and it continues


def test_the_log_being_written_reads_up_to_its_size_at_open_and_cannot_be_touched(vehicle):
    stack, tmp, logs = vehicle
    gcs = Gcs(stack)
    assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1.0).result == m.MAV_RESULT_ACCEPTED
    stack.run_for(0.5)
    client = FtpClient(stack)
    writing = sorted((tmp / "log").glob("*/*.ulg"))[-1]
    path = f"/log/{writing.parent.name}/{writing.name}"
    size = client.open(path)
    stack.run_for(0.3)  # the log grows meanwhile
    assert writing.stat().st_size > size
    out = bytearray()
    while True:
        answer = client.request(READ, offset=len(out))
        if answer.opcode == NAK:
            assert answer.error == E_EOF
            break
        out += answer.data
    assert bytes(out) == writing.read_bytes()[:size]
    client.request(TERMINATE)
    for opcode, data in ((REMOVE, path), (OPEN_WO, path), (CREATE, path), (TRUNCATE, path),
                         (RENAME, f"{path}\0/log/moved.ulg"), (RENAME, f"/log/{writing.parent.name}\0/log/x"),
                         (RMDIR, f"/log/{writing.parent.name}")):  # fmt: skip
        answer = client.request(opcode, data.encode() + b"\0")
        assert (answer.opcode, answer.error) == (NAK, E_PROTECTED), (opcode, data)
    assert writing.exists()
    assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 0.0).result == m.MAV_RESULT_ACCEPTED
    stack.run_for(0.2)  # closed: the logger is done with it
    assert client.request(REMOVE, path.encode() + b"\0").opcode == ACK and not writing.exists()


def test_files_are_written_where_px4_lets_a_ground_station_write(vehicle):
    stack, tmp, _ = vehicle
    client = FtpClient(stack)
    assert client.request(MKDIR, b"/log/upload\0").opcode == ACK
    assert client.request(MKDIR, b"/log/upload\0").error == E_EXISTS
    created = client.request(CREATE, b"/log/upload/plan.txt\0")
    assert created.opcode == ACK and created.u32 == 0
    body = bytes(random.Random(1).randrange(256) for _ in range(1000))
    for offset in range(0, len(body), DATA_MAX):
        chunk = body[offset : offset + DATA_MAX]
        answer = client.request(WRITE, chunk, offset=offset)
        assert answer.opcode == ACK and answer.u32 == len(chunk)
    assert client.request(TERMINATE).opcode == ACK
    target = tmp / "log" / "upload" / "plan.txt"
    assert target.read_bytes() == body
    assert client.request(CRC, b"/log/upload/plan.txt\0").u32 == reference_crc32(body)
    assert client.request(TRUNCATE, b"/log/upload/plan.txt\0", offset=10).opcode == ACK
    assert target.read_bytes() == body[:10]
    assert client.request(RENAME, b"/log/upload/plan.txt\0/log/upload/done.txt\0").opcode == ACK
    assert client.listing("/log/upload") == ["Fdone.txt\t10"]
    answer = client.request(RMDIR, b"/log/upload\0")
    assert (answer.opcode, answer.error, answer.data[1]) == (NAK, E_ERRNO, errno.ENOTEMPTY)
    assert client.request(REMOVE, b"/log/upload/done.txt\0").opcode == ACK
    assert client.request(REMOVE, b"/log/upload/done.txt\0").error == E_NOT_FOUND
    assert client.request(RMDIR, b"/log/upload\0").opcode == ACK
    # Read-only: the parameter file (the autopilot rewrites it), the root and the mounts themselves.
    for opcode, data in ((OPEN_WO, "/params.toml"), (REMOVE, "/params.toml"), (TRUNCATE, "/params.toml"),
                         (RMDIR, "/log"), (REMOVE, "/log"), (RENAME, "/log\0/logs")):  # fmt: skip
        assert client.request(opcode, data.encode() + b"\0").error == E_PROTECTED, (opcode, data)
    for opcode, data in ((CREATE, "/new.txt"), (MKDIR, "/new"), (RENAME, "/params.toml\0/log/p.toml")):
        assert client.request(opcode, data.encode() + b"\0").error in (E_NOT_FOUND, E_PROTECTED)
    assert (tmp / "params.toml").read_text() == "MIS_TAKEOFF_ALT = 3.0\n"
    assert client.read_all("/params.toml") == b"MIS_TAKEOFF_ALT = 3.0\n"


def test_paths_that_try_to_leave_the_root_are_refused(vehicle):
    stack, tmp, _ = vehicle
    client = FtpClient(stack)
    outside = tmp / "secret.txt"
    (tmp / "log" / "link.txt").symlink_to(outside)
    (tmp / "log" / "linkdir").symlink_to(tmp)
    session = next((tmp / "log").iterdir()).name
    refused = {
        "/..": E_PROTECTED, "/log/..": E_PROTECTED, "/log/../secret.txt": E_PROTECTED,
        "../secret.txt": E_PROTECTED, f"/log/{session}/../../secret.txt": E_PROTECTED,
        "/log/link.txt": E_PROTECTED, "/log/linkdir/secret.txt": E_PROTECTED, "/log/linkdir": E_PROTECTED,
        str(outside): E_NOT_FOUND, "/etc/passwd": E_NOT_FOUND, "/proc/self/environ": E_NOT_FOUND,
        "@PARAM/param.pck": E_NOT_FOUND, "/log/a\nb": E_NOT_FOUND, "/log/\t": E_NOT_FOUND,
    }  # fmt: skip
    for path, error in refused.items():
        for opcode in (OPEN_RO, CRC, LIST, OPEN_WO, CREATE, REMOVE, MKDIR, TRUNCATE, RMDIR):
            answer = client.request(opcode, path.encode() + b"\0")
            assert answer.opcode == NAK, (opcode, path)
            assert answer.error == error or (opcode == LIST and answer.error == E_NOT_FOUND), (opcode, path)
        answer = client.request(RENAME, f"/log/{session}\0{path}".encode() + b"\0")
        assert answer.opcode == NAK, path
    bad_utf8 = client.request(OPEN_RO, b"/log/\xff\xfe\0")
    assert bad_utf8.error == E_NOT_FOUND
    # Symbolic links are not listed; what they point at is untouched.
    assert [e for e in client.listing("/log") if "link" in e] == []
    assert outside.read_text() == "not for the ground station\n"
    assert (tmp / "log" / session).is_dir()


def test_hostile_fields_are_refused_at_their_edges(vehicle):
    stack, tmp, logs = vehicle
    client = FtpClient(stack)
    path = f"/log/{logs[0].parent.name}/{logs[0].name}".encode() + b"\0"
    size = logs[0].stat().st_size
    assert client.request(LIST, b"/\0", size=240).error == ftp.ERR_INVALID_DATA_SIZE  # one above 239
    assert client.request(LIST, b"/\0", size=255).error == ftp.ERR_INVALID_DATA_SIZE
    assert client.request(99).error == E_UNKNOWN and client.request(ACK).error == E_UNKNOWN
    assert client.request(0).opcode == ACK  # None: acknowledged, as PX4
    assert client.request(READ).error == E_SESSION  # no session open
    assert client.request(TERMINATE).error == E_SESSION
    assert client.request(BURST, offset=0).error == E_SESSION
    assert client.request(WRITE, b"x").error == E_SESSION
    assert client.open(path.decode()) == size
    assert client.request(OPEN_RO, path).error == E_NO_SESSIONS  # one session per station, as PX4
    assert client.request(READ, session=1).error == E_SESSION  # not the session opened
    assert client.request(READ, offset=size - 1).data == logs[0].read_bytes()[-1:]  # the last byte
    for offset in (size, size + 1, 0xFFFFFFFF):
        assert client.request(READ, offset=offset).error == E_EOF
    assert client.request(READ, size=0).size == DATA_MAX  # 0 asks for a full chunk
    answer = client.request(WRITE, b"x")  # a read session is not written
    assert (answer.error, answer.data[1]) == (E_ERRNO, errno.EBADF)
    client.request_burst(0xFFFFFFFF)  # a burst past the end: one NAK EOF, numbered request + 1
    end = client.wait_for(client.seq)
    assert (end.opcode, end.error, end.req_opcode) == (NAK, E_EOF, BURST)
    assert client.request(LIST, b"/\0", offset=0xFFFFFFFF).error == E_EOF
    assert client.request(RESET).opcode == ACK
    assert client.request(READ).error == E_SESSION
    # Writes past the largest file, or past this run's budget.
    assert client.request(CREATE, b"/log/big.bin\0").opcode == ACK
    answer = client.request(WRITE, b"x", offset=ftp.MAX_FILE_BYTES)
    assert (answer.error, answer.data[1]) == (E_ERRNO, errno.EFBIG)
    client.request(TERMINATE)
    answer = client.request(TRUNCATE, b"/log/big.bin\0", offset=ftp.MAX_FILE_BYTES + 1)
    assert (answer.error, answer.data[1]) == (E_ERRNO, errno.EFBIG)
    assert (tmp / "log" / "big.bin").stat().st_size == 0
    server = stack.autopilot.ftp
    server.written_bytes = ftp.WRITE_BUDGET_BYTES - 1  # (a run that has written nearly its budget)
    assert client.request(OPEN_WO, b"/log/big.bin\0").opcode == ACK
    answer = client.request(WRITE, b"xy")
    assert (answer.error, answer.data[1]) == (E_ERRNO, errno.ENOSPC)
    client.request(TERMINATE)
    # A file too large to checksum without holding up the control loop (sparse: no disk used).
    os.truncate(tmp / "log" / "big.bin", ftp.CRC_MAX_BYTES + 1)
    assert client.request(CRC, b"/log/big.bin\0").error == E_FAIL
    assert not stack.autopilot.faults.counts


def test_a_session_keeps_the_id_its_open_named(vehicle):
    """PX4's clients open with session 0 (and PX4 answers 0); a client choosing its own id, as
    ArduPilot lets MAVProxy, keeps it: its reads, bursts and terminate name it."""
    stack, tmp, logs = vehicle
    client = FtpClient(stack)
    path = f"/log/{logs[0].parent.name}/{logs[0].name}".encode() + b"\0"
    opened = client.request(OPEN_RO, path, session=7)
    assert (opened.opcode, opened.session) == (ACK, 7)
    assert client.request(READ, session=0).error == E_SESSION
    read = client.request(READ, session=7, size=10)
    assert (read.session, read.data) == (7, logs[0].read_bytes()[:10])
    client.send(HEADER.pack(client.seq, 7, BURST, 0, 0, 0, 0, 0))
    client.seq += 1
    assert client.wait_for(client.seq).session == 7
    assert client.request(TERMINATE, session=7).session == 7


def test_a_resent_request_gets_the_same_answer_without_being_done_twice(vehicle):
    stack, tmp, logs = vehicle
    client = FtpClient(stack)
    first = client.request(MKDIR, b"/log/once\0")
    assert first.opcode == ACK
    client.send(client.last_payload)  # the answer was lost: the same request again
    again = client.wait_for(first.seq)
    assert (again.opcode, again.data) == (ACK, b"")  # not FileExists: it was not done again
    renamed = client.request(RENAME, b"/log/once\0/log/twice\0")
    client.send(client.last_payload)
    assert client.wait_for(renamed.seq).opcode == ACK and (tmp / "log" / "twice").is_dir()
    # Another client starting its numbering at the same seq with another request is answered anew.
    other = client.request(MKDIR, b"/log/third\0", seq=renamed.seq - 1)
    assert other.opcode == ACK and (tmp / "log" / "third").is_dir()
    # Sequence numbers wrap as u16.
    assert client.request(LIST, b"/\0", seq=0xFFFF).seq == 0
    # The same request long after its answer is a new one (a client run again, numbering from 0).
    listed = client.request(LIST, b"/log\0", seq=0)
    (tmp / "log" / "later").mkdir()
    stack.run_for(ftp.RESEND_WINDOW_S + 0.5)
    client.send(client.last_payload)
    assert b"Dlater" in client.wait_for(listed.seq).data and b"Dlater" not in listed.data


def test_stations_sessions_and_idle_sessions(vehicle):
    stack, tmp, logs = vehicle
    path = f"/log/{logs[0].parent.name}/{logs[0].name}"
    first = FtpClient(stack, GCS_LINK)
    first.open(path)
    others = [FtpClient(stack, GCS_LINK, system_id=200 + k) for k in range(ftp.MAX_STATIONS_PER_LINK)]
    for other in others:  # each station its own session, until the link has no room for the first
        other.open(path)
    assert first.request(READ).error == E_SESSION  # evicted: its session was closed
    api = FtpClient(stack, API_LINK)  # the other link is not affected
    api.open(path)
    stack.run_for(SESSION_IDLE_S + 0.5)
    assert api.request(READ).error == E_SESSION  # idle for longer than PX4's 10 s: closed
    assert api.open(path) > 0


def test_a_flood_of_random_requests_is_answered_and_harms_nothing(vehicle):
    """Random payloads and random opcodes with plausible and implausible paths: every request
    answered (ACK or NAK), no fault, nothing outside the log directory touched (inside, whatever a
    ground station may do: a log may be removed)."""
    stack, tmp, logs = vehicle
    client = FtpClient(stack)
    rng = random.Random(7)
    a_log = f"/log/{logs[0].parent.name}/{logs[0].name}".encode()
    names = [b"/", b"/log", b"/log/x", b"/params.toml", b"/..", b"/log/../secret.txt", b"../../etc/passwd",
             a_log, b"\xff", b"/log/" + b"a" * 230]  # fmt: skip
    before = {p: p.read_bytes() for p in (tmp / "secret.txt", tmp / "params.toml")}  # (logs may go)
    answered = 0
    for k in range(1500):
        if k % 3 == 0:
            payload = bytes(rng.randrange(256) for _ in range(PAYLOAD_LEN))
        else:
            data = rng.choice(names) + (b"\0" + rng.choice(names) if rng.random() < 0.3 else b"")
            opcode = rng.choice([*range(0, 17), 127, 128, 129, 255])
            offset = rng.choice([0, 1, 239, 0xFFFFFFFF, rng.randrange(1 << 32)])
            session = rng.choice([0, 0, 1, 255])
            payload = HEADER.pack(k, session, opcode, min(len(data), 239), 0, 0, 0, offset) + data[:239]
        client.send(payload)
        client.pump()
        answered += len(client.answers)
        client.answers.clear()
    client.pump(200)
    assert answered >= 1000  # (a burst's chunks too; requests to other targets are not answered)
    assert not stack.autopilot.faults.counts
    assert {p: p.read_bytes() for p in before} == before
    assert sorted(p.name for p in tmp.iterdir()) == ["log", "params.toml", "secret.txt"]


def test_requests_for_another_vehicle_are_not_answered(tmp_path):
    stack = make_stack(log_dir=str(tmp_path))
    client = FtpClient(stack)
    client.send(HEADER.pack(0, 0, LIST, 2, 0, 0, 0, 0) + b"/\0", target=7)
    client.pump(20)
    assert client.answers == []
    assert client.request(LIST, b"/\0").data == b"Dlog\0"  # to this one (its system id), answered


def test_no_log_directory_is_an_empty_root():
    client = FtpClient(make_stack())
    assert client.listing("/") == []
    assert client.request(OPEN_RO, b"/log/x.ulg\0").error == E_NOT_FOUND
    assert client.request(CREATE, b"/x\0").error == E_NOT_FOUND


def test_requests_for_an_empty_log_directory(tmp_path):
    """Before the first flight the log directory does not exist yet: listed empty, created by a
    write."""
    stack = make_stack(log_dir=str(tmp_path / "log"))
    client = FtpClient(stack)
    answer = client.request(LIST, b"/log\0")
    assert (answer.opcode, answer.size) == (ACK, 0)
    assert client.request(MKDIR, b"/log/first\0").opcode == ACK
    assert Path(tmp_path / "log" / "first").is_dir()


def test_nul_bytes_and_over_long_names(vehicle):
    """A path ends at its first NUL, as PX4 reads it (what follows is not a second path); a path
    that fills the payload without a NUL is read to the payload's end (a longer one is refused by
    its size, test_hostile_fields_are_refused_at_their_edges), answered, never raised."""
    stack, tmp, logs = vehicle
    client = FtpClient(stack)
    log = f"/log/{logs[0].parent.name}/{logs[0].name}".encode()
    size = logs[0].stat().st_size
    assert client.open((log + b"\0/../../secret.txt").decode()) == size  # the log, not the tail
    client.request(TERMINATE)
    for path in (b"/..\0/log", b"/log/..\0"):
        answer = client.request(OPEN_RO, path)
        assert (answer.opcode, answer.error) == (NAK, E_PROTECTED), path
    assert client.request(OPEN_RO, b"/log\0/..\0/..").opcode == NAK  # /log: a directory, not opened
    assert client.request(OPEN_RO, b"\0/etc/passwd\0").opcode == NAK  # the empty path: the root
    full = b"/log/" + b"a" * (DATA_MAX - 5)  # DATA_MAX bytes, no terminator
    for opcode in (OPEN_RO, CREATE, MKDIR, LIST, REMOVE):
        answer = client.request(opcode, full)
        assert answer.opcode in (NAK, ACK), opcode
        client.request(TERMINATE)
    assert not stack.autopilot.faults.counts
