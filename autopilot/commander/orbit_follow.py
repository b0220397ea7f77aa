"""Orbit (MAV_CMD_DO_ORBIT) and follow-me (FOLLOW_TARGET, AUTO.FOLLOW_TARGET): entering them,
their settings from the parameters (``MC_ORBIT_*``, ``FLW_TGT_*``), the target reports, and the
reference each flies per step (:mod:`autopilot.guidance.orbit`, :mod:`autopilot.guidance.follow`).

A part of :class:`~.commander.Commander` (its state lives there); the transitions go through the
table (:mod:`.transitions`).
"""

from __future__ import annotations

from quadcommon.trajectories import Reference

from ..guidance.follow import FollowSettings, TargetReport
from ..guidance.orbit import SPEED_MAX_M_S, YAW_NAMES, OrbitLimits, OrbitRequest, OrbitStatus, radius_refusal
from .records import DENIED, GROUND_Z_M, SEVERITY_INFO, SEVERITY_WARNING, Outcome, VehicleState, at_rest
from .transitions import Event, Phase


class OrbitFollow:
    """Orbit and follow-me (module docstring): a part of the Commander."""

    def orbit_limits(self) -> OrbitLimits:
        """Orbit's limits from the parameters (MC_ORBIT_RAD_MAX, MC_ORBIT_YAW_MOD, the AUTO limits)."""
        p = self.params
        limits = self.limits()
        return OrbitLimits(p["MC_ORBIT_RAD_MAX"], min(SPEED_MAX_M_S, limits.speed_horizontal), limits,
                           int(p["MC_ORBIT_YAW_MOD"]))  # fmt: skip

    def follow_settings(self) -> FollowSettings:
        """Follow-me's settings from the parameters (FLW_TGT_*, the AUTO limits)."""
        p = self.params
        return FollowSettings(p["FLW_TGT_HT"], p["FLW_TGT_DST"], p["FLW_TGT_FA"], int(p["FLW_TGT_ALT_M"]),
                              p["FLW_TGT_MAX_VEL"], p["FLW_TGT_RS"], self.limits())  # fmt: skip

    @property
    def orbit_status(self) -> OrbitStatus | None:
        """The orbit flown (ORBIT_EXECUTION_STATUS), or None when not in Orbit."""
        return self.orbit.status if self.phase == Phase.ORBIT else None

    def orbit_command(self, t: float, request: OrbitRequest) -> Outcome:
        """MAV_CMD_DO_ORBIT (paper frame): enter Orbit (or change the orbit flown) with the request's
        radius, speed, yaw behaviour and centre (None: keep; entering, the defaults of
        :mod:`autopilot.guidance.orbit`)."""
        return self._fire(t, Event.ORBIT, request=request)

    def follow_target_report(self, report: TargetReport) -> None:
        """A FOLLOW_TARGET (checked at the edge): the target's estimate takes it in any mode, as
        PX4's target estimator runs whatever the mode."""
        self.follow.target.report(report, self._follow_settings.responsiveness)

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

    def _orbit_reference(self, t: float, dt: float, state: VehicleState) -> Reference:
        """Orbit's reference this step; the yaw stick turns the vehicle (PX4: POSCTL's sticks)."""
        previous = self.last_reference or at_rest(state)
        sticks = self.sticks.fresh(t, self._manual_limits.loss_s)
        yaw_stick = sticks.yaw * self._manual_limits.yaw_rate if sticks is not None else 0.0
        return self.orbit.reference(t, dt, state.position_m, previous, self._orbit_limits, yaw_stick)

    def _follow_reference(self, t: float, dt: float, state: VehicleState) -> Reference:
        """Follow-me's reference this step; the loss of the target and its return announced."""
        previous = self.last_reference or at_rest(state)
        home = self.home or (0.0, 0.0, GROUND_Z_M)
        reference = self.follow.reference(t, dt, state.position_m, previous, home, self._follow_settings)
        if self.follow.lost != self._follow_lost_said:
            self._follow_lost_said = self.follow.lost
            self._event(SEVERITY_WARNING if self.follow.lost else SEVERITY_INFO,
                        "follow-me: no target (no FOLLOW_TARGET for 3 s): holding position"
                        if self.follow.lost else "follow-me: target found, following")  # fmt: skip
        return reference
