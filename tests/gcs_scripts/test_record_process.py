"""The recorder as a real process: fed by a real zenoh publisher and real MAVLink over UDP.

The test plays both SITL processes: it opens the simulator's zenoh hub (truth + controller
batches, the two info queryables) and sends MAVLink 2 telemetry from the autopilot's GCS port
(18570+N) to the recorder (14550, every instance's GCS client port). One recorder is killed with
SIGKILL mid-run: the parts it wrote must be readable. Another stops by itself (--until-disarmed) and
merges its parts, while a second vehicle sends to the same port: only its own vehicle's system id
is recorded. A third
plays an autopilot flying on its EKF (estimator batches on ``quadsitl/N/estimator``): the merged
file has the estimate beside the truth.
"""

from __future__ import annotations

import json
import signal
import socket
import time
from pathlib import Path

import numpy as np
import pytest
import zenoh

from gcs_scripts import record as record_module
from gcs_scripts import session_log as sl
from gcs_scripts.analysis.log_reader import read_session
from gcs_scripts.link import mavutil
from quadcommon import bus, wire
from quadcommon.bus_records import CONTROLLER_CODEC, ESTIMATOR_CODEC, ESTIMATOR_FIELDS, TRUTH_CODEC
from sitl.launcher import Child, python_script
from tests.ports import instance_ports

from .helpers import Vehicle, control_times, controller_rows, ref_x, truth_rows

pytestmark = pytest.mark.processes  # (tests/conftest.py: the markers)

SIM_INFO = {"instance": 0, "vehicle": "paper_quad", "scenario": "circle", "actuation": "wrench",
            "physics_hz": 1000.0, "control_hz": 500.0, "speed": "max", "sim_time_s": 0.0}  # fmt: skip
AP_INFO = {"instance": 0, "controller": "intbs_nlhinf", "vehicle": "paper_quad", "control_hz": 500.0}


class FakeSitl:
    """The simulator's zenoh hub and the autopilot's GCS link, as the test's puppets."""

    def __init__(self, instance: int, estimator: bool = False) -> None:
        self.instance = instance
        ports = instance_ports(instance)
        self.session = bus.open_hub(ports.zenoh)
        self.truth_pub = self.session.declare_publisher(wire.zenoh_key(instance, "truth"))
        self.ctrl_pub = self.session.declare_publisher(wire.zenoh_key(instance, "controller"))
        self.est_pub = (
            self.session.declare_publisher(wire.zenoh_key(instance, "estimator")) if estimator else None
        )
        self.queryables = [
            (self.session.declare_queryable(wire.zenoh_key(instance, "info"), zenoh.handlers.FifoChannel(8)),
             dict(SIM_INFO, instance=instance)),
            (self.session.declare_queryable(wire.zenoh_key(instance, "autopilot/info"),
                                            zenoh.handlers.FifoChannel(8)), dict(AP_INFO, instance=instance)),
        ]  # fmt: skip
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind((wire.LOOPBACK, ports.gcs_local))
        self.gcs = (wire.LOOPBACK, ports.gcs_remote)
        self.vehicle = Vehicle(instance)
        self.k = 0  # control step counter
        self.mav_sent: list[tuple[float, float]] = []  # (stamp s, x) of LOCAL_POSITION_NED sent
        self.frames_sent = 0

    def send(self, frame: bytes) -> None:
        try:
            self.sock.sendto(frame, self.gcs)
            self.frames_sent += 1
        except OSError:
            pass  # recorder not listening yet (ICMP port unreachable)

    def answer_queries(self) -> None:
        for queryable, info in self.queryables:
            query = queryable.try_recv()
            if query is not None:
                with query:
                    query.reply(query.key_expr, json.dumps(info).encode())

    def step(self, armed: bool = True) -> None:
        """One batch: 10 control steps (20 ms of simulation time) on zenoh, telemetry on UDP."""
        times = control_times(0.0, 10) + self.k * 0.002
        self.k += 10
        self.truth_pub.put(TRUTH_CODEC.encode(truth_rows(times).tolist()))
        self.ctrl_pub.put(CONTROLLER_CODEC.encode(controller_rows(times).tolist()))
        if self.est_pub is not None:  # the estimate: truth + 1 mm in x
            est = np.zeros((len(times), len(ESTIMATOR_FIELDS)))
            est[:, 0] = times
            est[:, ESTIMATOR_FIELDS.index("x_est_m")] = np.sin(times) + 0.001
            self.est_pub.put(ESTIMATOR_CODEC.encode(est.tolist()))
        t = float(times[-1])
        x = round(t, 3) * 10.0
        self.send(self.vehicle.local_position(t, x=x))
        self.mav_sent.append((round(t, 3), x))
        if self.k % 500 == 0:  # 1 Hz of simulation time
            self.send(self.vehicle.heartbeat(armed=armed))
        self.answer_queries()

    def close(self) -> None:
        self.sock.close()
        self.session.close()


