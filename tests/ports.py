"""A block of free ports for each pytest process, so test runs never meet each other's SITLs.

Every vehicle a test starts takes its ports from ``sitl.toml``'s ``[ports]`` bases + its instance
(``quadcommon/wire.py``). Each pytest process (the run itself, or each pytest-xdist worker)
claims one block of :data:`BLOCK_STARTS`, checks that every port of every instance 0-249 is free
on 127.0.0.1 (UDP, and TCP for zenoh), and writes a ``sitl.toml`` with those bases into a
configuration directory of its own, put first in ``QUADSITL_CONFIG_DIR``
(:func:`claim_block`). The launcher, the two processes, the ground-station scripts and the
tests themselves (``load_sitl().ports(n)``) then all agree on the block, through the same
configuration mechanism a user has, and two checkouts (or two workers) test at once.

The claim is an exclusive ``flock`` on a file per block in the temporary directory, held until the
process exits (the kernel drops it even when the process is killed); the probe adds ports that
something else (a running ``quadsitl up``) holds. A block keeps the scheme's own layout (the API
client ports just above the one GCS client port is a block's own choice; the scheme moves each
link with its base), so its 250 instances meet nowhere, as with the defaults.
"""

from __future__ import annotations

import atexit
import fcntl
import os
import re
import shutil
import tempfile
from pathlib import Path
from typing import IO

from quadcommon import environment, wire
from quadcommon.config import SHIPPED_CONFIG_DIR

# Below Linux's ephemeral range (32768-60999), so no client's random source port lands in a
# block, and clear of the default bases' ports (4560-4809, 7447-7696, 14540-14550, 14580-14829,
# 18570-18819). A block at S: GCS client S, API client S+1..S+10 and local S+41..S+290, HIL
# S+291..S+540, zenoh S+541..S+790, GCS local S+4020..S+4269 (18570 - 14550 above the client
# port). The starts pack 17 blocks that never meet (tests/test_ports.py checks it).
BLOCK_STARTS = (1100, 1900, 2700, 3680, 7950, 8750, 9550, 10810, 15080, 15880, 16680, 17480,
                21750, 22550, 23350, 24150, 24950)  # fmt: skip
LOCK_DIR = Path(tempfile.gettempdir()) / "quadsitl-test-ports"

_held: list[IO[str]] = []  # the claimed block's lock file, open for the life of the process
_claimed: list[Path] = []  # the configuration directory holding its sitl.toml


def bases(start: int) -> dict[str, int]:
    """The ``[ports]`` keys of the block at ``start``."""
    return {"gcs_base": start, "api_base": start + 1, "hil_base": start + 291, "zenoh_base": start + 541}


def block_ports(start: int) -> set[tuple[str, int]]:
    """(protocol, port) of every port of instances 0-249 on the block at ``start``."""
    b = bases(start)
    found = set()
    for n in range(wire.INSTANCE_MIN, wire.INSTANCE_MAX + 1):
        p = wire.ports(n, b["hil_base"], b["gcs_base"], b["api_base"], b["zenoh_base"])
        found |= {(role.proto, role.port) for role in wire.port_roles(p)}
    return found


def sitl_toml(start: int) -> str:
    """The shipped ``sitl.toml`` with its ``[ports]`` bases on the block at ``start``."""
    text = (SHIPPED_CONFIG_DIR / "sitl.toml").read_text()
    for key, value in bases(start).items():
        text, count = re.subn(rf"(?m)^{key}\s*=\s*\d+", f"{key} = {value}", text)
        if count != 1:
            raise RuntimeError(f"{SHIPPED_CONFIG_DIR / 'sitl.toml'}: no '{key} = <port>' line to set")
    return text


def _busy(start: int) -> list[tuple[str, int]]:
    from sitl.launcher import port_in_use

    return sorted(p for p in block_ports(start) if port_in_use(*p))


def claim_block() -> tuple[int, Path]:
    """Claim a free block for this process and make it the configuration every process started from
    here reads; returns (its start, the configuration directory holding its ``sitl.toml``)."""
    LOCK_DIR.mkdir(parents=True, exist_ok=True)
    refused = []
    for start in BLOCK_STARTS:
        lock = (LOCK_DIR / f"{start}.lock").open("a")
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            lock.close()
            refused.append(f"{start}: claimed by another test process")
            continue
        busy = _busy(start)
        if busy:
            lock.close()
            refused.append(f"{start}: {len(busy)} ports in use, e.g. {busy[0][0]} {busy[0][1]}")
            continue
        _held.append(lock)
        directory = Path(tempfile.mkdtemp(prefix=f"quadsitl-test-ports-{start}-"))
        atexit.register(shutil.rmtree, directory, ignore_errors=True)
        (directory / "sitl.toml").write_text(sitl_toml(start))
        _claimed.append(directory)
        os.environ[environment.CONFIG_DIR] = os.pathsep.join([str(directory), *environment.config_dir_list()])
        return start, directory
    raise RuntimeError("no free port block for the tests that start a SITL: " + "; ".join(refused))


def instance_ports(instance: int) -> wire.Ports:
    """Every port of vehicle ``instance`` as the processes a test starts see them: under the
    ``sitl.toml`` found first (this process's block, :func:`claim_block`)."""
    from quadcommon.config import load_sitl

    return load_sitl().ports(instance)


def shipped_ports_environment() -> dict[str, str]:
    """This process's environment without its block's configuration directory: for a child that
    must run on the shipped default ports (inside a network namespace of its own)."""
    own = {str(directory) for directory in _claimed}
    rest = [d for d in environment.config_dir_list() if d not in own]
    env = dict(os.environ)
    if rest:
        env[environment.CONFIG_DIR] = os.pathsep.join(rest)
    else:
        env.pop(environment.CONFIG_DIR, None)
    return env


def block_config_dir() -> Path | None:
    """The configuration directory of this process's block (only its ``sitl.toml``), if claimed."""
    return _claimed[0] if _claimed else None
