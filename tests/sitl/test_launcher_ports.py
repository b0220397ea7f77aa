"""Ports by role and the launcher's port checks, without processes: ports are
computed, and "in use" is a socket this test binds on loopback itself.

Instances: 80-89 and the ones that share ports with them (40 = 80 - 40, 50 = 80 - 30, 70 = 80 - 10).
"""

from __future__ import annotations

import re
import socket
from collections.abc import Iterator
from contextlib import contextmanager

import pytest

from quadcommon import wire
from sitl.launcher import LaunchError, VehicleSpec, check_launch, check_ports, launch_conflicts, port_notes
from tests.ports import instance_ports

pytestmark = pytest.mark.processes  # (tests/conftest.py: the markers)

# The ports the checks below name, on this test process's block (tests/ports.py); with the default
# bases: 4640 and 4600 (HIL of 80 and 40), 7527 (zenoh of 80), 14620 (80's API client port, 40's
# autopilot API link, 70's GCS client port), 14630 (80's GCS client port, 90's API client port).
HIL_80, HIL_40, ZENOH_80 = instance_ports(80).hil, instance_ports(40).hil, instance_ports(80).zenoh
API_80, GCS_80 = instance_ports(80).api_remote, instance_ports(80).gcs_remote


@contextmanager
def bound(*ports: int, proto: str = "UDP", taken_is_fine: bool = False) -> Iterator[None]:
    """Loopback sockets on ``ports`` (as a running process or a listening ground station holds them).
    ``taken_is_fine``: a port someone else holds already is in use all the same."""
    socks = []
    try:
        for port in ports:
            sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM if proto == "TCP" else socket.SOCK_DGRAM)
            socks.append(sock)
            if proto == "TCP":  # as zenoh: a vehicle of an earlier test may linger in TIME_WAIT
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
            try:
                sock.bind((wire.LOOPBACK, port))
            except OSError:
                if not taken_is_fine:
                    raise
                continue
            if proto == "TCP":
                sock.listen()
        yield
    finally:
        for sock in socks:
            sock.close()


def test_ports_by_role_own_first_then_clients():
    roles = wire.port_roles(wire.ports(80))
    assert [(r.proto, r.port, r.own) for r in roles] == [
        ("UDP", 4640, True), ("UDP", 18650, True), ("UDP", 14660, True), ("TCP", 7527, True),
        ("UDP", 14630, False), ("UDP", 14620, False),
    ]  # fmt: skip
    assert {r.role for r in roles if not r.own} == {"GCS client port", "API client port"}
    no_hub = wire.port_roles(wire.ports(80), zenoh_listener=False)  # a zenoh router: no listener
    assert "zenoh" not in {r.field for r in no_hub} and len(no_hub) == 5


def test_overlapping_instances_are_10_30_and_40_apart_whatever_the_bases():
    assert wire.overlapping_offsets(wire.ports(0)) == (10, 30, 40)
    assert wire.overlapping_offsets(wire.ports(0, 4660, 14650, 14640, 7547)) == (10, 30, 40)  # all + 100
    for n in range(10, 100):  # the overlap the finding names, for every N >= 10
        assert wire.ports(n).api_remote == wire.ports(n - 10).gcs_remote
    assert wire.ports(40).api_remote == wire.ports(0).api_local == 14580


def test_the_valid_instance_range_is_0_to_99():
    wire.ports(0), wire.ports(99)
    with pytest.raises(ValueError, match=r"\[0, 99\]"):
        wire.ports(100)


def test_ten_vehicles_in_one_launch_fit_and_eleven_do_not():
    assert launch_conflicts([VehicleSpec(instance=n) for n in range(80, 90)]) == []
    problems = launch_conflicts([VehicleSpec(instance=n) for n in range(80, 91)])
    assert problems == [f"UDP {GCS_80}: instance 90's API client port is instance 80's GCS client port"]
    with pytest.raises(LaunchError) as err:  # refused before any socket is touched
        check_launch([VehicleSpec(instance=n) for n in range(80, 91)])
    text = str(err.value)
    assert (
        "instances 80, 81" in text
        and "instance 90's API client port is instance 80's GCS client port" in text
    )
    assert "--instance is 0-99; instances 10, 30 or 40 apart share ports" in text


