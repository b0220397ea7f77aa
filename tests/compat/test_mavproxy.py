"""MAVProxy (headless, scripted on stdin) flies a quadsitl vehicle as it would a PX4 SITL.

Connect, parameters (fetch, show, set: float and PX4's bytewise int32), mode changes, ``arm
throttle``, ``takeoff``, ``wp load`` of a QGC WPL 110 file, ``wp list``, the mission flown,
``link`` (no packet counted lost), land.
What each command did to the vehicle is checked on the simulator's ground truth (zenoh), not only
on what MAVProxy prints.

Two things a PX4 user meets here, both from the client side, both the same against PX4 SITL:

* ``mode NAME`` (and the bare ``NAME`` shortcuts) cannot set a PX4 mode in MAVProxy 1.8.75 with
  pymavlink 2.4.x: it prints ``ERROR in command [...]: required argument is not a float`` and sends
  nothing (pymavlink's ``px4_map`` tuple is passed on as a float). The working form is
  ``long DO_SET_MODE 1 MAIN SUB`` (e.g. ``1 4 3`` AUTO.LOITER, ``1 4 4`` AUTO.MISSION).
  :func:`test_mavproxy_flies_a_vehicle` tries ``mode`` first and warns while it is broken.
* ``takeoff ALT`` sends NAV_TAKEOFF with param7 = ALT metres above home (ArduPilot's meaning);
  the autopilot reads a param7 that would lie underground as AMSL as a height above home
  (autopilot/app.py), so ``takeoff 3`` climbs to 3 m. PX4 would ignore it and climb to
  MIS_TAKEOFF_ALT.

After the landing, ``log list`` / ``log download N FILE`` (MAVProxy's log module, LOG_REQUEST_*):
the flight's own log is listed beside the two the vehicle had, and one comes down byte-identical;
then the same over MAVLink FTP (MAVProxy's ftp module: ``ftp list``, ``ftp get``, ``ftp crc``).

Waypoint files: line 0 of a QGC WPL 110 file is a real mission item here (PX4's semantics; MAVProxy
uploads every line as seq 0..n-1). An ArduPilot file whose line 0 is the home position is flown
as a waypoint at home: with frame 0 (AMSL) at the home altitude that is a point on the ground.
"""

from __future__ import annotations

import math
import re
import time
import warnings

import pytest

from autopilot.mavlink.ftp import crc32
from quadcommon import frames
from quadcommon.config import load_sitl

from ..ulog_check import check_ulog
from .mavproxy_driver import MavProxy
from .vehicles import TruthTap, ports, sitl_output, vehicle, vehicle_logs

pytestmark = [pytest.mark.processes, pytest.mark.compat]  # (tests/conftest.py: the markers)

INSTANCE = 5  # sysid 6
SYSID = 1 + INSTANCE
ALT = 3.0
WAYPOINTS_NE = [(0.0, 0.0), (3.0, 0.0), (3.0, 3.0)]  # line 0 is flown: PX4 semantics
RTL, LOITER = (4 << 16) | (5 << 24), (4 << 16) | (3 << 24)  # PX4 custom_mode of AUTO.RTL, AUTO.LOITER
COMPLETE = 5  # MISSION_STATE_COMPLETE


def write_plan(path, home) -> list[tuple[float, float, float]]:
    """A QGC WPL 110 file (tab separated: seq, current, frame, command, p1-p4, lat, lon, alt,
    autocontinue); frame 3 = GLOBAL_RELATIVE_ALT. Returns the waypoints in the paper frame."""
    lines, targets = ["QGC WPL 110"], []
    for seq, (north, east) in enumerate(WAYPOINTS_NE):
        lat, lon, _ = frames.ned_to_geodetic(north, east, 0.0, home)
        acceptance = 0.3
        lines.append(f"{seq}\t{int(seq == 0)}\t3\t16\t0\t{acceptance}\t0\t0\t{lat:.9f}\t{lon:.9f}\t{ALT}\t1")
        targets.append((north, -east, ALT))
    path.write_text("\n".join(lines) + "\n")
    return targets


def position(row) -> tuple[float, float, float]:
    return (row["x_m"], row["y_m"], row["z_m"])


