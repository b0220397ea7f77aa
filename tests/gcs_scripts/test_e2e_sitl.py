"""End to end through the real SITL: simulator + autopilot processes, the flying scripts, the
recorder, the analysis. Skipped until both processes exist. Instances 60-69, --speed max.
"""

from __future__ import annotations

import re
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]

from gcs_scripts import fly_setpoints, fly_trajectory, record  # noqa: E402
from gcs_scripts.analysis.analyze import analyze  # noqa: E402
from gcs_scripts.analysis.log_reader import read_session  # noqa: E402

WALL_LIMIT_S = 60.0


def _spawn(*args: str) -> subprocess.Popen:
    return subprocess.Popen(
        [sys.executable, *args], cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
    )


def _terminate(proc: subprocess.Popen) -> str:
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=5)
        except subprocess.TimeoutExpired:
            proc.kill()
    try:
        return proc.communicate(timeout=5)[0] or ""
    except subprocess.TimeoutExpired:
        proc.kill()
        return ""


@contextmanager
def _sitl(instance: int, scenario: str, speed: str = "max") -> Iterator[None]:
    sim = _spawn("-m", "simulator", "--instance", str(instance), "--vehicle", "paper_quad",
                 "--scenario", scenario, "--speed", speed)  # fmt: skip
    ap = _spawn("-m", "autopilot", "--instance", str(instance), "--controller", "intbs_nlhinf",
                "--vehicle", "paper_quad")  # fmt: skip
    try:
        time.sleep(0.5)
        for proc, name in ((sim, "simulator"), (ap, "autopilot")):
            if proc.poll() is not None:
                pytest.fail(f"{name} exited: {proc.communicate()[0]}")
        yield
    finally:
        out_ap, out_sim = _terminate(ap), _terminate(sim)
        print("--- autopilot ---\n" + out_ap[-3000:] + "\n--- simulator ---\n" + out_sim[-3000:])


@pytest.fixture
def hover_sitl() -> Iterator[int]:
    with _sitl(60, "hover"):
        yield 60


@pytest.fixture
def circle_sitl() -> Iterator[int]:
    # Speed 2, not max: this test measures how the streamed trajectory lines up with the reference;
    # at max speed on a loaded 2-core machine the 100 Hz Python stream falls behind the simulation
    # by tenths of a (simulated) second now and then, which is the machine, not the stream.
    with _sitl(61, "circle", speed="2"):
        yield 61


def _run_script(module, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, str(Path(module.__file__)), *args],
        cwd=REPO,
        capture_output=True,
        text=True,
        timeout=WALL_LIMIT_S,
    )


def _finish_recorder(proc: subprocess.Popen) -> str:
    """The recorder stops by itself after the disarm (--until-disarmed)."""
    try:
        out = proc.communicate(timeout=15)[0]
    except subprocess.TimeoutExpired:
        out = _terminate(proc)
        pytest.fail(f"recorder did not stop after the disarm:\n{out}")
    assert proc.returncode == 0, out
    return out


def test_fly_setpoints_through_the_sitl_and_record_it(hover_sitl: int, tmp_path: Path) -> None:
    n = hover_sitl
    rec = _spawn(
        str(Path(record.__file__)), "--instance", str(n), "--out", str(tmp_path / "s"), "--until-disarmed"
    )
    try:
        done = _run_script(
            fly_setpoints, "--instance", str(n), "--takeoff-alt", "1.5", "--setpoint", "1", "0.5", "1.5",
            "--hold", "0.5", "--timeout", "30",
        )  # fmt: skip
        assert done.returncode == 0, done.stdout + done.stderr
        assert re.search(
            r"t=\d+\.\d\d s reached setpoint 1 \(1\.00, 0\.50, 1\.50\) error 0\.\d{3} m", done.stdout
        )
        assert "disarmed" in done.stdout
        rec_out = _finish_recorder(rec)
    finally:
        _terminate(rec)
    assert "stopped (disarmed)" in rec_out
    record_ = read_session(tmp_path / "s.parquet")
    assert record_.scenario == "hover" and record_.controller == "intbs_nlhinf"
    # Ground truth (paper frame, z up) went to the setpoint: 1 m north, 0.5 m LEFT, 1.5 m up.
    i = np.argmin(np.linalg.norm(record_.position_m - (1.0, 0.5, 1.5), axis=1))
    assert np.linalg.norm(record_.position_m[i] - (1.0, 0.5, 1.5)) < 0.1
    paths = analyze([tmp_path / "s.parquet"], tmp_path / "analysis")
    assert (tmp_path / "analysis" / "comparison.md").exists() and len(paths) == 6


def test_fly_trajectory_through_the_sitl_lines_up_with_the_reference(
    circle_sitl: int, tmp_path: Path
) -> None:
    n = circle_sitl
    duration = 4.0
    rec = _spawn(
        str(Path(record.__file__)), "--instance", str(n), "--out", str(tmp_path / "c"), "--until-disarmed"
    )
    try:
        done = _run_script(
            fly_trajectory, "--instance", str(n), "--scenario", "circle", "--duration", str(duration),
            "--settle", "0.5", "--hold", "0.5", "--timeout", "30",
        )  # fmt: skip
        assert done.returncode == 0, done.stdout + done.stderr
        t0 = float(re.search(r"^t0=(\d+\.\d+)$", done.stdout, re.M).group(1))
        _finish_recorder(rec)
    finally:
        _terminate(rec)
    flown = read_session(tmp_path / "c.parquet", window=(t0, duration))
    assert flown.time_s[0] == pytest.approx(0.0, abs=1e-6)
    assert flown.time_s[-1] == pytest.approx(duration, abs=0.003)
    _, scenario = fly_trajectory.parse_args(["--scenario", "circle"])
    trajectory = fly_trajectory.trajectory_from_spec(scenario.trajectory)
    p_d = np.array([trajectory.sample(t).position_m for t in flown.time_s])
    # The controller's reference is the streamed trajectory (late by the stream's transit time).
    assert np.max(np.abs(flown.position_ref_m - p_d)) < 0.02
    assert np.max(np.linalg.norm(flown.position_error_m, axis=1)) < 0.05


@pytest.fixture
def circle_sitl_62() -> Iterator[int]:
    with _sitl(62, "circle"):
        yield 62


def test_gusts_uploaded_for_t0_hit_at_the_in_process_times(circle_sitl_62: int, tmp_path: Path) -> None:
    n = circle_sitl_62
    profile = tmp_path / "steps.toml"
    profile.write_text(
        'description = "two steps"\n'
        '[[step]]\nchannel = "force_x"\nstart_s = 1.0\nvalue = 1.0\n'
        '[[step]]\nchannel = "torque_roll"\nstart_s = 2.0\nvalue = 0.5\n'
    )
    rec = _spawn(
        str(Path(record.__file__)), "--instance", str(n), "--out", str(tmp_path / "g"), "--until-disarmed"
    )
    try:
        done = _run_script(
            fly_trajectory, "--instance", str(n), "--scenario", "circle", "--duration", "3",
            "--settle", "0.5", "--hold", "0.5", "--timeout", "30", "--gusts", str(profile),
        )  # fmt: skip
        assert done.returncode == 0, done.stdout + done.stderr
        t0 = float(re.search(r"^t0=(\d+\.\d+)$", done.stdout, re.M).group(1))
        _finish_recorder(rec)
    finally:
        _terminate(rec)
    flown = read_session(tmp_path / "g.parquet", window=(t0, 3.0))
    assert flown.event_times_s == pytest.approx([1.0, 2.0], abs=0.0021)  # within one control step
