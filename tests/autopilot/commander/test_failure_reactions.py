"""The vehicle's answer to a failure, as PX4's (the whole stack in-process, simulation time): the
autopilot learns of a failure only from its data (a sensor that stops, repeats, or lies), judges
its estimates and sensors (commander/health.py) and reacts by PX4's rules: a mission without GPS
falls back RTL -> Land -> Descend and lands; a motion capture lost does the same; a barometer or
magnetometer lost or stuck lets the mission go on; an IMU that stops ends in flight termination.
Each reaction is announced, reported (SYS_STATUS bits, HEARTBEAT, GPS_RAW_INT, the failsafe flags)
and undone when the data returns. PX4's own tests of the same: test/mavsdk_tests/
test_multicopter_failsafe.cpp ("Land on GPS lost during mission", "Continue on mag/baro
lost/stuck during mission"). The flights with a failure in the square mission start from copies of
one flight of it to its takeoff (:func:`mission`), so each costs only its own seconds."""

from __future__ import annotations

import copy
import copyreg
import math
import struct

import pytest
from pymavlink.dialects.v20 import common as m

from autopilot.control.config import load_controller
from autopilot.core import AutopilotSetup
from gcs_scripts.upload_mission import MissionLink, items_from_list
from simulator.core import SimulatorSetup
from simulator.sensors import SensorFault
from simulator.sensors.frame import BARO_READING, DELIVERY
from sitl.inprocess import Lockstep
from tests.stack import Gcs, connect

pytestmark = pytest.mark.timeout(300)

# The flight is copied for each test; pymavlink's codec keeps precompiled struct.Struct objects,
# which copy by their format string.
copyreg.pickle(struct.Struct, lambda s: (struct.Struct, (s.format,)))
LAND_MODE = (4 << 16) | (6 << 24)  # AUTO.LAND: PX4 shows Descend as it
SQUARE = {
    "frame": "paper",
    "items": [
        {"type": "takeoff", "altitude_m": 6.0},
        {"type": "waypoint", "position": [6.0, 0.0, 6.0]},
        {"type": "waypoint", "position": [6.0, 6.0, 6.0]},
        {"type": "waypoint", "position": [0.0, 6.0, 6.0]},
        {"type": "rtl"},
    ],
}


def stack_with(sensors: str, estimator: str = "ekf") -> Lockstep:
    sim = SimulatorSetup.load(scenario="hover", sensors=sensors)
    ap = AutopilotSetup(sim.sitl, sim.vehicle, load_controller("intbs_nlhinf"), default_remotes=False,
                        estimator=estimator, estimator_profile=sensors)  # fmt: skip
    return Lockstep(sim, ap)


def break_sensors(stack: Lockstep, monkeypatch) -> dict:
    """The simulator's frames with a sensor broken as the returned dict says (set its keys):
    ``baro``/``mag`` "lost" (no fresh sample) or "stuck" (the value at that moment, repeated),
    ``imu`` "nan" (non-finite samples). Broken in the sensors' delivery, which the frame reads
    (``SensorSuite.deliver``, the ``DELIVERY`` layout)."""
    suite = stack.sim.sensors
    deliver = suite.deliver
    broken: dict = {}
    held: dict = {}
    at = DELIVERY
    baro = slice(at.held_baro_time, at.held_baro_time + BARO_READING.size)
    mag = slice(at.held_mag, at.held_mag + 3)

    def broken_deliver(t, truth):
        d = deliver(t, truth)
        if broken.get("baro") == "lost":
            d[at.baro_fresh] = 0.0
        elif broken.get("baro") == "stuck":
            d[baro] = held.setdefault("baro", d[baro].copy())
        if broken.get("mag") == "lost":
            d[at.mag_fresh] = 0.0
        elif broken.get("mag") == "stuck":
            d[mag] = held.setdefault("mag", d[mag].copy())
        if broken.get("imu") == "nan":
            d[at.force : at.force + 3] = math.nan
            d[at.rate : at.rate + 3] = math.nan
        return d

    monkeypatch.setattr(suite, "deliver", broken_deliver)
    return broken


