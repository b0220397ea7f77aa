"""The estimator's parameters: PX4 EKF2 names and defaults, the store, the config files."""

from __future__ import annotations

import math

import pytest

from autopilot.estimation import ESTIMATOR_PARAMS, estimator_params, estimator_store, load_estimator_params
from autopilot.params.definitions import default_parameters
from quadcommon.schema import ConfigError

pytestmark = pytest.mark.timeout(30)

# PX4-Autopilot src/modules/ekf2/*.yaml (module.yaml, params_gnss, params_barometer,
# params_magnetometer, params_external_vision, params_gyro_bias, params_accel_bias).
PX4_DEFAULTS = {
    "EKF2_PREDICT_US": 10000, "EKF2_GYR_NOISE": 0.015, "EKF2_ACC_NOISE": 0.35, "EKF2_GYR_B_NOISE": 0.001,
    "EKF2_ACC_B_NOISE": 0.003, "EKF2_MAG_B_NOISE": 0.0001, "EKF2_GBIAS_INIT": 0.1, "EKF2_ABIAS_INIT": 0.2,
    "EKF2_ANGERR_INIT": 0.1, "EKF2_GPS_CTRL": 7, "EKF2_GPS_DELAY": 110.0, "EKF2_GPS_P_NOISE": 0.5,
    "EKF2_GPS_V_NOISE": 0.3, "EKF2_GPS_P_GATE": 5.0, "EKF2_GPS_V_GATE": 5.0, "EKF2_REQ_EPH": 3.0,
    "EKF2_REQ_EPV": 5.0, "EKF2_REQ_NSATS": 6, "EKF2_BARO_CTRL": 1, "EKF2_BARO_RATE": 20.0,
    "EKF2_BARO_DELAY": 0.0, "EKF2_BARO_NOISE": 3.5, "EKF2_BARO_GATE": 5.0, "EKF2_MAG_TYPE": 0,
    "EKF2_MAG_RATE": 15.0, "EKF2_MAG_DELAY": 0.0, "EKF2_MAG_NOISE": 0.05, "EKF2_MAG_GATE": 3.0,
    "EKF2_HEAD_NOISE": 0.3, "EKF2_HDG_GATE": 2.6, "EKF2_MAG_CHECK": 1, "EKF2_MAG_CHK_STR": 0.2,
    "EKF2_MAG_CHK_INC": 20.0, "EKF2_EV_DELAY": 0.0, "EKF2_EV_NOISE_MD": 0, "EKF2_EVP_NOISE": 0.1,
    "EKF2_EVA_NOISE": 0.1, "EKF2_EVP_GATE": 5.0, "EKF2_EVV_NOISE": 0.1, "EKF2_EVV_GATE": 3.0,
    "EKF2_EV_QMIN": 0, "EKF2_NOAID_TOUT": 5000000,
}  # fmt: skip


def test_px4_names_carry_px4_defaults_and_ours_are_marked():
    specs = {s.name: s for s in ESTIMATOR_PARAMS}
    for name, default in PX4_DEFAULTS.items():
        assert specs[name].default == default, name
    # Everything not in PX4's EKF2 is EST_-prefixed; the one PX4 name with another default says why.
    others = set(specs) - set(PX4_DEFAULTS)
    assert others == {"EKF2_EV_CTRL"} | {n for n in specs if n.startswith("EST_")}
    assert "PX4's default is 0" in specs["EKF2_EV_CTRL"].description


def test_the_parameters_join_the_autopilot_table():
    store = default_parameters()
    for spec in ESTIMATOR_PARAMS:
        assert len(spec.name) <= 16 and spec.name not in store  # no clash with the existing table
        assert spec.lo <= spec.default <= spec.hi and spec.check(spec.default) is None
    estimator = estimator_store({"EKF2_GPS_P_NOISE": 0.8})
    assert estimator["EKF2_GPS_P_NOISE"] == 0.8
    assert "refused" in estimator.validate("EKF2_MAG_TYPE", 6)  # PX4's 'Init' is not supported
    with pytest.raises(ValueError, match="EKF2_GPS_P_GATE: 0.5 out of range"):
        estimator_store({"EKF2_GPS_P_GATE": 0.5})


def test_units_are_converted_to_si_and_px4_figures_to_densities():
    p = estimator_params({"EKF2_GPS_DELAY": 120.0, "EKF2_NOAID_TOUT": 7000000, "EKF2_MAG_CHK_INC": 30.0})
    assert p.gps_delay_s == pytest.approx(0.12)
    assert p.no_aid_timeout_s == pytest.approx(7.0)
    assert p.mag_inclination_tol_rad == pytest.approx(math.radians(30.0))
    assert p.gyro_noise_density == pytest.approx(0.015 * math.sqrt(0.01))
    slower = estimator_params({"EKF2_PREDICT_US": 20000})
    assert slower.accel_noise_density == pytest.approx(0.35 * math.sqrt(0.02))
    assert estimator_params().mag_period_s == pytest.approx(1.0 / 15.0)


def test_config_files_are_validated_with_file_key_value_and_range(tmp_path):
    assert load_estimator_params("mocap").ev_delay_s == pytest.approx(0.010)
    assert load_estimator_params("gps").gps_vel_noise_m_s == pytest.approx(0.05)
    assert load_estimator_params("default") == estimator_params()
    bad = tmp_path / "bad.toml"
    bad.write_text("EKF2_GPS_P_NOISE = 20.0\n")
    with pytest.raises(ConfigError, match=r"bad.toml: key 'EKF2_GPS_P_NOISE' = 20.0 .*\[0.01, 10\] m"):
        load_estimator_params(bad)
    bad.write_text("EKF2_GPS_NOISE = 1.0\n")
    with pytest.raises(ConfigError, match="key 'EKF2_GPS_NOISE' = 1.0 is not a parameter"):
        load_estimator_params(bad)
