"""The flight log (ULog) the autopilot writes, in simulation time on the in-process stack.

Every log written here is checked with :func:`tests.ulog_check.check_ulog` (pyulog, PlotJuggler's
parser's requirements, Flight Review's topics).
"""

from __future__ import annotations

import io
import math
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as m
from pyulog import ULog

from autopilot.commander.modes import FlightMode
from autopilot.logger import topics, ulog
from autopilot.logger.logger import FlightLogger, LogClose, LogOpen
from autopilot.logger.storage import LogDirectory
from autopilot.params.definitions import default_parameters
from quadcommon import ulog_topics
from simulator.core import SimulatorCore
from tests.stack import Gcs, make_stack
from tests.ulog_check import FLIGHT_REVIEW, check_plotjuggler, check_ulog, sampling_rate_hz

ARM, DISARM = 1.0, 0.0


def arm(gcs: Gcs, value: float = ARM) -> None:
    ack = gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, value)
    assert ack.result == m.MAV_RESULT_ACCEPTED, ack


def fly_up_and_down(gcs: Gcs) -> dict[str, float]:
    """Arm, take off to MIS_TAKEOFF_ALT, land, wait for the auto-disarm; when each happened."""
    times = {}
    gcs.wait_heartbeat()
    arm(gcs)
    times["armed"] = gcs.sim_time
    assert gcs.command(m.MAV_CMD_NAV_TAKEOFF).result == m.MAV_RESULT_ACCEPTED
    commander = gcs.stack.autopilot.commander
    gcs.wait(lambda g: commander.mode is FlightMode.AUTO_LOITER and commander.in_air(), 15.0, "takeoff")
    gcs.conn.mav.param_set_send(gcs.system_id, 1, b"MPC_XY_VEL_MAX", 1.5, m.MAV_PARAM_TYPE_REAL32)
    gcs.wait(lambda g: "PARAM_VALUE" in g.last, 1.0, "the parameter's echo")
    times["param_set"] = gcs.sim_time
    assert gcs.command(m.MAV_CMD_NAV_LAND).result == m.MAV_RESULT_ACCEPTED
    gcs.wait(lambda g: not g.stack.autopilot.commander.armed, 20.0, "landed and disarmed")
    times["disarmed"] = gcs.sim_time
    return times


