"""The sensor models' arithmetic, written once as kernels (:mod:`quadcommon.kernel`): what a reading
is, given the truth, the sensor's biases and its noise stream (:mod:`quadcommon.rng`).

:class:`~.models.SensorSuite` (the simulator) calls their compiled entries, or these functions
in Python where nothing compiles; a batch engine calls them from its own compiled loop. The
rates, latencies, faults and the readings' records stay in :mod:`.models` (Python): they decide
*when* a sensor samples and what it delivers, not what a sample is.

Every deviate comes from the one stream ``rng`` in a fixed order (x, y, z per vector; a sensor
whose standard deviation is zero draws nothing), so the same seed and the same calls give the
same readings wherever they run. Frames and units: those of :mod:`.models` (paper frames, SI,
gauss and hPa).
"""

from __future__ import annotations

import math
from typing import Any

from quadcommon.atmosphere import isa_altitude_m, isa_pressure_hpa, isa_temperature_c
from quadcommon.frames import wrap_pi
from quadcommon.kernel import kernel
from quadcommon.rigid_body import Quaternion, Vector3, rotation_from_quaternion, transpose_times
from quadcommon.rng import normal


@kernel
def draw3(rng: Any, std: float) -> Vector3:
    """Three independent deviates of standard deviation ``std`` (none drawn when it is 0)."""
    if std <= 0.0:
        return (0.0, 0.0, 0.0)
    x = std * normal(rng)
    y = std * normal(rng)
    z = std * normal(rng)
    return (x, y, z)


@kernel
def with_noise(rng: Any, value: Vector3, bias: Vector3, std: float) -> Vector3:
    """``value + bias + white noise`` of ``std`` per axis."""
    n = draw3(rng, std)
    return (value[0] + bias[0] + n[0], value[1] + bias[1] + n[1], value[2] + bias[2] + n[2])


@kernel
def random_walk(rng: Any, bias: Vector3, density: float, dt: float) -> Vector3:
    """A bias after ``dt`` of a random walk of ``density`` (unit per sqrt(s)) per axis."""
    if density <= 0.0 or dt <= 0.0:
        return bias
    n = draw3(rng, density * math.sqrt(dt))
    return (bias[0] + n[0], bias[1] + n[1], bias[2] + n[2])


@kernel
def imu_reading(
    rng: Any,
    specific_force: Vector3,
    body_rates: Vector3,
    accel_bias: Vector3,
    gyro_bias: Vector3,
    accel_std: float,
    gyro_std: float,
) -> tuple[Vector3, Vector3]:
    """Accelerometer and gyro of one IMU sample: truth + bias + white noise (per-sample std)."""
    force = with_noise(rng, specific_force, accel_bias, accel_std)
    rates = with_noise(rng, body_rates, gyro_bias, gyro_std)
    return force, rates


@kernel
def magnetometer_reading(rng: Any, q: Quaternion, field_world: Vector3, bias: Vector3, std: float) -> Vector3:
    """The earth field in the body (``R^T b``, ``R`` body to world), plus hard iron and noise."""
    R = rotation_from_quaternion(q[0], q[1], q[2], q[3])
    return with_noise(rng, transpose_times(R, field_world), bias, std)


@kernel
def barometer_reading(
    rng: Any, altitude_amsl_m: float, bias_hpa: float, drift_hpa: float, std_hpa: float
) -> tuple[float, float, float]:
    """``(pressure hPa, pressure altitude m, temperature deg C)``: bias, drift and noise are on
    the pressure; the altitude is what the noisy pressure means under the ISA."""
    pressure = isa_pressure_hpa(altitude_amsl_m) + bias_hpa + drift_hpa
    if std_hpa > 0.0:
        pressure += std_hpa * normal(rng)
    return pressure, isa_altitude_m(pressure), isa_temperature_c(altitude_amsl_m)


@kernel
def gauss_markov(rng: Any, error: Vector3, dt: float, tau: float, std: Vector3) -> Vector3:
    """First-order Gauss-Markov errors after ``dt``, exact discretisation per axis:
    ``x <- a x + s sqrt(1 - a^2) n``, ``a = exp(-dt / tau)`` (``tau = 0``: white). An axis with
    ``s = 0`` is exactly 0 and draws nothing."""
    a = math.exp(-dt / tau) if tau > 0.0 else 0.0
    k = math.sqrt(1.0 - a * a)
    x = a * error[0] + k * std[0] * normal(rng) if std[0] > 0.0 else 0.0
    y = a * error[1] + k * std[1] * normal(rng) if std[1] > 0.0 else 0.0
    z = a * error[2] + k * std[2] * normal(rng) if std[2] > 0.0 else 0.0
    return (x, y, z)


@kernel
def stationary(rng: Any, std: Vector3) -> Vector3:
    """A Gauss-Markov error drawn from its stationary distribution (a receiver switched on long
    ago): per axis a deviate of ``std`` (none drawn for a zero ``std``)."""
    x = std[0] * normal(rng) if std[0] > 0.0 else 0.0
    y = std[1] * normal(rng) if std[1] > 0.0 else 0.0
    z = std[2] * normal(rng) if std[2] > 0.0 else 0.0
    return (x, y, z)


@kernel
def vision_reading(
    rng: Any, position: Vector3, yaw: float, position_std: float, yaw_std: float
) -> tuple[Vector3, float]:
    """A motion-capture pose: position of O and the paper's yaw with white noise."""
    p = with_noise(rng, position, (0.0, 0.0, 0.0), position_std)
    if yaw_std > 0.0:
        yaw = wrap_pi(yaw + yaw_std * normal(rng))
    return p, yaw
