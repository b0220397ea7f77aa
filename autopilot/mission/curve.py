"""Timed trajectory samples -> a smooth curve in time with p, p', p'' and yaw (pure).

A ground station uploads a densely sampled curve as timed items (``WAYPOINT_USER_1``, param1 =
time). The wire quantises the samples: MISSION_ITEM_INT carries local x and y as int32 in units of
0.1 mm, and an interpolating spline turns that quantisation into derivative noise (measured on the
paper's circle sampled at 10 Hz: 0.2 m/s^2 of acceleration error from a quintic interpolant, for a
curve whose true acceleration is 0.05 m/s^2). So the curve is a least-squares quintic B-spline
(C4: p'' is twice continuously differentiable) with the coarsest knot spacing, tried from 4 s down
to 3 sample intervals, that still passes within one wire quantum (0.1 mm; yaw 1 mrad) of every
sample; if none does (fast or sparsely sampled curves), the quintic interpolant through the
samples. On the paper's circle and helix sampled at 2-50 Hz the result is within 0.06 mm,
0.5 mm/s and 2 mm/s^2 of the analytic curve. Fewer than 6 samples: a natural cubic spline (C2).
"""

from __future__ import annotations

import math
import os
import sys
import threading
from collections.abc import Sequence

import numpy as np

from quadcommon.trajectories import Reference

Vector3 = tuple[float, float, float]
ZERO3: Vector3 = (0.0, 0.0, 0.0)
POSITION_TOLERANCE_M = 1e-4  # one MISSION_ITEM_INT local-frame quantum (x, y, z)
GLOBAL_TOLERANCE_M = (0.012, 0.012, 1e-4)  # global frames: 1e-7 deg is up to 1.1 cm (x, y, z)
YAW_TOLERANCE_RAD = 1e-3
KNOT_SPACINGS_S = (4.0, 2.0, 1.0, 0.5, 0.25)
MIN_SAMPLES_PER_KNOT = 3


def _lsq_knots(times: np.ndarray, spacing: float, k: int) -> np.ndarray | None:
    span = times[-1] - times[0]
    count = int(math.floor(span / spacing))
    if count < 1:
        return None
    inner = times[0] + spacing * np.arange(1, count)
    if inner.size and times[-1] - inner[-1] < 0.5 * spacing:
        inner = inner[:-1]  # no sliver of an interval at the end
    return np.r_[[times[0]] * (k + 1), inner, [times[-1]] * (k + 1)]


_loader: threading.Thread | None = None


def preload() -> None:
    """Start importing scipy.interpolate (~0.13 s of CPU beyond the scipy.linalg numba loads
    anyway; only a timed mission needs it), in a thread of its own so the lockstep loop goes on.

    The mission service calls it when an upload begins (MISSION_COUNT): the items then take a
    round trip each, and a fit at the end of the upload that comes before the import is done waits
    for it (Python's import lock). Not at every start: most autopilots never fly a timed mission,
    and the import is about an eighth of an autopilot core's start-up CPU.
    """
    global _loader
    if _loader is None and "scipy.interpolate" not in sys.modules:
        _loader = threading.Thread(target=_import_interpolate, name="import scipy.interpolate", daemon=True)
        _loader.start()


def _finish_loading() -> None:
    """Before a fork: a child forked while another thread holds an import lock would wait for it
    forever (that thread does not exist in the child). A process pool forks (sitl/paper.py)."""
    if _loader is not None and _loader.is_alive():
        _loader.join()


os.register_at_fork(before=_finish_loading)


def _import_interpolate() -> None:
    try:
        import scipy.interpolate  # noqa: F401
    except Exception:  # noqa: BLE001 - the fit imports it again: the upload is refused with the reason
        pass


def fit_curve(
    times: np.ndarray,
    values: np.ndarray,
    tolerance_m: tuple[float, float, float] = (POSITION_TOLERANCE_M,) * 3,
):
    """A spline through ``values`` (n x 4: x, y, z, unwrapped yaw) at ``times`` (s, increasing),
    within ``tolerance_m`` (per axis, m) of every sample; callable as ``spline(t, nu)``."""
    # Imported here: only a timed mission needs scipy.interpolate (see preload).
    from scipy.interpolate import CubicSpline, make_interp_spline, make_lsq_spline

    n = len(times)
    if n < 6:
        return CubicSpline(times, values, bc_type="natural")
    h = float(np.median(np.diff(times)))
    tolerance = np.array([*tolerance_m, YAW_TOLERANCE_RAD])
    for spacing in KNOT_SPACINGS_S:
        if spacing < MIN_SAMPLES_PER_KNOT * h:
            break
        knots = _lsq_knots(times, spacing, 5)
        if knots is None:
            continue
        try:
            spline = make_lsq_spline(times, values, knots, k=5)
        except (ValueError, np.linalg.LinAlgError):
            continue  # knots that the samples do not support (Schoenberg-Whitney): try finer
        if np.all(np.abs(spline(times) - values) <= tolerance):
            return spline
    return make_interp_spline(times, values, k=5)