def ready(stack: Lockstep, gcs: Gcs) -> None:
    commander = stack.autopilot.commander
    gcs.wait(lambda g: commander.estimator_problem is None and not commander.in_air()
             and "SYS_STATUS" in g.last, sim_timeout=30.0, what="converged, on the ground")  # fmt: skip
    gcs.wait(lambda g: commander.flags.global_position_invalid is False, sim_timeout=3.0, what="position")


def fly_mission(stack: Lockstep) -> Gcs:
    link = connect(stack, MissionLink)
    link.upload(items_from_list(SQUARE))
    link.close()
    gcs = Gcs(stack)
    ready(stack, gcs)
    assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == m.MAV_RESULT_ACCEPTED
    assert gcs.command(m.MAV_CMD_MISSION_START, 0, 0).result == m.MAV_RESULT_ACCEPTED
    gcs.wait(lambda g: "LOCAL_POSITION_NED" in g.last and g.position()[2] > 5.5, sim_timeout=20.0,
             what="the mission's takeoff")  # fmt: skip
    return gcs


@pytest.fixture(scope="module")
def _mission_taken_off() -> tuple[Lockstep, Gcs]:
    stack = stack_with("gps")
    return stack, fly_mission(stack)


@pytest.fixture
def mission(_mission_taken_off) -> tuple[Lockstep, Gcs]:
    """The square mission on the EKF over GPS, flown to its takeoff (:func:`fly_mission`): a copy of
    one such flight for each test, the same as flying it again (the stack is deterministic)."""
    return copy.deepcopy(_mission_taken_off)


def fresh(gcs: Gcs, kind: str):
    gcs.last.pop(kind, None)
    gcs.wait(lambda g: kind in g.last, sim_timeout=2.0, what=kind)
    return gcs.last[kind]


def said(gcs: Gcs, text: str) -> None:
    """``text`` arrives (all its chunks) within 0.5 s."""
    gcs.wait(lambda g: text in texts(g), sim_timeout=0.5, what=repr(text))


def texts(gcs: Gcs) -> str:
    return "".join(gcs.statustext)  # (a long STATUSTEXT comes in 50-byte chunks)


def test_gps_lost_in_a_mission_falls_back_to_descend_and_lands(mission):
    stack, gcs = mission
    commander = stack.autopilot.commander
    t_lost = stack.t
    stack.sim.sensors.add_fault(SensorFault("gps_outage", t_lost, 1000.0))
    gcs.wait(lambda g: "Failsafe activated" in texts(g), sim_timeout=10.0, what="the failsafe")
    # The EKF dead reckons for EKF2_NOAID_TOUT (5 s), then the position is invalid: no Mission, no
    # Return, no Land (all need a position): Descend.
    assert 4.5 < stack.t - t_lost < 7.0
    said(gcs, "Failsafe activated: no global position for AUTO.MISSION, triggering Descend")
    flags = commander.flags
    assert flags.global_position_invalid and flags.local_position_invalid and not flags.local_altitude_invalid
    assert flags.gps.present and flags.gps.problem == "no 3D fix"
    heartbeat = fresh(gcs, "HEARTBEAT")
    assert heartbeat.custom_mode == LAND_MODE
    assert heartbeat.system_status == m.MAV_STATE_CRITICAL
    sys_status = fresh(gcs, "SYS_STATUS")
    assert sys_status.onboard_control_sensors_present & m.MAV_SYS_STATUS_SENSOR_GPS
    assert not sys_status.onboard_control_sensors_health & m.MAV_SYS_STATUS_SENSOR_GPS
    assert not sys_status.onboard_control_sensors_health & m.MAV_SYS_STATUS_SENSOR_XY_POSITION_CONTROL
    assert sys_status.onboard_control_sensors_health & m.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
    assert fresh(gcs, "GPS_RAW_INT").fix_type < m.GPS_FIX_TYPE_3D_FIX
    assert not fresh(gcs, "ESTIMATOR_STATUS").flags & m.ESTIMATOR_POS_HORIZ_ABS
    # PX4's test: disarmed within 30 s; the descent is level, at MPC_LAND_SPEED.
    gcs.wait(lambda g: not stack.autopilot.commander.armed, sim_timeout=30.0, what="landed and disarmed")
    assert "landing detected" in texts(gcs)
    assert texts(gcs).count("Failsafe activated") == 1  # taken once


