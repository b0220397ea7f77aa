"""Gust profiles: external forces, torques and wind as functions of simulation time.

A profile is a TOML file (``config/gusts/NAME.toml``) or the equivalent JSON object (uploads over
zenoh, :mod:`simulator.environment.gust_upload`). Times are seconds from the profile's start (the
simulator adds the start time it is told: ``DisturbanceSchedule(start_time_s=...)``).

Force/torque channels: ``force_x``, ``force_y``, ``force_z`` (N, world frame, z up, applied at
the CoM: the [Ax, Ay, Az] of eq. 1) and ``torque_roll``, ``torque_pitch``, ``torque_yaw`` (N m on
the Euler coordinates: the [Ap, Aq, Ar] of eq. 4).

Elements (any mix):

* ``[[step]]``: ``channel``, ``start_s``, ``value``, optional ``end_s`` (held to the end if absent);
* ``[[ramp]]``: ``channel``, ``start_s``, ``end_s``, ``value``: linear from 0 at ``start_s`` to
  ``value`` at ``end_s``, then held (optional ``hold_until_s`` ends it);
* ``[[one_minus_cosine]]``: a discrete 1-cos WIND gust (MIL-F-8785C), see
  :mod:`simulator.environment.discrete_gust`;
* ``[dryden]`` (at most one): continuous Dryden turbulence WIND (MIL-F-8785C low altitude) plus an
  optional mean wind, see :mod:`simulator.environment.dryden`.

Wind (m/s, world frame) acts through the plant's linear drag ``-k (v_O - wind)``; with the paper's
drag coefficients (0) it has no effect. Values of all elements add up when they overlap. At most
``MAX_ELEMENTS`` elements of each kind (the schedule loops over them at every physics step).
"""

from __future__ import annotations

import math
from bisect import bisect_right
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from quadcommon.config import config_path
from quadcommon.kernel import kernel
from quadcommon.schema import ConfigError, Section, load_toml

from .discrete_gust import OneMinusCosineGust, describe_gust, gust_to_mapping, parse_one_minus_cosine
from .dryden import DrydenTurbulence, DrydenWind, describe_dryden, dryden_to_mapping, parse_dryden

Vector3 = tuple[float, float, float]
CHANNELS = ("force_x", "force_y", "force_z", "torque_roll", "torque_pitch", "torque_yaw")
MAX_FORCE_N = 100.0
MAX_TORQUE_N_M = 10.0
MAX_ELEMENTS = 256  # per kind: bounds the per-step cost of an uploaded profile
DEFAULT_STEP_S = 1e-3  # the simulator's default physics step (1 kHz)
_ZERO3: Vector3 = (0.0, 0.0, 0.0)


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
    one_minus_cosine: tuple[OneMinusCosineGust, ...] = ()
    dryden: DrydenTurbulence | None = None

    @property
    def is_empty(self) -> bool:
        """No steps, ramps, 1-cos gusts or Dryden turbulence: the profile adds no wind."""
        return not (self.steps or self.ramps or self.one_minus_cosine or self.dryden)

    def event_times(self) -> list[float]:
        """Instants where something starts (for marking figures)."""
        times = {s.start_s for s in self.steps} | {r.start_s for r in self.ramps}
        times |= {g.start_s for g in self.one_minus_cosine}
        if self.dryden is not None:
            times.add(self.dryden.start_s)
        return sorted(times)


def _channel_value(sec: Section, channel: str) -> float:
    bound = MAX_FORCE_N if channel.startswith("force") else MAX_TORQUE_N_M
    unit = "N" if channel.startswith("force") else "N m"
    return sec.number("value", lo=-bound, hi=bound, unit=unit)


def _element_tables(root: Section, key: str) -> list[Section]:
    tables = root.sections(key)
    if len(tables) > MAX_ELEMENTS:
        raise ConfigError(
            f"{root.source}: key '{root.key_name(key)}' has {len(tables)} entries; "
            f"allowed: at most {MAX_ELEMENTS}"
        )
    return tables


