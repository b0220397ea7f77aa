"""The autopilot process: sockets, the selector and pacing around :class:`~autopilot.core.AutopilotCore`.

One thread, one loop. ``select`` waits on the HIL socket and the two GCS sockets; every datagram
goes into the core with the wall clock, and whatever the core returns goes out on the socket of
its link. A lockstep frame is answered before anything else is sent (the simulator is waiting).
Every 50 ms of wall time the core's housekeeping runs, its rows go to zenoh and its queries are
answered (:mod:`autopilot.bus_link`), and the flight log goes to the writer's thread
(:mod:`autopilot.log_files`). Nothing here decides anything about the vehicle.

With an impairment (``[impair]`` of sitl.toml, ``--impair``, or ``quadsitl impair`` on zenoh's
``quadsitl/<N>/impair`` while running) every send goes through the link's outgoing channel and every
ground-station datagram received through its incoming one (:mod:`quadcommon.impaired_udp`); the
loop's waits end when a held datagram is due.

Run: ``python -m autopilot --instance N --controller NAME --vehicle NAME``.
"""

from __future__ import annotations

import selectors
import time

from quadcommon import wire
from quadcommon.impaired_udp import ImpairedLinks, ImpairedReceiver, ImpairedSender, wait_s
from quadcommon.udp import bind_udp

from .bus_link import AutopilotBus
from .core import AutopilotCore
from .log_files import FlightLogFiles
from .mavlink.links import API_LINK, GCS_LINK, HIL_LINK, Outgoing
from .setup import AutopilotSetup
from .vehicle_files import VehicleFiles

HOUSEKEEPING_S = 0.05
LINK_NAMES = {HIL_LINK: "hil", GCS_LINK: "gcs", API_LINK: "api"}  # as --impair names them
SPIN_BELOW_GAP_S = 0.001  # frames closer than this (wall): spin-wait for the next one
MAX_DATAGRAM = 65535
# Ground-station datagrams handled per link and lockstep frame (and per housekeeping tick while no
# frame comes): 4,000 a simulated second per link at 500 Hz, far above any client's needs. A flood
# beyond it waits in the socket's buffer, which the kernel caps (and drops from), so it cannot
# starve the control loop: measured by benchmarks/hostile_load.py.
GCS_DATAGRAMS_PER_FRAME = 8