def _start_recorder(instance: int, out: Path, *extra: str) -> Child:
    script = Path(record_module.__file__)
    return Child("record.py", python_script(script, "--instance", str(instance), "--out", str(out), *extra))


def _wait_matching(sitl: FakeSitl, proc: Child) -> None:
    deadline = time.monotonic() + 8.0
    pubs = [p for p in (sitl.truth_pub, sitl.ctrl_pub, sitl.est_pub) if p is not None]
    while time.monotonic() < deadline:
        if all(p.matching_status.matching for p in pubs):
            return
        assert proc.alive, proc.output
        time.sleep(0.01)
    pytest.fail("the recorder's zenoh subscribers never matched")


def _stop(proc: Child) -> None:
    proc.signal(signal.SIGKILL)
    proc.wait(5.0)


def _check_rows(table_cols: dict[str, np.ndarray], sitl: FakeSitl) -> None:
    t = table_cols["time_s"]
    assert np.all(np.diff(t) > 0), "rows in time order, no duplicates"
    np.testing.assert_allclose(t / 0.002, np.rint(t / 0.002), atol=1e-6)  # on the control grid
    have_truth = ~np.isnan(table_cols["x_m"])
    have_ctrl = ~np.isnan(table_cols["x_ref_m"])
    assert have_truth.mean() > 0.99 and have_ctrl.mean() > 0.99  # nothing lost on loopback
    np.testing.assert_allclose(table_cols["x_m"][have_truth], np.sin(t[have_truth]), atol=1e-12)
    np.testing.assert_allclose(table_cols["x_ref_m"][have_ctrl], ref_x(t[have_ctrl]), atol=1e-12)
    # As-of join: the MAVLink value is the one sent with that stamp, and the stamp is <= the row.
    sent = dict(sitl.mav_sent)
    ok = ~np.isnan(table_cols["mav_local_time_s"])
    assert ok.sum() > 0.9 * len(t)
    stamps = table_cols["mav_local_time_s"][ok]
    assert np.all(stamps <= t[ok] + 1e-9)
    expected = np.array([sent[round(s, 3)] for s in stamps])
    np.testing.assert_allclose(table_cols["mav_local_x_m"][ok], expected, rtol=1e-6)


def test_recorder_killed_mid_run_leaves_readable_parts(tmp_path: Path) -> None:
    instance = 70
    out = tmp_path / "crash"
    sitl = FakeSitl(instance)
    proc = _start_recorder(instance, out)
    try:
        _wait_matching(sitl, proc)
        deadline = time.monotonic() + 8.0
        parts_dir = tmp_path / "crash.parts"
        # Feed at ~4x real time until at least two parts are on disk, then kill -9 mid-stream.
        while time.monotonic() < deadline and len(sl.part_paths(parts_dir)) < 2:
            sitl.step()
            time.sleep(0.005)
        assert len(sl.part_paths(parts_dir)) >= 2
        for _ in range(20):
            sitl.step()
        proc.signal(signal.SIGKILL)
        assert proc.wait(5.0) == -signal.SIGKILL
    finally:
        _stop(proc)
        sitl.close()
    assert not (tmp_path / "crash.parquet").exists()  # no merge after a crash
    table, meta = sl.read_session_table(parts_dir)
    cols = {n: table.column(n).to_numpy() for n in table.column_names}
    assert table.num_rows > 100
    _check_rows(cols, sitl)
    assert meta["instance"] == instance and meta["complete"] is False
    assert meta["scenario"] == "circle" and meta["controller"] == "intbs_nlhinf"  # from the queryables
    record = read_session(parts_dir)  # the analysis accepts the parts directory
    assert len(record.time_s) == int((~np.isnan(cols["x_ref_m"]) & ~np.isnan(cols["x_m"])).sum())
    # The tlog was flushed at least once a second: what is there reads back.
    log = mavutil.mavlink_connection(str(tmp_path / "crash.tlog"))
    types = []
    for _ in range(100_000):
        msg = log.recv_match(blocking=False)
        if msg is None:
            break
        types.append(msg.get_type())
    log.close()
    assert types.count("LOCAL_POSITION_NED") > 10 and "BAD_DATA" not in types


