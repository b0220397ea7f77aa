"""The plans the table's actions fly: takeoff, hold, reposition (and the climb to it from the
ground), landing, the return to launch (to home or a rally point, by ``RTL_TYPE``: :mod:`.rtl`),
PX4's Descend and flight termination; each one a trajectory from the reference flown so far (the
planner's :class:`~autopilot.guidance.planner.LineMove` and ``stop_from``), announced.

A part of :class:`~.commander.Commander` (its state lives there): each ``_act_*`` is a row's
action of the table (:mod:`.transitions`); None or an accepted Outcome lets the transition happen.
"""

from __future__ import annotations

import math
from dataclasses import replace

from quadcommon.trajectories import PiecewiseTrajectory, Trajectory

from ..guidance.planner import LineMove, stop_from
from .records import (
    DENIED,
    SEVERITY_EMERGENCY,
    SEVERITY_INFO,
    SEVERITY_WARNING,
    Outcome,
    Vector3,
    at_rest,
)
from .rtl import return_altitude, return_destination


class Plans:
    """The trajectories of the table's actions (module docstring): a part of the Commander."""

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
        here = at_rest(state).position_m
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

    def _act_touchdown(self, t: float, **_) -> None:
        self._touchdown_at = t
        if self.mission is not None:
            self.mission.landed()  # reaches a mission's LAND item (no-op otherwise)
        self._event(SEVERITY_INFO, "landing detected")

    def _fly(self, t: float, trajectory: Trajectory) -> None:
        self._trajectory = trajectory
        self._trajectory_start = t
