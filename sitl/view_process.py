"""``quadsitl up --view``: the live view as one more child process of the launcher.

The view (``python -m gcs_scripts.view``) is started after the vehicles are linked, so its first
zenoh sessions and heartbeats find them; its URL is read from its output for the banner, and it
is stopped with the rest (it also dies with the launcher: ``PR_SET_PDEATHSIG``, as the vehicles).
"""

from __future__ import annotations

import errno
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Sequence

from quadcommon.wire import LOOPBACK

from .up import LaunchError, _die_with_parent

URL_PREFIX = "quadsitl view: open "


class ViewProcess:
    """A running view server; :attr:`url` is where the browser goes."""

    def __init__(self, process: subprocess.Popen, echo: bool = True) -> None:
        self.process = process
        self.echo = echo
        self.url = ""
        self.lines: list[str] = []
        self._ready = threading.Event()
        threading.Thread(target=self._pump, daemon=True).start()

    def _pump(self) -> None:
        assert self.process.stdout is not None
        for line in self.process.stdout:
            line = line.rstrip("\n")
            self.lines.append(line)
            if len(self.lines) > 500:
                del self.lines[:250]
            if line.startswith(URL_PREFIX):
                self.url = line[len(URL_PREFIX) :].strip()
                self._ready.set()
            if self.echo:
                print(f"[view] {line}", flush=True)
        self._ready.set()  # exited: whoever waits must not wait for ever

    def wait_ready(self, timeout_s: float) -> str:
        if not self._ready.wait(timeout_s) or not self.url:
            self.stop()
            raise LaunchError(
                f"the view did not start within {timeout_s:.0f} s (exit code {self.process.returncode}):\n"
                + "\n".join(self.lines[-15:])
            )
        return self.url

    def alive(self) -> bool:
        return self.process.poll() is None

    def stop(self, grace_s: float = 5.0) -> int | None:
        if self.process.poll() is None:
            try:
                self.process.send_signal(signal.SIGTERM)
            except ProcessLookupError:
                pass
            try:
                self.process.wait(grace_s)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(2.0)
        return self.process.returncode


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


def start_view(
    instances: Sequence[int],
    port: int,
    sitl_config: str | None = None,
    timeout_s: float = 20.0,
    echo: bool = True,
) -> ViewProcess:
    """Start the view on ``instances`` at 127.0.0.1:``port``; raises LaunchError if it cannot."""
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
    if sitl_config:
        cmd += ["--sitl-config", sitl_config]
    process = subprocess.Popen(
        cmd,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        bufsize=1,
        preexec_fn=_die_with_parent,
    )
    view = ViewProcess(process, echo=echo)
    start = time.monotonic()
    view.wait_ready(max(timeout_s - (time.monotonic() - start), 0.1))
    return view
