"""Offboard attitude and body rates (SET_ATTITUDE_TARGET), the whole stack in simulation time: as a
companion computer flies its own outer loop on PX4 (MAVSDK's ``set_attitude`` and
``set_attitude_rate``). The target goes past the position law to the cascade's attitude law,
bounded as ACRO is; hostile targets are refused; the offboard-loss failsafe holds when the stream
stops."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as m

from autopilot.commander.modes import FlightMode
from autopilot.guidance.manual import ManualLimits, integrate_body_rates
from autopilot.guidance.offboard import AttitudeSetpoint, OffboardGuidance
from autopilot.guidance.planner import Limits
from autopilot.mavlink.offboard import decode_attitude_target
from quadcommon import frames
from quadcommon.rigid_body import quaternion_from_euler
from tests.stack import Gcs, make_stack

pytestmark = pytest.mark.timeout(120)

RATES_ONLY = 128  # ATTITUDE_TARGET_TYPEMASK_ATTITUDE_IGNORE: the body rates and the thrust
ATTITUDE_ONLY = 1 | 2 | 4  # the body rates ignored (MAVSDK's set_attitude)
OFFBOARD_MODE = (1, 6, 0, 0, 0, 0, 0)  # MAV_CMD_DO_SET_MODE: PX4's custom main mode 6


def q_ned(roll_deg: float, pitch_deg: float, yaw_deg: float) -> tuple[float, float, float, float]:
    """The attitude quaternion a client sends: PX4's roll/pitch/yaw (FRD body, NED world)."""
    paper = frames.euler_from_ned(tuple(math.radians(a) for a in (roll_deg, pitch_deg, yaw_deg)))
    return frames.quaternion_to_ned(quaternion_from_euler(*paper))


def send_attitude(gcs: Gcs, q, thrust: float, mask: int = ATTITUDE_ONLY, rates=(0.0, 0.0, 0.0)) -> None:
    gcs.conn.mav.set_attitude_target_send(int(gcs.sim_time * 1000), gcs.system_id, 1, mask, q, *rates, thrust)


def stream(gcs: Gcs, seconds: float, send) -> None:
    """``send(gcs)`` at 50 Hz for ``seconds`` of simulation time."""
    end = gcs.sim_time + seconds
    next_send = gcs.sim_time
    while gcs.sim_time < end:
        if gcs.sim_time >= next_send:
            send(gcs)
            next_send += 0.02
        gcs.poll()


def offboard_on_the_ground() -> tuple:
    stack = make_stack()
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == m.MAV_RESULT_ACCEPTED
    send_attitude(gcs, q_ned(0, 0, 0), 0.0)  # MAVSDK: one setpoint, then start()
    assert gcs.command(m.MAV_CMD_DO_SET_MODE, *OFFBOARD_MODE).result == m.MAV_RESULT_ACCEPTED
    return stack, gcs


def test_mavsdks_attitude_sequence_climbs_rolls_both_ways_and_holds_after_stop():
    """offboard_attitude.py's sequence: 70 % thrust climbs, 30 degrees of roll (PX4's, to the
    right) at 60 % moves the vehicle right, -30 degrees left; stopping offboard holds. (The thrust
    is PX4's, a fraction of the maximum: the paper's quadrotor hovers at 0.26 of it, so the
    example, written for airframes hovering near 0.6, climbs fast.)"""
    stack, gcs = offboard_on_the_ground()
    commander = stack.autopilot.commander
    stream(gcs, 1.0, lambda g: send_attitude(g, q_ned(0, 0, 0), 0.0))
    assert commander.mode is FlightMode.OFFBOARD and commander.state.position_m[2] < 0.05  # idles
    stream(gcs, 2.0, lambda g: send_attitude(g, q_ned(0, 0, 0), 0.7))
    climbed = commander.state.position_m[2]
    assert climbed > 1.0, climbed
    y0 = commander.state.position_m[1]
    stream(gcs, 1.0, lambda g: send_attitude(g, q_ned(30, 0, 0), 0.6))
    roll = math.degrees(commander.state.euler_rad[0])  # PX4's roll, right wing down, is the paper's phi
    assert roll == pytest.approx(30.0, abs=2.0)
    stream(gcs, 1.0, lambda g: send_attitude(g, q_ned(30, 0, 0), 0.6))
    assert commander.state.position_m[1] < y0 - 0.5  # moved right (the paper's y is left)
    vy = commander.state.velocity_m_s[1]
    stream(gcs, 2.0, lambda g: send_attitude(g, q_ned(-30, 0, 0), 0.6))
    assert math.degrees(commander.state.euler_rad[0]) == pytest.approx(-30.0, abs=2.0)
    assert commander.state.velocity_m_s[1] > vy + 10.0  # pushed left as hard as it was pushed right
    stream(gcs, 2.0, lambda g: send_attitude(g, q_ned(0, 0, 0), 0.6))
    assert max(abs(a) for a in commander.state.euler_rad[:2]) < math.radians(2.0)
    assert gcs.command(m.MAV_CMD_DO_SET_MODE, 1, 4, 3).result == m.MAV_RESULT_ACCEPTED  # MAVSDK stop(): hold
    stack.run_for(1.0)
    assert commander.mode is FlightMode.AUTO_LOITER and commander.in_air()
    assert commander.phase.name == "HOLD"