def test_a_flight_is_logged_from_arming_to_disarming_with_px4s_topics(tmp_path):
    stack = make_stack(log_dir=str(tmp_path))
    gcs = Gcs(stack)
    times = fly_up_and_down(gcs)
    stack.run_for(1.0)
    paths = stack.close()
    assert paths == [tmp_path / "sess001" / "log001.ulg"]  # PX4's numbering without a clock
    log = check_ulog(paths[0])
    data = {d.name: d.data for d in log.data_list}
    t = data[ulog_topics.TRACKING]["timestamp"] * 1e-6
    assert (
        times["armed"] - 0.05 < t[0] <= times["armed"]
        and times["disarmed"] - 0.05 < t[-1] <= times["disarmed"]
    )
    assert np.all(data[ulog_topics.TRACKING]["armed"] == 1) and np.all(np.diff(t) > 0)
    assert log.start_timestamp == data[ulog_topics.TRACKING]["timestamp"][0]
    # every control step (500 Hz), the other topics at PX4's rates
    assert np.allclose(np.diff(t), 0.002)
    for name in ("sensor_combined", "vehicle_angular_velocity"):  # every frame's IMU and body rates
        assert np.array_equal(data[name]["timestamp"], data[ulog_topics.TRACKING]["timestamp"]), name
    flying = data["vehicle_torque_setpoint"]["timestamp"]  # every step while the motors fly
    assert np.array_equal(data["vehicle_thrust_setpoint"]["timestamp"], flying)
    assert np.all(np.diff(flying.astype(np.int64)) == 2000)
    assert (flying[-1] - flying[0]) * 1e-6 > 0.6 * span_of(t)  # (not on the ground after landing)
    span = t[-1] - t[0]
    setpoints = ("vehicle_attitude_setpoint", "vehicle_rates_setpoint", "vehicle_local_position_setpoint",
                 "position_setpoint_triplet")  # fmt: skip
    for spec in topics.TOPICS:  # (the setpoints only while the motors fly; status also on changes)
        if spec.interval_ms and spec.name not in (*topics.EVENT_TOPICS, *setpoints, "vehicle_status"):
            if spec.name == "estimator_status":
                assert spec.name not in data  # flown on truth
                continue
            expected = span / (spec.interval_ms * 1e-3)
            assert abs(len(data[spec.name]["timestamp"]) - expected) <= 2, spec.name
    assert len(data["vehicle_gps_position"]["timestamp"]) == pytest.approx(span * 10, abs=2)  # HIL_GPS, 10 Hz
    # PX4's frames: NED, and the vehicle went to MIS_TAKEOFF_ALT and back
    truth_z = data["vehicle_local_position_groundtruth"]["z"]
    assert truth_z.min() == pytest.approx(-2.5, abs=0.05) and truth_z[-1] == pytest.approx(0.0, abs=0.02)
    tracking_z = data[ulog_topics.TRACKING]["position_m[2]"]
    assert tracking_z.max() == pytest.approx(-truth_z.min(), abs=0.02)  # z up
    # sensor_combined: HIL_SENSOR as sent, FRD (at rest on the ground, the specific force points up: -z)
    accel_z = data["sensor_combined"]["accelerometer_m_s2[2]"]
    assert accel_z[0] == pytest.approx(-9.81, abs=0.3) and np.median(accel_z) == pytest.approx(-9.81, abs=0.5)
    assert abs(data["sensor_combined"]["gyro_rad[2]"][0]) < 0.05
    lat = data["vehicle_gps_position"]["latitude_deg"]
    assert np.allclose(lat, 47.397742, atol=1e-5)
    nav = data["vehicle_status"]["nav_state"]
    changes = [int(n) for i, n in enumerate(nav) if i == 0 or n != nav[i - 1]]
    assert changes == [4, 17, 4, 18]  # hold, takeoff, hold, land (PX4's nav_state values)
    assert set(data["vehicle_status"]["arming_state"]) == {2}
    # parameters: every one at the start, the change where it happened
    params = default_parameters(stack.autopilot.setup.controller, stack.autopilot.setup.sitl.rates,
                                estimator=True).names()  # fmt: skip
    assert set(log.initial_parameters) == set(params)
    assert log.initial_parameters["SDLOG_MODE"] == 0 and isinstance(log.initial_parameters["SDLOG_MODE"], int)
    change = [c for c in log.changed_parameters if c[1] == "MPC_XY_VEL_MAX"]
    assert len(change) == 1 and change[0][2] == pytest.approx(1.5)
    assert abs(change[0][0] * 1e-6 - times["param_set"]) < 0.05
    # STATUSTEXT as logged strings, with their severity as the level
    texts = [(msg.message, msg.log_level - ord("0")) for msg in log.logged_messages]
    assert ("mode AUTO.TAKEOFF", m.MAV_SEVERITY_INFO) in texts and (
        "landing detected",
        m.MAV_SEVERITY_INFO,
    ) in texts
    heard = gcs.statustext  # what the ground station was told: the log has it, in order, from arming on
    first = heard.index(texts[0][0])
    assert [text for text, _ in texts] == heard[first : first + len(texts)]
    assert (
        log.msg_info_dict["sys_name"] == "quadsitl"
        and log.msg_info_dict["quadsitl_controller"] == "intbs_nlhinf"
    )
    # the cascade's own record, in the paper's frames, with the laws' integral states
    cascade = data[ulog_topics.CASCADE]
    names, _ = stack.autopilot.cascade.law_states()
    law_fields = [topics.law_state_field(name) for name in names]
    assert law_fields and all(field in cascade for field in law_fields)
    (integral_z,) = [f for f in law_fields if f.startswith("translational_") and f.endswith("_z")]
    assert np.any(cascade[integral_z] != 0.0)  # the altitude integral worked against gravity
    # no body-rate integral in this cascade (nlhinf integrates the attitude error): zeros, as PX4's
    # rate controller without one; no rotors under wrench actuation: no motor commands
    rate = data["rate_ctrl_status"]
    assert all(np.all(rate[f"{axis}speed_integ"] == 0.0) for axis in ("roll", "pitch", "yaw"))
    assert all(np.all(np.isnan(data["actuator_motors"][f"control[{i}]"])) for i in range(12))
    assert stack.autopilot.faults.counts == {}
    # PX4 users' first commands on a log: pyulog's ulog_info and ulog2csv
    bin_dir = Path(sys.executable).parent
    info = subprocess.run([bin_dir / "ulog_info", paths[0]], capture_output=True, text=True, timeout=60)
    assert info.returncode == 0 and "vehicle_local_position" in info.stdout
    assert "sys_name: quadsitl" in info.stdout
    csv = subprocess.run([bin_dir / "ulog2csv", "-o", tmp_path / "csv", "-m", "vehicle_attitude", paths[0]],
                         capture_output=True, text=True, timeout=60)  # fmt: skip
    assert csv.returncode == 0, csv.stderr
    (table,) = (tmp_path / "csv").glob("*vehicle_attitude_0.csv")
    assert table.read_text().splitlines()[0].startswith("timestamp,timestamp_sample,q[0]")


