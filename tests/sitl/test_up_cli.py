"""`quadsitl up` as a user runs it: banner with the endpoints and the restart policy, clean stop, no
orphans, port clashes (its own instance running; a port of its in use; instances past 249).
Process loss under it: test_up_process_loss.py."""

import os
import re
import signal
import socket
import sys
import time
from pathlib import Path

import pytest

from quadcommon import wire
from sitl.launcher import Child
from tests.ports import instance_ports

pytestmark = pytest.mark.processes  # (tests/conftest.py: the markers)

INSTANCE = 9


def children_of(pid: int) -> list[int]:
    """Direct children of ``pid`` (Linux /proc)."""
    out = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            ppid = int(stat.rsplit(")", 1)[1].split()[1])
            if ppid == pid:
                out.append(int(entry.name))
    return out


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state not in ("Z", "X")


def start_up(*args: str) -> Child:
    """``quadsitl up`` as a child of the launcher (its output read by a thread: no blocking read)."""
    cmd = [sys.executable, "-u", "-m", "sitl.cli", "up", "--instance", str(INSTANCE), "--speed", "max",
           "--no-log", *args]  # fmt: skip
    return Child("quadsitl up", cmd)


def test_up_prints_endpoints_stops_cleanly_and_refuses_a_port_clash():
    up = start_up()
    try:
        up.wait_line("Ctrl-C stops", 30.0)
        text = up.output
        assert f"vehicle {INSTANCE} is up (MAVLink sysid {INSTANCE + 1}" in text
        ports = instance_ports(INSTANCE)
        assert f"udp {ports.gcs_remote}" in text and f"udpin://0.0.0.0:{ports.api_remote}" in text
        assert f"tcp/127.0.0.1:{ports.zenoh}" in text
        assert "then the lost process is restarted (at most 3 restarts per 60 s; --no-restart" in text
        kids = children_of(up.process.pid)
        assert len(kids) == 2, kids  # simulator and autopilot

        clash = start_up()
        assert clash.wait(30.0) == 2
        pattern = rf"port {ports.hil} .*already in use.*--instance {INSTANCE}"
        assert re.search(pattern, clash.output), clash.output
    finally:
        up.signal(signal.SIGTERM)
        code = up.wait(30.0)
    assert code == 0, up.tail()
    assert "quadsitl: stopped" in up.output
    deadline = time.monotonic() + 5
    while any(alive(k) for k in kids) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not any(alive(k) for k in kids), "a child outlived quadsitl up"


def test_up_leaves_no_orphan_when_the_launcher_is_killed():
    up = start_up()
    try:
        up.wait_line("Ctrl-C stops", 30.0)
        kids = children_of(up.process.pid)
        assert len(kids) == 2
    finally:
        up.signal(signal.SIGKILL)  # no chance to clean up: PR_SET_PDEATHSIG must take the children down
        up.wait(10.0)
    deadline = time.monotonic() + 10
    while any(alive(k) for k in kids) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not any(alive(k) for k in kids), "orphaned simulator or autopilot"


def test_up_refuses_a_port_in_use_naming_it_and_refuses_instances_past_249():
    """Instance 80's autopilot GCS link port (18650 with the default bases) is taken: ``quadsitl up``
    refuses before anything starts, naming the port, the link and the instance (no traceback); a
    launch reaching past instance 249 is refused by its arguments."""
    gcs_link = instance_ports(80).gcs_local
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.bind((wire.LOOPBACK, gcs_link))
        up = Child("quadsitl up", [sys.executable, "-u", "-m", "sitl.cli", "up", "--instance", "80"])
        assert up.wait(30.0) == 2
    finally:
        sock.close()
    refusal = f"UDP port {gcs_link} (autopilot GCS link) is already in use: another SITL with --instance 80"
    assert refusal in up.output
    assert "Traceback" not in up.output
    assert "[simulator[80]]" not in up.output and "[autopilot[80]]" not in up.output  # nothing started
    many = Child(
        "quadsitl up", [sys.executable, "-u", "-m", "sitl.cli", "up", "--instance", "240", "--count", "11"]
    )
    assert many.wait(30.0) == 2
    assert "instances must be in [0, 249] (got 240..250)" in many.output