def parse_gust_profile(root: Section) -> GustProfile:
    """Validate a profile read as a :class:`Section` (from TOML or a JSON upload)."""
    description = root.string("description", "")
    steps = []
    for sec in _element_tables(root, "step"):
        channel = sec.choice("channel", CHANNELS)
        start = sec.number("start_s", lo=0.0, hi=1e6, unit="s")
        value = _channel_value(sec, channel)
        end = sec.number("end_s", lo=start, lo_open=True, hi=1e6, unit="s") if sec.has("end_s") else math.inf
        sec.finish()
        steps.append(Step(channel, start, value, end))
    ramps = []
    for sec in _element_tables(root, "ramp"):
        channel = sec.choice("channel", CHANNELS)
        start = sec.number("start_s", lo=0.0, hi=1e6, unit="s")
        end = sec.number("end_s", lo=start, lo_open=True, hi=1e6, unit="s")
        value = _channel_value(sec, channel)
        hold = sec.number("hold_until_s", lo=end, hi=1e6, unit="s") if sec.has("hold_until_s") else math.inf
        sec.finish()
        ramps.append(Ramp(channel, start, end, value, hold))
    gusts = tuple(parse_one_minus_cosine(sec) for sec in _element_tables(root, "one_minus_cosine"))
    # [dryden] is one table; an array of tables ([[dryden]]) is refused by section() ("a table").
    dryden = parse_dryden(root.section("dryden")) if root.has("dryden") else None
    root.finish()
    return GustProfile(description, tuple(steps), tuple(ramps), gusts, dryden)


def load_gust_profile(name_or_path: str | Path) -> GustProfile:
    """Load ``config/gusts/NAME.toml`` (or a path); ``""`` or ``"none"`` is the empty profile."""
    if name_or_path in ("", "none"):
        return GustProfile()
    return parse_gust_profile(load_toml(config_path("gusts", name_or_path)))


def gust_profile_from_mapping(data: Any, source: str = "uploaded profile", prefix: str = "") -> GustProfile:
    """Validate a profile given as a mapping (a parsed JSON upload, or a TOML file's table).

    ``prefix`` is prepended to key names in error messages (e.g. ``"profile."`` when the
    profile is the ``profile`` member of an upload request).
    """
    if not isinstance(data, dict):
        where = f" key '{prefix.rstrip('.')}'" if prefix else ""
        raise ConfigError(
            f"{source}:{where} a gust profile must be an object/table, got {type(data).__name__}"
        )
    return parse_gust_profile(Section(data, source, prefix))


def profile_to_mapping(profile: GustProfile) -> dict[str, Any]:
    """The profile as a JSON/TOML-ready mapping that :func:`gust_profile_from_mapping` reads back
    to an equal :class:`GustProfile` (infinite end times are left out, as in the files)."""
    out: dict[str, Any] = {}
    if profile.description:
        out["description"] = profile.description
    if profile.steps:
        out["step"] = []
        for s in profile.steps:
            item: dict[str, Any] = {"channel": s.channel, "start_s": s.start_s, "value": s.value}
            if math.isfinite(s.end_s):
                item["end_s"] = s.end_s
            out["step"].append(item)
    if profile.ramps:
        out["ramp"] = []
        for r in profile.ramps:
            item = {"channel": r.channel, "start_s": r.start_s, "end_s": r.end_s, "value": r.value}
            if math.isfinite(r.hold_until_s):
                item["hold_until_s"] = r.hold_until_s
            out["ramp"].append(item)
    if profile.one_minus_cosine:
        out["one_minus_cosine"] = [gust_to_mapping(g) for g in profile.one_minus_cosine]
    if profile.dryden is not None:
        out["dryden"] = dryden_to_mapping(profile.dryden)
    return out


def _plural(n: int, word: str) -> str:
    return f"{n} {word}{'' if n == 1 else 's'}"


def describe(profile: GustProfile, max_chars: int = 400) -> str:
    """One-line summary of ``profile`` (for upload acknowledgements and logs)."""
    parts = []
    if profile.steps:
        parts.append(_plural(len(profile.steps), "step"))
    if profile.ramps:
        parts.append(_plural(len(profile.ramps), "ramp"))
    gusts = profile.one_minus_cosine
    if 0 < len(gusts) <= 2:
        parts.extend(describe_gust(g) for g in gusts)
    elif gusts:
        first = min(g.start_s for g in gusts)
        last = max(g.end_s for g in gusts)
        peak = max(g.amplitude_m_s for g in gusts)
        parts.append(f"{len(gusts)} 1-cos gusts from {first:g} s to {last:g} s, up to {peak:g} m/s")
    if profile.dryden is not None:
        parts.append(describe_dryden(profile.dryden))
    text = "; ".join(parts) if parts else "empty profile (no disturbance)"
    if profile.description:
        text = " ".join(profile.description.split()) + ": " + text
    return text if len(text) <= max_chars else text[: max_chars - 3] + "..."


