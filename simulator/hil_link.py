"""The simulator process's HIL socket (part of its shell, beside :mod:`simulator.app`): the UDP
link to the autopilot, ``127.0.0.1:(4560 + N)``.

The autopilot's address is learned from its first datagram (it sends HEARTBEAT to this port until
frames flow). Frames go out through the link's impairment, if any (:mod:`quadcommon.impaired_udp`).
The answer to a frame is awaited for ``[lockstep] timeout_s`` of wall time; unanswered for the
core's resend wait, the frame is sent again, byte for byte (a lost frame or answer costs one
resend). Past the timeout the core is told the autopilot is lost; while it is, the socket is
drained without blocking until the autopilot answers again, at its address or, restarted, at a new
one (a message from this vehicle's autopilot). Strangers' datagrams and stale answers are ignored.
"""

from __future__ import annotations

import select
import time
from collections.abc import Callable
from typing import Any

from quadcommon import wire
from quadcommon.impaired_udp import ImpairedLinks, ImpairedSender, wait_s
from quadcommon.udp import bind_udp

from .core import SimulatorCore
from .mavlink.hil import ActuatorAnswer

POLL_S = 0.05  # longest blocking wait: bounds the reaction time to SIGTERM and info queries
MAX_DATAGRAM = 65535
MAX_DRAIN = 1000  # datagrams read per frame while the autopilot is lost (bounded)


class HilLink:
    """The HIL socket of one simulator process (module docstring). ``running()``: False once the
    process is asked to stop; ``poll()``: what to serve while waiting (the zenoh queries)."""

    def __init__(
        self,
        core: SimulatorCore,
        port: int,
        log: Callable[[str], None],
        running: Callable[[], bool],
        poll: Callable[[], None],
    ) -> None:
        sitl = core.setup.sitl
        self.core, self.port, self.log, self.running, self.poll = core, port, log, running, poll
        self.timeout_s, self.spin_s = sitl.lockstep_timeout_s, sitl.lockstep_spin_s
        self.sock: Any = None
        self.out = ImpairedSender(None, None)  # frames to the autopilot, impaired or not (open)
        self.peer: tuple[str, int] | None = None
        self._outage_wall = 0.0

    def open(self, impaired: ImpairedLinks) -> None:
        """Bind the port; PortInUse names it."""
        self.sock = bind_udp(self.port, f"HIL link, udp {wire.LOOPBACK}:{self.port}", True)
        self.sock.settimeout(POLL_S)
        self.out = impaired.sender(self.sock, "hil", "sim->ap", time.perf_counter)
        if self.out.channel is not None:
            described = self.out.channel.impairment.describe()
            self.log(f"HIL link impaired (frames to the autopilot): {described}")

    def close(self) -> None:
        """Close the socket (idempotent)."""
        if self.sock is not None:
            self.sock.close()
            self.sock = None

    def send(self, datagram: bytes) -> None:
        """A frame to the autopilot (a send that fails: the answer's timeout reports it)."""
        self.out.sendto(datagram, self.peer)

    def wait_for_link(self) -> bool:
        """Block until the autopilot's first datagram; remember its sender. False if stopped first."""
        self.log(f"waiting for the autopilot on udp {wire.LOOPBACK}:{self.port}")
        while self.running():
            try:
                data, address = self.sock.recvfrom(MAX_DATAGRAM)
            except TimeoutError:
                self.poll()
                continue
            except OSError:
                continue
            if self.core.is_autopilot(data):  # a message from system 1 + N, component 1
                self.peer = address
                self.log(f"linked with autopilot at {address[0]}:{address[1]}")
                return True
        return False

    def await_answer(self, sent_at: float) -> ActuatorAnswer | None:
        """The answer to the current frame, sent at ``sent_at`` (perf_counter s); None if stopped or
        after ``timeout_s`` (then the core's autopilot is lost). Unanswered for the core's
        ``resend_after_s``, the frame is sent again (a lost frame or answer)."""
        sock, core, perf_counter = self.sock, self.core, time.perf_counter
        deadline = sent_at + self.timeout_s
        resend_at = sent_at + core.resend_after_s
        out = self.out
        wire.spin_until_readable(sock, self.spin_s)  # the answer is due within ~100 µs
        while self.running():
            # Block until the socket is readable, a resend is due or a held datagram is: the
            # socket's own timeout is POLL_S, longer than the resend wait, so select first.
            now = perf_counter()
            if select.select((sock,), (), (), wait_s(POLL_S, now, resend_at, out.next_due()))[0]:
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
            out.flush(now)
            if now >= resend_at and now < deadline:
                out.sendto(core.resend_frame(), self.peer)
                resend_at = now + core.resend_after_s
            # Checked on every wake-up, so a peer chattering without answering is reported too.
            if now >= deadline:
                self.log(f"no HIL_ACTUATOR_CONTROLS for frame t={core.t:.3f} s within {self.timeout_s:.1f} s;"
                         f" is the autopilot running? (udp {wire.LOOPBACK}:{self.port})")  # fmt: skip
                core.autopilot_lost()
                self._outage_wall = time.perf_counter()
                return None
            if data is None:
                self.poll()
        return None

    def answers_again(self) -> bool:
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
