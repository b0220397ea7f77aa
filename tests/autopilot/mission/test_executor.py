"""Flying a mission (pure): legs, acceptance, hold times, speed changes, timed curves, land/RTL."""

import math
import sys

import numpy as np
import pytest

from autopilot.guidance.planner import Limits
from autopilot.mavlink.codec import mavlink
from autopilot.mission.executor import (
    MissionAction,
    MissionExecutor,
    MissionState,
    PlanContext,
    check_mission,
)
from autopilot.mission.items import CMD_TIMED, WireItem, parse_item
from quadcommon import frames
from quadcommon.trajectories import Reference, circle

m = mavlink
HOME = (47.397742, 8.545594, 488.0)
DT = 0.002
LIMITS = Limits(speed_horizontal=2.0, speed_up=1.5, speed_down=1.0, acceleration=2.0, yaw_rate=1.0)
CTX = PlanContext((0.0, 0.0, 0.0), LIMITS, 0.2, 2.5, 1.0)
REST = Reference((0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))


def wire(seq, command, frame=m.MAV_FRAME_LOCAL_NED, p=(0.0, 0.0, 0.0, math.nan), xyz_paper=(0.0, 0.0, 0.0),
         autocontinue=1, z=None):  # fmt: skip
    """A MISSION_ITEM_INT (as received) for a paper-frame position, x/y quantised as on the wire."""
    n, e, d = frames.vector_to_ned(xyz_paper)
    return WireItem(
        seq, frame, command, 0, autocontinue, *p, round(n * 1e4), round(e * 1e4), d if z is None else z
    )


def mission(*wires):
    items = []
    for w in wires:
        items.append(parse_item(w, HOME, items[-1] if items else None))
    return items


def fly(ex, t0, seconds, position=None, stop_on_action=True):
    """Step with a vehicle that follows the reference exactly (or sits at ``position``)."""
    t, refs, actions = t0, [], []
    pos = REST.position_m
    for _ in range(int(round(seconds / DT))):
        out = ex.step(t, pos if position is None else position)
        refs.append((t, out.reference))
        pos = out.reference.position_m
        if out.action != MissionAction.NONE:
            actions.append(out.action)
            if stop_on_action:
                break
        t += DT
    return t, refs, actions


def arrays(refs):
    t = np.array([r[0] for r in refs])
    p = np.array([r[1].position_m for r in refs])
    v = np.array([r[1].velocity_m_s for r in refs])
    a = np.array([r[1].acceleration_m_s2 for r in refs])
    return t, p, v, a


def assert_smooth(refs, limits=LIMITS):
    """No steps in p, v, a; speeds and acceleration within the limits (planner tolerance)."""
    t, p, v, a = arrays(refs)
    assert np.abs(np.diff(p, axis=0)).max() <= 2.0 * 1.05 * DT + 1e-9
    assert np.abs(np.diff(v, axis=0)).max() <= limits.acceleration * 1.05 * DT + 1e-6
    assert np.abs(np.diff(a, axis=0)).max() <= 20.0 * DT  # a continuous (jerk < 20 m/s^3): no jumps
    assert np.hypot(v[:, 0], v[:, 1]).max() <= limits.speed_horizontal * 1.05
    assert v[:, 2].max() <= limits.speed_up * 1.05 and -v[:, 2].min() <= limits.speed_down * 1.05
    assert np.linalg.norm(a, axis=1).max() <= limits.acceleration * 1.06


def test_waypoint_mission_reaches_items_in_order_within_limits():
    items = mission(
        wire(0, m.MAV_CMD_NAV_TAKEOFF, z=-2.5),
        wire(1, m.MAV_CMD_NAV_WAYPOINT, xyz_paper=(3.0, 0.0, 2.5)),
        wire(2, m.MAV_CMD_NAV_WAYPOINT, p=(1.5, 0.0, 0.0, 90.0), xyz_paper=(3.0, -2.0, 3.0)),
        wire(3, m.MAV_CMD_DO_CHANGE_SPEED, m.MAV_FRAME_MISSION, p=(1.0, 0.5, -1.0, 0.0)),
        wire(4, m.MAV_CMD_NAV_LOITER_TIME, p=(2.0, 0.0, 0.0, 0.0), xyz_paper=(0.0, -2.0, 3.0)),
        wire(5, m.MAV_CMD_NAV_LAND, xyz_paper=(0.0, 0.0, 0.0)),
    )
    ex = MissionExecutor(items, HOME)
    assert ex.start(0.0, REST, CTX, on_ground=True) is None
    assert ex.state == MissionState.ACTIVE
    t, refs, actions = fly(ex, 0.0, 60.0)
    assert actions == [MissionAction.LAND]
    assert ex.drain_reached() == [0, 1, 2, 3, 4]
    assert ex.current_seq == 5 and ex.awaiting_landing
    assert refs[-1][1].position_m == pytest.approx((0.0, 0.0, 3.0), abs=1e-6)
    assert_smooth(refs)
    t_arr, p, v, _ = arrays(refs)
    # the waypoint's yaw (90 deg clockwise in NED) is -pi/2 in the paper frame, kept afterwards
    assert refs[-1][1].yaw_rad == pytest.approx(-math.pi / 2, abs=1e-6)
    # DO_CHANGE_SPEED 0.5 m/s: the leg to item 4 (2 m along -x) cruises at 0.5 m/s
    leg4 = (p[:, 1] < -1.99) & (p[:, 0] < 2.9) & (p[:, 0] > 0.1)
    assert np.hypot(v[leg4, 0], v[leg4, 1]).max() == pytest.approx(0.5, abs=1e-3)
    ex.landed()
    assert ex.drain_reached() == [5] and ex.state == MissionState.COMPLETE


