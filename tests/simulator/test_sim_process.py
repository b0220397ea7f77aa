"""The simulator process over real UDP (and zenoh) with a scripted autopilot peer: what only the
process does (linking, wall-clock timeouts, zenoh, signals, ports). Frames, lockstep rules and the
emergency descent are tested on the core in simulation time (test_core.py).

Each test starts ``python -m simulator`` on its own instance (40-59) and bounds every wait.
"""

from __future__ import annotations

import json
import signal
import socket
import time

import pytest

from quadcommon import bus, frames, wire
from quadcommon.bus_records import TRUTH_CODEC, TRUTH_FIELDS
from quadcommon.config import load_sitl
from tests.ports import instance_ports

from .sim_harness import ScriptedAutopilot, SimProcess, sitl_toml_with

pytestmark = pytest.mark.processes  # (tests/conftest.py: the markers)

RATES = load_sitl().rates
FRAME_USEC = round(1e6 / RATES.control_hz)
HOME = load_sitl().home


def test_timeout_is_reported_then_simulation_goes_on_and_link_recovers(tmp_path):
    """A missing answer is reported once; the simulator then steps on by itself (autopilot lost:
    disarmed on the ground here, motors off) and resumes lockstep at the autopilot's next answer."""
    sitl = sitl_toml_with(tmp_path, timeout_s=0.3)
    with SimProcess(42, "--sitl-config", str(sitl)) as sim, ScriptedAutopilot(42) as ap:
        frame = ap.link()
        for _ in range(3):
            frame = ap.step(frame)
        stuck = frame.time_usec
        line = sim.wait_line("no HIL_ACTUATOR_CONTROLS", timeout=3.0)
        assert f"t={stuck * 1e-6:.3f} s within 0.3 s" in line
        assert f"udp 127.0.0.1:{instance_ports(42).hil}" in line and "autopilot running" in line
        sim.wait_line("autopilot lost: vehicle disarmed, motors off", timeout=1.0)
        # Until then the unanswered frame was sent again every [lockstep] resend_s (byte for byte)
        resent, later = 0, []
        while len(later) < 3 and (f := ap.recv_frame(1.0)) is not None and resent < 1000:
            if f.time_usec == stuck:
                resent += 1
            else:
                later.append(f)
        assert len(later) == 3 and 10 <= resent <= 31  # 0.3 s / 10 ms, fewer on a loaded machine
        assert stuck < later[0].time_usec < later[1].time_usec < later[2].time_usec  # time goes on
        assert later[-1]["ODOMETRY"].z == 0.0  # still resting on the ground
        # The message is printed once per outage, not per frame.
        assert sim.output.count("no HIL_ACTUATOR_CONTROLS") == 1
        while (newer := ap.recv_frame(0.0005)) is not None:  # the newest frame queued so far
            later.append(newer)
        ap.answer(later[-1].time_usec)
        sim.wait_line("link recovered", timeout=2.0)
        # Frames sent before the answer arrived, up to the one the simulator now waits on: it resends
        # that one every resend_s, so a copy (or 0.2 s of silence) ends the loop.
        seen = {f.time_usec for f in later}
        for _ in range(1000):
            newer = ap.recv_frame(0.2)
            if newer is None or newer.time_usec in seen:
                break
            seen.add(newer.time_usec)
            later.append(newer)
        frame = later[-1]
        resumed = frame.time_usec
        for _ in range(5):
            frame = ap.step(frame)
        assert frame.time_usec == resumed + 5 * FRAME_USEC  # lockstep again: one frame per answer
        assert sim.terminate() == 0


def test_peer_that_chatters_without_answering_is_reported(tmp_path):
    """Heartbeats and stale answers every 10 ms do not hide a missing answer."""
    sitl = sitl_toml_with(tmp_path, timeout_s=0.3)
    with SimProcess(56, "--sitl-config", str(sitl)) as sim, ScriptedAutopilot(56) as ap:
        frame = ap.link()
        frame = ap.step(frame)
        deadline = time.monotonic() + 1.5
        while time.monotonic() < deadline and "no HIL_ACTUATOR_CONTROLS" not in sim.output:
            ap.hello()
            ap.answer(frame.time_usec - FRAME_USEC)  # stale
            time.sleep(0.01)
        sim.wait_line(f"no HIL_ACTUATOR_CONTROLS for frame t={frame.time_usec * 1e-6:.3f} s", timeout=0.5)
        assert sim.terminate() == 0


