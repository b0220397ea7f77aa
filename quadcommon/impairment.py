"""Link impairment: loss, delay, jitter, duplication and reordering of datagrams, seeded.

The machines this runs on have no netem, so the faults of a real link are built in. One
:class:`ImpairedChannel` is one direction of one link; it decides, for each datagram and the time it
is sent, whether it is dropped, whether a second copy goes too, and when each copy arrives. It owns
no socket and reads no clock: time comes in as an argument, so the same model runs at the socket
edge of the two processes (wall time, :mod:`quadcommon.impaired_udp`) and in the in-process runner
(simulation time, :mod:`sitl.inprocess`).

Semantics of one :class:`Impairment` (the spec ``loss=5%,delay=50ms,jitter=20ms,dup=1%,reorder=1%``):

* ``loss``: each datagram is dropped with this probability (no copy of it arrives);
* ``dup``: a datagram that is not dropped is delivered twice with this probability, each copy with a
  delay of its own;
* ``delay`` and ``jitter``: each copy arrives ``delay + jitter * u`` after it was sent, ``u``
  uniform in [-1, 1], never before it was sent (as netem's ``delay D J``; copies closer together
  than the jitter may swap);
* ``reorder``: a datagram is held back :data:`REORDER_HOLD_S` beyond its delay with this
  probability, so the datagrams sent in that time overtake it.

Each datagram draws the same five numbers from the channel's generator whatever is decided, so the
n-th datagram of a channel meets the same fate for a given seed. The seed of a channel is derived
from the configuration's seed and the channel's name (``"hil sim->ap"``, ``"gcs in"`` ...): the two
directions of a link, and the links, are independent.
"""

from __future__ import annotations

import heapq
import random
import zlib
from dataclasses import dataclass, field, fields, replace
from typing import Any

from .schema import ConfigError

LINKS = ("hil", "gcs", "api")
REORDER_HOLD_S = 0.05  # a reordered datagram arrives this much later than its delay says
MAX_DELAY_S = 10.0  # delay and jitter: at most this (s)
_PERCENT_KEYS = {"loss": "loss", "dup": "duplicate", "reorder": "reorder"}
_TIME_KEYS = {"delay": "delay_s", "jitter": "jitter_s"}
_TIME_UNITS = {"ms": 1e-3, "us": 1e-6, "s": 1.0}


class ImpairmentError(ConfigError):
    """An impairment spec is invalid; the message names the value, its unit and the range."""


@dataclass(frozen=True)
class Impairment:
    """What one link does to each datagram (probabilities as fractions, times in s)."""

    loss: float = 0.0
    delay_s: float = 0.0
    jitter_s: float = 0.0
    duplicate: float = 0.0
    reorder: float = 0.0

    @property
    def active(self) -> bool:
        """Whether any impairment is set (a field not zero)."""
        return any(getattr(self, f.name) != 0.0 for f in fields(self))

    @property
    def latest_s(self) -> float:
        """The longest a copy can take to arrive (s), reordering aside."""
        return self.delay_s + self.jitter_s

    def describe(self) -> str:
        """The spec that parses back to this (``"none"`` when it does nothing)."""
        parts = [f"{key}={100.0 * getattr(self, name):g}%" for key, name in _PERCENT_KEYS.items()
                 if getattr(self, name)]  # fmt: skip
        parts += [f"{key}={1e3 * getattr(self, name):g}ms" for key, name in _TIME_KEYS.items()
                  if getattr(self, name)]  # fmt: skip
        return ",".join(parts) or "none"


NO_IMPAIRMENT = Impairment()


