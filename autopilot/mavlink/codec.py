"""One MAVLink 2 encoder/decoder setup for the autopilot (pymavlink's ``common`` dialect)."""

from __future__ import annotations

from pymavlink.dialects.v20 import common as mavlink

__all__ = ["mavlink", "Encoder", "new_parser"]


class Encoder:
    """Packs pymavlink messages as one system/component, keeping the sequence number."""

    def __init__(self, system_id: int, component_id: int) -> None:
        self.mav = mavlink.MAVLink(None, srcSystem=system_id, srcComponent=component_id)

    def pack(self, message) -> bytes:
        data = message.pack(self.mav)
        self.mav.seq = (self.mav.seq + 1) % 256  # pack() does not advance it; send() would
        return data

    def pack_unsigned(self, message) -> bytes:
        """As :meth:`pack`, never signed, whatever ``mav.signing`` says (the HIL link's frames:
        signing is for the ground-station links, :mod:`.signing`)."""
        signing = self.mav.signing
        sign, signing.sign_outgoing = signing.sign_outgoing, False
        try:
            return self.pack(message)
        finally:
            signing.sign_outgoing = sign


def new_parser() -> mavlink.MAVLink:
    """A parser for incoming datagrams (``parse_buffer``); robust to garbage between frames."""
    parser = mavlink.MAVLink(None)
    parser.robust_parsing = True
    return parser
