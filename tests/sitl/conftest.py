"""Fixtures of the tests under tests/sitl."""

import pytest

from ..stack import Gcs, make_stack


@pytest.fixture
def vehicle():
    """The whole stack in-process (a vehicle on the ground) and a ground station that heard it."""
    stack = make_stack()
    gcs = Gcs(stack)
    gcs.wait_heartbeat()
    yield stack, gcs
    gcs.close()
