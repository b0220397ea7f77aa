"""What a mode needs to be entered, and the mode requests: DO_SET_MODE (PX4's custom modes, each
an event of the table), PX4's refusal of a switch to a mode that cannot run now ("Switching to ...
is currently not possible"), the sticks the manual modes need (MANUAL_CONTROL) and the setpoint
stream OFFBOARD needs (within ``COM_OF_LOSS_T``).

A part of :class:`~.commander.Commander` (its state lives there); the transitions go through the
table (:mod:`.transitions`).
"""

from __future__ import annotations

from ..guidance.offboard import AttitudeSetpoint, OffboardSetpoint
from ..guidance.planner import stop_from
from ..guidance.sticks import Sticks
from ..params.definitions import POSCTL_NAVL_ALTITUDE
from .health import (
    NAV_ALTCTL,
    NAV_AUTO_FOLLOW_TARGET,
    NAV_AUTO_LAND,
    NAV_AUTO_LOITER,
    NAV_AUTO_MISSION,
    NAV_AUTO_RTL,
    NAV_AUTO_TAKEOFF,
    NAV_OFFBOARD,
    NAV_ORBIT,
    NAV_POSCTL,
    NAV_STATE_OF_MODE,
    missing_for,
    mode_can_run,
)
from .modes import FlightMode
from .records import ACCEPTED, DENIED, SEVERITY_INFO, UNSUPPORTED, Outcome, at_rest
from .transitions import FLYING, Event

# The navigation state a command asks for (its mode must be able to run: PX4 refuses the switch).
COMMAND_NAV = {
    Event.TAKEOFF: NAV_AUTO_TAKEOFF, Event.SELECT_TAKEOFF: NAV_AUTO_TAKEOFF, Event.HOLD: NAV_AUTO_LOITER,
    Event.REPOSITION: NAV_AUTO_LOITER, Event.LAND: NAV_AUTO_LAND, Event.RTL: NAV_AUTO_RTL,
    Event.OFFBOARD: NAV_OFFBOARD, Event.MISSION: NAV_AUTO_MISSION, Event.MISSION_START: NAV_AUTO_MISSION,
    Event.ORBIT: NAV_ORBIT, Event.FOLLOW: NAV_AUTO_FOLLOW_TARGET,
}  # fmt: skip
# The event each mode's selection raises (DO_SET_MODE, SET_MODE, the console's commander mode).
MODE_EVENTS = {
    FlightMode.MANUAL: Event.MANUAL,
    FlightMode.STABILIZED: Event.MANUAL,
    FlightMode.ALTCTL: Event.MANUAL,
    FlightMode.POSCTL: Event.MANUAL,
    FlightMode.ACRO: Event.MANUAL,
    FlightMode.OFFBOARD: Event.OFFBOARD,
    FlightMode.AUTO_LOITER: Event.HOLD,
    FlightMode.AUTO_LAND: Event.LAND,
    FlightMode.AUTO_RTL: Event.RTL,
    FlightMode.AUTO_TAKEOFF: Event.SELECT_TAKEOFF,
    FlightMode.AUTO_MISSION: Event.MISSION,
    FlightMode.ORBIT: Event.ORBIT,
    FlightMode.AUTO_FOLLOW_TARGET: Event.FOLLOW,
}
NAV_MODE_NAMES = {nav: mode.px4_name for mode, nav in NAV_STATE_OF_MODE.items()}


