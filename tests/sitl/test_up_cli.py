"""`quadsitl up` as a user runs it: banner with the endpoints, clean stop, no orphans, port clash."""

import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
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


def start_up(*args: str) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, "-u", "-m", "sitl.cli", "up", "--instance", str(INSTANCE), "--speed", "max", *args],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )


def read_until(proc: subprocess.Popen, needle: str, timeout: float) -> str:
    seen = []
    deadline = time.monotonic() + timeout
    assert proc.stdout is not None
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            break
        seen.append(line)
        if needle in line:
            return "".join(seen)
    raise AssertionError(f"no {needle!r} within {timeout} s:\n" + "".join(seen))


def test_up_prints_endpoints_stops_cleanly_and_refuses_a_port_clash():
    up = start_up()
    try:
        text = read_until(up, "Ctrl-C stops", 30.0)
        assert f"vehicle {INSTANCE} is up (MAVLink sysid {INSTANCE + 1}" in text
        assert f"udp {14550 + INSTANCE}" in text and f"udpin://0.0.0.0:{14540 + INSTANCE}" in text
        assert f"tcp/127.0.0.1:{7447 + INSTANCE}" in text
        kids = children_of(up.pid)
        assert len(kids) == 2, kids  # simulator and autopilot

        clash = start_up()
        out, _ = clash.communicate(timeout=30)
        assert clash.returncode == 2
        assert re.search(rf"port {4560 + INSTANCE} .*already in use.*--instance {INSTANCE}", out), out
    finally:
        up.send_signal(signal.SIGTERM)
        rest, _ = up.communicate(timeout=30)
    assert up.returncode == 0, rest
    assert "quadsitl: stopped" in rest
    deadline = time.monotonic() + 5
    while any(alive(k) for k in kids) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not any(alive(k) for k in kids), "a child outlived quadsitl up"


def test_up_leaves_no_orphan_when_the_launcher_is_killed():
    up = start_up()
    try:
        read_until(up, "Ctrl-C stops", 30.0)
        kids = children_of(up.pid)
        assert len(kids) == 2
    finally:
        up.kill()  # SIGKILL: no chance to clean up; PR_SET_PDEATHSIG must take the children down
        up.wait(10)
    deadline = time.monotonic() + 10
    while any(alive(k) for k in kids) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not any(alive(k) for k in kids), "orphaned simulator or autopilot"