class Autopilot:
    """The autopilot process around one :class:`~autopilot.core.AutopilotCore`; ``open`` -> ``run``
    -> ``close`` (in ``finally``)."""

    def __init__(self, setup: AutopilotSetup, zenoh: bool = True, quiet: bool = False) -> None:
        self.quiet = quiet
        self.log_files = FlightLogFiles(setup.log.directory)
        logs = self.log_files.directory
        files = VehicleFiles.for_vehicle(logs, setup.params_file)  # MAVLink FTP's root
        self.core = AutopilotCore(setup, self.log, log_store=logs, files=files)
        sitl = setup.sitl
        self.ports = sitl.ports(setup.instance)
        self.hil_address = (wire.LOOPBACK, self.ports.hil)
        self.use_zenoh = zenoh
        self.socks: dict[int, object] = {}
        self.selector = selectors.DefaultSelector()
        self.hil_only = selectors.DefaultSelector()  # while the GCS links' budgets are spent
        self.gcs_budget: dict[int, int] = {}
        self.impaired = ImpairedLinks(setup.sitl.impair, "autopilot")  # live: quadsitl/<N>/impair
        self.bus = AutopilotBus(self.core, self.impaired, self.log)  # zenoh: rows out, queries answered
        self.senders: dict[int, ImpairedSender] = {}
        self.receivers: dict[int, ImpairedReceiver] = {}
        self._running = True

    def log(self, text: str) -> None:
        """A line on stdout (none with ``quiet``)."""
        if not self.quiet:
            print(f"autopilot: {text}", flush=True)

    def open(self) -> None:
        """Bind the links and open zenoh; PortInUse / bus.BusError name what is taken."""
        self.socks[GCS_LINK] = bind_udp(self.ports.gcs_local, "GCS link")
        self.socks[API_LINK] = bind_udp(self.ports.api_local, "API link")
        self.socks[HIL_LINK] = bind_udp(0, "HIL link")
        impaired, names = self.impaired, LINK_NAMES
        self.senders = {link: impaired.sender(sock, names[link], "ap->sim" if link == HIL_LINK else "out")
                        for link, sock in self.socks.items()}  # fmt: skip
        self.receivers = {link: impaired.receiver(names[link], "in") for link in (GCS_LINK, API_LINK)}
        if impaired.config.active:
            self.log(f"links impaired: {impaired.config.describe()}")
        for link, sock in self.socks.items():
            self.selector.register(sock, selectors.EVENT_READ, link)
            if link == HIL_LINK:
                self.hil_only.register(sock, selectors.EVENT_READ, link)
            else:
                self.gcs_budget[link] = GCS_DATAGRAMS_PER_FRAME
        if self.use_zenoh:
            self.bus.open(self.ports.zenoh)

    def close(self) -> None:
        """Everything out (the last rows, the flight log, the signing timestamp), then the sockets."""
        self.bus.publish_rows(force=True)
        self.log_files.close(self.core)
        self.core.signing.save()  # the newest signing timestamp, so a restart refuses older frames
        for sock in self.socks.values():
            sock.close()
        self.bus.close()

    def stop(self, *_args) -> None:
        """End the loop (a signal handler)."""
        self._running = False

    def send(self, out: list[Outgoing]) -> None:
        """Out on the link's socket, through its impairment (a failed send, nobody listening, is
        normal for a GCS port and dropped)."""
        senders = self.senders
        for link, address, data in out:
            senders[link].sendto(data, address or self.hil_address)

    def _flush_impaired(self, now: float) -> None:
        """Held datagrams whose time has come: out, or into the core."""
        for sender in self.senders.values():
            sender.flush(now)
        for link, receiver in self.receivers.items():
            for data, address in receiver.due(now):
                self.send(self.core.on_gcs_datagram(link, address, data, now))

    def _next_due(self) -> list[float | None]:
        return [e.next_due() for e in self.impaired.endpoints.values()]

    def run(self, max_wall_s: float | None = None) -> int:
        """The loop until stopped (or ``max_wall_s`` of wall time); the exit status."""
        core, hil = self.core, self.socks[HIL_LINK]
        deadline = None if max_wall_s is None else time.monotonic() + max_wall_s
        spin_s = core.setup.sitl.lockstep_spin_s
        p = self.ports
        self.log(
            f"instance {core.setup.instance}, sysid {core.system_id}, "
            f"controller {core.setup.controller.name}, "
            f"GCS link udp {wire.LOOPBACK}:{p.gcs_local}->{p.gcs_remote}, "
            f"API link {p.api_local}->{p.api_remote}, simulator at udp {p.hil}"
        )
        next_housekeeping = 0.0
        while self._running:
            now = time.monotonic()
            if deadline is not None and now > deadline:
                break
            if now >= next_housekeeping:
                next_housekeeping = now + HOUSEKEEPING_S
                self._refill_gcs_budgets()  # served even while no frame comes (simulator lost)
                self.send(core.tick(now))
                self.bus.publish_rows(force=now - core.simulator.last_frame_wall > HOUSEKEEPING_S)
                self.log_files.write(core)
                self.bus.poll()
            # Frames in quick succession (faster than real time): wait for the next one awake
            # (see quadcommon.wire.spin_until_readable); paced at real time, just block.
            gap = core.simulator.frame_gap_s
            if gap < SPIN_BELOW_GAP_S:
                wire.spin_until_readable(hil, min(spin_s, 3.0 * gap))
            selector = self.selector if any(self.gcs_budget.values()) else self.hil_only
            if self.impaired.endpoints_active:
                self._flush_impaired(time.monotonic())
                timeout = wait_s(HOUSEKEEPING_S, time.monotonic(), *self._next_due())
            else:
                timeout = HOUSEKEEPING_S
            for key, _ in selector.select(timeout):
                self._drain(key.data, key.fileobj)
        return 0

    def _refill_gcs_budgets(self) -> None:
        for link in self.gcs_budget:
            self.gcs_budget[link] = GCS_DATAGRAMS_PER_FRAME

    def _drain(self, link: int, sock) -> None:
        """What waits on one socket: every HIL datagram; from a ground-station link at most what is
        left of its budget for this frame (GCS_DATAGRAMS_PER_FRAME), so a flood on it cannot hold
        back the lockstep: the budgets refill with each frame."""
        core, hil_address = self.core, self.hil_address
        gcs_budget = self.gcs_budget
        while link == HIL_LINK or gcs_budget[link] > 0:
            try:
                data, address = sock.recvfrom(MAX_DATAGRAM)
            except (BlockingIOError, InterruptedError):
                return
            except OSError:
                continue  # ICMP unreachable from an earlier send (a peer not up yet): ignore
            now = time.monotonic()
            if link == HIL_LINK:
                if address != hil_address:
                    core.on_foreign_datagram("HIL datagram not from the simulator")
                    continue
                answer = core.on_hil_datagram(data, now)
                if answer is not None:
                    self.send([Outgoing(HIL_LINK, None, answer)])  # first: the simulator waits
                    self._refill_gcs_budgets()
                self.send(core.after_frame())
                self.bus.publish_rows()
            else:
                gcs_budget[link] -= 1
                for held, sender in self.receivers[link].received(data, address, now):
                    self.send(core.on_gcs_datagram(link, sender, held, now))
