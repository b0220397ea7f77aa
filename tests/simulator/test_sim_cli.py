"""Command line of the simulator: configuration directory, bad names and values exit 2."""

from __future__ import annotations

import shutil
import subprocess
import sys

import pytest

from quadcommon.config import find_config

from .sim_harness import REPO, ScriptedAutopilot, SimProcess

pytestmark = pytest.mark.processes  # (tests/conftest.py: the markers)


def test_config_dir_is_where_configuration_is_read(tmp_path):
    config = tmp_path / "config"
    shutil.copytree(REPO / "config", config)
    shutil.copy(find_config("", "sitl"), config / "sitl.toml")  # on this test process's ports
    hover = config / "scenarios" / "hover.toml"
    text = hover.read_text().replace(
        "[initial_state]\nposition_m = [0.0, 0.0, 0.0]", "[initial_state]\nposition_m = [0.5, 0.0, 1.5]"
    )
    assert "[0.5, 0.0, 1.5]" in text
    hover.write_text(text)
    with SimProcess(54, "--config-dir", str(config)) as sim, ScriptedAutopilot(54) as ap:
        frame = ap.link()
        odo = frame["ODOMETRY"]
        assert (odo.x, odo.y, odo.z) == pytest.approx((0.5, 0.0, -1.5), abs=1e-6)
        assert sim.terminate() == 0


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--scenario", "no_such_scenario"], "no scenarios named 'no_such_scenario'"),
        (["--vehicle", "no_such_vehicle"], "no vehicle named 'no_such_vehicle'"),
        (["--sensors", "no_such_sensors"], "no sensors named 'no_such_sensors'"),
        (["--config-dir", "/nonexistent/dir"], "is not a directory"),
        (["--speed", "0"], "--speed must be a positive number or 'max'"),
        (["--speed", "fast"], "--speed must be a positive number or 'max'"),
        (["--duration", "-1"], "--duration must be > 0 s"),
        (["--instance", "250"], "--instance must be in [0, 249]"),
    ],
)
def test_bad_arguments_exit_2_with_a_message(args, message):
    result = subprocess.run(
        [sys.executable, "-m", "simulator", *args], cwd=REPO, capture_output=True, text=True, timeout=20
    )
    assert result.returncode == 2
    assert message in result.stderr
