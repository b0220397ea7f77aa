"""Ports by role and the launcher's port checks, without processes: ports are
computed, and "in use" is a socket this test binds on loopback itself.

With the scheme's bases no two instances' ports meet (tests/test_ports.py); the refusals between
instances are exercised with a ``sitl.toml`` whose bases cross (:func:`crossed`: HIL base one above
the GCS client port, so instance N's HIL link is instance N - 40's autopilot API link, and
instance 9's is every instance's API client port from 9 on).
"""

from __future__ import annotations

import re
import socket
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest

from quadcommon import wire
from quadcommon.config import load_sitl
from sitl.launcher import LaunchError, VehicleSpec, check_launch, check_ports, launch_conflicts, port_notes
from tests.ports import block_config_dir, instance_ports

pytestmark = pytest.mark.processes  # (tests/conftest.py: the markers)

# The ports the checks below name, on this test process's block (tests/ports.py); with the default
# bases: 4640 (HIL of 80), 18650 (its GCS link), 7527 (its zenoh), 14550 and 14549 (its client ports).
P80 = instance_ports(80)
HIL_80, GCS_LINK_80, ZENOH_80 = P80.hil, P80.gcs_local, P80.zenoh
GCS_CLIENT, API_CLIENT_SHARED = P80.gcs_remote, P80.api_remote


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


@pytest.fixture
def crossed(tmp_path: Path) -> str:
    """A sitl.toml on this block with ``hil_base`` = ``gcs_base`` + 1 (ports that meet)."""
    directory = block_config_dir()
    text = (directory / "sitl.toml").read_text() if directory else ""
    gcs = load_sitl().gcs_port_base
    text, count = re.subn(r"(?m)^hil_base\s*=\s*\d+", f"hil_base = {gcs + 1}", text)
    assert count == 1
    path = tmp_path / "sitl.toml"
    path.write_text(text)
    return str(path)


def test_ports_by_role_own_first_then_clients():
    roles = wire.port_roles(wire.ports(80))
    assert [(r.proto, r.port, r.own) for r in roles] == [
        ("UDP", 4640, True), ("UDP", 18650, True), ("UDP", 14660, True), ("TCP", 7527, True),
        ("UDP", 14550, False), ("UDP", 14549, False),
    ]  # fmt: skip
    assert {r.role for r in roles if not r.own} == {"GCS client port", "API client port"}
    no_hub = wire.port_roles(wire.ports(80), zenoh_listener=False)  # a zenoh router: no listener
    assert "zenoh" not in {r.field for r in no_hub} and len(no_hub) == 5


def test_the_valid_instance_range_is_0_to_249():
    wire.ports(0), wire.ports(249)
    with pytest.raises(ValueError, match=r"\[0, 249\]"):
        wire.ports(250)


def test_250_vehicles_in_one_launch_fit():
    everyone = [VehicleSpec(instance=n) for n in range(wire.INSTANCE_MIN, wire.INSTANCE_MAX + 1)]
    assert launch_conflicts(everyone) == []
    ports = check_launch(everyone)  # every own port of the block is free (tests/ports.py claimed it)
    assert len(ports) == 250 and {p.gcs_remote for p in ports.values()} == {GCS_CLIENT}


def test_one_launch_refuses_ports_that_meet(crossed):
    base = load_sitl(crossed).gcs_port_base
    problems = launch_conflicts([VehicleSpec(instance=40, sitl_config=crossed),
                                 VehicleSpec(instance=80, sitl_config=crossed)])  # fmt: skip
    clash = f"UDP {base + 81}: instance 80's simulator HIL link is instance 40's autopilot API link"
    assert clash in problems
    with pytest.raises(LaunchError) as err:  # refused before any socket is touched
        check_launch([VehicleSpec(instance=n, sitl_config=crossed) for n in (40, 80)])
    text = str(err.value)
    assert "instances 40, 80 cannot run together" in text
    assert "--instance is 0-249; sitl.toml's [ports]" in text
    assert launch_conflicts([VehicleSpec(instance=80), VehicleSpec(instance=80)]) == [
        "instance 80 is given twice"
    ]


