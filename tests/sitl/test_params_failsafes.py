"""Parameters and failsafes on the wire, in simulation time: the whole stack in-process (real
MAVLink bytes between a pymavlink ground station, the autopilot core and the simulator core), the
truth and the controller rows from the stack itself. Every wait is bounded in simulation time.
Losing a process for real (kill -9) is tested in test_process_loss.py.
"""

from __future__ import annotations

import math
import struct
import subprocess
import sys

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as m

from autopilot.commander.modes import FlightMode
from autopilot.core import AutopilotCore
from autopilot.mavlink.params import param_set_raw_value
from quadcommon.bus_records import CONTROLLER_FIELDS, TRUTH_FIELDS
from simulator.environment.gust_profile import gust_profile_from_mapping
from sitl.launcher import REPO, VehicleSpec

from ..stack import Gcs, make_stack

pytestmark = pytest.mark.processes  # (tests/conftest.py: the markers)

LOITER = FlightMode.AUTO_LOITER.custom_mode
POSCTL = FlightMode.POSCTL.custom_mode
RTL = FlightMode.AUTO_RTL.custom_mode
OFFBOARD = FlightMode.OFFBOARD.custom_mode
REAL32, INT32 = m.MAV_PARAM_TYPE_REAL32, m.MAV_PARAM_TYPE_INT32
TRUTH = {name: i for i, name in enumerate(TRUTH_FIELDS)}
CTRL = {name: i for i, name in enumerate(CONTROLLER_FIELDS)}


# -- ground-station helpers ---------------------------------------------------------------------
def texts(gcs: Gcs) -> str:
    """Every STATUSTEXT so far, chunks joined (long texts arrive in 50-character pieces)."""
    return "".join(gcs.statustext)


def value_of(msg) -> float:
    raw = param_set_raw_value(msg)  # bytewise INT32: read the bytes, never the float
    return struct.unpack("<i", raw)[0] if msg.param_type == INT32 else struct.unpack("<f", raw)[0]


def wait_param_value(gcs: Gcs, name: str, sim_timeout: float = 1.0):
    end = gcs.sim_time + sim_timeout
    while gcs.sim_time <= end:
        msg = gcs.poll()
        if msg is not None and msg.get_type() == "PARAM_VALUE" and msg.param_id == name:
            return msg
    raise AssertionError(f"no PARAM_VALUE {name} within {sim_timeout} s")


def param_list(gcs: Gcs, sim_timeout: float = 2.0) -> dict[int, object]:
    """PARAM_REQUEST_LIST: the PARAM_VALUEs by index, until all have come or ``sim_timeout`` s."""
    gcs.conn.mav.param_request_list_send(gcs.system_id, 1)
    values: dict[int, object] = {}
    end = gcs.sim_time + sim_timeout
    while gcs.sim_time < end:
        msg = gcs.poll()
        if msg is not None and msg.get_type() == "PARAM_VALUE":
            values[msg.param_index] = msg
            if len(values) == msg.param_count:
                break
    return values


def param_get(gcs: Gcs, name: str):
    gcs.conn.mav.param_request_read_send(gcs.system_id, 1, name.encode(), -1)
    return wait_param_value(gcs, name)


def param_set(gcs: Gcs, name: str, value: float, param_type: int = REAL32):
    """PARAM_SET (INT32 bytewise, as PX4/MAVSDK) and the PARAM_VALUE echo."""
    wire_value = struct.unpack("<f", struct.pack("<i", int(value)))[0] if param_type == INT32 else value
    gcs.conn.mav.param_set_send(gcs.system_id, 1, name.encode(), wire_value, param_type)
    return wait_param_value(gcs, name)


def keep_link(gcs: Gcs, state: dict) -> None:
    """A GCS heartbeat every 0.5 s of simulation time (the link-loss clock is simulation time)."""
    if gcs.sim_time - state.get("hb", -1.0) >= 0.5:
        gcs.conn.mav.heartbeat_send(m.MAV_TYPE_GCS, m.MAV_AUTOPILOT_INVALID, 0, 0, 0)
        state["hb"] = gcs.sim_time


