"""MAVSDK-Python 3 (gRPC API, ``from mavsdk import System``) flies a quadsitl vehicle as it flies PX4
SITL: the flows of ``mavsdk3_flows.py`` (what MAVSDK-Python's examples do: telemetry, all params,
the geofence example (a polygon and the "no circle" circle), a geofence upload, a QGC .plan with
rally points, takeoff, a mission with gimbal and camera items, goto, offboard position and
velocity, mission_raw, manual control, land, the manual control example and the loss of its
sticks), in sequence against one vehicle; and upstream's own examples unchanged (``upstream/``):
the log download, follow-me and orbit.

MAVSDK-Python 3 starts a ``mavsdk_server`` that listens for gRPC on every interface (a fixed port), so
the test runs it and the vehicle (``quadsitl up``, default instance 0 on the shipped default ports
MAVSDK expects, not the test process's port block) inside a network namespace of their own with only
loopback up (``unshare -n``): the one namespace of the suite. Where namespaces
are unavailable (not root, no user namespaces) the test is skipped, saying so. The client runs
from ``.venv-mavsdk3`` (``make .venv-mavsdk3``, which ``make test`` makes).
"""

from __future__ import annotations

import hashlib
import json
import shlex
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

from tests.ports import shipped_ports_environment

pytestmark = [pytest.mark.processes, pytest.mark.compat]  # (tests/conftest.py: the markers)

REPO = Path(__file__).resolve().parents[2]
CLIENT = REPO / ".venv-mavsdk3" / "bin" / "python"
FLOWS = Path(__file__).with_name("mavsdk3_flows.py")
QUADSITL = f"{shlex.quote(sys.executable)} -m sitl.cli"  # quadsitl, from this checkout
WALL_LIMIT_S = 240
# MAVSDK-Python 3.15.3's examples/follow_me_example.py and examples/do_orbit.py, byte for byte.
FOLLOW_EXAMPLE = Path(__file__).with_name("upstream") / "follow_me_example.py"
FOLLOW_EXAMPLE_BLOB = "3ec694085cbda5410b6a731748211412511b384b"  # its git blob id at tag 3.15.3
ORBIT_EXAMPLE = Path(__file__).with_name("upstream") / "do_orbit.py"
ORBIT_EXAMPLE_BLOB = "d824308bd682c21deb9d1bba4595e48fb3777670"
ATTITUDE_EXAMPLE = Path(__file__).with_name("upstream") / "offboard_attitude.py"
ATTITUDE_EXAMPLE_BLOB = "b1ca62589ed4ef4035533cfbbe30a2dfef12ec4f"
ORBIT_FOLLOW_LIMIT_S = 170  # the examples wait 27 s, 70 s and 8 s: 105 s at real time
# The vehicle's speed for the three examples; paced.py divides their waits by it, so they wait the
# simulated seconds they wait against a vehicle at real time (35 s of wall time in all).
ORBIT_FOLLOW_SPEED = 3
PACED = Path(__file__).with_name("paced.py")

INSIDE = """
set -u
ip link set lo up
{quadsitl} up --speed 2 --no-log > "{log}" 2>&1 &
up=$!
timeout {limit} "{client}" "{flows}" udpin://0.0.0.0:14540
rc=$?
kill -INT $up 2>/dev/null; wait $up
exit $rc
"""


