"""Encoding and decoding the lockstep messages without building pymavlink message objects.

In lockstep every frame crosses the wire twice before the plant may step, so decoding sits on the
critical path. pymavlink's generic ``MAVLink.decode`` builds a message object field by field:
measured here (2 vCPUs, loaded), 54 µs for ODOMETRY (its covariance arrays), 25 µs for
HIL_STATE_QUATERNION, 8 µs for HIL_ACTUATOR_CONTROLS. :class:`FastDecoder` does the same checks with
pymavlink's own pieces, the message class's ``struct`` unpacker, CRC extra and wire field order,
and the same MAVLink 2 rules (zero-padding of truncated payloads, CRC over header + payload +
CRC extra), and returns the fields by name from one ``unpack``: a few µs.

:class:`FastEncoder` is the other direction for the messages sent every frame (HIL_SENSOR,
HIL_STATE_QUATERNION, ODOMETRY, HIL_GPS, HIL_ACTUATOR_CONTROLS): a flat, reusable list of field
values in wire order, packed by the class's ``struct`` and framed exactly as pymavlink's
``MAVLink_message._pack`` frames it (MAVLink 2, trailing zeros of the payload dropped, CRC extra,
unsigned): the same bytes (tested), about 4x cheaper.

:func:`record_dtype` gives a message's payload as a numpy record type, made from the same class's
``struct`` format and wire field order: compiled code fills such a record, a view of a byte buffer
(:meth:`FastEncoder.buffer`), in place of the flat list, and its bytes are the payload ``struct``
would pack.

Only for the lockstep messages, whose layout is fixed by the dialect; everything else goes
through pymavlink as usual.
"""

from __future__ import annotations

import hashlib
import re
import struct

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

try:  # what pymavlink itself uses for the CRC when present (fastcrc, a project dependency)
    from fastcrc.crc16 import mcrf4xx as _crc
except ImportError:  # pragma: no cover - pymavlink's pure-Python CRC then

    def _crc(data: bytes, initial: int) -> int:
        crc = mavlink.x25crc()
        crc.crc = initial
        crc.accumulate(data)
        return crc.crc

_STX_V2 = 0xFD
_HEADER_LEN = 10
_SIGNED = 0x01
_SIGNATURE_LEN = 13


def split_frames(datagram: bytes) -> list[tuple[int, bytes]]:
    """``(msgid, frame bytes)`` of each MAVLink 2 frame in a datagram, without decoding.

    MAVLink 2 header: STX 0xFD, payload length, incompat flags (bit 0: signed, +13 bytes),
    compat flags, seq, sysid, compid, 24-bit message id; then payload and a 2-byte CRC. Splitting
    first lets the autopilot decode only the messages it uses (decoding is most of a frame's cost
    here: ~10 us per message with pymavlink); anything that is not MAVLink 2 ends the split.
    """
    out = []
    i, n = 0, len(datagram)
    while i + 12 <= n and datagram[i] == 0xFD:
        total = 12 + datagram[i + 1] + (13 if datagram[i + 2] & 1 else 0)
        out.append((datagram[i + 7] | datagram[i + 8] << 8 | datagram[i + 9] << 16, datagram[i : i + total]))
        i += total
    return out


class DecodeError(ValueError):
    """A frame that is not a valid MAVLink 2 frame of the expected message."""


class FastDecoder:
    """Decode one message type: :meth:`unpack` gives the flat field tuple (wire order, arrays
    inline); ``slices[name]`` says where a field sits in it (an index, or a slice for arrays)."""

    def __init__(self, message_class) -> None:
        self.message_class = message_class
        self.msg_id = message_class.id
        self.unpacker = message_class.unpacker
        self.size = self.unpacker.size
        self.crc_extra = message_class.crc_extra
        self._crc_extra = bytes((message_class.crc_extra,))
        self.slices = _flat_slices(message_class)  # where each field sits in unpack()'s tuple

    def unpack(self, frame: bytes) -> tuple:
        """The flat field tuple of one complete MAVLink 2 frame (CRC checked)."""
        return self.unpacker.unpack_from(self.payload(frame))

    def payload(self, frame: bytes) -> bytes:
        """The checked payload of one complete MAVLink 2 frame, zero-padded to the full size (for
        callers that unpack only the fields they need, with their own ``struct``)."""
        if len(frame) < _HEADER_LEN + 2 or frame[0] != _STX_V2:
            raise DecodeError("not a MAVLink 2 frame")
        length = frame[1]
        signed = frame[2] & _SIGNED
        end = _HEADER_LEN + length
        if len(frame) != end + 2 + (_SIGNATURE_LEN if signed else 0):
            raise DecodeError(f"frame length {len(frame)} does not match its payload length {length}")
        msg_id = frame[7] | frame[8] << 8 | frame[9] << 16
        if msg_id != self.msg_id:
            raise DecodeError(f"message id {msg_id}, expected {self.msg_id}")
        if _crc(frame[1:end] + self._crc_extra, 0xFFFF) != frame[end] | frame[end + 1] << 8:
            raise DecodeError(f"bad CRC in message {msg_id}")
        payload = frame[_HEADER_LEN:end]
        if length < self.size:  # MAVLink 2 drops trailing zero bytes: put them back
            payload = payload + bytes(self.size - length)
        return payload


