"""The mission service of the autopilot process: the protocol, the stored mission and the
commander, joined to the GCS links (this is the only part of :mod:`autopilot.mission` that sends).

* Mission messages go to :class:`~autopilot.mission.protocol.MissionProtocol` with the wall
  clock (transfers are paced by the ground station, not by simulation time); its replies go back
  to the address the message came from, its retries to the last address of the transfer's client.
* An accepted upload becomes a :class:`~autopilot.mission.executor.MissionExecutor` in the
  commander (a clear: none); MISSION_SET_CURRENT and MAV_CMD_DO_SET_MISSION_CURRENT (224) set the
  current item, MAV_CMD_MISSION_START (300) flies the mission (param1 >= 0: from that item, as PX4).
* Progress: MISSION_CURRENT (seq, total, mission_state, mission_mode) at 1 Hz of simulation time
  (wall time while no simulator runs) and at once whenever it changes; MISSION_ITEM_REACHED once
  per reached item, in order. Both go to every GCS link.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

from ..commander.commander import Commander
from ..commander.modes import FlightMode
from ..mavlink.codec import Encoder
from ..mavlink.codec import mavlink as m
from ..mavlink.commands import CommandDispatcher, CommandRequest
from . import curve
from .executor import MissionExecutor, MissionState, check_mission
from .plans import Geofence, rally_points
from .protocol import MissionProtocol, Output

MESSAGE_IDS = (
    m.MAVLINK_MSG_ID_MISSION_COUNT,
    m.MAVLINK_MSG_ID_MISSION_ITEM_INT,
    m.MAVLINK_MSG_ID_MISSION_ITEM,
    m.MAVLINK_MSG_ID_MISSION_REQUEST_LIST,
    m.MAVLINK_MSG_ID_MISSION_REQUEST_INT,
    m.MAVLINK_MSG_ID_MISSION_REQUEST,
    m.MAVLINK_MSG_ID_MISSION_ACK,
    m.MAVLINK_MSG_ID_MISSION_CLEAR_ALL,
    m.MAVLINK_MSG_ID_MISSION_SET_CURRENT,
)
CURRENT_INTERVAL_S = 1.0
NO_MISSION_TOTAL = 65535  # MISSION_CURRENT.total when there is no mission (as PX4)
MISSION_MODE_ACTIVE, MISSION_MODE_SUSPENDED = 1, 2  # MISSION_CURRENT.mission_mode


class MissionService:
    """The mission service (module docstring): the mission protocol on the GCS links, accepted plans handed to
    the commander, and MISSION_CURRENT and MISSION_ITEM_REACHED sent."""

    def __init__(
        self,
        commander: Commander,
        encoder: Encoder,
        links: Sequence,
        statustext: Callable[[int, str], None],
        origin: tuple[float, float, float],
        system_id: int,
        component_id: int,
        clock: Callable[[], float],
    ) -> None:
        """``links`` = the GCS links (each with ``send(data)`` and ``send_to(data, address)``);
        ``origin`` = the configured geodetic home of the local frame (lat, lon deg, alt m)."""
        self.commander = commander
        self.encoder = encoder
        self.links = links
        self.statustext = statustext
        self.origin = origin
        self.clock = clock
        self.protocol = MissionProtocol(
            system_id,
            component_id,
            origin,
            check=self._check,
        )
        self._peer: tuple[object, tuple[str, int]] | None = None  # the transfer client's link, address
        self._sim_time: Callable[[], float] = lambda: 0.0
        self._last_current: tuple[int, int, int, int] | None = None
        self._next_current_s = 0.0

    def _check(self, items):
        """An uploaded plan checked against the vehicle's limits, the geofence and home (a bound
        method, not a lambda: a deep copy of the service checks against its own commander)."""
        commander = self.commander
        return check_mission(items, self.origin, commander.limits(), commander.params.values,
                             fence=commander.target_problem, home_local=commander.home or (0.0, 0.0, 0.0))

    def register(self, handlers: dict, commands: CommandDispatcher, sim_time: Callable[[], float]) -> None:
        """Hook into the process shell's message table and command dispatcher."""
        self._sim_time = sim_time
        for msg_id in MESSAGE_IDS:
            handlers[msg_id] = self.on_message
        commands.register(m.MAV_CMD_MISSION_START, self._cmd_mission_start)
        commands.register(m.MAV_CMD_DO_SET_MISSION_CURRENT, self._cmd_set_current)

    # -- messages -------------------------------------------------------------------------------------
    def on_message(self, msg, link, address) -> None:
        """One mission-protocol message: handled with the wall clock, its replies sent to the sender, an
        accepted upload or clear applied to the commander."""
        if (
            msg.get_msgId() == m.MAVLINK_MSG_ID_MISSION_COUNT
            and msg.count > 0
            and msg.mission_type == m.MAV_MISSION_TYPE_MISSION
        ):
            curve.preload()  # its items may be a timed curve: scipy.interpolate, in the background
        self.protocol.max_items = int(self.commander.params["MIS_ITEMS_MAX"])
        out = self.protocol.handle(msg, self.clock(), self._current_seq())
        if self.protocol.busy:
            self._peer = (link, address)
        for reply in out.replies:
            link.send_to(self.encoder.pack(reply), address)
        self._apply(out)

    def poll(self) -> None:
        """Transfer timeouts and retries (call every <= 0.1 s of wall time)."""
        out = self.protocol.poll(self.clock())
        if out.replies and self._peer is not None:
            link, address = self._peer
            for reply in out.replies:
                link.send_to(self.encoder.pack(reply), address)
        self._apply(out)

    def _apply(self, out: Output) -> None:
        for severity, text in out.notices:
            self.statustext(severity, text)
        t = self._sim_time()
        if out.mission is not None:
            mission = out.mission
            executor = (
                MissionExecutor(mission.items, self.origin, mission.current_seq) if mission.count else None
            )
            self.commander.set_mission(t, executor)
        if out.fence is not None:
            self.commander.set_geofence(t, Geofence.from_items(out.fence.items, self.origin))
        if out.rally is not None:
            self.commander.set_rally_points(rally_points(out.rally.items, self.origin))
        if out.set_current is not None:
            self.commander.mission_set_current(t, out.set_current)
        self._drain_commander_events()
        self.update(t, force=out.mission is not None or out.set_current is not None)

    def _drain_commander_events(self) -> None:
        for severity, text in self.commander.drain_events():
            self.statustext(severity, text)

    # -- commands ---------------------------------------------------------------------------------------
    def _cmd_mission_start(self, r: CommandRequest) -> tuple[int, str]:
        first = r.params[0]
        mission = self.commander.mission
        count = mission.count if mission is not None else 0
        first_item = int(first) if math.isfinite(first) and 0 <= first < count else None
        outcome = self.commander.start_mission(self._sim_time(), first_item)
        self.update(self._sim_time(), force=True)
        return outcome.result, outcome.reason

    def _cmd_set_current(self, r: CommandRequest) -> tuple[int, str]:
        seq = r.params[0]
        if not math.isfinite(seq) or seq == -1:
            return m.MAV_RESULT_ACCEPTED, ""  # -1: keep the current item (reset not needed here)
        out = self.protocol.set_current_request(int(seq))
        for severity, text in out.notices:
            self.statustext(severity, text)
        if out.set_current is None:
            return m.MAV_RESULT_DENIED, out.notices[0][1] if out.notices else "not possible now"
        outcome = self.commander.mission_set_current(self._sim_time(), out.set_current)
        self.update(self._sim_time(), force=True)
        return outcome.result, outcome.reason

    def restart_clock(self) -> None:
        """The simulation clock started again: MISSION_CURRENT is due at once."""
        self._next_current_s = 0.0

    # -- progress ----------------------------------------------------------------------------------------
    def _current_seq(self) -> int:
        mission = self.commander.mission
        return mission.current_seq if mission is not None else 0

    def current_message(self):
        """MISSION_CURRENT now."""
        return m.MAVLink_mission_current_message(*self._current_key())

    def update(self, t: float, force: bool = False) -> None:
        """Send MISSION_ITEM_REACHED for newly reached items, and MISSION_CURRENT when it changed
        or is due (every second of ``t``, the simulation time)."""
        mission = self.commander.mission
        if mission is not None and mission.has_reached():
            for seq in mission.drain_reached():
                self._broadcast(m.MAVLink_mission_item_reached_message(seq))
        key = self._current_key()
        if force or key != self._last_current or t >= self._next_current_s:
            self._last_current = key
            self._next_current_s = t + CURRENT_INTERVAL_S
            self._broadcast(self.current_message())

    def _current_key(self) -> tuple[int, int, int, int]:
        """What MISSION_CURRENT would say now (compared every frame: no message built for it)."""
        mission = self.commander.mission
        if mission is None:
            return (0, NO_MISSION_TOTAL, int(MissionState.NO_MISSION), 0)
        active = self.commander.mode == FlightMode.AUTO_MISSION
        mode = MISSION_MODE_ACTIVE if active else MISSION_MODE_SUSPENDED
        return (mission.current_seq, mission.count, int(mission.state), mode)

    def _broadcast(self, msg) -> None:
        data = self.encoder.pack(msg)
        for link in self.links:
            link.send(data)
