"""The autopilot's estimate of the battery (autopilot/battery/estimator.py, PX4's battery library):
each step against hand-made reports, then against the simulator's pack in a flight."""

from __future__ import annotations

import math
from typing import NamedTuple

import pytest

from autopilot.battery.estimator import (
    CURRENT_UNKNOWN,
    FAULT_SPIKES,
    WARNING_CRITICAL,
    WARNING_EMERGENCY,
    WARNING_LOW,
    WARNING_NONE,
    BatteryEstimator,
)
from autopilot.params.definitions import default_parameters
from tests.stack import make_stack

REPORT_S = 0.05


def estimator(**params) -> BatteryEstimator:
    store = default_parameters()
    for name, value in params.items():
        assert store.set(name, value) is None, name
    return BatteryEstimator(store)


def feed(e: BatteryEstimator, seconds: float, voltage, current=math.nan, armed=True, t0=0.0):
    """Reports every 50 ms for ``seconds`` from ``t0``; ``voltage``/``current`` constants or
    functions of time. The last status."""
    status = None
    for k in range(round(seconds / REPORT_S)):
        t = t0 + k * REPORT_S
        v = voltage(t) if callable(voltage) else voltage
        i = current(t) if callable(current) else current
        status = e.update(t, v, i, armed)
    return status


def cell_voltage_for(soc: float, empty=3.6, charged=4.05) -> float:
    return empty + soc * (charged - empty)


def test_a_pack_connects_at_lithium_voltage_and_the_estimate_waits_two_seconds():
    e = estimator(BAT1_CAPACITY=-1.0)
    low = e.update(0.0, 1.5, math.nan, False)
    assert not low.connected and low.warning == WARNING_NONE
    flat = 3 * cell_voltage_for(0.02)  # an emergency level pack
    status = feed(e, 1.9, flat, t0=0.05)
    assert status.connected and status.warning == WARNING_NONE  # not yet: 2 s from connecting
    status = feed(e, 0.5, flat, t0=2.0)
    assert status.warning == WARNING_EMERGENCY


def test_coulomb_counting_and_the_time_remaining():
    e = estimator(BAT1_CAPACITY=2000.0, BAT_AVRG_CURRENT=10.0)
    status = feed(e, 360.0, 3 * cell_voltage_for(1.0) - 0.045 * 10.0, 10.0)
    assert status.discharged_mah == pytest.approx(1000.0, rel=1e-3)  # 10 A for 0.1 h (less one interval)
    assert status.remaining == pytest.approx(0.5, abs=0.003)  # never above the coulomb count
    assert status.current_average_a == pytest.approx(10.0)
    assert status.time_remaining_s == pytest.approx(0.5 * 2000.0 / 10_000.0 * 3600.0, rel=0.01)  # 6 min


def test_the_voltage_based_estimate_compensates_the_load_by_the_internal_resistance():
    """Without a capacity the charge is the cell voltage plus R I, linear from BAT1_V_EMPTY to
    BAT1_V_CHARGED."""
    r_cell, current = 0.015, 10.0
    e = estimator(BAT1_CAPACITY=-1.0, BAT1_R_INTERNAL=r_cell)
    loaded = 3 * (cell_voltage_for(0.6) - r_cell * current)
    status = feed(e, 10.0, loaded, current)
    assert status.remaining == pytest.approx(0.6, abs=1e-6)
    assert math.isnan(status.time_remaining_s)  # no capacity: no time remaining
    uncompensated = estimator(BAT1_CAPACITY=-1.0, BAT1_R_INTERNAL=0.0)
    expected = 0.6 - r_cell * current / 0.45
    assert feed(uncompensated, 10.0, loaded, current).remaining == pytest.approx(expected)


def test_px4s_online_resistance_estimate_finds_the_packs_under_a_varying_load():
    r_cell, ocv_cell = 0.012, 3.9
    e = estimator(BAT1_CAPACITY=-1.0, BAT1_R_INTERNAL=-1.0)
    current = lambda t: 10.0 + 8.0 * math.sin(1.3 * t)  # noqa: E731
    status = feed(e, 60.0, lambda t: 3 * (ocv_cell - r_cell * current(t)), current)
    assert status.internal_resistance_estimate == pytest.approx(r_cell, rel=0.1)
    assert status.ocv_estimate == pytest.approx(3 * ocv_cell, abs=0.05)


def test_the_fusion_follows_the_voltage_where_it_reads_lower_than_the_count():
    """A pack that was not full at boot: the count alone would read it full; the voltage pulls the
    estimate down, harder the emptier the voltage reads."""
    e = estimator(BAT1_CAPACITY=2000.0, BAT1_R_INTERNAL=0.0)
    half = 3 * cell_voltage_for(0.3)
    status = feed(e, 2.5, half, 0.5)
    assert status.remaining == pytest.approx(0.3, abs=0.02)  # voltage-based until the estimate starts
    status = feed(e, 20.0, half, 0.5, t0=2.5)
    assert status.remaining == pytest.approx(0.3, abs=0.02)
    assert status.remaining <= 1.0 - status.discharged_mah / 2000.0


@pytest.mark.parametrize("soc, warning", [(0.16, WARNING_NONE), (0.14, WARNING_LOW), (0.06, WARNING_CRITICAL),
                                          (0.04, WARNING_EMERGENCY)])  # fmt: skip
def test_warning_levels_at_the_thresholds(soc, warning):
    e = estimator(BAT1_CAPACITY=-1.0)
    assert feed(e, 3.0, 3 * cell_voltage_for(soc)).warning == warning