def test_body_rates_turn_the_vehicle_at_the_commanded_rate():
    """Hovering in offboard on a rate stream: a yaw rate of 45 deg/s (FRD: clockwise seen from
    above) turns the heading at that rate; roll and pitch rates of zero keep it level."""
    stack, gcs = offboard_on_the_ground()
    commander = stack.autopilot.commander
    hover = stack.autopilot.params["MPC_THR_HOVER"]
    stream(gcs, 2.0, lambda g: send_attitude(g, q_ned(0, 0, 0), 1.3 * hover))
    stream(gcs, 0.5, lambda g: send_attitude(g, (1, 0, 0, 0), hover, RATES_ONLY))
    psi0 = commander.state.euler_rad[2]
    yaw_45 = (0.0, 0.0, math.radians(45))
    stream(gcs, 2.0, lambda g: send_attitude(g, (1, 0, 0, 0), hover, RATES_ONLY, yaw_45))
    turned = math.degrees(math.remainder(commander.state.euler_rad[2] - psi0, 2 * math.pi))
    assert turned == pytest.approx(-90.0, abs=8.0)  # clockwise: the paper's psi decreases
    assert max(abs(a) for a in commander.state.euler_rad[:2]) < math.radians(3.0)
    assert commander.mode is FlightMode.OFFBOARD and commander.in_air()


def test_the_offboard_loss_failsafe_holds_when_the_attitude_stream_stops():
    """The attitude stream keeps OFFBOARD alive as a position stream does; COM_OF_LOSS_T after the
    last target the vehicle announces the loss and holds (no sticks: PX4's hold)."""
    stack, gcs = offboard_on_the_ground()
    commander = stack.autopilot.commander
    hover = stack.autopilot.params["MPC_THR_HOVER"]
    stream(gcs, 2.5, lambda g: send_attitude(g, q_ned(0, 0, 0), 1.15 * hover))
    last = stack.t - 0.02
    assert commander.mode is FlightMode.OFFBOARD and commander.in_air()
    gcs.wait(lambda g: commander.mode is not FlightMode.OFFBOARD, sim_timeout=3.0, what="the loss failsafe")
    assert stack.t - last == pytest.approx(stack.autopilot.params["COM_OF_LOSS_T"], abs=0.05)
    gcs.wait(lambda g: any("offboard setpoints lost" in text for text in g.statustext), sim_timeout=0.5)
    stack.run_for(3.0)
    assert commander.mode is FlightMode.AUTO_LOITER and commander.in_air()
    assert commander.phase.name == "HOLD"


class Target:
    """A SET_ATTITUDE_TARGET as pymavlink decodes it."""

    def __init__(self, type_mask=ATTITUDE_ONLY, q=(1.0, 0.0, 0.0, 0.0), rates=(0.0, 0.0, 0.0), thrust=0.5):
        self.type_mask, self.q, self.thrust = type_mask, q, thrust
        self.body_roll_rate, self.body_pitch_rate, self.body_yaw_rate = rates


NAN, INF = math.nan, math.inf


@pytest.mark.parametrize(
    "target, reason",
    [
        (Target(q=(NAN, 0.0, 0.0, 0.0)), "non-finite attitude quaternion"),
        (Target(q=(0.0, 0.0, 0.0, 0.0)), "not a unit quaternion"),
        (Target(q=(2.0, 0.0, 0.0, 0.0)), "not a unit quaternion"),
        (Target(thrust=INF), "non-finite thrust"),
        (Target(thrust=NAN), "non-finite thrust"),
        (Target(RATES_ONLY, rates=(NAN, 0.0, 0.0)), "non-finite body rate"),
        (Target(RATES_ONLY | 1), "ignores the attitude and the roll or pitch rate"),
        (Target(255), "ignores the attitude and the roll or pitch rate"),
    ],
)
def test_hostile_targets_are_refused_with_the_reason(target, reason):
    setpoint, why = decode_attitude_target(target, 1.0)
    assert setpoint is None and reason in why


