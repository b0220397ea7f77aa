"""MAVSDK-Python 4 (native: C++ core in-process) flies quadsitl vehicles as it flies PX4 SITL.

Each test starts one vehicle with the ``quadsitl up`` launcher at ``--speed 2`` (MAVSDK is a
wall-clock client: its command and parameter timeouts count wall seconds), runs one flow of
``mavsdk_flows.py`` in a subprocess under a hard timeout, and asserts on the JSON events it printed.
What the vehicle really did is checked on the simulator's ground truth and the autopilot's
reference (zenoh), independently of what MAVSDK reports.

Why MAVSDK 4 and not ``mavsdk-grpc``: the gRPC flavour starts a ``mavsdk_server`` process per
``System`` that listens for gRPC on every interface (no option to bind loopback only), which the
project's loopback-only rule forbids, and needs a free gRPC port per parallel test. The MAVLink
side (the C++ core) is the same in both. What changes for a PX4 user's script is listed in
``mavsdk_flows.py``'s docstring.
"""

from __future__ import annotations

import math
import struct
import time
from pathlib import Path

import numpy as np
import pytest

from quadcommon.build_info import this_build

from ..ulog_check import check_ulog
from .vehicles import LOG_NAMES, TruthTap, ports, run_flow, sitl_output, vehicle, vehicle_logs

pytestmark = [pytest.mark.processes, pytest.mark.compat]  # (tests/conftest.py: the markers)

HOME = (47.397742, 8.545594)  # config/sitl.toml [home]
FLOW_TIMEOUT_S = 50.0


def fly(flow: str, instance: int, config, *args: str, url_host: str = "0.0.0.0", truth_leaves=("truth",),
        impair: tuple[str, ...] = (), **vehicle_options):  # fmt: skip
    """Start vehicle ``instance`` (``vehicle_options``: :func:`vehicle`'s), tap its zenoh streams, run
    ``flow``; returns (result, taps)."""
    started = time.monotonic()
    with vehicle(instance, config, impair=impair, **vehicle_options) as sitl:
        taps = [TruthTap(instance, leaf) for leaf in truth_leaves]
        try:
            url = f"udpin://{url_host}:{ports(instance).api_remote}"
            result = run_flow(flow, url, FLOW_TIMEOUT_S, *args)
            arrays = [tap.drain() for tap in taps]
        finally:
            for tap in taps:
                tap.close()
        if result.returncode != 0 or result.timed_out:
            pytest.fail(f"MAVSDK flow {flow!r} failed\n{result.transcript()}\n{sitl_output(sitl)}")
    result.total_s = time.monotonic() - started
    assert result.total_s < 60, f"{flow}: {result.total_s:.1f} s wall"
    return result, arrays


def modes(result) -> list[str]:
    return [mode for _, mode in result.event("history")["flight_mode"]]


def values(result, stream: str) -> list:
    return [value for _, value in result.event("history")[stream]]


