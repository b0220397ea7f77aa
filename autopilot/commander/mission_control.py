"""The stored mission, the geofence and the rally points, as the commander flies them: a new
mission or fence checked as PX4 checks them ("Geofence violation for waypoint N"), AUTO.MISSION
entered, started and set to an item, and the mission's reference per step (its LAND and RTL items
raise the table's events: :mod:`autopilot.mission.executor` flies the legs).

A part of :class:`~.commander.Commander` (its state lives there); the transitions go through the
table (:mod:`.transitions`).
"""

from __future__ import annotations

from quadcommon.trajectories import Reference

from ..mission.executor import MissionAction, MissionExecutor, PlanContext, check_mission, fence_violation
from ..mission.plans import Geofence, RallyPoint
from .failsafe import fence_excess
from .records import (
    DENIED,
    SEVERITY_CRITICAL,
    SEVERITY_INFO,
    SEVERITY_WARNING,
    ZERO3,
    Outcome,
    Vector3,
    VehicleState,
    at_rest,
)
from .transitions import ON_GROUND, Event, Phase


class MissionControl:
    """The mission, the geofence and the rally points (module docstring): a part of the Commander."""

    def target_problem(self, target: Vector3) -> str | None:
        """Why a point the vehicle is asked to fly to (paper frame, m) breaks the geofence, or None."""
        if self.home is None:
            return None
        excess, what = fence_excess(self.params, target, self.home, self.failsafes.geofence)
        return f"outside the geofence: {what}" if excess > 0.0 else None

    def set_geofence(self, t: float, geofence: Geofence | None) -> None:
        """The uploaded geofence plan (None or no areas: only the GF_MAX_* limits). The stored
        mission is checked against it as PX4 does: the fence is accepted whatever the mission;
        a mission it excludes is announced ("Geofence violation for waypoint N"), AUTO.MISSION
        refuses it until the mission or the fence changes, and flying it, the vehicle holds."""
        self.failsafes.geofence = geofence if geofence is not None and geofence.areas else None
        problem = self.mission_fence_problem()
        if problem is None:
            return
        self._event(SEVERITY_CRITICAL, f"{problem}: the mission is not valid with this geofence")
        if self.phase == Phase.MISSION:
            self._fire(t, Event.MISSION_INVALID)
            self._event(SEVERITY_CRITICAL, "No valid mission available, loitering")

    def mission_fence_problem(self) -> str | None:
        """Why the stored mission breaks the geofence (PX4's "Geofence violation for waypoint N",
        N counted from 1), or None."""
        mission = self.mission
        if mission is None or mission.count == 0:
            return None
        violation = fence_violation(mission.items, mission.origin, self.target_problem,
                                    self.home or ZERO3)  # fmt: skip
        if violation is None:
            return None
        seq, why = violation
        return f"Geofence violation for waypoint {seq + 1} (item {seq}: {why})"

    def set_rally_points(self, points: list[RallyPoint]) -> None:
        """The rally plan: RTL's destinations besides home, by RTL_TYPE (:mod:`.rtl`)."""
        self.rally_points = list(points)

    def set_mission(self, t: float, mission: MissionExecutor | None) -> None:
        """A new stored mission (upload accepted) or none (cleared); flying the old one: hold."""
        if self.phase == Phase.MISSION:
            self._fire(t, Event.MISSION_REPLACED)
            self._event(SEVERITY_WARNING, "mission replaced in flight: holding (AUTO.MISSION flies it)")
        self.mission = mission

    def start_mission(self, t: float, first_item: int | None = None) -> Outcome:
        """MAV_CMD_MISSION_START: (optionally from ``first_item``) fly the mission, from any mode."""
        mission = self.mission
        if first_item is not None and mission is not None and not mission.set_current(first_item):
            return self._refuse(DENIED, f"mission start refused: no item {first_item}")
        return self._fire(t, Event.MISSION_START)

    def mission_set_current(self, t: float, seq: int) -> Outcome:
        """MISSION_SET_CURRENT / DO_SET_MISSION_CURRENT: fly to ``seq`` next (at once if flying it)."""
        if self.mission is None or not self.mission.set_current(seq):
            return self._refuse(DENIED, f"set current mission item refused: no item {seq}")
        return self._fire(t, Event.SET_CURRENT)

    def _act_check_mission(self, t: float, **_) -> Outcome | None:
        """Disarmed: AUTO.MISSION may be selected (arming then flies it) if the mission is flyable."""
        mission = self.mission
        if mission is None or mission.count == 0:
            return self._refuse(DENIED, "AUTO.MISSION refused: no mission loaded")
        problem = check_mission(mission.items, mission.origin, self.limits(), self.params.values)
        if problem is not None:
            return self._refuse(DENIED, f"AUTO.MISSION refused: {problem[1]}")
        fence_problem = self.mission_fence_problem()
        if fence_problem is not None:
            return self._refuse(DENIED, f"AUTO.MISSION refused: {fence_problem}")
        return None

    def _act_start_mission(self, t: float, **_) -> Outcome | None:
        """Fly the mission from the measured state, at its current item."""
        mission, state = self.mission, self.state
        if mission is None or mission.count == 0:
            return self._refuse(DENIED, "AUTO.MISSION refused: no mission loaded")
        fence_problem = self.mission_fence_problem()
        if fence_problem is not None:
            return self._refuse(DENIED, f"AUTO.MISSION refused: {fence_problem}")
        assert state is not None and self.home is not None
        on_ground = self.phase in ON_GROUND or not self.in_air()
        p = self.params
        context = PlanContext(
            self.home, self.limits(), p["NAV_ACC_RAD"], p["MIS_TAKEOFF_ALT"], p["MPC_TKO_SPEED"]
        )
        reason = mission.start(t, at_rest(state), context, on_ground)
        if reason is not None:
            return self._refuse(DENIED, f"AUTO.MISSION refused: {reason}")
        self._trajectory = None
        self._landed_since = None
        self._event(SEVERITY_INFO, f"mission: flying item {mission.current_seq} of {mission.count}")
        return None

    def _mission_reference(self, t: float, state: VehicleState) -> Reference | None:
        """The mission's reference this step; None when its LAND or RTL item changed the phase (the
        mode stays AUTO.MISSION for LAND)."""
        assert self.mission is not None
        out = self.mission.step(t, state.position_m)
        for severity, text in self.mission.drain_notices():
            self._event(severity, text)
        if out.action == MissionAction.LAND:  # the mission's LAND item: mode stays AUTO.MISSION
            self._fire(t, Event.MISSION_LAND)
            return None
        if out.action == MissionAction.RTL:
            self._fire(t, Event.MISSION_RTL)
            return None
        return out.reference