def test_recorder_stops_after_disarm_and_merges(tmp_path: Path) -> None:
    instance = 71
    out = tmp_path / "clean"
    sitl = FakeSitl(instance)
    other = Vehicle(5)  # another vehicle streaming to the same GCS client port (sysid 6)
    other_sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    proc = _start_recorder(instance, out, "--until-disarmed")

    def other_sends(k: int) -> None:
        frame = other.heartbeat(armed=k % 2 == 0) if k % 10 == 0 else other.local_position(k * 0.02, x=-1e3)
        if k % 50 == 25:
            frame = other.statustext("the other vehicle")
        try:
            other_sock.sendto(frame, sitl.gcs)
        except OSError:
            pass  # recorder not listening yet

    try:
        _wait_matching(sitl, proc)
        for _ in range(3):  # the recorder binds its UDP port at start: make sure it hears us
            sitl.send(sitl.vehicle.heartbeat(armed=False))
        for k in range(150):  # 3 s of simulation time, armed
            sitl.step(armed=True)
            other_sends(k)
            time.sleep(0.002)
        sitl.send(sitl.vehicle.statustext("landed: disarmed"))
        deadline = time.monotonic() + 8.0
        while proc.alive and time.monotonic() < deadline:
            sitl.step(armed=False)
            other_sends(0)  # the other one stays armed: it must not hold the recording open
            time.sleep(0.002)
        assert proc.wait(10.0) == 0, proc.output
        assert "stopped (disarmed)" in proc.output
    finally:
        _stop(proc)
        sitl.close()
        other_sock.close()
    log = mavutil.mavlink_connection(str(tmp_path / "clean.tlog"))
    systems = set()
    while (msg := log.recv_match(blocking=False)) is not None:
        systems.add(msg.get_srcSystem())
    log.close()
    assert systems == {wire.system_id(instance)}  # the other vehicle's frames are not in the tlog
    assert (tmp_path / "clean.parquet").exists() and not (tmp_path / "clean.parts").exists()
    table, meta = sl.read_session_table(tmp_path / "clean.parquet")
    cols = {n: table.column(n).to_numpy() for n in table.column_names}
    _check_rows(cols, sitl)
    assert meta["complete"] is True and meta["stopped_by"] == "disarmed"
    assert meta["simulator_info"]["physics_hz"] == 1000.0 and meta["control_hz"] == 500.0
    assert meta["recording_start_sim_time_s"] == pytest.approx(cols["time_s"][0], abs=0.05)
    assert [s[2] for s in meta["statustext"]] == ["landed: disarmed"]
    assert cols["mav_armed"][-1] == 0.0 and np.nanmax(cols["mav_armed"]) == 1.0
    assert meta["truth_rows"] == table.num_rows


@pytest.mark.timeout(30)
def test_recorder_stores_the_estimate_beside_the_truth(tmp_path: Path) -> None:
    instance = 23
    out = tmp_path / "ekf"
    sitl = FakeSitl(instance, estimator=True)
    proc = _start_recorder(instance, out, "--until-disarmed")
    try:
        _wait_matching(sitl, proc)
        for _ in range(3):
            sitl.send(sitl.vehicle.heartbeat(armed=False))
        for _ in range(100):  # 2 s of simulation time, armed
            sitl.step(armed=True)
            time.sleep(0.002)
        deadline = time.monotonic() + 8.0
        while proc.alive and time.monotonic() < deadline:
            sitl.step(armed=False)
            time.sleep(0.002)
        assert proc.wait(10.0) == 0, proc.output
    finally:
        _stop(proc)
        sitl.close()
    table, meta = sl.read_session_table(tmp_path / "ekf.parquet")
    cols = {n: table.column(n).to_numpy() for n in table.column_names}
    _check_rows(cols, sitl)
    have = ~np.isnan(cols["x_est_m"])
    assert have.mean() > 0.99  # nothing lost on loopback
    np.testing.assert_allclose(cols["x_est_m"][have] - cols["x_m"][have], 0.001, atol=1e-9)
    assert meta["estimator_rows"] == have.sum()
    record = read_session(tmp_path / "ekf.parquet")
    assert record.estimator is not None and len(record.estimator) == len(record.time_s)


def test_a_recorder_whose_vehicle_is_not_up_says_what_it_waits_for(tmp_path: Path, capsys) -> None:
    """No vehicle at its instance (one of a range that was never started): its progress line says
    what it waits for, where, and how to stop, instead of counting zeros (in this process, at the
    loop's wall times given)."""
    recorder = record_module.Recorder(record_module.RecorderOptions(instance=37, out=tmp_path / "r"))
    recorder.open()
    try:
        recorder.start(0.0)
        recorder.after_drain(record_module.PROGRESS_WALL_S)
    finally:
        recorder.close()
    out = capsys.readouterr().out
    port = instance_ports(37).gcs_remote
    where = f"(system id 38 on udpin:127.0.0.1:{port}, zenoh quadsitl/37/*)"
    assert f"nothing heard from instance 37 yet {where}" in out
    assert "Ctrl-C stops" in out and "0 rows" not in out
