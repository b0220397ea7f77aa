"""Change a running vehicle's link impairment: ``quadsitl impair [--instance N] LINK:SPEC ...``.

Both processes of vehicle N answer ``quadsitl/<N>/impair`` on zenoh (payload: the specs, e.g.
``api:loss=100%``; ``api:none`` restores the link): the autopilot applies it to its ends of the
GCS, API and HIL links, the simulator to its end of the HIL link. This asks until both have
answered (a fresh zenoh session may not have met them yet) and prints what each link does now.
Syntax and semantics: docs/links.md.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any

from quadcommon import bus, wire
from quadcommon.config import load_sitl
from quadcommon.impairment import ImpairConfig, ImpairmentError

PROCESSES = ("autopilot", "simulator")
RETRY_PERIOD_S = 0.2


class NoAnswer(RuntimeError):
    """A process of the vehicle did not answer in time."""


def change_impairment(
    specs: list[str], instance: int = 0, timeout_s: float = 10.0, *, session: Any = None, router: str = ""
) -> dict[str, dict[str, Any]]:
    """Send ``specs`` to both processes of vehicle ``instance``; their answers by process.
    Raises ImpairmentError for a bad spec (before sending), NoAnswer if a process stays silent."""
    ImpairConfig().with_specs(specs, "impair")  # refused here, naming the value, before anything is sent
    payload = " ".join(specs).encode()
    import zenoh

    own = session is None
    if own:
        session = bus.open_peer(load_sitl().ports(instance).zenoh, router)
    key = wire.zenoh_key(instance, "impair")
    answers: dict[str, dict[str, Any]] = {}
    deadline = time.monotonic() + timeout_s
    try:
        while len(answers) < len(PROCESSES) and time.monotonic() < deadline:
            # Both processes answer on the same key: no consolidation, or zenoh keeps one reply
            replies = session.get(key, payload=payload, timeout=max(deadline - time.monotonic(), 0.1),
                                  consolidation=zenoh.ConsolidationMode.NONE)  # fmt: skip
            for reply in replies:
                body = reply.ok.payload.to_bytes() if reply.ok is not None else reply.err.payload.to_bytes()
                try:
                    answer = json.loads(body)
                except (UnicodeDecodeError, ValueError):
                    continue
                if isinstance(answer, dict) and answer.get("process") in PROCESSES:
                    answers[answer["process"]] = answer
            if len(answers) < len(PROCESSES):
                time.sleep(RETRY_PERIOD_S)  # a change applied twice is the same change
    finally:
        if own:
            session.close()
    missing = [p for p in PROCESSES if p not in answers]
    if missing:
        raise NoAnswer(f"no answer from the {' and '.join(missing)} of vehicle {instance} on {key} within "
                       f"{timeout_s:g} s; is it running (quadsitl up --instance {instance})?")  # fmt: skip
    return answers


def main(argv: list[str] | None = None, prog: str = "quadsitl impair") -> int:
    """``quadsitl impair``: send the ``LINK:SPEC`` impairments to both processes of the vehicle and
    print their answers; 0 when both accept, 1 when one does not answer in ``--timeout`` wall
    seconds, 2 for a bad spec or a refusal."""
    parser = argparse.ArgumentParser(prog=prog, description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)  # fmt: skip
    parser.add_argument("specs", nargs="+", metavar="LINK:SPEC",
                        help="e.g. api:loss=100%%, gcs:loss=5%%,delay=50ms, hil:none")  # fmt: skip
    parser.add_argument("--instance", type=int, default=0, help="vehicle instance N (default 0)")
    parser.add_argument("--timeout", type=float, default=10.0, help="wall seconds to wait for both answers")
    args = parser.parse_args(argv)
    try:
        answers = change_impairment(args.specs, args.instance, args.timeout)
    except ImpairmentError as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return 2
    except (NoAnswer, bus.BusError) as exc:
        print(f"{prog}: {exc}", file=sys.stderr)
        return 1
    for process in PROCESSES:
        answer = answers[process]
        if not answer.get("accepted"):
            print(f"{process}: refused: {answer.get('error')}", file=sys.stderr)
            return 2
        for name, state in sorted(answer.get("links", {}).items()):
            print(f"{process}: {name}: {state['impairment']} ({state['sent']} sent, {state['dropped']} "
                  f"dropped, {state['duplicated']} duplicated, {state['reordered']} reordered)")  # fmt: skip
    return 0


if __name__ == "__main__":
    sys.exit(main())
