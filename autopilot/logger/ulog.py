"""ULog, PX4's flight-log format, as bytes: one function per message kind (pure: no file, no clock).

A ULog file (https://docs.px4.io/main/en/dev_log/ulog_file_format.html) is

* a 16-byte header: the magic ``ULog\\x01\\x12\\x35``, version 1, the start timestamp (µs);
* the definitions: the flag bits (``B``, 40 bytes, first), the message formats (``F``), info
  (``I``, ``M``) and the initial parameters (``P``);
* the data: subscriptions (``A``: a message id for a format), samples (``D``), logged strings
  (``L``), parameter changes (``P``), sync markers (``S``), dropouts (``O``).

Every message is ``uint16 payload size, uint8 type, payload``, little-endian and packed (no
alignment padding: readers take the layout from the format text). Timestamps are µs since boot;
here boot is simulation time zero, so a sample's timestamp is the ``time_usec`` of its frame.

Why our own writer and not pyulog's: pyulog (1.3.0 on PyPI) writes a log only as
``ULog.write_ulog(file)``, the re-serialisation of a whole parsed ``ULog`` object: everything must
be in memory first and is written at the end, field by field. A flight log has to be written
while it grows and flushed every second, so that a killed autopilot leaves a readable file;
pyulog stays the reader (tests, ``quadsitl analyze``, ``quadsitl view``).

What readers require and this module guarantees: the flag bits message first after the header
and 40 bytes long (PlotJuggler refuses anything else), no incompatible flag set, every format's
first field ``uint64_t timestamp`` (PlotJuggler and pyulog find the time there), a format for
every subscription before its first ``A`` (PlotJuggler dereferences it), and parameters typed
``int32_t`` or ``float`` only (PlotJuggler throws on any other type).

A field may be of a nested message type, as PX4's ``position_setpoint_triplet`` holds three
``position_setpoint``: its type is the nested format's name (``position_setpoint current``), the
nested format is defined by its own ``F`` message, and a sample holds the nested fields inline
(readers flatten them: pyulog's ``current.alt``).
"""

from __future__ import annotations

import struct
from collections.abc import Sequence
from typing import NamedTuple

MAGIC = b"ULog\x01\x12\x35"
FILE_VERSION = 1
SYNC_MAGIC = b"\x2f\x73\x13\x20\x25\x0c\xbb\x12"
HEADER_SIZE = 16
MAX_PAYLOAD = 0xFFFF
FLAG_BITS_SIZE = 40  # 8 compat flags, 8 incompat flags, 3 uint64 appended-data offsets

# Message types (one ASCII letter each).
FLAG_BITS, FORMAT, INFO, INFO_MULTIPLE = ord("B"), ord("F"), ord("I"), ord("M")
PARAMETER, PARAMETER_DEFAULT, ADD_LOGGED, REMOVE_LOGGED = ord("P"), ord("Q"), ord("A"), ord("R")
DATA, LOGGING, LOGGING_TAGGED, SYNC, DROPOUT = ord("D"), ord("L"), ord("C"), ord("S"), ord("O")

# ULog field types and their struct codes.
TYPE_CODES = {
    "int8_t": "b", "uint8_t": "B", "int16_t": "h", "uint16_t": "H", "int32_t": "i", "uint32_t": "I",
    "int64_t": "q", "uint64_t": "Q", "float": "f", "double": "d", "bool": "?", "char": "c",
}  # fmt: skip
_MESSAGE_HEADER = struct.Struct("<HB")


class Field(NamedTuple):
    """One field of a format: ``float[4] q`` is ``Field("float", "q", 4)``; count 0: a scalar;
    ``nested``: the format of a nested message type (``type`` is then its name)."""

    type: str
    name: str
    count: int = 0
    nested: Format | None = None

    @property
    def text(self) -> str:
        """The field in PX4's notation: ``float[4] q``, ``uint64_t timestamp``."""
        return f"{self.type}[{self.count}] {self.name}" if self.count else f"{self.type} {self.name}"

    @property
    def values(self) -> int:
        """How many values the field takes in a sample (1 for a scalar)."""
        return self.count or 1


def fields(text: str, nested: Sequence[Format] = ()) -> tuple[Field, ...]:
    """Fields from PX4's message notation: ``"uint64_t timestamp; float[4] q; bool valid"``; a
    field's type may be the name of one of the ``nested`` formats."""
    known = {fmt.name: fmt for fmt in nested}
    out = []
    for part in text.split(";"):
        part = part.strip()
        if not part:
            continue
        kind, name = part.split()
        count = 0
        if "[" in kind:
            kind, size = kind[:-1].split("[")
            count = int(size)
        if kind not in TYPE_CODES and kind not in known:
            raise ValueError(f"ULog field {part!r}: unknown type {kind!r}")
        out.append(Field(kind, name, count, known.get(kind)))
    return tuple(out)