# The three examples on one vehicle at --speed ORBIT_FOLLOW_SPEED, each run unchanged by paced.py with
# its waits (asyncio.sleep: wall seconds, against PX4 SITL at real time) divided by that factor:
# follow-me first (it ends landing), then, once the vehicle has landed and disarmed, the orbit (it
# ends with a return to launch, left to fly when the script leaves), then offboard attitude (taken
# over in the air: its arm is answered "already armed", its sequence then flown whole).
INSIDE_ORBIT_FOLLOW = """
set -u
ip link set lo up
{quadsitl} up --speed {speed} --no-log > "{log}" 2>&1 &
up=$!
timeout {limit} "{client}" "{paced}" {speed} "{follow}"
follow=$?
for i in $(seq 120); do grep -q "landed: disarmed" "{log}" && break; sleep 0.25; done
timeout {limit} "{client}" "{paced}" {speed} "{orbit}"
orbit=$?
timeout {limit} "{client}" "{paced}" {speed} "{attitude}"
attitude=$?
kill -INT $up 2>/dev/null; wait $up
echo "exit codes: follow $follow orbit $orbit attitude $attitude"
exit $((follow || orbit || attitude))
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
        ["unshare", "-n", "bash", "-c", script], capture_output=True, text=True, timeout=WALL_LIMIT_S + 30,
        cwd=REPO, env=shipped_ports_environment(),
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


def _git_blob_id(path: Path) -> str:
    data = path.read_bytes()
    return hashlib.sha1(b"blob %d\0" % len(data) + data).hexdigest()


# MAVSDK-Python 3.15.3's log, FTP, IMU and shell examples, byte for byte (upstream/README.md), their
# git blob ids at the tag.
CLIENT_EXAMPLES = {
    "logfile_download.py": "d6020b662c88f974f1d6ed680cc8dfe71f4ec35c",
    "ftp_list_dir.py": "23fac3852ec8d31af45fdda6e90a73cd5a7ec5dd",
    "ftp_download_file.py": "2bb78da0789dcbad7a82c9663ba71da1f81edce5",
    "highres_imu.py": "b23ead3d53a1e55f6130e7ad1e60cf4cdc609b8c",
    "shell.py": "5d7e0a26f087f026904e0b22bdc1bb8510cf3df1",
}
CLIENT_EXAMPLES_LIMIT_S = 150
# The FTP examples talk to a mavsdk_server already running on localhost:50051 (their
# ``mavsdk_server_address``), so the script starts one for the vehicle; the log, IMU and shell
# examples start their own on udpin://0.0.0.0:14540, as written. The download example's file is a PX4
# flight-controller firmware image: the one change is that path, to a log on this vehicle (sed on
# a temporary copy). The IMU example prints until it is stopped (10 s: it prints at 200 Hz once
# connected), maybe in the middle of a line: its exit status goes on a line of its own. The shell
# example is given "ver all" on its stdin after 8 s; the script does not wait for that input to be
# written when the example has left before (it leaves at the prompt).
INSIDE_CLIENT_EXAMPLES = """
set -u
ip link set lo up
{quadsitl} up --speed 2 --log-dir "{log_dir}" > "{log}" 2>&1 &
up=$!
cd "{downloads}"
"{server}" -p 50051 udpin://0.0.0.0:14540 > "{server_log}" 2>&1 &
server=$!
echo "=== ftp_list_dir"; timeout 40 "{client}" "{examples}/ftp_list_dir.py"; echo "=== rc $?"
echo "=== ftp_download_file"; timeout 40 "{client}" "{download}"; echo "=== rc $?"
kill $server; wait $server
echo "=== logfile_download"; timeout 60 "{client}" "{examples}/logfile_download.py"; echo "=== rc $?"
echo "=== highres_imu"; timeout 10 "{client}" "{examples}/highres_imu.py"; rc=$?; echo; echo "=== rc $rc"
echo "=== shell"; timeout 20 "{client}" "{examples}/shell.py" < <(exec 2>/dev/null; sleep 8; echo "ver all")
rc=$?; echo; echo "=== rc $rc"
kill -INT $up 2>/dev/null; wait $up
"""


def _sections(stdout: str) -> dict[str, tuple[str, int]]:
    """The script's output per example: (text, exit status)."""
    out, name, lines = {}, None, []
    for line in stdout.splitlines():
        if line.startswith("=== rc "):
            out[name] = ("\n".join(lines), int(line.split()[-1]))
        elif line.startswith("=== "):
            name, lines = line[4:], []
        else:
            lines.append(line)
    return out


