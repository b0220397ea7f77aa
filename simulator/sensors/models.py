"""Sensor models: ground truth in, readings out (pure: no clocks, no I/O; the caller owns time).

Every reading is in the paper's frames (body front-left-up, world x north / y west / z up) and SI
units (plus gauss and hPa, the units of ``HIL_SENSOR``); the MAVLink edge
(:mod:`simulator.mavlink.hil`) turns them into NED/FRD and scaled integers.

* IMU (every frame, i.e. at the control rate): specific force and body rates of O from
  :class:`TruthState`, plus a bias (switch-on value + random walk, + injected steps) and white
  noise of ``density * sqrt(rate)`` per sample.
* Magnetometer: the earth field at home rotated into the body, plus the hard-iron bias, white
  noise and injected disturbances.
* Barometer: the International Standard Atmosphere (troposphere) at the altitude AMSL of O; bias,
  slow drift (a random walk) and noise are on the pressure, and ``pressure_altitude_m`` is what the
  noisy pressure means under the ISA (as a real baro driver computes it).
* GPS: position and velocity of O with first-order Gauss-Markov errors per axis (exact
  discretisation at the fix rate), an honest eph/epv (the errors' standard deviation) unless the
  profile sets a figure, outages (fix type 1, "no fix") and glitches (a position jump) on demand.
* Vision / motion capture: position of O and yaw with white noise, its own rate; the reported
  accuracy is the noise's standard deviation.

Rates and latency: :meth:`SensorSuite.step` is called once per frame with the frame's time and
truth; a sensor samples when its period has elapsed and the sample is *delivered* ``latency_s``
after the time it is valid for (the frame whose time first reaches it). Every reading carries its
validity time ``time_s``; the wire carries the delivery (frame) time, as on a real vehicle.

What a sample is (truth + bias + noise, the ISA, the Gauss-Markov errors) is written once as
kernels in :mod:`.kernels`; this module decides when each sensor samples and what it delivers,
and calls their entries. Noise is drawn from one seeded stream (:mod:`quadcommon.rng`, seeded
from the config), so a run is repeatable, and a batch engine calling the same kernels with the
same seed draws the same noise; a sensor whose noise is zero draws nothing.
"""

from __future__ import annotations

import functools
import math
from collections import deque
from typing import Any, NamedTuple

from quadcommon import rng as random_stream
from quadcommon.kernel import compiled, compiling, freeze

from ..dynamics.plant import TruthState
from . import kernels
from .config import SensorConfig, SensorFault
from .kernels import (  # noqa: F401 - part of this module's interface
    ISA_EXPONENT,
    ISA_LAPSE_RATE_K_M,
    ISA_SEA_LEVEL_PRESSURE_HPA,
    ISA_SEA_LEVEL_TEMPERATURE_C,
    ISA_SEA_LEVEL_TEMPERATURE_K,
    isa_altitude_m,
    isa_pressure_hpa,
    isa_temperature_c,
)

Vector3 = tuple[float, float, float]
_Z3: Vector3 = (0.0, 0.0, 0.0)
_EPS_S = 1e-9  # time comparisons on a float grid

GPS_FIX_NONE = 1  # MAVLink GPS_FIX_TYPE_NO_FIX: the receiver talks but has no position
GPS_FIX_3D = 3

class ImuReading(NamedTuple):
    specific_force_m_s2: Vector3  # body, front-left-up (+g up at rest)
    angular_rate_rad_s: Vector3  # body, front-left-up
    time_s: float = 0.0


class BaroReading(NamedTuple):
    pressure_hpa: float
    pressure_altitude_m: float  # AMSL, from the (noisy) pressure under the ISA
    temperature_c: float
    time_s: float = 0.0  # validity time


class MagReading(NamedTuple):
    time_s: float  # validity time
    field_gauss: Vector3  # body, front-left-up