def test_hold_time_counts_from_arrival_and_acceptance_radius_holds_the_reference():
    items = mission(
        wire(0, m.MAV_CMD_NAV_WAYPOINT, p=(3.0, 0.5, 0.0, math.nan), xyz_paper=(1.0, 0.0, 2.0)),
        wire(1, m.MAV_CMD_NAV_WAYPOINT, xyz_paper=(2.0, 0.0, 2.0)),
    )
    start = Reference((0.0, 0.0, 2.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    ex = MissionExecutor(items, HOME)
    ex.start(0.0, start, CTX, on_ground=False)
    # The vehicle is stuck 1 m away from the waypoint: the item is never reached.
    t, refs, _ = fly(ex, 0.0, 10.0, position=(0.0, 0.0, 2.0))
    assert ex.drain_reached() == [] and ex.current_seq == 0
    assert refs[-1][1].position_m == pytest.approx((1.0, 0.0, 2.0))
    # 0.4 m away, inside the 0.5 m acceptance radius: reached after the 3 s hold time.
    t, refs, _ = fly(ex, t, 2.9, position=(0.6, 0.0, 2.0))
    assert ex.drain_reached() == []
    t, refs, _ = fly(ex, t, 0.2, position=(0.6, 0.0, 2.0))
    assert ex.drain_reached() == [0] and ex.current_seq == 1


def timed_circle(rate_hz=10.0, duration_s=40.0, first_seq=1):
    traj = circle(0.5, math.pi / 20, (0.0, 0.0, 2.5), -2.0)
    wires = []
    for k, tk in enumerate(np.arange(0.0, duration_s + 1e-9, 1.0 / rate_hz)):
        ref = traj.sample(float(tk))
        wires.append(
            wire(first_seq + k, CMD_TIMED, p=(float(tk) + 10.0, 0.0, 0.0, 0.0), xyz_paper=ref.position_m)
        )
    return traj, wires


def test_timed_circle_is_flown_on_the_clock_and_matches_the_analytic_curve():
    traj, timed = timed_circle()
    items = mission(wire(0, m.MAV_CMD_NAV_TAKEOFF, z=-2.5), *timed)
    ex = MissionExecutor(items, HOME)
    ex.start(0.0, REST, CTX, on_ground=True)
    t, refs, actions = fly(ex, 0.0, 55.0)
    assert actions == []
    reached = ex.drain_reached()
    assert reached == list(range(len(items)))
    assert ex.state == MissionState.COMPLETE
    assert_smooth(refs)
    # item times count from the mission start (10 s for the first sample): the curve starts then
    t_arr, p, v, a = arrays(refs)
    on_curve = (t_arr >= 10.0) & (t_arr <= 50.0)
    expected = [traj.sample(tk - 10.0) for tk in t_arr[on_curve]]
    assert np.abs(p[on_curve] - [e.position_m for e in expected]).max() < 1e-4
    assert np.abs(v[on_curve] - [e.velocity_m_s for e in expected]).max() < 1e-3
    assert np.abs(a[on_curve] - [e.acceleration_m_s2 for e in expected]).max() < 2e-3
    # after the last sample the vehicle brakes and holds
    assert np.linalg.norm(v[-1]) < 1e-9


def test_timed_curve_late_start_is_shifted_and_resume_rejoins_mid_curve():
    traj, timed = timed_circle(duration_s=20.0, first_seq=0)
    items = mission(*timed)
    start = Reference((3.0, 0.0, 2.5), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    ex = MissionExecutor(items, HOME)
    ex.start(100.0, start, CTX, on_ground=False)  # the mission starts at t = 100 s
    t, refs, _ = fly(ex, 100.0, 15.0)
    reached = ex.drain_reached()
    assert reached == list(range(len(reached))) and 0 < len(reached) < len(items)
    ex.pause()
    current = ex.current_seq
    assert ex.state == MissionState.PAUSED and current == reached[-1] + 1
    held = refs[-1][1]
    assert ex.start(t, Reference(held.position_m, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), held.yaw_rad), CTX,
                    on_ground=False) is None  # fmt: skip
    t, refs2, _ = fly(ex, t, 30.0)
    assert ex.drain_reached() == list(range(current, len(items)))
    assert_smooth(refs2)


def test_rtl_item_hands_over_and_completes():
    items = mission(
        wire(0, m.MAV_CMD_NAV_WAYPOINT, xyz_paper=(1.0, 0.0, 2.0)),
        wire(1, m.MAV_CMD_NAV_RETURN_TO_LAUNCH, m.MAV_FRAME_MISSION, p=(0.0, 0.0, 0.0, 0.0)),
    )
    ex = MissionExecutor(items, HOME)
    ex.start(0.0, Reference((0.0, 0.0, 2.0), (0.0,) * 3, (0.0,) * 3), CTX, on_ground=False)
    t, refs, actions = fly(ex, 0.0, 20.0)
    assert actions == [MissionAction.RTL] and ex.drain_reached() == [0, 1]
    assert ex.state == MissionState.COMPLETE


def test_autocontinue_zero_waits_for_set_current():
    items = mission(
        wire(0, m.MAV_CMD_NAV_WAYPOINT, xyz_paper=(1.0, 0.0, 2.0), autocontinue=0),
        wire(1, m.MAV_CMD_NAV_WAYPOINT, xyz_paper=(2.0, 0.0, 2.0)),
    )
    ex = MissionExecutor(items, HOME)
    ex.start(0.0, Reference((0.0, 0.0, 2.0), (0.0,) * 3, (0.0,) * 3), CTX, on_ground=False)
    t, refs, _ = fly(ex, 0.0, 20.0)
    assert ex.drain_reached() == [0] and ex.current_seq == 1
    assert refs[-1][1].position_m == pytest.approx((1.0, 0.0, 2.0))
    assert ex.set_current(1)
    ex.start(t, refs[-1][1], CTX, on_ground=False)
    t, refs, _ = fly(ex, t, 10.0)
    assert ex.drain_reached() == [1] and ex.state == MissionState.COMPLETE


def test_global_frames_resolve_against_origin_and_home():
    lat, lon, _ = frames.ned_to_geodetic(10.0, -5.0, 0.0, HOME)
    w = WireItem(0, m.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT, m.MAV_CMD_NAV_WAYPOINT, 0, 1, 0.0, 0.0, 0.0,
                 math.nan, round(lat * 1e7), round(lon * 1e7), 4.0)  # fmt: skip
    it = parse_item(w, HOME)
    x, y, z = it.position.to_paper(HOME, (1.0, 1.0, 0.5))
    assert (x, y) == pytest.approx((10.0, 5.0), abs=0.02) and z == pytest.approx(4.5)
    amsl = parse_item(w._replace(frame=m.MAV_FRAME_GLOBAL_INT, z=500.0), HOME)
    assert amsl.position.to_paper(HOME, (1.0, 1.0, 0.5))[2] == pytest.approx(12.0)


def test_check_refuses_a_timed_curve_faster_than_the_limits():
    _, timed = timed_circle(duration_s=4.0, first_seq=0)
    fast = [w._replace(param1=w.param1 / 20.0) for w in timed]  # the same curve 20 times faster
    problem = check_mission(mission(*fast), HOME, LIMITS)
    assert (
        problem is not None
        and problem[0] == m.MAV_MISSION_INVALID_PARAM1
        and "timed items 0-40" in problem[1]
    )
    assert check_mission(mission(*timed), HOME, LIMITS) is None


def test_a_timed_curve_that_cannot_be_fitted_for_want_of_scipy_is_refused_with_the_reason(monkeypatch):
    """scipy.interpolate is imported at the first upload (autopilot/mission/curve.py): a broken
    installation refuses the mission (MISSION_ACK with an error) rather than leaving it unanswered."""
    _, timed = timed_circle(duration_s=4.0, first_seq=0)
    monkeypatch.setitem(sys.modules, "scipy.interpolate", None)  # "import scipy.interpolate" fails
    problem = check_mission(mission(*timed), HOME, LIMITS)
    assert problem is not None and problem[0] == m.MAV_MISSION_ERROR
    assert "cannot fit a curve" in problem[1] and "scipy.interpolate" in problem[1]