def test_discovery_health_telemetry_and_action(compat_sitl_config):
    """udpin://0.0.0.0:14540+N as in PX4's docs; the ground truth, the IMU and a Mocap pose on
    request; arm -> takeoff -> land -> disarm."""
    result, (truth,) = fly("action", 0, compat_sitl_config)

    found = result.event("discovered")
    assert found["sysid"] == 1 and found["components"] == [1]
    assert found["autopilot"] == "PX4" and found["vehicle"] == "MULTICOPTER"
    assert found["after_s"] < 3.0

    healthy = result.event("healthy")
    assert all(healthy["health"].values()), healthy["health"]
    assert healthy["after_s"] < 5.0

    rest = result.event("at_rest")
    assert rest["armed"] is False and rest["in_air"] is False
    assert rest["landed_state"] == "ON_GROUND" and rest["flight_mode"] == "HOLD"
    assert math.dist(rest["ned"], (0, 0, 0)) < 0.01 and max(map(abs, rest["euler_deg"])) < 0.5
    home = result.event("home")["home"]
    assert math.dist((home["latitude_deg"], home["longitude_deg"]), HOME) < 1e-6
    assert abs(home["absolute_altitude_m"] - 488.0) < 0.01

    streams = result.event("streams")  # set_rate_ground_truth / set_rate_imu accepted (else they raise)
    # The IMU counted on its own stamps: exactly 50 in one second; the truth on arrival: 10 +- 1.
    assert abs(streams["counts"]["ground_truth"] - 10) <= 1 and streams["counts"]["imu"] == 50
    lat, lon, alt = streams["ground_truth"]  # the simulator's truth: at rest on home
    assert math.dist((lat, lon), HOME) < 1e-7 and abs(alt - 488.0) < 0.002
    assert streams["imu_acceleration"] == pytest.approx([0.0, 0.0, -9.81], abs=1e-4)  # exact sensors
    assert streams["imu_rates"] == pytest.approx([0.0, 0.0, 0.0], abs=1e-6)
    assert streams["imu_field"] == pytest.approx([0.21, 0.016, 0.43], abs=1e-4)  # the earth's, NED
    assert streams["imu_temperature"] == pytest.approx(11.8, abs=0.1)  # ISA at 488 m
    assert streams["vision"] == [  # the Mocap pose came, and this vehicle flies on the truth
        "vision refused: no estimator: the vehicle flies on the simulator's truth (EKF2_EN 0)"
    ]

    up = result.event("took_off")
    assert up["armed"] is True and up["in_air"] is True and up["landed_state"] == "IN_AIR"
    assert up["flight_mode"] == "HOLD" and abs(up["ned"][2] + 2.5) < 0.05  # MIS_TAKEOFF_ALT
    assert max(abs(a) for a in up["euler_deg"][:2]) < 1.0
    pos = result.event("position")["position"]
    assert abs(pos["relative_altitude_m"] - 2.5) < 0.05 and abs(pos["absolute_altitude_m"] - 490.5) < 0.05

    # The discrete telemetry followed the vehicle through every phase, in order.
    assert modes(result) == ["HOLD", "TAKEOFF", "HOLD", "LAND"]
    assert values(result, "armed") == [False, True, False]
    assert values(result, "in_air") == [False, True, False]
    assert values(result, "landed_state") == ["ON_GROUND", "TAKING_OFF", "IN_AIR", "LANDING", "ON_GROUND"]
    # and the real vehicle did what MAVSDK reported: 2.5 m up, back on the ground
    assert abs(truth[:, 3].max() - 2.5) < 0.05 and abs(truth[-1, 3]) < 0.01


def test_takeoff_and_land_over_lossy_slow_links(compat_sitl_config):
    """The same flow with 5 % of the datagrams lost and 50 ms of delay on both ground links, both
    ways (quadsitl up --impair): MAVSDK's retries and ours get every command through."""
    lossy = "loss=5%,delay=50ms"
    result, (truth,) = fly("action", 6, compat_sitl_config, impair=(f"gcs:{lossy}", f"api:{lossy}"))
    assert result.event("took_off")["in_air"] is True
    assert values(result, "armed") == [False, True, False]
    assert abs(truth[:, 3].max() - 2.5) < 0.05 and abs(truth[-1, 3]) < 0.01


def test_offboard_position_and_position_velocity(compat_sitl_config):
    result, (truth,) = fly("offboard", 1, compat_sitl_config)

    started = result.event("offboard_started")
    assert started["active"] is True and started["flight_mode"] == "OFFBOARD"

    reached = result.event("reached_position")
    assert math.dist(reached["ned"], reached["target"]) < 0.05
    assert abs(reached["euler_deg"][2] - 30.0) < 1.0  # set_position_ned's yaw, degrees
    north, east, down = reached["target"]
    closest = np.min(np.linalg.norm(truth[:, 1:4] - (north, -east, -down), axis=1))
    assert closest < 0.02  # the real vehicle was there (paper frame: y = -east, z = -down)

    line = result.event("line_done")
    # The flow computes each sample from the telemetry's clock and streams it on its own (wall)
    # clock, so its stalls add to the error it measures: ~5 cm alone, ~10 cm with two checkouts
    # testing at once.
    assert line["samples"] > 10 and line["max_tracking_error_m"] < 0.15
    assert math.dist(line["ned"], line["end"]) < 0.05

    stopped = result.event("offboard_stopped")
    assert stopped["active"] is False and stopped["flight_mode"] == "HOLD"
    assert stopped["drift_m"] < 0.05  # Hold keeps the position where offboard stopped
    assert result.event("disarmed")["armed"] is False