class ModeRequests:
    """Mode requests and what each mode needs (module docstring): a part of the Commander."""

    def set_mode(self, t: float, mode: FlightMode) -> Outcome:
        """Select ``mode`` (DO_SET_MODE, SET_MODE): its event of the table; selecting AUTO.MISSION
        again may (re)start the mission, re-selecting any other mode changes nothing."""
        if mode == self.mode and mode != FlightMode.AUTO_MISSION:  # re-selecting it may (re)start
            return Outcome(ACCEPTED)
        event = MODE_EVENTS.get(mode)
        if event is None:
            return self._refuse(UNSUPPORTED, f"mode {mode.px4_name} not supported")
        return self._fire(t, event, mode=mode)

    def _cannot_run(self, t: float, event: Event, mode: FlightMode | None) -> str:
        """Why the mode ``event`` asks for cannot run now ('' if it can): PX4 refuses the switch
        ("Switching to ... is currently not possible"). POSCTL is let in when ALTCTL can run and
        COM_POSCTL_NAVL is 0 (the fallback then flies ALTCTL until the position returns)."""
        flags = self.health_flags(t)
        if event in COMMAND_NAV:
            nav = COMMAND_NAV[event]
            if event == Event.OFFBOARD:  # the stream is OFFBOARD's own guard (enter_offboard)
                flags = flags._replace(offboard_control_signal_lost=False)
        else:
            nav = NAV_STATE_OF_MODE[FlightMode.POSCTL if mode is None else mode]
        if nav == NAV_AUTO_MISSION:  # the mission's own guards say what is missing there
            flags = flags._replace(auto_mission_missing=False)
        if mode_can_run(flags, nav):
            return ""
        if (nav == NAV_POSCTL and int(self.params["COM_POSCTL_NAVL"]) == POSCTL_NAVL_ALTITUDE
                and mode_can_run(flags, NAV_ALTCTL)):  # fmt: skip
            return ""
        name = mode.px4_name if mode is not None else NAV_MODE_NAMES.get(nav, event.value)
        return f"Switching to {name} is currently not possible: {missing_for(flags, nav)}"

    def manual_sticks(self, sticks: Sticks) -> None:
        """A MANUAL_CONTROL (flown in the manual modes; kept otherwise, as PX4 keeps RC)."""
        limits = self._manual_limits
        self.sticks.receive(sticks, limits.loss_s, limits.override_speed)

    def offboard_setpoint(self, setpoint: OffboardSetpoint | AttitudeSetpoint) -> None:
        """A setpoint of the offboard stream (position/velocity/acceleration, or attitude/body rates
        with a thrust): flown in OFFBOARD, and what keeps the stream alive (COM_OF_LOSS_T)."""
        self.offboard.update(setpoint)
        times = self._setpoint_times
        times.append(setpoint.time_s)
        if len(times) > 4:
            del times[0]

    def offboard_stream_active(self, t: float) -> bool:
        """A setpoint within the loss timeout COM_OF_LOSS_T (PX4's rule).

        Not "two setpoints": MAVSDK's ``set_position_ned(); start()`` sends one setpoint and then
        DO_SET_MODE at once, its 20 Hz stream starting on a timer thread that may come second; PX4
        accepts that, and the loss failsafe catches a stream that never follows.
        """
        window = self.params["COM_OF_LOSS_T"]
        return any(t - s <= window for s in self._setpoint_times)

    def _act_enter_manual(self, t: float, mode: FlightMode, **_) -> Outcome | None:
        """A manual mode needs the sticks (PX4: "No manual control input"); flying, it starts from
        the measured state (POSCTL holding until a stick moves)."""
        if self.sticks.fresh(t, self._manual_limits.loss_s) is None:
            return self._refuse(DENIED, f"Switching to {mode.px4_name} is currently not possible: no manual "
                                        "control input (send MANUAL_CONTROL first)")  # fmt: skip
        state = self.state
        if state is not None:
            self.manual.enter(state)
            if self.phase in FLYING:
                self._fly(t, stop_from(self.last_or_measured(state), self.limits()))
        return None

    def _act_enter_offboard(self, t: float, require_stream: bool = True, **_) -> Outcome | None:
        if require_stream and not self.offboard_stream_active(t):
            return self._refuse(DENIED, "OFFBOARD refused: no setpoint stream (send setpoints first)")
        self.offboard.reset()
        return None

    def _act_stick_takeoff(self, t: float, **_) -> None:
        """The throttle raised on the ground: the manual mode flies from the vehicle at rest."""
        state = self.state
        assert state is not None
        self.manual.enter(state)
        self.last_reference = at_rest(state)
        self._fly(t, stop_from(self.last_reference, self.limits()))
        self._landed_since = None
        self._event(SEVERITY_INFO, f"taking off on the sticks in {self.mode.px4_name}")