@pytest.mark.timeout(CLIENT_EXAMPLES_LIMIT_S + 60)
def test_mavsdk_python3s_own_log_ftp_imu_and_shell_examples_run(tmp_path, flight_logs):
    """MAVSDK-Python 3.15.3's ``examples/logfile_download.py`` (it lists the vehicle's logs and
    downloads each to ./log-<date>.ulog; the files are the vehicle's, byte for byte),
    ``ftp_list_dir.py``, ``ftp_download_file.py`` (its firmware path replaced by a log's),
    ``highres_imu.py`` and ``shell.py``, against one ``quadsitl up``."""
    why = _namespaces_available()
    if why:
        pytest.skip(f"MAVSDK-Python 3 needs a loopback-only network namespace for its mavsdk_server: {why}")
    assert CLIENT.exists(), "no .venv-mavsdk3: run `make .venv-mavsdk3` (make test does)"
    upstream = Path(__file__).with_name("upstream")
    for name, blob in CLIENT_EXAMPLES.items():
        assert _git_blob_id(upstream / name) == blob, f"{name} is not upstream's text"
    from .vehicles import LOG_NAMES, vehicle_logs

    log_dir, downloads = tmp_path / "log", tmp_path / "downloads"
    downloads.mkdir()
    on_vehicle = vehicle_logs(log_dir, flight_logs)
    firmware = "/etc/extras/px4_io-v2_default.bin"
    text = (upstream / "ftp_download_file.py").read_text()
    assert text.count(firmware) == 1
    download = tmp_path / "ftp_download_file.py"
    download.write_text(text.replace(firmware, f"/log/{LOG_NAMES[1]}"))
    server = CLIENT.parent.parent / "lib"
    server_binary = next(server.glob("python3*/site-packages/mavsdk/bin/mavsdk_server"))
    up_log, server_log = tmp_path / "up.log", tmp_path / "server.log"
    script = INSIDE_CLIENT_EXAMPLES.format(
        quadsitl=QUADSITL, log_dir=log_dir, log=up_log, downloads=downloads, server=server_binary,
        server_log=server_log, client=CLIENT, examples=upstream, download=download,
    )
    result = subprocess.run(["unshare", "-n", "bash", "-c", script], capture_output=True, text=True,
                            timeout=CLIENT_EXAMPLES_LIMIT_S + 30, cwd=REPO,
                            env=shipped_ports_environment())  # fmt: skip
    detail = (
        f"rc {result.returncode}\n{result.stdout[-4000:]}\n{result.stderr[-2000:]}\n--- quadsitl up:\n"
        + (up_log.read_text()[-3000:] if up_log.exists() else "")
    )
    sections = _sections(result.stdout)
    listed, status = sections["ftp_list_dir"]
    assert status == 0 and "ListDirectoryData: [dirs: ['log'], files: []]" in listed, detail
    got, status = sections["ftp_download_file"]
    size = on_vehicle[1].stat().st_size
    assert status == 0 and f"Got {size} of {size} bytes" in got, detail
    assert (downloads / Path(LOG_NAMES[1]).name).read_bytes() == on_vehicle[1].read_bytes()
    logs, status = sections["logfile_download"]
    assert status == 0, detail
    assert "Log 0 from 2024-05-01T10:00:00Z" in logs and "Log 1 from 2024-05-01T10:05:30Z" in logs
    expected = {
        "log-2024-05-01T10-00-00Z.ulog": on_vehicle[0],
        "log-2024-05-01T10-05-30Z.ulog": on_vehicle[1],
    }
    for name, original in expected.items():
        assert (downloads / name).read_bytes() == original.read_bytes(), name
    imu, status = sections["highres_imu"]
    assert status == 124, detail  # it prints until stopped
    assert imu.count("HIGHRES_IMU (105)") > 20, detail
    assert "Z Acceleration (m/s^2): -9." in imu, detail  # at rest: specific force up, FRD z down
    # examples/shell.py returns from run() once it printed the prompt, so asyncio.run ends there:
    # upstream's example stops before it reads stdin, against PX4 as here (the shell's own
    # commands run in test_mavsdk.py::test_log_files_ftp_and_shell).
    shell, status = sections["shell"]
    assert status == 0 and shell.endswith("-- Connected to drone!\nnsh> "), detail


