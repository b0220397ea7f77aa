"""Sensor models: exact by default; noise, bias random walks, Gauss-Markov GPS, rates, latency,
outages and faults as configured; the physics of the field and the barometer."""

from __future__ import annotations

import math
import statistics
from dataclasses import replace

import pytest

from quadcommon import frames
from quadcommon.config import load_scenario, load_vehicle
from quadcommon.schema import ConfigError
from simulator.dynamics.plant import Plant, TruthState
from simulator.sensors import (
    EXACT,
    SensorFault,
    SensorSuite,
    isa_altitude_m,
    isa_pressure_hpa,
    isa_temperature_c,
    load_sensors,
)
from simulator.sensors.config import BaroModel, GpsModel, ImuAxes, VisionModel

HOME_ALT = 488.0
RATE = 500.0
DT = 1.0 / RATE

pytestmark = pytest.mark.timeout(60)


def truth_at(
    position=(1.0, 2.0, 3.0), euler=(0.1, -0.2, 0.7), rates=(0.3, -0.1, 0.2), velocity=(1.0, -0.5, 0.2)
):
    plant = Plant(load_vehicle("paper_quad"), 0.001)
    plant.reset(position, euler, velocity, rates)
    plant.set_wrench(9.0, (0.01, -0.02, 0.003))
    return plant.truth()


def test_ideal_is_exact_default_is_its_alias_and_scenarios_name_a_profile():
    config = load_sensors("ideal")
    assert replace(config, name="exact") == EXACT
    assert load_sensors("default") == config
    assert config.earth_field_world_gauss == pytest.approx((0.21, -0.016, -0.43))  # NED -> z up
    assert load_scenario("helix").sensors == "ideal"


def test_profiles_mocap_and_gps():
    mocap, gps = load_sensors("mocap"), load_sensors("gps")
    assert mocap.vision.enabled and not mocap.gps.enabled
    assert gps.gps.enabled and not gps.vision.enabled
    assert (gps.gps.rate_hz, gps.gps.latency_s) == (10.0, 0.11)
    assert (mocap.vision.rate_hz, mocap.vision.latency_s, mocap.vision.position_noise_std_m) == (
        100.0,
        0.01,
        0.001,
    )
    # Honest accuracy: what the receiver reports is its errors' standard deviation.
    assert gps.gps.reported_eph_m == gps.gps.horizontal_noise_std_m == 0.3
    assert gps.gps.reported_epv_m == gps.gps.vertical_noise_std_m == 0.5
    for c in (mocap, gps):
        assert c.gyroscope.noise_density > 0.0 and c.accelerometer.bias_random_walk > 0.0


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
    tilted = suite.sample(truth_at()).magnetic_field_gauss
    assert math.dist(tilted, (0, 0, 0)) == pytest.approx(math.dist(EXACT.earth_field_world_gauss, (0, 0, 0)))
    assert frames.vector_to_ned(level) == pytest.approx((0.21, 0.016, 0.43))


def test_isa_standard_values_and_inverse():
    assert isa_pressure_hpa(0.0) == pytest.approx(1013.25)
    assert isa_pressure_hpa(1000.0) == pytest.approx(898.75, abs=0.05)  # ICAO table
    assert isa_pressure_hpa(5000.0) == pytest.approx(540.20, abs=0.05)
    assert isa_temperature_c(1000.0) == pytest.approx(8.5)
    for h in (-300.0, 0.0, 488.0, 4321.0):
        assert isa_altitude_m(isa_pressure_hpa(h)) == pytest.approx(h, abs=1e-6)
    assert isa_pressure_hpa(HOME_ALT) - isa_pressure_hpa(HOME_ALT + 1.0) == pytest.approx(0.113, abs=0.01)


