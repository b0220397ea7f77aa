"""The MAVLink parameter protocol on the GCS links, as PX4 speaks it (MAVSDK, MAVProxy, QGC).

* ``PARAM_REQUEST_LIST``: every parameter as ``PARAM_VALUE`` (``param_index`` 0..count-1 in
  declaration order, ``param_count`` = count) to the address that asked. Paced: the first
  :data:`LIST_BURST` at once, then :data:`LIST_BURST` per :meth:`ParamService.poll` (the process
  calls it every 50 ms of wall time), i.e. about 320 messages/s (12 kB/s). That is far below what
  a loopback socket buffer takes, and keeps a slow radio-like link or a GUI from being flooded;
  a new request restarts the stream. PX4's ``_HASH_CHECK`` pseudo-parameter is not sent.
* ``PARAM_REQUEST_READ``: by name (``param_index`` = -1) or by index; an unknown one gets a
  STATUSTEXT and no PARAM_VALUE (as PX4).
* ``PARAM_SET``: validated (name, type, range, read-only); accepted values take effect at once
  (between control steps) and are echoed as ``PARAM_VALUE`` on every link. A refused set is
  answered as PX4 does, with ``PARAM_VALUE`` carrying the unchanged current value and type (so
  MAVSDK, which waits for an echo equal to what it sent, retries and then reports failure), plus a
  STATUSTEXT saying why; an unknown name gets only the STATUSTEXT (as PX4).
* Encoding (PX4's, ``MAV_PROTOCOL_CAPABILITY_PARAM_ENCODE_BYTEWISE``): floats as
  ``MAV_PARAM_TYPE_REAL32``; integers as ``MAV_PARAM_TYPE_INT32`` whose four little-endian bytes
  fill the float field. Both directions go through raw bytes, never a Python float: an int32 whose
  bytes form a signalling-NaN float (0x7F800001..0x7FBFFFFF, 0xFF800001..0xFFBFFFFF) would come
  out with its quiet bit set after a float -> double conversion.
* ``MAV_CMD_PREFLIGHT_STORAGE`` (245), param1: 0 load the parameter file, 1 save it, 2 (and 4)
  reset every writable parameter to its default. With a file (``--params FILE``) every accepted
  change is also saved at once, as PX4 does.

(Parameters over MAVLink FTP: PX4 releases serve none; the FTP server (:mod:`.ftp`) answers
ArduPilot's ``@PARAM/param.pck`` with FileNotFound, so MAVProxy falls back to
PARAM_REQUEST_LIST at once.)
"""

from __future__ import annotations

import math
import struct
from collections.abc import Callable, Sequence
from pathlib import Path

from quadcommon.schema import ConfigError

from ..params.storage import load_params_file, write_params_file
from ..params.store import INT32, ParameterStore
from .codec import Encoder
from .codec import mavlink as m
from .commands import CommandDispatcher, CommandRequest

LIST_BURST = 16  # PARAM_VALUE messages per poll of a PARAM_REQUEST_LIST stream
REFUSAL_REPEAT_S = 1.0  # the same refusal text is not repeated within this (MAVSDK retries 5 times)

_PARAM_VALUE = struct.Struct("<iHH16sB")  # PARAM_VALUE payload with the value field as raw int32


def int32_to_wire_float(value: int) -> float:
    """PX4's bytewise encoding: the int32's bytes read as a float32 (for display and tests only)."""
    return struct.unpack("<f", struct.pack("<i", value))[0]


def wire_float_to_int32(value: float) -> int:
    """Inverse of :func:`int32_to_wire_float`; wrong for signalling-NaN patterns (see module doc)."""
    return struct.unpack("<i", struct.pack("<f", value))[0]


def float32_shortest(value: float) -> float:
    """The shortest decimal that rounds to the same float32 as ``value`` (0.3, not 0.30000001192).

    Values arriving as REAL32 are stored like this, so files and logs show what the user typed and
    the echo (packed as float32 again) carries exactly the bits that were sent.
    """
    bits = struct.pack("<f", value)
    target = struct.unpack("<f", bits)[0]
    if not math.isfinite(target):
        return target
    for digits in range(6, 10):
        candidate = float(f"{target:.{digits}g}")
        if struct.pack("<f", candidate) == bits:
            return candidate
    return target


def payload_bytes(msg) -> bytes:
    """The received message's payload as sent (MAVLink 1 or 2 framing; v2 trailing zeros restored)."""
    buf = bytes(msg.get_msgbuf())
    header = 10 if buf[:1] == b"\xfd" else 6
    return buf[header : header + buf[1]]


def param_set_raw_value(msg) -> bytes:
    """The four bytes of PARAM_SET.param_value (the first payload field), straight off the wire."""
    return payload_bytes(msg)[:4].ljust(4, b"\0")


