"""MAVLink FTP (``FILE_TRANSFER_PROTOCOL``) as PX4's ``mavlink_ftp`` serves it (QGC, MAVSDK, MAVProxy).

Every request and every answer is one ``FILE_TRANSFER_PROTOCOL`` whose 251-byte payload is
(https://mavlink.io/en/services/ftp.html) ``seq_number`` u16, ``session`` u8, ``opcode`` u8,
``size`` u8, ``req_opcode`` u8, ``burst_complete`` u8, padding u8, ``offset`` u32, then ``size``
bytes of ``data`` (at most :data:`DATA_MAX`). An answer is the request's header with
``seq_number + 1``, ``opcode`` ACK or NAK, ``req_opcode`` the request's opcode; a NAK carries the
error (``MAV_FTP_ERR``) in ``data[0]`` and, for ``FailErrno``, the errno in ``data[1]``. As PX4:

* ``ListDirectory(path, offset)``: entries from the ``offset``-th on, as many as fit:
  ``F<name>\\t<size>\\0`` for a file, ``D<name>\\0`` for a directory (sorted by name; symbolic
  links and other kinds are not listed); past the last entry, NAK ``EOF``; an empty directory,
  an ACK with no data. A directory that cannot be listed: ``FileNotFound``.
* ``OpenFileRO(path)``: the session and the file's size (u32) at that moment, which the session
  serves up to (a log still being written reads as far as it was when opened); a second open
  while the station's session is open: ``NoSessionsAvailable``. The session's id is the one the
  open request names: 0 from PX4's clients (MAVSDK, QGC), to which PX4 answers 0 whatever they
  send; a client that picks its own, as ArduPilot lets it (MAVProxy), keeps it. ``ReadFile(session, offset,
  size)``: up to ``size`` bytes (0 asks for :data:`DATA_MAX`), ``EOF`` at or past the end.
  ``BurstReadFile(session, offset)``: no ACK; the data streams as ACKs numbered ``seq + 1``,
  ``seq + 2``... (``req_opcode`` BurstReadFile, ``offset`` each chunk's) until the end of the
  file, then one NAK ``EOF``; after :data:`BURST_BYTES` the chunk carrying ``burst_complete = 1``
  ends the burst and the client asks for the next one (PX4's ~35 kB bursts). Bursts are paced
  (:meth:`FtpServer.pump`, :data:`MESSAGES_PER_S` per link), so a download never floods a link
  nor holds back lockstep. ``TerminateSession`` closes the session (``InvalidSession`` if none),
  ``ResetSessions`` closes the station's, idle sessions close after :data:`SESSION_IDLE_S`.
* ``CalcFileCRC32(path)``: the CRC-32 of the whole file (MAVLink's: zlib's polynomial without
  zlib's initial and final inversion, :func:`crc32`).
* Writing, where the file system allows it (:mod:`autopilot.vehicle_files`: the log directory):
  ``CreateFile`` (truncates) / ``OpenFileWO`` then ``WriteFile(session, offset, data)`` (the count
  written, u32), ``RemoveFile``, ``CreateDirectory``, ``RemoveDirectory`` (empty only),
  ``Rename(old\\0new)``, ``TruncateFile(path, offset = length)``.
* A request resent unchanged (its answer was lost) within :data:`RESEND_WINDOW_S` gets the same
  answer again without being carried out twice (PX4 matches on the sequence number alone; here the
  whole request must match, and be recent, so a client restarting its numbering is not answered
  from an earlier run's cache). ``None`` (opcode 0)
  is acknowledged; an unknown opcode is NAK ``UnknownCommand``; ``size`` above 239 is NAK
  ``InvalidDataSize``.

Refused here whatever the file system (every byte of a request may be hostile): a path with a
``..`` component (``FileProtected``: nothing outside the root is named), or with control
characters in a name (``FileNotFound``); offsets past the end (``EOF``), writes or truncations
beyond :data:`MAX_FILE_BYTES` (``FailErrno`` EFBIG); more than :data:`WRITE_BUDGET_BYTES` written
or :data:`CREATE_BUDGET` files and directories created in one run (``FailErrno`` ENOSPC); a CRC
of a file larger than :data:`CRC_MAX_BYTES` (``Fail``: it would hold the control loop). The file
system refuses the rest (a symbolic link, a read-only file, the log being written). Each
station (an address on a link) has its own session, burst and last answer; a link keeps
:data:`MAX_STATIONS_PER_LINK`, the one heard from longest ago making room (its session closed).

Pure: the files come in as a :class:`FileSystem` (the shell's, on disk:
:class:`autopilot.vehicle_files.VehicleFiles`).

(One module: one protocol's opcodes, sessions, resends and refusals, each opcode a row of one
table; the file system it serves is the other side, :mod:`autopilot.vehicle_files`.)
"""

