"""The commander: arming, flight modes, and what the vehicle should do next (the navigator).

Pure: no sockets, no clocks. Every method takes the simulation time ``t`` (s) and the latest
:class:`VehicleState`; :meth:`Commander.step` returns, once per control step, whether the motors
are off, idling on the ground, or flying, and the reference (p_d, p_d', p_d'', yaw) to fly. Events
worth telling a ground station (mode changes, failsafes, refusals with their reason) are queued
as ``(severity, text)`` for the MAVLink shell to send as STATUSTEXT.

Behaviour follows PX4 where PX4 users would expect it: arming only on the ground; takeoff climbs to
``MIS_TAKEOFF_ALT`` (or the commanded altitude) then holds (AUTO.LOITER); land descends at
``MPC_LAND_SPEED``, detects touchdown and disarms after ``COM_DISARM_LAND``; RTL climbs to
``RTL_RETURN_ALT`` above its destination (home or a rally point, by ``RTL_TYPE``: :mod:`.rtl`),
flies above it and lands; OFFBOARD needs a setpoint stream before it is
entered and falls back to hold when setpoints stop for ``COM_OF_LOSS_T`` (simulation time); an
armed vehicle that does not take off within ``COM_DISARM_PRFLT`` disarms itself. The manual modes
(MANUAL, STABILIZED, ALTCTL, POSCTL, ACRO) need the sticks (MANUAL_CONTROL) to be entered, take off
when the throttle is raised above 62.5 % on the ground, land on their own, and act by
``NAV_RCL_ACT`` when the sticks stop for ``COM_RC_LOSS_T``; sticks that move take over the AUTO
modes and OFFBOARD into POSCTL by ``COM_RC_OVERRIDE`` (:mod:`autopilot.guidance.sticks`).

Every change of phase or mode goes through the one table in :mod:`.transitions`; this module
decides which event happened and carries out the row's action (the plans and the guards).
(One module: the decisions and the actions share the commander's state; the
transitions themselves are the table.)
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, replace
from enum import Enum
from typing import NamedTuple

from quadcommon.trajectories import PiecewiseTrajectory, Reference, Trajectory

from ..battery.estimator import BatteryStatus
from ..estimation.status import EstimatorStatus
from ..guidance.follow import FollowSettings, FollowTarget, TargetReport
from ..guidance.manual import ManualGuidance, ManualLimits, ManualSetpoint
from ..guidance.offboard import AttitudeSetpoint, OffboardGuidance, OffboardSetpoint
from ..guidance.orbit import (
    SPEED_MAX_M_S,
    YAW_NAMES,
    Orbit,
    OrbitLimits,
    OrbitRequest,
    OrbitStatus,
    radius_refusal,
)
from ..guidance.planner import Limits, LineMove, stop_from
from ..guidance.sticks import LOST, Sticks, StickStream
from ..mission.executor import (
    MissionAction,
    MissionExecutor,
    MissionState,
    PlanContext,
    check_mission,
    fence_violation,
)
from ..mission.plans import Geofence, RallyPoint
from ..params.definitions import POSCTL_NAVL_ALTITUDE, RC_OVERRIDE_AUTO, RC_OVERRIDE_OFFBOARD
from ..params.store import ParameterStore
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
    BatteryWatch,
    FailsafeMonitor,
    fence_excess,
    mode_fallback,
    prearm_problem,
    rc_loss_action,
    resolve_action,
)
from .health import (
    NAV_ALTCTL,
    NAV_AUTO_FOLLOW_TARGET,
    NAV_AUTO_LAND,
    NAV_AUTO_LOITER,
    NAV_AUTO_MISSION,
    NAV_AUTO_RTL,
    NAV_AUTO_TAKEOFF,
    NAV_DESCEND,
    NAV_OFFBOARD,
    NAV_ORBIT,
    NAV_POSCTL,
    NAV_STATE_OF_MODE,
    FailsafeFlags,
    HealthMonitor,
    LinkState,
    missing_for,
    mode_can_run,
)
from .modes import FlightMode, LandedState
from .rtl import return_altitude, return_destination
from .transitions import (
    AFTER,
    ASKED,
    AUTOMATIC,
    DESCENDING,
    FLYING,
    ON_GROUND,
    REFUSALS,
    TABLE,
    Event,
    Phase,
    lookup,
)

__all__ = ["Commander", "Event", "Phase", "TABLE", "Motors", "GuidanceOutput", "Outcome", "VehicleState"]

Vector3 = tuple[float, float, float]
ZERO3: Vector3 = (0.0, 0.0, 0.0)

# MAV_RESULT
ACCEPTED, TEMPORARILY_REJECTED, DENIED, UNSUPPORTED, FAILED = 0, 1, 2, 3, 4
# MAV_SEVERITY
SEVERITY_EMERGENCY, SEVERITY_CRITICAL, SEVERITY_WARNING, SEVERITY_NOTICE, SEVERITY_INFO = 0, 2, 4, 5, 6
# The failsafe flags are evaluated this often (simulation time) and after every transition: PX4's
# commander runs its health and arming checks at 10 Hz and when its state changes; its failsafe
# state machine (here the mode fallback) reads the flags at 100 Hz, here when they or the mode change.
HEALTH_PERIOD_S = 0.1

CONTINUE_WITHIN_M = 0.5  # a new plan continues the reference if the vehicle is this close to it
GROUND_Z_M = 0.0  # the local frame's origin (the configured home) is on flat ground
ON_GROUND_HEIGHT_M = 0.05  # O within this of the ground counts as touching it
LANDED_SPEED_M_S = 0.1
LANDED_CONFIRM_S = 0.3
IN_AIR_HEIGHT_M = 0.1
# On the ground, a height within this many standard deviations of the estimate's height (its
# 1-sigma, 0 on the truth) above IN_AIR_HEIGHT_M is the ground (see Commander.in_air).
GROUND_HEIGHT_SIGMAS = 3.0
MOVING_SPEED_M_S = 0.2  # a vehicle on the ground faster than this is not at rest: arming refused
# The pre-arm verdict, announced while disarmed (PX4's "Preflight Fail: ..." STATUSTEXT): checked
# this often; the same verdict (its figures aside) not announced again within READINESS_REPEAT_S.
READINESS_CHECK_S = 0.1
READINESS_REPEAT_S = 10.0
STICK_TAKEOFF_UP = 0.25  # throttle stick above 62.5 % of its travel takes off a manual mode (PX4)


@dataclass(frozen=True)
class VehicleState:
    """What the commander knows of the vehicle (paper frames, SI)."""

    time_s: float
    position_m: Vector3
    velocity_m_s: Vector3
    euler_rad: Vector3
    euler_rates_rad_s: Vector3


class Motors(Enum):
    OFF = 0  # disarmed
    IDLE = 1  # armed on the ground, no thrust, controller states held at zero
    FLY = 2  # the cascade tracks the reference


class GuidanceOutput(NamedTuple):
    motors: Motors
    reference: Reference | None
    manual: ManualSetpoint | None = None  # a manual mode's overrides of the cascade (None: none)


class Outcome(NamedTuple):
    result: int  # MAV_RESULT
    reason: str = ""

    @property
    def accepted(self) -> bool:
        return self.result == ACCEPTED


PREFLIGHT_FAIL = "Preflight Fail: "  # PX4's prefix of a pre-arm failure reported unasked
_FIGURES = re.compile(r"\d+(?:\.\d+)?")  # the figures of a verdict (not part of which verdict it is)
_FAILSAFE_EVENTS = {HOLD: Event.FAILSAFE_HOLD, RTL: Event.FAILSAFE_RTL, LAND: Event.FAILSAFE_LAND,
                    DESCEND: Event.FAILSAFE_DESCEND, TERMINATE: Event.FAILSAFE_TERMINATE,
                    ALTCTL: Event.FAILSAFE_MANUAL, STABILIZED: Event.FAILSAFE_MANUAL}  # fmt: skip
_FAILSAFE_DOING = {HOLD: "holding", RTL: "returning to launch", LAND: "landing", DESCEND: "descending",
                   TERMINATE: "flight terminated", ALTCTL: "in ALTCTL",
                   STABILIZED: "in STABILIZED"}  # fmt: skip
_FALLBACK_MODES = {ALTCTL: FlightMode.ALTCTL, STABILIZED: FlightMode.STABILIZED}
# The navigation state a command asks for (its mode must be able to run: PX4 refuses the switch).
_COMMAND_NAV = {
    Event.TAKEOFF: NAV_AUTO_TAKEOFF, Event.SELECT_TAKEOFF: NAV_AUTO_TAKEOFF, Event.HOLD: NAV_AUTO_LOITER,
    Event.REPOSITION: NAV_AUTO_LOITER, Event.LAND: NAV_AUTO_LAND, Event.RTL: NAV_AUTO_RTL,
    Event.OFFBOARD: NAV_OFFBOARD, Event.MISSION: NAV_AUTO_MISSION, Event.MISSION_START: NAV_AUTO_MISSION,
    Event.ORBIT: NAV_ORBIT, Event.FOLLOW: NAV_AUTO_FOLLOW_TARGET,
}  # fmt: skip
_MODE_EVENTS = {
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
_NAV_MODE_NAMES = {nav: mode.px4_name for mode, nav in NAV_STATE_OF_MODE.items()}
# Modes PX4 does not arm in (mode_req_prevent_arming) that this vehicle refuses to arm in too: Orbit
# and follow-me (PX4 also lists RTL, Land and Descend, which arm here and stay on the ground).
_NOT_ARMED_IN = (NAV_ORBIT, NAV_AUTO_FOLLOW_TARGET)
_TRAJECTORY_PHASES = (Phase.TAKEOFF, Phase.HOLD, Phase.TRAJECTORY, Phase.LAND, Phase.RTL, Phase.RTL_LAND)
# The phases whose plan leads to a point (Commander.destination; a scenario's trajectory does not)
_NAVIGATED_PHASES = (Phase.TAKEOFF, Phase.HOLD, Phase.LAND, Phase.RTL, Phase.RTL_LAND)
_LIFTING_PHASES = (Phase.TAKEOFF, Phase.OFFBOARD, Phase.TRAJECTORY, Phase.MISSION)
# Each manual mode's control step (autopilot/guidance/manual.py); MANUAL flies as STABILIZED (PX4).
_MANUAL_STEPS = {
    FlightMode.POSCTL: ManualGuidance.position,
    FlightMode.ALTCTL: ManualGuidance.altitude,
    FlightMode.STABILIZED: ManualGuidance.stabilized,
    FlightMode.MANUAL: ManualGuidance.stabilized,
    FlightMode.ACRO: ManualGuidance.acro,
}


class Commander:
    """Arming, modes and the reference to fly; every state change goes through :data:`TABLE`."""

    def __init__(self, params: ParameterStore) -> None:
        self.params = params
        self.phase = Phase.DISARMED
        self.mode = FlightMode.AUTO_LOITER
        self.home: Vector3 | None = None
        self.state: VehicleState | None = None
        self.events: list[tuple[int, str]] = []
        self.offboard = OffboardGuidance(self.limits())
        self.sticks = StickStream()  # MANUAL_CONTROL: freshness, loss, override requests
        self.manual = ManualGuidance()  # the manual modes' state
        self._manual_limits = self.manual_limits()  # rebuilt when a parameter changes, not per step
        self.orbit = Orbit()  # the Orbit mode's state (guidance/orbit.py)
        self.follow = FollowTarget()  # follow-me: the target's estimate and the mode's state
        self._orbit_limits = self.orbit_limits()
        self._follow_settings = self.follow_settings()
        self.last_reference: Reference | None = None
        self.mission: MissionExecutor | None = None  # the stored mission (set by the mission service)
        self.rally_points: list[RallyPoint] = []  # the uploaded rally plan (RTL's destinations)
        self.failsafes = FailsafeMonitor(params)
        self.battery = BatteryWatch(params)  # the battery's levels, checks and failsafe
        self.position_valid = False  # sensor frames flowing (False until the first, and when lost)
        self.estimator_problem: str | None = None  # why the estimate is not fit to arm on (None: it is)
        self.height_uncertainty_m = 0.0  # 1-sigma of the estimate's height (0: the truth); see in_air()
        # What the vehicle knows of its health (health.py): fed by the shell every frame, the flags
        # evaluated every HEALTH_PERIOD_S and after a transition.
        self.health = HealthMonitor(params)
        self.estimator_status: EstimatorStatus | None = None  # the EKF's last status (None: none)
        self.on_ekf = False  # flying on the EKF (EKF2_EN 1), else on the simulator's state
        self.flags = FailsafeFlags()
        self._health_due = -math.inf
        self._fallback: str | None = None  # the mode fallback taken (failsafe.py), None: none
        # The fallback depends on the flags, the phase and mode, the parameters: checked again when
        # one of them has changed.
        self._fallback_due = True
        self._intended: FlightMode | None = None  # the mode chosen before the fallback
        self.in_failsafe = False  # a failsafe action is in force (HEARTBEAT: MAV_STATE_CRITICAL)
        self.terminated = False  # the flight was terminated (until the next arming)
        self._trajectory: Trajectory | None = None  # what the trajectory phases fly
        self._trajectory_start = 0.0
        self._after_trajectory: FlightMode | None = None  # a scenario's hand-over mode (None: none)
        self._armed_at = 0.0
        self._landed_since: float | None = None
        self._touchdown_at = 0.0
        self._setpoint_times: list[float] = []
        self._follow_lost_said = True  # follow-me: the loss of the target was announced (or none yet)
        self._next_readiness_check = 0.0
        self._readiness_key: str | None = None  # the verdict last announced (None: ready, or none yet)
        self._readiness_said: dict[str | None, float] = {}  # verdict -> when it was last announced
        params.on_change(self._on_param_change)

    # -- reading the state ----------------------------------------------------------------------
    @property
    def armed(self) -> bool:
        return self.phase != Phase.DISARMED

    @property
    def landed_state(self) -> LandedState:
        if self.phase == Phase.TAKEOFF:
            return LandedState.TAKEOFF
        if self.phase in DESCENDING or self.phase == Phase.DESCEND:
            # LANDING until touchdown is confirmed (phase LANDED), as PX4's land detector: scripts
            # wait for "not in air" and then disarm, which must not happen a few cm up.
            return LandedState.LANDING
        if self.state is None or not self.in_air():
            return LandedState.ON_GROUND
        return LandedState.IN_AIR

    def limits(self) -> Limits:
        p = self.params
        return Limits(
            speed_horizontal=p["MPC_XY_VEL_MAX"],
            speed_up=p["MPC_Z_VEL_MAX_UP"],
            speed_down=p["MPC_Z_VEL_MAX_DN"],
            acceleration=p["MPC_ACC_HOR"],
            yaw_rate=p["MPC_YAWRAUTO_MAX"],
        )

    def manual_limits(self) -> ManualLimits:
        p = self.params
        rad = math.radians
        return ManualLimits(
            speed_horizontal=p["MPC_VEL_MANUAL"],
            speed_up=p["MPC_Z_VEL_MAX_UP"],
            speed_down=p["MPC_Z_VEL_MAX_DN"],
            acceleration=p["MPC_ACC_HOR"],
            yaw_rate=rad(p["MPC_MAN_Y_MAX"]),
            deadzone=p["MPC_HOLD_DZ"],
            loss_s=p["COM_RC_LOSS_T"],
            tilt_max=rad(p["MPC_MAN_TILT_MAX"]),
            thrust_hover=p["MPC_THR_HOVER"],
            thrust_min=p["MPC_MANTHR_MIN"],
            thrust_max=p["MPC_THR_MAX"],
            thrust_rescale=p["MPC_THR_CURVE"] == 0,
            acro_rates=(rad(p["MC_ACRO_R_MAX"]), rad(p["MC_ACRO_P_MAX"]), rad(p["MC_ACRO_Y_MAX"])),
            acro_expo=p["MC_ACRO_EXPO"],
            acro_expo_yaw=p["MC_ACRO_EXPO_Y"],
            acro_super_expo=p["MC_ACRO_SUPEXPO"],
            acro_super_expo_yaw=p["MC_ACRO_SUPEXPOY"],
            acro_tilt=rad(p["ACRO_TILT_LIM"]),
            override_speed=p["COM_RC_STICK_OV"] / 100.0,
        )

    def orbit_limits(self) -> OrbitLimits:
        p = self.params
        limits = self.limits()
        return OrbitLimits(p["MC_ORBIT_RAD_MAX"], min(SPEED_MAX_M_S, limits.speed_horizontal), limits,
                           int(p["MC_ORBIT_YAW_MOD"]))  # fmt: skip

    def follow_settings(self) -> FollowSettings:
        p = self.params
        return FollowSettings(p["FLW_TGT_HT"], p["FLW_TGT_DST"], p["FLW_TGT_FA"], int(p["FLW_TGT_ALT_M"]),
                              p["FLW_TGT_MAX_VEL"], p["FLW_TGT_RS"], self.limits())  # fmt: skip

    @property
    def orbit_status(self) -> OrbitStatus | None:
        """The orbit flown (ORBIT_EXECUTION_STATUS), or None when not in Orbit."""
        return self.orbit.status if self.phase == Phase.ORBIT else None

    @property
    def destination(self) -> Reference | None:
        """Where the plan being flown ends (paper frame), what PX4's navigator publishes as its
        current position setpoint: the takeoff point, the hold point, the landing point (a descent
        planned through the ground ends on it), the return point, the mission leg's target; None
        where no plan leads anywhere (on the ground, offboard, the manual modes, a scenario's
        trajectory). Samples the plan: for the flight log, a few times a second."""
        if self.phase == Phase.MISSION:
            return self.mission.destination if self.mission is not None else None
        plan = self._trajectory
        if self.phase not in _NAVIGATED_PHASES or plan is None or not math.isfinite(plan.duration_s):
            return None
        end = plan.sample(plan.duration_s)
        x, y, z = end.position_m
        return end._replace(position_m=(x, y, GROUND_Z_M)) if z < GROUND_Z_M else end

    def in_air(self) -> bool:
        """Whether the vehicle is off the ground (flat, z = 0 in the local frame): its height at
        least :data:`IN_AIR_HEIGHT_M`.

        On the ground (disarmed, armed before a takeoff, landed) the height is the estimate's, and
        a height the estimate cannot tell from the ground is the ground: the clearance grows by
        :data:`GROUND_HEIGHT_SIGMAS` times the estimate's 1-sigma height uncertainty
        (``height_uncertainty_m``; 0 on the truth). A filter that has just aligned on GNSS and a
        barometer puts a vehicle resting on the ground tenths of a metre up, with as much
        uncertainty, and it must not read as flying (PX4's land detector reports a disarmed
        vehicle landed whatever its estimate says). In flight the plain clearance applies.
        """
        state = self.state
        if state is None:
            return False
        clearance = IN_AIR_HEIGHT_M
        if self.phase == Phase.DISARMED or self.phase in ON_GROUND:
            sigma = self.height_uncertainty_m
            clearance += GROUND_HEIGHT_SIGMAS * sigma if math.isfinite(sigma) else math.inf
        return state.position_m[2] - GROUND_Z_M >= clearance

    def _near_ground(self, state: VehicleState) -> bool:
        return state.position_m[2] - GROUND_Z_M < IN_AIR_HEIGHT_M

    def drain_events(self) -> list[tuple[int, str]]:
        events, self.events = self.events, []
        return events

    def offboard_stream_active(self, t: float) -> bool:
        """A setpoint within the loss timeout COM_OF_LOSS_T (PX4's rule).

        Not "two setpoints": MAVSDK's ``set_position_ned(); start()`` sends one setpoint and then
        DO_SET_MODE at once, its 20 Hz stream starting on a timer thread that may come second; PX4
        accepts that, and the loss failsafe catches a stream that never follows.
        """
        window = self.params["COM_OF_LOSS_T"]
        return any(t - s <= window for s in self._setpoint_times)

    def last_or_measured(self, state: VehicleState) -> Reference:
        """Where a new plan starts: the reference flown so far (p_d, p_d', p_d'' stay continuous,
        so the cascade sees no step) unless the vehicle is far from it (after a failsafe, or when
        nothing was flown yet): then the measured state, at rest in acceleration."""
        ref = self.last_reference
        if ref is not None and self.armed and math.dist(ref.position_m, state.position_m) < CONTINUE_WITHIN_M:
            return ref
        return _at_rest(state)

    # -- the machine --------------------------------------------------------------------------------
    def _fire(self, t: float, event: Event, **args) -> Outcome:
        """Apply ``event`` through the table: run the row's action, then enter its phase and mode."""
        row = lookup(self.phase, event)
        if row is None:
            reason = REFUSALS.get(event, f"{event.value} refused while {self.phase.value}")
            return Outcome(ACCEPTED) if not reason else self._refuse(DENIED, reason)
        user = event in _COMMAND_NAV or event in (Event.MANUAL, Event.RC_OVERRIDE)
        if user and self.armed:
            problem = self._cannot_run(t, event, args.get("mode"))
            if problem:
                return self._refuse(DENIED, problem)
        if row.action is not None:
            outcome = getattr(self, f"_act_{row.action}")(t, **args)
            if outcome is not None and not outcome.accepted:
                return outcome
        if isinstance(row.to, Phase):
            self.phase = row.to
        self._fallback_due = True
        self._health_due = -math.inf  # the flags again at the next look (PX4: on a state change)
        mode = row.mode
        if mode is ASKED:
            mode = args.get("mode", FlightMode.AUTO_LOITER)
        elif mode is AFTER:
            mode = self._after_trajectory
        if isinstance(mode, FlightMode):
            self._set_mode(mode)
        if user:  # the pilot's or the ground station's choice ends a fallback (PX4)
            self._fallback = self._intended = None
            self.in_failsafe = False
        return Outcome(ACCEPTED)

    def _cannot_run(self, t: float, event: Event, mode: FlightMode | None) -> str:
        """Why the mode ``event`` asks for cannot run now ('' if it can): PX4 refuses the switch
        ("Switching to ... is currently not possible"). POSCTL is let in when ALTCTL can run and
        COM_POSCTL_NAVL is 0 (the fallback then flies ALTCTL until the position returns)."""
        flags = self.health_flags(t)
        if event in _COMMAND_NAV:
            nav = _COMMAND_NAV[event]
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
        name = mode.px4_name if mode is not None else _NAV_MODE_NAMES.get(nav, event.value)
        return f"Switching to {name} is currently not possible: {missing_for(flags, nav)}"

    def _set_mode(self, mode: FlightMode) -> None:
        if mode != self.mode:
            if self.mode == FlightMode.AUTO_MISSION and self.mission is not None:
                self.mission.pause()  # any other mode pauses the mission at its current item
            self.mode = mode
            self._fallback_due = True
            self._event(SEVERITY_INFO, f"mode {mode.px4_name}")

    def _event(self, severity: int, text: str) -> None:
        self.events.append((severity, text))

    def _refuse(self, result: int, reason: str) -> Outcome:
        self._event(SEVERITY_WARNING, reason)
        return Outcome(result, reason)

    def _on_param_change(self, name: str, value: float) -> None:
        self._fallback_due = True
        self.offboard.limits = self.limits()
        self._manual_limits = self.manual_limits()
        self._orbit_limits = self.orbit_limits()
        self._follow_settings = self.follow_settings()

    # -- commands ----------------------------------------------------------------------------------
    def update_state(self, state: VehicleState) -> None:
        self.state = state
        self.position_valid = True
        if self.home is None:  # until arming: below where the vehicle booted, on the ground
            self.home = (state.position_m[0], state.position_m[1], GROUND_Z_M)

    def arm(self, t: float, force: bool = False) -> Outcome:
        if self.armed:
            return Outcome(ACCEPTED, "already armed")
        outcome = self._fire(t, Event.ARM, force=force)
        if not outcome.accepted:
            return outcome
        # Armed in a selected mode that flies by itself: enter it (PX4).
        if self.mode == FlightMode.OFFBOARD:
            self._fire(t, Event.OFFBOARD, require_stream=False)  # the stream was a pre-arm check
        elif self.mode == FlightMode.AUTO_MISSION and self.mission is not None:
            # A completed mission does not fly again by itself (no surprise takeoff): select
            # AUTO.MISSION again or send MISSION_START.
            if self.mission.state == MissionState.COMPLETE:
                self._event(SEVERITY_NOTICE, "mission complete: select AUTO.MISSION to fly it again")
            elif not self._fire(t, Event.MISSION).accepted:
                self._set_mode(FlightMode.AUTO_LOITER)
        return Outcome(ACCEPTED)

    def disarm(self, t: float, force: bool = False) -> Outcome:
        if not self.armed:
            return Outcome(ACCEPTED, "already disarmed")
        return self._fire(t, Event.DISARM, force=force, why="disarmed")

    def takeoff(self, t: float, altitude_m: float | None = None) -> Outcome:
        """Climb to ``altitude_m`` above home (default MIS_TAKEOFF_ALT), then hold."""
        return self._fire(t, Event.TAKEOFF, altitude_m=altitude_m)

    def hold(self, t: float, reason: str = "") -> Outcome:
        outcome = self._fire(t, Event.HOLD)
        if reason:
            self._event(SEVERITY_WARNING, reason)
        return outcome

    def land(self, t: float) -> Outcome:
        return self._fire(t, Event.LAND)

    def return_to_launch(self, t: float) -> Outcome:
        return self._fire(t, Event.RTL)

    def set_mode(self, t: float, mode: FlightMode) -> Outcome:
        if mode == self.mode and mode != FlightMode.AUTO_MISSION:  # re-selecting it may (re)start
            return Outcome(ACCEPTED)
        event = _MODE_EVENTS.get(mode)
        if event is None:
            return self._refuse(UNSUPPORTED, f"mode {mode.px4_name} not supported")
        return self._fire(t, event, mode=mode)

    def start_scenario(self, t: float, trajectory: Trajectory, then: FlightMode | None = None) -> Outcome:
        """The paper's experiment: armed from ``t`` and flying ``trajectory`` from its t = 0; when it
        ends, hold in ``then`` (None: keep sampling its end)."""
        return self._fire(t, Event.SCENARIO, trajectory=trajectory, then=then)

    def reposition(
        self,
        t: float,
        target: Vector3,
        speed_m_s: float | None = None,
        yaw_rad: float | None = None,
        change_mode: bool = True,
    ) -> Outcome:
        """MAV_CMD_DO_REPOSITION: fly to ``target`` (paper frame, m) at ``speed_m_s`` (None: the
        default, at most MPC_XY_VEL_MAX) turning to ``yaw_rad`` (None: keep), then hold there. Without
        ``change_mode`` (param2 bit 0) it is only accepted while already holding (PX4)."""
        if not change_mode and not (self.phase == Phase.HOLD and self.mode == FlightMode.AUTO_LOITER):
            return self._refuse(
                DENIED, f"reposition refused: in {self.mode.px4_name}, not hold (param2 bit 0 switches)"
            )
        return self._fire(t, Event.REPOSITION, target=target, speed_m_s=speed_m_s, yaw_rad=yaw_rad)

    def orbit_command(self, t: float, request: OrbitRequest) -> Outcome:
        """MAV_CMD_DO_ORBIT (paper frame): enter Orbit (or change the orbit flown) with the request's
        radius, speed, yaw behaviour and centre (None: keep; entering, the defaults of
        :mod:`autopilot.guidance.orbit`)."""
        return self._fire(t, Event.ORBIT, request=request)

    def follow_target_report(self, report: TargetReport) -> None:
        """A FOLLOW_TARGET (checked at the edge): the target's estimate takes it in any mode, as
        PX4's target estimator runs whatever the mode."""
        self.follow.target.report(report, self._follow_settings.responsiveness)

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

    # -- missions ------------------------------------------------------------------------------------
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

    # -- failsafes -------------------------------------------------------------------------------------
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

    # -- health: what the vehicle knows of its sensors and estimates (health.py) ----------------------
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
        self._take_failsafe(t, action, f"{reason} for {_NAV_MODE_NAMES.get(nav, 'the mode')}")

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
        event = _MODE_EVENTS.get(intended)
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

    # -- the per-step decision ------------------------------------------------------------------------
    def step(self, t: float, dt: float) -> GuidanceOutput:
        """Decide this control step (``dt`` = control period, s)."""
        self._check_sticks(t)
        self.health_flags(t)
        state = self.state
        if self.phase == Phase.DISARMED:
            self._announce_readiness(t)
        if self.phase == Phase.DISARMED or state is None:
            return GuidanceOutput(Motors.OFF, None)
        if self._fallback_due and self.phase in FLYING:  # what it depends on changed
            self._check_mode_fallback(t)
        if self.phase in FLYING:
            self._check_failsafes(t, state)
        if self.phase == Phase.DISARMED:  # terminated
            return GuidanceOutput(Motors.OFF, None)
        # An internal event (offboard loss, a mission's LAND or RTL item) changes the phase; the
        # new phase then decides this same step. Two rounds always settle (no event leads back).
        for _ in range(3):
            out = self._decide(t, dt, state)
            if out is not None:
                return out
        raise RuntimeError(f"commander: phase {self.phase.name} did not settle at t={t:.3f} s")

    def _decide(self, t: float, dt: float, state: VehicleState) -> GuidanceOutput | None:
        """This step's output in the current phase, or None when an event changed the phase."""
        phase = self.phase
        p = self.params
        if phase == Phase.DISARMED:
            return GuidanceOutput(Motors.OFF, None)
        if phase == Phase.IDLE:
            if t - self._armed_at > p["COM_DISARM_PRFLT"] > 0.0:
                self._fire(t, Event.PREFLIGHT_TIMEOUT, force=True, why="disarmed: no takeoff after arming")
                return GuidanceOutput(Motors.OFF, None)
            if self._throttle_raised(t):
                self._fire(t, Event.STICK_TAKEOFF)
                return None
            return GuidanceOutput(Motors.IDLE, None)
        if phase == Phase.LANDED:
            if t - self._touchdown_at >= p["COM_DISARM_LAND"]:
                self._fire(t, Event.LANDED_TIMEOUT, force=True, why="landed: disarmed")
                return GuidanceOutput(Motors.OFF, None)
            if self._throttle_raised(t):
                self._fire(t, Event.STICK_TAKEOFF)
                return None
            return GuidanceOutput(Motors.IDLE, None)
        if phase == Phase.MANUAL:
            return self._manual_step(t, dt, state)
        if phase == Phase.DESCEND:
            if self._touched_down(t, state):
                self._fire(t, Event.TOUCHDOWN)
                return GuidanceOutput(Motors.IDLE, None)
            previous = self.last_reference or _at_rest(state)
            altitude_valid = not self.flags.local_altitude_invalid
            setpoint = self.manual.descend(dt, previous, state, p["MPC_LAND_SPEED"], altitude_valid,
                                           self._manual_limits)  # fmt: skip
            self.last_reference = setpoint.reference
            return GuidanceOutput(Motors.FLY, setpoint.reference, setpoint)

        if phase == Phase.OFFBOARD:
            if not self.offboard_stream_active(t) and self.offboard.setpoint is not None:
                last = self._setpoint_times[-1] if self._setpoint_times else -math.inf
                if t - last > p["COM_OF_LOSS_T"]:
                    self._fire(t, Event.OFFBOARD_LOST)
                    self._event(SEVERITY_WARNING, "offboard setpoints lost: switching to hold")
                    return None
            if self.offboard.flies_attitude:  # attitude or body rates: past the position law
                setpoint = self.offboard.attitude_step(dt, state, self._manual_limits)
                self.last_reference = setpoint.reference
                lifts = (setpoint.thrust or 0.0) >= self._manual_limits.thrust_hover
                if self._near_ground(state) and not lifts:  # idle on the ground (no integrator wind-up)
                    return GuidanceOutput(Motors.IDLE, setpoint.reference)
                return GuidanceOutput(Motors.FLY, setpoint.reference, setpoint)
            previous = self.last_reference or _at_rest(state)
            reference = self.offboard.reference(t, dt, previous)
            if self.offboard.setpoint is None:
                reference = previous
        elif phase == Phase.ORBIT:
            previous = self.last_reference or _at_rest(state)
            sticks = self.sticks.fresh(t, self._manual_limits.loss_s)
            yaw_stick = sticks.yaw * self._manual_limits.yaw_rate if sticks is not None else 0.0
            reference = self.orbit.reference(t, dt, state.position_m, previous, self._orbit_limits, yaw_stick)
        elif phase == Phase.FOLLOW:
            previous = self.last_reference or _at_rest(state)
            home = self.home or (0.0, 0.0, GROUND_Z_M)
            reference = self.follow.reference(t, dt, state.position_m, previous, home, self._follow_settings)
            if self.follow.lost != self._follow_lost_said:
                self._follow_lost_said = self.follow.lost
                self._event(SEVERITY_WARNING if self.follow.lost else SEVERITY_INFO,
                            "follow-me: no target (no FOLLOW_TARGET for 3 s): holding position"
                            if self.follow.lost else "follow-me: target found, following")  # fmt: skip
        elif phase == Phase.MISSION:
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
            reference = out.reference
        else:
            assert self._trajectory is not None
            local = t - self._trajectory_start
            reference = self._trajectory.sample(local)
            if phase in DESCENDING:
                if self._touched_down(t, state):
                    self._fire(t, Event.TOUCHDOWN)
                    return GuidanceOutput(Motors.IDLE, None)
            elif (
                local >= self._trajectory.duration_s
                and lookup(phase, Event.PLAN_DONE) is not None  # holding: nothing ends
                and (phase != Phase.TRAJECTORY or self._after_trajectory is not None)
            ):
                self._fire(t, Event.PLAN_DONE)  # this step still flies the sample just taken
        self.last_reference = reference
        if (
            phase in _LIFTING_PHASES
            and self._near_ground(state)
            and reference.position_m[2] - GROUND_Z_M < 0.02
        ):
            # Waiting for the reference to lift off: do not fight the ground (integrators).
            return GuidanceOutput(Motors.IDLE, reference)
        return GuidanceOutput(Motors.FLY, reference)

    def _throttle_raised(self, t: float) -> bool:
        """On the ground in a manual mode: fresh sticks with the throttle above 62.5 % (PX4)."""
        if not self.mode.is_manual:
            return False
        sticks = self.sticks.fresh(t, self._manual_limits.loss_s)
        return sticks is not None and sticks.up > STICK_TAKEOFF_UP

    def _manual_step(self, t: float, dt: float, state: VehicleState) -> GuidanceOutput:
        """A manual mode's control step; touchdown with the throttle at or below centre lands."""
        limits = self._manual_limits
        sticks = self.sticks.fresh(t, limits.loss_s)  # (None only until NAV_RCL_ACT has acted)
        if sticks is None or sticks.up <= limits.deadzone:
            if self._touched_down(t, state):
                self._fire(t, Event.TOUCHDOWN)
                return GuidanceOutput(Motors.IDLE, None)
        else:
            self._landed_since = None
        if self.mode == FlightMode.POSCTL and not self.manual.engage_if_moved(sticks, limits):
            assert self._trajectory is not None  # POSCTL holds (the stop plan) until a stick moves
            reference = self._trajectory.sample(t - self._trajectory_start)
            self.last_reference = reference
            return GuidanceOutput(Motors.FLY, reference)
        previous = self.last_reference or _at_rest(state)
        setpoint = _MANUAL_STEPS[self.mode](self.manual, dt, previous, state, sticks, limits)
        self.last_reference = setpoint.reference
        return GuidanceOutput(Motors.FLY, setpoint.reference, setpoint if setpoint.overrides else None)

    def _touched_down(self, t: float, state: VehicleState) -> bool:
        resting = (
            state.position_m[2] - GROUND_Z_M < ON_GROUND_HEIGHT_M
            and abs(state.velocity_m_s[2]) < LANDED_SPEED_M_S
        )
        if not resting:
            self._landed_since = None
            return False
        if self._landed_since is None:
            self._landed_since = t
        return t - self._landed_since >= LANDED_CONFIRM_S

    # -- actions (the table's last column); None or an accepted Outcome lets the transition happen --
    def arm_problem(self, t: float) -> str | None:
        """Why arming would be refused at ``t`` (the pre-arm checks, in order), or None: ready to
        arm. The one verdict: the arming command, the armable bit of SYS_STATUS and the
        "Preflight Fail" announcements all read it."""
        state = self.state
        if state is None or not self.position_valid:
            why = self.estimator_problem or "no sensor frames from the simulator"
            return f"no position ({why})"
        if self.estimator_problem:  # before "not landed": that judges the estimate
            return self.estimator_problem
        if self.in_air():
            return "vehicle not landed"
        speed = math.hypot(*state.velocity_m_s)
        if speed > MOVING_SPEED_M_S:
            return f"vehicle not landed (moving at {speed:.2f} m/s)"
        if self.mode == FlightMode.OFFBOARD and not self.offboard_stream_active(t):
            return "OFFBOARD without a setpoint stream"
        if self.mode.is_manual and self.sticks.fresh(t, self._manual_limits.loss_s) is None:
            return f"no manual control input ({self.mode.px4_name} flies on MANUAL_CONTROL)"
        if NAV_STATE_OF_MODE[self.mode] in _NOT_ARMED_IN:
            return f"mode {self.mode.px4_name} prevents arming (select a mode that takes off)"
        return prearm_problem(
            self.params, state.position_m, self.home, self.position_valid, self.failsafes.geofence,
            self.health_flags(t), NAV_STATE_OF_MODE[self.mode],
        ) or self.battery.prearm_problem()

    def _announce_readiness(self, t: float) -> None:
        """While disarmed: a change of the pre-arm verdict as PX4 reports it, ``Preflight Fail:
        <reason>`` (and ``ready to arm`` once a failure was announced), so a ground station sees
        why the vehicle is not armable before it tries. A verdict whose figures alone changed (an
        alignment's elapsed time, a 1-sigma) is the same verdict; none is repeated within
        :data:`READINESS_REPEAT_S`."""
        if t < self._next_readiness_check:
            return
        self._next_readiness_check = t + READINESS_CHECK_S
        problem = self.arm_problem(t)
        key = None if problem is None else _FIGURES.sub("#", problem)
        if key == self._readiness_key:
            return
        last = self._readiness_said.get(key)
        if last is not None and t - last < READINESS_REPEAT_S:
            return
        self._readiness_key = key
        self._readiness_said[key] = t
        if problem is None:
            self._event(SEVERITY_INFO, "ready to arm")
        else:
            self._event(SEVERITY_WARNING, f"{PREFLIGHT_FAIL}{problem}")

    def _act_arm(self, t: float, force: bool = False, **_) -> Outcome | None:
        state = self.state
        if state is None or not self.position_valid:
            # Not even a forced arm: without a state there is nothing to control.
            return self._refuse(DENIED, f"arming refused: {self.arm_problem(t)}")
        if not force:  # the pre-arm checks (a forced arm skips them, as in PX4)
            problem = self.arm_problem(t)
            if problem:
                return self._refuse(DENIED, f"arming refused: {problem}")
        self._readiness_key = None  # after this flight, the first failure is announced again
        self._armed_at = t
        self.home = state.position_m  # PX4 sets home where it arms
        self._fallback = self._intended = None
        self.in_failsafe = self.terminated = False
        self._landed_since = None
        self._trajectory = None
        self._event(SEVERITY_INFO, "armed")
        return None

    def _act_disarm(self, t: float, force: bool = False, why: str = "disarmed", **_) -> Outcome | None:
        if not force and self.in_air() and self.phase != Phase.LANDED:
            return self._refuse(DENIED, "disarm refused: vehicle in air (force to override)")
        if self.mission is not None:
            self.mission.pause()
        self._trajectory = None
        self._event(SEVERITY_INFO, why)
        return None

    def _act_descend(self, t: float, **_) -> None:
        """PX4's Descend (guidance/manual.py descend): from the reference flown so far."""
        assert self.state is not None
        self.last_reference = self.last_or_measured(self.state)
        self._trajectory = None
        self._landed_since = None
        self._event(SEVERITY_INFO, "descending")

    def _act_terminate(self, t: float, **_) -> None:
        """Flight termination (PX4's last failsafe): motors off at once, disarmed."""
        if self.mission is not None:
            self.mission.pause()
        self._trajectory = None
        self._fallback = self._intended = None
        self.terminated = True
        self._event(SEVERITY_EMERGENCY, "flight terminated: motors off")

    def _act_start_scenario(self, t: float, trajectory: Trajectory, then: FlightMode | None, **_) -> None:
        self._armed_at = t
        if self.state is not None:
            self.home = (self.state.position_m[0], self.state.position_m[1], GROUND_Z_M)
        self._event(SEVERITY_INFO, "armed for the scenario")
        self._fly(t, trajectory)
        self._after_trajectory = then

    def _act_plan_takeoff(self, t: float, altitude_m: float | None = None, **_) -> Outcome | None:
        state = self.state
        assert state is not None and self.home is not None
        altitude = self.params["MIS_TAKEOFF_ALT"] if altitude_m is None else altitude_m
        if not 0.2 <= altitude <= 1000.0:
            return self._refuse(DENIED, f"takeoff refused: altitude {altitude:.2f} m out of range")
        target = (state.position_m[0], state.position_m[1], self.home[2] + altitude)
        climb = replace(self.limits(), speed_up=self.params["MPC_TKO_SPEED"])
        yaw = state.euler_rad[2]
        self._fly(t, LineMove(self.last_or_measured(state).position_m, target, climb, yaw, yaw))
        self._event(SEVERITY_INFO, f"takeoff to {altitude:.2f} m")
        return None

    def _act_plan_hold(self, t: float, **_) -> None:
        assert self.state is not None
        self._fly(t, stop_from(self.last_or_measured(self.state), self.limits()))

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

    def _act_stick_takeoff(self, t: float, **_) -> None:
        """The throttle raised on the ground: the manual mode flies from the vehicle at rest."""
        state = self.state
        assert state is not None
        self.manual.enter(state)
        self.last_reference = _at_rest(state)
        self._fly(t, stop_from(self.last_reference, self.limits()))
        self._landed_since = None
        self._event(SEVERITY_INFO, f"taking off on the sticks in {self.mode.px4_name}")

    def _act_plan_reposition(
        self, t: float, target: Vector3, speed_m_s: float | None, yaw_rad: float | None, **_
    ) -> None:
        assert self.state is not None
        limits = self.limits()
        if speed_m_s is not None:
            limits = replace(limits, speed_horizontal=min(limits.speed_horizontal, speed_m_s))
        start = self.last_or_measured(self.state)
        brake = stop_from(start, limits)
        p = brake.sample(brake.duration_s).position_m
        yaw0 = start.yaw_rad
        yaw1 = yaw0 if yaw_rad is None else yaw_rad
        self._fly(t, PiecewiseTrajectory([brake, LineMove(p, target, limits, yaw0, yaw1)]))
        distance = math.dist(p, target)
        self._event(SEVERITY_INFO, f"repositioning {distance:.1f} m at {limits.speed_horizontal:.1f} m/s")

    def _act_plan_climb_reposition(
        self, t: float, target: Vector3, speed_m_s: float | None, yaw_rad: float | None, **_
    ) -> Outcome | None:
        """Armed on the ground (PX4): climb straight up to the target's altitude (MIS_TAKEOFF_ALT
        above home if the target keeps the ground's) at MPC_TKO_SPEED, then fly there and hold."""
        state = self.state
        assert state is not None and self.home is not None
        altitude = target[2] - self.home[2]
        if altitude < 0.2:  # "keep the altitude" on the ground: the takeoff altitude
            altitude = self.params["MIS_TAKEOFF_ALT"]
        if altitude > 1000.0:
            return self._refuse(DENIED, f"reposition refused: altitude {altitude:.2f} m out of range")
        target = (target[0], target[1], self.home[2] + altitude)
        climb = replace(self.limits(), speed_up=self.params["MPC_TKO_SPEED"])
        across = self.limits()
        if speed_m_s is not None:
            across = replace(across, speed_horizontal=min(across.speed_horizontal, speed_m_s))
        here = _at_rest(state).position_m
        top = (here[0], here[1], target[2])
        yaw0 = state.euler_rad[2]
        yaw1 = yaw0 if yaw_rad is None else yaw_rad
        self._fly(t, PiecewiseTrajectory([LineMove(here, top, climb, yaw0, yaw0),
                                          LineMove(top, target, across, yaw0, yaw1)]))  # fmt: skip
        self._event(SEVERITY_INFO, f"taking off to {altitude:.2f} m, then repositioning "
                                   f"{math.dist(top, target):.1f} m")  # fmt: skip
        return None

    def _act_plan_landing(self, t: float, **_) -> None:
        """Brake, then aim far below the ground: the descent goes on at the landing speed until
        touchdown is detected."""
        assert self.state is not None
        limits = self.limits()
        descend = replace(limits, speed_down=self.params["MPC_LAND_SPEED"])
        start = self.last_or_measured(self.state)
        brake = stop_from(start, limits)
        end = brake.sample(brake.duration_s).position_m
        yaw = start.yaw_rad
        down = LineMove(end, (end[0], end[1], end[2] - 1000.0), descend, yaw, yaw)
        self._fly(t, PiecewiseTrajectory([brake, down]))
        self._landed_since = None
        self._event(SEVERITY_INFO, "landing")

    def _act_plan_return(self, t: float, **_) -> None:
        """Climb to the return altitude, fly above the destination RTL_TYPE picks (:mod:`.rtl`),
        then (PLAN_DONE) land there."""
        state, home = self.state, self.home
        assert state is not None and home is not None
        limits = self.limits()
        start = self.last_or_measured(state)
        yaw = start.yaw_rad
        brake = stop_from(start, limits)
        p = brake.sample(brake.duration_s).position_m
        rtl_type = int(self.params["RTL_TYPE"])
        destination = return_destination(rtl_type, p, home, self.rally_points)
        if destination.name == "here":  # RTL_TYPE 5 without a rally point: PX4 lands where it is
            self._fly(t, brake)
            self._event(SEVERITY_WARNING, "no rally point to return to (RTL_TYPE 5): landing here")
            return
        altitude = return_altitude(state.position_m[2], destination, self.params["RTL_RETURN_ALT"])
        climb_to = (p[0], p[1], altitude)
        above = (destination.position_m[0], destination.position_m[1], altitude)
        pieces = [
            brake,
            LineMove(p, climb_to, limits, yaw, yaw),
            LineMove(climb_to, above, limits, yaw, yaw),
        ]
        self._fly(t, PiecewiseTrajectory(pieces))
        self._event(SEVERITY_INFO, f"returning to {destination.name} at {altitude - home[2]:.1f} m")

    def _act_touchdown(self, t: float, **_) -> None:
        self._touchdown_at = t
        if self.mission is not None:
            self.mission.landed()  # reaches a mission's LAND item (no-op otherwise)
        self._event(SEVERITY_INFO, "landing detected")

    def _act_enter_offboard(self, t: float, require_stream: bool = True, **_) -> Outcome | None:
        if require_stream and not self.offboard_stream_active(t):
            return self._refuse(DENIED, "OFFBOARD refused: no setpoint stream (send setpoints first)")
        self.offboard.reset()
        return None

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
        reason = mission.start(t, _at_rest(state), context, on_ground)
        if reason is not None:
            return self._refuse(DENIED, f"AUTO.MISSION refused: {reason}")
        self._trajectory = None
        self._landed_since = None
        self._event(SEVERITY_INFO, f"mission: flying item {mission.current_seq} of {mission.count}")
        return None

    def _act_start_orbit(self, t: float, request: OrbitRequest | None = None, **_) -> Outcome | None:
        """Enter Orbit (centre here, PX4's defaults) unless flying it, then apply the DO_ORBIT's
        parameters; a radius PX4 refuses is refused here before anything changes."""
        state = self.state
        assert state is not None
        limits = self._orbit_limits
        orbit = self.orbit
        refusal = radius_refusal(request, limits) if request is not None else None
        if refusal is not None:
            return self._refuse(DENIED, refusal)
        yaw = state.euler_rad[2]
        if self.phase != Phase.ORBIT:
            self.last_reference = self.last_or_measured(state)
            orbit.enter(state.position_m, yaw, limits)
        if request is not None:
            orbit.apply(request, yaw, limits)
        asked = None if request is None or request.speed_m_s is None else abs(request.speed_m_s)
        speed = abs(orbit.velocity_m_s)
        clipped = f" (asked {asked:g} m/s: limited)" if asked is not None and asked > speed + 1e-6 else ""
        way = "clockwise" if orbit.velocity_m_s > 0.0 else "counter-clockwise"
        yaw_name = YAW_NAMES.get(orbit.yaw_behaviour, YAW_NAMES[0])
        self._event(SEVERITY_INFO, f"orbit: radius {orbit.radius_m:.1f} m {way} at {speed:.1f} m/s{clipped}, "
                                   f"yaw {yaw_name}")  # fmt: skip
        return None

    def _act_start_follow(self, t: float, **_) -> None:
        state = self.state
        assert state is not None
        self.last_reference = self.last_or_measured(state)
        self.follow.enter(state.euler_rad[2])
        none_yet = self.follow.target.estimate(t) is None
        self._follow_lost_said = none_yet  # (said now; the next change of the target's state is said)
        self._event(SEVERITY_INFO, "follow-me: following the target (FOLLOW_TARGET)"
                                   + (": none yet, holding position" if none_yet else ""))  # fmt: skip

    def _fly(self, t: float, trajectory: Trajectory) -> None:
        self._trajectory = trajectory
        self._trajectory_start = t


def _at_rest(state: VehicleState) -> Reference:
    """A reference at the measured state, at rest in acceleration."""
    return Reference(state.position_m, state.velocity_m_s, ZERO3, state.euler_rad[2], 0.0, 0.0)