def test_truth_stream_and_info_on_zenoh():
    n = 45
    with SimProcess(n) as sim:
        sim.wait_line("waiting for the autopilot")
        session = bus.open_peer(instance_ports(n).zenoh)
        try:
            sub = session.declare_subscriber(wire.zenoh_key(n, "truth"), bus.zenoh.handlers.FifoChannel(256))
            info = None
            deadline = time.monotonic() + 5.0
            while info is None and time.monotonic() < deadline:  # also proves the link is up
                for reply in session.get(wire.zenoh_key(n, "info"), timeout=1.0):
                    if reply.ok is not None:
                        info = json.loads(reply.ok.payload.to_bytes())
            battery = info.pop("battery")  # the pack's truth, full at the start (simulator.battery)
            assert battery["state_of_charge"] == 1.0 and battery["failure"] == "ok", battery
            assert info == {
                "instance": n, "vehicle": "paper_quad", "scenario": "hover", "actuation": "wrench",
                "physics_hz": RATES.physics_hz, "control_hz": RATES.control_hz, "speed": "max",
                "home": list(HOME), "sim_time_s": 0.0, "resends": 0, "impairment": {}, "failures": {},
                "requests": {"applied": 0, "refused": {}},
            }  # fmt: skip
            # The info reply above is the barrier: our subscription was declared before the query
            # on the same link, so the simulator knows it (zenoh keeps no history).
            with ScriptedAutopilot(n) as ap:
                frame = ap.link()
                positions = {}
                for _ in range(25):
                    positions[frame.time_usec] = frame["ODOMETRY"]
                    frame = ap.step(frame, controls=(0.6, 0.0, 0.0, 0.0), armed=True)
                positions[frame.time_usec] = frame["ODOMETRY"]
                assert sim.terminate() == 0  # flushes the partial batch
            batches = []
            deadline = time.monotonic() + 3.0
            while sum(len(b) for b in batches) < 26 and time.monotonic() < deadline:
                sample = sub.try_recv()
                if sample is None:
                    time.sleep(0.01)
                    continue
                batches.append(TRUTH_CODEC.decode(sample.payload.to_bytes()))
        finally:
            session.close()
    assert [len(b) for b in batches] == [10, 10, 6]
    rows = [row for batch in batches for row in batch]
    col = {name: i for i, name in enumerate(TRUTH_FIELDS)}
    assert [round(r[col["time_s"]] * 1e6) for r in rows] == sorted(positions)
    for row in rows:
        odo = positions[round(row[col["time_s"]] * 1e6)]
        xyz = (row[col["x_m"]], row[col["y_m"]], row[col["z_m"]])
        assert frames.vector_to_ned(xyz) == pytest.approx((odo.x, odo.y, odo.z), abs=1e-6)
    assert rows[0][col["on_ground"]] == 1.0 and rows[-1][col["z_m"]] > 0.0
    assert rows[-1][col["thrust_n"]] == pytest.approx(0.6 * 28.0)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_signal_stops_cleanly_while_linked(sig):
    n = 46 if sig == signal.SIGTERM else 47
    with SimProcess(n) as sim, ScriptedAutopilot(n) as ap:
        frame = ap.link()
        for _ in range(5):
            frame = ap.step(frame)
        start = time.monotonic()
        assert sim.terminate(timeout=2.0, sig=sig) == 0
        assert time.monotonic() - start < 2.0
        line = sim.wait_line("simulator: stopped at t=")
        assert line.startswith(f"simulator: stopped at t={5 * 0.002:.3f} s")


def test_sigterm_while_waiting_for_the_autopilot():
    with SimProcess(48) as sim:
        line = sim.wait_line("waiting for the autopilot")
        assert f"udp 127.0.0.1:{instance_ports(48).hil}" in line
        assert sim.terminate(timeout=2.0) == 0
        sim.wait_line("simulator: stopped at t=0.000 s")


def test_duration_stops_after_the_final_frame():
    with SimProcess(49, "--duration", "0.02") as sim, ScriptedAutopilot(49) as ap:
        frame = ap.link()
        times = [frame.time_usec]
        while True:
            ap.answer(frame.time_usec)
            frame = ap.recv_frame(1.0)
            if frame is None:
                break
            times.append(frame.time_usec)
        assert times == [k * FRAME_USEC for k in range(11)]
        assert sim.wait(10.0) == 0
        sim.wait_line("simulator: stopped at t=0.020 s")


def test_hil_port_in_use_exits_2_naming_the_port():
    n = 51
    port = instance_ports(n).hil
    blocker = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    blocker.bind((wire.LOOPBACK, port))
    try:
        with SimProcess(n) as sim:
            assert sim.wait(20.0) == 2
            assert str(port) in sim.output and "--instance 51" in sim.output
    finally:
        blocker.close()


def test_zenoh_port_in_use_exits_2_naming_the_port():
    n = 52
    port = instance_ports(n).zenoh
    blocker = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
    blocker.bind((wire.LOOPBACK, port))
    blocker.listen(1)
    try:
        with SimProcess(n) as sim:
            assert sim.wait(20.0) == 2
            assert f"zenoh port {port}" in sim.output and "--instance 52" in sim.output
    finally:
        blocker.close()
