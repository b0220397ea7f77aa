"""The autopilot's MAVLink edge: setpoint decoding (PX4 type_mask), telemetry, HIL frames."""

import math

import pytest

from autopilot.mavlink import telemetry
from autopilot.mavlink.codec import Encoder, mavlink, new_parser
from autopilot.mavlink.hil import ActuatorEncoder, CorruptFrame, frame_of
from autopilot.mavlink.offboard import decode_setpoint
from autopilot.records import StateEstimate
from quadcommon import frames
from quadcommon.mavlink_fast import MessageParts
from quadcommon.rigid_body import quaternion_from_euler

m = mavlink
HOME = (47.397742, 8.545594, 488.0)


def decode(datagram: bytes, home, use_odometry: bool = True):
    """The lockstep frame in a datagram, as the autopilot reads it off its HIL socket."""
    return frame_of(MessageParts.of_datagram(datagram), home, use_odometry)


def setpoint(
    mask,
    frame=m.MAV_FRAME_LOCAL_NED,
    pos=(1.0, 2.0, -3.0),
    vel=(0.1, 0.2, -0.3),
    acc=(0.0, 0.0, 0.0),
    yaw=0.5,
    yaw_rate=0.0,
):
    return m.MAVLink_set_position_target_local_ned_message(
        0, 1, 1, frame, mask, *pos, *vel, *acc, yaw, yaw_rate
    )


def test_position_only_setpoint_in_local_ned():
    mask = 8 | 16 | 32 | 64 | 128 | 256 | 2048
    sp, reason = decode_setpoint(setpoint(mask), 1.0, (0.0, 0.0, 0.0), 0.0, (0.0, 0.0, 0.0))
    assert reason == ""
    assert sp.position == (1.0, -2.0, 3.0)  # NED -> paper: y and z flip
    assert sp.velocity is None and sp.acceleration is None
    assert sp.yaw == pytest.approx(-0.5)
    assert sp.time_s == 1.0


def test_position_velocity_acceleration_feedforward():
    sp, _ = decode_setpoint(setpoint(1024 | 2048, acc=(0.5, 0.0, 1.0)), 0.0, (0, 0, 0), 0.0, (0, 0, 0))
    assert sp.position == (1.0, -2.0, 3.0)
    assert sp.velocity == pytest.approx((0.1, -0.2, 0.3))
    assert sp.acceleration == pytest.approx((0.5, 0.0, -1.0))
    assert sp.yaw is None and sp.yaw_rate is None


def test_body_frame_velocity_is_rotated_by_yaw():
    mask = 1 | 2 | 4 | 64 | 128 | 256 | 1024 | 2048
    # vehicle heading 90 deg to the left in the paper frame (psi = +pi/2 -> NED yaw -pi/2)
    sp, _ = decode_setpoint(
        setpoint(mask, m.MAV_FRAME_BODY_NED, vel=(1.0, 0.0, 0.0)), 0.0, (0, 0, 0), math.pi / 2, (0, 0, 0)
    )
    assert sp.velocity == pytest.approx((0.0, 1.0, 0.0), abs=1e-12)  # forward = world +y (left)


def test_offset_frame_adds_to_current_position():
    mask = 8 | 16 | 32 | 64 | 128 | 256 | 1024 | 2048
    sp, _ = decode_setpoint(
        setpoint(mask, m.MAV_FRAME_LOCAL_OFFSET_NED, pos=(1.0, 0.0, -1.0)),
        0.0,
        (5.0, 5.0, 2.0),
        0.0,
        (5.0, 5.0, 2.0),
    )
    assert sp.position == pytest.approx((6.0, 5.0, 3.0))


@pytest.mark.parametrize(
    "frame, mask, reason",
    [
        (m.MAV_FRAME_GLOBAL, 0, "coordinate_frame"),
        (m.MAV_FRAME_LOCAL_NED, 512, "force"),
        (m.MAV_FRAME_LOCAL_NED, 0xFFF & ~512, "ignores everything"),
    ],
)
def test_refused_setpoints_say_why(frame, mask, reason):
    sp, why = decode_setpoint(setpoint(mask, frame), 0.0, (0, 0, 0), 0.0, (0, 0, 0))
    assert sp is None and reason in why


