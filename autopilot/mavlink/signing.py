"""MAVLink 2 message signing on the GCS links (https://mavlink.io/en/guide/message_signing.html).

When a key is set, every frame a ground-station link receives must carry a valid signature with a
fresh timestamp, and every frame the autopilot sends on those links is signed:

* **Incoming.** Each link's parser is a pymavlink ``MAVLink``; with ``signing.secret_key`` set its
  ``decode`` asks ``check_signature`` about every signed frame and ``allow_unsigned_callback``
  about the rest, and a refused frame comes out as ``BAD_DATA`` (robust parsing), which the
  dispatcher drops. :class:`Signing` puts its own ``check_signature`` on the parsers: the same rule
  (SHA-256 over key + frame, the first 6 bytes; per stream ``(link_id, sysid, compid)`` the
  timestamp must grow; a new stream may be at most a minute behind), with two differences from
  pymavlink 2.4's: the stream's timestamp is recorded only for a frame whose signature is valid
  (pymavlink records it before checking, so one forged frame with a high timestamp would lock a
  ground station out), and a refusal is classified (bad signature, replayed) and counted.
* **Accept-list.** Unsigned (or badly signed) frames of :data:`ACCEPT_UNSIGNED` are accepted and
  counted: RADIO_STATUS only, the one message ArduPilot and PX4 both accept unsigned (SiK radios
  inject it and cannot sign).
* **Outgoing.** The core's one :class:`~.codec.Encoder` signs (pymavlink's ``_pack`` signs when
  ``mav.signing.sign_outgoing``), so telemetry, ACKs, PARAM_VALUE, mission messages and STATUSTEXT
  are all signed, as one stream (link id 0); a frame packed once for both links is signed again by
  each link once it has put its own sequence number in (:meth:`.links.GcsLink.send`, the same link id
  and timestamp). The HIL link stays unsigned: its answers come from
  :class:`~.hil.ActuatorEncoder` (a FastEncoder, never signed) and its hello from
  :meth:`~.codec.Encoder.pack_unsigned`.
* **Keys.** From a key file (:func:`read_key_file`: 64 hex digits, or a passphrase hashed as
  MAVProxy's ``signing setup PASSPHRASE`` does), from the state file, or from SETUP_SIGNING
  (accepted only while disarmed, as ArduPilot; an all-zero key with timestamp 0 turns signing off).
* **Timestamps** are MAVLink's: 10 us units since 2015-01-01 00:00 UTC. Two are kept: the one the
  autopilot signs with (:attr:`Signing.timestamp`, +1 per frame sent, as the spec says) and the
  newest time it knows of (:attr:`Signing.reference`: the wall clock the shell injects, the newest
  accepted incoming timestamp, SETUP_SIGNING's ``initial_timestamp``), which the one-minute rule
  for new streams is measured against. They are kept apart because the first runs ahead of time
  on purpose: after a restart it resumes past the stored one, and without a wall clock (in-process)
  it grows by one per frame sent; measured against it, a ground station whose timestamps follow
  the wall clock could be refused.
* **State** (:class:`SigningState`: key, both timestamps, the streams' newest timestamps) is kept in
  a JSON file written atomically (mode 0600), loaded at start: the timestamp the autopilot signs
  with resumes :data:`RESTART_MARGIN` past the stored one (ArduPilot's rule, with its margin
  sized to what can be signed between two saves), so a ground station that stayed connected sees
  it grow; the streams resume where they were, so frames recorded before a restart are refused
  after it. It is saved on every key change, every :data:`SAVE_EVERY_S` while it changes (sooner
  if the timestamp jumps), and when the process stops (:meth:`Signing.save`).

The core reads no clock: the wall clock comes in through :attr:`SigningOptions.epoch_clock` (the
process shell passes ``time.time``; in-process runs pass nothing, or a fake clock, and stay
deterministic).
"""

from __future__ import annotations

import hashlib
import hmac
import json
import os
import re
import tempfile
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

