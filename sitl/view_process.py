"""``quadsitl up --view``: the live view as one more child of the launcher.

The view (``python -m gcs_scripts.view``) is started after the vehicles are linked, so its first
zenoh sessions and heartbeats find them; its URL is read from its output for the banner, and it
is stopped with the rest (a :class:`~sitl.launcher.Child`: it dies with the launcher too).
"""

from __future__ import annotations

import errno
import socket
import sys
from collections.abc import Sequence

from quadcommon.wire import LOOPBACK

from .launcher import Child, Launcher, LaunchError

URL_PREFIX = "quadsitl view: open "
VIEW = "view"  # the child's name


def check_view_port(port: int) -> None:
    """LaunchError if TCP ``port`` on 127.0.0.1 is taken (0: any free port, nothing to check)."""
    if port == 0:
        return
    sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as the server binds it
    try:
        sock.bind((LOOPBACK, port))
    except OSError as exc:
        if exc.errno == errno.EADDRINUSE:
            raise LaunchError(
                f"TCP port {port} (live view) is already in use: choose another --view-port"
            ) from None
        raise
    finally:
        sock.close()


def view_command(instances: Sequence[int], port: int, sitl_config: str | None = None) -> list[str]:
    """The command line of a ``quadsitl view`` process watching ``instances`` on ``port``."""
    cmd = [
        sys.executable,
        "-u",
        "-m",
        "gcs_scripts.view",
        "--instance",
        *map(str, instances),
        "--port",
        str(port),
    ]
    return cmd + (["--sitl-config", sitl_config] if sitl_config else [])


def start_view(
    launcher: Launcher,
    instances: Sequence[int],
    port: int,
    sitl_config: str | None = None,
    timeout_s: float = 20.0,
) -> tuple[Child, str]:
    """Start the view on ``instances`` at 127.0.0.1:``port`` as a child of ``launcher``; the child
    and its URL. LaunchError (with its output) if it does not say where it listens in time."""
    child = launcher.spawn(VIEW, view_command(instances, port, sitl_config))
    line = child.wait_line(URL_PREFIX, timeout_s)
    return child, line[line.index(URL_PREFIX) + len(URL_PREFIX) :].strip()