def span_of(t: np.ndarray) -> float:
    return float(t[-1] - t[0])


def at_common_times(a: dict, b: dict) -> tuple[np.ndarray, np.ndarray]:
    """The indices of the samples of topics ``a`` and ``b`` taken at the same timestamps."""
    _, ia, ib = np.intersect1d(a["timestamp"], b["timestamp"], return_indices=True)
    assert len(ia) > 5
    return ia, ib


def test_flight_review_finds_every_topic_field_and_rate_its_plots_read(tmp_path):
    """PX4's cascade (a body-rate integral per axis) on four rotors, up and down: every need of
    Flight Review's plots met (tests/ulog_check.FLIGHT_REVIEW: the spectra at the control rate),
    and the new topics hold the vehicle's own numbers in PX4's conventions."""
    stack = make_stack(controller="px4_pid", vehicle="paper_quad_rotors", log_dir=str(tmp_path))
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    arm(gcs)
    assert gcs.command(m.MAV_CMD_NAV_TAKEOFF).result == m.MAV_RESULT_ACCEPTED
    commander = stack.autopilot.commander
    gcs.wait(lambda g: commander.mode is FlightMode.AUTO_LOITER and commander.in_air(), 15.0, "takeoff")
    stack.run_for(1.0)  # holding
    assert gcs.command(m.MAV_CMD_NAV_LAND).result == m.MAV_RESULT_ACCEPTED
    gcs.wait(lambda g: not commander.armed, 20.0, "landed and disarmed")
    (path,) = stack.close()
    log = check_ulog(path)  # every need of FLIGHT_REVIEW with its rate, besides pyulog's and PlotJuggler's
    data = {d.name: d.data for d in log.data_list}
    assert {need.topic for need in FLIGHT_REVIEW} <= set(data)  # the takeoff, hold and landing points too
    for name in ("sensor_combined", "vehicle_angular_velocity", "vehicle_torque_setpoint"):
        assert sampling_rate_hz(log.get_dataset(name)) == 500, name  # the control rate: spectra to 250 Hz
    vehicle = stack.autopilot.setup.vehicle
    tau_max, u1_max = vehicle.actuation.torque_max_n_m, vehicle.actuation.thrust_max_n
    cascade, tracking = data[ulog_topics.CASCADE], data[ulog_topics.TRACKING]
    # torque and thrust: PX4's normalised setpoints, FRD (y, z and the thrust's z turn)
    torque = data["vehicle_torque_setpoint"]
    i, j = at_common_times(torque, cascade)
    for axis, sign in enumerate((1.0, -1.0, -1.0)):
        expected = sign * cascade[f"torque_body_n_m[{axis}]"][j] / tau_max[axis]
        assert np.allclose(torque[f"xyz[{axis}]"][i], expected, rtol=1e-6, atol=1e-7)
    assert np.all(np.abs([torque[f"xyz[{axis}]"] for axis in range(3)]) <= 1.0)
    thrust = data["vehicle_thrust_setpoint"]
    i, j = at_common_times(thrust, tracking)
    assert np.allclose(thrust["xyz[2]"][i], -tracking["thrust_n"][j] / u1_max, rtol=1e-6)
    assert np.all(thrust["xyz[0]"] == 0.0) and np.all(thrust["xyz[2]"] < 0.0)  # up is -z
    hover = vehicle.nominal.mass_kg * vehicle.nominal.gravity_m_s2 / u1_max
    assert np.median(thrust["xyz[2]"]) == pytest.approx(-hover, rel=0.05)
    # the rate integrals of px4_attitude, FRD, as cascade_status has them (body FLU)
    rate = data["rate_ctrl_status"]
    i, j = at_common_times(rate, cascade)
    for axis, sign in (("roll", 1.0), ("pitch", -1.0), ("yaw", -1.0)):
        state = {"roll": "x", "pitch": "y", "yaw": "z"}[axis]
        expected = sign * cascade[f"rotational_rate_int_{state}"][j]
        assert np.array_equal(rate[f"{axis}speed_integ"][i], expected.astype(np.float32))
    assert np.any(rate["rollspeed_integ"] != 0.0) and np.any(rate["yawspeed_integ"] != 0.0)
    # the motors: each rotor's thrust over its largest, (Omega / Omega_max)^2, while armed
    motors = data["actuator_motors"]
    i, j = at_common_times(motors, cascade)
    for k in range(4):
        expected = cascade[f"actuator_controls[{k}]"][j].astype(np.float64) ** 2
        assert np.allclose(motors[f"control[{k}]"][i], expected, rtol=1e-6)
    assert all(np.all(np.isnan(motors[f"control[{k}]"])) for k in range(4, 12))
    assert 0.2 < np.median(motors["control[0]"]) < 0.4  # hover: thrust m g / 4 per rotor
    # where the plan leads: takeoff (PX4's type 3) at MIS_TAKEOFF_ALT, hold (2), land (4) on the ground
    triplet = data["position_setpoint_triplet"]
    home_lat, home_lon, home_alt = stack.autopilot.setup.sitl.home
    kind = triplet["current.type"]
    kinds = [int(k) for n, k in enumerate(kind) if n == 0 or k != kind[n - 1]]
    assert kinds == [3, 2, 4] and np.all(triplet["current.valid"] == 1) and np.all(triplet["next.valid"] == 0)
    alt = triplet["current.alt"]
    takeoff_alt = stack.autopilot.params["MIS_TAKEOFF_ALT"]
    assert np.allclose(alt[kind == 3], home_alt + takeoff_alt, atol=0.01)
    assert np.allclose(alt[kind == 4], home_alt, atol=0.01)
    assert np.allclose(triplet["current.lat"], home_lat, atol=1e-6)
    assert np.allclose(triplet["current.lon"], home_lon, atol=1e-6)
    assert stack.autopilot.faults.counts == {}


