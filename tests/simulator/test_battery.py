"""The flight battery's model (simulator/battery.py): the pack's physics, PX4's drain simulation,
the monitor's reports, its failures and parameters; the vehicle file's ``[battery]``."""

from __future__ import annotations

import math
from dataclasses import replace

import pytest
from pymavlink.dialects.v20 import common as m

from quadcommon.config import BatteryConfig, config_path, load_vehicle
from quadcommon.schema import ConfigError
from simulator.battery import (
    LIPO_OCV_V,
    MAH_TO_COULOMB,
    BatteryModel,
    BatteryReading,
    air_density_kg_m3,
    cell_ocv_v,
    momentum_power_coefficient,
    pack_current_a,
)
from simulator.dynamics.plant import TruthState

HOME_ALT_M = 488.0
REPORT_S = 0.05
DT = 0.002  # the control period at 500 Hz


def truth(thrust_n: float = 0.0, rotor_speeds=(0.0, 0.0, 0.0, 0.0)) -> TruthState:
    z3 = (0.0, 0.0, 0.0)
    return TruthState(z3, z3, z3, (1.0, 0.0, 0.0, 0.0), z3, z3, z3, z3, tuple(rotor_speeds), thrust_n, z3,
                      False)  # fmt: skip


def model(vehicle: str = "paper_quad", **battery) -> BatteryModel:
    v = load_vehicle(vehicle)
    return BatteryModel(replace(v, battery=replace(v.battery, **battery)), HOME_ALT_M, REPORT_S)


def fly(bm: BatteryModel, seconds: float, state: TruthState, armed: bool = True, t0: float = 0.0):
    """Frames of DT for ``seconds`` after ``t0``; the readings reported (time, reading)."""
    reports = []
    frames = round(seconds / DT)
    for k in range(1, frames + 1):
        t = t0 + k * DT
        reading = bm.frame(t, DT, state, armed)
        if reading is not None:
            reports.append((t, reading))
    return reports


HOVER_N = 0.74 * 9.81


def test_the_ocv_curve_is_a_lipo_cells_and_rises_with_the_charge():
    assert cell_ocv_v(1.0) == 4.20 and cell_ocv_v(0.0) == 3.27
    assert cell_ocv_v(0.5) == LIPO_OCV_V[10]
    assert cell_ocv_v(0.525) == pytest.approx((LIPO_OCV_V[10] + LIPO_OCV_V[11]) / 2)
    socs = [i / 200 for i in range(201)]
    assert all(cell_ocv_v(a) < cell_ocv_v(b) for a, b in zip(socs, socs[1:], strict=False))
    assert cell_ocv_v(-0.1) == 3.27 and cell_ocv_v(1.5) == 4.20  # clamped


def test_the_current_delivers_the_power_at_the_sagged_voltage():
    e, r = 12.0, 0.05
    for p in (1.0, 100.0, 500.0):
        i = pack_current_a(e, r, p)
        assert (e - r * i) * i == pytest.approx(p, rel=1e-12)  # P = V I, V = E - R I
        assert i < e / (2 * r)  # the operating point below the greatest power
    assert pack_current_a(e, 0.0, 120.0) == pytest.approx(10.0)
    assert pack_current_a(e, r, 0.0) == 0.0
    assert pack_current_a(e, r, 1e6) == pytest.approx(e / (2 * r))  # past E^2 / 4R: the voltage halves


def test_the_terminal_voltage_sags_with_the_load_and_recovers_without_it():
    bm = model()
    idle = fly(bm, 0.5, truth(0.0))[-1][1]
    loaded = fly(bm, 0.5, truth(HOVER_N), t0=0.5)[-1][1]
    heavy = fly(bm, 0.5, truth(2.5 * HOVER_N), t0=1.0)[-1][1]
    light_again = fly(bm, 0.5, truth(0.0), t0=1.5)[-1][1]
    assert idle.voltage_v > loaded.voltage_v > heavy.voltage_v
    assert loaded.current_a < heavy.current_a
    for reading in (loaded, heavy):  # V = N E(s) - R I at the pack's state
        ocv = bm.truth.open_circuit_v
        assert reading.voltage_v == pytest.approx(ocv - 0.045 * reading.current_a, abs=0.02)
    assert light_again.voltage_v > heavy.voltage_v + 1.0  # the sag goes with the load
    stiff = model(internal_resistance_ohm=0.0)
    assert fly(stiff, 0.5, truth(2.5 * HOVER_N))[-1][1].voltage_v == pytest.approx(
        stiff.truth.open_circuit_v, rel=1e-12)  # fmt: skip


