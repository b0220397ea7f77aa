"""MAV_CMD_INJECT_FAILURE through the whole stack in-process, as PX4 users send it (MAVSDK's Failure
plugin, ``quadsitl fail``): refused while SYS_FAILURE_EN is 0 and for what the table does not model,
accepted otherwise and announced in PX4's words; a failure of the simulator's travels in the next
lockstep answer and acts from the frame after it, on the data the vehicle receives; the links'
failures act in the autopilot and the existing failsafes follow."""

from __future__ import annotations

import math

import pytest
from pymavlink.dialects.v20 import common as m

from autopilot.control.config import load_controller
from autopilot.core import AutopilotSetup
from gcs_scripts.fail import inject
from quadcommon.config import estimator_profile_for
from quadcommon.failures import FAILURES, Type, Unit, Where
from quadcommon.mavlink_fast import MessageParts, split_frames
from quadcommon.wire import LockstepAnswer, new_parser, parse_datagram
from simulator.core import SimulatorSetup
from simulator.dynamics.plant import ROTOR_POSITIONS
from sitl.inprocess import Lockstep
from tests.sitl.test_params_failsafes import INT32, keep_link, param_set, take_off
from tests.stack import Gcs, connect, make_stack

pytestmark = pytest.mark.timeout(120)

INJECT = m.MAV_CMD_INJECT_FAILURE


class Wire:
    """The lockstep datagrams as they cross, by frame: the simulator's frames and the answers."""

    def __init__(self, stack: Lockstep) -> None:
        self.frames: list[tuple[int, bytes]] = []
        self.answers: list[tuple[int, bytes | None]] = []
        sim, ap = stack.sim, stack.autopilot
        begin, answer = sim.begin_frame_parts, ap.on_hil_frame

        def frame() -> MessageParts:
            parts = begin()
            self.frames.append((sim.k, sim.frame_datagram))
            return parts

        def answered(parts: MessageParts, now: float) -> LockstepAnswer | None:
            reply = answer(parts, now)
            self.answers.append((sim.k, reply.datagram if reply is not None else None))
            return reply

        sim.begin_frame_parts, ap.on_hil_frame = frame, answered

    def request_frames(self) -> list[int]:
        """The frames whose answers carried a request to the simulator (a COMMAND_LONG)."""
        return [k for k, data in self.answers if data is not None
                and any(i == m.MAVLINK_MSG_ID_COMMAND_LONG for i, _ in split_frames(data))]  # fmt: skip

    def messages(self, since: int, kind: str) -> list[tuple[int, object]]:
        parser = new_parser()
        return [(k, msg) for k, data in self.frames if k >= since
                for msg in parse_datagram(parser, data) if msg.get_type() == kind]  # fmt: skip


def ekf_stack(vehicle: str | None = None, enabled: bool = True) -> tuple[Lockstep, Gcs]:
    """On the ground, flying on the EKF (gps profile), SYS_FAILURE_EN as asked; a ground station."""
    sim = SimulatorSetup.load(scenario="hover", vehicle=vehicle, sensors="gps")
    ap = AutopilotSetup(sim.sitl, sim.vehicle, load_controller("intbs_nlhinf"), default_remotes=False,
                        estimator="ekf", estimator_profile=estimator_profile_for("gps"))  # fmt: skip
    stack = Lockstep(sim, ap)
    stack.autopilot.params.set("SYS_FAILURE_EN", 1.0 if enabled else 0.0)
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    return stack, gcs


def texts(gcs: Gcs) -> str:
    """Every STATUSTEXT so far (what is waiting read first; a long text's 50-byte chunks joined)."""
    while gcs.conn.station.inbox:
        gcs.poll()
    return "".join(gcs.statustext)


def command(gcs: Gcs, unit: int, failure_type: int, instance: float = 0.0, param4: float = 0.0) -> int:
    return gcs.command(INJECT, unit, failure_type, instance, param4).result