SEQUENCE = (("idle", 1.0), ("arm", 1.0), ("disarm", 1.0), ("arm", 1.0), ("disarm", 0.5))
# SDLOG_MODE -> the logs expected, as (start, end) events of SEQUENCE (PX4's meaning of each value)
EXPECTED = {
    -1: [],
    0: [("arm1", "disarm1"), ("arm2", "disarm2")],
    1: [("boot", "disarm1"), ("arm2", "disarm2")],
    2: [("boot", "close")],
    4: [("arm1", "close")],
}


@pytest.mark.parametrize("mode", sorted(EXPECTED))
def test_sdlog_mode_decides_when_a_log_runs(tmp_path, mode):
    params = tmp_path / "params.toml"
    params.write_text(f"SDLOG_MODE = {mode}\n")
    stack = make_stack(log_dir=str(tmp_path / "log"), params_file=str(params))
    gcs = Gcs(stack)
    events = {"boot": 0.0}
    counts = {"arm": 0, "disarm": 0}
    for what, hold in SEQUENCE:
        if what != "idle":
            arm(gcs, ARM if what == "arm" else DISARM)
            counts[what] += 1
            events[f"{what}{counts[what]}"] = stack.t
        stack.run_for(hold)
    events["close"] = stack.t
    paths = stack.close()
    assert len(paths) == len(EXPECTED[mode])
    for path, (start, end) in zip(paths, EXPECTED[mode], strict=True):
        t = check_ulog(path, flight_review=False).get_dataset(ulog_topics.TRACKING).data["timestamp"] * 1e-6
        assert events[start] - 0.06 < t[0] <= events[start] + 0.002, (start, t[0], events)
        assert events[end] - 0.06 < t[-1] <= events[end], (end, t[-1], events)


