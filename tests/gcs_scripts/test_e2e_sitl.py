"""End to end through the real SITL, as a newcomer runs it: simulator + autopilot processes (the
project's launcher), the flying scripts and the recorder as processes, the analysis from the
recorded log. The trajectory-streaming fidelity is measured in-process (simulation time, same
cores and bytes) in test_fly_trajectory_lines_up_with_the_reference.
"""

from __future__ import annotations

import re
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest

from gcs_scripts import fly_setpoints, fly_trajectory, record
from gcs_scripts.analysis.analyze import analyze
from gcs_scripts.analysis.log_reader import read_session
from gcs_scripts.analysis.metrics import indices
from sitl.launcher import Launcher, VehicleSpec, python_script

from ..stack import connect, make_stack
from ..ulog_check import check_ulog
from .test_ulog_analysis import assert_same_indices

pytestmark = pytest.mark.processes  # (tests/conftest.py: the markers)

WALL_LIMIT_S = 60.0


@contextmanager
def _sitl(instance: int, scenario: str, speed: str = "4", log_dir: Path | None = None) -> Iterator[Launcher]:
    # --speed 4, not max: the scripts stream setpoints paced on the telemetry but must still get the
    # CPU; at max the 1 s offboard timeout is ~50 ms of wall time (docs/running.md, "Time and speed").
    spec = VehicleSpec(instance=instance, scenario=scenario, speed=speed,
                       log_dir=str(log_dir) if log_dir is not None else None)  # fmt: skip
    with Launcher() as launcher:
        launcher.start_vehicles([spec], 20.0)
        yield launcher


def _script(launcher: Launcher, module, *args: str):
    return launcher.spawn(Path(module.__file__).name, python_script(Path(module.__file__), *args))


def _recorder(launcher: Launcher, instance: int, out: Path):
    return _script(launcher, record, "--instance", str(instance), "--out", str(out), "--until-disarmed")


def test_fly_setpoints_through_the_sitl_and_record_it(tmp_path: Path) -> None:
    n = 60
    with _sitl(n, "hover", log_dir=tmp_path / "log") as launcher:
        rec = _recorder(launcher, n, tmp_path / "s")
        done = _script(
            launcher, fly_setpoints, "--instance", str(n), "--takeoff-alt", "1.5", "--setpoint", "1", "0.5",
            "1.5", "--hold", "0.5", "--timeout", "30",
        )  # fmt: skip
        assert done.wait(WALL_LIMIT_S) == 0, done.tail()
        reached = r"t=\d+\.\d\d s reached setpoint 1 \(1\.00, 0\.50, 1\.50\) error 0\.\d{3} m"
        assert re.search(reached, done.output)
        assert "disarmed" in done.output
        assert rec.wait(15.0) == 0, rec.tail()  # --until-disarmed: it stops by itself
        assert "stopped (disarmed)" in rec.output
    record_ = read_session(tmp_path / "s.parquet")
    assert record_.scenario == "hover" and record_.controller == "intbs_nlhinf"
    # Ground truth (paper frame, z up) went to the setpoint: 1 m north, 0.5 m LEFT, 1.5 m up.
    i = np.argmin(np.linalg.norm(record_.position_m - (1.0, 0.5, 1.5), axis=1))
    assert np.linalg.norm(record_.position_m[i] - (1.0, 0.5, 1.5)) < 0.1
    paths = analyze([tmp_path / "s.parquet"], tmp_path / "analysis")
    assert (tmp_path / "analysis" / "comparison.md").exists() and len(paths) == 6
    # The autopilot's flight log of the same flight gives the same paper indices (float32 in the
    # log: docs/logs.md's tolerance), over the span both cover.
    (ulg,) = (tmp_path / "log").glob("*/*.ulg")
    check_ulog(ulg)
    from_log = read_session(ulg)
    t0 = max(from_log.time_s[0], record_.time_s[0])
    span = min(from_log.time_s[-1], record_.time_s[-1]) - t0
    parquet, ulog = (indices(read_session(p, (t0, span))) for p in (tmp_path / "s.parquet", ulg))
    assert_same_indices(parquet, ulog)


def test_fly_trajectory_lines_up_with_the_reference() -> None:
    """fly_trajectory's own flight (p, v, a setpoints streamed at 100 Hz, paced by the telemetry)
    against the whole stack in-process: the controller's reference is the streamed trajectory."""
    duration = 4.0
    args, scenario = fly_trajectory.parse_args(
        ["--scenario", "circle", "--duration", str(duration), "--settle", "0.5", "--hold", "0.5"]
    )
    stack = make_stack("circle")
    link = connect(stack)
    trajectory = fly_trajectory.trajectory_from_spec(scenario.trajectory)
    flight = fly_trajectory.TrajectoryFlight(link, trajectory, args.duration)
    args.zenoh = None
    fly_trajectory.fly(link, args, flight)
    t = np.asarray(stack.controller_rows)[:, 0]
    ref = np.asarray(stack.controller_rows)[:, 1:4]
    truth = np.asarray(stack.truth_rows)[:, 1:4]
    window = (t >= flight.t0) & (t <= flight.t0 + duration)
    p_d = np.array([trajectory.sample(x - flight.t0).position_m for x in t[window]])
    # The reference is the streamed trajectory (late by the stream's one-message transit time).
    assert np.max(np.abs(ref[window] - p_d)) < 0.02
    assert np.max(np.linalg.norm(truth[window] - ref[window], axis=1)) < 0.05


def test_gusts_uploaded_for_t0_hit_at_the_in_process_times(tmp_path: Path) -> None:
    """fly_trajectory --gusts: the profile goes over zenoh to the simulator process, anchored at
    the trajectory's t0; the recorded disturbance steps land at t0 + 1 s and t0 + 2 s."""
    n = 62
    profile = tmp_path / "steps.toml"
    profile.write_text(
        'description = "two steps"\n'
        '[[step]]\nchannel = "force_x"\nstart_s = 1.0\nvalue = 1.0\n'
        '[[step]]\nchannel = "torque_roll"\nstart_s = 2.0\nvalue = 0.5\n'
    )
    with _sitl(n, "circle") as launcher:
        rec = _recorder(launcher, n, tmp_path / "g")
        done = _script(
            launcher, fly_trajectory, "--instance", str(n), "--scenario", "circle", "--duration", "3",
            "--settle", "0.5", "--hold", "0.5", "--timeout", "30", "--gusts", str(profile),
        )  # fmt: skip
        assert done.wait(WALL_LIMIT_S) == 0, done.tail()
        t0 = float(re.search(r"^t0=(\d+\.\d+)$", done.output, re.M).group(1))
        assert rec.wait(15.0) == 0, rec.tail()
    flown = read_session(tmp_path / "g.parquet", window=(t0, 3.0))
    assert flown.event_times_s == pytest.approx([1.0, 2.0], abs=0.0021)  # within one control step
