"""MANUAL_CONTROL on the wire: POSCTL flown from the sticks as PX4's position mode, and the sticks'
bad input (out of range, not an integer, a flood, a manual mode or an arm without a stream),
refused with a reason and never a crash. In simulation time, the whole stack in-process, the
messages as a ground station sends them. The other manual modes: tests/autopilot/guidance/test_manual.py; the
override and the loss of the stream: test_rc_override_loss.py."""

from __future__ import annotations

import copy
import copyreg
import math
import struct
from types import SimpleNamespace

import pytest
from pymavlink.dialects.v20 import common as m

from autopilot.commander.modes import (
    MAIN_ACRO,
    MAIN_ALTCTL,
    MAIN_MANUAL,
    MAIN_POSCTL,
    MAIN_STABILIZED,
    FlightMode,
)
from autopilot.guidance.manual import ManualGuidance, ManualLimits
from autopilot.guidance.sticks import Sticks
from autopilot.mavlink.manual import decode_sticks
from quadcommon.trajectories import Reference
from tests.sitl.test_params_failsafes import take_off
from tests.stack import Gcs, make_stack

POSCTL = FlightMode.POSCTL.custom_mode
LOITER = FlightMode.AUTO_LOITER.custom_mode
ZERO3 = (0.0, 0.0, 0.0)
MANUAL_MAINS = (MAIN_MANUAL, MAIN_STABILIZED, MAIN_ALTCTL, MAIN_POSCTL, MAIN_ACRO)


# -- helpers shared by the manual-mode tests ----------------------------------------------------------
# The takeoffs flown in this process, by (altitude, controller); pymavlink's codec keeps precompiled
# struct.Struct objects, which copy by their format string.
_AIRBORNE: dict[tuple[float, str], tuple] = {}
copyreg.pickle(struct.Struct, lambda s: (struct.Struct, (s.format,)))


def airborne(altitude: float = 2.5, controller: str = "intbs_nlhinf"):
    """A vehicle holding at ``altitude`` in AUTO.LOITER (the takeoff the failsafe tests use): a copy
    of the one takeoff to it this process flies, the same as flying it again (the stack is
    deterministic)."""
    key = (altitude, controller)
    if key not in _AIRBORNE:
        stack = make_stack(controller=controller)
        gcs = Gcs(stack)
        gcs.wait_heartbeat()
        take_off(gcs, altitude)
        _AIRBORNE[key] = (stack, gcs)
    return copy.deepcopy(_AIRBORNE[key])


def hold_sticks(stack, gcs, seconds: float, x=0, y=0, z=500, r=0, every_s: float = 0.1, sample=None) -> None:
    """MANUAL_CONTROL every ``every_s`` (10 Hz, as MAVSDK's example sends it) for ``seconds`` of
    simulation; ``sample(stack)`` after each."""
    end = stack.t + seconds - 1e-9
    while stack.t < end:
        gcs.conn.mav.manual_control_send(gcs.system_id, x, y, z, r, 0)
        stack.run_for(every_s)
        if sample is not None:
            sample(stack)


def enter_mode(stack, gcs, main: int) -> None:
    """The sticks streaming, then DO_SET_MODE to a manual mode (accepted)."""
    hold_sticks(stack, gcs, 0.3)
    assert gcs.command(m.MAV_CMD_DO_SET_MODE, 1, main, 0).result == m.MAV_RESULT_ACCEPTED
    assert stack.autopilot.commander.mode == FlightMode.from_px4(main, 0)


def truth(stack):
    return stack.sim.plant.truth()


def texts(gcs) -> str:
    return "".join(gcs.statustext)


def flying_in_posctl():
    stack, gcs = airborne()
    enter_mode(stack, gcs, MAIN_POSCTL)
    hold_sticks(stack, gcs, 2.0)
    return stack, gcs


# -- POSCTL -----------------------------------------------------------------------------------------
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


def test_posctl_holds_until_a_stick_moves():
    stack, gcs = airborne()
    held = truth(stack).position_m
    enter_mode(stack, gcs, MAIN_POSCTL)
    hold_sticks(stack, gcs, 3.0, x=50)  # inside the deadzone: held as AUTO.LOITER would
    assert math.dist(truth(stack).position_m, held) < 0.02


def test_held_deflection_in_hold_does_not_move_the_vehicle():
    stack, gcs = airborne()
    held = truth(stack).position_m
    hold_sticks(stack, gcs, 3.0, x=1000)  # deflected from the stream's first sample: no movement
    assert stack.autopilot.commander.mode == FlightMode.AUTO_LOITER
    assert math.dist(truth(stack).position_m, held) < 0.05


def test_the_reference_is_smooth_within_the_limits_and_never_below_ground():
    limits = ManualLimits(speed_horizontal=2.0, acceleration=2.0, speed_down=1.0)
    guidance = ManualGuidance()
    ref = Reference((0.0, 0.0, 0.3), ZERO3, ZERO3, 0.0, 0.0, 0.0)
    state = SimpleNamespace(position_m=ref.position_m, velocity_m_s=ZERO3, euler_rad=ZERO3)
    dt = 0.002
    sticks = Sticks(0.0, forward=1.0, up=-1.0)
    assert guidance.engage_if_moved(sticks, limits)
    speeds = []
    for _ in range(1000):
        new = guidance.position(dt, ref, state, sticks, limits).reference
        dv = math.dist(new.velocity_m_s, ref.velocity_m_s)
        assert dv <= limits.acceleration * dt * math.sqrt(3) + 1e-12
        assert new.position_m[2] >= 0.0
        ref = new
        speeds.append(new.velocity_m_s[0])
    assert speeds[-1] == pytest.approx(2.0)  # (1 - deadzone) rescaled: full stick is full speed
    assert ref.position_m[2] == 0.0 and ref.velocity_m_s[2] == 0.0
    # inside the deadzone: centred
    inside = ManualGuidance()
    assert not inside.engage_if_moved(Sticks(10.0, forward=0.09, left=-0.09, up=0.05, yaw=0.1), limits)
    assert inside.engage_if_moved(Sticks(10.1, forward=0.11), limits)
    assert not ManualGuidance().engage_if_moved(None, limits)


