"""The commander: arming, flight modes, and what the vehicle should do next (the navigator).

Pure: no sockets, no clocks. Every method takes the simulation time ``t`` (s) and the latest
:class:`VehicleState`; :meth:`Commander.step` returns, once per control step, whether the motors
are off, idling on the ground, or flying, and the reference (p_d, p_d', p_d'', yaw) to fly. Events
worth telling a ground station (mode changes, failsafes, refusals with their reason) are queued
as ``(severity, text)`` for the MAVLink shell to send as STATUSTEXT.

Behaviour follows PX4 where PX4 users would expect it: arming only on the ground; takeoff climbs to
``MIS_TAKEOFF_ALT`` (or the commanded altitude) then holds (AUTO.LOITER); land descends at
``MPC_LAND_SPEED``, detects touchdown and disarms after ``COM_DISARM_LAND``; RTL climbs to
``RTL_RETURN_ALT``, returns above home and lands; OFFBOARD needs a setpoint stream before it is
entered and falls back to hold when setpoints stop for ``COM_OF_LOSS_T`` (simulation time); an
armed vehicle that does not take off within ``COM_DISARM_PRFLT`` disarms itself.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import Enum
from typing import NamedTuple

from ..guidance.offboard import OffboardGuidance, OffboardSetpoint
from ..guidance.planner import Limits, LineMove, stop_from
from ..guidance.trajectories import PiecewiseTrajectory, Reference, Trajectory
from ..mission.executor import MissionAction, MissionExecutor, MissionState, PlanContext, check_mission
from ..params.store import ParameterStore
from .failsafe import HOLD, LAND, RTL, WARN, FailsafeMonitor, prearm_problem
from .modes import FlightMode, LandedState

Vector3 = tuple[float, float, float]
ZERO3: Vector3 = (0.0, 0.0, 0.0)

# MAV_RESULT
ACCEPTED, TEMPORARILY_REJECTED, DENIED, UNSUPPORTED, FAILED = 0, 1, 2, 3, 4
# MAV_SEVERITY
SEVERITY_CRITICAL, SEVERITY_WARNING, SEVERITY_NOTICE, SEVERITY_INFO = 2, 4, 5, 6

CONTINUE_WITHIN_M = 0.5  # a new plan continues the reference if the vehicle is this close to it
GROUND_Z_M = 0.0  # the local frame's origin (the configured home) is on flat ground
ON_GROUND_HEIGHT_M = 0.05  # O within this of the ground counts as touching it
LANDED_SPEED_M_S = 0.1
LANDED_CONFIRM_S = 0.3
IN_AIR_HEIGHT_M = 0.1


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


class Outcome(NamedTuple):
    result: int  # MAV_RESULT
    reason: str = ""

    @property
    def accepted(self) -> bool:
        return self.result == ACCEPTED


class Phase(Enum):
    IDLE = "idle"  # armed, on the ground, waiting
    TAKEOFF = "takeoff"
    HOLD = "hold"
    OFFBOARD = "offboard"
    LAND = "land"
    LANDED = "landed"  # touched down, waiting to disarm
    RTL = "rtl"
    TRAJECTORY = "trajectory"  # a trajectory installed by a scenario
    MISSION = "mission"  # flying the stored mission (AUTO.MISSION)


class Commander:
    def __init__(self, params: ParameterStore) -> None:
        self.params = params
        self.armed = False
        self.mode = FlightMode.AUTO_LOITER
        self.phase = Phase.IDLE
        self.home: Vector3 | None = None
        self.state: VehicleState | None = None
        self.events: list[tuple[int, str]] = []
        self.offboard = OffboardGuidance(self.limits())
        self.last_reference: Reference | None = None
        self._trajectory: Trajectory | None = None
        self._trajectory_start = 0.0
        self._armed_at = 0.0
        self._landed_since: float | None = None
        self._touchdown_at = 0.0
        self._setpoint_times: list[float] = []
        self._rtl_landing = False
        self._after_trajectory: FlightMode | None = None
        self.mission: MissionExecutor | None = None  # the stored mission (set by the MAVLink shell)
        self.failsafes = FailsafeMonitor(params)
        self.position_valid = False  # sensor frames flowing (False until the first, and when lost)
        params.on_change(self._on_param_change)

    # -- helpers -----------------------------------------------------------------------------------
    def limits(self) -> Limits:
        p = self.params
        return Limits(
            speed_horizontal=p["MPC_XY_VEL_MAX"],
            speed_up=p["MPC_Z_VEL_MAX_UP"],
            speed_down=p["MPC_Z_VEL_MAX_DN"],
            acceleration=p["MPC_ACC_HOR"],
            yaw_rate=p["MPC_YAWRAUTO_MAX"],
        )

    def _on_param_change(self, name: str, value: float) -> None:
        self.offboard.limits = self.limits()

    def _event(self, severity: int, text: str) -> None:
        self.events.append((severity, text))

    def drain_events(self) -> list[tuple[int, str]]:
        events, self.events = self.events, []
        return events

    def _set_mode(self, mode: FlightMode) -> None:
        if mode != self.mode:
            if self.mode == FlightMode.AUTO_MISSION and self.mission is not None:
                self.mission.pause()  # any other mode pauses the mission at its current item
            self.mode = mode
            self._event(SEVERITY_INFO, f"mode {mode.px4_name}")

    def _near_ground(self, state: VehicleState) -> bool:
        return state.position_m[2] - GROUND_Z_M < IN_AIR_HEIGHT_M

    def in_air(self) -> bool:
        return self.state is not None and not self._near_ground(self.state)

    @property
    def landed_state(self) -> LandedState:
        if self.armed and self.phase == Phase.TAKEOFF:
            return LandedState.TAKEOFF
        if self.armed and self.phase == Phase.LAND or self._rtl_landing:
            # LANDING until touchdown is confirmed (phase LANDED), as PX4's land detector: scripts
            # wait for "not in air" and then disarm, which must not happen a few cm up.
            return LandedState.LANDING
        if self.state is None or not self.in_air():
            return LandedState.ON_GROUND
        return LandedState.IN_AIR

    def _fly(self, t: float, trajectory: Trajectory, phase: Phase) -> None:
        self._trajectory = trajectory
        self._trajectory_start = t
        self.phase = phase

    def _start_reference(self, state: VehicleState) -> Reference:
        return Reference(state.position_m, state.velocity_m_s, ZERO3, state.euler_rad[2], 0.0, 0.0)

    # -- inputs ------------------------------------------------------------------------------------
    def update_state(self, state: VehicleState) -> None:
        self.state = state
        self.position_valid = True
        if self.home is None:  # until arming: below where the vehicle booted, on the ground
            self.home = (state.position_m[0], state.position_m[1], GROUND_Z_M)

    def arm(self, t: float, force: bool = False) -> Outcome:
        if self.armed:
            return Outcome(ACCEPTED, "already armed")
        state = self.state
        if state is None or not self.position_valid:
            # Not even a forced arm: without a state there is nothing to control.
            return self._refuse(DENIED, "arming refused: no position (no sensor frames from the simulator)")
        if not force:  # the pre-arm checks (a forced arm skips them, as in PX4)
            if self.in_air() or math.hypot(*state.velocity_m_s) > 0.2:
                return self._refuse(DENIED, "arming refused: vehicle not landed")
            if self.mode == FlightMode.OFFBOARD and not self.offboard_stream_active(t):
                return self._refuse(DENIED, "arming refused: OFFBOARD without a setpoint stream")
            problem = prearm_problem(self.params, state.position_m, self.home, self.position_valid)
            if problem:
                return self._refuse(DENIED, f"arming refused: {problem}")
        self.armed = True
        self._armed_at = t
        self.home = state.position_m  # PX4 sets home where it arms
        self._landed_since = None
        self._rtl_landing = False
        self.phase = Phase.IDLE
        self._event(SEVERITY_INFO, "armed")
        if self.mode == FlightMode.OFFBOARD:
            self.offboard.reset()
            self.phase = Phase.OFFBOARD
        elif self.mode == FlightMode.AUTO_MISSION and self.mission is not None:
            # Armed in AUTO.MISSION: fly it (PX4). A completed mission does not fly again by
            # itself (no surprise takeoff): select AUTO.MISSION again or send MISSION_START.
            if self.mission.state == MissionState.COMPLETE:
                self._event(SEVERITY_NOTICE, "mission complete: select AUTO.MISSION to fly it again")
            elif not self._start_mission(t).accepted:
                self._set_mode(FlightMode.AUTO_LOITER)
        return Outcome(ACCEPTED)

    def disarm(self, t: float, force: bool = False) -> Outcome:
        if not self.armed:
            return Outcome(ACCEPTED, "already disarmed")
        if not force and self.in_air() and self.phase != Phase.LANDED:
            return self._refuse(DENIED, "disarm refused: vehicle in air (force to override)")
        self._disarm("disarmed")
        return Outcome(ACCEPTED)

    def _disarm(self, why: str) -> None:
        if self.mission is not None:
            self.mission.pause()
        self.armed = False
        self.phase = Phase.IDLE
        self._trajectory = None
        self._rtl_landing = False
        self._event(SEVERITY_INFO, why)

    def _refuse(self, result: int, reason: str) -> Outcome:
        self._event(SEVERITY_WARNING, reason)
        return Outcome(result, reason)

    def takeoff(self, t: float, altitude_m: float | None = None) -> Outcome:
        """Climb to ``altitude_m`` above home (default MIS_TAKEOFF_ALT), then hold."""
        if not self.armed:
            return self._refuse(DENIED, "takeoff refused: arm first")
        state = self.state
        assert state is not None and self.home is not None
        altitude = self.params["MIS_TAKEOFF_ALT"] if altitude_m is None else altitude_m
        if not 0.2 <= altitude <= 1000.0:
            return self._refuse(DENIED, f"takeoff refused: altitude {altitude:.2f} m out of range")
        target = (state.position_m[0], state.position_m[1], self.home[2] + altitude)
        limits = self.limits()
        climb = Limits(
            limits.speed_horizontal,
            self.params["MPC_TKO_SPEED"],
            limits.speed_down,
            limits.acceleration,
            limits.yaw_rate,
        )
        yaw = state.euler_rad[2]
        self._fly(
            t, LineMove(self.last_or_measured(state).position_m, target, climb, yaw, yaw), Phase.TAKEOFF
        )
        self._set_mode(FlightMode.AUTO_TAKEOFF)
        self._event(SEVERITY_INFO, f"takeoff to {altitude:.2f} m")
        return Outcome(ACCEPTED)

    def last_or_measured(self, state: VehicleState) -> Reference:
        """Where a new plan starts: the reference flown so far (p_d, p_d', p_d'' stay continuous,
        so the cascade sees no step) unless the vehicle is far from it (after a failsafe, or when
        nothing was flown yet): then the measured state, at rest in acceleration."""
        ref = self.last_reference
        if ref is not None and self.armed and math.dist(ref.position_m, state.position_m) < CONTINUE_WITHIN_M:
            return ref
        return self._start_reference(state)

    def hold(self, t: float, reason: str = "") -> Outcome:
        state = self.state
        if self.armed and state is not None and self.phase not in (Phase.IDLE, Phase.LANDED):
            self._fly(t, stop_from(self.last_or_measured(state), self.limits()), Phase.HOLD)
        self._rtl_landing = False
        self._set_mode(FlightMode.AUTO_LOITER)
        if reason:
            self._event(SEVERITY_WARNING, reason)
        return Outcome(ACCEPTED)

    def land(self, t: float) -> Outcome:
        state = self.state
        self._set_mode(FlightMode.AUTO_LAND)
        if not self.armed or state is None or self.phase in (Phase.IDLE, Phase.LANDED):
            return Outcome(ACCEPTED)
        self._start_landing(t, state)
        return Outcome(ACCEPTED)

    def _start_landing(self, t: float, state: VehicleState) -> None:
        limits = self.limits()
        descend = Limits(
            limits.speed_horizontal,
            limits.speed_up,
            self.params["MPC_LAND_SPEED"],
            limits.acceleration,
            limits.yaw_rate,
        )
        # Brake, then aim far below the ground: the descent goes on at the landing speed until
        # touchdown is detected.
        start = self.last_or_measured(state)
        brake = stop_from(start, limits)
        end = brake.sample(brake.duration_s).position_m
        yaw = start.yaw_rad
        down = LineMove(end, (end[0], end[1], end[2] - 1000.0), descend, yaw, yaw)
        self._fly(t, PiecewiseTrajectory([brake, down]), Phase.LAND)
        self._landed_since = None
        self._event(SEVERITY_INFO, "landing")

    def return_to_launch(self, t: float) -> Outcome:
        state = self.state
        self._set_mode(FlightMode.AUTO_RTL)
        if not self.armed or state is None or self.phase in (Phase.IDLE, Phase.LANDED):
            return Outcome(ACCEPTED)
        assert self.home is not None
        limits = self.limits()
        start = self.last_or_measured(state)
        yaw = start.yaw_rad
        altitude = max(state.position_m[2], self.home[2] + self.params["RTL_RETURN_ALT"])
        brake = stop_from(start, limits)
        p = brake.sample(brake.duration_s).position_m
        climb_to = (p[0], p[1], altitude)
        above_home = (self.home[0], self.home[1], altitude)
        pieces = [
            brake,
            LineMove(p, climb_to, limits, yaw, yaw),
            LineMove(climb_to, above_home, limits, yaw, yaw),
        ]
        self._fly(t, PiecewiseTrajectory(pieces), Phase.RTL)
        self._rtl_landing = False
        self._event(SEVERITY_INFO, f"returning to launch at {altitude - self.home[2]:.1f} m")
        return Outcome(ACCEPTED)

    def set_mode(self, t: float, mode: FlightMode) -> Outcome:
        if mode == self.mode and mode != FlightMode.AUTO_MISSION:  # re-selecting it may (re)start
            return Outcome(ACCEPTED)
        if mode == FlightMode.OFFBOARD:
            if not self.offboard_stream_active(t):
                return self._refuse(DENIED, "OFFBOARD refused: no setpoint stream (send setpoints first)")
            self.offboard.reset()
            self._set_mode(FlightMode.OFFBOARD)
            if self.armed:
                self.phase = Phase.OFFBOARD
            return Outcome(ACCEPTED)
        if mode in (FlightMode.AUTO_LOITER, FlightMode.POSCTL):
            self.hold(t)
            self._set_mode(mode)
            return Outcome(ACCEPTED)
        if mode == FlightMode.AUTO_LAND:
            return self.land(t)
        if mode == FlightMode.AUTO_RTL:
            return self.return_to_launch(t)
        if mode == FlightMode.AUTO_TAKEOFF:
            if not self.armed:
                self._set_mode(mode)
                return Outcome(ACCEPTED)
            return self.takeoff(t)
        if mode == FlightMode.AUTO_MISSION:
            return self._enter_mission(t)
        return self._refuse(UNSUPPORTED, f"mode {mode.px4_name} not supported")

    # -- missions ------------------------------------------------------------------------------------
    def set_mission(self, t: float, mission: MissionExecutor | None) -> None:
        """A new stored mission (upload accepted) or none (cleared); flying the old one: hold."""
        if self.phase == Phase.MISSION:
            self.hold(t, "mission replaced in flight: holding (AUTO.MISSION flies the new one)")
        self.mission = mission

    def start_mission(self, t: float, first_item: int | None = None) -> Outcome:
        """MAV_CMD_MISSION_START: (optionally from ``first_item``) fly the mission, from any mode."""
        mission = self.mission
        if first_item is not None and mission is not None and not mission.set_current(first_item):
            return self._refuse(DENIED, f"mission start refused: no item {first_item}")
        return self._enter_mission(t, restart=True)

    def mission_set_current(self, t: float, seq: int) -> Outcome:
        """MISSION_SET_CURRENT / DO_SET_MISSION_CURRENT: fly to ``seq`` next (at once if flying it)."""
        if self.mission is None or not self.mission.set_current(seq):
            return self._refuse(DENIED, f"set current mission item refused: no item {seq}")
        if self.phase == Phase.MISSION:
            return self._start_mission(t)
        return Outcome(ACCEPTED)

    def _enter_mission(self, t: float, restart: bool = False) -> Outcome:
        mission = self.mission
        if mission is None or mission.count == 0:
            return self._refuse(DENIED, "AUTO.MISSION refused: no mission loaded")
        if not self.armed or self.state is None:
            # PX4: the mode may be selected on the ground; arming then starts the mission.
            problem = check_mission(mission.items, mission.origin, self.limits())
            if problem is not None:
                return self._refuse(DENIED, f"AUTO.MISSION refused: {problem[1]}")
            self._set_mode(FlightMode.AUTO_MISSION)
            return Outcome(ACCEPTED)
        if self.phase == Phase.MISSION and not restart:
            return Outcome(ACCEPTED)
        return self._start_mission(t)

    def _start_mission(self, t: float) -> Outcome:
        """Fly the mission from the measured state, at its current item."""
        mission, state = self.mission, self.state
        assert mission is not None and state is not None and self.home is not None
        on_ground = self.phase in (Phase.IDLE, Phase.LANDED) or not self.in_air()
        p = self.params
        context = PlanContext(
            self.home, self.limits(), p["NAV_ACC_RAD"], p["MIS_TAKEOFF_ALT"], p["MPC_TKO_SPEED"]
        )
        reason = mission.start(t, self._start_reference(state), context, on_ground)
        if reason is not None:
            return self._refuse(DENIED, f"AUTO.MISSION refused: {reason}")
        self.phase = Phase.MISSION
        self._trajectory = None
        self._landed_since = None
        self._rtl_landing = False
        self._set_mode(FlightMode.AUTO_MISSION)
        self._event(SEVERITY_INFO, f"mission: flying item {mission.current_seq} of {mission.count}")
        return Outcome(ACCEPTED)

    def offboard_setpoint(self, setpoint: OffboardSetpoint) -> None:
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

    def fly_trajectory(
        self,
        t: float,
        trajectory: Trajectory,
        mode: FlightMode,
        then: FlightMode | None = FlightMode.AUTO_LOITER,
    ) -> None:
        """Fly a trajectory given on the simulation clock from ``t`` (missions, scenarios)."""
        self._fly(t, trajectory, Phase.TRAJECTORY)
        self._after_trajectory = then
        self._set_mode(mode)

    def start_scenario(self, t: float, trajectory: Trajectory) -> None:
        """The paper's experiment: armed from ``t`` and flying ``trajectory`` from its t = 0."""
        self.armed = True
        self._armed_at = t
        if self.state is not None:
            self.home = (self.state.position_m[0], self.state.position_m[1], 0.0)
        self._event(SEVERITY_INFO, "armed for the scenario")
        self.fly_trajectory(t, trajectory, FlightMode.AUTO_MISSION, then=None)

    # -- failsafes ----------------------------------------------------------------------------------
    def gcs_heartbeat(self, t: float) -> None:
        """A HEARTBEAT from a ground station (MAV_TYPE_GCS) at simulation time ``t``."""
        for text in self.failsafes.gcs_heartbeat(t):
            self._event(SEVERITY_INFO, text)

    def simulator_lost(self) -> None:
        """No sensor frames any more: the position is unknown until they resume (no arming)."""
        self.position_valid = False

    def _check_failsafes(self, t: float, state: VehicleState) -> None:
        """Data link loss and geofence (failsafe.py); called once per step while armed off the ground."""
        flying = self.in_air()
        for action, text in self.failsafes.check(t, state.position_m, self.home, flying):
            busy = self.phase in (Phase.LAND, Phase.RTL) or self._rtl_landing
            if action == HOLD and not busy:
                self.hold(t)
                self._event(SEVERITY_CRITICAL, f"{text}: holding")
            elif action == RTL and not busy:
                self.return_to_launch(t)
                self._event(SEVERITY_CRITICAL, f"{text}: returning to launch")
            elif action == LAND and self.phase != Phase.LAND:
                self.land(t)
                self._event(SEVERITY_CRITICAL, f"{text}: landing")
            elif action == WARN:
                self._event(SEVERITY_WARNING, text)
            else:  # the vehicle is already returning or landing: let it
                self._event(SEVERITY_CRITICAL, f"{text} (already {self.mode.px4_name})")

    # -- the per-step decision ------------------------------------------------------------------------
    def step(self, t: float, dt: float) -> GuidanceOutput:
        """Decide this control step (``dt`` = control period, s)."""
        state = self.state
        if not self.armed or state is None:
            return GuidanceOutput(Motors.OFF, None)
        if self.phase not in (Phase.IDLE, Phase.LANDED):
            self._check_failsafes(t, state)
        phase = self.phase
        if phase == Phase.IDLE:
            if t - self._armed_at > self.params["COM_DISARM_PRFLT"] > 0.0:
                self._disarm("disarmed: no takeoff after arming")
                return GuidanceOutput(Motors.OFF, None)
            return GuidanceOutput(Motors.IDLE, None)
        if phase == Phase.LANDED:
            if t - self._touchdown_at >= self.params["COM_DISARM_LAND"]:
                self._disarm("landed: disarmed")
                return GuidanceOutput(Motors.OFF, None)
            return GuidanceOutput(Motors.IDLE, None)

        if phase == Phase.OFFBOARD:
            if not self.offboard_stream_active(t) and self.offboard.setpoint is not None:
                last = self._setpoint_times[-1] if self._setpoint_times else float("-inf")
                if t - last > self.params["COM_OF_LOSS_T"]:
                    self.hold(t, "offboard setpoints lost: switching to hold")
                    return self.step(t, dt)
            previous = self.last_reference or self._start_reference(state)
            reference = self.offboard.reference(t, dt, previous)
            if self.offboard.setpoint is None:
                reference = previous
        elif phase == Phase.MISSION:
            assert self.mission is not None
            out = self.mission.step(t, state.position_m)
            if out.action == MissionAction.LAND:
                self._start_landing(t, state)  # the mission's LAND item: mode stays AUTO.MISSION
                return self.step(t, dt)
            if out.action == MissionAction.RTL:
                self.return_to_launch(t)
                return self.step(t, dt)
            reference = out.reference
        else:
            assert self._trajectory is not None
            local = t - self._trajectory_start
            reference = self._trajectory.sample(local)
            done = local >= self._trajectory.duration_s
            if phase == Phase.TAKEOFF and done:
                self.phase = Phase.HOLD
                self._set_mode(FlightMode.AUTO_LOITER)
            elif phase == Phase.RTL and done:
                self._start_landing(t, state)
                self._rtl_landing = True
                self.phase = Phase.LAND
                self._set_mode(FlightMode.AUTO_RTL)
            elif phase == Phase.TRAJECTORY and done and self._after_trajectory is not None:
                self.hold(t)
                self._set_mode(self._after_trajectory)
            elif phase == Phase.LAND and self._touched_down(t, state):
                self.phase = Phase.LANDED
                self._touchdown_at = t
                self._rtl_landing = False
                if self.mission is not None:
                    self.mission.landed()  # reaches a mission's LAND item (no-op otherwise)
                self._event(SEVERITY_INFO, "landing detected")
                return GuidanceOutput(Motors.IDLE, None)
        ground = GROUND_Z_M
        if (
            phase in (Phase.TAKEOFF, Phase.OFFBOARD, Phase.TRAJECTORY, Phase.MISSION)
            and self._near_ground(state)
            and reference.position_m[2] - ground < 0.02
        ):
            # Waiting for the reference to lift off: do not fight the ground (integrators).
            self.last_reference = reference
            return GuidanceOutput(Motors.IDLE, reference)
        self.last_reference = reference
        return GuidanceOutput(Motors.FLY, reference)

    def _touched_down(self, t: float, state: VehicleState) -> bool:
        ground = GROUND_Z_M
        resting = (
            state.position_m[2] - ground < ON_GROUND_HEIGHT_M
            and abs(state.velocity_m_s[2]) < LANDED_SPEED_M_S
        )
        if not resting:
            self._landed_since = None
            return False
        if self._landed_since is None:
            self._landed_since = t
        return t - self._landed_since >= LANDED_CONFIRM_S
