"""Gust profiles: external forces, torques and wind as functions of simulation time.

A profile is a TOML file (``config/gusts/NAME.toml``) or the equivalent JSON object (uploads over
zenoh). Times are seconds from the profile's start (the simulator adds the start time it is told).

Channels: ``force_x``, ``force_y``, ``force_z`` (N, world frame, z up, applied at the CoM: the
[Ax, Ay, Az] of eq. 1) and ``torque_roll``, ``torque_pitch``, ``torque_yaw`` (N m on the Euler
coordinates: the [Ap, Aq, Ar] of eq. 4).

Elements (any mix, each an array of tables):

* ``[[step]]``: ``channel``, ``start_s``, ``value``, optional ``end_s`` (held to the end if absent);
* ``[[ramp]]``: ``channel``, ``start_s``, ``end_s``, ``value``: linear from 0 at ``start_s`` to
  ``value`` at ``end_s``, then held (optional ``hold_until_s`` ends it).

Values add up when elements overlap.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from quadcommon.config import config_path
from quadcommon.schema import ConfigError, Section, load_toml

Vector3 = tuple[float, float, float]
CHANNELS = ("force_x", "force_y", "force_z", "torque_roll", "torque_pitch", "torque_yaw")
MAX_FORCE_N = 100.0
MAX_TORQUE_N_M = 10.0


@dataclass(frozen=True)
class Step:
    channel: str
    start_s: float
    value: float
    end_s: float = math.inf


@dataclass(frozen=True)
class Ramp:
    channel: str
    start_s: float
    end_s: float
    value: float
    hold_until_s: float = math.inf


@dataclass(frozen=True)
class GustProfile:
    description: str = ""
    steps: tuple[Step, ...] = ()
    ramps: tuple[Ramp, ...] = field(default_factory=tuple)

    @property
    def is_empty(self) -> bool:
        return not (self.steps or self.ramps)

    def event_times(self) -> list[float]:
        """Instants where something starts (for marking figures)."""
        times = {s.start_s for s in self.steps} | {r.start_s for r in self.ramps}
        return sorted(times)


def _channel_value(sec: Section, channel: str) -> float:
    bound = MAX_FORCE_N if channel.startswith("force") else MAX_TORQUE_N_M
    unit = "N" if channel.startswith("force") else "N m"
    return sec.number("value", lo=-bound, hi=bound, unit=unit)


def parse_gust_profile(root: Section) -> GustProfile:
    """Validate a profile read as a :class:`Section` (from TOML or a JSON upload)."""
    description = root.string("description", "")
    steps = []
    for sec in root.sections("step"):
        channel = sec.choice("channel", CHANNELS)
        start = sec.number("start_s", lo=0.0, hi=1e6, unit="s")
        value = _channel_value(sec, channel)
        end = sec.number("end_s", lo=start, lo_open=True, hi=1e6, unit="s") if sec.has("end_s") else math.inf
        sec.finish()
        steps.append(Step(channel, start, value, end))
    ramps = []
    for sec in root.sections("ramp"):
        channel = sec.choice("channel", CHANNELS)
        start = sec.number("start_s", lo=0.0, hi=1e6, unit="s")
        end = sec.number("end_s", lo=start, lo_open=True, hi=1e6, unit="s")
        value = _channel_value(sec, channel)
        hold = sec.number("hold_until_s", lo=end, hi=1e6, unit="s") if sec.has("hold_until_s") else math.inf
        sec.finish()
        ramps.append(Ramp(channel, start, end, value, hold))
    root.finish()
    return GustProfile(description, tuple(steps), tuple(ramps))


def load_gust_profile(name_or_path: str | Path) -> GustProfile:
    """Load ``config/gusts/NAME.toml`` (or a path); ``""`` or ``"none"`` is the empty profile."""
    if name_or_path in ("", "none"):
        return GustProfile()
    return parse_gust_profile(load_toml(config_path("gusts", name_or_path)))


def gust_profile_from_mapping(data: Any, source: str = "uploaded profile") -> GustProfile:
    """Validate a profile given as a mapping (a parsed JSON upload)."""
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: a gust profile must be an object/table, got {type(data).__name__}")
    return parse_gust_profile(Section(data, source))


class DisturbanceSchedule:
    """Evaluates a profile at simulation time ``t``: (force_world, torque_euler, wind_world).

    ``start_time_s`` shifts the profile onto the simulator's clock.
    """

    def __init__(self, profile: GustProfile, start_time_s: float = 0.0) -> None:
        self.profile = profile
        self.start_time_s = start_time_s
        index = {c: i for i, c in enumerate(CHANNELS)}
        self._steps = [(index[s.channel], s.start_s, s.end_s, s.value) for s in profile.steps]
        self._ramps = [(index[r.channel], r.start_s, r.end_s, r.hold_until_s, r.value) for r in profile.ramps]
        times = {s.start_s for s in profile.steps} | {s.end_s for s in profile.steps}
        times |= {r.start_s for r in profile.ramps} | {r.end_s for r in profile.ramps}
        times |= {r.hold_until_s for r in profile.ramps}
        self._breakpoints = sorted(x for x in times if math.isfinite(x))
        self._valid_from = self._valid_until = math.nan  # empty cache
        self._cached: tuple[Vector3, Vector3, Vector3] = ((0.0,) * 3,) * 3  # type: ignore[assignment]

    def evaluate(self, t: float) -> tuple[Vector3, Vector3, Vector3]:
        """Disturbance at simulation time ``t``; constant stretches are served from a cache."""
        if self._valid_from <= t < self._valid_until:
            return self._cached
        tau = t - self.start_time_s
        values = [0.0] * 6
        ramping = False
        for channel, start, end, value in self._steps:
            if start <= tau < end:
                values[channel] += value
        for channel, start, end, hold, value in self._ramps:
            if start <= tau < hold:
                values[channel] += value * min((tau - start) / (end - start), 1.0)
                ramping = ramping or tau < end
        result = (
            (values[0], values[1], values[2]),
            (values[3], values[4], values[5]),
            (0.0, 0.0, 0.0),
        )
        if not ramping:
            i = bisect_right(self._breakpoints, tau)
            lo = self._breakpoints[i - 1] if i > 0 else -math.inf
            hi = self._breakpoints[i] if i < len(self._breakpoints) else math.inf
            self._valid_from = lo + self.start_time_s
            self._valid_until = hi + self.start_time_s
            self._cached = result
        return result
