"""POSCTL on the sticks: MANUAL_CONTROL flies the vehicle as PX4's position mode does (in
simulation time, the whole stack in-process, the messages as a ground station sends them)."""

import math

import pytest
from pymavlink.dialects.v20 import common as m

from autopilot.commander.modes import FlightMode
from autopilot.guidance.manual import ManualGuidance, ManualLimits, Sticks
from quadcommon.trajectories import Reference

from ..sitl.test_params_failsafes import take_off
from ..stack import Gcs, make_stack

POSCTL = FlightMode.POSCTL.custom_mode
ZERO3 = (0.0, 0.0, 0.0)


def airborne():
    """A vehicle holding at 2.5 m in AUTO.LOITER (the takeoff the failsafe tests use)."""
    stack = make_stack()
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    take_off(gcs, 2.5)
    return stack, gcs


def flying_in_posctl():
    stack, gcs = airborne()
    assert gcs.command(m.MAV_CMD_DO_SET_MODE, 1, 3, 0).result == m.MAV_RESULT_ACCEPTED  # POSCTL
    gcs.wait(lambda g: g.custom_mode == POSCTL, sim_timeout=2.0, what="POSCTL in the heartbeat")
    stack.run_for(2.0)
    return stack, gcs


def hold_sticks(stack, gcs, seconds: float, x=0, y=0, z=500, r=0, every_s: float = 0.1) -> None:
    """MANUAL_CONTROL at 10 Hz (as MAVSDK's example sends it) for ``seconds`` of simulation."""
    end = stack.t + seconds
    while stack.t < end:
        gcs.conn.mav.manual_control_send(gcs.system_id, x, y, z, r, 0)
        stack.run_for(every_s)


def truth(stack):
    return stack.sim.plant.truth()


def test_sticks_fly_forward_left_up_and_yaw_in_the_heading_frame_then_hold():
    stack, gcs = flying_in_posctl()
    start = truth(stack).position_m
    hold_sticks(stack, gcs, 3.0, x=1000)  # full forward: +x (heading 0)
    moved = truth(stack).position_m
    assert moved[0] - start[0] > 2.0 and abs(moved[1] - start[1]) < 0.1 and abs(moved[2] - start[2]) < 0.1
    assert math.hypot(*truth(stack).velocity_m_s[:2]) <= 2.0 * 1.05  # MPC_VEL_MANUAL
    hold_sticks(stack, gcs, 4.0)  # centred: brakes and holds
    stopped = truth(stack).position_m
    hold_sticks(stack, gcs, 2.0)
    assert math.dist(truth(stack).position_m, stopped) < 0.02
    # roll stick right = -y (the paper's y is left); throttle up = +z
    before = truth(stack).position_m
    hold_sticks(stack, gcs, 2.0, y=1000, z=1000)
    hold_sticks(stack, gcs, 3.0)
    after = truth(stack).position_m
    assert after[1] - before[1] < -1.0 and after[2] - before[2] > 1.0
    # yaw stick clockwise (r > 0) = negative yaw in the paper's frame
    yaw0 = truth(stack).euler_rad[2]
    hold_sticks(stack, gcs, 1.0, r=500)
    hold_sticks(stack, gcs, 2.0)
    yaw1 = truth(stack).euler_rad[2]
    turned = math.remainder(yaw1 - yaw0, 2 * math.pi)
    assert turned < -0.5
    # and forward now goes along the new heading
    p0 = truth(stack).position_m
    hold_sticks(stack, gcs, 2.0, x=1000)
    hold_sticks(stack, gcs, 3.0)
    p1 = truth(stack).position_m
    course = math.atan2(p1[1] - p0[1], p1[0] - p0[0])
    assert abs(math.remainder(course - yaw1, 2 * math.pi)) < 0.1
    assert stack.autopilot.commander.mode == FlightMode.POSCTL


def test_stale_sticks_read_as_centred_and_the_vehicle_says_so_once():
    stack, gcs = flying_in_posctl()
    hold_sticks(stack, gcs, 1.0, x=1000)
    stack.run_for(6.0)  # no MANUAL_CONTROL for 6 s (COM_RC_LOSS_T 0.5 s): brake and hold
    held = truth(stack).position_m
    stack.run_for(2.0)
    assert math.dist(truth(stack).position_m, held) < 0.02
    gcs.wait(lambda g: any("manual control lost" in s for s in g.statustext), sim_timeout=1.0,
             what="the loss notice")  # fmt: skip
    assert sum("manual control lost" in s for s in gcs.statustext) == 1


def test_sticks_outside_posctl_are_kept_but_not_flown():
    stack, gcs = airborne()
    stack.run_for(2.0)  # AUTO.LOITER
    held = truth(stack).position_m
    hold_sticks(stack, gcs, 2.0, x=1000)
    assert math.dist(truth(stack).position_m, held) < 0.05


@pytest.mark.parametrize("axis, value", [("x", 1001), ("y", -32768), ("r", 5000), ("z", 1200)])
def test_a_stick_outside_its_range_is_refused_with_its_axis_named(axis, value):
    stack, gcs = flying_in_posctl()
    held = truth(stack).position_m
    sticks = {"x": 0, "y": 0, "z": 500, "r": 0, axis: value}
    for _ in range(20):
        gcs.conn.mav.manual_control_send(gcs.system_id, sticks["x"], sticks["y"], sticks["z"], sticks["r"], 0)
        stack.run_for(0.1)
    assert math.dist(truth(stack).position_m, held) < 0.05
    gcs.wait(lambda g: any(f"MANUAL_CONTROL {axis}={value}" in s for s in g.statustext), sim_timeout=2.0,
             what="the refusal")  # fmt: skip


def test_an_axis_sent_as_int16_max_is_not_sent_it_reads_as_centred():
    stack, gcs = flying_in_posctl()
    start = truth(stack).position_m
    hold_sticks(stack, gcs, 2.0, x=1000, y=32767, z=32767, r=32767)  # only the pitch stick is sent
    stack.run_for(3.0)
    end = truth(stack).position_m
    assert end[0] - start[0] > 1.0 and abs(end[1] - start[1]) < 0.05 and abs(end[2] - start[2]) < 0.05


def test_the_reference_is_smooth_within_the_limits_and_never_below_ground():
    limits = ManualLimits(speed_horizontal=2.0, acceleration=2.0, speed_down=1.0)
    guidance = ManualGuidance()
    ref = Reference((0.0, 0.0, 0.3), ZERO3, ZERO3, 0.0, 0.0, 0.0)
    dt = 0.002
    guidance.update(Sticks(0.0, forward=1.0, up=-1.0))
    assert guidance.engage_if_moved(0.0, limits)
    speeds = []
    for k in range(1000):
        new = guidance.reference(k * dt * 0.2, dt, ref, limits)  # fresh: t stays within the loss time
        dv = math.dist(new.velocity_m_s, ref.velocity_m_s)
        assert dv <= limits.acceleration * dt * math.sqrt(3) + 1e-12
        assert new.position_m[2] >= 0.0
        ref = new
        speeds.append(new.velocity_m_s[0])
    assert speeds[-1] == pytest.approx(2.0)  # (1 - deadzone) rescaled: full stick is full speed
    assert ref.position_m[2] == 0.0 and ref.velocity_m_s[2] == 0.0
    # inside the deadzone: centred
    inside = ManualGuidance()
    inside.update(Sticks(10.0, forward=0.09, left=-0.09, up=0.05, yaw=0.1))
    assert not inside.engage_if_moved(10.0, limits)
    inside.update(Sticks(10.1, forward=0.11))
    assert inside.engage_if_moved(10.1, limits)
