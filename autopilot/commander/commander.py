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

Every change of phase or mode goes through the one table in :mod:`.transitions`
(:meth:`Commander._fire`, here); the commander decides which event happened and carries out the
row's action (the plans and the guards). One state, several modules, each a part of
:class:`Commander` that reads and changes that state: this module holds the state, the machine
(``_fire``), the commands and the per-step decision; :mod:`.arming` the pre-arm checks and
arming; :mod:`.mode_requests` what each mode needs to be entered; :mod:`.reactions` the failsafe
flags, the mode fallback and the failsafes; :mod:`.plans` the trajectories of the table's
actions; :mod:`.orbit_follow` Orbit and follow-me; :mod:`.mission_control` the mission, the
geofence and the rally points. The records they share are in :mod:`.records`.
"""

from __future__ import annotations

import math

from quadcommon.trajectories import Reference, Trajectory

from ..estimation.status import EstimatorStatus
from ..guidance.follow import FollowTarget
from ..guidance.manual import ManualGuidance, ManualLimits
from ..guidance.offboard import OffboardGuidance
from ..guidance.orbit import Orbit
from ..guidance.planner import Limits
from ..guidance.sticks import StickStream
from ..mission.executor import MissionExecutor
from ..mission.plans import RallyPoint
from ..params.store import ParameterStore
from .arming import Arming
from .failsafe import BatteryWatch, FailsafeMonitor
from .health import FailsafeFlags, HealthMonitor
from .mission_control import MissionControl
from .mode_requests import COMMAND_NAV, ModeRequests
from .modes import FlightMode, LandedState
from .orbit_follow import OrbitFollow
from .plans import Plans
from .reactions import FailsafeReactions
from .records import (
    ACCEPTED,
    DENIED,
    GROUND_Z_M,
    SEVERITY_INFO,
    SEVERITY_WARNING,
    GuidanceOutput,
    Motors,
    Outcome,
    Vector3,
    VehicleState,
    at_rest,
)
from .transitions import (
    AFTER,
    ASKED,
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

CONTINUE_WITHIN_M = 0.5  # a new plan continues the reference if the vehicle is this close to it
ON_GROUND_HEIGHT_M = 0.05  # O within this of the ground counts as touching it
LANDED_SPEED_M_S = 0.1
LANDED_CONFIRM_S = 0.3
IN_AIR_HEIGHT_M = 0.1
# On the ground, a height within this many standard deviations of the estimate's height (its
# 1-sigma, 0 on the truth) above IN_AIR_HEIGHT_M is the ground (see Commander.in_air).
GROUND_HEIGHT_SIGMAS = 3.0
STICK_TAKEOFF_UP = 0.25  # throttle stick above 62.5 % of its travel takes off a manual mode (PX4)
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


class Commander(Arming, ModeRequests, FailsafeReactions, Plans, OrbitFollow, MissionControl):
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
        """Any phase but DISARMED."""
        return self.phase != Phase.DISARMED

    @property
    def landed_state(self) -> LandedState:
        """MAV_LANDED_STATE as PX4's land detector reports it: TAKEOFF while taking off, LANDING
        while descending to a touchdown not yet confirmed, else on the ground or in the air
        (:meth:`in_air`)."""
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
        """The planner's limits of the AUTO modes from the parameters (MPC_XY_VEL_MAX, MPC_Z_VEL_MAX_UP
        and _DN, MPC_ACC_HOR, MPC_YAWRAUTO_MAX)."""
        p = self.params
        return Limits(
            speed_horizontal=p["MPC_XY_VEL_MAX"],
            speed_up=p["MPC_Z_VEL_MAX_UP"],
            speed_down=p["MPC_Z_VEL_MAX_DN"],
            acceleration=p["MPC_ACC_HOR"],
            yaw_rate=p["MPC_YAWRAUTO_MAX"],
        )

    def manual_limits(self) -> ManualLimits:
        """The manual modes' limits from the parameters (MPC_*, MC_ACRO_*, COM_RC_LOSS_T,
        COM_RC_STICK_OV; angles in rad)."""
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
        """The queued events, (MAV_SEVERITY, text) in order, removed from the queue."""
        events, self.events = self.events, []
        return events

    def last_or_measured(self, state: VehicleState) -> Reference:
        """Where a new plan starts: the reference flown so far (p_d, p_d', p_d'' stay continuous,
        so the cascade sees no step) unless the vehicle is far from it (after a failsafe, or when
        nothing was flown yet): then the measured state, at rest in acceleration."""
        ref = self.last_reference
        if ref is not None and self.armed and math.dist(ref.position_m, state.position_m) < CONTINUE_WITHIN_M:
            return ref
        return at_rest(state)

    # -- the machine --------------------------------------------------------------------------------
    def _fire(self, t: float, event: Event, **args) -> Outcome:
        """Apply ``event`` through the table: run the row's action, then enter its phase and mode."""
        row = lookup(self.phase, event)
        if row is None:
            reason = REFUSALS.get(event, f"{event.value} refused while {self.phase.value}")
            return Outcome(ACCEPTED) if not reason else self._refuse(DENIED, reason)
        user = event in COMMAND_NAV or event in (Event.MANUAL, Event.RC_OVERRIDE)
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
        """This control step's state (truth or estimate); home, until arming, below where the
        vehicle first is, on the ground."""
        self.state = state
        self.position_valid = True
        if self.home is None:  # until arming: below where the vehicle booted, on the ground
            self.home = (state.position_m[0], state.position_m[1], GROUND_Z_M)

    def takeoff(self, t: float, altitude_m: float | None = None) -> Outcome:
        """Climb to ``altitude_m`` above home (default MIS_TAKEOFF_ALT), then hold."""
        return self._fire(t, Event.TAKEOFF, altitude_m=altitude_m)

    def hold(self, t: float, reason: str = "") -> Outcome:
        """AUTO.LOITER: brake and hold where the reference stops (``reason``: announced with it)."""
        outcome = self._fire(t, Event.HOLD)
        if reason:
            self._event(SEVERITY_WARNING, reason)
        return outcome

    def land(self, t: float) -> Outcome:
        """AUTO.LAND: brake, then descend at MPC_LAND_SPEED to touchdown."""
        return self._fire(t, Event.LAND)

    def return_to_launch(self, t: float) -> Outcome:
        """AUTO.RTL: return to home or a rally point (RTL_TYPE) and land there."""
        return self._fire(t, Event.RTL)

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
            previous = self.last_reference or at_rest(state)
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
            previous = self.last_reference or at_rest(state)
            reference = self.offboard.reference(t, dt, previous)
            if self.offboard.setpoint is None:
                reference = previous
        elif phase == Phase.ORBIT:
            reference = self._orbit_reference(t, dt, state)
        elif phase == Phase.FOLLOW:
            reference = self._follow_reference(t, dt, state)
        elif phase == Phase.MISSION:
            reference = self._mission_reference(t, state)
            if reference is None:  # the mission's LAND or RTL item changed the phase
                return None
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
        previous = self.last_reference or at_rest(state)
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
