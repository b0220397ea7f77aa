"""The sprayer's traffic (sitl/spray.py: datagrams a correct autopilot must refuse or ignore,
from 300 source addresses) changes nothing: a flight with the spray is the flight without it,
state for state, in simulation time. The real-socket run is tests/sitl/test_hostile_udp.py."""

import math

import pytest
from pymavlink.dialects.v20 import common as m

from sitl.inprocess import GCS_LINK
from sitl.spray import HOSTILE_KINDS, HostileTraffic
from tests.stack import make_stack

PER_FRAME = 6  # 3,000 datagrams per simulated second


def fly(spray: bool):
    stack = make_stack()
    ap = stack.autopilot
    pilot = stack.ground_station(GCS_LINK)
    traffic = HostileTraffic(seed=5, system_id=ap.system_id)
    sources = [("127.0.0.1", 50000 + k) for k in range(300)]
    sent = 0

    def script(s, t):
        nonlocal sent
        if s.frames % 250 == 0:
            pilot.heartbeat()
        if spray and 1.0 <= t < 14.0:
            for _ in range(PER_FRAME):
                s.deliver(GCS_LINK, sources[sent % len(sources)], traffic.next()[1])
                sent += 1

    stack.run_for(0.5, script=script)
    pilot.command(m.MAV_CMD_COMPONENT_ARM_DISARM, 1)
    stack.run_for(0.1, script=script)
    pilot.command(m.MAV_CMD_NAV_TAKEOFF, 0, 0, 0, math.nan, math.nan, math.nan, ap.setup.sitl.home[2] + 2.0)
    stack.run_for(8.0, script=script)
    pilot.command(m.MAV_CMD_NAV_LAND, 0, 0, 0, math.nan, math.nan, math.nan, math.nan)
    stack.run_for(8.0, script=script)
    acks = [(a.command, a.result) for a in pilot.of_type("COMMAND_ACK")]
    return stack, acks, traffic, sent


@pytest.mark.timeout(300)
def test_a_flight_under_hostile_traffic_is_the_flight_without_it():
    quiet, quiet_acks, _, _ = fly(spray=False)
    sprayed, sprayed_acks, traffic, sent = fly(spray=True)
    assert sent > 35_000 and set(traffic.sent) == set(HOSTILE_KINDS)
    assert quiet_acks == sprayed_acks and all(result == m.MAV_RESULT_ACCEPTED for _, result in quiet_acks)
    assert sprayed.sim.plant.state == quiet.sim.plant.state  # bit for bit
    truth = sprayed.sim.plant.truth()
    assert truth.on_ground and not sprayed.autopilot.commander.armed  # landed and disarmed
    info = sprayed.autopilot.info()
    assert info["faults"] == {}  # no handler raised
    refused = info["refused"]
    reasons = (
        "ARM_DISARM refused", "DO_SET_MODE refused", "param set refused", "SET_MESSAGE_INTERVAL refused",
        "setpoint refused: non-finite", "farther than NAV_REF_MAX_DIST",
    )  # fmt: skip
    for reason in reasons:
        assert any(reason in key for key in refused), (reason, refused)
    for name in ("NAV_LAND", "NAV_RETURN_TO_LAUNCH", "DO_SET_MODE"):  # a value in an unused slot
        assert any(f"{name} refused: param" in key and ": unused (" in key for key in refused), name
    assert info["peers"] and all(len(peers) <= 16 for peers in info["peers"].values())
