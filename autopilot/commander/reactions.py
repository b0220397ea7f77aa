"""The vehicle's reactions to what goes wrong, as PX4's: the failsafe flags (health and estimates,
:mod:`.health`) evaluated every :data:`HEALTH_PERIOD_S` and after each transition; PX4's mode
fallback when the mode chosen cannot run (RTL, Land, Descend, Terminate; ALTCTL and STABILIZED for
the manual modes) and the way back when it can again; the loss and the return of the sticks
(``NAV_RCL_ACT``) and their override of the AUTO modes and OFFBOARD (``COM_RC_OVERRIDE``); the
data link, geofence and battery failsafes (:mod:`.failsafe`).

A part of :class:`~.commander.Commander` (its state lives there); every action is taken through
the table (:mod:`.transitions`).
"""

from __future__ import annotations

from ..battery.estimator import BatteryStatus
from ..guidance.sticks import LOST
from ..params.definitions import RC_OVERRIDE_AUTO, RC_OVERRIDE_OFFBOARD
from ..records import SensorSamples
from .failsafe import (
    ACTION_NAMES,
    ALTCTL,
    DESCEND,
    HOLD,
    LAND,
    RTL,
    STABILIZED,
    TERMINATE,
    WARN,
    mode_fallback,
    rc_loss_action,
    resolve_action,
)
from .health import NAV_DESCEND, NAV_STATE_OF_MODE, FailsafeFlags, LinkState, missing_for
from .mode_requests import MODE_EVENTS, NAV_MODE_NAMES
from .modes import FlightMode
from .records import SEVERITY_CRITICAL, SEVERITY_INFO, SEVERITY_NOTICE, SEVERITY_WARNING, VehicleState
from .transitions import AUTOMATIC, FLYING, Event, Phase, lookup

# The failsafe flags are evaluated this often (simulation time) and after every transition: PX4's
# commander runs its health and arming checks at 10 Hz and when its state changes; its failsafe
# state machine (here the mode fallback) reads the flags at 100 Hz, here when they or the mode change.
HEALTH_PERIOD_S = 0.1
_FAILSAFE_EVENTS = {HOLD: Event.FAILSAFE_HOLD, RTL: Event.FAILSAFE_RTL, LAND: Event.FAILSAFE_LAND,
                    DESCEND: Event.FAILSAFE_DESCEND, TERMINATE: Event.FAILSAFE_TERMINATE,
                    ALTCTL: Event.FAILSAFE_MANUAL, STABILIZED: Event.FAILSAFE_MANUAL}  # fmt: skip
_FAILSAFE_DOING = {HOLD: "holding", RTL: "returning to launch", LAND: "landing", DESCEND: "descending",
                   TERMINATE: "flight terminated", ALTCTL: "in ALTCTL",
                   STABILIZED: "in STABILIZED"}  # fmt: skip
_FALLBACK_MODES = {ALTCTL: FlightMode.ALTCTL, STABILIZED: FlightMode.STABILIZED}