def parse_impairment(text: str, where: str = "impairment") -> Impairment:
    """``loss=5%,delay=50ms,jitter=20ms,dup=1%,reorder=1%`` (any subset, any order; ``""`` or
    ``none``: nothing). Percentages take ``%``, in [0, 100]; times take ``ms``, ``us`` or ``s``, in
    [0, 10 s]. ``where`` starts every error message (the option or file and key)."""
    text = text.strip()
    if text in ("", "none"):
        return NO_IMPAIRMENT
    values: dict[str, float] = {}
    for part in text.split(","):
        key, sep, raw = part.strip().partition("=")
        key, raw = key.strip(), raw.strip()
        if not sep or not raw:
            raise ImpairmentError(f"{where}: {part.strip()!r} is not KEY=VALUE (e.g. loss=5%)")
        if key in _PERCENT_KEYS:
            if not raw.endswith("%"):
                raise ImpairmentError(f"{where}: {key}={raw}: give a percentage with '%', e.g. {key}=1%")
            value = _number(raw[:-1], where, key, raw)
            if not 0.0 <= value <= 100.0:
                raise ImpairmentError(f"{where}: {key}={raw} is out of range; allowed: 0 % to 100 %")
            values[_PERCENT_KEYS[key]] = value / 100.0
        elif key in _TIME_KEYS:
            unit = next((u for u in ("ms", "us", "s") if raw.endswith(u)), None)
            if unit is None:
                raise ImpairmentError(f"{where}: {key}={raw}: give a time with its unit (ms, us or s), "
                                      f"e.g. {key}=50ms")  # fmt: skip
            seconds = _number(raw[: -len(unit)], where, key, raw) * _TIME_UNITS[unit]
            if not 0.0 <= seconds <= MAX_DELAY_S:
                raise ImpairmentError(f"{where}: {key}={raw} is out of range; allowed: 0 ms to "
                                      f"{MAX_DELAY_S * 1e3:g} ms")  # fmt: skip
            values[_TIME_KEYS[key]] = seconds
        else:
            known = ", ".join([*_PERCENT_KEYS, *_TIME_KEYS])
            raise ImpairmentError(f"{where}: unknown key {key!r}; known: {known}")
    return Impairment(**values)