def pack_param_value(encoder: Encoder, name: str, value: float, kind: str, count: int, index: int) -> bytes:
    """One PARAM_VALUE frame, its value field written from raw bytes (exact for every int32)."""
    if kind == INT32:
        raw = struct.pack("<i", int(value))
        param_type = m.MAV_PARAM_TYPE_INT32
    else:
        raw = struct.pack("<f", value)
        param_type = m.MAV_PARAM_TYPE_REAL32
    name_raw = name.encode("ascii")[:16]
    msg = m.MAVLink_param_value_message(name_raw, 0.0, param_type, count, index)
    payload = raw + _PARAM_VALUE.pack(0, count, index, name_raw, param_type)[4:]
    data = msg._pack(encoder.mav, msg.crc_extra, payload)  # pack() would route raw through a float
    encoder.mav.seq = (encoder.mav.seq + 1) % 256
    return data


class ParamService:
    """Parameters on the GCS links: the protocol above, and the file."""

    def __init__(
        self,
        store: ParameterStore,
        encoder: Encoder,
        links: Sequence,
        statustext: Callable[[int, str], None],
        system_id: int,
        component_id: int,
        storage_path: str | Path | None = None,
        header: str = "",
        *,
        clock: Callable[[], float],
        refusals: Callable[[str], None] | None = None,
    ) -> None:
        """``links`` = the GCS links (``send(data)``, ``send_to(data, address)``); ``refusals``: the
        core's one refusal counter and announcer (its own rate-limited STATUSTEXT when None)."""
        self.store = store
        self.encoder = encoder
        self.links = links
        self.statustext = statustext
        self.system_id = system_id
        self.component_id = component_id
        self.storage_path = Path(storage_path) if storage_path else None
        self.header = header
        self.clock = clock
        self.refusals = refusals
        self._streams: dict[tuple[int, tuple[str, int]], list] = {}  # -> [link, address, next index]
        self._last_refusal: tuple[str, float] = ("", -math.inf)
        self._autosave = True
        store.on_change(self._on_change)

    def register(self, handlers: dict, commands: CommandDispatcher) -> None:
        """Hook into the process shell's message table and command dispatcher."""
        handlers[m.MAVLINK_MSG_ID_PARAM_REQUEST_LIST] = self.on_message
        handlers[m.MAVLINK_MSG_ID_PARAM_REQUEST_READ] = self.on_message
        handlers[m.MAVLINK_MSG_ID_PARAM_SET] = self.on_message
        commands.register(m.MAV_CMD_PREFLIGHT_STORAGE, self._cmd_storage)

    # -- encoding ------------------------------------------------------------------------------------
    def value_frame(self, name: str) -> bytes:
        """The packed PARAM_VALUE of ``name``: its current value (INT32 bytewise), type, index and the
        parameter count."""
        spec = self.store.specs[name]
        return pack_param_value(
            self.encoder, name, self.store[name], spec.kind, len(self.store), self.store.index(name)
        )

    def _for_us(self, msg) -> bool:
        return msg.target_system in (0, self.system_id) and msg.target_component in (0, self.component_id)

    # -- messages --------------------------------------------------------------------------------------
    def on_message(self, msg, link, address) -> None:
        """Answer PARAM_REQUEST_LIST (a paced stream to the sender), PARAM_REQUEST_READ and PARAM_SET
        addressed to this vehicle (module docstring)."""
        if not self._for_us(msg):
            return
        kind = msg.get_msgId()
        if kind == m.MAVLINK_MSG_ID_PARAM_REQUEST_LIST:
            self._streams[(id(link), address)] = [link, address, 0]
            self._pump(self._streams[(id(link), address)])
        elif kind == m.MAVLINK_MSG_ID_PARAM_REQUEST_READ:
            self._on_read(msg, link, address)
        elif kind == m.MAVLINK_MSG_ID_PARAM_SET:
            self._on_set(msg, link, address)

    def _on_read(self, msg, link, address) -> None:
        names = self.store.names()
        if msg.param_index >= 0:
            if msg.param_index >= len(names):
                self.statustext(m.MAV_SEVERITY_WARNING, f"param read: no parameter index {msg.param_index}")
                return
            name = names[msg.param_index]
        else:
            name = msg.param_id
            if name not in self.store:
                self.statustext(m.MAV_SEVERITY_WARNING, f"param read: unknown parameter '{name}'")
                return
        link.send_to(self.value_frame(name), address)

    def _on_set(self, msg, link, address) -> None:
        name = msg.param_id
        spec = self.store.specs.get(name)
        if spec is None:
            self._refused(f"param set refused: unknown parameter '{name}'")
            return
        raw = param_set_raw_value(msg)
        wanted = m.MAV_PARAM_TYPE_INT32 if spec.kind == INT32 else m.MAV_PARAM_TYPE_REAL32
        if msg.param_type != wanted:
            have = "INT32" if spec.kind == INT32 else "REAL32"
            problem = f"{name}: type {msg.param_type} refused, it is {have} (MAV_PARAM_TYPE {wanted})"
        else:
            if spec.kind == INT32:
                value: float = struct.unpack("<i", raw)[0]
            else:
                value = float32_shortest(struct.unpack("<f", raw)[0])
            problem = self.store.set(name, value)
        if problem:
            self._refused(f"param set refused: {problem}")
        data = self._announce(name)
        if address not in getattr(link, "peers", ()):
            link.send_to(data, address)

    def set_value(self, name: str, value: float) -> str | None:
        """Set a parameter as a PARAM_SET does, from inside the vehicle (its console): the store's
        checks, the refusal said by STATUSTEXT, the value after it on every link. None when
        accepted, else why not."""
        if name not in self.store.specs:
            problem = f"unknown parameter '{name}'"
        else:
            kind = self.store.specs[name].kind
            problem = self.store.set(name, value if kind == INT32 else float32_shortest(value))
        if problem:
            self._refused(f"param set refused: {problem}")
        if name in self.store.specs:
            self._announce(name)
        return problem

    def _announce(self, name: str) -> bytes:
        """PARAM_VALUE of ``name`` on every link (new if a set was accepted, unchanged if not)."""
        data = self.value_frame(name)
        for each in self.links:
            each.send(data)
        return data

    def _refused(self, text: str) -> None:
        if self.refusals is not None:
            self.refusals(text)
            return
        last_text, last_at = self._last_refusal
        now = self.clock()
        if text != last_text or now - last_at > REFUSAL_REPEAT_S:
            self.statustext(m.MAV_SEVERITY_WARNING, text)
        self._last_refusal = (text, now)

    # -- list streams ------------------------------------------------------------------------------------
    def poll(self) -> None:
        """Send the next burst of every PARAM_REQUEST_LIST stream (call every ~50 ms)."""
        for key, stream in list(self._streams.items()):
            if self._pump(stream):
                del self._streams[key]

    def _pump(self, stream: list) -> bool:
        """One burst; True when the stream is complete."""
        link, address, start = stream
        names = self.store.names()
        end = min(start + LIST_BURST, len(names))
        for name in names[start:end]:
            link.send_to(self.value_frame(name), address)
        stream[2] = end
        return end >= len(names)

    @property
    def streaming(self) -> bool:
        """True while a PARAM_REQUEST_LIST stream still has values to send."""
        return bool(self._streams)

    # -- storage ------------------------------------------------------------------------------------------
    def _on_change(self, name: str, value: float) -> None:
        if self._autosave and self.storage_path is not None:
            problem = self.save()
            if problem:
                self.statustext(m.MAV_SEVERITY_WARNING, problem)

    def save(self) -> str | None:
        """Write the file; None on success, else why not."""
        if self.storage_path is None:
            return "no parameter file: start the autopilot with --params FILE"
        try:
            write_params_file(self.storage_path, self.store, self.header)
        except OSError as exc:
            return f"cannot save parameters to {self.storage_path}: {exc.strerror or exc}"
        return None

    def load(self) -> str | None:
        """Apply the file (all or nothing); None on success, else why not."""
        if self.storage_path is None:
            return "no parameter file: start the autopilot with --params FILE"
        before = dict(self.store.values)
        self._autosave = False
        try:
            load_params_file(self.storage_path, self.store)
        except ConfigError as exc:
            return str(exc)
        finally:
            self._autosave = True
        self._announce_changes(before)
        return None

    def reset_to_defaults(self) -> None:
        """Every writable parameter back to its default (MAV_CMD_PREFLIGHT_STORAGE param1 2): the file saved
        once, each changed value announced as PARAM_VALUE on every link."""
        before = dict(self.store.values)
        self._autosave = False
        try:
            defaults = {n: self.store.specs[n].default for n in self.store.writable()}
            self.store.set_many(defaults)
        finally:
            self._autosave = True
        if self.storage_path is not None and self.store.values != before:
            self.save()
        self._announce_changes(before)

    def _announce_changes(self, before: dict[str, float]) -> None:
        """PARAM_VALUE of every changed parameter on every link (ground stations keep caches)."""
        for name, value in self.store.values.items():
            if before.get(name) != value:
                data = self.value_frame(name)
                for link in self.links:
                    link.send(data)

    def _cmd_storage(self, r: CommandRequest) -> tuple[int, str]:
        action = r.params[0]
        if action == 0:
            problem = self.load()
            what = f"parameters loaded from {self.storage_path}"
        elif action == 1:
            problem = self.save()
            what = f"parameters saved to {self.storage_path}"
        elif action in (2, 4):
            self.reset_to_defaults()
            problem, what = None, "parameters reset to their defaults"
        else:
            return m.MAV_RESULT_UNSUPPORTED, f"PREFLIGHT_STORAGE param1={action:g} not supported"
        if problem:
            self.statustext(m.MAV_SEVERITY_WARNING, problem)
            return m.MAV_RESULT_DENIED, problem
        self.statustext(m.MAV_SEVERITY_INFO, what)
        return m.MAV_RESULT_ACCEPTED, ""
