"""The vehicle's files as MAVLink FTP serves them: the process shell's side (directories, descriptors).

The root ``/`` is virtual, one entry per mount (:meth:`VehicleFiles.for_vehicle`):

* ``/log/``: the flight-log directory (``--log-dir``, :class:`~autopilot.logger.storage.LogDirectory`),
  in PX4 SITL's layout (``/log/2025-06-15/15_06_40.ulg``, or ``/log/sess001/log001.ulg`` without a
  wall clock). Read, and written as PX4 lets a ground station write its storage: files created,
  written, truncated, renamed, removed, directories created and removed; never the log being
  written (``FileProtected``: it is the logger's until it closes);
* ``/params.toml``: the parameter file (``--params FILE``), when there is one: read-only, since the
  autopilot rewrites it on every change (load it with ``MAV_CMD_PREFLIGHT_STORAGE``).

Missions and rally points live in the autopilot's memory, not in files: the mission protocol
transfers them. Nothing else of the machine is reachable: a name resolving outside its mount, or
through a symbolic link anywhere below the mount's directory, is ``FileProtected``; the final
component is opened with ``O_NOFOLLOW``, so a link swapped in meanwhile is not followed either;
only regular files and directories are listed and opened.

Errors: :class:`~autopilot.mavlink.ftp.FtpError` for what is refused by rule, ``OSError`` for what
the system refuses (the FTP core answers both as PX4 does).
"""

from __future__ import annotations

import os
import stat
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import NamedTuple

from .mavlink.ftp import ERR_FILE_NOT_FOUND, ERR_FILE_PROTECTED, Entry, FtpError, OpenMode

LOG_MOUNT = "log"
PARAMS_MOUNT = "params.toml"
MAX_LIST_ENTRIES = 10_000  # entries of one directory looked at (a listing sorts them all)
_OPEN_FLAGS = {
    OpenMode.READ: os.O_RDONLY,
    OpenMode.WRITE: os.O_WRONLY | os.O_CREAT,
    OpenMode.CREATE: os.O_WRONLY | os.O_CREAT | os.O_TRUNC,
}
_NOFOLLOW = getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_CLOEXEC", 0)


class Mount(NamedTuple):
    """One entry of the root: a directory (and everything below it) or a single file."""

    name: str
    path: Path
    is_dir: bool
    writable: bool


