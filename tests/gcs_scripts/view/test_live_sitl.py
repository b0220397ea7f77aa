"""The view's live source against a real vehicle (no browser): ports, rates, telemetry, failsafe.

A real SITL (instance 66: simulator + autopilot processes, real UDP and zenoh) at ``--speed 2``
(ticks of the view wait on the wall clock: a faster vehicle takes more of the cores from the rest
of the suite for the module's whole run, to fly the same checks); the view's :class:`LiveSource`
ticked as the server ticks it. A socket on the ground-station port 14550 stands for
QGroundControl, bound before the view starts.
"""

from __future__ import annotations

import json
import socket
import sys
import threading
import time

import pytest

from gcs_scripts import link as mavlink_link
from gcs_scripts.view.live import VIEW_SYSTEM_ID
from gcs_scripts.view.server import LiveSource
from quadcommon import wire
from sitl.launcher import Child, Launcher, VehicleSpec
from tests.ports import instance_ports

pytestmark = [pytest.mark.processes, pytest.mark.timeout(180)]
INSTANCE = 66  # of the view tests: 65-69 (tests/gcs_scripts/test_e2e_sitl.py uses 60-62)
SPEED = "2"


@pytest.fixture(scope="module")
def vehicle():
    with Launcher() as launcher:
        launcher.start_vehicles([VehicleSpec(instance=INSTANCE, speed=SPEED)])
        yield launcher


def _tick_until(source: LiveSource, predicate, wall_s: float, period_s: float = 1 / 30) -> list[dict]:
    """Tick like the server does; returns the frames, stops when ``predicate(frames)``."""
    frames: list[dict] = []
    deadline = time.monotonic() + wall_s
    while time.monotonic() < deadline:
        frames += [m for m in source.tick(time.monotonic()) if m["type"] == "frame"]
        if predicate(frames):
            return frames
        time.sleep(period_s)
    raise AssertionError(f"condition not met within {wall_s} s; last frame: {json.dumps(frames[-1:])[:800]}")


def test_view_is_a_peer_on_its_own_port_and_leaves_the_ground_station_port_alone(vehicle):
    ports = instance_ports(INSTANCE)
    qgc = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    qgc.bind(("127.0.0.1", ports.gcs_remote))  # as QGC would: must stay possible with the view running
    qgc.settimeout(3.0)
    source = LiveSource([INSTANCE])
    source.open()
    try:
        v = source.vehicles[0]
        assert v.mavlink_port not in (ports.gcs_remote, ports.api_remote)
        frames = _tick_until(source, lambda f: f and f[-1]["v"][0]["st"]["mode"], 15.0)
        assert frames[-1]["v"][0]["st"]["linked"]
        # The heartbeats keep going (one per wall second) and the autopilot keeps streaming to us.
        sent, decoded = v.heartbeats_sent, v.decoded
        _tick_until(source, lambda f: v.heartbeats_sent >= sent + 2 and v.decoded > decoded + 2, 5.0)
        data, _ = qgc.recvfrom(65535)  # QGC's port still gets the vehicle's telemetry
        assert data[0] == 0xFD and data[5] == wire.system_id(INSTANCE)
        assert VIEW_SYSTEM_ID not in (255, wire.system_id(INSTANCE))
    finally:
        source.close()
        qgc.close()


def test_frames_carry_decimated_samples_and_the_description(vehicle):
    source = LiveSource([INSTANCE])
    source.open()
    try:
        period = 1 / 30
        start = time.monotonic()
        frames = _tick_until(source, lambda f: len(f) >= 60, 10.0, period)
        wall = time.monotonic() - start
        with_sample = [f for f in frames if f["v"][0]["s"] is not None]
        assert len(with_sample) >= 0.8 * len(frames)
        assert len(frames) <= wall / period + 2  # one frame per tick at most: <= 30 Hz
        times = [f["v"][0]["s"]["t"] for f in with_sample]
        assert times == sorted(times) and len(set(times)) == len(times)
        # Each sample is the newest at its tick, however many control steps passed in between
        # (~33 at --speed 2: 1,000 steps per wall second, 30 ticks): the view decimates, it does
        # not queue.
        assert source.vehicles[0].sampler.truth_rows > 3 * len(with_sample)
        sample = with_sample[-1]["v"][0]["s"]
        assert len(sample["p"]) == 3 and len(sample["q"]) == 4 and sample["ground"] is True
        tracks = source.tracks()
        _tick_until(source, lambda f: source.vehicles[0].describe()["controller"], 10.0)
        assert source.tracks()[0]["controller"] == "intbs_nlhinf" and tracks[0]["instance"] == INSTANCE
    finally:
        source.close()


class Ticker:
    """Ticks a LiveSource at 30 Hz in a thread (as the server does) while the test flies."""

    def __init__(self, source: LiveSource) -> None:
        self.source = source
        self.frames: list[dict] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.wait(1 / 30):
            self.frames += [m for m in self.source.tick(time.monotonic()) if m["type"] == "frame"]

    def wait(self, predicate, wall_s: float) -> None:
        deadline = time.monotonic() + wall_s
        while time.monotonic() < deadline:
            if self.frames and predicate(self.frames[-1]["v"][0]["st"]):
                return
            time.sleep(0.02)
        last = self.frames[-1]["v"] if self.frames else None
        raise AssertionError(f"not within {wall_s} s; last status {last}")

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(5.0)


