"""Upload a gust profile to a running simulator over zenoh (``quadsitl/<N>/sim/gusts``).

    quadsitl gusts upload NAME|FILE.toml|FILE.json [--instance N]
        [--start-at S | --start-after S | --now] [--timeout 3] [--router ENDPOINT]
    (or python gcs_scripts/upload_gusts.py ... from a checkout)

A NAME is a shipped profile (``config/gusts/NAME.toml``) or one in your configuration directory
(``--config-dir``, ``QUADSITL_CONFIG_DIR``). The file holds a gust profile in the schema of
``config/gusts/*.toml`` (TOML, or the same structure as a JSON object). It is only parsed here:
the simulator validates it and is the authority. Start: ``--start-at S`` at simulation time S
(s; not in the simulator's past), ``--start-after S`` S seconds of simulation time after the
simulator receives it, ``--now`` (default). The uploaded profile REPLACES the active one (the
previous upload, or the scenario's start-up profile such as the paper's steps); to combine
disturbances put all elements in
one file. Protocol: :mod:`simulator.environment.gust_upload`.

Exit status: 0 accepted (prints the start time and the simulator's summary); 1 rejected (prints
the simulator's exact validation message), also for an unreadable file or bad arguments;
2 no simulator answered within --timeout (the message names the zenoh key and port).

From another script: ``upload_gusts(profile_mapping, instance, start, timeout)`` returns the
simulator's answer as a dict, and raises :class:`NoSimulatorAnswer` when nobody answers.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import tomllib
from pathlib import Path
from typing import Any

# Allow ``python gcs_scripts/upload_gusts.py`` from a checkout without installing.
if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import zenoh  # noqa: E402

from quadcommon import bus, wire  # noqa: E402
from quadcommon.cli_help import HelpFormatter  # noqa: E402

DEFAULT_TIMEOUT_S = 3.0
RETRY_PERIOD_S = 0.05  # a get that finds no queryable ends at once: try again until the deadline
Start = str | dict[str, float]


class NoSimulatorAnswer(TimeoutError):
    """No simulator answered the upload within the timeout (the message says where we asked)."""


class ProfileFileError(ValueError):
    """The profile file cannot be read or parsed."""


def profile_path(text: str | Path) -> Path:
    """A file as given, or a gust profile's name looked up in the configuration directories."""
    path = Path(text)
    if path.exists() or path.suffix or len(path.parts) > 1:
        return path
    from quadcommon.config import config_path
    from quadcommon.schema import ConfigError

    try:
        return config_path("gusts", str(text))
    except ConfigError as exc:
        raise ProfileFileError(str(exc)) from None


def load_profile_file(path: str | Path) -> dict[str, Any]:
    """Parse ``path`` (``.toml``, else JSON) into a mapping; no schema validation here."""
    path = Path(path)
    try:
        raw = path.read_bytes()
    except OSError as exc:
        raise ProfileFileError(f"{path}: cannot read: {exc.strerror or exc}") from None
    try:
        if path.suffix.lower() == ".toml":
            data: Any = tomllib.loads(raw.decode("utf-8"))
        else:
            data = json.loads(raw)
    except (UnicodeDecodeError, ValueError) as exc:  # TOMLDecodeError and JSONDecodeError are ValueErrors
        kind = "TOML" if path.suffix.lower() == ".toml" else "JSON"
        raise ProfileFileError(f"{path}: not valid {kind}: {exc}") from None
    if not isinstance(data, dict):
        raise ProfileFileError(f"{path}: a gust profile must be a table/object, got {type(data).__name__}")
    return data


def start_spec(at_s: float | None = None, after_s: float | None = None) -> Start:
    """The request's ``start``: ``{"at_s": S}``, ``{"after_s": S}`` or ``"now"``."""
    if at_s is not None and after_s is not None:
        raise ValueError("give at most one of at_s and after_s")
    if at_s is not None:
        return {"at_s": float(at_s)}
    if after_s is not None:
        return {"after_s": float(after_s)}
    return "now"


def build_request(profile_mapping: dict[str, Any], start: Start = "now") -> bytes:
    """The query payload (UTF-8 JSON). Raises ProfileFileError if the profile is not JSON-able
    (e.g. a TOML date)."""
    try:
        return json.dumps({"profile": profile_mapping, "start": start}).encode()
    except (TypeError, ValueError) as exc:
        raise ProfileFileError(f"the profile cannot be sent as JSON: {exc}") from None


def _decode_answer(body: bytes) -> dict[str, Any] | None:
    """The simulator's answer, or None for anything else (zenoh's own b"Timeout" error reply)."""
    try:
        answer = json.loads(body)
    except (UnicodeDecodeError, ValueError):
        return None
    if isinstance(answer, dict) and isinstance(answer.get("accepted"), bool):
        return answer
    return None


