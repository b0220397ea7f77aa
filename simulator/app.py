"""The simulator process: UDP, pacing and zenoh around :class:`~simulator.core.SimulatorCore`.

One thread, one loop, the lockstep period of the core (:mod:`simulator.core`): per frame it sends
the core's datagram to the autopilot, publishes the frame's truth row on zenoh and answers info
queries while the autopilot computes (:mod:`simulator.bus_link`), waits for the answer to that
frame (:mod:`simulator.hil_link`: the peer learned from its first datagram, resends, the
wall-clock timeout), lets the core step the plant, and paces on the wall clock: sleeps until
``wall_start + t / speed`` (no sleeping for ``max``); more than 0.2 s behind, it re-anchors
instead of sprinting to catch up (:mod:`simulator.pacing`).

A frame unanswered for ``[lockstep] resend_s`` (plus the HIL impairment's delay and jitter both
ways) is sent again, byte for byte, and again after each such wait: a lost frame or answer costs
one resend, and the autopilot answers a frame it has answered already from that answer. With
``[impair] hil`` (or ``--impair hil:...``) the frames go out through the impaired channel
(:mod:`quadcommon.impairment`); the autopilot impairs its answers the same way.

Autopilot lost: after ``[lockstep] timeout_s`` of wall time without the answer the simulator says
so and keeps stepping (paced as before) under the core's own emergency descent (level, descend at
0.5 m/s, motors off on touchdown; a vehicle on the ground or disarmed keeps its motors off), still
sending every frame. Under ``--speed max`` the descent runs as fast as it can (it ends on the
ground) and, once down, time goes on at real time (1x) so an idle simulator does not spin. The
first answer from the autopilot (or a restarted autopilot, at a new address) resumes lockstep.

Ports in use, like bad configuration, end the process with exit code 2 and a message naming the
port and ``--instance``. SIGINT/SIGTERM stop the loop cleanly (truth batch flushed, zenoh closed,
socket closed; exit 0).
"""

from __future__ import annotations

import sys
import time

from quadcommon import bus
from quadcommon.impaired_udp import ImpairedLinks
from quadcommon.udp import PortInUse

from .bus_link import SimulatorBus
from .core import PlantDiverged, SimulatorCore, SimulatorSetup
from .hil_link import HilLink
from .loop_stats import LoopStats
from .pacing import Pacer


class StartupError(RuntimeError):
    """The simulator cannot start (port in use, ...); the message says which and why."""


class Simulator:
    """The simulator process; ``open`` -> ``run`` -> ``close`` (in ``finally``)."""

    def __init__(self, setup: SimulatorSetup, speed: float | None = 1.0, duration_s: float | None = None):
        self.core = SimulatorCore(setup, self.log)
        self.speed = speed  # wall-clock pacing factor; None = as fast as lockstep allows
        self.duration_s = duration_s
        self.instance = setup.instance
        self.ports = setup.sitl.ports(setup.instance)
        self.impaired = ImpairedLinks(setup.sitl.impair, "simulator")  # live changes: quadsitl/<N>/impair
        self.bus = SimulatorBus(self.core, self.impaired, speed, self.log)  # zenoh: truth out, queries in
        self.hil = HilLink(self.core, self.ports.hil, self.log, lambda: self._running, self.bus.poll)
        self._running = True
        self.pacer: Pacer | None = None
        self.stats = LoopStats()

    def log(self, text: str) -> None:
        """Print ``text`` as the simulator's own line of the launcher's log."""
        print(f"simulator: {text}", flush=True)

    def open(self) -> None:
        """Bind the HIL port and open the zenoh hub; raises :class:`StartupError` on a port in use."""
        try:
            self.hil.open(self.impaired)
            self.bus.open(self.ports.zenoh)
        except (PortInUse, bus.BusError) as exc:
            raise StartupError(f"{exc}: is another simulator running with --instance {self.instance}? "
                               "(pick another --instance)") from None  # fmt: skip

    def close(self) -> None:
        """Flush the truth batch, close zenoh and the socket (idempotent)."""
        self.bus.close()
        self.hil.close()

    def stop(self, *_args: object) -> None:
        """Ask the loop to stop (signal handler: SIGINT, SIGTERM)."""
        self._running = False

    def _report_warnings(self) -> None:
        for text in self.core.warnings:
            print(f"simulator: {text}", file=sys.stderr, flush=True)
        self.core.warnings.clear()

    # -- loop -----------------------------------------------------------------------------------
    def run(self) -> int:
        """Until stopped or ``duration_s`` of simulated time; returns the exit code."""
        if not self.hil.wait_for_link():
            return 0
        core, append_truth = self.core, self.bus.truth.append
        perf_counter = time.perf_counter
        last_frame = None if self.duration_s is None else round(self.duration_s / core.dt_control)
        pacer = self.pacer = Pacer(self.speed, self.log, lambda: self._running)
        stats = self.stats
        stats.loop_start = perf_counter()
        try:
            return self._loop(core, append_truth, last_frame, pacer)
        finally:
            stats.loop_s = perf_counter() - stats.loop_start

    def _loop(self, core, append_truth, last_frame, pacer) -> int:
        perf_counter, stats, hil = time.perf_counter, self.stats, self.hil
        while self._running:
            start = perf_counter()
            try:
                datagram = core.begin_frame()
            except PlantDiverged as exc:
                print(f"simulator: {exc}; stopping", file=sys.stderr, flush=True)
                return 1
            sent_at = perf_counter()
            hil.send(datagram)  # a send that fails: the timeout reports it
            stats.frames_sent += 1
            append_truth(core.truth_row)  # bookkeeping while the autopilot computes its answer
            self.bus.poll()
            if last_frame is not None and core.k >= last_frame:
                break  # the final frame (t = duration) is sent and recorded, not stepped
            sent = perf_counter()
            if core.emergency:  # our own descent this frame; lockstep again once it answers
                if hil.answers_again():
                    pacer.resync()
                answer = None
            else:
                answer = hil.await_answer(sent_at)
                if answer is None and not core.emergency:
                    break  # stopped while waiting
                if answer is None:
                    pacer.resync()  # the wait was an outage, not simulated time
                else:
                    stats.round_trips.add(perf_counter() - sent_at)
            answered = perf_counter()
            core.end_frame(answer)
            if core.warnings:
                self._report_warnings()
            stats.work_s += (sent - start) + (perf_counter() - answered)
            stats.wait_s += answered - sent
            pacer.pace(core.t, idle=core.emergency and core.emergency_landed)
        return 0

    def summary(self) -> str:
        """The run in one line for the log at exit (:meth:`~simulator.loop_stats.LoopStats.summary`)."""
        overruns = self.pacer.overruns if self.pacer else 0
        return self.stats.summary(self.core.t, overruns, self.core.resends)