# -- bad input ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("axis, value", [("x", 1001), ("y", -32768), ("r", 5000), ("z", 1200)])
def test_a_stick_outside_its_range_is_refused_with_its_axis_named(axis, value):
    stack, gcs = flying_in_posctl()
    held = truth(stack).position_m
    sticks = {"x": 0, "y": 0, "z": 500, "r": 0, axis: value}
    for _ in range(3):  # the good stream goes on (else the loss would act), the bad one is refused
        gcs.conn.mav.manual_control_send(gcs.system_id, sticks["x"], sticks["y"], sticks["z"], sticks["r"], 0)
        hold_sticks(stack, gcs, 0.1)
    assert math.dist(truth(stack).position_m, held) < 0.05
    gcs.wait(lambda g: f"MANUAL_CONTROL {axis}={value}" in texts(g), sim_timeout=2.0, what="the refusal")
    assert stack.autopilot.commander.mode == FlightMode.POSCTL


def test_an_axis_sent_as_int16_max_is_not_sent_it_reads_as_centred():
    stack, gcs = flying_in_posctl()
    start = truth(stack).position_m
    hold_sticks(stack, gcs, 2.0, x=1000, y=32767, z=32767, r=32767)  # only the pitch stick is sent
    hold_sticks(stack, gcs, 3.0)
    end = truth(stack).position_m
    assert end[0] - start[0] > 1.0 and abs(end[1] - start[1]) < 0.05 and abs(end[2] - start[2]) < 0.05


def test_a_value_that_is_not_an_integer_is_refused_at_the_edge():
    """pymavlink decodes int16, so this only reaches an in-process caller: refused all the same."""
    for bad in (math.nan, math.inf, 0.5):
        msg = SimpleNamespace(x=0, y=bad, z=500, r=0)
        sticks, reason = decode_sticks(msg, 1.0)
        assert sticks is None and "MANUAL_CONTROL y=" in reason and "not an integer" in reason
    below = decode_sticks(SimpleNamespace(x=0, y=0, z=-400, r=0), 1.0)[0]  # PX4 clamps z < 0: full down
    assert below is not None and below.up == -1.0


def test_a_flood_of_sticks_is_bounded_the_latest_counts():
    stack, gcs = flying_in_posctl()
    start = truth(stack).position_m
    ap = stack.autopilot
    refusals_before = sum(1 for t in gcs.statustext if "MANUAL_CONTROL" in t)
    for k in range(5000):  # one frame's worth of traffic: 5,000 MANUAL_CONTROL, every other bad
        if k % 2:
            gcs.conn.mav.manual_control_send(gcs.system_id, 2000, 0, 500, 0, 0)
        else:
            gcs.conn.mav.manual_control_send(gcs.system_id, 0, 0, 500, 0, 0)
    gcs.conn.mav.manual_control_send(gcs.system_id, 1000, 0, 500, 0, 0)  # the latest: full forward
    stack.run_for(0.05)
    assert ap.refusals.refused >= 2500  # every bad one refused
    assert ap.commander.sticks.sticks.forward == 1.0  # of the good ones, the latest counts
    stack.run_for(0.4)
    assert truth(stack).velocity_m_s[0] > 0.1
    refusals = sum(1 for t in gcs.statustext if "MANUAL_CONTROL" in t) - refusals_before
    assert refusals <= 2  # the refusal is said once a second, not 2,500 times
    assert not ap.faults.counts
    hold_sticks(stack, gcs, 2.0, x=1000)
    assert truth(stack).position_m[0] - start[0] > 0.5  # the stream flies on, from the latest sticks
    assert ap.commander.mode == FlightMode.POSCTL


@pytest.mark.parametrize("main", MANUAL_MAINS)
def test_a_manual_mode_without_sticks_is_refused_with_the_reason(main):
    stack, gcs = airborne()
    ack = gcs.command(m.MAV_CMD_DO_SET_MODE, 1, main, 0)
    assert ack.result == m.MAV_RESULT_DENIED
    name = FlightMode.from_px4(main, 0).px4_name
    gcs.wait(lambda g: f"Switching to {name} is currently not possible: no manual control input" in texts(g),
             sim_timeout=1.0, what="the refusal")  # fmt: skip
    stack.run_for(1.0)
    assert gcs.custom_mode == LOITER


def test_arming_in_a_manual_mode_needs_the_sticks():
    stack = make_stack()
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    enter_mode(stack, gcs, MAIN_ALTCTL)  # selected on the ground, with the sticks
    stack.run_for(1.0)  # the sticks stop
    ack = gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    assert ack.result == m.MAV_RESULT_DENIED
    gcs.wait(lambda g: "arming refused: no manual control input (ALTCTL" in texts(g), sim_timeout=1.0,
             what="the refusal")  # fmt: skip
    hold_sticks(stack, gcs, 0.3)
    assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == m.MAV_RESULT_ACCEPTED
