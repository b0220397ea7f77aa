"""The simulator process: UDP, pacing and zenoh around :class:`~simulator.core.SimulatorCore`.

One thread, one loop, the lockstep period of the core (:mod:`simulator.core`): per frame it sends
the core's datagram to the autopilot, publishes the frame's truth row on zenoh and answers info
queries while the autopilot computes, waits for the answer to that frame (stale answers and
strangers' datagrams are ignored), lets the core step the plant, and paces on the wall clock:
sleeps until ``wall_start + t / speed`` (no sleeping for ``max``); more than 0.2 s behind, it
re-anchors instead of sprinting to catch up.

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

The UDP link binds 127.0.0.1:(4560 + N) and learns the autopilot's address from its first
datagram (the autopilot sends HEARTBEAT to this port until frames flow). Ports in use, like bad
configuration, end the process with exit code 2 and a message naming the port and ``--instance``.
SIGINT/SIGTERM stop the loop cleanly (truth batch flushed, zenoh closed, socket closed; exit 0).
"""

from __future__ import annotations

import select
import sys
import time
from typing import Any

from quadcommon import bus, wire
from quadcommon.impaired_udp import ImpairedLinks, ImpairedSender, wait_s
from quadcommon.udp import PortInUse, bind_udp

from .core import PlantDiverged, SimulatorCore, SimulatorSetup
from .latency import LatencyHistogram
from .mavlink.hil import ActuatorAnswer
from .pacing import Pacer
from .truth_bus import GustUploadServer, InfoServer, RequestServer, TruthStream

POLL_S = 0.05  # longest blocking wait: bounds the reaction time to SIGTERM and info queries
MAX_DATAGRAM = 65535
MAX_DRAIN = 1000  # datagrams read per frame while the autopilot is lost (bounded)


class StartupError(RuntimeError):
    """The simulator cannot start (port in use, ...); the message says which and why."""


