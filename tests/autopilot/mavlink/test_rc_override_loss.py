"""PX4's stick override and manual control loss, on the wire in simulation time (the whole stack
in-process): moving sticks take over the AUTO modes (and OFFBOARD when COM_RC_OVERRIDE says so)
into POSCTL; losing the sticks in a manual mode acts by NAV_RCL_ACT, in the other modes it is
announced only; each with PX4's STATUSTEXT."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as m

from autopilot.commander.modes import MAIN_ALTCTL, MAIN_POSCTL, MAIN_STABILIZED, FlightMode
from tests.autopilot.mavlink.test_manual import airborne, enter_mode, hold_sticks, texts, truth
from tests.sitl.test_params_failsafes import INT32, param_set

LOITER, RTL, LAND = FlightMode.AUTO_LOITER, FlightMode.AUTO_RTL, FlightMode.AUTO_LAND


def mode(stack) -> FlightMode:
    return stack.autopilot.commander.mode


def statustexts(stack, gcs, seconds: float = 0.2) -> str:
    """Every STATUSTEXT so far (the ground station reads what is waiting for ``seconds``)."""
    end = stack.t + seconds
    gcs.wait(lambda g: g.sim_time >= end, sim_timeout=seconds + 1.0, what="the texts")
    return texts(gcs)


# -- manual control loss ----------------------------------------------------------------------------
@pytest.mark.timeout(120)
@pytest.mark.parametrize(
    "action, main, after, doing",
    [
        (1, MAIN_ALTCTL, LOITER, "holding"),
        (2, MAIN_POSCTL, RTL, "returning to launch"),
        (3, MAIN_STABILIZED, LAND, "landing"),
    ],
)
def test_losing_the_sticks_in_a_manual_mode_acts_by_nav_rcl_act(action, main, after, doing):
    stack, gcs = airborne(3.0)
    assert param_set(gcs, "NAV_RCL_ACT", action, INT32) is not None
    enter_mode(stack, gcs, main)
    hold_sticks(stack, gcs, 2.0, x=200)
    last_sticks = stack.t - 0.1
    name = FlightMode.from_px4(main, 0).px4_name
    while mode(stack).is_manual:
        stack.run_for(0.01)
        assert stack.t - last_sticks < 0.6, "no action 0.6 s after the last sticks"
    assert stack.t - last_sticks == pytest.approx(0.5, abs=0.02)  # COM_RC_LOSS_T
    assert mode(stack) == after
    said = statustexts(stack, gcs)
    assert "Manual control lost" in said
    assert f"manual control lost in {name}: {doing} (NAV_RCL_ACT {action})" in said
    # Whatever the action, it ends on the ground, disarmed (hold: landed by a command).
    if after == LOITER:
        stack.run_for(3.0)
        assert truth(stack).position_m[2] > 2.0  # holding
        assert gcs.command(m.MAV_CMD_NAV_LAND).result == m.MAV_RESULT_ACCEPTED
    gcs.wait(lambda g: not g.armed, sim_timeout=30.0, what="landed and disarmed")
    assert truth(stack).position_m[2] < 0.01


def test_the_sticks_back_are_announced_and_take_over_the_failsafe_again():
    stack, gcs = airborne(3.0)
    assert param_set(gcs, "NAV_RCL_ACT", 1, INT32) is not None
    enter_mode(stack, gcs, MAIN_ALTCTL)
    hold_sticks(stack, gcs, 1.0)
    stack.run_for(2.0)  # lost: holding
    assert mode(stack) == LOITER
    hold_sticks(stack, gcs, 0.5)  # back, held still: announced, no takeover
    assert "Manual control regained after 2.1s" in statustexts(stack, gcs)  # since the last sample
    assert mode(stack) == LOITER
    hold_sticks(stack, gcs, 1.0, x=400)  # and moved: the pilot takes over (POSCTL)
    assert mode(stack) == FlightMode.POSCTL
    assert "Pilot took over using sticks" in statustexts(stack, gcs)


def test_losing_the_sticks_outside_a_manual_mode_is_announced_only():
    stack, gcs = airborne(3.0)
    hold_sticks(stack, gcs, 1.0)  # a stream while AUTO.LOITER flies
    stack.run_for(2.0)
    said = statustexts(stack, gcs)
    assert "Manual control lost" in said and "NAV_RCL_ACT" not in said
    assert mode(stack) == LOITER and truth(stack).position_m[2] > 2.9


# -- stick override --------------------------------------------------------------------------------------
def test_moving_sticks_take_over_hold_into_posctl_and_fly():
    stack, gcs = airborne(3.0)
    hold_sticks(stack, gcs, 1.0)  # centred sticks streaming: nothing happens
    assert mode(stack) == LOITER
    start = truth(stack).position_m
    hold_sticks(stack, gcs, 2.0, x=1000)  # a stick moves
    assert mode(stack) == FlightMode.POSCTL
    assert "Pilot took over using sticks" in statustexts(stack, gcs)
    hold_sticks(stack, gcs, 1.0, x=1000)
    assert truth(stack).position_m[0] - start[0] > 1.0  # and the sticks fly it


def test_the_override_takes_over_a_mission_and_can_be_disabled():
    stack, gcs = airborne(3.0)
    nan = math.nan
    ack = gcs.command(m.MAV_CMD_DO_REPOSITION, -1, 1, 0, nan, *_here_plus(gcs, 30.0), 491.0)
    assert ack.result == m.MAV_RESULT_ACCEPTED  # a long way to fly (AUTO.LOITER repositioning)
    assert param_set(gcs, "COM_RC_OVERRIDE", 0, INT32) is not None  # disabled
    hold_sticks(stack, gcs, 0.5)
    hold_sticks(stack, gcs, 1.0, y=800, r=-600)
    assert mode(stack) == LOITER and "Pilot took over" not in statustexts(stack, gcs)
    assert param_set(gcs, "COM_RC_OVERRIDE", 1, INT32) is not None  # AUTO modes (PX4's default)
    hold_sticks(stack, gcs, 0.5, y=-800)
    assert mode(stack) == FlightMode.POSCTL
    hold_sticks(stack, gcs, 3.0)  # centred: brakes and holds, the reposition abandoned
    here = truth(stack).position_m
    hold_sticks(stack, gcs, 2.0)
    assert math.dist(truth(stack).position_m, here) < 0.05


def _here_plus(gcs, north: float) -> tuple[float, float]:
    """Latitude, longitude (deg) ``north`` m north of the vehicle's home (COMMAND_LONG params)."""
    from quadcommon import frames
    from tests.sitl.test_reposition import HOME

    lat, lon, _ = frames.ned_to_geodetic(north, 0.0, 0.0, HOME)
    return lat, lon