def noisy_config(seed=7):
    return replace(
        EXACT,
        seed=seed,
        accelerometer=ImuAxes(0.02, 0.0, (0.1, -0.2, 0.3)),
        gyroscope=ImuAxes(0.001, 0.0, (0.01, 0.0, -0.01)),
        magnetometer=replace(EXACT.magnetometer, noise_std_gauss=0.01, bias_gauss=(0.0, 0.05, 0.0)),
        barometer=BaroModel(500.0, 0.0, 0.2, 1.0, 0.0),
        gps=GpsModel(True, 10.0, 0.0, 0.5, 0.8, 0.0, 0.1, 0.0, 7, eph_m=2.0, epv_m=3.0),
    )


def test_white_noise_and_bias_have_the_configured_statistics():
    truth = truth_at()
    suite = SensorSuite(noisy_config(), HOME_ALT, imu_rate_hz=RATE)
    samples = [suite.sample(truth) for _ in range(4000)]
    for axis in range(3):
        errors = [s.imu.specific_force_m_s2[axis] - truth.specific_force_body_m_s2[axis] for s in samples]
        assert statistics.fmean(errors) == pytest.approx((0.1, -0.2, 0.3)[axis], abs=0.03)
        # Density 0.02 m/s^2/sqrt(Hz) sampled at 500 Hz: 0.447 m/s^2 per sample.
        assert statistics.stdev(errors) == pytest.approx(0.02 * math.sqrt(RATE), rel=0.05)
        gyro = [s.imu.angular_rate_rad_s[axis] - truth.body_rates_rad_s[axis] for s in samples]
        assert statistics.stdev(gyro) == pytest.approx(0.001 * math.sqrt(RATE), rel=0.05)
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


def test_bias_random_walks_have_the_configured_density():
    """Increments of a random walk of density s over dt: N(0, s^2 dt); the baro drift likewise."""
    config = replace(
        EXACT,
        accelerometer=ImuAxes(0.0, 0.05),
        gyroscope=ImuAxes(0.0, 0.002),
        barometer=BaroModel(500.0, 0.0, 0.0, 0.0, 0.01),
    )
    suite = SensorSuite(config, HOME_ALT, imu_rate_hz=RATE)
    truth = truth_at()
    prev = None
    da, dg, dp = [], [], []
    for k in range(5000):
        suite.step(k * DT, truth)
        now = (suite.accel_bias[0], suite.gyro_bias[2], suite.baro_drift_hpa)
        if prev is not None:
            da.append(now[0] - prev[0])
            dg.append(now[1] - prev[1])
            dp.append(now[2] - prev[2])
        prev = now
    assert statistics.stdev(da) == pytest.approx(0.05 * math.sqrt(DT), rel=0.05)
    assert statistics.stdev(dg) == pytest.approx(0.002 * math.sqrt(DT), rel=0.05)
    assert statistics.stdev(dp) == pytest.approx(0.01 * math.sqrt(DT), rel=0.05)
    assert abs(statistics.fmean(da)) < 4.0 * 0.05 * math.sqrt(DT) / math.sqrt(len(da))


def test_gps_errors_are_gauss_markov_with_the_configured_time_constant():
    tau, sigma = 0.5, 0.4
    gps = GpsModel(True, 10.0, 0.0, sigma, sigma, tau, 0.0, 0.0, 10)
    suite = SensorSuite(replace(EXACT, gps=gps), HOME_ALT, imu_rate_hz=RATE)
    truth = truth_at()
    errors = []
    for k in range(20000 * 5):  # 2000 s of frames, one fix each 50
        fix = suite.step(k * DT, truth).gps
        if fix is not None:
            errors.append(fix.position_m[0] - truth.position_m[0])
    assert len(errors) == 2000
    assert statistics.stdev(errors) == pytest.approx(sigma, rel=0.08)
    lag1 = statistics.correlation(errors[:-1], errors[1:])
    assert lag1 == pytest.approx(math.exp(-0.1 / tau), abs=0.04)  # 0.819 at 10 Hz


