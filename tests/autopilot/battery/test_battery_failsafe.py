"""The low-battery chain (autopilot/commander/failsafe.py BatteryWatch, the commander, the table):
levels, their actions by COM_LOW_BAT_ACT, the pre-arm check; then whole flights in-process on
PX4's drain simulation (SIM_BAT_DRAIN) and arming on a flat pack."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as m

from autopilot.battery.estimator import (
    FAULT_SPIKES,
    WARNING_CRITICAL,
    WARNING_EMERGENCY,
    WARNING_LOW,
    WARNING_NONE,
    BatteryStatus,
)
from autopilot.commander.commander import Phase
from autopilot.commander.failsafe import LAND, RTL, WARN, BatteryWatch
from autopilot.commander.modes import FlightMode
from autopilot.params.definitions import default_parameters
from tests.autopilot.commander.test_failsafe import airborne, fly, texts
from tests.stack import Gcs, make_stack

REMAINING = {WARNING_NONE: 0.5, WARNING_LOW: 0.1, WARNING_CRITICAL: 0.06, WARNING_EMERGENCY: 0.02}


def battery(warning: int = WARNING_NONE, t: float = 0.0, connected: bool = True, faults: int = 0):
    return BatteryStatus(t, connected, 11.5, 11.5, 8.0, 8.0, 8.0, 100.0, REMAINING[warning], 1.0, 600.0, 3,
                         2200.0, warning, faults, 0.015, 11.6, 11.6, 0.5)  # fmt: skip


def watch(**params) -> BatteryWatch:
    store = default_parameters()
    for name, value in params.items():
        assert store.set(name, value) is None
    return BatteryWatch(store)


def test_the_level_rises_only_while_armed_and_follows_the_estimate_disarmed():
    w = watch()
    w.update(battery(WARNING_CRITICAL, 1.0), False, armed=False)
    assert w.warning == WARNING_CRITICAL
    w.update(battery(WARNING_NONE, 2.0), False, armed=False)  # disarmed: follows (a recovered pack)
    assert w.warning == WARNING_NONE
    w.update(battery(WARNING_LOW, 3.0), False, armed=True)
    w.update(battery(WARNING_NONE, 4.0), False, armed=True)  # a lighter load: the level stays
    assert w.warning == WARNING_LOW
    w.update(battery(WARNING_CRITICAL, 5.0), False, armed=True)
    assert w.warning == WARNING_CRITICAL
    w.update(battery(WARNING_NONE, 6.0), False, armed=False)
    assert w.warning == WARNING_NONE


@pytest.mark.parametrize("act, critical, emergency", [
    (0, WARN, WARN), (1, RTL, RTL), (2, LAND, LAND), (3, RTL, LAND),
])  # fmt: skip
def test_each_level_acts_once_by_com_low_bat_act(act, critical, emergency):
    w = watch(COM_LOW_BAT_ACT=act)
    w.update(battery(WARNING_NONE, 0.0), False, armed=True)
    got = []
    levels = (WARNING_LOW, WARNING_LOW, WARNING_CRITICAL, WARNING_EMERGENCY, WARNING_EMERGENCY)
    for k, level in enumerate(levels):
        w.update(battery(level, 1.0 + k), False, armed=True)
        due = w.action()
        if due is not None:
            got.append(due)
    assert [action for _, (action, _) in got] == [WARN, critical, emergency]
    (s_low, low), (s_crit, crit), (s_emerg, emerg) = got
    assert (s_low, low.text) == (m.MAV_SEVERITY_WARNING, "Low battery level, return advised")
    if critical == WARN:
        assert (s_crit, crit.text) == (m.MAV_SEVERITY_CRITICAL, "Critical battery level, land now")
        assert (s_emerg, emerg.text) == (m.MAV_SEVERITY_EMERGENCY,
                                         "Emergency battery level, land immediately")
    else:
        word = {RTL: "RTL", LAND: "land"}
        assert crit.text == (f"Failsafe activated due to critical battery level, triggering {word[critical]} "
                             f"(COM_LOW_BAT_ACT {act})")  # fmt: skip
        assert emerg.text.startswith(f"Failsafe activated due to emergency battery level, triggering "
                                     f"{word[emergency]}")  # fmt: skip


def test_a_level_there_at_arming_only_warns_and_a_worse_one_acts():
    w = watch(COM_LOW_BAT_ACT=2)
    w.update(battery(WARNING_CRITICAL, 0.0), False, armed=False)
    w.update(battery(WARNING_CRITICAL, 1.0), False, armed=True)
    assert w.action()[1].action == WARN
    w.update(battery(WARNING_EMERGENCY, 2.0), False, armed=True)
    assert w.action()[1].action == LAND


def test_a_disconnection_in_flight_is_critical_and_announced_once():
    w = watch(COM_LOW_BAT_ACT=3)
    w.update(battery(WARNING_NONE, 0.0), False, armed=False)
    w.update(battery(WARNING_NONE, 1.0), False, armed=True)
    notices = w.update(battery(WARNING_NONE, 2.0, connected=False), False, armed=True)
    assert notices == [(m.MAV_SEVERITY_EMERGENCY, "Battery 1 disconnected")]
    assert not w.update(battery(WARNING_NONE, 3.0, connected=False), False, armed=True)
    assert w.warning == WARNING_CRITICAL and w.action()[1].action == RTL


def test_unhealthy_and_faults_are_announced_once():
    w = watch()
    assert w.update(battery(WARNING_NONE, 0.0), True, armed=False) == [
        (m.MAV_SEVERITY_CRITICAL, "Battery unhealthy: no battery report for 5 s")]  # fmt: skip
    assert not w.update(battery(WARNING_NONE, 0.0), True, armed=False)
    notices = w.update(battery(WARNING_NONE, 1.0, faults=1 << FAULT_SPIKES), False, armed=True)
    assert notices == [(m.MAV_SEVERITY_EMERGENCY, "Battery 1: over voltage. Land now!")]
    assert not w.update(battery(WARNING_NONE, 2.0, faults=1 << FAULT_SPIKES), False, armed=True)


@pytest.mark.parametrize("warning, unhealthy, faults, problem", [
    (WARNING_NONE, False, 0, None),
    (WARNING_LOW, False, 0, None),  # PX4 arms on a low pack (and warns)
    (WARNING_CRITICAL, False, 0, "Critical battery (remaining 6 % < BAT_CRIT_THR 7 %)"),
    (WARNING_EMERGENCY, False, 0, "Emergency battery level (remaining 2 % < BAT_EMERGEN_THR 5 %)"),
    (WARNING_NONE, True, 0, "Battery unhealthy (no battery report for 5 s)"),
    (WARNING_NONE, False, 1 << FAULT_SPIKES, "Battery 1: over voltage"),
])  # fmt: skip
def test_the_prearm_check(warning, unhealthy, faults, problem):
    w = watch()
    assert w.prearm_problem() is None  # no battery has reported: nothing to refuse on
    w.update(battery(warning, 1.0, faults=faults), unhealthy, armed=False)
    assert w.prearm_problem() == problem


def test_a_return_gives_way_to_an_emergency_landing_and_a_landing_is_never_undone():
    c, t = airborne(COM_LOW_BAT_ACT=3)
    c.update_battery(battery(WARNING_CRITICAL, t), False)
    t = fly(c, t, 0.5)
    assert c.mode == FlightMode.AUTO_RTL
    c.update_battery(battery(WARNING_EMERGENCY, t), False)
    t = fly(c, t, 0.5)
    assert c.mode == FlightMode.AUTO_LAND and c.phase == Phase.LAND
    # A landing the user asked for: a critical return does not undo it.
    c, t = airborne(COM_LOW_BAT_ACT=1)
    assert c.land(t).accepted
    c.drain_events()
    c.update_battery(battery(WARNING_CRITICAL, t), False)
    t = fly(c, t, 0.5)
    assert c.mode == FlightMode.AUTO_LAND
    events = texts(c)
    assert events == ["Failsafe activated due to critical battery level, triggering RTL (COM_LOW_BAT_ACT 1): "
                      "already AUTO.LAND"]  # fmt: skip


# -- whole flights, in-process --------------------------------------------------------------------------
def drain_flight(com_low_bat_act: int, drain_s: float, min_pct: float, away_m: float = 0.0, until_s=90.0):
    """paper_quad on PX4's linear drain: armed at 2.5 s, up to 3 m, ``away_m`` north; recorded
    before each frame: (its time, the autopilot's estimated remaining, mode), and the STATUSTEXTs
    (the time of the frame that raised them, text)."""
    texts: list[tuple[float, str]] = []

    def log(text: str) -> None:
        if text.startswith("[t="):
            end = text.index("]")
            texts.append((float(text[3:end]), text[end + 2 :]))

    stack = make_stack(battery={"drain_s": drain_s, "drain_min_pct": min_pct}, log=log)
    ap = stack.autopilot
    assert ap.params.set("COM_LOW_BAT_ACT", com_low_bat_act) is None
    frames: list[tuple[float, float, str]] = []

    def record(stack, t) -> None:
        status = ap.battery.status
        frames.append((t, status.remaining if status else math.nan, ap.commander.mode.px4_name))

    stack.run_until(2.5)
    c = ap.commander
    assert c.arm(stack.t).accepted and c.takeoff(stack.t, 3.0).accepted
    stack.run_until(stack.t + 5.0)
    if away_m:
        assert c.reposition(stack.t, (away_m, 0.0, 3.0)).accepted
        stack.run_until(stack.t + 8.0)
    stack.run_until(until_s, until=lambda s: not c.armed, script=record)
    return stack, frames, texts


def announced(texts, start: str) -> list[float]:
    return [t for t, text in texts if text.startswith(start)]


def crossing(frames, t: float) -> tuple[float, float]:
    """The estimate before the frame at ``t`` and after it."""
    before = next(r for time, r, _ in frames if time >= t - 1e-9)
    after = next(r for time, r, _ in frames if time > t + 1e-9)
    return before, after


def test_a_draining_battery_warns_returns_then_lands_at_its_thresholds():
    """COM_LOW_BAT_ACT 3, SIM_BAT_DRAIN 25 s to 0 %: at 15 % "Low battery level", at 7 % a return,
    at 5 % a landing where the vehicle is; in that order, each once, at the estimate's crossing."""
    stack, frames, texts = drain_flight(3, drain_s=25.0, min_pct=0.0)
    low = announced(texts, "Low battery level, return advised")
    critical = announced(texts, "Failsafe activated due to critical battery level, triggering RTL")
    emergency = announced(texts, "Failsafe activated due to emergency battery level, triggering land")
    assert len(low) == len(critical) == len(emergency) == 1
    assert low[0] < critical[0] < emergency[0]
    p = stack.autopilot.params
    for (t,), threshold in ((low, p["BAT_LOW_THR"]), (critical, p["BAT_CRIT_THR"]),
                            (emergency, p["BAT_EMERGEN_THR"])):  # fmt: skip
        before, after = crossing(frames, t)
        assert after < threshold <= before
    modes = [mode for _, _, mode in frames]
    assert modes.index("AUTO.RTL") < modes.index("AUTO.LAND")
    assert [mode for time, _, mode in frames if time > emergency[0]][-1] == "AUTO.LAND"
    assert not stack.autopilot.commander.armed  # landed and disarmed


def test_a_critical_battery_returns_home_and_lands_there():
    """COM_LOW_BAT_ACT 3 with the drain held at 6 % (SIM_BAT_MIN_PCT, between the critical and the
    emergency levels): the vehicle 8 m away returns and lands at home; no emergency."""
    stack, frames, texts = drain_flight(3, drain_s=30.0, min_pct=6.0, away_m=8.0)
    assert len(announced(texts, "Failsafe activated due to critical battery level, triggering RTL")) == 1
    assert announced(texts, "Failsafe activated due to emergency") == []
    assert not stack.autopilot.commander.armed
    x, y, z = stack.sim.plant.truth().position_m
    assert math.hypot(x, y) < 0.3 and z < 0.05  # at home, on the ground


def test_arming_is_refused_on_a_flat_pack():
    stack = make_stack(battery={"initial_charge": 0.02})
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    stack.run_until(2.5)  # the estimate starts 2 s after the pack connected
    ack = gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    assert ack.result == m.MAV_RESULT_DENIED
    gcs.wait(lambda g: any("arming refused: Emergency battery level" in s for s in g.statustext),
             sim_timeout=1.0, what="the refusal's reason")  # fmt: skip
    assert not stack.autopilot.commander.armed
    gcs.close()


def test_sim_bat_parameters_set_from_a_ground_station_reach_the_simulator():
    """PX4 SITL's way to rehearse a low battery: PARAM_SET SIM_BAT_DRAIN / SIM_BAT_MIN_PCT on the
    vehicle; the simulator's battery drains by them from the next lockstep answer."""
    stack = make_stack()
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    gcs.conn.mav.param_set_send(stack.autopilot.system_id, 1, b"SIM_BAT_DRAIN", 30.0,
                                m.MAV_PARAM_TYPE_REAL32)  # fmt: skip
    gcs.conn.mav.param_set_send(stack.autopilot.system_id, 1, b"SIM_BAT_MIN_PCT", 0.0,
                                m.MAV_PARAM_TYPE_REAL32)  # fmt: skip
    stack.run_for(0.1)
    battery = stack.sim.info()["battery"]
    assert (battery["SIM_BAT_DRAIN"], battery["SIM_BAT_MIN_PCT"]) == (30.0, 0.0)
    assert stack.autopilot.params["SIM_BAT_DRAIN"] == 30.0


def test_sim_bat_parameters_from_a_parameters_file_reach_a_new_simulator(tmp_path):
    """A SIM_BAT_* the autopilot starts with (a parameters file) differs from the vehicle file the
    simulator starts from: it is sent at the simulator's first frame."""
    params = tmp_path / "params.toml"
    params.write_text("SIM_BAT_DRAIN = 45.0\n")
    stack = make_stack(params_file=str(params))
    stack.run_for(0.05)
    assert stack.sim.info()["battery"]["SIM_BAT_DRAIN"] == 45.0
