"""One frame of the sensors as a kernel (simulator/sensors/frame.py): SensorSuite is its shell, and
a batch engine calling it on its own arrays draws the same readings from the same seed."""

from __future__ import annotations

import math

import numpy as np
import pytest

from quadcommon.kernel import compiling
from quadcommon.rigid_body import quaternion_from_euler
from quadcommon.rng import stream
from simulator.dynamics.equations import TruthState
from simulator.sensors import SensorFault, SensorSuite, load_sensors
from simulator.sensors import frame as sf
from simulator.sensors.models import sensor_entries, sensor_kernels

pytestmark = pytest.mark.timeout(120)

DT = 0.002
HOME_ALTITUDE = 488.0


def truth_at(t: float):
    q = quaternion_from_euler(0.05 * math.sin(t), 0.03, 0.3 * t)
    position = (math.cos(0.3 * t), math.sin(0.3 * t), 1.0 + 0.2 * t)
    velocity = (-0.3 * math.sin(0.3 * t), 0.3 * math.cos(0.3 * t), 0.2)
    return (0.1, -0.05, 9.81), (0.01, -0.02, 0.3), q, position, velocity, 0.3 * t


def fly_arrays(entries, config, frames: int) -> list[list[float]]:
    """The frames' deliveries from :func:`sf.sensor_frame` called directly (its entry)."""
    a, g, m = config.accelerometer, config.gyroscope, config.magnetometer
    rng, C = stream(config.seed), sf.config_array(config, HOME_ALTITUDE, 1.0 / DT)
    S, out, faults = np.zeros(sf.STATE.size), np.zeros(sf.DELIVERY.size), sf.fault_array(config.faults)
    f3 = lambda v: tuple(float(c) for c in v)  # noqa: E731
    entries.initial_state(rng, C, f3(a.bias), f3(g.bias), f3(m.bias_gauss), float(a.turn_on_bias_std),
                          float(g.turn_on_bias_std), float(m.turn_on_bias_std_gauss), S)  # fmt: skip
    rows = []
    for k in range(frames):
        t = k * DT
        force, rates, q, position, velocity, yaw = truth_at(t)
        z3 = (0.0, 0.0, 0.0)  # (what the sensors do not read)
        truth = TruthState(position, velocity, z3, q, (0.0, 0.0, yaw), rates, z3, force, (0.0,) * 4, 0.0, z3,
                           False)  # fmt: skip
        entries.sensor_frame_fields(rng, S, C, faults, t, tuple(truth), out)
        rows.append(out.tolist())
    return rows


def with_faults(name: str):
    from dataclasses import replace

    faults = (SensorFault("gps_glitch", 1.0, 0.5, (5.0, 0.0, 0.0)), SensorFault("gps_outage", 2.0, 0.5),
              SensorFault("mag_disturbance", 0.5, 1.0, (0.1, 0.0, 0.0)),
              SensorFault("accel_bias_step", 1.5, math.inf, (0.0, 0.0, 0.3)))  # fmt: skip
    return replace(load_sensors(name), faults=faults)


@pytest.mark.parametrize("profile", ["gps", "mocap"])
def test_the_suite_is_a_shell_around_the_frame_kernel(profile):
    """SensorSuite.step delivers exactly what the kernel writes (same seed, same draws), and the
    rates, latencies and faults are those of the profile."""
    from simulator.dynamics.plant import TruthState

    config = with_faults(profile)
    rows = fly_arrays(sensor_entries(), config, 1500)
    suite = SensorSuite(config, HOME_ALTITUDE, imu_rate_hz=1.0 / DT)
    gps_times, gps_fix_types, glitched = [], [], []
    for k, row in enumerate(rows):
        t = k * DT
        force, rates, q, position, velocity, yaw = truth_at(t)
        z3 = (0.0, 0.0, 0.0)
        rotors = (0.0, 0.0, 0.0, 0.0)
        euler = (0.0, 0.0, yaw)
        truth = TruthState(position, velocity, z3, q, euler, rates, z3, force, rotors, 0.0, z3, False)
        f = suite.step(t, truth)
        assert f.imu.specific_force_m_s2 == tuple(row[sf.DELIVERY.force : sf.DELIVERY.force + 3])
        assert f.readings.magnetic_field_gauss == tuple(row[sf.DELIVERY.held_mag : sf.DELIVERY.held_mag + 3])
        assert (f.gps is not None) == (row[sf.DELIVERY.gps_fresh] == 1.0)
        if f.gps is not None:
            assert f.gps.position_m == tuple(row[sf.DELIVERY.gps_position : sf.DELIVERY.gps_position + 3])
            gps_times.append((t, f.gps.time_s))
            gps_fix_types.append((t, f.gps.fix_type))
            glitched.append((f.gps.time_s, f.gps.position_m[0] - position[0]))
    gps = config.gps
    if gps.enabled:
        delays = [t - valid for t, valid in gps_times]
        assert min(delays) >= gps.latency_s - 1e-9 and max(delays) < gps.latency_s + DT + 1e-9
        assert len(gps_times) == pytest.approx(3.0 * gps.rate_hz, abs=2)
        assert {fix for t, fix in gps_fix_types if 2.0 + gps.latency_s + DT < t < 2.5} == {1}
        assert all(abs(dx - 5.0) < 2.0 for valid, dx in glitched if 1.0 <= valid < 1.5)
    assert suite.imu_biases(2.0)[0][2] - suite.accel_bias[2] == pytest.approx(0.3)


@pytest.mark.skipif(not compiling(), reason="numba is not available: nothing compiles")
def test_compiled_and_python_draw_the_same_readings():
    """The compiled kernel and the same function run by Python give the same bits (the stream is
    exact in float64; the readings are sums and products of its deviates)."""
    config = with_faults("gps")
    compiled_rows = np.array(fly_arrays(sensor_entries(), config, 300))
    python_rows = np.array(fly_arrays(sensor_kernels(), config, 300))
    assert np.allclose(compiled_rows, python_rows, rtol=1e-12, atol=1e-12)
