"""The log directory on disk and the thread that writes into it: the process shell's side of logging.

:class:`LogDirectory` is PX4's layout, ``ROOT/YYYY-MM-DD/HH_MM_SS.ulg`` (UTC, when the log
started; ``HH_MM_SS_1.ulg`` ... if that name is taken), or, without a wall clock (in-process
runs), PX4's own fallback ``ROOT/sess001/log001.ulg`` numbering. It lists, reads and erases the
logs for the MAVLink log download (:class:`autopilot.mavlink.log_transfer.LogStore`).

:class:`LogWriter` writes what :class:`~autopilot.logger.logger.FlightLogger` produced, in a
thread of its own: the autopilot's loop only queues the bytes (every housekeeping tick, 50 ms of
wall time) and the thread writes them at once with ``os.write``, so they are the operating
system's as soon as they are handed over (a ``kill -9`` of the autopilot loses nothing written
before the last tick), and ``fsync``s the file at least once a second (a crash of the machine
loses at most that). A write that fails (disk full, permissions) is reported once through
:attr:`LogWriter.error` and that log is abandoned; the vehicle flies on. The in-process runner
uses the same writer without the thread (``threaded=False``).
"""

from __future__ import annotations

import os
import queue
import threading
import time
from calendar import timegm
from pathlib import Path

from ..mavlink.log_transfer import LogEntry
from .logger import LogClose, LogOpen

FSYNC_EVERY_S = 1.0
SUFFIX = ".ulg"


class LogDirectory:
    """The logs under ``root`` in PX4's layout (module docstring): names for a new log, and the
    :class:`~autopilot.mavlink.log_transfer.LogStore` the MAVLink log download reads (list, read, erase)."""

    def __init__(self, root: str | Path) -> None:
        self.root = Path(root)
        self.writing: Path | None = None  # the log being written (never erased)
        self._read_key: str | None = None
        self._read_fd: int | None = None
        self._session: Path | None = None  # sessNNN of this boot (logs without a clock)
        self._logs_in_session = 0

    def new_path(self, utc_s: float | None) -> Path:
        """Where a log starting now goes (directories created)."""
        if utc_s is not None:
            folder = self.root / time.strftime("%Y-%m-%d", time.gmtime(utc_s))
            stem = time.strftime("%H_%M_%S", time.gmtime(utc_s))
        else:  # PX4's numbering without a clock: a session folder per boot, its logs numbered
            if self._session is None:
                taken = [int(p.name[4:]) for p in self.root.glob("sess[0-9][0-9][0-9]")]
                self._session = self.root / f"sess{max(taken, default=0) + 1:03d}"
            folder = self._session
            self._logs_in_session += 1
            stem = f"log{self._logs_in_session:03d}"
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / f"{stem}{SUFFIX}"
        n = 0
        while path.exists():
            n += 1
            path = folder / f"{stem}_{n}{SUFFIX}"
        return path

    # -- LogStore (the MAVLink log download) -------------------------------------------------------
    def entries(self) -> list[LogEntry]:
        """Every ``.ulg`` one level down, oldest first (by folder, then name), with its size now."""
        if not self.root.is_dir():
            return []
        out = []
        for path in sorted(self.root.glob(f"*/*{SUFFIX}"), key=lambda p: (p.parent.name, p.name)):
            try:
                stat = path.stat()
            except OSError:
                continue  # removed meanwhile
            out.append(LogEntry(str(path), stat.st_size, _start_time(path, stat.st_mtime)))
        return out

    def read(self, key: str, offset: int, count: int) -> bytes:
        """Up to ``count`` bytes of log ``key`` from ``offset`` (fewer at its end; b"" if gone)."""
        try:
            if key != self._read_key:
                self._close_reader()
                self._read_fd = os.open(key, os.O_RDONLY)
                self._read_key = key
            return os.pread(self._read_fd, count, offset)
        except (OSError, ValueError, OverflowError):
            self._close_reader()
            return b""

    def erase(self) -> int:
        """Delete every log but the one being written (and the folders left empty); how many."""
        self._close_reader()
        erased = 0
        for entry in self.entries():
            path = Path(entry.key)
            if self.writing is not None and path == self.writing:
                continue
            try:
                path.unlink()
                erased += 1
            except OSError:
                pass
        for folder in self.root.glob("*/") if self.root.is_dir() else ():
            try:
                folder.rmdir()  # only if empty
            except OSError:
                pass
        return erased

    def close(self) -> None:
        """Close the file a log download was reading, if any."""
        self._close_reader()

    def _close_reader(self) -> None:
        if self._read_fd is not None:
            try:
                os.close(self._read_fd)
            except OSError:
                pass
        self._read_fd = self._read_key = None


