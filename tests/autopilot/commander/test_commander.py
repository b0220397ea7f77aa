"""The commander (pure): arming rules, takeoff/hold/land/RTL, offboard stream and loss."""

import math

import pytest

from autopilot.commander.commander import (
    ACCEPTED,
    DENIED,
    Commander,
    Motors,
    Phase,
    VehicleState,
)
from autopilot.commander.modes import FlightMode, LandedState
from autopilot.guidance.offboard import OffboardSetpoint
from autopilot.params.definitions import default_parameters

DT = 0.002


def state(t, p=(0.0, 0.0, 0.0), v=(0.0, 0.0, 0.0), yaw=0.0):
    return VehicleState(t, p, v, (0.0, 0.0, yaw), (0.0, 0.0, 0.0))


def fly(c: Commander, t0: float, seconds: float, perfect=True):
    """Step the commander, letting the vehicle follow its reference exactly."""
    t = t0
    out = None
    for _ in range(int(round(seconds / DT))):
        out = c.step(t, DT)
        if perfect and out.reference is not None and out.motors == Motors.FLY:
            ref = out.reference
            c.update_state(state(t, ref.position_m, ref.velocity_m_s, ref.yaw_rad))
        t += DT
    return t, out


@pytest.fixture
def commander():
    c = Commander(default_parameters())
    c.update_state(state(0.0))
    return c


def test_arm_refused_without_state_and_in_air():
    c = Commander(default_parameters())
    assert c.arm(0.0).result != ACCEPTED
    c.update_state(state(0.0, p=(0.0, 0.0, 3.0)))
    out = c.arm(0.0)
    assert out.result == DENIED and "not landed" in out.reason
    assert any("not landed" in text for _, text in c.drain_events())


def test_on_the_ground_a_height_the_estimate_cannot_tell_from_the_ground_is_the_ground():
    """A filter just aligned on GNSS and a barometer puts the resting vehicle 0.39 m up with a 1-sigma
    of 0.3 m: on the ground, not flying, and it arms; the same height known to 1 cm is in the air."""
    c = Commander(default_parameters())
    c.update_state(state(0.0, p=(0.0, 0.0, 0.39)))
    c.height_uncertainty_m = 0.3
    assert not c.in_air() and c.landed_state == LandedState.ON_GROUND and c.arm_problem(0.0) is None
    c.height_uncertainty_m = 0.01
    assert c.in_air() and c.arm_problem(0.0) == "vehicle not landed"
    c.height_uncertainty_m = math.inf  # no uncertainty known yet: nothing tells it from the ground
    assert not c.in_air()
    c.estimator_problem = "estimator not ready: aligning"
    assert c.arm(0.0).reason == "arming refused: estimator not ready: aligning"  # the cause, first
    c.estimator_problem, c.height_uncertainty_m = None, 0.3
    assert c.arm(0.0).accepted
    c.update_state(state(0.1, p=(0.0, 0.0, 0.39)))
    assert c.landed_state == LandedState.ON_GROUND  # armed, not taken off: on the ground too


def test_the_prearm_verdict_is_announced_when_it_changes_while_disarmed():
    c = Commander(default_parameters())
    c.update_state(state(0.0))
    c.estimator_problem = "estimator not ready: aligning: IMU at rest for 0.2 s of 1.0 s"
    t, _ = fly(c, 0.0, 0.5)
    c.estimator_problem = "estimator not ready: aligning: IMU at rest for 0.7 s of 1.0 s"  # figures only
    t, _ = fly(c, t, 0.5)
    c.estimator_problem = None
    t, _ = fly(c, t, 0.5)
    assert [text for _, text in c.drain_events()] == [
        "Preflight Fail: estimator not ready: aligning: IMU at rest for 0.2 s of 1.0 s",
        "ready to arm",
    ]
    fly(c, t, 1.0)
    assert c.drain_events() == []  # ready, and said so: nothing more


def test_takeoff_climbs_to_takeoff_altitude_then_holds(commander):
    assert commander.arm(0.0).accepted
    assert commander.takeoff(0.0).accepted
    assert commander.mode == FlightMode.AUTO_TAKEOFF
    assert commander.landed_state == LandedState.TAKEOFF
    t, out = fly(commander, 0.0, 6.0)
    assert commander.mode == FlightMode.AUTO_LOITER
    assert out.reference.position_m == pytest.approx((0.0, 0.0, 2.5))
    assert commander.landed_state == LandedState.IN_AIR


def test_takeoff_reference_is_smooth_and_within_limits(commander):
    commander.arm(0.0)
    commander.takeoff(0.0, 2.0)
    prev = None
    climb = commander.params["MPC_TKO_SPEED"]
    for k in range(2000):
        out = commander.step(k * DT, DT)
        ref = out.reference
        assert abs(ref.velocity_m_s[2]) <= climb + 1e-9
        assert abs(ref.acceleration_m_s2[2]) <= 2.0 + 1e-6  # MPC_ACC_HOR
        if prev is not None:
            assert abs(ref.position_m[2] - prev.position_m[2]) <= climb * DT + 1e-9
        prev = ref
        commander.update_state(state(k * DT, ref.position_m, ref.velocity_m_s))