def take_off(gcs: Gcs, altitude: float = 2.0, link: dict | None = None) -> None:
    assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == m.MAV_RESULT_ACCEPTED
    nan = math.nan
    ack = gcs.command(m.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, nan, nan, nan, 488.0 + altitude)
    assert ack.result == m.MAV_RESULT_ACCEPTED

    def up(g: Gcs) -> bool:
        if link is not None:
            keep_link(g, link)
        return (
            "LOCAL_POSITION_NED" in g.last and g.position()[2] > altitude - 0.03 and g.custom_mode == LOITER
        )

    gcs.wait(up, sim_timeout=15, what="takeoff")


def wait_sim(gcs: Gcs, seconds: float, link: dict | None = None, feed=None) -> None:
    t0 = gcs.sim_time

    def done(g: Gcs) -> bool:
        if link is not None:
            keep_link(g, link)
        if feed is not None:
            feed(g)
        return g.sim_time > t0 + seconds

    gcs.wait(done, sim_timeout=seconds + 5, what=f"{seconds} s of simulation")


def push_now(stack, mapping: dict) -> float:
    """The gust profile ``mapping`` from the next frame on (as an upload with ``--now``); its start."""
    start = stack.t + stack.sim.dt_control
    stack.sim.schedule_gust_profile(gust_profile_from_mapping(mapping), start)
    return start


def column(rows, index, name):
    return np.asarray(rows)[:, index[name]]


# -- parameter protocol ---------------------------------------------------------------------------------
def test_param_list_get_set_and_refusals(vehicle):
    _, gcs = vehicle
    values = param_list(gcs)
    count = next(iter(values.values())).param_count
    assert sorted(values) == list(range(count)) and all(v.param_count == count for v in values.values())
    by_name = {v.param_id: v for v in values.values()}
    for name in (
        "MIS_TAKEOFF_ALT",
        "BS_KI_X",
        "NLH_W3",
        "CF_WN",
        "COM_DL_LOSS_T",
        "NAV_DLL_ACT",
        "GF_ACTION",
    ):
        assert name in by_name
    assert by_name["MIS_TAKEOFF_ALT"].param_type == REAL32 and value_of(by_name["MIS_TAKEOFF_ALT"]) == 2.5
    assert by_name["GF_ACTION"].param_type == INT32 and value_of(by_name["GF_ACTION"]) == 2
    assert value_of(by_name["MAV_SYS_ID"]) == gcs.system_id

    # get / set a float
    assert value_of(param_get(gcs, "NLH_W3")) == 9.0
    echo = param_set(gcs, "NLH_W3", 4.5)
    assert (echo.param_type, value_of(echo)) == (REAL32, 4.5)
    assert value_of(param_get(gcs, "NLH_W3")) == 4.5
    # get / set an int32, bytewise
    echo = param_set(gcs, "NAV_DLL_ACT", 3, INT32)
    assert (echo.param_type, value_of(echo)) == (INT32, 3)
    assert echo.param_value == pytest.approx(4.2e-45)  # the int's bytes in the float field

    # refusals: the old value comes back, and a STATUSTEXT says why
    echo = param_set(gcs, "MIS_TAKEOFF_ALT", 500.0)
    assert value_of(echo) == 2.5
    echo = param_set(gcs, "GF_ACTION", 4, INT32)
    assert value_of(echo) == 2
    echo = param_set(gcs, "NAV_DLL_ACT", 1.0, REAL32)  # wrong type
    assert (echo.param_type, value_of(echo)) == (INT32, 3)
    gcs.conn.mav.param_set_send(gcs.system_id, 1, b"NO_SUCH_PARAM", 1.0, REAL32)
    gcs.wait(lambda g: "unknown parameter 'NO_SUCH_PARAM'" in texts(g), sim_timeout=0.2,
             what="unknown-parameter STATUSTEXT")  # fmt: skip
    all_text = texts(gcs)
    assert "MIS_TAKEOFF_ALT: 500 out of range [0.2, 100] m" in all_text
    assert "flight termination is not supported" in all_text
    assert "type 9 refused, it is INT32" in all_text

    # ArduPilot's parameter file over MAVLink FTP is FileNotFound, as on PX4 (MAVProxy then falls
    # back to PARAM_REQUEST_LIST at once)
    header = struct.pack("<HBBBBBBI", 1, 0, 4, 16, 0, 0, 0, 0) + b"@PARAM/param.pck"
    gcs.conn.mav.file_transfer_protocol_send(0, gcs.system_id, 1, list(header.ljust(251, b"\0")))
    end = gcs.sim_time + 0.2
    reply = None
    while reply is None and gcs.sim_time < end:
        msg = gcs.poll()
        if msg is not None and msg.get_type() == "FILE_TRANSFER_PROTOCOL":
            reply = msg
    assert reply is not None
    seq, _, opcode, size, req_opcode = struct.unpack_from("<HBBBB", bytes(reply.payload))
    assert (seq, opcode, size, req_opcode, reply.payload[12]) == (2, 129, 1, 4, 10)  # NAK FileNotFound