class FailsafeReactions:
    """Health flags, mode fallback, stick loss and override, failsafes (module docstring): a part
    of the Commander."""

    def gcs_heartbeat(self, t: float) -> None:
        """A HEARTBEAT from a ground station (MAV_TYPE_GCS) at simulation time ``t``."""
        for text in self.failsafes.gcs_heartbeat(t):
            self._event(SEVERITY_INFO, text)

    def update_battery(self, status: BatteryStatus | None, unhealthy: bool) -> None:
        """The battery's estimate at this control step (None: no battery has reported) and whether
        its reports stopped (:mod:`autopilot.battery.estimator`); what changed is announced."""
        for severity, text in self.battery.update(status, unhealthy, self.armed):
            self._event(severity, text)

    def simulator_lost(self) -> None:
        """No sensor frames any more: the position is unknown until they resume (no arming)."""
        self.position_valid = False

    def observe_sensors(self, t: float, samples: SensorSamples | None, streams: int | None = None) -> None:
        """A frame's sensor samples (None: none, or not decoded: ``health.wants_samples``) and the
        streams that delivered (``STREAM_*`` bits of autopilot/mavlink/hil.py; None: those of
        ``samples``); a sensor stream that stopped or resumed is announced."""
        if streams is None:
            streams = samples.streams if samples is not None else 0
        self.health.observe(t, streams, samples, self.state)
        if self.health.announcements:
            self._announce_streams()

    def _announce_streams(self) -> None:
        for text in self.health.take_announcements():
            self._event(SEVERITY_WARNING, text)

    def health_flags(self, t: float) -> FailsafeFlags:
        """The failsafe flags, evaluated again when :data:`HEALTH_PERIOD_S` has passed (the same
        record while they are unchanged)."""
        if t >= self._health_due or t < self._health_due - 1.0:  # (or the clock restarted)
            self._health_due = t + HEALTH_PERIOD_S
            failsafes = self.failsafes
            mission = self.mission
            links = LinkState(
                # (a scenario's trajectory is the mission flown in its AUTO.MISSION)
                mission_missing=(mission is None or mission.count == 0) and self.phase != Phase.TRAJECTORY,
                offboard_lost=not self.offboard_stream_active(t),
                home_invalid=self.home is None,
                manual_control_lost=self.sticks.fresh(t, self._manual_limits.loss_s) is None,
                gcs_connection_lost=failsafes.link_lost,
                geofence_breached=failsafes.fence_breached,
            )
            has_state = self.position_valid and self.state is not None
            # Airborne by the phase, not by the estimate's height (which a failing sensor corrupts):
            # after the touchdown is detected, a change of the estimate's speed is not the vehicle's.
            flags = self.health.evaluate(t, self.estimator_status, self.on_ekf, has_state, links,
                                         airborne=self.phase in FLYING)
            if self.health.announcements:
                self._announce_streams()
            if flags is not self.flags:
                self.flags = flags
                self._fallback_due = True
        return self.flags

    def _nav_state(self, mode: FlightMode) -> int:
        if self.phase == Phase.DESCEND and self._fallback is None:
            return NAV_DESCEND
        return NAV_STATE_OF_MODE[mode]

    def _check_mode_fallback(self, t: float) -> None:
        """PX4's mode fallback: when the mode chosen cannot run (an estimate or a sensor is gone),
        the first of RTL, Land, Descend, Terminate that can (POSCTL and ALTCTL first to ALTCTL,
        STABILIZED: failsafe.py mode_fallback); taken once and announced; when the mode can run
        again, the vehicle goes back to it (PX4: the fallback clears with its condition)."""
        self._fallback_due = False
        # The offboard stream has its own rule (COM_OF_LOSS_T, below), as PX4's COM_OBL_RC_ACT.
        flags = self.flags._replace(offboard_control_signal_lost=False)
        intended = self._intended or self.mode
        nav = self._nav_state(intended)
        action = mode_fallback(flags, nav, self.params)
        if action is None:
            if self._fallback is not None:
                self._recover(t, intended)
            return
        if action == self._fallback:
            return
        if self._fallback is None:
            self._intended = self.mode
        self._fallback = action
        reason = missing_for(flags, nav) or "the mode cannot run"
        self._take_failsafe(t, action, f"{reason} for {NAV_MODE_NAMES.get(nav, 'the mode')}")

    def _take_failsafe(self, t: float, action: str, reason: str) -> None:
        """Carry out a failsafe action (through the table) and announce it as PX4 does."""
        event = _FAILSAFE_EVENTS[action]
        row = lookup(self.phase, event)
        if row is None or (not isinstance(row.to, Phase) and row.action is None):
            self._event(SEVERITY_CRITICAL, f"Failsafe activated: {reason} (already {self.mode.px4_name})")
            return
        self._event(SEVERITY_CRITICAL, f"Failsafe activated: {reason}, triggering {ACTION_NAMES[action]}")
        self._fire(t, event, mode=_FALLBACK_MODES.get(action))
        self.in_failsafe = True

    def _recover(self, t: float, intended: FlightMode) -> None:
        self._fallback = self._intended = None
        self.in_failsafe = False
        if self.phase not in FLYING:
            return
        event = MODE_EVENTS.get(intended)
        if event is not None and self._fire(t, event, mode=intended).accepted:
            self._event(SEVERITY_NOTICE, f"Failsafe deactivated: back to {intended.px4_name}")

    def _check_sticks(self, t: float) -> None:
        """The sticks' stream (PX4's rules): announce a loss and a return; a loss while flying a
        manual mode acts by NAV_RCL_ACT; sticks that move take over by COM_RC_OVERRIDE."""
        limits = self._manual_limits
        change = self.sticks.poll(t, limits.loss_s)
        if change is not None:
            kind, gap = change
            if kind == LOST:
                self._event(SEVERITY_WARNING, "Manual control lost")
                if self.phase == Phase.MANUAL:
                    mode = self.mode.px4_name
                    action, number = rc_loss_action(self.params)
                    action = resolve_action(self.health_flags(t), action)  # a mode that can run
                    self._fire(t, _FAILSAFE_EVENTS[action], mode=_FALLBACK_MODES.get(action))
                    self.in_failsafe = True
                    doing = f"{_FAILSAFE_DOING[action]} (NAV_RCL_ACT {number})"
                    self._event(SEVERITY_CRITICAL, f"manual control lost in {mode}: {doing}")
            else:
                self._event(SEVERITY_INFO, f"Manual control regained after {gap:.1f}s")
        override = self.sticks.take_override() and self._override_allowed()
        if override and self._fire(t, Event.RC_OVERRIDE, mode=FlightMode.POSCTL).accepted:
            self._event(SEVERITY_INFO, "Pilot took over using sticks")

    def _override_allowed(self) -> bool:
        """COM_RC_OVERRIDE: bit 0 the AUTO modes (flying), bit 1 OFFBOARD."""
        bits = int(self.params["COM_RC_OVERRIDE"])
        if self.phase == Phase.OFFBOARD:
            return bool(bits & RC_OVERRIDE_OFFBOARD)
        return self.phase in AUTOMATIC and bool(bits & RC_OVERRIDE_AUTO)

    def _check_failsafes(self, t: float, state: VehicleState) -> None:
        """Data link loss, geofence and battery (failsafe.py); once per step while flying."""
        for action, text in self.failsafes.check(t, state.position_m, self.home, self.in_air()):
            if action == WARN:
                self._event(SEVERITY_WARNING, text)
                continue
            taken = self._failsafe(t, action)
            if taken is not None:
                self._event(SEVERITY_CRITICAL, f"{text}: {_FAILSAFE_DOING[taken]}")
            else:  # the vehicle is already returning or landing: let it
                self._event(SEVERITY_CRITICAL, f"{text} (already {self.mode.px4_name})")
        battery = self.battery.action()
        if battery is not None:
            severity, (action, text) = battery
            if action == WARN or self._failsafe(t, action) is not None:
                self._event(severity, text)
            else:  # a landing (or a return, for a return) under way goes on
                self._event(severity, f"{text}: already {self.mode.px4_name}")

    def _failsafe(self, t: float, action: str) -> str | None:
        """Take a failsafe's action through the table, as a mode that can run (PX4's chain:
        :func:`~.failsafe.resolve_action`); the action taken, or None when the row keeps the phase
        (a return or landing under way goes on)."""
        action = resolve_action(self.flags, action)
        event = _FAILSAFE_EVENTS[action]
        row = lookup(self.phase, event)
        if row is not None and isinstance(row.to, Phase):
            self._fire(t, event, mode=_FALLBACK_MODES.get(action))
            self.in_failsafe = True
            return action
        return None