def test_refused_while_sys_failure_en_is_0_with_the_reason():
    stack = make_stack()
    wire = Wire(stack)
    link = connect(stack)
    said: list[str] = []
    assert inject(link, Unit.gps, Type.off, out=said.append) == m.MAV_RESULT_DENIED
    assert said == ["failure gps off (instance 0): DENIED: failure injection disabled: set SYS_FAILURE_EN to "
                    "1"]  # fmt: skip
    stack.run_for(0.1)
    assert wire.request_frames() == [] and stack.sim.failures == {}
    assert stack.autopilot.params["SYS_FAILURE_EN"] == 0.0  # PX4's default


def test_enable_then_inject_as_quadsitl_fail_does():
    stack, gcs = ekf_stack(enabled=False)
    link = connect(stack)
    said: list[str] = []
    assert inject(link, Unit.baro, Type.stuck, enable=True, out=said.append) == m.MAV_RESULT_ACCEPTED
    assert said == ["SYS_FAILURE_EN = 1", "failure baro stuck (instance 0): ACCEPTED: Injected: baro stuck, "
                    "all instances"]  # fmt: skip
    stack.run_for(0.01)
    assert stack.sim.failures == {"baro": "stuck"}


def test_every_pair_the_table_does_not_model_is_unsupported():
    stack, gcs = ekf_stack()
    for unit in Unit:
        model = FAILURES.get(unit)
        for failure_type in Type:
            if model is None or failure_type not in model.types:
                assert command(gcs, unit, failure_type) == m.MAV_RESULT_UNSUPPORTED, (unit, failure_type)
    said = texts(gcs)
    assert "failure servo not supported: this vehicle has no servos" in said
    assert "failure gyro delayed not supported (modelled: ok, off, stuck, garbage, wrong, slow, " \
           "intermittent)" in said  # fmt: skip
    assert command(gcs, 107, Type.off) == m.MAV_RESULT_UNSUPPORTED  # not a MAVLink unit
    assert command(gcs, Unit.gps, Type.off, 2) == m.MAV_RESULT_DENIED  # one receiver
    assert command(gcs, Unit.gps, Type.off, 0.5) == m.MAV_RESULT_DENIED  # not an integer
    assert command(gcs, Unit.gps, Type.off, math.inf) == m.MAV_RESULT_DENIED
    assert stack.sim.failures == {} and stack.sim.requests_applied == 0


def test_sensor_failures_act_on_the_ekf_and_a_motor_fails_on_the_wrench_vehicle_too():
    stack = make_stack()  # truth (EKF2_EN 0), the wrench vehicle
    stack.autopilot.params.set("SYS_FAILURE_EN", 1.0)
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    assert command(gcs, Unit.gps, Type.off) == m.MAV_RESULT_DENIED
    assert "failure gps acts on the EKF: this vehicle flies on the simulator's state (EKF2_EN 0); start " \
           "it with --estimator ekf (EKF2_EN 1)" in texts(gcs)  # fmt: skip
    assert command(gcs, Unit.gps, Type.ok) == m.MAV_RESULT_ACCEPTED  # a recovery always passes
    # the ideal wrench's rotor: its share of the wrench (the allocation's equation)
    assert command(gcs, Unit.motor, Type.off, 1) == m.MAV_RESULT_ACCEPTED
    stack.step()
    assert stack.sim.plant.rotor_effectiveness[ROTOR_POSITIONS.index("right")] == 0.0


SENSOR_PAIRS = [(m_.unit, t) for m_ in FAILURES.values() if m_.where is Where.SENSORS for t in m_.effects]


def test_each_sensor_failure_reaches_the_simulator_from_the_frame_after_its_answer():
    stack, gcs = ekf_stack()
    wire = Wire(stack)
    dt = stack.sim.dt_control
    for unit, failure_type in SENSOR_PAIRS:
        for kind in (failure_type, Type.ok):
            wire.answers.clear()
            assert command(gcs, unit, kind) == m.MAV_RESULT_ACCEPTED
            stack.step()
            (k,) = wire.request_frames()  # the next answer carried it, once
            name = f"{unit.name}_{failure_type.name}"
            row = [f for f in stack.sim.sensors.faults if f.kind == name][-1]
            if kind == failure_type:
                assert row.start_s == pytest.approx((k + 1) * dt, abs=1e-12)
                assert f"Injected: {unit.name} {failure_type.name}, all instances" in texts(gcs)
            else:
                assert row.start_s + row.duration_s == pytest.approx((k + 1) * dt, abs=1e-12)
                assert f"Cleared: {unit.name}, all instances" in texts(gcs)
    assert stack.sim.requests_applied == 2 * len(SENSOR_PAIRS) and stack.sim.failures == {}