def test_a_target_is_read_as_px4_reads_it():
    """Thrust clamped to 0..1 and ignored by bit 64; a near-unit quaternion normalised; FRD rates
    to FLU; the yaw rate 0 when bit 4 ignores it; NaN in an ignored field does no harm."""
    assert decode_attitude_target(Target(thrust=1.7), 0.0)[0].thrust == 1.0
    assert decode_attitude_target(Target(thrust=-0.2), 0.0)[0].thrust == 0.0
    assert decode_attitude_target(Target(ATTITUDE_ONLY | 64, thrust=NAN), 0.0)[0].thrust is None
    sp, _ = decode_attitude_target(Target(q=tuple(1.05 * v for v in q_ned(10, 20, 30))), 2.0)
    assert sp.time_s == 2.0 and sp.body_rates is None
    assert sp.attitude == pytest.approx(frames.euler_from_ned(tuple(math.radians(a) for a in (10, 20, 30))))
    sp, _ = decode_attitude_target(Target(RATES_ONLY, q=(NAN,) * 4, rates=(0.1, 0.2, 0.3)), 0.0)
    assert sp.attitude is None and sp.body_rates == pytest.approx((0.1, -0.2, -0.3))
    sp, _ = decode_attitude_target(Target(RATES_ONLY | 4, rates=(0.1, 0.2, NAN)), 0.0)
    assert sp.body_rates == pytest.approx((0.1, -0.2, 0.0))


def test_targets_are_flown_within_acros_bounds():
    """An attitude beyond ACRO_TILT_LIM flies at the limit; rates beyond MC_ACRO_*_MAX at the
    maximum, integrated by ACRO's own step; thrust kept from the last target that gave one."""
    limits = ManualLimits(acro_rates=(1.0, 1.0, 0.5), acro_tilt=math.radians(60))
    guidance = OffboardGuidance(Limits(2.0, 1.5, 1.0, 2.0, 1.0))

    class State:
        position_m, velocity_m_s, euler_rad = (0.0, 0.0, 2.0), (0.0, 0.0, 0.0), (0.1, 0.0, 0.0)

    guidance.update(AttitudeSetpoint(0.0, attitude=(1.5, -1.5, 0.3), thrust=0.6))
    step = guidance.attitude_step(0.002, State, limits)
    tilt = math.radians(60)
    assert step.attitude[0] == pytest.approx((tilt, -tilt, 0.3)) and step.thrust == 0.6
    guidance.update(AttitudeSetpoint(0.002, body_rates=(5.0, 0.0, -5.0)))  # no thrust: the last one kept
    step = guidance.attitude_step(0.002, State, limits)
    assert step.thrust == 0.6
    bounded = (1.0, 0.0, -0.5)
    assert step.attitude[:2] == integrate_body_rates(State.euler_rad, bounded, 0.002, tilt)
    again = guidance.attitude_step(0.002, State, limits)  # integrates on from its own attitude
    assert again.attitude[0] == integrate_body_rates(step.attitude[0], bounded, 0.002, tilt)[0]


def test_hostile_targets_over_the_wire_are_refused_said_and_never_flown():
    """pymavlink on the API link, in OFFBOARD on an attitude stream: a NaN quaternion, a zero one,
    an infinite thrust and an empty mask are each refused with a STATUSTEXT naming the reason; the
    vehicle keeps flying the last good target, level."""
    stack, gcs = offboard_on_the_ground()
    commander = stack.autopilot.commander
    hover = stack.autopilot.params["MPC_THR_HOVER"]
    stream(gcs, 2.0, lambda g: send_attitude(g, q_ned(0, 0, 0), 1.1 * hover))
    hostile = [((NAN, 0.0, 0.0, 0.0), 0.5, ATTITUDE_ONLY, "non-finite attitude quaternion"),
               ((0.0, 0.0, 0.0, 0.0), 0.5, ATTITUDE_ONLY, "not a unit quaternion"),
               (q_ned(0, 0, 0), INF, ATTITUDE_ONLY, "non-finite thrust"),
               (q_ned(0, 0, 0), 0.5, 255, "ignores the attitude and the roll or pitch rate")]  # fmt: skip
    for q, thrust, mask, reason in hostile:
        send_attitude(gcs, q, thrust, mask)
        gcs.wait(lambda g, r=reason: any(r in text for text in g.statustext), sim_timeout=0.5, what=reason)
        assert "attitude target refused" in gcs.statustext[-1]
        assert commander.offboard.setpoint.thrust == pytest.approx(1.1 * hover)  # the last good one
    assert commander.mode is FlightMode.OFFBOARD and commander.in_air()
    assert max(abs(a) for a in commander.state.euler_rad[:2]) < math.radians(2.0)