def test_charge_is_conserved_and_counted():
    bm = model(capacity_mah=1000.0)
    reports = fly(bm, 60.0, truth(HOVER_N))
    assert reports[-1][0] == pytest.approx(60.0)
    intervals = [t - before for (t, _), before in zip(reports, [0.0] + [t for t, _ in reports], strict=False)]
    drawn = bm.truth.charge_drawn_c
    # The charge drawn is the current integrated over the reports' intervals, and it is what the
    # state of charge lost.
    integral = sum(r.current_a * dt for (_, r), dt in zip(reports, intervals, strict=True))
    assert integral == pytest.approx(drawn, rel=1e-9)
    assert 1.0 - bm.truth.state_of_charge == pytest.approx(drawn / (1000.0 * MAH_TO_COULOMB), rel=1e-12)
    # Energy: what the pack delivered is the power drawn (shaft over efficiency, plus avionics), to
    # the open-circuit voltage's change over one report (the voltage is read at the report's end).
    delivered = sum(r.voltage_v * r.current_a * dt for (_, r), dt in zip(reports, intervals, strict=True))
    k = momentum_power_coefficient(bm.config, air_density_kg_m3(HOME_ALT_M))
    demanded = (k * HOVER_N**1.5 / 0.75 + 3.0) * 60.0
    assert delivered == pytest.approx(demanded, rel=1e-4)


def test_the_wrench_vehicle_draws_what_the_rotor_vehicle_draws_in_hover():
    """paper_quad's momentum theory (r = 0.127 m, FM 0.4) against paper_quad_rotors' d Omega^3 at
    the hover speed: the same airframe, the same draw within a few per cent."""
    wrench = model("paper_quad")
    rotors = model("paper_quad_rotors")
    v = load_vehicle("paper_quad_rotors")
    omega = math.sqrt(HOVER_N / 4 / v.rotors.thrust_coefficient_n_s2)
    fly(wrench, 1.0, truth(HOVER_N))
    fly(rotors, 1.0, truth(0.0, (omega,) * 4))
    assert rotors.truth.power_w == pytest.approx(4 * v.rotors.drag_coefficient_n_m_s2 * omega**3 / 0.75 + 3.0)
    assert wrench.truth.power_w == pytest.approx(rotors.truth.power_w, rel=0.05)
    assert 85.0 < wrench.truth.power_w < 110.0  # ~70 W of shaft in hover


def test_a_full_pack_hovers_the_paper_quad_about_fifteen_minutes():
    bm = model()
    fly(bm, 60.0, truth(HOVER_N))
    per_minute = 1.0 - bm.truth.state_of_charge
    assert 13.0 < 1.0 / per_minute < 17.0


def test_the_model_is_deterministic():
    a, b = model(), model()
    thrusts = [HOVER_N * (1.0 + 0.3 * math.sin(0.7 * k)) for k in range(2000)]
    for k, thrust in enumerate(thrusts, start=1):
        ra = a.frame(k * DT, DT, truth(thrust), True)
        rb = b.frame(k * DT, DT, truth(thrust), True)
        assert ra == rb
    assert a.truth == b.truth


def test_reports_come_at_the_monitors_rate_and_not_while_disabled():
    bm = model()
    assert bm.frame(0.0, 0.0, truth(), False) is not None  # the first frame reports
    assert len(fly(bm, 1.0, truth())) == 20  # 20 Hz
    assert bm.set_parameter("SIM_BAT_ENABLE", 0)
    assert fly(bm, 1.0, truth(HOVER_N), t0=1.0) == []
    soc = bm.truth.state_of_charge
    assert soc < 1.0 - 1e-4  # the pack drains on, unreported
    assert bm.set_parameter("SIM_BAT_ENABLE", 1)
    assert len(fly(bm, 1.0, truth(), t0=2.0)) == 20


def test_px4s_drain_reaches_its_minimum_and_a_disarmed_pack_is_full():
    """SIM_BAT_DRAIN: full to empty in that time while armed, linear in voltage between the empty
    and charged cells, stopping at SIM_BAT_MIN_PCT; no current measured."""
    bm = model()
    assert bm.set_parameter("SIM_BAT_DRAIN", 10.0) and bm.set_parameter("SIM_BAT_MIN_PCT", 20.0)
    reports = fly(bm, 12.0, truth(HOVER_N))
    cells, empty, full = 3, 3.6, 4.05
    for t, reading in reports:
        soc = max(1.0 - t / 10.0, 0.2)
        assert reading.voltage_v == pytest.approx(cells * (empty + soc * (full - empty)), abs=1e-6)
        assert math.isnan(reading.current_a)
    at_minimum = [t for t, r in reports if r.voltage_v <= cells * (empty + 0.2 * (full - empty)) + 1e-9]
    assert at_minimum[0] == pytest.approx(8.0, abs=1e-6)  # (1 - 0.2) x 10 s
    disarmed = fly(bm, 0.1, truth(), armed=False, t0=12.0)
    assert disarmed[-1][1].voltage_v == pytest.approx(cells * full)
    # the physical model again: the drain's state of charge carries over, the current is measured
    assert bm.set_parameter("SIM_BAT_DRAIN", 0.0)
    assert not math.isnan(fly(bm, 0.1, truth(HOVER_N), t0=12.1)[-1][1].current_a)


