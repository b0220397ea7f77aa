"""The battery on the wire: the monitor's BATTERY_STATUS in the lockstep frame (simulator encodes,
autopilot decodes and refuses what is no reading), and the one estimate in SYS_STATUS and
BATTERY_STATUS to ground stations; in-process, simulation time."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as m

from autopilot.mavlink.hil import BATTERY_ID, RefusedReport, battery_report
from quadcommon import wire
from quadcommon.mavlink_fast import MessageParts
from simulator.battery import BatteryReading
from simulator.core import SimulatorCore, SimulatorSetup
from simulator.mavlink.hil import HilFrameEncoder
from tests.stack import Gcs, make_stack

HOME = (47.397742, 8.545594, 488.0)


def encoded(reading: BatteryReading) -> MessageParts:
    """The frame's messages with the BATTERY_STATUS the simulator's encoder makes of ``reading``."""
    core = SimulatorCore(SimulatorSetup.load())
    truth = core.plant.truth()
    readings = core.sensors.step(0.0, truth).readings
    datagram = HilFrameEncoder(1, HOME).encode(0, truth, readings, battery=reading)
    return MessageParts.of_datagram(datagram)


@pytest.mark.parametrize("volts, amps", [(12.6, 0.24), (9.81, 63.5), (0.0, 0.0), (100.0, 1.5)])
def test_the_reading_crosses_the_wire_to_the_millivolt_and_centiamp(volts, amps):
    report = battery_report(encoded(BatteryReading(volts, amps)))
    assert report.voltage_v == pytest.approx(volts, abs=5e-4)  # 100 V: MAVLink's split over two cells
    assert report.current_a == pytest.approx(amps, abs=5e-3)


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_what_the_monitor_does_not_know_crosses_as_unknown(bad):
    assert math.isnan(battery_report(encoded(BatteryReading(11.1, bad))).current_a)
    with pytest.raises(RefusedReport, match="no voltage"):
        battery_report(encoded(BatteryReading(bad, 8.0)))


def hostile(**fields) -> bytes:
    """A BATTERY_STATUS as the simulator would send it, with ``fields`` changed (``component``:
    the sender's component)."""
    component = fields.pop("component", wire.SIMULATOR_COMPONENT_ID)
    values = dict(id=0, battery_function=0, type=1, temperature=32767, voltages=[12000] + [65535] * 9,
                  current_battery=800, current_consumed=-1, energy_consumed=-1, battery_remaining=-1,
                  time_remaining=0, charge_state=0, voltages_ext=[0] * 4, mode=0,
                  fault_bitmask=0)  # fmt: skip
    values.update(fields)
    mav = m.MAVLink(None, srcSystem=1, srcComponent=component)
    return m.MAVLink_battery_status_message(**values).pack(mav)


def corrupt(frame: bytes) -> bytes:
    data = bytearray(frame)
    data[12] ^= 0x55
    return bytes(data)


HOSTILE = {
    "corrupt": corrupt(hostile()),
    "not from the simulator's component": hostile(component=1),
    "not battery 0": hostile(id=1),
    "no voltage": hostile(voltages=[65535] * 10),
    "negative current": hostile(current_battery=-500),
}


@pytest.mark.parametrize("reason", HOSTILE)
def test_a_hostile_battery_status_on_the_hil_link_is_refused_counted_and_harmless(reason):
    """Appended to every frame for a second (so it also replaces the genuine report of the frames
    that carry one): refused each time with its reason, counted, never a fault; the estimate is the
    genuine reports' alone, and the vehicle flies on."""
    stack = make_stack()
    sim, ap = stack.sim, stack.autopilot
    stack.run_until(1.0)
    genuine = ap.battery.status
    for _ in range(500):
        t = stack.clock
        datagram = sim.begin_frame() + HOSTILE[reason]
        answer = ap.on_hil_datagram(datagram, t)
        ap.after_frame()
        assert answer is not None
        sim.end_frame(sim.answer_to_frame(answer))
        stack.clock = t + sim.dt_control
    assert ap.dropped == {f"HIL BATTERY_STATUS refused: {reason}": 500}
    assert not ap.faults.counts
    assert ap.battery.status is genuine  # nothing got through (the genuine ones were displaced)
    stack.run_until(stack.t + 1.0)
    assert ap.battery.status.time_s > genuine.time_s  # the genuine reports go on
    assert ap.battery.status.voltage_v == pytest.approx(sim.battery.truth.terminal_v, abs=1e-3)


def test_the_frame_carries_the_monitor_at_its_rate_from_the_simulators_component():
    core = SimulatorCore(SimulatorSetup.load())
    count = 0
    for _ in range(500):  # one second at 500 Hz
        parts = MessageParts.of_datagram(core.begin_frame())
        if BATTERY_ID in parts:
            count += 1
            assert parts.component_id(BATTERY_ID) == wire.SIMULATOR_COMPONENT_ID
        core.end_frame(None)
    assert count == wire.BATTERY_REPORT_HZ


# -- to ground stations: one estimate ---------------------------------------------------------------
def streams(gcs: Gcs) -> None:
    for msg_id in (m.MAVLINK_MSG_ID_BATTERY_STATUS, m.MAVLINK_MSG_ID_SYS_STATUS):
        assert gcs.command(m.MAV_CMD_SET_MESSAGE_INTERVAL, msg_id, 100_000).result == m.MAV_RESULT_ACCEPTED


def fresh(gcs: Gcs, sim_timeout: float = 1.0):
    for kind in ("BATTERY_STATUS", "SYS_STATUS"):
        gcs.last.pop(kind, None)
    gcs.wait(lambda g: "BATTERY_STATUS" in g.last and "SYS_STATUS" in g.last, sim_timeout,
             "battery telemetry")
    return gcs.last["SYS_STATUS"], gcs.last["BATTERY_STATUS"]


def test_sys_status_and_battery_status_report_the_one_estimate():
    stack = make_stack()
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    streams(gcs)
    stack.run_until(3.0)
    assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == m.MAV_RESULT_ACCEPTED
    assert gcs.command(m.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, 488.0 + 3.0).result == 0
    gcs.wait(lambda g: g.stack.t > 12.0, sim_timeout=15.0, what="a while in the air")
    sys_status, battery = fresh(gcs)
    estimate = stack.autopilot.battery.status
    bit = m.MAV_SYS_STATUS_SENSOR_BATTERY
    assert sys_status.onboard_control_sensors_present & bit
    assert sys_status.onboard_control_sensors_enabled & bit
    assert sys_status.onboard_control_sensors_health & bit
    millivolts = pytest.approx(estimate.voltage_v * 1000, abs=30)
    assert sys_status.voltage_battery == battery.voltages[0] == millivolts
    assert sys_status.current_battery == battery.current_battery == pytest.approx(estimate.current_a * 100,
                                                                                  abs=20)  # fmt: skip
    assert 750 < battery.current_battery < 950  # the paper's quadrotor hovers on about 8 A
    assert sys_status.battery_remaining == battery.battery_remaining == round(100 * estimate.remaining)
    assert battery.current_consumed == pytest.approx(estimate.discharged_mah, abs=2)
    assert battery.time_remaining == pytest.approx(estimate.time_remaining_s, abs=2)
    assert battery.charge_state == m.MAV_BATTERY_CHARGE_STATE_OK and battery.fault_bitmask == 0
    assert list(battery.voltages[1:]) == [65535] * 9
    gcs.close()


def test_a_garbage_monitor_makes_the_battery_unhealthy_and_refuses_arming():
    """FAILURE_TYPE_GARBAGE: every report refused at the edge; after 5 s without one the battery is
    unhealthy (announced, health bit clear, BATTERY_STATUS unhealthy) and arming is refused."""
    stack = make_stack()
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    streams(gcs)
    stack.run_until(3.0)
    assert stack.sim.battery.inject_failure(m.FAILURE_TYPE_GARBAGE)
    gcs.wait(lambda g: any(s.startswith("Battery unhealthy") for s in g.statustext), sim_timeout=6.0,
             what="Battery unhealthy")  # fmt: skip
    assert stack.autopilot.dropped["HIL BATTERY_STATUS refused: no voltage"] >= 100
    sys_status, battery = fresh(gcs)
    assert not sys_status.onboard_control_sensors_health & m.MAV_SYS_STATUS_SENSOR_BATTERY
    assert battery.charge_state == m.MAV_BATTERY_CHARGE_STATE_UNHEALTHY
    assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == m.MAV_RESULT_DENIED
    assert stack.sim.battery.inject_failure(m.FAILURE_TYPE_OK)
    gcs.wait(lambda g: g.stack.autopilot.battery.status.time_s > g.stack.t - 0.1, sim_timeout=1.0,
             what="reports again")  # fmt: skip
    sys_status, _ = fresh(gcs)
    assert sys_status.onboard_control_sensors_health & m.MAV_SYS_STATUS_SENSOR_BATTERY
    gcs.close()


def test_a_wrong_voltage_divider_reads_over_voltage_a_fault():
    stack = make_stack()
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    streams(gcs)
    assert stack.sim.battery.inject_failure(m.FAILURE_TYPE_WRONG)  # a full pack reads 10 % high
    gcs.wait(lambda g: "Battery 1: over voltage." in g.statustext, sim_timeout=3.0, what="over voltage")
    sys_status, battery = fresh(gcs)
    assert battery.fault_bitmask == m.MAV_BATTERY_FAULT_SPIKES
    assert battery.charge_state == m.MAV_BATTERY_CHARGE_STATE_UNHEALTHY
    assert not sys_status.onboard_control_sensors_health & m.MAV_SYS_STATUS_SENSOR_BATTERY
    gcs.close()


def test_without_a_battery_monitor_the_battery_is_unknown():
    stack = make_stack(battery={"enabled": False})
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    streams(gcs)
    gcs.last.pop("SYS_STATUS", None)
    gcs.wait(lambda g: "SYS_STATUS" in g.last, sim_timeout=1.0, what="SYS_STATUS")
    status = gcs.last["SYS_STATUS"]
    assert (status.voltage_battery, status.current_battery, status.battery_remaining) == (65535, -1, -1)
    assert not status.onboard_control_sensors_present & m.MAV_SYS_STATUS_SENSOR_BATTERY
    assert "BATTERY_STATUS" not in gcs.last
    gcs.close()