def test_land_detects_touchdown_and_disarms(commander):
    commander.arm(0.0)
    commander.takeoff(0.0)
    t, _ = fly(commander, 0.0, 6.0)
    assert commander.land(t).accepted
    assert commander.landed_state == LandedState.LANDING
    # follow the reference down but stop at the ground (as the plant does)
    for _ in range(int(10 / DT)):
        out = commander.step(t, DT)
        if out.motors == Motors.FLY:
            ref = out.reference
            z = max(ref.position_m[2], 0.0)
            vz = ref.velocity_m_s[2] if z > 0.0 else 0.0
            commander.update_state(state(t, (0.0, 0.0, z), (0.0, 0.0, vz)))
        t += DT
        if not commander.armed:
            break
    assert not commander.armed
    events = [text for _, text in commander.drain_events()]
    assert "landing detected" in events and "landed: disarmed" in events


def test_offboard_needs_a_stream_and_falls_back_to_hold(commander):
    commander.arm(0.0)
    out = commander.set_mode(0.0, FlightMode.OFFBOARD)
    assert out.result == DENIED and "setpoint" in out.reason
    for k in range(5):
        commander.offboard_setpoint(OffboardSetpoint(k * 0.05, position=(1.0, 0.0, 2.0)))
    assert commander.set_mode(0.25, FlightMode.OFFBOARD).accepted
    assert commander.phase == Phase.OFFBOARD
    t, out = fly(commander, 0.25, 0.5)
    assert out.motors == Motors.FLY
    # no more setpoints: after COM_OF_LOSS_T (1 s of simulation time) the vehicle holds
    t, out = fly(commander, t, 1.0)
    assert commander.mode == FlightMode.AUTO_LOITER
    assert any("offboard setpoints lost" in text for _, text in commander.drain_events())


def test_offboard_position_step_becomes_a_smooth_transition(commander):
    commander.arm(0.0)
    t = 0.0
    for _ in range(3):
        commander.offboard_setpoint(OffboardSetpoint(t, position=(0.0, 0.0, 2.0)))
        t += 0.02
    commander.set_mode(t, FlightMode.OFFBOARD)
    top_speed = 0.0
    for k in range(int(8 / DT)):
        now = t + k * DT
        if k % 10 == 0:
            commander.offboard_setpoint(OffboardSetpoint(now, position=(3.0, 0.0, 2.0)))
        out = commander.step(now, DT)
        ref = out.reference
        if out.motors == Motors.FLY:
            commander.update_state(state(now, ref.position_m, ref.velocity_m_s))
            top_speed = max(top_speed, math.hypot(*ref.velocity_m_s))
    assert ref.position_m == pytest.approx((3.0, 0.0, 2.0), abs=1e-3)
    assert top_speed <= 2.0 * 1.05  # MPC_XY_VEL_MAX


def test_rtl_returns_home_and_lands(commander):
    commander.arm(0.0)
    for k in range(3):
        commander.offboard_setpoint(OffboardSetpoint(k * 0.02, position=(4.0, 3.0, 2.0)))
    commander.set_mode(0.06, FlightMode.OFFBOARD)
    t = 0.06
    for k in range(int(10 / DT)):
        if k % 10 == 0:
            commander.offboard_setpoint(OffboardSetpoint(t, position=(4.0, 3.0, 2.0)))
        out = commander.step(t, DT)
        if out.motors == Motors.FLY:
            ref = out.reference
            commander.update_state(state(t, ref.position_m, ref.velocity_m_s))
        t += DT
    assert commander.state.position_m == pytest.approx((4.0, 3.0, 2.0), abs=1e-3)
    assert commander.return_to_launch(t).accepted
    highest = 0.0
    for _ in range(int(40 / DT)):
        out = commander.step(t, DT)
        if out.motors == Motors.FLY:
            ref = out.reference
            z = max(ref.position_m[2], 0.0)
            highest = max(highest, z)
            commander.update_state(
                state(
                    t,
                    (ref.position_m[0], ref.position_m[1], z),
                    ref.velocity_m_s if z > 0 else (0.0, 0.0, 0.0),
                )
            )
        t += DT
        if not commander.armed:
            break
    assert not commander.armed
    assert highest == pytest.approx(5.0, abs=0.01)  # RTL_RETURN_ALT
    assert commander.state.position_m[:2] == pytest.approx((0.0, 0.0), abs=1e-3)


def test_disarm_in_air_needs_force(commander):
    commander.arm(0.0)
    commander.takeoff(0.0)
    t, _ = fly(commander, 0.0, 5.0)
    assert commander.disarm(t).result == DENIED
    assert commander.disarm(t, force=True).accepted
    assert commander.step(t, DT).motors == Motors.OFF


def test_auto_disarm_when_no_takeoff(commander):
    commander.arm(0.0)
    assert commander.step(5.0, DT).motors == Motors.IDLE
    assert commander.step(10.5, DT).motors == Motors.OFF
    assert not commander.armed


def test_px4_mode_numbers():
    assert FlightMode.OFFBOARD.custom_mode == 393216
    assert FlightMode.POSCTL.custom_mode == 196608
    assert FlightMode.AUTO_MISSION.custom_mode == 67371008
    assert FlightMode.from_custom_mode(FlightMode.AUTO_RTL.custom_mode) == FlightMode.AUTO_RTL
    assert FlightMode.AUTO_LOITER.px4_name == "AUTO.LOITER"