def test_gain_change_in_flight_changes_the_flight_without_a_jump(vehicle):
    """Under a sustained 1 N push the x integral carries the load; lowering BS_KI_X then keeps
    U1 and the attitude references continuous (the integral is rescaled), and the next push is
    rejected far more slowly (the new gain acts)."""
    stack, gcs = vehicle
    take_off(gcs, 2.0)
    push = {"description": "test", "step": [{"channel": "force_x", "start_s": 0.0, "value": 1.0}]}
    t1 = push_now(stack, push)
    wait_sim(gcs, 4.0)
    echo = param_set(gcs, "BS_KI_X", 0.3)
    assert value_of(echo) == pytest.approx(0.3)
    t_change = gcs.sim_time
    wait_sim(gcs, 1.0)
    push["step"][0]["value"] = 2.0  # one more newton (an upload replaces the profile)
    t2 = push_now(stack, push)
    wait_sim(gcs, 3.5)

    rows = np.asarray(stack.controller_rows)
    t = rows[:, CTRL["time_s"]]
    window = (t > t_change - 1.0) & (t < t_change + 0.5)
    assert window.sum() > 200
    for field in ("U1_n", "theta_raw_rad", "phi_raw_rad", "tau_theta_n_m"):
        steps = np.abs(np.diff(rows[window, CTRL[field]]))
        # Without the rescale the x integral term would jump by (1.5 - 0.3) * xi ~ 1 m/s^2,
        # i.e. ~0.1 rad in theta_r: the largest step here is orders of magnitude below.
        assert steps.max() < 2e-3, (field, steps.max())
    truth = np.asarray(stack.truth_rows)
    tt, x = truth[:, TRUTH["time_s"]], truth[:, TRUTH["x_m"]]

    def error_at(time_s: float) -> float:
        return abs(x[np.argmin(np.abs(tt - time_s))])

    peak1 = np.abs(x[(tt > t1) & (tt < t1 + 3.0)]).max()
    peak2 = np.abs(x[(tt > t2) & (tt < t2 + 3.0)] - error_at(t2)).max()
    assert 0.01 < peak1 < 0.06 and 0.01 < peak2 < 0.1
    # 3 s after each push: k_xi = 1.5 has removed most of the offset, k_xi = 0.3 has not.
    assert error_at(t2 + 3.0) > 2.5 * error_at(t1 + 3.0), (error_at(t1 + 3.0), error_at(t2 + 3.0))


