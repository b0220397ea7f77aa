"""The simulator process over real UDP (and zenoh) with a scripted autopilot peer.

Each test starts ``python -m simulator`` on its own instance (40-59) and bounds every wait.
"""

from __future__ import annotations

import json
import math
import signal
import socket
import time

import pytest

from quadcommon import bus, frames, wire
from quadcommon.bus_records import TRUTH_CODEC, TRUTH_FIELDS
from quadcommon.config import apply_uncertainty, load_scenario, load_sitl, load_vehicle
from simulator.dynamics.plant import make_plant
from simulator.environment.gust_profile import DisturbanceSchedule, load_gust_profile
from simulator.sensors import isa_pressure_hpa

from .sim_harness import ScriptedAutopilot, SimProcess, airborne_scenario, sitl_toml_with

RATES = load_sitl().rates
FRAME_USEC = round(1e6 / RATES.control_hz)
HOME = load_sitl().home


def quaternion_yaw_pitch_roll(q):
    """ZYX Euler angles of a (w, x, y, z) quaternion, written out independently of the project."""
    w, x, y, z = q
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw


def check_frame_against_truth(frame, truth, wind=(0.0, 0.0, 0.0)):
    odo = frame["ODOMETRY"]
    ned = frames.vector_to_ned(truth.position_m)
    assert (odo.x, odo.y, odo.z) == pytest.approx(ned, abs=1e-6)
    assert odo.frame_id == odo.child_frame_id == 1  # MAV_FRAME_LOCAL_NED: twist in world NED
    assert (odo.vx, odo.vy, odo.vz) == pytest.approx(frames.vector_to_ned(truth.velocity_m_s), abs=1e-5)
    assert tuple(odo.q) == pytest.approx(frames.quaternion_to_ned(truth.quaternion), abs=1e-6)
    rates_frd = frames.vector_to_ned(truth.body_rates_rad_s)
    assert (odo.rollspeed, odo.pitchspeed, odo.yawspeed) == pytest.approx(rates_frd, abs=1e-6)
    assert math.isnan(odo.pose_covariance[0]) and math.isnan(odo.velocity_covariance[0])
    assert odo.quality == 100

    hsq = frame["HIL_STATE_QUATERNION"]
    lat, lon, alt = frames.ned_to_geodetic(*ned, HOME)
    assert (hsq.lat, hsq.lon, hsq.alt) == (round(lat * 1e7), round(lon * 1e7), round(alt * 1e3))
    assert tuple(hsq.attitude_quaternion) == pytest.approx(tuple(odo.q), abs=1e-7)
    assert (hsq.rollspeed, hsq.pitchspeed, hsq.yawspeed) == pytest.approx(rates_frd, abs=1e-6)
    v_ned = frames.vector_to_ned(truth.velocity_m_s)
    assert (hsq.vx, hsq.vy, hsq.vz) == tuple(round(100 * v) for v in v_ned)
    f_frd = frames.vector_to_ned(truth.specific_force_body_m_s2)
    assert (hsq.xacc, hsq.yacc, hsq.zacc) == tuple(round(f * 1000 / 9.80665) for f in f_frd)

    sensor = frame["HIL_SENSOR"]
    assert (sensor.xacc, sensor.yacc, sensor.zacc) == pytest.approx(f_frd, abs=1e-5)
    assert (sensor.xgyro, sensor.ygyro, sensor.zgyro) == pytest.approx(rates_frd, abs=1e-6)
    assert sensor.abs_pressure == pytest.approx(isa_pressure_hpa(HOME[2] + truth.position_m[2]), abs=1e-3)
    assert sensor.pressure_alt == pytest.approx(HOME[2] + truth.position_m[2], abs=2e-3)
    assert sensor.fields_updated == 0x1FFF
    assert frame["HIL_STATE_QUATERNION"].time_usec == odo.time_usec == sensor.time_usec