from __future__ import annotations

import errno
import struct
import zlib
from collections import Counter, OrderedDict
from collections.abc import Callable
from dataclasses import dataclass
from enum import Enum
from typing import NamedTuple, Protocol

from quadcommon import wire

from .codec import Encoder
from .codec import mavlink as m
from .links import Address, GcsLink, SendAllowance

HEADER = struct.Struct("<HBBBBBBI")  # seq, session, opcode, size, req_opcode, burst_complete, pad, offset
PAYLOAD_LEN = 251  # FILE_TRANSFER_PROTOCOL.payload
DATA_MAX = PAYLOAD_LEN - HEADER.size  # 239
U32 = struct.Struct("<I")

# Opcodes and error codes: MAVLink's MAV_FTP_OPCODE and MAV_FTP_ERR.
ACK, NAK = m.MAV_FTP_OPCODE_ACK, m.MAV_FTP_OPCODE_NAK
BURST_READ = m.MAV_FTP_OPCODE_BURSTREADFILE
ERR_FAIL, ERR_FAIL_ERRNO = m.MAV_FTP_ERR_FAIL, m.MAV_FTP_ERR_FAILERRNO
ERR_INVALID_DATA_SIZE, ERR_INVALID_SESSION = m.MAV_FTP_ERR_INVALIDDATASIZE, m.MAV_FTP_ERR_INVALIDSESSION
ERR_NO_SESSIONS, ERR_EOF = m.MAV_FTP_ERR_NOSESSIONSAVAILABLE, m.MAV_FTP_ERR_EOF
ERR_UNKNOWN_COMMAND, ERR_FILE_EXISTS = m.MAV_FTP_ERR_UNKNOWNCOMMAND, m.MAV_FTP_ERR_FILEEXISTS
ERR_FILE_PROTECTED, ERR_FILE_NOT_FOUND = m.MAV_FTP_ERR_FILEPROTECTED, m.MAV_FTP_ERR_FILENOTFOUND

BURST_BYTES = 35_000  # data per burst before burst_complete (PX4's, found "empirically")
# Burst chunks per link per second of the caller's clock (the process's wall clock; in-process,
# simulation time), and per call of pump(): 240 kB/s of data, what a Python client keeps up with.
MESSAGES_PER_S = 1000
MESSAGES_AT_ONCE = 20  # a link may send this many at once after a pause
SESSION_IDLE_S = 10.0  # a session without a request for this long is closed (PX4's)
RESEND_WINDOW_S = 10.0  # a request repeated within this is a resend (its answer was lost)
MAX_STATIONS_PER_LINK = 4
MAX_FILE_BYTES = 64 * 1024 * 1024  # no write or truncation makes a file longer
WRITE_BUDGET_BYTES = 256 * 1024 * 1024  # bytes a run writes through FTP, at most
CREATE_BUDGET = 1000  # files and directories a run creates through FTP, at most
CRC_MAX_BYTES = 64 * 1024 * 1024  # the largest file checksummed (~22 ms of the loop, page-cached)
CRC_CHUNK = 64 * 1024
CRC_CACHE = 16  # checksums kept, by file identity (a repeated request costs nothing)