def test_gps_back_during_the_descent_resumes_the_mission(mission):
    stack, gcs = mission
    commander = stack.autopilot.commander
    stack.sim.sensors.add_fault(SensorFault("gps_outage", stack.sim.t, 7.0))
    gcs.wait(lambda g: "triggering Descend" in texts(g), sim_timeout=10.0, what="the descent")
    gcs.wait(lambda g: "Failsafe deactivated: back to AUTO.MISSION" in texts(g), sim_timeout=15.0,
             what="the mission again")  # fmt: skip
    assert commander.armed and commander.in_air() and commander.mode.name == "AUTO_MISSION"
    assert not commander.flags.global_position_invalid and commander.flags.gps.healthy
    gcs.wait(lambda g: not commander.armed, sim_timeout=120.0, what="the mission flown to its end")
    assert "mission: flying item" in texts(gcs)


def test_vision_lost_under_motion_capture_descends_and_lands():
    stack = stack_with("mocap")
    gcs = Gcs(stack)
    ready(stack, gcs)
    commander = stack.autopilot.commander
    assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == m.MAV_RESULT_ACCEPTED
    nan = math.nan
    assert gcs.command(m.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, nan, nan, nan, 488.0 + 3.0).result == 0
    gcs.wait(lambda g: commander.phase.name == "HOLD", sim_timeout=20.0, what="holding")
    t_lost = stack.t
    stack.sim.sensors.add_fault(SensorFault("vision_outage", t_lost, 1000.0))
    gcs.wait(lambda g: "Failsafe activated" in texts(g), sim_timeout=10.0, what="the failsafe")
    assert 4.5 < stack.t - t_lost < 7.0  # EKF2_NOAID_TOUT
    said(gcs, "Failsafe activated: no global position for AUTO.LOITER, triggering Descend")
    assert commander.flags.vision.problem == "stopped"
    sys_status = fresh(gcs, "SYS_STATUS")
    assert sys_status.onboard_control_sensors_present & m.MAV_SYS_STATUS_SENSOR_VISION_POSITION
    assert not sys_status.onboard_control_sensors_health & m.MAV_SYS_STATUS_SENSOR_VISION_POSITION
    assert not sys_status.onboard_control_sensors_present & m.MAV_SYS_STATUS_SENSOR_GPS  # none indoors
    gcs.wait(lambda g: not commander.armed, sim_timeout=30.0, what="landed and disarmed")


@pytest.mark.parametrize("sensor, how", [("baro", "lost"), ("baro", "stuck"), ("mag", "lost"),
                                         ("mag", "stuck")])  # fmt: skip
def test_a_mission_goes_on_without_its_barometer_or_magnetometer(sensor, how, mission, monkeypatch):
    stack, gcs = mission
    broken = break_sensors(stack, monkeypatch)  # (nothing broken yet: the frames as they were)
    commander = stack.autopilot.commander
    broken[sensor] = how
    seen = set()
    bit = {"baro": m.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE, "mag": m.MAV_SYS_STATUS_SENSOR_3D_MAG}[sensor]

    def watch(g) -> bool:
        health = commander.flags.sensor(sensor)
        if not health.healthy:
            seen.add(health.problem)
            status = g.last.get("SYS_STATUS")
            if status is not None and not status.onboard_control_sensors_health & bit:
                seen.add("reported")
        return not commander.armed

    gcs.wait(watch, sim_timeout=120.0, what="the mission flown to its end, landed")
    expected = {"lost": "stopped", "stuck": "stuck"}[how]
    assert expected in seen and "reported" in seen, seen
    assert "Failsafe activated" not in texts(gcs)  # PX4: continue (height from GPS, heading kept)
    assert "mission: flying item 4" in texts(gcs) or "returning" in texts(gcs)
    x, y, _ = stack.sim.plant.truth().position_m
    assert math.hypot(x, y) < 1.5  # back home