def test_an_unconfigured_cell_count_leaves_the_charge_unknown_without_a_warning():
    e = estimator(BAT1_N_CELLS=0, BAT1_CAPACITY=-1.0)
    status = feed(e, 3.0, 9.0)
    assert status.remaining == -1.0 and status.warning == WARNING_NONE


def test_over_voltage_is_a_fault():
    e = estimator()
    assert feed(e, 1.0, 3 * 4.2).faults == 0  # a freshly charged pack at rest
    assert feed(e, 1.0, 3 * 4.05 * 1.06, t0=1.0).faults == 1 << FAULT_SPIKES


def test_a_pack_that_stops_reporting_is_unhealthy_after_five_seconds():
    e = estimator()
    assert not e.unhealthy(100.0)  # never reported: no battery, not an unhealthy one
    feed(e, 1.0, 12.0)
    assert not e.unhealthy(5.9) and e.unhealthy(6.0)
    feed(e, 0.1, 12.0, t0=6.0)
    assert not e.unhealthy(6.1)


def test_an_unmeasured_current_counts_nothing():
    e = estimator(BAT1_CAPACITY=2000.0)
    status = feed(e, 30.0, 3 * cell_voltage_for(0.8))
    assert status.current_a == CURRENT_UNKNOWN and status.discharged_mah == 0.0
    assert status.current_average_a == pytest.approx(e.params["BAT_AVRG_CURRENT"])
    assert status.remaining == pytest.approx(0.8, abs=0.01)


# -- against the simulator's pack, in flight --------------------------------------------------------
def test_the_estimate_follows_the_packs_truth_in_a_hover(battery_flight):
    """The paper's quadrotor hovering on a small pack (the vehicle's file: BAT1_R_INTERNAL is its
    pack's, BAT1_CAPACITY its capacity): the estimate is the pack's charge to 1 % until the cells'
    knee near empty, where the voltage reads lower and the estimate goes first."""
    samples = battery_flight.samples
    assert len(samples) > 800
    flying = [(est, truth) for est, truth, airborne in samples if airborne and truth > 0.12]
    assert len(flying) > 500
    assert max(abs(est - truth) for est, truth in flying) < 0.01
    near_empty = [(est, truth) for est, truth, airborne in samples if airborne and truth < 0.08]
    assert near_empty and all(est <= truth + 0.005 for est, truth in near_empty)


class Flight(NamedTuple):
    samples: list[tuple[float, float, bool]]  # per report: (estimated remaining, the pack's truth, airborne)
    texts: list[tuple[float, str]]  # STATUSTEXT (simulation time, text)
    modes: list[tuple[float, str]]  # the mode at each change (simulation time, PX4 name)
    landed_at: float | None  # disarmed after landing at


@pytest.fixture(scope="module")
def battery_flight() -> Flight:
    """paper_quad_rotors on a 100 mAh pack (45 s of hover) with the vehicle's defaults,
    COM_LOW_BAT_ACT 2 (land at the critical level): armed at 2.5 s, up to 3 m, hovering until the
    battery lands it."""
    texts: list[tuple[float, str]] = []

    def log(text: str) -> None:
        if text.startswith("[t="):
            end = text.index("]")
            texts.append((float(text[3:end]), text[end + 2 :]))

    stack = make_stack(vehicle="paper_quad_rotors", battery={"capacity_mah": 100.0}, log=log)
    ap, sim = stack.autopilot, stack.sim
    assert ap.params.set("COM_LOW_BAT_ACT", 2) is None
    samples: list[tuple[float, float, bool]] = []
    modes: list[tuple[float, str]] = []

    def record(stack, t) -> None:
        status = ap.battery.status
        if status is not None and (not samples or status.time_s > record.last):
            record.last = status.time_s
            samples.append((status.remaining, sim.battery.truth.state_of_charge, ap.commander.in_air()))
        if not modes or modes[-1][1] != ap.commander.mode.px4_name:
            modes.append((t, ap.commander.mode.px4_name))

    record.last = -1.0
    stack.run_until(2.5, script=record)
    assert ap.commander.arm(stack.t).accepted and ap.commander.takeoff(stack.t, 3.0).accepted
    stack.run_until(stack.t + 5.0, script=record)
    assert ap.commander.in_air()
    stack.run_until(120.0, until=lambda s: not ap.commander.armed, script=record)
    return Flight(samples, texts, modes, stack.t if not ap.commander.armed else None)


def test_a_critical_pack_lands_the_vehicle_announced_as_px4_does(battery_flight):
    """COM_LOW_BAT_ACT 2: the low level warns, the critical one lands, the emergency level (reached
    while landing) does not interrupt the landing; each announced once, in order."""
    texts = [text for _, text in battery_flight.texts]
    battery = [t for t in texts if "battery" in t.lower()]
    assert battery[0] == "Low battery level, return advised"
    assert battery[1] == ("Failsafe activated due to critical battery level, triggering land "
                          "(COM_LOW_BAT_ACT 2)")
    assert all(texts.count(t) == 1 for t in battery)
    if len(battery) > 2:  # the emergency level came before touchdown: the landing went on
        assert battery[2].startswith("Failsafe activated due to emergency battery level, triggering land")
        assert battery[2].endswith("already AUTO.LAND")
    assert [mode for _, mode in battery_flight.modes][-2:] == ["AUTO.LOITER", "AUTO.LAND"]
    assert battery_flight.landed_at is not None  # landed and disarmed
