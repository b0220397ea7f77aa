"""Arming and disarming, and the pre-arm checks: the one verdict (:meth:`Arming.arm_problem`) the
arming command, SYS_STATUS's armable bit and the ``Preflight Fail: ...`` announcements all read
(PX4's commander: arming only on the ground, at rest, with a position, in a mode that can take off,
with the health and failsafe checks passing); a forced arm skips the checks but not the position.

A part of :class:`~.commander.Commander` (its state lives there); the transitions go through the
table (:mod:`.transitions`).
"""

from __future__ import annotations

import math
import re

from quadcommon.trajectories import Trajectory

from ..mission.executor import MissionState
from .failsafe import prearm_problem
from .health import NAV_AUTO_FOLLOW_TARGET, NAV_ORBIT, NAV_STATE_OF_MODE
from .modes import FlightMode
from .records import (
    ACCEPTED,
    DENIED,
    GROUND_Z_M,
    SEVERITY_INFO,
    SEVERITY_NOTICE,
    SEVERITY_WARNING,
    Outcome,
)
from .transitions import Event, Phase

MOVING_SPEED_M_S = 0.2  # a vehicle on the ground faster than this is not at rest: arming refused
# The pre-arm verdict, announced while disarmed (PX4's "Preflight Fail: ..." STATUSTEXT): checked
# this often; the same verdict (its figures aside) not announced again within READINESS_REPEAT_S.
READINESS_CHECK_S = 0.1
READINESS_REPEAT_S = 10.0
PREFLIGHT_FAIL = "Preflight Fail: "  # PX4's prefix of a pre-arm failure reported unasked
_FIGURES = re.compile(r"\d+(?:\.\d+)?")  # the figures of a verdict (not part of which verdict it is)
# Modes PX4 does not arm in (mode_req_prevent_arming) that this vehicle refuses to arm in too: Orbit
# and follow-me (PX4 also lists RTL, Land and Descend, which arm here and stay on the ground).
_NOT_ARMED_IN = (NAV_ORBIT, NAV_AUTO_FOLLOW_TARGET)


class Arming:
    """Arming, disarming and the pre-arm checks (module docstring): a part of the Commander."""

    def arm(self, t: float, force: bool = False) -> Outcome:
        """Arm (``force``: without the pre-arm checks, as MAV_CMD_COMPONENT_ARM_DISARM's 21196);
        armed in OFFBOARD or AUTO.MISSION, the vehicle enters it at once (PX4)."""
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
        """Disarm; in the air only with ``force`` (motors off wherever the vehicle is)."""
        if not self.armed:
            return Outcome(ACCEPTED, "already disarmed")
        return self._fire(t, Event.DISARM, force=force, why="disarmed")

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

    def _act_start_scenario(self, t: float, trajectory: Trajectory, then: FlightMode | None, **_) -> None:
        self._armed_at = t
        if self.state is not None:
            self.home = (self.state.position_m[0], self.state.position_m[1], GROUND_Z_M)
        self._event(SEVERITY_INFO, "armed for the scenario")
        self._fly(t, trajectory)
        self._after_trajectory = then
