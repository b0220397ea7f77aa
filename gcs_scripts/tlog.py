"""Writing a MAVLink telemetry log (.tlog) as QGroundControl and MAVProxy do.

A .tlog is a plain sequence of records: an 8-byte big-endian Unix time in microseconds followed
by one raw MAVLink frame. pymavlink (``mavutil.mavlink_connection("x.tlog")``, ``mavlogdump.py``)
and MAVExplorer read it. On read, pymavlink takes the low 2 bits of the stamp as a link id, so
stamps are written with those bits cleared (as mavutil does).

mavutil's own logging does not work for UDP links (``mavudp.recv_msg`` never writes the log),
hence this writer. Appended and flushed by the caller (the recorder flushes every second).
"""

from __future__ import annotations

import struct
import time
from pathlib import Path

_STAMP = struct.Struct(">Q")


class TlogWriter:
    """Appends ``(wall time, raw frame)`` records to a .tlog file."""

    def __init__(self, path: str | Path) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(self.path, "ab")  # noqa: SIM115 - kept open for the whole recording
        self.records = 0
        self.bytes = 0

    def write(self, frame: bytes, unix_time_s: float | None = None) -> None:
        """One raw MAVLink frame (e.g. ``msg.get_msgbuf()``) stamped ``unix_time_s`` (default now)."""
        t = time.time() if unix_time_s is None else unix_time_s
        usec = int(t * 1e6) & ~3  # low 2 bits = link id on read: keep them 0
        record = _STAMP.pack(usec) + bytes(frame)
        self._file.write(record)
        self.records += 1
        self.bytes += len(record)

    def flush(self) -> None:
        """Hand the buffered records to the OS (survives the recorder dying, not a power cut)."""
        self._file.flush()

    def close(self) -> None:
        """Flush and close the file; a second call does nothing."""
        if not self._file.closed:
            self._file.flush()
            self._file.close()
