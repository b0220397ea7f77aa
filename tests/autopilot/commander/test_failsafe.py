"""Failsafes in the commander (pure, simulation time): GCS link loss, geofence, pre-arm checks,
simulator loss; each announced, visible in the mode, and taken once per event."""

import pytest

from autopilot.commander.commander import ACCEPTED, DENIED, Commander, Motors, Phase, VehicleState
from autopilot.commander.failsafe import FailsafeMonitor, fence_excess, prearm_problem
from autopilot.commander.modes import FlightMode
from autopilot.guidance.sticks import Sticks
from autopilot.params.definitions import default_parameters

DT = 0.002


def state(t, p=(0.0, 0.0, 0.0), v=(0.0, 0.0, 0.0), yaw=0.0):
    return VehicleState(t, p, v, (0.0, 0.0, yaw), (0.0, 0.0, 0.0))


def fly(c: Commander, t0: float, seconds: float, drift=(0.0, 0.0, 0.0), heartbeat_every=None, sticks=False):
    """Step the commander; the vehicle follows its reference exactly, plus ``drift`` m/s; with
    ``sticks``, centred sticks at 10 Hz (a pilot's stream, for the manual modes)."""
    t = t0
    offset = [0.0, 0.0, 0.0]
    next_hb = next_sticks = t0
    for _ in range(int(round(seconds / DT))):
        if heartbeat_every is not None and t >= next_hb:
            c.gcs_heartbeat(t)
            next_hb = t + heartbeat_every
        if sticks and t >= next_sticks:
            c.manual_sticks(Sticks(t))
            next_sticks = t + 0.1
        out = c.step(t, DT)
        if out.reference is not None and out.motors == Motors.FLY:
            offset = [o + d * DT for o, d in zip(offset, drift, strict=True)]
            ref = out.reference
            p = tuple(r + o for r, o in zip(ref.position_m, offset, strict=True))
            c.update_state(state(t, p, ref.velocity_m_s, ref.yaw_rad))
        t += DT
    return t


def airborne(**params):
    c = Commander(default_parameters())
    for name, value in params.items():
        assert c.params.set(name, value) is None
    c.update_state(state(0.0))
    assert c.arm(0.0).accepted and c.takeoff(0.0).accepted
    t = fly(c, 0.0, 4.0)
    assert c.mode == FlightMode.AUTO_LOITER and c.state.position_m[2] > 2.4
    c.drain_events()
    return c, t


def texts(c):
    return [text for _, text in c.drain_events()]


# -- GCS heartbeat loss ---------------------------------------------------------------------------
def test_link_loss_default_is_none_and_silent():
    c, t = airborne()
    c.gcs_heartbeat(t)
    t = fly(c, t, 15.0)
    assert c.mode == FlightMode.AUTO_LOITER and texts(c) == []


def test_link_loss_without_any_heartbeat_never_triggers():
    c, t = airborne(NAV_DLL_ACT=1)
    t = fly(c, t, 15.0)
    assert c.mode == FlightMode.AUTO_LOITER and texts(c) == []


@pytest.mark.parametrize(
    "action, mode, phase",
    [
        (1, FlightMode.AUTO_LOITER, Phase.HOLD),
        (2, FlightMode.AUTO_RTL, Phase.RTL),
        (3, FlightMode.AUTO_LAND, Phase.LAND),
    ],
)
def test_link_loss_action_is_taken_once_and_announced(action, mode, phase):
    c, t = airborne(NAV_DLL_ACT=action, COM_DL_LOSS_T=5)
    c.manual_sticks(Sticks(t))
    assert c.set_mode(t, FlightMode.POSCTL).accepted  # some other mode, to see the switch
    c.drain_events()
    t = fly(c, t, 3.0, heartbeat_every=1.0, sticks=True)  # heartbeats flowing: nothing
    assert c.mode == FlightMode.POSCTL and texts(c) == []
    last_hb = t - 1.0
    t = fly(c, t, 5.5, sticks=True)  # > 5 s after the last heartbeat
    events = texts(c)
    lost = [e for e in events if e.startswith("GCS connection lost")]
    assert len(lost) == 1 and f"NAV_DLL_ACT {action}" in lost[0]
    assert c.mode == mode and c.phase == phase
    assert t - last_hb > 5.0
    # Taken once: a user may switch mode back and the loss does not fight them.
    if phase == Phase.HOLD:
        c.set_mode(t, FlightMode.POSCTL)
        fly(c, t, 2.0, sticks=True)
        assert c.mode == FlightMode.POSCTL
        assert not any(e.startswith("GCS connection lost") for e in texts(c))
    # A heartbeat ends the loss.
    c.gcs_heartbeat(t)
    assert "GCS connection regained" in texts(c)


