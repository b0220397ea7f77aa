"""Offboard guidance: what a velocity or yaw setpoint does to the reference the cascade flies."""

import math
import random

import pytest
from pymavlink.dialects.v20 import common as m

from autopilot.commander.modes import FlightMode
from autopilot.guidance.offboard import OffboardGuidance, OffboardSetpoint
from autopilot.guidance.planner import Limits
from quadcommon.trajectories import Reference
from tests.stack import Gcs, make_stack

ZERO3 = (0.0, 0.0, 0.0)
LIMITS = Limits(speed_horizontal=2.0, speed_up=1.5, speed_down=1.0, acceleration=2.0, yaw_rate=1.0)
DT = 0.002


def fly(guidance: OffboardGuidance, ref: Reference, steps: int, t0: float = 0.0) -> list[Reference]:
    refs = []
    for k in range(steps):
        ref = guidance.reference(t0 + k * DT, DT, ref)
        refs.append(ref)
    return refs


def hover(yaw: float = 0.0) -> Reference:
    return Reference((0.0, 0.0, 2.0), ZERO3, ZERO3, yaw, 0.0, 0.0)


@pytest.mark.parametrize("start, target", [(ZERO3, (2.0, 0.0, 0.0)), ((2.0, 0.0, 0.0), (-2.0, 0.0, 0.0)),
                                           (ZERO3, (1.0, -1.0, 1.0))])  # fmt: skip
