"""The restart policy and the supervisor's decisions, without processes: fake children
print what the real ones print, and time is given (monotonic seconds), never slept.
Real processes killed with SIGKILL under ``quadsitl up``: test_up_process_loss.py.
"""

from __future__ import annotations

import signal

from sitl.launcher import VehicleSpec
from sitl.supervise import (
    DOWN,
    FINISHED,
    GAVE_UP,
    LINK_TIMEOUT_S,
    LINKING,
    UP,
    RestartPolicy,
    VehicleSupervisor,
    exit_reason,
)


class FakeChild:
    """What the supervisor uses of :class:`sitl.launcher.Child`."""

    pids = iter(range(1000, 100000))

    def __init__(self, name: str, cmd: list[str], started: float = 0.0) -> None:
        self.name, self.cmd, self.started, self.pid = name, cmd, started, next(self.pids)
        self.lines: list[str] = []
        self.returncode: int | None = None
        self.stopped = False

    @property
    def alive(self) -> bool:
        return self.returncode is None

    def print(self, line: str) -> None:
        self.lines.append(line)

    def lines_since(self, count: int) -> tuple[list[str], int]:
        return self.lines[count:], len(self.lines)

    def tail(self, n: int = 40) -> str:
        return "\n".join(self.lines[-n:])

    def stop(self, grace_s: float = 5.0) -> int:
        if self.returncode is None:
            self.returncode, self.stopped = -signal.SIGTERM, True
        return self.returncode


class Rig:
    """One vehicle under a supervisor; ``now`` advanced by hand."""

    def __init__(self, policy: RestartPolicy | None = None, spec: VehicleSpec | None = None) -> None:
        self.spec = spec or VehicleSpec(instance=80, autostart=True)
        self.now = 0.0
        self.said: list[str] = []
        self.spawned: list[FakeChild] = []
        sim = FakeChild("simulator[80]", self.spec.simulator_command())
        ap = FakeChild("autopilot[80]", self.spec.autopilot_command())
        self.sup = VehicleSupervisor(self.spec, sim, ap, policy or RestartPolicy(), self.respawn, self.say)

    def respawn(self, old: FakeChild, cmd: list[str]) -> FakeChild:
        assert not old.alive
        child = FakeChild(old.name, cmd, self.now)
        self.spawned.append(child)
        return child

    def say(self, text: str, error: bool = False) -> None:
        self.said.append(text)

    @property
    def sim(self) -> FakeChild:
        return self.sup.sim.child

    @property
    def ap(self) -> FakeChild:
        return self.sup.ap.child

    def at(self, t: float) -> Rig:
        self.now = t
        self.sup.poll(t)
        return self

    def text(self) -> str:
        return "\n".join(self.said)


def test_policy_delay_doubles_and_the_cap_counts_restarts_in_the_window():
    p = RestartPolicy()
    assert (p.max_restarts, p.window_s, p.first_delay_s) == (3, 60.0, 0.5)
    assert [p.delay_s([0.0] * k, 1.0) for k in range(5)] == [0.5, 1.0, 2.0, 4.0, 8.0]
    assert p.delay_s([0.0] * 10, 1.0) == p.max_delay_s
    assert p.allows([10.0, 20.0], 30.0) and not p.allows([10.0, 20.0, 25.0], 30.0)
    assert p.allows([10.0, 20.0, 25.0], 70.1)  # the first one left the window
    assert not RestartPolicy(enabled=False).allows([], 0.0)
    assert "at most 3 restarts per 60 s; --no-restart keeps it down" in p.describe()
    assert "stays down (--no-restart)" in RestartPolicy(enabled=False).describe()


def test_exit_reasons_name_the_signal_or_the_code():
    assert exit_reason(-signal.SIGKILL) == "killed by SIGKILL"
    assert exit_reason(-signal.SIGSEGV) == "killed by SIGSEGV"
    assert exit_reason(2) == "exited with code 2"


def test_a_lost_autopilot_restarts_only_once_the_simulator_has_landed_the_vehicle():
    rig = Rig()
    old = rig.ap
    rig.ap.returncode = -signal.SIGKILL
    rig.at(12.5)
    assert rig.said[0] == f"autopilot[80] lost: killed by SIGKILL after 12.5 s (pid {old.pid})"
    assert rig.sup.ap.state == DOWN and "simulator[80] keeps running: it lands the vehicle" in rig.text()
    rig.sim.print("simulator: autopilot lost: emergency descent from z=2.50 m at 0.5 m/s ...")
    rig.at(20.0)
    assert rig.spawned == []  # still descending: a new (disarmed) autopilot would cut the motors in the air
    rig.sim.print("simulator: emergency descent: touchdown at t=14.100 s, motors off")
    rig.at(20.1)
    assert len(rig.spawned) == 1 and rig.sup.ap.state == LINKING
    assert "--autostart" not in rig.ap.cmd and "-m" in rig.ap.cmd  # never takes off by itself again
    rig.ap.print("autopilot: linked with simulator (frames at t=14.200 s)")
    rig.at(20.2)
    assert rig.sup.ap.state == UP
    assert rig.said[-1] == "vehicle 80 relinked: autopilot restarted (1 restart so far)"


def test_a_disarmed_vehicle_is_on_the_ground_at_once_and_the_delay_still_applies():
    rig = Rig()
    rig.ap.returncode = -signal.SIGKILL
    rig.at(10.0)
    rig.sim.print("simulator: autopilot lost: vehicle disarmed, motors off; waiting for the autopilot")
    rig.at(10.3)
    assert rig.spawned == []  # 0.5 s after the loss at the earliest
    rig.at(10.6)
    assert len(rig.spawned) == 1