def test_rates_and_latency_with_validity_times():
    config = replace(
        EXACT,
        magnetometer=replace(EXACT.magnetometer, rate_hz=50.0),
        barometer=replace(EXACT.barometer, rate_hz=25.0, latency_s=0.02),
        gps=replace(EXACT.gps, rate_hz=10.0, latency_s=0.11),
        vision=VisionModel(True, 100.0, 0.01, 0.0, 0.0),
    )
    suite = SensorSuite(config, HOME_ALT, imu_rate_hz=RATE)
    truth = truth_at()
    got = {"mag": [], "baro": [], "gps": [], "vision": []}
    fresh = []
    for k in range(501):  # 1 s
        t = k * DT
        frame = suite.step(t, truth)
        assert frame.imu.time_s == t
        for name in got:
            reading = getattr(frame, name)
            if reading is not None:
                got[name].append((t, reading.time_s))
        fresh.append((frame.readings.mag_fresh, frame.readings.baro_fresh))
    assert len(got["mag"]) == 51 and len(got["vision"]) == 100  # 0..1 s at 50 Hz; from 10 ms at 100 Hz
    assert all(d == pytest.approx(v) for d, v in got["mag"])  # no latency: delivered when valid
    assert all(d - v == pytest.approx(0.02) for d, v in got["baro"])
    assert all(d - v == pytest.approx(0.11) for d, v in got["gps"])
    assert [v for _, v in got["gps"]] == pytest.approx([0.0, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8])
    assert all(d - v == pytest.approx(0.01) for d, v in got["vision"])
    # HIL_SENSOR holds the magnetometer between its samples and says so.
    assert sum(m for m, _ in fresh) == 51 and sum(b for _, b in fresh) == len(got["baro"])


def test_gps_outage_glitch_and_vision_outage_on_demand():
    config = replace(EXACT, vision=VisionModel(True, 100.0, 0.0, 0.0, 0.0), faults=(
        SensorFault("gps_glitch", 1.0, 0.5, (10.0, 0.0, 0.0)),
        SensorFault("vision_outage", 0.5, 0.2),
    ))  # fmt: skip
    suite = SensorSuite(config, HOME_ALT, imu_rate_hz=RATE)
    suite.gps_outage(2.0, 1.0)  # the method, besides the config
    truth = truth_at()
    fixes, poses = {}, []
    for k in range(2000):
        frame = suite.step(k * DT, truth)
        if frame.gps is not None:
            fixes[round(frame.gps.time_s, 3)] = frame.gps
        if frame.vision is not None:
            poses.append(frame.vision.time_s)
    assert fixes[0.9].position_m == truth.position_m
    assert fixes[1.2].position_m[0] == pytest.approx(truth.position_m[0] + 10.0)  # glitch
    assert fixes[1.2].eph_m == fixes[0.9].eph_m  # the receiver does not know
    assert fixes[1.5].position_m == truth.position_m
    assert all(fixes[t].fix_type == 1 for t in (2.0, 2.5, 2.9))  # no fix, still reported
    assert fixes[3.0].fix_type == 3
    assert not [t for t in poses if 0.5 <= t < 0.7] and 0.49 in [round(t, 3) for t in poses]


def test_mag_disturbance_and_imu_bias_steps():
    config = replace(EXACT, faults=(
        SensorFault("mag_disturbance", 1.0, 1.0, (0.0, 0.3, 0.0)),
        SensorFault("gyro_bias_step", 0.5, math.inf, (0.0, 0.0, 0.02)),
        SensorFault("accel_bias_step", 0.5, math.inf, (0.0, 0.0, 0.2)),
    ))  # fmt: skip
    suite = SensorSuite(config, HOME_ALT, imu_rate_hz=RATE)
    truth = truth_at()
    before = suite.step(0.4, truth)
    during = suite.step(1.5, truth)
    after = suite.step(2.5, truth)
    assert during.readings.magnetic_field_gauss[1] - before.readings.magnetic_field_gauss[1] == pytest.approx(
        0.3
    )
    assert after.readings.magnetic_field_gauss == pytest.approx(before.readings.magnetic_field_gauss)
    assert after.imu.angular_rate_rad_s[2] - before.imu.angular_rate_rad_s[2] == pytest.approx(0.02)
    assert after.imu.specific_force_m_s2[2] - before.imu.specific_force_m_s2[2] == pytest.approx(0.2)
    assert suite.imu_biases(2.5) == ((0.0, 0.0, 0.2), (0.0, 0.0, 0.02))