class FtpError(Exception):
    """A request refused: its NAK's ``MAV_FTP_ERR`` code (and the errno for ``FailErrno``)."""

    def __init__(self, code: int, errno_value: int = 0, why: str = "") -> None:
        super().__init__(why or f"MAV_FTP_ERR {code}")
        self.code = code
        self.errno = errno_value


class Entry(NamedTuple):
    """One directory entry as listed: a file (with its size, bytes) or a directory."""

    name: str
    is_dir: bool
    size: int = 0


class OpenMode(Enum):
    READ = "read"  # OpenFileRO
    WRITE = "write"  # OpenFileWO: created if missing, kept otherwise
    CREATE = "create"  # CreateFile: created, or emptied


class FileSystem(Protocol):
    """The files FTP serves, named by path components below its root (``("log", "x.ulg")``;
    ``()`` is the root). Refusals raise :class:`FtpError`, the system's failures ``OSError``."""

    def list(self, path: tuple[str, ...]) -> list[Entry]:
        """The entries of directory ``path`` (``()``: the root), files with their size in bytes."""

    def open(self, path: tuple[str, ...], mode: OpenMode) -> tuple[object, int]:
        """Open file ``path`` in ``mode``: a handle and the file's size (bytes) when opened."""

    def read(self, handle: object, offset: int, count: int) -> bytes:
        """Up to ``count`` bytes of the open file from ``offset`` (fewer at its end, ``b""`` past it)."""

    def write(self, handle: object, offset: int, data: bytes) -> int:
        """Write ``data`` at ``offset`` of the open file; how many bytes were written."""

    def close(self, handle: object) -> None:
        """Close the handle (the session ended)."""

    def identity(self, handle: object) -> tuple:
        """What identifies the open file's content (device, inode, modification time, size): the key under
        which the server caches its CRC-32."""

    def remove_file(self, path: tuple[str, ...]) -> None:
        """Delete file ``path`` (RemoveFile)."""

    def create_directory(self, path: tuple[str, ...]) -> None:
        """Create directory ``path`` (CreateDirectory)."""

    def remove_directory(self, path: tuple[str, ...]) -> None:
        """Delete the empty directory ``path`` (RemoveDirectory)."""

    def rename(self, old: tuple[str, ...], new: tuple[str, ...]) -> None:
        """Rename ``old`` to ``new`` (Rename)."""

    def truncate(self, path: tuple[str, ...], length: int) -> None:
        """Cut or extend file ``path`` to ``length`` bytes (TruncateFile)."""


class NoFiles:
    """A vehicle with nothing to serve: the root lists empty, every name is FileNotFound."""

    def list(self, path: tuple[str, ...]) -> list[Entry]:
        """The root lists empty; any other path is FileNotFound."""
        if path:
            raise FtpError(ERR_FILE_NOT_FOUND)
        return []

    def open(self, path: tuple[str, ...], mode: OpenMode) -> tuple[object, int]:
        """Refused: FileNotFound (there is nothing to open)."""
        raise FtpError(ERR_FILE_NOT_FOUND)

    def read(self, handle: object, offset: int, count: int) -> bytes:
        """Nothing: no handle is ever open."""
        return b""

    def write(self, handle: object, offset: int, data: bytes) -> int:
        """Nothing written: no handle is ever open."""
        return 0

    def close(self, handle: object) -> None:
        """Nothing to close."""
        pass

    def identity(self, handle: object) -> tuple:
        """An empty identity: no handle is ever open."""
        return ()

    def remove_file(self, path: tuple[str, ...]) -> None:
        """Refused: FileNotFound (also as ``create_directory`` and ``remove_directory``)."""
        raise FtpError(ERR_FILE_NOT_FOUND)

    create_directory = remove_directory = remove_file

    def rename(self, old: tuple[str, ...], new: tuple[str, ...]) -> None:
        """Refused: FileNotFound."""
        raise FtpError(ERR_FILE_NOT_FOUND)

    def truncate(self, path: tuple[str, ...], length: int) -> None:
        """Refused: FileNotFound."""
        raise FtpError(ERR_FILE_NOT_FOUND)


