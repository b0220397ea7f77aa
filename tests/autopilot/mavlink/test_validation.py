"""What the autopilot accepts, decided in one place (autopilot.mavlink.validation), and the bounds
behind it: command parameter rules, the one distance rule, rate-limited refusal notices,
saturating telemetry, the link's peer and datagram bounds, bounded references, anti-windup."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as m

from autopilot.control.cascade import Cascade
from autopilot.control.config import PAPER_CONTROLLERS, load_controller
from autopilot.control.translational import acceleration_limits
from autopilot.guidance.offboard import OffboardGuidance, OffboardSetpoint
from autopilot.guidance.planner import Limits, transition
from autopilot.mavlink import telemetry
from autopilot.mavlink.links import MAX_DATAGRAM_BYTES, MAX_PEERS, PEER_EXPIRY_S, GcsLink
from autopilot.mavlink.validation import COMMAND_RULES, RefusalNotices, check_command, reference_problem
from autopilot.records import StateEstimate
from quadcommon import wire
from quadcommon.config import load_vehicle
from quadcommon.trajectories import Reference
from tests.autopilot import laws

NAN, INF = math.nan, math.inf
ZERO3 = (0.0, 0.0, 0.0)


def params7(*values: float) -> tuple[float, ...]:
    return tuple(values) + (0.0,) * (7 - len(values))


# -- commands -----------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "command, params, refused",
    [
        (m.MAV_CMD_COMPONENT_ARM_DISARM, params7(1), False),
        (m.MAV_CMD_COMPONENT_ARM_DISARM, params7(0, 21196), False),
        (m.MAV_CMD_COMPONENT_ARM_DISARM, params7(1, NAN), False),
        (m.MAV_CMD_COMPONENT_ARM_DISARM, params7(2), True),
        (m.MAV_CMD_COMPONENT_ARM_DISARM, params7(1, 5), True),
        (m.MAV_CMD_SET_MESSAGE_INTERVAL, params7(0, -1), False),
        (m.MAV_CMD_SET_MESSAGE_INTERVAL, params7(0, 0), False),
        (m.MAV_CMD_SET_MESSAGE_INTERVAL, params7(0, NAN), True),
        (m.MAV_CMD_SET_MESSAGE_INTERVAL, params7(0, -0.5), True),
        (m.MAV_CMD_SET_MESSAGE_INTERVAL, params7(0, 1e12), True),
        (m.MAV_CMD_SET_MESSAGE_INTERVAL, params7(2**24, 1000), True),
        (m.MAV_CMD_SET_MESSAGE_INTERVAL, params7(30.5, 1000), True),
        (m.MAV_CMD_REQUEST_MESSAGE, params7(-3), True),
        (m.MAV_CMD_DO_SET_MODE, params7(1, 6, 0), False),
        (m.MAV_CMD_DO_SET_MODE, params7(0, 6, 0), True),  # custom mode flag missing
        (m.MAV_CMD_DO_SET_MODE, params7(1, 300, 0), True),
        (m.MAV_CMD_NAV_TAKEOFF, params7(0, 0, 0, NAN, NAN, NAN, NAN), False),
        (m.MAV_CMD_NAV_TAKEOFF, params7(0, 0, 0, NAN, NAN, NAN, 1e6), True),
        (m.MAV_CMD_PREFLIGHT_STORAGE, params7(3), True),
        (m.MAV_CMD_NAV_LAND, params7(0, 0, 0, NAN, INF), True),  # inf anywhere, any command
    ],
)
def test_command_rules(command, params, refused):
    problem = check_command(command, params)
    assert (problem is not None) == refused, problem
    if refused:
        assert "param" in problem or "DO_SET_MODE" in problem  # the reason names what is wrong


def test_every_rule_names_a_parameter_between_1_and_7():
    for rules in COMMAND_RULES.values():
        for rule in rules:
            assert 1 <= rule.number <= 7 and rule.what


def test_the_distance_rule_refuses_far_and_nan_positions():
    params = {"NAV_REF_MAX_DIST": 100.0}
    assert reference_problem((99.0, 0.0, 0.0), ZERO3, params) is None
    assert "NAV_REF_MAX_DIST" in reference_problem((0.0, 101.0, 0.0), ZERO3, params)
    assert reference_problem((NAN, 0.0, 0.0), ZERO3, params) is not None
    assert reference_problem((150.0, 0.0, 0.0), (100.0, 0.0, 0.0), params) is None  # from home


def test_refusal_notices_are_rate_limited_per_text():
    sent, now = [], [0.0]
    notices = RefusalNotices(lambda severity, text: sent.append(text), lambda: now[0])
    for k in range(1000):
        now[0] = k * 0.01  # 10 s of a 100 Hz flood of two different refusals
        notices("setpoint refused: A")
        notices("setpoint refused: B")
    assert notices.refused == 2000
    assert sent.count("setpoint refused: A") == 10 and sent.count("setpoint refused: B") == 10


# -- telemetry saturates ------------------------------------------------------------------------------
@pytest.mark.parametrize("scale", [1e6, 1e12, -1e12, NAN])
def test_every_telemetry_message_packs_whatever_the_state(scale):
    state = StateEstimate((scale, scale, scale), (scale, -scale, scale), (scale, 0.1, scale), (scale,) * 3)
    status = telemetry.VehicleStatus(1, time_usec=10**15, state=state, armed=True, thrust_normalised=scale,
                                     controls=(scale, 0.5, -scale, 1.0))  # fmt: skip
    status.reference = Reference((scale,) * 3, (scale,) * 3, ZERO3, 0.0, 0.0, 0.0)
    encoder = m.MAVLink(None, 1, 1)
    for msg_id in telemetry.BUILDERS:
        msg = telemetry.build(msg_id, status)
        if msg is not None:
            msg.pack(encoder)  # struct.error if a field left its type's range


def test_saturating_conversions():
    assert wire.sat_i16(1e9) == 32767 and wire.sat_i16(-1e9) == -32767 and wire.sat_i16(NAN) == 0
    assert wire.sat_u16(-5) == 0 and wire.sat_u16(1e9) == 65534 and wire.sat_u16(NAN) == 65535
    assert wire.sat_i32(1e30) == 2**31 - 1 and wire.sat_i32(-INF) == -(2**31 - 1) and wire.sat_i32(12.4) == 12


# -- the link's bounds --------------------------------------------------------------------------------
def heartbeat_frame(system_id: int = 255) -> bytes:
    msg = m.MAVLink_heartbeat_message(m.MAV_TYPE_GCS, m.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3)
    return msg.pack(m.MAVLink(None, srcSystem=system_id, srcComponent=190))


def test_a_peer_is_who_sent_a_valid_message_bounded_and_expiring():
    outbox = []
    link = GcsLink(1, ("127.0.0.1", 14540), outbox)
    link.receive(b"garbage", ("127.0.0.1", 40000), now=0.0)
    assert ("127.0.0.1", 40000) not in link.peers
    for k in range(3 * MAX_PEERS):
        link.receive(heartbeat_frame(), ("127.0.0.1", 50000 + k), now=float(k))
    assert len(link.peers) == MAX_PEERS
    assert ("127.0.0.1", 14540) in link.peers  # the default remote stays
    assert ("127.0.0.1", 50000 + 3 * MAX_PEERS - 1) in link.peers  # the newest are kept
    assert link.evicted == 3 * MAX_PEERS - (MAX_PEERS - 1)
    link.expire(3 * MAX_PEERS + PEER_EXPIRY_S + 1)
    assert list(link.peers) == [("127.0.0.1", 14540)]


def test_a_truncated_frame_does_not_swallow_the_next_datagram():
    link = GcsLink(1, None, [])
    frame = heartbeat_frame()
    assert [msg.get_type() for msg in link.receive(frame[:7], ("127.0.0.1", 1), 0.0)] in ([], ["BAD_DATA"])
    assert "HEARTBEAT" in [msg.get_type() for msg in link.receive(frame, ("127.0.0.1", 2), 0.0)]


def test_an_oversize_datagram_is_cut_and_counted():
    link = GcsLink(1, None, [])
    frame = heartbeat_frame()
    messages = link.receive(frame * 200, ("127.0.0.1", 1), 0.0)  # 4,200 bytes
    assert link.oversize == 1
    assert sum(msg.get_type() == "HEARTBEAT" for msg in messages) == MAX_DATAGRAM_BYTES // len(frame)


# -- bounded references -------------------------------------------------------------------------------
LIMITS = Limits(speed_horizontal=2.0, speed_up=1.5, speed_down=1.0, acceleration=2.0)


def test_a_far_target_from_a_moving_state_brakes_then_flies_a_line_within_the_limits():
    start = Reference((0.0, 0.0, 2.0), (0.0, 0.0, 0.3), (0.0, 0.0, -1.9), 0.0, 0.0, 0.0)
    plan = transition(start, (500.0, 0.0, 2.0), LIMITS)
    speeds, heights = [], []
    t = 0.0
    while t <= plan.duration_s:
        ref = plan.sample(t)
        speeds.append(math.hypot(*ref.velocity_m_s[:2]))
        heights.append(ref.position_m[2])
        t += 0.05
    assert max(speeds) <= LIMITS.speed_horizontal * 1.01
    assert min(heights) > 1.9  # no overshoot towards the ground
    assert plan.duration_s < 500.0 / LIMITS.speed_horizontal + 10.0  # it does cruise
    assert math.dist(plan.sample(plan.duration_s).position_m, (500.0, 0.0, 2.0)) < 1e-6


def test_offboard_feedforward_is_limited_and_a_far_sample_is_joined_not_jumped_to():
    guidance = OffboardGuidance(LIMITS)
    ref = Reference((0.0, 0.0, 2.0), ZERO3, ZERO3, 0.0, 0.0, 0.0)
    dt = 0.002
    top_speed, largest_step = 0.0, 0.0
    for k in range(5000):  # 10 s
        t = k * dt
        guidance.update(OffboardSetpoint(t, (200.0, 0.0, 2.0), (1e9, 0.0, -1e9), (1e9, 0.0, 0.0), None, None))
        new = guidance.reference(t, dt, ref)
        largest_step = max(largest_step, math.dist(new.position_m, ref.position_m))
        top_speed = max(top_speed, math.hypot(*new.velocity_m_s[:2]))
        ref = new
    assert top_speed <= LIMITS.speed_horizontal * 1.01
    assert largest_step <= LIMITS.speed_horizontal * dt * 1.01
    assert 15.0 < ref.position_m[0] < 200.0  # on its way at the limit, not there


@pytest.mark.parametrize("name", PAPER_CONTROLLERS)
def test_integrals_stay_bounded_while_the_vehicle_cannot_follow(name):
    """A vehicle held 50 m off its reference and tilted (stuck): no integral winds up past what
    the actuators can give (the state's share of the commanded acceleration within the vehicle's
    limits, of the torque within the actuators'), and each is held at that limit."""
    config = load_controller(name)
    cascade = Cascade(config, load_vehicle("paper_quad"), 0.002)
    state = StateEstimate((0.0, 0.0, 0.0), ZERO3, (0.5, -0.5, 1.0), ZERO3)
    ref = Reference((50.0, -50.0, 20.0), ZERO3, ZERO3, 0.0, 0.0, 0.0)
    for _ in range(20000):  # 40 s
        cascade.step(state, ref)
    tr, rot = laws.translational(name), laws.rotational(name)
    tr.state, rot.state = list(cascade.xt), list(cascade.xr)
    args = (state.position_m, ZERO3, state.euler_rad, ref.position_m, ZERO3, ZERO3, 0.0, 0.002, False)
    shares = [(laws.state_term(tr, args)[3:6], acceleration_limits(cascade.context))]
    at_hover = (ZERO3, ZERO3, ZERO3, ZERO3, ZERO3, ZERO3, 0.002, False)
    shares.append((laws.state_term(rot, at_hover), cascade.context.torque_max_n_m))
    for share, limit in shares:
        ratios = [abs(v) / lim for v, lim in zip(share, limit, strict=True)]
        assert max(ratios) <= 1.0 + 1e-9
        if any(share):  # a law with integral action: held at its limit
            assert max(ratios) > 0.99