def test_same_seed_same_noise_other_seed_other_noise():
    def run(seed):
        suite = SensorSuite(replace(load_sensors("gps"), seed=seed), HOME_ALT, imu_rate_hz=RATE)
        truth = truth_at()
        return [suite.step(k * DT, truth) for k in range(100)]

    a, b, c = run(3), run(3), run(4)
    assert a == b and a != c
    # Switch-on biases are drawn from the seed as well.
    assert SensorSuite(replace(load_sensors("gps"), seed=3), HOME_ALT).gyro_bias == \
        SensorSuite(replace(load_sensors("gps"), seed=3), HOME_ALT).gyro_bias  # fmt: skip


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
    path.write_text("[gyroscope]\nnoise_density_rad_s_rthz = -1.0\n")
    with pytest.raises(ConfigError, match=r"bad.toml: key 'gyroscope.noise_density_rad_s_rthz' = -1.0"):
        load_sensors(path)
    path.write_text("[gps]\nsatelites_visible = 3\n")
    with pytest.raises(ConfigError, match="unknown key 'gps.satelites_visible'"):
        load_sensors(path)
    path.write_text("[[faults]]\nkind = 'gps_jam'\nstart_s = 1.0\n")
    with pytest.raises(ConfigError, match="faults\\[0\\].kind' = 'gps_jam'"):
        load_sensors(path)
    path.write_text("[gps]\nrate_hz = 0.0\n")
    with pytest.raises(ConfigError, match=r"'gps.rate_hz' = 0.0 is invalid; allowed: \(0, 1000\] \(Hz\)"):
        load_sensors(path)
    with pytest.raises(ConfigError, match="no sensors named 'nope'"):
        load_sensors("nope")


def test_a_fault_from_config_is_read(tmp_path):
    path = tmp_path / "faulty.toml"
    path.write_text('[[faults]]\nkind = "gps_outage"\nstart_s = 10.0\nduration_s = 10.0\n')
    (fault,) = load_sensors(path).faults
    assert fault == SensorFault("gps_outage", 10.0, 10.0, (0.0, 0.0, 0.0))
    assert fault.active(10.0) and fault.active(19.99) and not fault.active(20.0)


def test_the_suite_draws_the_same_readings_compiled_and_in_python(monkeypatch):
    """The readings are the kernels of simulator.sensors.kernels fed by the seeded stream: run by
    Python instead of their compiled entries, the same seed gives the same readings, bit for bit
    (what lets a batch engine's compiled loop fly the SITL's noise)."""
    from quadcommon import rng
    from simulator.sensors import models

    config = load_sensors("gps")
    vision = replace(load_sensors("mocap").vision, rate_hz=50.0)
    fault = SensorFault("mag_disturbance", 0.5, 0.3, (0.1, 0.0, 0.0))
    config = replace(config, vision=vision, faults=(fault,))
    native = SensorSuite(config, HOME_ALT, RATE)
    python_kernels = models.sensor_kernels()
    monkeypatch.setattr(models, "sensor_entries", lambda: python_kernels)
    monkeypatch.setattr(models.random_stream, "stream", rng.seeded_state)  # a list of floats
    python = SensorSuite(config, HOME_ALT, RATE)
    assert python._k is python_kernels and isinstance(python.rng, list)
    assert (python.accel_bias, python.gyro_bias, python.mag_bias) == (native.accel_bias, native.gyro_bias,
                                                                      native.mag_bias)  # fmt: skip
    assert python.accel_bias != (0.0, 0.0, 0.0)
    truth = truth_at()
    seen = {"gps": 0, "vision": 0, "baro": 0, "mag": 0}
    for k in range(1000):
        t = k * DT
        a, b = python.step(t, truth), native.step(t, truth)
        assert a == b, t
        for name in seen:
            seen[name] += getattr(a, name) is not None
    assert all(count > 10 for count in seen.values())