def test_mavproxy_flies_a_vehicle(tmp_path, compat_sitl_config, flight_logs):
    started = time.monotonic()
    home = load_sitl(str(compat_sitl_config)).home
    targets = write_plan(tmp_path / "mission.txt", home)
    log_dir = tmp_path / "log"
    on_vehicle = vehicle_logs(log_dir, flight_logs)
    with (
        vehicle(INSTANCE, compat_sitl_config, speed="2", log_dir=log_dir) as sitl,
        TruthTap(INSTANCE) as truth,
    ):
        mp = MavProxy(ports(INSTANCE).gcs_remote, tmp_path)
        try:
            mp.expect(rf"online system {SYSID}\b", 15)
            mp.expect(r"Mode LOITER", 10)  # PX4's AUTO.LOITER, as the vehicle boots

            # Parameters: MAVProxy fetches the whole list first (FTP, else PARAM_REQUEST_LIST).
            count = int(mp.expect(r"Received (\d+) parameters", 30).group(1))
            assert count > 20
            mp.command("param show MIS_TAKEOFF_ALT", r"MIS_TAKEOFF_ALT\s+2\.5\b", 5)
            mp.send("param set MIS_TAKEOFF_ALT 3.5")  # prints nothing; the cache follows the echo
            poll_param(mp, "MIS_TAKEOFF_ALT", r"3\.5\b")
            mp.command("param show COM_DL_LOSS_T", r"COM_DL_LOSS_T\s+10\b", 5)
            mp.send("param set COM_DL_LOSS_T 12")  # INT32: MAVProxy encodes it bytewise for PX4
            poll_param(mp, "COM_DL_LOSS_T", r"12\b")

            # Modes: "mode NAME" first, as a user would type it. MAVProxy announces "Mode X" at
            # most every 2 s, so the mode it sees is read back with "status HEARTBEAT".
            mp.send("mode RTL")  # (POSCTL would need the sticks: MAVProxy sends none here)
            line = mp.expect(r"ERROR in command|Got COMMAND_ACK: DO_SET_MODE", 5)
            if line.group(0).startswith("ERROR"):
                warnings.warn(
                    "MAVProxy 'mode NAME' cannot set PX4 modes (client bug: pymavlink px4_map tuple "
                    "passed as a float); using 'long DO_SET_MODE 1 MAIN SUB'",
                    stacklevel=1,
                )
                mp.command("long DO_SET_MODE 1 4 5", r"Got COMMAND_ACK: DO_SET_MODE: ACCEPTED", 5)
            wait_status(mp, "HEARTBEAT", lambda f: f["custom_mode"] == RTL, "AUTO.RTL")
            mp.command("long DO_SET_MODE 1 4 3", r"Got COMMAND_ACK: DO_SET_MODE: ACCEPTED", 5)
            wait_status(mp, "HEARTBEAT", lambda f: f["custom_mode"] == LOITER, "AUTO.LOITER")

            mp.command("arm throttle", r"^ARMED", 5)
            mp.command("takeoff 3", r"Got COMMAND_ACK: NAV_TAKEOFF: ACCEPTED", 5)
            row = truth.wait("hover at 3 m", lambda r: abs(r["z_m"] - ALT) < 0.02 and abs(r["vz_m_s"]) < 0.02,
                             15)  # fmt: skip
            assert math.hypot(row["x_m"], row["y_m"]) < 0.05
            wait_status(mp, "HEARTBEAT", lambda f: f["custom_mode"] == LOITER, "AUTO.LOITER after takeoff")

            mp.command("wp load mission.txt", r"Loaded 3 waypoints", 5)
            mp.expect(r"Sent all 3 waypoints", 5)
            mp.expect(r"Got MISSION_ACK: TYPE_MISSION: ACCEPTED", 5)
            mp.command("wp list", r"Requesting 3 waypoints", 5)
            for north, east in WAYPOINTS_NE:  # the download: the items as uploaded
                item = mp.expect(r"^16 3 (\S+) (\S+) (\S+) ", 5)
                lat, lon, _ = frames.ned_to_geodetic(north, east, 0.0, home)
                got = tuple(float(v) for v in item.groups())
                assert math.dist(got, (lat, lon, ALT)) < 1e-6, (got, (lat, lon, ALT))

            mp.command("long DO_SET_MODE 1 4 4", r"Got COMMAND_ACK: DO_SET_MODE: ACCEPTED", 5)
            mp.expect(r"waypoint 1\b", 10)  # MISSION_CURRENT moves on (printed on every change)
            complete = wait_status(
                mp, "MISSION_CURRENT", lambda f: f["mission_state"] == COMPLETE, "mission complete", 25
            )
            assert complete["seq"] == 2 and complete["total"] == 3
            last = targets[-1]
            truth.wait("at the last waypoint", lambda r: math.dist(position(r), last) < 0.05, 5)
            track = truth.drain()
            for target in targets:  # every waypoint visited, line 0 included
                closest = min(math.dist((r[1], r[2], r[3]), target) for r in track)
                assert closest < 0.3, (target, closest)

            # MAVProxy's link statistics count a gap in a link's sequence numbers as lost packets:
            # none on loopback (each of the vehicle's links numbers its own frames, as PX4's).
            stats = mp.command("link", r"link 1 OK \((\d+) packets, .*?(\d+) lost, ([\d.]+)% loss", 5)
            assert int(stats.group(1)) > 500 and float(stats.group(3)) < 5.0, stats.group(0)
            mp.command("long NAV_LAND", r"Got COMMAND_ACK: NAV_LAND: ACCEPTED", 5)
            mp.expect(r"^DISARMED", 30)  # landed; disarmed after COM_DISARM_LAND
            row = truth.latest()
            assert row is not None and row["z_m"] < 0.01

            # The flight logs: the two the vehicle had, and this flight's (from arming to disarming)
            flight = [p for p in log_dir.glob("*/*.ulg") if p not in on_vehicle]
            mp.send("log list")
            listed = {}
            for _ in range(3):
                entry = mp.expect(r"^Log (\d+)\s+numLogs (\d+)\s+lastLog (\d+)\s+size (\d+)", 10)
                log_id, count, last, size = (int(v) for v in entry.groups())
                assert (count, last) == (3, 2)
                listed[log_id] = size
            assert len(flight) == 1
            check_ulog(flight[0])  # this flight's log, written by the autopilot process
            assert listed == {k: p.stat().st_size for k, p in enumerate([*on_vehicle, *flight])}
            mp.send("log download 1 got1.ulg")
            mp.expect(r"Finished downloading got1.ulg", 30)
            assert (tmp_path / "got1.ulg").read_bytes() == on_vehicle[1].read_bytes()

            # MAVLink FTP: the log directory in PX4 SITL's layout, a log by bursts, its CRC.
            day, name = on_vehicle[0].parent.name, on_vehicle[0].name
            mp.command("ftp list /log", rf"^ D {day}$", 10)
            mp.send(f"ftp list /log/{day}")
            for log in on_vehicle:
                mp.expect(rf"^\s+{log.name}\t{log.stat().st_size}$", 10)
            mp.command(f"ftp get /log/{day}/{name} got_ftp.ulg", r"^Wrote \d+ bytes to got_ftp.ulg", 30)
            got, size = tmp_path / "got_ftp.ulg", on_vehicle[0].stat().st_size
            flushed = time.monotonic() + 5.0  # MAVProxy prints "Wrote" before its file is closed
            while got.stat().st_size < size and time.monotonic() < flushed:
                time.sleep(0.05)
            assert got.read_bytes() == on_vehicle[0].read_bytes()
            crc = mp.command(f"ftp crc /log/{day}/{name}", rf"^crc: /log/{day}/{name} (0x[0-9a-f]+)", 10)
            assert int(crc.group(1), 16) == crc32(on_vehicle[0].read_bytes())
        except AssertionError as exc:
            raise AssertionError(f"{exc}\n--- MAVProxy:\n{mp.tail()}\n{sitl_output(sitl)}") from None
        finally:
            mp.close()
    assert time.monotonic() - started < 60


