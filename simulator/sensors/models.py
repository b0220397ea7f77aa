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

What a sample is (truth + bias + noise, the Gauss-Markov errors) is written once as kernels in
:mod:`.kernels`, the ISA in :mod:`quadcommon.atmosphere`; this module decides when each sensor
samples and what it delivers, and calls their entries. Noise is drawn from one seeded stream
(:mod:`quadcommon.rng`, seeded from the config), so a run is repeatable, and a batch engine
calling the same kernels with the same seed draws the same noise; a sensor whose noise is zero
draws nothing.
"""

from __future__ import annotations

import functools
import math
from dataclasses import replace
from typing import Any, NamedTuple

import numpy as np

from quadcommon import rng as random_stream
from quadcommon.failures import Type
from quadcommon.kernel import compiled, compiling, freeze
from quadcommon.layout import generated

from ..dynamics.plant import TruthState
from . import frame, kernels
from .config import SensorConfig, SensorFault, default_fault_value, fault_unit, load_sensors

Vector3 = tuple[float, float, float]

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
    (``baro_fresh``) is False: the encoder then clears those bits of ``fields_updated``. The IMU
    samples at every frame unless a failure stops it (``accel_fresh``, ``gyro_fresh``).
    """

    imu: ImuReading
    magnetic_field_gauss: Vector3  # body, front-left-up
    baro: BaroReading
    mag_fresh: bool = True
    baro_fresh: bool = True
    accel_fresh: bool = True  # False: the accelerometer holds its last sample (a failure: off, slow...)
    gyro_fresh: bool = True


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


# What step() makes of a frame's delivery: its readings, read at offsets generated from the layout.
_delivered = generated(frame.DELIVERY, """
def delivered(x, t_s):
    imu = ImuReading({force}, {rate}, t_s)
    mag = MagReading({mag_time}, {mag_field}) if {mag_fresh} else None
    baro = None
    if {baro_fresh}:
        baro = BaroReading({baro_pressure}, {baro_altitude}, {baro_temperature}, {baro_time})
    gps = None
    if {gps_fresh}:
        gps = GpsReading({gps_position}, {gps_velocity}, {gps_eph}, {gps_epv}, int({gps_satellites}),
                         {gps_time}, {gps_speed_accuracy}, int({gps_fix_type}))
    vision = None
    if {vision_fresh}:
        vision = VisionReading({vision_time}, {vision_position}, {vision_yaw}, {vision_position_std},
                               {vision_yaw_std})
    held_baro = BaroReading({held_baro_pressure}, {held_baro_altitude}, {held_baro_temperature},
                            {held_baro_time})
    readings = SensorReadings(imu, {held_mag}, held_baro, mag is not None, baro is not None,
                              {accel_fresh} != 0.0, {gyro_fresh} != 0.0)
    return SensorFrame(t_s, imu, readings, mag, baro, gps, vision)
""", globals())  # fmt: skip