from quadcommon import wire
from quadcommon.mavlink_fast import signature
from quadcommon.schema import ConfigError

from .codec import Encoder
from .codec import mavlink as m
from .dispatch import MessageDispatcher
from .links import Address, GcsLink

EPOCH_2015_S = 1420070400  # 2015-01-01 00:00:00 UTC, MAVLink signing's epoch (s since 1970)
TICKS_PER_S = 100_000  # the timestamp's unit is 10 us
NEW_STREAM_WINDOW = 60 * TICKS_PER_S  # a new stream may be this far behind the reference (the spec's minute)
TIMESTAMP_MAX = (1 << 48) - 1  # six bytes on the wire
SAVE_EVERY_S = 10.0  # the state is saved at most this often while it changes (caller's clock)
# After a restart we sign on from this far past the stored timestamp: twice what can be signed
# between two saves (the wall clock moves SAVE_EVERY_S; frames add one tick each, far less; a
# bigger jump is saved at once, see poll()). ArduPilot: saves every 30 s, resumes 60 s past.
RESTART_MARGIN = int(2 * SAVE_EVERY_S * TICKS_PER_S)
ANNOUNCE_EVERY_S = 10.0  # refusals are summed up in one STATUSTEXT at most this often
MAX_STREAMS = 256  # streams remembered (only frames with a valid signature create one)
LINK_ID = 0  # the link id of everything the autopilot signs (one stream for both GCS links)
STATE_FORMAT = "quadsitl-signing-1"

# Messages accepted without a (valid) signature. RADIO_STATUS: both ArduPilot (with RADIO, 166, of
# its own dialect: not in common) and PX4 (with ADSB_VEHICLE and COLLISION, from traffic receivers,
# which this vehicle has not) accept it; SiK radios inject it and cannot sign.
ACCEPT_UNSIGNED: dict[int, str] = {m.MAVLINK_MSG_ID_RADIO_STATUS: "RADIO_STATUS"}

UNSIGNED, BAD_SIGNATURE, REPLAYED = "unsigned", "bad_signature", "replayed"
_SAID = {UNSIGNED: "unsigned", BAD_SIGNATURE: "badly signed", REPLAYED: "replayed (old timestamp)"}
_HEX_KEY = re.compile(r"[0-9a-fA-F]{64}")


@dataclass(frozen=True)
class SigningOptions:
    """How one autopilot does signing (``python -m autopilot --signing-key FILE --signing-state FILE``).

    ``key_file``: the key at start (:func:`read_key_file`), over whatever the state file holds;
    ``state_file``: where the key and timestamps are kept (None: :func:`default_state_file`);
    ``epoch_clock``: the wall clock in seconds since 1970 (``time.time``), injected by the shell;
    None (in-process runs): the timestamps move only with the state, the frames and SETUP_SIGNING.
    """

    key_file: str | None = None
    state_file: str | None = None
    epoch_clock: Callable[[], float] | None = field(default=None, compare=False)


def passphrase_to_key(passphrase: str) -> bytes:
    """The 32-byte key of ``passphrase``: SHA-256 of its ASCII bytes, as MAVProxy's
    ``signing setup PASSPHRASE`` and ``signing key PASSPHRASE`` derive it."""
    return hashlib.sha256(passphrase.encode("ascii")).digest()


