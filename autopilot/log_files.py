"""The autopilot process's flight-log side (part of its shell, beside :mod:`autopilot.app`): the
log directory the MAVLink log download and FTP serve, and the writer's thread the core's flight
log goes to (:mod:`autopilot.logger.storage`). A write that fails is announced once (STATUSTEXT)
and the vehicle flies on. Nothing here decides anything about the vehicle.
"""

from __future__ import annotations

from .core import AutopilotCore
from .logger.storage import LogDirectory, LogWriter
from .mavlink.codec import mavlink


class FlightLogFiles:
    """The flight logs on disk under ``directory`` (None: no flight log at all)."""

    def __init__(self, directory: str | None) -> None:
        self.directory = LogDirectory(directory) if directory is not None else None
        self.writer = LogWriter(self.directory) if self.directory is not None else None
        self._error_reported = False

    def write(self, core: AutopilotCore) -> None:
        """The flight log the core wrote since the last call, to the writer's thread; its first
        write failure announced on every link."""
        if self.writer is None:
            return
        self.writer.handle(core.take_log())
        error = self.writer.error
        if error is not None and not self._error_reported:
            self._error_reported = True
            core.statustext(mavlink.MAV_SEVERITY_CRITICAL, f"flight log not written: {error}"[:200])

    def close(self, core: AutopilotCore) -> None:
        """The log being written closed and written out, the writer's thread ended."""
        if self.writer is None:
            return
        core.flight_log.stop()
        self.write(core)
        self.writer.close()
        self.directory.close()
