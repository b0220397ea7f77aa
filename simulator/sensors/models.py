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

Noise is drawn from one :class:`random.Random` seeded from the config, so a run is repeatable; a
sensor whose noise is zero draws nothing (an exact sensor costs one tuple).
"""

from __future__ import annotations

import math
import random
from collections import deque
from typing import NamedTuple

from quadcommon.frames import wrap_pi

from ..dynamics.plant import TruthState
from .config import SensorConfig, SensorFault

Vector3 = tuple[float, float, float]
_Z3: Vector3 = (0.0, 0.0, 0.0)
_EPS_S = 1e-9  # time comparisons on a float grid

GPS_FIX_NONE = 1  # MAVLink GPS_FIX_TYPE_NO_FIX: the receiver talks but has no position
GPS_FIX_3D = 3

# ISA troposphere (ICAO Doc 7488): p = p0 (1 - L h / T0)^(g M / (R L)).
ISA_SEA_LEVEL_PRESSURE_HPA = 1013.25
ISA_SEA_LEVEL_TEMPERATURE_C = 15.0
ISA_LAPSE_RATE_K_M = 0.0065
ISA_SEA_LEVEL_TEMPERATURE_K = 288.15
ISA_EXPONENT = 5.255877  # g M / (R L)


def isa_pressure_hpa(altitude_amsl_m: float) -> float:
    """Static pressure (hPa) at ``altitude_amsl_m`` (m) in the ISA troposphere (< 11 km)."""
    ratio = 1.0 - ISA_LAPSE_RATE_K_M * altitude_amsl_m / ISA_SEA_LEVEL_TEMPERATURE_K
    return ISA_SEA_LEVEL_PRESSURE_HPA * ratio**ISA_EXPONENT


def isa_altitude_m(pressure_hpa: float) -> float:
    """Pressure altitude (m AMSL) of ``pressure_hpa`` (hPa): the inverse of :func:`isa_pressure_hpa`."""
    ratio = (pressure_hpa / ISA_SEA_LEVEL_PRESSURE_HPA) ** (1.0 / ISA_EXPONENT)
    return (1.0 - ratio) * ISA_SEA_LEVEL_TEMPERATURE_K / ISA_LAPSE_RATE_K_M


def isa_temperature_c(altitude_amsl_m: float) -> float:
    """Air temperature (deg C) at ``altitude_amsl_m`` (m) in the ISA troposphere."""
    return ISA_SEA_LEVEL_TEMPERATURE_C - ISA_LAPSE_RATE_K_M * altitude_amsl_m


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
        self.rng = rng = random.Random(config.seed)
        gauss = rng.gauss
        a, g = config.accelerometer, config.gyroscope
        # Switch-on biases: the fixed part plus a draw of the random part (same seed, same bias).
        self.accel_bias = _add(a.bias, _draw3(gauss, a.turn_on_bias_std))
        self.gyro_bias = _add(g.bias, _draw3(gauss, g.turn_on_bias_std))
        self._accel_std = a.noise_density * math.sqrt(imu_rate_hz)
        self._gyro_std = g.noise_density * math.sqrt(imu_rate_hz)
        self._mag = config.magnetometer
        self.mag_bias = _add(
            config.magnetometer.bias_gauss, _draw3(gauss, config.magnetometer.turn_on_bias_std_gauss)
        )
        self._field = config.magnetometer.earth_field_world_gauss
        self._baro = config.barometer
        self.baro_drift_hpa = 0.0
        self._gps = gps = config.gps
        self._vision = config.vision
        # Gauss-Markov GPS errors start from their stationary distribution.
        self.gps_position_error = (
            gauss(0.0, gps.horizontal_noise_std_m) if gps.horizontal_noise_std_m > 0.0 else 0.0,
            gauss(0.0, gps.horizontal_noise_std_m) if gps.horizontal_noise_std_m > 0.0 else 0.0,
            gauss(0.0, gps.vertical_noise_std_m) if gps.vertical_noise_std_m > 0.0 else 0.0,
        )
        s = gps.velocity_noise_std_m_s
        self.gps_velocity_error = _draw3(gauss, s) if s > 0.0 else _Z3
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
        rng = self.rng
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
            vision = vision_s.deliver(t_s, self._vision_pose(truth, t_s, rng))
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
        gauss = self.rng.gauss
        a, g = self.config.accelerometer, self.config.gyroscope
        if a.bias_random_walk > 0.0:
            self.accel_bias = _add(self.accel_bias, _draw3(gauss, a.bias_random_walk * math.sqrt(dt)))
        if g.bias_random_walk > 0.0:
            self.gyro_bias = _add(self.gyro_bias, _draw3(gauss, g.bias_random_walk * math.sqrt(dt)))
        if self._baro.drift_hpa_rthz > 0.0:
            self.baro_drift_hpa += gauss(0.0, self._baro.drift_hpa_rthz * math.sqrt(dt))

    def _imu(self, truth: TruthState, t: float) -> ImuReading:
        ba, bg = self.imu_biases(t) if self.faults else (self.accel_bias, self.gyro_bias)
        return ImuReading(
            self._perturb(truth.specific_force_body_m_s2, ba, self._accel_std),
            self._perturb(truth.body_rates_rad_s, bg, self._gyro_std),
            t,
        )

    def _perturb(self, v: Vector3, bias: Vector3, std: float) -> Vector3:
        if std > 0.0:
            gauss = self.rng.gauss
            return (
                v[0] + bias[0] + gauss(0.0, std),
                v[1] + bias[1] + gauss(0.0, std),
                v[2] + bias[2] + gauss(0.0, std),
            )
        return (v[0] + bias[0], v[1] + bias[1], v[2] + bias[2])

    def _magnetometer(self, truth: TruthState, t: float) -> Vector3:
        # Earth field into the body: R^T b_world (R maps body to world; rotation_from_quaternion's
        # entries written out, the same operations: the magnetometer may sample every frame).
        w, x, y, z = truth.quaternion
        xx, yy, zz = x * x, y * y, z * z
        xy, xz, yz = x * y, x * z, y * z
        wx, wy, wz = w * x, w * y, w * z
        bx, by, bz = self._field
        field_body = (
            (1.0 - 2.0 * (yy + zz)) * bx + 2.0 * (xy + wz) * by + 2.0 * (xz - wy) * bz,
            2.0 * (xy - wz) * bx + (1.0 - 2.0 * (xx + zz)) * by + 2.0 * (yz + wx) * bz,
            2.0 * (xz + wy) * bx + 2.0 * (yz - wx) * by + (1.0 - 2.0 * (xx + yy)) * bz,
        )
        bias = self.mag_bias
        if self.faults:
            bias = _add(bias, self._fault_sum("mag_disturbance", t))
        return self._perturb(field_body, bias, self._mag.noise_std_gauss)

    def _barometer(self, truth: TruthState, t: float) -> BaroReading:
        altitude = self.home_altitude_m + truth.position_m[2]
        pressure = isa_pressure_hpa(altitude) + self._baro.bias_hpa + self.baro_drift_hpa
        if self._baro.noise_std_hpa > 0.0:
            pressure += self.rng.gauss(0.0, self._baro.noise_std_hpa)
        return BaroReading(pressure, isa_altitude_m(pressure), isa_temperature_c(altitude), t)

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
        """First-order Gauss-Markov, exact discretisation: x <- a x + s sqrt(1 - a^2) n, a = e^(-dt/tau)."""
        gps = self._gps
        gauss = self.rng.gauss
        e = self.gps_position_error
        tau = gps.position_correlation_time_s
        a = math.exp(-dt / tau) if tau > 0.0 else 0.0
        k = math.sqrt(1.0 - a * a)
        sh, sv = gps.horizontal_noise_std_m, gps.vertical_noise_std_m
        self.gps_position_error = (
            a * e[0] + k * gauss(0.0, sh) if sh > 0.0 else 0.0,
            a * e[1] + k * gauss(0.0, sh) if sh > 0.0 else 0.0,
            a * e[2] + k * gauss(0.0, sv) if sv > 0.0 else 0.0,
        )
        s = gps.velocity_noise_std_m_s
        if s > 0.0:
            u = self.gps_velocity_error
            tau = gps.velocity_correlation_time_s
            a = math.exp(-dt / tau) if tau > 0.0 else 0.0
            k = math.sqrt(1.0 - a * a)
            self.gps_velocity_error = (
                a * u[0] + k * gauss(0.0, s),
                a * u[1] + k * gauss(0.0, s),
                a * u[2] + k * gauss(0.0, s),
            )

    def _vision_pose(self, truth: TruthState, t: float, rng: random.Random) -> VisionReading:
        vis = self._vision
        p = truth.position_m
        s = vis.position_noise_std_m
        if s > 0.0:
            p = (p[0] + rng.gauss(0.0, s), p[1] + rng.gauss(0.0, s), p[2] + rng.gauss(0.0, s))
        yaw = truth.euler_rad[2]
        if vis.yaw_noise_std_rad > 0.0:
            yaw = wrap_pi(yaw + rng.gauss(0.0, vis.yaw_noise_std_rad))
        return VisionReading(t, p, yaw, s, vis.yaw_noise_std_rad)

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


def _draw3(gauss, std: float) -> Vector3:
    if std <= 0.0:
        return _Z3
    return (gauss(0.0, std), gauss(0.0, std), gauss(0.0, std))
