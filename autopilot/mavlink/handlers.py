"""The ground-station messages the vehicle acts on directly: MAV_CMDs (COMMAND_LONG/INT), mode
changes, offboard setpoints and attitude targets, sticks, follow-me targets, GCS heartbeats,
TIMESYNC and a client's vision. Each is checked at the edge by its decoder (:mod:`.offboard`,
:mod:`.manual`, :mod:`.follow_target`, :mod:`.vision_in`, :mod:`.validation`) and handed to the
commander or the estimator; a refusal is said (STATUSTEXT, rate-limited per reason).

The handlers see a :class:`HandlerContext` (the commander, the clocks, the parameters, the
refusals, the estimator and the few services they answer through), never the core that owns them.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from quadcommon import wire

from ..commander.commander import Commander
from ..commander.modes import FlightMode
from ..params.store import ParameterStore
from .codec import mavlink as m
from .commands import CommandDispatcher, CommandRequest, command_ack, request_from_message
from .follow_target import decode_follow_target
from .links import Address, GcsLink
from .manual import decode_sticks
from .offboard import decode_attitude_target, decode_setpoint
from .validation import check_command, reference_problem
from .vehicle_commands import VehicleCommands
from .vision_in import ExternalVision


@dataclass(frozen=True)
class HandlerContext:
    """What the message handlers reach."""

    system_id: int
    commander: Commander
    now: Callable[[], float]  # simulation time (s)
    wall_now: Callable[[], float]  # the caller's clock at the latest entry point (s)
    params: ParameterStore
    refuse: Callable[[str], None]  # a refusal's STATUSTEXT (rate-limited per reason)
    statustext: Callable[[int, str], None]
    send_events: Callable[[], None]  # the commander's announcements out now
    pack: Callable[[Any], bytes]  # a message as this vehicle's frame
    log: Callable[[str], None]
    origin: tuple[float, float, float]  # the geodetic home (lat deg, lon deg, alt m AMSL)
    estimator: Callable[[], Any]  # the EKF's loop (autopilot.estimation.loop), None on the truth
    commands: CommandDispatcher
    vehicle_commands: VehicleCommands
    external_vision: ExternalVision


class MessageHandlers:
    """The handlers (module docstring), registered on a :class:`~.dispatch.MessageDispatcher`."""

    def __init__(self, context: HandlerContext) -> None:
        self.context = context

    def register(self, d) -> None:
        """Each handler on its message id(s)."""
        d[m.MAVLINK_MSG_ID_COMMAND_LONG] = self.command
        d[m.MAVLINK_MSG_ID_COMMAND_INT] = self.command
        d[m.MAVLINK_MSG_ID_SET_POSITION_TARGET_LOCAL_NED] = self.setpoint
        d[m.MAVLINK_MSG_ID_SET_ATTITUDE_TARGET] = self.attitude_target
        d[m.MAVLINK_MSG_ID_MANUAL_CONTROL] = self.manual_control
        d[m.MAVLINK_MSG_ID_FOLLOW_TARGET] = self.follow_target
        d[m.MAVLINK_MSG_ID_SET_MODE] = self.set_mode
        d[m.MAVLINK_MSG_ID_HEARTBEAT] = self.gcs_heartbeat
        d[m.MAVLINK_MSG_ID_TIMESYNC] = self.timesync
        d[m.MAVLINK_MSG_ID_VISION_POSITION_ESTIMATE] = self.vision
        d[m.MAVLINK_MSG_ID_ODOMETRY] = self.vision

    def _for_us(self, msg) -> bool:
        return msg.target_system in (0, self.context.system_id)

    def command(self, msg, link: GcsLink, address: Address) -> None:
        """COMMAND_LONG / COMMAND_INT: run, answered with a COMMAND_ACK, then the message it asked
        for (REQUEST_MESSAGE...) after the ACK, as PX4 sends them."""
        c = self.context
        if not self._for_us(msg) or msg.target_component not in (0, wire.AUTOPILOT_COMPONENT_ID):
            return
        request = request_from_message(msg, link, address)
        c.vehicle_commands.after_ack = None
        result, reason = self.run_command(request)
        link.send_to(c.pack(command_ack(request, result)), address)
        if c.vehicle_commands.after_ack is not None:  # a requested message, after its ACK (PX4)
            link.send_to(c.pack(c.vehicle_commands.after_ack), address)
            c.vehicle_commands.after_ack = None
        c.send_events()

    def run_command(self, request: CommandRequest) -> tuple[int, str]:
        """A MAV_CMD through the vehicle's one command path: its parameters checked
        (:mod:`.validation`), then its handler; (MAV_RESULT, reason)."""
        c = self.context
        known = request.command in c.commands.handlers  # an unknown one is UNSUPPORTED, not DENIED
        problem = check_command(request.command, request.params, request.frame is not None) if known else None
        if problem:
            name = getattr(m.enums["MAV_CMD"].get(request.command), "name", f"command {request.command}")
            result, reason = m.MAV_RESULT_DENIED, f"{name} refused: {problem}"
            c.refuse(reason)
        else:
            result, reason = c.commands.dispatch(request)
        if reason and result != m.MAV_RESULT_ACCEPTED:
            c.log(f"command {request.command} -> result {result}: {reason}")
        return result, reason

    def set_mode(self, msg, link: GcsLink, address: Address) -> None:
        """SET_MODE (deprecated by MAVLink, still sent by some stations): PX4's custom mode."""
        if not self._for_us(msg):
            return
        mode = FlightMode.from_custom_mode(msg.custom_mode)
        if mode is not None:
            self.context.commander.set_mode(self.context.now(), mode)
            self.context.send_events()

    def setpoint(self, msg, link: GcsLink, address: Address) -> None:
        """SET_POSITION_TARGET_LOCAL_NED: an offboard setpoint (:mod:`.offboard`), its position
        checked against the geofence's and the reference's limits."""
        c = self.context
        state = c.commander.state
        if not self._for_us(msg) or state is None:
            return
        ref = c.commander.last_reference
        ref_pos = ref.position_m if ref is not None else state.position_m
        setpoint, reason = decode_setpoint(msg, c.now(), state.position_m, state.euler_rad[2], ref_pos)
        if setpoint is not None and setpoint.position is not None:
            home = c.commander.home or (0.0, 0.0, 0.0)
            reason = reference_problem(setpoint.position, home, c.params.values) or ""
            setpoint = None if reason else setpoint
        if setpoint is None:
            c.refuse(f"setpoint refused: {reason}")
            return
        c.commander.offboard_setpoint(setpoint)

    def attitude_target(self, msg, link: GcsLink, address: Address) -> None:
        """SET_ATTITUDE_TARGET: offboard attitude or body rates with a collective thrust."""
        c = self.context
        if not self._for_us(msg) or msg.target_component not in (0, wire.AUTOPILOT_COMPONENT_ID):
            return
        setpoint, reason = decode_attitude_target(msg, c.now())
        if setpoint is None:
            c.refuse(f"attitude target refused: {reason}")
            return
        c.commander.offboard_setpoint(setpoint)

    def manual_control(self, msg, link: GcsLink, address: Address) -> None:
        """MANUAL_CONTROL: the sticks (flown in the manual modes, :mod:`autopilot.guidance.manual`)."""
        c = self.context
        if msg.target not in (0, c.system_id):
            return
        sticks, reason = decode_sticks(msg, c.now())
        if sticks is None:
            c.refuse(f"sticks refused: {reason}")
            return
        c.commander.manual_sticks(sticks)

    def follow_target(self, msg, link: GcsLink, address: Address) -> None:
        """FOLLOW_TARGET: the follow-me target (:mod:`.follow_target`), checked at the edge, then
        the commander's target estimate."""
        c = self.context
        home = c.commander.home or (0.0, 0.0, 0.0)
        report, reason = decode_follow_target(msg, c.now(), c.origin, home, c.params.values)
        if report is None:
            c.refuse(f"FOLLOW_TARGET refused: {reason}")
            return
        c.commander.follow_target_report(report)

    def gcs_heartbeat(self, msg, link: GcsLink, address: Address) -> None:
        """A ground station's HEARTBEAT: the link is alive (the data-link loss failsafe)."""
        if msg.type != m.MAV_TYPE_GCS:
            return  # another vehicle or an onboard component: only ground stations count (link loss)
        c = self.context
        link.last_heartbeat_s = c.now()
        c.commander.gcs_heartbeat(c.now())
        c.send_events()

    def timesync(self, msg, link: GcsLink, address: Address) -> None:
        """TIMESYNC: a request is answered with the vehicle's (simulation) clock in ns."""
        if msg.tc1 == 0:
            reply = m.MAVLink_timesync_message(int(self.context.now() * 1e9), msg.ts1)
            link.send_to(self.context.pack(reply), address)

    def vision(self, msg, link: GcsLink, address: Address) -> None:
        """A client's VISION_POSITION_ESTIMATE or ODOMETRY: checked and timed at the edge
        (:mod:`.vision_in`), then fused by the EKF with the next frame's aiding."""
        c = self.context
        sender = (link.index, address, msg.get_srcSystem(), msg.get_srcComponent())
        estimator = c.estimator()
        on_ekf = estimator is not None
        pose = c.external_vision.receive(msg, sender, c.now(), c.wall_now(), on_ekf, c.params.values)
        if pose is not None:
            estimator.external_vision(pose)
        for text in c.external_vision.take_announcements():
            c.statustext(m.MAV_SEVERITY_WARNING, text)
