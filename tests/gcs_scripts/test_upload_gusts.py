"""upload_gusts.py without a simulator: file parsing, request building, exit codes."""

from __future__ import annotations

import json
import time
from pathlib import Path

import pytest

from gcs_scripts import upload_gusts as ug
from quadcommon.config import CONFIG_DIR
from simulator.environment.gust_profile import load_gust_profile, profile_to_mapping
from tests.ports import instance_ports

pytestmark = pytest.mark.processes  # (tests/conftest.py: the markers)


def test_toml_and_json_files_parse_to_the_same_mapping(tmp_path: Path) -> None:
    toml_path = CONFIG_DIR / "gusts" / "mixed.toml"
    mapping = ug.load_profile_file(toml_path)
    json_path = tmp_path / "mixed.json"
    json_path.write_text(json.dumps(mapping))
    assert ug.load_profile_file(json_path) == mapping
    assert mapping["dryden"]["seed"] == 7


def test_unreadable_files_raise_profile_file_error(tmp_path: Path) -> None:
    with pytest.raises(ug.ProfileFileError, match="cannot read"):
        ug.load_profile_file(tmp_path / "missing.toml")
    bad = tmp_path / "bad.toml"
    bad.write_text("[[step]\n")
    with pytest.raises(ug.ProfileFileError, match="not valid TOML"):
        ug.load_profile_file(bad)
    bad_json = tmp_path / "bad.json"
    bad_json.write_text("[1, 2]")
    with pytest.raises(ug.ProfileFileError, match="must be a table/object, got list"):
        ug.load_profile_file(bad_json)


def test_request_payload_is_the_protocol_object() -> None:
    mapping = profile_to_mapping(load_gust_profile("gust_1cos_x"))
    assert json.loads(ug.build_request(mapping, ug.start_spec(at_s=4))) == {
        "profile": mapping,
        "start": {"at_s": 4.0},
    }
    assert ug.start_spec() == "now"
    assert ug.start_spec(after_s=2) == {"after_s": 2.0}
    with pytest.raises(ValueError):
        ug.start_spec(1.0, 2.0)


def test_toml_dates_cannot_be_sent(tmp_path: Path) -> None:
    path = tmp_path / "dated.toml"
    path.write_text("description = 'x'\nwhen = 2024-01-01\n")
    with pytest.raises(ug.ProfileFileError, match="cannot be sent as JSON"):
        ug.build_request(ug.load_profile_file(path))


def test_exit_1_for_a_bad_file_or_bad_arguments(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert ug.main([str(tmp_path / "nope.json"), "--instance", "87"]) == 1
    assert "cannot read" in capsys.readouterr().err
    with pytest.raises(SystemExit) as info:
        ug.main([str(CONFIG_DIR / "gusts" / "mixed.toml"), "--now", "--start-at", "3"])
    assert info.value.code == 1
    assert ug.main([str(CONFIG_DIR / "gusts" / "mixed.toml"), "--instance", "250"]) == 1
    assert "--instance must be in [0, 249]" in capsys.readouterr().err


def test_exit_2_naming_key_and_port_when_no_simulator_answers(capsys: pytest.CaptureFixture[str]) -> None:
    begin = time.monotonic()
    code = ug.main([str(CONFIG_DIR / "gusts" / "gust_1cos_x.toml"), "--instance", "89", "--timeout", "0.3"])
    elapsed = time.monotonic() - begin
    assert code == 2
    err = capsys.readouterr().err
    assert "quadsitl/89/sim/gusts" in err and f"tcp/127.0.0.1:{instance_ports(89).zenoh}" in err
    assert elapsed < 3.0  # open (<= 0.5 s scouting) + the 0.3 s timeout
