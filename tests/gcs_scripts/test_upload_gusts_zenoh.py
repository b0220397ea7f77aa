"""End to end over real zenoh sessions on loopback: upload_gusts() against the simulator's own
GustUploadServer and SimulatorCore on a hub session, polled from a loop as simulator/app.py polls
it (the core held at t = 10 s: no frames are flown here).
"""

from __future__ import annotations

import json
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from gcs_scripts import upload_gusts as ug
from quadcommon import bus, wire
from quadcommon.config import CONFIG_DIR
from simulator.core import SimulatorCore, SimulatorSetup
from simulator.environment.gust_profile import GustProfile, load_gust_profile, profile_to_mapping
from simulator.environment.gust_upload import handle_gust_request
from simulator.truth_bus import GustUploadServer
from tests.ports import instance_ports

pytestmark = pytest.mark.processes  # (tests/conftest.py: the markers)

INSTANCE = 81  # (its zenoh port on the test process's port block: tests/ports.py)


class ServedSimulator:
    """A real SimulatorCore at t = 10 s behind the real upload server on a hub session, polled by a
    bounded background loop (the simulator's loop); uploads land in the core as in the process."""

    def __init__(self, instance: int) -> None:
        self.session = bus.open_hub(instance_ports(instance).zenoh)
        # The circle's profile is paper_steps; a vehicle with drag, so wind is accepted silently.
        self.core = SimulatorCore(SimulatorSetup.load(scenario="circle", vehicle="paper_quad_drag"))
        self.core.k = round(10.0 / self.core.dt_control)
        self.sim_time_s = self.core.t
        self.installed: list[tuple[GustProfile, float]] = []
        core_install = self.core.schedule_gust_profile

        def install(profile: GustProfile, start_s: float) -> None:
            core_install(profile, start_s)
            self.installed.append((profile, start_s))

        self.core.schedule_gust_profile = install  # type: ignore[method-assign] # observe, then the core
        key = wire.zenoh_key(instance, "sim/gusts")
        self.server = GustUploadServer(self.session, key, self.core.upload_gusts)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)
        self._thread.start()

    @property
    def schedule(self):
        """The schedule the next frame flies (an accepted upload swaps in at a frame boundary)."""
        return self.core._pending_schedule or self.core.schedule

    def _loop(self) -> None:
        deadline = time.monotonic() + 60.0  # bounded even if a test forgets to stop it
        while not self._stop.is_set() and time.monotonic() < deadline:
            self.server.poll()
            time.sleep(0.001)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=5.0)
        self.server.close()
        self.session.close()


@pytest.fixture(scope="module")
def simulator() -> Iterator[ServedSimulator]:
    sim = ServedSimulator(INSTANCE)
    try:
        yield sim
    finally:
        sim.close()


def test_accepted_upload_replaces_the_start_up_profile(simulator: ServedSimulator) -> None:
    mapping = profile_to_mapping(load_gust_profile("gust_1cos_x"))
    answer = ug.upload_gusts(mapping, INSTANCE, ug.start_spec(after_s=1.5), timeout=5.0)
    assert answer == {
        "accepted": True,
        "start_s": 11.5,
        "summary": "3 m/s 1-cos gust along x, 10-12 s: 1-cos gust 3 m/s along +x at 10 s for 2 s",
    }
    profile, start_s = simulator.installed[-1]
    assert profile == load_gust_profile("gust_1cos_x") and start_s == 11.5
    force, torque, wind = simulator.schedule.evaluate(11.5 + 11.0)  # the gust's peak
    assert force == (0.0, 0.0, 0.0) and torque == (0.0, 0.0, 0.0)  # the paper's steps are gone
    assert wind == pytest.approx((3.0, 0.0, 0.0))


def test_rejected_upload_returns_the_exact_validation_message(simulator: ServedSimulator) -> None:
    before = len(simulator.installed)
    bad = {
        "one_minus_cosine": [
            {"start_s": 0.0, "duration_s": 1.0, "amplitude_m_s": 2.0, "direction": [0, 0, 0]}
        ]
    }
    answer = ug.upload_gusts(bad, INSTANCE, "now", timeout=5.0)
    expected = json.loads(handle_gust_request(ug.build_request(bad, "now"), simulator.sim_time_s).reply)
    assert answer == expected
    assert answer["error"].startswith("gust upload: key 'profile.one_minus_cosine[0].direction' = [0, 0, 0]")
    assert len(simulator.installed) == before


def test_reusing_an_open_session(simulator: ServedSimulator) -> None:
    session = bus.open_peer(instance_ports(INSTANCE).zenoh)
    try:
        for at in (20.0, 30.0):
            answer = ug.upload_gusts({}, INSTANCE, {"at_s": at}, timeout=5.0, session=session)
            assert answer["accepted"] and answer["start_s"] == at
    finally:
        session.close()
    assert simulator.installed[-1] == (GustProfile(), 30.0)


def test_command_line_exit_codes(
    simulator: ServedSimulator, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    good = str(CONFIG_DIR / "gusts" / "mixed.toml")
    assert ug.main([good, "--instance", str(INSTANCE), "--start-at", "12", "--timeout", "5"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("accepted: starts at t = 12.000 s (simulation time): Mixed:")
    assert simulator.installed[-1] == (load_gust_profile("mixed"), 12.0)

    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"dryden": {"w20_m_s": 99.0, "altitude_m": 2.5, "seed": 1}}))
    assert ug.main([str(bad), "--instance", str(INSTANCE), "--timeout", "5"]) == 1
    err = capsys.readouterr().err
    assert err.strip() == (
        "rejected: gust upload: key 'profile.dryden.w20_m_s' = 99.0 is invalid; allowed: [0, 30] (m/s)"
    )

    assert ug.main([good, "--instance", str(INSTANCE), "--start-at", "1", "--timeout", "5"]) == 1  # past
    assert "key 'start.at_s' = 1.0 is invalid" in capsys.readouterr().err


def test_script_runs_as_a_file_from_any_directory(simulator: ServedSimulator, tmp_path: Path) -> None:
    profile = str(CONFIG_DIR / "gusts" / "dryden_light.toml")
    command = [
        sys.executable,
        str(Path(ug.__file__)),
        profile,
        "--instance",
        str(INSTANCE),
        "--start-after",
        "2",
    ]
    done = subprocess.run(command, cwd=tmp_path, capture_output=True, text=True, timeout=60, check=False)
    assert done.returncode == 0, done.stderr
    assert "accepted: starts at t = 12.000 s (simulation time): Light Dryden turbulence" in done.stdout
    assert simulator.installed[-1] == (load_gust_profile("dryden_light"), 12.0)