def test_sdlog_mode_3_is_refused_and_a_simulator_restart_ends_the_log(tmp_path):
    stack = make_stack(log_dir=str(tmp_path))
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    gcs.conn.mav.param_set_send(gcs.system_id, 1, b"SDLOG_MODE", struct.unpack("<f", struct.pack("<i", 3))[0],
                                m.MAV_PARAM_TYPE_INT32)  # fmt: skip
    gcs.wait(lambda g: any("AUX1" in s for s in g.statustext), 1.0, "the refusal")
    assert stack.autopilot.params["SDLOG_MODE"] == 0
    stack.autopilot.params.set("SDLOG_MODE", 2)  # from now until shutdown
    stack.run_for(2.0)
    stack.sim = SimulatorCore(stack.sim.setup)  # a new simulator: its time starts at 0 again
    stack.run_for(1.0)
    first, second = stack.close()
    for path in (first, second):  # each log's time runs forward
        t = check_ulog(path, flight_review=False).get_dataset(ulog_topics.TRACKING).data["timestamp"]
        assert np.all(np.diff(t.astype(np.int64)) > 0)
    assert ULog(str(second)).get_dataset(ulog_topics.TRACKING).data["timestamp"][0] == 0


def test_the_ulog_encoding_is_what_pyulog_reads():
    """Formats (one with a nested type), info of each type, parameters, subscriptions, samples,
    strings, sync, dropout."""
    inner = ulog.Format("inner", ulog.fields("uint64_t timestamp; bool valid; double lat"))
    layout = "uint64_t timestamp; float[3] v; double d; int8_t i; bool b; uint32_t u; inner[2] pair"
    fmt = ulog.Format("demo", ulog.fields(layout, [inner]))
    assert fmt.nested == (inner,)
    assert fmt.field_names()[-3:] == ["pair[1].timestamp", "pair[1].valid", "pair[1].lat"]
    topic = ulog.Topic(fmt, 0)
    pair = (7, True, 47.5, 8, False, -1.25)
    data = (ulog.file_header(1000) + ulog.flag_bits() + ulog.format_message(inner) + ulog.format_message(fmt)
            + ulog.info("sys_name", "quadsitl") + ulog.info("ver_sw_release", 0x010203FF, "uint32_t")
            + ulog.info("answer", 42) + ulog.info("ratio", 0.25)
            + ulog.parameter("A_FLOAT", 0.3, integer=False) + ulog.parameter("AN_INT", -7, integer=True)
            + ulog.add_logged(0, "demo")
            + topic.sample((1000, 1.0, -2.0, 3.5, 1e300, -5, True, 2**32 - 1, *pair))
            + ulog.logged_string(4, 1500, "a warning") + ulog.sync() + ulog.dropout(20)
            + ulog.parameter("AN_INT", 8, integer=True)
            + topic.sample((2000, math.nan, 0.0, 0.0, -1.0, 127, False, 0, *pair)))  # fmt: skip
    counts = check_plotjuggler(data)
    assert counts == {"demo": 2}
    log = ULog(io.BytesIO(data))
    assert not log.file_corruption and log.start_timestamp == 1000 and log.last_timestamp == 2000
    assert log.msg_info_dict == {
        "sys_name": "quadsitl",
        "ver_sw_release": 0x010203FF,
        "answer": 42,
        "ratio": 0.25,
    }
    assert log.get_version_info() == (1, 2, 3, 255) and log.get_version_info_str() == "v1.2.3"
    assert log.initial_parameters == {"A_FLOAT": pytest.approx(0.3), "AN_INT": -7}
    assert log.changed_parameters == [(1000, "AN_INT", 8)]  # pyulog stamps it with the last sample's time
    d = log.get_dataset("demo").data
    assert (
        list(d["timestamp"]) == [1000, 2000] and d["v[1]"][0] == np.float32(-2.0) and math.isnan(d["v[0]"][1])
    )
    assert list(d["d"]) == [1e300, -1.0] and list(d["i"]) == [-5, 127] and list(d["u"]) == [2**32 - 1, 0]
    assert sorted(c for c in d if c.startswith("pair")) == sorted(fmt.field_names()[-6:])  # nested, flattened
    assert list(d["pair[0].lat"]) == [47.5, 47.5] and list(d["pair[1].valid"]) == [0, 0]
    assert list(d["pair[1].timestamp"]) == [8, 8]
    (msg,) = log.logged_messages
    assert (msg.log_level_str(), msg.timestamp, msg.message) == ("WARNING", 1500, "a warning")
    assert [dropout.duration for dropout in log.dropouts] == [20]


