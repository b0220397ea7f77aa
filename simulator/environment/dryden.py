"""Dryden continuous turbulence, MIL-F-8785C low-altitude model (below 1000 ft), as a wind.

Profile element (``[dryden]``, at most one per profile):

* ``w20_m_s``: mean wind speed 20 ft (6.1 m) above ground, m/s. MIL-F-8785C's categories:
  light 15 kt (7.7 m/s), moderate 30 kt (15.4 m/s), severe 45 kt (23.2 m/s);
* ``altitude_m``: height above ground h used for the scale lengths and intensities, m
  (the vehicle's altitude is not read: the turbulence is defined for one reference height);
* ``airspeed_m_s`` (default 5 m/s): the reference speed V at which the frozen turbulence field
  is swept past the vehicle (Taylor's hypothesis: temporal frequency omega = V Omega). A hovering
  vehicle has no airspeed, yet the spectra need V > 0; 5 m/s is a breezy day's mean wind. With a
  mean wind the physical choice is V = |mean horizontal wind| (the wind carries the field past a
  vehicle that holds its position); set it so;
* ``seed``: integer seed of the noise; the same seed gives the same turbulence, bit for bit;
* ``start_s`` (default 0), ``end_s`` (default: to the end), profile time, s;
* ``mean_wind_m_s`` (default [0, 0, 0]): constant wind added while the turbulence is active
  (world frame, paper axes x forward/north, y left, z up), m/s;
* ``warm_start`` (default true): the filters start in a state drawn from their stationary
  distribution, so the turbulence has its full intensity from ``start_s`` on (a step of order
  sigma at ``start_s``); false starts them at rest (the intensity builds up over a few L/V).

Low-altitude scales and intensities (MIL-F-8785C §3.7.2.3 and MIL-HDBK-1797 §4.9.1, h in FEET)::

    L_w = h,   L_u = L_v = h / (0.177 + 0.000823 h)^1.2                  (ft)
    sigma_w = 0.1 W20,   sigma_u / sigma_w = sigma_v / sigma_w = 1 / (0.177 + 0.000823 h)^0.4

Shaping filters (MIL-F-8785C / MIL-HDBK-1797 Dryden form; Laplace variable s in rad/s)::

    H_u(s) = sigma_u sqrt(2 L_u / (pi V)) / (1 + (L_u/V) s)
    H_v(s) = sigma_v sqrt(L_v / (pi V)) (1 + sqrt(3) (L_v/V) s) / (1 + (L_v/V) s)^2
    H_w(s) = sigma_w sqrt(L_w / (pi V)) (1 + sqrt(3) (L_w/V) s) / (1 + (L_w/V) s)^2

Noise scaling, the one subtle point. The MIL spectra are ONE-sided in omega:
Phi_u(omega) = |H_u(j omega)|^2 with int_0^inf Phi_u d omega = sigma_u^2. Hence the white noise
driving H must have a one-sided PSD of 1 per rad/s, i.e. an autocorrelation pi delta(tau)
(intensity pi). Unit-intensity white noise (autocorrelation delta(tau), which sampled at dt has
variance 1/dt) would give sigma^2 / pi: turbulence 44 % too weak. So each filter is driven by
band-limited white noise held over one step dt with variance pi / dt: samples
e_k sqrt(pi / dt), e_k ~ N(0, 1). The test suite checks the resulting sigma_u, sigma_v, sigma_w
and the correlation times.

Discretisation (once, at construction): each H is converted to state space (:func:`tf2ss`,
scipy's realisation) and discretised with a zero-order hold at the step dt (exact for noise
held over the step): the exponential of the augmented matrix [[A, B], [0, 0]] dt, computed here
by scaling and squaring of its Taylor series in numpy. ``scipy.signal.cont2discrete`` computes
the same (the tests compare both), but its ``scipy.linalg.expm`` took 8 ms per 3x3 call on the
project's 2-vCPU machines (scipy's bundled OpenBLAS threading; numpy's small matmuls take 1 µs),
which would stall the simulator's loop for ~40 ms when an upload installs a profile.

Generation: the noise is drawn in blocks of ``BLOCK_SIZE`` samples
(``numpy.random.Generator(PCG64(seed))``, rows u, v, w) and filtered (:func:`lfilter`, scipy's
transposed direct form II), carrying the filter state from block to block; the world-frame wind of
a whole block is precomputed, so one step costs a list lookup. The stationary warm start draws
the state from the solution of the discrete Lyapunov equation P = Ad P Ad^T + Bd Bd^T.

No scipy here (numpy only, each function tested against scipy's): ``scipy.signal`` and
``scipy.linalg`` cost ~1 s of CPU to import, which every simulator start paid so that a Dryden
upload in flight would not stall the lockstep loop on the import.

Axes: u (longitudinal) along the horizontal mean wind when there is one (|mean_xy| >= 0.1 m/s),
world x otherwise (a hover in still air: the turbulence is swept along x); v lateral, to the
left of u (world y for a hover); w vertical (world z, up).

The value is a function of the step index n = round((t - t_start) / dt): a sample does not
depend on which times were evaluated before, but the generator only runs forward, so asking for
a step earlier than the last one asked for raises :class:`TurbulenceOrderError`. Skipping ahead
generates the skipped blocks (cost proportional to the time skipped).

References: MIL-F-8785C, Military Specification, Flying Qualities of Piloted Airplanes,
5 Nov 1980, §3.7; MIL-HDBK-1797, Flying Qualities of Piloted Aircraft, 19 Dec 1997, §4.9.1 and
Appendix; M. M. Madden, "Verifying Implementation of the Dryden Turbulence Model and MIL-F-8785
Gust Gradient", NASA Langley (on discrete implementations and their verification).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from quadcommon.schema import Section

Vector3 = tuple[float, float, float]

FT = 0.3048  # m per ft
KNOT = 0.514444  # m/s per kt
LOW_ALTITUDE_LIMIT_M = 1000.0 * FT  # the low-altitude model holds below 1000 ft
MIN_ALTITUDE_M = 1.0  # L_w = h: below ~1 m the vertical scale is shorter than the vehicle
MAX_W20_M_S = 30.0  # above "severe" (45 kt = 23.2 m/s) with margin
MIN_AIRSPEED_M_S = 0.5
MAX_AIRSPEED_M_S = 30.0
DEFAULT_AIRSPEED_M_S = 5.0
MAX_MEAN_WIND_M_S = 30.0
MAX_TIME_S = 1e6
BLOCK_SIZE = 1024  # samples per generated block (1 s at 1 kHz); see BLOCK_SIZE note in __init__
MIN_SAMPLES_PER_TIME_CONSTANT = 4.0


class TurbulenceOrderError(RuntimeError):
    """The Dryden generator was asked for a step earlier than one it has already produced."""


@dataclass(frozen=True)
class DrydenTurbulence:
    """The ``[dryden]`` element of a gust profile (validated; SI units; times in profile time)."""

    w20_m_s: float
    altitude_m: float
    seed: int
    airspeed_m_s: float = DEFAULT_AIRSPEED_M_S
    start_s: float = 0.0
    end_s: float = math.inf
    mean_wind_m_s: Vector3 = (0.0, 0.0, 0.0)
    warm_start: bool = True

    def scales(self) -> DrydenScales:
        """Scale lengths and intensities of the low-altitude model at ``altitude_m``."""
        return low_altitude_scales(self.w20_m_s, self.altitude_m)


@dataclass(frozen=True)
class DrydenScales:
    """MIL-F-8785C low-altitude scale lengths (m) and turbulence intensities (m/s)."""

    length_u_m: float
    length_v_m: float
    length_w_m: float
    sigma_u_m_s: float
    sigma_v_m_s: float
    sigma_w_m_s: float


def low_altitude_scales(w20_m_s: float, altitude_m: float) -> DrydenScales:
    """MIL-F-8785C §3.7.2.3 low-altitude model: ``h`` converted to feet, lengths back to metres.

    ``L_w = h``, ``L_u = L_v = h / (0.177 + 0.000823 h)^1.2``, ``sigma_w = 0.1 W20``,
    ``sigma_u = sigma_v = sigma_w / (0.177 + 0.000823 h)^0.4`` (h in ft).
    """
    h_ft = altitude_m / FT
    k = 0.177 + 0.000823 * h_ft
    length_uv_m = h_ft / k**1.2 * FT
    sigma_w = 0.1 * w20_m_s
    sigma_uv = sigma_w / k**0.4
    return DrydenScales(length_uv_m, length_uv_m, altitude_m, sigma_uv, sigma_uv, sigma_w)


def shaping_filters(scales: DrydenScales, airspeed_m_s: float) -> tuple[tuple[list[float], list[float]], ...]:
    """Continuous Dryden filters ``(num, den)`` in descending powers of s, for u, v and w.

    ``|H(j omega)|^2`` is the one-sided PSD (m^2/s^2 per rad/s) of each component.
    """
    V = airspeed_m_s
    Tu = scales.length_u_m / V
    Tv = scales.length_v_m / V
    Tw = scales.length_w_m / V
    ku = scales.sigma_u_m_s * math.sqrt(2.0 * Tu / math.pi)
    kv = scales.sigma_v_m_s * math.sqrt(Tv / math.pi)
    kw = scales.sigma_w_m_s * math.sqrt(Tw / math.pi)
    root3 = math.sqrt(3.0)
    return (
        ([ku], [Tu, 1.0]),
        ([kv * root3 * Tv, kv], [Tv * Tv, 2.0 * Tv, 1.0]),
        ([kw * root3 * Tw, kw], [Tw * Tw, 2.0 * Tw, 1.0]),
    )


def check_step(params: DrydenTurbulence, dt_s: float) -> None:
    """Raise ValueError unless the step ``dt_s`` (s) resolves the fastest filter time constant.

    The noise held over one step stands for white noise only when dt << L/V; at
    ``MIN_SAMPLES_PER_TIME_CONSTANT`` samples per L/V the stationary standard deviation of the
    ZOH scheme is within 1 % of sigma (0.6 % for w at the limit; 1e-6 at 2.5 m, 5 m/s, 1 ms).
    The parser's ranges (altitude >= 1 m, airspeed <= 30 m/s: L/V >= 33 ms) keep every valid
    profile within this bound for steps up to 8 ms.
    """
    if not (dt_s > 0.0 and math.isfinite(dt_s)):
        raise ValueError(f"the Dryden step must be a positive number of seconds, got {dt_s!r}")
    s = params.scales()
    fastest = min(s.length_u_m, s.length_v_m, s.length_w_m) / params.airspeed_m_s
    if fastest < MIN_SAMPLES_PER_TIME_CONSTANT * dt_s:
        raise ValueError(
            f"the physics step {dt_s:g} s is too coarse for the shortest Dryden time constant "
            f"L/V = {fastest:g} s (altitude {params.altitude_m:g} m, airspeed {params.airspeed_m_s:g} m/s); "
            f"allowed: a step <= {fastest / MIN_SAMPLES_PER_TIME_CONSTANT:g} s"
        )


def _expm_small(M: np.ndarray) -> np.ndarray:
    """exp(M) for a small matrix: Taylor series after scaling to norm <= 1/4, then squaring.

    18 terms at norm 1/4 leave a truncation error below 1e-22 relative.
    """
    norm = float(np.abs(M).sum(axis=1).max())
    squarings = max(0, math.ceil(math.log2(norm / 0.25))) if norm > 0.25 else 0
    X = M / 2.0**squarings
    E = np.eye(M.shape[0])
    term = np.eye(M.shape[0])
    for k in range(1, 19):
        term = term @ X / k
        E = E + term
    for _ in range(squarings):
        E = E @ E
    return E


def zoh(A: np.ndarray, B: np.ndarray, dt_s: float) -> tuple[np.ndarray, np.ndarray]:
    """Zero-order-hold discretisation (Ad, Bd) of dx/dt = A x + B u at step ``dt_s`` (s)."""
    n, m = B.shape
    M = np.zeros((n + m, n + m))
    M[:n, :n] = A * dt_s
    M[:n, n:] = B * dt_s
    E = _expm_small(M)
    return E[:n, :n], E[:n, n:]


def tf2ss(num: list[float], den: list[float]) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """A single-input single-output transfer function ``num / den`` (highest power first, proper) in
    state space, controller canonical form: ``scipy.signal.tf2ss``'s realisation (tested against it).

    Here rather than scipy's: importing ``scipy.signal`` costs ~0.8 s of CPU, which every simulator
    start paid so that a Dryden upload in flight would not stall its loop on the import."""
    den_a = np.asarray(den, dtype=float)
    num_a = np.asarray(num, dtype=float)
    if den_a.ndim != 1 or den_a.size == 0 or den_a[0] == 0.0 or num_a.size > den_a.size:
        raise ValueError(f"transfer function {num}/{den}: need a proper one with den[0] != 0")
    num_a = np.concatenate([np.zeros(den_a.size - num_a.size), num_a]) / den_a[0]
    den_a = den_a / den_a[0]
    n = den_a.size - 1
    D = np.array([[num_a[0]]])
    if n == 0:
        return np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), D
    A = np.zeros((n, n))
    A[0, :] = -den_a[1:]
    A[1:, :-1] = np.eye(n - 1)
    B = np.zeros((n, 1))
    B[0, 0] = 1.0
    C = (num_a[1:] - num_a[0] * den_a[1:]).reshape(1, n)
    return A, B, C, D


def ss2tf(A: np.ndarray, B: np.ndarray, C: np.ndarray, D: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(num, den)`` of a single-input single-output state-space system, as ``scipy.signal.ss2tf``
    computes them: ``den`` the characteristic polynomial of A, ``num = poly(A - B C) + (D - 1) den``."""
    den = np.poly(A)
    num = np.poly(A - B @ C) + (D.item() - 1.0) * den
    return num, den


