"""quadcommon.environment: the variables quadsitl reads, and what it sets for pymavlink."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from quadcommon import environment

pytestmark = pytest.mark.timeout(60)


def test_pymavlink_gets_mavlink_2_and_common_unless_the_user_chose():
    env: dict[str, str] = {}
    environment.use_mavlink2(env)
    assert env == {"MAVLINK20": "1", "MAVLINK_DIALECT": "common"}
    chosen = {"MAVLINK20": "", "MAVLINK_DIALECT": "ardupilotmega"}
    environment.use_mavlink2(chosen)
    assert chosen == {"MAVLINK20": "", "MAVLINK_DIALECT": "ardupilotmega"}


def test_a_ground_station_script_speaks_mavlink_2_from_its_first_import():
    # a fresh interpreter without the variables: importing the client sets them before pymavlink
    code = (
        "import gcs_scripts.link; from pymavlink import mavutil; "
        "print(mavutil.mavlink.WIRE_PROTOCOL_VERSION)"
    )
    env = {k: v for k, v in os.environ.items() if k not in environment.PYMAVLINK_SETTINGS}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=60)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "2.0"


def test_what_quadsitl_sets_for_pymavlink_is_listed_with_the_variables():
    # (the docs' table is VARIABLES' rendering, checked against docs/configuration.md in tests/docs)
    assert all(name in environment.VARIABLES for name in environment.PYMAVLINK_SETTINGS)
