"""Process loss under ``quadsitl up``: the survivor's failsafe acts, then the lost process restarts.

Each vehicle is two processes, and each one has a failsafe for losing the other (docs/parameters.md,
"Failsafes"): the simulator lands the vehicle when its autopilot stops answering
(``[lockstep] timeout_s``, 2 s wall), and the autopilot announces "simulator lost" and keeps
answering ground stations when frames stop (``COM_SIM_LOSS_T``, 1 s wall). So when one process
dies the supervisor leaves the other one running and:

1. reports which process died, why (``killed by SIGKILL``, ``exited with code 1`` and its last
   output lines) and how long it ran;
2. waits for the survivor's failsafe to act, read from the survivor's own output: the simulator
   reports the vehicle on the ground (``autopilot lost: vehicle disarmed / on the ground`` or
   ``emergency descent: touchdown``); the autopilot reports ``simulator lost`` (at most
   :data:`SIM_LOSS_WAIT_S`: its parameter may be set up to 30 s). A restarted autopilot starts
   disarmed, so starting it while the simulator still descends would switch the motors off in
   the air: it is started only once the vehicle is down;
3. restarts the lost process after a delay (:class:`RestartPolicy`: 0.5 s, doubling with each
   restart in the last minute; at most 3 restarts per 60 s, then the process stays down and the
   survivor keeps running); ``--no-restart`` keeps every lost process down. A restarted
   autopilot never gets ``--autostart`` (it must not take off by itself from where the simulator
   landed the vehicle); a restarted simulator starts a new flight at t = 0 (the autopilot sees its
   clock go backwards, disarms and resets);
4. prints ``quadsitl: vehicle N relinked (... restarted ...)`` once the two processes are linked
   again (the line a script waits for); a restarted process that does not link within
   :data:`LINK_TIMEOUT_S` is stopped and counts as lost again.

A simulator that exits with code 0 while ``--duration`` is set has reached it: the vehicle's run
is over (its autopilot is stopped); ``quadsitl up`` ends when every vehicle is over or has no
process left. Every other exit (a signal, a non-zero code, an autopilot ending on its own) is a
loss. The supervisor never blocks: :meth:`Supervisor.poll` is called from the foreground loop.
"""

from __future__ import annotations

import dataclasses
import signal
import sys
import threading
import time
from collections import deque
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from .launcher import LINKED, Child, Launcher, VehicleSpec

SIM, AP = "simulator", "autopilot"
LINK_TIMEOUT_S = 30.0  # wall: a restarted process must link within this
SIM_LOSS_WAIT_S = 35.0  # wall: longest wait for the autopilot's "simulator lost" (COM_SIM_LOSS_T <= 30 s)

# What the processes print, read here (simulator/core.py, simulator/app.py, autopilot/core.py).
SIM_ON_GROUND = ("simulator: autopilot lost: vehicle", "simulator: emergency descent: touchdown")
SIM_AP_BACK = ("simulator: link recovered", LINKED)
AP_SIM_LOST = "simulator lost: "
AP_LINKED = "autopilot: linked with simulator"

UP, LINKING, DOWN, GAVE_UP, FINISHED = "up", "linking", "down", "gave up", "finished"


@dataclass(frozen=True)
class RestartPolicy:
    """When a lost process is started again: after ``first_delay_s`` doubled for each restart in
    the last ``window_s`` (at most ``max_delay_s``), at most ``max_restarts`` per ``window_s``."""

    enabled: bool = True
    max_restarts: int = 3
    window_s: float = 60.0
    first_delay_s: float = 0.5
    max_delay_s: float = 8.0

    def recent(self, restarts: Sequence[float], now: float) -> int:
        """Restarts within the window ending at ``now`` (monotonic seconds)."""
        return sum(1 for t in restarts if now - t < self.window_s)

    def allows(self, restarts: Sequence[float], now: float) -> bool:
        """Whether another restart is allowed: enabled, and fewer than ``max_restarts`` in the window."""
        return self.enabled and self.recent(restarts, now) < self.max_restarts

    def delay_s(self, restarts: Sequence[float], now: float) -> float:
        """The wait before the next restart (s): ``first_delay_s`` doubled for each recent restart, at most
        ``max_delay_s``."""
        return min(self.first_delay_s * 2.0 ** self.recent(restarts, now), self.max_delay_s)

    def describe(self) -> str:
        """The banner's sentence."""
        if not self.enabled:
            return ("  Process loss: the survivor keeps running and its failsafe acts; the lost process "
                    "stays down (--no-restart).")  # fmt: skip
        return (f"  Process loss: the survivor keeps running and its failsafe acts, then the lost process "
                f"is restarted (at most {_restarts(self.max_restarts)} per {self.window_s:g} s; "
                f"--no-restart keeps it down).")  # fmt: skip


def exit_reason(returncode: int) -> str:
    """``killed by SIGKILL``, ``exited with code 2``."""
    if returncode < 0:
        try:
            return f"killed by {signal.Signals(-returncode).name}"
        except ValueError:
            return f"killed by signal {-returncode}"
    return f"exited with code {returncode}"