def test_frames_match_an_in_process_plant_step_for_step(tmp_path):
    """Decoded frames equal the truth of the same plant coupled as sitl.inprocess does (gusts too)."""
    scenario_path = airborne_scenario(tmp_path)
    scenario = load_scenario(scenario_path)
    dt_control = 1.0 / RATES.control_hz
    substeps = RATES.physics_steps_per_control
    dt_physics = dt_control / substeps
    plant = make_plant(apply_uncertainty(load_vehicle("paper_quad"), scenario), dt_physics)
    plant.reset(scenario.initial_position_m, scenario.initial_euler_rad)
    schedule = DisturbanceSchedule(load_gust_profile(scenario.gusts))
    controls = (0.3, 0.02, -0.03, 0.01)

    with SimProcess(40, "--scenario", str(scenario_path)) as sim, ScriptedAutopilot(40) as ap:
        frame = ap.link()
        # Sign conventions, checked without the project's helpers: paper yaw +0.7 (CCW from
        # above, z up) is NED yaw -0.7; paper pitch -0.2 (about y-left) is NED pitch +0.2.
        roll, pitch, yaw = quaternion_yaw_pitch_roll(frame["ODOMETRY"].q)
        assert (roll, pitch, yaw) == pytest.approx((0.1, 0.2, -0.7), abs=1e-6)
        assert (frame["ODOMETRY"].y, frame["ODOMETRY"].z) == pytest.approx((2.0, -3.0), abs=1e-6)
        assert "HIL_GPS" in frame
        gps = frame["HIL_GPS"]
        assert (gps.fix_type, gps.satellites_visible, gps.eph, gps.epv) == (3, 10, 100, 100)
        for k in range(40):
            assert frame.time_usec == k * FRAME_USEC
            truth = plant.truth()
            check_frame_against_truth(frame, truth)
            assert ("HIL_GPS" in frame) == (k % round(RATES.control_hz / RATES.gps_hz) == 0)
            t = k * dt_control
            plant.set_actuator_controls(controls)
            for j in range(substeps):
                plant.set_disturbance(*schedule.evaluate(t + j * dt_physics))
                plant.step()
            frame = ap.step(frame, controls=controls, armed=True)
        assert sim.proc.poll() is None


def test_lockstep_waits_for_the_answer_and_never_skips_a_frame():
    with SimProcess(41) as sim, ScriptedAutopilot(41) as ap:
        frame = ap.link()
        assert frame.time_usec == 0
        sim.wait_line("simulator: linked with autopilot at 127.0.0.1:")
        # Unanswered: nothing new arrives (well inside the 2 s lockstep timeout).
        assert ap.recv_frame(0.3) is None
        # A stale or future answer does not advance the simulator either.
        ap.answer(frame.time_usec + FRAME_USEC)
        assert ap.recv_frame(0.2) is None
        times = [frame.time_usec]
        for _ in range(60):
            frame = ap.step(frame)
            times.append(frame.time_usec)
        assert [b - a for a, b in zip(times, times[1:], strict=False)] == [FRAME_USEC] * 60
        # An old answer arriving late is ignored: still exactly one frame per answer.
        ap.answer(times[-2])
        assert ap.recv_frame(0.2) is None


def test_timeout_is_reported_then_simulation_goes_on_and_link_recovers(tmp_path):
    """A missing answer is reported once; the simulator then steps on by itself (autopilot lost:
    disarmed on the ground here, motors off) and resumes lockstep at the autopilot's next answer."""
    sitl = sitl_toml_with(tmp_path, timeout_s=0.3)
    with SimProcess(42, "--sitl-config", str(sitl)) as sim, ScriptedAutopilot(42) as ap:
        frame = ap.link()
        for _ in range(3):
            frame = ap.step(frame)
        stuck = frame.time_usec
        line = sim.wait_line("no HIL_ACTUATOR_CONTROLS", timeout=3.0)
        assert f"t={stuck * 1e-6:.3f} s within 0.3 s" in line
        assert f"udp 127.0.0.1:{wire.ports(42).hil}" in line and "autopilot running" in line
        sim.wait_line("autopilot lost: vehicle disarmed, motors off", timeout=1.0)
        later = [ap.recv_frame(1.0) for _ in range(3)]
        assert all(f is not None for f in later)
        assert stuck < later[0].time_usec < later[1].time_usec < later[2].time_usec  # time goes on
        assert later[-1]["ODOMETRY"].z == 0.0  # still resting on the ground
        # The message is printed once per outage, not per frame.
        assert sim.output.count("no HIL_ACTUATOR_CONTROLS") == 1
        while (newer := ap.recv_frame(0.0005)) is not None:  # the newest frame queued so far
            later.append(newer)
        ap.answer(later[-1].time_usec)
        sim.wait_line("link recovered", timeout=2.0)
        while (newer := ap.recv_frame(0.2)) is not None:  # frames sent before the answer arrived
            later.append(newer)
        frame = later[-1]
        resumed = frame.time_usec
        for _ in range(5):
            frame = ap.step(frame)
        assert frame.time_usec == resumed + 5 * FRAME_USEC  # lockstep again: one frame per answer
        assert sim.terminate() == 0


