"""The simulator's core in simulation time: frames, lockstep, actuation checks, the emergency
descent and gust swaps, driven frame by frame without sockets (the process is tested in
test_sim_process.py)."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as mavlink

from quadcommon import frames, wire
from quadcommon.config import apply_uncertainty, load_scenario, load_sitl, load_vehicle
from simulator.core import PlantDiverged, SimulatorCore, SimulatorSetup
from simulator.dynamics.plant import make_plant
from simulator.environment.gust_profile import DisturbanceSchedule, GustProfile, Step, load_gust_profile
from simulator.sensors import isa_pressure_hpa

from .sim_harness import airborne_scenario

pytestmark = pytest.mark.timeout(60)
RATES = load_sitl().rates
FRAME_USEC = round(1e6 / RATES.control_hz)
HOME = load_sitl().home
_mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)


def answer(time_usec, controls=(0.0, 0.0, 0.0, 0.0), armed=False, wrench=True, lockstep=True) -> bytes:
    """HIL_ACTUATOR_CONTROLS as an autopilot packs it (pymavlink)."""
    mode = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED | (mavlink.MAV_MODE_FLAG_SAFETY_ARMED if armed else 0)
    flags = (wire.HIL_FLAG_LOCKSTEP if lockstep else 0) | (wire.HIL_FLAG_WRENCH if wrench else 0)
    msg = mavlink.MAVLink_hil_actuator_controls_message(time_usec, [*controls, *[0.0] * 12], mode, flags)
    return bytes(msg.pack(_mav))


def parse(datagram: bytes) -> dict:
    parser = mavlink.MAVLink(None)
    return {m.get_type(): m for m in parser.parse_buffer(datagram)}


def core_for(scenario: str = "hover", **setup) -> SimulatorCore:
    base = SimulatorSetup.load(scenario=scenario)
    for key, value in setup.items():
        base = base.__class__(**{**base.__dict__, key: value})
    return SimulatorCore(base)


def fly(core: SimulatorCore, frames_: int, **answer_kw) -> dict:
    """Answer ``frames_`` frames with the same controls; the last frame's messages."""
    frame = {}
    for _ in range(frames_):
        frame = parse(core.begin_frame())
        core.end_frame(core.answer_to_frame(answer(core.time_usec, **answer_kw)))
    return frame


def quaternion_yaw_pitch_roll(q):
    """ZYX Euler angles of a (w, x, y, z) quaternion, written out independently of the project."""
    w, x, y, z = q
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw


def check_frame_against_truth(frame, truth):
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


def test_frames_match_a_plant_stepped_by_hand(tmp_path):
    """Decoded frames equal the truth of the same plant stepped by hand (gusts at every physics
    step, zero-order hold of the controls), in the wire's frames and units."""
    scenario_path = airborne_scenario(tmp_path)
    scenario = load_scenario(scenario_path)
    dt_control = 1.0 / RATES.control_hz
    substeps = RATES.physics_steps_per_control
    dt_physics = dt_control / substeps
    plant = make_plant(apply_uncertainty(load_vehicle("paper_quad"), scenario), dt_physics)
    plant.reset(scenario.initial_position_m, scenario.initial_euler_rad)
    schedule = DisturbanceSchedule(load_gust_profile(scenario.gusts))
    controls = (0.3, 0.02, -0.03, 0.01)
    core = SimulatorCore(SimulatorSetup.load(scenario=str(scenario_path)))
    for k in range(40):
        frame = parse(core.begin_frame())
        if k == 0:
            # Sign conventions, checked without the project's helpers: paper yaw +0.7 (CCW from
            # above, z up) is NED yaw -0.7; paper pitch -0.2 (about y-left) is NED pitch +0.2.
            roll, pitch, yaw = quaternion_yaw_pitch_roll(frame["ODOMETRY"].q)
            assert (roll, pitch, yaw) == pytest.approx((0.1, 0.2, -0.7), abs=1e-6)
            assert (frame["ODOMETRY"].y, frame["ODOMETRY"].z) == pytest.approx((2.0, -3.0), abs=1e-6)
            gps = frame["HIL_GPS"]
            assert (gps.fix_type, gps.satellites_visible, gps.eph, gps.epv) == (3, 10, 100, 100)
        assert frame["HIL_SENSOR"].time_usec == k * FRAME_USEC
        check_frame_against_truth(frame, plant.truth())
        assert ("HIL_GPS" in frame) == (k % round(RATES.control_hz / RATES.gps_hz) == 0)
        t = k * dt_control
        plant.set_actuator_controls(controls)
        for j in range(substeps):
            plant.set_disturbance(*schedule.evaluate(t + j * dt_physics))
            plant.step()
        core.end_frame(core.answer_to_frame(answer(core.time_usec, controls, armed=True)))


def test_only_the_answer_to_the_current_frame_counts():
    core = core_for()
    core.begin_frame()
    assert core.time_usec == 0
    assert core.answer_to_frame(answer(FRAME_USEC)) is None  # a future answer
    assert core.answer_to_frame(b"hello") is None  # garbage
    hb = mavlink.MAVLink_heartbeat_message(2, 12, 0, 0, 0, 3).pack(_mav)
    assert core.answer_to_frame(bytes(hb)) is None
    good = core.answer_to_frame(answer(0, armed=True))
    assert good is not None and good.armed and good.lockstep and good.wrench
    core.end_frame(good)
    core.begin_frame()
    assert core.time_usec == FRAME_USEC
    assert core.answer_to_frame(answer(0)) is None  # a late answer to the previous frame