# -- geofence --------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "action, mode", [(2, FlightMode.AUTO_LOITER), (3, FlightMode.AUTO_RTL), (5, FlightMode.AUTO_LAND)]
)
def test_vertical_fence_breach_takes_the_action_once(action, mode):
    c, t = airborne(GF_MAX_VER_DIST=4.0, RTL_RETURN_ALT=3.0, GF_ACTION=action)
    c.manual_sticks(Sticks(t))
    assert c.set_mode(t, FlightMode.POSCTL).accepted
    c.drain_events()
    t = fly(c, t, 6.0, drift=(0.0, 0.0, 0.5), sticks=True)  # pushed up at 0.5 m/s beyond the reference
    events = texts(c)
    breached = [e for e in events if e.startswith("geofence breached")]
    assert len(breached) == 1, events
    assert "above home > GF_MAX_VER_DIST 4 m" in breached[0]
    assert c.mode == mode


def test_horizontal_fence_warning_only_and_rearm_after_coming_back():
    c, t = airborne(GF_MAX_HOR_DIST=3.0, GF_ACTION=1)
    t = fly(c, t, 8.0, drift=(0.5, 0.0, 0.0))  # drifts out (hold keeps its reference)
    events = texts(c)
    assert [e for e in events if e.startswith("geofence")] == [
        next(e for e in events if e.startswith("geofence"))
    ]
    assert "from home > GF_MAX_HOR_DIST 3 m" in events[0]
    assert c.mode == FlightMode.AUTO_LOITER  # warning only
    assert c.failsafes.fence_breached
    # Back inside by the margin: the fence re-arms (and would trigger again).
    c.update_state(state(t, (1.0, 0.0, 2.5)))
    c.step(t, DT)
    assert not c.failsafes.fence_breached


def test_fence_excess_and_monitor_latch():
    params = default_parameters()
    params.set("GF_MAX_HOR_DIST", 10.0)
    params.set("GF_MAX_VER_DIST", 5.0)
    home = (1.0, 1.0, 0.0)
    assert fence_excess(params, (7.0, 9.0, 2.0), home)[0] == pytest.approx(0.0)
    assert fence_excess(params, (1.0, 1.0, 6.0), home) == (
        pytest.approx(1.0),
        "6.0 m above home > GF_MAX_VER_DIST 5 m",
    )
    monitor = FailsafeMonitor(params)
    assert [a.action for a in monitor.check(0.0, (1.0, 1.0, 6.0), home, True)] == ["hold"]
    assert monitor.check(0.1, (1.0, 1.0, 6.5), home, True) == []  # latched
    assert monitor.check(0.2, (1.0, 1.0, 4.9), home, True) == []  # inside, but within the margin
    assert monitor.fence_breached
    assert monitor.check(0.3, (1.0, 1.0, 4.0), home, True) == []
    assert not monitor.fence_breached
    assert monitor.check(0.4, (1.0, 1.0, 5.5), home, False) == []  # on the ground: not checked


# -- pre-arm checks ------------------------------------------------------------------------------------
def test_arming_refused_without_position_and_after_simulator_loss():
    c = Commander(default_parameters())
    out = c.arm(0.0)
    assert out.result == DENIED and "no position" in out.reason
    c.update_state(state(0.0))
    c.simulator_lost()
    out = c.arm(0.0, force=True)  # not even forced
    assert out.result == DENIED and "no position" in out.reason
    c.update_state(state(0.1))
    assert c.arm(0.1).result == ACCEPTED


def test_arming_refused_with_bad_parameters():
    c = Commander(default_parameters())
    c.update_state(state(0.0))
    c.params.set("GF_MAX_VER_DIST", 2.0)  # below the takeoff and return altitudes
    out = c.arm(0.0)
    assert out.result == DENIED
    assert (
        "bad parameters" in out.reason
        and "MIS_TAKEOFF_ALT 2.5 m is not below GF_MAX_VER_DIST 2 m" in out.reason
    )
    assert any("arming refused: bad parameters" in text for text in texts(c))
    assert c.arm(0.0, force=True).accepted  # forced arming skips the pre-arm checks (PX4)


def test_arming_refused_outside_the_geofence():
    c = Commander(default_parameters())
    c.update_state(state(0.0))  # home below the boot position
    c.update_state(state(1.0, (30.0, 0.0, 0.0)))  # landed far away since
    c.params.set("GF_MAX_HOR_DIST", 20.0)
    out = c.arm(1.0)
    assert (
        out.result == DENIED and "outside the geofence: 30.0 m from home > GF_MAX_HOR_DIST 20 m" in out.reason
    )
    assert prearm_problem(c.params, (5.0, 0.0, 0.0), (0.0, 0.0, 0.0), True) is None
