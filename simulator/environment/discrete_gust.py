"""Discrete "1 - cosine" wind gust (MIL-F-8785C §3.7.4), specified in time for a hovering vehicle.

MIL-F-8785C defines the discrete gust by the distance x travelled into it::

    v(x) = (V_m / 2) (1 - cos(pi x / d_m))        0 <= x <= d_m

rising from 0 to the peak V_m over the gust length d_m (the specification then holds V_m). The
profile element here is the full bump: that rise followed by its mirror image, i.e. the same
formula for 0 <= x <= 2 d_m and zero outside (the "1-cos" gust of gust-load criteria with gust
gradient d_m). It is C1: value and slope are zero at both ends, the peak V_m is at x = d_m.
With x = V (t - start) it lasts ``duration_s = 2 d_m / V``, and in time::

    v(t) = (V_m / 2) (1 - cos(2 pi (t - start) / duration))     start <= t <= start + duration

It is a WIND (world frame, m/s): it acts through the plant's aerodynamic drag ``-k (v - wind)``,
not as a force (with the paper's drag coefficients of zero it has no effect on the vehicle).

Profile element (``[[one_minus_cosine]]``, any number):

* ``start_s``: profile time at which the gust begins, s;
* either ``duration_s`` (the whole bump, s), or ``length_m`` (d_m, the distance from onset to
  peak, m) with ``airspeed_m_s`` (V, m/s), giving ``duration_s = 2 length_m / airspeed_m_s``;
* ``amplitude_m_s``: the peak wind speed V_m, m/s (>= 0; the direction carries the sign);
* either ``direction``: a non-zero 3-vector in the world frame (paper axes: x forward/north,
  y left, z up), normalised here; or ``axis``: ``"x"``, ``"y"`` or ``"z"``.

Reference: MIL-F-8785C, Military Specification, Flying Qualities of Piloted Airplanes,
5 Nov 1980, §3.7.4 (discrete gust model).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from quadcommon.schema import ConfigError, Section

Vector3 = tuple[float, float, float]

MAX_TIME_S = 1e6
MIN_DURATION_S = 0.01  # ten physics steps at 1 kHz: shorter is not a resolvable bump
MAX_DURATION_S = 3600.0
MAX_AMPLITUDE_M_S = 50.0
MAX_LENGTH_M = 1e4
MAX_AIRSPEED_M_S = 100.0
AXES: dict[str, Vector3] = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0)}


@dataclass(frozen=True)
class OneMinusCosineGust:
    """A full 1-cos wind bump (validated). ``direction`` is kept as given; see :meth:`unit`."""

    start_s: float
    duration_s: float
    amplitude_m_s: float
    direction: Vector3

    @property
    def end_s(self) -> float:
        """When the gust is over (s of simulation time)."""
        return self.start_s + self.duration_s

    def unit(self) -> Vector3:
        """``direction`` normalised (the parser guarantees it is non-zero)."""
        x, y, z = self.direction
        n = math.sqrt(x * x + y * y + z * z)
        return (x / n, y / n, z / n)

    def speed(self, t_s: float) -> float:
        """Wind speed along :meth:`unit` at profile time ``t_s`` (m/s); zero outside the bump."""
        if not self.start_s <= t_s <= self.end_s:
            return 0.0
        phase = 2.0 * math.pi * (t_s - self.start_s) / self.duration_s
        return 0.5 * self.amplitude_m_s * (1.0 - math.cos(phase))


def parse_one_minus_cosine(sec: Section) -> OneMinusCosineGust:
    """Validate one ``[[one_minus_cosine]]`` table (keys in the module docstring)."""
    start = sec.number("start_s", lo=0.0, hi=MAX_TIME_S, unit="s")
    if sec.has("duration_s") and (sec.has("length_m") or sec.has("airspeed_m_s")):
        other = "length_m" if sec.has("length_m") else "airspeed_m_s"
        raise sec.error(
            other, sec.data[other], "either 'duration_s', or 'length_m' with 'airspeed_m_s', not both"
        )
    if sec.has("duration_s"):
        duration = sec.number("duration_s", lo=MIN_DURATION_S, hi=MAX_DURATION_S, unit="s")
    elif sec.has("length_m") or sec.has("airspeed_m_s"):
        length = sec.number("length_m", lo=0.0, lo_open=True, hi=MAX_LENGTH_M, unit="m")
        airspeed = sec.number("airspeed_m_s", lo=0.0, lo_open=True, hi=MAX_AIRSPEED_M_S, unit="m/s")
        duration = 2.0 * length / airspeed
        if not MIN_DURATION_S <= duration <= MAX_DURATION_S:
            raise sec.error(
                "length_m",
                length,
                f"2 length_m / airspeed_m_s (= {duration:g} s here) within "
                f"[{MIN_DURATION_S:g}, {MAX_DURATION_S:g}] s",
            )
    else:
        raise ConfigError(
            f"{sec.source}: missing key '{sec.key_name('duration_s')}'; give the bump's duration_s (s), "
            "or length_m (m) with airspeed_m_s (m/s)"
        )
    amplitude = sec.number("amplitude_m_s", lo=0.0, hi=MAX_AMPLITUDE_M_S, unit="m/s")
    if sec.has("direction") and sec.has("axis"):
        raise sec.error("axis", sec.data["axis"], "either 'direction' or 'axis', not both")
    if sec.has("axis"):
        direction = AXES[sec.choice("axis", tuple(AXES))]
    elif sec.has("direction"):
        direction = sec.vector("direction", 3, lo=-1e3, hi=1e3)
        if math.sqrt(sum(c * c for c in direction)) < 1e-9:
            raise sec.error(
                "direction",
                sec.data["direction"],
                "a non-zero 3-vector (world frame: x forward, y left, z up)",
            )
    else:
        raise ConfigError(
            f"{sec.source}: missing key '{sec.key_name('direction')}'; give direction = [x, y, z] "
            "(world frame, non-zero) or axis = 'x', 'y' or 'z'"
        )
    sec.finish()
    return OneMinusCosineGust(start, duration, amplitude, direction)  # type: ignore[arg-type]


def gust_to_mapping(g: OneMinusCosineGust) -> dict:
    """The ``[[one_minus_cosine]]`` table of ``g`` (JSON-ready; parses back to an equal record)."""
    return {
        "start_s": g.start_s,
        "duration_s": g.duration_s,
        "amplitude_m_s": g.amplitude_m_s,
        "direction": list(g.direction),
    }


def describe_direction(direction: Vector3) -> str:
    """``"+x"``, ``"-z"``... for an axis, else the unit vector."""
    x, y, z = direction
    n = math.sqrt(x * x + y * y + z * z)
    for name, axis in AXES.items():
        dot = (x * axis[0] + y * axis[1] + z * axis[2]) / n
        if abs(abs(dot) - 1.0) < 1e-12:
            return ("+" if dot > 0 else "-") + name
    return "[" + ", ".join(f"{c / n:.3g}" for c in direction) + "]"


def describe_gust(g: OneMinusCosineGust) -> str:
    """A one-line human description of ``g`` (amplitude, direction, start and duration), for logs and
    the CLI."""
    return (
        f"1-cos gust {g.amplitude_m_s:g} m/s along {describe_direction(g.direction)} "
        f"at {g.start_s:g} s for {g.duration_s:g} s"
    )