class SensorReadings(NamedTuple):
    """What ``HIL_SENSOR`` carries: IMU, magnetometer and barometer of one frame.

    Between two magnetometer (barometer) samples the last one is held and ``mag_fresh``
    (``baro_fresh``) is False: the encoder then clears those bits of ``fields_updated``.
    """

    imu: ImuReading
    magnetic_field_gauss: Vector3  # body, front-left-up
    baro: BaroReading
    mag_fresh: bool = True
    baro_fresh: bool = True


class GpsReading(NamedTuple):
    """One GPS fix in the paper's world frame (the MAVLink edge makes it geodetic)."""

    position_m: Vector3  # world (x north, y west, z up), relative to home
    velocity_m_s: Vector3  # world
    eph_m: float  # reported 1-sigma horizontal accuracy per axis
    epv_m: float  # reported 1-sigma vertical accuracy
    satellites_visible: int
    time_s: float = 0.0  # validity time
    speed_accuracy_m_s: float = 0.0  # reported 1-sigma per axis
    fix_type: int = GPS_FIX_3D


class VisionReading(NamedTuple):
    """A motion-capture / vision pose: position of O and the paper's yaw."""

    time_s: float  # validity time
    position_m: Vector3  # world
    yaw_rad: float
    position_std_m: float  # reported 1-sigma per axis
    yaw_std_rad: float


class SensorFrame(NamedTuple):
    """What the sensors deliver at one frame: the IMU sample and whatever else arrived."""

    time_s: float
    imu: ImuReading
    readings: SensorReadings  # for HIL_SENSOR (held mag/baro between their samples)
    mag: MagReading | None = None
    baro: BaroReading | None = None
    gps: GpsReading | None = None
    vision: VisionReading | None = None


class _Schedule:
    """Samples at ``k / rate`` and delivers each ``latency`` later (a FIFO of pending readings)."""

    __slots__ = ("period", "latency", "k", "pending")

    def __init__(self, rate_hz: float, latency_s: float) -> None:
        self.period = 1.0 / rate_hz
        self.latency = latency_s
        self.k = 0
        self.pending: deque = deque()

    def due(self, t: float) -> bool:
        """True (once) when the next sample's time has been reached."""
        if t + _EPS_S >= self.k * self.period:
            # Skip samples a coarse caller jumped over: one sample per call at most.
            self.k = int((t + _EPS_S) / self.period) + 1
            return True
        return False

    def push(self, t_valid: float, reading) -> None:
        self.pending.append((t_valid + self.latency, reading))

    def deliver(self, t_valid: float, reading):
        """:meth:`push` then :meth:`pop` at ``t_valid``: without latency and with nothing pending
        (the ideal profile, every frame) the reading itself, without the queue."""
        if self.latency == 0.0 and not self.pending:
            return reading
        self.push(t_valid, reading)
        return self.pop(t_valid)

    def pop(self, t: float):
        """The newest reading whose delivery time has come (older ones in the same frame are dropped)."""
        out = None
        pending = self.pending
        while pending and pending[0][0] <= t + _EPS_S:
            out = pending.popleft()[1]
        return out


