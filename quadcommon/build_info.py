"""What this build of quadsitl is: its version and its git commit, and how PX4 reports its own.

PX4 tells a ground station what it runs in ``AUTOPILOT_VERSION`` (QGC's "Firmware Version" and
"Git Revision", MAVSDK's ``Info.get_version()``), and its flight logs carry the same numbers:

* ``flight_sw_version``: ``0xMMmmppTT``, major, minor, patch and the release type
  (``FIRMWARE_VERSION_TYPE``: 0 development, 64 alpha, 128 beta, 192 release candidate, 255 a
  release), :func:`flight_sw_version`. Here the version is the package's (``pyproject.toml``),
  read as PEP 440: ``0.1.0`` is a release, ``0.2.0rc1`` a release candidate, ``0.2.0.dev3`` and a
  local version (``+g1234``) development;
* ``flight_custom_version``: the first 8 bytes of the git commit. PX4 reads the first 16 hex
  digits of its hash as a 64-bit integer and copies it little-endian, so the bytes are in reverse
  order (QGC and MAVSDK reverse them back to print the hash), :meth:`BuildInfo.custom_version`.

Where the commit comes from, in order (:func:`this_build`; file reads, so a process's shell calls
it and hands the result to its core):

1. the checkout the code runs from: its ``.git`` next to the packages (a worktree's ``.git``
   file followed), ``HEAD`` resolved through ``refs/`` or ``packed-refs``, without running git;
2. else the commit written into the wheel when it was built from a checkout
   (``quadcommon/GIT_COMMIT``, by ``setup.py``);
3. else none: zeros on the wire, "unknown" in text.
"""

from __future__ import annotations

import re
from importlib import metadata
from pathlib import Path
from typing import NamedTuple

PACKAGE = "quadsitl"
COMMIT_FILE = "GIT_COMMIT"  # beside this module in a built wheel (setup.py writes it)
CHECKOUT = Path(__file__).resolve().parent.parent  # the repository root, when run from a checkout
FIRMWARE_TYPE_DEV, FIRMWARE_TYPE_ALPHA, FIRMWARE_TYPE_BETA, FIRMWARE_TYPE_RC, FIRMWARE_TYPE_OFFICIAL = (
    0, 64, 128, 192, 255)  # fmt: skip
_PRE_RELEASE = {"a": FIRMWARE_TYPE_ALPHA, "b": FIRMWARE_TYPE_BETA, "rc": FIRMWARE_TYPE_RC}
_VERSION = re.compile(
    r"v?(\d+)(?:\.(\d+))?(?:\.(\d+))?(?:\.\d+)*(?:[-_.]?(a|b|rc)\d*)?(?:[-_.]?post\d*)?([-_.]?dev\d*)?(\+.*)?")
_HASH = re.compile(r"[0-9a-f]{40}([0-9a-f]{24})?")  # SHA-1, or SHA-256


class BuildInfo(NamedTuple):
    """A build: the package's ``version`` ("" when unknown) and its git ``commit`` (40 or 64 hex
    digits; None when unknown)."""

    version: str = ""
    commit: str | None = None

    @property
    def flight_sw_version(self) -> int:
        """``flight_sw_version``: the package version in PX4's encoding (:func:`flight_sw_version`)."""
        return flight_sw_version(self.version)

    @property
    def custom_version(self) -> list[int]:
        """``flight_custom_version``: the commit's first 16 hex digits as PX4 sends them (a uint64
        copied little-endian: reversed bytes); zeros without a commit."""
        if self.commit is None:
            return [0] * 8
        return list(int(self.commit[:16], 16).to_bytes(8, "little"))

    @property
    def commit_text(self) -> str:
        """The git commit as text, ``unknown`` without one."""
        return self.commit or "unknown"


def flight_sw_version(version: str) -> int:
    """PX4's encoding of a version, ``0xMMmmppTT`` (each part at most 255; 0 for what is not a
    version)."""
    match = _VERSION.fullmatch(version.strip())
    if match is None:
        return 0
    major, minor, patch = (min(int(part or 0), 255) for part in match.group(1, 2, 3))
    pre, dev, local = match.group(4, 5, 6)
    if dev or local:
        kind = FIRMWARE_TYPE_DEV
    elif pre:
        kind = _PRE_RELEASE[pre]
    else:
        kind = FIRMWARE_TYPE_OFFICIAL
    return (major << 24) | (minor << 16) | (patch << 8) | kind


def this_build() -> BuildInfo:
    """The running build (reads the installed metadata and files; see the module's docstring)."""
    return BuildInfo(package_version(), checkout_commit(CHECKOUT / ".git") or packaged_commit())


def package_version() -> str:
    """The installed package's version, else the checkout's ``pyproject.toml``'s, else ""."""
    try:
        return metadata.version(PACKAGE)
    except metadata.PackageNotFoundError:
        pass
    try:
        import tomllib

        with open(CHECKOUT / "pyproject.toml", "rb") as file:
            return str(tomllib.load(file)["project"]["version"])
    except (OSError, KeyError, ValueError):
        return ""


def packaged_commit() -> str | None:
    """The commit ``setup.py`` wrote into the wheel, if it did."""
    try:
        text = (Path(__file__).resolve().parent / COMMIT_FILE).read_text().strip().lower()
    except OSError:
        return None
    return text if _HASH.fullmatch(text) else None


def checkout_commit(git: Path) -> str | None:
    """The commit checked out in the repository whose ``.git`` is ``git`` (a directory, or a
    worktree's file naming one), or None (no repository, or one this reader does not follow)."""
    try:
        if git.is_file():
            text = git.read_text().strip()
            if not text.startswith("gitdir:"):
                return None
            git = (git.parent / text[len("gitdir:") :].strip()).resolve()
        head = (git / "HEAD").read_text().strip()
        common = git
        if (git / "commondir").is_file():  # a worktree: refs live in the main repository
            common = (git / (git / "commondir").read_text().strip()).resolve()
        if not head.startswith("ref:"):
            return head.lower() if _HASH.fullmatch(head.lower()) else None
        ref = head[len("ref:") :].strip()
        for base in (git, common):
            path = base / ref
            if path.is_file():
                commit = path.read_text().strip().lower()
                return commit if _HASH.fullmatch(commit) else None
        packed = common / "packed-refs"
        if packed.is_file():
            for line in packed.read_text().splitlines():
                parts = line.split()
                if len(parts) == 2 and parts[1] == ref and _HASH.fullmatch(parts[0].lower()):
                    return parts[0].lower()
    except (OSError, UnicodeDecodeError, ValueError):
        return None
    return None