def fields_updated(wire: Wire, since: int) -> set[int]:
    return {msg.fields_updated for _, msg in wire.messages(since, "HIL_SENSOR")}


def test_the_frames_carry_the_failures_data_on_the_ground():
    stack, gcs = ekf_stack()
    wire = Wire(stack)
    for unit, bits in ((Unit.mag, 0x1C0), (Unit.gyro, 0x38), (Unit.accel, 0x7)):
        assert command(gcs, unit, Type.off) == m.MAV_RESULT_ACCEPTED
        stack.run_for(0.1)
        (k,) = wire.request_frames()[-1:]
        assert all(not updated & bits for updated in fields_updated(wire, k + 1)), unit
        assert command(gcs, unit, Type.ok) == m.MAV_RESULT_ACCEPTED
        stack.run_for(0.1)
        since = wire.request_frames()[-1] + 1
        again = [msg.fields_updated & bits for _, msg in wire.messages(since, "HIL_SENSOR")]
        fresh = len(again) if unit != Unit.mag else pytest.approx(len(again) / 10, abs=1)  # 50 Hz
        assert again.count(bits) == fresh


@pytest.mark.timeout(180)
def test_in_flight_gps_off_and_baro_stuck_are_in_the_data_and_recover():
    stack, gcs = ekf_stack()
    wire = Wire(stack)
    end = stack.t + 20.0
    while gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1).result != m.MAV_RESULT_ACCEPTED:
        assert stack.t < end, texts(gcs)  # the filter aligns and converges, the vehicle is landed
        stack.run_for(0.5)
    nan = math.nan
    assert gcs.command(m.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, nan, nan, nan, 488.0 + 2.0).result == 0
    gcs.wait(lambda g: "LOCAL_POSITION_NED" in g.last and g.position()[2] > 1.9, sim_timeout=20.0,
             what="takeoff")  # fmt: skip
    assert command(gcs, Unit.gps, Type.off) == m.MAV_RESULT_ACCEPTED  # in flight
    stack.run_for(1.0)
    (k,) = wire.request_frames()
    assert wire.messages(k + 1, "HIL_GPS") == [] and wire.messages(0, "HIL_GPS")  # none from k + 1 on
    assert "Injected: gps off, all instances" in texts(gcs)
    assert command(gcs, Unit.gps, Type.ok) == m.MAV_RESULT_ACCEPTED
    assert command(gcs, Unit.baro, Type.stuck) == m.MAV_RESULT_ACCEPTED
    stack.run_for(1.0)
    k = wire.request_frames()[-1]
    assert len(wire.messages(k + 1, "HIL_GPS")) >= 9  # 10 Hz again
    pressures = {msg.abs_pressure for _, msg in wire.messages(k + 1, "HIL_SENSOR")}
    updated = [msg.fields_updated & 0x200 for _, msg in wire.messages(k + 1, "HIL_SENSOR")]
    assert len(pressures) == 1 and sum(1 for u in updated if u) >= 45  # the same pressure, fresh at 50 Hz
    assert command(gcs, Unit.baro, Type.ok) == m.MAV_RESULT_ACCEPTED
    stack.run_for(0.5)
    since = wire.request_frames()[-1] + 1
    assert len({msg.abs_pressure for _, msg in wire.messages(since, "HIL_SENSOR")}) > 10
    assert stack.sim.failures == {} and stack.autopilot.info()["failures"]["active"] == {}