def test_injected_failures_change_the_report_not_the_pack():
    bm = model()
    ok = fly(bm, 1.0, truth(HOVER_N))[-1][1]
    assert bm.inject_failure(m.FAILURE_TYPE_OFF)
    off = fly(bm, 1.0, truth(HOVER_N), t0=1.0)[-1][1]
    assert off.voltage_v == pytest.approx(3 * 3.6) and math.isnan(off.current_a) and ok.current_a > 1.0
    assert bm.truth.terminal_v > 11.0  # the pack itself is fine
    assert bm.inject_failure(m.FAILURE_TYPE_OK)
    assert bm.inject_failure(m.FAILURE_TYPE_STUCK)
    stuck = fly(bm, 2.0, truth(2 * HOVER_N), t0=2.0)
    assert {r for _, r in stuck} == {stuck[0][1]} and stuck[0][1].voltage_v > bm.truth.terminal_v
    assert bm.inject_failure(m.FAILURE_TYPE_GARBAGE)
    garbage = fly(bm, 0.2, truth(HOVER_N), t0=4.0)[-1][1]
    assert math.isnan(garbage.voltage_v) and math.isnan(garbage.current_a)
    assert bm.inject_failure(m.FAILURE_TYPE_WRONG)
    wrong = fly(bm, 0.2, truth(HOVER_N), t0=4.2)[-1][1]
    assert wrong.voltage_v == pytest.approx(1.1 * bm.truth.terminal_v)
    for refused in (m.FAILURE_TYPE_SLOW, m.FAILURE_TYPE_DELAYED, m.FAILURE_TYPE_INTERMITTENT, 8, -1):
        assert not bm.inject_failure(refused)
    assert bm.failure == m.FAILURE_TYPE_WRONG  # a refused type leaves the failure in force
    assert bm.inject_failure(m.FAILURE_TYPE_OK)
    assert fly(bm, 0.2, truth(HOVER_N), t0=4.4)[-1][1] == BatteryReading(bm.truth.terminal_v,
                                                                         bm.truth.current_a)  # fmt: skip


@pytest.mark.parametrize("name, value", [
    ("SIM_BAT_DRAIN", -1.0), ("SIM_BAT_DRAIN", math.nan), ("SIM_BAT_DRAIN", math.inf), ("SIM_BAT_DRAIN", 1e9),
    ("SIM_BAT_MIN_PCT", 100.5), ("SIM_BAT_MIN_PCT", -0.1), ("SIM_BAT_ENABLE", 0.5), ("SIM_BAT_ENABLE", 2),
    ("SIM_BAT_ENABLE", True), ("SIM_BAT_DRAIN", "60"), ("BAT1_CAPACITY", 1000.0), ("", 0.0),
])  # fmt: skip
def test_battery_parameters_out_of_range_are_refused(name, value):
    bm = model()
    before = (bm.enabled, bm.drain_s, bm.drain_min)
    assert not bm.set_parameter(name, value)
    assert (bm.enabled, bm.drain_s, bm.drain_min) == before


def test_the_simulator_core_takes_the_battery_parameters():
    from simulator.core import SimulatorCore, SimulatorSetup

    core = SimulatorCore(SimulatorSetup.load())
    assert core.set_battery_parameter("SIM_BAT_MIN_PCT", 12.5) and core.battery.drain_min == 0.125
    assert not core.set_battery_parameter("SIM_BAT_MIN_PCT", math.nan)
    assert core.battery.drain_min == 0.125
    assert core.battery.inject_failure(m.FAILURE_TYPE_OFF)
    battery = core.info()["battery"]
    assert battery["SIM_BAT_MIN_PCT"] == 12.5 and battery["failure"] == "off (reads empty)"
    assert battery["state_of_charge"] == 1.0


def test_the_vehicle_files_battery_is_validated_naming_file_key_value_and_range(tmp_path):
    text = config_path("vehicle", "paper_quad").read_text()
    cases = {
        "cells = 3": ("cells = 0", "battery.cells", "0", "[1, 16]"),
        "capacity_mah = 2200.0": ("capacity_mah = -5.0", "battery.capacity_mah", "-5.0", "(0, 100000]"),
        "charged_cell_v = 4.05": ("charged_cell_v = 3.5", "battery.charged_cell_v", "3.5", "(3.6, 4.5]"),
        "drain_min_pct = 50.0": ("drain_min_pct = 101.0", "battery.drain_min_pct", "101.0", "[0, 100]"),
        "figure_of_merit = 0.4": ("figure_of_merit = nan", "battery.figure_of_merit", "nan", "(0, 1]"),
    }
    for old, (new, key, value, allowed) in cases.items():
        path = tmp_path / "bad.toml"
        path.write_text(text.replace(old, new))
        with pytest.raises(ConfigError) as error:
            load_vehicle(path)
        message = str(error.value)
        assert str(path) in message and key in message and value in message and allowed in message, message
    path.write_text(text.replace("enabled = true", "enabled = true\nvoltage = 12"))
    with pytest.raises(ConfigError, match="unknown key 'battery.voltage'"):
        load_vehicle(path)
    # A vehicle file without [battery] flies the default pack.
    start = text.index("[battery]")
    path.write_text(text[:start])
    assert load_vehicle(path).battery == BatteryConfig()