def test_peer_that_chatters_without_answering_is_reported(tmp_path):
    """Heartbeats and stale answers every 10 ms do not hide a missing answer."""
    sitl = sitl_toml_with(tmp_path, timeout_s=0.3)
    with SimProcess(56, "--sitl-config", str(sitl)) as sim, ScriptedAutopilot(56) as ap:
        frame = ap.link()
        frame = ap.step(frame)
        deadline = time.monotonic() + 1.5
        while time.monotonic() < deadline and "no HIL_ACTUATOR_CONTROLS" not in sim.output:
            ap.hello()
            ap.answer(frame.time_usec - FRAME_USEC)  # stale
            time.sleep(0.01)
        sim.wait_line(f"no HIL_ACTUATOR_CONTROLS for frame t={frame.time_usec * 1e-6:.3f} s", timeout=0.5)
        assert sim.terminate() == 0


def test_actuation_mismatch_is_refused_with_motors_off():
    """paper_quad flies a wrench; rotor-speed controls (flags bit 1 clear) are refused."""
    with SimProcess(43) as sim, ScriptedAutopilot(43) as ap:
        frame = ap.link()
        for _ in range(100):
            frame = ap.step(frame, controls=(1.0, 0.0, 0.0, 0.0), armed=True, wrench=False)
        assert frame["ODOMETRY"].z == 0.0  # full "thrust" refused: still on the ground
        line = sim.wait_line("refusing HIL_ACTUATOR_CONTROLS")
        assert "rotors" in line and "wrench" in line
        assert sim.output.count("refusing") == 1
        # The same thrust with the right flag lifts off: the refusal was what held it down.
        for _ in range(50):
            frame = ap.step(frame, controls=(1.0, 0.0, 0.0, 0.0), armed=True, wrench=True)
        assert frame["ODOMETRY"].z < -0.01  # NED: up is negative
        assert sim.terminate() == 0


def test_disarmed_vehicle_rests_cleanly_on_the_ground():
    with SimProcess(44) as sim, ScriptedAutopilot(44) as ap:
        frame = ap.link()
        for _ in range(250):  # half a second of "full thrust" while disarmed
            frame = ap.step(frame, controls=(1.0, 0.5, 0.5, 0.5), armed=False)
            odo = frame["ODOMETRY"]
            assert (odo.x, odo.y, odo.z) == (0.0, 0.0, 0.0)
            assert (odo.vx, odo.vy, odo.vz) == (0.0, 0.0, 0.0)
            assert (odo.rollspeed, odo.pitchspeed, odo.yawspeed) == (0.0, 0.0, 0.0)
        assert tuple(odo.q) == (1.0, 0.0, 0.0, 0.0)
        sensor = frame["HIL_SENSOR"]
        assert (sensor.xacc, sensor.yacc) == (0.0, 0.0)
        assert sensor.zacc == pytest.approx(-9.81, abs=1e-6)  # FRD: the ground pushes up
        hsq = frame["HIL_STATE_QUATERNION"]
        assert (hsq.vx, hsq.vy, hsq.vz, hsq.alt) == (0, 0, 0, round(HOME[2] * 1000))
        assert sim.terminate() == 0