def test_offboard_loss_shows_as_the_active_failsafe_until_the_pilot_takes_over(vehicle):
    source = LiveSource([INSTANCE])
    source.open()
    ticker = Ticker(source)
    link = mavlink_link.connect(instance=INSTANCE)
    try:
        ticker.wait(lambda st: st["linked"], 10.0)
        link.arm()
        link.takeoff(2.0)
        link.wait_until(lambda lk: lk.position_paper and lk.position_paper[2] > 1.8, 20.0, what="climb")
        link.wait_mode("AUTO.LOITER", 15.0)
        x, y, _ = link.position_paper
        link.send_target(mavlink_link.PositionTarget((x, y, 2.0)))
        link.set_mode("OFFBOARD")  # one fresh setpoint is enough to enter; then nothing follows
        ticker.wait(lambda st: st["failsafe"] == "offboard loss", 10.0)
        texts = [t[3] for f in ticker.frames for t in f["texts"]]
        assert "armed" in texts and any(t.startswith("offboard setpoints lost") for t in texts), texts
        link.land()  # the pilot takes over: the failsafe is over
        ticker.wait(lambda st: st["mode"] == "AUTO.LAND" and st["failsafe"] is None, 10.0)
        link.wait_until(lambda lk: not lk.armed, 60.0, what="landing and disarm")
        ticker.wait(lambda st: st["armed"] is False and st["landed"] == "ON_GROUND", 10.0)
    finally:
        ticker.stop()
        link.close()
        source.close()


def test_a_fleet_beside_a_vehicle_in_one_page_each_with_its_colour(vehicle):
    """Beside the first vehicle (two processes), a fleet of two (instances 68 and 69, one process,
    `quadsitl fleet --zenoh --spacing 3`): one scene, one card and one colour each, and each fleet
    vehicle drawn about its own home, 3 m x its instance north of the configured one."""
    from .helpers import ARTIFACTS, browser_page, served, view_state

    fleet = (68, 69)
    # At a finite speed, as the fixture's: one at max would take a core from Chromium (2 cores here;
    # the page then took > 60 s to start under the rest of the suite). Colours and cards do not
    # depend on the speed.
    child = Child("quadsitl fleet", [sys.executable, "-u", "-m", "sitl.cli", "fleet", "--count", "2",
                                     "--instance", str(fleet[0]), "--zenoh", "--speed", "4", "--spacing", "3",
                                     "--scenario", "circle", "--autostart", "circle"])  # fmt: skip
    try:
        child.wait_line("vehicles, instances", timeout=60.0)
        source = LiveSource([INSTANCE, *fleet])
        with served(source) as server, browser_page(server.url) as page:
            page.wait_for_function(
                "() => { const s = window.quadsitlView; return s.tracks.length === 3"
                " && s.tracks.every(t => t.cols.t.length > 5 && t.obj.body.visible && t.desc.offset_m); }",
                timeout=30000,
            )
            state = view_state(page)
            colours = page.evaluate("() => window.quadsitlView.tracks.map(t => t.color)")
            where = "() => window.quadsitlView.tracks.map(t => t.obj.group.position.toArray())"
            placed = page.evaluate(where)  # each vehicle's frame in the scene (m)
            target = page.evaluate("() => window.quadsitlView.cameraTarget")  # framed about the homes
            cards = page.locator(".card").all_inner_texts()
            ARTIFACTS.mkdir(parents=True, exist_ok=True)
            page.screenshot(path=str(ARTIFACTS / "live_fleet_beside_a_vehicle.png"))
    finally:
        child.stop()
    assert len(set(colours)) == 3
    assert placed[0] == [0, 0, 0]  # the first vehicle's frame is the scene's
    for (x, y, z), n in zip(placed[1:], fleet, strict=True):
        assert x == pytest.approx(3.0 * n, abs=0.01) and abs(y) < 0.01 and abs(z) < 0.01
    # The homes 0 m and 204-207 m north: the first view would show only the first vehicle, so the
    # page frames them all (the first view's few metres about each home: x from -1 to 210 m).
    assert target is not None and target[0] == pytest.approx((-1.0 + 3.0 * fleet[1] + 3.0) / 2, abs=0.01)
    for card, n in zip(cards, (INSTANCE, *fleet), strict=True):
        assert f"vehicle {n}" in card
    assert all(n > 5 for n in state["samples"]) and state["errors"] == []
    assert child.returncode == 0, child.tail()


def test_cpu_priority_yields_only_while_the_simulation_runs_much_faster_than_real_time(monkeypatch):
    from gcs_scripts.view.live import CpuPriority

    policies: list[int] = []
    p = CpuPriority(enabled=True)
    monkeypatch.setattr(p, "_set", lambda policy: (policies.append(policy), setattr(p, "idle", policy != 0)))
    wall, sim = 0.0, 0.0
    for rtf, seconds in ((1.0, 6), (2.0, 6), (12.0, 6), (3.5, 6), (1.0, 6)):
        for _ in range(int(seconds / 0.5)):
            wall += 0.5
            sim += 0.5 * rtf
            p.update(wall, sim)
    import os

    assert policies == [os.SCHED_IDLE, os.SCHED_OTHER]  # into idle at 12x; 3.5x stays (hysteresis); out at 1x
    assert p.rtf == pytest.approx(1.0)
    off = CpuPriority(enabled=False)
    for k in range(20):
        off.update(k * 0.5, k * 6.0)
    assert not off.idle and off.rtf == pytest.approx(12.0)