# The profile's elements as rows of numbers (what DisturbanceSchedule and the campaign engine
# evaluate), each kind in one flat table of rows of its width. Channels index CHANNELS (force x,
# y, z, torque on phi, theta, psi).
STEP_WIDTH = 4  # channel, start, end, value
RAMP_WIDTH = 5  # channel, start, end, hold until, value
GUST_WIDTH = 7  # start, end, V_m / 2, 2 pi / duration, unit direction (3)


def element_rows(profile: GustProfile) -> tuple[list[float], list[float], list[float]]:
    """The steps, ramps and 1-cos gusts as flat tables, one row of ``*_WIDTH`` numbers after the
    other: what :func:`steps_and_ramps` and :func:`one_minus_cosine_wind` read (a flat sequence
    indexes cheaply both as a Python list and as a compiled array; a row view per element does not)."""
    index = {c: i for i, c in enumerate(CHANNELS)}
    steps = [float(x) for s in profile.steps for x in (index[s.channel], s.start_s, s.end_s, s.value)]
    ramps = [float(x) for r in profile.ramps
             for x in (index[r.channel], r.start_s, r.end_s, r.hold_until_s, r.value)]  # fmt: skip
    gusts = [float(x) for g in profile.one_minus_cosine
             for x in (g.start_s, g.end_s, 0.5 * g.amplitude_m_s, 2.0 * math.pi / g.duration_s,
                       *g.unit())]  # fmt: skip
    return steps, ramps, gusts