class Request(NamedTuple):
    seq: int
    session: int
    opcode: int
    size: int
    offset: int
    data: bytes  # the request's ``size`` bytes of data


class Reply(NamedTuple):
    """An ACK's variable part: its data, session and offset."""

    data: bytes = b""
    session: int = 0
    offset: int = 0


def crc32(data: bytes, crc: int = 0) -> int:
    """MAVLink FTP's CRC-32 (PX4's ``crc32part``): zlib's table, no initial or final inversion;
    ``crc`` continues a checksum over what came before."""
    return zlib.crc32(data, crc ^ 0xFFFFFFFF) ^ 0xFFFFFFFF


def path_of(data: bytes) -> tuple[str, ...]:
    """The path a request names (its data up to the first NUL, as PX4 reads it): components below
    the root; empty and ``.`` components dropped, a leading ``/`` optional."""
    raw = data.split(b"\0", 1)[0]
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise FtpError(ERR_FILE_NOT_FOUND, why="path not UTF-8") from None
    parts = []
    for part in text.split("/"):
        if part in ("", "."):
            continue
        if part == "..":
            raise FtpError(ERR_FILE_PROTECTED, why="'..' would leave the root")
        if any(ord(c) < 0x20 or c == "\x7f" for c in part):
            raise FtpError(ERR_FILE_NOT_FOUND, why="control characters in a name")
        parts.append(part)
    return tuple(parts)


def entry_bytes(entry: Entry) -> bytes:
    """One entry of a ListDirectory answer (PX4's ``F<name>\\t<size>`` / ``D<name>``, NUL-ended)."""
    if entry.is_dir:
        return b"D" + entry.name.encode("utf-8") + b"\0"
    return b"F" + entry.name.encode("utf-8") + b"\t" + str(min(entry.size, 0xFFFFFFFF)).encode() + b"\0"


@dataclass
class _Session:
    handle: object
    size: int  # bytes served (the file's size when opened, at most u32)
    writable: bool
    number: int  # the id the open request named (PX4's clients: 0)


@dataclass
class _Burst:
    offset: int
    seq: int  # of the next chunk
    target: tuple[int, int]  # (system, component) of the station
    sent: int = 0  # bytes in this burst so far


@dataclass
class _Station:
    address: Address
    heard: float  # the caller's clock at its last request
    session: _Session | None = None
    burst: _Burst | None = None
    last_request: bytes = b""  # the request answered last (its whole payload), the answer, when
    last_answer: tuple[bytes, tuple[int, int]] | None = None
    answered_at: float = 0.0