def test_actuation_mismatch_is_refused_with_motors_off():
    """paper_quad flies a wrench; rotor-speed controls (flags bit 1 clear) are refused, once said."""
    core = core_for()
    frame = fly(core, 100, controls=(1.0, 0.0, 0.0, 0.0), armed=True, wrench=False)
    assert frame["ODOMETRY"].z == 0.0  # full "thrust" refused: still on the ground
    assert len(core.warnings) == 1 and "rotors" in core.warnings[0] and "wrench" in core.warnings[0]
    frame = fly(core, 50, controls=(1.0, 0.0, 0.0, 0.0), armed=True, wrench=True)
    frame = parse(core.begin_frame())
    assert frame["ODOMETRY"].z < -0.01  # NED: up is negative; the refusal was what held it down


def test_non_finite_controls_are_motors_off():
    core = core_for()
    fly(core, 50, controls=(math.nan, 0.0, 0.0, 0.0), armed=True)
    assert parse(core.begin_frame())["ODOMETRY"].z == 0.0
    assert any("non-finite" in w for w in core.warnings)


def test_disarmed_vehicle_rests_cleanly_on_the_ground():
    core = core_for()
    for _ in range(250):  # half a second of "full thrust" while disarmed
        frame = fly(core, 1, controls=(1.0, 0.5, 0.5, 0.5), armed=False)
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


def test_autopilot_lost_in_the_air_lands_the_vehicle_then_lockstep_resumes(tmp_path):
    scenario = tmp_path / "aloft.toml"
    scenario.write_text(
        'name = "aloft"\nduration_s = 5.0\n[trajectory]\nkind = "hover"\nposition_m = [1.0, -2.0, 3.0]\n'
        "[initial_state]\nposition_m = [1.0, -2.0, 3.0]\neuler_rad = [0.05, -0.05, 0.7]\n"
    )
    core = SimulatorCore(SimulatorSetup.load(scenario=str(scenario)))
    hover = (0.74 * 9.81 / 28.0, 0.0, 0.0, 0.0)
    fly(core, 10, controls=hover, armed=True)  # armed in the air, slightly tilted
    core.begin_frame()
    core.autopilot_lost()
    assert core.emergency and not core.emergency_landed
    for _ in range(int(12.0 * RATES.control_hz)):  # 3 m at 0.5 m/s, with margin
        core.end_frame(None)
        core.begin_frame()
        if core.emergency_landed:
            break
    assert core.emergency_landed, "no touchdown within 12 s"
    truth = core.plant.truth()
    assert truth.position_m[2] < 0.03 and abs(truth.euler_rad[0]) < 0.05 and abs(truth.euler_rad[1]) < 0.05
    assert math.dist(truth.position_m[:2], (1.0, -2.0)) < 1.0  # came down near where it was lost
    assert not core.answers_again(answer(core._lost_usec - FRAME_USEC))  # an answer from before
    assert core.answers_again(answer(core._lost_usec))
    assert not core.emergency
    core.end_frame(None)  # this frame still under our own law; lockstep from the next one
    core.begin_frame()
    assert core.answer_to_frame(answer(core.time_usec)) is not None


def test_autopilot_lost_while_disarmed_keeps_the_motors_off():
    core = core_for()
    fly(core, 5)
    core.begin_frame()
    core.autopilot_lost()
    assert core.emergency_landed
    for _ in range(50):
        core.end_frame(None)
        assert parse(core.begin_frame())["ODOMETRY"].z == 0.0


def test_uploaded_profile_replaces_the_schedule_from_the_next_frame():
    core = core_for()
    upload = GustProfile("test", (Step("force_y", 0.0, 3.0), Step("torque_yaw", 0.004, -0.5)))
    fly(core, 5, controls=(0.5, 0.0, 0.0, 0.0), armed=True)
    core.begin_frame()  # frame 5 is out: the swap lands at frame 6
    core.schedule_gust_profile(upload, 6 * core.dt_control)
    assert core.schedule.profile != upload
    core.end_frame(core.answer_to_frame(answer(core.time_usec, (0.5, 0.0, 0.0, 0.0), armed=True)))
    core.begin_frame()
    assert core.schedule.profile == upload
    assert core.truth_row[1:4] != ()  # the frame's truth row carries the new disturbance
    force = core.schedule.evaluate(core.t + 0.01)[0]
    assert force == (0.0, 3.0, 0.0)


def test_a_diverged_plant_is_reported_not_encoded():
    core = core_for()
    core.plant.state[0] = math.inf
    with pytest.raises(PlantDiverged, match="not finite at t=0.000 s"):
        core.begin_frame()


def test_a_state_past_float32_is_reported_not_raised_from_the_encoder():
    """Finite but beyond what HIL's float32 fields carry (a tumble through the Euler torque
    disturbance's gimbal lock gets there): the simulator stops with a reason, not a traceback."""
    core = core_for()
    core.plant.state[3] = 1e39  # a velocity
    assert math.isfinite(core.plant.truth().velocity_m_s[0])
    with pytest.raises(PlantDiverged, match="no longer fits the wire's float32 at t=0.000 s"):
        core.begin_frame()


def test_wind_on_a_drag_free_vehicle_is_warned():
    core = core_for()
    profile = load_gust_profile("gust_1cos_x")
    assert "zero drag" in core.wind_warning(profile)
    assert core_for(vehicle=load_vehicle("paper_quad_drag")).wind_warning(profile) is None