def test_the_failure_plugin_gps_off_in_a_mission_on_the_ekf(compat_sitl_config):
    """MAVSDK's Failure plugin unchanged: refused while SYS_FAILURE_EN is 0 (MAVSDK reads the
    parameter of a PX4 autopilot and answers DISABLED itself), accepted at 1; GPS off in a mission
    on the EKF: PX4's answer (docs/failures.md), dead reckoning, then no global position: Mission,
    RTL and Land cannot run, Descend (MAVSDK's LAND: PX4's AUTO.LAND custom mode), lands, disarms."""
    result, (truth,) = fly("failure", 7, compat_sitl_config, estimator="ekf", sensors="gps")
    assert result.event("refused")["result"] == "DISABLED"
    landed = result.event("landed")
    assert any("Failsafe activated: no global position for AUTO.MISSION, triggering Descend" in text
               for text in landed["texts"]), landed["texts"]  # fmt: skip
    flown = modes(result)
    assert flown[flown.index("MISSION") :][:2] == ["MISSION", "LAND"], flown
    assert truth[-1, 3] < 0.05  # on the ground, where it came down (no return)
    assert math.hypot(truth[-1, 1], truth[-1, 2]) > 1.0


def test_mission_upload_download_fly_and_return(compat_sitl_config):
    """Also shows the loopback-only connection string udpin://127.0.0.1:PORT."""
    result, (truth,) = fly("mission", 2, compat_sitl_config, url_host="127.0.0.1")

    assert result.event("uploaded")["count"] == 3
    down = result.event("downloaded")
    assert len(down["items"]) == len(down["sent"]) == 3
    for got, sent in zip(down["items"], down["sent"], strict=True):
        assert math.dist((got["lat"], got["lon"]), (sent["lat"], sent["lon"])) < 1e-6
        assert abs(got["alt"] - sent["alt"]) < 1e-3
        assert got["fly_through"] == sent["fly_through"]
        assert got["camera"] == sent["camera"]  # gimbal and camera items came back
        for key in ("speed", "loiter_s", "acceptance_m"):  # float32 on the wire; None = NaN (unset)
            expected = None if sent[key] is None else pytest.approx(sent[key], rel=1e-6)
            assert got[key] == expected, (key, got, sent)
    assert down["items"][0]["gimbal_pitch"] == pytest.approx(-45.0)

    end = result.event("mission_end")
    assert end["finished"] is True
    progress = [tuple(p) for p in end["progress"]]
    assert progress[-1] == (3, 3) and [c for c, _ in progress] == sorted(c for c, _ in progress)
    assert all(d < 0.35 for d in end["closest_m"]), end["closest_m"]  # acceptance radius 0.3 m

    back = result.event("returned")
    assert back["armed"] is False and back["in_air"] is False
    assert modes(result)[-2:] == ["MISSION", "RETURN_TO_LAUNCH"]
    assert math.hypot(truth[-1, 1], truth[-1, 2]) < 0.1 and abs(truth[-1, 3]) < 0.01  # home
    assert truth[:, 3].max() > 4.9  # RTL climbed to RTL_RETURN_ALT (5 m) first


