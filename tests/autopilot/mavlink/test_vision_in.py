"""External vision in: a client's VISION_POSITION_ESTIMATE and ODOMETRY, read as PX4 reads them,
checked and timed at the edge (autopilot/mavlink/vision_in.py), fused by the EKF through its vision
fusion (EKF2_EV_*). The edge's rules one by one, then the whole stack in-process, in simulation
time: a mocap bridge streaming the ground truth keeps the vehicle's position with the GPS off;
EKF2_EV_CTRL 0 ignores it; hostile vision messages are refused and counted, never fused."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as m

from autopilot.mavlink import vision_in as v
from quadcommon import frames
from quadcommon.rigid_body import euler_from_quaternion, quaternion_from_euler
from tests.sitl.test_params_failsafes import INT32, LOITER, param_set
from tests.stack import Gcs, make_stack

pytestmark = pytest.mark.timeout(120)

NAN = math.nan
UNKNOWN = [NAN] + [0.0] * 20
PARAMS = {"EKF2_EV_CTRL": 11.0, "EKF2_EV_QMIN": 0.0}


def covariance(x: float, y: float, z: float, yaw: float) -> list[float]:
    """A pose covariance (row-major upper triangle of x, y, z, roll, pitch, yaw) with this diagonal."""
    c = [0.0] * 21
    c[0], c[6], c[11], c[15], c[18], c[20] = x, y, z, 0.01, 0.01, yaw
    return c


def vpe(usec=0, xyz=(1.0, 2.0, -3.0), rpy=(0.0, 0.0, 0.5), cov=None):
    return m.MAVLink_vision_position_estimate_message(usec, *xyz, *rpy, UNKNOWN if cov is None else cov, 0)


def odometry(time_usec=0, xyz=(1.0, 2.0, -3.0), yaw=0.5, frame=m.MAV_FRAME_LOCAL_NED,
             estimator=m.MAV_ESTIMATOR_TYPE_VISION, quality=100, q=None, cov=None,
             velocity=(NAN, NAN, NAN)):  # fmt: skip
    q = list(q) if q is not None else [math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2)]  # NED yaw
    pose_cov = UNKNOWN if cov is None else cov
    return m.MAVLink_odometry_message(time_usec, frame, m.MAV_FRAME_BODY_FRD, *xyz, q, *velocity,
                                      0.0, 0.0, 0.0, pose_cov, UNKNOWN, 0, estimator, quality)  # fmt: skip


# -- reading the messages -----------------------------------------------------------------------------
def test_vision_position_estimate_and_odometry_read_as_px4_reads_them():
    stamp, pose = v.read_vision_position_estimate(vpe(123, cov=covariance(0.01, 0.04, 0.09, 0.0004)))
    assert stamp == 123
    assert pose.position_m == pytest.approx((1.0, -2.0, 3.0))  # NED -> x north, y west, z up
    assert pose.yaw_rad == pytest.approx(-0.5)  # NED yaw (clockwise) -> the paper's psi
    assert pose.position_std_m == pytest.approx(0.3)  # the largest of the three
    assert pose.yaw_std_rad == pytest.approx(0.02)
    assert v.read_vision_position_estimate(vpe())[1].position_std_m == 0.0  # NaN first: unknown (the floors)
    for frame in (m.MAV_FRAME_LOCAL_NED, m.MAV_FRAME_LOCAL_FRD):  # FRD read as NED
        stamp, same = v.read_odometry(odometry(456, frame=frame, cov=covariance(0.01, 0.04, 0.09, 0.0004)), 0)
        assert stamp == 456 and same == pose
    # ODOMETRY's q is body FRD -> NED: its ZYX yaw is VISION_POSITION_ESTIMATE's yaw
    q = frames.quaternion_to_ned(quaternion_from_euler(0.1, -0.2, 2.5))
    assert v.read_odometry(odometry(q=q), 0)[1].yaw_rad == pytest.approx(2.5)
    assert euler_from_quaternion(*frames.quaternion_from_ned(q))[2] == pytest.approx(2.5)
    naive = odometry(estimator=m.MAV_ESTIMATOR_TYPE_NAIVE, cov=covariance(1.0, 1.0, 1.0, 1.0))
    assert v.read_odometry(naive, 0)[1].position_std_m == 0.0  # NAIVE: covariance not read (PX4)
    unnormalised = odometry(q=[1.05, 0.0, 0.0, 0.0])
    assert v.read_odometry(unnormalised, 0)[1].yaw_rad == 0.0


@pytest.mark.parametrize(
    "msg, reason",
    [
        (vpe(xyz=(NAN, 0.0, 0.0)), v.NOT_FINITE),
        (vpe(xyz=(0.0, math.inf, 0.0)), v.NOT_FINITE),
        (vpe(rpy=(0.0, NAN, 0.0)), v.NOT_FINITE),
        (vpe(xyz=(3.4e38, 0.0, 0.0)), v.TOO_FAR),
        (vpe(xyz=(3.4e38, 3.4e38, 0.0)), v.TOO_FAR),  # finite, however large
        (vpe(cov=covariance(0.01, NAN, 0.0, 0.0)), v.BAD_VARIANCE),
        (vpe(xyz=(0.0, 0.0, -10_001.0)), v.TOO_FAR),
        (vpe(rpy=(0.0, 0.0, 7.0)), v.BAD_ANGLE),
        (vpe(cov=covariance(-0.01, 0.0, 0.0, 0.0)), v.BAD_VARIANCE),
        (vpe(cov=covariance(0.01, 0.0, 0.0, math.inf)), v.BAD_VARIANCE),
        (odometry(xyz=(0.0, NAN, 0.0)), v.NOT_FINITE),
        (odometry(q=[NAN, 0.0, 0.0, 0.0]), v.NOT_FINITE),
        (odometry(q=[0.0, 0.0, 0.0, 0.0]), v.BAD_QUATERNION),
        (odometry(q=[2.0, 0.0, 0.0, 0.0]), v.BAD_QUATERNION),
        (odometry(frame=m.MAV_FRAME_LOCAL_ENU), v.BAD_FRAME),
        (odometry(frame=m.MAV_FRAME_BODY_FRD), v.BAD_FRAME),
        (odometry(frame=14), v.BAD_FRAME),  # MOCAP_NED, as MAVSDK's Mocap.set_odometry may send
        (odometry(estimator=m.MAV_ESTIMATOR_TYPE_MOCAP), v.MOCAP_ODOMETRY),
        (odometry(estimator=m.MAV_ESTIMATOR_TYPE_GPS), v.OTHER_ESTIMATOR),
        (odometry(estimator=m.MAV_ESTIMATOR_TYPE_AUTOPILOT), v.OTHER_ESTIMATOR),
        (odometry(quality=-1), v.LOW_QUALITY),  # failed, whatever EKF2_EV_QMIN
    ],
)
def test_a_vision_message_outside_its_rules_is_refused_with_its_reason(msg, reason):
    vision = v.ExternalVision()
    assert vision.receive(msg, ("in-process", 1), 10.0, 10.0, True, PARAMS) is None
    assert vision.refused == {reason: 1} and vision.accepted == 0
    assert vision.take_announcements() == [f"vision refused: {reason}"]


def test_quality_below_ekf2_ev_qmin_the_estimator_and_ekf2_ev_ctrl():
    vision = v.ExternalVision()
    sender = ("in-process", 1)
    qmin = PARAMS | {"EKF2_EV_QMIN": 50.0}
    assert vision.receive(odometry(quality=40), sender, 1.0, 1.0, True, qmin) is None
    assert vision.receive(odometry(quality=60), sender, 1.0, 1.0, True, qmin) is not None
    assert vision.receive(vpe(), sender, 2.0, 2.0, False, PARAMS) is None
    assert vision.receive(vpe(), sender, 3.0, 3.0, True, PARAMS | {"EKF2_EV_CTRL": 0.0}) is None
    assert vision.refused == {v.LOW_QUALITY: 1, v.NO_EKF: 1, v.EV_OFF: 1} and vision.accepted == 1
    # A velocity travels with the pose (the filter fuses it when EKF2_EV_CTRL has bit 2)
    moving = odometry(velocity=(1.0, 0.0, 0.0))
    pose = vision.receive(moving, sender, 4.0, 4.0, True, PARAMS | {"EKF2_EV_CTRL": 15.0})
    assert pose is not None and pose.velocity_m_s is not None


def test_odometry_velocity_is_read_in_its_child_frame_as_px4_reads_it():
    """``child_frame_id`` BODY_FRD: rotated by ``q`` into the pose's frame; LOCAL_NED / LOCAL_FRD:
    as the position; then to the paper's frame. NaN: no velocity (the pose alone); absurd speeds
    and bad variances refused; another child frame (BODY_OFFSET_NED here): no velocity, said."""
    yaw = 0.5  # NED yaw: forward points 0.5 rad east of north
    _, pose = v.read_odometry(odometry(yaw=yaw, velocity=(2.0, 0.0, 0.0)), 0)
    assert pose.velocity_m_s == pytest.approx((2.0 * math.cos(yaw), -2.0 * math.sin(yaw), 0.0))
    assert pose.velocity_std_m_s == 0.0  # unknown covariance: the EKF2_EVV_NOISE floor
    local = odometry(yaw=yaw, velocity=(1.0, 2.0, -0.5))
    local.child_frame_id = m.MAV_FRAME_LOCAL_NED
    local.velocity_covariance = covariance(0.01, 0.04, 0.09, 0.0)
    _, pose = v.read_odometry(local, 0)
    assert pose.velocity_m_s == pytest.approx((1.0, -2.0, 0.5))
    assert pose.velocity_std_m_s == pytest.approx(0.3)
    assert v.read_odometry(odometry(velocity=(NAN, 0.0, 0.0)), 0)[1].velocity_m_s is None
    with pytest.raises(v.Refused, match="faster than"):
        v.read_odometry(odometry(velocity=(150.0, 0.0, 0.0)), 0)
    bad = odometry(velocity=(1.0, 0.0, 0.0))
    bad.velocity_covariance = covariance(-1.0, 0.04, 0.09, 0.0)
    with pytest.raises(v.Refused, match="variance"):
        v.read_odometry(bad, 0)
    other = odometry(velocity=(1.0, 0.0, 0.0))
    other.child_frame_id = m.MAV_FRAME_BODY_OFFSET_NED
    vision = v.ExternalVision()
    pose = vision.receive(other, ("in-process", 1), 1.0, 1.0, True, PARAMS)
    assert pose is not None and pose.velocity_m_s is None
    assert v.VELOCITY_FRAME in vision.take_announcements()


def test_one_sample_a_control_frame_and_refusals_announced_at_most_every_10_s():
    vision = v.ExternalVision()
    sender = ("in-process", 1)
    assert vision.receive(vpe(), sender, 1.0, 1.0, True, PARAMS) is not None
    assert vision.receive(vpe(), sender, 1.0, 1.0, True, PARAMS) is None  # the same frame: a flood
    assert vision.receive(vpe(), sender, 1.002, 1.002, True, PARAMS) is not None  # the next frame
    assert vision.take_announcements() == [f"vision refused: {v.FLOOD}"]
    texts = []
    for k in range(2000):  # a 100 Hz flood of one bad message for 20 s
        t = 2.0 + k * 0.01
        vision.receive(vpe(xyz=(NAN, 0.0, 0.0)), sender, t, t, True, PARAMS)
        texts += vision.take_announcements()
    assert vision.refused == {v.FLOOD: 1, v.NOT_FINITE: 2000}
    assert texts == [f"vision refused: {v.NOT_FINITE}"] * 2  # at 2 s and at 12 s
    assert vision.info() == {"accepted": 2, "refused": {v.FLOOD: 1, v.NOT_FINITE: 2000}}


def test_a_sender_on_the_vehicles_clock_is_timed_by_its_stamps():
    clocks = v.SenderClocks()
    a = ("gcs", 1)
    assert clocks.sample_time(a, 9_990_000, 10.0, 0.0) == pytest.approx(9.99)  # within 1 s: our clock
    assert clocks.sample_time(a, 10_050_000, 10.04, 0.0) == 10.04  # 10 ms ahead: at arrival
    with pytest.raises(v.Refused, match=v.OUT_OF_ORDER):
        clocks.sample_time(a, 10_050_000, 10.1, 0.0)  # the same stamp again
    with pytest.raises(v.Refused, match=v.OUT_OF_ORDER):
        clocks.sample_time(a, 10_000_000, 10.1, 0.0)  # older than the last
    with pytest.raises(v.Refused, match=v.FUTURE):
        clocks.sample_time(a, 10_400_000, 10.2, 0.0)
    with pytest.raises(v.Refused, match=v.TOO_OLD):
        clocks.sample_time(a, 10_060_000, 10.7, 0.0)
    assert clocks.sample_time(a, 0, 10.8, 0.0) == 10.8  # 0: at arrival
    # After 5 refusals in a row the sender's clock is decided again: its clock drifted off ours
    with pytest.raises(v.Refused, match=v.TOO_OLD):
        clocks.sample_time(a, 10_070_000, 11.0, 0.0)  # the 5th in a row
    assert clocks.sample_time(a, 10_080_000, 14.0, 0.0) == 14.0  # now its own clock: at arrival
    # A restarted simulator: every sender's clock is decided again
    clocks.restart()
    assert clocks.sample_time(a, 20_000, 0.02, 0.0) == pytest.approx(0.02)


def test_a_sender_on_its_own_clock_is_timed_at_arrival_and_its_stamps_must_increase():
    clocks = v.SenderClocks()
    script = ("api", 2)
    unix_us = 1_700_000_000_000_000
    assert clocks.sample_time(script, unix_us, 5.0, 0.0) == 5.0
    assert clocks.sample_time(script, unix_us + 20_000, 5.02, 0.0) == 5.02
    with pytest.raises(v.Refused, match=v.OUT_OF_ORDER):
        clocks.sample_time(script, unix_us + 10_000, 5.04, 0.0)  # a reordered or replayed message
    for k in range(v.RELEARN_AFTER - 1):  # the script restarted, its clock with it: 5 refusals, then
        with pytest.raises(v.Refused, match=v.OUT_OF_ORDER):
            clocks.sample_time(script, 1000 + k, 5.06 + k * 0.02, 0.0)
    assert clocks.sample_time(script, 2000, 5.2, 0.0) == 5.2  # ... its clock is learned again
    boot = ("api", 3)
    assert clocks.sample_time(boot, 120_000_000, 5.0, 0.0) == 5.0  # 2 minutes off ours: its own
    for k in range(3 * v.MAX_SENDERS):  # senders are remembered within a bound
        clocks.sample_time(("api", 100 + k), 1 + k, 5.0, float(k))
    assert len(clocks.clocks) == v.MAX_SENDERS


# -- in the loop -----------------------------------------------------------------------------------------
def test_on_the_truth_a_clients_vision_is_refused_counted_and_said_once():
    """EKF2_EN 0 (the default: the vehicle flies on the simulator's state) has no filter to fuse
    vision into: each message is counted in the autopilot's info, the reason said once."""
    stack = make_stack()
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    for _ in range(50):
        gcs.conn.mav.vision_position_estimate_send(0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, UNKNOWN, 0)
        stack.step()
    gcs.wait(lambda g: any(v.NO_EKF in text for text in g.statustext), sim_timeout=0.1, what="the reason")
    assert stack.autopilot.info()["vision"] == {"accepted": 0, "refused": {v.NO_EKF: 50}}
    assert gcs.statustext.count(f"vision refused: {v.NO_EKF}") == 1


class TruthBridge:
    """A mocap bridge as a user writes one against PX4 SITL: it asks for the ground truth
    (HIL_STATE_QUATERNION) and sends each sample back as VISION_POSITION_ESTIMATE, in the local
    NED frame about the vehicle's HOME_POSITION, stamped with the truth's time_usec."""

    def __init__(self, gcs: Gcs, rate_hz: float = 50.0) -> None:
        self.gcs = gcs
        self.home = None
        self.sent = 0
        self._last = None
        truth = m.MAVLINK_MSG_ID_HIL_STATE_QUATERNION
        ack = gcs.command(m.MAV_CMD_SET_MESSAGE_INTERVAL, truth, 1e6 / rate_hz)
        assert ack.result == m.MAV_RESULT_ACCEPTED
        assert gcs.command(m.MAV_CMD_REQUEST_MESSAGE, m.MAVLINK_MSG_ID_HOME_POSITION).result == 0

    def __call__(self, gcs: Gcs) -> None:
        home = gcs.last.get("HOME_POSITION")
        truth = gcs.last.get("HIL_STATE_QUATERNION")
        if home is None or truth is None or truth is self._last:
            return
        self._last = truth
        origin = (home.latitude * 1e-7, home.longitude * 1e-7, home.altitude * 1e-3)
        n, e, d = frames.geodetic_to_ned(truth.lat * 1e-7, truth.lon * 1e-7, truth.alt * 1e-3, origin)
        roll, pitch, yaw = euler_from_quaternion(*truth.attitude_quaternion)  # NED/FRD Euler angles
        gcs.conn.mav.vision_position_estimate_send(truth.time_usec, n, e, d, roll, pitch, yaw, UNKNOWN, 0)
        self.sent += 1


def run(gcs: Gcs, seconds: float, feed, until=None) -> bool:
    end = gcs.sim_time + seconds
    while gcs.sim_time < end:
        gcs.poll()
        feed(gcs)
        if until is not None and until(gcs):
            return True
    return until is None


def take_off_on(gcs: Gcs, bridge: TruthBridge, altitude: float = 2.0) -> None:
    """Arm and take off while the bridge streams (as tests.sitl.test_params_failsafes.take_off)."""
    assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == m.MAV_RESULT_ACCEPTED
    ack = gcs.command(m.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, NAN, NAN, NAN, 488.0 + altitude)
    assert ack.result == m.MAV_RESULT_ACCEPTED
    assert run(gcs, 15.0, bridge, lambda g: g.custom_mode == LOITER and g.position()[2] > altitude - 0.03)


def gps_off_on_client_vision(ev_ctrl: int = 11):
    """The `gps` sensor profile's vehicle on its EKF with EKF2_GPS_CTRL 0, a TruthBridge streaming."""
    stack = make_stack(estimator="ekf", sensors="gps")
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    param_set(gcs, "EKF2_GPS_CTRL", 0, INT32)
    param_set(gcs, "EKF2_EV_CTRL", ev_ctrl, INT32)
    return stack, gcs, TruthBridge(gcs)


def test_a_mocap_bridge_keeps_the_vehicle_on_position_with_the_gps_off():
    """The filter aligns on the client's vision (position and yaw), the vehicle arms, takes off
    and holds 2 m for 10 s on it: the truth stays on the spot, the estimate on the truth; the GPS
    fixes in the frames are never fused."""
    stack, gcs, bridge = gps_off_on_client_vision()
    ap = stack.autopilot
    assert run(gcs, 15.0, bridge, lambda g: ap.commander.estimator_problem is None)
    armed_at = len(stack.truth_rows)
    take_off_on(gcs, bridge)
    run(gcs, 10.0, bridge)
    truth = np.asarray(stack.truth_rows)[armed_at:, 1:4]
    estimate = np.asarray(stack.estimator_rows)[armed_at:, 1:4]
    # The vision is the truth to 1 cm (HIL_STATE_QUATERNION's 1e-7 deg), weighed with PX4's
    # default floors (EKF2_EVP_NOISE 0.1 m, EKF2_EVA_NOISE 0.1 rad).
    assert np.abs(estimate - truth).max() < 0.03
    assert np.hypot(truth[:, 0], truth[:, 1]).max() < 0.03  # through the takeoff too
    assert np.abs(truth[-4000:] - (0.0, 0.0, 2.0)).max() < 0.03  # the last 8 s
    src = ap.estimator.ekf.sources
    flown_s = stack.t - ap.estimator.ekf.init_time_s
    assert src["ev_pos"].fused == src["ev_yaw"].fused >= 0.95 * 50.0 * flown_s  # every 50 Hz sample
    assert src["ev_pos"].rejected == 0
    assert src["gps_pos"].fused == 0
    assert ap.external_vision.refused == {} and ap.external_vision.accepted >= bridge.sent - 1
    assert not ap.faults.counts


def test_ekf2_ev_ctrl_0_ignores_the_clients_vision_and_says_so():
    stack, gcs, bridge = gps_off_on_client_vision(ev_ctrl=0)
    ap = stack.autopilot
    run(gcs, 5.0, bridge)
    assert ap.estimator.ekf.sources["ev_pos"].fused == 0 and not ap.estimator.ekf.initialised
    assert ap.commander.estimator_problem.endswith("waiting for a position source (none enabled "
                                                    "(EKF2_GPS_CTRL, EKF2_EV_CTRL))")  # fmt: skip
    assert ap.external_vision.refused == {v.EV_OFF: bridge.sent} and bridge.sent > 200
    assert gcs.statustext.count(f"vision refused: {v.EV_OFF}") == 1  # said once (then every 10 s)
    assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == m.MAV_RESULT_DENIED


def test_hostile_vision_in_flight_is_refused_and_counted_and_moves_nothing():
    """While the vehicle holds on a bridge's vision, another sender on the vehicle's clock (its
    first ODOMETRY, VISION in LOCAL_FRD, is fused) sends vision messages at every edge, one a
    frame between the bridge's: each is refused under its reason, none reaches the filter, the
    vehicle stays put."""
    stack, gcs, bridge = gps_off_on_client_vision()
    ap = stack.autopilot
    assert run(gcs, 15.0, bridge, lambda g: ap.commander.estimator_problem is None)
    take_off_on(gcs, bridge)
    run(gcs, 2.0, bridge)
    hostile = stack.ground_station(listen=False, system_id=77)
    now_us = lambda: round(stack.t * 1e6)  # noqa: E731 - the vehicle's clock, as a synchronised sender's

    def truthful():
        p = stack.sim.plant.truth()
        yaw = frames.yaw_to_ned(p.euler_rad[2])
        first.append(odometry(now_us(), frames.vector_to_ned(p.position_m), yaw, m.MAV_FRAME_LOCAL_FRD))
        return first[0]

    first: list = []

    attacks = [
        (lambda: vpe(now_us(), xyz=(NAN, 0.0, -2.0)), v.NOT_FINITE),
        (lambda: vpe(now_us(), xyz=(50.0, 0.0, -2.0), rpy=(0.0, 0.0, math.inf)), v.NOT_FINITE),
        (lambda: vpe(now_us(), xyz=(3.4e38, 0.0, -2.0)), v.TOO_FAR),
        (lambda: vpe(now_us(), rpy=(0.0, 0.0, 100.0)), v.BAD_ANGLE),
        (lambda: vpe(now_us(), cov=covariance(-1.0, 0.0, 0.0, 0.0)), v.BAD_VARIANCE),
        (lambda: odometry(now_us(), q=[0.0, 0.0, 0.0, 0.0]), v.BAD_QUATERNION),
        (lambda: odometry(now_us(), frame=m.MAV_FRAME_LOCAL_ENU), v.BAD_FRAME),
        (lambda: odometry(now_us(), estimator=m.MAV_ESTIMATOR_TYPE_MOCAP), v.MOCAP_ODOMETRY),
        (lambda: odometry(now_us(), quality=-1), v.LOW_QUALITY),
    ]
    sequence = [(truthful, None)] + attacks * 10 + [
        (lambda: vpe(now_us() + 5_000_000), v.FUTURE),  # 5 s ahead of the vehicle's clock
        (lambda: first[0], v.OUT_OF_ORDER),  # the truthful one again: a replay
    ]
    late = stack.ground_station(listen=False, system_id=78)  # its first stamp: 0.9 s old
    fused_before, sent_before = ap.estimator.ekf.sources["ev_pos"].fused, bridge.sent
    for make, _ in sequence:
        while True:  # a frame in which the bridge sent nothing: the next one carries this alone
            sent = bridge.sent
            stack.step()
            while gcs.conn.station.inbox:
                gcs.poll()
                bridge(gcs)
            if bridge.sent == sent:
                break
        hostile.write(make().pack(hostile.mav))
    stack.step()
    late.write(vpe(now_us() - 900_000).pack(late.mav))
    run(gcs, 1.0, bridge)
    expected = {v.TOO_OLD: 1}
    for _, reason in sequence[1:]:
        expected[reason] = expected.get(reason, 0) + 1
    assert ap.external_vision.refused == expected  # no flood: one sample a frame
    src = ap.estimator.ekf.sources["ev_pos"]
    assert src.rejected == 0  # nothing hostile reached the filter
    assert src.fused - fused_before >= bridge.sent - sent_before  # the bridge's, and the truthful one
    truth = np.asarray(stack.truth_rows)[-1500:, 1:4]
    assert np.abs(truth - (0.0, 0.0, 2.0)).max() < 0.05
    assert not ap.faults.counts