def read_key_file(path: str | Path) -> bytes:
    """The key in ``path``: one line, either 64 hex digits (the key itself) or a passphrase
    (:func:`passphrase_to_key`; ASCII, no whitespace: MAVProxy's console takes one word).
    ConfigError names the file and what is wrong."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(f"{path}: signing key file not found") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"{path}: cannot read the signing key: {exc}") from None
    lines = [line.strip() for line in text.splitlines() if line.strip()]
    if len(lines) != 1:
        raise ConfigError(
            f"{path}: a signing key file holds one line (64 hex digits, or a passphrase), found {len(lines)}"
        )
    line = lines[0]
    if _HEX_KEY.fullmatch(line):
        return bytes.fromhex(line)
    if not line.isascii() or any(c.isspace() for c in line):
        raise ConfigError(
            f"{path}: the passphrase must be one word of ASCII characters (MAVProxy's "
            "'signing setup PASSPHRASE' hashes exactly one such word), or the key as 64 hex digits"
        )
    return passphrase_to_key(line)


def mavlink_timestamp(epoch_s: float) -> int:
    """Seconds since 1970 -> MAVLink signing timestamp (10 us units since 2015-01-01 UTC)."""
    return min(max(int((epoch_s - EPOCH_2015_S) * TICKS_PER_S), 0), TIMESTAMP_MAX)


def default_state_file(options: SigningOptions, params_file: str | None, instance: int) -> Path | None:
    """Where the state lives: ``--signing-state``; else ``signing-<N>.json`` beside ``--params``,
    else beside the key file; else nowhere (in memory: a SETUP_SIGNING key lasts until the process
    stops, the wall clock alone keeps the timestamps fresh)."""
    if options.state_file:
        return Path(options.state_file)
    for beside in (params_file, options.key_file):
        if beside:
            return Path(beside).resolve().parent / f"signing-{instance}.json"
    return None


@dataclass
class SigningState:
    """What persists across restarts (JSON, see :func:`load_state` / :func:`save_state`)."""

    key: bytes | None = None
    timestamp: int = 0  # the newest timestamp the autopilot signed with
    reference: int = 0  # the newest time known (the new-stream rule's reference)
    streams: dict[tuple[int, int, int], int] = field(default_factory=dict)  # (link_id, sys, comp) -> ts
    key_source: str = ""


def _int_in(path: Path, what: str, value: object, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= hi:
        raise ConfigError(f"{path}: key '{what}' = {value!r} is invalid; allowed: an integer in [0, {hi}]")
    return value


def load_state(path: str | Path) -> SigningState | None:
    """The state in ``path``, None if there is no such file; ConfigError names a broken one (a
    start with a broken state file is refused: its replay protection would be gone)."""
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return None
    except (OSError, ValueError) as exc:
        raise ConfigError(f"{path}: not a readable signing state file: {exc}") from None
    if not isinstance(data, dict) or data.get("format") != STATE_FORMAT:
        raise ConfigError(f"{path}: not a signing state file (expected format {STATE_FORMAT!r})")
    key = data.get("key")
    if key is not None and not (isinstance(key, str) and _HEX_KEY.fullmatch(key)):
        raise ConfigError(f"{path}: key 'key' must be 64 hex digits or null")
    streams = {}
    raw_streams = data.get("streams", [])
    if not isinstance(raw_streams, list):
        raise ConfigError(f"{path}: key 'streams' must be a list of [link_id, sysid, compid, timestamp]")
    for entry in raw_streams:
        if not (isinstance(entry, list) and len(entry) == 4):
            raise ConfigError(f"{path}: key 'streams': {entry!r} is not [link_id, sysid, compid, timestamp]")
        link_id, sysid, compid = (_int_in(path, "streams", v, 255) for v in entry[:3])
        streams[(link_id, sysid, compid)] = _int_in(path, "streams", entry[3], TIMESTAMP_MAX)
    return SigningState(
        key=bytes.fromhex(key) if key else None,
        timestamp=_int_in(path, "timestamp", data.get("timestamp", 0), TIMESTAMP_MAX),
        reference=_int_in(path, "reference", data.get("reference", 0), TIMESTAMP_MAX),
        streams=streams,
        key_source=str(data.get("key_source", "")),
    )


def save_state(path: str | Path, state: SigningState) -> None:
    """Write ``state`` to ``path`` atomically (a temporary file in the same directory, fsync'd, then
    renamed over it), readable by the owner only: it holds the key."""
    path = Path(path)
    data = {
        "format": STATE_FORMAT,
        "key": state.key.hex() if state.key is not None else None,
        "key_source": state.key_source,
        "timestamp": state.timestamp,
        "reference": state.reference,
        "streams": [[*stream, ts] for stream, ts in sorted(state.streams.items())],
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as handle:
            os.fchmod(handle.fileno(), 0o600)
            json.dump(data, handle, indent=1)
            handle.write("\n")
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


class Signing:
    """Signing for the GCS links of one autopilot: the key, timestamps, refusals and SETUP_SIGNING.

    ``links`` are the core's :class:`~.links.GcsLink` objects (their parsers are set up here),
    ``encoder`` the core's one encoder (it signs while a key is set), ``statustext(severity, text)``
    the core's announcer, ``armed()`` whether the vehicle is armed (SETUP_SIGNING is refused then).
    """

    def __init__(
        self,
        options: SigningOptions,
        encoder: Encoder,
        links: Sequence[GcsLink],
        statustext: Callable[[int, str], None],
        armed: Callable[[], bool],
        system_id: int,
        log: Callable[[str], None] = lambda text: None,
        params_file: str | None = None,
        instance: int = 0,
    ) -> None:
        self.options = options
        self.encoder = encoder
        self.links = list(links)
        self.statustext = statustext
        self.armed = armed
        self.system_id = system_id
        self.log = log
        self.epoch_clock = options.epoch_clock
        self.state_file = default_state_file(options, params_file, instance)
        self.refused: Counter[str] = Counter()
        self.refused_by_link: dict[str, Counter[str]] = {link.name: Counter() for link in self.links}
        self.accepted_unsigned: Counter[str] = Counter()
        self.setup_signing: Counter[str] = Counter()  # accepted, refused_armed, refused_zero_key
        self.save_errors = 0
        self.key: bytes | None = None
        self.key_source = ""
        self.reference = 0
        self._streams: dict[tuple[int, int, int], int] = {}
        self._pending: dict[int, str | None] = {link.index: None for link in self.links}
        self._unreported: Counter[str] = Counter()  # refusals not yet announced, by kind
        self._setup_notes: Counter[str] = Counter()  # SETUP_SIGNING refusals not yet announced
        self._announced_at: float | None = None
        self._saved_at: float | None = None
        self._saved: tuple | None = None
        for link in self.links:  # pymavlink calls these from decode() once a key is set
            link.parser.check_signature = partial(self._check, link)
            link.parser.signing.allow_unsigned_callback = partial(self._unsigned, link)
        self._start()

    # -- start, key, timestamps --------------------------------------------------------------
    def _start(self) -> None:
        stored = load_state(self.state_file) if self.state_file is not None else None
        if stored is not None:
            self._streams = dict(stored.streams)
            self.reference = stored.reference
            if stored.timestamp:
                self._raise_timestamp(stored.timestamp + RESTART_MARGIN)
        key, source = (stored.key, stored.key_source or "state file") if stored else (None, "")
        if self.options.key_file:
            file_key = read_key_file(self.options.key_file)  # ConfigError: file and reason
            _warn_if_readable(self.options.key_file, self.log)
            if key is not None and key != file_key:
                self.log(f"signing: the key in {self.options.key_file} replaces the stored one")
            key, source = file_key, f"key file {self.options.key_file}"
        self._set_key(key, source)
        self._advance_clock()
        where = f"state in {self.state_file}" if self.state_file else "state in memory only (no file)"
        self.log(f"signing {'on' if key else 'off'}{f' (key from {source})' if key else ''}; {where}; "
                 "SETUP_SIGNING accepted while disarmed")  # fmt: skip
        if key is not None:  # at once: the timestamp resumed past the stored one must be on file
            self.save()

    @property
    def enabled(self) -> bool:
        """True while a key is set: every frame sent on the GCS links is signed, and every frame received must
        be validly signed (but those of :data:`ACCEPT_UNSIGNED`)."""
        return self.key is not None

    @property
    def timestamp(self) -> int:
        """The timestamp the next signed frame carries (pymavlink's ``signing.timestamp`` of the
        encoder, which adds one per frame)."""
        return self.encoder.mav.signing.timestamp

    def _raise_timestamp(self, value: int) -> None:
        """The signing timestamp only ever grows (a ground station tracks our stream)."""
        out = self.encoder.mav.signing
        out.timestamp = min(max(out.timestamp, int(value)), TIMESTAMP_MAX)

    def _set_key(self, key: bytes | None, source: str) -> None:
        self.key, self.key_source = key, source if key is not None else ""
        out = self.encoder.mav.signing
        out.secret_key, out.sign_outgoing, out.link_id = key, key is not None, LINK_ID
        for link in self.links:
            link.parser.signing.secret_key = key  # None: pymavlink accepts every frame, unchecked
        self._raise_timestamp(self.reference)

    def _advance_clock(self) -> None:
        """The reference (and so the signing timestamp) never behind the wall clock, if there is one."""
        if self.epoch_clock is not None:
            self.reference = max(self.reference, mavlink_timestamp(self.epoch_clock()))
            self._raise_timestamp(self.reference)

    # -- incoming frames (called by pymavlink's decode) -----------------------------------------
    def _check(self, link: GcsLink, msgbuf: bytearray, src_system: int, src_component: int) -> bool:
        """A signed frame: its signature valid and its timestamp fresh?"""
        key = self.key
        if key is None:  # not reachable: pymavlink asks only while a key is set
            return False
        expected = signature(key, bytes(msgbuf[:-6]))
        if not hmac.compare_digest(expected, bytes(msgbuf[-6:])):
            self._pending[link.index] = BAD_SIGNATURE
            return False
        timestamp = int.from_bytes(msgbuf[-12:-6], "little")
        stream = (msgbuf[-13], src_system, src_component)
        last = self._streams.get(stream)
        if (timestamp <= last) if last is not None else (timestamp + NEW_STREAM_WINDOW < self.reference):
            self._pending[link.index] = REPLAYED
            return False
        if last is None and len(self._streams) >= MAX_STREAMS:
            del self._streams[min(self._streams, key=self._streams.__getitem__)]  # the stalest one
        self._streams[stream] = timestamp
        self.reference = max(self.reference, timestamp)
        self._raise_timestamp(timestamp)  # the spec: we send on from the newest timestamp seen
        return True

    def _unsigned(self, link: GcsLink, mav, msg_id: int) -> bool:
        """A frame without a valid signature: accepted only if it is on the accept-list."""
        reason = self._pending[link.index] or UNSIGNED
        self._pending[link.index] = None
        name = ACCEPT_UNSIGNED.get(msg_id)
        if name is not None:
            self.accepted_unsigned[name] += 1
            return True
        self.refused[reason] += 1
        self.refused_by_link[link.name][reason] += 1
        self._unreported[reason] += 1
        return False

    # -- SETUP_SIGNING ----------------------------------------------------------------------------
    def register(self, dispatcher: MessageDispatcher) -> None:
        """Handle SETUP_SIGNING."""
        dispatcher[m.MAVLINK_MSG_ID_SETUP_SIGNING] = self.on_setup_signing

    def on_setup_signing(self, msg, link: GcsLink, address: Address) -> None:
        """SETUP_SIGNING (256): a new key and initial timestamp, or (all-zero key, timestamp 0)
        signing off; only while disarmed. With signing on it arrives signed (it is not on the
        accept-list), so only a holder of the current key can change it."""
        if msg.target_system not in (0, self.system_id) or msg.target_component not in (
            0, wire.AUTOPILOT_COMPONENT_ID,
        ):  # fmt: skip
            return
        if self.armed():
            self.setup_signing["refused_armed"] += 1
            self._setup_notes["SETUP_SIGNING refused: the vehicle is armed (disarm first)"] += 1
            return
        key = bytes(msg.secret_key)
        if not any(key):
            if msg.initial_timestamp != 0:
                self.setup_signing["refused_zero_key"] += 1
                self._setup_notes["SETUP_SIGNING refused: all-zero key (with timestamp 0: signing off)"] += 1
                return
            self.setup_signing["accepted"] += 1
            if self.enabled:
                self._set_key(None, "")
                self.save()
                self.statustext(m.MAV_SEVERITY_NOTICE, "signing off (SETUP_SIGNING)")
            return
        self.setup_signing["accepted"] += 1
        # The reference becomes initial_timestamp, as ArduPilot and PX4 take it (so a reference
        # pushed too far ahead can be brought back); the timestamp we sign with never goes back.
        self.reference = min(int(msg.initial_timestamp), TIMESTAMP_MAX)
        self._set_key(key, "SETUP_SIGNING")
        self._advance_clock()
        self.save()
        self.statustext(m.MAV_SEVERITY_NOTICE, "signing on: key set by SETUP_SIGNING")

    # -- housekeeping -------------------------------------------------------------------------------
    def poll(self, now: float) -> None:
        """Every housekeeping tick (``now``: the caller's clock, s): follow the wall clock, sum up the
        refusals in one rate-limited STATUSTEXT, save the state while it changes."""
        self._advance_clock()
        due = self._announced_at is None or now - self._announced_at >= ANNOUNCE_EVERY_S
        if (self._unreported or self._setup_notes) and due:
            self._announced_at = now
            if self._unreported:
                parts = ", ".join(f"{self._unreported[k]} {_SAID[k]}" for k in _SAID if self._unreported[k])
                self.statustext(m.MAV_SEVERITY_WARNING, f"signing: refused {parts} message(s)")
            for text, n in self._setup_notes.items():
                self.statustext(m.MAV_SEVERITY_WARNING, text if n == 1 else f"{text} ({n}x)")
            self._unreported.clear()
            self._setup_notes.clear()
        if not self.enabled:
            return
        jumped = self._saved is None or self.timestamp - self._saved[1] >= RESTART_MARGIN // 2
        if jumped or self._saved_at is None or now - self._saved_at >= SAVE_EVERY_S:
            self._saved_at = now
            if self._snapshot() != self._saved:
                self.save()

    def _snapshot(self) -> tuple:
        return (self.key, self.timestamp, self.reference, tuple(sorted(self._streams.items())))

    def state(self) -> SigningState:
        """What :meth:`save` writes."""
        return SigningState(self.key, self.timestamp, self.reference, dict(self._streams), self.key_source)

    def save(self) -> bool:
        """Write the state file now (the process shell calls this when it stops); False if there is
        no file or writing failed (logged, counted: the vehicle goes on)."""
        if self.state_file is None:
            return False
        snapshot = self._snapshot()
        try:
            save_state(self.state_file, self.state())
        except OSError as exc:
            self.save_errors += 1
            if self.save_errors == 1:
                self.log(f"signing: cannot save the state to {self.state_file}: {exc}")
            return False
        self._saved = snapshot
        return True

    def info(self) -> dict:
        """Counters and state for ``quadsitl/<N>/autopilot/info`` (never the key)."""
        return {
            "enabled": self.enabled,
            "key_source": self.key_source,
            "state_file": str(self.state_file) if self.state_file else None,
            "timestamp": self.timestamp,
            "refused": {kind: self.refused[kind] for kind in (UNSIGNED, BAD_SIGNATURE, REPLAYED)},
            "refused_by_link": {name: dict(c) for name, c in self.refused_by_link.items()},
            "accepted_unsigned": dict(self.accepted_unsigned),
            "setup_signing": dict(self.setup_signing),
            "streams": len(self._streams),
            "save_errors": self.save_errors,
        }


def _warn_if_readable(path: str, log: Callable[[str], None]) -> None:
    try:
        mode = os.stat(path).st_mode
    except OSError:
        return
    if mode & 0o077:
        log(f"signing: warning: {path} is readable by others (chmod 600 it)")
