"""The port scheme (quadcommon/wire.py) for all 250 instances, and the tests' port blocks
(tests/ports.py): no two instances' own ports meet, no own port is a client port, no two blocks
share a port, none meets the default bases' ports or the ephemeral range."""

import pytest

from quadcommon import wire
from tests.ports import BLOCK_STARTS, bases, block_ports

EVERYONE = range(wire.INSTANCE_MIN, wire.INSTANCE_MAX + 1)
DEFAULT_PORTS = {role.port for n in EVERYONE for role in wire.port_roles(wire.ports(n))}


def _roles(b: dict[str, int]):
    def roles_of(n: int) -> tuple[wire.PortRole, ...]:
        return wire.port_roles(wire.ports(n, b["hil_base"], b["gcs_base"], b["api_base"], b["zenoh_base"]))

    return roles_of


DEFAULT_BASES = {"hil_base": 4560, "gcs_base": 14550, "api_base": 14540, "zenoh_base": 7447}


@pytest.mark.parametrize("b", [DEFAULT_BASES, bases(BLOCK_STARTS[0])], ids=["default", "test block"])
def test_250_instances_never_collide(b):
    roles_of = _roles(b)
    assert wire.INSTANCE_MAX - wire.INSTANCE_MIN + 1 == 250
    assert wire.system_id(wire.INSTANCE_MAX) == 250
    own: dict[tuple[str, int], tuple[int, str]] = {}
    clients: dict[tuple[str, int], set[int]] = {}
    for n in EVERYONE:
        for r in roles_of(n):
            if r.own:
                assert (r.proto, r.port) not in own, (n, r, own.get((r.proto, r.port)))
                own[(r.proto, r.port)] = (n, r.role)
            else:
                clients.setdefault((r.proto, r.port), set()).add(n)
    assert not own.keys() & clients.keys()
    assert len(own) == 250 * 4  # HIL, GCS link, API link, zenoh: each instance's own
    assert wire.port_collisions(roles_of, EVERYONE) == []


def test_default_ports_are_px4s():
    p0, p9, p37, p249 = (wire.ports(n) for n in (0, 9, 37, 249))
    assert (p0.hil, p0.gcs_remote, p0.gcs_local, p0.api_remote, p0.api_local, p0.zenoh) == (
        4560, 14550, 18570, 14540, 14580, 7447)  # fmt: skip
    assert {wire.ports(n).gcs_remote for n in EVERYONE} == {14550}  # one GCS port for the fleet
    assert (p9.api_remote, p37.api_remote, p249.api_remote) == (14549, 14549, 14549)  # PX4: N > 9
    assert (p37.hil, p37.gcs_local, p37.api_local) == (4597, 18607, 14617)
    assert (p249.hil, p249.gcs_local, p249.api_local, p249.zenoh) == (4809, 18819, 14829, 7696)
    assert wire.api_connect_url(p0, 0) == "udpin://0.0.0.0:14540"
    assert wire.api_connect_url(p37, 37) == "udpout://127.0.0.1:14617"
    with pytest.raises(ValueError, match=r"\[0, 249\]"):
        wire.ports(250)


def test_bases_that_meet_are_collisions():
    b = dict(DEFAULT_BASES, hil_base=18570)  # HIL of N is the GCS link of N
    clash = wire.port_collisions(_roles(b), [3, 4])
    assert {(c.port, c.first[0], c.second[0]) for c in clash} == {(18573, 3, 3), (18574, 4, 4)}
    b = dict(DEFAULT_BASES, hil_base=14550 - 5)  # HIL of 5: everyone's GCS client port; of 0: 5's API one
    clash = wire.port_collisions(_roles(b), [0, 5])
    assert sorted((c.port, c.first[0], c.second[0], c.second[1].role) for c in clash) == [
        (14545, 0, 5, "API client port"),
        (14550, 5, 0, "GCS client port"),
        (14550, 5, 5, "GCS client port"),
    ]


def test_blocks_never_share_a_port_nor_meet_the_defaults_or_the_ephemeral_range():
    seen: set[int] = set()
    for start in BLOCK_STARTS:
        ports = {port for _, port in block_ports(start)}
        assert not ports & seen, start
        assert not ports & DEFAULT_PORTS, start
        assert min(ports) >= 1024 and max(ports) < 32768, start  # Linux's ephemeral ports start there
        seen |= ports
