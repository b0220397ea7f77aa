"""Sensor models: ground truth in, readings out (pure: no clocks, no I/O; the caller owns time).

Every reading is in the paper's frames (body front-left-up, world x north / y west / z up) and SI
units (plus gauss and hPa, the units of ``HIL_SENSOR``); the MAVLink edge
(:mod:`simulator.mavlink.hil_frame`) turns them into NED/FRD and scaled integers.

* IMU: an ideal accelerometer and gyroscope at the geometric centre O: specific force and body
  rates from :class:`TruthState`, plus a constant bias and white noise.
* Magnetometer: a fixed earth field at home (world frame) rotated into the body, plus bias/noise.
* Barometer: the International Standard Atmosphere (troposphere) at the altitude AMSL of O;
  bias and noise are on the pressure, and ``pressure_altitude_m`` is what the noisy pressure
  means under the ISA (as a real baro driver computes it).
* GPS: position and velocity of O in the world frame plus white noise (per axis).

Noise is drawn from one :class:`random.Random` seeded from the config, so a run is repeatable;
a sensor whose noise is zero draws nothing (an exact sensor costs one tuple).
"""

from __future__ import annotations

import random
from typing import NamedTuple

from quadcommon.rigid_body import rotation_from_quaternion

from ..dynamics.plant import TruthState
from .config import SensorConfig

Vector3 = tuple[float, float, float]

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


class BaroReading(NamedTuple):
    pressure_hpa: float
    pressure_altitude_m: float  # AMSL, from the (noisy) pressure under the ISA
    temperature_c: float


class SensorReadings(NamedTuple):
    """What ``HIL_SENSOR`` carries: IMU, magnetometer and barometer of one frame."""

    imu: ImuReading
    magnetic_field_gauss: Vector3  # body, front-left-up
    baro: BaroReading


class GpsReading(NamedTuple):
    """One GPS fix in the paper's world frame (the MAVLink edge makes it geodetic)."""

    position_m: Vector3  # world (x north, y west, z up), relative to home
    velocity_m_s: Vector3  # world
    eph_m: float
    epv_m: float
    satellites_visible: int


class SensorSuite:
    """The vehicle's sensors: ``sample(truth)`` each frame, ``sample_gps(truth)`` per fix."""

    def __init__(self, config: SensorConfig, home_altitude_m: float) -> None:
        self.config = config
        self.home_altitude_m = home_altitude_m
        self.rng = random.Random(config.seed)
        self._accel = config.accelerometer
        self._gyro = config.gyroscope
        self._mag = config.magnetometer
        self._field = config.earth_field_world_gauss
        self._baro_std = config.barometer_noise_std_hpa
        self._baro_bias = config.barometer_bias_hpa
        self._gps = config.gps

    def _perturb(self, v: Vector3, bias: Vector3, std: float) -> Vector3:
        if std > 0.0:
            gauss = self.rng.gauss
            return (
                v[0] + bias[0] + gauss(0.0, std),
                v[1] + bias[1] + gauss(0.0, std),
                v[2] + bias[2] + gauss(0.0, std),
            )
        return (v[0] + bias[0], v[1] + bias[1], v[2] + bias[2])

    def sample(self, truth: TruthState) -> SensorReadings:
        """IMU, magnetometer and barometer readings for the state ``truth``."""
        a, g, m = self._accel, self._gyro, self._mag
        imu = ImuReading(
            self._perturb(truth.specific_force_body_m_s2, a.bias, a.noise_std),
            self._perturb(truth.body_rates_rad_s, g.bias, g.noise_std),
        )
        # Earth field into the body: R^T b_world (R maps body to world).
        R = rotation_from_quaternion(*truth.quaternion)
        bx, by, bz = self._field
        field_body = (
            R[0][0] * bx + R[1][0] * by + R[2][0] * bz,
            R[0][1] * bx + R[1][1] * by + R[2][1] * bz,
            R[0][2] * bx + R[1][2] * by + R[2][2] * bz,
        )
        mag = self._perturb(field_body, m.bias, m.noise_std)
        altitude = self.home_altitude_m + truth.position_m[2]
        pressure = isa_pressure_hpa(altitude) + self._baro_bias
        if self._baro_std > 0.0:
            pressure += self.rng.gauss(0.0, self._baro_std)
        baro = BaroReading(pressure, isa_altitude_m(pressure), isa_temperature_c(altitude))
        return SensorReadings(imu, mag, baro)

    def sample_gps(self, truth: TruthState) -> GpsReading:
        """One GPS fix for the state ``truth``."""
        gps = self._gps
        position, velocity = truth.position_m, truth.velocity_m_s
        h, v, s = gps.horizontal_noise_std_m, gps.vertical_noise_std_m, gps.velocity_noise_std_m_s
        if h > 0.0 or v > 0.0 or s > 0.0:
            gauss = self.rng.gauss
            position = (
                position[0] + gauss(0.0, h) if h > 0.0 else position[0],
                position[1] + gauss(0.0, h) if h > 0.0 else position[1],
                position[2] + gauss(0.0, v) if v > 0.0 else position[2],
            )
            if s > 0.0:
                velocity = (
                    velocity[0] + gauss(0.0, s),
                    velocity[1] + gauss(0.0, s),
                    velocity[2] + gauss(0.0, s),
                )
        return GpsReading(position, velocity, gps.eph_m, gps.epv_m, gps.satellites_visible)