def test_own_port_in_use_names_the_port_its_link_and_the_instance():
    """The start-up check refuses (a LaunchError, printed by ``quadsitl up`` without a traceback)."""
    in_use = rf"UDP port {HIL_80} \(simulator HIL link\) is already in use.*--instance 80"
    with bound(HIL_80), pytest.raises(LaunchError, match=in_use):
        check_ports(VehicleSpec(instance=80))
    in_use = rf"UDP port {GCS_LINK_80} \(autopilot GCS link\) is already in use.*--instance 80"
    with bound(GCS_LINK_80), pytest.raises(LaunchError, match=in_use):
        check_launch([VehicleSpec(instance=n) for n in range(70, 90)])
    zenoh_in_use = pytest.raises(LaunchError, match=rf"TCP port {ZENOH_80} \(simulator zenoh endpoint\)")
    with bound(ZENOH_80, proto="TCP"), zenoh_in_use:
        check_ports(VehicleSpec(instance=80))


def test_own_port_in_use_names_who_else_uses_it(crossed):
    base = load_sitl(crossed).gcs_port_base
    api_link_40 = load_sitl(crossed).ports(40).api_local
    assert api_link_40 == base + 81
    with bound(api_link_40), pytest.raises(LaunchError) as err:
        check_ports(VehicleSpec(instance=40, sitl_config=crossed))
    assert f"UDP port {api_link_40} (autopilot API link) is already in use" in str(err.value)
    assert "it is also instance 80's simulator HIL link (is instance 80 running?)" in str(err.value)


def test_a_ground_station_on_a_client_port_is_normal():
    with bound(GCS_CLIENT, API_CLIENT_SHARED):  # QGroundControl on 14550, MAVSDK on 14549
        assert check_ports(VehicleSpec(instance=80)) == P80
        assert check_ports(VehicleSpec(instance=3)) == instance_ports(3)


def test_client_port_that_is_a_running_instance_s_own_port_is_refused(crossed):
    """With the crossed bases instance 80's API client port is instance 9's simulator HIL link."""
    cfg = load_sitl(crossed)
    other, api_80 = cfg.ports(9), cfg.ports(80).api_remote
    with (
        bound(other.gcs_local, other.api_local),
        pytest.raises(LaunchError) as err,
    ):  # instance 9 running
        check_ports(VehicleSpec(instance=80, sitl_config=crossed))
    text = str(err.value)
    assert text.startswith(f"UDP {api_80}: instance 80's API client port is instance 9's simulator HIL link")
    assert f"instance 9 looks running (UDP {other.gcs_local}, its autopilot GCS link, is in use)" in text


def test_own_port_that_is_a_running_instance_s_client_port_is_refused(crossed):
    """The other way round: instance 80 runs, instance 9 would bind 80's API client port and get
    80's API stream."""
    cfg = load_sitl(crossed)
    other = cfg.ports(80)
    with (
        bound(other.gcs_local, other.api_local),
        pytest.raises(LaunchError) as err,
    ):  # instance 80 running, no ground station on its API client port
        check_ports(VehicleSpec(instance=9, sitl_config=crossed))
    text = str(err.value)
    assert re.match(rf"UDP {other.api_remote}: instance 9's simulator HIL link is instance \d+'s API client "
                    rf"port, and instance \d+ looks running", text), text  # fmt: skip


def test_instances_of_the_same_launch_are_not_mistaken_for_running_ones(crossed):
    # The launch's own instances are checked against each other by launch_conflicts only.
    other = load_sitl(crossed).ports(40)
    with bound(other.gcs_local):  # as if 40 had started already
        check_ports(VehicleSpec(instance=80, sitl_config=crossed), [VehicleSpec(instance=40)])


def test_client_ports_shared_with_a_running_instance_are_a_note_not_a_refusal():
    """Every instance's GCS client port is the one port (PX4's 14550), and instances from 9 on share
    the API one (14549): with 70 running, a ground station there hears both vehicles (they differ
    by system id), which is allowed."""
    with bound(instance_ports(70).hil, taken_is_fine=True):  # instance 70 running
        assert check_ports(VehicleSpec(instance=80)) == P80
        notes = port_notes([VehicleSpec(instance=80)])
    heard = "and of running instance(s) 70: a ground station there hears them all (system id 1 + N)"
    assert sorted(notes) == sorted([
        f"note: UDP {API_CLIENT_SHARED} is the API client port of instance(s) 80 {heard}",
        f"note: UDP {GCS_CLIENT} is the GCS client port of instance(s) 80 {heard}",
    ])  # fmt: skip