def _number(text: str, where: str, key: str, raw: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if value != value or value in (float("inf"), float("-inf")):
        raise ImpairmentError(f"{where}: {key}={raw} is not a number")
    return value


def parse_link_spec(text: str, where: str = "--impair") -> tuple[str, Impairment]:
    """``LINK:SPEC`` with LINK one of hil, gcs, api (``hil:loss=1%``)."""
    link, sep, spec = text.partition(":")
    link = link.strip()
    if not sep or link not in LINKS:
        raise ImpairmentError(f"{where} {text!r}: give LINK:SPEC with LINK one of {', '.join(LINKS)} "
                              "(e.g. hil:loss=1%)")  # fmt: skip
    return link, parse_impairment(spec, f"{where} {link}")


@dataclass(frozen=True)
class ImpairConfig:
    """The impairment of each link (``[impair]`` of sitl.toml, ``--impair``) and the seed."""

    seed: int = 0
    hil: Impairment = NO_IMPAIRMENT
    gcs: Impairment = NO_IMPAIRMENT
    api: Impairment = NO_IMPAIRMENT

    @property
    def active(self) -> bool:
        """Whether any of the links (HIL, GCS, API) is impaired."""
        return self.hil.active or self.gcs.active or self.api.active

    def of(self, link: str) -> Impairment:
        """The impairment of ``link`` (``hil``, ``gcs`` or ``api``)."""
        return getattr(self, link)

    def with_specs(self, specs: list[str] | tuple[str, ...], where: str = "--impair") -> ImpairConfig:
        """These ``LINK:SPEC`` replace the links they name (a later one wins)."""
        changed = dict(parse_link_spec(text, where) for text in specs)
        return replace(self, **changed)

    def channel(self, link: str, direction: str) -> ImpairedChannel | None:
        """The channel of ``link`` in ``direction`` (a name: "sim->ap", "in", "out" ...), or None
        when the link is not impaired (the caller takes its direct path)."""
        impairment = self.of(link)
        name = f"{link} {direction}"
        return ImpairedChannel(impairment, channel_seed(self.seed, name), name) if impairment.active else None

    def describe(self) -> str:
        """``hil: loss=1%; gcs: delay=50ms`` (``none`` when every link is perfect)."""
        text = "; ".join(f"{link}: {self.of(link).describe()}" for link in LINKS if self.of(link).active)
        return text or "none"


def channel_seed(seed: int, name: str) -> int:
    """A channel's seed: the configuration's and the channel's name (stable across processes)."""
    return (seed * 1_000_003 + zlib.crc32(name.encode())) & 0xFFFFFFFF


@dataclass
class ChannelCounts:
    """What a channel did so far (datagrams)."""

    sent: int = 0  # handed to the channel
    dropped: int = 0
    duplicated: int = 0  # second copies
    delayed: int = 0  # copies that arrived later than they were sent
    reordered: int = 0  # held back by REORDER_HOLD_S
    delivered: int = 0  # copies handed out by due()


@dataclass
class ImpairedChannel:
    """One direction of an impaired link: :meth:`send` items in, :meth:`due` them out when their
    time has come. Items are anything (bytes, an address and bytes ...), handed out as they went in;
    a duplicated item is handed out twice. Items due at the same time leave in the order sent."""

    impairment: Impairment
    seed: int
    name: str = "link"
    counts: ChannelCounts = field(default_factory=ChannelCounts)

    def __post_init__(self) -> None:
        self._random = random.Random(self.seed)
        self._queue: list[tuple[float, int, Any]] = []  # (arrival, order, item): a heap
        self._order = 0

    def set(self, impairment: Impairment) -> None:
        """Change what the link does from now on (the generator runs on; queued copies stay)."""
        self.impairment = impairment

    def send(self, item: Any, now: float) -> int:
        """``item`` sent at ``now``; returns how many copies will arrive (0, 1 or 2)."""
        imp, draw, counts = self.impairment, self._random.random, self.counts
        u_loss, u_dup, u_reorder, u_first, u_second = draw(), draw(), draw(), draw(), draw()
        counts.sent += 1
        if u_loss < imp.loss:
            counts.dropped += 1
            return 0
        hold = 0.0
        if u_reorder < imp.reorder:
            counts.reordered += 1
            hold = REORDER_HOLD_S
        self._queue_copy(item, now, imp, u_first, hold)
        if u_dup < imp.duplicate:
            counts.duplicated += 1
            self._queue_copy(item, now, imp, u_second, 0.0)
            return 2
        return 1

    def _queue_copy(self, item: Any, now: float, imp: Impairment, u: float, hold: float) -> None:
        delay = max(imp.delay_s + imp.jitter_s * (2.0 * u - 1.0), 0.0) + hold
        if delay > 0.0:
            self.counts.delayed += 1
        self._order += 1
        heapq.heappush(self._queue, (now + delay, self._order, item))

    def due(self, now: float) -> list[Any]:
        """The items whose arrival time is ``now`` or earlier, in order of arrival."""
        queue = self._queue
        out = []
        while queue and queue[0][0] <= now:
            out.append(heapq.heappop(queue)[2])
        self.counts.delivered += len(out)
        return out

    def next_due(self) -> float | None:
        """When the next queued item arrives, or None if none is queued."""
        return self._queue[0][0] if self._queue else None

    def pending(self) -> int:
        """How many datagrams the channel holds."""
        return len(self._queue)

    def info(self) -> dict[str, Any]:
        """For a process's ``info``: the impairment and the counts."""
        c = self.counts
        return {
            "impairment": self.impairment.describe(), "sent": c.sent, "dropped": c.dropped,
            "duplicated": c.duplicated, "delayed": c.delayed, "reordered": c.reordered,
            "delivered": c.delivered, "queued": len(self._queue),
        }  # fmt: skip