def test_a_motor_off_on_the_rotors_vehicle_in_the_plant_from_the_next_frame():
    stack = make_stack(vehicle="paper_quad_rotors")
    stack.autopilot.params.set("SYS_FAILURE_EN", 1.0)
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    wire = Wire(stack)
    assert command(gcs, Unit.motor, Type.off, 3) == m.MAV_RESULT_ACCEPTED  # PX4's motor 3: the front
    assert "Injected: motor off, instances 3" in texts(gcs)
    stack.step()
    assert wire.request_frames()
    assert stack.sim.plant.rotor_effectiveness[ROTOR_POSITIONS.index("front")] == 0.0
    assert stack.sim.failures == {"motor 3": "off"} == stack.autopilot.info()["failures"]["active"]
    assert command(gcs, Unit.motor, Type.ok, 0) == m.MAV_RESULT_ACCEPTED
    stack.step()
    assert stack.sim.plant.rotor_effectiveness == [1.0] * 4 and stack.sim.failures == {}


def test_a_motors_loss_of_effectiveness_given_in_param4_or_sim_mot_eff():
    """``wrong``: the effectiveness the motor keeps, param4 when in (0, 1], else SIM_MOT_EFF (unset
    param4: 0 from pymavlink, NaN from MAVSDK); outside [0, 1] DENIED with the reason; stuck."""
    stack = make_stack(vehicle="paper_quad_rotors")
    stack.autopilot.params.set("SYS_FAILURE_EN", 1.0)
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    left = ROTOR_POSITIONS.index("left")  # PX4's motor 2
    assert command(gcs, Unit.motor, Type.wrong, 2, 0.7) == m.MAV_RESULT_ACCEPTED
    stack.step()
    assert stack.sim.plant.rotor_effectiveness[left] == pytest.approx(0.7)
    assert stack.sim.failures == {"motor 2": "wrong"}
    for unset in (0.0, math.nan):
        stack.autopilot.params.set("SIM_MOT_EFF", 0.25)
        assert command(gcs, Unit.motor, Type.wrong, 2, unset) == m.MAV_RESULT_ACCEPTED
        stack.step()
        assert stack.sim.plant.rotor_effectiveness[left] == 0.25
        stack.autopilot.params.set("SIM_MOT_EFF", 0.5)
    assert command(gcs, Unit.motor, Type.wrong, 2, 1.5) == m.MAV_RESULT_DENIED
    assert "(0 or NaN: SIM_MOT_EFF)) = 1.5 out of range [0, 1]" in texts(gcs)  # the parameter's rule
    assert command(gcs, Unit.motor, Type.stuck, 2) == m.MAV_RESULT_ACCEPTED
    stack.step()
    assert stack.sim.plant.rotor_fault(left + 1).failure_type == Type.stuck
    assert stack.sim.rotor_health[4 + left] == Type.stuck and stack.sim.rotor_health[left] == 1.0


def test_a_battery_failure_reaches_the_simulators_battery_monitor():
    """battery off: the simulator's monitor reads the pack empty (as PX4's battery simulator), the
    autopilot's estimate falls with it; ok: the monitor reports the pack again."""
    stack = make_stack()
    stack.autopilot.params.set("SYS_FAILURE_EN", 1.0)
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    stack.run_for(3.0)  # the estimate starts 2 s after the pack connected
    full = stack.autopilot.battery.status.remaining
    assert full > 0.9
    assert command(gcs, Unit.battery, Type.off) == m.MAV_RESULT_ACCEPTED
    stack.run_for(10.0)
    assert stack.sim.failures == {"battery": "off"}
    assert stack.sim.info()["battery"]["failure"].startswith("off")
    assert stack.autopilot.battery.status.remaining < 0.15 < full
    assert command(gcs, Unit.battery, Type.ok) == m.MAV_RESULT_ACCEPTED
    stack.step()
    assert stack.sim.info()["battery"]["failure"] == "ok" and stack.sim.failures == {}


