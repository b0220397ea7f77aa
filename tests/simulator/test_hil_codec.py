"""The simulator's MAVLink edge without sockets: frame encoding and actuator decoding."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest
from pymavlink.dialects.v20 import common as mavlink

from autopilot.mavlink.hil import ActuatorEncoder
from quadcommon import frames, wire
from quadcommon.bus_records import TRUTH_FIELDS
from quadcommon.config import load_vehicle
from simulator.dynamics.plant import Plant
from simulator.mavlink.hil import ActuatorDecoder, HilFrameEncoder
from simulator.sensors import EXACT, SensorSuite
from simulator.truth_bus import truth_row

HOME = (47.397742, 8.545594, 488.0)


def make_truth(position=(3.0, -4.0, 5.0), euler=(0.2, 0.1, -1.0), velocity=(2.0, 1.0, -0.5)):
    plant = Plant(load_vehicle("paper_quad"), 0.001)
    plant.reset(position, euler, velocity, (0.5, -0.4, 0.3))
    plant.set_wrench(8.0, (0.0, 0.0, 0.0))
    return plant.truth()


def decode(datagram: bytes) -> dict:
    parser = mavlink.MAVLink(None)
    return {m.get_type(): m for m in parser.parse_buffer(datagram)}


def test_one_datagram_carries_the_frame_with_one_time_and_rising_sequence_numbers():
    encoder = HilFrameEncoder(system_id=5, home=HOME)
    truth = make_truth()
    readings = SensorSuite(EXACT, HOME[2]).sample(truth)
    gps = SensorSuite(EXACT, HOME[2]).sample_gps(truth)
    parser = mavlink.MAVLink(None)
    messages = parser.parse_buffer(encoder.encode(123_000, truth, readings, gps=gps))
    assert [m.get_type() for m in messages] == ["HIL_SENSOR", "HIL_STATE_QUATERNION", "ODOMETRY", "HIL_GPS"]
    assert {m.time_usec for m in messages} == {123_000}
    assert [m.get_seq() for m in messages] == [0, 1, 2, 3]
    assert {(m.get_srcSystem(), m.get_srcComponent()) for m in messages} == {(5, wire.SIMULATOR_COMPONENT_ID)}
    again = parser.parse_buffer(encoder.encode(125_000, truth, readings))
    assert [m.get_seq() for m in again] == [4, 5, 6]  # no GPS this time


def test_a_frame_from_the_sensors_delivery_is_the_frame_from_its_readings():
    """What the simulator sends every frame (the delivery read in compiled code, frame_payloads) is
    what payloads makes of the same frame's readings, byte for byte: sensors at their own rates
    (fields_updated), noise, a failure that stops the gyro, GPS fixes."""
    config = replace(EXACT, magnetometer=replace(EXACT.magnetometer, rate_hz=100.0),
                     barometer=replace(EXACT.barometer, rate_hz=50.0))  # fmt: skip
    suites = [SensorSuite(config, HOME[2], imu_rate_hz=500.0) for _ in range(2)]
    for suite in suites:
        suite.inject_failure("gyro", 1, 0.05)  # MAV_CMD_INJECT_FAILURE off from t = 0.05 s
    by_readings, by_delivery = HilFrameEncoder(1, HOME), HilFrameEncoder(1, HOME)
    truth, wind = make_truth(), (1.0, -0.5, 0.25)
    kinds = set()
    for k in range(60):
        t = k / 500.0
        frame = suites[0].step(t, truth)
        delivery = suites[1].deliver(t, truth)
        gps = suites[1].delivered(t).gps
        expected = by_readings.payloads(k * 2000, truth, frame.readings, wind, frame.gps, None, None, None)
        got = by_delivery.frame_payloads(k * 2000, truth, delivery, wind, gps, None, None, None)
        assert got == expected, t
        kinds.add(decode(by_delivery.datagram(got))["HIL_SENSOR"].fields_updated)
    assert len(kinds) >= 3  # fresh, held and failed sensors among the frames


def test_gps_fix_fields():
    truth = make_truth(velocity=(0.0, -3.0, 1.0))  # paper: 3 m/s toward +y... negative: east
    encoder = HilFrameEncoder(system_id=1, home=HOME)
    suite = SensorSuite(EXACT, HOME[2])
    msgs = decode(encoder.encode(0, truth, suite.sample(truth), gps=suite.sample_gps(truth)))
    g = msgs["HIL_GPS"]
    lat, lon, alt = frames.ned_to_geodetic(*frames.vector_to_ned(truth.position_m), HOME)
    assert (g.lat, g.lon, g.alt) == (round(lat * 1e7), round(lon * 1e7), round(alt * 1000))
    vn, ve, vd = frames.vector_to_ned(truth.velocity_m_s)
    assert (g.vn, g.ve, g.vd) == (round(vn * 100), round(ve * 100), round(vd * 100))
    assert ve > 0 and vd < 0  # moving east and climbing, in NED
    assert g.vel == round(100 * math.hypot(vn, ve))
    assert g.cog == round(math.degrees(math.atan2(ve, vn)) * 100) % 36000
    assert (g.fix_type, g.eph, g.epv, g.satellites_visible, g.yaw) == (3, 100, 100, 10, 0)


def test_fields_updated_and_fix_type_follow_the_sensor_rates_and_outages():
    """Between magnetometer/barometer samples their bits are cleared; in an outage HIL_GPS says no fix."""
    config = replace(
        EXACT,
        magnetometer=replace(EXACT.magnetometer, rate_hz=100.0),
        barometer=replace(EXACT.barometer, rate_hz=50.0),
    )
    suite = SensorSuite(config, HOME[2], imu_rate_hz=500.0)
    suite.gps_outage(0.1, 1.0)
    encoder = HilFrameEncoder(1, HOME)
    truth = make_truth()
    updated, fixes = [], []
    for k in range(60):
        frame = suite.step(k / 500.0, truth)
        msgs = decode(encoder.encode(k * 2000, truth, frame.readings, gps=frame.gps))
        updated.append(msgs["HIL_SENSOR"].fields_updated)
        if "HIL_GPS" in msgs:
            fixes.append(msgs["HIL_GPS"].fix_type)
    assert updated[0] == 0x1FFF  # every sensor sampled at t = 0
    assert updated[1] == 0x1FFF & ~0x1C0 & ~0x1A00  # IMU and differential pressure only
    assert updated[5] == 0x1FFF & ~0x1A00  # magnetometer (100 Hz) fresh, barometer (50 Hz) held
    assert updated[10] == 0x1FFF
    assert fixes == [3, 1]  # t = 0 valid; t = 0.1 in the outage


def test_wild_state_is_clamped_not_crashing():
    truth = make_truth()._replace(
        velocity_m_s=(1e4, -1e4, 5e3),
        specific_force_body_m_s2=(1e5, 0.0, -1e5),
    )
    suite = SensorSuite(EXACT, HOME[2])
    msgs = decode(HilFrameEncoder(1, HOME).encode(0, truth, suite.sample(truth), gps=suite.sample_gps(truth)))
    h = msgs["HIL_STATE_QUATERNION"]
    assert (h.vx, h.vy, h.vz) == (32767, 32767, -32767)
    assert (h.xacc, h.zacc) == (32767, 32767)
    assert h.true_airspeed == 65534
    assert msgs["HIL_GPS"].vel == 65534


def test_airspeed_is_relative_to_the_wind():
    truth = make_truth(velocity=(2.0, 0.0, 0.0))
    suite = SensorSuite(EXACT, HOME[2])
    wind = (-1.0, 0.0, 0.0)
    h = decode(HilFrameEncoder(1, HOME).encode(0, truth, suite.sample(truth), wind_world_m_s=wind))
    v = truth.velocity_m_s
    assert h["HIL_STATE_QUATERNION"].true_airspeed == round(100 * math.dist(v, (-1.0, 0.0, 0.0)))


def controls_message(time_usec, controls, mode, flags) -> bytes:
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    msg = mavlink.MAVLink_hil_actuator_controls_message(time_usec, [*controls, *[0.0] * 12], mode, flags)
    return msg.pack(mav)


@pytest.mark.parametrize(
    ("mode", "flags", "armed", "lockstep", "wrench"),
    [(128 | 1, 3, True, True, True), (1, 1, False, True, False), (128, 0, True, False, False)],
)
def test_actuator_decoder_reads_armed_bit_and_flags(mode, flags, armed, lockstep, wrench):
    answer = ActuatorDecoder().decode(controls_message(42, (0.5, -0.25, 0.125, 1.0), mode, flags))
    assert answer is not None
    assert answer.time_usec == 42
    assert answer.controls == (0.5, -0.25, 0.125, 1.0)
    assert (answer.armed, answer.lockstep, answer.wrench) == (armed, lockstep, wrench)


def test_actuator_decoder_ignores_other_messages_and_garbage():
    decoder = ActuatorDecoder()
    mav = mavlink.MAVLink(None, srcSystem=1, srcComponent=1)
    heartbeat = mavlink.MAVLink_heartbeat_message(2, 12, 0, 0, 3, 3).pack(mav)
    assert decoder.decode(heartbeat) is None
    assert decoder.decode(b"\x00\x01garbage\xfd\xfd") is None
    # and the parser still works afterwards
    assert decoder.decode(controls_message(7, (0.1, 0, 0, 0), 128, 3)).time_usec == 7


@pytest.mark.parametrize("armed", [True, False])
@pytest.mark.parametrize("requests", [0, 2])
def test_an_answer_handed_over_unframed_reads_as_its_datagram(armed, requests):
    """The autopilot's answer as the in-process runner hands it over (the controls' payload, the
    requests after it) decodes to what its datagram decodes to, float32 rounding included."""
    from autopilot.mavlink.codec import Encoder
    from autopilot.mavlink.simulator_link import SimulatorLink

    encoder = Encoder(1, wire.AUTOPILOT_COMPONENT_ID)
    actuators = ActuatorEncoder(encoder, wrench=True)
    link = SimulatorLink(encoder, 1, HOME)
    for _ in range(requests):
        link.request_failure(1, 1, 0, 0.0)
    controls = (0.1 + 1e-9, -1.0 / 3.0, math.pi / 10.0, 2.0 / 7.0)  # none exact in float32
    answer = link.answer(actuators.payload(123_456, controls, armed), actuators.frame)
    decoder = ActuatorDecoder()
    unframed = decoder.decode_unframed(answer)
    assert unframed == decoder.decode(answer.datagram)
    assert unframed.armed == armed and len(unframed.others) == requests
    assert unframed.controls != controls if armed else unframed.controls == (0.0,) * 4  # float32 on the way


def test_truth_row_follows_the_field_layout():
    truth = make_truth()
    health = (1.0, 0.7, 1.0, 0.0, 0.0, 4.0, 0.0, 1.0)  # rotor 2 at 70 %, rotor 4 off
    row = truth_row(1.5, truth, (1.0, 2.0, 3.0), (0.1, 0.2, 0.3), (4.0, 5.0, 6.0), health)
    assert len(row) == len(TRUTH_FIELDS)
    named = dict(zip(TRUTH_FIELDS, row, strict=True))
    assert named["time_s"] == 1.5
    assert (named["x_m"], named["y_m"], named["z_m"]) == truth.position_m
    assert (named["qw"], named["qx"], named["qy"], named["qz"]) == truth.quaternion
    assert (named["p_rad_s"], named["q_rad_s"], named["r_rad_s"]) == truth.body_rates_rad_s
    assert (named["Ax_n"], named["Ay_n"], named["Az_n"]) == (1.0, 2.0, 3.0)
    assert (named["Ap_n_m"], named["Aq_n_m"], named["Ar_n_m"]) == (0.1, 0.2, 0.3)
    assert (named["wind_x_m_s"], named["wind_y_m_s"], named["wind_z_m_s"]) == (4.0, 5.0, 6.0)
    assert named["thrust_n"] == truth.thrust_n == 8.0
    assert [named[f"rotor{n}_effectiveness"] for n in (1, 2, 3, 4)] == [1.0, 0.7, 1.0, 0.0]
    assert [named[f"rotor{n}_failure"] for n in (1, 2, 3, 4)] == [0.0, 4.0, 0.0, 1.0]
    assert named["on_ground"] == 0.0