def _restarts(n: int) -> str:
    return f"{n} restart" + ("" if n == 1 else "s")


_OUTPUT = threading.Lock()


def stop_on_signals() -> threading.Event:
    """An event that Ctrl-C (SIGINT) or SIGTERM sets: a foreground command's loop runs until it is
    set, then stops its processes or vehicles cleanly."""
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    return stop


def write_line(text: str, error: bool = False) -> None:
    """One whole line on stdout (stderr if ``error``), never interleaved with another thread's: the
    children's output is echoed by reader threads while the supervisor reports."""
    stream = sys.stderr if error else sys.stdout
    with _OUTPUT:
        stream.write(text + "\n")
        stream.flush()


def _say(text: str, error: bool = False) -> None:
    write_line(f"quadsitl: {text}", error)


@dataclass
class _Slot:
    """One of a vehicle's two processes, as the supervisor sees it."""

    role: str
    child: Child
    state: str = UP
    seen: int = 0  # output lines already scanned
    down_at: float = 0.0
    restart_at: float = 0.0
    restarts: deque[float] = dataclasses.field(default_factory=lambda: deque(maxlen=64))  # times
    restarted: int = 0  # in all

    @property
    def name(self) -> str:
        return self.child.name


class VehicleSupervisor:
    """Simulator + autopilot of one vehicle: loss, failsafe, restart, relink."""

    def __init__(
        self,
        spec: VehicleSpec,
        simulator: Child,
        autopilot: Child,
        policy: RestartPolicy,
        respawn: Callable[[Child, list[str]], Child],
        say: Callable[..., None] = _say,
    ) -> None:
        self.spec, self.policy, self.respawn, self.say = spec, policy, respawn, say
        self.sim, self.ap = _Slot(SIM, simulator), _Slot(AP, autopilot)
        self.on_ground = False  # the simulator reports the vehicle down after losing its autopilot
        self.sim_lost = False  # the autopilot reports the simulator lost
        self.losses = 0

    @property
    def instance(self) -> int:
        """The supervised vehicle's instance N."""
        return self.spec.instance

    @property
    def active(self) -> bool:
        """Something still runs or will be restarted."""
        return any(s.state in (UP, LINKING, DOWN) for s in (self.sim, self.ap))

    @property
    def whole(self) -> bool:
        """Both processes up (or the run is over): nothing lost for good."""
        return all(s.state in (UP, LINKING, FINISHED) for s in (self.sim, self.ap))

    def _command(self, role: str) -> list[str]:
        if role == SIM:
            return self.spec.simulator_command()
        return dataclasses.replace(self.spec, autostart=False).autopilot_command()

    def _scan(self) -> None:
        """Follow the survivor's output: has its failsafe acted?"""
        lines, self.sim.seen = self.sim.child.lines_since(self.sim.seen)
        for line in lines:
            if any(needle in line for needle in SIM_ON_GROUND):
                self.on_ground = True
            elif any(needle in line for needle in SIM_AP_BACK):
                self.on_ground = False
        lines, self.ap.seen = self.ap.child.lines_since(self.ap.seen)
        for line in lines:
            if AP_SIM_LOST in line:
                self.sim_lost = True
            elif AP_LINKED in line:
                self.sim_lost = False
                if self.ap.state == LINKING or self.sim.state == LINKING:
                    self._relinked()

    def _relinked(self) -> None:
        what = " and ".join(f"{s.role} restarted ({_restarts(s.restarted)} so far)"
                            for s in (self.sim, self.ap) if s.state == LINKING)  # fmt: skip
        self.sim.state = UP if self.sim.state == LINKING else self.sim.state
        self.ap.state = UP if self.ap.state == LINKING else self.ap.state
        self.say(f"vehicle {self.instance} relinked: {what}")

    def poll(self, now: float) -> None:
        """Check both processes at monotonic time ``now`` (s): note exits and restarts that never linked,
        and restart when due."""
        self._scan()
        for slot in (self.sim, self.ap):
            if slot.state in (UP, LINKING) and not slot.child.alive:
                self._exited(slot, now)
            elif slot.state == LINKING and now - slot.child.started > LINK_TIMEOUT_S:
                self.say(f"{slot.name} did not link within {LINK_TIMEOUT_S:g} s of its restart; stopping it",
                         error=True)  # fmt: skip
                slot.child.stop(2.0)
                self._lost(slot, now, f"did not link within {LINK_TIMEOUT_S:g} s")
        self._restart_due(now)

    def _exited(self, slot: _Slot, now: float) -> None:
        rc = slot.child.returncode
        assert rc is not None
        if slot.role == SIM and rc == 0 and self.spec.duration_s is not None:
            self.say(f"vehicle {self.instance}: the simulator reached --duration {self.spec.duration_s:g} s")
            self.sim.state = FINISHED
            if self.ap.child.alive:
                self.ap.child.stop()
            self.ap.state = FINISHED
            return
        why = exit_reason(rc)
        if rc > 0:
            tail = [line for line in slot.child.tail(3).splitlines() if line.strip()]
            why += "".join(f"\n    | {line}" for line in tail)
        self._lost(slot, now, why)

    def _lost(self, slot: _Slot, now: float, why: str) -> None:
        self.losses += 1
        ran = now - slot.child.started
        first, *rest = why.split("\n", 1)
        detail = f"\n{rest[0]}" if rest else ""
        self.say(f"{slot.name} lost: {first} after {ran:.1f} s (pid {slot.child.pid}){detail}", error=True)
        other = self.ap if slot.role == SIM else self.sim
        if other.state in (UP, LINKING):
            if slot.role == AP:
                self.say(f"{other.name} keeps running: it lands the vehicle ([lockstep] timeout_s)")
            else:
                self.say(f"{other.name} keeps running: it reports 'simulator lost' (COM_SIM_LOSS_T) and "
                         "keeps answering ground stations")  # fmt: skip
        if not self.policy.enabled:
            slot.state = GAVE_UP
            survivor = "the survivor keeps running; " if other.state in (UP, LINKING) else ""
            self.say(f"not restarting {slot.name} (--no-restart); {survivor}Ctrl-C stops", error=True)
        elif not self.policy.allows(slot.restarts, now):
            slot.state = GAVE_UP
            p = self.policy
            self.say(f"giving up on {slot.name}: lost {p.recent(slot.restarts, now) + 1} times within "
                     f"{p.window_s:g} s (at most {_restarts(p.max_restarts)} per {p.window_s:g} s); "
                     f"{'the survivor keeps running; ' if other.state in (UP, LINKING) else ''}Ctrl-C stops",
                     error=True)  # fmt: skip
        else:
            slot.state, slot.down_at = DOWN, now
            slot.restart_at = now + self.policy.delay_s(slot.restarts, now)
            n = self.policy.recent(slot.restarts, now) + 1
            when = ("once the simulator reports the vehicle on the ground" if slot.role == AP
                    else "once the autopilot reports the simulator lost")  # fmt: skip
            self.say(f"{slot.name} will be restarted {when}, {slot.restart_at - now:.1f} s after the loss at "
                     f"the earliest (restart {n} of at most {self.policy.max_restarts} per "
                     f"{self.policy.window_s:g} s)")  # fmt: skip
        if other.state == GAVE_UP and slot.state == DOWN or slot.state == GAVE_UP and other.state == DOWN:
            for s in (self.sim, self.ap):
                if s.state == DOWN:
                    s.state = GAVE_UP
                    self.say(f"not restarting {s.name}: its partner stays down", error=True)
        if not self.active:
            self.say(f"vehicle {self.instance} has no process left running", error=True)

    def _restart_due(self, now: float) -> None:
        sim, ap = self.sim, self.ap
        # The simulator: with its autopilot down too (a fresh start), restarted (not linked yet, it
        # says hello anyway), or once the autopilot has noticed the loss (it then says hello).
        ap_ready = ap.state in (DOWN, LINKING) or self.sim_lost or now - sim.down_at > SIM_LOSS_WAIT_S
        if sim.state == DOWN and now >= sim.restart_at and ap_ready:
            self._restart(sim, now)
            self.on_ground = False
        # The autopilot: once its simulator has put the vehicle on the ground, or a new simulator.
        sim_ready = sim.state == LINKING or (sim.state == UP and self.on_ground)
        if ap.state == DOWN and now >= ap.restart_at and sim_ready:
            self._restart(ap, now)
            self.sim_lost = False

    def _restart(self, slot: _Slot, now: float) -> None:
        n = self.policy.recent(slot.restarts, now) + 1
        slot.restarts.append(now)
        slot.restarted += 1
        slot.child = self.respawn(slot.child, self._command(slot.role))
        slot.state, slot.seen = LINKING, 0
        self.say(f"restarting {slot.name} (pid {slot.child.pid}; restart {n} of at most "
                 f"{self.policy.max_restarts} per {self.policy.window_s:g} s)")  # fmt: skip


class Supervisor:
    """Every vehicle of one ``quadsitl up`` (see the module's docstring)."""

    def __init__(self, launcher: Launcher, specs: Sequence[VehicleSpec], policy: RestartPolicy,
                 say: Callable[..., None] = _say) -> None:  # fmt: skip
        self.vehicles = [
            VehicleSupervisor(spec, launcher.child(f"{SIM}[{spec.instance}]"),
                              launcher.child(f"{AP}[{spec.instance}]"), policy, launcher.respawn, say)
            for spec in specs
        ]  # fmt: skip

    def poll(self, now: float | None = None) -> None:
        """Poll every vehicle at monotonic time ``now`` (s; default the clock's)."""
        now = time.monotonic() if now is None else now
        for vehicle in self.vehicles:
            vehicle.poll(now)

    @property
    def active(self) -> bool:
        """Some vehicle still has a process running or to be restarted."""
        return any(v.active for v in self.vehicles)

    @property
    def whole(self) -> bool:
        """Every vehicle has both processes up (or its run is over): nothing lost for good."""
        return all(v.whole for v in self.vehicles)
