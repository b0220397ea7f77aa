"""Failsafe monitors and pre-arm checks of the commander (pure: simulation time in, decisions out).

Each failsafe is a parameter with PX4's name, values and default:

* GCS data link loss: no HEARTBEAT from a ground station (MAV_TYPE_GCS) for ``COM_DL_LOSS_T``
  seconds of simulation time -> ``NAV_DLL_ACT`` (0 none, the default as in PX4; 1 hold, 2 return,
  3 land). A ground station that never sent a heartbeat never triggers it; with action 0 nothing is
  announced either (at ``--speed max`` a 1 Hz wall-clock heartbeat is many simulated seconds apart,
  so a silent default keeps fast runs quiet). The action is taken once per loss, while flying; a
  heartbeat ends the loss ("regained").
* Geofence: horizontal distance from home above ``GF_MAX_HOR_DIST`` or height above home above
  ``GF_MAX_VER_DIST`` (0 disables either; both 0 by default, as PX4) -> ``GF_ACTION`` (0 none,
  1 warning, 2 hold (PX4's default), 3 return, 5 land). A breach latches: the action is taken once,
  and the fence re-arms only when the vehicle is back inside by a margin (hysteresis, so holding at
  the boundary does not retrigger every step). An uploaded geofence plan (inclusion/exclusion
  polygons and circles, :class:`autopilot.mission.plans.Geofence`) counts the same way: the worst
  excess of all decides, so a breach of any of them acts by ``GF_ACTION``.
* Manual control loss: no MANUAL_CONTROL for ``COM_RC_LOSS_T`` while flying a manual mode ->
  ``NAV_RCL_ACT`` (1 hold, 2 return (PX4's default), 3 land): :func:`rc_loss_action`; the stream
  itself is watched by the commander (:class:`autopilot.guidance.sticks.StickStream`). In the AUTO
  modes and OFFBOARD the loss is announced and nothing else (as PX4 with ``COM_RCL_EXCEPT``
  excepting them).
* Offboard setpoint loss (``COM_OF_LOSS_T``) and simulator loss (``COM_SIM_LOSS_T``) live in the
  commander and the process shell respectively.
* Battery (:class:`BatteryWatch`, PX4's batteryCheck.cpp and failsafe.cpp on the estimate of
  :mod:`autopilot.battery.estimator`): the warning level (low, critical, emergency below
  ``BAT_LOW_THR``, ``BAT_CRIT_THR``, ``BAT_EMERGEN_THR``) only rises while armed (the hysteresis:
  a sagging pack that recovers under a lighter load does not clear it), and follows the estimate
  while disarmed; a pack connected at arming that disconnects counts as critical. Each level
  reached while flying is announced once as PX4 words it and acts by ``COM_LOW_BAT_ACT``
  (:data:`LOW_BATTERY_ACTIONS`), unless the level was there at arming already (then only
  announced). A pack that stops reporting for 5 s is unhealthy (announced, no action: PX4's
  warning after spool-up); faults (over-voltage) are announced. Arming is refused at the critical
  level or below, with an unhealthy pack or a fault (PX4, ``COM_ARM_BAT_MIN`` unset).

Actions are returned as :class:`FailsafeAction` records; the commander applies them (it knows how
to hold, return and land) and a failsafe never overrides a landing or return already under way.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import NamedTuple

from ..battery.estimator import (
    FAULT_NAMES,
    WARNING_CRITICAL,
    WARNING_EMERGENCY,
    WARNING_LOW,
    WARNING_NONE,
    BatteryStatus,
)
from ..mission.plans import Geofence
from ..params.definitions import (
    DLL_HOLD,
    DLL_LAND,
    DLL_RTL,
    GF_HOLD,
    GF_LAND,
    GF_RTL,
    GF_WARN,
    LOW_BAT_LAND,
    LOW_BAT_RTL,
    LOW_BAT_RTL_THEN_LAND,
    LOW_BAT_WARN,
    POSCTL_NAVL_LAND,
    RCL_HOLD,
    RCL_LAND,
    RCL_RTL,
    consistency_problems,
)
from ..params.store import ParameterStore
from .health import (
    NAV_ALTCTL,
    NAV_AUTO_LAND,
    NAV_AUTO_LOITER,
    NAV_AUTO_RTL,
    NAV_DESCEND,
    NAV_NAMES,
    NAV_POSCTL,
    NAV_STAB,
    FailsafeFlags,
    missing_for,
    mode_can_run,
)

Vector3 = tuple[float, float, float]

WARN, HOLD, RTL, LAND = "warn", "hold", "rtl", "land"
_DLL_ACTIONS = {DLL_HOLD: HOLD, DLL_RTL: RTL, DLL_LAND: LAND}
_GF_ACTIONS = {GF_WARN: WARN, GF_HOLD: HOLD, GF_RTL: RTL, GF_LAND: LAND}
_RCL_ACTIONS = {RCL_HOLD: HOLD, RCL_RTL: RTL, RCL_LAND: LAND}
FENCE_REARM_M = 0.5  # back inside by this much (or 10 % of the limit if smaller) re-arms the fence


class FailsafeAction(NamedTuple):
    action: str  # WARN, HOLD, RTL or LAND
    text: str  # for STATUSTEXT (the commander adds what it does)


# MAV_SEVERITY
EMERGENCY, CRITICAL, WARNING = 0, 2, 4
# COM_LOW_BAT_ACT -> what each battery level does (PX4's failsafe.cpp, fromBatteryWarningActParam).
_W, _R, _L, _RL = LOW_BAT_WARN, LOW_BAT_RTL, LOW_BAT_LAND, LOW_BAT_RTL_THEN_LAND
# fmt: off
LOW_BATTERY_ACTIONS = {  # level: {COM_LOW_BAT_ACT: action}
    #                  0 warning, 1 return, 2 land,   3 return, then land
    WARNING_LOW:       {_W: WARN, _R: WARN, _L: WARN, _RL: WARN},
    WARNING_CRITICAL:  {_W: WARN, _R: RTL,  _L: LAND, _RL: RTL},
    WARNING_EMERGENCY: {_W: WARN, _R: RTL,  _L: LAND, _RL: LAND},
}
# fmt: on
# PX4's words for each level: the warning (severity, text), the failsafe's cause, the pre-arm check's.
BATTERY_WARNINGS = {
    WARNING_LOW: (WARNING, "Low battery level, return advised"),
    WARNING_CRITICAL: (CRITICAL, "Critical battery level, land now"),
    WARNING_EMERGENCY: (EMERGENCY, "Emergency battery level, land immediately"),
}
BATTERY_CAUSES = {WARNING_LOW: "low battery level", WARNING_CRITICAL: "critical battery level",
                  WARNING_EMERGENCY: "emergency battery level"}  # fmt: skip
BATTERY_CHECKS = {WARNING_LOW: "Low battery", WARNING_CRITICAL: "Critical battery",
                  WARNING_EMERGENCY: "Emergency battery level"}  # fmt: skip
_ACTION_WORDS = {RTL: "RTL", LAND: "land"}  # PX4's failsafe_action_t


class BatteryWatch:
    """The commander's view of the battery (see the module's docstring): :meth:`update` once per
    control step with the estimate, :meth:`action` while flying, :meth:`prearm_problem` at arming.
    """

    def __init__(self, params: ParameterStore) -> None:
        self.params = params
        self.status: BatteryStatus | None = None
        self.unhealthy = False
        self.warning = WARNING_NONE  # rises only while armed
        self._armed = False
        self._warning_at_arming = WARNING_NONE
        self._connected_at_arming = False
        self._acted = WARNING_NONE  # the highest level announced in this armed period
        self._told_unhealthy = False
        self._told_faults = 0
        self._told_disconnected = False

    def update(
        self, status: BatteryStatus | None, unhealthy: bool, armed: bool
    ) -> Sequence[tuple[int, str]]:
        """The estimate now; returns what to announce (severity, text): a pack that became
        unhealthy, a new fault, a disconnection in flight."""
        if status is self.status and unhealthy == self.unhealthy and armed == self._armed:
            return ()  # most steps: no new report
        notices: list[tuple[int, str]] = []
        if armed != self._armed:
            self._armed = armed
            self._acted = WARNING_NONE
            self._told_disconnected = False
            if armed:
                self._warning_at_arming = self.warning
                self._connected_at_arming = status is not None and status.connected
        worst = WARNING_NONE
        self.status = status
        if status is not None:
            if status.connected:
                worst = status.warning
            elif armed and self._connected_at_arming:  # PX4: a critical warning, to act on it
                worst = WARNING_CRITICAL
                if not self._told_disconnected:
                    self._told_disconnected = True
                    notices.append((EMERGENCY, "Battery 1 disconnected"))
            new_faults = status.faults & ~self._told_faults
            self._told_faults = status.faults
            for bit, name in FAULT_NAMES.items():
                if new_faults & (1 << bit):
                    notices.append((EMERGENCY, f"Battery 1: {name}." + (" Land now!" if armed else "")))
        self.warning = max(self.warning, worst) if armed else worst
        if unhealthy != self.unhealthy:
            self.unhealthy = unhealthy
            if unhealthy:
                notices.append((CRITICAL, "Battery unhealthy: no battery report for 5 s"))
        return notices

    def action(self) -> tuple[int, FailsafeAction] | None:
        """The level just reached while flying, once: (severity, what to do and say); None when
        nothing new. A level no worse than at arming only warns (PX4)."""
        level = self.warning
        if level <= self._acted:
            return None
        self._acted = level
        number = int(self.params["COM_LOW_BAT_ACT"])
        action = LOW_BATTERY_ACTIONS[level].get(number, WARN) if level > self._warning_at_arming else WARN
        if action == WARN:
            severity, text = BATTERY_WARNINGS[level]
            return severity, FailsafeAction(WARN, text)
        text = f"Failsafe activated due to {BATTERY_CAUSES[level]}, triggering {_ACTION_WORDS[action]}"
        return CRITICAL, FailsafeAction(action, f"{text} (COM_LOW_BAT_ACT {number})")

    def prearm_problem(self) -> str | None:
        """Why the battery refuses arming (PX4's batteryCheck), or None: critical or emergency
        level, an unhealthy pack, a fault."""
        status = self.status
        if status is None:
            return None  # no battery reported at all: nothing to check (PX4)
        if self.unhealthy:
            return "Battery unhealthy (no battery report for 5 s)"
        for bit, name in FAULT_NAMES.items():
            if status.faults & (1 << bit):
                return f"Battery 1: {name}"
        if self.warning >= WARNING_CRITICAL:
            p = self.params
            threshold = "BAT_EMERGEN_THR" if self.warning == WARNING_EMERGENCY else "BAT_CRIT_THR"
            return (f"{BATTERY_CHECKS[self.warning]} (remaining {100.0 * status.remaining:.0f} % < "
                    f"{threshold} {100.0 * p[threshold]:g} %)")  # fmt: skip
        return None


def rc_loss_action(params: ParameterStore) -> tuple[str, int]:
    """What losing the sticks in a manual mode does: (HOLD, RTL or LAND, the NAV_RCL_ACT value)."""
    number = int(params["NAV_RCL_ACT"])
    return _RCL_ACTIONS.get(number, RTL), number


def fence_excess(
    params: ParameterStore, position: Vector3, home: Vector3, geofence: Geofence | None = None
) -> tuple[float, str]:
    """How far outside the geofence ``position`` is (m, <= 0 inside) and a description: the
    ``GF_MAX_*`` limits around ``home`` and the uploaded ``geofence`` plan, the worst of them."""
    worst, what = geofence.excess(position) if geofence is not None else (-math.inf, "")
    limit = params["GF_MAX_HOR_DIST"]
    if limit > 0.0:
        d = math.hypot(position[0] - home[0], position[1] - home[1])
        if d - limit > worst:
            worst, what = d - limit, f"{d:.1f} m from home > GF_MAX_HOR_DIST {limit:g} m"
    limit = params["GF_MAX_VER_DIST"]
    if limit > 0.0:
        h = position[2] - home[2]
        if h - limit > worst:
            worst, what = h - limit, f"{h:.1f} m above home > GF_MAX_VER_DIST {limit:g} m"
    return worst, what


def _rearm_margin(params: ParameterStore) -> float:
    limits = [v for v in (params["GF_MAX_HOR_DIST"], params["GF_MAX_VER_DIST"]) if v > 0.0]
    return min([FENCE_REARM_M] + [0.1 * v for v in limits])


class FailsafeMonitor:
    """Data link loss and geofence state; :meth:`check` once per control step while flying."""

    def __init__(self, params: ParameterStore) -> None:
        self.params = params
        self.last_gcs_heartbeat_s: float | None = None
        self.link_lost = False  # a loss was announced and no heartbeat came since
        self._link_acted = False  # the loss action was taken for this loss
        self.fence_breached = False  # latched until back inside by the margin
        self.geofence: Geofence | None = None  # the uploaded geofence plan (None: none)

    def gcs_heartbeat(self, t: float) -> list[str]:
        """A ground station's HEARTBEAT at ``t``; returns messages to announce (link regained)."""
        self.last_gcs_heartbeat_s = t
        if self.link_lost:
            self.link_lost = False
            self._link_acted = False
            return ["GCS connection regained"]
        return []

    def check(self, t: float, position: Vector3, home: Vector3 | None, flying: bool) -> list[FailsafeAction]:
        """Failsafe actions due at ``t`` (each at most once per event)."""
        out: list[FailsafeAction] = []
        p = self.params
        action = int(p["NAV_DLL_ACT"])
        last = self.last_gcs_heartbeat_s
        if action in _DLL_ACTIONS and last is not None and t - last > p["COM_DL_LOSS_T"]:
            if not self.link_lost:
                self.link_lost = True
                if not flying:
                    text = f"GCS connection lost: no heartbeat for {t - last:.1f} s"
                    out.append(FailsafeAction(WARN, text))
            if flying and not self._link_acted:
                self._link_acted = True
                out.append(
                    FailsafeAction(
                        _DLL_ACTIONS[action],
                        f"GCS connection lost: no heartbeat for {t - last:.1f} s (NAV_DLL_ACT {action})",
                    )
                )
        if home is not None and flying:
            excess, what = fence_excess(p, position, home, self.geofence)
            if excess > 0.0 and not self.fence_breached:
                self.fence_breached = True
                gf_action = _GF_ACTIONS.get(int(p["GF_ACTION"]))
                if gf_action is not None:
                    out.append(FailsafeAction(gf_action, f"geofence breached: {what}"))
            elif self.fence_breached and excess < -_rearm_margin(p):
                self.fence_breached = False
        return out


def prearm_problem(
    params: ParameterStore,
    position: Vector3 | None,
    home: Vector3 | None,
    position_valid: bool,
    geofence: Geofence | None = None,
    flags: FailsafeFlags | None = None,
    nav_state: int | None = None,
) -> str | None:
    """Why arming must be refused (beyond "not landed", which the commander checks), or None.

    Checked: a position (sensor frames flowing), every sensor healthy and the mode armed in able
    to run (``flags``, PX4's health and mode checks; the mission, the offboard stream and home
    have their own checks), consistent parameters
    (:func:`~autopilot.params.definitions.consistency_problems`), and the vehicle inside the
    geofence around the current home (PX4 checks the fence before arming too).
    """
    if position is None or not position_valid:
        return "no position (no sensor frames from the simulator)"
    if flags is not None:
        sick = flags.unhealthy_sensors()
        if sick:
            return "sensor failure: " + ", ".join(sick)
        own_checks = flags._replace(auto_mission_missing=False, offboard_control_signal_lost=False,
                                    home_position_invalid=False)  # fmt: skip
        if nav_state is not None and not mode_can_run(own_checks, nav_state):
            name = NAV_NAMES.get(nav_state, "this mode")
            return f"{name} not possible: {missing_for(own_checks, nav_state)}"
    problems = consistency_problems(params)
    if problems:
        return "bad parameters: " + "; ".join(problems)
    if home is not None:
        excess, what = fence_excess(params, position, home, geofence)
        if excess > 0.0:
            return f"outside the geofence: {what}"
    return None


# -- when the current mode cannot run: PX4's mode fallback and its chain ------------------------------
ALTCTL, STABILIZED, DESCEND, TERMINATE = "altctl", "stabilized", "descend", "terminate"
# PX4's fallback order (FailsafeBase::getSelectedAction): an action whose mode cannot run falls
# through to the next.
FALLBACK_CHAIN = (ALTCTL, STABILIZED, HOLD, RTL, LAND, DESCEND, TERMINATE)
FALLBACK_NAV = {ALTCTL: NAV_ALTCTL, STABILIZED: NAV_STAB, HOLD: NAV_AUTO_LOITER, RTL: NAV_AUTO_RTL,
                LAND: NAV_AUTO_LAND, DESCEND: NAV_DESCEND}  # fmt: skip
# PX4's names of the actions (events' failsafe_action_t), as the announcements say them.
ACTION_NAMES = {ALTCTL: "Altitude mode", STABILIZED: "Stabilized mode", HOLD: "Hold", RTL: "Return",
                LAND: "Land", DESCEND: "Descend", TERMINATE: "Terminate"}  # fmt: skip


def resolve_action(flags: FailsafeFlags, action: str) -> str:
    """The first action of :data:`FALLBACK_CHAIN` from ``action`` on whose mode can run
    (TERMINATE when none can); WARN is returned as it is."""
    if action not in FALLBACK_CHAIN:
        return action
    for candidate in FALLBACK_CHAIN[FALLBACK_CHAIN.index(action) :]:
        nav = FALLBACK_NAV.get(candidate)
        if nav is None or mode_can_run(flags, nav):
            return candidate
    return TERMINATE


def mode_fallback(flags: FailsafeFlags, nav_state: int, params: ParameterStore) -> str | None:
    """PX4's ``Failsafe::checkModeFallback`` then the chain: what to do when the mode the pilot or
    the ground station chose (``nav_state``) cannot run; None when it can. POSCTL by
    ``COM_POSCTL_NAVL`` (0: ALTCTL, then STABILIZED; 1: land, then descend), ALTCTL to STABILIZED,
    any other mode to RTL; then RTL -> Land -> Descend -> Terminate as far as needed. A manual
    fallback without the sticks acts by ``NAV_RCL_ACT``."""
    action = None
    if nav_state == NAV_POSCTL and not mode_can_run(flags, NAV_POSCTL):
        if int(params["COM_POSCTL_NAVL"]) == POSCTL_NAVL_LAND:
            action, nav_state = LAND, NAV_AUTO_LAND
        else:
            action, nav_state = ALTCTL, NAV_ALTCTL
    if nav_state == NAV_ALTCTL and not mode_can_run(flags, NAV_ALTCTL):
        action, nav_state = STABILIZED, NAV_STAB
    if flags.manual_control_signal_lost and action in (ALTCTL, STABILIZED):
        action, _ = rc_loss_action(params)
    elif not mode_can_run(flags, nav_state):
        action = RTL
    return None if action is None else resolve_action(flags, action)
