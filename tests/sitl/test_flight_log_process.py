"""The flight log of a real autopilot process: pymavlink downloads it over UDP while it is being
written, then the autopilot is killed with SIGKILL and what it wrote reads in pyulog up to the
last second before the kill (the writer thread gets the bytes every 50 ms of wall time)."""

from __future__ import annotations

import os
import signal
import time
from pathlib import Path

import numpy as np
import pytest
import zenoh
from pymavlink import mavutil

from quadcommon import bus, wire
from quadcommon.bus_records import CONTROLLER_CODEC
from quadcommon.ulog_topics import TRACKING
from sitl.launcher import Launcher, VehicleSpec
from tests.ulog_check import check_ulog

pytestmark = pytest.mark.processes  # (tests/conftest.py: the markers)

INSTANCE = 76
ALL = 0xFFFFFFFF


def download(conn, sysid: int, log_id: int, size: int, timeout_s: float = 20.0) -> bytes:
    """As a ground station does: everything at once, then what is missing again (UDP may drop)."""
    got: dict[int, bytes] = {}
    deadline = time.monotonic() + timeout_s
    conn.mav.log_request_data_send(sysid, 1, log_id, 0, ALL)
    quiet_since = time.monotonic()
    while sum(map(len, got.values())) < size:
        assert time.monotonic() < deadline, f"downloaded {sum(map(len, got.values()))} of {size} bytes"
        msg = conn.recv_match(type="LOG_DATA", blocking=True, timeout=0.2)
        if msg is not None and msg.id == log_id and msg.count:
            got[msg.ofs] = bytes(msg.data[: msg.count])
            quiet_since = time.monotonic()
        elif time.monotonic() - quiet_since > 0.5:  # ask again for the first gap
            offset = 0
            while offset in got:
                offset += len(got[offset])
            conn.mav.log_request_data_send(sysid, 1, log_id, offset, ALL)
            quiet_since = time.monotonic()
    return b"".join(got[k] for k in sorted(got))


@pytest.mark.timeout(90)
def test_pymavlink_downloads_the_log_being_written_and_a_killed_autopilot_leaves_it_readable(tmp_path):
    log_dir = tmp_path / "log"
    spec = VehicleSpec(instance=INSTANCE, scenario="hover", speed="1", autostart=True, log_dir=str(log_dir))
    ports = spec.ports()
    sysid = wire.system_id(INSTANCE)
    with Launcher() as launcher:
        launcher.start_vehicles([spec], 30.0)
        session = bus.open_peer(ports.zenoh)
        rows = session.declare_subscriber(
            wire.zenoh_key(INSTANCE, "controller"), zenoh.handlers.FifoChannel(10_000)
        )
        conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{ports.api_remote}", source_system=255)
        try:
            assert conn.wait_heartbeat(timeout=10) is not None
            # The heartbeat may come before the simulator links (the vehicle arms, its log starts, its
            # writer thread puts the first bytes on disk): until then the listing is num_logs 0.
            deadline = time.monotonic() + 15
            while True:
                conn.mav.log_request_list_send(sysid, 1, 0, 0xFFFF)
                entry = conn.recv_match(type="LOG_ENTRY", blocking=True, timeout=5)
                assert entry is not None, "no LOG_ENTRY"
                if entry.num_logs or time.monotonic() > deadline:
                    break
                time.sleep(0.2)  # (a poll interval: nothing is asserted on its count)
            assert (entry.id, entry.num_logs) == (0, 1) and entry.size > 0
            assert abs(entry.time_utc - time.time()) < 60  # its start, from its name (UTC)
            (path,) = log_dir.glob("*/*.ulg")  # log/YYYY-MM-DD/HH_MM_SS.ulg
            assert time.strftime("%Y-%m-%d", time.gmtime(entry.time_utc)) == path.parent.name
            got = download(conn, sysid, 0, entry.size)
            assert got == path.read_bytes()[: entry.size]  # the log grew meanwhile; its start is this

            last_t = 0.0
            deadline = time.monotonic() + 30
            while last_t < 4.0:  # the autopilot's own record of its frames (published every 50 ms)
                assert time.monotonic() < deadline, "no controller rows"
                sample = rows.recv()
                last_t = float(CONTROLLER_CODEC.decode(sample.payload.to_bytes())[-1, 0])
            os.kill(launcher.child(f"autopilot[{INSTANCE}]").pid, signal.SIGKILL)
        finally:
            conn.close()
            rows.undeclare()
            session.close()
    log = check_ulog(path, cut=True)
    t = log.get_dataset(TRACKING).data["timestamp"] * 1e-6
    assert t[0] == 0.0 and np.all(np.diff(t) > 0)
    assert t[-1] >= last_t - 1.0, f"the log ends at {t[-1]:.3f} s, the autopilot was at {last_t:.3f} s"
    part = Path(tmp_path / "downloaded.ulg")
    part.write_bytes(got)
    check_ulog(part, flight_review=False)