def _flat_slices(message_class) -> dict[str, int | slice]:
    """Where each field lands in the flat tuple of the class's struct (wire order, arrays inline)."""
    slices: dict[str, int | slice] = {}
    offset = 0
    for name, length in zip(message_class.ordered_fieldnames, _lengths(message_class), strict=True):
        slices[name] = offset if length == 1 else slice(offset, offset + length)
        offset += length
    return slices


def _lengths(message_class) -> list[int]:
    names = message_class.ordered_fieldnames
    return [message_class.lengths[message_class.ordered_fieldnames.index(n)] for n in names]


# A struct code as a little-endian numpy type ("s": a char array, its count its length in bytes).
_NUMPY_TYPES = {"Q": "<u8", "q": "<i8", "I": "<u4", "i": "<i4", "H": "<u2", "h": "<i2", "B": "u1",
                "b": "i1", "f": "<f4", "d": "<f8"}  # fmt: skip


def record_dtype(message_class) -> np.dtype:
    """The message's payload as a numpy record type: its fields in wire order, packed, little-endian,
    array fields as subarrays, char arrays as bytes; the record's bytes are what the class's
    ``struct`` packs of the same values (its size is the struct's)."""
    fmt = message_class.unpacker.format
    tokens = [(int(count or 1), code) for count, code in re.findall(r"(\d*)([a-zA-Z?])", fmt)]
    fields: list[tuple] = []
    for name, length in zip(message_class.ordered_fieldnames, _lengths(message_class), strict=True):
        count, code = tokens.pop(0)
        if code == "s":  # char[count]: one field of ``count`` bytes
            fields.append((name, f"S{count}"))
            continue
        if count != length:
            tokens.insert(0, (count - length, code))  # "13f": several fields of one code
        fields.append((name, _NUMPY_TYPES[code]) if length == 1 else (name, _NUMPY_TYPES[code], (length,)))
    dtype = np.dtype(fields)
    if dtype.itemsize != message_class.unpacker.size:  # pragma: no cover - a dialect we do not know
        raise ValueError(f"{message_class.msgname}: record of {dtype.itemsize} bytes, struct of "
                         f"{message_class.unpacker.size}")  # fmt: skip
    return dtype


_HEADER_V2 = struct.Struct("<BBBBBBBHB")


class FastEncoder:
    """One message type, framed from :attr:`values` (flat, wire order; ``slices[name]`` says where).

    Fill ``values[slices[name]]`` and call :meth:`frame`; fields never written keep the values of
    the ``template`` message given at construction (or zero).
    """

    def __init__(self, message_class, system_id: int, component_id: int, template=None) -> None:
        self.msg_id = message_class.id
        self.packer = message_class.unpacker
        self.slices = _flat_slices(message_class)
        self._crc_extra = bytes((message_class.crc_extra,))
        self._ids = (system_id, component_id, self.msg_id & 0xFFFF, self.msg_id >> 16)
        flat: list = []
        for name, length in zip(message_class.ordered_fieldnames, _lengths(message_class), strict=True):
            value = getattr(template, name) if template is not None else (0 if length == 1 else [0] * length)
            if length == 1:
                flat.append(value)
            else:
                flat.extend(value[:length])
        self.values = flat

    def payload(self) -> bytes:
        """The whole payload of :attr:`values` (every field, wire order): what a decoder's
        :meth:`FastDecoder.payload` gives back of the :meth:`frame`, trailing zeros and all."""
        return self.packer.pack(*self.values)

    def buffer(self) -> np.ndarray:
        """:meth:`payload` as a uint8 array to fill in place, the template's values in it: compiled
        code views it as one record of the message's :func:`record_dtype` (an array's view is a
        fraction of the cost of passing it a record array); its ``tobytes()`` is a payload."""
        return np.frombuffer(self.payload(), dtype=np.uint8).copy()

    def frame(self, seq: int) -> bytes:
        """The MAVLink 2 frame of :attr:`values` with sequence number ``seq`` (0-255)."""
        return self.frame_of(self.payload(), seq)

    def frame_of(self, payload: bytes, seq: int) -> bytes:
        """The MAVLink 2 frame of a :meth:`payload` made earlier, with sequence number ``seq``."""
        return _frame(payload, seq, self._ids, self._crc_extra)