class TimedCurve:
    """The timed samples ``times`` (s), ``positions`` (paper frame, m), ``yaws`` (rad, paper
    frame; None entries are filled with the previous yaw, or ``default_yaw`` at the start) as a
    trajectory: ``sample(tau)`` with ``tau`` in seconds from the first sample. ``tolerance_m``:
    the samples' resolution per axis (m), which the fit may deviate by."""

    def __init__(
        self,
        times: Sequence[float],
        positions: Sequence[Vector3],
        yaws: Sequence[float | None],
        default_yaw: float = 0.0,
        tolerance_m: tuple[float, float, float] = (POSITION_TOLERANCE_M,) * 3,
    ) -> None:
        t = np.asarray(times, dtype=float)
        if t.ndim != 1 or t.size == 0 or np.any(np.diff(t) <= 0.0):
            raise ValueError("timed samples need strictly increasing times")
        filled = []
        last = default_yaw
        for yaw in yaws:
            last = last if yaw is None else yaw
            filled.append(last)
        values = np.column_stack(
            [np.asarray(positions, dtype=float), np.unwrap(np.asarray(filled, dtype=float))]
        )
        self.t0 = float(t[0])
        self.times = t - self.t0
        self.duration_s = float(self.times[-1])
        self._constant = values[0] if t.size == 1 else None
        if self._constant is None:
            spline = fit_curve(self.times, values, tolerance_m)
            self._p = spline
            self._v = spline.derivative(1)
            self._a = spline.derivative(2)
            self._pieces = _Pieces(spline)

    def sample(self, tau: float) -> Reference:
        """p_d, p_d', p_d'' and yaw at ``tau`` seconds after the first sample (clamped to the curve)."""
        if self._constant is not None:
            c = self._constant
            return Reference((c[0], c[1], c[2]), ZERO3, ZERO3, _wrap(c[3]), 0.0, 0.0)
        tau = min(max(tau, 0.0), self.duration_s)
        (px, py, pz, pyaw), (vx, vy, vz, vyaw), (ax, ay, az, ayaw) = self._pieces.evaluate(tau)
        return Reference((px, py, pz), (vx, vy, vz), (ax, ay, az), _wrap(pyaw), vyaw, ayaw)

    def peaks(self, samples_per_s: float = 50.0) -> tuple[float, float, float, float]:
        """(max horizontal speed, max climb rate, max descent rate, max |acceleration|) over the curve."""
        if self._constant is not None:
            return (0.0, 0.0, 0.0, 0.0)
        tau = np.linspace(0.0, self.duration_s, max(int(self.duration_s * samples_per_s), 2) + 1)
        v, a = self._v(tau), self._a(tau)
        return (
            float(np.hypot(v[:, 0], v[:, 1]).max()),
            float(max(v[:, 2].max(), 0.0)),
            float(max(-v[:, 2].min(), 0.0)),
            float(np.linalg.norm(a[:, :3], axis=1).max()),
        )


class _Pieces:
    """The spline as one polynomial per knot interval (Taylor coefficients at its left end, from the
    spline's own derivatives there), evaluated with Horner's scheme in plain floats: p, p', p'' for
    the four channels in one pass. Why: the control loop samples the curve every step, and three
    scipy calls (p, p', p'') cost ~25 µs of a ~100 µs lockstep frame; this costs a few. Equal to
    the spline to rounding (tests/autopilot/mission/test_mission_curve.py)."""

    def __init__(self, spline) -> None:
        if hasattr(spline, "c") and hasattr(spline, "x"):  # CubicSpline: a PPoly already
            breaks, coefficients = np.asarray(spline.x, dtype=float), np.asarray(spline.c, dtype=float)
        else:  # BSpline of degree k: its pieces between distinct knots
            k = spline.k
            breaks = np.unique(spline.t[k : len(spline.t) - k])
            left = breaks[:-1]
            coefficients = np.stack([spline(left, nu=k - j) / math.factorial(k - j) for j in range(k + 1)])
        self.breaks = [float(b) for b in breaks]
        # coefficients[j, piece, channel], highest power first -> per piece, per channel, a list
        self.pieces = [
            [[float(v) for v in coefficients[:, i, ch]] for ch in range(coefficients.shape[2])]
            for i in range(coefficients.shape[1])
        ]
        # The same coefficients by power: one (c_x, c_y, c_z, c_yaw) tuple per power, so that one
        # pass of Horner's scheme serves the four channels (a loop per channel costs twice as much).
        self._by_power = [list(zip(*piece, strict=True)) for piece in self.pieces]
        if any(len(piece) != 4 for piece in self.pieces):
            raise ValueError("a timed curve has four channels (x, y, z, yaw)")
        self._last = 0

    def evaluate(self, tau: float) -> tuple[tuple[float, ...], tuple[float, ...], tuple[float, ...]]:
        """(p, p', p'') per channel at ``tau`` (within the breakpoints)."""
        breaks, i, last = self.breaks, self._last, len(self.pieces) - 1
        while i < last and tau >= breaks[i + 1]:
            i += 1
        while i > 0 and tau < breaks[i]:
            i -= 1
        self._last = i
        dx = tau - breaks[i]
        powers = self._by_power[i]
        # Per channel: value, first, half_second = c[0], 0, 0; then for each further c:
        # half_second = half_second dx + first; first = first dx + value; value = value dx + c.
        p0, p1, p2, p3 = powers[0]
        v0 = v1 = v2 = v3 = h0 = h1 = h2 = h3 = 0.0
        for c0, c1, c2, c3 in powers[1:]:
            h0 = h0 * dx + v0
            v0 = v0 * dx + p0
            p0 = p0 * dx + c0
            h1 = h1 * dx + v1
            v1 = v1 * dx + p1
            p1 = p1 * dx + c1
            h2 = h2 * dx + v2
            v2 = v2 * dx + p2
            p2 = p2 * dx + c2
            h3 = h3 * dx + v3
            v3 = v3 * dx + p3
            p3 = p3 * dx + c3
        return (p0, p1, p2, p3), (v0, v1, v2, v3), (2.0 * h0, 2.0 * h1, 2.0 * h2, 2.0 * h3)


def _wrap(angle: float) -> float:
    return (angle + math.pi) % (2.0 * math.pi) - math.pi