@pytest.mark.timeout(60)
def test_offboard_is_taken_over_only_when_com_rc_override_says_so():
    stack, gcs = airborne(3.0)

    def stream(seconds: float, x: int = 0) -> None:  # setpoints and sticks, both at 10 Hz
        end = stack.t + seconds - 1e-9
        while stack.t < end:
            gcs.send_position_setpoint(0.0, 0.0, 3.0)
            hold_sticks(stack, gcs, 0.1, x=x)

    stream(0.3)
    assert gcs.command(m.MAV_CMD_DO_SET_MODE, 1, 6, 0).result == m.MAV_RESULT_ACCEPTED
    stream(1.0)
    stream(1.0, x=1000)  # PX4's default (bit 0 only): OFFBOARD is not taken over
    assert mode(stack) == FlightMode.OFFBOARD
    assert param_set(gcs, "COM_RC_OVERRIDE", 3, INT32) is not None
    stream(0.5)
    stream(0.5, x=-1000)
    assert mode(stack) == FlightMode.POSCTL
    assert "Pilot took over using sticks" in statustexts(stack, gcs)


def test_a_slow_stick_below_com_rc_stick_ov_does_not_take_over():
    stack, gcs = airborne(3.0)
    hold_sticks(stack, gcs, 0.5)
    for k in range(20):  # 0.2 of full travel per second, below the 30 %/s threshold
        hold_sticks(stack, gcs, 0.1, x=20 * k)
    assert mode(stack) == LOITER
    assert param_set(gcs, "COM_RC_STICK_OV", 10.0).param_value == pytest.approx(10.0)
    for k in range(20):  # the same ramp, now above the threshold
        hold_sticks(stack, gcs, 0.1, x=380 - 20 * k)
    assert mode(stack) == FlightMode.POSCTL