class SensorSuite:
    """The vehicle's sensors: :meth:`step` once per frame; ``sample``/``sample_gps`` read instantly.

    ``imu_rate_hz`` is the frame rate (the IMU samples once per frame); it sets the per-sample
    white noise of the IMU from its density.
    """

    def __init__(self, config: SensorConfig, home_altitude_m: float, imu_rate_hz: float = 500.0) -> None:
        self.config = config
        self.home_altitude_m = home_altitude_m
        self.imu_rate_hz = imu_rate_hz
        self.rng = rng = random_stream.stream(config.seed)
        self._k = k = sensor_entries()
        a, g = config.accelerometer, config.gyroscope
        # Switch-on biases: the fixed part plus a draw of the random part (same seed, same bias).
        self.accel_bias = _add(_floats(a.bias), k.draw3(rng, float(a.turn_on_bias_std)))
        self.gyro_bias = _add(_floats(g.bias), k.draw3(rng, float(g.turn_on_bias_std)))
        self._accel_std = a.noise_density * math.sqrt(imu_rate_hz)
        self._gyro_std = g.noise_density * math.sqrt(imu_rate_hz)
        self._mag = config.magnetometer
        self.mag_bias = _add(
            _floats(config.magnetometer.bias_gauss),
            k.draw3(rng, float(config.magnetometer.turn_on_bias_std_gauss)),
        )
        self._field = _floats(config.magnetometer.earth_field_world_gauss)
        self._baro = config.barometer
        self.baro_drift_hpa = 0.0
        self._gps = gps = config.gps
        self._vision = config.vision
        # Gauss-Markov GPS errors start from their stationary distribution.
        sh, sv = float(gps.horizontal_noise_std_m), float(gps.vertical_noise_std_m)
        self._gps_position_std = (sh, sh, sv)
        s = float(gps.velocity_noise_std_m_s)
        self._gps_velocity_std = (s, s, s)
        self.gps_position_error = k.stationary(rng, self._gps_position_std)
        self.gps_velocity_error = k.stationary(rng, self._gps_velocity_std)
        self.faults: list[SensorFault] = list(config.faults)
        self._t_last: float | None = None
        self._mag_s = _Schedule(self._mag.rate_hz, self._mag.latency_s)
        self._baro_s = _Schedule(self._baro.rate_hz, self._baro.latency_s)
        self._gps_s = _Schedule(gps.rate_hz, gps.latency_s)
        self._vision_s = _Schedule(self._vision.rate_hz, self._vision.latency_s)
        self._t_gps: float | None = None
        self._held_mag: Vector3 | None = None
        self._held_baro: BaroReading | None = None
        self._last_fix: GpsReading | None = None

    # -- faults -----------------------------------------------------------------------------------
    def add_fault(self, fault: SensorFault) -> None:
        """Inject ``fault`` (see :data:`~simulator.sensors.config.FAULT_KINDS`)."""
        self.faults.append(fault)

    def gps_outage(self, start_s: float, duration_s: float = math.inf) -> None:
        """No GPS fix over ``[start_s, start_s + duration_s)`` (on demand)."""
        self.add_fault(SensorFault("gps_outage", start_s, duration_s))

    def imu_biases(self, t_s: float) -> tuple[Vector3, Vector3]:
        """``(accelerometer, gyro)`` biases in effect at ``t_s`` (switch-on + drift + injected steps):
        the truth an estimator's bias estimates are compared with."""
        return (
            _add(self.accel_bias, self._fault_sum("accel_bias_step", t_s)),
            _add(self.gyro_bias, self._fault_sum("gyro_bias_step", t_s)),
        )

    def _fault_sum(self, kind: str, t: float) -> Vector3:
        x = y = z = 0.0
        for f in self.faults:
            if f.kind == kind and f.active(t):
                x, y, z = x + f.value[0], y + f.value[1], z + f.value[2]
        return (x, y, z)

    def _fault_active(self, kind: str, t: float) -> bool:
        return any(f.kind == kind and f.active(t) for f in self.faults)

    # -- the timed interface ------------------------------------------------------------------------
    def step(self, t_s: float, truth: TruthState) -> SensorFrame:
        """Advance the sensors' random walks to ``t_s`` and return what is delivered at ``t_s``."""
        if self._t_last is not None:
            dt = t_s - self._t_last
            if dt > 0.0:
                self._advance_biases(dt)
        self._t_last = t_s
        imu = self._imu(truth, t_s)

        mag = baro = gps = vision = None
        mag_s, baro_s = self._mag_s, self._baro_s
        if mag_s.due(t_s):
            mag = mag_s.deliver(t_s, MagReading(t_s, self._magnetometer(truth, t_s)))
        elif mag_s.pending:
            mag = mag_s.pop(t_s)
        if baro_s.due(t_s):
            baro = baro_s.deliver(t_s, self._barometer(truth, t_s))
        elif baro_s.pending:
            baro = baro_s.pop(t_s)
        gps_s, vision_s = self._gps_s, self._vision_s
        if self._gps.enabled and gps_s.due(t_s):
            gps = gps_s.deliver(t_s, self._gps_fix(truth, t_s))
        elif gps_s.pending:
            gps = gps_s.pop(t_s)
        if self._vision.enabled and vision_s.due(t_s) and not self._fault_active("vision_outage", t_s):
            vision = vision_s.deliver(t_s, self._vision_pose(truth, t_s))
        elif vision_s.pending:
            vision = vision_s.pop(t_s)

        if mag is not None:
            self._held_mag = mag.field_gauss
        if baro is not None:
            self._held_baro = baro
        held_mag = self._held_mag if self._held_mag is not None else self._magnetometer(truth, t_s)
        held_baro = self._held_baro if self._held_baro is not None else self._barometer(truth, t_s)
        readings = SensorReadings(imu, held_mag, held_baro, mag is not None, baro is not None)
        return SensorFrame(t_s, imu, readings, mag, baro, gps, vision)

    def _advance_biases(self, dt: float) -> None:
        k, rng = self._k, self.rng
        a, g = self.config.accelerometer, self.config.gyroscope
        if a.bias_random_walk > 0.0:
            self.accel_bias = k.random_walk(rng, self.accel_bias, a.bias_random_walk, dt)
        if g.bias_random_walk > 0.0:
            self.gyro_bias = k.random_walk(rng, self.gyro_bias, g.bias_random_walk, dt)
        if self._baro.drift_hpa_rthz > 0.0:
            self.baro_drift_hpa += self._baro.drift_hpa_rthz * math.sqrt(dt) * self._k.normal(rng)

    def _imu(self, truth: TruthState, t: float) -> ImuReading:
        ba, bg = self.imu_biases(t) if self.faults else (self.accel_bias, self.gyro_bias)
        force, rates = self._k.imu_reading(self.rng, truth.specific_force_body_m_s2, truth.body_rates_rad_s,
                                           ba, bg, self._accel_std, self._gyro_std)  # fmt: skip
        return ImuReading(force, rates, t)

    def _magnetometer(self, truth: TruthState, t: float) -> Vector3:
        bias = self.mag_bias
        if self.faults:
            bias = _add(bias, self._fault_sum("mag_disturbance", t))
        return self._k.magnetometer_reading(self.rng, truth.quaternion, self._field, bias,
                                            float(self._mag.noise_std_gauss))  # fmt: skip

    def _barometer(self, truth: TruthState, t: float) -> BaroReading:
        altitude = self.home_altitude_m + truth.position_m[2]
        baro = self._baro
        pressure, pressure_altitude, temperature = self._k.barometer_reading(
            self.rng, altitude, float(baro.bias_hpa), self.baro_drift_hpa, float(baro.noise_std_hpa)
        )
        return BaroReading(pressure, pressure_altitude, temperature, t)

    def _gps_fix(self, truth: TruthState, t: float) -> GpsReading:
        gps = self._gps
        if self._t_gps is not None:
            self._advance_gps_errors(t - self._t_gps)
        self._t_gps = t
        if self._fault_active("gps_outage", t):
            # No fix: the receiver repeats its last position (home before any), with no accuracy.
            position = self._last_fix.position_m if self._last_fix is not None else _Z3
            return GpsReading(position, _Z3, 99.99, 99.99, 0, t, 99.99, GPS_FIX_NONE)
        e, u = self.gps_position_error, self.gps_velocity_error
        p, v = truth.position_m, truth.velocity_m_s
        position = (p[0] + e[0], p[1] + e[1], p[2] + e[2])
        if self.faults:
            position = _add(position, self._fault_sum("gps_glitch", t))
        fix = GpsReading(
            position,
            (v[0] + u[0], v[1] + u[1], v[2] + u[2]),
            gps.reported_eph_m,
            gps.reported_epv_m,
            gps.satellites_visible,
            t,
            gps.reported_speed_accuracy_m_s,
            GPS_FIX_3D,
        )
        self._last_fix = fix
        return fix

    def _advance_gps_errors(self, dt: float) -> None:
        """The Gauss-Markov position and velocity errors over ``dt`` (:func:`.kernels.gauss_markov`)."""
        gps, k, rng = self._gps, self._k, self.rng
        tau_p, tau_v = float(gps.position_correlation_time_s), float(gps.velocity_correlation_time_s)
        e, u = self.gps_position_error, self.gps_velocity_error
        self.gps_position_error = k.gauss_markov(rng, e, dt, tau_p, self._gps_position_std)
        self.gps_velocity_error = k.gauss_markov(rng, u, dt, tau_v, self._gps_velocity_std)

    def _vision_pose(self, truth: TruthState, t: float) -> VisionReading:
        vis = self._vision
        s, s_yaw = float(vis.position_noise_std_m), float(vis.yaw_noise_std_rad)
        p, yaw = self._k.vision_reading(self.rng, truth.position_m, truth.euler_rad[2], s, s_yaw)
        return VisionReading(t, p, yaw, s, s_yaw)

    # -- instantaneous reads (no time: codec tests, single samples) -----------------------------------
    def sample(self, truth: TruthState) -> SensorReadings:
        """IMU, magnetometer and barometer readings for ``truth`` now (no rate, latency or drift)."""
        t = self._t_last if self._t_last is not None else 0.0
        return SensorReadings(self._imu(truth, t), self._magnetometer(truth, t), self._barometer(truth, t))

    def sample_gps(self, truth: TruthState) -> GpsReading:
        """One GPS fix for ``truth`` now (no latency; the Gauss-Markov errors advance one period)."""
        t = (self._t_gps + self._gps_s.period) if self._t_gps is not None else 0.0
        return self._gps_fix(truth, t)


