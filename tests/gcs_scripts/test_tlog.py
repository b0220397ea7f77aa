"""The .tlog writer, read back by pymavlink's mavutil and by the installed mavlogdump.py."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

from gcs_scripts.link import mavutil
from gcs_scripts.tlog import TlogWriter

from .helpers import Vehicle

T0_UNIX = 1_700_000_000.0


def _write_log(path: Path) -> list[tuple[str, float]]:
    vehicle = Vehicle(instance=3)
    writer = TlogWriter(path)
    written = []
    for k in range(20):
        t = k * 0.1
        writer.write(vehicle.local_position(t, x=float(k), y=-1.0, z=-2.5), T0_UNIX + t)
        written.append(("LOCAL_POSITION_NED", T0_UNIX + t))
        if k % 5 == 0:
            writer.write(vehicle.heartbeat(armed=k >= 10), T0_UNIX + t + 0.01)
            written.append(("HEARTBEAT", T0_UNIX + t + 0.01))
    writer.write(vehicle.statustext("landing detected"), T0_UNIX + 2.5)
    written.append(("STATUSTEXT", T0_UNIX + 2.5))
    writer.close()
    return written


def test_tlog_round_trip_through_mavutil(tmp_path: Path) -> None:
    path = tmp_path / "run.tlog"
    written = _write_log(path)
    log = mavutil.mavlink_connection(str(path))
    got = []
    positions = []
    for _ in range(1000):  # bounded: the log has 25 messages
        msg = log.recv_match(blocking=False)
        if msg is None:
            break
        got.append((msg.get_type(), msg._timestamp))
        if msg.get_type() == "LOCAL_POSITION_NED":
            positions.append((msg.time_boot_ms, msg.x, msg.y, msg.z))
            assert msg.get_srcSystem() == 4 and msg.get_srcComponent() == 1
        if msg.get_type() == "STATUSTEXT":
            assert msg.text == "landing detected"
    log.close()
    assert [g[0] for g in got] == [w[0] for w in written]
    for (_, t_got), (_, t_written) in zip(got, written, strict=True):
        assert abs(t_got - t_written) < 1e-5  # µs stamps, low 2 bits cleared
    assert positions[3] == (300, 3.0, -1.0, -2.5)


def test_tlog_readable_by_mavlogdump(tmp_path: Path) -> None:
    path = tmp_path / "run.tlog"
    _write_log(path)
    mavlogdump = Path(sys.executable).parent / "mavlogdump.py"
    assert mavlogdump.exists(), "mavlogdump.py is installed with pymavlink"
    out = subprocess.run(
        [sys.executable, str(mavlogdump), "--types", "LOCAL_POSITION_NED", "--format", "json", str(path)],
        capture_output=True,
        text=True,
        timeout=30,
        check=True,
    )
    records = [json.loads(line) for line in out.stdout.splitlines() if line.startswith("{")]
    assert len(records) == 20
    assert records[5]["data"]["x"] == 5.0
    assert abs(records[5]["meta"]["timestamp"] - (T0_UNIX + 0.5)) < 1e-5
    types = subprocess.run(
        [sys.executable, str(mavlogdump), "--show-types", str(path)],
        capture_output=True,
        text=True,
        timeout=30,
        check=True,
    ).stdout.split()
    assert set(types) == {"LOCAL_POSITION_NED", "HEARTBEAT", "STATUSTEXT"}


def test_tlog_appends_and_flush_makes_records_visible(tmp_path: Path) -> None:
    path = tmp_path / "run.tlog"
    vehicle = Vehicle()
    writer = TlogWriter(path)
    writer.write(vehicle.heartbeat(False), T0_UNIX)
    writer.flush()
    size = path.stat().st_size  # visible to another reader while still open
    assert size == writer.bytes == 8 + len(vehicle.heartbeat(False))
    writer.close()