@kernel
def steps_and_ramps(tau, steps, ramps):
    """The steps' and ramps' sum at profile time ``tau`` (flat tables of :func:`element_rows`):
    force (3), torque (3), and whether a ramp is still rising (the sum is not constant until the
    next breakpoint)."""
    v0 = v1 = v2 = v3 = v4 = v5 = 0.0
    ramping = False
    n_steps = len(steps) // STEP_WIDTH
    for k in range(n_steps + len(ramps) // RAMP_WIDTH):
        if k < n_steps:  # a step: its value over [start, end)
            i = k * STEP_WIDTH
            if not steps[i + 1] <= tau < steps[i + 2]:
                continue
            channel, value = steps[i], steps[i + 3]
        else:  # a ramp: up from start to end, held until its hold time
            i = (k - n_steps) * RAMP_WIDTH
            start, end = ramps[i + 1], ramps[i + 2]
            if not start <= tau < ramps[i + 3]:
                continue
            channel, value = ramps[i], ramps[i + 4] * min((tau - start) / (end - start), 1.0)
            if tau < end:
                ramping = True
        if channel == 0.0:
            v0 += value
        elif channel == 1.0:
            v1 += value
        elif channel == 2.0:
            v2 += value
        elif channel == 3.0:
            v3 += value
        elif channel == 4.0:
            v4 += value
        else:
            v5 += value
    return v0, v1, v2, v3, v4, v5, ramping


@kernel
def one_minus_cosine_wind(tau, gusts):
    """The 1-cos gusts' wind at profile time ``tau`` (m/s, world; a flat table of
    :func:`element_rows`), and whether one is active."""
    wx = wy = wz = 0.0
    active = False
    for i in range(0, len(gusts), GUST_WIDTH):
        start = gusts[i]
        if start <= tau < gusts[i + 1]:
            speed = gusts[i + 2] * (1.0 - math.cos(gusts[i + 3] * (tau - start)))
            wx += speed * gusts[i + 4]
            wy += speed * gusts[i + 5]
            wz += speed * gusts[i + 6]
            active = True
    return wx, wy, wz, active


class DisturbanceSchedule:
    """Evaluates a profile at simulation time ``t``: (force_world, torque_euler, wind_world).

    ``start_time_s`` shifts the profile onto the simulator's clock; ``step_s`` is the step at
    which the simulator evaluates it (its physics step, 1 ms by default), the sampling step of
    the Dryden turbulence.

    Constant stretches (no ramp rising, no 1-cos gust or Dryden turbulence active) are served
    from a cache. The Dryden wind is a function of the step index
    ``round((t - start_time_s - dryden.start_s) / step_s)``; its generator only runs forward, so
    while it is active ``evaluate`` must be called with non-decreasing ``t`` (calling twice at
    the same ``t`` is fine), else it raises
    :class:`~simulator.environment.dryden.TurbulenceOrderError`. The same profile, seed, start
    time and step give the same values, whatever the times evaluated in between.
    """

    def __init__(
        self, profile: GustProfile, start_time_s: float = 0.0, step_s: float = DEFAULT_STEP_S
    ) -> None:
        self.profile = profile
        self.start_time_s = start_time_s
        self.step_s = step_s
        self._steps, self._ramps, self._gusts = element_rows(profile)
        ft_times = {s.start_s for s in profile.steps} | {s.end_s for s in profile.steps}
        ft_times |= {r.start_s for r in profile.ramps} | {r.end_s for r in profile.ramps}
        ft_times |= {r.hold_until_s for r in profile.ramps}
        wind_times = {g.start_s for g in profile.one_minus_cosine} | {
            g.end_s for g in profile.one_minus_cosine
        }
        d = profile.dryden
        self._dryden = DrydenWind(d, step_s) if d is not None else None
        self._dryden_from = d.start_s if d is not None else math.inf
        self._dryden_until = d.end_s if d is not None else math.inf
        self._dryden_t0 = start_time_s + self._dryden_from
        if d is not None:
            wind_times |= {d.start_s, d.end_s}
        self._ft_breakpoints = sorted(x for x in ft_times if math.isfinite(x))
        self._breakpoints = sorted(x for x in ft_times | wind_times if math.isfinite(x))
        # Two caches: the whole result over stretches where nothing changes, and the
        # force/torque part alone (so a turbulent wind does not re-run the step loops).
        self._valid_from = self._valid_until = math.nan  # empty caches
        self._cached: tuple[Vector3, Vector3, Vector3] = (_ZERO3, _ZERO3, _ZERO3)
        self._ft_from = self._ft_until = math.nan
        self._ft: tuple[Vector3, Vector3] = (_ZERO3, _ZERO3)

    @staticmethod
    def _window(breakpoints: list[float], tau: float) -> tuple[float, float]:
        i = bisect_right(breakpoints, tau)
        lo = breakpoints[i - 1] if i > 0 else -math.inf
        hi = breakpoints[i] if i < len(breakpoints) else math.inf
        return lo, hi

    def _forces_torques(self, tau: float) -> tuple[Vector3, Vector3, bool]:
        """Sum of steps and ramps at profile time ``tau``; True when constant until the next breakpoint."""
        f0, f1, f2, t0, t1, t2, ramping = steps_and_ramps(tau, self._steps, self._ramps)
        return (f0, f1, f2), (t0, t1, t2), not ramping

    def evaluate(self, t: float) -> tuple[Vector3, Vector3, Vector3]:
        """Disturbance at simulation time ``t`` (s): force (N, world), torque (N m, Euler
        coordinates), wind (m/s, world). Constant stretches are served from a cache."""
        if self._valid_from <= t < self._valid_until:
            return self._cached
        tau = t - self.start_time_s
        if self._ft_from <= t < self._ft_until:
            force, torque = self._ft
            ft_constant = True
        else:
            force, torque, ft_constant = self._forces_torques(tau)
            if ft_constant:
                lo, hi = self._window(self._ft_breakpoints, tau)
                self._ft_from = lo + self.start_time_s
                self._ft_until = hi + self.start_time_s
                self._ft = (force, torque)
        wx, wy, wz, gusting = one_minus_cosine_wind(tau, self._gusts)
        wind_constant = not gusting
        if self._dryden_from <= tau < self._dryden_until:
            # Step index of the turbulence (rounded: t carries float error from k * dt sums).
            n = int(math.floor((t - self._dryden_t0) / self.step_s + 0.5))
            dx, dy, dz = self._dryden.at_step(n if n > 0 else 0)  # type: ignore[union-attr]
            wx += dx
            wy += dy
            wz += dz
            wind_constant = False
        result = (force, torque, (wx, wy, wz))
        if ft_constant and wind_constant:
            lo, hi = self._window(self._breakpoints, tau)
            self._valid_from = lo + self.start_time_s
            self._valid_until = hi + self.start_time_s
            self._cached = result
        return result
