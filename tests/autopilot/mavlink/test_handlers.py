"""The ground station's message handlers on their narrow context (autopilot/mavlink/handlers.py):
built from the rooms they act on (the commander, the parameters, the vehicle's commands, a sink
for refusals) and no core, they answer, refuse with a reason, or hand the message to the
commander; a message for another vehicle is left alone."""

from __future__ import annotations

import pytest
from pymavlink.dialects.v20 import common as m

from autopilot.commander.commander import Commander, VehicleState
from autopilot.commander.modes import FlightMode
from autopilot.mavlink.codec import Encoder, new_parser
from autopilot.mavlink.commands import CommandDispatcher
from autopilot.mavlink.dispatch import FaultLog, MessageDispatcher
from autopilot.mavlink.failure_injection import FailureInjection
from autopilot.mavlink.handlers import HandlerContext, MessageHandlers
from autopilot.mavlink.links import GCS_LINK, GcsLink
from autopilot.mavlink.telemetry import VehicleStatus
from autopilot.mavlink.vehicle_commands import CommandContext, VehicleCommands
from autopilot.mavlink.vision_in import ExternalVision
from autopilot.params.definitions import default_parameters
from quadcommon import wire
from quadcommon.build_info import BuildInfo

pytestmark = pytest.mark.timeout(30)

SYSTEM_ID = 1
STATION = ("127.0.0.1", 14550)
HOME = (47.397742, 8.545594, 488.0)


class Vehicle:
    """The handlers wired to real rooms, a clock the test sets and the answers and refusals kept."""

    def __init__(self) -> None:
        self.t = 10.0
        self.params = default_parameters()
        self.commander = Commander(self.params)
        self.refused: list[str] = []
        self.said: list[tuple[int, str]] = []
        self.out: list = []
        self.link = GcsLink(GCS_LINK, None, self.out, 0.002)
        encoder = Encoder(SYSTEM_ID, wire.AUTOPILOT_COMPONENT_ID)
        status = VehicleStatus(SYSTEM_ID)
        self.commands = CommandDispatcher()
        failures = FailureInjection(self.params, lambda *request: True, lambda: False, self.refused.append,
                                    self._say)  # fmt: skip
        vehicle_commands = VehicleCommands(CommandContext(
            self.commander, self.now, lambda: status, self.params, self.refused.append, failures, HOME,
            BuildInfo(), SYSTEM_ID,
        ))  # fmt: skip
        vehicle_commands.register(self.commands)
        self.handlers = MessageHandlers(HandlerContext(
            SYSTEM_ID, self.commander, self.now, self.now, self.params, self.refused.append, self._say,
            lambda: None, encoder.pack, lambda text: None, HOME, lambda: None, self.commands,
            vehicle_commands, ExternalVision(),
        ))  # fmt: skip
        self.faults = FaultLog(lambda text: None, lambda text: None)
        self.dispatcher = MessageDispatcher(self.faults)
        self.handlers.register(self.dispatcher)

    def now(self) -> float:
        return self.t

    def _say(self, severity: int, text: str) -> None:
        self.said.append((severity, text))

    def receive(self, msg) -> None:
        """``msg`` from the station, through the dispatcher the core routes with; no fault."""
        self.dispatcher.dispatch(msg, self.link, STATION, self.t)
        assert not self.faults.counts

    def answers(self) -> list:
        parser = new_parser()
        return [parser.parse_char(data) for _, _, data in self.out]


def resting(t: float) -> VehicleState:
    return VehicleState(t, (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0), (0.0, 0.0, 0.0))


def test_every_message_the_vehicle_acts_on_has_its_handler():
    vehicle = Vehicle()
    assert set(vehicle.dispatcher.handlers) == {
        m.MAVLINK_MSG_ID_COMMAND_LONG, m.MAVLINK_MSG_ID_COMMAND_INT,
        m.MAVLINK_MSG_ID_SET_POSITION_TARGET_LOCAL_NED, m.MAVLINK_MSG_ID_SET_ATTITUDE_TARGET,
        m.MAVLINK_MSG_ID_MANUAL_CONTROL, m.MAVLINK_MSG_ID_FOLLOW_TARGET, m.MAVLINK_MSG_ID_SET_MODE,
        m.MAVLINK_MSG_ID_HEARTBEAT, m.MAVLINK_MSG_ID_TIMESYNC, m.MAVLINK_MSG_ID_VISION_POSITION_ESTIMATE,
        m.MAVLINK_MSG_ID_ODOMETRY,
    }  # fmt: skip


def test_a_command_is_answered_with_its_ack_and_one_for_another_vehicle_is_not():
    vehicle = Vehicle()
    vehicle.commander.update_state(resting(vehicle.t))
    arm_command = m.MAV_CMD_COMPONENT_ARM_DISARM
    arm = m.MAVLink_command_long_message(SYSTEM_ID + 1, 1, arm_command, 0, 1, 0, 0, 0, 0, 0, 0)
    vehicle.receive(arm)
    assert vehicle.out == []  # another system's
    unknown = m.MAVLink_command_long_message(SYSTEM_ID, 1, 31000, 0, 0, 0, 0, 0, 0, 0, 0)
    vehicle.receive(unknown)
    (ack,) = vehicle.answers()
    assert ack.get_type() == "COMMAND_ACK" and ack.command == 31000
    assert ack.result == m.MAV_RESULT_UNSUPPORTED
    assert vehicle.out[0].address == STATION  # answered to the station that asked


def test_a_hostile_attitude_target_is_refused_with_its_reason_and_a_good_one_reaches_the_commander():
    vehicle = Vehicle()
    nan_q = m.MAVLink_set_attitude_target_message(0, SYSTEM_ID, 1, 7, [float("nan"), 0, 0, 0], 0, 0, 0, 0.5)
    vehicle.receive(nan_q)
    assert vehicle.refused == ["attitude target refused: non-finite attitude quaternion"]
    assert vehicle.commander.offboard.setpoint is None
    level = m.MAVLink_set_attitude_target_message(0, SYSTEM_ID, 1, 7, [1, 0, 0, 0], 0, 0, 0, 0.5)
    vehicle.receive(level)
    assert vehicle.commander.offboard.setpoint is not None
    assert vehicle.commander.offboard_stream_active(vehicle.t)


def test_set_mode_selects_px4s_custom_mode():
    vehicle = Vehicle()
    land = FlightMode.AUTO_LAND.custom_mode
    vehicle.receive(m.MAVLink_set_mode_message(SYSTEM_ID, m.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, land))
    assert vehicle.commander.mode == FlightMode.AUTO_LAND


def test_timesync_is_answered_on_the_simulation_clock_and_only_a_ground_stations_heartbeat_counts():
    vehicle = Vehicle()
    vehicle.receive(m.MAVLink_timesync_message(0, 123456))
    (reply,) = vehicle.answers()
    assert reply.get_type() == "TIMESYNC" and reply.tc1 == int(vehicle.t * 1e9) and reply.ts1 == 123456
    drone = m.MAVLink_heartbeat_message(m.MAV_TYPE_QUADROTOR, m.MAV_AUTOPILOT_PX4, 0, 0, 0, 3)
    vehicle.receive(drone)
    assert vehicle.link.last_heartbeat_s != vehicle.t
    station = m.MAVLink_heartbeat_message(m.MAV_TYPE_GCS, m.MAV_AUTOPILOT_INVALID, 0, 0, 0, 3)
    vehicle.receive(station)
    assert vehicle.link.last_heartbeat_s == vehicle.t
