"""A fleet over several processes (``quadsitl fleet --processes P``): the instances split into P
contiguous shares, each flown by a ``quadsitl fleet`` process of its own (one core each), watched
and restarted when lost.

A fleet process holds its vehicles' simulators and autopilots together, so losing it loses those
vehicles whole (no survivor whose failsafe could act, as with ``quadsitl up``'s two processes per
vehicle): the supervisor reports which process died, why and which instances it flew, and
restarts it after :class:`~sitl.supervise.RestartPolicy`'s delay (0.5 s, doubling with each
restart in the last minute, at most 3 per 60 s; ``--no-restart`` keeps it down). Its vehicles
start again on the ground, disarmed (a restarted process never gets ``--autostart``), and
``quadsitl: fleet process K relinked (instances A..B)`` is printed once it is flying again. The
other processes fly on undisturbed. The supervisor ends when every process has ended (Ctrl-C
stops them all).
"""

from __future__ import annotations

import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field

from .launcher import Child
from .supervise import RestartPolicy, exit_reason, stop_on_signals, write_line

READY = "vehicles, instances"  # the line a fleet process prints once its vehicles fly (sitl/fleet.py)
POLL_S = 0.2


def shares(first: int, count: int, processes: int) -> list[tuple[int, int]]:
    """``(first instance, count)`` of each process: contiguous, sizes differing by at most one."""
    processes = max(1, min(processes, count))
    base, extra = divmod(count, processes)
    out, at = [], first
    for k in range(processes):
        n = base + (1 if k < extra else 0)
        out.append((at, n))
        at += n
    return out


@dataclass
class FleetProcess:
    """One share of the fleet and the process flying it."""

    index: int
    first: int
    count: int
    arguments: list[str]  # the options every share's process gets (speed, scenario, ...)
    autostart: list[str]  # ``--autostart NAME`` for the first start only
    child: Child | None = None
    restarts: list[float] = field(default_factory=list)
    restart_at: float | None = None
    announced: bool = False
    gave_up: bool = False

    @property
    def instances(self) -> str:
        """Its instances, ``A..B``."""
        return f"{self.first}..{self.first + self.count - 1}"

    def start(self, first_start: bool) -> None:
        """Start its process (``--autostart`` only on the first start: a restarted vehicle waits on
        the ground)."""
        cmd = [sys.executable, "-u", "-m", "sitl.cli", "fleet", "--processes", "1",
               "--count", str(self.count), "--instance", str(self.first), *self.arguments,
               *(self.autostart if first_start else [])]  # fmt: skip
        self.child = Child(f"fleet process {self.index}", cmd,
                           echo=lambda name, line: write_line(f"[{self.index}] {line}"))  # fmt: skip
        self.announced = False


def supervise(first: int, count: int, processes: int, arguments: Sequence[str], autostart: Sequence[str],
              policy: RestartPolicy) -> int:  # fmt: skip
    """Fly the fleet over ``processes`` processes until all have ended; 0, or 1 if one was lost
    for good."""
    fleet = [FleetProcess(k, n0, n, list(arguments), list(autostart))
             for k, (n0, n) in enumerate(shares(first, count, processes))]  # fmt: skip
    stop = stop_on_signals()
    for share in fleet:
        share.start(first_start=True)
    write_line(f"quadsitl: fleet of {count} vehicles in {len(fleet)} processes: "
               + ", ".join(f"process {s.index} instances {s.instances}" for s in fleet))  # fmt: skip
    try:
        while not stop.is_set() and any(s.child is not None or s.restart_at is not None for s in fleet):
            now = time.monotonic()
            for share in fleet:
                _watch(share, now, policy)
            time.sleep(POLL_S)
    finally:
        for share in fleet:
            if share.child is not None and share.child.alive:
                share.child.stop()
    return 1 if any(s.gave_up for s in fleet) else 0


def _watch(share: FleetProcess, now: float, policy: RestartPolicy) -> None:
    child = share.child
    if child is None:
        if share.restart_at is not None and now >= share.restart_at:
            share.restart_at = None
            share.restarts.append(now)
            share.start(first_start=False)
        return
    if not share.announced and READY in child.output:
        share.announced = True
        if share.restarts:
            write_line(f"quadsitl: fleet process {share.index} relinked (instances {share.instances}, "
                       f"restart {len(share.restarts)})")  # fmt: skip
    code = child.returncode
    if code is None:
        return
    share.child = None
    if code == 0:
        return  # its --duration reached, or stopped
    why = exit_reason(code)
    if policy.allows(share.restarts, now):
        delay = policy.delay_s(share.restarts, now)
        share.restart_at = now + delay
        write_line(f"quadsitl: fleet process {share.index} (instances {share.instances}) lost: {why}; "
                   f"restarting in {delay:g} s, its vehicles on the ground", error=True)  # fmt: skip
    else:
        share.gave_up = True
        write_line(f"quadsitl: fleet process {share.index} (instances {share.instances}) lost: {why}; "
                   "left down", error=True)  # fmt: skip
