"""Reference trajectories with analytic derivatives: p_d, p_d', p_d'' and the yaw reference.

Pure: functions of time only. Every trajectory answers ``sample(t) -> Reference``; the
translational laws need up to p_d'' (eq. 28), the yaw channel psi_d, psi_d', psi_d''.

* :class:`HarmonicTrajectory`: per axis ``offset + amplitude cos(w t + phase) + rate t``; the
  paper's circle and helix (Section IV) are instances (:func:`trajectory_from_spec`).
* :class:`QuinticSegment`: a C2 segment between two (p, v, a) states (minimum-jerk form), the
  building block of smooth waypoint missions.
* :class:`PiecewiseTrajectory`: segments back to back on one time axis.
"""

from __future__ import annotations

import math
from bisect import bisect_right
from collections.abc import Sequence
from typing import NamedTuple, Protocol

from .config import TrajectorySpec

Vector3 = tuple[float, float, float]
ZERO3: Vector3 = (0.0, 0.0, 0.0)


class Reference(NamedTuple):
    """Desired state at one instant (paper frames, SI units)."""

    position_m: Vector3
    velocity_m_s: Vector3
    acceleration_m_s2: Vector3
    yaw_rad: float = 0.0
    yaw_rate_rad_s: float = 0.0
    yaw_acceleration_rad_s2: float = 0.0


class Trajectory(Protocol):
    duration_s: float

    def sample(self, t: float) -> Reference:
        """The reference at ``t`` (s from the trajectory's start): position, velocity, acceleration, yaw."""
        ...


class HarmonicTrajectory:
    """``p_i(t) = offset_i + amplitude_i cos(w t + phase_i) + rate_i t`` with constant yaw.

    Derivatives are exact: ``p' = -A w sin(.) + rate``, ``p'' = -A w^2 cos(.)``.
    """

    def __init__(
        self,
        offset: Vector3,
        amplitude: Vector3,
        phase: Vector3,
        rate: Vector3,
        angular_rate: float,
        yaw: float = 0.0,
        duration_s: float = math.inf,
    ) -> None:
        self.offset, self.amplitude, self.phase, self.rate = offset, amplitude, phase, rate
        self.w = angular_rate
        self.yaw = yaw
        self.duration_s = duration_s

    def sample(self, t: float) -> Reference:
        """The reference at ``t`` (s from the start), the harmonic path and its first two derivatives."""
        # (sampled at every control step: the three axes written out, the same arithmetic per axis)
        w = self.w
        (ox, oy, oz), (ax, ay, az) = self.offset, self.amplitude
        (px, py, pz), (rx, ry, rz) = self.phase, self.rate
        cx, sx = math.cos(w * t + px), math.sin(w * t + px)
        cy, sy = math.cos(w * t + py), math.sin(w * t + py)
        cz, sz = math.cos(w * t + pz), math.sin(w * t + pz)
        return Reference(
            (ox + ax * cx + rx * t, oy + ay * cy + ry * t, oz + az * cz + rz * t),
            (-ax * w * sx + rx, -ay * w * sy + ry, -az * w * sz + rz),
            (-ax * w * w * cx, -ay * w * w * cy, -az * w * w * cz),
            self.yaw, 0.0, 0.0,
        )  # fmt: skip


def circle(
    radius_m: float,
    angular_rate_rad_s: float,
    center_m: Vector3,
    vertical_amplitude_m: float,
    yaw_rad: float = 0.0,
) -> HarmonicTrajectory:
    """Section IV circle: ``x = cx + r cos(w t)``, ``y = cy + r sin(w t)``, ``z = cz + A cos(w t)``.

    The paper's: r = 1/2, w = pi/20, c = (0, 0, 2.5), A = -2.
    """
    return HarmonicTrajectory(
        offset=center_m,
        amplitude=(radius_m, radius_m, vertical_amplitude_m),
        phase=(0.0, -0.5 * math.pi, 0.0),
        rate=ZERO3,
        angular_rate=angular_rate_rad_s,
        yaw=yaw_rad,
    )


def helix(
    radius_m: float,
    angular_rate_rad_s: float,
    center_m: Vector3,
    climb_rate_m_s: float,
    yaw_rad: float = 0.0,
) -> HarmonicTrajectory:
    """Vertical helix: ``x = cx + r cos(w t)``, ``y = cy + r sin(w t)``, ``z = cz + v_z t``."""
    return HarmonicTrajectory(
        offset=center_m,
        amplitude=(radius_m, radius_m, 0.0),
        phase=(0.0, -0.5 * math.pi, 0.0),
        rate=(0.0, 0.0, climb_rate_m_s),
        angular_rate=angular_rate_rad_s,
        yaw=yaw_rad,
    )


class Hover:
    """Hold a position and yaw."""

    def __init__(self, position_m: Vector3, yaw_rad: float = 0.0, duration_s: float = math.inf):
        self.reference = Reference(position_m, ZERO3, ZERO3, yaw_rad, 0.0, 0.0)
        self.duration_s = duration_s

    def sample(self, t: float) -> Reference:
        """The reference at any ``t``: the hover point, at rest."""
        return self.reference