def test_raising_nlh_wu_in_flight_under_a_torque_push_keeps_the_vehicle_upright(vehicle):
    """NLH_WU multiplies w_u^-2 into the attitude integral's torque. With a 0.05 N m roll push held
    by the integral, raising NLH_WU from 1.5 to 900 (inside its range) in flight: keeping that
    torque exactly would take a ~3.6e5 times larger integral, which the law's C(eta, eta') s term
    turns into a runaway; the integral's share of s is kept, and the vehicle stays upright."""
    stack, gcs = vehicle
    take_off(gcs, 2.0)
    push = {"description": "test", "step": [{"channel": "torque_roll", "start_s": 0.0, "value": 0.05}]}
    push_now(stack, push)
    wait_sim(gcs, 4.0)
    echo = param_set(gcs, "NLH_WU", 900.0)
    assert value_of(echo) == pytest.approx(900.0)
    t_change = gcs.sim_time
    wait_sim(gcs, 3.0)
    truth = np.asarray(stack.truth_rows)
    after = truth[:, TRUTH["time_s"]] > t_change
    tilt = np.hypot(truth[after, TRUTH["phi_rad"]], truth[after, TRUTH["theta_rad"]])
    assert tilt.max() < 0.1, tilt.max()
    drift = np.hypot(truth[after, TRUTH["x_m"]], truth[after, TRUTH["y_m"]])
    assert drift.max() < 0.2, drift.max()


def test_saved_parameters_persist_across_a_restart(vehicle, tmp_path):
    stack, gcs = vehicle  # a first vehicle without --params: saving is refused with the reason
    ack = gcs.command(m.MAV_CMD_PREFLIGHT_STORAGE, 1)
    assert ack.result == m.MAV_RESULT_DENIED
    gcs.wait(lambda g: "--params FILE" in texts(g), sim_timeout=0.2, what="reason")

    path = tmp_path / "params.toml"
    g2 = Gcs(make_stack(params_file=str(path)))
    g2.wait_heartbeat()
    assert value_of(param_set(g2, "NLH_W3", 4.5)) == 4.5
    assert value_of(param_set(g2, "NAV_DLL_ACT", 2, INT32)) == 2
    assert g2.command(m.MAV_CMD_PREFLIGHT_STORAGE, 1).result == m.MAV_RESULT_ACCEPTED
    text = path.read_text()
    assert "NLH_W3 = 4.5" in text and "NAV_DLL_ACT = 2" in text
    lines: list[str] = []
    g3 = Gcs(make_stack(params_file=str(path), log=lines.append))
    g3.wait_heartbeat()
    assert value_of(param_get(g3, "NLH_W3")) == 4.5
    assert value_of(param_get(g3, "NAV_DLL_ACT")) == 2
    assert any("parameters loaded from" in line for line in lines)


