"""A pymavlink client against ``quadsitl up --estimator ekf --sensors gps``: takeoff, hover, land.

The vehicle flies on its own EKF over the GPS profile. A plain MAVLink client must see what it
would see from PX4: arming refused with the filter's reason while it aligns, accepted once it
has converged; ESTIMATOR_STATUS; and GLOBAL_POSITION_INT that is the estimate, so off the ground
truth (read from zenoh at the same simulation instant) by a small, non-zero amount.

Instance 23 (on the test process's port block, tests/ports.py). Waits are bounded on
the wall clock but every check is on simulation-time stamps.
"""

from __future__ import annotations

import math
import sys
import time

import numpy as np
import pytest

from gcs_scripts.link import mavutil
from quadcommon import bus, frames, wire
from quadcommon.bus_records import TRUTH_CODEC, TRUTH_FIELDS
from sitl.launcher import Child
from tests.ports import instance_ports

from ..ulog_check import check_ulog

pytestmark = [pytest.mark.processes, pytest.mark.compat]  # (tests/conftest.py: the markers)

INSTANCE = 23
SPEED = "2"  # wall-clock pacing: pymavlink in Python keeps up with every message; the flow ~10 s
_T = {n: i for i, n in enumerate(TRUTH_FIELDS)}


class Client:
    """A ground station on the vehicle's GCS port, with the latest message of each type."""

    def __init__(self, port: int, system_id: int) -> None:
        m = mavutil.mavlink
        self.m = m
        self.system_id = system_id
        self.conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255, dialect="common")
        self.last: dict[str, object] = {}
        self.statustext: list[str] = []
        self.global_positions: list[object] = []
        self.acks: list[object] = []
        self._next_heartbeat = 0.0

    def poll(self, wall_s: float = 0.05) -> None:
        end = time.monotonic() + wall_s
        while True:
            now = time.monotonic()
            if now >= self._next_heartbeat:
                self._next_heartbeat = now + 0.5
                self.conn.mav.heartbeat_send(self.m.MAV_TYPE_GCS, self.m.MAV_AUTOPILOT_INVALID, 0, 0, 0)
            msg = self.conn.recv_match(blocking=True, timeout=max(end - now, 0.0))
            if msg is None:
                return
            if msg.get_srcSystem() != self.system_id or msg.get_type() == "BAD_DATA":
                continue
            kind = msg.get_type()
            self.last[kind] = msg
            if kind == "STATUSTEXT":
                self.statustext.append(msg.text)
            elif kind == "GLOBAL_POSITION_INT":
                self.global_positions.append(msg)
            elif kind == "COMMAND_ACK":
                self.acks.append(msg)

    def wait(self, predicate, what: str, wall_timeout_s: float) -> None:
        deadline = time.monotonic() + wall_timeout_s
        while time.monotonic() < deadline:
            self.poll()
            if predicate():
                return
        raise AssertionError(f"no {what} within {wall_timeout_s} s (wall); statustext {self.statustext[-8:]}")

    def command(self, command: int, *params: float, wall_timeout_s: float = 3.0) -> int:
        """COMMAND_LONG (params 1-7, missing ones 0); the result of its COMMAND_ACK."""
        p = [*params, *(0.0,) * (7 - len(params))]
        self.acks.clear()
        self.conn.mav.command_long_send(self.system_id, 1, command, 0, *p)
        self.wait(lambda: any(a.command == command for a in self.acks), f"ACK of {command}", wall_timeout_s)
        return next(a.result for a in self.acks if a.command == command)

    def armed(self) -> bool:
        hb = self.last.get("HEARTBEAT")
        return hb is not None and bool(hb.base_mode & self.m.MAV_MODE_FLAG_SAFETY_ARMED)

    def close(self) -> None:
        self.conn.close()