def test_a_velocity_step_becomes_a_ramp_at_mpc_acc_hor(start, target):
    """Velocity-only setpoints: p_d' ramps to the setpoint at the acceleration limit with p_d'' the
    ramp's (a step in p_d' would be an impulse in p_d''); p_d integrates p_d'."""
    guidance = OffboardGuidance(LIMITS)
    guidance.update(OffboardSetpoint(0.0, velocity=target))
    previous = Reference((0.0, 0.0, 2.0), start, ZERO3, 0.0, 0.0, 0.0)
    refs = fly(guidance, previous, 1500)  # 3 s
    gap = math.dist(start, target)
    ramp_steps = math.ceil(gap / (LIMITS.acceleration * DT))
    for k, ref in enumerate(refs):
        step = math.dist(ref.velocity_m_s, previous.velocity_m_s)
        assert step <= LIMITS.acceleration * DT * (1 + 1e-9), k
        assert math.hypot(*ref.acceleration_m_s2) <= LIMITS.acceleration * (1 + 1e-9)
        moved = tuple(b - a for a, b in zip(previous.position_m, ref.position_m, strict=True))
        assert moved == pytest.approx(tuple(v * DT for v in ref.velocity_m_s), abs=1e-12)
        previous = ref
    on_the_way = refs[ramp_steps // 2]
    expected = tuple((b - a) / gap * LIMITS.acceleration for a, b in zip(start, target, strict=True))
    assert on_the_way.acceleration_m_s2 == pytest.approx(expected)  # the ramp's acceleration, fed forward
    assert refs[ramp_steps].velocity_m_s == pytest.approx(target)  # there after |dv| / MPC_ACC_HOR
    assert refs[ramp_steps - 2].velocity_m_s != pytest.approx(target)
    assert refs[-1].acceleration_m_s2 == ZERO3 and refs[-1].velocity_m_s == target


def test_an_acceleration_fed_with_the_velocity_applies_once_the_velocity_is_reached():
    guidance = OffboardGuidance(LIMITS)
    guidance.update(OffboardSetpoint(0.0, velocity=(0.5, 0.0, 0.0), acceleration=(0.3, 0.0, 0.0)))
    refs = fly(guidance, hover(), 500)
    assert refs[0].acceleration_m_s2 == pytest.approx((LIMITS.acceleration, 0.0, 0.0))
    assert refs[-1].velocity_m_s == (0.5, 0.0, 0.0) and refs[-1].acceleration_m_s2 == (0.3, 0.0, 0.0)


YAW_CASES = [(0.0, 1.0, 1.0), (math.pi - 0.1, -math.pi + 0.1, 0.2),
             (0.5, -165.0, math.remainder(-165.0 - 0.5, 2 * math.pi))]  # fmt: skip


@pytest.mark.parametrize("start, target, turn", YAW_CASES)
def test_an_absolute_yaw_is_reached_the_shorter_way_at_the_yaw_rate_limit(start, target, turn):
    """Velocity setpoints with a yaw: the yaw reference turns the shorter way round (through +-pi
    when that is shorter; a yaw of -165 rad is -165 rad wrapped) at MPC_YAWRAUTO_MAX, its rate fed
    forward, and ends on the target."""
    guidance = OffboardGuidance(LIMITS)
    guidance.update(OffboardSetpoint(0.0, velocity=ZERO3, yaw=target))
    previous = hover(start)
    refs = fly(guidance, previous, 2000)
    travelled = 0.0
    for ref in refs:
        step = math.remainder(ref.yaw_rad - previous.yaw_rad, 2 * math.pi)
        assert abs(step) <= LIMITS.yaw_rate * DT * (1 + 1e-9)
        assert -math.pi <= ref.yaw_rad <= math.pi
        if step:
            assert ref.yaw_rate_rad_s == pytest.approx(step / DT) or ref.yaw_rad == pytest.approx(
                math.remainder(target, 2 * math.pi)
            )
        travelled += step
        previous = ref
    assert travelled == pytest.approx(turn, abs=1e-9)
    assert refs[-1].yaw_rad == pytest.approx(math.remainder(target, 2 * math.pi))
    assert refs[-1].yaw_rate_rad_s == 0.0


def test_a_position_setpoints_yaw_is_still_planned_with_its_transition():
    """A position-only setpoint plans its C2 transition to the setpoint's own yaw (unchanged)."""
    guidance = OffboardGuidance(LIMITS)
    guidance.update(OffboardSetpoint(0.0, position=(1.0, 0.0, 2.0), yaw=0.5))
    refs = fly(guidance, hover(), 3000)
    assert refs[-1].position_m == pytest.approx((1.0, 0.0, 2.0)) and refs[-1].yaw_rad == pytest.approx(0.5)


# A velocity setpoint with a yaw (PX4's type mask: position, acceleration and yaw rate ignored).
VELOCITY_AND_YAW = 1 | 2 | 4 | 64 | 128 | 256 | 2048


@pytest.mark.timeout(120)
@pytest.mark.parametrize("controller", ["intbs_nlhinf", "bs_nlhinf", "se3"])
def test_a_ground_station_spamming_modes_and_velocity_steps_does_not_tip_the_vehicle(controller):
    """Hovering, then 3 s of a hostile ground station: on 30 % of the frames a random TAKEOFF, LAND
    or RTL, on 10 % an offboard velocity setpoint of up to 2 m/s in a random direction with a yaw
    anywhere in +-4 rad (sometimes with a switch to OFFBOARD). Velocity steps fed to the reference
    as steps tip IntBS-NLHinf over (69 degrees with seed 1); ramped, the tilt stays small."""
    stack = make_stack(controller=controller)
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == m.MAV_RESULT_ACCEPTED
    assert gcs.command(m.MAV_CMD_NAV_TAKEOFF).result == m.MAV_RESULT_ACCEPTED
    commander = stack.autopilot.commander
    gcs.wait(lambda g: commander.mode is FlightMode.AUTO_LOITER and commander.in_air(), 20, "hovering")
    stack.run_for(2.0)
    rng = random.Random(1)
    modes = (m.MAV_CMD_NAV_TAKEOFF, m.MAV_CMD_NAV_LAND, m.MAV_CMD_NAV_RETURN_TO_LAUNCH)
    worst, offboard = 0.0, 0
    for _ in range(1500):
        r = rng.random()
        if r < 0.3:
            gcs.conn.mav.command_long_send(gcs.system_id, 1, rng.choice(modes), 0, 0, 0, 0, 0, 0, 0, 0)
        elif r < 0.4:
            gcs.conn.mav.set_position_target_local_ned_send(
                0, gcs.system_id, 1, m.MAV_FRAME_LOCAL_NED, VELOCITY_AND_YAW, 0, 0, 0,
                rng.uniform(-2, 2), rng.uniform(-1, 1), 0, 0, 0, 0, rng.uniform(-4, 4), 0,
            )  # fmt: skip
            if rng.random() < 0.3:
                offboard_mode = (1, 6, 0, 0, 0, 0, 0)  # PX4's custom main mode 6
                gcs.conn.mav.command_long_send(gcs.system_id, 1, m.MAV_CMD_DO_SET_MODE, 0, *offboard_mode)
        stack.step()
        offboard += commander.mode is FlightMode.OFFBOARD
        roll, pitch, _ = commander.state.euler_rad
        worst = max(worst, abs(roll), abs(pitch))
    assert offboard > 100  # the spam did fly offboard velocity steps
    assert worst < 0.35, f"tilted by {worst:.2f} rad"