def _add(a: Vector3, b: Vector3) -> Vector3:
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


def _floats(v) -> Vector3:
    return (float(v[0]), float(v[1]), float(v[2]))


class SensorEntries(NamedTuple):
    """What :class:`SensorSuite` calls: the entries of :mod:`.kernels` (and of the stream's
    :func:`~quadcommon.rng.normal`), or the kernels themselves where nothing compiles."""

    draw3: Any
    stationary: Any
    random_walk: Any
    normal: Any
    imu_reading: Any
    magnetometer_reading: Any
    barometer_reading: Any
    gauss_markov: Any
    vision_reading: Any


def sensor_kernels() -> SensorEntries:
    """The kernels themselves (what Python runs where nothing compiles)."""
    return SensorEntries(
        *(getattr(random_stream, n) if n == "normal" else getattr(kernels, n) for n in SensorEntries._fields)
    )


@functools.cache
def sensor_entries() -> SensorEntries:
    """The entries, compiled (or loaded from numba's cache) and called once now on a scratch
    stream, then frozen (an argument of another type is refused instead of stalling a flight for
    a compilation). Once per process."""
    entries = SensorEntries(*(compiled(fn) for fn in sensor_kernels()))
    if compiling():
        rng = random_stream.stream(0)
        z3, q = (0.0, 0.0, 0.0), (1.0, 0.0, 0.0, 0.0)
        entries.draw3(rng, 1.0)
        entries.stationary(rng, z3)
        entries.random_walk(rng, z3, 1.0, 0.002)
        entries.normal(rng)
        entries.imu_reading(rng, z3, z3, z3, z3, 1.0, 1.0)
        entries.magnetometer_reading(rng, q, z3, z3, 1.0)
        entries.barometer_reading(rng, 488.0, 0.0, 0.0, 1.0)
        entries.gauss_markov(rng, z3, 0.1, 0.1, z3)
        entries.vision_reading(rng, z3, 0.0, 1.0, 1.0)
        for entry in entries:
            freeze(entry)
    return entries
