"""Missions flown through the whole stack in-process (simulator core + autopilot core, real MAVLink
bytes, simulation time), driven by gcs_scripts/upload_mission.py's own client: a waypoint mission
with every MISSION_ITEM_REACHED in order, ending landed and disarmed; the paper's circle as timed
items, tracked to a fraction of a millimetre after the approach (no gusts: the hover scenario)."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np

from gcs_scripts import link as mavlink_link
from gcs_scripts.upload_mission import MissionLink, curve_items, fly, items_from_list
from quadcommon import frames
from quadcommon.config import load_scenario
from quadcommon.trajectories import trajectory_from_spec

from ..stack import connect, make_stack

m = mavlink_link.mavutil.mavlink
REPO = Path(__file__).resolve().parents[2]


class Recorder(MissionLink):
    """Also keeps LOCAL_POSITION_NED and POSITION_TARGET_LOCAL_NED (paper frame) by time."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.positions: dict[int, tuple[float, float, float]] = {}
        self.targets: dict[int, tuple[float, float, float]] = {}

    def _handle(self, msg) -> None:
        super()._handle(msg)
        kind = msg.get_type()
        if kind == "LOCAL_POSITION_NED":
            self.positions[msg.time_boot_ms] = frames.vector_from_ned((msg.x, msg.y, msg.z))
        elif kind == "POSITION_TARGET_LOCAL_NED":
            self.targets[msg.time_boot_ms] = frames.vector_from_ned((msg.x, msg.y, msg.z))


def open_link() -> Recorder:
    link = connect(make_stack(), Recorder)
    link.wait_until(lambda lk: lk.position_ned is not None, 1.0, what="telemetry")
    return link


def test_waypoint_mission_reaches_every_item_in_order_and_ends_disarmed(tmp_path):
    spec = {
        "frame": "paper",
        "items": [
            {"type": "takeoff", "altitude_m": 2.0},
            {"type": "waypoint", "position": [2.0, 0.0, 2.0], "hold_s": 1.0},
            {"type": "speed", "speed_m_s": 0.8},
            {"type": "waypoint", "position": [2.0, 1.5, 2.5], "yaw_deg": 90},
            {"type": "loiter", "position": [0.5, 1.5, 2.5], "time_s": 1.0},
            {"type": "land", "position": [0.5, 0.0, 0.0]},
        ],
    }
    items = items_from_list(spec)
    link = open_link()
    try:
        link.upload(items)
        fly(link, items, timeout_s=120.0)
        reached = [seq for _, seq in link.reached]
        assert reached == list(range(len(items)))  # each once, in order
        assert not link.armed and link.landed_state == m.MAV_LANDED_STATE_ON_GROUND
        x, y, z = link.position_paper
        assert math.hypot(x - 0.5, y) < 0.05 and abs(z) < 0.05
    finally:
        link.close()


def test_timed_circle_mission_is_tracked_to_the_analytic_curve(tmp_path):
    duration = 20.0
    traj = trajectory_from_spec(load_scenario("circle").trajectory)
    items = curve_items(traj, duration, 10.0, end="land")
    link = open_link()
    try:
        link.set_message_interval(m.MAVLINK_MSG_ID_LOCAL_POSITION_NED, 50.0)
        link.set_message_interval(m.MAVLINK_MSG_ID_POSITION_TARGET_LOCAL_NED, 50.0)
        link.upload(items)
        fly(link, items, timeout_s=120.0)
        assert [seq for _, seq in link.reached] == list(range(len(items)))
    finally:
        link.close()
    t_ref = np.array(sorted(link.targets)) * 1e-3
    ref = np.array([link.targets[k] for k in sorted(link.targets)])
    t_pos = np.array(sorted(link.positions)) * 1e-3
    pos = np.array([link.positions[k] for k in sorted(link.positions)])
    vehicle = np.column_stack([np.interp(t_ref, t_pos, pos[:, i]) for i in range(3)])

    def curve(t):
        return np.array([traj.sample(float(x)).position_m for x in t])

    def misfit(t0):
        sel = (t_ref > t0 + 1.0) & (t_ref < t0 + duration - 1.0)
        return float(np.abs(ref[sel] - curve(t_ref[sel] - t0)).max())

    # The curve's start time: where the reference fits the analytic circle (the item times are
    # honoured as "not before"; takeoff and the approach make the curve start later).
    first = next(t for t, seq in link.reached if seq == 1)
    coarse = min(np.arange(first - 0.5, first + 0.5, 0.01), key=misfit)
    t0 = min(np.arange(coarse - 0.01, coarse + 0.01, 0.0002), key=misfit)
    assert misfit(t0) < 5e-4  # the reference is the circle (to 0.5 mm, with telemetry float32)
    after = (t_ref >= t0 + 3.0) & (t_ref <= t0 + duration)
    error = np.linalg.norm(vehicle[after] - curve(t_ref[after] - t0), axis=1)
    print(f"circle as a timed mission: error RMS {1e3 * np.sqrt((error**2).mean()):.4f} mm, "
          f"max {1e3 * error.max():.4f} mm over {after.sum()} samples")  # fmt: skip
    assert error.max() < 2e-3


def test_scipy_interpolate_is_imported_at_a_mission_upload_not_at_start():
    """An autopilot core starts and flies frames without scipy.interpolate (~0.13 s of CPU at every
    start before); a mission upload loads it (in the background), and the timed curve's fit at the
    upload's end works: the upload is accepted. In a fresh interpreter: this one has it already."""
    code = (
        "import sys\n"
        "from gcs_scripts.upload_mission import MissionLink, curve_items\n"
        "from quadcommon.config import load_scenario\n"
        "from quadcommon.trajectories import trajectory_from_spec\n"
        "from tests.stack import connect, make_stack\n"
        "link = connect(make_stack(), MissionLink)\n"
        "link.wait_until(lambda lk: lk.position_ned is not None, 1.0, what='telemetry')\n"
        "print('at start', 'scipy.interpolate' in sys.modules)\n"
        "traj = trajectory_from_spec(load_scenario('circle').trajectory)\n"
        "link.upload(curve_items(traj, 5.0, 10.0, end='land'))\n"
        "print('after upload', 'scipy.interpolate' in sys.modules)\n"
        "link.close()\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=90, cwd=REPO)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.split("\n")[:2] == ["at start False", "after upload True"], out.stdout