@pytest.mark.timeout(ORBIT_FOLLOW_LIMIT_S + 60)
def test_mavsdk_python3s_own_follow_me_orbit_and_offboard_attitude_examples_run_unchanged(tmp_path):
    """``examples/follow_me_example.py``, ``examples/do_orbit.py`` and
    ``examples/offboard_attitude.py`` of MAVSDK-Python 3.15.3, unchanged, against one vehicle (at
    ``--speed 3``, their waits paced to it by ``paced.py``: the same simulated seconds): every
    call they make succeeds (the FLW_TGT_* configuration, AUTO.FOLLOW_TARGET, the target reports,
    DO_ORBIT, the return, OFFBOARD on SET_ATTITUDE_TARGET and its stop), and the vehicle says it flew
    them. What they fly is checked in simulation time (tests/sitl/test_orbit_follow.py,
    tests/autopilot/mavlink/test_offboard.py)."""
    why = _namespaces_available()
    if why:
        pytest.skip(f"MAVSDK-Python 3 needs a loopback-only network namespace for its mavsdk_server: {why}")
    assert CLIENT.exists(), "no .venv-mavsdk3: run `make .venv-mavsdk3` (make test does)"
    assert _git_blob_id(FOLLOW_EXAMPLE) == FOLLOW_EXAMPLE_BLOB, "the example is not upstream's text"
    assert _git_blob_id(ORBIT_EXAMPLE) == ORBIT_EXAMPLE_BLOB, "the example is not upstream's text"
    assert _git_blob_id(ATTITUDE_EXAMPLE) == ATTITUDE_EXAMPLE_BLOB, "the example is not upstream's text"
    up_log = tmp_path / "up.log"
    each = ORBIT_FOLLOW_LIMIT_S // 2 + 10
    script = INSIDE_ORBIT_FOLLOW.format(quadsitl=QUADSITL, log=up_log, limit=each, client=CLIENT,
                                        speed=ORBIT_FOLLOW_SPEED, paced=PACED, follow=FOLLOW_EXAMPLE,
                                        orbit=ORBIT_EXAMPLE, attitude=ATTITUDE_EXAMPLE)  # fmt: skip
    result = subprocess.run(["unshare", "-n", "bash", "-c", script], capture_output=True, text=True,
                            timeout=ORBIT_FOLLOW_LIMIT_S + 30, cwd=REPO,
                            env=shipped_ports_environment())  # fmt: skip
    full_log = up_log.read_text() if up_log.exists() else ""
    detail = (f"rc {result.returncode}\n{result.stdout[-3000:]}\n{result.stderr[-2000:]}\n--- quadsitl up:\n"
              f"{full_log[-4000:]}")  # fmt: skip
    assert result.returncode == 0, detail
    assert "-- Stopping Follow Me Mode" in result.stdout and "--- Landing" in result.stdout, detail
    assert "-- Hover at 60% thrust" in result.stdout and "failed with error code" not in result.stdout, detail
    for said in ("mode AUTO.FOLLOW_TARGET", "follow-me: target found, following", "landed: disarmed",
                 "mode ORBIT", "orbit: radius 10.0 m clockwise at 2.0 m/s, yaw front to the centre",
                 "mode AUTO.RTL", "mode OFFBOARD"):  # fmt: skip
        assert said in full_log, (said, detail)
    assert "mode AUTO.LAND" in full_log[full_log.rindex("mode OFFBOARD"):], detail  # its stop, then land
    assert "refused" not in full_log, detail