@pytest.mark.timeout(180)
def test_mavlink_signal_off_is_a_data_link_loss_and_the_recovery_gets_through():
    stack = make_stack()
    stack.autopilot.params.set("SYS_FAILURE_EN", 1.0)
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    link = {}
    assert param_set(gcs, "NAV_DLL_ACT", 1, INT32) is not None  # hold
    assert stack.autopilot.params["NAV_DLL_ACT"] == 1.0
    take_off(gcs, 2.0, link)
    assert command(gcs, Unit.mavlink_signal, Type.off) == m.MAV_RESULT_ACCEPTED
    assert "Injected: mavlink_signal off, all instances" in texts(gcs)
    end = stack.t + 12.0
    while stack.t < end and "GCS connection lost" not in texts(gcs):
        keep_link(gcs, link)  # the heartbeats go out, the vehicle drops them
        gcs.poll()
    assert "GCS connection lost: no heartbeat for" in texts(gcs) and "(NAV_DLL_ACT 1)" in texts(gcs)
    dropped = stack.autopilot.info()["failures"]["dropped"]["mavlink_signal"]
    assert dropped >= 10
    gcs.conn.mav.param_set_send(gcs.system_id, 1, b"NAV_DLL_ACT", 0.0, m.MAV_PARAM_TYPE_INT32)
    stack.run_for(0.1)
    assert stack.autopilot.params["NAV_DLL_ACT"] == 1.0  # dropped too
    assert command(gcs, Unit.mavlink_signal, Type.ok) == m.MAV_RESULT_ACCEPTED  # the recovery passes
    keep_link(gcs, {})
    gcs.wait(lambda g: "GCS connection regained" in texts(g), sim_timeout=1.0, what="regained")
    assert "Cleared: mavlink_signal, all instances" in texts(gcs)


@pytest.mark.timeout(180)
def test_rc_signal_off_is_a_manual_control_loss():
    from tests.autopilot.mavlink.test_manual import enter_mode, hold_sticks

    stack = make_stack()
    stack.autopilot.params.set("SYS_FAILURE_EN", 1.0)
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    take_off(gcs, 2.0)
    enter_mode(stack, gcs, 3)  # POSCTL
    assert command(gcs, Unit.rc_signal, Type.off) == m.MAV_RESULT_ACCEPTED
    hold_sticks(stack, gcs, 1.0)  # sent, dropped
    assert "Manual control lost" in texts(gcs)
    assert "manual control lost in POSCTL: returning to launch (NAV_RCL_ACT 2)" in texts(gcs)
    assert stack.autopilot.info()["failures"]["dropped"]["rc_signal"] >= 5
    assert command(gcs, Unit.rc_signal, Type.ok) == m.MAV_RESULT_ACCEPTED
    hold_sticks(stack, gcs, 0.3)
    assert "Manual control regained" in texts(gcs)


def test_the_flight_log_keeps_the_announcements(tmp_path):
    from pyulog import ULog

    stack = make_stack(log_dir=str(tmp_path))
    stack.autopilot.params.set("SYS_FAILURE_EN", 1.0)
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    assert gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1).result == m.MAV_RESULT_ACCEPTED  # a log runs
    assert command(gcs, Unit.rc_signal, Type.off) == m.MAV_RESULT_ACCEPTED
    assert command(gcs, Unit.rc_signal, Type.ok) == m.MAV_RESULT_ACCEPTED
    stack.run_for(0.2)
    (path,) = stack.close()
    logged = [msg.message for msg in ULog(str(path)).logged_messages]
    assert "Injected: rc_signal off, all instances" in logged
    assert "Cleared: rc_signal, all instances" in logged


def test_a_flood_of_requests_is_bounded_and_temporarily_rejected():
    stack, _ = ekf_stack()
    injection = stack.autopilot.failure_injection
    answers = [injection.command(Unit.gps, Type.off if i % 2 else Type.ok, 0)[0] for i in range(70)]
    waiting = stack.autopilot.simulator_requests.MAX_PENDING
    assert answers == [m.MAV_RESULT_ACCEPTED] * waiting + [m.MAV_RESULT_TEMPORARILY_REJECTED] * (70 - waiting)
    stack.step()  # one answer carries a few of them
    assert injection.command(Unit.gps, Type.ok, 0)[0] == m.MAV_RESULT_ACCEPTED