def test_formats_readers_cannot_take_are_refused():
    with pytest.raises(ValueError, match="first field must be 'uint64_t timestamp'"):
        ulog.Format("bad", ulog.fields("float x; uint64_t timestamp")).check()
    with pytest.raises(ValueError, match="unknown type"):
        ulog.fields("uint64_t timestamp; vector3 v")
    with pytest.raises(ValueError, match="appears twice"):
        ulog.Format("bad", ulog.fields("uint64_t timestamp; float x; float x")).check()
    with pytest.raises(ValueError, match="at most 65535"):
        ulog.message(ulog.INFO, bytes(70000))
    for spec in topics.TOPICS:  # every topic's format is one readers take
        spec.format().check()


def test_a_killed_logger_leaves_what_it_wrote_readable(tmp_path):
    """What a killed autopilot leaves: the bytes written so far, cut anywhere; pyulog reads the
    samples before the cut, and the PlotJuggler check stops at it."""
    stack = make_stack(log_dir=str(tmp_path))
    stack.autopilot.params.set("SDLOG_MODE", 2)
    stack.run_for(1.0)
    (path,) = stack.close()
    whole = path.read_bytes()
    for cut in (len(whole) // 3, len(whole) // 2 + 7, len(whole) - 5):
        part = tmp_path / f"cut{cut}.ulg"
        part.write_bytes(whole[:cut])
        log = check_ulog(part, cut=True, flight_review=False)
        t = log.get_dataset(ulog_topics.TRACKING).data["timestamp"]
        assert len(t) > 100 and np.all(np.diff(t.astype(np.int64)) == 2000)


def test_the_logger_writes_nothing_while_disabled_and_hands_bytes_in_file_order():
    params = default_parameters()
    snapshot = topics.Snapshot()
    logger = FlightLogger(params, {}, lambda: ((), ()), snapshot, enabled=False)
    assert logger.update(0, True) is False and logger.take() == []
    params.set("SDLOG_MODE", 2)
    logger = FlightLogger(params, {"sys_name": "x"}, lambda: ((), ()), snapshot, utc_clock=lambda: 1.7e9)
    assert logger.update(5_000_000, False)
    logger.stop()
    items = logger.take()
    assert isinstance(items[0], LogOpen) and items[0] == LogOpen(5_000_000, 1.7e9)
    assert isinstance(items[1], bytes) and items[1].startswith(ulog.MAGIC) and isinstance(items[-1], LogClose)
    assert snapshot.utc_offset_us == round(1.7e15) - 5_000_000


def test_the_log_directory_names_logs_as_px4_and_lists_them_oldest_first(tmp_path):
    directory = LogDirectory(tmp_path)
    utc = 1_750_000_000.0  # 2025-06-15 15:06:40 UTC
    first = directory.new_path(utc)
    assert first == tmp_path / "2025-06-15" / "15_06_40.ulg"
    first.write_bytes(b"x" * 10)
    second = directory.new_path(utc)
    assert second.name == "15_06_40_1.ulg"
    second.write_bytes(b"y" * 3)
    session = directory.new_path(None)
    assert session == tmp_path / "sess001" / "log001.ulg"
    session.write_bytes(b"")
    entries = directory.entries()
    assert [Path(e.key) for e in entries] == [first, second, session]
    assert [e.size for e in entries] == [10, 3, 0] and entries[0].time_utc == int(utc)
    assert directory.read(str(first), 8, 90) == b"xx" and directory.read(str(first), 20, 5) == b""
    assert directory.read(str(tmp_path / "gone.ulg"), 0, 5) == b""
    directory.writing = second
    assert directory.erase() == 2 and [Path(e.key) for e in directory.entries()] == [second]


def test_a_log_directory_that_cannot_be_written_is_reported_and_the_vehicle_flies_on(tmp_path):
    blocker = tmp_path / "a_file"
    blocker.write_text("not a directory")
    stack = make_stack(log_dir=str(blocker / "log"))
    stack.autopilot.params.set("SDLOG_MODE", 2)
    stack.run_for(0.5)
    assert stack.close() == [] and "a_file/log: " in stack.log_writer.error
    assert stack.autopilot.faults.counts == {} and stack.t >= 0.5