def _start_time(path: Path, mtime: float) -> int:
    """POSIX seconds from ``YYYY-MM-DD/HH_MM_SS[_n].ulg`` (UTC), else the file's mtime (as PX4)."""
    try:
        stamp = time.strptime(f"{path.parent.name} {path.stem[:8]}", "%Y-%m-%d %H_%M_%S")
        return int(timegm(stamp))
    except ValueError:
        return int(mtime)


class LogWriter:
    """Writes :meth:`FlightLogger.take`'s items into :class:`LogDirectory` files."""

    def __init__(self, directory: LogDirectory, threaded: bool = True) -> None:
        """``threaded=False``: every item is written at once by the caller, without fsync (the
        in-process runner: simulation time, where a 5 ms fsync would be the run's cost)."""
        self.directory = directory
        self._fsync = threaded
        self.error: str | None = None  # the first write failure (the shell reports it once)
        self.written: list[Path] = []  # every log opened, in order
        self._fd: int | None = None
        self._path: Path | None = None
        self._last_sync = 0.0
        self._dirty = False
        self._queue: queue.SimpleQueue | None = None
        self._thread: threading.Thread | None = None
        if threaded:
            self._queue = queue.SimpleQueue()
            self._thread = threading.Thread(target=self._run, name="ulog-writer", daemon=True)
            self._thread.start()

    def handle(self, items: list) -> None:
        """The logger's items, in order: a LogOpen gets its path here (the listing knows at once
        which log is being written), the bytes and the close are the thread's."""
        for item in items:
            if isinstance(item, LogOpen):
                try:
                    path = self.directory.new_path(item.utc_s)
                except OSError as exc:  # the directory cannot be made: this log is not written
                    if self.error is None:
                        self.error = f"{self.directory.root}: {exc.strerror or exc}"
                    self._do(("open", None))
                    continue
                self.directory.writing = path
                self.written.append(path)
                self._do(("open", path))
            elif isinstance(item, LogClose):
                self.directory.writing = None
                self._do(("close", None))
            else:
                self._do(("data", item))

    def close(self, timeout_s: float = 5.0) -> None:
        """Write what is queued, close the file, end the thread."""
        self._do(("close", None))
        if self._thread is not None:
            self._queue.put(("stop", None))
            self._thread.join(timeout_s)

    def _do(self, op: tuple) -> None:
        if self._queue is not None:
            self._queue.put(op)
        else:
            self._apply(*op)

    def _run(self) -> None:
        while True:
            try:
                op = self._queue.get(timeout=FSYNC_EVERY_S)
            except queue.Empty:
                self._sync_if_due(force=True)
                continue
            if op[0] == "stop":
                return
            self._apply(*op)

    def _apply(self, kind: str, value) -> None:
        try:
            if kind == "open":
                self._close_file()
                self._path = value
                if value is not None:  # None: a log that could not be placed (its bytes are dropped)
                    self._fd = os.open(value, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
                    self._last_sync = time.monotonic()
            elif kind == "data":
                if self._fd is not None:
                    view = memoryview(value)
                    while view:
                        view = view[os.write(self._fd, view) :]
                    self._dirty = True
                    self._sync_if_due()
            elif kind == "close":
                self._close_file()
        except OSError as exc:
            if self.error is None:
                self.error = f"{self._path}: {exc.strerror or exc}"
            self._abandon()

    def _sync_if_due(self, force: bool = False) -> None:
        if self._fd is None or not self._dirty or not self._fsync:
            return
        now = time.monotonic()
        if force or now - self._last_sync >= FSYNC_EVERY_S:
            try:
                os.fsync(self._fd)
            except OSError:
                pass  # a file system without fsync: the data is written, not forced to disk
            self._last_sync = now
            self._dirty = False

    def _close_file(self) -> None:
        if self._fd is not None:
            self._sync_if_due(force=True)
            os.close(self._fd)
            self._fd = None

    def _abandon(self) -> None:
        if self._fd is not None:
            try:
                os.close(self._fd)
            except OSError:
                pass
        self._fd = None
