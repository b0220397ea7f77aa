"""The configuration directories: a user's own overlay the shipped ones (QUADSITL_CONFIG_DIR,
--config-dir), a missing name lists every place looked in, ``config copy`` writes the defaults."""

from __future__ import annotations

import os

import pytest

from quadcommon import config
from quadcommon.schema import ConfigError


@pytest.fixture
def user_dir(tmp_path, monkeypatch):
    d = tmp_path / "mine"
    (d / "scenarios").mkdir(parents=True)
    monkeypatch.setenv(config.CONFIG_ENV, str(d))
    return d


@pytest.mark.timeout(10)
def test_shipped_dir_has_the_defaults():
    files = {str(p) for p in config.shipped_files()}
    assert {"sitl.toml", "scenarios/circle.toml", "controllers/intbs.toml", "gusts/mixed.toml"} <= files


@pytest.mark.timeout(10)
def test_user_file_overlays_the_shipped_one_and_adds_names(user_dir):
    shipped = (config.SHIPPED_CONFIG_DIR / "scenarios" / "hover.toml").read_text()
    (user_dir / "scenarios" / "hover.toml").write_text(shipped.replace("hover", "my hover", 1))
    (user_dir / "scenarios" / "mine.toml").write_text(shipped)
    assert config.config_path("scenarios", "hover") == user_dir / "scenarios" / "hover.toml"
    assert config.config_path("scenarios", "mine") == user_dir / "scenarios" / "mine.toml"
    # what the user's directory does not have still comes from the shipped one
    shipped = config.SHIPPED_CONFIG_DIR
    assert config.config_path("scenarios", "circle") == shipped / "scenarios" / "circle.toml"
    assert config.load_sitl().rates.physics_hz > 0  # sitl.toml from the shipped directory
    assert "mine" in config.available_names("scenarios")


@pytest.mark.timeout(10)
def test_missing_name_lists_every_place_looked_and_what_exists(user_dir):
    (user_dir / "scenarios" / "mine.toml").write_text("")
    with pytest.raises(ConfigError) as info:
        config.load_scenario("nosuch")
    text = str(info.value)
    assert str(user_dir / "scenarios" / "nosuch.toml") in text
    assert str(config.SHIPPED_CONFIG_DIR / "scenarios" / "nosuch.toml") in text
    assert "available: circle, helix, hover, mine" in text


@pytest.mark.timeout(10)
def test_env_directory_that_does_not_exist_is_a_config_error(tmp_path, monkeypatch):
    monkeypatch.setenv(config.CONFIG_ENV, str(tmp_path / "nowhere"))
    with pytest.raises(ConfigError, match="QUADSITL_CONFIG_DIR: .*nowhere is not a directory"):
        config.load_scenario("circle")


@pytest.mark.timeout(10)
def test_with_config_dir_puts_it_first(tmp_path):
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir()
    b.mkdir()
    env = config.with_config_dir(a, {config.CONFIG_ENV: str(b)})
    assert config.config_dirs(env) == (a.resolve(), b, config.SHIPPED_CONFIG_DIR)
    with pytest.raises(ConfigError, match="is not a directory"):
        config.with_config_dir(tmp_path / "nope", {})


@pytest.mark.timeout(10)
def test_copy_writes_the_defaults_and_refuses_to_overwrite(tmp_path):
    target = tmp_path / "cfg"
    written = config.copy_shipped_config(target)
    assert sorted(p.relative_to(target) for p in written) == config.shipped_files()
    assert (target / "scenarios" / "circle.toml").read_text() == (
        config.SHIPPED_CONFIG_DIR / "scenarios" / "circle.toml"
    ).read_text()
    edited = target / "scenarios" / "circle.toml"
    edited.write_text("# mine\n")
    with pytest.raises(ConfigError, match="already there; nothing written"):
        config.copy_shipped_config(target)
    assert edited.read_text() == "# mine\n"
    config.copy_shipped_config(target, force=True)
    assert edited.read_text() != "# mine\n"


@pytest.mark.timeout(10)
def test_copied_directory_loads_as_an_overlay(tmp_path, monkeypatch):
    target = tmp_path / "cfg"
    config.copy_shipped_config(target)
    monkeypatch.setenv(config.CONFIG_ENV, str(target) + os.pathsep)
    assert config.config_path("scenarios", "helix") == target / "scenarios" / "helix.toml"
    assert config.load_scenario("helix").name