class Truth:
    """The simulator's ground truth on zenoh, every row kept (time_s first)."""

    def __init__(self, instance: int) -> None:
        import zenoh

        self.session = bus.open_peer(instance_ports(instance).zenoh)
        self.sub = self.session.declare_subscriber(
            wire.zenoh_key(instance, "truth"), zenoh.handlers.FifoChannel(100_000)
        )
        self.chunks: list[np.ndarray] = []

    def rows(self) -> np.ndarray:
        while (sample := self.sub.try_recv()) is not None:
            self.chunks.append(TRUTH_CODEC.decode(sample.payload.to_bytes()).copy())
        return np.concatenate(self.chunks) if self.chunks else np.zeros((0, len(TRUTH_FIELDS)))

    def close(self) -> None:
        self.sub.undeclare()
        self.session.close()


def _estimate_minus_truth(gpi, home, truth: np.ndarray) -> np.ndarray:
    """GLOBAL_POSITION_INT (paper frames, via the home position) minus the truth at its stamp."""
    north, east, down = frames.geodetic_to_ned(
        gpi.lat * 1e-7,
        gpi.lon * 1e-7,
        gpi.alt * 1e-3,
        (home.latitude * 1e-7, home.longitude * 1e-7, home.altitude * 1e-3),
    )
    local = frames.vector_from_ned((north + home.x, east + home.y, down + home.z))
    t = gpi.time_boot_ms * 1e-3
    i = int(np.argmin(np.abs(truth[:, 0] - t)))
    assert abs(truth[i, 0] - t) < 0.002, "a truth row at the telemetry's instant"
    return np.array(local) - truth[i, [_T["x_m"], _T["y_m"], _T["z_m"]]]


