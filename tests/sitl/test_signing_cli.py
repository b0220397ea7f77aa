"""``--signing-key`` on the command lines: ``python -m autopilot`` and ``quadsitl up`` (through the
launcher's VehicleSpec). A bad key file stops the start with the file and the reason, before any
socket is bound or process started. (The processes themselves: tests/compat/test_signing_processes.py.)"""

from __future__ import annotations

import pytest

from autopilot.__main__ import main as autopilot_main
from sitl import cli
from sitl.launcher import VehicleSpec

pytestmark = pytest.mark.processes  # (tests/conftest.py: the markers)


def test_vehicle_spec_passes_the_key_file_to_the_autopilot():
    cmd = VehicleSpec(instance=70, signing_key_file="/keys/key.txt").autopilot_command()
    assert cmd[cmd.index("--signing-key") + 1] == "/keys/key.txt"
    assert "--signing-key" not in VehicleSpec(instance=70).autopilot_command()
    assert "--signing-key" not in VehicleSpec(instance=70, signing_key_file="/k").simulator_command()


def test_a_bad_key_file_stops_the_start_naming_file_and_reason(tmp_path, capsys):
    bad = tmp_path / "key.txt"
    bad.write_text("two words\n")
    assert autopilot_main(["--instance", "70", "--no-zenoh", "--quiet", "--signing-key", str(bad)]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "one word" in err
    assert cli.main(["up", "--instance", "70", "--signing-key", str(bad)]) == 2
    err = capsys.readouterr().err
    assert str(bad) in err and "one word" in err
    assert cli.main(["up", "--instance", "70", "--signing-key", str(tmp_path / "none.txt")]) == 2
    assert "not found" in capsys.readouterr().err
