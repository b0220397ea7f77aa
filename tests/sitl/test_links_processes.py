"""Faults on the links of the real SITL (two processes, UDP, ``quadsitl up --impair``): the
ground-station scripts complete over lossy, slow links, and the offboard-loss failsafe fires when
``quadsitl impair`` cuts the API link (quadcommon/impairment.py at the processes' sockets). The
lockstep under HIL loss is in test_sitl_vs_inprocess.py; everything else in simulation time in
test_links_impaired.py."""

from __future__ import annotations

import json
import re
import time
from pathlib import Path

import pytest

from gcs_scripts import fly_setpoints, impair, upload_mission
from quadcommon import bus, wire
from sitl.launcher import Launcher, VehicleSpec, python_script
from tests.ports import instance_ports

pytestmark = pytest.mark.processes  # (tests/conftest.py: the markers)

LOSSY = "loss=5%,delay=50ms"
WALL_LIMIT_S = 90.0


def _info(instance: int, leaf: str) -> dict:
    session = bus.open_peer(instance_ports(instance).zenoh)
    try:
        deadline = time.monotonic() + 20.0
        while time.monotonic() < deadline:  # a fresh session may not know the queryable yet: no reply
            for reply in session.get(wire.zenoh_key(instance, leaf), timeout=2.0):
                if reply.ok is not None:
                    return json.loads(reply.ok.payload.to_bytes())
            time.sleep(0.2)
        raise AssertionError(f"no answer on {leaf} within 20 s")
    finally:
        session.close()


def _script(launcher: Launcher, module, *args: str):
    return launcher.spawn(Path(module.__file__).name, python_script(Path(module.__file__), *args))


@pytest.mark.timeout(240)
def test_fly_setpoints_and_a_mission_upload_complete_over_lossy_slow_ground_links(tmp_path: Path):
    n = 13
    spec = VehicleSpec(instance=n, speed="4", impair=(f"gcs:{LOSSY}", f"api:{LOSSY}"))
    with Launcher() as launcher:
        launcher.start_vehicles([spec], 20.0)
        mission = tmp_path / "square.toml"
        mission.write_text('frame = "paper"\n[[items]]\ntype = "takeoff"\naltitude_m = 2.0\n'
                           + "".join(f'[[items]]\ntype = "waypoint"\nposition = [{x}, {y}, 2.0]\n'
                                     for x, y in [(1, 0), (1, 1), (0, 1)] * 4)
                           + '[[items]]\ntype = "land"\n')  # fmt: skip
        upload = _script(launcher, upload_mission, str(mission), "--instance", str(n),
                         "--url", f"udpin:127.0.0.1:{spec.ports().gcs_remote}")  # fmt: skip
        assert upload.wait(WALL_LIMIT_S) == 0, upload.tail()
        done = _script(launcher, fly_setpoints, "--instance", str(n), "--takeoff-alt", "1.5", "--setpoint",
                       "1", "0.5", "1.5", "--hold", "0.5", "--timeout", "30")  # fmt: skip
        assert done.wait(WALL_LIMIT_S) == 0, done.tail()
        assert re.search(r"reached setpoint 1 \(1\.00, 0\.50, 1\.50\) error 0\.\d{3} m", done.output)
        assert "disarmed" in done.output
        launcher.child(f"autopilot[{n}]").stop()
        out = launcher.child(f"autopilot[{n}]").output
    assert "links impaired: gcs: loss=5%,delay=50ms; api: loss=5%,delay=50ms" in out


@pytest.mark.timeout(240)
def test_offboard_loss_fires_after_com_of_loss_t_once_quadsitl_impair_cuts_the_api_link():
    n = 14
    spec = VehicleSpec(instance=n, speed="1")
    with Launcher() as launcher:
        launcher.start_vehicles([spec], 20.0)
        autopilot = launcher.child(f"autopilot[{n}]")
        flight = _script(launcher, fly_setpoints, "--instance", str(n), "--takeoff-alt", "1.5", "--setpoint",
                         "0", "0", "1.5", "--hold", "60", "--timeout", "30")  # fmt: skip
        flight.wait_line("reached setpoint 1", 60.0)
        answers = impair.change_impairment(["api:loss=100%"], n, 10.0)
        assert answers["autopilot"]["accepted"] and answers["simulator"]["accepted"]
        assert answers["autopilot"]["links"]["api in"]["impairment"] == "loss=100%"
        changed = autopilot.wait_line("impairment changed at t=", 10.0)
        lost = autopilot.wait_line("offboard setpoints lost", 10.0)
        t_cut = float(re.search(r"changed at t=([\d.]+) s", changed).group(1))
        t_lost = float(re.search(r"\[t=\s*([\d.]+)\]", lost).group(1))
        # COM_OF_LOSS_T (1 s) after the last setpoint, which came at most a telemetry period and the
        # zenoh query's handling (a housekeeping tick, 50 ms) before the cut
        assert 0.85 <= t_lost - t_cut <= 1.05, (t_cut, t_lost)
        info = _info(n, "autopilot/info")  # the counts on the autopilot's info queryable
        assert info["impairment"]["api out"]["impairment"] == "loss=100%"
        assert info["impairment"]["api out"]["dropped"] == info["impairment"]["api out"]["sent"] > 0
        assert _info(n, "info")["resends"] >= 0  # the simulator's, beside its sim time
        lines = autopilot.output.splitlines()
        at = lines.index(lost)
        assert lines[at - 1].endswith("mode AUTO.LOITER") and lines[at - 1][:22] == lost[:22]  # hold, then
        flight.stop()