def poll_param(mp: MavProxy, name: str, value_pattern: str, timeout_s: float = 5.0) -> None:
    """``param show`` until the cached value (updated by the vehicle's echo) matches."""
    deadline = time.monotonic() + timeout_s
    while True:
        mp.send(f"param show {name}")
        line = mp.expect(rf"^{name}\s+\S+", 3)
        if re.search(rf"^{name}\s+{value_pattern}", line.string):
            return
        if time.monotonic() > deadline:
            raise AssertionError(f"{name} never showed {value_pattern!r}; last: {line.string!r}")
        time.sleep(0.3)


def wait_status(mp: MavProxy, message: str, predicate, what: str, timeout_s: float = 5.0) -> dict:
    """``status MESSAGE`` (MAVProxy's copy of the last one received) until ``predicate(fields)``."""
    deadline = time.monotonic() + timeout_s
    while True:
        mp.send(f"status {message}")
        line = mp.expect(rf"^\d+: {message} \{{(.*)\}}", 3)
        fields = {k: _number(v) for k, v in re.findall(r"(\w+) : ([^,}]+)", line.group(1))}
        if predicate(fields):
            return fields
        if time.monotonic() > deadline:
            raise AssertionError(f"MAVProxy never saw {what}: last {message} {fields}")
        time.sleep(0.25)


def _number(text: str):
    try:
        return int(text)
    except ValueError:
        try:
            return float(text)
        except ValueError:
            return text
