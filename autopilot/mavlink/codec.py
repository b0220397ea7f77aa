"""One MAVLink 2 encoder/decoder setup for the autopilot (pymavlink's ``common`` dialect)."""

from __future__ import annotations

import struct

from pymavlink.dialects.v20 import common as mavlink

from quadcommon.wire import new_parser, restart_parser, saturate_fields

__all__ = ["mavlink", "Encoder", "new_parser", "restart_parser"]


class Encoder:
    """Packs pymavlink messages as one system/component, keeping the sequence number."""

    def __init__(self, system_id: int, component_id: int) -> None:
        self.mav = mavlink.MAVLink(None, srcSystem=system_id, srcComponent=component_id)

    def pack(self, message) -> bytes:
        """The frame; a field beyond its type's range (a vehicle 1e39 m away) goes out saturated
        at the edge of the range (:func:`quadcommon.wire.saturate_fields`) instead of failing."""
        try:
            data = message.pack(self.mav)
        except (OverflowError, struct.error):
            saturate_fields(message)
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