class SensorSuite:
    """The vehicle's sensors: :meth:`step` once per frame; ``sample``/``sample_gps`` read instantly.

    A thin shell around the kernel :func:`.frame.sensor_frame` (rates, latencies, faults, the
    draws), whose memory it holds; ``imu_rate_hz`` is the frame rate (the IMU samples once per
    frame): it sets the per-sample white noise of the IMU from its density.
    """

    def __init__(self, config: SensorConfig, home_altitude_m: float, imu_rate_hz: float = 500.0) -> None:
        self.config = config
        self.home_altitude_m = home_altitude_m
        self.imu_rate_hz = imu_rate_hz
        self._k = k = sensor_entries()
        # Switch-on biases: the fixed part plus a draw of the random part (same seed, same bias).
        self.rng, self._S, self._C = frame.new_sensors(config, home_altitude_m, imu_rate_hz, k.initial_state)
        self._out = np.zeros(frame.DELIVERY.size)
        self.faults: list[SensorFault] = []
        self._faults = frame.fault_array(())
        for fault in config.faults:
            self.add_fault(fault)

    # -- the state, read from the kernel's memory -----------------------------------------------------
    def _vector(self, at: int) -> Vector3:
        s = self._S
        return (float(s[at]), float(s[at + 1]), float(s[at + 2]))

    @property
    def accel_bias(self) -> Vector3:
        """Switch-on bias + random walk so far (without injected steps)."""
        return self._vector(frame.STATE.accel_bias)

    @property
    def gyro_bias(self) -> Vector3:
        """The gyro's bias so far (rad/s, body): switch-on bias plus random walk."""
        return self._vector(frame.STATE.gyro_bias)

    @property
    def mag_bias(self) -> Vector3:
        """The magnetometer's hard-iron bias (gauss, body)."""
        return self._vector(frame.STATE.mag_bias)

    @property
    def baro_drift_hpa(self) -> float:
        """The barometer's drifted offset so far (hPa)."""
        return float(self._S[frame.STATE.baro_drift])

    @property
    def gps_position_error(self) -> Vector3:
        """The GNSS position error now (m, world): the Gauss-Markov processes' state."""
        return self._vector(frame.STATE.gps_position_error)

    @property
    def gps_velocity_error(self) -> Vector3:
        """The GNSS velocity error now (m/s, world)."""
        return self._vector(frame.STATE.gps_velocity_error)

    # -- faults -----------------------------------------------------------------------------------
    def add_fault(self, fault: SensorFault) -> None:
        """Inject ``fault`` (see :data:`~simulator.sensors.config.FAULT_KINDS`)."""
        self.faults.append(fault)
        self._faults = frame.fault_array(self.faults)

    def inject_failure(self, unit: str, failure_type: int, t_s: float) -> None:
        """A failure of the sensor ``unit`` (``gps``, ``baro``, ... of :mod:`quadcommon.failures`)
        from ``t_s`` on: the unit's active faults end at ``t_s``; unless ``failure_type`` is ok, a
        fault of kind ``<unit>_<type>`` starts there with the table's figure."""
        ended = [replace(f, duration_s=t_s - f.start_s) if fault_unit(f.kind) == unit and f.active(t_s) else f
                 for f in self.faults]  # fmt: skip
        if failure_type != Type.ok:
            kind = f"{unit}_{Type(failure_type).name}"
            ended.append(SensorFault(kind, t_s, math.inf, default_fault_value(kind)))
        self.faults = ended
        self._faults = frame.fault_array(self.faults)

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

    # -- the timed interface ------------------------------------------------------------------------
    def step(self, t_s: float, truth: TruthState) -> SensorFrame:
        """Advance the sensors' random walks to ``t_s`` and return what is delivered at ``t_s``."""
        self.deliver(t_s, truth)
        return self.delivered(t_s)

    def deliver(self, t_s: float, truth: TruthState) -> np.ndarray:
        """:meth:`step` as the flat delivery (:data:`.frame.DELIVERY`; the suite's own buffer,
        overwritten by the next call), for compiled code that reads it: the simulator's frame."""
        self._k.sensor_frame_fields(self.rng, self._S, self._C, self._faults, t_s, tuple(truth), self._out)
        return self._out

    def delivered(self, t_s: float) -> SensorFrame:
        """What the last :meth:`deliver` (at ``t_s``) delivered, as :meth:`step` returns it."""
        return _delivered(self._out.tolist(), t_s)

    # -- instantaneous reads (no time: codec tests, single samples) -----------------------------------
    def _time(self) -> float:
        t = float(self._S[frame.STATE.t_last])
        return 0.0 if math.isnan(t) else t

    def _imu(self, truth: TruthState, t: float) -> ImuReading:
        ba, bg = self.imu_biases(t)
        std_a, std_g = float(self._C[frame.FIGURES.accel_std]), float(self._C[frame.FIGURES.gyro_std])
        force, rates = self._k.imu_reading(self.rng, truth.specific_force_body_m_s2, truth.body_rates_rad_s,
                                           ba, bg, std_a, std_g)  # fmt: skip
        return ImuReading(force, rates, t)

    def _magnetometer(self, truth: TruthState, t: float) -> Vector3:
        return self._k.magnetometer(self.rng, self._S, self._C, self._faults, truth.quaternion, t)

    def _barometer(self, truth: TruthState, t: float) -> BaroReading:
        pressure, altitude, temperature = self._k.barometer(self.rng, self._S, self._C, truth.position_m[2])
        return BaroReading(pressure, altitude, temperature, t)

    def sample(self, truth: TruthState) -> SensorReadings:
        """IMU, magnetometer and barometer readings for ``truth`` now (no rate, latency or drift)."""
        t = self._time()
        return SensorReadings(self._imu(truth, t), self._magnetometer(truth, t), self._barometer(truth, t))

    def sample_gps(self, truth: TruthState) -> GpsReading:
        """One GPS fix for ``truth`` now (no latency; the Gauss-Markov errors advance one period)."""
        t_gps = float(self._S[frame.STATE.t_gps])
        t = 0.0 if math.isnan(t_gps) else t_gps + float(self._C[frame.FIGURES.period + frame.GPS])
        r, G = np.empty(frame.GPS_READING.size), frame.GPS_READING
        self._k.gps_fix(self.rng, self._S, self._C, self._faults, t, truth.position_m, truth.velocity_m_s, r)
        o = r.tolist()
        p, v = G.position, G.velocity
        return GpsReading((o[p], o[p + 1], o[p + 2]), (o[v], o[v + 1], o[v + 2]), o[G.eph], o[G.epv],
                          int(o[G.satellites]), o[G.time], o[G.speed_accuracy],
                          int(o[G.fix_type]))  # fmt: skip


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
    initial_state: Any
    sensor_frame_fields: Any
    gps_fix: Any
    magnetometer: Any
    barometer: Any


def sensor_kernels() -> SensorEntries:
    """The kernels themselves (what Python runs where nothing compiles)."""

    def source(name: str) -> Any:
        if name == "normal":
            return random_stream
        return kernels if name in _ARITHMETIC else frame

    return SensorEntries(*(getattr(source(name), name) for name in SensorEntries._fields))


_ARITHMETIC = ("draw3", "stationary", "random_walk", "imu_reading", "magnetometer_reading",
               "barometer_reading", "gauss_markov", "vision_reading")  # fmt: skip


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
        config = load_sensors("gps")
        C = frame.config_array(config, 488.0, 500.0)
        S, out = np.zeros(frame.STATE.size), np.zeros(frame.DELIVERY.size)
        faults = frame.fault_array(config.faults)
        entries.initial_state(rng, C, z3, z3, z3, 0.1, 0.1, 0.1, S)
        truth = TruthState(position_m=z3, velocity_m_s=z3, acceleration_m_s2=z3, quaternion=q,
                           euler_rad=z3, body_rates_rad_s=z3, euler_rates_rad_s=z3,
                           specific_force_body_m_s2=(0.0, 0.0, 9.81), rotor_speeds_rad_s=(0.0, 0.0, 0.0, 0.0),
                           thrust_n=0.0, torque_body_n_m=z3, on_ground=True)  # fmt: skip
        entries.sensor_frame_fields(rng, S, C, faults, 0.0, tuple(truth), out)
        entries.gps_fix(rng, S, C, faults, 0.1, z3, z3, np.empty(12))
        entries.magnetometer(rng, S, C, faults, q, 0.0)
        entries.barometer(rng, S, C, 1.0)
        for entry in entries:
            freeze(entry)
    return entries
