"""Fixtures of the client-compatibility tests (real MAVSDK / MAVProxy against ``quadsitl up``)."""

from __future__ import annotations

import pytest

from .vehicles import write_sitl_config


@pytest.fixture(scope="session")
def compat_sitl_config(tmp_path_factory):
    """A sitl.toml putting every vehicle of these tests on the ports of PX4 instances 100-119."""
    return write_sitl_config(tmp_path_factory.mktemp("compat"))
