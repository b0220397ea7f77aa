"""Headless MAVProxy driven through stdin/stdout, as a user types into its console.

MAVProxy reads commands from stdin only in its interactive mode (``--daemon`` and
``--non-interactive`` leave stdin unread), so it runs without those flags, with stdin a pipe that
stays open (EOF makes it exit) and stdout read line by line by a thread. Every wait is bounded:
:meth:`MavProxy.expect` fails with the transcript when its pattern does not show in time.
"""

from __future__ import annotations

import queue
import re
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

# Installed next to this interpreter by `make test` (pip install --no-deps MAVProxy).
MAVPROXY = Path(sys.executable).with_name("mavproxy.py")
if not MAVPROXY.exists():
    MAVPROXY = Path(shutil.which("mavproxy.py") or MAVPROXY)
# The modules a console session needs; the default set adds GUI and hardware modules that only
# print "Failed to load module" without their (uninstalled) dependencies.
MODULES = "log,signing,wp,rally,fence,ftp,param,arm,mode,cmdlong,misc,link"
# The console prompt ("MAV> ", "LOITER> ", one per command typed) is printed in front of output
# lines; expect() matches what follows it.
PROMPT = re.compile(r"^(?:[A-Za-z0-9_.]+> )+")


class MavProxy:
    def __init__(self, port: int, cwd: Path, source_system: int = 255) -> None:
        if not MAVPROXY.exists():
            raise AssertionError(
                f"mavproxy.py not found ({MAVPROXY}): `make test` installs it with "
                "`pip install --no-deps MAVProxy` (its runtime needs pyserial, in the dev extra)"
            )
        cmd = [
            sys.executable,
            str(MAVPROXY),
            f"--master=udpin:127.0.0.1:{port}",
            f"--source-system={source_system}",
            "--no-state",  # no logs or aircraft directories written
            "--nowait",
            f"--default-modules={MODULES}",
        ]
        self.proc = subprocess.Popen(
            cmd, cwd=cwd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
            text=True, bufsize=1,
        )  # fmt: skip
        self.t0 = time.monotonic()
        self.transcript: list[str] = []
        self._lines: queue.Queue[str] = queue.Queue()
        threading.Thread(target=self._pump, daemon=True).start()

    def _pump(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            line = line.rstrip("\n")
            self.transcript.append(f"[{time.monotonic() - self.t0:6.2f}] {line}")
            self._lines.put(PROMPT.sub("", line))

    def send(self, command: str) -> None:
        self.transcript.append(f"[{time.monotonic() - self.t0:6.2f}] >>> {command}")
        assert self.proc.stdin is not None
        self.proc.stdin.write(command + "\n")
        self.proc.stdin.flush()

    def expect(self, pattern: str, timeout_s: float) -> re.Match:
        """The first line from now on matching ``pattern`` (lines before it are consumed)."""
        rx = re.compile(pattern)
        deadline = time.monotonic() + timeout_s
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise AssertionError(
                    f"MAVProxy: no line matching {pattern!r} within {timeout_s} s\n" + self.tail()
                )
            try:
                line = self._lines.get(timeout=min(remaining, 0.1))
            except queue.Empty:
                if self.proc.poll() is not None and self._lines.empty():
                    raise AssertionError(
                        f"MAVProxy exited (rc {self.proc.returncode}) waiting for {pattern!r}\n" + self.tail()
                    ) from None
                continue
            match = rx.search(line)
            if match:
                return match

    def command(self, command: str, pattern: str, timeout_s: float) -> re.Match:
        self.send(command)
        return self.expect(pattern, timeout_s)

    def tail(self, lines: int = 80) -> str:
        return "\n".join(self.transcript[-lines:])

    def close(self) -> int:
        """``exit``, then EOF; killed if it is still there after 5 s."""
        if self.proc.poll() is None:
            try:
                self.send("exit")
                assert self.proc.stdin is not None
                self.proc.stdin.close()
            except (BrokenPipeError, OSError):
                pass
            try:
                self.proc.wait(5.0)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait(5.0)
        return self.proc.returncode