class Format(NamedTuple):
    """A message format: its name (the topic's) and its fields, the timestamp first."""

    name: str
    fields: tuple[Field, ...]

    @property
    def text(self) -> str:
        """The format message's text: ``name:type field;type field;...``."""
        return f"{self.name}:" + "".join(f"{f.text};" for f in self.fields)

    @property
    def struct(self) -> struct.Struct:
        """The little-endian :class:`struct.Struct` that packs one sample (timestamp first, arrays and nested
        messages inline)."""
        return struct.Struct("<" + self.codes)

    @property
    def codes(self) -> str:
        """The ``struct`` codes of a sample, nested messages inline."""
        return "".join(
            f.nested.codes * f.values if f.nested is not None else f"{f.count or ''}{TYPE_CODES[f.type]}"
            for f in self.fields
        )

    @property
    def nested(self) -> tuple[Format, ...]:
        """The formats of its nested message types (theirs first), each once."""
        out: list[Format] = []
        for f in self.fields:
            if f.nested is not None:
                out.extend(n for n in (*f.nested.nested, f.nested) if n not in out)
        return tuple(out)

    def field_names(self) -> list[str]:
        """The names pyulog gives the columns: ``q[0]`` .. ``q[3]`` for arrays, ``current.alt`` for
        a nested message's field."""
        names = []
        for f in self.fields:
            for i in range(f.values):
                name = f"{f.name}[{i}]" if f.count else f.name
                if f.nested is None:
                    names.append(name)
                else:
                    names.extend(f"{name}.{inner}" for inner in f.nested.field_names())
        return names

    def check(self) -> None:
        """ValueError unless the format is one every reader takes (see the module docstring)."""
        if not self.fields or self.fields[0] != Field("uint64_t", "timestamp"):
            raise ValueError(f"ULog format {self.name}: the first field must be 'uint64_t timestamp'")
        names = [f.name for f in self.fields]
        if len(set(names)) != len(names):
            raise ValueError(f"ULog format {self.name}: a field name appears twice")
        if not self.name.isidentifier() or not all(n.isidentifier() for n in names):
            raise ValueError(f"ULog format {self.name}: names must be identifiers ({names})")


def message(kind: int, payload: bytes) -> bytes:
    """One message: size, type, payload (ValueError if the payload exceeds 65535 bytes)."""
    if len(payload) > MAX_PAYLOAD:
        raise ValueError(f"ULog message {chr(kind)!r} of {len(payload)} bytes (at most {MAX_PAYLOAD})")
    return _MESSAGE_HEADER.pack(len(payload), kind) + payload


def file_header(timestamp_us: int) -> bytes:
    """The 16-byte file header: magic, version, the log's start time (µs since boot)."""
    return MAGIC + bytes((FILE_VERSION,)) + struct.pack("<Q", timestamp_us)


def flag_bits() -> bytes:
    """The flag bits message (no flag set: no appended data), which must follow the header."""
    return message(FLAG_BITS, bytes(FLAG_BITS_SIZE))


def format_message(fmt: Format) -> bytes:
    """The ``F`` (format definition) message of ``fmt``, checked first (ValueError if a reader would refuse
    it)."""
    fmt.check()
    return message(FORMAT, fmt.text.encode("ascii"))


def _key_value(type_name: str, key: str, value: bytes) -> bytes:
    key_bytes = f"{type_name} {key}".encode("ascii")
    if len(key_bytes) > 255:
        raise ValueError(f"ULog key {key!r} too long")
    return bytes((len(key_bytes),)) + key_bytes + value


def info(key: str, value: str | int | float, type_name: str | None = None) -> bytes:
    """An information message: a string (``char[N]``), or a number of ``type_name`` (default
    ``int32_t`` for an int, ``float`` for a float)."""
    if isinstance(value, str):
        raw = value.encode("utf-8")
        return message(INFO, _key_value(f"char[{len(raw)}]", key, raw))
    type_name = type_name or ("int32_t" if isinstance(value, int) else "float")
    return message(INFO, _key_value(type_name, key, struct.pack("<" + TYPE_CODES[type_name], value)))


def parameter(name: str, value: float, integer: bool) -> bytes:
    """A parameter (``int32_t`` or ``float``: the only types PlotJuggler reads). In the
    definitions it is an initial value; in the data section, a change at that point of the log."""
    if integer:
        return message(PARAMETER, _key_value("int32_t", name, struct.pack("<i", int(value))))
    return message(PARAMETER, _key_value("float", name, struct.pack("<f", value)))


def add_logged(msg_id: int, name: str, multi_id: int = 0) -> bytes:
    """A subscription: data messages with ``msg_id`` are samples of format ``name``."""
    return message(ADD_LOGGED, struct.pack("<BH", multi_id, msg_id) + name.encode("ascii"))


def logged_string(level: int, timestamp_us: int, text: str) -> bytes:
    """A logged string; ``level`` as the Linux kernel's (and MAV_SEVERITY): 0 emergency .. 7 debug,
    written as the ASCII digit PX4 writes."""
    level = min(max(int(level), 0), 7)
    raw = text.encode("utf-8", "replace")[: MAX_PAYLOAD - 9]
    return message(LOGGING, struct.pack("<BQ", ord("0") + level, timestamp_us) + raw)


def sync() -> bytes:
    """A sync marker (lets a reader resynchronise after a corrupted stretch)."""
    return message(SYNC, SYNC_MAGIC)


def dropout(duration_ms: int) -> bytes:
    """A dropout message (``O``): ``duration_ms`` of data lost, clipped to [0, 65535] ms."""
    return message(DROPOUT, struct.pack("<H", min(max(int(duration_ms), 0), 0xFFFF)))


class Topic:
    """One logged topic: its format and message id; :meth:`sample` packs one data message."""

    def __init__(self, fmt: Format, msg_id: int, multi_id: int = 0) -> None:
        fmt.check()
        self.format = fmt
        self.name = fmt.name
        self.msg_id = msg_id
        self.multi_id = multi_id
        packer = fmt.struct
        self.size = packer.size
        self.pack = packer.pack  # (timestamp, *values) -> the sample's payload without the id
        self.prefix = _MESSAGE_HEADER.pack(2 + packer.size, DATA) + struct.pack("<H", msg_id)

    def sample(self, values: Sequence) -> bytes:
        """One data message of ``values`` (timestamp first, arrays inline)."""
        return self.prefix + self.pack(*values)