@pytest.mark.timeout(60)
def test_a_pymavlink_client_arms_only_on_the_aligned_ekf_and_sees_the_estimate(tmp_path) -> None:
    ports = instance_ports(INSTANCE)
    sysid = wire.system_id(INSTANCE)
    # Listening before the vehicle starts (the GCS client port is the client's, not the launcher's):
    # the first arming request then goes out in the vehicle's first simulated second, before the
    # filter can have aligned (it needs EST_ALIGN_T = 1 s of IMU at rest).
    client = Client(ports.gcs_remote, sysid)
    m = client.m
    up = Child("quadsitl up", [sys.executable, "-u", "-m", "sitl.cli", "up", "--instance", str(INSTANCE),
                               "--speed", SPEED, "--estimator", "ekf", "--sensors", "gps",
                               "--log-dir", str(tmp_path / "log")])  # fmt: skip
    truth = None
    try:
        client.wait(lambda: "HEARTBEAT" in client.last, "the first HEARTBEAT", 30.0)
        # Until the simulator's first frames the refusal is "no sensor frames"; then the filter's.
        deadline = time.monotonic() + 10.0
        while "estimator not ready" not in "".join(client.statustext):
            result = client.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1)
            at_ms = max(getattr(msg, "time_boot_ms", 0) for msg in client.last.values())
            assert result == m.MAV_RESULT_DENIED, f"armed at t={at_ms} ms without a refusal by the filter"
            assert time.monotonic() < deadline, f"no refusal by the filter; statustext {client.statustext}"
            client.poll(0.05)
        client.wait(lambda: "SYS_STATUS" in client.last, "SYS_STATUS", 2.0)
        assert not client.last["SYS_STATUS"].onboard_control_sensors_health & m.MAV_SYS_STATUS_AHRS
        up.wait_line("Ctrl-C stops", 30.0)
        truth = Truth(INSTANCE)
        # Arms once the filter has aligned and converged, not before.
        deadline = time.monotonic() + 15.0
        while client.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1) != m.MAV_RESULT_ACCEPTED:
            assert time.monotonic() < deadline, f"never armed; statustext {client.statustext[-8:]}"
            client.poll(0.3)
        armed_at_ms = max(getattr(msg, "time_boot_ms", 0) for msg in client.last.values())
        assert armed_at_ms >= 1000, armed_at_ms  # not before EST_ALIGN_T of simulation time
        client.last.pop("SYS_STATUS", None)
        client.wait(lambda: "SYS_STATUS" in client.last, "SYS_STATUS", 3.0)
        assert client.last["SYS_STATUS"].onboard_control_sensors_health & m.MAV_SYS_STATUS_AHRS
        client.last.pop("ESTIMATOR_STATUS", None)
        client.wait(lambda: "ESTIMATOR_STATUS" in client.last, "ESTIMATOR_STATUS", 3.0)
        status = client.last["ESTIMATOR_STATUS"]
        assert status.flags & m.ESTIMATOR_ATTITUDE and status.flags & m.ESTIMATOR_POS_HORIZ_ABS
        assert 0.0 < status.pos_horiz_accuracy < 5.0  # GPS: a figure in metres, known
        # Takeoff to MIS_TAKEOFF_ALT, hover, land: the vehicle disarms on the ground.
        nan = math.nan
        assert client.command(m.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, nan, nan, nan, nan) == m.MAV_RESULT_ACCEPTED

        def height_mm() -> float:
            gpi = client.last.get("GLOBAL_POSITION_INT")
            return -1.0 if gpi is None else gpi.relative_alt

        client.wait(lambda: height_mm() > 1500, "takeoff", 15.0)
        client.global_positions.clear()
        hover_from = client.last["GLOBAL_POSITION_INT"].time_boot_ms
        client.wait(lambda: client.last["GLOBAL_POSITION_INT"].time_boot_ms - hover_from > 3000, "hover", 6.0)
        if "HOME_POSITION" not in client.last:
            client.conn.mav.command_long_send(sysid, 1, m.MAV_CMD_REQUEST_MESSAGE, 0,
                                              m.MAVLINK_MSG_ID_HOME_POSITION, 0, 0, 0, 0, 0, 0)  # fmt: skip
            client.wait(lambda: "HOME_POSITION" in client.last, "HOME_POSITION", 3.0)
        home = client.last["HOME_POSITION"]
        # The truth comes in batches of ten frames: wait for the one holding the last telemetry's instant.
        last_s = client.global_positions[-1].time_boot_ms * 1e-3
        rows, deadline = truth.rows(), time.monotonic() + 5.0
        while (len(rows) == 0 or rows[-1, 0] < last_s) and time.monotonic() < deadline:
            time.sleep(0.01)
            rows = truth.rows()
        diffs = np.array([_estimate_minus_truth(g, home, rows) for g in client.global_positions[5:]])
        assert len(diffs) > 5
        error = np.linalg.norm(diffs, axis=1)
        # The estimate, not the truth: off by the filter's error on GPS (centimetres to decimetres).
        assert np.all(error < 1.0), error.max()
        assert np.median(error) > 0.005, np.median(error)
        assert client.command(m.MAV_CMD_NAV_LAND) == m.MAV_RESULT_ACCEPTED
        client.wait(lambda: not client.armed(), "disarm after landing", 15.0)
        on_ground = truth.rows()[-1]
        assert on_ground[_T["z_m"]] < 0.1 and on_ground[_T["on_ground"]] == 1.0  # the truth: landed
        # The reported height is the estimate's: on GPS it may sit decimetres off the ground.
        assert abs(height_mm() * 1e-3 - on_ground[_T["z_m"]]) < 1.0
        print(
            f"hover: |GLOBAL_POSITION_INT - truth| median {np.median(error):.3f} m, max {error.max():.3f} m; "
            f"landed: reported height {height_mm() * 1e-3:.3f} m, truth {on_ground[_T['z_m']]:.3f} m"
        )
    except Exception as exc:
        raise AssertionError(f"{exc}\n--- quadsitl up:\n{up.tail(40)}") from None
    finally:
        client.close()
        if truth is not None:
            truth.close()
        assert up.stop(10.0) == 0
    # The flight's log, flown on the EKF: what Flight Review plots of an EKF flight is there.
    (log,) = (tmp_path / "log").glob("*/*.ulg")
    ulog = check_ulog(log, ekf=True)
    assert ulog.msg_info_dict["quadsitl_estimator"] == "ekf"
    assert len(ulog.get_dataset("estimator_status").data["timestamp"]) > 10
