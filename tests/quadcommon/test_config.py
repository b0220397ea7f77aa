"""Config files load, and bad values are refused with file, key, value and allowed range."""

import shutil

import pytest

from autopilot.control import config as controllers
from quadcommon import config
from quadcommon.schema import ConfigError


def test_shipped_configs_load():
    vehicle = config.load_vehicle("paper_quad")
    assert vehicle.nominal.mass_kg == 0.74
    assert vehicle.nominal.inertia_kg_m2 == (0.004, 0.004, 0.0084)
    for name in controllers.CONTROLLER_NAMES:
        assert controllers.load_controller(name).name == name
    for name in ("circle", "helix", "hover"):
        assert config.load_scenario(name).name == name
    sitl = config.load_sitl()
    assert sitl.rates.physics_steps_per_control == 2


def test_nlhinf_gain_formulae():
    g = controllers.load_controller("intbs_nlhinf").rotational
    assert g.k_d == pytest.approx((9 + 2 * 0.1 * 9) ** 0.5 / 0.1)
    assert g.k_p == pytest.approx(90.0)


def copy_config(tmp_path, kind, name):
    src = config.config_path(kind, name)
    dst = tmp_path / f"{name}.toml"
    shutil.copy(src, dst)
    return dst


def test_out_of_range_value_names_file_key_value_and_range(tmp_path):
    path = copy_config(tmp_path, "vehicle", "paper_quad")
    path.write_text(path.read_text().replace("mass_kg = 0.74", "mass_kg = -1.0"))
    with pytest.raises(ConfigError) as info:
        config.load_vehicle(path)
    msg = str(info.value)
    assert str(path) in msg and "nominal.mass_kg" in msg and "-1.0" in msg and "(0, 100]" in msg


def test_unknown_key_is_refused(tmp_path):
    path = copy_config(tmp_path, "controllers", "intbs_nlhinf")
    path.write_text(path.read_text().replace("omega1 = 0.1", "omega1 = 0.1\nomgea2 = 3.0"))
    with pytest.raises(ConfigError, match=r"unknown key 'rotational.omgea2'"):
        controllers.load_controller(path)


def test_wrong_type_is_refused(tmp_path):
    path = copy_config(tmp_path, "scenarios", "circle")
    path.write_text(path.read_text().replace("duration_s = 40.0", 'duration_s = "forty"'))
    with pytest.raises(ConfigError, match=r"duration_s.*'forty'.*a number"):
        config.load_scenario(path)


def test_wrong_choice_lists_the_options(tmp_path):
    path = copy_config(tmp_path, "controllers", "intbs")
    path.write_text(path.read_text().replace('law = "integral_first_step"', 'law = "pid"'))
    with pytest.raises(ConfigError, match=r"translational.law.*'pid'.*integral_second_step"):
        controllers.load_controller(path)


def test_unknown_name_lists_available():
    with pytest.raises(ConfigError, match=r"available: .*circle.*helix"):
        config.load_scenario("no_such_scenario")


def test_rates_must_divide(tmp_path):
    path = tmp_path / "sitl.toml"
    path.write_text("[rates]\nphysics_hz = 1000.0\ncontrol_hz = 300.0\n")
    with pytest.raises(ConfigError, match="whole divisor"):
        config.load_sitl(path)


def test_inertia_tensor_must_be_positive_definite(tmp_path):
    path = copy_config(tmp_path, "vehicle", "paper_quad")
    path.write_text(path.read_text().replace("[1e-4, 1e-4, 2e-4]", "[0.005, 0.0, 0.0]"))
    with pytest.raises(ConfigError, match="positive definite"):
        config.load_vehicle(path)


def test_uncertainty_scales_plant_only():
    vehicle = config.load_vehicle()
    helix = config.load_scenario("helix")
    scaled = config.apply_uncertainty(vehicle, helix)
    assert scaled.plant.mass_kg == pytest.approx(0.74 * 1.3)
    assert scaled.plant.inertia_kg_m2 == pytest.approx((0.0052, 0.0052, 0.01092))
    assert scaled.nominal == vehicle.nominal


def test_the_lockstep_spin_is_overridden_by_the_environment_and_checked(monkeypatch):
    monkeypatch.setenv(config.SPIN_ENV, "0")
    assert config.load_sitl().lockstep_spin_s == 0.0
    monkeypatch.setenv(config.SPIN_ENV, "0.001")
    assert config.load_sitl().lockstep_spin_s == 0.001
    for bad in ("fast", "-1", "nan", "1"):
        monkeypatch.setenv(config.SPIN_ENV, bad)
        with pytest.raises(ConfigError, match=f"QUADSITL_LOCKSTEP_SPIN_S: '{bad}'"):
            config.load_sitl()
    monkeypatch.delenv(config.SPIN_ENV)
    assert config.load_sitl().lockstep_spin_s == 0.002  # config/sitl.toml