class MessageParts:
    """The MAVLink 2 messages of one datagram by message id (the last one of each id), each read
    as its checked payload (:meth:`FastDecoder.payload`, zero-padded to the full size) when asked.

    Two ways in, one way out: :meth:`of_datagram` splits bytes that came over a socket (each
    message's CRC and length checked when it is first read, DecodeError if they fail);
    :meth:`of_payloads` takes the payloads a :class:`FastEncoder` packed in this process (a
    lockstep frame that never became bytes on a wire: the in-process runner and the fleet). A
    payload is the same bytes either way (the framing drops trailing zeros that the decoder puts
    back), so what is read of a frame does not depend on how it came.
    """

    __slots__ = ("_frames", "_payloads", "_component_id")

    def __init__(
        self, frames: dict[int, bytes], payloads: dict[int, bytes], component_id: int | None
    ) -> None:
        self._frames = frames  # msg id -> the frame, unchecked (of_datagram)
        self._payloads = payloads  # msg id -> its checked payload
        self._component_id = component_id  # of every message (of_payloads), else read from each frame

    @classmethod
    def of_datagram(cls, datagram: bytes) -> MessageParts:
        """The messages of a datagram (:func:`split_frames`), checked when read."""
        return cls(dict(split_frames(datagram)), {}, None)

    @classmethod
    def of_payloads(cls, payloads: dict[int, bytes], component_id: int) -> MessageParts:
        """Payloads packed in this process (:meth:`FastEncoder.payload`) by ``component_id``."""
        return cls({}, payloads, component_id)

    def __contains__(self, msg_id: object) -> bool:
        return msg_id in self._payloads or msg_id in self._frames

    def ids(self) -> list[int]:
        """The message ids, in the datagram's order."""
        return list(self._frames or self._payloads)

    def payload(self, decoder: FastDecoder) -> bytes | None:
        """The checked payload of ``decoder``'s message, or None when there is none;
        DecodeError if its frame is corrupt."""
        payload = self._payloads.get(decoder.msg_id)
        if payload is None:
            frame = self._frames.get(decoder.msg_id)
            if frame is None:
                return None
            payload = self._payloads[decoder.msg_id] = decoder.payload(frame)
        return payload

    def component_id(self, msg_id: int) -> int | None:
        """The component that sent message ``msg_id``, or None when there is none."""
        if self._component_id is not None:
            return self._component_id if msg_id in self._payloads else None
        frame = self._frames.get(msg_id)
        return frame[6] if frame is not None else None


def frame_payload(message_class, payload: bytes, seq: int, system_id: int, component_id: int) -> bytes:
    """The unsigned MAVLink 2 frame of a ``message_class`` whose payload (all fields, wire order)
    the caller packed itself: for a message whose bulk is already bytes (LOG_DATA's 90 bytes),
    where building the message object and packing it field by field costs ~40 µs."""
    msg_id = message_class.id
    ids = (system_id, component_id, msg_id & 0xFFFF, msg_id >> 16)
    return _frame(payload, seq, ids, bytes((message_class.crc_extra,)))


def _frame(payload: bytes, seq: int, ids: tuple[int, int, int, int], crc_extra: bytes) -> bytes:
    """MAVLink 2 framing as pymavlink's: trailing zeros of the payload dropped, CRC extra, unsigned."""
    payload = payload.rstrip(b"\0") or b"\0"
    system_id, component_id, id_low, id_high = ids
    body = _HEADER_V2.pack(0xFD, len(payload), 0, 0, seq, system_id, component_id, id_low, id_high)
    body += payload
    crc = _crc(body[1:] + crc_extra, 0xFFFF)
    return body + bytes((crc & 0xFF, crc >> 8))


def signature(secret_key: bytes, signed_part: bytes | bytearray) -> bytes:
    """MAVLink 2's signature of a frame: the first 6 bytes of SHA-256 over the key and
    ``signed_part``, the frame up to the signature (header, payload, CRC, link id, timestamp)."""
    return hashlib.sha256(secret_key + signed_part).digest()[:6]


def with_sequence(frame: bytes, seq: int, secret_key: bytes | None = None) -> bytes:
    """``frame`` (one MAVLink 2 frame of a message of the dialect) with sequence number ``seq``
    (0-255): the header's seq byte, then the CRC over it again; a signed frame is signed again with
    ``secret_key`` under its own link id and timestamp (:func:`signature`). Anything else comes
    back unchanged: not one whole MAVLink 2 frame, an unknown message id, a signed frame without
    the key.

    What lets one packed message go out on several links, each numbered on its own, as PX4
    numbers each MAVLink channel: a ground station counts its losses from the gaps."""
    if len(frame) < _HEADER_LEN + 2 or frame[0] != _STX_V2 or frame[4] == seq:
        return frame
    end = _HEADER_LEN + frame[1]
    signed = frame[2] & _SIGNED
    if len(frame) != end + 2 + (_SIGNATURE_LEN if signed else 0) or (signed and secret_key is None):
        return frame
    message_class = mavlink.mavlink_map.get(frame[7] | frame[8] << 8 | frame[9] << 16)
    if message_class is None:
        return frame
    out = bytearray(frame)
    out[4] = seq
    crc = _crc(bytes(out[1:end]) + bytes((message_class.crc_extra,)), 0xFFFF)
    out[end], out[end + 1] = crc & 0xFF, crc >> 8
    if signed:  # link id and timestamp (7 bytes) stay; the 6 bytes of signature after them
        signed_part = end + 2 + _SIGNATURE_LEN - 6
        out[signed_part:] = signature(secret_key, out[:signed_part])
    return bytes(out)
