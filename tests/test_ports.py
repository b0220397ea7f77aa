"""The tests' port blocks (tests/ports.py): no two blocks share a port, none meets the default
bases' ports or the ephemeral range, and each keeps the default bases' overlaps between instances."""

from quadcommon import wire
from tests.ports import BLOCK_STARTS, bases, block_ports

DEFAULT_PORTS = {port for n in range(100) for role in wire.port_roles(wire.ports(n)) for port in [role.port]}


def test_blocks_never_share_a_port_nor_meet_the_defaults_or_the_ephemeral_range():
    seen: set[int] = set()
    for start in BLOCK_STARTS:
        ports = {port for _, port in block_ports(start)}
        assert not ports & seen, start
        assert not ports & DEFAULT_PORTS, start
        assert max(ports) < 32768, start  # Linux's ephemeral ports start there
        seen |= ports


def test_a_block_keeps_the_default_overlaps_between_instances():
    b = bases(BLOCK_STARTS[0])
    shifted = wire.ports(0, b["hil_base"], b["gcs_base"], b["api_base"], b["zenoh_base"])
    assert wire.overlapping_offsets(shifted) == wire.overlapping_offsets(wire.ports(0)) == (10, 30, 40)