def test_params_get_set_and_a_gain_that_changes_the_flight(compat_sitl_config):
    """PX4's encodings (float; int32 bytewise), MIS_TAKEOFF_ALT for takeoff, and BS_C1_X retuned in
    flight: the same offboard step tracks its reference visibly worse with the gain lowered."""
    result, (truth, controller) = fly(
        "params", 3, compat_sitl_config, "--param-gain", "BS_C1_X", "--gain-factor", "0.3",
        truth_leaves=("truth", "controller"),
    )  # fmt: skip

    sysid = result.event("sysid_param")
    assert sysid["value"] == sysid["sysid"] == 4  # INT32 MAV_SYS_ID read bytewise

    alt = result.event("takeoff_alt")
    assert (alt["before"], alt["after"], alt["action_reads"]) == (2.5, 4.0, 4.0)
    every = result.event("all_params")
    assert {"MIS_TAKEOFF_ALT", "BS_C1_X", "MAV_SYS_ID"} <= set(every["names"])
    assert every["ints"]["MAV_SYS_ID"] == 4
    refused = result.event("out_of_range")  # MAVSDK reports a refused value as an error
    assert refused["error"] and refused["kept"] == 4.0

    assert abs(result.event("took_off")["ned"][2] + 4.0) < 0.05  # flew to the new MIS_TAKEOFF_ALT
    assert result.event("gain_set")["value"] == pytest.approx(17.0 * 0.3, rel=1e-6)

    # Tracking error of x against the autopilot's own reference, in simulation time (zenoh):
    # immune to the wall-clock jitter of when MAVSDK's setpoint arrived.
    rms = {}
    for step in (e for e in result.events if e["event"] == "step"):
        rows = controller[(controller[:, 0] >= step["t0"]) & (controller[:, 0] <= step["t1"])]
        x = np.interp(rows[:, 0], truth[:, 0], truth[:, 1])
        rms[step["label"]] = float(np.sqrt(np.mean((x - rows[:, 1]) ** 2)))
        arrived = np.interp(step["t1"], truth[:, 0], truth[:, 1])
        assert abs(arrived - step["goal_n"]) < 0.02, step["label"]
    assert rms["changed"] > 2.0 * rms["default"], rms
    assert rms["changed"] < 0.05, rms  # retuned in flight without a bump


def test_log_files_ftp_and_shell(compat_sitl_config, flight_logs, tmp_path):
    """MAVSDK's log_files plugin (what QGC's Log Download does too): the logs on the vehicle, and
    one it writes while the flow arms and disarms it, downloaded byte-identical; the same log over
    MAVLink FTP (the Ftp plugin: PX4 SITL's /log layout, bursts and plain reads, CRC), the MAVLink
    shell (the Shell plugin: ver, param, commander, listener); then the logs erased."""
    log_dir, out = tmp_path / "log", tmp_path / "downloads"
    out.mkdir()
    vehicle_logs(log_dir, flight_logs)
    with vehicle(6, compat_sitl_config, log_dir=log_dir) as sitl:
        url = f"udpin://0.0.0.0:{ports(6).api_remote}"
        result = run_flow("logs", url, FLOW_TIMEOUT_S, "--out", str(out))
        if result.returncode != 0 or result.timed_out:
            pytest.fail(f"MAVSDK flow 'logs' failed\n{result.transcript()}\n{sitl_output(sitl)}")
    first = result.event("entries")["entries"]
    assert [(e["id"], e["date"], e["size"]) for e in first] == [
        (0, "2024-05-01T10:00:00Z", flight_logs[0].stat().st_size),
        (1, "2024-05-01T10:05:30Z", flight_logs[1].stat().st_size),
    ]
    downloads = [e for e in result.events if e["event"] == "downloaded"]
    assert [d["id"] for d in downloads] == [0, 1, 2] and all(d["last"] == 1.0 for d in downloads)
    for original, d in zip(flight_logs, downloads[:2], strict=False):
        assert Path(d["path"]).read_bytes() == original.read_bytes()
    assert result.event("entries_after_flight")["entries"][-1]["id"] == 2
    assert result.event("after_erase").get("error") == "NO_LOGFILES"  # num_logs 0: nothing left
    assert not list(log_dir.glob("*/*.ulg"))  # erased on the vehicle
    ulog = check_ulog(Path(downloads[2]["path"]), flight_review=False)  # the flow's arming, logged
    assert ulog.get_dataset("paper_tracking").data["armed"].all()

    # MAVLink FTP: the root is the log directory (no parameter file on this vehicle), as PX4 SITL's.
    assert result.event("ftp_root")["entries"] == [["log", "DIRECTORY", 0]]
    days = result.event("ftp_logs")["days"]
    day = Path(LOG_NAMES[0]).parent.name  # the day the vehicle's two logs are filed under
    assert days[day] == [[Path(n).name, "FILE", log.stat().st_size] for n, log in
                         zip(LOG_NAMES, flight_logs, strict=True)]  # fmt: skip
    assert len(days) == 2  # and the day of the flow's flight (UTC)
    flown = Path(downloads[2]["path"]).read_bytes()  # the newest log, as the log protocol gave it
    for burst in (True, False):
        ftp = next(e for e in result.events if e["event"] == "ftp_download" and e["burst"] is burst)
        assert ftp["result"] == "SUCCESS" and ftp["progress"] == [len(flown), len(flown)], ftp
        assert ftp["identical"] is True, ftp  # CalcFileCRC32 agrees with MAVSDK's own CRC
        assert Path(ftp["local"]).read_bytes() == flown
    assert result.event("ftp_outside")["error"] == "FILE_PROTECTED"  # '/..' leaves the root

    # The MAVLink shell: each command's output, then the prompt.
    shell = result.event("shell")["outputs"]
    assert all(out.rstrip().endswith("nsh>") for out in shell.values()), shell
    assert f"quadsitl git-hash: {this_build().commit_text}" in shell["ver all"]
    shown = shell["param show MPC_TKO_SPEED"]
    assert "MPC_TKO_SPEED [" in shown and ": 1.5000" in shown
    assert "armed: no" in shell["commander status"]
    assert "arming_state: 1" in shell["listener vehicle_status"]