def status_in_flight():
    s = telemetry.VehicleStatus(system_id=3, home_geodetic=HOME)
    s.time_usec = 12_345_678
    s.state = StateEstimate((1.0, 2.0, 3.0), (0.5, -0.5, 0.2), (0.1, -0.2, 0.3), (0.0, 0.0, 0.0))
    s.armed = True
    s.custom_mode = (4 << 16) | (3 << 24)
    return s


def roundtrip(msg):
    enc = Encoder(3, 1)
    return new_parser().parse_buffer(enc.pack(msg))[0]


def test_local_position_and_attitude_are_ned():
    s = status_in_flight()
    lp = roundtrip(telemetry.build(m.MAVLINK_MSG_ID_LOCAL_POSITION_NED, s))
    assert (lp.x, lp.y, lp.z) == pytest.approx((1.0, -2.0, -3.0))
    assert (lp.vx, lp.vy, lp.vz) == pytest.approx((0.5, 0.5, -0.2))
    assert lp.time_boot_ms == 12345
    att = roundtrip(telemetry.build(m.MAVLINK_MSG_ID_ATTITUDE, s))
    assert (att.roll, att.pitch, att.yaw) == pytest.approx((0.1, 0.2, -0.3))


def test_heartbeat_is_px4_with_armed_flag():
    hb = roundtrip(telemetry.build(m.MAVLINK_MSG_ID_HEARTBEAT, status_in_flight()))
    assert hb.autopilot == m.MAV_AUTOPILOT_PX4 and hb.type == m.MAV_TYPE_QUADROTOR
    assert hb.base_mode & m.MAV_MODE_FLAG_SAFETY_ARMED and hb.base_mode & m.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
    assert hb.custom_mode == (4 << 16) | (3 << 24)
    assert hb.get_srcSystem() == 3


def test_global_position_from_local_and_home():
    gp = roundtrip(telemetry.build(m.MAVLINK_MSG_ID_GLOBAL_POSITION_INT, status_in_flight()))
    lat, lon, alt = frames.ned_to_geodetic(1.0, -2.0, -3.0, HOME)
    assert gp.lat == round(lat * 1e7) and gp.lon == round(lon * 1e7)
    assert gp.alt == round(alt * 1000) and gp.relative_alt == 3000
    assert gp.hdg == round(math.degrees(-0.3) * 100) % 36000


def test_stream_table_default_and_interval_changes():
    table = telemetry.StreamTable()
    assert m.MAVLINK_MSG_ID_HEARTBEAT in table.due(0.0)
    assert m.MAVLINK_MSG_ID_HEARTBEAT not in table.due(0.5)
    assert m.MAVLINK_MSG_ID_HEARTBEAT in table.due(1.0)
    assert table.set_interval_us(m.MAVLINK_MSG_ID_LOCAL_POSITION_NED, 10_000, 1.0)
    due = [
        t for t in (1.0 + k * 0.002 for k in range(51)) if m.MAVLINK_MSG_ID_LOCAL_POSITION_NED in table.due(t)
    ]
    assert len(due) == 11  # 100 Hz over 0.1 s, both ends included
    assert table.set_interval_us(m.MAVLINK_MSG_ID_ATTITUDE, -1, 1.0)
    assert m.MAVLINK_MSG_ID_ATTITUDE not in table.interval_s
    assert not table.set_interval_us(99999, 1000, 1.0)


def test_hil_frame_decoding_prefers_odometry():
    enc = Encoder(1, 51)
    q_ned = frames.quaternion_to_ned(quaternion_from_euler(0.1, 0.2, 0.3))
    odo = m.MAVLink_odometry_message(
        5_000_000,
        m.MAV_FRAME_LOCAL_NED,
        m.MAV_FRAME_LOCAL_NED,
        1.234567,
        -2.0,
        -3.0,
        list(q_ned),
        0.1,
        0.2,
        0.3,
        0.0,
        0.0,
        0.0,
        [math.nan] * 21,
        [math.nan] * 21,
        0,
        m.MAV_ESTIMATOR_TYPE_MOCAP,
        100,
    )
    hb = m.MAVLink_heartbeat_message(1, 12, 0, 0, 0, 3)
    data = enc.pack(hb) + enc.pack(odo)
    frame = decode(data, HOME)
    assert frame.time_usec == 5_000_000
    assert frame.state.position_m == pytest.approx((1.234567, 2.0, 3.0), abs=1e-6)
    assert frame.state.velocity_m_s == pytest.approx((0.1, -0.2, -0.3), abs=1e-7)
    assert frame.state.euler_rad == pytest.approx((0.1, 0.2, 0.3), abs=1e-6)