class VehicleFiles:
    """:class:`~autopilot.mavlink.ftp.FileSystem` over real directories; ``protected()`` names the
    files nothing may write, remove or rename (the log being written)."""

    def __init__(self, mounts: Sequence[Mount], protected: Callable[[], Sequence[Path]] = tuple) -> None:
        self.mounts = {mount.name: mount for mount in mounts}
        self.protected = protected

    @classmethod
    def for_vehicle(cls, logs=None, params_file: str | os.PathLike | None = None) -> VehicleFiles:
        """The root of a vehicle: ``logs`` its :class:`~autopilot.logger.storage.LogDirectory` (None:
        no flight logs), ``params_file`` its parameter file (None: none)."""
        mounts = []
        if logs is not None:
            mounts.append(Mount(LOG_MOUNT, Path(logs.root), is_dir=True, writable=True))
        if params_file is not None:
            mounts.append(Mount(PARAMS_MOUNT, Path(params_file), is_dir=False, writable=False))

        def protected() -> tuple[Path, ...]:
            return (logs.writing,) if logs is not None and logs.writing is not None else ()

        return cls(mounts, protected)

    # -- names ----------------------------------------------------------------------------------
    def _resolve(self, path: tuple[str, ...]) -> tuple[Mount, Path]:
        """The mount ``path`` is in and the real path it names (never the root itself)."""
        mount = self.mounts.get(path[0]) if path else None
        if mount is None:
            raise FtpError(ERR_FILE_NOT_FOUND, why="no such entry in the root")
        if not mount.is_dir:
            if len(path) > 1:
                raise FtpError(ERR_FILE_NOT_FOUND, why=f"{mount.name} is a file")
            return mount, Path(os.path.realpath(mount.path))  # the file the user named, wherever it is
        base = Path(os.path.realpath(mount.path))
        target = base.joinpath(*path[1:])
        if os.path.realpath(target) != str(target):  # a symbolic link on the way (or a '..' in it)
            raise FtpError(ERR_FILE_PROTECTED, why="symbolic links are not followed")
        return mount, target

    def _writable(self, path: tuple[str, ...], whole_tree: bool = False) -> Path:
        """The real path of a name that may be written (a file or directory below a writable
        mount, not the mount itself, nothing the logger is writing at or below it)."""
        mount, target = self._resolve(path)
        if not mount.writable or len(path) < 2:
            raise FtpError(ERR_FILE_PROTECTED, why=f"/{mount.name} is read-only")
        for busy in self.protected():
            busy = Path(os.path.realpath(busy))
            if busy == target or (whole_tree and busy.is_relative_to(target)):
                raise FtpError(ERR_FILE_PROTECTED, why="the log being written")
        os.makedirs(Path(os.path.realpath(mount.path)), exist_ok=True)  # a log directory not made yet
        return target

    # -- FileSystem -----------------------------------------------------------------------------
    def list(self, path: tuple[str, ...]) -> list[Entry]:
        """The root's mounts, or a directory's regular files (with sizes) and directories, sorted; symbolic
        links and other kinds are not listed, at most :data:`MAX_LIST_ENTRIES` looked at."""
        if not path:
            return [entry for mount in self.mounts.values() if (entry := self._mount_entry(mount))]
        mount, target = self._resolve(path)
        if not mount.is_dir:
            raise NotADirectoryError(f"/{mount.name} is a file")
        if len(path) == 1 and not target.exists():
            return []  # the log directory before the first log
        entries = []
        with os.scandir(target) as scan:
            for count, item in enumerate(scan):
                if count >= MAX_LIST_ENTRIES:
                    break
                try:
                    item.name.encode("utf-8")  # (undecodable names come as surrogates)
                    if item.is_dir(follow_symlinks=False):
                        entries.append(Entry(item.name, True))
                    elif item.is_file(follow_symlinks=False):
                        entries.append(Entry(item.name, False, item.stat(follow_symlinks=False).st_size))
                except (OSError, UnicodeEncodeError):
                    continue  # gone meanwhile, or a name FTP cannot carry
        return sorted(entries)

    def _mount_entry(self, mount: Mount) -> Entry | None:
        if mount.is_dir:
            return Entry(mount.name, True)
        try:
            return Entry(mount.name, False, os.stat(mount.path).st_size)
        except OSError:
            return None  # a parameter file not saved yet

    def open(self, path: tuple[str, ...], mode: OpenMode) -> tuple[int, int]:
        """Open a regular file without following a symbolic link: for reading below any mount, for writing
        only below a writable one and never the log being written; the descriptor and the size."""
        target = self._resolve(path)[1] if mode is OpenMode.READ else self._writable(path)
        fd = os.open(target, _OPEN_FLAGS[mode] | _NOFOLLOW, 0o644)
        try:
            info = os.fstat(fd)
            if not stat.S_ISREG(info.st_mode):
                raise IsADirectoryError(f"not a regular file: /{'/'.join(path)}")
        except BaseException:
            os.close(fd)
            raise
        return fd, info.st_size

    def read(self, handle: int, offset: int, count: int) -> bytes:
        """``os.pread`` of the descriptor: up to ``count`` bytes from ``offset``."""
        return os.pread(handle, count, offset)

    def write(self, handle: int, offset: int, data: bytes) -> int:
        """``os.pwrite`` of ``data`` at ``offset``; the count written."""
        return os.pwrite(handle, data, offset)

    def close(self, handle: int) -> None:
        """Close the descriptor."""
        os.close(handle)

    def identity(self, handle: int) -> tuple:
        """The open file's device, inode, modification time (ns) and size: a changed file gets a new CRC."""
        info = os.fstat(handle)
        return (info.st_dev, info.st_ino, info.st_mtime_ns, info.st_size)

    def remove_file(self, path: tuple[str, ...]) -> None:
        """Delete a file below a writable mount (a directory: IsADirectoryError; the log being written:
        FileProtected)."""
        target = self._writable(path)
        if os.path.isdir(target):
            raise IsADirectoryError(f"a directory: /{'/'.join(path)}")
        os.unlink(target)

    def create_directory(self, path: tuple[str, ...]) -> None:
        """Create a directory below a writable mount (mode 0755)."""
        os.mkdir(self._writable(path), 0o755)

    def remove_directory(self, path: tuple[str, ...]) -> None:
        """Delete an empty directory below a writable mount, unless it holds the log being written."""
        os.rmdir(self._writable(path, whole_tree=True))

    def rename(self, old: tuple[str, ...], new: tuple[str, ...]) -> None:
        """Rename within one writable mount; neither name may be or hold the log being written."""
        source, target = self._writable(old, whole_tree=True), self._writable(new, whole_tree=True)
        if old[0] != new[0]:
            raise FtpError(ERR_FILE_PROTECTED, why="a rename stays within its mount")
        os.rename(source, target)

    def truncate(self, path: tuple[str, ...], length: int) -> None:
        """Cut or extend a regular file below a writable mount to ``length`` bytes (without following a
        symbolic link)."""
        fd = os.open(self._writable(path), os.O_WRONLY | _NOFOLLOW)
        try:
            if not stat.S_ISREG(os.fstat(fd).st_mode):
                raise IsADirectoryError(f"not a regular file: /{'/'.join(path)}")
            os.ftruncate(fd, length)
        finally:
            os.close(fd)
