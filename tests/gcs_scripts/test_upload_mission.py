"""gcs_scripts/upload_mission.py: mission files and curves -> items (pure), and the script against a
real autopilot process over UDP on 127.0.0.1 (instance 22, no simulator needed)."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import pytest

from autopilot.mission.items import WireItem, parse_item
from gcs_scripts.upload_mission import (
    CMD_TIMED,
    MissionFileError,
    curve_items,
    items_from_list,
    read_mission_file,
    read_wpl,
    same_item,
    write_wpl,
)
from quadcommon.trajectories import circle
from sitl.launcher import Launcher

pytestmark = pytest.mark.processes  # (tests/conftest.py: the markers)

REPO = Path(__file__).resolve().parents[2]
SCRIPT = REPO / "gcs_scripts" / "upload_mission.py"
HOME = (47.397742, 8.545594, 488.0)
m = __import__("gcs_scripts.link", fromlist=["mavutil"]).mavutil.mavlink

WPL = """QGC WPL 110
0\t1\t0\t16\t0\t0\t0\t0\t47.397742\t8.545594\t488.0\t1
1\t0\t3\t22\t0\t0\t0\t0\t0\t0\t10\t1
2\t0\t3\t16\t1.5\t0.5\t0\t90\t47.398\t8.546\t10\t1
3\t0\t1\t16\t0\t0\t0\t0\t2.5\t-1.25\t-3\t1
4\t0\t2\t178\t1\t0.8\t-1\t0\t0\t0\t0\t1
5\t0\t3\t21\t0\t0\t0\t0\t0\t0\t0\t1
"""

TOML = """
frame = "paper"
[[items]]
type = "takeoff"
altitude_m = 2.5
[[items]]
type = "waypoint"
position = [2.0, 1.0, 3.0]
hold_s = 1.0
yaw_deg = 30
[[items]]
type = "speed"
speed_m_s = 0.5
[[items]]
type = "loiter"
position = [0.0, 1.0, 3.0]
time_s = 2.0
[[items]]
type = "delay"
time_s = 1.0
[[items]]
type = "land"
"""


def wire(item, seq=0) -> WireItem:
    return WireItem(seq, item.frame, item.command, 0, item.autocontinue, item.param1, item.param2,
                    item.param3, item.param4, item.x, item.y, item.z)  # fmt: skip


def test_wpl_scales_global_and_local_coordinates():
    items = read_wpl(WPL)
    assert len(items) == 6  # PX4 semantics: line 0 is an item too
    assert (items[2].x, items[2].y, items[2].z) == (473980000, 85460000, 10.0)
    assert (items[3].frame, items[3].x, items[3].y) == (m.MAV_FRAME_LOCAL_NED, 25000, -12500)
    assert items[2].param1 == 1.5 and items[2].param4 == 90.0
    assert len(read_wpl(WPL, skip_first=True)) == 5
    back = read_wpl(write_wpl(items))
    assert all(same_item(a, b) for a, b in zip(items, back, strict=True))
    with pytest.raises(MissionFileError, match="QGC WPL 110"):
        read_wpl("hello\n")


def test_every_wpl_item_is_accepted_by_the_autopilot_validation():
    for seq, item in enumerate(read_wpl(WPL)):
        parse_item(wire(item, seq), HOME)


def test_paper_frame_list_flips_y_z_and_yaw_to_ned(tmp_path):
    path = tmp_path / "mission.toml"
    path.write_text(TOML)
    items = read_mission_file(path)
    assert [it.command for it in items] == [22, 16, 178, 19, 93, 21]
    takeoff, wp = items[0], items[1]
    assert takeoff.z == -2.5
    assert (wp.x, wp.y, wp.z) == (20000, -10000, -3.0)  # y left -> east negative, z up -> down
    assert wp.param4 == -30.0  # counter-clockwise (paper) -> clockwise (NED)
    assert items[-1].frame == m.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT and items[-1].x == 0  # land here
    ned = items_from_list({"frame": "ned", "items": [{"type": "waypoint", "position": [2.0, 1.0, -3.0]}]})
    assert (ned[0].x, ned[0].y, ned[0].z) == (20000, 10000, -3.0)
    for seq, item in enumerate(items):
        parse_item(wire(item, seq), HOME)


@pytest.mark.parametrize(
    "spec, message",
    [
        ({"items": [{"type": "rtl"}]}, "frame must be"),
        ({"frame": "enu", "items": [{"type": "rtl"}]}, "frame must be"),
        ({"frame": "ned", "items": []}, "no [[items]]"),
        ({"frame": "ned", "items": [{"type": "jump"}]}, "unknown type"),
        ({"frame": "ned", "items": [{"type": "waypoint", "position": [1, 2]}]}, "position must be"),
        ({"frame": "ned", "items": [{"type": "loiter", "position": [1, 2, 3]}]}, "missing 'time_s'"),
    ],
)
def test_bad_lists_are_explained(spec, message):
    with pytest.raises(MissionFileError, match=message.replace("[", r"\[").replace("]", r"\]")):
        items_from_list(spec)


def test_curve_is_sampled_into_timed_local_items():
    traj = circle(0.5, math.pi / 20, (0.0, 0.0, 2.5), -2.0)
    items = curve_items(traj, 40.0, 10.0, start_time_s=5.0, end="land")
    assert len(items) == 1 + 401 + 1
    assert items[0].command == m.MAV_CMD_NAV_TAKEOFF and items[-1].command == m.MAV_CMD_NAV_LAND
    timed = items[1:-1]
    assert all(it.command == CMD_TIMED and it.frame == m.MAV_FRAME_LOCAL_NED for it in timed)
    assert timed[0].param1 == 5.0 and timed[-1].param1 == pytest.approx(45.0)
    ref = traj.sample(10.0)  # paper frame -> NED, x/y in 0.1 mm
    assert (timed[100].x, timed[100].y) == (round(ref.position_m[0] * 1e4), round(-ref.position_m[1] * 1e4))
    assert timed[100].z == pytest.approx(-ref.position_m[2], abs=1e-6)
    assert curve_items(traj, 1.0, 10.0, end="hold")[-1].command == CMD_TIMED


def run(*args: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, str(SCRIPT), *args], cwd=REPO, capture_output=True, text=True, timeout=timeout
    )


def test_bad_file_exits_2_without_contacting_a_vehicle(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text('frame = "enu"\n[[items]]\ntype = "rtl"\n')
    out = run("--instance", "29", str(path), timeout=20.0)
    assert out.returncode == 2 and "frame must be" in out.stderr


@pytest.fixture(scope="module")
def autopilot():
    """An autopilot process alone (no simulator needed for the mission protocol), for the script's
    command line; the protocol itself is tested in-process (tests/autopilot/mission/test_mission_wire.py)."""
    instance = 22
    with Launcher() as launcher:
        proc = launcher.spawn("autopilot", [sys.executable, "-u", "-m", "autopilot", "--instance",
                                            str(instance), "--no-zenoh"])  # fmt: skip
        proc.wait_line("autopilot: instance", 20.0)
        yield instance
        print(proc.tail(40))


def test_script_uploads_verifies_downloads_and_clears(autopilot, tmp_path):
    instance = str(autopilot)
    path = tmp_path / "mission.toml"
    path.write_text(TOML)
    out = run("--instance", instance, str(path))
    assert out.returncode == 0, out.stderr
    assert "uploaded 6 items" in out.stdout and "download matches the upload" in out.stdout
    saved = tmp_path / "back.waypoints"
    out = run("--instance", instance, "--download", "--save", str(saved))
    assert out.returncode == 0, out.stderr
    assert all(
        same_item(a, b) for a, b in zip(read_mission_file(path), read_wpl(saved.read_text()), strict=True)
    )
    out = run("--instance", instance, "--curve", "helix", "--duration", "20", "--rate", "10")
    assert out.returncode == 0 and "uploaded 203 items" in out.stdout, out.stderr
    out = run("--instance", instance, "--clear")
    assert out.returncode == 0 and "mission cleared" in out.stdout
    out = run("--instance", instance, "--download")
    assert out.returncode == 0 and out.stdout.strip() == "QGC WPL 110"


def test_script_reports_a_refused_upload(autopilot, tmp_path):
    path = tmp_path / "servo.waypoints"
    path.write_text("QGC WPL 110\n0\t1\t2\t183\t1\t1500\t0\t0\t0\t0\t0\t1\n")  # DO_SET_SERVO
    out = run("--instance", str(autopilot), str(path))
    assert out.returncode == 1 and "MAV_MISSION_UNSUPPORTED" in out.stderr