def test_what_mavsdk_needs_item_by_item(compat_sitl_config):
    """The wire facts MAVSDK relies on, checked one by one with pymavlink (so a regression names
    the item rather than failing a flow): identity, mode encoding, ACK latency, requested
    messages, health bits, landed state, bytewise int32 parameters."""
    from pymavlink.dialects.v20 import common as m

    from ..sitl.harness import UdpGcs as Gcs

    with vehicle(4, compat_sitl_config) as sitl:
        gcs = Gcs(ports(4).api_remote, 5)
        try:
            gcs.wait(lambda g: {"HEARTBEAT", "SYS_STATUS", "EXTENDED_SYS_STATE"} <= set(g.last),
                     sim_timeout=1e9, wall_timeout=10, what="telemetry")  # fmt: skip
            hb = gcs.last["HEARTBEAT"]
            assert hb.get_srcComponent() == 1 and hb.autopilot == m.MAV_AUTOPILOT_PX4
            assert hb.type == m.MAV_TYPE_QUADROTOR and hb.base_mode & m.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
            assert hb.custom_mode == (4 << 16) | (3 << 24)  # AUTO.LOITER: main 4, sub 3 (PX4 layout)
            status = gcs.last["SYS_STATUS"]
            bits = 0x01 | 0x02 | 0x04 | 0x20  # gyro, accel, mag, GPS
            assert status.onboard_control_sensors_present & bits == bits
            assert status.onboard_control_sensors_health & (bits | 1 << 28) == bits | 1 << 28  # armable
            assert gcs.last["EXTENDED_SYS_STATE"].landed_state == m.MAV_LANDED_STATE_ON_GROUND

            # MAVSDK's offboard start(): ONE setpoint, then DO_SET_MODE at once (its 20 Hz stream
            # starts on a timer thread that may come second). PX4 accepts a fresh setpoint.
            gcs.send_position_setpoint(0.0, 0.0, 0.0)
            ack = gcs.command(m.MAV_CMD_DO_SET_MODE, 1, 6, 0)
            assert ack.result == m.MAV_RESULT_ACCEPTED, gcs.statustext[-2:]

            nan = math.nan
            latency = {}
            for command, params in (
                (m.MAV_CMD_REQUEST_MESSAGE, (m.MAVLINK_MSG_ID_AUTOPILOT_VERSION, nan, nan)),
                (m.MAV_CMD_REQUEST_MESSAGE, (m.MAVLINK_MSG_ID_HOME_POSITION, nan, nan)),
                (m.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES, (1,)),
                (m.MAV_CMD_SET_MESSAGE_INTERVAL, (m.MAVLINK_MSG_ID_EXTENDED_SYS_STATE, 1e6, nan)),
                (m.MAV_CMD_DO_SET_MODE, (1, 4, 3, nan)),
                (m.MAV_CMD_COMPONENT_ARM_DISARM, (1, nan)),  # MAVSDK: param2 NaN
                (m.MAV_CMD_NAV_TAKEOFF, (nan,) * 7),  # MAVSDK: all NaN = MIS_TAKEOFF_ALT
                (m.MAV_CMD_NAV_LAND, (nan,) * 7),
            ):
                t = time.monotonic()
                ack = gcs.command(command, *params, timeout=2.0)
                latency[(command, params[0])] = time.monotonic() - t
                assert ack.result == m.MAV_RESULT_ACCEPTED, (command, ack.result, gcs.statustext[-2:])
                assert (ack.target_system, ack.target_component) == (255, 190)
            assert max(latency.values()) < 0.5, latency  # MAVSDK resends after 0.5 s

            gcs.wait(lambda g: {"AUTOPILOT_VERSION", "HOME_POSITION"} <= set(g.last),
                     sim_timeout=1e9, wall_timeout=2, what="requested messages")  # fmt: skip
            caps = gcs.last["AUTOPILOT_VERSION"].capabilities
            assert caps & m.MAV_PROTOCOL_CAPABILITY_MISSION_INT
            assert caps & m.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE
            assert not caps & m.MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_C_CAST
            assert gcs.last["HOME_POSITION"].altitude == 488_000  # mm AMSL

            # INT32 parameters travel bytewise (the int's bits in the float), type INT32.
            gcs.conn.mav.param_request_read_send(5, 1, b"MAV_SYS_ID", -1)
            gcs.wait(lambda g: "PARAM_VALUE" in g.last, sim_timeout=1e9, wall_timeout=3, what="PARAM_VALUE")
            value = gcs.last["PARAM_VALUE"]
            assert value.param_id == "MAV_SYS_ID" and value.param_type == m.MAV_PARAM_TYPE_INT32
            assert struct.unpack("<i", struct.pack("<f", value.param_value))[0] == 5
        except AssertionError as exc:
            raise AssertionError(f"{exc}\n{sitl_output(sitl)}") from None
        finally:
            gcs.close()


