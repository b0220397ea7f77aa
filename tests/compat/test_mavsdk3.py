"""MAVSDK-Python 3 (gRPC API, ``from mavsdk import System``) flies a quadsitl vehicle as it flies PX4
SITL: the flows of ``mavsdk3_flows.py`` (what MAVSDK-Python's examples do: telemetry, all params,
the geofence example (a polygon and the "no circle" circle), a geofence upload, a QGC .plan with
rally points, takeoff, a mission with gimbal and camera items, goto, offboard position and
velocity, mission_raw, manual control, land, the manual control example and the loss of its
sticks), in sequence against one vehicle.

MAVSDK-Python 3 starts a ``mavsdk_server`` that listens for gRPC on every interface, so the test
runs it and the vehicle (``quadsitl up``, default instance 0: the default ports MAVSDK expects)
inside a network namespace of their own with only loopback up (``unshare -n``). Where namespaces
are unavailable (not root, no user namespaces) the test is skipped, saying so. The client runs
from ``.venv-mavsdk3`` (``make .venv-mavsdk3``, which ``make test`` makes).
"""

from __future__ import annotations

import json
import shutil
import subprocess
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
CLIENT = REPO / ".venv-mavsdk3" / "bin" / "python"
FLOWS = Path(__file__).with_name("mavsdk3_flows.py")
QUADSITL = REPO / ".venv" / "bin" / "quadsitl"
WALL_LIMIT_S = 240

INSIDE = """
set -u
ip link set lo up
"{quadsitl}" up --speed 2 > "{log}" 2>&1 &
up=$!
timeout {limit} "{client}" "{flows}" udpin://0.0.0.0:14540
rc=$?
kill -INT $up 2>/dev/null; wait $up
exit $rc
"""


def _namespaces_available() -> str | None:
    if shutil.which("unshare") is None or shutil.which("ip") is None:
        return "unshare/ip not installed"
    probe = subprocess.run(["unshare", "-n", "ip", "link", "set", "lo", "up"], capture_output=True, text=True)
    if probe.returncode != 0:
        return f"no network namespace here (unshare -n: {probe.stderr.strip() or probe.returncode})"
    return None


@pytest.mark.timeout(WALL_LIMIT_S + 60)
def test_mavsdk_python3_examples_fly_in_a_loopback_only_namespace(tmp_path):
    why = _namespaces_available()
    if why:
        pytest.skip(f"MAVSDK-Python 3 needs a loopback-only network namespace for its mavsdk_server: {why}")
    assert CLIENT.exists(), "no .venv-mavsdk3: run `make .venv-mavsdk3` (make test does)"
    log = tmp_path / "up.log"
    script = INSIDE.format(quadsitl=QUADSITL, log=log, limit=WALL_LIMIT_S, client=CLIENT, flows=FLOWS)
    started = time.monotonic()
    result = subprocess.run(
        ["unshare", "-n", "bash", "-c", script], capture_output=True, text=True, timeout=WALL_LIMIT_S + 30
    )
    wall = time.monotonic() - started
    events = [json.loads(line) for line in result.stdout.splitlines() if line.startswith("{")]
    transcript = "\n".join(line[:400] for line in result.stdout.splitlines()[-60:])
    full_log = log.read_text() if log.exists() else ""
    up_log = full_log[-3000:]
    detail = f"rc {result.returncode}\n{transcript}\n--- quadsitl up:\n{up_log}"
    by_name = {e["event"]: e for e in events}
    assert "done" in by_name and not [e for e in events if e["event"] == "step_error"], detail
    assert by_name["telemetry"]["local_ok"] and abs(by_name["telemetry"]["lat"] - 47.397742) < 1e-5
    assert by_name["params"]["count"] > 50 and len(by_name["params"]["has"]) == 3
    assert by_name["geofence"]["downloaded"] == 5 and by_name["geofence"]["commands"][-1] == 5004
    example = by_name["geofence_example"]  # examples/geofence.py: accepted, stored as uploaded
    assert example["downloaded"] == 5 and example["commands"] == [5001] * 4 + [5003]
    assert example["radii"][-1] == 0.0
    assert "geofence item 4: a circle of radius <= 0 is no circle, ignored" in full_log
    assert by_name["plan_import"]["rally"] == 2 and by_name["plan_import"]["rally_downloaded"] == 2
    mission = by_name["mission"]
    assert mission["finished"] and mission["total"] == 3
    assert {1000, 1001, 2000} <= set(mission["commands"])  # gimbal and camera items stored, flown
    assert by_name["offboard"]["velocity_north"] > 0.9
    assert by_name["mission_raw"]["total"] == 2
    assert by_name["manual_control"]["mode"] == "POSCTL"
    assert by_name["manual_control"]["north_moved"] > 1.0 > abs(by_name["manual_control"]["east_moved"])
    assert by_name["land"]["disarmed"]
    sticks = by_name["manual_control_example"]  # examples/manual_control.py, 6 s of its inputs
    assert "POSCTL" in sticks["modes"] and set(sticks["modes"]) <= {"HOLD", "POSCTL"}, sticks
    assert sticks["in_air"] == [True]
    lost = by_name["manual_control_lost"]  # then the sticks stop: NAV_RCL_ACT 2, return and land
    assert lost["mode"] == "RETURN_TO_LAUNCH" and lost["disarmed"]
    assert "manual control lost in POSCTL: returning to launch (NAV_RCL_ACT 2)" in full_log
    steps = {e["step"]: e["wall_s"] for e in events if e["event"] == "step_time"}
    print(f"MAVSDK-Python 3 flows: {wall:.1f} s wall in all; per step: {steps}")
    assert wall < WALL_LIMIT_S