def test_an_imu_that_stops_in_flight_terminates_the_flight(monkeypatch):
    stack = stack_with("gps")
    broken = break_sensors(stack, monkeypatch)
    gcs = Gcs(stack)
    ready(stack, gcs)
    commander = stack.autopilot.commander
    assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == m.MAV_RESULT_ACCEPTED
    nan = math.nan
    assert gcs.command(m.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, nan, nan, nan, 488.0 + 3.0).result == 0
    gcs.wait(lambda g: commander.phase.name == "HOLD", sim_timeout=20.0, what="holding")
    t_lost = stack.t
    broken["imu"] = "nan"
    gcs.wait(lambda g: not commander.armed, sim_timeout=3.0, what="the termination")
    assert 0.9 < stack.t - t_lost < 1.2  # PX4: the angular velocity is invalid after 1 s
    said(gcs, "Failsafe activated: no angular velocity for AUTO.LOITER, triggering Terminate")
    said(gcs, "flight terminated: motors off")
    assert commander.flags.angular_velocity_invalid and commander.flags.gyro.problem == "stopped"
    heartbeat = fresh(gcs, "HEARTBEAT")
    assert heartbeat.system_status == m.MAV_STATE_FLIGHT_TERMINATION
    assert not fresh(gcs, "SYS_STATUS").onboard_control_sensors_health & m.MAV_SYS_STATUS_SENSOR_3D_GYRO


def test_on_the_truth_a_failed_sensor_refuses_arming_until_it_returns(monkeypatch):
    """EKF2_EN 0: the vehicle flies on the simulator's state, so nothing it flies on fails; but the
    sensors' health still follows their data, and PX4 refuses to arm with a failed sensor. An
    ideal (noise-free) barometer repeating its value at rest is not a failure."""
    stack = stack_with("ideal", estimator="truth")
    broken = break_sensors(stack, monkeypatch)
    gcs = Gcs(stack)
    gcs.wait(lambda g: "SYS_STATUS" in g.last, what="SYS_STATUS")
    stack.run_for(3.0)  # an exact barometer at rest repeats its value: healthy still
    commander = stack.autopilot.commander
    assert commander.flags.baro.healthy and commander.flags.mag.healthy
    broken["baro"] = "lost"
    gcs.wait(lambda g: not commander.flags.baro.healthy, sim_timeout=2.0, what="the barometer stopped")
    assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == m.MAV_RESULT_DENIED
    said(gcs, "arming refused: sensor failure: barometer (stopped)")
    status = fresh(gcs, "SYS_STATUS")
    assert not status.onboard_control_sensors_health & m.MAV_SYS_STATUS_SENSOR_ABSOLUTE_PRESSURE
    assert not status.onboard_control_sensors_health & m.MAV_SYS_STATUS_PREARM_CHECK
    broken.clear()
    gcs.wait(lambda g: commander.flags.baro.healthy, sim_timeout=2.0, what="the barometer back")
    said(gcs, "sensor stream resumed: barometer")
    assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == m.MAV_RESULT_ACCEPTED


def test_a_noise_free_imu_after_a_landing_on_the_ekf_is_not_stuck():
    """At the touchdown the plant stops in a frame and a noise-free IMU reads exactly g and 0 from
    then on, while the EKF's velocity settles from the landing speed to 0: that change is the
    estimate's, not the vehicle's, and the IMU (and the GPS) at rest are healthy: arming again is
    accepted. (A stuck accelerometer in flight is still caught: test_failures_flown.py.)"""
    stack = stack_with("ideal")
    gcs = Gcs(stack)
    ready(stack, gcs)
    commander = stack.autopilot.commander
    assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == m.MAV_RESULT_ACCEPTED
    nan = math.nan
    assert gcs.command(m.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, nan, nan, nan, 488.0 + 2.0).result == 0
    gcs.wait(lambda g: commander.phase.name == "HOLD", sim_timeout=20.0, what="holding")
    assert gcs.command(m.MAV_CMD_NAV_LAND, 0, 0, 0, nan, nan, nan, nan).result == 0
    gcs.wait(lambda g: not commander.armed, sim_timeout=20.0, what="landed and disarmed")
    stack.run_for(2.0)  # the filter's velocity settled; the IMU's values repeated all along
    assert stack.autopilot.commander.health._stuck["accel"].equal > 100  # frozen: judged by the motion
    flags = commander.flags
    assert flags.accel.healthy and flags.gyro.healthy and flags.gps.healthy, flags
    assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == m.MAV_RESULT_ACCEPTED, texts(gcs)[-300:]