def test_truth_stream_and_info_on_zenoh():
    n = 45
    with SimProcess(n) as sim:
        sim.wait_line("waiting for the autopilot")
        session = bus.open_peer(wire.ports(n).zenoh)
        try:
            sub = session.declare_subscriber(wire.zenoh_key(n, "truth"), bus.zenoh.handlers.FifoChannel(256))
            info = None
            deadline = time.monotonic() + 5.0
            while info is None and time.monotonic() < deadline:  # also proves the link is up
                for reply in session.get(wire.zenoh_key(n, "info"), timeout=1.0):
                    if reply.ok is not None:
                        info = json.loads(reply.ok.payload.to_bytes())
            assert info == {
                "instance": n, "vehicle": "paper_quad", "scenario": "hover", "actuation": "wrench",
                "physics_hz": RATES.physics_hz, "control_hz": RATES.control_hz, "speed": "max",
                "sim_time_s": 0.0,
            }  # fmt: skip
            time.sleep(0.2)  # let the subscription reach the simulator (no history on zenoh)
            with ScriptedAutopilot(n) as ap:
                frame = ap.link()
                positions = {}
                for _ in range(25):
                    positions[frame.time_usec] = frame["ODOMETRY"]
                    frame = ap.step(frame, controls=(0.6, 0.0, 0.0, 0.0), armed=True)
                positions[frame.time_usec] = frame["ODOMETRY"]
                assert sim.terminate() == 0  # flushes the partial batch
            batches = []
            deadline = time.monotonic() + 3.0
            while sum(len(b) for b in batches) < 26 and time.monotonic() < deadline:
                sample = sub.try_recv()
                if sample is None:
                    time.sleep(0.01)
                    continue
                batches.append(TRUTH_CODEC.decode(sample.payload.to_bytes()))
        finally:
            session.close()
    assert [len(b) for b in batches] == [10, 10, 6]
    rows = [row for batch in batches for row in batch]
    col = {name: i for i, name in enumerate(TRUTH_FIELDS)}
    assert [round(r[col["time_s"]] * 1e6) for r in rows] == sorted(positions)
    for row in rows:
        odo = positions[round(row[col["time_s"]] * 1e6)]
        xyz = (row[col["x_m"]], row[col["y_m"]], row[col["z_m"]])
        assert frames.vector_to_ned(xyz) == pytest.approx((odo.x, odo.y, odo.z), abs=1e-6)
    assert rows[0][col["on_ground"]] == 1.0 and rows[-1][col["z_m"]] > 0.0
    assert rows[-1][col["thrust_n"]] == pytest.approx(0.6 * 28.0)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_signal_stops_cleanly_while_linked(sig):
    n = 46 if sig == signal.SIGTERM else 47
    with SimProcess(n) as sim, ScriptedAutopilot(n) as ap:
        frame = ap.link()
        for _ in range(5):
            frame = ap.step(frame)
        start = time.monotonic()
        assert sim.terminate(timeout=2.0, sig=sig) == 0
        assert time.monotonic() - start < 2.0
        line = sim.wait_line("simulator: stopped at t=")
        assert line.startswith(f"simulator: stopped at t={5 * 0.002:.3f} s")


def test_sigterm_while_waiting_for_the_autopilot():
    with SimProcess(48) as sim:
        line = sim.wait_line("waiting for the autopilot")
        assert f"udp 127.0.0.1:{wire.ports(48).hil}" in line
        assert sim.terminate(timeout=2.0) == 0
        sim.wait_line("simulator: stopped at t=0.000 s")


def test_duration_stops_after_the_final_frame():
    with SimProcess(49, "--duration", "0.02") as sim, ScriptedAutopilot(49) as ap:
        frame = ap.link()
        times = [frame.time_usec]
        while True:
            ap.answer(frame.time_usec)
            frame = ap.recv_frame(1.0)
            if frame is None:
                break
            times.append(frame.time_usec)
        assert times == [k * FRAME_USEC for k in range(11)]
        assert sim.proc.wait(3.0) == 0
        sim.wait_line("simulator: stopped at t=0.020 s")


def test_speed_factor_paces_the_wall_clock():
    """--speed 2 over 0.4 s of simulated time takes about 0.2 s of wall time."""
    with SimProcess(50, "--duration", "0.4", speed="2") as sim, ScriptedAutopilot(50) as ap:
        frame = ap.link()
        start = time.perf_counter()
        while frame is not None:
            ap.answer(frame.time_usec)
            frame = ap.recv_frame(1.0)
        elapsed = time.perf_counter() - start - 1.0  # the last recv timed out
        assert sim.proc.wait(3.0) == 0
        assert 0.18 < elapsed < 0.6


def test_hil_port_in_use_exits_2_naming_the_port():
    n = 51
    port = wire.ports(n).hil
    blocker = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    blocker.bind((wire.LOOPBACK, port))
    try:
        with SimProcess(n) as sim:
            assert sim.proc.wait(8.0) == 2
            sim._thread.join(2.0)
            assert str(port) in sim.output and "--instance 51" in sim.output
    finally:
        blocker.close()


def test_zenoh_port_in_use_exits_2_naming_the_port():
    n = 52
    port = wire.ports(n).zenoh
    blocker = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    blocker.bind((wire.LOOPBACK, port))
    blocker.listen(1)
    try:
        with SimProcess(n) as sim:
            assert sim.proc.wait(8.0) == 2
            sim._thread.join(2.0)
            assert f"zenoh port {port}" in sim.output and "--instance 52" in sim.output
    finally:
        blocker.close()