class FtpServer:
    """PX4's ``mavlink_ftp`` over ``files`` (module docstring): a session, a paced burst and the last answer
    per station on each link; counters for the autopilot's info."""

    def __init__(
        self,
        files: FileSystem,
        encoder: Encoder,
        links: list[GcsLink],
        system_id: int,
        clock: Callable[[], float],
    ) -> None:
        self.files = files
        self.encoder = encoder
        self.links = links
        self.system_id = system_id
        self.clock = clock
        self.stations: list[OrderedDict[Address, _Station]] = [OrderedDict() for _ in links]
        self.allowance = [SendAllowance(MESSAGES_PER_S, MESSAGES_AT_ONCE, clock) for _ in links]
        self.requests: Counter[str] = Counter()  # by opcode name
        self.refused: Counter[str] = Counter()  # NAKs by error name (EOF included)
        self.written_bytes = 0
        self.created = 0
        self._crc_cache: OrderedDict[tuple, int] = OrderedDict()
        self._busy = False  # a station has a session or a burst: pump() has work
        self._handlers: dict[int, Callable[[_Station, Request, tuple[int, int]], Reply | None]] = {
            m.MAV_FTP_OPCODE_NONE: self._none,
            m.MAV_FTP_OPCODE_TERMINATESESSION: self._terminate,
            m.MAV_FTP_OPCODE_RESETSESSION: self._reset,
            m.MAV_FTP_OPCODE_LISTDIRECTORY: self._list,
            m.MAV_FTP_OPCODE_OPENFILERO: self._open_read,
            m.MAV_FTP_OPCODE_READFILE: self._read,
            m.MAV_FTP_OPCODE_CREATEFILE: self._open_create,
            m.MAV_FTP_OPCODE_WRITEFILE: self._write,
            m.MAV_FTP_OPCODE_REMOVEFILE: self._remove_file,
            m.MAV_FTP_OPCODE_CREATEDIRECTORY: self._create_directory,
            m.MAV_FTP_OPCODE_REMOVEDIRECTORY: self._remove_directory,
            m.MAV_FTP_OPCODE_OPENFILEWO: self._open_write,
            m.MAV_FTP_OPCODE_TRUNCATEFILE: self._truncate,
            m.MAV_FTP_OPCODE_RENAME: self._rename,
            m.MAV_FTP_OPCODE_CALCFILECRC: self._crc,
            BURST_READ: self._burst,
        }

    def register(self, dispatcher) -> None:
        """Put :meth:`on_message` in the dispatcher's table for FILE_TRANSFER_PROTOCOL."""
        dispatcher[m.MAVLINK_MSG_ID_FILE_TRANSFER_PROTOCOL] = self.on_message

    def info(self) -> dict:
        """The counters for ``quadsitl/<N>/autopilot/info``: requests by opcode, NAKs by error, bytes written
        and files and directories created."""
        return {"requests": dict(self.requests), "refused": dict(self.refused),
                "written_bytes": self.written_bytes, "created": self.created}  # fmt: skip

    # -- requests -------------------------------------------------------------------------------
    def on_message(self, msg, link: GcsLink, address: Address) -> None:
        """Answer one FILE_TRANSFER_PROTOCOL from ``address`` on ``link``: an ACK or a NAK (a resent request
        gets its answer again), or a burst started; requests for another system or component are ignored."""
        if msg.target_system not in (0, self.system_id) or msg.target_component not in (
            0, wire.AUTOPILOT_COMPONENT_ID):  # fmt: skip
            return
        raw = bytes(msg.payload).ljust(PAYLOAD_LEN, b"\0")
        target = (msg.get_srcSystem(), msg.get_srcComponent())
        station = self._station(link, address)
        resent = station.last_answer is not None and raw == station.last_request
        if resent and station.heard - station.answered_at < RESEND_WINDOW_S:
            answer, _ = station.last_answer  # the answer was lost: the same again, not done twice
            self._send(link, address, answer, target)
            return
        seq, session, opcode, size, _, _, _, offset = HEADER.unpack_from(raw)
        data = raw[HEADER.size : HEADER.size + min(size, DATA_MAX)]
        request = Request(seq, session, opcode, size, offset, data)
        name = _OPCODE_NAMES.get(opcode, "unknown")
        self.requests[name] += 1
        try:
            if size > DATA_MAX:
                raise FtpError(ERR_INVALID_DATA_SIZE)
            handler = self._handlers.get(opcode)
            if handler is None:
                raise FtpError(ERR_UNKNOWN_COMMAND)
            reply = handler(station, request, target)
        except FtpError as refusal:
            answer = self._nak(request, refusal.code, refusal.errno)
        except OSError as failure:
            answer = self._nak(request, *_os_error(failure, listing=opcode == m.MAV_FTP_OPCODE_LISTDIRECTORY))
        else:
            if reply is None:  # a burst: its data is the answer
                station.last_request, station.last_answer = b"", None
                return
            answer = _payload(seq + 1, reply.session, ACK, opcode, reply.offset, reply.data)
        station.last_request, station.last_answer, station.answered_at = raw, (answer, target), station.heard
        self._send(link, address, answer, target)

    def _station(self, link: GcsLink, address: Address) -> _Station:
        stations = self.stations[link.index]
        station = stations.get(address)
        now = self.clock()
        if station is None:
            if len(stations) >= MAX_STATIONS_PER_LINK:
                _, oldest = stations.popitem(last=False)
                self._close(oldest)
            station = stations[address] = _Station(address, now)
        else:
            stations.move_to_end(address)
            station.heard = now
        return station

    def _nak(self, request: Request, code: int, errno_value: int = 0) -> bytes:
        self.refused[_ERROR_NAMES.get(code, str(code))] += 1
        data = _nak_data(code, errno_value)
        return _payload(request.seq + 1, request.session, NAK, request.opcode, request.offset, data)

    def _send(self, link: GcsLink, address: Address, payload: bytes, target: tuple[int, int]) -> None:
        msg = m.MAVLink_file_transfer_protocol_message(0, target[0], target[1], payload)
        link.send_to(self.encoder.pack(msg), address)

    # -- the operations -------------------------------------------------------------------------
    def _list(self, station: _Station, r: Request, target) -> Reply:
        entries = [e for e in self.files.list(path_of(r.data)) if len(entry_bytes(e)) <= DATA_MAX]
        if r.offset >= len(entries):
            if r.offset == 0:
                return Reply(offset=r.offset)  # an empty directory
            raise FtpError(ERR_EOF)
        out = bytearray()
        for entry in entries[r.offset :]:
            item = entry_bytes(entry)
            if len(out) + len(item) > DATA_MAX:
                break
            out += item
        return Reply(bytes(out), r.session, r.offset)

    # The table's handlers are bound methods, not lambdas: a deep copy of the server rebinds them.
    def _none(self, station: _Station, r: Request, target) -> Reply:
        return Reply()

    def _open_read(self, station: _Station, r: Request, target) -> Reply:
        return self._open(station, r, OpenMode.READ)

    def _open_create(self, station: _Station, r: Request, target) -> Reply:
        return self._open(station, r, OpenMode.CREATE)

    def _open_write(self, station: _Station, r: Request, target) -> Reply:
        return self._open(station, r, OpenMode.WRITE)

    def _remove_file(self, station: _Station, r: Request, target) -> Reply:
        return self._path_op(self.files.remove_file, r)

    def _remove_directory(self, station: _Station, r: Request, target) -> Reply:
        return self._path_op(self.files.remove_directory, r)

    def _open(self, station: _Station, r: Request, mode: OpenMode) -> Reply:
        if station.session is not None:
            raise FtpError(ERR_NO_SESSIONS)
        path = path_of(r.data)
        writing = mode is not OpenMode.READ
        self._check_budget(files=int(writing))
        handle, size = self.files.open(path, mode)
        self.created += int(writing)
        size = min(size, 0xFFFFFFFF)
        station.session = _Session(handle, size, writing, r.session)
        self._busy = True
        return Reply(U32.pack(size), r.session, r.offset)

    def _session(self, station: _Station, r: Request) -> _Session:
        if station.session is None or r.session != station.session.number:
            raise FtpError(ERR_INVALID_SESSION)
        return station.session

    def _read(self, station: _Station, r: Request, target) -> Reply:
        session = self._session(station, r)
        if r.offset >= session.size:
            raise FtpError(ERR_EOF)
        count = min(r.size or DATA_MAX, DATA_MAX, session.size - r.offset)
        return Reply(self.files.read(session.handle, r.offset, count), session.number, r.offset)

    def _burst(self, station: _Station, r: Request, target) -> None:
        self._session(station, r)
        station.burst = _Burst(r.offset, (r.seq + 1) & 0xFFFF, target)
        self._busy = True
        return None

    def _write(self, station: _Station, r: Request, target) -> Reply:
        session = self._session(station, r)
        if not session.writable:
            raise FtpError(ERR_FAIL_ERRNO, errno.EBADF, "the session is open for reading")
        if r.offset + len(r.data) > MAX_FILE_BYTES:
            raise FtpError(ERR_FAIL_ERRNO, errno.EFBIG, "beyond the largest file written here")
        self._check_budget(data=len(r.data))
        written = self.files.write(session.handle, r.offset, r.data)
        self.written_bytes += written
        return Reply(U32.pack(written), session.number, r.offset)

    def _terminate(self, station: _Station, r: Request, target) -> Reply:
        self._session(station, r)
        self._close(station)
        return Reply(session=r.session, offset=r.offset)

    def _reset(self, station: _Station, r: Request, target) -> Reply:
        self._close(station)
        return Reply(session=r.session, offset=r.offset)

    def _path_op(self, operation: Callable[[tuple[str, ...]], None], r: Request) -> Reply:
        operation(path_of(r.data))
        return Reply(session=r.session, offset=r.offset)

    def _create_directory(self, station: _Station, r: Request, target) -> Reply:
        self._check_budget(files=1)
        reply = self._path_op(self.files.create_directory, r)
        self.created += 1
        return reply

    def _truncate(self, station: _Station, r: Request, target) -> Reply:
        if r.offset > MAX_FILE_BYTES:
            raise FtpError(ERR_FAIL_ERRNO, errno.EFBIG, "beyond the largest file written here")
        self.files.truncate(path_of(r.data), r.offset)
        return Reply(session=r.session, offset=r.offset)

    def _rename(self, station: _Station, r: Request, target) -> Reply:
        old, sep, rest = r.data.partition(b"\0")
        if not sep or not rest.split(b"\0", 1)[0]:
            raise FtpError(ERR_FAIL_ERRNO, errno.EINVAL, "no new path")
        self.files.rename(path_of(old), path_of(rest))
        return Reply(session=r.session, offset=r.offset)

    def _crc(self, station: _Station, r: Request, target) -> Reply:
        handle, size = self.files.open(path_of(r.data), OpenMode.READ)
        try:
            if size > CRC_MAX_BYTES:
                raise FtpError(ERR_FAIL, why="too large to checksum here")
            key = self.files.identity(handle)
            crc = self._crc_cache.get(key)
            if crc is None:
                crc, offset = 0, 0
                while chunk := self.files.read(handle, offset, CRC_CHUNK):
                    crc = crc32(chunk, crc)
                    offset += len(chunk)
                self._crc_cache[key] = crc
                if len(self._crc_cache) > CRC_CACHE:
                    self._crc_cache.popitem(last=False)
        finally:
            self.files.close(handle)
        return Reply(U32.pack(crc), r.session, r.offset)

    def _check_budget(self, data: int = 0, files: int = 0) -> None:
        """ENOSPC when writing ``data`` bytes or creating ``files`` would exceed this run's budget
        (counted once done: :attr:`written_bytes`, :attr:`created`, opens for writing included)."""
        if self.written_bytes + data > WRITE_BUDGET_BYTES or self.created + files > CREATE_BUDGET:
            raise FtpError(ERR_FAIL_ERRNO, errno.ENOSPC, "this run's FTP write budget is spent")

    def _close(self, station: _Station) -> None:
        session, station.session, station.burst = station.session, None, None
        if session is not None:
            try:
                self.files.close(session.handle)
            except OSError:
                pass

    # -- bursts and idle sessions ---------------------------------------------------------------
    def pump(self, budget: int) -> None:
        """Stream the bursts in progress, at most ``budget`` chunks per link (the stations taking
        turns) and no more than :data:`MESSAGES_PER_S` of the clock allows; close idle sessions."""
        if not self._busy:
            return
        now = self.clock()
        busy = False
        for link, stations, allowance in zip(self.links, self.stations, self.allowance, strict=True):
            for station in list(stations.values()):
                idle = station.burst is None and now - station.heard > SESSION_IDLE_S
                if station.session is not None and idle:
                    self._close(station)
            streaming = [s for s in stations.values() if s.burst is not None]
            if not streaming:
                continue
            left = allowance.take(budget)
            while left > 0 and streaming:
                for station in streaming:
                    if left > 0 and station.burst is not None:
                        self._send_chunk(link, station)
                        left -= 1
                streaming = [s for s in streaming if s.burst is not None]
            allowance.give_back(left)
            busy = busy or bool(streaming)
        self._busy = busy or any(st.session is not None for sts in self.stations for st in sts.values())

    def _send_chunk(self, link: GcsLink, station: _Station) -> None:
        burst, session = station.burst, station.session
        offset, number = burst.offset, session.number
        try:
            chunk = self.files.read(session.handle, offset, min(DATA_MAX, session.size - offset)) if (
                offset < session.size) else b""  # fmt: skip
        except OSError as failure:
            code, errno_value = _os_error(failure)
            self.refused[_ERROR_NAMES[code]] += 1
            payload = _payload(burst.seq, number, NAK, BURST_READ, offset, _nak_data(code, errno_value))
            station.burst = None
        else:
            if not chunk:  # the end (or a file shorter than when it was opened)
                self.refused[_ERROR_NAMES[ERR_EOF]] += 1
                payload = _payload(burst.seq, number, NAK, BURST_READ, offset, _nak_data(ERR_EOF))
                station.burst = None
            else:
                burst.sent += len(chunk)
                complete = burst.sent >= BURST_BYTES
                payload = _payload(burst.seq, number, ACK, BURST_READ, offset, chunk, burst_complete=complete)
                burst.offset += len(chunk)
                burst.seq = (burst.seq + 1) & 0xFFFF
                if complete:
                    station.burst = None
        self._send(link, station.address, payload, burst.target)