def lfilter(b: np.ndarray, a: np.ndarray, x: np.ndarray, zi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``scipy.signal.lfilter(b, a, x, zi=zi)`` for one channel (transposed direct form II, ``a[0]``
    normalised, ``b`` and ``a`` of one length): the output and the final state. In plain floats:
    the Dryden filters are of order 1 and 2, and a block of 1024 samples costs well under a ms."""
    a0 = float(a[0])
    bs = [float(v) / a0 for v in b]
    as_ = [float(v) / a0 for v in a]
    if len(bs) != len(as_) or len(zi) != len(bs) - 1:
        raise ValueError("lfilter: b, a of one length and zi of that length - 1")
    z = [float(v) for v in zi]
    out = []
    append = out.append
    if len(z) == 1:
        b0, b1, a1 = bs[0], bs[1], as_[1]
        z0 = z[0]
        for xk in x.tolist():
            y = z0 + b0 * xk
            z0 = b1 * xk - a1 * y
            append(y)
        z = [z0]
    elif len(z) == 2:
        b0, b1, b2, a1, a2 = bs[0], bs[1], bs[2], as_[1], as_[2]
        z0, z1 = z
        for xk in x.tolist():
            y = z0 + b0 * xk
            z0 = z1 + b1 * xk - a1 * y
            z1 = b2 * xk - a2 * y
            append(y)
        z = [z0, z1]
    else:  # any order (not a Dryden filter)
        n = len(z)
        for xk in x.tolist():
            y = z[0] + bs[0] * xk
            for i in range(n - 1):
                z[i] = z[i + 1] + bs[i + 1] * xk - as_[i + 1] * y
            z[n - 1] = bs[n] * xk - as_[n] * y
            append(y)
    return np.array(out), np.array(z)


def solve_discrete_lyapunov(A: np.ndarray, Q: np.ndarray) -> np.ndarray:
    """P with ``P = A P A^T + Q`` (A stable), by the Kronecker form ``(I - A (x) A) vec P = vec Q``:
    exact for the 1x1 and 2x2 systems of the Dryden filters (``scipy.linalg``'s would cost its
    import, ~0.3 s)."""
    n = A.shape[0]
    vec = np.linalg.solve(np.eye(n * n) - np.kron(A, A), Q.reshape(n * n))
    return vec.reshape(n, n)


class _DiscreteFilter:
    """One shaping filter discretised (ZOH) for unit-normal samples; gain sqrt(pi/dt) folded in."""

    def __init__(self, num: list[float], den: list[float], dt_s: float) -> None:
        A, B, C, D = tf2ss(num, den)
        Ad, Bd = zoh(A, B, dt_s)
        Cd, Dd = C, D
        # Band-limited white noise of one-sided PSD 1 (intensity pi) held over dt: variance pi/dt.
        Bd = Bd * math.sqrt(math.pi / dt_s)
        b, a = ss2tf(Ad, Bd, Cd, Dd)
        self.Ad, self.Bd, self.Cd = Ad, Bd, Cd
        self.b = np.asarray(b, dtype=float).ravel()
        self.a = np.asarray(a, dtype=float).ravel()
        self.order = Ad.shape[0]
        self.zi = np.zeros(self.order)

    def stationary_covariance(self) -> np.ndarray:
        """State covariance P = Ad P Ad^T + Bd Bd^T of the filter driven by unit-normal samples."""
        return solve_discrete_lyapunov(self.Ad, self.Bd @ self.Bd.T)

    def set_state(self, x0: np.ndarray) -> None:
        """Start ``lfilter`` from state-space state ``x0``: match the first ``order`` outputs.

        With zero input, the transposed direct form II of ``lfilter`` outputs
        ``y_k = zi_0`` ... ; solving ``zi_i = sum_{j<=i} a_j y_{i-j}`` for the free response
        ``y_k = Cd Ad^k x0`` makes both forms give the same free response for every k (both obey
        the same recurrence with the same initial values).
        """
        y = []
        x = x0
        for _ in range(self.order):
            y.append(float((self.Cd @ x).item()))
            x = self.Ad @ x
        a = self.a
        self.zi = np.array([sum(a[j] * y[i - j] for j in range(i + 1)) for i in range(self.order)])

    def run(self, noise: np.ndarray) -> np.ndarray:
        out, self.zi = lfilter(self.b, self.a, noise, self.zi)
        return out


class DrydenWind:
    """Generates the Dryden wind (world frame, m/s, mean wind included) step by step.

    ``dt_s`` is the step the simulator evaluates the disturbance at (the physics step, 1 ms by
    default): each step gets a fresh sample. ``block_size`` trades the cost of one block (drawn
    with numpy and filtered in plain floats, ~1 ms for 1024 samples) against its latency spike;
    the per-step cost is a list lookup either way.
    """

    def __init__(self, params: DrydenTurbulence, dt_s: float = 1e-3, block_size: int = BLOCK_SIZE) -> None:
        if block_size < 1:
            raise ValueError(f"block_size must be >= 1, got {block_size}")
        check_step(params, dt_s)
        self.params = params
        self.dt_s = dt_s
        self.scales = params.scales()
        V = params.airspeed_m_s
        # Filters for unit intensity, scaled per block: W20 = 0 (calm, mean wind only) must not
        # give all-zero numerators, which scipy's tf2ss refuses with a warning.
        unit = replace(self.scales, sigma_u_m_s=1.0, sigma_v_m_s=1.0, sigma_w_m_s=1.0)
        self.filters = [_DiscreteFilter(num, den, dt_s) for num, den in shaping_filters(unit, V)]
        mx, my, mz = params.mean_wind_m_s
        horizontal = math.hypot(mx, my)
        # u along the horizontal mean wind (the frozen field is carried by it), else world x.
        self.u_axis: Vector3 = (1.0, 0.0, 0.0)
        if horizontal >= 0.1:
            self.u_axis = (mx / horizontal, my / horizontal, 0.0)
        self._rng = np.random.Generator(np.random.PCG64(params.seed))
        if params.warm_start:
            for f in self.filters:
                P = f.stationary_covariance()
                # eigh rather than Cholesky: P is symmetric PSD but may be nearly singular.
                w, Q = np.linalg.eigh(P)
                x0 = Q @ (np.sqrt(np.clip(w, 0.0, None)) * self._rng.standard_normal(f.order))
                f.set_state(x0.reshape(-1, 1))
        self.block_size = block_size
        self._block_start = 0  # step index of self._block[0]
        self._block: list[Vector3] = []
        self._last_n = -1
        self._last: Vector3 = (0.0, 0.0, 0.0)
        self._next_block()

    def _next_block(self) -> None:
        if self._block:
            self._block_start += len(self._block)
        noise = self._rng.standard_normal((3, self.block_size))
        s = self.scales
        u = s.sigma_u_m_s * self.filters[0].run(noise[0])
        v = s.sigma_v_m_s * self.filters[1].run(noise[1])
        w = s.sigma_w_m_s * self.filters[2].run(noise[2])
        cx, cy, _ = self.u_axis
        mx, my, mz = self.params.mean_wind_m_s
        # v is to the left of u: (-cy, cx, 0).
        wx = mx + cx * u - cy * v
        wy = my + cy * u + cx * v
        wz = mz + w
        self._block = list(zip(wx.tolist(), wy.tolist(), wz.tolist(), strict=True))

    def at_step(self, n: int) -> Vector3:
        """Wind at step ``n`` (0 at the turbulence's start), world frame, m/s.

        Raises :class:`TurbulenceOrderError` if ``n`` is earlier than the last step asked for.
        """
        if n == self._last_n:
            return self._last
        if n < self._last_n:
            raise TurbulenceOrderError(
                f"Dryden turbulence runs forward only: step {n} (t = {n * self.dt_s:.6f} s after its "
                f"start) was asked for after step {self._last_n}; evaluate the schedule at "
                "non-decreasing times (one physics step after another)"
            )
        i = n - self._block_start
        size = self.block_size
        while i >= size:  # bounded: one block per block_size steps skipped
            self._next_block()
            i -= size
        value = self._block[i]
        self._last_n = n
        self._last = value
        return value


def parse_dryden(sec: Section) -> DrydenTurbulence:
    """Validate a ``[dryden]`` table (see the module docstring for the keys)."""
    w20 = sec.number("w20_m_s", lo=0.0, hi=MAX_W20_M_S, unit="m/s")
    altitude = sec.number("altitude_m", lo=MIN_ALTITUDE_M, hi=round(LOW_ALTITUDE_LIMIT_M, 1), unit="m")
    airspeed = sec.number(
        "airspeed_m_s", DEFAULT_AIRSPEED_M_S, lo=MIN_AIRSPEED_M_S, hi=MAX_AIRSPEED_M_S, unit="m/s"
    )
    seed = sec.integer("seed", lo=0)
    start = sec.number("start_s", 0.0, lo=0.0, hi=MAX_TIME_S, unit="s")
    end = (
        sec.number("end_s", lo=start, lo_open=True, hi=MAX_TIME_S, unit="s") if sec.has("end_s") else math.inf
    )
    bound = MAX_MEAN_WIND_M_S
    mean = sec.vector("mean_wind_m_s", 3, [0.0, 0.0, 0.0], lo=-bound, hi=bound, unit="m/s")
    warm = sec.boolean("warm_start", True)
    sec.finish()
    return DrydenTurbulence(w20, altitude, seed, airspeed, start, end, mean, warm)  # type: ignore[arg-type]


def dryden_to_mapping(d: DrydenTurbulence) -> dict:
    """The ``[dryden]`` table of ``d`` (JSON-ready; parses back to an equal record)."""
    out: dict = {
        "w20_m_s": d.w20_m_s,
        "altitude_m": d.altitude_m,
        "airspeed_m_s": d.airspeed_m_s,
        "seed": d.seed,
        "start_s": d.start_s,
        "mean_wind_m_s": list(d.mean_wind_m_s),
        "warm_start": d.warm_start,
    }
    if math.isfinite(d.end_s):
        out["end_s"] = d.end_s
    return out


def describe_dryden(d: DrydenTurbulence) -> str:
    """One-line summary: intensities, scales and timing."""
    s = d.scales()
    text = (
        f"Dryden W20 {d.w20_m_s:g} m/s at {d.altitude_m:g} m (sigma u/v/w "
        f"{s.sigma_u_m_s:.2f}/{s.sigma_v_m_s:.2f}/{s.sigma_w_m_s:.2f} m/s, L u/w "
        f"{s.length_u_m:.1f}/{s.length_w_m:.1f} m, V {d.airspeed_m_s:g} m/s, seed {d.seed}) "
        f"from {d.start_s:g} s"
    )
    if math.isfinite(d.end_s):
        text += f" to {d.end_s:g} s"
    if any(d.mean_wind_m_s):
        text += " + mean wind [" + ", ".join(f"{c:g}" for c in d.mean_wind_m_s) + "] m/s"
    return text