def test_actuator_answer_carries_time_flags_and_armed_bit():
    enc = ActuatorEncoder(Encoder(1, 1), wrench=True)
    msg = new_parser().parse_buffer(enc.encode(42_000, (0.3, 0.1, -0.1, 0.0), armed=True))[0]
    assert msg.time_usec == 42_000 and msg.flags == 3
    assert msg.mode & m.MAV_MODE_FLAG_SAFETY_ARMED
    assert list(msg.controls[:4]) == pytest.approx([0.3, 0.1, -0.1, 0.0])
    off = new_parser().parse_buffer(enc.encode(44_000, (0.3, 0.1, -0.1, 0.0), armed=False))[0]
    assert not off.mode & m.MAV_MODE_FLAG_SAFETY_ARMED and max(off.controls) == 0.0


def test_hil_state_quaternion_source_and_corruption():
    enc = Encoder(1, 51)
    q_ned = frames.quaternion_to_ned(quaternion_from_euler(0.0, 0.0, 0.5))
    lat, lon, alt = frames.ned_to_geodetic(1.0, 2.0, -3.0, HOME)
    hsq = m.MAVLink_hil_state_quaternion_message(
        7_000,
        list(q_ned),
        0.0,
        0.0,
        0.0,
        round(lat * 1e7),
        round(lon * 1e7),
        round(alt * 1000),
        10,
        -20,
        30,
        0,
        0,
        0,
        0,
        1000,
    )
    frame = decode(enc.pack(hsq), HOME, use_odometry=True)
    assert frame.time_usec == 7_000
    # quantised: 1e-7 deg of latitude is ~1.1 cm
    assert frame.state.position_m == pytest.approx((1.0, -2.0, 3.0), abs=0.01)
    assert frame.state.velocity_m_s == pytest.approx((0.1, 0.2, -0.3))
    assert frame.state.euler_rad[2] == pytest.approx(0.5, abs=1e-6)
    data = bytearray(enc.pack(hsq))
    data[20] ^= 0xFF  # corrupt the payload: the CRC check refuses it
    with pytest.raises(CorruptFrame):
        decode(bytes(data), HOME)
    assert decode(enc.pack(m.MAVLink_heartbeat_message(1, 12, 0, 0, 0, 3)), HOME) is None


def test_setpoint_sample_time_comes_from_time_boot_ms_on_our_clock():
    def at(time_boot_ms, t):
        msg = m.MAVLink_set_position_target_local_ned_message(time_boot_ms, 1, 1, 1, 0xDF8, 1, 2, -3, 0, 0, 0,
                                                              0, 0, 0, 0, 0)  # fmt: skip
        return decode_setpoint(msg, t, (0, 0, 0), 0.0, (0, 0, 0))[0].time_s

    assert at(9_990, 10.0) == pytest.approx(9.99)  # sampled 10 ms before it arrived
    assert at(123_456_789, 10.0) == 10.0  # another clock (e.g. MAVSDK's uptime): arrival time
    assert at(0, 10.0) == 10.0


def test_odometry_with_a_body_frame_twist_is_rotated_into_the_world():
    """child_frame_id BODY_FRD: vx, vy, vz are in the body (MAVLink); the state is world velocity."""
    enc = Encoder(1, 51)
    q_ned = frames.quaternion_to_ned(quaternion_from_euler(0.0, 0.0, math.pi / 2))  # nose along +y (left)
    odo = m.MAVLink_odometry_message(
        7_000, m.MAV_FRAME_LOCAL_NED, m.MAV_FRAME_BODY_FRD, 0.0, 0.0, -1.0, list(q_ned),
        2.0, 0.0, 0.0, 0.0, 0.0, 0.0, [math.nan] * 21, [math.nan] * 21, 0, m.MAV_ESTIMATOR_TYPE_MOCAP, 100,
    )  # fmt: skip
    frame = decode(enc.pack(odo), HOME)
    assert frame.state.velocity_m_s == pytest.approx((0.0, 2.0, 0.0), abs=1e-6)  # forward = world +y