def test_the_geofence_and_manual_control_examples(compat_sitl_config):
    """MAVSDK-Python's geofence.py and manual_control.py, in the native API: the "no circle" circle
    accepted and ignored (MAVSDK 4's Geofence plugin refuses it itself, so it goes through
    MissionRaw, as MAVSDK-Python 3 sends it); POSCTL flown on the example's random sticks; their
    loss returns home."""
    result, (truth,) = fly("examples", 5, compat_sitl_config)

    fence = result.event("geofence_example")
    # MAVSDK 4 refuses the example's "no circle" itself (nothing sent); the same items go raw.
    assert fence["refused_by_mavsdk"] in (None, "INVALID_ARGUMENT")
    assert fence["polygons"] == [4] and fence["circles"] == [0.0]  # stored as uploaded
    assert any("a circle of radius <= 0 is no circle, ignored" in t for t in fence["texts"]), fence["texts"]

    sticks = result.event("manual_control_example")
    assert "POSCTL" in sticks["modes"] and set(sticks["modes"]) <= {"HOLD", "POSCTL"}, sticks["modes"]
    assert not sticks["touched_ground"] and sticks["in_air"] is True
    lost = result.event("manual_control_lost")
    assert any("manual control lost in POSCTL: returning to launch" in t for t in lost["texts"])
    assert lost["armed"] is False and lost["in_air"] is False
    assert modes(result)[-1] == "RETURN_TO_LAUNCH"
    assert math.hypot(truth[-1, 1], truth[-1, 2]) < 0.1 and abs(truth[-1, 3]) < 0.01  # landed at home