class Simulator:
    """The simulator process; ``open`` -> ``run`` -> ``close`` (in ``finally``)."""

    def __init__(self, setup: SimulatorSetup, speed: float | None = 1.0, duration_s: float | None = None):
        self.core = SimulatorCore(setup, self.log)
        self.speed = speed  # wall-clock pacing factor; None = as fast as lockstep allows
        self.duration_s = duration_s
        sitl = setup.sitl
        self.instance = setup.instance
        self.ports = wire.ports(setup.instance, sitl.hil_port_base, sitl.gcs_port_base,
                                sitl.api_port_base, sitl.zenoh_port_base)  # fmt: skip
        self.timeout_s, self.spin_s = sitl.lockstep_timeout_s, sitl.lockstep_spin_s
        self.sock: Any = None
        self.impaired = ImpairedLinks(sitl.impair, "simulator")  # live changes: quadsitl/<N>/impair
        self.hil_out = ImpairedSender(None, None)  # frames to the autopilot, impaired or not (open)
        self.session: Any = None
        self.truth_stream: TruthStream | None = None
        self.services: list = []  # zenoh queryables polled from the loop
        self.peer: tuple[str, int] | None = None
        self._running = True
        self.frames_sent = 0
        self.pacer: Pacer | None = None
        self.work_s = self.wait_s = 0.0  # wall time per frame: own work, waiting for the autopilot
        self.loop_start = self.loop_s = 0.0  # the frame loop's wall time (linked to the last frame)
        self.round_trips = LatencyHistogram()  # HIL round trip per frame (wall s); constant memory
        self._outage_wall = 0.0

    def log(self, text: str) -> None:
        """Print ``text`` to stdout as a ``simulator:`` line, flushed (the launcher relays it)."""
        print(f"simulator: {text}", flush=True)

    def open(self) -> None:
        """Bind the HIL port and open the zenoh hub; raises :class:`StartupError` on a port in use."""
        n, core = self.instance, self.core
        try:
            self.sock = bind_udp(self.ports.hil, f"HIL link, udp {wire.LOOPBACK}:{self.ports.hil}", True)
        except PortInUse as exc:
            raise StartupError(f"{exc}: is another simulator running with --instance {n}? "
                               "(pick another --instance)") from None  # fmt: skip
        self.sock.settimeout(POLL_S)
        self.hil_out = self.impaired.sender(self.sock, "hil", "sim->ap", time.perf_counter)
        if self.hil_out.channel is not None:
            described = self.hil_out.channel.impairment.describe()
            self.log(f"HIL link impaired (frames to the autopilot): {described}")
        try:
            self.session = bus.open_hub(self.ports.zenoh, core.setup.sitl.zenoh_router)
        except bus.BusError as exc:
            raise StartupError(f"{exc}: is another simulator running with --instance {n}? "
                               "(pick another --instance)") from None  # fmt: skip
        self.truth_stream = TruthStream(self.session, wire.zenoh_key(n, "truth"))
        self.services = [
            InfoServer(self.session, wire.zenoh_key(n, "info"), self.describe),
            GustUploadServer(self.session, wire.zenoh_key(n, "sim/gusts"), core.upload_gusts),
            RequestServer(self.session, wire.zenoh_key(n, "impair"), self._change_impairment),
        ]  # fmt: skip

    def close(self) -> None:
        """Flush the truth batch, close zenoh and the socket (idempotent)."""
        if self.truth_stream is not None:
            self.truth_stream.close()
            self.truth_stream = None
        for service in self.services:
            service.close()
        self.services = []
        if self.session is not None:
            self.session.close()
            self.session = None
        if self.sock is not None:
            self.sock.close()
            self.sock = None

    def stop(self, *_args: object) -> None:
        """Ask the loop to stop (signal handler: SIGINT, SIGTERM)."""
        self._running = False

    def describe(self) -> dict[str, Any]:
        """The answer of the ``quadsitl/<N>/info`` queryable."""
        info = {**self.core.info(), "speed": "max" if self.speed is None else self.speed}
        info["impairment"] = self.impaired.info()
        return info

    def _change_impairment(self, payload: bytes) -> tuple[bool, bytes]:
        ok, reply = self.impaired.change(payload)
        if ok:
            self.log(f"impairment changed at t={self.core.t:.3f} s: {self.impaired.config.describe()}")
        return ok, reply

    def _poll_services(self) -> None:
        for service in self.services:
            service.poll()

    def _report_warnings(self) -> None:
        for text in self.core.warnings:
            print(f"simulator: {text}", file=sys.stderr, flush=True)
        self.core.warnings.clear()

    # -- link -----------------------------------------------------------------------------------
    def _wait_for_link(self) -> bool:
        """Block until the autopilot's first datagram; remember its sender. False if stopped first."""
        self.log(f"waiting for the autopilot on udp {wire.LOOPBACK}:{self.ports.hil}")
        while self._running:
            try:
                data, address = self.sock.recvfrom(MAX_DATAGRAM)
            except TimeoutError:
                self._poll_services()
                continue
            except OSError:
                continue
            if self.core.is_autopilot(data):  # a message from system 1 + N, component 1
                self.peer = address
                self.log(f"linked with autopilot at {address[0]}:{address[1]}")
                return True
        return False

    def _await_answer(self, sent_at: float) -> ActuatorAnswer | None:
        """The answer to the current frame; None if stopped or after ``timeout_s`` (then LOST).
        Unanswered for ``core.resend_after_s``, the frame is sent again (a lost frame or answer)."""
        sock, core, perf_counter = self.sock, self.core, time.perf_counter
        deadline = sent_at + self.timeout_s
        resend_at = sent_at + core.resend_after_s
        hil_out = self.hil_out
        wire.spin_until_readable(sock, self.spin_s)  # the answer is due within ~100 µs
        while self._running:
            # Block until the socket is readable, a resend is due or a held datagram is: the
            # socket's own timeout is POLL_S, longer than the resend wait, so select first.
            now = perf_counter()
            if select.select((sock,), (), (), wait_s(POLL_S, now, resend_at, hil_out.next_due()))[0]:
                try:
                    data, address = sock.recvfrom(MAX_DATAGRAM)
                except OSError:  # ICMP port unreachable: the peer is gone
                    data = None
            else:
                data = None
            if data is not None and address == self.peer:
                answer = core.answer_to_frame(data)
                if answer is not None:
                    return answer
            now = perf_counter()
            hil_out.flush(now)
            if now >= resend_at and now < deadline:
                hil_out.sendto(core.resend_frame(), self.peer)
                resend_at = now + core.resend_after_s
            # Checked on every wake-up, so a peer chattering without answering is reported too.
            if now >= deadline:
                self.log(f"no HIL_ACTUATOR_CONTROLS for frame t={core.t:.3f} s within {self.timeout_s:.1f} s;"
                         f" is the autopilot running? (udp {wire.LOOPBACK}:{self.ports.hil})")  # fmt: skip
                core.autopilot_lost()
                self._outage_wall = time.perf_counter()
                return None
            if data is None:
                self._poll_services()
        return None

    def _autopilot_answers_again(self) -> bool:
        """While lost: drain the socket without blocking; True once the autopilot answers again.
        A message from this vehicle's autopilot at a new address is a restarted autopilot saying
        hello: that address becomes the peer."""
        sock = self.sock
        for _ in range(MAX_DRAIN):
            if not select.select((sock,), (), (), 0.0)[0]:  # a socket with a timeout: ask first
                return False
            try:
                data, address = sock.recvfrom(MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError, TimeoutError):
                return False
            except OSError:
                continue  # ICMP unreachable from a send to the dead autopilot
            if address != self.peer:
                if self.core.is_autopilot(data):  # a restarted autopilot; anyone else: ignored
                    self.peer = address
                    self.log(f"autopilot now at {address[0]}:{address[1]}")
            elif self.core.answers_again(data):
                self.log(f"the outage lasted {time.perf_counter() - self._outage_wall:.1f} s (wall)")
                return True
        return False

    # -- loop -----------------------------------------------------------------------------------
    def run(self) -> int:
        """Until stopped or ``duration_s`` of simulated time; returns the exit code."""
        if not self._wait_for_link():
            return 0
        core, sock, append_truth = self.core, self.sock, self.truth_stream.append
        perf_counter = time.perf_counter
        last_frame = None if self.duration_s is None else round(self.duration_s / core.dt_control)
        pacer = self.pacer = Pacer(self.speed, self.log, lambda: self._running)
        self.loop_start = perf_counter()
        try:
            return self._loop(core, sock, append_truth, last_frame, pacer)
        finally:
            self.loop_s = perf_counter() - self.loop_start

    def _loop(self, core, sock, append_truth, last_frame, pacer) -> int:
        perf_counter = time.perf_counter
        while self._running:
            start = perf_counter()
            try:
                datagram = core.begin_frame()
            except PlantDiverged as exc:
                print(f"simulator: {exc}; stopping", file=sys.stderr, flush=True)
                return 1
            sent_at = perf_counter()
            self.hil_out.sendto(datagram, self.peer)  # a send that fails: the timeout reports it
            self.frames_sent += 1
            append_truth(core.truth_row)  # bookkeeping while the autopilot computes its answer
            self._poll_services()
            if last_frame is not None and core.k >= last_frame:
                break  # the final frame (t = duration) is sent and recorded, not stepped
            sent = perf_counter()
            if core.emergency:  # our own descent this frame; lockstep again once it answers
                if self._autopilot_answers_again():
                    pacer.resync()
                answer = None
            else:
                answer = self._await_answer(sent_at)
                if answer is None and not core.emergency:
                    break  # stopped while waiting
                if answer is None:
                    pacer.resync()  # the wait was an outage, not simulated time
                else:
                    self.round_trips.add(perf_counter() - sent_at)
            answered = perf_counter()
            core.end_frame(answer)
            if core.warnings:
                self._report_warnings()
            self.work_s += (sent - start) + (perf_counter() - answered)
            self.wait_s += answered - sent
            pacer.pace(core.t, idle=core.emergency and core.emergency_landed)
        return 0

    def summary(self) -> str:
        """The one-line report printed at stop: simulated time, frames sent and resent, own work and
        waiting per frame (us), re-anchors, the speed-up over the frame loop and the HIL round trip's
        median and 99th percentile (us)."""
        n = max(self.frames_sent - 1, 1)  # the final frame is not answered
        text = (
            f"stopped at t={self.core.t:.3f} s ({self.frames_sent} frames; per frame "
            f"{1e6 * self.work_s / n:.0f} us own work, {1e6 * self.wait_s / n:.0f} us waiting for the "
            f"autopilot; {self.pacer.overruns if self.pacer else 0} re-anchors; "
            f"{self.core.resends} frames resent)"
        )
        if self.loop_s > 0.0:
            t = self.core.t
            text += f"; {t:.3f} s simulated in {self.loop_s:.3f} s of frame loop ({t / self.loop_s:.1f}x)"
        if self.round_trips:
            median, p99 = self.round_trips.quantile(0.5), self.round_trips.quantile(0.99)
            text += f"; HIL round trip median {1e6 * median:.0f} us, p99 {1e6 * p99:.0f} us"
        return text