def test_a_lost_simulator_restarts_once_the_autopilot_reports_it_lost():
    rig = Rig()
    rig.sim.returncode = -signal.SIGKILL
    rig.at(5.0)
    assert "simulator[80] lost: killed by SIGKILL after 5.0 s" in rig.said[0]
    assert "autopilot[80] keeps running: it reports 'simulator lost'" in rig.text()
    rig.at(7.0)
    assert rig.spawned == []
    rig.ap.print(
        "autopilot: [t=  12.000] simulator lost: no sensor frame for 1 s (COM_SIM_LOSS_T); motors off"
    )
    rig.at(7.1)
    assert (
        len(rig.spawned) == 1 and rig.sup.sim.state == LINKING and rig.sim.cmd == rig.spec.simulator_command()
    )
    rig.ap.print("autopilot: simulator time went backwards: simulator restarted; resetting")
    rig.ap.print("autopilot: linked with simulator (frames at t=0.002 s)")
    rig.at(7.2)
    assert (
        rig.sup.sim.state == UP
        and rig.said[-1] == "vehicle 80 relinked: simulator restarted (1 restart so far)"
    )


def test_a_crash_loop_is_capped_and_the_survivor_keeps_running():
    rig = Rig(RestartPolicy(max_restarts=2))
    rig.ap.returncode = -signal.SIGKILL
    rig.at(1.0)
    rig.sim.print("simulator: autopilot lost: vehicle on the ground, motors off")
    t = 1.0
    for k in range(2):  # each restart dies at start (its port taken): code 2, its reason printed
        t += 10.0
        rig.at(t)
        assert len(rig.spawned) == k + 1
        rig.ap.print("autopilot: UDP port 18650 (GCS link) is already in use")
        rig.ap.returncode = 2
        rig.at(t + 0.5)
    assert rig.sup.ap.state == GAVE_UP and rig.sup.sim.state == UP and rig.sim.alive
    assert "autopilot[80] lost: exited with code 2 after 0.5 s" in rig.text()
    assert "    | autopilot: UDP port 18650 (GCS link) is already in use" in rig.text()
    assert (
        "giving up on autopilot[80]: lost 3 times within 60 s (at most 2 restarts per 60 s)" in rig.said[-1]
    )
    assert "the survivor keeps running" in rig.said[-1]
    rig.at(100.0)
    assert len(rig.spawned) == 2 and rig.sup.active and not rig.sup.whole


def test_no_restart_leaves_the_lost_process_down():
    rig = Rig(RestartPolicy(enabled=False))
    rig.sim.returncode = 1
    rig.at(3.0)
    rig.ap.print(
        "autopilot: [t=   3.000] simulator lost: no sensor frame for 1 s (COM_SIM_LOSS_T); motors off"
    )
    rig.at(30.0)
    assert rig.spawned == [] and rig.sup.sim.state == GAVE_UP and rig.ap.alive
    assert (
        "not restarting simulator[80] (--no-restart); the survivor keeps running; Ctrl-C stops" in rig.text()
    )
    rig.ap.returncode = -signal.SIGKILL  # then the survivor dies too: nothing left
    rig.at(31.0)
    assert not rig.sup.active and rig.said[-1] == "vehicle 80 has no process left running"


def test_the_simulator_reaching_duration_ends_the_run_normally():
    rig = Rig(spec=VehicleSpec(instance=80, duration_s=5.0))
    rig.sim.returncode = 0
    rig.at(4.0)
    assert rig.sup.sim.state == FINISHED and rig.sup.ap.state == FINISHED and rig.ap.stopped
    assert rig.said == ["vehicle 80: the simulator reached --duration 5 s"]
    assert not rig.sup.active and rig.sup.whole and rig.spawned == []


def test_a_clean_exit_without_duration_is_a_loss():
    rig = Rig(spec=VehicleSpec(instance=80))
    rig.sim.returncode = 0  # someone stopped the simulator: its vehicle lost it
    rig.at(4.0)
    assert rig.sup.sim.state == DOWN and "exited with code 0" in rig.said[0]


def test_both_lost_restart_as_a_fresh_start():
    rig = Rig()
    rig.sim.returncode = rig.ap.returncode = -signal.SIGKILL
    rig.at(2.0)
    rig.at(2.6)
    assert [c.name for c in rig.spawned] == ["simulator[80]", "autopilot[80]"]
    rig.ap.print("autopilot: linked with simulator (frames at t=0.000 s)")
    rig.at(6.0)
    assert rig.sup.sim.state == UP and rig.sup.ap.state == UP
    assert rig.said[-1].startswith(
        "vehicle 80 relinked: simulator restarted (1 restart so far) and autopilot"
    )


def test_a_restart_that_does_not_link_is_stopped_and_counts_as_lost():
    rig = Rig()
    rig.ap.returncode = -signal.SIGKILL
    rig.at(1.0)
    rig.sim.print("simulator: autopilot lost: vehicle disarmed, motors off")
    rig.at(2.0)
    stuck = rig.ap
    rig.at(2.0 + LINK_TIMEOUT_S + 0.1)
    assert stuck.stopped and rig.sup.ap.state == DOWN
    assert f"autopilot[80] did not link within {LINK_TIMEOUT_S:g} s of its restart; stopping it" in rig.text()
    rig.at(2.0 + LINK_TIMEOUT_S + 2.0)  # second restart after 1 s (doubled)
    assert len(rig.spawned) == 2
