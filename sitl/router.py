"""``quadsitl router``: a zenoh router for a fleet spread over several launches or hosts.

Without a router, each vehicle's processes meet on its own zenoh hub port (loopback, peer mode).
With ``[zenoh] router = "tcp/HOST:PORT"`` in every launch's ``sitl.toml`` (``quadsitl config copy``,
``--config-dir``), every session is a client of that router instead, so a recorder, the live view
or a script connected to it sees every vehicle of every launch, told apart by instance
(``quadsitl/<N>/...``): give each launch its own instances (``--instance``). Any zenoh router
works (``zenohd``); this one needs nothing beyond the project's zenoh package.

It listens on ``127.0.0.1:PORT`` unless ``--listen`` names another endpoint: a router on a
network interface is the one way this project's traffic leaves the machine (docs/security.md).

Run: ``quadsitl router [--port 7446] [--listen tcp/HOST:PORT]``; Ctrl-C stops it.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from quadcommon import bus, wire

from .supervise import stop_on_signals

DEFAULT_PORT = 7446  # below the vehicles' hubs (7447 + N)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the router until Ctrl-C (or SIGTERM)."""
    parser = argparse.ArgumentParser(prog="quadsitl router", description=__doc__.split("\n\n")[0])
    parser.add_argument("--port", type=int, default=DEFAULT_PORT,
                        help=f"listen on 127.0.0.1:PORT (default {DEFAULT_PORT})")
    parser.add_argument("--listen", default=None, help="another endpoint, e.g. tcp/192.168.1.10:7446")
    args = parser.parse_args(argv)
    if not 1 <= args.port <= 65535:
        parser.error(f"--port {args.port}: must be in 1..65535")
    endpoint = args.listen or f"tcp/{wire.LOOPBACK}:{args.port}"
    try:
        session = bus.open_router(endpoint)
    except bus.BusError as exc:
        print(f"quadsitl router: {exc}", file=sys.stderr)
        return 2
    stop = stop_on_signals()
    print(f'router: listening on {endpoint}; in each launch\'s sitl.toml: [zenoh] router = "{endpoint}"',
          flush=True)  # fmt: skip
    try:
        while not stop.wait(0.5):
            pass
    finally:
        session.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
