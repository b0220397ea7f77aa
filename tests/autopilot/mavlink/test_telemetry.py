"""Telemetry streams are honest: every message a client asks for (SET_MESSAGE_INTERVAL,
REQUEST_MESSAGE) is served at the rate granted or refused, never accepted and left silent. The
whole stack in-process, in simulation time: the ground truth (HIL_STATE_QUATERNION) and the
sensors (HIGHRES_IMU) on request, on the truth and on the EKF."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as m

from autopilot.mavlink import telemetry
from autopilot.mavlink.links import API_LINK, GCS_LINK
from quadcommon import frames
from quadcommon.bus_records import TRUTH_FIELDS
from quadcommon.rigid_body import quaternion_from_euler
from tests.sitl.test_params_failsafes import take_off
from tests.stack import Gcs, make_stack, sequence_gaps

pytestmark = pytest.mark.timeout(120)

REFUSED = (m.MAV_RESULT_DENIED, m.MAV_RESULT_UNSUPPORTED)
_T = {name: i for i, name in enumerate(TRUTH_FIELDS)}


def count_for(gcs: Gcs, seconds: float) -> dict[int, list]:
    """Every message the vehicle sends the station over ``seconds`` of simulation, by id."""
    got: dict[int, list] = {}
    end = gcs.sim_time + seconds
    while gcs.sim_time < end:
        msg = gcs.poll()
        if msg is not None:
            got.setdefault(msg.get_msgId(), []).append(msg)
    return got


def request(gcs: Gcs, msg_id: int):
    """REQUEST_MESSAGE; (the ACK's result, the message that came right after the ACK or None)."""
    ack = gcs.command(m.MAV_CMD_REQUEST_MESSAGE, msg_id)
    inbox = gcs.conn.station.inbox
    after = inbox[0] if inbox else None
    return ack.result, after


def test_every_message_a_client_can_request_is_served_at_its_rate_or_refused():
    """Table-driven over every message of the dialect (and one outside it): SET_MESSAGE_INTERVAL at
    10 Hz, then 2 s counted: a granted stream arrives 20 times (+-1), a refused one is DENIED or
    UNSUPPORTED; REQUEST_MESSAGE: granted, the message follows its ACK; refused, nothing does. On
    the truth, flying (a reference, a battery report): ESTIMATOR_STATUS alone is refused of the
    streams (no estimator)."""
    stack = make_stack()
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    take_off(gcs)
    ids = sorted(m.mavlink_map) + [99_999]
    granted, refused = set(), {}
    for msg_id in ids:
        result = gcs.command(m.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 100_000).result
        if result == m.MAV_RESULT_ACCEPTED:
            granted.add(msg_id)
        else:
            assert result in REFUSED, (msg_id, result)
            refused[msg_id] = result
    assert granted == set(telemetry.STREAMS) - {m.MAVLINK_MSG_ID_ESTIMATOR_STATUS}
    got = count_for(gcs, 2.0)
    # (sent only while orbiting: granted, and nothing comes while the vehicle holds)
    orbiting = {i for i in granted if telemetry.STREAMS[i].needs == telemetry.ORBITING}
    rates = {m.mavlink_map[i].msgname: len(got.get(i, [])) for i in granted - orbiting}
    assert all(abs(n - 20) <= 1 for n in rates.values()), rates
    assert orbiting and not any(i in got for i in orbiting)
    assert m.MAVLINK_MSG_ID_ESTIMATOR_STATUS not in got  # refused: nothing comes

    answered = {}
    for msg_id in ids:
        result, after = request(gcs, msg_id)
        answered[msg_id] = result
        if result == m.MAV_RESULT_ACCEPTED:
            assert after is not None and after.get_msgId() == msg_id, (msg_id, after)
        else:
            assert result in REFUSED, (msg_id, result)
            assert after is None or after.get_msgId() != msg_id, msg_id
    served = {i for i, result in answered.items() if result == m.MAV_RESULT_ACCEPTED}
    assert served == (granted - orbiting) | {m.MAVLINK_MSG_ID_AUTOPILOT_VERSION}
    assert all(answered[i] == m.MAV_RESULT_DENIED for i in orbiting)  # nothing to report while holding
    assert answered[m.MAVLINK_MSG_ID_ESTIMATOR_STATUS] == m.MAV_RESULT_DENIED
    assert answered[99_999] == m.MAV_RESULT_UNSUPPORTED
    assert not stack.autopilot.faults.counts


def test_a_stream_faster_than_the_frames_is_granted_at_the_frame_rate_and_says_so():
    stack = make_stack()
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    attitude = m.MAVLINK_MSG_ID_ATTITUDE
    ack = gcs.command(m.MAV_CMD_SET_MESSAGE_INTERVAL, attitude, 100)  # 10 kHz
    assert ack.result == m.MAV_RESULT_ACCEPTED
    gcs.command(m.MAV_CMD_GET_MESSAGE_INTERVAL, attitude)
    gcs.wait(lambda g: "MESSAGE_INTERVAL" in g.last, sim_timeout=0.1, what="MESSAGE_INTERVAL")
    granted = gcs.last["MESSAGE_INTERVAL"]
    assert (granted.message_id, granted.interval_us) == (attitude, 2000)  # one a control frame (500 Hz)
    assert abs(len(count_for(gcs, 1.0).get(attitude, [])) - 500) <= 1
    assert gcs.command(m.MAV_CMD_SET_MESSAGE_INTERVAL, attitude, -1).result == m.MAV_RESULT_ACCEPTED
    gcs.command(m.MAV_CMD_GET_MESSAGE_INTERVAL, attitude)
    gcs.wait(lambda g: g.last["MESSAGE_INTERVAL"].interval_us == -1, sim_timeout=0.1, what="off")
    assert attitude not in count_for(gcs, 0.2)
    for msg_id in (m.MAVLINK_MSG_ID_MISSION_ITEM_INT, m.MAVLINK_MSG_ID_ESTIMATOR_STATUS):  # on the truth
        gcs.command(m.MAV_CMD_GET_MESSAGE_INTERVAL, msg_id)
        gcs.wait(lambda g: g.last["MESSAGE_INTERVAL"].message_id == msg_id, sim_timeout=0.1, what="answer")  # noqa: B023
        assert gcs.last["MESSAGE_INTERVAL"].interval_us == 0  # not available


def truth_at(stack, time_usec: int) -> np.ndarray:
    rows = np.asarray(stack.truth_rows)
    k = int(np.argmin(np.abs(rows[:, 0] - time_usec * 1e-6)))
    assert abs(rows[k, 0] - time_usec * 1e-6) < 1e-9
    return rows[k]


def test_ground_truth_on_request_is_the_simulators_at_its_granted_rate_on_the_ekf():
    """HIL_STATE_QUATERNION as PX4 SITL serves it (MAVSDK's Telemetry.ground_truth): on a vehicle
    flying on its EKF over GPS it is the simulator's truth, not the estimate: lat/lon/alt within
    the message's quantisation (1e-7 deg, 1 mm) of the truth's, the attitude the truth's."""
    stack = make_stack(estimator="ekf", sensors="gps")
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    gcs.wait(lambda g: stack.autopilot.commander.estimator_problem is None, sim_timeout=20, what="the EKF")
    take_off(gcs)
    rates = {m.MAVLINK_MSG_ID_HIL_STATE_QUATERNION: 40_000, m.MAVLINK_MSG_ID_HIGHRES_IMU: 20_000,
             m.MAVLINK_MSG_ID_ESTIMATOR_STATUS: 100_000}  # fmt: skip
    for msg_id, interval_us in rates.items():
        assert gcs.command(m.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, interval_us).result == 0
    got = count_for(gcs, 2.0)
    truths = got[m.MAVLINK_MSG_ID_HIL_STATE_QUATERNION]
    assert abs(len(truths) - 50) <= 1  # 25 Hz
    assert abs(len(got[m.MAVLINK_MSG_ID_HIGHRES_IMU]) - 100) <= 1  # 50 Hz
    assert abs(len(got[m.MAVLINK_MSG_ID_ESTIMATOR_STATUS]) - 20) <= 1  # 10 Hz, on the EKF
    home = stack.autopilot.setup.sitl.home
    estimates = np.asarray(stack.estimator_rows)
    off_estimate = []
    for msg in truths:
        row = truth_at(stack, msg.time_usec)
        position = [row[_T[n]] for n in ("x_m", "y_m", "z_m")]
        lat, lon, alt = frames.ned_to_geodetic(*frames.vector_to_ned(position), home)
        assert abs(msg.lat - lat * 1e7) <= 1 and abs(msg.lon - lon * 1e7) <= 1  # 1e-7 deg
        assert abs(msg.alt - alt * 1e3) <= 1  # mm
        euler = [row[_T[n]] for n in ("phi_rad", "theta_rad", "psi_rad")]
        q = frames.quaternion_to_ned(quaternion_from_euler(*euler))
        assert np.allclose(msg.attitude_quaternion, q, atol=1e-6)
        estimate = estimates[np.argmin(np.abs(estimates[:, 0] - msg.time_usec * 1e-6)), 1:4]
        off_estimate.append(math.dist(position, estimate))
    assert np.median(off_estimate) > 0.01  # the estimate over GPS is centimetres off: this is the truth
    assert abs(truths[-1].alt * 1e-3 - (home[2] + 2.0)) < 0.1


def test_highres_imu_on_the_truth_is_the_simulators_sensors_at_the_rate_granted():
    """HIGHRES_IMU whatever the vehicle flies on: on the truth (EKF2_EN 0, no filter reading the
    sensors), the frames' HIL_SENSOR (on the default, exact sensors: -g on z at rest, the earth's
    field, the ISA at home)."""
    stack = make_stack()
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    assert gcs.command(m.MAV_CMD_SET_MESSAGE_INTERVAL, m.MAVLINK_MSG_ID_HIGHRES_IMU, 10_000).result == 0
    imus = count_for(gcs, 1.0)[m.MAVLINK_MSG_ID_HIGHRES_IMU]
    assert abs(len(imus) - 100) <= 1
    imu = imus[-1]
    assert imu.fields_updated == 0b1101111111111  # acc, gyro, mag, abs_pressure, pressure_alt, temperature
    assert (imu.xacc, imu.yacc, imu.zacc) == pytest.approx((0.0, 0.0, -9.81), abs=1e-5)
    assert (imu.xgyro, imu.ygyro, imu.zgyro) == pytest.approx((0.0, 0.0, 0.0), abs=1e-9)
    field = stack.sim.sensors.config.earth_field_world_gauss  # paper world (x north, y west, z up)
    assert (imu.xmag, imu.ymag, imu.zmag) == pytest.approx(frames.vector_to_ned(field), abs=1e-6)
    assert imu.pressure_alt == pytest.approx(stack.autopilot.setup.sitl.home[2], abs=1e-3)
    assert imu.diff_pressure == 0.0
    assert [msg.time_usec for msg in imus] == sorted({msg.time_usec for msg in imus})


def test_each_link_numbers_its_frames_on_its_own_so_a_loss_free_link_shows_no_loss():
    """As PX4 numbers each MAVLink channel: a station on the GCS link and one on the API link each
    get gapless sequence numbers, through the wrap past 255, although the vehicle packs most
    messages once for both and answers the API station's commands on the API link alone."""
    stack = make_stack()
    gcs, api = stack.ground_station(GCS_LINK), stack.ground_station(API_LINK)
    system = stack.autopilot.system_id
    for _ in range(5):
        api.command(m.MAV_CMD_REQUEST_MESSAGE, m.MAVLINK_MSG_ID_AUTOPILOT_VERSION)
        api.mav.param_request_read_send(system, 1, b"MIS_TAKEOFF_ALT", -1)
        gcs.command(m.MAV_CMD_SET_MESSAGE_INTERVAL, m.MAVLINK_MSG_ID_ATTITUDE, 20_000)
        stack.run_for(0.6)
    for station in (gcs, api):
        assert len(station.messages) > 300  # the sequence wrapped
        assert sequence_gaps(station.messages) == []
    assert len(api.acks(m.MAV_CMD_REQUEST_MESSAGE)) == 5 and gcs.acks(m.MAV_CMD_REQUEST_MESSAGE) == []
    assert len(gcs.of_type("ATTITUDE")) > len(api.of_type("ATTITUDE"))  # the GCS asked for 50 Hz