def _payload(seq: int, session: int, opcode: int, req_opcode: int, offset: int, data: bytes,
             burst_complete: bool = False) -> bytes:  # fmt: skip
    header = HEADER.pack(seq & 0xFFFF, session, opcode, len(data), req_opcode, int(burst_complete), 0,
                         offset & 0xFFFFFFFF)  # fmt: skip
    return (header + data).ljust(PAYLOAD_LEN, b"\0")


def _nak_data(code: int, errno_value: int = 0) -> bytes:
    """A NAK's data: the error, and for FailErrno the errno."""
    return bytes((code, errno_value & 0xFF)) if code == ERR_FAIL_ERRNO else bytes((code,))


def _os_error(failure: OSError, listing: bool = False) -> tuple[int, int]:
    """A file-system failure as PX4 answers it: ENOENT FileNotFound, EEXIST FileExists, else
    FailErrno with the errno; any failure to list a directory is FileNotFound."""
    if listing or failure.errno == errno.ENOENT:
        return ERR_FILE_NOT_FOUND, 0
    if failure.errno == errno.EEXIST:
        return ERR_FILE_EXISTS, 0
    return ERR_FAIL_ERRNO, failure.errno or errno.EIO


_OPCODE_NAMES = {value: name[len("MAV_FTP_OPCODE_") :] for name, value in vars(m).items()
                 if name.startswith("MAV_FTP_OPCODE_") and name != "MAV_FTP_OPCODE_ENUM_END"}  # fmt: skip
_ERROR_NAMES = {value: name[len("MAV_FTP_ERR_") :] for name, value in vars(m).items()
                if name.startswith("MAV_FTP_ERR_") and name != "MAV_FTP_ERR_ENUM_END"}  # fmt: skip
