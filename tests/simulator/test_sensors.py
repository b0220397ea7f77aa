"""Sensor models: exact by default, bias and white noise as configured, physics of the field/baro."""

from __future__ import annotations

import math
import statistics
from dataclasses import replace

import pytest

from quadcommon import frames
from quadcommon.config import load_vehicle
from quadcommon.schema import ConfigError
from simulator.dynamics.plant import Plant, TruthState
from simulator.sensors import (
    EXACT,
    SensorSuite,
    isa_altitude_m,
    isa_pressure_hpa,
    isa_temperature_c,
    load_sensors,
)
from simulator.sensors.config import GpsModel, NoisyVector

HOME_ALT = 488.0


def truth_at(
    position=(1.0, 2.0, 3.0), euler=(0.1, -0.2, 0.7), rates=(0.3, -0.1, 0.2), velocity=(1.0, -0.5, 0.2)
):
    plant = Plant(load_vehicle("paper_quad"), 0.001)
    plant.reset(position, euler, velocity, rates)
    plant.set_wrench(9.0, (0.01, -0.02, 0.003))
    return plant.truth()


def test_default_config_is_exact_and_matches_the_builtin_record():
    config = load_sensors("default")
    assert replace(config, name="exact") == EXACT
    assert config.earth_field_world_gauss == pytest.approx((0.21, -0.016, -0.43))  # NED -> z up


def test_exact_sensors_read_the_truth():
    truth = truth_at()
    suite = SensorSuite(EXACT, HOME_ALT)
    readings = suite.sample(truth)
    assert readings.imu.specific_force_m_s2 == truth.specific_force_body_m_s2
    assert readings.imu.angular_rate_rad_s == truth.body_rates_rad_s
    gps = suite.sample_gps(truth)
    assert gps.position_m == truth.position_m and gps.velocity_m_s == truth.velocity_m_s
    assert readings.baro.pressure_altitude_m == pytest.approx(HOME_ALT + 3.0, abs=1e-6)


def test_magnetometer_reads_the_earth_field_rotated_into_the_body():
    suite = SensorSuite(EXACT, HOME_ALT)
    level = suite.sample(truth_at(euler=(0.0, 0.0, 0.0))).magnetic_field_gauss
    assert level == pytest.approx(EXACT.earth_field_world_gauss, abs=1e-12)
    # Nose turned 90 deg left (paper yaw +pi/2, to the west): north now lies on the body's right
    # (-y of front-left-up) and the field's east component points backwards (-x).
    west = suite.sample(truth_at(euler=(0.0, 0.0, math.pi / 2))).magnetic_field_gauss
    assert west == pytest.approx((-0.016, -0.21, -0.43), abs=1e-12)
    # A rotation keeps the field's magnitude, whatever the attitude.
    tilted = suite.sample(truth_at()).magnetic_field_gauss
    assert math.dist(tilted, (0, 0, 0)) == pytest.approx(math.dist(EXACT.earth_field_world_gauss, (0, 0, 0)))
    # Through frames.vector_to_ned (what the wire carries) the body field is FRD.
    assert frames.vector_to_ned(level) == pytest.approx((0.21, 0.016, 0.43))


def test_isa_standard_values_and_inverse():
    assert isa_pressure_hpa(0.0) == pytest.approx(1013.25)
    assert isa_pressure_hpa(1000.0) == pytest.approx(898.75, abs=0.05)  # ICAO table
    assert isa_pressure_hpa(5000.0) == pytest.approx(540.20, abs=0.05)
    assert isa_temperature_c(1000.0) == pytest.approx(8.5)
    for h in (-300.0, 0.0, 488.0, 4321.0):
        assert isa_altitude_m(isa_pressure_hpa(h)) == pytest.approx(h, abs=1e-6)
    # About 0.12 hPa per metre near sea level: a 1 m climb is visible to a barometer.
    assert isa_pressure_hpa(HOME_ALT) - isa_pressure_hpa(HOME_ALT + 1.0) == pytest.approx(0.113, abs=0.01)


def noisy_config(seed=7):
    return replace(
        EXACT,
        seed=seed,
        accelerometer=NoisyVector(0.5, (0.1, -0.2, 0.3)),
        gyroscope=NoisyVector(0.02, (0.01, 0.0, -0.01)),
        magnetometer=NoisyVector(0.01, (0.0, 0.05, 0.0)),
        barometer_noise_std_hpa=0.2,
        barometer_bias_hpa=1.0,
        gps=GpsModel(0.5, 0.8, 0.1, 2.0, 3.0, 7),
    )


