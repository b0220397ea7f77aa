"""Flying a mission: the reference at every control step, the current item, the items reached.

Pure: no sockets, no clock; every call takes the simulation time ``t`` (s). The commander owns one
:class:`MissionExecutor` per stored mission and calls :meth:`~MissionExecutor.start` (entering
AUTO.MISSION, also to resume), :meth:`~MissionExecutor.step` every control step,
:meth:`~MissionExecutor.pause` (hold, or any other mode) and :meth:`~MissionExecutor.landed`.

The mission is flown as a chain of *legs*, each a time-parameterised trajectory built when the
leg begins from the reference the previous leg ended with, so p_d, p_d', p_d'' are continuous
(C2) across the whole mission and within the speed and acceleration limits (``MPC_*``, lowered by
DO_CHANGE_SPEED for every later leg):

* takeoff: a vertical :class:`~autopilot.guidance.planner.LineMove` at ``MPC_TKO_SPEED``; if the
  mission starts on the ground at an item that moves, an implicit takeoff to ``MIS_TAKEOFF_ALT``
  comes first (as PX4);
* waypoint / loiter time: a rest-to-rest S-curve move (or, after a timed curve, a quintic from the
  moving state to rest); the item is *reached* when the move has finished AND the vehicle is within
  the acceptance radius (item param2, else ``NAV_ACC_RAD``) -- the reference holds at the waypoint
  until then -- and the hold time (param1) has passed;
* delay: hold where the vehicle is;
* timed items (``WAYPOINT_USER_1``): consecutive timed items form one curve
  (:class:`~autopilot.mission.curve.TimedCurve`); a quintic *approach* joins the previous state to
  the curve's full state (p, p', p'', yaw, yaw', yaw'') at the current item, then the curve is
  flown on the clock. Item times count from the mission start: when the approach would arrive
  early the vehicle first waits at rest; when late (takeoff and approach took longer, or after a
  pause) the rest of the curve is shifted later, its shape and speed unchanged. A timed item is
  reached when the reference passes its time (a moving curve does not wait for the vehicle);
* land: fly to above the land point, then the commander lands (mode stays AUTO.MISSION); the item
  is reached at touchdown. Return to launch: reached at once, then the commander returns (AUTO.RTL);
* after the last item the vehicle holds (mode stays AUTO.MISSION, mission state COMPLETE);
* payload items (camera, gimbal, ROI, ...) are reached at once and do nothing (one STATUSTEXT per
  run of the mission says so); DO_JUMP jumps to its target while it has repeats left (counted per
  run of the mission, as PX4), else it is passed. A loop over items that take no time is refused
  at upload; a jump chain that still takes none holds after ``MAX_INSTANT_ITEMS``.

An item with ``autocontinue = 0`` is reached and then held until the ground station sets the
current item (MISSION_SET_CURRENT) or restarts the mission.

(One module: the legs of every item kind share the reference continuity rules and
the executor's state; split by item kind, each part would need all of it.)
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from enum import Enum, IntEnum
from typing import NamedTuple

import numpy as np

from quadcommon.trajectories import (
    Hover,
    PiecewiseTrajectory,
    Reference,
    Trajectory,
    eval_quintic,
    quintic_coefficients,
)

from ..guidance.planner import Limits, LineMove, transition
from ..mavlink.codec import mavlink as m
from ..mavlink.validation import reference_problem
from .curve import GLOBAL_TOLERANCE_M, POSITION_TOLERANCE_M, TimedCurve
from .items import ItemKind, MissionItem, PositionKind

Vector3 = tuple[float, float, float]
ZERO3: Vector3 = (0.0, 0.0, 0.0)
AT_REST = 1e-6  # |v|, |a| below this: the reference is at rest
LIMIT_TOLERANCE = 1.05  # sampled peaks may exceed a limit by this factor (as the planner)
MAX_INSTANT_ITEMS = 100_000  # items that take no time processed in a row before the mission holds
JERK_LIMIT_M_S3 = 5.0  # approach quintics: PX4's MPC_JERK_AUTO is 4; the S-curve moves stay below 4
NO_PAYLOAD_TEXT = "mission: no gimbal/camera on this vehicle, payload items skipped"


class MissionState(IntEnum):
    """MISSION_CURRENT.mission_state (MISSION_STATE)."""

    NO_MISSION = m.MISSION_STATE_NO_MISSION
    NOT_STARTED = m.MISSION_STATE_NOT_STARTED
    ACTIVE = m.MISSION_STATE_ACTIVE
    PAUSED = m.MISSION_STATE_PAUSED
    COMPLETE = m.MISSION_STATE_COMPLETE


class MissionAction(Enum):
    NONE = "none"
    LAND = "land"  # the commander lands here (the LAND item is reached at touchdown)
    RTL = "rtl"  # the commander returns to launch


@dataclass(frozen=True)
class PlanContext:
    """What the commander knows when a mission (re)starts (paper frame, SI)."""

    home_local: Vector3  # the vehicle's home (m)
    limits: Limits
    acceptance_radius_m: float  # NAV_ACC_RAD
    takeoff_altitude_m: float  # MIS_TAKEOFF_ALT (above home)
    takeoff_speed_m_s: float  # MPC_TKO_SPEED


class MissionStep(NamedTuple):
    reference: Reference
    action: MissionAction = MissionAction.NONE


@dataclass
class _Leg:
    seq: int  # the item this leg flies
    trajectory: Trajectory
    start_s: float  # simulation time at which the trajectory's t = 0
    target: Vector3 | None = None  # acceptance check at the end, if any
    radius_m: float = 0.0
    hold_s: float = 0.0
    timed: list[tuple[float, int]] = field(default_factory=list)  # (leg time, seq) of timed items
    action: MissionAction = MissionAction.NONE
    implicit: bool = False  # no item asked for it (implicit takeoff, final hold): reports nothing
    moving_end: bool = False  # ends in motion (a timed curve): no acceptance wait, no hold


def _at_rest(ref: Reference) -> bool:
    return all(abs(v) < AT_REST for v in (*ref.velocity_m_s, *ref.acceleration_m_s2))


def _final(trajectory: Trajectory) -> Reference:
    """The state a trajectory ends in (for a PiecewiseTrajectory, its last piece's own end: sampling
    the whole at its duration may land, by rounding, on the at-rest hold that follows it)."""
    if isinstance(trajectory, PiecewiseTrajectory):
        trajectory = trajectory.pieces[-1]
    return trajectory.sample(trajectory.duration_s)


class _Blend:
    """Quintic in x, y, z and yaw from one full state to another over ``duration_s`` (C2 joins)."""

    def __init__(self, duration_s: float, start: Reference, end: Reference) -> None:
        self.duration_s = duration_s
        T = duration_s
        self.coeffs = [
            quintic_coefficients(
                start.position_m[i], start.velocity_m_s[i], start.acceleration_m_s2[i],
                end.position_m[i], end.velocity_m_s[i], end.acceleration_m_s2[i], T,
            )
            for i in range(3)
        ]  # fmt: skip
        yaw1 = start.yaw_rad + math.remainder(end.yaw_rad - start.yaw_rad, 2.0 * math.pi)
        self.yaw_coeffs = quintic_coefficients(
            start.yaw_rad, start.yaw_rate_rad_s, start.yaw_acceleration_rad_s2,
            yaw1, end.yaw_rate_rad_s, end.yaw_acceleration_rad_s2, T,
        )  # fmt: skip

    def jerk(self, t: float) -> float:
        """Magnitude of the third derivative of p_d at ``t`` (m/s^3)."""
        return math.sqrt(sum((6.0 * c[3] + t * (24.0 * c[4] + t * 60.0 * c[5])) ** 2 for c in self.coeffs))

    def sample(self, t: float) -> Reference:
        t = min(max(t, 0.0), self.duration_s)
        axes = [eval_quintic(c, t) for c in self.coeffs]
        y, yd, ydd = eval_quintic(self.yaw_coeffs, t)
        return Reference(
            (axes[0][0], axes[1][0], axes[2][0]),
            (axes[0][1], axes[1][1], axes[2][1]),
            (axes[0][2], axes[1][2], axes[2][2]),
            math.remainder(y, 2.0 * math.pi), yd, ydd,
        )  # fmt: skip


class _CurveFrom:
    """A timed curve flown from ``tau0`` (s after its first sample) to its end."""

    def __init__(self, curve: TimedCurve, tau0: float) -> None:
        self.curve, self.tau0 = curve, tau0
        self.duration_s = max(curve.duration_s - tau0, 0.0)

    def sample(self, t: float) -> Reference:
        return self.curve.sample(self.tau0 + min(max(t, 0.0), self.duration_s))


def _within(traj: _Blend, limits: Limits, floor_speed: float, samples: int = 48) -> bool:
    """Sampled speed, acceleration and jerk within the limits (speeds at least ``floor_speed``)."""
    duration = traj.duration_s
    for i in range(samples + 1):
        ref = traj.sample(duration * i / samples)
        if traj.jerk(duration * i / samples) > JERK_LIMIT_M_S3:
            return False
        vx, vy, vz = ref.velocity_m_s
        if math.hypot(vx, vy) > max(limits.speed_horizontal, floor_speed) * LIMIT_TOLERANCE:
            return False
        if vz > max(limits.speed_up, floor_speed) * LIMIT_TOLERANCE:
            return False
        if -vz > max(limits.speed_down, floor_speed) * LIMIT_TOLERANCE:
            return False
        if math.dist(ref.acceleration_m_s2, ZERO3) > limits.acceleration * LIMIT_TOLERANCE:
            return False
    return True


def approach(start: Reference, end: Reference, limits: Limits) -> _Blend:
    """The shortest quintic (within the limits) from the state ``start`` to the state ``end``."""
    distance = math.dist(start.position_m, end.position_m)
    v0 = math.dist(start.velocity_m_s, ZERO3)
    v1 = math.dist(end.velocity_m_s, ZERO3)
    vmax = min(limits.speed_horizontal, limits.speed_up, limits.speed_down)
    amax = limits.acceleration
    dyaw = abs(math.remainder(end.yaw_rad - start.yaw_rad, 2.0 * math.pi))
    T = max(
        1.875 * distance / vmax,
        math.sqrt(5.7735 * distance / amax),
        2.0 * (v0 + v1) / amax,
        1.875 * dyaw / limits.yaw_rate,
        0.5,
    )
    floor_speed = max(v0, v1)
    blend = _Blend(T, start, end)
    for _ in range(40):
        if _within(blend, limits, floor_speed):
            break
        T *= 1.2
        blend = _Blend(T, start, end)
    return blend


def _timed_block(items: Sequence[MissionItem], seq: int) -> tuple[int, int]:
    """First and last seq of the run of consecutive timed items containing ``seq``."""
    first = seq
    while first > 0 and items[first - 1].kind == ItemKind.TIMED:
        first -= 1
    last = seq
    while last + 1 < len(items) and items[last + 1].kind == ItemKind.TIMED:
        last += 1
    return first, last


def _resolution(block: Sequence[MissionItem]) -> tuple[float, float, float]:
    """Per-axis resolution (m) of timed samples as the wire carried them (for the curve fit)."""
    if all(it.position is not None and it.position.kind == PositionKind.LOCAL_NED for it in block):
        return (POSITION_TOLERANCE_M,) * 3
    return GLOBAL_TOLERANCE_M


_TAKES_TIME = frozenset(
    (ItemKind.TAKEOFF, ItemKind.WAYPOINT, ItemKind.LOITER_TIME, ItemKind.DELAY, ItemKind.LAND,
     ItemKind.TIMED, ItemKind.RETURN_TO_LAUNCH)
)  # fmt: skip


def fence_violation(
    items: Sequence[MissionItem],
    origin: tuple[float, float, float],
    fence: Callable[[Vector3], str | None],
    home_local: Vector3 = ZERO3,
) -> tuple[int, str] | None:
    """The first item whose position breaks the geofence (``fence``: why a paper-frame point does,
    or None), as (seq, why); None if every one is inside. Relative altitudes above ``home_local``,
    an item without altitude checked at the ground (PX4's feasibility check)."""
    for item in items:
        if item.position is None or not item.position.horizontal_given:
            continue
        x, y, z = item.position.to_paper(origin, home_local)
        problem = fence((x, y, home_local[2] if math.isnan(z) else z))
        if problem:
            return item.seq, problem
    return None


def check_mission(
    items: Sequence[MissionItem],
    origin: tuple[float, float, float],
    limits: Limits,
    params: Mapping[str, float] | None = None,
    fence: Callable[[Vector3], str | None] | None = None,
    home_local: Vector3 = ZERO3,
) -> tuple[int, str] | None:
    """Whole-mission feasibility: None, or (MAV_MISSION_RESULT, reason) for the first problem.

    Every position within ``NAV_REF_MAX_DIST`` of home (the configured origin; the rule offboard
    setpoints follow too, :func:`autopilot.mavlink.validation.reference_problem`), and, given
    ``fence`` (why a paper-frame point breaks the geofence, or None), inside the geofence as it is
    at upload (PX4's feasibility check; relative altitudes above ``home_local``, an item without
    altitude checked at the ground). Timed curves must stay within the vehicle's speed and
    acceleration limits (their speed is set by their times, so they are refused rather than
    slowed down)."""
    if params is not None:
        for item in items:
            if item.position is None or not item.position.horizontal_given:
                continue
            x, y, z = item.position.to_paper(origin, ZERO3)
            problem = reference_problem((x, y, 0.0 if math.isnan(z) else z), ZERO3, params)
            if problem:
                return m.MAV_MISSION_INVALID_PARAM5_X, f"item {item.seq}: {problem}"
    if fence is not None:
        violation = fence_violation(items, origin, fence, home_local)
        if violation is not None:
            return m.MAV_MISSION_INVALID_PARAM5_X, f"item {violation[0]}: {violation[1]}"
    for item in items:
        if item.kind != ItemKind.JUMP:
            continue
        if item.jump_target >= len(items):
            return (
                m.MAV_MISSION_INVALID_PARAM1,
                f"item {item.seq}: jump target {item.jump_target} not in the mission of {len(items)}",
            )
        loop = items[item.jump_target : item.seq]
        if item.jump_repeats and loop and not any(it.kind in _TAKES_TIME for it in loop):
            return (
                m.MAV_MISSION_INVALID_PARAM1,
                f"item {item.seq}: jump back to {item.jump_target} loops over no item that moves or waits",
            )
    seq = 0
    while seq < len(items):
        if items[seq].kind != ItemKind.TIMED:
            seq += 1
            continue
        first, last = _timed_block(items, seq)
        block = items[first : last + 1]
        try:
            curve = TimedCurve(
                [it.time_s for it in block],
                [it.position.to_paper(origin, ZERO3) for it in block],
                [None] * len(block),
                tolerance_m=_resolution(block),
            )
        except (ValueError, np.linalg.LinAlgError) as exc:  # e.g. samples no fit can pass through
            return m.MAV_MISSION_INVALID_PARAM1, f"timed items {first}-{last}: no curve fits them ({exc})"
        except ImportError as exc:  # a broken installation: refused with the reason, not unanswered
            return m.MAV_MISSION_ERROR, f"timed items {first}-{last}: cannot fit a curve ({exc})"
        vh, vup, vdown, acc = curve.peaks()
        checks = (
            (vh, limits.speed_horizontal, "horizontal speed", "m/s", "MPC_XY_VEL_MAX"),
            (vup, limits.speed_up, "climb rate", "m/s", "MPC_Z_VEL_MAX_UP"),
            (vdown, limits.speed_down, "descent rate", "m/s", "MPC_Z_VEL_MAX_DN"),
            (acc, limits.acceleration, "acceleration", "m/s^2", "MPC_ACC_HOR"),
        )
        for value, limit, what, unit, name in checks:
            if value > limit * (1.0 + 1e-6):
                return (
                    m.MAV_MISSION_INVALID_PARAM1,
                    f"timed items {first}-{last}: {what} {value:.2f} {unit} above {name} {limit:.2f} "
                    "(give the samples later times)",
                )
        seq = last + 1
    return None


class MissionExecutor:
    """Runs one stored mission (a tuple of validated items) in the paper frame."""

    def __init__(
        self, items: Sequence[MissionItem], origin: tuple[float, float, float], current_seq: int = 0
    ) -> None:
        """``origin`` = the configured geodetic home (lat, lon deg, alt m AMSL) of the local frame."""
        self.items = tuple(items)
        self.origin = origin
        self.current_seq = min(max(current_seq, 0), max(len(self.items) - 1, 0))
        self.state = MissionState.NOT_STARTED if self.items else MissionState.NO_MISSION
        self._reached: list[int] = []
        self._leg: _Leg | None = None
        self._ctx: PlanContext | None = None
        self._mission_t0 = 0.0
        self._arrived_at: float | None = None
        self._on_ground = False
        self._awaiting_landing = False
        self._pending: MissionAction = MissionAction.NONE
        self._speeds: dict[int, float | None] = {1: None, 2: None, 3: None}
        self._held = Reference(ZERO3, ZERO3, ZERO3)
        self._jumps: dict[int, int] = {}  # DO_JUMP seq -> jumps done in this run of the mission
        self._payload_noted = False  # the "no payload" STATUSTEXT went out in this run
        self._notices: list[tuple[int, str]] = []

    @property
    def count(self) -> int:
        """The number of items in the mission."""
        return len(self.items)

    def _note(self, severity: int, text: str) -> None:
        self._notices.append((severity, text))

    def drain_notices(self) -> list[tuple[int, str]]:
        """STATUSTEXTs (severity, text) the mission raised since the last call."""
        notices, self._notices = self._notices, []
        return notices

    def has_reached(self) -> bool:
        """Items reached and not yet drained (checked every frame; draining allocates)."""
        return bool(self._reached)

    def drain_reached(self) -> list[int]:
        """Items reached since the last call, in order (each reported once)."""
        reached, self._reached = self._reached, []
        return reached

    # -- control from the commander ---------------------------------------------------------------
    def set_current(self, seq: int) -> bool:
        """Make ``seq`` the current item (the commander restarts the leg if flying)."""
        if not 0 <= seq < self.count:
            return False
        self.current_seq = seq
        self._leg = None
        self._awaiting_landing = False
        if self.state == MissionState.COMPLETE:
            self.state = MissionState.PAUSED  # resume from there, not from the beginning
        return True

    def start(self, t: float, start: Reference, context: PlanContext, on_ground: bool) -> str | None:
        """Fly from the state ``start`` at the current item; None, or why the mission cannot fly."""
        if not self.items:
            return "no mission"
        problem = check_mission(self.items, self.origin, context.limits)
        if problem is not None:
            return problem[1]
        if self.state == MissionState.COMPLETE:
            self.current_seq = 0
        if self.state in (MissionState.NOT_STARTED, MissionState.COMPLETE):
            self._mission_t0 = t
            self._jumps = {}
            self._payload_noted = False
        self.state = MissionState.ACTIVE
        self._ctx = context
        self._on_ground = on_ground
        self._awaiting_landing = False
        self._pending = MissionAction.NONE
        self._speeds = {1: None, 2: None, 3: None}
        for item in self.items[: self.current_seq]:
            if item.kind == ItemKind.CHANGE_SPEED:
                self._apply_speed(item)
        self._begin(t, start)
        return None

    def pause(self) -> None:
        """Hold or another mode took over: forget the leg, keep the current item."""
        if self.state == MissionState.ACTIVE:
            self.state = MissionState.PAUSED
        self._leg = None
        self._awaiting_landing = False

    def landed(self) -> None:
        """Touchdown after the mission's LAND item: the item is reached, the mission complete."""
        if self._awaiting_landing:
            self._awaiting_landing = False
            self._reach(self.current_seq)
            self.state = MissionState.COMPLETE

    @property
    def awaiting_landing(self) -> bool:
        """True after the mission's LAND item handed the landing to the commander and until touchdown
        (:meth:`landed`) or a pause."""
        return self._awaiting_landing

    @property
    def destination(self) -> Reference | None:
        """Where the current leg leads (paper frame): its acceptance target, else where its
        trajectory ends (a hover: its point); None between legs."""
        leg = self._leg
        if leg is None:
            return None
        plan = leg.trajectory
        if isinstance(plan, Hover):
            end = plan.sample(0.0)
        else:
            end = _final(plan) if math.isfinite(plan.duration_s) else None
        if leg.target is None:
            return end
        yaw = end.yaw_rad if end is not None else self._held.yaw_rad
        return Reference(leg.target, ZERO3, ZERO3, yaw)

    # -- the per-step reference --------------------------------------------------------------------
    def step(self, t: float, position: Vector3) -> MissionStep:
        """The reference at ``t`` given the vehicle's ``position`` (paper frame, m)."""
        for _ in range(2 * self.count + 4):  # legs that end at once chain within one step
            if self._pending != MissionAction.NONE:
                action, self._pending = self._pending, MissionAction.NONE
                return MissionStep(self._held, action)
            leg = self._leg
            if leg is None:
                return MissionStep(self._held)
            local = t - leg.start_s
            ref = leg.trajectory.sample(local)
            while leg.timed and leg.timed[0][0] <= local:
                _, seq = leg.timed.pop(0)
                self._reach(seq)
                self.current_seq = min(seq + 1, self.count - 1)
            self._held = ref
            if local < leg.trajectory.duration_s:
                return MissionStep(ref)
            end = _final(leg.trajectory)
            if not leg.moving_end:
                if leg.target is not None and math.dist(position, leg.target) > leg.radius_m:
                    self._arrived_at = None
                    return MissionStep(end)  # hold at the waypoint until the vehicle is there
                if self._arrived_at is None:
                    self._arrived_at = t
                if t - self._arrived_at < leg.hold_s:
                    return MissionStep(end)
            self._arrived_at = None
            self._held = end
            if leg.action == MissionAction.LAND:
                self._leg = None
                self._awaiting_landing = True
                return MissionStep(end, MissionAction.LAND)
            if leg.moving_end:  # a timed curve: the next leg starts where it ended, in motion
                self.current_seq = leg.seq
                self._begin(leg.start_s + leg.trajectory.duration_s, end)
                continue
            if not leg.implicit:
                self._reach(leg.seq)
                self.current_seq = leg.seq + 1
                if not self.items[leg.seq].autocontinue and self.current_seq < self.count:
                    # autocontinue = 0: hold here until the ground station sets the current item.
                    self._leg = _Leg(self.current_seq, Hover(end.position_m, end.yaw_rad), t, implicit=True)
                    return MissionStep(end)
            self._begin(t, end)
        return MissionStep(self._held)

    # -- legs --------------------------------------------------------------------------------------
    def _reach(self, seq: int) -> None:
        self._reached.append(seq)

    def _limits(self) -> Limits:
        assert self._ctx is not None
        limits = self._ctx.limits
        horizontal, climb, descent = self._speeds[1], self._speeds[2], self._speeds[3]
        return replace(
            limits,
            speed_horizontal=min(limits.speed_horizontal, horizontal or math.inf),
            speed_up=min(limits.speed_up, climb or math.inf),
            speed_down=min(limits.speed_down, descent or math.inf),
        )

    def _apply_speed(self, item: MissionItem) -> None:
        if not item.speed_unchanged:
            self._speeds[item.speed_channel] = item.speed_m_s

    def _move(self, start: Reference, target: Vector3, limits: Limits, yaw: float | None) -> Trajectory:
        yaw1 = start.yaw_rad if yaw is None else yaw
        if _at_rest(start):
            return LineMove(start.position_m, target, limits, start.yaw_rad, yaw1)
        return transition(start, target, limits, yaw1)

    def _brake(self, start: Reference, limits: Limits) -> list[Trajectory]:
        """Pieces that bring a moving reference to rest (none if at rest)."""
        if _at_rest(start):
            return []
        speed = math.dist(start.velocity_m_s, ZERO3)
        stop = speed * speed / (2.0 * limits.acceleration)
        target = tuple(
            p + v / speed * stop for p, v in zip(start.position_m, start.velocity_m_s, strict=True)
        )
        return [transition(start, target, limits, start.yaw_rad)]  # type: ignore[arg-type]

    def _begin(self, t: float, start: Reference) -> None:
        """Build the leg for the current item (processing items that take no time) from ``start``."""
        ctx = self._ctx
        assert ctx is not None
        self._arrived_at = None
        self._held = start
        budget = MAX_INSTANT_ITEMS
        while True:
            seq = self.current_seq
            if seq >= self.count:
                self._finish(t, start)
                return
            budget -= 1
            if budget < 0:  # jumps among items that take no time (the upload check catches most)
                self._note(m.MAV_SEVERITY_CRITICAL, "mission: jump loop without movement, holding")
                self._finish(t, start)
                return
            item = self.items[seq]
            limits = self._limits()
            kind = item.kind
            if kind == ItemKind.CHANGE_SPEED:
                self._apply_speed(item)
                self._reach(seq)
                self.current_seq += 1
                continue
            if kind == ItemKind.PAYLOAD:
                if not self._payload_noted:
                    self._payload_noted = True
                    self._note(m.MAV_SEVERITY_INFO, NO_PAYLOAD_TEXT)
                self._reach(seq)
                self.current_seq += 1
                continue
            if kind == ItemKind.JUMP:
                done = self._jumps.get(seq, 0)
                self._reach(seq)
                if done < item.jump_repeats:
                    self._jumps[seq] = done + 1
                    self.current_seq = item.jump_target
                else:
                    self.current_seq += 1
                continue
            if kind == ItemKind.RETURN_TO_LAUNCH:
                self._reach(seq)
                self.state = MissionState.COMPLETE
                self._leg = None
                self._pending = MissionAction.RTL
                return
            if kind == ItemKind.LAND:
                self._leg = self._land_leg(t, start, item, limits)
                return
            if self._on_ground and kind != ItemKind.TAKEOFF:
                self._on_ground = False
                target = (
                    start.position_m[0],
                    start.position_m[1],
                    ctx.home_local[2] + ctx.takeoff_altitude_m,
                )
                self._leg = _Leg(seq, self._climb(start, target, limits, None), t, implicit=True)
                return
            self._on_ground = False
            if kind == ItemKind.TAKEOFF:
                z = item.position.altitude_paper(self.origin, ctx.home_local) if item.position else math.nan
                if math.isnan(z):
                    z = ctx.home_local[2] + ctx.takeoff_altitude_m
                target = (start.position_m[0], start.position_m[1], z)
                trajectory = self._climb(start, target, limits, item.yaw_rad)
                self._leg = _Leg(seq, trajectory, t, target, ctx.acceptance_radius_m)
                return
            if kind in (ItemKind.WAYPOINT, ItemKind.LOITER_TIME):
                target = item.position.to_paper(self.origin, ctx.home_local)
                radius = item.acceptance_radius_m or ctx.acceptance_radius_m
                trajectory = self._move(start, target, limits, item.yaw_rad)
                self._leg = _Leg(seq, trajectory, t, target, radius, item.hold_s)
                return
            if kind == ItemKind.DELAY:
                pieces = self._brake(start, limits)
                end = _final(pieces[-1]) if pieces else start
                pieces.append(Hover(end.position_m, end.yaw_rad, duration_s=max(item.hold_s, 1e-3)))
                self._leg = _Leg(seq, PiecewiseTrajectory(pieces), t)
                return
            if kind == ItemKind.TIMED:
                self._leg = self._timed_leg(t, start, seq, limits)
                return
            raise AssertionError(f"unhandled item kind {kind}")

    def _climb(self, start: Reference, target: Vector3, limits: Limits, yaw: float | None) -> Trajectory:
        ctx = self._ctx
        assert ctx is not None
        climb = replace(limits, speed_up=min(limits.speed_up, ctx.takeoff_speed_m_s))
        return self._move(start, target, climb, yaw)

    def _land_leg(self, t: float, start: Reference, item: MissionItem, limits: Limits) -> _Leg:
        assert self._ctx is not None
        position = item.position
        if position is not None and position.horizontal_given:
            x, y, _ = position.to_paper(self.origin, self._ctx.home_local)
            target = (x, y, start.position_m[2])
            if math.dist(target, start.position_m) > 1e-3 or not _at_rest(start):
                trajectory = self._move(start, target, limits, item.yaw_rad)
                return _Leg(item.seq, trajectory, t, target, self._ctx.acceptance_radius_m,
                            action=MissionAction.LAND)  # fmt: skip
        # Land where the vehicle is: the commander's landing brakes from the measured state.
        return _Leg(
            item.seq, Hover(start.position_m, start.yaw_rad, duration_s=0.0), t, action=MissionAction.LAND
        )

    def _timed_leg(self, t: float, start: Reference, seq: int, limits: Limits) -> _Leg:
        ctx = self._ctx
        assert ctx is not None
        first, last = _timed_block(self.items, seq)
        block = self.items[first : last + 1]
        curve = TimedCurve(
            [it.time_s for it in block],
            [it.position.to_paper(self.origin, ctx.home_local) for it in block],
            [it.yaw_rad for it in block],
            default_yaw=start.yaw_rad,
            tolerance_m=_resolution(block),
        )
        item = self.items[seq]
        tau0 = item.time_s - curve.t0
        on_curve = curve.sample(tau0)
        join = approach(start, on_curve, limits)
        wait = 0.0
        if _at_rest(start):
            # Item times count from the mission start: do not arrive early.
            wait = max(self._mission_t0 + item.time_s - join.duration_s - t, 0.0)
        pieces: list[Trajectory] = []
        if wait > 0.0:
            pieces.append(Hover(start.position_m, start.yaw_rad, duration_s=wait))
        pieces += [join, _CurveFrom(curve, tau0)]
        offset = wait + join.duration_s
        timed = [(offset + self.items[s].time_s - item.time_s, s) for s in range(seq, last + 1)]
        # The leg's seq is the item after the curve: it becomes current when the curve ends.
        return _Leg(last + 1, PiecewiseTrajectory(pieces), t, timed=timed, moving_end=True)

    def _finish(self, t: float, start: Reference) -> None:
        """No items left: brake if moving, then hold (mission complete, mode unchanged)."""
        pieces = self._brake(start, self._limits())
        end = _final(pieces[-1]) if pieces else start
        pieces.append(Hover(end.position_m, end.yaw_rad))
        self._leg = _Leg(self.count - 1, PiecewiseTrajectory(pieces), t, implicit=True)
        self.current_seq = max(self.count - 1, 0)
        self.state = MissionState.COMPLETE
