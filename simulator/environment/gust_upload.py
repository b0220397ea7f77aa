"""Gust-profile uploads: the request/reply protocol and its pure handling (no zenoh here).

Protocol (``quadsitl/<N>/sim/gusts``, a zenoh queryable declared by the simulator of vehicle N;
the client is ``gcs_scripts/upload_gusts.py``):

* the getter sends ONE query whose payload is a UTF-8 JSON object::

      {"profile": <profile object>,
       "start": {"at_s": <simulation time, s>} | {"after_s": <delay from now, s>} | "now",
       "mode": "replace"}

  ``profile`` has the schema of a ``config/gusts/*.toml`` file (:mod:`.gust_profile`: ``step``,
  ``ramp``, ``one_minus_cosine`` arrays, a ``dryden`` object, ``description``). ``start``
  defaults to ``"now"``; ``at_s`` may lie in the simulator's past only as far as the
  profile's first event still lies in its future (a script anchors a profile on an instant it
  has observed). ``mode`` is optional
  and ``"replace"`` is its only value (see below). Unknown keys are refused;
* the simulator validates it and answers exactly one reply:

  - accepted: ``query.reply(key, {"accepted": true, "start_s": <absolute simulation time, s>,
    "summary": "<one-line description>"})``;
  - rejected: ``query.reply_err({"accepted": false, "error": "<validation message>"})``, the
    message naming the source ("gust upload"), the key (e.g. ``profile.dryden.w20_m_s``), the
    value and the allowed range, exactly as for configuration files.

Semantics: REPLACE. An accepted profile replaces the active one, whatever it is: the profile
of the previous upload or the scenario's start-up profile (e.g. the paper's steps). The
simulator swaps the schedule at the next frame boundary after answering; from then on only the
uploaded elements act, their times counted from ``start_s`` (nothing acts between the swap and
``start_s``). When several uploads arrive, the last accepted one wins. There is no "add" mode:
to combine disturbances, upload one profile holding all the elements (values of elements add
up), e.g. the paper's steps plus a gust. An empty profile (``{}``) removes every disturbance.

Determinism: the result depends only on the profile, the start time and the physics step (the
Dryden turbulence is seeded and indexed by physics step from its start).

The simulator's side (``simulator.truth_bus.GustUploadServer``) declares the queryable with a
FIFO channel, polls it from the main loop, answers with ``handle_gust_request`` inside
``with query:`` and swaps the schedule at the next frame boundary.
"""

from __future__ import annotations

import json
import math
from typing import Any, NamedTuple

from quadcommon.schema import ConfigError, Section

from .dryden import check_step
from .gust_profile import DEFAULT_STEP_S, GustProfile, describe, parse_gust_profile

SOURCE = "gust upload"
MAX_PAYLOAD_BYTES = 1 << 20  # 1 MiB: far above any sensible profile (256 elements per kind)
MAX_DELAY_S = 1e6
MODES = ("replace",)


class GustRequestResult(NamedTuple):
    """What the simulator does with one request: reply with ``reply`` (``query.reply`` when
    ``ok``, ``query.reply_err`` otherwise) and, when ``ok``, install ``profile`` at ``start_s``."""

    ok: bool
    reply: bytes
    profile: GustProfile | None
    start_s: float | None


def _reject(message: str) -> GustRequestResult:
    return GustRequestResult(False, json.dumps({"accepted": False, "error": message}).encode(), None, None)


def parse_gust_request(
    payload: bytes, now_s: float, step_s: float = DEFAULT_STEP_S
) -> tuple[GustProfile, float]:
    """Validate an upload request; returns ``(profile, absolute start time in s)``.

    Raises :class:`~quadcommon.schema.ConfigError` with a message naming source, key, value and
    the allowed range. ``step_s`` is the simulator's physics step (checked against the Dryden
    time constants).
    """
    if len(payload) > MAX_PAYLOAD_BYTES:
        raise ConfigError(
            f"{SOURCE}: payload of {len(payload)} bytes; allowed: at most {MAX_PAYLOAD_BYTES} bytes"
        )
    try:
        data: Any = json.loads(payload)
    except (UnicodeDecodeError, ValueError) as exc:
        raise ConfigError(f"{SOURCE}: payload is not valid UTF-8 JSON: {exc}") from None
    if not isinstance(data, dict):
        raise ConfigError(
            f'{SOURCE}: the request must be a JSON object {{"profile": {{...}}, "start": ...}}, '
            f"got {type(data).__name__}"
        )
    root = Section(data, SOURCE)
    profile = parse_gust_profile(root.section("profile"))
    if isinstance(root.data.get("start", "now"), str):
        root.choice("start", ("now",), "now")
        start_s = now_s
    else:
        start = root.section("start")  # refuses anything but an object
        if start.has("at_s") == start.has("after_s"):
            raise ConfigError(
                f"{SOURCE}: key 'start' = {root.data['start']!r} is invalid; allowed: \"now\", "
                '{"at_s": <simulation time, s>} or {"after_s": <delay, s>} (exactly one key)'
            )
        if start.has("at_s"):
            start_s = start.number("at_s", lo=0.0, hi=now_s + MAX_DELAY_S, unit="s, simulation time")
            first_event = min(profile.event_times(), default=0.0)
            if start_s + first_event < now_s:
                # A start in the past is fine (a script anchors the profile on an instant it has
                # just observed) as long as nothing of the profile would have happened already.
                raise start.error(
                    "at_s",
                    start_s,
                    f">= {now_s - first_event:.6f} s: the profile's first event ({first_event:g} s after "
                    f'at_s) would lie before the simulation time now, {now_s:.6f} s (use "now" or after_s)',
                )
        else:
            start_s = now_s + start.number("after_s", lo=0.0, hi=MAX_DELAY_S, unit="s")
        start.finish()
    mode = root.string("mode", "replace")
    if mode not in MODES:
        raise root.error(
            "mode",
            mode,
            "'replace' (an upload replaces the active profile; to combine disturbances, put all "
            "the elements in one profile: they add up)",
        )
    root.finish()
    if profile.dryden is not None:
        try:
            check_step(profile.dryden, step_s)
        except ValueError as exc:
            raise ConfigError(f"{SOURCE}: key 'profile.dryden': {exc}") from None
    return profile, start_s


def handle_gust_request(payload: bytes, now_s: float, step_s: float = DEFAULT_STEP_S) -> GustRequestResult:
    """Handle one upload request received at simulation time ``now_s`` (s). Pure, never raises
    on bad input: a rejection is a result with ``ok`` False and the error in ``reply``.

    Unpacks as ``ok, reply, profile, start_s = handle_gust_request(payload, now_s)``.
    """
    if not math.isfinite(now_s):
        raise ValueError(f"now_s must be a finite simulation time, got {now_s!r}")
    try:
        profile, start_s = parse_gust_request(payload, now_s, step_s)
    except ConfigError as exc:
        return _reject(str(exc))
    reply = {"accepted": True, "start_s": start_s, "summary": describe(profile)}
    return GustRequestResult(True, json.dumps(reply).encode(), profile, start_s)
