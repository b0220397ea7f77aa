"""The whole flight stack in-process for tests: a Lockstep (simulator core + autopilot core, real
MAVLink bytes) and ground-station clients on it, all in simulation time."""

from __future__ import annotations

from dataclasses import replace

from autopilot.control.config import load_controller
from autopilot.core import AutopilotSetup
from autopilot.logger.logger import LogOptions
from gcs_scripts.link import Link
from gcs_scripts.view.telemetry import StatusTextAssembler
from quadcommon.config import estimator_profile_for
from simulator.core import SimulatorSetup
from sitl.inprocess import API_LINK, Lockstep, StackConnection


def sequence_gaps(messages: list) -> list[tuple[int, int]]:
    """(previous, next) for every pair of consecutive frames whose sequence numbers do not follow
    one another (modulo 256): what pymavlink, MAVProxy and QGroundControl count as lost."""
    seqs = [msg.get_seq() for msg in messages if msg.get_type() != "BAD_DATA"]
    return [(a, b) for a, b in zip(seqs, seqs[1:], strict=False) if b != (a + 1) % 256]


def make_stack(
    scenario: str = "hover",
    controller: str = "intbs_nlhinf",
    params_file: str | None = None,
    sensors: str | None = None,
    vehicle: str | None = None,
    log=lambda text: None,
    log_dir: str | None = None,
    estimator: str = "truth",
    battery: dict | None = None,
    **sitl_changes,
) -> Lockstep:
    """A vehicle on the ground (or where ``scenario`` puts it), nothing armed, no client yet;
    ``log_dir``: its flight logs (ULog) go there (default: no flight log); ``estimator="ekf"``:
    it flies on its EKF, with the filter's parameters for ``sensors`` (as ``quadsitl up``);
    ``battery``: changes to the vehicle's ``[battery]`` (``BatteryConfig`` fields), for both
    processes."""
    sim = SimulatorSetup.load(scenario=scenario, vehicle=vehicle, sensors=sensors)
    if battery:
        sim = replace(sim, vehicle=replace(sim.vehicle, battery=replace(sim.vehicle.battery, **battery)))
    if sitl_changes:
        sim = replace(sim, sitl=replace(sim.sitl, **sitl_changes))
    profile = estimator_profile_for(sensors or "default") if estimator == "ekf" else "default"
    ap = AutopilotSetup(sim.sitl, sim.vehicle, load_controller(controller), params_file=params_file,
                        default_remotes=False, log=LogOptions(log_dir), estimator=estimator,
                        estimator_profile=profile)  # fmt: skip
    return Lockstep(sim, ap, log=log)


def connect(stack: Lockstep, link_class=Link, link: int = API_LINK, **kw):
    """A gcs_scripts client (Link or a subclass) on the stack, after the vehicle's first heartbeat."""
    client = link_class(StackConnection(stack, link), 0, **kw)
    client.wait_heartbeat(5.0)
    return client


class Gcs:
    """A minimal pymavlink ground station on the stack's API link, timed by simulation time (the
    in-process counterpart of a UDP client: the same messages, no sockets, no wall clock)."""

    def __init__(self, stack: Lockstep, link: int = API_LINK) -> None:
        self.stack = stack
        self.conn = StackConnection(stack, link)
        self.system_id = stack.autopilot.system_id
        self.last: dict[str, object] = {}
        self.statustext: list[str] = []
        self._texts = StatusTextAssembler()
        self.acks: list = []

    @property
    def sim_time(self) -> float:
        return self.stack.t

    def close(self) -> None:
        self.conn.close()

    def poll(self):
        """The next message from the vehicle (stepping one frame when none is waiting), or None."""
        msg = self.conn.recv_msg()
        if msg is None or msg.get_srcSystem() != self.system_id:
            return msg
        kind = msg.get_type()
        self.last[kind] = msg
        if kind == "STATUSTEXT":  # a long text comes in chunks: recorded once whole
            raw = msg.text.encode("utf-8", "replace") if isinstance(msg.text, str) else bytes(msg.text)
            for _, text in self._texts.add(msg.severity, raw, msg.id, msg.chunk_seq):
                self.statustext.append(text)
        elif kind == "COMMAND_ACK":
            self.acks.append(msg)
        return msg

    def wait(self, predicate, sim_timeout: float = 30.0, what: str = ""):
        """Poll until ``predicate(self)``; AssertionError after ``sim_timeout`` s of simulation."""
        end = self.stack.t + sim_timeout
        while self.stack.t <= end:
            self.poll()
            if predicate(self):
                return
        raise AssertionError(f"timed out waiting for {what or predicate} (sim t={self.stack.t:.2f} s)")

    def wait_heartbeat(self) -> None:
        self.wait(lambda g: "HEARTBEAT" in g.last, sim_timeout=2.0, what="heartbeat")

    def command(self, command: int, *params: float, sim_timeout: float = 0.5):
        """COMMAND_LONG; returns the COMMAND_ACK (fails if none within ``sim_timeout``)."""
        p = list(params) + [0.0] * (7 - len(params))
        self.acks.clear()
        self.conn.mav.command_long_send(self.system_id, 1, command, 0, *p)
        self.wait(lambda g: any(a.command == command for a in g.acks), sim_timeout, f"COMMAND_ACK {command}")
        return next(a for a in self.acks if a.command == command)

    @property
    def armed(self) -> bool:
        hb = self.last.get("HEARTBEAT")
        return bool(hb and hb.base_mode & 128)

    @property
    def custom_mode(self) -> int:
        hb = self.last.get("HEARTBEAT")
        return hb.custom_mode if hb else -1

    def position(self) -> tuple[float, float, float]:
        """Last LOCAL_POSITION_NED in the paper frame (x, y left, z up)."""
        lp = self.last["LOCAL_POSITION_NED"]
        return (lp.x, -lp.y, -lp.z)

    def send_position_setpoint(self, x: float, y: float, z: float) -> None:
        """A position-only setpoint in the paper frame."""
        mask = 8 | 16 | 32 | 64 | 128 | 256 | 1024 | 2048
        self.conn.mav.set_position_target_local_ned_send(
            int(self.sim_time * 1000), self.system_id, 1, 1, mask, x, -y, -z, 0, 0, 0, 0, 0, 0, 0, 0
        )