def test_bias_and_white_noise_have_the_configured_statistics():
    truth = truth_at()
    suite = SensorSuite(noisy_config(), HOME_ALT)
    samples = [suite.sample(truth) for _ in range(4000)]
    for axis in range(3):
        errors = [s.imu.specific_force_m_s2[axis] - truth.specific_force_body_m_s2[axis] for s in samples]
        assert statistics.fmean(errors) == pytest.approx((0.1, -0.2, 0.3)[axis], abs=0.03)
        assert statistics.stdev(errors) == pytest.approx(0.5, rel=0.05)
        gyro = [s.imu.angular_rate_rad_s[axis] - truth.body_rates_rad_s[axis] for s in samples]
        assert statistics.stdev(gyro) == pytest.approx(0.02, rel=0.05)
    p_true = isa_pressure_hpa(HOME_ALT + truth.position_m[2])
    baro = [s.baro.pressure_hpa - p_true for s in samples]
    assert statistics.fmean(baro) == pytest.approx(1.0, abs=0.02)
    assert statistics.stdev(baro) == pytest.approx(0.2, rel=0.05)
    # A +1 hPa bias reads as ~8.8 m lower: the altitude follows the (noisy) pressure.
    assert statistics.fmean(s.baro.pressure_altitude_m for s in samples) < HOME_ALT + 3.0 - 8.0
    fixes = [suite.sample_gps(truth) for _ in range(2000)]
    assert statistics.stdev(f.position_m[0] for f in fixes) == pytest.approx(0.5, rel=0.07)
    assert statistics.stdev(f.position_m[2] for f in fixes) == pytest.approx(0.8, rel=0.07)
    assert statistics.stdev(f.velocity_m_s[1] for f in fixes) == pytest.approx(0.1, rel=0.07)
    assert (fixes[0].eph_m, fixes[0].epv_m, fixes[0].satellites_visible) == (2.0, 3.0, 7)


def test_same_seed_same_noise_other_seed_other_noise():
    truth = truth_at()
    a = [SensorSuite(noisy_config(3), HOME_ALT).sample(truth) for _ in range(1)]
    b = [SensorSuite(noisy_config(3), HOME_ALT).sample(truth) for _ in range(1)]
    c = [SensorSuite(noisy_config(4), HOME_ALT).sample(truth) for _ in range(1)]
    assert a == b and a != c


def test_sensors_take_a_truth_state_only():
    """Pure: a hand-made TruthState (no plant) is enough."""
    truth = TruthState(
        position_m=(0.0, 0.0, 0.0), velocity_m_s=(0.0, 0.0, 0.0), acceleration_m_s2=(0.0, 0.0, 0.0),
        quaternion=(1.0, 0.0, 0.0, 0.0), euler_rad=(0.0, 0.0, 0.0), body_rates_rad_s=(0.0, 0.0, 0.0),
        euler_rates_rad_s=(0.0, 0.0, 0.0), specific_force_body_m_s2=(0.0, 0.0, 9.81),
        rotor_speeds_rad_s=(0.0, 0.0, 0.0, 0.0), thrust_n=0.0, torque_body_n_m=(0.0, 0.0, 0.0),
        on_ground=True,
    )  # fmt: skip
    readings = SensorSuite(EXACT, 0.0).sample(truth)
    assert readings.imu.specific_force_m_s2 == (0.0, 0.0, 9.81)
    assert readings.baro.pressure_hpa == pytest.approx(1013.25)
    assert readings.baro.temperature_c == pytest.approx(15.0)


def test_config_errors_name_file_key_and_range(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text("[gyroscope]\nnoise_std_rad_s = -1.0\n")
    with pytest.raises(ConfigError, match=r"bad.toml: key 'gyroscope.noise_std_rad_s' = -1.0"):
        load_sensors(path)
    path.write_text("[gps]\nsatelites_visible = 3\n")
    with pytest.raises(ConfigError, match="unknown key 'gps.satelites_visible'"):
        load_sensors(path)
    with pytest.raises(ConfigError, match="no sensors named 'nope'"):
        load_sensors("nope")
