"""``quadsitl campaign --full-stack K``: fly K sampled runs through the whole in-process stack.

NOT DONE. The check is meant to take K runs of a campaign, fly each through the in-process full
stack (commander, mission, MAVLink encoding and decoding of every frame, as the SITL does
without sockets) and report whether their indices match the batch engine's. That full-stack
runner is being built (the in-process coupling of ``AutopilotCore`` and ``SimulatorCore``); this
hook is where the campaign calls it, and it says so instead of pretending.

What exists meanwhile: the batch engine's ``wire_float32`` switch emulates the wire's float32
quantisation and frame conversions, and ``tests/campaign/test_agreement.py`` checks it against
the encoder/decoder path (plant.truth() -> HilFrameEncoder -> decode_frame -> cascade ->
ActuatorEncoder -> ActuatorDecoder -> plant).
"""

from __future__ import annotations

from collections.abc import Sequence

import pyarrow as pa

from .spec import CampaignSpec


class FullStackUnavailable(NotImplementedError):
    """The in-process full-stack runner the check needs has not landed yet."""


def check(runs: Sequence[int], spec: CampaignSpec | None = None, table: pa.Table | None = None) -> None:
    """Fly ``runs`` through the in-process full stack and compare their indices with ``table``.

    Raises :class:`FullStackUnavailable` until the in-process full stack lands.
    """
    raise FullStackUnavailable(
        f"--full-stack: not available yet; it lands with the in-process full-stack runner (commander, "
        f"mission, MAVLink encoding without sockets). Asked to check {len(runs)} run(s). The batch "
        "engine's float32 wire emulation is checked against the MAVLink encoder/decoder path by "
        "tests/campaign/test_agreement.py meanwhile."
    )