def test_one_launch_refuses_own_ports_shared_with_another_instance():
    problems = launch_conflicts([VehicleSpec(instance=40), VehicleSpec(instance=80)])
    assert problems == [f"UDP {API_80}: instance 80's API client port is instance 40's autopilot API link"]
    problems = launch_conflicts([VehicleSpec(instance=50), VehicleSpec(instance=80)])
    assert problems == [f"UDP {GCS_80}: instance 80's GCS client port is instance 50's autopilot API link"]
    assert launch_conflicts([VehicleSpec(instance=80), VehicleSpec(instance=80)]) == [
        "instance 80 is given twice"
    ]


def test_own_port_in_use_names_it_the_instance_and_who_else_uses_it():
    with (
        bound(instance_ports(80).hil),
        pytest.raises(
            LaunchError, match=rf"UDP port {HIL_80} \(simulator HIL link\) is already in use.*--instance 80"
        ),
    ):
        check_ports(VehicleSpec(instance=80))
    zenoh_in_use = pytest.raises(LaunchError, match=rf"TCP port {ZENOH_80} \(simulator zenoh endpoint\)")
    with bound(instance_ports(80).zenoh, proto="TCP"), zenoh_in_use:
        check_ports(VehicleSpec(instance=80))
    with (
        bound(instance_ports(40).api_local),
        pytest.raises(LaunchError) as err,
    ):  # a MAVSDK script waiting for instance 80 on 14620
        check_ports(VehicleSpec(instance=40))
    assert f"UDP port {API_80} (autopilot API link) is already in use" in str(err.value)
    assert "it is also instance 80's API client port (a ground station of instance 80?)" in str(err.value)


def test_a_ground_station_on_a_client_port_is_normal():
    p = instance_ports(80)
    # 14630 is also instance 50's autopilot API link and 14620 instance 40's: neither is running.
    with bound(p.gcs_remote, p.api_remote):
        assert check_ports(VehicleSpec(instance=80)) == p


def test_client_port_that_is_a_running_instance_s_own_port_is_refused():
    """Instance 80's API client port 14620 is instance 40's autopilot API link."""
    other = instance_ports(40)
    with (
        bound(other.hil, other.gcs_local, other.api_local),
        pytest.raises(LaunchError) as err,
    ):  # instance 40 running
        check_ports(VehicleSpec(instance=80))
    text = str(err.value)
    assert text.startswith(f"UDP {API_80}: instance 80's API client port is instance 40's autopilot API link")
    assert f"instance 40 looks running (UDP {HIL_40}, its simulator HIL link, is in use)" in text
    assert "instances 10, 30 or 40 apart share ports" in text


def test_own_port_that_is_a_running_instance_s_client_port_is_refused():
    """The other way round: instance 80 runs, instance 40 would bind 80's API client port and get
    80's API stream."""
    other = instance_ports(80)
    with (
        bound(other.hil, other.gcs_local),
        pytest.raises(LaunchError) as err,
    ):  # instance 80 running, no ground station on 14620
        check_ports(VehicleSpec(instance=40))
    text = str(err.value)
    assert re.match(rf"UDP {API_80}: instance 40's autopilot API link is instance 80's API client port, and "
                    rf"instance 80 looks running \(UDP {HIL_80}", text), text  # fmt: skip
    assert (
        "instance 80's traffic for its API client port would reach instance 40's autopilot API link" in text
    )


def test_instances_of_the_same_launch_are_not_mistaken_for_running_ones():
    # The launch's own instances are checked against each other by launch_conflicts only.
    other = instance_ports(81)
    with bound(other.hil):  # as if 81 had started already
        check_ports(VehicleSpec(instance=80), [VehicleSpec(instance=81)])


def test_client_ports_shared_with_a_running_instance_are_a_note_not_a_refusal():
    """Instance 80's API client port 14620 is instance 70's GCS client port: with 70 running, a
    ground station there hears both vehicles (they differ by sysid), which is allowed."""
    with bound(instance_ports(70).hil, taken_is_fine=True):  # instance 70 running
        assert check_ports(VehicleSpec(instance=80)) == instance_ports(80)
        notes = port_notes([VehicleSpec(instance=80)])
    assert notes == [
        f"note: UDP {API_80}: instance 80's API client port is instance 70's GCS client port and instance 70 "
        f"is running: a ground station on UDP {API_80} hears both vehicles (sysid 81 and 71)"
    ]