def query_simulator(session: zenoh.Session, key: str, payload: bytes, timeout_s: float, where: str) -> dict:
    """Send the upload on ``key`` and return the simulator's answer; retries while no
    queryable is reachable (a fresh session may not have met the simulator's yet)."""
    deadline = time.monotonic() + timeout_s
    attempts = 0
    while attempts < 100_000:  # bounded; the deadline ends it long before
        attempts += 1
        remaining = deadline - time.monotonic()
        if remaining <= 0.0:
            break
        for reply in session.get(key, payload=payload, timeout=remaining):
            body = reply.ok.payload.to_bytes() if reply.ok is not None else reply.err.payload.to_bytes()
            answer = _decode_answer(body)
            if answer is not None:
                return answer
            # The query reached a queryable that did not answer in time. Do not send it again:
            # a slow simulator may still apply the first one.
            raise NoSimulatorAnswer(
                f"no answer on {where} within {timeout_s:g} s (zenoh said {body[:80]!r}); the simulator "
                "received the upload but did not reply in time: it may still apply it"
            )
        time.sleep(min(RETRY_PERIOD_S, max(deadline - time.monotonic(), 0.0)))
    raise NoSimulatorAnswer(
        f"no simulator answered on {where} within {timeout_s:g} s; is the simulator of that instance "
        "running (quadsitl up --instance N) with zenoh enabled?"
    )


def upload_gusts(
    profile_mapping: dict[str, Any],
    instance: int = 0,
    start: Start = "now",
    timeout: float = DEFAULT_TIMEOUT_S,
    *,
    session: zenoh.Session | None = None,
    router: str = "",
) -> dict[str, Any]:
    """Upload ``profile_mapping`` to the simulator of vehicle ``instance``; return its answer.

    ``start``: ``"now"``, ``{"at_s": S}`` (simulation time, s) or ``{"after_s": S}`` (s; see
    :func:`start_spec`). ``timeout`` in seconds of wall-clock time. ``session``: an open zenoh
    session to reuse (else one is opened with :func:`quadcommon.bus.open_peer` and closed).

    Returns ``{"accepted": True, "start_s": ..., "summary": ...}`` or
    ``{"accepted": False, "error": ...}``; raises :class:`NoSimulatorAnswer` when nobody answers
    and :class:`quadcommon.bus.BusError` when no session can be opened.
    """
    key = wire.zenoh_key(instance, "sim/gusts")
    from quadcommon.config import load_sitl

    port = load_sitl().ports(instance).zenoh  # sitl.toml's [ports] zenoh_base + N
    where = f"zenoh key '{key}' (" + (f"router {router})" if router else f"hub tcp/{wire.LOOPBACK}:{port})")
    payload = build_request(profile_mapping, start)
    own = session is None
    if session is None:
        session = bus.open_peer(port, router)
    try:
        return query_simulator(session, key, payload, timeout, where)
    finally:
        if own:
            session.close()


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> None:  # type: ignore[override]
        # Exit 1, not argparse's 2: 2 means "no simulator answered" for this script.
        self.print_usage(sys.stderr)
        self.exit(1, f"{self.prog}: error: {message}\n")


def build_parser(prog: str = "upload_gusts.py") -> argparse.ArgumentParser:
    """The ``upload_gusts.py`` command line (profile, instance, start time, timeout, router)."""
    parser = _Parser(
        prog=prog, description=__doc__, formatter_class=HelpFormatter
    )
    parser.add_argument("file", help="gust profile: a name (config/gusts, or yours) or a .toml/.json file")
    parser.add_argument("--instance", type=int, default=0, help="vehicle instance N (ports +N), default 0")
    when = parser.add_mutually_exclusive_group()
    when.add_argument("--start-at", type=float, metavar="S", help="start at simulation time S (s)")
    when.add_argument("--start-after", type=float, metavar="S", help="start S seconds after receipt")
    when.add_argument("--now", action="store_true", help="start at once (default)")
    parser.add_argument(
        "--timeout", type=float, default=DEFAULT_TIMEOUT_S, help="seconds to wait for the answer (default 3)"
    )
    parser.add_argument(
        "--router", default="", help="zenoh router endpoint (multi-host runs), e.g. tcp/host:7447"
    )
    return parser


def main(argv: list[str] | None = None, prog: str = "upload_gusts.py") -> int:
    """Upload a gust profile to vehicle N's simulator and print its answer; 0 when accepted, 1 for a
    bad profile or argument or a refusal, 2 when the simulator does not answer."""
    args = build_parser(prog).parse_args(argv)
    try:
        wire.ports(args.instance)
        if not args.timeout > 0.0:
            raise ValueError(f"--timeout must be > 0 s, got {args.timeout:g}")
        profile = load_profile_file(profile_path(args.file))
        start = start_spec(args.start_at, args.start_after)
        answer = upload_gusts(profile, args.instance, start, args.timeout, router=args.router)
    except (ProfileFileError, ValueError) as exc:
        print(f"upload_gusts: {exc}", file=sys.stderr)
        return 1
    except (NoSimulatorAnswer, bus.BusError) as exc:
        print(f"upload_gusts: {exc}", file=sys.stderr)
        return 2
    if answer["accepted"]:
        start_s = answer.get("start_s")
        when = f"t = {start_s:.3f} s" if isinstance(start_s, int | float) else "an unknown time"
        print(f"accepted: starts at {when} (simulation time): {answer.get('summary', '')}")
        return 0
    print(f"rejected: {answer.get('error', '(no message)')}", file=sys.stderr)
    return 1


if __name__ == "__main__":
    sys.exit(main())