def trajectory_from_spec(spec: TrajectorySpec) -> Trajectory:
    """The analytic trajectory a scenario names."""
    if spec.kind == "circle":
        return circle(
            spec.radius_m,
            spec.angular_rate_rad_s,
            spec.center_m,
            spec.vertical_amplitude_m,
            spec.yaw_rad,
        )
    if spec.kind == "helix":
        return helix(spec.radius_m, spec.angular_rate_rad_s, spec.center_m, spec.climb_rate_m_s, spec.yaw_rad)
    if spec.kind == "hover":
        return Hover(spec.center_m, spec.yaw_rad)
    raise ValueError(f"unknown trajectory kind {spec.kind!r}")


class QuinticSegment:
    """C2 segment from ``(p0, v0, a0)`` to ``(p1, v1, a1)`` over ``duration_s``, per axis a quintic.

    Yaw moves with the same quintic blend from ``yaw0`` to ``yaw1`` (shortest way round).
    """

    def __init__(
        self,
        duration_s: float,
        p0: Vector3,
        p1: Vector3,
        v0: Vector3 = ZERO3,
        v1: Vector3 = ZERO3,
        a0: Vector3 = ZERO3,
        a1: Vector3 = ZERO3,
        yaw0: float = 0.0,
        yaw1: float = 0.0,
    ) -> None:
        if not duration_s > 0.0:
            raise ValueError(f"segment duration must be > 0 s, got {duration_s}")
        self.duration_s = duration_s
        T = duration_s
        self.coeffs = [quintic_coefficients(p0[i], v0[i], a0[i], p1[i], v1[i], a1[i], T) for i in range(3)]
        dyaw = (yaw1 - yaw0 + math.pi) % (2.0 * math.pi) - math.pi
        self.yaw_coeffs = quintic_coefficients(yaw0, 0.0, 0.0, yaw0 + dyaw, 0.0, 0.0, T)

    def sample(self, t: float) -> Reference:
        """The reference at ``t`` (clamped to the segment): the quintic's position, velocity,
        acceleration and yaw."""
        t = min(max(t, 0.0), self.duration_s)
        pos, vel, acc = [], [], []
        for c in self.coeffs:
            p, v, a = eval_quintic(c, t)
            pos.append(p)
            vel.append(v)
            acc.append(a)
        y, yd, ydd = eval_quintic(self.yaw_coeffs, t)
        y = (y + math.pi) % (2.0 * math.pi) - math.pi
        return Reference(tuple(pos), tuple(vel), tuple(acc), y, yd, ydd)  # type: ignore[arg-type]


def quintic_coefficients(p0, v0, a0, p1, v1, a1, T):
    """Coefficients c0..c5 of p(t) = sum c_k t^k meeting p, p', p'' at t = 0 and t = T."""
    T2, T3, T4, T5 = T * T, T**3, T**4, T**5
    c0, c1, c2 = p0, v0, 0.5 * a0
    d = p1 - (c0 + c1 * T + c2 * T2)
    dv = v1 - (c1 + 2.0 * c2 * T)
    da = a1 - 2.0 * c2
    c3 = (10.0 * d - 4.0 * dv * T + 0.5 * da * T2) / T3
    c4 = (-15.0 * d + 7.0 * dv * T - da * T2) / T4
    c5 = (6.0 * d - 3.0 * dv * T + 0.5 * da * T2) / T5
    return (c0, c1, c2, c3, c4, c5)


def eval_quintic(c, t):
    """``(p, p', p'')`` at ``t`` of the quintic with coefficients ``c0..c5`` (Horner's rule)."""
    c0, c1, c2, c3, c4, c5 = c
    p = c0 + t * (c1 + t * (c2 + t * (c3 + t * (c4 + t * c5))))
    v = c1 + t * (2.0 * c2 + t * (3.0 * c3 + t * (4.0 * c4 + t * 5.0 * c5)))
    a = 2.0 * c2 + t * (6.0 * c3 + t * (12.0 * c4 + t * 20.0 * c5))
    return p, v, a


class PiecewiseTrajectory:
    """Trajectories laid end to end; after the last one ends its final reference is held."""

    def __init__(self, pieces: Sequence[Trajectory]) -> None:
        if not pieces:
            raise ValueError("a piecewise trajectory needs at least one piece")
        self.pieces = list(pieces)
        self.starts = []
        t = 0.0
        for piece in self.pieces:
            self.starts.append(t)
            t += piece.duration_s
        self.duration_s = t

    def sample(self, t: float) -> Reference:
        """The reference at ``t``: the piece that holds ``t``, sampled at the time since its start."""
        i = max(bisect_right(self.starts, t) - 1, 0)
        piece = self.pieces[i]
        local = t - self.starts[i]
        if local > piece.duration_s:  # past the end: hold the final point at rest
            ref = piece.sample(piece.duration_s)
            return Reference(ref.position_m, ZERO3, ZERO3, ref.yaw_rad, 0.0, 0.0)
        return piece.sample(local)
