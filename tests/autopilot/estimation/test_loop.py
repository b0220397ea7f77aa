"""The autopilot flying on its own estimate (EKF2_EN = 1): the whole stack in-process, simulation
time, seeded sensors. Arming waits for the filter and says why; telemetry reports the estimate;
ESTIMATOR_STATUS and the SYS_STATUS health bits follow it; EKF2_EN switches only on the ground."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as m

from autopilot.control.config import load_controller
from autopilot.core import AutopilotSetup
from autopilot.estimation.loop import EstimatorLoop
from autopilot.estimation.parameters import estimator_params
from autopilot.records import SensorSamples, StateEstimate, VisionPose
from quadcommon.atmosphere import isa_altitude_m
from simulator.core import SimulatorSetup
from simulator.sensors import SensorFault
from simulator.sensors.frame import DELIVERY
from sitl.inprocess import Lockstep
from tests.sitl.test_params_failsafes import INT32, param_set
from tests.stack import Gcs, make_stack

pytestmark = pytest.mark.timeout(120)


def ekf_stack(sensors: str) -> Lockstep:
    sim = SimulatorSetup.load(scenario="hover", sensors=sensors)
    ap = AutopilotSetup(sim.sitl, sim.vehicle, load_controller("intbs_nlhinf"), default_remotes=False,
                        estimator="ekf", estimator_profile=sensors)  # fmt: skip
    return Lockstep(sim, ap)


def truth_position(stack: Lockstep) -> tuple[float, float, float]:
    return stack.sim.plant.truth().position_m


def arm(gcs: Gcs) -> int:
    return gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1).result


@pytest.mark.parametrize("sensors", ["gps", "mocap"])
def test_arming_waits_for_the_filter_then_the_vehicle_flies_on_its_estimate(sensors):
    stack = ekf_stack(sensors)
    gcs = Gcs(stack)
    gcs.wait(lambda g: "SYS_STATUS" in g.last, what="SYS_STATUS")
    assert arm(gcs) == m.MAV_RESULT_DENIED  # aligning: no estimate yet, or not converged
    gcs.wait(lambda g: any(t.startswith("arming refused") for t in g.statustext), sim_timeout=0.5,
             what="the reason")  # fmt: skip
    assert "arming refused: no position (estimator not ready: aligning" in "".join(gcs.statustext)
    assert not gcs.last["SYS_STATUS"].onboard_control_sensors_health & m.MAV_SYS_STATUS_AHRS
    gcs.wait(lambda g: stack.autopilot.commander.estimator_problem is None, sim_timeout=20.0,
             what="the filter converged")  # fmt: skip
    gcs.last.pop("ESTIMATOR_STATUS", None)
    gcs.wait(lambda g: "ESTIMATOR_STATUS" in g.last, sim_timeout=2.0, what="ESTIMATOR_STATUS")
    status = gcs.last["ESTIMATOR_STATUS"]
    assert status.flags & m.ESTIMATOR_ATTITUDE and status.flags & m.ESTIMATOR_POS_HORIZ_REL
    gcs.last.pop("SYS_STATUS")
    gcs.wait(lambda g: "SYS_STATUS" in g.last, what="SYS_STATUS")
    assert gcs.last["SYS_STATUS"].onboard_control_sensors_health & m.MAV_SYS_STATUS_AHRS
    assert arm(gcs) == m.MAV_RESULT_ACCEPTED
    nan = math.nan
    assert gcs.command(m.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, nan, nan, nan, 488.0 + 2.0).result == 0
    gcs.wait(lambda g: "LOCAL_POSITION_NED" in g.last and g.position()[2] > 1.9, sim_timeout=20.0,
             what="takeoff")  # fmt: skip
    stack.run_for(3.0)
    while gcs.conn.station.inbox:  # the telemetry of those 3 s, up to the last frame
        gcs.poll()
    reported = np.array(gcs.position())
    truth = np.array(truth_position(stack))
    estimate = np.array(stack.autopilot.commander.state.position_m)
    assert np.allclose(reported, estimate, atol=0.02)  # telemetry is the estimate, not the truth
    bound = 0.01 if sensors == "mocap" else 0.5
    assert np.linalg.norm(truth - estimate) < bound
    assert abs(truth[2] - 2.0) < bound + 0.05  # flown on the estimate, the truth holds the height


def test_an_in_air_start_flies_the_paper_on_the_filter_from_the_first_frame():
    sim = SimulatorSetup.load(scenario="helix", sensors="mocap")
    ap = AutopilotSetup(sim.sitl, sim.vehicle, load_controller("intbs_nlhinf"), default_remotes=False,
                        estimator="ekf", estimator_profile="mocap")  # fmt: skip
    from quadcommon.config import load_scenario
    from quadcommon.trajectories import trajectory_from_spec

    ap = replace(ap, autostart=trajectory_from_spec(load_scenario("helix").trajectory))
    stack = Lockstep(sim, ap)
    stack.run_for(5.0)
    rows = np.asarray(stack.estimator_rows)
    truth = np.asarray(stack.truth_rows)
    assert len(rows) == len(truth) and not np.isnan(rows[:, 1:4]).any()  # an estimate at every frame
    error = rows[:, 1:4] - truth[:, 1:4]
    assert np.abs(error).max() < 0.01


def test_ekf2_en_takes_effect_only_while_disarmed():
    stack = make_stack(sensors="gps")
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    ap = stack.autopilot
    assert ap.estimator is None  # EKF2_EN = 0: the truth, the paper's assumption
    assert arm(gcs) == m.MAV_RESULT_ACCEPTED
    assert param_set(gcs, "EKF2_EN", 1, INT32).param_value != 0
    stack.run_for(1.0)
    assert ap.estimator is None  # armed: no switch
    assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 0).result == m.MAV_RESULT_ACCEPTED
    stack.run_for(0.1)
    assert ap.estimator is not None  # disarmed: the EKF starts (and must align before arming)
    assert arm(gcs) == m.MAV_RESULT_DENIED


def test_a_gps_glitch_is_rejected_in_flight_and_the_vehicle_holds():
    stack = ekf_stack("gps")
    gcs = Gcs(stack)
    commander = stack.autopilot.commander
    # Converged, and its height (GPS: 0.5 m vertical noise) reads on the ground: arming wants both.
    gcs.wait(lambda g: commander.estimator_problem is None and not commander.in_air(), sim_timeout=20.0,
             what="the filter converged, on the ground")  # fmt: skip
    assert arm(gcs) == m.MAV_RESULT_ACCEPTED
    nan = math.nan
    assert gcs.command(m.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, nan, nan, nan, 488.0 + 2.0).result == 0
    gcs.wait(lambda g: "LOCAL_POSITION_NED" in g.last and g.position()[2] > 1.9, sim_timeout=20.0,
             what="takeoff")  # fmt: skip
    stack.run_for(2.0)
    before = np.array(truth_position(stack))
    stack.sim.sensors.add_fault(SensorFault("gps_glitch", stack.sim.t, 2.0, (10.0, 0.0, 0.0)))
    stack.run_for(4.0)
    after = np.array(truth_position(stack))
    assert np.linalg.norm(after - before) < 0.5  # a 10 m jump for 2 s does not move the vehicle
    assert stack.autopilot.estimator.ekf.sources["gps_pos"].rejected >= 10


def test_non_finite_sensor_samples_are_refused_at_the_edge_and_the_flight_goes_on(monkeypatch):
    """A broken simulator sends NaN in HIL_SENSOR's IMU for 5 frames, then NaN compass, baro and
    vision samples for 0.1 s: none reaches the filter (each counted), the estimate stays finite
    and the vehicle flies the helix on as if nothing happened (a NaN once in the filter is there
    for good: before this test, the vehicle fell)."""
    from quadcommon.config import load_scenario
    from quadcommon.trajectories import trajectory_from_spec

    sim = SimulatorSetup.load(scenario="helix", sensors="mocap")
    ap = AutopilotSetup(sim.sitl, sim.vehicle, load_controller("intbs_nlhinf"), default_remotes=False,
                        estimator="ekf", estimator_profile="mocap")  # fmt: skip
    stack = Lockstep(sim, replace(ap, autostart=trajectory_from_spec(load_scenario("helix").trajectory)))
    stack.run_for(2.0)
    suite, nan = stack.sim.sensors, math.nan
    deliver, broken, at = suite.deliver, set(), DELIVERY

    def broken_deliver(t, truth):  # the suite's delivery with the broken fields, as the frame reads it
        d = deliver(t, truth)
        if "imu" in broken:
            d[at.force] = nan
        if "aiding" in broken:
            d[at.held_mag] = nan
            d[at.held_baro_altitude] = math.inf
            d[at.vision_position] = nan  # (counted only when a pose is due)
        return d

    monkeypatch.setattr(suite, "deliver", broken_deliver)
    broken.add("imu")
    stack.run_for(0.01)  # 5 frames
    broken.clear()
    broken.add("aiding")
    stack.run_for(0.1)
    broken.clear()
    stack.run_for(2.0)
    dropped = stack.autopilot.dropped
    assert dropped["HIL frame with a non-finite imu sample"] == 5
    assert dropped["HIL frame with a non-finite vision sample"] >= 9  # 100 Hz
    assert dropped["HIL frame with a non-finite mag sample"] >= 1
    assert dropped["HIL frame with a non-finite baro sample"] >= 1
    rows, truth = np.asarray(stack.estimator_rows), np.asarray(stack.truth_rows)
    assert len(rows) == len(truth) and np.isfinite(rows[:, 1:10]).all()
    assert np.abs(rows[:, 1:4] - truth[:, 1:4]).max() < 0.01  # the estimate never left the truth
    ref = np.asarray(stack.controller_rows)[-1, 1:4]
    assert np.linalg.norm(truth[-1, 1:4] - ref) < 0.01  # still on the helix
    assert not stack.autopilot.faults.counts


@pytest.mark.parametrize("sensors", ["gps", "mocap"])
def test_highres_imu_on_request_reports_the_sensors_on_the_ekf(sensors):
    """HIGHRES_IMU (MAVSDK's Telemetry.imu) as PX4 fills it: acceleration and rates, the
    magnetometer and the barometer of the frames' HIL_SENSOR (the samples the filter reads),
    finite, with their fields_updated bits; the simulator's barometer is an ISA one."""
    stack = ekf_stack(sensors)
    gcs = Gcs(stack)
    gcs.wait(lambda g: "SYS_STATUS" in g.last, what="SYS_STATUS")
    stack.run_for(2.0)  # at rest on the ground: the magnetometer and the barometer have sampled
    request = gcs.command(m.MAV_CMD_REQUEST_MESSAGE, m.MAVLINK_MSG_ID_HIGHRES_IMU)
    assert request.result == m.MAV_RESULT_ACCEPTED
    gcs.wait(lambda g: "HIGHRES_IMU" in g.last, sim_timeout=0.5, what="HIGHRES_IMU")
    imu = gcs.last["HIGHRES_IMU"]
    values = [getattr(imu, name) for name in imu.fieldnames if name not in ("time_usec", "fields_updated")]
    assert all(math.isfinite(v) for v in values), imu
    assert imu.fields_updated == 0b1101111111111  # acc, gyro, mag, abs_pressure, pressure_alt, temperature
    assert imu.zacc == pytest.approx(-9.81, abs=0.3)  # specific force FRD at rest
    field = stack.sim.sensors.config.earth_field_world_gauss  # paper world (x north, y west, z up)
    level_north = (field[0], -field[1], -field[2])  # body FRD = NED, level and facing north
    assert (imu.xmag, imu.ymag, imu.zmag) == pytest.approx(level_north, abs=0.05)
    assert imu.pressure_alt == pytest.approx(stack.autopilot.setup.sitl.home[2], abs=5.0)  # a baro offset
    assert isa_altitude_m(imu.abs_pressure) == pytest.approx(imu.pressure_alt, abs=0.01)
    assert imu.temperature == pytest.approx(11.8, abs=0.1)  # ISA at ~488 m: 15 - 6.5 K/km
    assert imu.diff_pressure == 0.0  # no airspeed sensor: its bit is clear


def test_the_loop_reads_the_estimate_again_only_after_it_changed_the_filter():
    """A frame without aiding reads the estimate twice (before and after its answer): the same
    record; a prediction, a fusion of the frame's aiding or of a client's vision gives a new one."""
    loop = EstimatorLoop(estimator_params({"EKF2_EV_CTRL": 15}), 0.002)  # vision fused too
    imu_only = SensorSamples((0.0, 0.0, 0.0), (0.0, 0.0, 9.81), None, None, None, None, (), True)
    loop.start_in_air(0.0, imu_only, StateEstimate((0.0, 0.0, 5.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0),
                                                   (0.0, 0.0, 0.0)))  # fmt: skip
    before = loop.predict(0.002, imu_only)
    loop.fuse()  # nothing to fuse
    assert loop.estimate() is before
    with_baro = imu_only._replace(baro_height_m=5.5)
    predicted = loop.predict(0.004, with_baro)
    assert predicted is not before
    loop.fuse()
    fused = loop.estimate()
    assert fused is not predicted and fused.position_m[2] > predicted.position_m[2]  # pulled up to 5.5 m
    loop.external_vision(VisionPose(0.004, (0.2, 0.0, 5.0), 0.0, 0.05, 0.05))
    predicted = loop.predict(0.006, imu_only)
    loop.fuse()
    assert loop.estimate() is not predicted
    assert loop.estimate().position_m[0] > predicted.position_m[0]  # the client's pose, 0.2 m ahead