def test_bad_parameter_file_is_a_clear_startup_error(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("MIS_TAKEOFF_ALT = 3.0\nNLH_W3 = -1.0\n")
    result = subprocess.run(
        [sys.executable, "-m", "autopilot", "--instance", "97", "--no-zenoh", "--params", str(path)],
        cwd=REPO, capture_output=True, text=True, timeout=20,
    )  # fmt: skip
    assert result.returncode == 2
    assert str(path) in result.stderr and "'NLH_W3' = -1.0" in result.stderr
    assert "allowed: [0.001, 1000]" in result.stderr


# -- failsafes ------------------------------------------------------------------------------------
def test_gcs_heartbeat_loss_with_hold_action(vehicle):
    _, gcs = vehicle
    link: dict = {}
    keep_link(gcs, link)
    assert value_of(param_set(gcs, "NAV_DLL_ACT", 1, INT32)) == 1
    assert value_of(param_set(gcs, "COM_DL_LOSS_T", 5, INT32)) == 5
    take_off(gcs, 2.0, link)
    sticks: dict = {}

    def joystick(g: Gcs) -> None:  # centred sticks at 10 Hz: POSCTL flies on them
        if g.sim_time - sticks.get("t", -1.0) >= 0.1:
            g.conn.mav.manual_control_send(g.system_id, 0, 0, 500, 0, 0)
            sticks["t"] = g.sim_time

    wait_sim(gcs, 0.3, link, feed=joystick)
    assert gcs.command(m.MAV_CMD_DO_SET_MODE, 1, 3, 0).result == m.MAV_RESULT_ACCEPTED  # POSCTL
    wait_sim(gcs, 2.0, link, feed=joystick)
    assert gcs.custom_mode == POSCTL and "GCS connection lost" not in texts(gcs)
    last_heartbeat = link["hb"]
    gcs.wait(lambda g: joystick(g) or g.custom_mode == LOITER, sim_timeout=10, what="hold after link loss")
    # (the autopilot stamps the heartbeat on arrival, a little after the telemetry time we saw)
    assert 4.5 < gcs.sim_time - last_heartbeat < 7.0
    gcs.wait(lambda g: "GCS connection lost" in texts(g), sim_timeout=2, what="announcement")
    assert "(NAV_DLL_ACT 1): holding" in texts(gcs)
    keep_link(gcs, {})
    gcs.wait(lambda g: "GCS connection regained" in texts(g), sim_timeout=2, what="regained")


def test_arming_refused_with_a_reason_then_geofence_breach_returns(vehicle):
    _, gcs = vehicle
    # An inconsistent combination: a vertical fence below the takeoff altitude.
    assert value_of(param_set(gcs, "GF_MAX_VER_DIST", 2.0)) == 2.0
    ack = gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    assert ack.result == m.MAV_RESULT_DENIED
    gcs.wait(lambda g: "arming refused: bad parameters" in texts(g), sim_timeout=0.2,
             what="arming refusal STATUSTEXT")  # fmt: skip
    assert "MIS_TAKEOFF_ALT 2.5 m is not below GF_MAX_VER_DIST 2 m" in texts(gcs)
    assert not gcs.armed
    param_set(gcs, "GF_MAX_VER_DIST", 0.0)
    # Horizontal fence at 3 m, breach -> return to launch.
    param_set(gcs, "GF_MAX_HOR_DIST", 3.0)
    assert value_of(param_set(gcs, "GF_ACTION", 3, INT32)) == 3
    take_off(gcs, 2.0)
    for _ in range(10):
        gcs.send_position_setpoint(6.0, 0.0, 2.0)
        gcs.poll()
    assert gcs.command(m.MAV_CMD_DO_SET_MODE, 1, 6, 0).result == m.MAV_RESULT_ACCEPTED  # OFFBOARD

    def flying_out(g: Gcs) -> bool:
        if g.last.get("LOCAL_POSITION_NED") is not None:
            g.send_position_setpoint(6.0, 0.0, 2.0)
        return g.custom_mode == RTL

    gcs.wait(flying_out, sim_timeout=15, what="RTL after the geofence breach")
    assert 2.9 < gcs.position()[0] < 4.0  # caught at the fence, not at the setpoint
    gcs.wait(lambda g: "geofence breached" in texts(g), sim_timeout=2, what="announcement")
    assert "from home > GF_MAX_HOR_DIST 3 m: returning to launch" in texts(gcs)
    fence = m.MAV_SYS_STATUS_GEOFENCE

    def fence_bits(g: Gcs) -> tuple[bool, bool] | None:
        status = g.last.get("SYS_STATUS")
        if status is None:
            return None
        return bool(status.onboard_control_sensors_present & fence), bool(
            status.onboard_control_sensors_health & fence
        )

    gcs.wait(lambda g: fence_bits(g) == (True, False), sim_timeout=3, what="SYS_STATUS: fence breached")
    gcs.wait(lambda g: g.position()[0] < 0.5, sim_timeout=15, what="back home")
    gcs.wait(lambda g: fence_bits(g) == (True, True), sim_timeout=3, what="SYS_STATUS: fence healthy again")


def test_simulator_gone_autopilot_reports_and_keeps_answering(vehicle):
    """No more frames (the simulator stopped): after COM_SIM_LOSS_T of the autopilot's clock it says
    so, keeps its heartbeat going and keeps answering commands (arming refused, with the reason)."""
    stack, gcs = vehicle
    gcs.wait(lambda g: "LOCAL_POSITION_NED" in g.last, what="telemetry")
    stack.frames_flow = False
    gcs.wait(lambda g: "(COM_SIM_LOSS_T); motors off" in texts(g), sim_timeout=1.5, what="simulator lost")
    assert "simulator lost: no sensor frame for 1 s" in texts(gcs)
    gcs.last.pop("HEARTBEAT", None)
    gcs.wait(lambda g: "HEARTBEAT" in g.last, sim_timeout=1.5, what="wall-clock heartbeat")
    ack = gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    assert ack.result == m.MAV_RESULT_DENIED
    gcs.wait(lambda g: "arming refused: no position" in texts(g), sim_timeout=0.2, what="reason")
    assert value_of(param_get(gcs, "MIS_TAKEOFF_ALT")) == 2.5
    stack.frames_flow = True  # the simulator is back: frames again, and the link is announced
    gcs.wait(lambda g: "simulator link recovered" in texts(g), sim_timeout=0.5, what="recovery")


def test_autopilot_gone_in_flight_simulator_lands_the_vehicle_and_a_new_one_takes_over(vehicle):
    stack, gcs = vehicle
    take_off(gcs, 2.0)
    stack.answer_frames = False  # the autopilot is gone: the simulator flies its own descent
    start = stack.t
    stack.run_for(15.0, until=lambda s: s.sim.emergency_landed)
    assert stack.sim.emergency_landed
    stack.run_for(0.5)  # landed: motors off from the next frame on
    truth = np.asarray(stack.truth_rows)
    after = truth[truth[:, TRUTH["time_s"]] >= start]
    assert after[-1, TRUTH["on_ground"]] == 1.0 and abs(after[-1, TRUTH["z_m"]]) < 1e-6
    assert after[-1, TRUTH["thrust_n"]] == 0.0  # motors off
    airborne = after[after[:, TRUTH["z_m"]] > 0.1]
    descent = airborne[airborne[:, TRUTH["time_s"]] > airborne[-1, TRUTH["time_s"]] - 1.0]
    assert np.mean(descent[:, TRUTH["vz_m_s"]]) == pytest.approx(-0.5, abs=0.1)
    assert np.abs(after[-1, [TRUTH["x_m"], TRUTH["y_m"]]]).max() < 0.5  # landed where it was lost
    # A new autopilot resumes lockstep from the current (landed) state.
    stack.autopilot = AutopilotCore(stack.autopilot.setup)
    stack.answer_frames = True
    gcs2 = Gcs(stack)
    gcs2.wait(lambda g: "EXTENDED_SYS_STATE" in g.last and "LOCAL_POSITION_NED" in g.last, 2.0, "telemetry")
    assert not stack.sim.emergency
    assert abs(gcs2.position()[2]) < 0.01 and not gcs2.armed
    assert gcs2.last["EXTENDED_SYS_STATE"].landed_state == m.MAV_LANDED_STATE_ON_GROUND


# -- quadsitl up --params ---------------------------------------------------------------------------
def test_quadsitl_up_refuses_a_bad_parameter_file_before_starting(tmp_path):
    path = tmp_path / "params.toml"
    path.write_text("GF_ACTION = 4\n")
    result = subprocess.run(
        [sys.executable, "-m", "sitl.cli", "up", "--instance", "98", "--params", str(path)],
        cwd=REPO, capture_output=True, text=True, timeout=20,
    )  # fmt: skip
    assert result.returncode == 2
    assert str(path) in result.stderr and "'GF_ACTION' = 4" in result.stderr
    assert "flight termination is not supported" in result.stderr and "allowed: [0, 5]" in result.stderr
    result = subprocess.run(
        [sys.executable, "-m", "sitl.cli", "up", "--instance", "98", "--count", "2", "--params", str(path)],
        cwd=REPO, capture_output=True, text=True, timeout=20,
    )  # fmt: skip
    assert result.returncode == 2 and "{instance}" in result.stderr


def test_quadsitl_up_passes_the_parameter_file_to_the_autopilot(tmp_path):
    spec = VehicleSpec(instance=99, params_file=str(tmp_path / "params-99.toml"))
    cmd = spec.autopilot_command()
    assert cmd[cmd.index("--params") + 1] == str(tmp_path / "params-99.toml")
