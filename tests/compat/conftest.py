"""Fixtures of the client-compatibility tests (real MAVSDK / MAVProxy against ``quadsitl up``)."""

from __future__ import annotations

import pytest

from quadcommon.config import find_config


@pytest.fixture(scope="session")
def flight_logs(tmp_path_factory) -> list:
    """Two flight logs as the autopilot writes them (armed on the ground for 0.6 s each, in-process
    in simulation time; each checked as every test log is): what the log-download tests put on
    their vehicles."""
    from pymavlink.dialects.v20 import common as m

    from tests.stack import Gcs, make_stack
    from tests.ulog_check import check_ulog

    out = tmp_path_factory.mktemp("flight_logs")
    stack = make_stack(log_dir=str(out))
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    for _ in range(2):
        for value in (1.0, 0.0):
            gcs.command(m.MAV_CMD_COMPONENT_ARM_DISARM, value)
            stack.run_for(0.6)
    logs = stack.close()
    assert len(logs) == 2
    for log in logs:  # (on the ground: no flight for Flight Review's plots)
        check_ulog(log, flight_review=False)
    return logs


@pytest.fixture(scope="session")
def compat_sitl_config():
    """The sitl.toml of this pytest process's port block (tests/ports.py), named explicitly."""
    return find_config("", "sitl")
